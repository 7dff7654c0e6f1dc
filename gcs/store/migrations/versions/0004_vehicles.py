"""Registered live vehicles (a restart lists them under the same ids and reopens their links).

Revision ID: 0004
Revises: 0003
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "vehicles",
        sa.Column("id", sa.String(16), primary_key=True),
        sa.Column("connection", sa.String(200), nullable=False, unique=True),
        sa.Column("system_id", sa.Integer(), nullable=True),
        sa.Column("signed", sa.Boolean(), nullable=False),
        sa.Column("registered_utc_s", sa.Float(), nullable=False),
    )


def downgrade() -> None:
    op.drop_table("vehicles")

"""A flight's checkpoint: the team controller as it was, for a restart.

Revision ID: 0002
Revises: 0001
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("flights") as batch:
        batch.add_column(sa.Column("checkpoint", sa.LargeBinary(), nullable=True))
        batch.add_column(sa.Column("checkpoint_utc_s", sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("flights") as batch:
        batch.drop_column("checkpoint_utc_s")
        batch.drop_column("checkpoint")

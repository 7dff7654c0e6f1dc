"""Scenarios, flights, their vehicles, events and uploads.

Revision ID: 0001
Revises:
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "scenarios",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("media_type", sa.String(40), nullable=False),
        sa.Column("body", sa.Text(), nullable=False),
        sa.Column("created_utc_s", sa.Float(), nullable=False),
    )
    op.create_table(
        "flights",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("scenario_id", sa.String(64), sa.ForeignKey("scenarios.id"), nullable=False),
        sa.Column("state", sa.String(20), nullable=False),
        sa.Column("team_time_s", sa.Float(), nullable=True),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("start_utc_s", sa.Float(), nullable=True),
        sa.Column("resume", sa.JSON(), nullable=True),
        sa.Column("created_utc_s", sa.Float(), nullable=False),
        sa.Column("updated_utc_s", sa.Float(), nullable=False),
    )
    op.create_table(
        "flight_vehicles",
        sa.Column("flight_id", sa.String(64), sa.ForeignKey("flights.id"), primary_key=True),
        sa.Column("vehicle_id", sa.String(64), primary_key=True),
        sa.Column("connection", sa.String(200), nullable=True),
        sa.Column("system_id", sa.Integer(), nullable=True),
        sa.Column("phase", sa.String(20), nullable=False),
    )
    op.create_table(
        "events",
        sa.Column("flight_id", sa.String(64), sa.ForeignKey("flights.id"), primary_key=True),
        sa.Column("seq", sa.Integer(), primary_key=True),
        sa.Column("kind", sa.String(20), nullable=False),
        sa.Column("utc_s", sa.Float(), nullable=True),
        sa.Column("t_s", sa.Float(), nullable=False),
        sa.Column("vehicle", sa.String(64), nullable=True),
        sa.Column("strategy", sa.String(20), nullable=True),
        sa.Column("value", sa.Float(), nullable=True),
        sa.Column("reason", sa.Text(), nullable=False),
        sa.Column("payload", sa.JSON(), nullable=True),
    )
    op.create_table(
        "uploads",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("flight_id", sa.String(64), sa.ForeignKey("flights.id"), nullable=False),
        sa.Column("vehicle_id", sa.String(64), nullable=False),
        sa.Column("utc_s", sa.Float(), nullable=True),
        sa.Column("what", sa.String(200), nullable=False),
        sa.Column("items", sa.JSON(), nullable=False),
    )
    op.create_index("ix_uploads_flight_id", "uploads", ["flight_id"])


def downgrade() -> None:
    op.drop_index("ix_uploads_flight_id", "uploads")
    for table in ("uploads", "events", "flight_vehicles", "flights", "scenarios"):
        op.drop_table(table)

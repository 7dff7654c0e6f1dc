"""Alembic's environment: run on the connection :class:`gcs.store.repository.Store` gives."""

from __future__ import annotations

from alembic import context

from gcs.store.models import Base

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=Base.metadata)
with context.begin_transaction():
    context.run_migrations()

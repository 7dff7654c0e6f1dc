"""Persistence: scenarios, flights, their events, the missions uploaded and the live vehicles
registered, in SQL.

SQLite by default (a file, nothing to set up), PostgreSQL through the same SQLAlchemy URL;
the schema is created and upgraded by Alembic migrations (:func:`gcs.store.repository.Store.open`
runs them).
"""

from gcs.store.repository import FlightRecordRow, Registration, Store, StoreError

__all__ = ["FlightRecordRow", "Registration", "Store", "StoreError"]

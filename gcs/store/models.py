"""The tables (SQLAlchemy 2 declarative models); the schema itself is the migrations'."""

from __future__ import annotations

from typing import Any

from sqlalchemy import JSON, Boolean, Float, ForeignKey, Integer, LargeBinary, String, Text
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column


class Base(DeclarativeBase):
    pass


class ScenarioRow(Base):
    """A scenario as uploaded: immutable, named by the SHA-256 of its text."""

    __tablename__ = "scenarios"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    media_type: Mapped[str] = mapped_column(String(40))
    body: Mapped[str] = mapped_column(Text)
    created_utc_s: Mapped[float] = mapped_column(Float)


class FlightRow(Base):
    """One flight: its scenario, state, team time (with a version for updates) and what it
    needs to resume."""

    __tablename__ = "flights"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    scenario_id: Mapped[str] = mapped_column(ForeignKey("scenarios.id"))
    state: Mapped[str] = mapped_column(String(20))
    team_time_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    version: Mapped[int] = mapped_column(Integer, default=1)
    start_utc_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    resume: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    checkpoint: Mapped[bytes | None] = mapped_column(LargeBinary, nullable=True, deferred=True)
    """The flight runner's checkpoint (its team controller), for a restart."""
    checkpoint_utc_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    created_utc_s: Mapped[float] = mapped_column(Float)
    updated_utc_s: Mapped[float] = mapped_column(Float)


class FlightVehicleRow(Base):
    """A vehicle in a flight: how it is reached and the phase it is in."""

    __tablename__ = "flight_vehicles"

    flight_id: Mapped[str] = mapped_column(ForeignKey("flights.id"), primary_key=True)
    vehicle_id: Mapped[str] = mapped_column(String(64), primary_key=True)
    connection: Mapped[str | None] = mapped_column(String(200), nullable=True)
    system_id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    phase: Mapped[str] = mapped_column(String(20))


class EventRow(Base):
    """One flight event, by its sequence number in the flight."""

    __tablename__ = "events"

    flight_id: Mapped[str] = mapped_column(ForeignKey("flights.id"), primary_key=True)
    seq: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(20))
    utc_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    t_s: Mapped[float] = mapped_column(Float)
    vehicle: Mapped[str | None] = mapped_column(String(64), nullable=True)
    strategy: Mapped[str | None] = mapped_column(String(20), nullable=True)
    value: Mapped[float | None] = mapped_column(Float, nullable=True)
    reason: Mapped[str] = mapped_column(Text)
    payload: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)


class UploadRow(Base):
    """The mission items uploaded to one vehicle of a flight, each time."""

    __tablename__ = "uploads"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    flight_id: Mapped[str] = mapped_column(ForeignKey("flights.id"), index=True)
    vehicle_id: Mapped[str] = mapped_column(String(64))
    utc_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    what: Mapped[str] = mapped_column(String(200))
    items: Mapped[list[dict[str, Any]]] = mapped_column(JSON)


class ScheduleRow(Base):
    """A planned schedule: its summary, and the schedule and world themselves (pickled, as
    a flight's checkpoint is)."""

    __tablename__ = "schedules"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    scenario_id: Mapped[str] = mapped_column(ForeignKey("scenarios.id"))
    seed: Mapped[int] = mapped_column(Integer)
    plan_wall_s: Mapped[float] = mapped_column(Float)
    view: Mapped[dict[str, Any]] = mapped_column(JSON)
    blob: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)
    created_utc_s: Mapped[float] = mapped_column(Float)


class IdempotencyRow(Base):
    """The first answer to a request sent with an ``Idempotency-Key``: ``key`` is the
    token's digest with the key, ``digest`` the request's meaning."""

    __tablename__ = "idempotency_keys"

    key: Mapped[str] = mapped_column(String(64), primary_key=True)
    digest: Mapped[str] = mapped_column(String(64))
    status: Mapped[int] = mapped_column(Integer)
    body: Mapped[bytes] = mapped_column(LargeBinary)
    headers: Mapped[list[list[str]]] = mapped_column(JSON)
    created_utc_s: Mapped[float] = mapped_column(Float, index=True)


class VehicleRow(Base):
    """A live vehicle registered with ``POST /v1/vehicles``: its API id, how it is reached and
    the system id asked for. ``signed``: it was registered with a signing key (the key itself
    is kept for the link only, never here)."""

    __tablename__ = "vehicles"

    id: Mapped[str] = mapped_column(String(16), primary_key=True)
    connection: Mapped[str] = mapped_column(String(200), unique=True)
    system_id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    signed: Mapped[bool] = mapped_column(Boolean)
    registered_utc_s: Mapped[float] = mapped_column(Float)
    """When it was first registered (UTC s)."""

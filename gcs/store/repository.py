"""The store's operations: scenarios by content hash, flights and their state, events in
sequence, the missions uploaded, the live vehicles registered; and a bus subscriber that
writes a flight's events as they happen.

Every operation is one transaction. Sans-asyncio: :class:`EventWriter` runs the writes in a
worker thread so that a slow database never holds up the control loop.
"""

from __future__ import annotations

import asyncio
import dataclasses
import hashlib
import math
import time
import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from sqlalchemy import Engine, create_engine, select
from sqlalchemy.exc import IntegrityError, OperationalError
from sqlalchemy.orm import Session

from gcs.coordination.bus import EventBus, Subscription
from gcs.coordination.events import EventKind, FlightEvent
from gcs.coordination.member import VehicleState
from gcs.errors import GcsError
from gcs.store.models import (
    EventRow,
    FlightRow,
    FlightVehicleRow,
    IdempotencyRow,
    ScenarioRow,
    ScheduleRow,
    UploadRow,
    VehicleRow,
)
from planner.mission import MissionItem

__all__ = [
    "FLIGHT_STATES",
    "VEHICLE_PHASES",
    "CheckpointWriter",
    "EventWriter",
    "FlightKeeper",
    "FlightRecordRow",
    "Registration",
    "Store",
    "StoreConflict",
    "StoreError",
    "StoreNotFound",
]

FLIGHT_STATES = ("planned", "uploading", "ready", "running", "completed", "aborted", "failed")
VEHICLE_PHASES = tuple(state.value for state in VehicleState)
_MIGRATIONS = Path(__file__).with_name("migrations")


class StoreError(GcsError):
    """The store refused an operation or could not be reached; the message says which."""


class StoreNotFound(StoreError, KeyError):
    """No such scenario or flight."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class StoreConflict(StoreError):
    """An update made on a stale version, or a second flight for a vehicle."""


@dataclass(frozen=True)
class FlightRecordRow:
    """What the store holds of one flight."""

    id: str
    scenario_id: str
    state: str
    team_time_s: float | None
    version: int
    start_utc_s: float | None
    resume: Mapping[str, Any] | None
    vehicles: Mapping[str, tuple[str, str | None, int | None]]
    """Vehicle id -> (phase, connection, system id)."""


@dataclass(frozen=True)
class Registration:
    """A live vehicle registered with ``POST /v1/vehicles``, as the store keeps it."""

    id: str
    """The API's id (``v1``, ``v2``, ...)."""
    connection: str
    system_id: int | None
    """The system id asked for (None: the first vehicle heard at the connection)."""
    signed: bool
    """Registered with a signing key (the key is kept for the link only, never here)."""
    registered_utc_s: float
    """When it was first registered (UTC s)."""


def _registration(row: VehicleRow) -> Registration:
    return Registration(row.id, row.connection, row.system_id, row.signed, row.registered_utc_s)


def _item_json(it: MissionItem) -> dict[str, Any]:
    return dataclasses.asdict(it)


_Row = TypeVar("_Row", ScenarioRow, FlightRow, FlightVehicleRow, ScheduleRow)


def _get(session: Session, model: type[_Row], key: Any, what: str, *, lock: bool = False) -> _Row:
    """The row with this primary key, or StoreNotFound naming ``what``."""
    row = session.get(model, key, with_for_update=lock)
    if row is None:
        raise StoreNotFound(f"no {what}")
    return row


def _change_flight(
    session: Session,
    flight_id: str,
    *,
    expected_version: int | None = None,
    state: str | None = None,
    team_time_s: float | None = None,
    start_utc_s: float | None = None,
    resume: Mapping[str, Any] | None = None,
) -> int:
    """:meth:`Store.update_flight` within ``session``'s transaction."""
    if state is not None and state not in FLIGHT_STATES:
        raise StoreError(f"flight state {state!r} is not one of {', '.join(FLIGHT_STATES)}")
    row = _get(session, FlightRow, flight_id, f"flight {flight_id!r}", lock=True)
    if expected_version is not None and row.version != expected_version:
        raise StoreConflict(
            f"flight {flight_id}: version {expected_version} is stale (now {row.version})"
        )
    if state is not None:
        row.state = state
    if team_time_s is not None:
        row.team_time_s = team_time_s
    if start_utc_s is not None:
        row.start_utc_s = start_utc_s
    if resume is not None:
        row.resume = dict(resume)
    row.version += 1
    row.updated_utc_s = time.time()
    return row.version


def _change_vehicle(
    session: Session,
    flight_id: str,
    vehicle_id: str,
    *,
    phase: str | None = None,
    system_id: int | None = None,
) -> None:
    """:meth:`Store.set_vehicle` within ``session``'s transaction."""
    if phase is not None and phase not in VEHICLE_PHASES:
        raise StoreError(f"vehicle phase {phase!r} is not one of {', '.join(VEHICLE_PHASES)}")
    row = _get(
        session,
        FlightVehicleRow,
        (flight_id, vehicle_id),
        f"vehicle {vehicle_id!r} in flight {flight_id!r}",
    )
    if phase is not None:
        row.phase = phase
    if system_id is not None:
        row.system_id = system_id


def _follow(session: Session, flight_id: str, events: Sequence[FlightEvent]) -> None:
    """What events change in the flight's row, in their order, within ``session``'s
    transaction: the team time, the flight's state, a vehicle's phase."""
    for e in events:
        if e.kind is EventKind.ARRIVAL and e.value is not None:
            _change_flight(session, flight_id, team_time_s=e.value)
        if e.kind is EventKind.FLIGHT and "state" in e.payload:
            _change_flight(session, flight_id, state=str(e.payload["state"]))
        if e.kind is EventKind.STATE and e.vehicle is not None:
            _change_vehicle(session, flight_id, e.vehicle, phase=str(e.payload["state"]))


class Store:
    """Scenarios, flights, events, uploads and registered vehicles in one SQL database (see the
    package)."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    @classmethod
    def open(cls, url: str, *, migrate: bool = True) -> Store:
        """Connect to ``url`` (e.g. ``sqlite:///tcgcs.db``,
        ``postgresql+psycopg://user@host/db``) and bring the schema to the latest revision."""
        kwargs: dict[str, Any] = {}
        if url.startswith("sqlite"):
            kwargs["connect_args"] = {"check_same_thread": False}
        try:
            engine = create_engine(url, **kwargs)
        except Exception as err:  # a malformed URL or a missing driver
            raise StoreError(f"database URL {url!r}: {err}") from None
        store = cls(engine)
        if migrate:
            store.upgrade()
        return store

    def upgrade(self) -> None:
        """Run the migrations up to head (Alembic)."""
        from alembic import command  # only where a database is opened
        from alembic.config import Config

        cfg = Config()
        cfg.set_main_option("script_location", str(_MIGRATIONS))
        try:
            with self.engine.begin() as connection:
                cfg.attributes["connection"] = connection
                command.upgrade(cfg, "head")
        except OperationalError as err:
            raise StoreError(f"database {self.engine.url!r} unreachable: {err.orig}") from None

    def close(self) -> None:
        self.engine.dispose()

    # -- scenarios ----------------------------------------------------------------------------

    def save_scenario(self, body: str, *, name: str, media_type: str = "application/yaml") -> str:
        """Keep a scenario's text; its id is the SHA-256 of the text (the same text, the same
        id; a scenario is never changed)."""
        sid = hashlib.sha256(body.encode("utf-8")).hexdigest()
        with Session(self.engine) as session, session.begin():
            if session.get(ScenarioRow, sid) is None:
                session.add(
                    ScenarioRow(
                        id=sid,
                        name=name,
                        media_type=media_type,
                        body=body,
                        created_utc_s=time.time(),
                    )
                )
        return sid

    def scenario(self, scenario_id: str) -> ScenarioRow:
        with Session(self.engine) as session:
            row = _get(session, ScenarioRow, scenario_id, f"scenario {scenario_id!r}")
            session.expunge(row)
            return row

    # -- schedules ----------------------------------------------------------------------------

    def save_schedule(
        self,
        schedule_id: str,
        scenario_id: str,
        *,
        seed: int,
        plan_wall_s: float,
        view: Mapping[str, Any],
        blob: bytes,
    ) -> None:
        """Keep a planned schedule: its summary and the pickled schedule and world."""
        with Session(self.engine) as session, session.begin():
            session.add(
                ScheduleRow(
                    id=schedule_id,
                    scenario_id=scenario_id,
                    seed=seed,
                    plan_wall_s=plan_wall_s,
                    view=dict(view),
                    blob=blob,
                    created_utc_s=time.time(),
                )
            )

    def schedule(self, schedule_id: str) -> tuple[ScheduleRow, bytes]:
        """A kept schedule's row and its pickled schedule and world."""
        with Session(self.engine) as session:
            row = _get(session, ScheduleRow, schedule_id, f"schedule {schedule_id!r}")
            blob = row.blob
            session.expunge(row)
            return row, blob

    # -- idempotency keys ---------------------------------------------------------------------

    def kept_answer(self, key: str) -> IdempotencyRow | None:
        """The first answer given under ``key``, if any."""
        with Session(self.engine) as session:
            row = session.get(IdempotencyRow, key)
            if row is not None:
                session.expunge(row)
            return row

    def keep_answer(
        self,
        key: str,
        digest: str,
        status: int,
        body: bytes,
        headers: Sequence[tuple[str, str]],
        *,
        max_keys: int,
    ) -> None:
        """Keep the first answer under ``key`` (a second one under the same key, given at
        the same moment by another process, is dropped), the oldest keys past ``max_keys``
        forgotten."""
        with Session(self.engine) as session, session.begin():
            if session.get(IdempotencyRow, key) is not None:
                return
            session.add(
                IdempotencyRow(
                    key=key,
                    digest=digest,
                    status=status,
                    body=body,
                    headers=[list(h) for h in headers],
                    created_utc_s=time.time(),
                )
            )
        with Session(self.engine) as session, session.begin():
            stale = session.scalars(
                select(IdempotencyRow.key)
                .order_by(IdempotencyRow.created_utc_s.desc())
                .offset(max_keys)
            ).all()
            for old in stale:
                row = session.get(IdempotencyRow, old)
                if row is not None:
                    session.delete(row)

    # -- registered vehicles ------------------------------------------------------------------

    def register_vehicle(
        self, vehicle_id: str, connection: str, *, system_id: int | None, signed: bool
    ) -> Registration:
        """Keep a registered vehicle. One registered again (the same id) keeps its connection
        and first registration time; the system id asked for and ``signed`` are the new ones.

        Raises
        ------
        StoreConflict
            The id is kept with another connection, or the connection with another id.
        """
        with Session(self.engine) as session, session.begin():
            row = session.get(VehicleRow, vehicle_id, with_for_update=True)
            if row is None:
                row = VehicleRow(
                    id=vehicle_id,
                    connection=connection,
                    system_id=system_id,
                    signed=signed,
                    registered_utc_s=time.time(),
                )
                session.add(row)
            elif row.connection != connection:
                raise StoreConflict(f"vehicle {vehicle_id} is kept at {row.connection}")
            else:
                row.system_id = system_id
                row.signed = signed
            try:
                session.flush()
            except IntegrityError:
                raise StoreConflict(f"{connection} is kept as another vehicle") from None
            return _registration(row)

    def registered_vehicles(self) -> list[Registration]:
        """Every registered vehicle, in the order they were first registered."""
        with Session(self.engine) as session:
            query = select(VehicleRow).order_by(VehicleRow.registered_utc_s, VehicleRow.id)
            return [_registration(row) for row in session.scalars(query)]

    # -- flights ------------------------------------------------------------------------------

    def create_flight(
        self,
        scenario_id: str,
        vehicles: Mapping[str, str | None],
        *,
        flight_id: str | None = None,
    ) -> str:
        """A new flight in state ``planned`` flying ``vehicles`` (id -> connection string).

        Raises
        ------
        StoreNotFound
            No such scenario.
        StoreConflict
            A connection is already in a flight that has not ended (named).
        """
        fid = flight_id or uuid.uuid4().hex
        now = time.time()
        with Session(self.engine) as session, session.begin():
            _get(session, ScenarioRow, scenario_id, f"scenario {scenario_id!r}")
            conns = [c for c in vehicles.values() if c is not None]
            if conns:
                busy = session.execute(
                    select(FlightVehicleRow.connection, FlightRow.id)
                    .join(FlightRow, FlightRow.id == FlightVehicleRow.flight_id)
                    .where(FlightVehicleRow.connection.in_(conns))
                    .where(FlightRow.state.not_in(("completed", "aborted", "failed")))
                ).first()
                if busy is not None:
                    raise StoreConflict(f"vehicle {busy[0]} is already in flight {busy[1]}")
            session.add(
                FlightRow(
                    id=fid,
                    scenario_id=scenario_id,
                    state="planned",
                    version=1,
                    created_utc_s=now,
                    updated_utc_s=now,
                )
            )
            session.flush()
            for vid, conn in vehicles.items():
                session.add(
                    FlightVehicleRow(
                        flight_id=fid,
                        vehicle_id=vid,
                        connection=conn,
                        phase=VehicleState.WAITING_TAKEOFF.value,
                    )
                )
        return fid

    def flights_in(self, states: Sequence[str]) -> list[str]:
        """The ids of the flights in these states, oldest first."""
        with Session(self.engine) as session:
            query = (
                select(FlightRow.id)
                .where(FlightRow.state.in_(list(states)))
                .order_by(FlightRow.created_utc_s)
            )
            return list(session.scalars(query))

    def flight(self, flight_id: str) -> FlightRecordRow:
        with Session(self.engine) as session:
            row = _get(session, FlightRow, flight_id, f"flight {flight_id!r}")
            vehicles = session.scalars(
                select(FlightVehicleRow).where(FlightVehicleRow.flight_id == flight_id)
            ).all()
            return FlightRecordRow(
                id=row.id,
                scenario_id=row.scenario_id,
                state=row.state,
                team_time_s=row.team_time_s,
                version=row.version,
                start_utc_s=row.start_utc_s,
                resume=row.resume,
                vehicles={v.vehicle_id: (v.phase, v.connection, v.system_id) for v in vehicles},
            )

    def update_flight(
        self,
        flight_id: str,
        *,
        expected_version: int | None = None,
        state: str | None = None,
        team_time_s: float | None = None,
        start_utc_s: float | None = None,
        resume: Mapping[str, Any] | None = None,
    ) -> int:
        """Change a flight; returns its new version.

        Raises
        ------
        StoreNotFound
            No such flight.
        StoreConflict
            ``expected_version`` is not the flight's version (someone changed it first).
        StoreError
            ``state`` is not one of :data:`FLIGHT_STATES`.
        """
        with Session(self.engine) as session, session.begin():
            return _change_flight(
                session,
                flight_id,
                expected_version=expected_version,
                state=state,
                team_time_s=team_time_s,
                start_utc_s=start_utc_s,
                resume=resume,
            )

    def save_checkpoint(self, flight_id: str, blob: bytes) -> None:
        """Keep the flight's checkpoint (the newest replaces the one before)."""
        with Session(self.engine) as session, session.begin():
            row = _get(session, FlightRow, flight_id, f"flight {flight_id!r}")
            row.checkpoint = blob
            row.checkpoint_utc_s = time.time()

    def checkpoint(self, flight_id: str) -> bytes | None:
        """The flight's last checkpoint (None: never kept)."""
        with Session(self.engine) as session:
            row = _get(session, FlightRow, flight_id, f"flight {flight_id!r}")
            return row.checkpoint

    def set_vehicle(
        self,
        flight_id: str,
        vehicle_id: str,
        *,
        phase: str | None = None,
        system_id: int | None = None,
    ) -> None:
        with Session(self.engine) as session, session.begin():
            _change_vehicle(session, flight_id, vehicle_id, phase=phase, system_id=system_id)

    # -- events -------------------------------------------------------------------------------

    def add_events(self, flight_id: str, events: Sequence[FlightEvent]) -> int:
        """Keep events (by their ``seq``), and what the new ones change in the flight's row
        (the team time, the flight's state, a vehicle's phase) in the same transaction: the
        row never runs ahead of, or behind, the events kept, whenever the process dies. One
        already kept is not written again. Returns how many were new."""
        if not events:
            return 0
        seqs = [e.seq for e in events]
        with Session(self.engine) as session, session.begin():
            have = set(
                session.scalars(
                    select(EventRow.seq)
                    .where(EventRow.flight_id == flight_id)
                    .where(EventRow.seq.in_(seqs))
                )
            )
            new = [e for e in events if e.seq not in have]
            session.add_all(
                EventRow(
                    flight_id=flight_id,
                    seq=e.seq,
                    kind=str(e.kind),
                    utc_s=None if math.isnan(e.utc_s) else e.utc_s,  # NaN: no clock yet
                    t_s=e.t_s,
                    vehicle=e.vehicle,
                    strategy=e.strategy,
                    value=e.value,
                    reason=e.reason,
                    payload=dict(e.payload) or None,
                )
                for e in new
            )
            try:
                session.flush()
            except IntegrityError as err:
                raise StoreError(f"flight {flight_id}: events not kept: {err.orig}") from None
            _follow(session, flight_id, new)
        return len(new)

    def events(
        self, flight_id: str, *, after_seq: int = 0, limit: int | None = None
    ) -> list[FlightEvent]:
        """A flight's events after ``after_seq``, in order (at most ``limit``)."""
        query = (
            select(EventRow)
            .where(EventRow.flight_id == flight_id)
            .where(EventRow.seq > after_seq)
            .order_by(EventRow.seq)
        )
        if limit is not None:
            query = query.limit(limit)
        with Session(self.engine) as session:
            return [
                FlightEvent(
                    utc_s=float("nan") if r.utc_s is None else r.utc_s,
                    t_s=r.t_s,
                    vehicle=r.vehicle,
                    kind=r.kind,  # type: ignore[arg-type]  # FlightEvent makes it an EventKind
                    reason=r.reason,
                    strategy=r.strategy,
                    value=r.value,
                    seq=r.seq,
                    payload=r.payload or {},
                )
                for r in session.scalars(query)
            ]

    def events_to_resume(self, flight_id: str) -> list[FlightEvent]:
        """A flight's events as a flight taken on from its checkpoint reads them: each
        vehicle's last upload event carries its mission items again (kept apart, in the
        uploads table), so that a mission it told of and the checkpoint still had pending is
        adopted without being told again."""
        events = self.events(flight_id)
        last: dict[str, int] = {}
        for i, e in enumerate(events):
            if e.kind is EventKind.UPLOAD and e.vehicle is not None and "what" in e.payload:
                last[e.vehicle] = i
        for vid, i in last.items():
            items = self.last_upload(flight_id, vid)
            if items is not None:
                e = events[i]
                payload = {**e.payload, "items": [_item_json(it) for it in items]}
                events[i] = dataclasses.replace(e, payload=payload)
        return events

    # -- uploads ------------------------------------------------------------------------------

    def record_upload(
        self,
        flight_id: str,
        vehicle_id: str,
        items: Sequence[MissionItem],
        *,
        what: str,
        utc_s: float | None = None,
    ) -> None:
        """Keep the mission items uploaded to a vehicle."""
        with Session(self.engine) as session, session.begin():
            session.add(
                UploadRow(
                    flight_id=flight_id,
                    vehicle_id=vehicle_id,
                    utc_s=utc_s,
                    what=what,
                    items=[_item_json(it) for it in items],
                )
            )

    def last_upload(self, flight_id: str, vehicle_id: str) -> list[MissionItem] | None:
        """The items last uploaded to a vehicle of a flight (None: none yet)."""
        with Session(self.engine) as session:
            row = session.scalars(
                select(UploadRow)
                .where(UploadRow.flight_id == flight_id)
                .where(UploadRow.vehicle_id == vehicle_id)
                .order_by(UploadRow.id.desc())
                .limit(1)
            ).first()
            return None if row is None else [MissionItem(**it) for it in row.items]

    def upload_count(self, flight_id: str) -> int:
        with Session(self.engine) as session:
            return len(
                session.scalars(select(UploadRow.id).where(UploadRow.flight_id == flight_id)).all()
            )


class CheckpointWriter:
    """Keeps a flight's newest checkpoint in the store from a worker thread: the control loop
    hands it over and goes on; a checkpoint superseded before it was written is skipped.

    With ``bus`` and ``events`` (its :class:`EventWriter`), a checkpoint is written only once
    every event the bus had published when it was offered is kept: a process that dies
    between the two never leaves a checkpoint ahead of its events (a mission on board whose
    upload no kept event says, and that a flight resumed from it would not say again)."""

    def __init__(
        self,
        store: Store,
        flight_id: str,
        *,
        bus: EventBus | None = None,
        events: EventWriter | None = None,
    ) -> None:
        self.store = store
        self.flight_id = flight_id
        self.written = 0
        self._bus = bus
        self._events = events
        self._latest: tuple[bytes, int] | None = None
        self._closing = False
        self._wake = asyncio.Event()
        self._idle = asyncio.Event()
        self._idle.set()
        self._task = asyncio.get_running_loop().create_task(self._run())

    def offer(self, blob: bytes) -> None:
        self._latest = blob, 0 if self._bus is None else self._bus.last_seq
        self._idle.clear()
        self._wake.set()

    async def kept(self) -> None:
        """Until the newest checkpoint offered is written (or the writer has stopped)."""
        idle = asyncio.ensure_future(self._idle.wait())
        try:
            await asyncio.wait([idle, self._task], return_when=asyncio.FIRST_COMPLETED)
        finally:
            idle.cancel()

    async def _run(self) -> None:
        while not self._closing:
            await self._wake.wait()
            self._wake.clear()
            await self._flush()
            if self._latest is None:
                self._idle.set()

    async def _flush(self) -> None:
        latest, self._latest = self._latest, None
        if latest is None:
            return
        blob, seq = latest
        if self._events is not None:
            await self._events.kept_through(seq)
        await asyncio.to_thread(self.store.save_checkpoint, self.flight_id, blob)
        self.written += 1

    async def close(self) -> None:
        """Write what is pending, then stop."""
        self._closing = True
        self._wake.set()
        await self._task
        await self._flush()


class FlightKeeper:
    """A flight kept in the store as it happens: every event of its bus (an
    :class:`EventWriter` on a subscription from the first event) and its newest checkpoint
    (a :class:`CheckpointWriter`: hand :meth:`CheckpointWriter.offer` to the runner)."""

    def __init__(self, store: Store, flight_id: str, bus: EventBus) -> None:
        self.events = bus.subscribe(maxsize=1_000_000, after_seq=0)
        writer = EventWriter(store, flight_id)
        self.checkpoints = CheckpointWriter(store, flight_id, bus=bus, events=writer)
        self._writer = asyncio.get_running_loop().create_task(writer.run(self.events))

    async def close(self) -> None:
        """The pending checkpoint and every queued event written, then stop."""
        await self.checkpoints.close()
        self.events.close()  # the writer drains what is queued, then ends
        await self._writer


class EventWriter:
    """Writes a flight's events from its bus subscription to the store, in batches, in a
    worker thread: the control loop never waits for the database."""

    def __init__(self, store: Store, flight_id: str, *, batch: int = 200) -> None:
        self.store = store
        self.flight_id = flight_id
        self.batch = batch
        self.written = 0
        self.kept_seq = 0
        """The last event kept (its seq)."""
        self._ended = False
        self._kept = asyncio.Condition()

    async def run(self, events: Subscription) -> None:
        """Until the subscription is closed and drained."""
        try:
            while (first := await events.get()) is not None:
                pending = [first]
                while len(pending) < self.batch and (more := events.get_nowait()) is not None:
                    pending.append(more)
                self.written += await asyncio.to_thread(self.write, pending)
                await self._said(pending[-1].seq)
        finally:
            self._ended = True
            await self._said(self.kept_seq)

    async def _said(self, seq: int) -> None:
        async with self._kept:
            self.kept_seq = seq
            self._kept.notify_all()

    async def kept_through(self, seq: int) -> None:
        """Until every event up to ``seq`` is kept (or the writer has stopped)."""
        async with self._kept:
            await self._kept.wait_for(lambda: self.kept_seq >= seq or self._ended)

    def write(self, events: Sequence[FlightEvent]) -> int:
        """Keep the events (one already kept is not written again) and what they change in
        the flight's row; an upload event's mission items go to the uploads table. Returns
        how many were new."""
        kept = []
        for e in events:
            items = e.payload.get("items") if e.kind is EventKind.UPLOAD else None
            if items is not None and e.vehicle is not None:
                self.store.record_upload(
                    self.flight_id,
                    e.vehicle,
                    [MissionItem(**it) for it in items],
                    what=str(e.payload.get("what", e.reason)),
                    utc_s=None if math.isnan(e.utc_s) else e.utc_s,
                )
                e = dataclasses.replace(
                    e, payload={k: v for k, v in e.payload.items() if k != "items"}
                )
            kept.append(e)
        return self.store.add_events(self.flight_id, kept)

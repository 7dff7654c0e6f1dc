"""The service's engine: the fleet, the store, planning (:mod:`gcs.service.planning`) and the
flights, for the life of the process.

Everything an API request does goes through :class:`Engine`: register a vehicle (kept in the
store, :mod:`gcs.service.registry`: a restarted service lists it under the same id and opens
its link again), keep a scenario and plan a schedule as a job (its
:class:`~gcs.service.planning.Planning`), create a flight on a schedule and vehicles, upload,
launch, steer it (threats, team time, abort) and read it (snapshot, events, record, report).
A flight is a :class:`~gcs.coordination.runner.FlightRunner` with its event and checkpoint
writers to the store; its vehicles are claimed from the fleet for as long as it runs. Errors
are :class:`ServiceError` subclasses that name what is wrong; the API maps them to status
codes.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gcs.coordination.config import FlightConfig
from gcs.coordination.events import FlightEvent
from gcs.coordination.runner import ENDED, FlightState
from gcs.errors import GcsError
from gcs.mavlink.signing import SigningConfig
from gcs.rehearsal.figures import FIGURES
from gcs.rehearsal.report import write_figure
from gcs.service.ended import FINAL_FILE, EndedFlight, EndedFlights, keep_final
from gcs.service.fleet import Fleet, FleetVehicle, VehicleBusy, unreached_view
from gcs.service.flight import Rehearsal, stop_kept_simulator
from gcs.service.planning import Limits, Planning
from gcs.service.registry import Registry
from gcs.service.scenariotext import (
    Conflict,
    Infeasible,
    InvalidInput,
    NotFound,
    PreconditionFailed,
    ServiceError,
    TooBusy,
    parse_scenario_text,
)
from gcs.service.worker import FlightSpec, VehicleSpec
from gcs.service.workers import FEED_SILENCE_S, RECONNECT_WALL_S, Spawner, WorkerFlight
from gcs.store.repository import EventWriter, Store, StoreError
from planner.scenario import Threat
from sitl_stub.lockstep import LOCKSTEP_BYTES, Lockstep

__all__ = [
    "Conflict",
    "Engine",
    "Infeasible",
    "InvalidInput",
    "Limits",
    "NotFound",
    "PreconditionFailed",
    "Rehearsal",
    "ServiceError",
    "TooBusy",
    "WorkerFlight",
    "parse_scenario_text",
]

log = logging.getLogger(__name__)

ENDED_STATES = tuple(s.value for s in ENDED)
"""The store's states of a flight that has ended."""


class Engine:
    """The fleet, the store, jobs and flights of one service process."""

    def __init__(
        self,
        store: Store,
        data_dir: Path,
        *,
        config: FlightConfig | None = None,
        limits: Limits | None = None,
        worker_silence_s: float = FEED_SILENCE_S,
        worker_answer_s: float = RECONNECT_WALL_S,
        plan_ray: str | None = None,
        spare_worker: bool = True,
        lockstep_dir: Path | None = None,
        worker_nice: int | None = None,
    ):
        self.store = store
        self.workers = Spawner(
            store.engine.url.render_as_string(hide_password=False),
            feed_silence_s=worker_silence_s,
            answer_wall_s=worker_answer_s,
            spare=spare_worker,
            nice=worker_nice,
        )
        """Starts the flight workers (they find the store by its URL) and says how long one
        may be silent (:class:`Spawner`)."""
        self.data_dir = data_dir
        self.lockstep_dir = lockstep_dir
        """Where the lock-step files a flight on registered vehicles may join lie."""
        self.config = config or FlightConfig()
        self.limits = limits or Limits()
        self.planning = Planning(store, self.limits, self.config.method, plan_ray)
        """Scenarios, planning jobs and planned schedules."""
        self.ended = EndedFlights(data_dir / "flights")
        """Flights that ended before this process started (read from their folders)."""
        self._drawing: dict[tuple[str, str], asyncio.Lock] = {}
        """A lock per report figure being drawn: (flight, file name)."""
        self.fleet = Fleet()
        self.registry = Registry(store, self.fleet)
        """The API's vehicle ids, and the registered vehicles kept in the store."""
        self.flights: dict[str, WorkerFlight] = {}
        self._tasks: set[asyncio.Task[Any]] = set()

    async def close(self) -> None:
        """Stop: flights on bundled simulator vehicles end (failed: their simulator stops
        with the service); flights on live vehicles in the air fly on in their workers, and
        the next service process follows them again (:meth:`resume_kept`); those not launched
        yet stop with the service."""
        for flight in list(self.flights.values()):
            airborne = flight.state is FlightState.RUNNING
            await flight.close(stop=flight.simulated or not airborne)
        for task in list(self._tasks):
            task.cancel()
        await self.registry.close()
        await self.planning.close()
        await self.workers.close()
        await self.fleet.close()

    def _spawn(self, coro: Any) -> asyncio.Task[Any]:
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    # -- vehicles -------------------------------------------------------------------------------

    async def add_vehicle(
        self, connection: str, *, system_id: int | None = None, signing_key: str | None = None
    ) -> dict[str, Any]:
        """Register a live vehicle by connection string (its link opened, HEARTBEAT heard), and
        keep the registration in the store (nothing is kept when no vehicle answers). A
        connection already registered answers with its id: a vehicle whose link is open (or
        in a flight) as it is; one whose link is not open (kept by an earlier service process
        and not answering yet, or registered with a signing key, which is not kept) has it
        opened now, with ``signing_key`` if given, the system id kept if none is given.

        Raises
        ------
        InvalidInput
            A malformed connection string or signing key; no signing key for a vehicle that
            was registered with one and whose link is not open.
        ServiceError
            No vehicle answered there.
        """
        signing = None if signing_key is None else _signing(signing_key)
        vid = self.registry.id_of(connection)
        if vid is not None and self._reached(connection):
            return self.vehicle_view(vid)
        kept = self.registry.kept.get(connection)
        if kept is not None:
            if signing is None and self.registry.key_needed(connection):
                raise InvalidInput(
                    f"signing_key: vehicle {kept.id} ({connection}) was registered with a "
                    "signing key, which is not kept: give it again"
                )
            system_id = kept.system_id if system_id is None else system_id
            await self.registry.stop_reopening(connection)
        try:
            held = await self.fleet.vehicle(connection, system_id, signing=signing)
        except ValueError as err:
            raise InvalidInput(f"connection: {err}") from None
        except (GcsError, TimeoutError, OSError) as err:
            self.registry.reopen(connection)  # a kept one: tried again in the background
            raise ServiceError(f"no vehicle answered at {connection}: {err}") from None
        signed = held.connection in self.fleet.signing
        try:
            vid = await self.registry.keep(held.connection, system_id, signed=signed)
        except StoreError:
            if kept is None:
                await self.fleet.drop([held.connection])
            raise
        return self.vehicle_view(vid)

    def _reached(self, connection: str) -> bool:
        """The service holds a link to the vehicle at ``connection``, or a running flight's
        worker does."""
        return self.fleet.held(connection) is not None or self._flying(connection) is not None

    def _flying(self, connection: str) -> WorkerFlight | None:
        """The flight, not over, whose worker holds (or reaches for) the vehicle at
        ``connection``, if any."""
        return next(
            (
                f
                for f in self.flights.values()
                if not f.over and connection in f.connections.values()
            ),
            None,
        )

    def _held(self, vehicle_id: str) -> FleetVehicle:
        conn = self.registry.ids.get(vehicle_id)
        held = None if conn is None else self.fleet.held(conn)
        if conn is not None and held is None:
            flight = self._flying(conn)
            if flight is not None:
                raise Conflict(f"vehicle {conn} is already in flight {flight.id}")
            if conn in self.registry.kept:
                why = (
                    "it was registered with a signing key: register it again with the key"
                    if self.registry.key_needed(conn)
                    else "no vehicle answers there yet; it is tried again in the background"
                )
                raise Conflict(f"vehicle {vehicle_id} ({conn}): its link is not open ({why})")
        if held is None:
            raise NotFound(f"no vehicle {vehicle_id!r}")
        return held

    def vehicle_view(self, vehicle_id: str) -> dict[str, Any]:
        """A vehicle the service knows: held by the service, by the worker of the flight it
        is in, or registered and kept with its link not open (``link.open`` false, nothing
        known now). Its link, and its mode and armed state while the link is up (null once it
        is down, its last word kept as ``last_mode`` and ``last_armed``); and whether a
        signing key must be given again (``signing_key_needed``)."""
        conn = self.registry.ids.get(vehicle_id)
        view = None if conn is None else self._view(conn)
        if view is None:
            raise NotFound(f"no vehicle {vehicle_id!r}")
        return {"id": vehicle_id, **view}

    def _view(self, connection: str) -> dict[str, Any] | None:
        held = self.fleet.held(connection)
        flight = self._flying(connection)
        kept = self.registry.kept.get(connection)
        if held is not None and not held.lent:
            view = held.view()
        elif flight is not None and connection in flight.vehicle_views():
            view = dict(flight.vehicle_views()[connection])
        elif flight is not None or kept is not None:
            system_id = None if kept is None else kept.system_id
            view = unreached_view(connection, system_id, self.registry.last_word.get(connection))
            view["flight_id"] = None if flight is None else flight.id
        else:
            return None
        view.pop("counters", None)
        view["signing_key_needed"] = self.registry.key_needed(connection)
        return view

    def vehicle_views(self) -> list[dict[str, Any]]:
        out = []
        for vid, conn in self.registry.ids.items():
            view = self._view(conn)
            if view is not None:
                out.append({"id": vid, **view})
        return out

    def link_counters(self) -> dict[str, dict[str, int]]:
        """Per connection of every open link (here and in the flight workers), its
        counters (``/metrics``)."""
        out = {}
        for conn in self.registry.ids.values():
            held = self.fleet.held(conn)
            if held is not None and not held.lent:
                out[conn] = held.view()["counters"]
        for flight in self.flights.values():
            if not flight.over:
                for conn, view in flight.vehicle_views().items():
                    out[conn] = view["counters"]
        return out

    # -- flights --------------------------------------------------------------------------------

    def _pace_file(self, lockstep: str, registered: bool) -> str:
        """The lock-step file a flight on registered vehicles joins, checked."""
        if not registered:
            raise InvalidInput("lockstep: only with vehicles (a rehearsal keeps its own)")
        if self.lockstep_dir is None:
            raise InvalidInput("lockstep: this service joins no simulator (no TCGCS_LOCKSTEP_DIR)")
        path = Path(lockstep).resolve()
        if not path.is_relative_to(self.lockstep_dir.resolve()):
            raise InvalidInput(f"lockstep: {lockstep} is not in TCGCS_LOCKSTEP_DIR")
        try:
            if not path.is_file() or path.stat().st_size != LOCKSTEP_BYTES:
                raise ValueError(f"not a file of {LOCKSTEP_BYTES} bytes")
            pace = Lockstep(path)
        except (OSError, ValueError) as err:
            raise InvalidInput(f"lockstep: {lockstep}: not a lock-step file ({err})") from None
        try:
            fields = (pace.speedup, pace.lead_s, pace.pace_s() + 1.0)
            if not all(math.isfinite(x) and x > 0.0 for x in fields):
                raise InvalidInput(f"lockstep: {lockstep}: not a lock-step file (its clock)")
        finally:
            pace.close()
        return str(path)

    async def create_flight(
        self,
        schedule_id: str,
        vehicles: Mapping[str, str] | None,
        rehearsal: Rehearsal | None,
        *,
        lockstep: str | None = None,
    ) -> WorkerFlight:
        """A flight of ``schedule_id`` on registered vehicles (scenario vehicle -> vehicle
        id), or, with ``rehearsal`` and no vehicles, on bundled simulator vehicles started for
        it (on the ground at each start, nose along its path); flown by a worker process of
        its own (:mod:`gcs.service.worker`), which is ready when this returns.

        Raises
        ------
        NotFound
            No such schedule or vehicle.
        Conflict
            A vehicle is already in a flight (named, with that flight).
        InvalidInput
            A scenario vehicle without a vehicle, or one named that the scenario lacks; a
            ``lockstep`` without vehicles, outside :attr:`lockstep_dir` or not a lock-step file.
        """
        pace = None if lockstep is None else self._pace_file(lockstep, vehicles is not None)
        entry = await self.planning.planned(schedule_id)
        ids = [v.id for v in entry.scenario.vehicles]
        lent: list[str] = []
        specs = None
        fid = uuid.uuid4().hex
        if vehicles is not None:
            unknown = sorted(set(vehicles) - set(ids))
            if unknown:
                raise InvalidInput(f"vehicles: {', '.join(unknown)} not in the scenario")
            missing = [i for i in ids if i not in vehicles]
            if missing:
                raise InvalidInput(f"vehicles: no vehicle for {', '.join(missing)}")
            chosen = [self._held(vehicles[i]) for i in ids]
            specs = tuple(
                VehicleSpec(h.connection, h.vehicle.system_id, _key_hex(self.fleet, h.connection))
                for h in chosen
            )
            lent = [h.connection for h in chosen]
            try:
                await self.fleet.lend(lent, fid)
            except VehicleBusy as err:
                raise Conflict(str(err)) from None
        elif rehearsal is None:
            raise InvalidInput("a flight needs vehicles, or rehearsal options for stubs")
        folder = self.data_dir / "flights" / fid
        FlightSpec(fid, schedule_id, specs, rehearsal, pace).write(folder)
        try:
            flight = await WorkerFlight.start(folder, self.workers)
        except BaseException:
            await self.fleet.take_back(lent)
            raise
        self._adopt(flight)
        return flight

    def _adopt(self, flight: WorkerFlight) -> None:
        for conn in flight.connections.values():
            self.registry.name(conn)
        flight.on_over = self._over
        flight.keep_told = EventWriter(self.store, flight.id).write
        self.flights[flight.id] = flight

    def _over(self, flight: WorkerFlight) -> None:
        if flight.lost:
            self._spawn(self._keep_lost(flight))
        conns = sorted(set(flight.connections.values()))
        if flight.simulated:
            # Its simulator vehicles went with their simulator: no longer the service's.
            self.registry.forget(conns)
        else:
            views = flight.vehicle_views()
            for conn in conns:
                if conn in views:
                    self.registry.last_word[conn] = views[conn]
            self._spawn(self._take_back(conns))

    async def _take_back(self, connections: list[str]) -> None:
        """The vehicles of a flight that has ended are the service's again: the links it lent
        opened again; a kept vehicle that does not answer, or that the service never held (a
        flight an earlier process started), is reopened in the background."""
        lent = [c for c in connections if (h := self.fleet.held(c)) is not None and h.lent]
        await self.fleet.take_back(lent)
        for conn in connections:
            self.registry.reopen(conn)

    async def _keep_lost(self, flight: WorkerFlight) -> None:
        """A flight no worker flies on, kept failed (with the events that say so), and its
        bundled simulator, if any, stopped: a later process shows it failed too."""
        # Its events as told, the failure's with them (which sets its state in the store).
        await flight.keep_told_events()
        await asyncio.to_thread(keep_final, flight.folder, flight.snapshot(), None)
        await stop_kept_simulator(flight.folder)

    # -- restart --------------------------------------------------------------------------------

    async def resume_kept(self) -> list[str]:
        """Take on what an earlier service process left. Its registered vehicles first
        (their ids and connections, :meth:`Registry.load`); then every flight it left (killed,
        or stopped with live vehicles in the air) that has not left its last snapshot yet:
        its worker if it still answers, else, for a flight the store says is running, a new
        worker on its checkpoint, on the vehicles it was flying (reached again by their
        connections), each mission compared before anything is sent. Last, the link to each
        registered vehicle no flight's worker holds is opened again in the background (not
        waited for: tried until it answers). Returns the ids of the flights (a vehicle that
        cannot be reached fails its flight, with an event)."""
        self.registry.load()
        resumed = []
        for fid in self.store.flights_in([s.value for s in FlightState]):
            folder = self.data_dir / "flights" / fid
            if fid in self.flights or (folder / FINAL_FILE).exists():
                continue
            flight = await WorkerFlight.adopt(folder, self.workers)
            if flight is None:
                if self.store.flight(fid).state != "running" or not self.store.checkpoint(fid):
                    continue
                try:
                    flight = await WorkerFlight.start(folder, self.workers, resume=True)
                except ServiceError as err:
                    log.error("flight %s: not flown on: %s", fid, err)
                    continue
            self._adopt(flight)
            resumed.append(fid)
        for conn in list(self.registry.kept):
            if self._flying(conn) is None:
                self.registry.reopen(conn)
        return resumed

    def flight(self, flight_id: str) -> WorkerFlight:
        """A flight of this process (running, or ended since it started)."""
        flight = self.flights.get(flight_id)
        if flight is None:
            raise NotFound(f"no flight {flight_id!r}")
        return flight

    def known(self, flight_id: str) -> WorkerFlight | EndedFlight:
        """A flight of this process, or one that ended before it started."""
        flight = self.flights.get(flight_id)
        if flight is not None:
            return flight
        ended = self.ended.get(flight_id)
        if ended is None:
            raise NotFound(f"no flight {flight_id!r}")
        return ended

    async def record(self, flight_id: str) -> dict[str, Any]:
        """The flight record (``tcgcs-flight/1``) once the flight is over."""
        found = self.known(flight_id)
        if isinstance(found, WorkerFlight) and not found.over:
            raise NotFound(f"flight {flight_id} has no record yet (it is {found.state})")
        try:
            doc: dict[str, Any] = json.loads(await asyncio.to_thread(found.record_path.read_text))
        except (OSError, ValueError):
            raise NotFound(f"flight {flight_id} left no record") from None
        return doc

    def report_dir(self, flight_id: str) -> Path:
        """The folder of the flight's report."""
        found = self.known(flight_id)
        folder = found.report_dir
        if folder is None or not folder.is_dir():
            raise NotFound(f"flight {flight_id} has no report yet")
        return folder

    async def report_file(self, flight_id: str, name: str) -> Path:
        """A file of the flight's report: a figure is drawn from the record the first time
        it is asked for (a second or so; the flight's worker leaves only the pages)."""
        folder = self.report_dir(flight_id)
        path = folder / name
        if "/" in name or name.startswith("."):
            raise NotFound(f"no report file {name!r}")
        if name in FIGURES and not path.is_file():
            async with self._drawing.setdefault((flight_id, name), asyncio.Lock()):
                if not path.is_file():
                    record = await self.record(flight_id)
                    await asyncio.to_thread(write_figure, record, folder, name)
        if not path.is_file():
            raise NotFound(f"no report file {name!r}")
        return path

    # -- steering (commands to the flight's worker) ---------------------------------------------

    async def upload(self, flight_id: str) -> dict[str, Any]:
        """Start the upload of every vehicle's mission (:meth:`Flight.upload`)."""
        result: dict[str, Any] = await self.flight(flight_id).request("upload")
        return result

    async def launch(
        self, flight_id: str, start_utc_s: float | None, delay_s: float | None
    ) -> dict[str, Any]:
        """Start the flight at a UTC, or ``delay_s`` mission seconds from now
        (:meth:`Flight.launch`)."""
        result: dict[str, Any] = await self.flight(flight_id).request(
            "launch", start_utc_s=start_utc_s, delay_s=delay_s
        )
        return result

    async def add_threat(
        self, flight_id: str, threat: Threat, at_s: float | None
    ) -> dict[str, Any]:
        result: dict[str, Any] = await self.flight(flight_id).request(
            "add_threat", threat=threat.model_dump(mode="json"), at_s=at_s
        )
        return result

    async def remove_threat(self, flight_id: str, threat_id: str) -> None:
        await self.flight(flight_id).request("remove_threat", threat_id=threat_id)

    async def team_time(self, flight_id: str) -> dict[str, Any]:
        found = self.known(flight_id)
        if isinstance(found, EndedFlight) or found.over:
            snap = found.snapshot if isinstance(found, EndedFlight) else found.snapshot()
            return {"team_time_s": snap["team_time_s"], "version": snap["team_time_version"]}
        result: dict[str, Any] = await found.request("team_time")
        return result

    async def move_team_time(
        self, flight_id: str, arrival_s: float, version: int | None
    ) -> dict[str, Any]:
        """Move the team arrival, mission s (:meth:`Flight.move_team_time`)."""
        result: dict[str, Any] = await self.flight(flight_id).request(
            "move_team_time", arrival_s=arrival_s, version=version
        )
        return result

    async def abort(self, flight_id: str, vehicle: str | None, mode: str) -> dict[str, Any]:
        result: dict[str, Any] = await self.flight(flight_id).request(
            "abort", vehicle=vehicle, mode=mode
        )
        return result

    async def pause(self, flight_id: str, at_s: float | None) -> dict[str, Any]:
        """A rehearsal waits at mission second ``at_s`` (:meth:`Flight.pause`)."""
        result: dict[str, Any] = await self.flight(flight_id).request("pause", at_s=at_s)
        return result

    async def resume(self, flight_id: str) -> dict[str, Any]:
        """A paused rehearsal flies on (:meth:`Flight.resume`)."""
        result: dict[str, Any] = await self.flight(flight_id).request("resume")
        return result

    # -- reading --------------------------------------------------------------------------------

    def snapshot(self, flight_id: str) -> dict[str, Any]:
        """The flight's snapshot (as its worker last told it, within a quarter of a second
        of wall time)."""
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            return found.snapshot
        return found.snapshot()

    async def flight_map(self, flight_id: str) -> dict[str, Any]:
        """What the map draws (:meth:`Flight.flight_map`)."""
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            if found.map is None:
                raise NotFound(f"flight {flight_id} left no map")
            return found.map
        return await found.flight_map()

    def flight_views(self) -> list[dict[str, Any]]:
        """Every flight: this process's, then those that ended before it started."""
        out: list[dict[str, Any]] = [
            {"id": fid, "state": f.state.value, "schedule_id": f.schedule_id}
            for fid, f in self.flights.items()
        ]
        for fid in self.store.flights_in(ENDED_STATES):
            ended = None if fid in self.flights else self.ended.get(fid)
            if ended is not None:
                schedule_id = ended.snapshot.get("schedule_id")
                out.append({"id": fid, "state": ended.state, "schedule_id": schedule_id})
        return out

    def events(self, flight_id: str, after_seq: int, limit: int) -> list[FlightEvent]:
        self.known(flight_id)
        return self.store.events(flight_id, after_seq=after_seq, limit=limit)


def _key_hex(fleet: Fleet, connection: str) -> str | None:
    signing = fleet.signing.get(connection)
    return None if signing is None else signing.secret_key.hex()


def _signing(key_hex: str) -> SigningConfig:
    """A 32-byte signing key given as 64 hex digits."""
    try:
        return SigningConfig.from_hex(key_hex)
    except ValueError as err:
        raise InvalidInput(f"signing_key: {err}") from None

"""The service's engine: the fleet, the store, planning (:mod:`gcs.service.planning`) and the
flights, for the life of the process.

Everything an API request does goes through :class:`Engine`: register a vehicle (or start
bundled simulator vehicles), keep a scenario and plan a schedule as a job (its
:class:`~gcs.service.planning.Planning`), create a flight on a schedule and vehicles, upload,
launch, steer it (threats, team time, abort) and read it (snapshot, events, record, report).
A flight is a :class:`~gcs.coordination.runner.FlightRunner` with its event and checkpoint
writers to the store; its vehicles are claimed from the fleet for as long as it runs. Errors
are :class:`ServiceError` subclasses that name what is wrong; the API maps them to status
codes.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gcs.coordination.bus import EventBus
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import FlightEvent
from gcs.coordination.missionclock import MissionClock
from gcs.coordination.runner import ENDED, FlightRunner, FlightState
from gcs.coordination.team import TeamTimeRefused
from gcs.errors import GcsError
from gcs.mavlink.signing import SigningConfig
from gcs.rehearsal.rehearse import RehearsalOptions, flight_record, stub_args
from gcs.rehearsal.report import write_report
from gcs.service.ended import EndedFlight, EndedFlights, keep_final
from gcs.service.fleet import Fleet, FleetVehicle, VehicleBusy
from gcs.service.mapview import flight_map
from gcs.service.planning import Limits, PlannedSchedule, Planning
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
from gcs.service.stubs import DEFAULT_SPEEDUP, StubProcess, follow_lockstep, stop_pid
from gcs.store.repository import FlightKeeper, Store
from planner.scenario import SrtmTerrainSpec, Threat

__all__ = [
    "Conflict",
    "Engine",
    "Infeasible",
    "InvalidInput",
    "Limits",
    "NotFound",
    "PreconditionFailed",
    "ServiceError",
    "TooBusy",
    "parse_scenario_text",
]

log = logging.getLogger(__name__)

ENDED_STATES = tuple(s.value for s in ENDED)
"""The store's states of a flight that has ended."""


LOCKSTEP_FILE = "pace"
"""A flight's bundled simulator keeps its lock-step file here, beside the flight's other
files (``sitl_stub --lockstep``): a service restarted on the flight follows it again."""


@dataclass
class Rehearsal:
    """Bundled simulator vehicles for a flight: speed-up, wind, loss, seed."""

    speedup: float = DEFAULT_SPEEDUP
    wind_m_s: float | None = None
    wind_from_deg: float = 0.0
    loss: float = 0.0
    seed: int = 0


@dataclass
class FlightHandle:
    id: str
    schedule: PlannedSchedule
    runner: FlightRunner
    vehicles: dict[str, FleetVehicle]
    connections: dict[str, str]
    rehearsal: Rehearsal | None = None
    stub: StubProcess | None = None
    truth_path: Path | None = None
    pacer: asyncio.Task[None] | None = None
    """Lock step with the flight's bundled simulator (:func:`follow_lockstep`)."""
    simulator_stopped: bool = False
    """The bundled simulator has been stopped (its pid, were it another process's, may be
    another program's by now)."""
    upload_task: asyncio.Task[None] | None = None
    task: asyncio.Task[None] | None = None
    keeper: FlightKeeper | None = None
    record: dict[str, Any] | None = None
    report_dir: Path | None = None
    wall0: float = field(default_factory=time.perf_counter)
    snapshot_cache: tuple[float, dict[str, Any]] | None = None
    final: tuple[dict[str, Any], dict[str, Any]] | None = None
    """Once it has ended and its record is written: its last snapshot and map, as kept."""


class Engine:
    """The fleet, the store, jobs and flights of one service process."""

    def __init__(
        self,
        store: Store,
        data_dir: Path,
        *,
        config: FlightConfig | None = None,
        limits: Limits | None = None,
    ):
        self.store = store
        self.data_dir = data_dir
        self.config = config or FlightConfig()
        self.limits = limits or Limits()
        self.planning = Planning(store, self.limits, self.config.method)
        """Scenarios, planning jobs and planned schedules."""
        self.ended = EndedFlights(data_dir / "flights")
        """Flights that ended before this process started (read from their folders)."""
        self.fleet = Fleet()
        self.flights: dict[str, FlightHandle] = {}
        self.vehicle_ids: dict[str, str] = {}
        """Vehicle id (the API's) -> connection string."""
        self._named = 0
        self._tasks: set[asyncio.Task[Any]] = set()
        self._stubs: list[StubProcess] = []

    async def close(self) -> None:
        """Stop: flights on bundled simulator vehicles end (failed: their simulator stops
        with the service); flights on live vehicles stay running in the store, and the next
        service process flies them on (:meth:`resume_kept`)."""
        for handle in list(self.flights.values()):
            simulated = (
                handle.stub is not None
                or (self.data_dir / "flights" / handle.id / "stub.pid").exists()
            )
            if simulated and handle.runner.state not in ENDED:
                handle.runner.fail("the service stopped, and its simulator vehicles with it")
            task = handle.task
            if task is not None and not task.done():
                task.cancel()
                with contextlib.suppress(BaseException):
                    await task
            await self._stop_writers(handle)
            await self._stop_simulator(handle)
        for task in list(self._tasks):
            task.cancel()
        await self.planning.close()
        await self.fleet.close()
        for stub in self._stubs:
            await stub.stop()

    def _spawn(self, coro: Any) -> asyncio.Task[Any]:
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    # -- vehicles -------------------------------------------------------------------------------

    async def add_vehicle(
        self, connection: str, *, system_id: int | None = None, signing_key: str | None = None
    ) -> dict[str, Any]:
        """Register a live vehicle by connection string (its link opened, HEARTBEAT heard).

        Raises
        ------
        InvalidInput
            A malformed connection string or signing key.
        ServiceError
            No vehicle answered there.
        """
        for vid, conn in self.vehicle_ids.items():
            if conn == connection:
                return self.vehicle_view(vid)
        try:
            signing = None if signing_key is None else _signing(signing_key)
            held = await self.fleet.vehicle(connection, system_id, signing=signing)
        except ValueError as err:
            raise InvalidInput(f"connection: {err}") from None
        except (GcsError, TimeoutError, OSError) as err:
            raise ServiceError(f"no vehicle answered at {connection}: {err}") from None
        return self.vehicle_view(self._name(held.connection))

    def _name(self, connection: str) -> str:
        """The API's id of the vehicle at ``connection`` (a new one the first time: ids are
        never given twice, even once a vehicle has gone)."""
        for vid, conn in self.vehicle_ids.items():
            if conn == connection:
                return vid
        self._named += 1
        vid = f"v{self._named}"
        self.vehicle_ids[vid] = connection
        return vid

    def _held(self, vehicle_id: str) -> FleetVehicle:
        conn = self.vehicle_ids.get(vehicle_id)
        held = None if conn is None else self.fleet.held(conn)
        if held is None:
            raise NotFound(f"no vehicle {vehicle_id!r}")
        return held

    def vehicle_view(self, vehicle_id: str) -> dict[str, Any]:
        """A vehicle held by the service: its link, and its mode and armed state while the
        link is up (null once it is down, its last word kept as ``last_mode`` and
        ``last_armed``)."""
        held = self._held(vehicle_id)
        st = held.vehicle.state
        c = held.link.counters
        now_s = held.link.clock()  # what it stamps receptions with
        age = st.heartbeat_age_s(now_s)
        mode, armed = st.mode_now(now_s)
        return {
            "id": vehicle_id,
            "connection": held.connection,
            "system_id": held.vehicle.system_id,
            "flight_id": held.flight_id,
            "link": {
                "heartbeat_age_s": None if age is None else round(max(age, 0.0), 3),
                "healthy": st.link_ok(now_s),
                "received": c.received,
                "sent": c.sent,
                "malformed": c.malformed + c.crc_errors,
                "rtt_s": c.rtt_s,
            },
            "mode": mode,
            "armed": armed,
            "last_mode": st.mode,
            "last_armed": st.armed,
            "lat_deg": st.lat_deg,
            "lon_deg": st.lon_deg,
            "alt_amsl_m": st.alt_amsl_m,
            "battery_pct": st.battery_remaining_pct,
        }

    def vehicle_views(self) -> list[dict[str, Any]]:
        return [self.vehicle_view(vid) for vid in self.vehicle_ids]

    # -- flights --------------------------------------------------------------------------------

    async def create_flight(
        self,
        schedule_id: str,
        vehicles: Mapping[str, str] | None,
        rehearsal: Rehearsal | None,
    ) -> FlightHandle:
        """A flight of ``schedule_id`` on registered vehicles (scenario vehicle -> vehicle
        id), or, with ``rehearsal`` and no vehicles, on bundled simulator vehicles started for
        it (on the ground at each start, nose along its path).

        Raises
        ------
        NotFound
            No such schedule or vehicle.
        Conflict
            A vehicle is already in a flight (named, with that flight).
        InvalidInput
            A scenario vehicle without a vehicle, or one named that the scenario lacks.
        """
        entry = await self.planning.planned(schedule_id)
        ids = [v.id for v in entry.scenario.vehicles]
        fid = uuid.uuid4().hex
        clock = MissionClock()
        bus = EventBus()
        runner = FlightRunner.planned(
            entry.scenario,
            entry.schedule,
            entry.world,
            clock,
            config=FlightConfig(seed=entry.seed),
            bus=bus,
            plan_wall_s=entry.plan_wall_s,
        )
        stub: StubProcess | None = None
        truth: Path | None = None
        pacer: asyncio.Task[None] | None = None
        flight_dir = self.data_dir / "flights" / fid
        if vehicles is None:
            if rehearsal is None:
                raise InvalidInput("a flight needs vehicles, or rehearsal options for stubs")
            flight_dir.mkdir(parents=True, exist_ok=True)
            truth = flight_dir / "truth.jsonl"
            opts = self._options(entry, rehearsal, flight_dir, None)
            pace = flight_dir / LOCKSTEP_FILE
            stub = await self.fleet.start_stubs(
                len(ids), [*stub_args(opts, runner, truth, time.time()), "--lockstep", str(pace)]
            )
            pacer = follow_lockstep(pace, clock, runner.unwatched)
            conns = dict(zip(ids, stub.connections, strict=True))
            sysids: list[int | None] = list(range(1, len(ids) + 1))
        else:
            unknown = sorted(set(vehicles) - set(ids))
            if unknown:
                raise InvalidInput(f"vehicles: {', '.join(unknown)} not in the scenario")
            missing = [i for i in ids if i not in vehicles]
            if missing:
                raise InvalidInput(f"vehicles: no vehicle for {', '.join(missing)}")
            conns = {i: self._held(vehicles[i]).connection for i in ids}
            sysids = [self._held(vehicles[i]).vehicle.system_id for i in ids]
        try:
            held = await self.fleet.claim(list(conns.values()), fid, sysids)
        except VehicleBusy as err:
            raise Conflict(str(err)) from None
        handle = FlightHandle(
            fid,
            entry,
            runner,
            dict(zip(ids, held, strict=True)),
            conns,
            rehearsal=rehearsal,
            stub=stub,
            truth_path=truth,
            pacer=pacer,
        )
        for h in held:
            self._name(h.connection)
        runner.bind({vid: h.vehicle for vid, h in handle.vehicles.items()})
        self.store.create_flight(entry.scenario_id, conns, flight_id=fid)
        for vid, h in handle.vehicles.items():
            self.store.set_vehicle(fid, vid, system_id=h.vehicle.system_id)
        if stub is not None:
            (flight_dir / "stub.pid").write_text(f"{stub.proc.pid}\n", encoding="utf-8")
        self._keep(handle)
        self.flights[fid] = handle
        return handle

    def _keep(self, handle: FlightHandle) -> None:
        """The flight's events and checkpoints go to the store as they happen."""
        handle.keeper = FlightKeeper(self.store, handle.id, handle.runner.bus)
        handle.runner.on_checkpoint = handle.keeper.checkpoints.offer

    # -- restart --------------------------------------------------------------------------------

    def resume_kept(self) -> list[str]:
        """Fly on every flight the store says is running (its service process died): from its
        checkpoint, on the vehicles it was flying (reached again by their connections), each
        mission compared before anything is sent. Returns their ids; each goes on in a task
        (a vehicle that cannot be reached fails the flight, with an event)."""
        resumed = []
        for fid in self.store.flights_in(("running",)):
            blob = self.store.checkpoint(fid)
            if blob is None or fid in self.flights:
                continue
            row = self.store.flight(fid)
            events = self.store.events(fid)
            bus = EventBus(first_seq=(events[-1].seq if events else 0) + 1)
            clock = MissionClock()
            runner = FlightRunner.resume(blob, clock, bus=bus, events=events)
            team = runner.team
            assert team is not None
            entry = PlannedSchedule(
                f"kept-{fid}", row.scenario_id, team.scenario, team.schedule, team.world,
                team.config.seed, runner.plan_wall_s,
            )  # fmt: skip
            conns = {vid: str(v[1]) for vid, v in row.vehicles.items()}
            flight_dir = self.data_dir / "flights" / fid
            truth = flight_dir / "truth.jsonl"
            handle = FlightHandle(
                fid, entry, runner, {}, conns, truth_path=truth if truth.exists() else None
            )
            if (flight_dir / LOCKSTEP_FILE).exists():  # its bundled simulator, still flying
                with contextlib.suppress(OSError, ValueError):
                    handle.pacer = follow_lockstep(
                        flight_dir / LOCKSTEP_FILE, clock, runner.unwatched
                    )
            self.flights[fid] = handle
            sysids = [row.vehicles[v.id][2] for v in team.scenario.vehicles]
            handle.task = self._spawn(self._resume(handle, sysids))
            resumed.append(fid)
        return resumed

    async def _resume(self, handle: FlightHandle, sysids: Sequence[int | None]) -> None:
        runner = handle.runner
        ids = [v.id for v in runner.scenario.vehicles]
        self._keep(handle)
        try:
            held = await self.fleet.claim([handle.connections[i] for i in ids], handle.id, sysids)
            handle.vehicles = dict(zip(ids, held, strict=True))
            for h in held:
                self._name(h.connection)
            runner.bind({vid: h.vehicle for vid, h in handle.vehicles.items()})
            await self._wait_clock(handle)
            await runner.reconcile()
        except (GcsError, TimeoutError, OSError, ValueError) as err:
            runner.fail(f"not resumed after a restart: {err}")
            if handle.pacer is not None:
                handle.pacer.cancel()
            await self._stop_writers(handle)
            self.fleet.release(handle.id)
            handle.task = None
            return
        assert runner.start_utc_s is not None
        await self._fly(handle, runner.start_utc_s)

    def _options(
        self,
        entry: PlannedSchedule,
        rehearsal: Rehearsal | None,
        flight_dir: Path,
        connections: Sequence[str] | None,
    ) -> RehearsalOptions:
        """The flight as the rehearsal's record describes one (``connections`` None: on
        bundled simulator vehicles)."""
        scenario_file = flight_dir / "scenario.yaml"
        if not scenario_file.exists():
            flight_dir.mkdir(parents=True, exist_ok=True)
            body = self.store.scenario(entry.scenario_id).body
            if isinstance(entry.scenario.terrain, SrtmTerrainSpec):
                # The simulator's terrain from the folder the planner read (the client's
                # folder name is relative to the service's SRTM folder, not to this file).
                body = json.dumps(entry.scenario.model_dump(mode="json", exclude_unset=True))
            scenario_file.write_text(body, encoding="utf-8")
        r = rehearsal or Rehearsal()
        wind = None if r.wind_m_s is None else (r.wind_m_s, r.wind_from_deg)
        return RehearsalOptions(
            scenario_path=scenario_file,
            scenario=entry.scenario,
            speedup=r.speedup,
            wind=wind,
            loss=r.loss,
            seed=r.seed,
            connect=() if connections is None else tuple(connections),
        )

    def flight(self, flight_id: str) -> FlightHandle:
        """A flight of this process (running, or ended since it started)."""
        handle = self.flights.get(flight_id)
        if handle is None:
            raise NotFound(f"no flight {flight_id!r}")
        return handle

    def known(self, flight_id: str) -> FlightHandle | EndedFlight:
        """A flight of this process, or one that ended before it started."""
        handle = self.flights.get(flight_id)
        if handle is not None:
            return handle
        ended = self.ended.get(flight_id)
        if ended is None:
            raise NotFound(f"no flight {flight_id!r}")
        return ended

    async def record(self, flight_id: str) -> dict[str, Any]:
        """The flight record (``tcgcs-flight/1``) once the flight is over."""
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            try:
                doc: dict[str, Any] = json.loads(
                    await asyncio.to_thread(found.record_path.read_text)
                )
            except (OSError, ValueError):
                raise NotFound(f"flight {flight_id} left no record") from None
            return doc
        if found.record is None:
            raise NotFound(f"flight {flight_id} has no record yet (it is {found.runner.state})")
        return found.record

    def report_dir(self, flight_id: str) -> Path:
        """The folder of the flight's report."""
        found = self.known(flight_id)
        folder = found.report_dir
        if folder is None or not folder.is_dir():
            raise NotFound(f"flight {flight_id} has no report yet")
        return folder

    async def _wait_clock(self, handle: FlightHandle) -> None:
        clock = handle.runner.clock
        try:
            async with asyncio.timeout(15.0):
                while not clock.synced:
                    await asyncio.sleep(0.02)
        except TimeoutError:
            raise ServiceError(f"flight {handle.id}: no SYSTEM_TIME from its vehicles") from None

    def upload(self, flight_id: str) -> dict[str, Any]:
        """Start the upload of every vehicle's mission; per-vehicle results in the snapshot.

        Raises
        ------
        Conflict
            The flight is not planned (already uploaded, running or over).
        """
        handle = self.flight(flight_id)
        state = handle.runner.state
        if state is not FlightState.PLANNED or handle.upload_task is not None:
            raise Conflict(f"flight {flight_id} is {state.value}: nothing to upload")
        handle.upload_task = self._spawn(self._upload(handle))
        return {"flight_id": flight_id, "state": "uploading", "vehicles": _uploads(handle)}

    async def _upload(self, handle: FlightHandle) -> None:
        runner = handle.runner
        try:
            await self._wait_clock(handle)
            await runner.upload_all()
        except GcsError as err:
            log.info("flight %s: upload failed: %s", handle.id, err)

    def launch(
        self, flight_id: str, start_utc_s: float | None, delay_s: float | None
    ) -> dict[str, Any]:
        """Start the flight at a UTC (or ``delay_s`` mission seconds from now).

        Raises
        ------
        Conflict
            Not uploaded yet, or already launched or over.
        """
        handle = self.flight(flight_id)
        runner = handle.runner
        if runner.state is not FlightState.READY or handle.task is not None:
            raise Conflict(f"flight {flight_id} is {runner.state.value}: it cannot be launched")
        clock = runner.clock
        if start_utc_s is None:
            wait = clock.start_lead_s() if delay_s is None else delay_s
            start_utc_s = clock.now_utc_s() + wait
        elif not math.isfinite(start_utc_s) or start_utc_s < clock.now_utc_s():
            raise InvalidInput(f"start_utc_s: {start_utc_s!r} is not a UTC in the future")
        self.store.update_flight(flight_id, start_utc_s=start_utc_s, team_time_s=runner.team_ref_s)
        handle.task = self._spawn(self._fly(handle, start_utc_s))
        return {"flight_id": flight_id, "start_utc_s": start_utc_s}

    async def _fly(self, handle: FlightHandle, start_utc_s: float) -> None:
        runner = handle.runner
        try:
            await runner.run(start_utc_s)
        except Exception:
            log.exception("flight %s failed", handle.id)
        finally:
            await runner.close()
            await self._finish(handle)

    async def _finish(self, handle: FlightHandle) -> None:
        """The record and the report, the writers flushed, the vehicles released."""
        runner = handle.runner
        if handle.truth_path is not None:
            # The simulator stopped first: its truth log is then whole (closed) when the
            # record reads it, however far behind the writing a busy machine has left it.
            await self._stop_simulator(handle)
        flight_dir = self.data_dir / "flights" / handle.id
        try:
            conns = None if handle.stub is not None else list(handle.connections.values())
            opts = self._options(handle.schedule, handle.rehearsal, flight_dir, conns)
            if runner.start_utc_s is not None:
                wall_s = time.perf_counter() - handle.wall0

                def record_file() -> dict[str, Any]:
                    # Seconds of work for a large team's truth log: off the event loop,
                    # which other flights and the API share (the runner has stopped).
                    record = flight_record(runner, opts, handle.truth_path, wall_s)
                    record["flight_id"] = handle.id
                    text = json.dumps(record, indent=1) + "\n"
                    (flight_dir / "flight.json").write_text(text)
                    return record

                handle.record = await asyncio.to_thread(record_file)
                report = flight_dir / "report"
                await asyncio.to_thread(write_report, handle.record, report)
                handle.report_dir = report
        except Exception:
            log.exception("flight %s: record or report failed", handle.id)
        try:
            # Its last snapshot and map, kept: from now on the flight is answered with them,
            # by this process and by any after it.
            snap = self._snapshot(handle)
            snap["record_ready"] = handle.record is not None
            final = snap, self.flight_map(handle.id)
            await asyncio.to_thread(keep_final, self.data_dir / "flights" / handle.id, *final)
            handle.final = final
        except Exception:
            log.exception("flight %s: its last snapshot was not kept", handle.id)
        await self._stop_writers(handle)
        self.fleet.release(handle.id)
        if handle.pacer is not None:
            handle.pacer.cancel()
        simulated = handle.stub is not None or (flight_dir / "stub.pid").exists()
        await self._stop_simulator(handle)
        if simulated:
            # Its simulator vehicles went with their simulator: no longer the service's.
            gone = set(handle.connections.values())
            await self.fleet.drop(sorted(gone))
            self.vehicle_ids = {v: c for v, c in self.vehicle_ids.items() if c not in gone}

    async def _stop_simulator(self, handle: FlightHandle) -> None:
        """The flight's bundled simulator: ours, or one an earlier process started for it
        (its pid kept beside the flight's files)."""
        if handle.simulator_stopped:
            return
        handle.simulator_stopped = True
        if handle.stub is not None:
            await handle.stub.stop()
            return
        pid_file = self.data_dir / "flights" / handle.id / "stub.pid"
        if pid_file.exists():
            with contextlib.suppress(ValueError, OSError):
                await stop_pid(int(pid_file.read_text()))

    async def _stop_writers(self, handle: FlightHandle) -> None:
        handle.runner.on_checkpoint = None
        if handle.keeper is not None:
            keeper, handle.keeper = handle.keeper, None
            with contextlib.suppress(BaseException):
                await keeper.close()

    # -- steering -------------------------------------------------------------------------------

    def _running(self, flight_id: str) -> FlightHandle:
        handle = self.flight(flight_id)
        if handle.runner.state in ENDED:
            raise Conflict(f"flight {flight_id} is {handle.runner.state.value}")
        return handle

    def add_threat(self, flight_id: str, threat: Threat, at_s: float | None) -> dict[str, Any]:
        handle = self._running(flight_id)
        try:
            handle.runner.add_threat(threat, at_s)
        except ValueError as err:
            raise Conflict(str(err)) from None
        return {"id": threat.id, "flight_id": flight_id}

    def remove_threat(self, flight_id: str, threat_id: str) -> None:
        handle = self._running(flight_id)
        try:
            handle.runner.remove_threat(threat_id)
        except KeyError as err:
            raise NotFound(str(err.args[0])) from None

    def team_time(self, flight_id: str) -> dict[str, Any]:
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            snap = found.snapshot
            return {"team_time_s": snap["team_time_s"], "version": snap["team_time_version"]}
        team = found.runner.team
        assert team is not None
        return {"team_time_s": team.team_ref_s, "version": team.version}

    def move_team_time(
        self, flight_id: str, arrival_s: float, version: int | None
    ) -> dict[str, Any]:
        """Move the team arrival (mission s).

        Raises
        ------
        PreconditionFailed
            ``version`` is not the current one.
        Infeasible
            Some vehicle cannot make it (the earliest feasible time and that vehicle).
        """
        handle = self._running(flight_id)
        team = handle.runner.team
        assert team is not None
        if version is not None and version != team.version:
            raise PreconditionFailed(f"team time version {version} is stale (now {team.version})")
        try:
            handle.runner.move_team_time(arrival_s, version=version)
        except TeamTimeRefused as err:
            raise Infeasible(str(err), err.earliest_s, err.vehicle_id, err.latest_s) from None
        except GcsError as err:
            raise Conflict(str(err)) from None
        return self.team_time(flight_id)

    async def abort(self, flight_id: str, vehicle: str | None, mode: str) -> dict[str, Any]:
        handle = self._running(flight_id)
        try:
            results = await handle.runner.abort(vehicle, mode="rtl" if mode == "rtl" else "loiter")
        except KeyError as err:
            raise NotFound(str(err.args[0])) from None
        return {"flight_id": flight_id, "vehicles": results}

    # -- reading --------------------------------------------------------------------------------

    def snapshot(self, flight_id: str, *, max_age_s: float = 0.0) -> dict[str, Any]:
        """The flight's snapshot; with ``max_age_s``, one taken that recently may be given
        again (many stream clients share one per flight)."""
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            return found.snapshot
        handle = found
        if handle.final is not None:
            return handle.final[0]
        now = time.monotonic()
        if max_age_s > 0.0 and handle.snapshot_cache is not None:
            taken, snap = handle.snapshot_cache
            if now - taken <= max_age_s:
                return snap
        snap = self._snapshot(handle)
        handle.snapshot_cache = (now, snap)
        return snap

    def _snapshot(self, handle: FlightHandle) -> dict[str, Any]:
        flight_id = handle.id
        snap = handle.runner.snapshot()
        snap["flight_id"] = flight_id
        snap["schedule_id"] = handle.schedule.id
        snap["uploads"] = _uploads(handle)
        snap["record_ready"] = handle.final is not None and handle.record is not None
        return snap

    def flight_map(self, flight_id: str) -> dict[str, Any]:
        """What the map draws (:func:`gcs.service.mapview.flight_map`), with the flight's
        scenario id (its terrain image)."""
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            if found.map is None:
                raise NotFound(f"flight {flight_id} left no map")
            return found.map
        if found.final is not None:
            return found.final[1]
        team = found.runner.team
        assert team is not None
        doc = flight_map(team, found.runner.now_s())
        doc["scenario_id"] = found.schedule.scenario_id
        return doc

    def flight_views(self) -> list[dict[str, Any]]:
        """Every flight: this process's, then those that ended before it started."""
        out: list[dict[str, Any]] = [
            {"id": fid, "state": h.runner.state.value, "schedule_id": h.schedule.id}
            for fid, h in self.flights.items()
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


def _uploads(handle: FlightHandle) -> dict[str, dict[str, Any]]:
    """Per vehicle, once an upload was asked for: pending, ok, or failed and why (read from
    the runner's results, so it never lags the flight's state)."""
    if handle.upload_task is None:
        return {}
    results = handle.runner.upload_results
    out: dict[str, dict[str, Any]] = {}
    for vid in handle.vehicles:
        if vid not in results:
            out[vid] = {"state": "pending"}
        else:
            why = results[vid]
            out[vid] = {"state": "ok" if why is None else "failed", "error": why}
    return out


def _signing(key_hex: str) -> SigningConfig:
    """A 32-byte signing key given as 64 hex digits."""
    try:
        return SigningConfig.from_hex(key_hex)
    except ValueError as err:
        raise InvalidInput(f"signing_key: {err}") from None

"""One flight of the service: its runner, the vehicles it has claimed, its bundled simulator
and its writers to the store, from its creation until its record, report and last snapshot are
kept.

A :class:`Flight` is made by :meth:`Flight.create` (a planned schedule on vehicles, or on
bundled simulator vehicles started for it) or :meth:`Flight.resumed` (from the checkpoint of a
flight whose service process died). It is steered (:meth:`Flight.upload`, :meth:`Flight.launch`,
threats, team time, abort) and read (:meth:`Flight.snapshot`, :meth:`Flight.flight_map`). Errors
are :class:`~gcs.service.scenariotext.ServiceError` subclasses that name what is wrong.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcs.coordination.bus import EventBus
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind
from gcs.coordination.missionclock import MissionClock
from gcs.coordination.runner import ENDED, FlightRunner, FlightState
from gcs.coordination.separationlog import separation_kind
from gcs.coordination.team import TeamTimeRefused
from gcs.errors import GcsError
from gcs.rehearsal.rehearse import RehearsalOptions, flight_record, stub_args
from gcs.rehearsal.report import write_report
from gcs.service.ended import keep_final
from gcs.service.fleet import Fleet, FleetVehicle, VehicleBusy
from gcs.service.flightjobs import FlightJobs
from gcs.service.mapview import flight_map
from gcs.service.pauses import Pauses
from gcs.service.planning import PlannedSchedule
from gcs.service.scenariotext import (
    Conflict,
    Infeasible,
    InvalidInput,
    NotFound,
    PreconditionFailed,
    ServiceError,
)
from gcs.service.stubs import DEFAULT_SPEEDUP, StubProcess, follow_lockstep, stop_pid
from gcs.store.repository import FlightKeeper, Store
from planner.scenario import SrtmTerrainSpec, Threat

__all__ = [
    "COUNTERS_FILE",
    "LOCKSTEP_FILE",
    "STUB_PID_FILE",
    "Flight",
    "Rehearsal",
    "stop_kept_simulator",
]

log = logging.getLogger(__name__)

LOCKSTEP_FILE = "pace"
"""A flight's bundled simulator keeps its lock-step file here, beside the flight's other
files (``sitl_stub --lockstep``): a service restarted on the flight follows it again."""
COUNTERS_FILE = "counters.json"
"""What a flight's bundled simulator's vehicles were made to do (arms, AUTO entries, mission
transfers: ``sitl_stub --counters``), beside its files."""
STUB_PID_FILE = "stub.pid"
"""The pid of a flight's bundled simulator, beside its files: a later process stops it."""
CLOCK_WAIT_S = 15.0
"""How long (wall s) a flight waits for its vehicles' SYSTEM_TIME before it uploads."""


@dataclass
class Rehearsal:
    """Bundled simulator vehicles for a flight: speed-up, wind, loss, seed."""

    speedup: float = DEFAULT_SPEEDUP
    wind_m_s: float | None = None
    wind_from_deg: float = 0.0
    loss: float = 0.0
    seed: int = 0
    lockstep: bool = True
    """The simulator waits for the flight (a busy machine slows it instead of making the
    flight late); False: it runs on the wall clock, as real vehicles do."""


class Flight:
    """One flight: its runner, its claimed vehicles, its simulator and its store writers.

    The vehicles are claimed from ``fleet`` for as long as it flies; ``folder`` keeps its
    scenario, its simulator's files, its record, report and last snapshot (``final.json``).
    """

    def __init__(
        self,
        flight_id: str,
        schedule: PlannedSchedule,
        runner: FlightRunner,
        *,
        store: Store,
        fleet: Fleet,
        folder: Path,
        connections: dict[str, str],
        rehearsal: Rehearsal | None = None,
        stub: StubProcess | None = None,
        pacer: asyncio.Task[None] | None = None,
    ) -> None:
        self.id = flight_id
        self.schedule = schedule
        self.runner = runner
        self.store = store
        self.fleet = fleet
        self.folder = folder
        self.connections = connections
        """Scenario vehicle -> the connection string of the vehicle flying it."""
        self.rehearsal = rehearsal
        self.stub = stub
        truth = folder / "truth.jsonl"
        self.truth_path: Path | None = truth if stub is not None or truth.exists() else None
        self.pacer = pacer
        """Lock step with the flight's bundled simulator (:func:`follow_lockstep`)."""
        self.vehicles: dict[str, FleetVehicle] = {}
        self.upload_task: asyncio.Task[None] | None = None
        self.task: asyncio.Task[None] | None = None
        """The flight flying (after :meth:`launch`, or a resume)."""
        self.record: dict[str, Any] | None = None
        self.report_dir: Path | None = None
        self.final: tuple[dict[str, Any], dict[str, Any]] | None = None
        """Once it has ended and its record is written: its last snapshot and map, as kept."""
        self.about_worker: Callable[[], dict[str, Any]] | None = None
        """The snapshot's ``worker``: the process flying it (:mod:`gcs.service.worker`)."""
        self.on_over: Callable[[Flight], None] | None = None
        """Called once it has ended and all it leaves is kept."""
        self._simulator_stopped = False
        """Its bundled simulator has been stopped (its pid, were it another process's, may
        be another program's by now)."""
        self.jobs = FlightJobs()
        """Its planning jobs, each in a process of its own."""
        runner.run_job = self.jobs.run
        self.taken_on = asyncio.Event()
        """Set once its vehicles are found as the flight left them (at once for a new
        flight; after :meth:`resumed`, once they are reached again and compared)."""
        self.pauses = Pauses(flight_id, runner.clock, folder)
        self._wall0 = time.perf_counter()
        self._keeper: FlightKeeper | None = FlightKeeper(store, flight_id, runner.bus)
        runner.on_checkpoint = self._keeper.checkpoints.offer

    # -- making one -----------------------------------------------------------------------------

    @classmethod
    async def create(
        cls,
        flight_id: str,
        entry: PlannedSchedule,
        vehicles: Sequence[tuple[str, int | None]] | None,
        rehearsal: Rehearsal | None,
        *,
        store: Store,
        fleet: Fleet,
        folder: Path,
        lockstep: Path | None = None,
    ) -> Flight:
        """A flight of ``entry`` on the vehicles at ``vehicles`` (``(connection, system
        id)`` per scenario vehicle, in its order), or with ``rehearsal`` and no vehicles on
        bundled simulator vehicles started for it (on the ground at each start, nose along
        its path); its vehicles claimed and its row in the store. ``lockstep``: the vehicles'
        simulator's lock-step file, joined (and linked from the folder: a worker that takes the
        flight on joins it again).

        Raises
        ------
        Conflict
            A vehicle is already in a flight (named, with that flight).
        InvalidInput
            Neither vehicles nor rehearsal options.
        """
        ids = [v.id for v in entry.scenario.vehicles]
        clock = MissionClock()
        runner = FlightRunner.planned(
            entry.scenario,
            entry.schedule,
            entry.world,
            clock,
            config=FlightConfig(seed=entry.seed),
            bus=EventBus(),
            plan_wall_s=entry.plan_wall_s,
        )
        stub: StubProcess | None = None
        pacer: asyncio.Task[None] | None = None
        if vehicles is None:
            if rehearsal is None:
                raise InvalidInput("a flight needs vehicles, or rehearsal options for stubs")
            folder.mkdir(parents=True, exist_ok=True)
            opts = _options(store, entry, rehearsal, folder, None)
            pace = folder / LOCKSTEP_FILE
            args = stub_args(opts, runner, folder / "truth.jsonl", time.time())
            args += ["--counters", str(folder / COUNTERS_FILE)]
            if rehearsal.lockstep:
                args += ["--lockstep", str(pace)]
            stub = await fleet.start_stubs(len(ids), args)
            if rehearsal.lockstep:
                pacer = follow_lockstep(pace, clock, runner.unwatched)
            vehicles = [(c, k) for k, c in enumerate(stub.connections, start=1)]
        elif lockstep is not None:
            folder.mkdir(parents=True, exist_ok=True)
            with contextlib.suppress(FileNotFoundError):
                (folder / LOCKSTEP_FILE).unlink()
            (folder / LOCKSTEP_FILE).symlink_to(lockstep)
            pacer = follow_lockstep(lockstep, clock, runner.unwatched)
        conns = {vid: conn for vid, (conn, _) in zip(ids, vehicles, strict=True)}
        try:
            held = await fleet.claim(list(conns.values()), flight_id, [s for _, s in vehicles])
        except BaseException as err:
            if pacer is not None:
                pacer.cancel()
            if stub is not None:
                await stub.stop()
            if isinstance(err, VehicleBusy):
                raise Conflict(str(err)) from None
            raise
        store.create_flight(entry.scenario_id, conns, flight_id=flight_id)
        flight = cls(
            flight_id, entry, runner, store=store, fleet=fleet, folder=folder,
            connections=conns, rehearsal=rehearsal, stub=stub, pacer=pacer,
        )  # fmt: skip
        flight._bind(held)
        flight.taken_on.set()
        for vid, h in flight.vehicles.items():
            store.set_vehicle(flight_id, vid, system_id=h.vehicle.system_id)
        if stub is not None:
            (folder / STUB_PID_FILE).write_text(f"{stub.proc.pid}\n", encoding="utf-8")
        return flight

    @classmethod
    def resumed(cls, flight_id: str, *, store: Store, fleet: Fleet, folder: Path) -> Flight | None:
        """The flight ``flight_id`` the store says is running, from its checkpoint (None
        without one); :meth:`fly_on` reaches its vehicles again and flies it on."""
        blob = store.checkpoint(flight_id)
        if blob is None:
            return None
        row = store.flight(flight_id)
        events = store.events_to_resume(flight_id)
        bus = EventBus(first_seq=(events[-1].seq if events else 0) + 1)
        clock = MissionClock()
        runner = FlightRunner.resume(blob, clock, bus=bus, events=events)
        team = runner.team
        assert team is not None
        entry = PlannedSchedule(
            f"kept-{flight_id}", row.scenario_id, team.scenario, team.schedule, team.world,
            team.config.seed, runner.plan_wall_s,
        )  # fmt: skip
        conns = {vid: str(v[1]) for vid, v in row.vehicles.items()}
        pacer = None
        if (folder / LOCKSTEP_FILE).exists():  # its simulator, still flying
            with contextlib.suppress(OSError, ValueError):
                pacer = follow_lockstep(folder / LOCKSTEP_FILE, clock, runner.unwatched)
        flight = cls(
            flight_id, entry, runner, store=store, fleet=fleet, folder=folder,
            connections=conns, pacer=pacer,
        )  # fmt: skip
        sysids = [row.vehicles[v.id][2] for v in team.scenario.vehicles]
        flight.task = asyncio.get_running_loop().create_task(flight._fly_on(sysids))
        return flight

    def _bind(self, held: Sequence[FleetVehicle]) -> None:
        ids = [v.id for v in self.runner.scenario.vehicles]
        self.vehicles = dict(zip(ids, held, strict=True))
        self.runner.bind({vid: h.vehicle for vid, h in self.vehicles.items()})

    async def _fly_on(self, sysids: Sequence[int | None]) -> None:
        try:
            start_utc_s = await self._take_on(sysids)
        finally:
            self.taken_on.set()
        if start_utc_s is not None:
            await self._fly(start_utc_s)

    async def _take_on(self, sysids: Sequence[int | None]) -> float | None:
        """Reach the vehicles again and compare them with the checkpoint: the mission's start
        to fly on from, or None (not launched: ready again, its vehicles holding their
        missions, for a launch; or it could not be taken on, and has failed)."""
        runner = self.runner
        ids = [v.id for v in runner.scenario.vehicles]
        try:
            held = await self.fleet.claim([self.connections[i] for i in ids], self.id, sysids)
            self._bind(held)
            await self._wait_clock()
            await runner.reconcile()
            start_utc_s = runner.start_utc_s
            if start_utc_s is None:  # launched after its last checkpoint, or not launched
                start_utc_s = (await asyncio.to_thread(self.store.flight, self.id)).start_utc_s
        except (GcsError, TimeoutError, OSError, ValueError) as err:
            runner.fail(f"not resumed after a restart: {err}")
            if self.pacer is not None:
                self.pacer.cancel()
            await self._stop_writers()
            self.fleet.release(self.id)
            start_utc_s = None
        if start_utc_s is None:
            self.task = None
        else:
            self.pauses.launched(start_utc_s)
        return start_utc_s

    # -- views ----------------------------------------------------------------------------------

    @property
    def bus(self) -> EventBus:
        """Every event of the flight, numbered."""
        return self.runner.bus

    @property
    def state(self) -> FlightState:
        return self.runner.state

    @property
    def simulated(self) -> bool:
        """Flown on bundled simulator vehicles (this process's, or an earlier one's)."""
        return self.stub is not None or (self.folder / STUB_PID_FILE).exists()

    @property
    def over(self) -> bool:
        """It has ended and its record, report and last snapshot are kept."""
        return self.runner.state in ENDED and self.final is not None

    def snapshot(self) -> dict[str, Any]:
        """The flight's snapshot now (its last, as kept, once it is over)."""
        if self.final is not None:
            return self.final[0]
        return self._snapshot()

    def _snapshot(self) -> dict[str, Any]:
        snap = self.runner.snapshot()
        if snap["state"] == FlightState.READY.value and self._uploading():
            # Ready once kept: a worker that dies before leaves nothing to fly on from.
            snap["state"] = FlightState.UPLOADING.value
        snap["flight_id"] = self.id
        snap["schedule_id"] = self.schedule.id
        snap["uploads"] = self._uploads()
        snap["record_ready"] = self.final is not None and self.record is not None
        # Paused or not at the snapshot's own mission time (the simulator moves on meanwhile).
        launched = self.pauses.start_utc_s is not None and self.runner.start_utc_s is not None
        snap["pause"] = self.pauses.view(snap["t_s"] if launched else self._mission_s())
        if self.about_worker is not None:
            snap["worker"] = self.about_worker()
        return snap

    def _uploading(self) -> bool:
        return self.upload_task is not None and not self.upload_task.done()

    def _uploads(self) -> dict[str, dict[str, Any]]:
        """Per vehicle, once an upload was asked for: pending, ok, or failed and why (read
        from the runner's results, so it never lags the flight's state)."""
        if self.upload_task is None:
            return {}
        results = self.runner.upload_results
        out: dict[str, dict[str, Any]] = {}
        for vid in self.connections:
            if vid not in results:
                out[vid] = {"state": "pending"}
            else:
                why = results[vid]
                out[vid] = {"state": "ok" if why is None else "failed", "error": why}
        return out

    def flight_map(self) -> dict[str, Any]:
        """What the map draws (:func:`gcs.service.mapview.flight_map`), with the flight's
        scenario id (its terrain image)."""
        if self.final is not None:
            return self.final[1]
        team = self.runner.team
        assert team is not None
        doc = flight_map(team, self.runner.now_s())
        doc["scenario_id"] = self.schedule.scenario_id
        return doc

    def vehicle_views(self) -> dict[str, dict[str, Any]]:
        """Per connection, its vehicle as ``/v1/vehicles`` shows it (:meth:`FleetVehicle.view`)."""
        return {h.connection: h.view() for h in self.vehicles.values()}

    def figures(self) -> dict[str, Any]:
        """What ``/metrics`` shows of the flight: its state, commands and uploads by result,
        each arrival's error against its slot, the events a subscriber could not take, its
        separation events by kind and the least distance a separation alarm reported."""
        commands: Counter[str] = Counter()
        uploads: Counter[str] = Counter()
        separations: Counter[str] = Counter()
        lost_m: list[float] = []
        for ev in self.runner.events:
            sep = separation_kind(ev)
            if sep is not None:
                separations[sep.kind] += 1
                if sep.kind == "loss" and sep.said_m is not None:
                    lost_m.append(sep.said_m)
            if ev.kind is EventKind.SPEED:
                commands["speed " + ("failed" if "failed" in ev.reason else "ok")] += 1
            elif ev.kind is EventKind.LAUNCH:
                commands["launch " + ("ok" if ev.payload.get("ok", True) else "failed")] += 1
            elif ev.kind is EventKind.UPLOAD:
                uploads["failed" if "failed" in ev.reason else "ok"] += 1
        late_s = {
            m.vehicle_id: m.arrival_s - m.target_s
            for m in self.runner.members.values()
            if m.arrival_s is not None
        }
        return {
            "state": self.state.value,
            "commands": dict(commands),
            "uploads": dict(uploads),
            "arrival_error_s": late_s,
            "event_drops": self.bus.dropped,
            "separation_events": dict(separations),
            "separation_loss_min_m": min(lost_m) if lost_m else None,
        }

    def team_time(self) -> dict[str, Any]:
        team = self.runner.team
        assert team is not None
        return {"team_time_s": team.team_ref_s, "version": team.version}

    # -- steering -------------------------------------------------------------------------------

    def _running(self) -> None:
        if self.runner.state in ENDED:
            raise Conflict(f"flight {self.id} is {self.runner.state.value}")

    def upload(self) -> dict[str, Any]:
        """Start the upload of every vehicle's mission; per-vehicle results in the snapshot.

        Raises
        ------
        Conflict
            The flight is not planned (already uploaded, running or over).
        """
        state = self.runner.state
        if state is not FlightState.PLANNED or self.upload_task is not None:
            raise Conflict(f"flight {self.id} is {state.value}: nothing to upload")
        self.upload_task = asyncio.get_running_loop().create_task(self._upload())
        return {"flight_id": self.id, "state": "uploading", "vehicles": self._uploads()}

    async def _upload(self) -> None:
        try:
            await self._wait_clock()
            await self.runner.upload_all()
            if self._keeper is not None:
                await self._keeper.checkpoints.kept()
        except GcsError as err:
            log.info("flight %s: upload failed: %s", self.id, err)

    async def _wait_clock(self) -> None:
        clock = self.runner.clock
        try:
            async with asyncio.timeout(CLOCK_WAIT_S):
                while not clock.synced:
                    await asyncio.sleep(0.02)
        except TimeoutError:
            raise ServiceError(f"flight {self.id}: no SYSTEM_TIME from its vehicles") from None

    async def launch(self, start_utc_s: float | None, delay_s: float | None) -> dict[str, Any]:
        """Start the flight at a UTC (or ``delay_s`` mission seconds from now); one taken on
        after a restart once its vehicles are found as it left them.

        Raises
        ------
        Conflict
            Not uploaded yet, or already launched or over.
        InvalidInput
            A start that is not in the future.
        """
        await self.taken_on.wait()
        runner = self.runner
        if runner.state is not FlightState.READY or self.task is not None:
            raise Conflict(f"flight {self.id} is {runner.state.value}: it cannot be launched")
        clock = runner.clock
        if start_utc_s is None:
            wait = clock.start_lead_s() if delay_s is None else delay_s
            start_utc_s = clock.now_utc_s() + wait
        elif not math.isfinite(start_utc_s) or start_utc_s < clock.now_utc_s():
            raise InvalidInput(f"start_utc_s: {start_utc_s!r} is not a UTC in the future")
        self.store.update_flight(self.id, start_utc_s=start_utc_s, team_time_s=runner.team_ref_s)
        self.pauses.launched(start_utc_s)
        self.task = asyncio.get_running_loop().create_task(self._fly(start_utc_s))
        return {"flight_id": self.id, "start_utc_s": start_utc_s}

    def pause(self, at_s: float | None) -> dict[str, Any]:
        """A rehearsal in lock step waits at mission second ``at_s`` (None: now) until
        :meth:`resume` (:class:`~gcs.service.pauses.Pauses`)."""
        self._running()
        return self.pauses.add(at_s, self._mission_s())

    def resume(self) -> dict[str, Any]:
        """A paused rehearsal flies on."""
        self._running()
        return self.pauses.resume(self._mission_s())

    def _mission_s(self) -> float | None:
        """Mission seconds now (None before the launch, or before the clock has synced)."""
        start, clock = self.pauses.start_utc_s, self.runner.clock
        return None if start is None or not clock.synced else clock.now_utc_s() - start

    def add_threat(self, threat: Threat, at_s: float | None) -> dict[str, Any]:
        self._running()
        try:
            self.runner.add_threat(threat, at_s)
        except ValueError as err:
            raise Conflict(str(err)) from None
        return {"id": threat.id, "flight_id": self.id}

    def remove_threat(self, threat_id: str) -> None:
        self._running()
        try:
            self.runner.remove_threat(threat_id)
        except KeyError as err:
            raise NotFound(str(err.args[0])) from None

    def move_team_time(self, arrival_s: float, version: int | None) -> dict[str, Any]:
        """Move the team arrival (mission s).

        Raises
        ------
        PreconditionFailed
            ``version`` is not the current one.
        Infeasible
            Some vehicle cannot make it (the earliest feasible time and that vehicle).
        """
        self._running()
        team = self.runner.team
        assert team is not None
        if version is not None and version != team.version:
            raise PreconditionFailed(f"team time version {version} is stale (now {team.version})")
        try:
            self.runner.move_team_time(arrival_s, version=version)
        except TeamTimeRefused as err:
            raise Infeasible(str(err), err.earliest_s, err.vehicle_id, err.latest_s) from None
        except GcsError as err:
            raise Conflict(str(err)) from None
        return self.team_time()

    async def abort(self, vehicle: str | None, mode: str) -> dict[str, Any]:
        self._running()
        try:
            results = await self.runner.abort(vehicle, mode="rtl" if mode == "rtl" else "loiter")
        except KeyError as err:
            raise NotFound(str(err.args[0])) from None
        return {"flight_id": self.id, "vehicles": results}

    # -- flying and ending ----------------------------------------------------------------------

    async def _fly(self, start_utc_s: float) -> None:
        runner = self.runner
        try:
            await runner.run(start_utc_s)
        except Exception:
            log.exception("flight %s failed", self.id)
        finally:
            await runner.close()
            await self._finish()

    async def _finish(self) -> None:
        """The record and the report, the writers flushed, the vehicles released."""
        if self.truth_path is not None:
            # The simulator stopped first: its truth log is then whole (closed) when the
            # record reads it, however far behind the writing a busy machine has left it.
            await self._stop_simulator()
        try:
            await self._write_record()
        except Exception:
            log.exception("flight %s: record or report failed", self.id)
        try:
            # Its last snapshot and map, kept: from now on the flight is answered with them,
            # by this process and by any after it.
            snap = self._snapshot()
            snap["record_ready"] = self.record is not None
            final = snap, self.flight_map()
            await asyncio.to_thread(keep_final, self.folder, *final)
            self.final = final
        except Exception:
            log.exception("flight %s: its last snapshot was not kept", self.id)
        await self._stop_writers()
        self.jobs.close()
        self.fleet.release(self.id)
        if self.pacer is not None:
            self.pacer.cancel()
        simulated = self.simulated
        await self._stop_simulator()
        if simulated:
            # Its simulator vehicles went with their simulator: no longer the service's.
            await self.fleet.drop(sorted(set(self.connections.values())))
        if self.on_over is not None:
            self.on_over(self)

    async def _write_record(self) -> None:
        runner = self.runner
        if runner.start_utc_s is None:
            return
        conns = None if self.stub is not None else list(self.connections.values())
        opts = _options(self.store, self.schedule, self.rehearsal, self.folder, conns)
        wall_s = time.perf_counter() - self._wall0
        folder, truth = self.folder, self.truth_path

        def record_file() -> dict[str, Any]:
            # Seconds of work for a large team's truth log: off the event loop, which other
            # flights and the API share (the runner has stopped).
            record = flight_record(runner, opts, truth, wall_s)
            record["flight_id"] = self.id
            (folder / "flight.json").write_text(json.dumps(record, indent=1) + "\n")
            return record

        self.record = await asyncio.to_thread(record_file)
        report = folder / "report"
        # The pages now; each figure drawn by the service when it is first asked for.
        await asyncio.to_thread(write_report, self.record, report, figures=False)
        self.report_dir = report

    async def _stop_simulator(self) -> None:
        """The flight's bundled simulator: ours, or one an earlier process started for it
        (its pid kept beside the flight's files)."""
        if self._simulator_stopped:
            return
        self._simulator_stopped = True
        if self.stub is not None:
            await self.stub.stop()
            return
        await stop_kept_simulator(self.folder)

    async def _stop_writers(self) -> None:
        self.runner.on_checkpoint = None
        keeper, self._keeper = self._keeper, None
        if keeper is not None:
            with contextlib.suppress(BaseException):
                await keeper.close()

    async def close(self) -> None:
        """The service stops: a flight on bundled simulator vehicles ends (failed: its
        simulator stops with the service); one on live vehicles stays running in the store,
        and the next service process flies it on (:meth:`resumed`)."""
        if self.simulated and self.runner.state not in ENDED:
            self.runner.fail("the service stopped, and its simulator vehicles with it")
        task = self.task
        if task is not None and not task.done():
            task.cancel()
            with contextlib.suppress(BaseException):
                await task
        if self.upload_task is not None and not self.upload_task.done():
            self.upload_task.cancel()
        await self._stop_writers()
        self.jobs.close()
        await self._stop_simulator()


async def stop_kept_simulator(folder: Path) -> None:
    """Stop the bundled simulator a process started for the flight of ``folder`` (its pid
    kept beside the flight's files), if there is one."""
    with contextlib.suppress(ValueError, OSError):
        await stop_pid(int((folder / STUB_PID_FILE).read_text()))


def _options(
    store: Store,
    entry: PlannedSchedule,
    rehearsal: Rehearsal | None,
    folder: Path,
    connections: Sequence[str] | None,
) -> RehearsalOptions:
    """The flight as the rehearsal's record describes one (``connections`` None: on bundled
    simulator vehicles)."""
    scenario_file = folder / "scenario.yaml"
    if not scenario_file.exists():
        folder.mkdir(parents=True, exist_ok=True)
        body = store.scenario(entry.scenario_id).body
        if isinstance(entry.scenario.terrain, SrtmTerrainSpec):
            # The simulator's terrain from the folder the planner read (the client's folder
            # name is relative to the service's SRTM folder, not to this file).
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

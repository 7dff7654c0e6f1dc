"""``python -m gcs rehearse``: fly a scenario's mission against stub vehicles (or vehicles
already running, with ``--connect``) and report how well the team held its arrival time.

Without ``--connect`` the rehearsal starts ``python -m sitl_stub`` in a child process, one
vehicle per scenario vehicle on the ground at its start (nose along its planned path), flying
over the scenario's terrain (and any ``--hill`` only the simulator has), with the scenario's
airspeed limits, the wind, loss and seed asked for and a truth log of the simulated states.
The coordinator reaches those vehicles over TCP exactly as it would reach any others; the truth
log is read only afterwards, for the true goal crossings and separations.

With ``--connect`` the arrivals come from the vehicles' own telemetry, unless ``--truth`` names
the truth log of the simulator being flown (``python -m sitl_stub --truth FILE``); without, the
stub's truth log is kept at ``--truth`` when it is given.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import math
import sys
import tempfile
import time
import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gcs.coordination.actions import AbortMode
from gcs.coordination.bus import EventBus, Subscription
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind, FlightEvent
from gcs.coordination.member import Member
from gcs.coordination.missionclock import MissionClock
from gcs.coordination.runner import FlightRunner
from gcs.coordination.separationlog import separation_events
from gcs.errors import GcsError
from gcs.mavlink.link import Link
from gcs.mavlink.vehicle import Vehicle
from gcs.rehearsal.flightrecord import FLIGHT_FORMAT
from gcs.rehearsal.truth import TruthSample, closest_approach, min_separation, read_truth
from gcs.service.fleet import Fleet
from gcs.service.stubs import DEFAULT_SPEEDUP, StubProcess, follow_lockstep
from gcs.store.repository import FlightKeeper, Store
from planner.deconflict import separation
from planner.scenario import Scenario
from planner.schedulefile import schedule_json
from planner.terrain import build_terrain

TRUTH_ARRIVAL_WINDOW_S = 30.0
"""The simulator's goal passage is looked for from this long before the one telemetry saw."""


@dataclass(frozen=True)
class Blackout:
    vehicle_id: str
    start_s: float
    """Mission time (s) at which the link goes dark."""
    duration_s: float


@dataclass(frozen=True)
class Hill:
    """Ground only the simulator has (``sitl_stub --hill``): ``height_m`` above the scenario's
    terrain at its top, a cosine bump of ``radius_m``."""

    lat_deg: float
    lon_deg: float
    radius_m: float
    height_m: float


@dataclass(frozen=True)
class Abort:
    vehicle_id: str | None
    """None: every vehicle."""
    at_s: float
    """Mission time (s) of the abort."""
    mode: AbortMode = "rtl"


@dataclass
class RehearsalOptions:
    scenario_path: Path
    scenario: Scenario
    speedup: float = DEFAULT_SPEEDUP
    wind: tuple[float, float] | None = None
    loss: float = 0.0
    seed: int = 0
    connect: Sequence[str] = ()
    truth: Path | None = None
    """With ``connect``: the connected simulator's truth log, for the true arrivals; without,
    where the rehearsal's own stub writes its truth log (kept; by default a temporary file)."""
    json_out: Path | None = None
    report_dir: Path | None = None
    required_arrival_s: float | None = None
    blackouts: Sequence[Blackout] = ()
    aborts: Sequence[Abort] = ()
    """Operator aborts at mission times: the vehicle flies home (or circles) and leaves the team."""
    speed_bias: Mapping[str, float] = field(default_factory=dict)
    """Vehicle id -> fraction: the stub vehicle flies (1 + f) x the true airspeed it should."""
    utc_offsets_s: Mapping[str, float] = field(default_factory=dict)
    """Vehicle id -> seconds: the stub vehicle's UTC is the true UTC plus this."""
    hills: Sequence[Hill] = ()
    """Hills in the stub's terrain that the scenario's lacks (a terrain database error)."""
    threats_from: Path | None = None
    quiet: bool = False
    config: FlightConfig = field(default_factory=FlightConfig)
    bus: EventBus | None = None
    """The flight's event bus (a new one if None): other subscribers may listen in."""
    fleet: Fleet | None = None
    """Take the ``connect`` vehicles from this fleet (its links, kept open; a vehicle already
    in another flight is refused, naming it and that flight) instead of opening links."""
    lockstep: bool = True
    """The rehearsal's own stub waits for the coordinator (:mod:`sitl_stub.lockstep`): a busy
    machine slows the flight instead of delaying the coordinator's answers in it."""
    lockstep_file: Path | None = None
    """With ``connect``: the lock-step file of the simulator flown (``sitl_stub --lockstep
    FILE``): its pace clock is the mission clock's, and it waits for this coordinator."""
    db_url: str | None = None
    """Keep the flight in this database (SQLAlchemy URL) as it happens: scenario, flight and
    its state, every event, every mission uploaded, the checkpoint a restart resumes from."""
    resume: str | None = None
    """Resume this flight of ``db_url`` from its last checkpoint (its process died): the
    vehicles are reached again (``connect``, else the flight's own connections), their
    missions compared with the kept ones, and the closed loop goes on; nothing is launched
    or uploaded again that is already so."""


def stub_homes(runner: FlightRunner) -> list[str]:
    assert runner.schedule is not None
    scenario = runner.scenario
    frame = scenario.frame()
    terrain = build_terrain(scenario)
    out = []
    for vs in runner.schedule.vehicles:
        start = vs.path.start
        ground = float(terrain.elevation_m(np.array([start.east_m]), np.array([start.north_m]))[0])
        lat, lon = frame.to_geodetic(start.east_m, start.north_m)
        home = (
            f"{float(lat):.8f},{float(lon):.8f},{ground:.1f},{math.degrees(start.heading_rad):.2f}"
        )
        if vs.airborne_start:
            # Flying at its start (circling it) when the simulator starts.
            home += f",{scenario.vehicle(vs.vehicle_id).start.alt_m:.1f}"
        out.append(home)
    return out


def stub_args(
    opts: RehearsalOptions, runner: FlightRunner, truth: Path, start_utc_s: float
) -> list[str]:
    scenario = opts.scenario
    cmd = [
        "--speedup",
        repr(opts.speedup),
        "--seed",
        str(opts.seed),
        "--loss",
        repr(opts.loss),
        "--truth",
        str(truth),
        "--start-utc",
        repr(start_utc_s),
        # The stub re-requests a lost mission item after this many WALL seconds. ArduPilot's
        # 1.5 s suits radio links; on loopback at 200x one such wait is 300 s of mission.
        "--mission-timeout",
        "0.05",
        # The terrain to fly over (the homes are given: on the ground, nose along the path).
        "--scenario",
        str(opts.scenario_path),
    ]
    for hill in opts.hills:
        cmd += ["--hill", f"{hill.lat_deg!r},{hill.lon_deg!r},{hill.radius_m!r},{hill.height_m!r}"]
    for home in stub_homes(runner):
        cmd += ["--home", home]
    for v in scenario.vehicles:
        cmd += ["--airspeed", f"{v.speed_min_m_s:g},{v.cruise_m_s:g},{v.speed_max_m_s:g}"]
        cmd += ["--takeoff-climb", f"{v.takeoff_climb_m_s:g}"]
    if opts.wind is not None:
        cmd += ["--wind", f"{opts.wind[0]:g},{opts.wind[1]:g}"]
    ids = [v.id for v in scenario.vehicles]
    for vid, fraction in opts.speed_bias.items():
        cmd += ["--speed-bias", f"{ids.index(vid)},{fraction!r}"]
    for vid, offset in opts.utc_offsets_s.items():
        cmd += ["--utc-offset", f"{ids.index(vid)},{offset!r}"]
    return cmd


class Progress:
    """One status line per vehicle every so often while the mission runs."""

    def __init__(self, runner: FlightRunner, quiet: bool) -> None:
        self.runner = runner
        self.quiet = quiet

    def event(self, ev: FlightEvent) -> None:
        if self.quiet or ev.kind in (EventKind.UPLOAD, EventKind.STATE):
            return
        who = f"{ev.vehicle:>6}" if ev.vehicle else "  team"
        print(f"{ev.t_s:9.1f} s {who} {ev.kind:<8} {ev.reason}", flush=True)

    async def follow(self, events: Subscription) -> None:
        """Print each event of the flight as it comes (a subscriber of the flight's bus)."""
        async for ev in events:
            self.event(ev)

    async def run(self, every_wall_s: float = 5.0) -> None:
        while True:
            await asyncio.sleep(every_wall_s)
            if self.quiet or self.runner.start_utc_s is None:
                continue
            t = self.runner.now_s()
            parts = []
            for m in self.runner.members.values():
                parts.append(_member_line(m))
            print(f"{t:9.1f} s  | " + " | ".join(parts), flush=True)


def _member_line(m: Member) -> str:
    d = m.last_decision
    eta = "" if d is None else f" eta {d.error_s:+.1f}s"
    s = "" if m.s_m is None else f" {m.s_m / 1000:.1f}/{m.track.length_m / 1000:.1f} km"
    lvl = "" if m.level_m_s is None else f" {m.level_m_s:g} m/s"
    return f"{m.vehicle_id} {m.phase}{s}{lvl}{eta}"


async def _watch_threats(runner: FlightRunner, path: Path) -> None:
    """Threats appended to a file (one JSON threat per line) appear when read."""
    from pydantic import TypeAdapter, ValidationError

    from planner.scenario import Threat

    adapter: TypeAdapter[Any] = TypeAdapter(Threat)
    offset = 0
    while True:
        await asyncio.sleep(0.2)
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            continue
        while True:
            nl = data.find(b"\n", offset)
            if nl < 0:
                break
            line = data[offset:nl].strip()
            offset = nl + 1
            if not line or runner.start_utc_s is None:
                continue
            try:
                threat = adapter.validate_json(line)
            except ValidationError as err:
                first = err.errors()[0]
                where = ".".join(str(x) for x in first["loc"])
                print(
                    f"rehearse: {path}: bad threat ({where}: {first['msg']}); ignored",
                    file=sys.stderr,
                )
                continue
            try:
                runner.add_threat(threat)
            except ValueError as err:
                print(f"rehearse: {path}: {err}; ignored", file=sys.stderr)


async def rehearse(opts: RehearsalOptions) -> dict[str, Any]:
    """Run the rehearsal; return the flight record (also written to ``--json``)."""
    wall0 = time.perf_counter()
    clock = MissionClock()
    store = _open_store(opts)
    try:
        if opts.resume is not None:
            flight_id = opts.resume
            runner, conns = _resumed(opts, store, clock)
            opts = dataclasses.replace(opts, connect=conns)
        else:
            flight_id = uuid.uuid4().hex
            runner = FlightRunner(
                opts.scenario,
                clock,
                config=opts.config,
                required_arrival_s=opts.required_arrival_s,
                bus=opts.bus,
            )
        record = await _rehearse(opts, runner, flight_id, store, wall0)
    finally:
        if store is not None:
            store.close()
    if opts.json_out is not None:
        opts.json_out.parent.mkdir(parents=True, exist_ok=True)
        opts.json_out.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return record


async def _rehearse(
    opts: RehearsalOptions, runner: FlightRunner, flight_id: str, store: Store | None, wall0: float
) -> dict[str, Any]:
    clock = runner.clock
    progress = Progress(runner, opts.quiet)
    printed = runner.bus.subscribe(maxsize=100_000)
    printer = asyncio.create_task(progress.follow(printed))
    if not runner.resumed:
        try:
            await runner.prepare()
        except BaseException:
            printed.close()
            await printer
            raise
        if not opts.quiet:
            print(
                f"rehearse: planned {len(opts.scenario.vehicles)} vehicles in "
                f"{runner.plan_wall_s:.1f} s; team arrival {runner.fmt_ref()}",
                flush=True,
            )
    truth_path: Path | None = None
    stub: StubProcess | None = None
    pacer: asyncio.Task[None] | None = None
    tmp = tempfile.TemporaryDirectory(prefix="tcgcs-rehearse-")
    try:
        mission_start: float | None = None
        stub_start = 0.0
        if opts.connect:
            if len(opts.connect) != len(opts.scenario.vehicles):
                raise GcsError(
                    f"--connect: {len(opts.connect)} connection(s) for "
                    f"{len(opts.scenario.vehicles)} scenario vehicles"
                )
            conns = list(opts.connect)
            sysids: list[int | None] = [None] * len(conns)
            truth_path = opts.truth
            if opts.lockstep_file is not None:
                pacer = follow_lockstep(opts.lockstep_file, clock, runner.unwatched)
        else:
            truth_path = opts.truth or Path(tmp.name) / "truth.jsonl"
            stub_start = time.time()
            args = stub_args(opts, runner, truth_path, stub_start)
            pace_path = Path(tmp.name) / "pace"
            if opts.lockstep:
                args += ["--lockstep", str(pace_path)]
            stub = await StubProcess.start(
                len(opts.scenario.vehicles), args, control=bool(opts.blackouts)
            )
            if opts.lockstep:
                pacer = follow_lockstep(pace_path, clock, runner.unwatched)
            conns = stub.connections
            sysids = [i + 1 for i in range(len(conns))]
        async with contextlib.AsyncExitStack() as stack:
            vehicles: dict[str, Vehicle] = {}
            if opts.fleet is not None and opts.connect:
                held = await opts.fleet.claim(conns, flight_id, sysids)
                stack.callback(opts.fleet.release, flight_id)
                vehicles = {
                    v.id: h.vehicle for v, h in zip(opts.scenario.vehicles, held, strict=True)
                }
            else:
                for v, conn, sysid in zip(opts.scenario.vehicles, conns, sysids, strict=True):
                    link = await stack.enter_async_context(Link.open(conn))
                    peer = await link.wait_vehicle(sysid, timeout_s=15.0)
                    vehicles[v.id] = Vehicle(link, peer.system_id, peer.component_id)
            runner.bind(vehicles)
            kept = _Kept.start(
                opts, runner, dict(zip(vehicles, conns, strict=True)), flight_id, store
            )
            stack.push_async_callback(kept.finish, runner)
            async with asyncio.timeout(15.0):
                while not clock.synced:
                    await asyncio.sleep(0.02)
            if runner.resumed:
                await runner.reconcile()
                mission_start = runner.start_utc_s
            else:
                await runner.upload_all()
                mission_start = clock.now_utc_s() + clock.start_lead_s()
                kept.state("running", start_utc_s=mission_start, team_time_s=runner.team_ref_s)
            assert mission_start is not None
            if stub is not None and opts.blackouts:
                _send_blackouts(stub, opts, stub_start, mission_start)
            tasks = [asyncio.create_task(progress.run())]
            tasks += [asyncio.create_task(_abort_at(runner, a, mission_start)) for a in opts.aborts]
            if opts.threats_from is not None:
                tasks.append(asyncio.create_task(_watch_threats(runner, opts.threats_from)))
            try:
                await runner.run(mission_start)
            finally:
                for task in tasks:
                    task.cancel()
                await runner.close()
        if pacer is not None:
            pacer.cancel()
            pacer = None
        truth = None
        if stub is not None:
            await stub.stop()
            stub = None
        elif truth_path is not None:
            truth = await _await_truth(truth_path, runner)
        record = flight_record(runner, opts, truth_path, time.perf_counter() - wall0, truth)
        record["flight_id"] = flight_id
    finally:
        printed.close()  # the printer drains what is queued, then ends
        await printer
        if pacer is not None:
            pacer.cancel()
        if stub is not None:
            await stub.stop()
        tmp.cleanup()
    return record


@dataclass
class _Kept:
    """The flight in the store (``--db``), or nothing: its events, states and checkpoints
    as they happen."""

    store: Store | None = None
    flight_id: str | None = None
    keeper: FlightKeeper | None = None

    @classmethod
    def start(
        cls,
        opts: RehearsalOptions,
        runner: FlightRunner,
        conns: Mapping[str, str],
        flight_id: str,
        store: Store | None,
    ) -> _Kept:
        if store is None:
            return cls()
        if not runner.resumed:
            suffix = opts.scenario_path.suffix.lower()
            scenario_id = store.save_scenario(
                opts.scenario_path.read_text(encoding="utf-8"),
                name=opts.scenario.name,
                media_type="application/json" if suffix == ".json" else "application/yaml",
            )
            store.create_flight(scenario_id, conns, flight_id=flight_id)
            if runner.schedule is not None and runner.world is not None:
                sep = separation(runner.schedule.vehicles, runner.scenario.separation_m)
                doc = schedule_json(
                    runner.schedule,
                    sep,
                    runner.world.terrain,
                    scenario_file=str(opts.scenario_path),
                )
                store.update_flight(flight_id, resume={"schedule": doc})
        keeper = FlightKeeper(store, flight_id, runner.bus)
        runner.on_checkpoint = keeper.checkpoints.offer
        if not opts.quiet:
            print(f"rehearse: flight {flight_id} kept in {store.engine.url!r}", flush=True)
        return cls(store, flight_id, keeper)

    def state(self, state: str, **fields: Any) -> None:
        if self.store is not None and self.flight_id is not None:
            self.store.update_flight(self.flight_id, state=state, **fields)

    async def finish(self, runner: FlightRunner) -> None:
        """The last events and checkpoint written (the final state is the last event's)."""
        runner.on_checkpoint = None
        if self.keeper is not None:
            await self.keeper.close()


def _open_store(opts: RehearsalOptions) -> Store | None:
    return None if opts.db_url is None else Store.open(opts.db_url)


def _resumed(
    opts: RehearsalOptions, store: Store | None, clock: MissionClock
) -> tuple[FlightRunner, list[str]]:
    """The runner of ``opts.resume``'s flight from its last checkpoint, and its vehicles'
    connections (``--connect``, else the ones the flight was flown on).

    Raises
    ------
    GcsError
        No database, no such flight, one that has ended or never started, or a scenario
        file that is not the flight's.
    """
    fid = opts.resume
    assert fid is not None
    if store is None:
        raise GcsError("--resume needs --db: the database the flight is kept in")
    row = store.flight(fid)
    if row.state in ("completed", "aborted", "failed"):
        raise GcsError(f"--resume: flight {fid} has ended ({row.state}); nothing to resume")
    blob = store.checkpoint(fid)
    if blob is None:
        raise GcsError(f"--resume: flight {fid} has no checkpoint (it never started)")
    if store.scenario(row.scenario_id).body != opts.scenario_path.read_text(encoding="utf-8"):
        raise GcsError(
            f"--resume: {opts.scenario_path} is not the scenario flight {fid} was planned on"
        )
    events = store.events_to_resume(fid)
    bus = opts.bus or EventBus(first_seq=(events[-1].seq if events else 0) + 1)
    runner = FlightRunner.resume(blob, clock, bus=bus, events=events)
    conns = list(opts.connect)
    if not conns:
        conns = [str(row.vehicles[v.id][1]) for v in runner.scenario.vehicles]
    return runner, conns


async def _abort_at(runner: FlightRunner, abort: Abort, start_utc_s: float) -> None:
    await runner.clock.sleep_until(start_utc_s + abort.at_s)
    await runner.abort(abort.vehicle_id, mode=abort.mode)


async def _await_truth(
    path: Path, runner: FlightRunner, timeout_s: float = 5.0
) -> dict[int, list[TruthSample]] | None:
    """Wait until a running simulator's truth log has reached past every arrival (it is
    flushed about once a wall second); that log as read then, or None when it did not."""
    need = max(
        (m.arrival_s for m in runner.members.values() if m.arrival_s is not None), default=None
    )
    if need is None or runner.start_utc_s is None:
        return None
    need += runner.start_utc_s
    loop = asyncio.get_running_loop()
    until = loop.time() + timeout_s
    while loop.time() < until:
        if path.exists():
            truth = read_truth(path)
            if truth and all(s and s[-1].utc_s > need for s in truth.values()):
                return truth
        await asyncio.sleep(0.25)
    return None


def _send_blackouts(
    stub: StubProcess, opts: RehearsalOptions, stub_start: float, start: float
) -> None:
    """Blackouts in mission time, sent to the stub in its simulated time."""
    ids = [v.id for v in opts.scenario.vehicles]
    for b in opts.blackouts:
        sim_s = start - stub_start + b.start_s
        stub.control(f"blackout {ids.index(b.vehicle_id)} {sim_s:.3f} {b.duration_s:g}")


def flight_record(
    runner: FlightRunner,
    opts: RehearsalOptions,
    truth_path: Path | None,
    wall_s: float,
    truth: dict[int, list[TruthSample]] | None = None,
) -> dict[str, Any]:
    """The flight as data: arrivals (true when the simulator is ours), separations, events.
    ``truth``: the truth log already read from ``truth_path``, if it was."""
    assert runner.start_utc_s is not None
    start = runner.start_utc_s
    frame = runner.scenario.frame()
    if truth is None:
        truth = {}
        if truth_path is not None and truth_path.exists():
            truth = read_truth(truth_path)
    vehicles: list[dict[str, Any]] = []
    until: dict[int, float] = {}
    tracks: dict[int, list[TruthSample]] = {}
    for m in runner.members.values():
        sysid = runner.vehicles[m.vehicle_id].system_id
        target_utc = start + m.target_s
        telemetry_arrival = None if m.arrival_s is None else start + m.arrival_s
        launched = None if m.launched_s is None else start + m.launched_s
        arrival = telemetry_arrival
        track = m.track_log
        samples = truth.get(sysid)
        source = "simulator" if samples else "telemetry"
        if samples:
            glat, glon = frame.to_geodetic(*m.goal_en_m)
            # The passage the coordinator saw (within half a minute of it), not an earlier one
            # of a route that comes near its own goal on the way round.
            after = launched
            if telemetry_arrival is not None and launched is not None:
                after = max(launched, telemetry_arrival - TRUTH_ARRIVAL_WINDOW_S)
            ca = closest_approach(
                samples, float(glat), float(glon), runner.config.arrival_radius_m, after_utc_s=after
            )
            arrival = None if ca is None else ca[0]
            every = samples[:: max(1, int(round(2.0 / _period(samples))))]
            east, north = frame.to_local(
                np.array([smp.lat_deg for smp in every]), np.array([smp.lon_deg for smp in every])
            )
            track = [
                [
                    round(smp.utc_s, 3),
                    round(float(e), 1),
                    round(float(n), 1),
                    round(smp.alt_m, 1),
                    round(smp.airspeed_m_s, 2),
                    round(smp.groundspeed_m_s, 2),
                ]
                for smp, e, n in zip(every, np.atleast_1d(east), np.atleast_1d(north), strict=True)
            ]
            tracks[sysid] = samples
        else:
            tracks[sysid] = [_sample(frame, row) for row in m.track_log]
        if arrival is not None:
            until[sysid] = arrival
        landed = None if m.landed_s is None else start + m.landed_s
        if landed is not None:
            until[sysid] = landed  # the glide counts too
        vs = m.schedule
        vehicles.append(
            {
                "id": m.vehicle_id,
                "state": m.phase,
                "system_id": sysid,
                "speed_min_m_s": m.limits.airspeed_min_m_s,
                "speed_max_m_s": m.limits.airspeed_max_m_s,
                "target_arrival_utc_s": round(target_utc, 3),
                "planned_arrival_s": round(m.planned_s, 3),
                "arrival_utc_s": None if arrival is None else round(arrival, 3),
                "error_s": None if arrival is None else round(arrival - target_utc, 3),
                "arrival_source": source,
                "telemetry_arrival_utc_s": None
                if telemetry_arrival is None
                else round(telemetry_arrival, 3),
                "takeoff_utc_s": None if launched is None else round(launched, 3),
                "landed_utc_s": None if landed is None else round(landed, 3),
                "lost": None
                if m.lost is None
                else {
                    "cause": m.lost.cause,
                    "utc_s": round(start + m.lost.t_s, 3),
                    "t_s": round(m.lost.t_s, 3),
                    "why": m.lost.why,
                },
                "planned_paths": [
                    {"label": p["label"], "utc_s": round(start + p["t_s"], 3), "en_m": p["en_m"]}
                    for p in m.planned_paths
                ],
                "loiters": [{**lo, "utc_s": round(start + lo["t_s"], 3)} for lo in m.loiter_log],
                "track": track,
                "commanded": m.commanded,
                "planned_speeds": [
                    [
                        round(start + leg.t_start_s, 3),
                        round(start + leg.t_end_s, 3),
                        leg.speed_m_s,
                        "leg",
                    ]
                    for leg in vs.legs
                ]
                + [
                    [
                        round(start + lo.t_start_s, 3),
                        round(start + lo.t_end_s, 3),
                        lo.speed_m_s,
                        "loiter",
                    ]
                    for lo in vs.loiters
                ],
            }
        )
    sep = min_separation(tracks, until_utc_s=until)
    ids = {v.system_id: vid for vid, v in runner.vehicles.items()}
    by_vehicle = {ids[k]: v for k, v in tracks.items() if k in ids}
    zones = zone_clearances(runner, by_vehicle)
    ref = runner.team_ref_s
    planned_ref = None if runner.team is None else runner.team.planned_ref_s
    return {
        "format": FLIGHT_FORMAT,
        "scenario_file": str(opts.scenario_path),
        "state": runner.state.value,
        "state_reason": runner.state_reason,
        "start_utc_s": round(start, 3),
        "required_arrival_utc_s": None if ref is None else round(start + ref, 3),
        "required_arrival_s": None if ref is None else round(ref, 3),
        "planned_arrival_s": None if planned_ref is None else round(planned_ref, 3),
        "separation_m": runner.scenario.separation_m,
        "min_separation_m": None if sep is None else round(sep[0], 1),
        "min_separation_pair": None if sep is None else [ids.get(sep[1]), ids.get(sep[2])],
        "min_separation_utc_s": None if sep is None else round(sep[3], 3),
        "separation_events": separation_events(runner.events, by_vehicle, start),
        "zone_clearances": zones,
        "zone_entries": [z for z in zones if z["inside_samples"] > 0],
        "alarms": [
            {"vehicle": ev.vehicle, "t_s": round(ev.t_s, 3), "reason": ev.reason}
            for ev in runner.events
            if ev.kind is EventKind.ALARM
        ],
        "wall_s": round(wall_s, 2),
        "speedup": None if opts.connect else opts.speedup,
        "wind": None
        if opts.wind is None
        else {"speed_m_s": opts.wind[0], "from_deg": opts.wind[1]},
        "loss": opts.loss,
        "seed": opts.seed,
        "arrival_source": _team_source(vehicles),
        "vehicles": vehicles,
        "events": [ev.to_json(start) for ev in runner.events],
        "adjustments": [ev.to_json(start) for ev in runner.adjustments],
        "threats_appeared": [
            {"id": t["id"], "utc_s": round(t["utc_s"], 3)} for t in runner.threats_appeared
        ],
        # The world as flown, for the report: the scenario (with any requested arrival) and
        # the threats the operator added in flight.
        "scenario": runner.scenario.model_dump(mode="json", exclude_none=True),
        "operator_threats": [
            t.model_dump(mode="json", exclude_none=True) for t in runner.operator_threats
        ],
        # What an operator's screen showed last (the runner's snapshot at the end).
        "snapshot": runner.snapshot(),
    }


def zone_clearances(
    runner: FlightRunner, tracks: Mapping[str, Sequence[TruthSample]]
) -> list[dict[str, Any]]:
    """Per vehicle and forbidden zone (the operator's included), from the flown track alone
    (the simulator's truth when it is ours): the closest it came to the zone below its
    ceiling once the zone was there (m, negative inside), and how many samples were inside."""
    assert runner.start_utc_s is not None and runner.team is not None
    frame = runner.scenario.frame()
    out: list[dict[str, Any]] = []
    zones = [z for z in runner.team.zones() if z.forbidden]
    for vid, samples in tracks.items():
        if not samples:
            continue
        utc = np.array([smp.utc_s for smp in samples])
        alt = np.array([smp.alt_m for smp in samples])
        east, north = frame.to_local(
            np.array([smp.lat_deg for smp in samples]), np.array([smp.lon_deg for smp in samples])
        )
        for zone in zones:
            appears = zone.appears_at_s
            since = -math.inf if appears is None else runner.start_utc_s + appears
            keep = (utc >= since) & (alt < zone.ceiling_m)
            if not keep.any():
                continue
            d = zone.distance_m(np.atleast_1d(east)[keep], np.atleast_1d(north)[keep])
            inside = d < 0.0
            out.append(
                {
                    "vehicle": vid,
                    "zone": zone.id,
                    "closest_m": round(float(d.min()), 1),
                    "inside_samples": int(inside.sum()),
                    "first_inside_utc_s": round(float(utc[keep][inside][0]), 3)
                    if inside.any()
                    else None,
                    "inside_s": round(float(inside.sum()) * _period(samples), 1),
                }
            )
    return out


def _team_source(vehicles: Sequence[Mapping[str, Any]]) -> str:
    sources = {v["arrival_source"] for v in vehicles}
    return sources.pop() if len(sources) == 1 else "mixed"


def _sample(frame: Any, row: Sequence[float]) -> TruthSample:
    lat, lon = frame.to_geodetic(row[1], row[2])
    return TruthSample(row[0], float(lat), float(lon), row[3], row[4], row[5], True)


def _period(samples: Sequence[TruthSample]) -> float:
    if len(samples) < 2:
        return 1.0
    return max((samples[-1].utc_s - samples[0].utc_s) / (len(samples) - 1), 1e-3)


def passed(record: Mapping[str, Any], tolerance_s: float) -> bool:
    """Every vehicle not aborted arrived within tolerance, the separation held and no vehicle
    entered a forbidden zone (a lost vehicle never arrived)."""
    ok = all(
        v["error_s"] is not None and abs(v["error_s"]) <= tolerance_s
        for v in record["vehicles"]
        if v.get("state") != "aborted"
    )
    sep = record.get("min_separation_m")
    entered = record.get("zone_entries") or []
    return ok and not entered and (sep is None or sep >= record["separation_m"])


__all__ = [
    "Abort",
    "Blackout",
    "Hill",
    "RehearsalOptions",
    "flight_record",
    "passed",
    "rehearse",
    "zone_clearances",
]

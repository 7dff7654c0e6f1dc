"""The arrival-time coordinator: one mission in execution, closed loop on live telemetry.

Plan -> schedule -> compile -> upload -> scheduled launches (the takeoff strategy) -> closed-loop
speed control (eqs. 6-7 on the remaining route, wind from telemetry, quantised airspeed) ->
loiter insertion when a vehicle would be early even at its minimum speed (eqs. 8-9, by
replacing the rest of its mission ahead of the leg it flies) -> a later team arrival when one
would be late even at its maximum speed. Pop-up threats re-plan the affected vehicles from a
waypoint ahead of them and re-time the team.

Mission time is the vehicles' UTC (SYSTEM_TIME) through
:class:`~gcs.coordination.missionclock.MissionClock`; nothing here reads the wall clock or
knows whether the vehicles are simulated, and every wait and timeout scales with the clock's
rate, so a rehearsal at 200x runs the same logic as a live flight. Planning runs in a worker
thread so the links keep being served."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from gcs.coordination.arrival import (
    ArrivalController,
    Decision,
    LoiterSpec,
    RouteTrack,
    SpeedLimits,
    Wind,
)
from gcs.coordination.bus import EventBus
from gcs.coordination.events import EventKind, FlightEvent
from gcs.coordination.missionclock import MissionClock
from gcs.coordination.speedbias import SpeedBiasEstimator
from gcs.coordination.tracks import TruthSample, closest_approach
from gcs.errors import GcsError
from gcs.mavlink.vehicle import Vehicle
from planner.atmosphere import eas2tas
from planner.errors import InfeasibleError, PlannerError
from planner.mission import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_LOITER_TURNS,
    MAV_CMD_NAV_WAYPOINT,
)
from planner.plan import Method, World, build_world, plan
from planner.popup import apply_popup, popup_zones
from planner.retime import build_schedule, retime_vehicle
from planner.scenario import Appearance, Scenario, Threat
from planner.schedule import Adjustment, Anchor, Schedule, VehicleSchedule
from planner.schedulefile import PathMission, path_mission, splice_mission
from planner.threats import ThreatZone, active, build_threats
from planner.timing import SpeedLimits as PlannerLimits
from planner.timing import takeoff_time_s

log = logging.getLogger(__name__)

Phase = Literal["ground", "takeoff", "route", "arrived", "aborted"]
AbortMode = Literal["rtl", "loiter"]
_DONE: frozenset[str] = frozenset({"arrived", "aborted"})
FIRST_ROUTE_SEQ = 2
"""Item 0 is home, item 1 the takeoff; the route starts at item 2."""

TELEMETRY_HZ: dict[str, float] = {
    "GLOBAL_POSITION_INT": 2.0,  # fixes along the route; the goal crossing
    "VFR_HUD": 1.0,  # airspeed and groundspeed
    "WIND": 0.5,
    "SYSTEM_TIME": 1.0,  # the mission clock
    "MISSION_CURRENT": 0.5,
    "SYS_STATUS": 0.2,
    "GPS_RAW_INT": 0.2,
    "ATTITUDE": 0.0,  # not used: off
    "NAV_CONTROLLER_OUTPUT": 0.0,
}
"""What the coordinator asks each vehicle to send (Hz of the VEHICLE's time: a simulator at
200x sends 200 times as many per wall second), by MAV_CMD_SET_MESSAGE_INTERVAL; 0 turns a
message off on our link. With the heartbeat that is 6.4 messages per vehicle second: 1284 per
wall second from one stub vehicle at 200x, against 3800 with every stream at 2 Hz (measured),
which MAVProxy could not route fast enough for mission transfers to complete."""


CLOCK_OFFSET_NOTE_S = 0.5
"""A vehicle's UTC this far from the team's (or from what was said last) is reported."""


class InfeasibleRequest(GcsError):
    """The required arrival cannot be met; refused before launch."""


@dataclass(frozen=True)
class CoordinatorConfig:
    """Knobs of the closed loop (mission seconds unless named otherwise)."""

    tolerance_s: float = 0.5
    """An ETA within this of the target needs no loiter and no new team time."""
    loiter_margin_m_s: float = 2.0
    """Loiter turns leave the speed this far above the minimum (room to slow down after)."""
    late_margin_s: float = 2.0
    """A late vehicle moves the team time to its earliest arrival plus this."""
    min_lead_s: float = 60.0
    """Mission changes start at a waypoint at least this far ahead (more at high clock rates:
    the planning and upload wall time scaled by the rate)."""
    loiter_min_time_left_s: float = 300.0
    """No loiter is inserted closer than this to the arrival (the speed trims the rest)."""
    speed_reserve_m_s: float = 1.0
    """Farther than ``loiter_min_time_left_s`` from the arrival, a vehicle whose required
    airspeed is less than this above its minimum gets loiter turns as if it were early: its
    last minutes keep room to slow down (a pop-up re-plan, timed in still air, can leave it
    at the minimum in wind)."""
    arrival_radius_m: float = 1000.0
    """Goal passages are looked for within this distance of the goal."""
    link_silence_s: float = 3.0
    """A vehicle silent this long (mission s) is reported; its mission keeps it flying."""
    link_silence_wall_s: float = 0.025
    """...and at least this long in wall time: at 200x, 3 s of mission is 15 ms, less than a
    busy two-core machine's scheduling jitter (25 ms wall is 5 s of mission at 200x)."""
    runout_m: float = 300.0
    """A last waypoint this far past the goal, so the aircraft flies through the goal."""
    waypoint_spacing_m: float = 5000.0
    """Long legs are split into waypoints this far apart: a mission change splices in at a
    waypoint ahead, and the nearest one should not be half an hour away."""
    off_route_m: float = 500.0
    """A vehicle this far from its route is still joining it (after the climb-out, which
    heads wherever the aircraft was pointing): its ETA along the route runs late until it is
    on it, so it does not move the team time meanwhile (it is commanded its top speed)."""
    final_m: float = 150.0
    """No speed decisions closer than this to the goal (the autopilot could not act)."""
    method: Method = "aco"
    seed: int = 0
    command_retries: int = 8
    overrun_s: float = 900.0
    """Give up this long after the latest target if a vehicle has not arrived."""


@dataclass
class Member:
    """One vehicle of the team in flight."""

    vehicle_id: str
    vehicle: Vehicle
    limits: SpeedLimits
    offset_s: float
    schedule: VehicleSchedule
    mission: PathMission
    track: RouteTrack
    controller: ArrivalController
    target_s: float
    takeoff_s: float
    phase: Phase = "ground"
    launched_utc_s: float | None = None
    level_m_s: float | None = None
    s_m: float | None = None
    cross_track_m: float = 0.0
    last_fix_wall_s: float = 0.0
    """Local monotonic time the last fix was taken in (link gaps in wall time)."""
    joining: bool = False
    """Off its route by more than ``off_route_m`` when last late (said once per episode)."""
    last_seq: int | None = None
    next_decision_s: float = -math.inf
    busy_command: bool = False
    busy_mission: bool = False
    last_loiter_s: float = -math.inf
    arrival_utc_s: float | None = None
    near_goal: list[TruthSample] = field(default_factory=list)
    goal_en_m: tuple[float, float] = (0.0, 0.0)
    last_fix_utc_s: float | None = None
    last_decision: Decision | None = None
    track_log: list[list[float]] = field(default_factory=list)
    commanded: list[list[Any]] = field(default_factory=list)
    planned_paths: list[dict[str, Any]] = field(default_factory=list)
    loiter_log: list[dict[str, Any]] = field(default_factory=list)
    clock_offset_said_s: float = 0.0
    """The offset of its UTC from the team's last reported (s)."""
    no_utc_said: bool = False
    bias: SpeedBiasEstimator = field(default_factory=SpeedBiasEstimator)
    """What the aircraft really flies for a commanded airspeed, learnt from its fixes."""

    def tas_per_eas(self, s_m: float) -> float:
        """True airspeed flown per unit commanded from ``s_m`` on: the route's atmosphere
        (the autopilot commands equivalent airspeed) times the scale learnt in flight."""
        return self.schedule.tas_per_eas(s_m) * self.bias.scale


def route_track(vs: VehicleSchedule) -> RouteTrack:
    loiters = [
        LoiterSpec(
            lo.s_m,
            lo.centre_east_m,
            lo.centre_north_m,
            lo.radius_m,
            lo.turns,
            lo.clockwise,
            lo.detour_m,
        )
        for lo in sorted(vs.loiters, key=lambda x: x.s_m)
    ]
    return RouteTrack(vs.path, loiters)


def _path_en(vs: VehicleSchedule, step_m: float = 500.0) -> list[list[float]]:
    n = max(2, int(vs.path.length_m / step_m) + 1)
    out = []
    for s in np.linspace(0.0, vs.path.length_m, n):
        p = vs.path.pose_at(float(s))
        out.append([round(p.east_m, 1), round(p.north_m, 1)])
    return out


class Coordinator:
    """Flies a scenario's team to its required arrival time.

    Use: :meth:`prepare` (plan, schedule, refuse an infeasible request), :meth:`bind` (each
    scenario vehicle's :class:`~gcs.mavlink.vehicle.Vehicle`), :meth:`upload_all`, :meth:`run`.
    """

    def __init__(
        self,
        scenario: Scenario,
        clock: MissionClock,
        *,
        config: CoordinatorConfig | None = None,
        on_event: Callable[[FlightEvent], None] | None = None,
        bus: EventBus | None = None,
        required_arrival_s: float | None = None,
    ) -> None:
        self.scenario = scenario
        self.vehicles: dict[str, Vehicle] = {}
        self.clock = clock
        self.config = config or CoordinatorConfig()
        self.on_event = on_event
        self.requested_arrival_s = required_arrival_s
        self.rng = np.random.default_rng(self.config.seed)
        self.frame = scenario.frame()
        self.bus = bus if bus is not None else EventBus()
        """Every event is published here (numbered); subscribers cannot slow the loop."""
        self.events: list[FlightEvent] = []
        self.adjustments: list[FlightEvent] = []
        self.members: dict[str, Member] = {}
        self.schedule: Schedule | None = None
        self.world: World | None = None
        self.start_utc_s: float | None = None
        self.team_ref_s: float | None = None
        self.plan_wall_s = 1.0
        self.threats_appeared: list[dict[str, Any]] = []
        self._extra_threats: list[Threat] = []
        self._detach: list[Callable[[], None]] = []
        self._tasks: set[asyncio.Task[None]] = set()
        self._popups_done: set[str] = set()

    # -- time ------------------------------------------------------------------------------

    def bind(self, vehicles: Mapping[str, Vehicle]) -> None:
        """The vehicle flying each scenario vehicle: asks it for the telemetry the loop uses
        (:data:`TELEMETRY_HZ`) and feeds its SYSTEM_TIME to the clock."""
        missing = [v.id for v in self.scenario.vehicles if v.id not in vehicles]
        if missing:
            raise GcsError(f"no link for vehicle(s) {', '.join(missing)}")
        self.vehicles = {v.id: vehicles[v.id] for v in self.scenario.vehicles}
        for vehicle in self.vehicles.values():
            # The link keeps these and asks again after a silence (the vehicle may reboot).
            vehicle.link.message_rates_hz.update(TELEMETRY_HZ)
            vehicle.link.request_streams(vehicle.system_id)
        self.attach_clock()

    def attach_clock(self) -> None:
        """Feed every vehicle's SYSTEM_TIME into the mission clock, each dated back by half the
        least round trip seen on its link (TIMESYNC): a vehicle behind a router is heard later
        than one reached directly, and at 200x 5 ms of it would read as a clock 1 s behind."""
        for vehicle in self.vehicles.values():
            sysid = vehicle.system_id
            link = vehicle.link
            least_rtt_s = [math.inf]

            def on_msg(
                msg: Any,
                rx_s: float,
                sysid: int = sysid,
                link: Any = link,
                least: Any = least_rtt_s,
            ) -> None:
                if msg.get_type() != "SYSTEM_TIME" or msg.get_srcSystem() != sysid:
                    return
                rtt = link.counters.rtt_s
                if rtt is not None and rtt < least[0]:
                    least[0] = rtt
                sent_s = rx_s - (0.0 if math.isinf(least[0]) else 0.5 * least[0])
                if msg.time_unix_usec:
                    self.clock.observe(
                        sysid, msg.time_unix_usec * 1e-6, msg.time_boot_ms * 1e-3, sent_s
                    )
                else:
                    self.clock.observe_no_utc(sysid, msg.time_boot_ms * 1e-3, sent_s)

            self._detach.append(link.add_listener(on_msg))

    def now_s(self) -> float:
        """Mission time now (s since the mission start)."""
        assert self.start_utc_s is not None
        return self.clock.now_utc_s() - self.start_utc_s

    def _wall_timeout_s(self, vehicle: Vehicle) -> float:
        """A reply timeout from the link's round trip, not tuned to any vehicle."""
        rtt = vehicle.link.counters.rtt_s
        return float(min(1.5, max(0.05, 5.0 * rtt))) if rtt else 0.25

    def _emit(
        self,
        kind: EventKind | str,
        reason: str,
        vehicle: str | None = None,
        strategy: str | None = None,
        value: float | None = None,
        t_s: float | None = None,
        payload: Mapping[str, Any] | None = None,
    ) -> FlightEvent:
        """Publish one event (a kind that is not an :class:`EventKind` is a ValueError)."""
        utc = self.clock.now_utc_s() if self.clock.synced else math.nan
        t = t_s if t_s is not None else (utc - self.start_utc_s if self.start_utc_s else 0.0)
        ev = self.bus.publish(
            FlightEvent(utc, t, vehicle, EventKind(kind), reason, strategy, value, 0, payload or {})
        )
        self.events.append(ev)
        if strategy is not None:
            self.adjustments.append(ev)
        if self.on_event is not None:
            self.on_event(ev)
        return ev

    # -- preparation -----------------------------------------------------------------------

    async def prepare(self) -> Schedule:
        """Plan, schedule and check the request; refuse an infeasible one before launch.

        Raises
        ------
        InfeasibleRequest
            The required arrival cannot be met: names the earliest feasible time and the
            vehicle that forces it.
        """
        t0 = time.perf_counter()
        schedule = await asyncio.to_thread(self._plan)
        self.plan_wall_s = time.perf_counter() - t0
        self.schedule = schedule
        self.team_ref_s = schedule.required_arrival_s
        for a in schedule.adjustments:
            self._emit("plan", a.reason, a.vehicle, a.strategy, a.value, t_s=a.time_s)
        return schedule

    def _plan(self) -> Schedule:
        scenario = self.scenario
        if self.requested_arrival_s is not None:
            arrival = scenario.arrival
            if arrival.kind == "simultaneous":
                arrival = arrival.model_copy(update={"required_s": self.requested_arrival_s})
            elif arrival.kind == "spaced":
                arrival = arrival.model_copy(update={"first_s": self.requested_arrival_s})
            else:
                raise InfeasibleRequest("a required arrival time needs a team arrival kind")
            scenario = scenario.model_copy(update={"arrival": arrival})
            self.scenario = scenario
        world = build_world(scenario)
        self.world = world
        try:
            p = plan(scenario, method=self.config.method, rng=self.rng, world=world)
            schedule = build_schedule(scenario, p, world=world)
        except InfeasibleError as err:
            raise InfeasibleRequest(f"refused before launch: {err}") from None
        requested = schedule.requested_arrival_s
        ref = schedule.required_arrival_s
        if requested is not None and ref is not None and abs(ref - requested) > 1e-3:
            raise InfeasibleRequest(
                f"refused before launch: required arrival {requested:.1f} s cannot be met; "
                f"earliest feasible {ref:.1f} s ({schedule.arrival_reason})"
            )
        return schedule

    async def upload_all(self) -> None:
        """Compile each vehicle's mission and upload it (verified by download)."""
        assert self.schedule is not None and self.world is not None
        schedule = self.schedule
        for vs in schedule.vehicles:
            v = self.scenario.vehicle(vs.vehicle_id)
            pm = self._path_mission(vs)
            goal = vs.path.end
            step = schedule.step_m_s
            limits = SpeedLimits(v.speed_min_m_s, v.speed_max_m_s, step)
            offset = schedule.offsets_s.get(v.id, 0.0)
            target = (self.team_ref_s or vs.arrival_s) + offset
            m = Member(
                v.id,
                self.vehicles[v.id],
                limits,
                offset,
                vs,
                pm,
                route_track(vs),
                ArrivalController(limits, tolerance_s=self.config.tolerance_s),
                target if self.team_ref_s is not None else vs.arrival_s,
                vs.takeoff_s,
                goal_en_m=(goal.east_m, goal.north_m),
            )
            m.planned_paths.append({"label": "initial", "t_s": 0.0, "en_m": _path_en(vs)})
            self.members[v.id] = m
        await asyncio.gather(
            *(self._upload(m, m.mission, "initial mission") for m in self.members.values())
        )

    async def _upload(self, m: Member, pm: PathMission, what: str) -> None:
        """Upload with the adaptive retry policy (:mod:`gcs.mavlink.retry`), restarting the whole
        transfer (a vehicle may drop a stalled one) twice.

        In flight the new mission must be on board before the vehicle reaches the splice
        point, ``_lead_s()`` mission seconds ahead: the attempts together get half of that
        lead in wall seconds, so a lossy link either delivers in time or fails early enough
        for the fallback (the vehicle keeps flying the mission it has).
        """
        v = m.vehicle
        in_flight = m.phase != "ground"
        loop = asyncio.get_running_loop()
        end_s = loop.time() + 0.5 * self._lead_s() / self.clock.rate if in_flight else None
        for attempt in range(3):
            within_s = None if end_s is None else end_s - loop.time()
            try:
                await v.upload_mission(list(pm.items), verify=not in_flight, within_s=within_s)
                break
            except GcsError as err:
                if attempt == 2 or (end_s is not None and loop.time() > end_s - 0.05):
                    raise
                log.info("%s: %s upload failed (%s); starting it again", m.vehicle_id, what, err)
        self._emit(
            "upload",
            f"{what}: {len(pm.items)} items",
            m.vehicle_id,
            payload={"what": what, "items": [dataclasses.asdict(it) for it in pm.items]},
        )

    # -- the flight ------------------------------------------------------------------------

    @property
    def operator_threats(self) -> tuple[Threat, ...]:
        """The threats added in flight (:meth:`add_threat`), with the time they appear."""
        return tuple(self._extra_threats)

    def add_threat(self, threat: Threat, at_s: float | None = None) -> None:
        """A threat for the mission: re-planned around when it appears.

        It appears at mission time ``at_s`` if given, else when its own ``appears`` says (a
        mission time, or a delay after a vehicle's takeoff), else now; a time already past is
        now. Before the mission starts it is queued ("now" is the start). Until it appears no
        plan avoids it.

        Raises
        ------
        ValueError
            A threat with this id is already in the mission.
        """
        if threat.id in {t.id for t in (*self.scenario.threats, *self._extra_threats)}:
            raise ValueError(f"threat {threat.id}: a threat with this id is already in the mission")
        now = self.now_s() if self.start_utc_s is not None else 0.0
        if at_s is not None or threat.appears is None:
            when = now if at_s is None else max(now, at_s)
            threat = threat.model_copy(update={"appears": Appearance(at_s=when)})
        elif threat.appears.at_s is not None and threat.appears.at_s < now:
            threat = threat.model_copy(update={"appears": Appearance(at_s=now)})
        self._extra_threats.append(threat)

    async def run(self, start_utc_s: float | None = None) -> None:
        """Launch on schedule and hold the arrival times until every vehicle has arrived."""
        if not self.members:
            await self.upload_all()
        if start_utc_s is None:
            start_utc_s = self.clock.now_utc_s() + max(5.0, 2.0 * self.clock.rate)
        self.start_utc_s = start_utc_s
        self._emit(
            "start",
            f"mission start at UTC {start_utc_s:.1f}; team arrival "
            f"{self.fmt_ref()} ({self.schedule.arrival_reason if self.schedule else ''})",
            t_s=0.0,
        )
        async with asyncio.TaskGroup() as tg:
            for m in self.members.values():
                tg.create_task(self._fly(m))
            tg.create_task(self._timeline())

    def fmt_ref(self) -> str:
        return "per-vehicle" if self.team_ref_s is None else f"{self.team_ref_s:.1f} s"

    def _all_arrived(self) -> bool:
        return all(m.phase in _DONE for m in self.members.values())

    def _deadline_s(self) -> float:
        return max(m.target_s for m in self.members.values()) + self.config.overrun_s

    async def _timeline(self) -> None:
        """Launches at their takeoff times, scenario pop-ups, operator threats."""
        while not self._all_arrived():
            now = self.now_s()
            if now > self._deadline_s():
                self._emit("abort", "mission overran its last target; stopping the loop")
                for m in self.members.values():
                    m.phase = "arrived"
                return
            for m in self.members.values():
                if m.phase == "ground" and now >= m.takeoff_s:
                    m.phase = "takeoff"
                    self._spawn(self._launch(m))
            for zone in self._due_popups(now):
                await self._popup(zone)
            self._check_clocks()
            await self.clock.sleep(1.0)

    def _check_clocks(self) -> None:
        """Say which vehicles keep a UTC of their own (they are flown on the team's)."""
        for m in self.members.values():
            sysid = m.vehicle.system_id
            if sysid in self.clock.without_utc:
                if not m.no_utc_said:
                    m.no_utc_said = True
                    self._emit(
                        "clock",
                        "reports no UTC (SYSTEM_TIME.time_unix_usec 0): its times are the "
                        "team clock's when its messages arrive",
                        m.vehicle_id,
                    )
                continue
            offset = self.clock.offset_s(sysid)
            if offset is None or abs(offset - m.clock_offset_said_s) < CLOCK_OFFSET_NOTE_S:
                continue
            m.clock_offset_said_s = offset
            self._emit(
                "clock",
                f"its UTC is {offset:+.1f} s from the team's (the median of the vehicles' "
                "clocks): its times are mapped to the team's",
                m.vehicle_id,
                value=round(offset, 3),
            )

    def _takeoffs_s(self) -> dict[str, float]:
        """Mission time of each launch so far (pop-ups may be timed from them)."""
        return {
            m.vehicle_id: m.launched_utc_s - (self.start_utc_s or 0.0)
            for m in self.members.values()
            if m.launched_utc_s is not None
        }

    def _zones(self) -> list[ThreatZone]:
        """Every threat of the mission, the operator's included, timed from the launches."""
        scenario = self.scenario.model_copy(
            update={"threats": [*self.scenario.threats, *self._extra_threats]}
        )
        return build_threats(scenario, self._takeoffs_s())

    def _due_popups(self, now: float) -> list[ThreatZone]:
        out = []
        for z in popup_zones(self._zones()):
            appears_s = math.inf if z.appears_at_s is None else z.appears_at_s
            if z.id not in self._popups_done and appears_s <= now:
                self._popups_done.add(z.id)
                out.append(z)
        return out

    def _spawn(self, coro: Any) -> None:
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _launch(self, m: Member) -> None:
        v = m.vehicle
        timeout = self._wall_timeout_s(v)
        retries = self.config.command_retries
        try:
            await v.arm(timeout_s=timeout, retries=retries)
            await v.set_mode("AUTO", timeout_s=timeout, retries=retries)
        except GcsError as err:
            self._emit(
                "launch", f"launch failed: {err}; retrying", m.vehicle_id, payload={"ok": False}
            )
            m.phase = "ground"
            return
        m.launched_utc_s = self.clock.now_utc_s()
        t = m.launched_utc_s - (self.start_utc_s or 0.0)
        self._emit(
            "launch",
            f"armed and AUTO at {t:.1f} s (scheduled takeoff {m.takeoff_s:.1f} s)",
            m.vehicle_id,
            payload={"ok": True},
        )

    # -- per-vehicle loop --------------------------------------------------------------------

    async def _fly(self, m: Member) -> None:
        sub = m.vehicle.link.subscribe({"GLOBAL_POSITION_INT"}, m.vehicle.system_id, maxsize=64)
        try:
            silent = False
            while m.phase not in _DONE:
                # Look for silence often enough to see the shortest one reported.
                poll_s = self._silence_s() / max(self.clock.rate, 1.0) / 2.0
                msg = await sub.get(timeout_s=min(0.05, max(0.005, poll_s)))
                if msg is None:
                    silent = self._check_link(m, silent)
                    continue
                if silent:
                    silent = False
                    gap = self.clock.now_utc_s() - (m.last_fix_utc_s or 0.0)
                    wall_ms = (time.monotonic() - m.last_fix_wall_s) * 1000.0
                    self._emit(
                        "link",
                        f"telemetry back after {gap:.1f} s ({wall_ms:.0f} ms wall); re-deciding",
                        m.vehicle_id,
                    )
                    m.next_decision_s = -math.inf
                self._on_fix(m)
        finally:
            sub.close()

    def _check_link(self, m: Member, silent: bool) -> bool:
        """Say when a flying vehicle's position reports stop (the mission carries on)."""
        if silent or m.last_fix_utc_s is None or self.start_utc_s is None:
            return silent
        age = self.clock.now_utc_s() - m.last_fix_utc_s
        wall_s = time.monotonic() - m.last_fix_wall_s
        cfg = self.config
        if (
            m.phase in ("takeoff", "route")
            and age > cfg.link_silence_s
            and wall_s > cfg.link_silence_wall_s
        ):
            self._emit(
                "link",
                f"no position for {age:.1f} s ({wall_s * 1000:.0f} ms wall): the vehicle flies "
                "its uploaded mission and last speed meanwhile",
                m.vehicle_id,
            )
            return True
        return False

    def _silence_s(self) -> float:
        """A position gap (mission s) long enough to report: config, with its wall floor."""
        cfg = self.config
        return max(cfg.link_silence_s, cfg.link_silence_wall_s * self.clock.rate)

    def _on_fix(self, m: Member) -> None:
        st = m.vehicle.state
        if st.lat_deg is None or st.lon_deg is None or st.position_time_boot_s is None:
            return
        utc = self.clock.utc_of_boot(m.vehicle.system_id, st.position_time_boot_s)
        if utc is None or self.start_utc_s is None:
            return
        if m.last_fix_utc_s is not None and utc <= m.last_fix_utc_s:
            return
        m.last_fix_utc_s = utc
        m.last_fix_wall_s = time.monotonic()
        t = utc - self.start_utc_s
        e, n = self.frame.to_local(st.lat_deg, st.lon_deg)
        e, n = float(e), float(n)
        if not m.track_log or utc - m.track_log[-1][0] >= 2.0:
            m.track_log.append(
                [
                    round(utc, 3),
                    round(e, 1),
                    round(n, 1),
                    round(st.alt_amsl_m or 0.0, 1),
                    round(st.airspeed_m_s or 0.0, 2),
                    round(st.groundspeed_m_s or 0.0, 2),
                ]
            )
        seq = st.mission_current_seq
        if m.phase == "takeoff":
            if m.launched_utc_s is not None and seq is not None and seq >= FIRST_ROUTE_SEQ:
                m.phase = "route"
                self._emit("route", f"climb-out done at {t:.1f} s, on the route", m.vehicle_id)
            else:
                return
        if m.phase != "route":
            return
        seq_changed = seq != m.last_seq
        if seq_changed and seq is not None:
            self._passed_items(m, m.last_seq, seq)
            m.last_seq = seq
        self._watch_goal(m, utc, e, n, st)
        if m.phase != "route":
            return
        s, m.cross_track_m = m.track.locate(e, n, m.s_m)
        m.s_m = s
        self._learn_bias(m, t, st)
        if m.cross_track_m <= self.config.off_route_m:
            m.joining = False
        in_loiter = (
            seq is not None
            and m.mission.items[min(seq, len(m.mission.items) - 1)].command
            == MAV_CMD_NAV_LOITER_TURNS
        )
        if in_loiter or m.busy_mission:
            return
        if not seq_changed and t < m.next_decision_s:
            return
        if m.track.length_m - s < self.config.final_m:
            return
        self._decide(m, t, s, st)

    def _passed_items(self, m: Member, old: int | None, new: int) -> None:
        """DO_CHANGE_SPEED items the vehicle ran set the airspeed it flies."""
        lo = FIRST_ROUTE_SEQ if old is None else old
        for k in range(lo, min(new, len(m.mission.items))):
            it = m.mission.items[k]
            if it.command == MAV_CMD_DO_CHANGE_SPEED and it.param2 > 0:
                m.level_m_s = float(it.param2)
                m.next_decision_s = -math.inf

    def _loiters_done(self, m: Member) -> int:
        seq = m.last_seq or 0
        return sum(
            1
            for k, it in enumerate(m.mission.items)
            if it.command == MAV_CMD_NAV_LOITER_TURNS and k < seq
        )

    def _reported_wind(self, st: Any) -> Wind:
        """The vehicle's wind estimate (WIND), else ground velocity minus true airspeed."""
        if st.wind_speed_m_s is not None and st.wind_from_deg is not None:
            return Wind.from_speed_from(st.wind_speed_m_s, st.wind_from_deg)
        if (
            st.airspeed_m_s is not None
            and st.heading_deg is not None
            and st.vn_m_s is not None
            and st.ve_m_s is not None
        ):
            h = math.radians(st.heading_deg)
            tas = st.airspeed_m_s * eas2tas(st.alt_amsl_m or 0.0)
            return Wind(st.ve_m_s - tas * math.sin(h), st.vn_m_s - tas * math.cos(h))
        return Wind()

    def _wind(self, m: Member) -> Wind:
        """The wind to time with: the vehicle's estimate plus the error learnt in flight."""
        return m.bias.corrected(self._reported_wind(m.vehicle.state))

    def _learn_bias(self, m: Member, t: float, st: Any) -> None:
        """Feed one fix to the airspeed-scale and wind-error estimate.

        The prediction is from the airspeed the autopilot reports (VFR_HUD: the equivalent
        airspeed it believes it flies) and only with a VFR_HUD of the same moment as the fix
        (within 1.5 s of mission time): a stale one, or one taken while a new speed settles,
        would teach a bias that is not there.
        """
        if (
            m.level_m_s is None
            or st.ve_m_s is None
            or st.vn_m_s is None
            or st.heading_deg is None
            or st.alt_amsl_m is None
            or st.airspeed_m_s is None
        ):
            return
        fix_rx, hud_rx = st.rx_times.get("GLOBAL_POSITION_INT"), st.rx_times.get("VFR_HUD")
        if fix_rx is None or hud_rx is None or abs(fix_rx - hud_rx) * self.clock.rate > 1.5:
            return
        climb = st.climb_m_s if st.climb_m_s is not None else -(st.vd_m_s or 0.0)
        m.bias.update(
            t,
            ve_m_s=st.ve_m_s,
            vn_m_s=st.vn_m_s,
            heading_rad=math.radians(st.heading_deg),
            predicted_tas_m_s=st.airspeed_m_s * eas2tas(st.alt_amsl_m),
            wind=self._reported_wind(st),
            airspeed_m_s=st.airspeed_m_s,
            commanded_m_s=m.level_m_s,
            climb_m_s=climb,
        )

    def _decide(self, m: Member, t: float, s: float, st: Any) -> None:
        inputs: dict[str, Any] = {
            "s_m": s,
            "now_s": t,
            "target_s": m.target_s,
            "wind": self._wind(m),
            "current_level_m_s": m.level_m_s,
            "loiters_done": self._loiters_done(m),
            "tas_per_eas": m.tas_per_eas(s),
        }
        d = m.controller.decide(m.track, **inputs)
        m.last_decision = d
        time_left = m.target_s - t
        m.next_decision_s = t + ArrivalController.period_s(time_left)
        if d.command_m_s is not None and not m.busy_command:
            m.busy_command = True
            self._spawn(self._command_speed(m, d, t))
        if d.verdict == "late" and m.cross_track_m > self.config.off_route_m:
            if not m.joining:
                m.joining = True
                self._emit(
                    "arrival",
                    f"late by {d.eta_min_s - m.target_s:.1f} s at top speed, but "
                    f"{m.cross_track_m:.0f} m off the route and joining it: the team time "
                    "stays until it is on the route",
                    m.vehicle_id,
                    t_s=t,
                )
        elif d.verdict == "late":
            self._late(m, d, t)
        elif time_left > self.config.loiter_min_time_left_s and t - m.last_loiter_s > 120.0:
            # Early, or so little above the minimum speed that the last minutes would have no
            # room to slow down: loiter turns now, while a buffer is ahead (judged as if the
            # minimum were higher by the reserve; the turns leave the loiter margin above it).
            reserve = self.config.speed_reserve_m_s
            lo, hi = m.limits.airspeed_min_m_s, m.limits.airspeed_max_m_s
            if d.verdict != "early" and reserve > 0.0 and d.required_m_s < min(lo + reserve, hi):
                held = SpeedLimits(min(lo + reserve, hi), hi, m.limits.step_m_s)
                d = ArrivalController(held, tolerance_s=self.config.tolerance_s).decide(
                    m.track, **inputs
                )
            if d.verdict == "early":
                m.last_loiter_s = t
                self._spawn(self._insert_loiter(m, d, t, s))

    async def _command_speed(self, m: Member, d: Decision, t: float) -> None:
        assert d.command_m_s is not None
        v = m.vehicle
        try:
            await v.change_speed(
                d.command_m_s,
                timeout_s=self._wall_timeout_s(v),
                retries=self.config.command_retries,
            )
        except GcsError as err:
            self._emit("speed", f"speed command failed ({err}); will retry", m.vehicle_id)
            m.next_decision_s = -math.inf
            return
        finally:
            m.busy_command = False
        m.level_m_s = d.command_m_s
        m.commanded.append([round(self.clock.now_utc_s(), 3), d.command_m_s, "command"])
        self._emit("speed", d.reason, m.vehicle_id, "speed", d.command_m_s, t_s=t)

    # -- lateness: move the team time ---------------------------------------------------------

    def _late(self, m: Member, d: Decision, t: float) -> None:
        ref = self.team_ref_s
        if ref is None:
            return
        new_ref = d.eta_min_s - m.offset_s + self.config.late_margin_s
        if new_ref <= ref:
            return
        self.team_ref_s = new_ref
        self._emit(
            "arrival",
            f"team arrival moved {ref:.1f} -> {new_ref:.1f} s: {m.vehicle_id} cannot arrive "
            f"before {d.eta_min_s:.1f} s even at {m.limits.airspeed_max_m_s:g} m/s",
            m.vehicle_id,
            value=new_ref,
            t_s=t,
        )
        for other in self.members.values():
            other.target_s = new_ref + other.offset_s
            other.next_decision_s = -math.inf
            if other.phase == "ground":
                self._retime_takeoff(other, t)

    def _retime_takeoff(self, m: Member, t: float) -> None:
        v = self.scenario.vehicle(m.vehicle_id)
        limits = PlannerLimits(v.speed_min_m_s, v.speed_max_m_s, v.cruise_m_s, m.limits.step_m_s)
        window = (max(v.takeoff_window_s[0], t), max(v.takeoff_window_s[1], t))
        new = takeoff_time_s(
            m.schedule.path.length_m, m.target_s, limits, window, m.schedule.tas_per_eas()
        )
        if abs(new - m.takeoff_s) > 0.5:
            m.takeoff_s = new
            self._emit(
                "takeoff",
                f"take off at {new:.1f} s to arrive at {m.target_s:.1f} s (eq. 5)",
                m.vehicle_id,
                "takeoff_delay",
                round(new, 3),
                t_s=t,
            )

    # -- mission changes --------------------------------------------------------------------

    def _lead_s(self) -> float:
        """How far ahead (mission s) a changed mission may start: planning and upload time."""
        wall = self.plan_wall_s + 0.3
        return max(self.config.min_lead_s, 1.5 * wall * self.clock.rate)

    def _keep_seq(self, m: Member, lead_m: float) -> int | None:
        """The first route waypoint at least ``lead_m`` ahead of the vehicle."""
        s_now = m.s_m or 0.0
        seq = max(m.last_seq or FIRST_ROUTE_SEQ, FIRST_ROUTE_SEQ)
        for k in range(seq, len(m.mission.items)):
            it = m.mission.items[k]
            s = m.mission.item_s_m[k]
            if it.command == MAV_CMD_NAV_WAYPOINT and s is not None and s >= s_now + lead_m:
                return k
        return None

    def _speed_now(self, m: Member) -> float:
        return float(m.level_m_s or self.scenario.vehicle(m.vehicle_id).cruise_m_s)

    async def _insert_loiter(self, m: Member, d: Decision, t: float, s: float) -> None:
        assert self.schedule is not None
        gs = max(m.vehicle.state.groundspeed_m_s or 0.0, 10.0)
        keep = self._keep_seq(m, gs * self._lead_s())
        if keep is None:
            return
        s_k = m.mission.item_s_m[keep]
        assert s_k is not None
        t_k = t + (s_k - s) / gs
        threats = self._in_force(t)
        # The planner's loiter arithmetic (eq. 8) is in still air at the ISA true airspeed;
        # give it the surplus the wind- and bias-aware ETA found, as a still-air target from
        # the splice waypoint. The new mission replaces the loiters after that waypoint, so
        # their time is kept too.
        v_min = m.limits.airspeed_min_m_s
        tas_min = v_min * m.tas_per_eas(s_k)
        surplus = m.target_s - d.eta_max_s
        wind = self._wind(m)
        track = m.track
        before = sum(1 for lo in track.loiters if lo.s_m < s_k)
        held_s = track.time_to_go_s(s_k, tas_min, wind, before) - track.time_to_go_s(
            s_k, tas_min, wind, len(track.loiters)
        )
        planner_tas_min = v_min * m.schedule.tas_per_eas(s_k)
        target_still_air = t_k + (track.length_m - s_k) / planner_tas_min + held_s + surplus
        m.busy_mission = True
        try:
            schedule = self._current_schedule()
            vs, adjustments = await asyncio.to_thread(
                retime_vehicle,
                schedule,
                m.vehicle_id,
                now_s=t_k,
                s_m=s_k,
                speed_m_s=self._speed_now(m),
                target_s=target_still_air,
                threats=threats,
                loiter_margin_m_s=self.config.loiter_margin_m_s,
            )
            if not vs.loiters or all(lo.s_m < s_k for lo in vs.loiters):
                return
            await self._install(m, vs, keep, "loiter inserted")
            for a in adjustments:
                self._record_adjustment(a, t)
        except (InfeasibleError, PlannerError) as err:
            self._emit("loiter", f"no loiter possible: {err}", m.vehicle_id, t_s=t)
        except GcsError as err:
            self._emit("loiter", f"mission upload failed ({err}); flying on", m.vehicle_id, t_s=t)
        finally:
            m.busy_mission = False

    def _record_adjustment(self, a: Adjustment, t: float) -> None:
        if a.strategy == "loiter":
            self._emit("loiter", a.reason, a.vehicle, "loiter", a.value, t_s=t)
        elif a.strategy == "takeoff_delay":
            self._emit("takeoff", a.reason, a.vehicle, "takeoff_delay", a.value, t_s=t)
        else:
            self._emit("plan", a.reason, a.vehicle, None, a.value, t_s=t)

    def _path_mission(self, vs: VehicleSchedule) -> PathMission:
        assert self.schedule is not None and self.world is not None
        return path_mission(
            self.schedule,
            vs,
            self.world.terrain,
            runout_m=self.config.runout_m,
            max_spacing_m=self.config.waypoint_spacing_m,
        )

    async def _install(self, m: Member, vs: VehicleSchedule, keep: int | None, what: str) -> None:
        """Upload the vehicle's new schedule (spliced after item ``keep`` when flying)."""
        assert self.schedule is not None and self.world is not None
        new = self._path_mission(vs)
        pm = new if keep is None else splice_mission(m.mission, keep, new)
        await self._upload(m, pm, what)
        m.mission = pm
        m.schedule = vs
        m.track = route_track(vs)
        m.next_decision_s = -math.inf
        t = self.now_s()
        s_k = 0.0 if keep is None else (m.mission.item_s_m[keep] or 0.0)
        m.loiter_log = [x for x in m.loiter_log if x["s_m"] < s_k]
        for lo in vs.loiters:
            if lo.s_m >= s_k:
                m.loiter_log.append(
                    {
                        "s_m": lo.s_m,
                        "centre_east_m": lo.centre_east_m,
                        "centre_north_m": lo.centre_north_m,
                        "radius_m": lo.radius_m,
                        "turns": lo.turns,
                        "buffer_id": lo.buffer_id,
                        "t_s": t,
                    }
                )
        self.schedule = replace(
            self.schedule,
            vehicles=tuple(
                vs if x.vehicle_id == m.vehicle_id else x for x in self.schedule.vehicles
            ),
        )

    def _current_schedule(self) -> Schedule:
        """The schedule with today's targets as its arrival times."""
        assert self.schedule is not None
        vehicles = tuple(
            replace(
                self.members[vs.vehicle_id].schedule, arrival_s=self.members[vs.vehicle_id].target_s
            )
            for vs in self.schedule.vehicles
        )
        return replace(self.schedule, vehicles=vehicles, required_arrival_s=self.team_ref_s)

    def _in_force(self, t: float) -> list[ThreatZone]:
        return list(active(self._zones(), t))

    async def _popup(self, zone: ThreatZone) -> None:
        """Re-plan around a new threat from waypoints ahead, re-time, re-upload."""
        t = self.now_s()
        self.threats_appeared.append({"id": zone.id, "utc_s": self.clock.now_utc_s(), "t_s": t})
        lead = self._lead_s()
        while True:
            try:
                await self._replan_around(zone, t, lead)
                return
            except InfeasibleError as err:
                if "inside forbidden zone" not in str(err) or lead <= self.config.min_lead_s:
                    self._emit("popup", f"re-plan around {zone.id} failed: {err}", t_s=t)
                    return
                lead = max(self.config.min_lead_s, lead / 2.0)
                self._emit("popup", f"{err}; re-planning from {lead:.0f} s ahead", t_s=t)

    async def _replan_around(self, zone: ThreatZone, t: float, lead: float) -> None:
        assert self.world is not None
        at_s = t + lead
        anchors: dict[str, Anchor] = {}
        keeps: dict[str, int | None] = {}
        for m in self.members.values():
            if m.phase in _DONE:
                continue
            if m.phase == "ground" and m.takeoff_s > at_s:
                keeps[m.vehicle_id] = None
                continue
            gs = max(m.vehicle.state.groundspeed_m_s or 0.0, 10.0)
            keep = self._keep_seq(m, gs * lead) if m.phase == "route" else None
            if keep is None:
                self._emit(
                    "popup",
                    f"{zone.id}: no waypoint far enough ahead to re-plan from",
                    m.vehicle_id,
                )
                continue
            s_k = m.mission.item_s_m[keep]
            assert s_k is not None
            # The vehicle reaches the splice waypoint at its own time, not at t + lead: the
            # waypoint is the first one at least that far ahead and may be much farther.
            t_k = t + (s_k - (m.s_m or 0.0)) / gs
            anchors[m.vehicle_id] = Anchor(s_k, self._speed_now(m), t_k)
            keeps[m.vehicle_id] = keep
        threats = self._in_force(t)
        if zone.id not in {z.id for z in threats}:
            threats.append(zone)
        world = replace(self.world, threats=tuple(threats))
        self._emit("popup", f"threat {zone.id} appears; re-planning from {lead:.0f} s ahead", t_s=t)
        t0 = time.perf_counter()
        try:
            outcome = await asyncio.to_thread(
                apply_popup,
                self._current_schedule(),
                zone,
                at_s=at_s,
                world=world,
                threats=threats,
                method=self.config.method,
                rng=self.rng,
                anchors=anchors,
                loiter_margin_m_s=self.config.loiter_margin_m_s,
            )
        except PlannerError as err:
            if isinstance(err, InfeasibleError):
                raise
            self._emit("popup", f"re-plan around {zone.id} failed: {err}", t_s=t)
            return
        self.plan_wall_s = max(self.plan_wall_s, time.perf_counter() - t0)
        new_ref = outcome.schedule.required_arrival_s
        for ev in outcome.events:
            # The re-timed team arrival is said with its time (the store keeps it).
            value = new_ref if ev.kind == EventKind.ARRIVAL else None
            self._emit(ev.kind, ev.text, value=value, t_s=t)
        if (
            new_ref is not None
            and self.team_ref_s is not None
            and abs(new_ref - self.team_ref_s) > 1e-3
        ):
            self.team_ref_s = new_ref
        for a in outcome.adjustments:
            self._record_adjustment(a, t)
        installs = []
        for m in self.members.values():
            vs = outcome.schedule.vehicle(m.vehicle_id)
            if new_ref is not None:
                m.target_s = new_ref + m.offset_s
            m.next_decision_s = -math.inf
            if vs is m.schedule or m.vehicle_id not in keeps:
                continue
            if m.vehicle_id in outcome.affected:
                m.planned_paths.append(
                    {"label": f"after {zone.id}", "t_s": t, "en_m": _path_en(vs)}
                )
            if m.phase == "ground":
                m.takeoff_s = vs.takeoff_s
            installs.append(self._install_guarded(m, vs, keeps[m.vehicle_id], f"after {zone.id}"))
        await asyncio.gather(*installs)

    async def _install_guarded(
        self, m: Member, vs: VehicleSchedule, keep: int | None, what: str
    ) -> None:
        m.busy_mission = True
        try:
            if keep is not None and (m.last_seq or 0) > keep:
                self._emit(
                    "upload",
                    f"{what}: the vehicle passed the splice waypoint; not installed",
                    m.vehicle_id,
                )
                return
            await self._install(m, vs, keep, what)
        except GcsError as err:
            self._emit("upload", f"{what}: upload failed ({err})", m.vehicle_id)
        finally:
            m.busy_mission = False

    # -- arrival ------------------------------------------------------------------------------

    def _watch_goal(self, m: Member, utc: float, e: float, n: float, st: Any) -> None:
        d = math.hypot(e - m.goal_en_m[0], n - m.goal_en_m[1])
        if d > self.config.arrival_radius_m:
            if m.near_goal:
                self._arrive(m)
            return
        m.near_goal.append(
            TruthSample(
                utc,
                st.lat_deg,
                st.lon_deg,
                st.alt_amsl_m or 0.0,
                st.airspeed_m_s or 0.0,
                st.groundspeed_m_s or 0.0,
                True,
            )
        )
        if len(m.near_goal) >= 3:
            d_prev = self._goal_distance(m, m.near_goal[-2])
            if d > d_prev + 1.0:
                self._arrive(m)

    def _goal_distance(self, m: Member, s: TruthSample) -> float:
        e, n = self.frame.to_local(s.lat_deg, s.lon_deg)
        return math.hypot(float(e) - m.goal_en_m[0], float(n) - m.goal_en_m[1])

    def _arrive(self, m: Member) -> None:
        glat, glon = self.frame.to_geodetic(*m.goal_en_m)
        ca = closest_approach(m.near_goal, float(glat), float(glon), self.config.arrival_radius_m)
        utc = ca[0] if ca is not None else m.near_goal[-1].utc_s
        m.arrival_utc_s = utc
        m.phase = "arrived"
        t = utc - (self.start_utc_s or 0.0)
        self._emit(
            "arrived",
            f"passed the goal at {t:.2f} s (target {m.target_s:.2f} s, "
            f"error {t - m.target_s:+.2f} s; telemetry)",
            m.vehicle_id,
            value=round(t - m.target_s, 3),
            t_s=t,
        )

    async def abort(
        self, vehicle_id: str | None = None, *, mode: AbortMode = "rtl"
    ) -> dict[str, str | None]:
        """Abort one vehicle (or every one): it leaves the team and flies home (``rtl``) or
        circles where it is (``loiter``); a vehicle still on the ground stays there. The rest
        keep their arrival time. Returns per vehicle None (done) or why not.

        Raises
        ------
        KeyError
            No such vehicle in the flight (named).
        """
        if vehicle_id is not None and vehicle_id not in self.members:
            raise KeyError(f"no vehicle {vehicle_id!r} in the flight")
        chosen = [self.members[vehicle_id]] if vehicle_id else list(self.members.values())
        results: dict[str, str | None] = {}
        for m in chosen:
            if m.phase in _DONE:
                results[m.vehicle_id] = f"already {m.phase}"
                continue
            on_ground = m.phase == "ground"
            m.phase = "aborted"
            if on_ground:
                self._emit("abort", "aborted on the ground: it will not take off", m.vehicle_id)
                results[m.vehicle_id] = None
                continue
            flight_mode = "RTL" if mode == "rtl" else "LOITER"
            try:
                await m.vehicle.set_mode(
                    flight_mode,
                    timeout_s=self._wall_timeout_s(m.vehicle),
                    retries=self.config.command_retries,
                )
            except GcsError as err:
                results[m.vehicle_id] = str(err)
                self._emit(
                    "abort", f"aborted, but {flight_mode} was not taken: {err}", m.vehicle_id
                )
                continue
            results[m.vehicle_id] = None
            what = "returning home (RTL)" if mode == "rtl" else "circling where it is (LOITER)"
            self._emit("abort", f"aborted: {what}; the others keep their time", m.vehicle_id)
        return results

    async def close(self) -> None:
        for task in list(self._tasks):
            task.cancel()
        for task in list(self._tasks):
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        for detach in self._detach:
            detach()

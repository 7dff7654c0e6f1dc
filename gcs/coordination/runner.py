"""The flight runner: one flight's asyncio side around its :class:`~team.TeamController`.

It plans (in a worker thread), uploads, feeds the controller the vehicles' fixes and the
mission clock's ticks, and carries out the actions it returns on the vehicles, each in a
supervised task whose outcome goes back to the controller as an input (a failed command or
upload is an event and a state, never lost). It keeps the flight's state
(:class:`FlightState`), publishes every event on the flight's bus, hands a checkpoint of the
controller to whoever keeps the flight (a restart resumes from it: :meth:`FlightRunner.resume`)
and takes the operator's requests: start at a UTC, add or remove a threat, move the team
time, abort one vehicle or all, snapshot.

Mission time is the vehicles' UTC (SYSTEM_TIME) through
:class:`~gcs.coordination.missionclock.MissionClock`; nothing here knows whether the vehicles
are simulated, and every wait and timeout scales with the clock's rate, so a rehearsal at 200x
runs the same logic as a live flight.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import logging
import math
import pickle
import time
from collections.abc import Awaitable, Callable, Coroutine, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gcs.coordination import actions as act
from gcs.coordination.bus import EventBus
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind, FlightEvent
from gcs.coordination.member import Member
from gcs.coordination.missionclock import MissionClock
from gcs.coordination.team import TeamController
from gcs.errors import GcsError
from gcs.mavlink import commands, mission_client
from gcs.mavlink.dialect import mavlink2
from gcs.mavlink.vehicle import Vehicle
from planner.deconflict import PairSeparation
from planner.errors import InfeasibleError
from planner.plan import World, build_world, plan
from planner.retime import build_schedule, check_feasible
from planner.scenario import Scenario, Threat
from planner.schedule import Schedule

__all__ = [
    "CHECKPOINT_FORMAT",
    "TELEMETRY_HZ",
    "FlightRunner",
    "FlightState",
    "InfeasibleRequest",
]

log = logging.getLogger(__name__)

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
    "TERRAIN_REPORT": 0.0,
}
"""What the runner asks each vehicle to send (Hz of the VEHICLE's time: a simulator at
200x sends 200 times as many per wall second), by MAV_CMD_SET_MESSAGE_INTERVAL; 0 turns a
message off on our link. With the heartbeat that is 6.4 messages per vehicle second: 1284 per
wall second from one stub vehicle at 200x, against 3800 with every stream at 2 Hz (measured),
which MAVProxy could not route fast enough for mission transfers to complete."""

CLOCK_OFFSET_NOTE_S = 0.5
"""A vehicle's UTC this far from the team's (or from what was said last) is reported."""
CHECKPOINT_FORMAT = "tcgcs-checkpoint/1"
CHECKPOINT_WALL_S = 0.5
"""Routine changes (a speed, a state) are checkpointed at most this often (wall s); mission
changes, launches, arrivals and team-time moves at once."""
_AT_ONCE = frozenset(
    {
        EventKind.UPLOAD,
        EventKind.LAUNCH,
        EventKind.ROUTE,
        EventKind.ARRIVAL,
        EventKind.ARRIVED,
        EventKind.POPUP,
        EventKind.REPLAN,
        EventKind.LOITER,
        EventKind.TAKEOFF,
        EventKind.ABORT,
        EventKind.START,
        EventKind.FLIGHT,
        EventKind.VEHICLE_LOST,
    }
)


PACED_TIMEOUT_FLIGHT_S = 1.0
"""On a pace clock, a command's reply is awaited at least this long in flight time..."""
MIN_TIMEOUT_WALL_S = 0.004
"""...and at least this long in wall time (a loopback round trip with room to spare)..."""
PACED_TIMEOUT_MAX_FLIGHT_S = 2.0
"""...and at most this long in flight time, whatever the round trips measured in wall time
(a busy machine makes them long in wall time, not in flight time: with five of them as the
timeout a lost command cost up to 47 s of flight at 200x, a takeoff that late)."""
MIN_COMMAND_WALL_S = 0.4
"""A command is retried for at least this long (wall s) before it is given up."""
PACED_PLAN_WALL_S = 0.2
"""A re-plan's planning time (wall s) on a pace clock, where the simulator waits while it
plans: what the paper's re-plan takes on a quiet machine, so the lead (150 s of flight at
200x) is the same however busy the machine is."""
PACED_UPLOAD_HOLD_WALL_S = 3.0
"""On a pace clock a mission upload in flight holds the simulator (:meth:`MissionClock.hold`)
for at most this long (wall s): on any machine, however busy, it is on board within that and
took no flight time. Its exchanges are timed in wall time (resends after wall timeouts, on a
link that loses packets), and the simulator flew on meanwhile at its speed-up: a loaded
machine made a 52-item upload after a pop-up outlast its 78 s of flight, the vehicle was held
short of the zone 2,100 s later and re-planned, and the team time moved 375 s. A vehicle that
does not answer (a link blackout, which ends in flight time) lets the flight go on after it."""
PACED_COMMAND_HOLD_WALL_S = 1.0
"""On a pace clock a command that changes what a vehicle flies at a moment of its own (the
launch's arm and AUTO, a loiter's exit, a hold, a resume, a mode) holds the simulator for at
most this long (wall s) while it goes, to a vehicle whose reports still come: its round trips
take no flight time, as they take next to none at 1x. Timed in wall time, under load they
came seconds of flight late at 200x (a launch 3.2 s late, its vehicle 4 loiter turns where 5
were planned and a slot missed by 1 s)."""
REPLAN_SEARCH_SHARE = 0.25
"""A re-plan's route search (the ACO) ends with the best routes so far once this share of the
planning lead, in wall time, is spent: the lead allows one and a half times the longest
planning so far (plus 0.3 s), and half of it goes to the uploads."""
REPLAN_SEPARATION_SHARE = 0.4
"""Its separation (timing, then altitude layers) ends with what it has separated so far once
this share of the lead, in wall time, is spent (the search's share included): the rest of the
half before the uploads is for finishing."""


@dataclass(frozen=True)
class WallDeadline:
    """True once ``time.perf_counter()`` reaches ``at_s`` (the machine's monotonic clock: the
    same in a job's own process)."""

    at_s: float

    def __call__(self) -> bool:
        return time.perf_counter() >= self.at_s


async def _in_a_thread(job: act.LoiterJob | act.PopupJob) -> Any:
    return await asyncio.to_thread(job.run)


class InfeasibleRequest(GcsError):
    """The required arrival cannot be met; refused before launch."""


class FlightState(enum.StrEnum):
    PLANNED = "planned"
    UPLOADING = "uploading"
    READY = "ready"
    RUNNING = "running"
    COMPLETED = "completed"
    ABORTED = "aborted"
    FAILED = "failed"


ENDED: frozenset[FlightState] = frozenset(
    {FlightState.COMPLETED, FlightState.ABORTED, FlightState.FAILED}
)


class FlightRunner:
    """Flies a scenario's team to its required arrival time.

    Use: :meth:`prepare` (plan, schedule, refuse an infeasible request), :meth:`bind` (each
    scenario vehicle's :class:`~gcs.mavlink.vehicle.Vehicle`), :meth:`upload_all`, :meth:`run`;
    or, after a restart, :meth:`resume`, :meth:`bind`, :meth:`reconcile`, :meth:`run`.
    """

    def __init__(
        self,
        scenario: Scenario,
        clock: MissionClock,
        *,
        config: FlightConfig | None = None,
        on_event: Callable[[FlightEvent], None] | None = None,
        bus: EventBus | None = None,
        required_arrival_s: float | None = None,
    ) -> None:
        self.scenario = scenario
        self.clock = clock
        self.config = config or FlightConfig()
        self.on_event = on_event
        self.requested_arrival_s = required_arrival_s
        self.rng = np.random.default_rng(self.config.seed)
        self.bus = bus if bus is not None else EventBus()
        """Every event is published here (numbered); subscribers cannot slow the loop."""
        self.events: list[FlightEvent] = []
        self.adjustments: list[FlightEvent] = []
        self.team: TeamController | None = None
        self.vehicles: dict[str, Vehicle] = {}
        self.state = FlightState.PLANNED
        self.state_reason = ""
        """Why the flight is in its state, when it was said (a failure's reason)."""
        self.plan_wall_s = 1.0
        self._planned_conflicts: tuple[PairSeparation, ...] = ()
        """The pairs the plan left under the separation (launched with ``allow_conflicts``)."""
        self.loiter_wall_s = 0.2
        """The longest loiter job so far (wall s): it sets the loiter lead."""
        self.on_checkpoint: Callable[[bytes], None] | None = None
        """Called with a pickled controller after every change worth keeping (see
        :data:`CHECKPOINT_WALL_S`); :meth:`resume` takes it back."""
        self.resumed = False
        self.run_job: Callable[[act.LoiterJob | act.PopupJob], Awaitable[Any]] = _in_a_thread
        """Where planning jobs run (their ``run()``): a thread of this process by default; a
        flight worker runs them in processes of their own, so that no job holds its event
        loop (the interpreter's lock) however long it computes."""
        self.upload_results: dict[str, str | None] = {}
        """Per vehicle, after :meth:`upload_all`: None (on board) or why it failed."""
        self._checkpoint_wall_s = -math.inf
        self._checkpoint_dirty = False
        self._group: asyncio.TaskGroup | None = None
        self._loose: set[asyncio.Task[object]] = set()
        self._detach: list[Callable[[], None]] = []
        self._stopped = False
        self._fix_wall_s: dict[str, float] = {}
        self._clock_said: dict[str, float | None] = {}
        self._computing = 0
        """Planning jobs running while the simulator waits for them (a pace clock)."""
        self._deferred: list[act.Fix] = []
        """Fixes heard while :attr:`_computing`: taken after the job's result (
        :meth:`_compute`)."""

    # -- views ----------------------------------------------------------------------------------

    def _team(self) -> TeamController:
        if self.team is None:
            raise GcsError("the flight is not planned yet")
        return self.team

    @property
    def members(self) -> dict[str, Member]:
        return {} if self.team is None else self.team.members

    @property
    def schedule(self) -> Schedule | None:
        return None if self.team is None else self.team.schedule

    @property
    def world(self) -> World | None:
        return None if self.team is None else self.team.world

    @property
    def team_ref_s(self) -> float | None:
        return None if self.team is None else self.team.team_ref_s

    @property
    def start_utc_s(self) -> float | None:
        return None if self.team is None else self.team.start_utc_s

    @property
    def operator_threats(self) -> tuple[Threat, ...]:
        return () if self.team is None else self.team.operator_threats

    @property
    def threats_appeared(self) -> list[dict[str, Any]]:
        start = self.start_utc_s or 0.0
        team = self._team()
        return [{"id": x["id"], "utc_s": start + x["t_s"]} for x in team.threats_appeared]

    def fmt_ref(self) -> str:
        return self._team().fmt_ref()

    def now_s(self) -> float:
        """Mission time now (s since the mission start; 0 before it)."""
        start = self.start_utc_s
        if start is None or not self.clock.synced:
            return 0.0
        return self.clock.now_utc_s() - start

    def snapshot(self) -> dict[str, Any]:
        """What a UI shows, as data: the team's view (:meth:`TeamController.snapshot`), the
        flight's state and each vehicle's link."""
        team = self._team()
        snap = team.snapshot(self.now_s())
        snap["state"] = self.state.value
        snap["last_seq"] = self.bus.last_seq
        for v in snap["vehicles"]:
            vehicle = self.vehicles.get(v["id"])
            if vehicle is None:
                continue
            st = vehicle.state
            # Judged as the flight judges its telemetry (on a simulator's pace clock, in its
            # time): while the vehicle's reports have stopped, what it does now is unknown.
            down = bool(v.get("link_silent"))
            v["link"] = {
                "system_id": vehicle.system_id,
                "healthy": not down,
                "mode": None if down else st.mode,
                "armed": None if down else st.armed,
                "last_mode": st.mode,
                "last_armed": st.armed,
                "battery_pct": st.battery_remaining_pct,
                "rtt_s": vehicle.link.counters.rtt_s,
            }
        return snap

    # -- events ---------------------------------------------------------------------------------

    def _publish(self, r: act.Report) -> FlightEvent:
        utc = self.clock.now_utc_s() if self.clock.synced else math.nan
        start = self.start_utc_s
        t = r.t_s if r.t_s is not None else (utc - start if start is not None else 0.0)
        ev = self.bus.publish(
            FlightEvent(utc, t, r.vehicle, r.kind, r.reason, r.strategy, r.value, 0, r.payload)
        )
        self.events.append(ev)
        if r.strategy is not None:
            self.adjustments.append(ev)
        if self.on_event is not None:
            self.on_event(ev)
        return ev

    def unwatched(self, flight_s: float) -> None:
        """The lock-step simulator flew ``flight_s`` seconds beyond its lead without this
        coordinator (its event loop was held longer than the simulator waits): an alarm, as
        the aircraft flew their missions unwatched and uncorrected meanwhile."""
        self._say(
            EventKind.ALARM,
            f"the coordinator was held: the flight ran {flight_s:.1f} s unwatched",
            payload={"unwatched_s": round(flight_s, 2)},
        )

    def _say(self, kind: EventKind, reason: str, vehicle: str | None = None, **kw: Any) -> None:
        self._publish(act.Report(kind, reason, vehicle, **kw))
        self._checkpoint(kind in _AT_ONCE)

    def _set_state(self, state: FlightState, reason: str = "") -> None:
        if state is self.state:
            return
        self.state = state
        self.state_reason = reason
        text = f"flight {state.value}" + (f": {reason}" if reason else "")
        self._say(EventKind.FLIGHT, text, payload={"state": state.value})

    def _checkpoint(self, at_once: bool) -> None:
        if self.on_checkpoint is None or self.team is None:
            return
        self._checkpoint_dirty = True
        now = time.monotonic()
        if not at_once and now - self._checkpoint_wall_s < CHECKPOINT_WALL_S:
            return
        self._checkpoint_wall_s = now
        self._checkpoint_dirty = False
        self.on_checkpoint(pickle.dumps({"format": CHECKPOINT_FORMAT, "team": self.team}))

    # -- planning -------------------------------------------------------------------------------

    async def prepare(self) -> Schedule:
        """Plan, schedule and check the request; refuse an infeasible one before launch.

        Raises
        ------
        InfeasibleRequest
            The required arrival cannot be met: names the earliest feasible time and the
            vehicle that forces it.
        """
        t0 = time.perf_counter()
        schedule, world = await asyncio.to_thread(self._plan)
        self._adopt_schedule(schedule, world, time.perf_counter() - t0)
        return schedule

    @classmethod
    def planned(
        cls,
        scenario: Scenario,
        schedule: Schedule,
        world: World,
        clock: MissionClock,
        *,
        config: FlightConfig | None = None,
        bus: EventBus | None = None,
        plan_wall_s: float = 1.0,
    ) -> FlightRunner:
        """A runner for a schedule planned already (``plan_wall_s``: how long that took, the
        first estimate of a re-plan's wall time)."""
        runner = cls(scenario, clock, config=config, bus=bus)
        runner._adopt_schedule(schedule, world, plan_wall_s)
        return runner

    def _adopt_schedule(self, schedule: Schedule, world: World, plan_wall_s: float) -> None:
        self.plan_wall_s = plan_wall_s
        self.team = TeamController(self.scenario, schedule, world, self.config, rng=self.rng)
        for a in schedule.adjustments:
            self._publish(
                act.Report(EventKind.PLAN, a.reason, a.vehicle, a.strategy, a.value, a.time_s)
            )
        for c in self._planned_conflicts:
            said = (
                f"{c.a} and {c.b} are planned {c.distance_m:.0f} m apart at {c.time_s:.1f} s, "
                f"under the separation {self.scenario.separation_m:g} m: launched so "
                "(allow_conflicts), left to the resolution in flight"
            )
            payload = {"pair": [c.a, c.b], "distance_m": round(c.distance_m, 1),
                       "at_s": round(c.time_s, 1)}  # fmt: skip
            self._publish(act.Report(EventKind.CONFLICT, said, c.a, payload=payload))
            self._publish(act.Report(EventKind.ALARM, said, c.a, payload=payload))

    def _plan(self) -> tuple[Schedule, World]:
        scenario = self.scenario
        if self.requested_arrival_s is not None:
            requested = scenario.with_team_arrival_s(self.requested_arrival_s)
            if requested is None:
                raise InfeasibleRequest("a required arrival time needs a team arrival kind")
            scenario = self.scenario = requested
        world = build_world(scenario)
        try:
            p = plan(scenario, method=self.config.method, rng=self.rng, world=world)
            schedule = build_schedule(scenario, p, world=world)
            sep = check_feasible(schedule, allow_conflicts=self.config.allow_conflicts)
        except InfeasibleError as err:
            raise InfeasibleRequest(f"refused before launch: {err}") from None
        self._planned_conflicts = sep.conflicts
        return schedule, world

    def _lead_s(self) -> float:
        """How far ahead (mission s) a changed mission may start: planning and upload time.
        On a pace clock the simulator waits while a job plans (:meth:`MissionClock.hold`):
        the planning is taken at :data:`PACED_PLAN_WALL_S`, not as long as a busy machine
        made it, and at the simulator's speed-up (:attr:`MissionClock.pace_rate`), not the rate
        fitted on reports dated when handled: a lead that moved with the load (73-76 s at 100x)
        moved the waypoints the re-planned routes start from."""
        plan_s = PACED_PLAN_WALL_S if self.clock.paced else self.plan_wall_s
        return max(self.config.min_lead_s, 1.5 * (plan_s + 0.3) * self._lead_rate())

    def _lead_rate(self) -> float:
        """Mission seconds per clock second for the leads: the pace clock's speed-up when the
        simulator says it, else the fitted rate."""
        return self.clock.pace_rate or self.clock.rate

    def _loiter_lead_s(self) -> float:
        """The same for loiter turns: one vehicle re-timed (milliseconds) and its upload (a
        second allowed)."""
        plan_s = 0.0 if self.clock.paced else self.loiter_wall_s
        return max(self.config.min_lead_s, 1.5 * (plan_s + 1.0) * self._lead_rate())

    def _planning_lead(self) -> act.PlanningLead:
        return act.PlanningLead(self._lead_s(), self._loiter_lead_s())

    # -- vehicles -------------------------------------------------------------------------------

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
        than one reached directly, and at 200x 5 ms of it would read as a clock 1 s behind.
        On a pace clock, every report's boot-time stamp also tells the clock how far that
        vehicle has been heard (:meth:`MissionClock.heard`)."""
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
                if msg.get_srcSystem() != sysid:
                    return
                if self.clock.paced:
                    boot_ms = getattr(msg, "time_boot_ms", None)
                    if boot_ms is not None:
                        self.clock.heard(sysid, boot_ms * 1e-3, rx_s)
                if msg.get_type() != "SYSTEM_TIME":
                    return
                rtt = link.counters.rtt_s
                if rtt is not None and rtt < least[0]:
                    least[0] = rtt
                if self.clock.paced:
                    sent_s = self.clock.monotonic()  # the pace clock: no link delay to remove
                else:
                    sent_s = rx_s - (0.0 if math.isinf(least[0]) else 0.5 * least[0])
                if msg.time_unix_usec:
                    self.clock.observe(
                        sysid, msg.time_unix_usec * 1e-6, msg.time_boot_ms * 1e-3, sent_s
                    )
                else:
                    self.clock.observe_no_utc(sysid, msg.time_boot_ms * 1e-3, sent_s)

            self._detach.append(link.add_listener(on_msg))

    def _wall_timeout_s(self, vehicle: Vehicle) -> float:
        """A reply timeout from the link's round trip, not tuned to any vehicle. On a pace
        clock (lock step with a simulator) it is at least a second of flight rather than 50 ms
        of wall time, which at 200x is 10 s of flight flown on a lost command."""
        rtt = vehicle.link.counters.rtt_s
        if self.clock.paced:
            rate = self.clock.rate
            floor = max(PACED_TIMEOUT_FLIGHT_S / rate, MIN_TIMEOUT_WALL_S)
            cap = max(PACED_TIMEOUT_MAX_FLIGHT_S / rate, floor)
            return float(min(cap, max(floor, 5.0 * (rtt or 0.0))))
        floor = max(0.05, MIN_TIMEOUT_WALL_S)
        return float(min(1.5, max(floor, 5.0 * rtt))) if rtt else max(floor, 0.25)

    def _command(self, vehicle: Vehicle) -> dict[str, Any]:
        """``timeout_s`` and ``retries`` for a command: the configured retries, and more when
        the timeout is short, so that a command is given up only after
        :data:`MIN_COMMAND_WALL_S` of wall time however busy the machine."""
        timeout = self._wall_timeout_s(vehicle)
        retries = max(self.config.command_retries, math.ceil(MIN_COMMAND_WALL_S / timeout))
        return {"timeout_s": timeout, "retries": retries}

    # -- carrying out actions -------------------------------------------------------------------

    def _feed(self, inp: act.Input) -> None:
        self._dispatch(self._team().handle(inp, self.now_s()))

    def _dispatch(self, actions: Iterable[act.Action]) -> None:
        at_once = False
        changed = False
        for a in actions:
            match a:
                case act.Report():
                    self._publish(a)
                    changed = True
                    at_once = at_once or a.kind in _AT_ONCE
                case act.Arm():
                    self._spawn(self._arm_ahead(a))
                case act.Launch():
                    self._spawn(self._launch(a))
                case act.CommandSpeed():
                    self._spawn(self._command_speed(a))
                case act.CommandAltitude():
                    self._spawn(self._command_altitude(a))
                case act.Upload():
                    # The team has it pending (a mission sent before a restart is known by
                    # it), whether or not an event goes with it.
                    changed = at_once = True
                    self._spawn(self._install(a))
                case act.Compute():
                    self._spawn(self._compute(a))
                case act.SetMode():
                    self._spawn(self._set_mode(a))
                case act.Hold():
                    self._spawn(self._hold(a))
                case act.Resume():
                    self._spawn(self._resume(a))
                case act.LeaveLoiter():
                    self._spawn(self._leave_loiter(a))
                case act.Stop():
                    self._stopped = True
        if changed:
            self._checkpoint(at_once)

    def _spawn(self, coro: Coroutine[Any, Any, object]) -> None:
        """Run an action in the flight's task group (supervised: every action wrapper turns
        its failure into an input, so nothing is lost); before :meth:`run`, loose but kept."""
        if self._group is not None:
            self._group.create_task(coro)
            return
        task = asyncio.get_running_loop().create_task(coro)
        self._loose.add(task)
        task.add_done_callback(self._loose.discard)

    @staticmethod
    async def _outcome(coro: Coroutine[Any, Any, Any]) -> str | None:
        """None if the step succeeded, else what went wrong (an unexpected exception is
        logged with its traceback and said by its type)."""
        try:
            await coro
        except GcsError as err:
            return str(err)
        except Exception as err:
            log.exception("action failed")
            return f"{type(err).__name__}: {err}"
        return None

    async def _arm_auto(self, v: Vehicle) -> None:
        await v.arm(**self._command(v))
        await self._auto(v)

    async def _auto(self, v: Vehicle) -> None:
        await v.set_mode("AUTO", **self._command(v))

    async def _arm_ahead(self, a: act.Arm) -> None:
        v = self.vehicles[a.vehicle_id]
        err = await self._outcome(v.arm(**self._command(v)))
        if err is not None:
            log.info("%s: arming ahead of takeoff failed (%s); the launch arms it", v, err)

    def _command_held(self, vehicle_id: str) -> contextlib.AbstractContextManager[None]:
        """The clock held while a timed command goes (:data:`PACED_COMMAND_HOLD_WALL_S`), unless
        the vehicle's reports have stopped (a blackout ends in flight time: it must not wait
        on the hold)."""
        m = self.members.get(vehicle_id)
        if not self.clock.paced or (m is not None and m.link_silent):
            return contextlib.nullcontext()
        return self._held_clock(PACED_COMMAND_HOLD_WALL_S)

    async def _launch(self, a: act.Launch) -> None:
        v = self.vehicles[a.vehicle_id]
        armed = v.state.armed is True
        with self._command_held(a.vehicle_id):
            err = await self._outcome(self._auto(v) if a.airborne or armed else self._arm_auto(v))
        self._feed(act.Launched(a.vehicle_id, err))

    async def _command_speed(self, a: act.CommandSpeed) -> None:
        v = self.vehicles[a.vehicle_id]
        err = await self._outcome(v.change_speed(a.airspeed_m_s, **self._command(v)))
        self._feed(act.SpeedCommanded(a.vehicle_id, a.airspeed_m_s, a.reason, a.decided_s, err))

    async def _command_altitude(self, a: act.CommandAltitude) -> None:
        v = self.vehicles[a.vehicle_id]
        err = await self._outcome(
            v.change_altitude(a.alt_m, above_home=a.above_home, **self._command(v))
        )
        self._feed(act.AltitudeCommanded(a.vehicle_id, a.alt_m, a.above_home, a.decided_s, err))

    async def _set_mode(self, a: act.SetMode) -> str | None:
        v = self.vehicles[a.vehicle_id]
        with self._command_held(a.vehicle_id):
            err = await self._outcome(v.set_mode(a.mode, **self._command(v)))
        r = self._team().abort_done(a.vehicle_id, a.mode, err, self.now_s())
        self._publish(r)
        self._checkpoint(True)
        return err

    async def _reposition(self, a: act.Hold) -> None:
        """MAV_CMD_DO_REPOSITION as COMMAND_INT with the change-mode flag: ArduPlane goes to
        GUIDED and circles the point (ArduPlane/GCS_Mavlink.cpp,
        handle_command_int_do_reposition); so does the stub. The altitude is AMSL."""
        v = self.vehicles[a.vehicle_id]
        await commands.command_int(
            v.link,
            v.system_id,
            int(mavlink2.MAV_CMD_DO_REPOSITION),
            (-1.0, float(mavlink2.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE), 0.0, 0.0),
            frame=int(mavlink2.MAV_FRAME_GLOBAL_INT),
            x=round(a.lat_deg * 1e7),
            y=round(a.lon_deg * 1e7),
            z=a.alt_amsl_m,
            target_component=v.component_id,
            **self._command(v),
        )

    async def _hold(self, a: act.Hold) -> None:
        with self._command_held(a.vehicle_id):
            err = await self._outcome(self._reposition(a))
        self._feed(act.HoldTaken(a, err))

    async def _auto_at(self, a: act.Resume) -> None:
        """The item to go on from (MISSION_SET_CURRENT while in GUIDED), then AUTO: ArduPlane
        resumes its mission at the current item (AP_Mission::resume)."""
        v = self.vehicles[a.vehicle_id]
        await v.set_current_item(a.seq, **self._command(v))
        await v.set_mode("AUTO", **self._command(v))

    async def _resume(self, a: act.Resume) -> None:
        with self._command_held(a.vehicle_id):
            err = await self._outcome(self._auto_at(a))
        self._feed(act.Resumed(a, err))

    async def _leave_loiter(self, a: act.LeaveLoiter) -> None:
        """MISSION_SET_CURRENT to the item after the loiter, in AUTO: ArduPlane leaves the
        turns and starts that item at once (AP_Mission::set_current_cmd)."""
        v = self.vehicles[a.vehicle_id]
        with self._command_held(a.vehicle_id):
            err = await self._outcome(v.set_current_item(a.seq, **self._command(v)))
        self._feed(act.LoiterLeft(a, err))

    async def _upload(self, a: act.Upload) -> None:
        """Upload with the adaptive retry policy (:mod:`gcs.mavlink.retry`), restarting the whole
        transfer (a vehicle may drop a stalled one) twice.

        In flight the new mission must be on board before the vehicle reaches the splice
        point, the planning lead ahead: the attempts together get half of that lead (in wall
        seconds at the clock's rate; on a pace clock in flight seconds, however slowly the
        flight goes), so a lossy link either delivers in time or fails early enough for the
        fallback (the vehicle keeps flying the mission it has).
        """
        v = self.vehicles[a.vehicle_id]
        loop = asyncio.get_running_loop()
        lead = self._loiter_lead_s() if a.what == "loiter inserted" else self._lead_s()
        if a.in_flight and self.clock.paced:
            # On a pace clock the budget is flight time: a busy machine slows the flight, and
            # half the lead in wall seconds at the clock's rate ran out with only seconds of
            # it flown (seen: 0.233 s of wall, a route round a pop-up never installed). The
            # simulator waits while the mission goes up (PACED_UPLOAD_HOLD_WALL_S): the
            # transfer's wall-time round trips and resends take no flight time.
            attempts = asyncio.ensure_future(self._upload_attempts(v, a, None))
            budget = asyncio.ensure_future(self.clock.sleep(0.5 * lead))
            try:
                with self._held_clock(PACED_UPLOAD_HOLD_WALL_S):
                    await asyncio.wait({attempts, budget}, return_when=asyncio.FIRST_COMPLETED)
            except BaseException:
                budget.cancel()
                attempts.cancel()
                raise
            budget.cancel()
            expired = budget.done() and not budget.cancelled() and budget.exception() is None
            if not attempts.done() and expired:
                attempts.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await attempts
                raise GcsError(f"mission upload not finished within {0.5 * lead:.0f} s of flight")
            await attempts  # done, or the budget could not be timed: the attempts decide
            return
        end_s = loop.time() + 0.5 * lead / self.clock.rate if a.in_flight else None
        await self._upload_attempts(v, a, end_s)

    @contextlib.contextmanager
    def _held_clock(self, wall_s: float) -> Iterator[None]:
        """Hold the mission clock (:meth:`MissionClock.hold`) while in the block, for at most
        ``wall_s`` of wall time (released once, whichever comes first)."""
        self.clock.hold()
        held = True

        def release() -> None:
            nonlocal held
            if held:
                held = False
                self.clock.release()

        timer = asyncio.get_running_loop().call_later(wall_s, release)
        try:
            yield
        finally:
            timer.cancel()
            release()

    async def _upload_attempts(self, v: Vehicle, a: act.Upload, end_s: float | None) -> None:
        """Up to three attempts, the later ones only while ``end_s`` (loop time) allows."""
        loop = asyncio.get_running_loop()
        for attempt in range(3):
            within_s = None if end_s is None else end_s - loop.time()
            try:
                await v.upload_mission(
                    list(a.mission.items), verify=not a.in_flight, within_s=within_s
                )
                return
            except GcsError as err:
                if attempt == 2 or (end_s is not None and loop.time() > end_s - 0.05):
                    raise
                log.info("%s: %s upload failed (%s); starting again", a.vehicle_id, a.what, err)

    async def _install(self, a: act.Upload) -> None:
        v = self.vehicles[a.vehicle_id]
        seq = v.state.mission_current_seq
        if a.keep_seq is not None and not a.holding and seq is not None and seq > a.keep_seq:
            self._feed(act.Installed(a, skipped=True))
            return
        err = await self._outcome(self._upload(a))
        self._feed(act.Installed(a, err))

    async def _compute(self, a: act.Compute) -> None:
        t0 = time.perf_counter()
        result: Any = None
        error: Exception | None = None
        job = a.job
        if isinstance(job, act.PopupJob) and not self.clock.paced:
            # The route search ends with its best routes so far once a share of the lead's
            # wall time is spent, the separation once a larger share is: the rest is for
            # finishing and the uploads (on a pace clock the simulator waits for the whole
            # search).
            end_s = t0 + REPLAN_SEARCH_SHARE * job.lead_s / self.clock.rate
            apart_s = t0 + REPLAN_SEPARATION_SHARE * job.lead_s / self.clock.rate
            job = replace(job, time_up=WallDeadline(end_s), separation_up=WallDeadline(apart_s))
        self.clock.hold()  # a simulator in lock step waits for the plan
        self._computing += self.clock.paced
        try:
            result = await self.run_job(job)
        except Exception as err:
            if not isinstance(err, GcsError | ValueError):
                log.exception("planning job failed")
            error = err
        finally:
            self.clock.release()
            self._computing -= self.clock.paced
        wall = time.perf_counter() - t0
        if isinstance(a.job, act.LoiterJob):
            self.loiter_wall_s = max(self.loiter_wall_s, wall)
        if isinstance(a.job, act.PopupJob):
            self.plan_wall_s = max(self.plan_wall_s, wall)
            if self.config.replan_delay_wall_s > 0.0 and not a.job.from_hold:
                self._take_deferred()  # the vehicles fly on through the delay
                await self._late_by(self.config.replan_delay_wall_s)  # the test hook
        self._feed(act.Computed(a.job, result, error, wall))
        self._feed(self._planning_lead())
        self._take_deferred()

    def _take_deferred(self) -> None:
        """Feed the fixes heard while planning jobs ran in lock step, once none runs.

        The simulator waits for a job (:meth:`MissionClock.hold`), but its reports of the
        lead it may already have flown (:meth:`MissionClock.follow`) still come in while the
        job runs, and how many depends on how busy the machine is. Taken then, they would let
        the team act on that stretch (a zone's guard holding a vehicle the re-plan is about to
        route round) before the plan it waits for, and the flight would differ with the
        machine's load. Taken after the result, the job takes no flight time at all."""
        if self._computing:
            return
        deferred, self._deferred = self._deferred, []
        for fix in deferred:
            self._feed(fix)

    async def _late_by(self, wall_s: float) -> None:
        """Wait ``wall_s`` of wall time, or on a pace clock ``wall_s`` times its rate of
        mission time: what that wait is at the nominal speed-up, however busy the machine
        (a loaded machine flies fewer mission seconds in a wall second)."""
        if self.clock.paced:
            await self.clock.sleep(wall_s * self.clock.rate)
        else:
            await asyncio.sleep(wall_s)

    # -- before the start -----------------------------------------------------------------------

    async def upload_all(self) -> dict[str, str | None]:
        """Upload each vehicle's mission (verified by download): per vehicle None or why it
        failed.

        Raises
        ------
        GcsError
            Some vehicle's upload failed (each named, with why); the flight is ``failed``.
        """
        team = self._team()
        self._set_state(FlightState.UPLOADING)
        uploads = team.initial_uploads()
        errors = await asyncio.gather(*(self._outcome(self._upload(u)) for u in uploads))
        results = self.upload_results
        for u, err in zip(uploads, errors, strict=True):
            results[u.vehicle_id] = err
            self._feed(act.Installed(u, err))
        failed = {vid: err for vid, err in results.items() if err is not None}
        if failed:
            why = "; ".join(f"{vid}: {err}" for vid, err in failed.items())
            self._set_state(FlightState.FAILED, f"upload failed ({why})")
            raise GcsError(f"mission upload failed for {', '.join(failed)}: {why}")
        self._set_state(FlightState.READY)
        return results

    # -- the flight -----------------------------------------------------------------------------

    async def run(self, start_utc_s: float | None = None) -> FlightState:
        """Launch on schedule and hold the arrival times until every vehicle has arrived (or
        was aborted, or the mission overran); returns the flight's final state."""
        team = self._team()
        if self.state is FlightState.PLANNED:
            await self.upload_all()
        if team.start_utc_s is None:  # not started before (nor before a restart)
            if start_utc_s is None:
                start_utc_s = self.clock.now_utc_s() + self.clock.start_lead_s()
            self._dispatch(team.start(start_utc_s))
        self._set_state(FlightState.RUNNING)
        self._feed(self._planning_lead())
        try:
            async with asyncio.TaskGroup() as tg:
                self._group = tg
                for vid in team.members:
                    tg.create_task(self._fly(vid))
                tg.create_task(self._timeline())
        finally:
            self._group = None
        members = list(team.members.values())
        failures = [
            f"{m.vehicle_id} lost at {m.lost.t_s:.1f} s ({m.lost.cause}: {m.lost.why})"
            for m in members
            if m.lost is not None
        ]
        late = [m.vehicle_id for m in members if not m.done]
        if team.stopped is not None:
            failures.append(team.stopped)
        elif late:
            failures.append(f"not arrived: {', '.join(late)}")
        if failures:
            self._set_state(FlightState.FAILED, "; ".join(failures))
        elif all(m.phase == "aborted" for m in members):
            self._set_state(FlightState.ABORTED)
        else:
            self._set_state(FlightState.COMPLETED)
        if self._checkpoint_dirty:
            self._checkpoint(True)
        return self.state

    def fail(self, reason: str) -> None:
        """The flight ends as failed (said as an event), e.g. when it cannot be resumed."""
        self._stopped = True
        self._set_state(FlightState.FAILED, reason)
        if self._checkpoint_dirty:
            self._checkpoint(True)

    def _over(self) -> bool:
        return self._stopped or self._team().finished

    async def _timeline(self) -> None:
        """Ticks of the mission clock: launches, pop-ups, the overrun, the clocks."""
        while not self._over():
            if not self._computing:  # a tick is at the newest time heard: see _take_deferred
                self._feed(self._planning_lead())
                self._feed(act.Tick())
            self._check_clocks()
            if self._checkpoint_dirty:
                self._checkpoint(False)
            now = self.now_s()
            await self.clock.sleep(min(1.0, self._team().next_due_s(now) - now))

    def _check_clocks(self) -> None:
        """Say which vehicles keep a UTC of their own (they are flown on the team's)."""
        for vid, vehicle in self.vehicles.items():
            sysid = vehicle.system_id
            said = self._clock_said.get(vid, 0.0)
            if sysid in self.clock.without_utc:
                if said is not None:
                    self._clock_said[vid] = None
                    self._say(
                        EventKind.CLOCK,
                        "reports no UTC (SYSTEM_TIME.time_unix_usec 0): its times are the "
                        "team clock's when its messages arrive",
                        vid,
                    )
                continue
            offset = self.clock.offset_s(sysid)
            if offset is None or said is None or abs(offset - said) < CLOCK_OFFSET_NOTE_S:
                continue
            self._clock_said[vid] = offset
            self._say(
                EventKind.CLOCK,
                f"its UTC is {offset:+.1f} s from the team's (the median of the vehicles' "
                "clocks): its times are mapped to the team's",
                vid,
                value=round(offset, 3),
            )

    def _silence_s(self) -> float:
        """A position gap (mission s) long enough to report: config, with its wall floor
        taken at the clock's rate (on a pace clock the gap is judged in mission time alone:
        the simulator waits for this process, so a busy machine makes no gap)."""
        cfg = self.config
        return max(cfg.link_silence_s, cfg.link_silence_wall_s * self.clock.rate)

    async def _fly(self, vid: str) -> None:
        """Feed one vehicle's fixes, heartbeats and critical texts to the controller, while it
        is in the air (past its slot or aborted too: its separation is still watched); say
        when its fixes stop and come back."""
        vehicle = self.vehicles[vid]
        m = self._team().members[vid]
        sub = vehicle.link.subscribe(
            {"GLOBAL_POSITION_INT", "HEARTBEAT", "STATUSTEXT"}, vehicle.system_id, maxsize=64
        )
        try:
            silent = False
            while m.phase != "lost" and not self._over():
                # Look for silence often enough to see the shortest one reported.
                poll_s = self._silence_s() / max(self.clock.rate, 1.0) / 2.0
                msg = await sub.get(timeout_s=min(0.05, max(0.005, poll_s)))
                if msg is None or msg.get_type() != "GLOBAL_POSITION_INT":
                    silent = silent or self._went_silent(m)
                    if msg is not None:
                        self._on_status(vid, msg)
                    continue
                if silent:
                    silent = False
                    self._link_back(m, vehicle)
                self._on_fix(vid, vehicle)
        finally:
            sub.close()

    def _link_back(self, m: Member, vehicle: Vehicle) -> None:
        """Say how long a silent vehicle's fixes stopped: the gap between the fixes' own times
        (what the vehicle did not report, whatever this process was doing meanwhile)."""
        vid = m.vehicle_id
        boot_s = vehicle.state.position_time_boot_s
        utc = None if boot_s is None else self.clock.utc_of_boot(vehicle.system_id, boot_s)
        fix_s = self.now_s() if utc is None or self.start_utc_s is None else utc - self.start_utc_s
        gap = fix_s - (m.last_fix_s or 0.0)
        wall_ms = (time.monotonic() - self._fix_wall_s.get(vid, 0.0)) * 1000.0
        self._say(
            EventKind.LINK,
            f"telemetry back after {gap:.1f} s ({wall_ms:.0f} ms wall); re-deciding",
            vid,
        )
        self._feed(act.LinkBack(vid))

    def _went_silent(self, m: Member) -> bool:
        """Say when a flying vehicle's position reports stop (the mission carries on)."""
        if m.last_fix_s is None or self.start_utc_s is None:
            return False
        age = self.now_s() - m.last_fix_s
        wall_s = time.monotonic() - self._fix_wall_s.get(m.vehicle_id, 0.0)
        cfg = self.config
        if (
            m.phase in ("takeoff", "route")
            and age > (self._silence_s() if self.clock.paced else cfg.link_silence_s)
            and (self.clock.paced or wall_s > cfg.link_silence_wall_s)
        ):
            self._say(
                EventKind.LINK,
                f"no position for {age:.1f} s ({wall_s * 1000:.0f} ms wall): the vehicle flies "
                "its uploaded mission and last speed meanwhile",
                m.vehicle_id,
            )
            self._feed(act.LinkSilent(m.vehicle_id))
            return True
        return False

    def _on_status(self, vid: str, msg: Any) -> None:
        """A HEARTBEAT (armed, MAV_STATE_EMERGENCY) or a STATUSTEXT at MAV_SEVERITY_CRITICAL
        or worse, for the controller's supervision."""
        if msg.get_type() == "HEARTBEAT":
            self._feed(
                act.Heartbeat(
                    vid,
                    bool(msg.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED),
                    msg.system_status == mavlink2.MAV_STATE_EMERGENCY,
                )
            )
        elif msg.severity <= mavlink2.MAV_SEVERITY_CRITICAL:
            text = msg.text.decode(errors="replace") if isinstance(msg.text, bytes) else msg.text
            self._feed(act.Alarm(vid, int(msg.severity), text.rstrip("\x00")))

    def _on_fix(self, vid: str, vehicle: Vehicle) -> None:
        st = vehicle.state
        if st.lat_deg is None or st.lon_deg is None or st.position_time_boot_s is None:
            return
        utc = self.clock.utc_of_boot(vehicle.system_id, st.position_time_boot_s)
        if utc is None or self.start_utc_s is None:
            return
        self._fix_wall_s[vid] = time.monotonic()
        fix_rx, hud_rx = st.rx_times.get("GLOBAL_POSITION_INT"), st.rx_times.get("VFR_HUD")
        fresh = (
            fix_rx is not None
            and hud_rx is not None
            and abs(fix_rx - hud_rx) * self.clock.rate <= 1.5
        )
        climb = st.climb_m_s if st.climb_m_s is not None else -(st.vd_m_s or 0.0)
        fix = act.Fix(
            vid,
            utc,
            st.lat_deg,
            st.lon_deg,
            st.alt_amsl_m,
            st.airspeed_m_s,
            st.groundspeed_m_s,
            st.heading_deg,
            st.ve_m_s,
            st.vn_m_s,
            climb,
            st.mission_current_seq,
            st.wind_speed_m_s,
            st.wind_from_deg,
            fresh,
        )
        self._take_fix(fix)

    def _take_fix(self, fix: act.Fix) -> None:
        """Feed a fix to the team, or keep it until the planning jobs in lock step are done
        (:meth:`_take_deferred`)."""
        if self._computing:
            self._deferred.append(fix)
        else:
            self._feed(fix)

    # -- operator requests ----------------------------------------------------------------------

    def add_threat(self, threat: Threat, at_s: float | None = None) -> None:
        """A threat for the mission (see :meth:`TeamController.add_threat`); before the start
        it is queued."""
        team = self._team()
        team.add_threat(threat, self.now_s(), at_s)
        added = team.extra_threats[-1]
        when = added.appears.at_s if added.appears and added.appears.at_s is not None else None
        self._say(
            EventKind.POPUP,
            f"threat {threat.id} added" + ("" if when is None else f"; appears at {when:.1f} s"),
            payload={"threat": added.model_dump(mode="json", exclude_none=True)},
        )

    def remove_threat(self, threat_id: str) -> None:
        self._dispatch(self._team().remove_threat(threat_id, self.now_s()))

    def move_team_time(self, arrival_s: float, *, version: int | None = None) -> int:
        """Move the team arrival (mission s); returns the new team-time version.

        Raises
        ------
        TeamTimeRefused
            Some vehicle cannot make it (the earliest feasible time and that vehicle).
        """
        team = self._team()
        self._dispatch(team.move_team_time(arrival_s, self.now_s(), version=version))
        return team.version

    async def abort(
        self, vehicle_id: str | None = None, *, mode: act.AbortMode = "rtl"
    ) -> dict[str, str | None]:
        """Abort one vehicle (or every one): it leaves the team and flies home (``rtl``) or
        circles where it is (``loiter``); a vehicle still on the ground stays there. The rest
        keep their arrival time. Returns per vehicle None (done) or why not.

        Raises
        ------
        KeyError
            No such vehicle in the flight (named).
        """
        results, actions = self._team().abort(vehicle_id, mode, self.now_s())
        modes = [a for a in actions if isinstance(a, act.SetMode)]
        self._dispatch(a for a in actions if not isinstance(a, act.SetMode))
        errors = await asyncio.gather(*(self._set_mode(a) for a in modes))
        for a, err in zip(modes, errors, strict=True):
            results[a.vehicle_id] = err
        return results

    # -- restart --------------------------------------------------------------------------------

    @classmethod
    def resume(
        cls,
        checkpoint: bytes,
        clock: MissionClock,
        *,
        bus: EventBus | None = None,
        events: Sequence[FlightEvent] = (),
        on_event: Callable[[FlightEvent], None] | None = None,
    ) -> FlightRunner:
        """A runner for a flight that was running when its process died, from the last
        checkpoint its store kept (``events``: those the store kept, for the record).

        Raises
        ------
        GcsError
            The checkpoint is not one this version reads.
        """
        doc = pickle.loads(checkpoint)
        if not isinstance(doc, dict) or doc.get("format") != CHECKPOINT_FORMAT:
            raise GcsError(f"flight checkpoint is not {CHECKPOINT_FORMAT}")
        team: TeamController = doc["team"]
        team.rebind_world(build_world(team.scenario))
        runner = cls(team.scenario, clock, config=team.config, bus=bus, on_event=on_event)
        runner.team = team
        runner.rng = team.rng
        runner.events = list(events)
        runner.adjustments = [e for e in events if e.strategy is not None]
        runner.state = FlightState.READY
        runner.resumed = True
        team.restarted()
        return runner

    async def reconcile(self) -> dict[str, str]:
        """After :meth:`resume` and :meth:`bind`: compare each vehicle's mission and state with
        the checkpoint's; re-upload only a mission that differs; adopt a launch or an upload
        that happened after the last checkpoint. Returns per vehicle what was found."""
        team = self._team()
        found: dict[str, str] = {}

        async def one(vid: str, m: Member) -> None:
            v = self.vehicles[vid]
            try:
                got = await v.download_mission()
            except GcsError as err:
                found[vid] = f"mission not read ({err}); flying on what it has"
                return
            pending = team.pending.get(vid)
            if mission_client.held_difference(v.link, v.system_id, m.mission.items, got) is None:
                found[vid] = "holds the kept mission"
                if pending is not None:
                    del team.pending[vid]
            elif pending is not None and (
                mission_client.held_difference(v.link, v.system_id, pending.mission.items, got)
                is None
            ):
                found[vid] = f"holds the mission sent before the restart ({pending.what})"
                self._feed(act.Installed(pending, said=pending.told_in(self.events)))
            else:
                k = mission_client.held_difference(v.link, v.system_id, m.mission.items, got)
                found[vid] = f"its mission differs at item {k}; uploading the kept one"
                up = act.Upload(
                    vid, m.mission, m.schedule, None, "kept mission", m.phase != "ground"
                )
                failed = await self._outcome(self._upload(up))
                if failed is not None:
                    found[vid] += f" failed ({failed})"
            st = v.state
            if m.phase == "ground" and st.armed and st.mode == "AUTO":
                m.phase = "takeoff"
                m.launched_s = self.now_s()
                found[vid] += "; armed in AUTO: launched before the restart"
            elif m.phase in ("takeoff", "route") and st.armed is False:
                found[vid] += "; not armed (it was flying)"

        # On a pace clock the simulator waits while the missions are read back (and a kept one
        # sent again), as for an upload in flight (PACED_UPLOAD_HOLD_WALL_S): the transfers'
        # wall-timed round trips and resends take no flight time. Read on a running simulator,
        # the vehicles flew on unwatched 100-250 s of flight past the restart, more the busier
        # the machine.
        with self._held_clock(PACED_UPLOAD_HOLD_WALL_S):
            await asyncio.gather(*(one(vid, m) for vid, m in team.members.items() if not m.done))
        for vid, what in found.items():
            self._say(EventKind.FLIGHT, f"resumed: {what}", vid)
        return found

    async def close(self) -> None:
        for task in list(self._loose):
            task.cancel()
        for task in list(self._loose):
            with contextlib.suppress(BaseException):
                await task
        for detach in self._detach:
            detach()
        self._detach.clear()

"""One vehicle of a team in flight, as the team controller sees it (no link, no clock).

A :class:`Member` holds the vehicle's schedule, the mission it flies, its route track and what
was last seen of it (mission times are seconds since the mission start; UTC fields are the
team clock's). :class:`VehicleState` is what an operator is shown.
"""

from __future__ import annotations

import bisect
import enum
import math
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from gcs.coordination.arrival import ArrivalController, Decision, SpeedLimits
from gcs.coordination.resolution import Resolution
from gcs.coordination.routetrack import LoiterSpec, RouteTrack
from gcs.coordination.speedbias import SpeedBiasEstimator
from gcs.coordination.tracks import TruthSample
from planner.mission import MAV_CMD_NAV_LOITER_TURNS
from planner.schedule import VehicleSchedule
from planner.schedulefile import PathMission
from planner.wind import Wind

__all__ = [
    "Lost",
    "Member",
    "Phase",
    "VehicleState",
    "path_en",
    "route_track",
]

Phase = Literal["ground", "takeoff", "route", "arrived", "aborted", "lost"]
"""Where a vehicle is in its mission (the flight record's per-vehicle ``state``)."""
DONE: frozenset[str] = frozenset({"arrived", "aborted", "lost"})
LostCause = Literal["crash", "stall"]


class VehicleState(enum.StrEnum):
    """What an operator is shown for a vehicle (finer than its :data:`Phase`)."""

    WAITING_TAKEOFF = "waiting_takeoff"
    CLIMBING = "climbing"
    JOINING = "joining"
    """Climbed out, but farther than ``off_route_m`` from its route."""
    ON_ROUTE = "on_route"
    LOITERING = "loitering"
    HOLDING = "holding"
    """Holding short of a forbidden zone its route enters, with no route around it on board
    yet (the safe fallback)."""
    LINK_SILENT = "link_silent"
    """In the air with no position report for longer than the silence threshold."""
    ARRIVED = "arrived"
    LANDING = "landing"
    """Past its slot fix, gliding to the runway (landing slots)."""
    LANDED = "landed"
    """Down on the runway and disarmed after its slot."""
    ABORTED = "aborted"
    CRASHED = "crashed"
    """It reported a crash (STATUSTEXT "Crash ...", MAV_STATE_EMERGENCY, disarmed on its route)."""
    LOST = "lost"
    """Its progress along its route stalled for longer than ``stall_bound_s``."""


VIA_SLOT_TOL_S = 0.5
"""A place its schedule times a vehicle through is flown to while its slot is still the one
so timed, within this (s)."""


@dataclass(frozen=True)
class Lost:
    """Why and when a vehicle was lost to the team (mission s)."""

    cause: LostCause
    t_s: float
    why: str


@dataclass
class Member:
    """One vehicle of the team in flight."""

    vehicle_id: str
    limits: SpeedLimits
    offset_s: float
    """Its slot: the team arrival time plus this."""
    schedule: VehicleSchedule
    mission: PathMission
    track: RouteTrack
    controller: ArrivalController
    target_s: float
    takeoff_s: float
    planned_s: float = math.nan
    """Its slot as the schedule set it before launch (``target_s`` then; mission s)."""
    phase: Phase = "ground"
    arm_sent: bool = False
    """Armed ahead of the takeoff time (:class:`gcs.coordination.actions.Arm` sent)."""
    launched_s: float | None = None
    """Mission time it was armed and put in AUTO."""
    level_m_s: float | None = None
    """The airspeed it flies (commanded, or set by a DO_CHANGE_SPEED item it passed)."""
    s_m: float | None = None
    cross_track_m: float = 0.0
    groundspeed_m_s: float = 0.0
    airspeed_m_s: float | None = None
    east_m: float | None = None
    north_m: float | None = None
    alt_amsl_m: float | None = None
    climb_m_s: float = 0.0
    """Its vertical speed at its last fix (up +), m/s."""
    heading_deg: float | None = None
    joining: bool = False
    """Off its route by more than ``off_route_m`` when last late (said once per episode)."""
    late_said: bool = False
    """A lateness the team time cannot follow (others had arrived, or past its window) was
    said (an alarm, once)."""
    speed_refusals: int = 0
    """Speed commands the vehicle refused in a row (an alarm at ``SPEED_REFUSALS_ALARM``)."""
    link_silent: bool = False
    last_seq: int | None = None
    next_decision_s: float = -math.inf
    busy_command: bool = False
    busy_mission: bool = False
    last_loiter_s: float = -math.inf
    loiter_entered_s: float | None = None
    """Mission time its current mission item last became a loiter (turns flown since)."""
    loiter_flown_m: float = 0.0
    """Ground distance flown since then (each fix's groundspeed times the time since the one
    before, link gaps included: the aircraft flew on)."""
    leaving_seq: int | None = None
    """The item after the loiter it is being taken out of (a
    :class:`~gcs.coordination.actions.LeaveLoiter` on its way)."""
    arrival_s: float | None = None
    """Mission time it passed its goal (from its own telemetry)."""
    landing_due: bool = False
    """Arrived at its slot fix and not yet down (landing slots): still watched."""
    landed_s: float | None = None
    """Mission time it was down and disarmed after its slot."""
    landed_en_m: tuple[float, float] | None = None
    near_goal: list[TruthSample] = field(default_factory=list)
    goal_en_m: tuple[float, float] = (0.0, 0.0)
    last_fix_s: float | None = None
    heard_since_s: float = -math.inf
    """Mission time since which its fixes have come without a gap longer than
    ``resettle_gap_s`` (the flight's first fixes count from the start)."""
    last_decision: Decision | None = None
    """Its last decision for its slot (a pass timed on the way changes only what it flies)."""
    via_track: RouteTrack | None = None
    """Its route up to the place its schedule times it through (:attr:`planner.schedule.
    VehicleSchedule.via`), built when first flown to."""
    eta_min_seen: tuple[tuple[float, float], ...] = ()
    """``(when, eta_min_s)`` of its last two decisions, mission s: a vehicle heard again after
    a gap moves the team time only when they agree (``resettle_drift``)."""
    wind: Wind | None = None
    """The wind its last decision was timed in (its estimate, corrected): re-plans and
    re-times in flight count on it instead of the forecast."""
    wind_reported: bool = False
    """It has reported its own wind estimate (WIND): timed with that, never a working-out."""
    track_log: list[list[float]] = field(default_factory=list)
    """``[utc_s, east_m, north_m, alt_m, airspeed_m_s, groundspeed_m_s]`` every 2 s."""
    commanded: list[list[Any]] = field(default_factory=list)
    planned_paths: list[dict[str, Any]] = field(default_factory=list)
    loiter_log: list[dict[str, Any]] = field(default_factory=list)
    bias: SpeedBiasEstimator = field(default_factory=SpeedBiasEstimator)
    """What the aircraft really flies for a commanded airspeed, learnt from its fixes."""
    state: VehicleState = VehicleState.WAITING_TAKEOFF
    """The last state said (see :meth:`current_state`)."""
    joined: bool = False
    """It has been within ``off_route_m`` of its route since its climb-out (its progress is
    watched from then on)."""
    progress: tuple[RouteTrack, float, float] | None = None
    """``(track, s_m, t_s)``: the farthest it has come along that track and when it got there
    (mission s); a new track (a re-plan, new loiters) starts it again."""
    still: tuple[float, float, float, int] | None = None
    """``(east_m, north_m, t_s, fixes)``: where a fix last found it more than ``stopped_m`` from
    the one before, when (mission s), and how many fixes since found it there."""
    lost: Lost | None = None
    splice_seq: int | None = None
    """The waypoint after which its mission was last replaced in flight."""
    rejoin_seq: int | None = None
    """After a hold: the item it resumed at. Until it passes it, it flies to it from where it
    held (perhaps back along the route), which is no stall."""
    hold_zone: str | None = None
    """The zone it is told to hold short of (from the hold command to its resumption): not
    timed, not watched for progress meanwhile."""
    leave_hold_s: float | None = None
    """When the route installed while it holds has it leave its hold point (mission s): it
    holds until then, so that it flies the route at the times it was planned for."""
    resolving: Resolution | None = None
    """The speed it flies to keep the separation from another vehicle, until when: not timed
    for its slot meanwhile."""
    next_resolve_s: float = -math.inf
    """When its pairs are next predicted for resolution."""
    _loiter_seqs: tuple[PathMission, tuple[int, ...]] | None = field(
        default=None, init=False, repr=False, compare=False
    )
    """``(mission, seqs)``: the seqs of that mission's loiter items (:meth:`loiter_seqs`)."""

    def tas_per_eas(self, s_m: float) -> float:
        """True airspeed flown per unit commanded from ``s_m`` on: the route's atmosphere
        (the autopilot commands equivalent airspeed) times the scale learnt in flight."""
        return self.schedule.tas_per_eas(s_m) * self.bias.scale

    def tas_m_s(self, s_m: float) -> float | None:
        """Its true airspeed from ``s_m`` on (m/s): its last airspeed reported, as flown there
        (:meth:`tas_per_eas`); None before one is reported."""
        if not self.airspeed_m_s:
            return None
        return self.airspeed_m_s * self.tas_per_eas(s_m)

    @property
    def done(self) -> bool:
        """No longer timed (arrived, aborted or lost)."""
        return self.phase in DONE

    @property
    def over(self) -> bool:
        """Neither timed nor watched: done, and down if it lands after its slot."""
        return self.phase in DONE and not (self.phase == "arrived" and self.landing_due)

    def via_live(self) -> tuple[float, float] | None:
        """The place and time its schedule times it through (:attr:`planner.schedule.
        VehicleSchedule.via`) while its slot is still the one so timed (within
        :data:`VIA_SLOT_TOL_S`): once the team time has moved, the pass no longer keeps what it
        kept."""
        via = self.schedule.via
        if via is None or abs(self.target_s - self.schedule.arrival_s) > VIA_SLOT_TOL_S:
            return None
        return via

    def on_final(self, final_m: float) -> bool:
        """Within ``final_m`` of its goal along its route: its final approach, where no speed
        is asked any more."""
        return self.s_m is not None and self.track.length_m - self.s_m < final_m

    def in_loiter(self) -> bool:
        seq = self.last_seq
        if seq is None:
            return False
        items = self.mission.items
        return items[min(seq, len(items) - 1)].command == MAV_CMD_NAV_LOITER_TURNS

    def loiter_seqs(self) -> tuple[int, ...]:
        """The seqs of its mission's loiter items, in order: read once per mission installed
        (it is asked at every fix)."""
        cached = self._loiter_seqs
        if cached is None or cached[0] is not self.mission:
            seqs = tuple(
                k
                for k, it in enumerate(self.mission.items)
                if it.command == MAV_CMD_NAV_LOITER_TURNS
            )
            cached = self._loiter_seqs = (self.mission, seqs)
        return cached[1]

    def loiters_done(self) -> int:
        """Its mission's loiter items before the item it flies to."""
        return bisect.bisect_left(self.loiter_seqs(), self.last_seq or 0)

    def loiter_turns_left(self) -> float:
        """Loiter turns still ahead in its mission."""
        seq = self.last_seq or 0
        return float(
            sum(
                it.param1
                for k, it in enumerate(self.mission.items)
                if it.command == MAV_CMD_NAV_LOITER_TURNS and k >= seq
            )
        )

    def current_state(self, off_route_m: float) -> VehicleState:
        if self.phase == "arrived":
            if self.landed_s is not None:
                return VehicleState.LANDED
            return VehicleState.LANDING if self.landing_due else VehicleState.ARRIVED
        if self.phase == "aborted":
            return VehicleState.ABORTED
        if self.lost is not None:
            return VehicleState.CRASHED if self.lost.cause == "crash" else VehicleState.LOST
        if self.phase == "ground":
            return VehicleState.WAITING_TAKEOFF
        if self.link_silent:
            return VehicleState.LINK_SILENT
        if self.phase == "takeoff":
            return VehicleState.CLIMBING
        if self.hold_zone is not None:
            return VehicleState.HOLDING
        if self.in_loiter():
            return VehicleState.LOITERING
        if self.cross_track_m > off_route_m:
            return VehicleState.JOINING
        return VehicleState.ON_ROUTE


def route_track(vs: VehicleSchedule, up_to_m: float | None = None) -> RouteTrack:
    """The schedule's route and loiter turns as flown (up to ``up_to_m`` along it: to the
    place it is timed through)."""
    if up_to_m is not None:
        head = vs.path.prefix(up_to_m)
        assert head is not None, "a place on the path ahead"
        vs = replace(vs, path=head, loiters=tuple(lo for lo in vs.loiters if lo.s_m <= up_to_m))
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


def path_en(vs: VehicleSchedule, step_m: float = 500.0) -> list[list[float]]:
    """The planned path as ``[east_m, north_m]`` points ``step_m`` apart (for drawing)."""
    n = max(2, int(vs.path.length_m / step_m) + 1)
    out = []
    for s in np.linspace(0.0, vs.path.length_m, n):
        p = vs.path.pose_at(float(s))
        out.append([round(p.east_m, 1), round(p.north_m, 1)])
    return out

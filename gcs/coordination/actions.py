"""What goes into the team controller and what comes out of it.

Inputs are observations (a position fix, a tick of the mission clock, a link going silent)
and the outcomes of actions the runner carried out (a launch, a speed command, an upload, a
planning job). Actions are what the runner is asked to do on the vehicles, plus
:class:`Report` (an event to publish) and :class:`Compute` (pure planning work to run off the
control loop; its result comes back as :class:`Computed`). Every type here is plain data.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from gcs.coordination.events import EventKind, FlightEvent
from planner.mission import MissionItem, items_equal
from planner.plan import Method, World
from planner.popup import apply_popup
from planner.retime import retime_vehicle
from planner.schedule import Adjustment, Anchor, Schedule, VehicleSchedule
from planner.schedulefile import PathMission
from planner.terrain import Terrain
from planner.threats import ThreatZone

AbortMode = Literal["rtl", "loiter"]

# -- inputs ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Tick:
    """The mission clock moved on: launches, pop-ups and the overrun are checked."""


@dataclass(frozen=True)
class Fix:
    """A position report of a vehicle, with what it says of its speeds and the wind."""

    vehicle_id: str
    utc_s: float
    """When the position was taken, on the team clock."""
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float | None = None
    airspeed_m_s: float | None = None
    """What the autopilot reports (VFR_HUD: equivalent airspeed)."""
    groundspeed_m_s: float | None = None
    heading_deg: float | None = None
    ve_m_s: float | None = None
    vn_m_s: float | None = None
    climb_m_s: float | None = None
    mission_seq: int | None = None
    wind_speed_m_s: float | None = None
    wind_from_deg: float | None = None
    airspeed_fresh: bool = True
    """The airspeed was reported at the moment of the fix (a stale one teaches no bias)."""


@dataclass(frozen=True)
class Heartbeat:
    """What a vehicle's HEARTBEAT says of it."""

    vehicle_id: str
    armed: bool
    emergency: bool
    """system_status MAV_STATE_EMERGENCY (ArduPlane: it has detected a crash)."""


@dataclass(frozen=True)
class Alarm:
    """A STATUSTEXT at MAV_SEVERITY_CRITICAL or worse (0 emergency .. 2 critical)."""

    vehicle_id: str
    severity: int
    text: str


@dataclass(frozen=True)
class LinkSilent:
    vehicle_id: str


@dataclass(frozen=True)
class LinkBack:
    vehicle_id: str


@dataclass(frozen=True)
class Launched:
    """The outcome of :class:`Launch` (``error`` None: armed and in AUTO)."""

    vehicle_id: str
    error: str | None = None


@dataclass(frozen=True)
class SpeedCommanded:
    """The outcome of :class:`CommandSpeed`."""

    vehicle_id: str
    airspeed_m_s: float
    reason: str
    decided_s: float
    error: str | None = None


@dataclass(frozen=True)
class AltitudeCommanded:
    """The outcome of :class:`CommandAltitude`."""

    vehicle_id: str
    alt_m: float
    above_home: bool
    decided_s: float
    error: str | None = None


@dataclass(frozen=True)
class Installed:
    """The outcome of :class:`Upload` (``skipped``: the vehicle had passed the splice
    waypoint, so it was not sent; ``said``: its events were told and kept before a restart,
    and are not told again)."""

    upload: Upload
    error: str | None = None
    skipped: bool = False
    said: bool = False


@dataclass(frozen=True)
class Computed:
    """The outcome of :class:`Compute`: the job's result, or the planner error it raised."""

    job: LoiterJob | PopupJob
    result: Any = None
    error: Exception | None = None
    wall_s: float = 0.0


@dataclass(frozen=True)
class HoldTaken:
    """The outcome of :class:`Hold` (``error`` None: the vehicle flies to the point and
    circles it)."""

    hold: Hold
    error: str | None = None


@dataclass(frozen=True)
class Resumed:
    """The outcome of :class:`Resume` (``error`` None: back in AUTO at the item)."""

    resume: Resume
    error: str | None = None


@dataclass(frozen=True)
class LoiterLeft:
    """The outcome of :class:`LeaveLoiter` (``error`` None: it flies the item after)."""

    leave: LeaveLoiter
    error: str | None = None


@dataclass(frozen=True)
class PlanningLead:
    """How far ahead (mission s) a changed mission may start: the runner's measure of
    planning plus upload time at the clock's rate."""

    lead_s: float
    """For a pop-up re-plan (the team's planning)."""
    loiter_lead_s: float | None = None
    """For loiter turns (one vehicle re-timed: fast); None: ``lead_s``."""


# -- actions --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Report:
    """An event to publish (times in mission s)."""

    kind: EventKind
    reason: str
    vehicle: str | None = None
    strategy: str | None = None
    value: float | None = None
    t_s: float | None = None
    payload: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Arm:
    """Arm a vehicle on the ground ahead of its takeoff time, so that :class:`Launch` has only
    AUTO left to send (ArduPlane waits on the ground, armed, until AUTO starts the takeoff).
    Best effort: the launch arms a vehicle that does not report itself armed."""

    vehicle_id: str


@dataclass(frozen=True)
class Launch:
    """Arm the vehicle and put it in AUTO (only AUTO when ``airborne``: it is flying; or when
    it reports itself armed already, after :class:`Arm`)."""

    vehicle_id: str
    airborne: bool = False


@dataclass(frozen=True)
class CommandSpeed:
    vehicle_id: str
    airspeed_m_s: float
    reason: str
    decided_s: float


@dataclass(frozen=True)
class CommandAltitude:
    """The altitude of the waypoint the vehicle flies to now (MAV_CMD_DO_CHANGE_ALTITUDE):
    AMSL, or above home with ``above_home`` (the mission's own frame)."""

    vehicle_id: str
    alt_m: float
    above_home: bool
    reason: str
    decided_s: float


@dataclass(frozen=True)
class Upload:
    """Upload ``mission`` (the vehicle's new ``schedule``); in flight, only if the vehicle
    has not passed item ``keep_seq`` (the splice waypoint)."""

    vehicle_id: str
    mission: PathMission
    schedule: VehicleSchedule
    keep_seq: int | None
    what: str
    in_flight: bool
    adjustments: tuple[Adjustment, ...] = ()
    """Said once the mission is on board."""
    decided_s: float = 0.0
    holding: bool = False
    """The vehicle holds outside a zone (GUIDED): it is not flying the mission, so its
    current item says nothing about the splice waypoint and the upload goes ahead."""
    leave_hold_s: float | None = None
    """Holding: when its new route has it leave its hold point (mission s)."""

    def payload(self) -> dict[str, Any]:
        """The upload event's payload once the mission is on board."""
        return {"what": self.what, "items": [dataclasses.asdict(it) for it in self.mission.items]}

    def told_in(self, events: Sequence[FlightEvent]) -> bool:
        """Whether a flight's ``events`` already tell this upload on board: the last upload
        they tell of its vehicle (with its items) is this one."""
        told = next(
            (
                e
                for e in reversed(events)
                if e.kind is EventKind.UPLOAD
                and e.vehicle == self.vehicle_id
                and "items" in e.payload
            ),
            None,
        )
        if told is None or told.payload.get("what") != self.what:
            return False
        return items_equal([MissionItem(**it) for it in told.payload["items"]], self.mission.items)


@dataclass(frozen=True)
class SetMode:
    vehicle_id: str
    mode: str
    """The flight mode by name (``RTL``, ``LOITER``)."""


@dataclass(frozen=True)
class Hold:
    """Fly to a point and circle it until told otherwise: the safe fallback short of a
    forbidden zone (MAV_CMD_DO_REPOSITION with the change-mode flag: GUIDED)."""

    vehicle_id: str
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    zone_id: str
    decided_s: float


@dataclass(frozen=True)
class Resume:
    """Back to AUTO from mission item ``seq`` (after a hold, on the route installed since)."""

    vehicle_id: str
    seq: int
    zone_id: str
    decided_s: float


@dataclass(frozen=True)
class LeaveLoiter:
    """Out of the loiter turns now: mission item ``seq`` (the one after the
    NAV_LOITER_TURNS) becomes the current one (MISSION_SET_CURRENT; ArduPlane starts it
    where the aircraft is, AP_Mission::set_current_cmd)."""

    vehicle_id: str
    seq: int
    reason: str
    decided_s: float


@dataclass(frozen=True)
class Stop:
    """The flight is over for the controller (every vehicle done, or it overran)."""

    reason: str


@dataclass(frozen=True)
class LoiterJob:
    """Re-time one vehicle from a splice waypoint with loiter turns (pure; may take a while)."""

    vehicle_id: str
    schedule: Schedule
    keep_seq: int
    now_s: float
    s_m: float
    speed_m_s: float
    target_s: float
    threats: tuple[ThreatZone, ...]
    loiter_margin_m_s: float
    decided_s: float
    terrain: Terrain | None = None
    """With it, turns on the path where no buffer serves (clear of threats and terrain)."""

    def run(self) -> tuple[VehicleSchedule, list[Adjustment]]:
        vs, adjustments = retime_vehicle(
            self.schedule,
            self.vehicle_id,
            now_s=self.now_s,
            s_m=self.s_m,
            speed_m_s=self.speed_m_s,
            target_s=self.target_s,
            threats=list(self.threats),
            loiter_margin_m_s=self.loiter_margin_m_s,
            terrain=self.terrain,
            separate=True,
        )
        return vs, list(adjustments)


@dataclass(frozen=True)
class PopupJob:
    """Re-plan the team around a threat from waypoints ``lead_s`` ahead (pure; slow)."""

    zone: ThreatZone
    schedule: Schedule
    world: World
    threats: tuple[ThreatZone, ...]
    anchors: Mapping[str, Anchor]
    keeps: Mapping[str, int | None]
    method: Method
    rng: np.random.Generator
    loiter_margin_m_s: float
    decided_s: float
    lead_s: float
    holding: frozenset[str] = frozenset()
    """Vehicles re-planned from the point they hold at (anchored there, not ahead)."""
    from_hold: bool = False
    """Asked for by a vehicle holding short of the zone with no route around it (not as the
    zone appeared, nor again after a re-plan that failed)."""
    missions: Mapping[str, PathMission] = field(default_factory=dict)
    """Each vehicle's mission as it was when the job was decided (``keeps`` are its items)."""
    time_up: Callable[[], bool] | None = None
    """Ends the route search with the best routes so far (the runner's wall-clock budget:
    :attr:`planner.aco.AcoOptions.time_up`)."""
    separation_up: Callable[[], bool] | None = None
    """Ends the separation of the re-planned team with what it has separated so far (the
    runner's wall-clock budget: :func:`planner.replanseparation.separate_replan`)."""

    def run(self) -> Any:
        return apply_popup(
            self.schedule,
            self.zone,
            at_s=self.decided_s + self.lead_s,
            world=self.world,
            threats=list(self.threats),
            method=self.method,
            rng=self.rng,
            anchors=dict(self.anchors),
            loiter_margin_m_s=self.loiter_margin_m_s,
            time_up=self.time_up,
            others_may_stay=True,
            separation_up=self.separation_up,
        )


@dataclass(frozen=True)
class Compute:
    job: LoiterJob | PopupJob


Input = (
    Tick
    | Fix
    | Heartbeat
    | Alarm
    | LinkSilent
    | LinkBack
    | Launched
    | SpeedCommanded
    | AltitudeCommanded
    | Installed
    | Computed
    | HoldTaken
    | Resumed
    | LoiterLeft
    | PlanningLead
)
Action = (
    Report
    | Arm
    | Launch
    | CommandSpeed
    | CommandAltitude
    | Upload
    | SetMode
    | Hold
    | Resume
    | LeaveLoiter
    | Stop
    | Compute
)

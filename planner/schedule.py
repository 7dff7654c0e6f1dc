"""The team schedule: each vehicle's timed route (legs, loiters, takeoff and arrival), the
adjustments that timed it, the speed-profile stages and events of the story, and where an
airborne vehicle really is (:class:`Anchor`).

:mod:`planner.retime` builds and re-times a schedule (section 4); :mod:`planner.popup` re-plans
it around pop-up threats (section 5).

Model: a vehicle is at the start of its path at takeoff and flies its leg speeds from there
(climb-out is not modelled). Speeds are equivalent airspeeds, as ArduPlane commands them (the
scenario's limits, every DO_CHANGE_SPEED); they carry the aircraft at the true airspeed of the
air density along the route (:mod:`planner.atmosphere`): a vehicle's remaining path is timed
at ``speed x tas_per_eas``, the route's harmonic-mean ratio from where it is, and each leg and
loiter keeps the ratio it was timed with. A loiter is ``n`` turns on a circle tangent to the
path at a path point (so it adds exactly ``2 n pi r``), or, when no tangent circle fits in a
buffer, on a circle in the buffer reached by a straight out-and-back detour counted in the
length.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from planner.atmosphere import mean_eas2tas
from planner.flightpath import FlightPath
from planner.scenario import Scenario
from planner.timing import SPEED_STEP_M_S, TeamWindow

FloatArray = NDArray[np.float64]
Strategy = Literal["takeoff_delay", "speed", "loiter"]


@dataclass(frozen=True, slots=True)
class Leg:
    """A stretch of the path flown at one speed: along-path distances (m), times (s)."""

    s_start_m: float
    s_end_m: float
    speed_m_s: float
    """Equivalent airspeed commanded, m/s."""
    t_start_s: float
    t_end_s: float
    tas_per_eas: float = 1.0
    """True airspeed per unit of ``speed_m_s`` it was timed with (still air: metres per s)."""

    @property
    def true_airspeed_m_s(self) -> float:
        return self.speed_m_s * self.tas_per_eas


@dataclass(frozen=True, slots=True)
class LoiterPlan:
    """``turns`` circles of ``radius_m`` about a centre, entered at path distance ``s_m``."""

    s_m: float
    centre_east_m: float
    centre_north_m: float
    entry_east_m: float
    """Where the circle is entered (on the path unless there is a detour), m."""
    entry_north_m: float
    radius_m: float
    turns: int
    clockwise: bool
    detour_m: float
    speed_m_s: float
    """Equivalent airspeed, m/s."""
    t_start_s: float
    t_end_s: float
    buffer_id: str
    tas_per_eas: float = 1.0
    """True airspeed per unit of ``speed_m_s`` it was timed with."""

    @property
    def length_m(self) -> float:
        return self.detour_m + 2.0 * math.pi * self.radius_m * self.turns


@dataclass(frozen=True, slots=True)
class Adjustment:
    """One time adjustment: when it was decided, to whom, which strategy and its value."""

    time_s: float
    vehicle: str
    strategy: Strategy
    value: float
    """takeoff_delay: takeoff time, s after the mission start; speed: first new speed, m/s;
    loiter: turns."""
    reason: str


@dataclass(frozen=True, slots=True)
class SpeedSpan:
    """A constant speed over a time span, for the speed-profile plots."""

    t_start_s: float
    t_end_s: float
    speed_m_s: float
    kind: Literal["leg", "loiter", "required"]


@dataclass(frozen=True)
class Stage:
    """The team's speed profiles at one step of the story (pre-plan, takeoff, pop-up ...)."""

    name: str
    time_s: float
    spans: Mapping[str, tuple[SpeedSpan, ...]]


@dataclass(frozen=True)
class VehicleSchedule:
    """One vehicle's timed route."""

    vehicle_id: str
    path: FlightPath
    wp_s_m: FloatArray
    """Along-path distances of the route's altitude waypoints, m."""
    wp_alt_m: FloatArray
    takeoff_s: float
    arrival_s: float
    legs: tuple[Leg, ...]
    loiters: tuple[LoiterPlan, ...]
    speed_min_m_s: float
    speed_max_m_s: float
    airborne_start: bool
    replanned_at_s: tuple[float, ...] = ()

    def alt_at(self, s_m: float) -> float:
        return float(np.interp(s_m, self.wp_s_m, self.wp_alt_m))

    def tas_per_eas(self, s_from_m: float = 0.0) -> float:
        """True per equivalent airspeed that times the path from ``s_from_m`` (ISA)."""
        return mean_eas2tas(self.wp_s_m, self.wp_alt_m, s_from_m=s_from_m)

    def state_at(self, t_s: float) -> tuple[str, float, float]:
        """``(phase, s_m, speed_m_s)`` at time t: phase ground, leg, loiter or arrived."""
        if not self.airborne_start and (not self.legs or t_s < self.takeoff_s):
            return "ground", 0.0, 0.0
        for lo in self.loiters:
            if lo.t_start_s <= t_s < lo.t_end_s:
                return "loiter", lo.s_m, lo.speed_m_s
        for leg in self.legs:
            if leg.t_start_s <= t_s < leg.t_end_s:
                s_m = leg.s_start_m + (t_s - leg.t_start_s) * leg.true_airspeed_m_s
                return "leg", s_m, leg.speed_m_s
        if t_s >= self.arrival_s:
            return "arrived", self.path.length_m, 0.0
        return "leg", 0.0, self.legs[0].speed_m_s if self.legs else 0.0

    def position_at(self, t_s: float) -> tuple[float, float] | None:
        """Horizontal position (m) at time t; None while on the ground or after arrival."""
        if t_s < self.takeoff_s or t_s > self.arrival_s:
            return None
        for lo in self.loiters:
            if lo.t_start_s <= t_s < lo.t_end_s:
                u_m = (t_s - lo.t_start_s) * lo.speed_m_s * lo.tas_per_eas
                return _loiter_position(lo, u_m)
        for leg in self.legs:
            if leg.t_start_s <= t_s <= leg.t_end_s:
                s = leg.s_start_m + (t_s - leg.t_start_s) * leg.true_airspeed_m_s
                p = self.path.pose_at(min(max(s, 0.0), self.path.length_m))
                return p.east_m, p.north_m
        p = self.path.end
        return p.east_m, p.north_m


def _loiter_position(lo: LoiterPlan, u_m: float) -> tuple[float, float]:
    half = 0.5 * lo.detour_m
    pe, pn = lo.entry_east_m, lo.entry_north_m
    if lo.detour_m > 0.0:
        # The path point lies on the line from the centre through the entry point.
        ux, uy = pe - lo.centre_east_m, pn - lo.centre_north_m
        norm = math.hypot(ux, uy) or 1.0
        ux, uy = ux / norm, uy / norm
        path_e, path_n = pe + ux * half, pn + uy * half
        if u_m < half:
            return path_e - ux * u_m, path_n - uy * u_m
        circle = 2.0 * math.pi * lo.radius_m * lo.turns
        if u_m > half + circle:
            back = u_m - half - circle
            return pe + ux * back, pn + uy * back
        u_m -= half
    theta0 = math.atan2(pn - lo.centre_north_m, pe - lo.centre_east_m)
    dtheta = u_m / lo.radius_m
    theta = theta0 - dtheta if lo.clockwise else theta0 + dtheta
    return (
        lo.centre_east_m + lo.radius_m * math.cos(theta),
        lo.centre_north_m + lo.radius_m * math.sin(theta),
    )


@dataclass(frozen=True)
class Event:
    time_s: float
    kind: str
    text: str


@dataclass(frozen=True)
class Schedule:
    """The team's timed routes, the story of how they were timed, and the arrival reference."""

    scenario: Scenario
    requested_arrival_s: float | None
    required_arrival_s: float | None
    arrival_reason: str
    vehicles: tuple[VehicleSchedule, ...]
    adjustments: tuple[Adjustment, ...]
    stages: tuple[Stage, ...]
    events: tuple[Event, ...]
    step_m_s: float = SPEED_STEP_M_S
    offsets_s: Mapping[str, float] = field(default_factory=dict)
    team_window: TeamWindow | None = None
    """The reference arrival times the team could make when the schedule was built, and the
    vehicles that bound them (None for per-vehicle windows); kept through pop-up re-plans."""

    def vehicle(self, vehicle_id: str) -> VehicleSchedule:
        for v in self.vehicles:
            if v.vehicle_id == vehicle_id:
                return v
        raise KeyError(vehicle_id)


class Anchor(NamedTuple):
    """Where an airborne vehicle really is: ``s_m`` along its path at ``speed_m_s``, at
    ``t_s`` (mission s; None: at the re-plan time). A coordinator in flight re-plans from a
    waypoint ahead, which the vehicle reaches at its own time."""

    s_m: float
    speed_m_s: float
    t_s: float | None = None


Anchors = Mapping[str, Anchor]
"""Vehicle id -> its :class:`Anchor`."""

"""The team schedule: each vehicle's timed route (legs, loiters, takeoff and arrival), the
adjustments that timed it, the speed-profile stages and events of the story, and where an
airborne vehicle really is (:class:`Anchor`).

:mod:`planner.retime` builds and re-times a schedule (section 4); :mod:`planner.popup` re-plans
it around pop-up threats (section 5).

Model: a vehicle on the ground takes off at its takeoff time and climbs out along the start of
its path (:mod:`planner.climbout`: the climb's time and where it ends, as ArduPlane flies
NAV_TAKEOFF); from there, or from its start when it is already flying, it flies its leg
speeds. Speeds are equivalent airspeeds, as ArduPlane commands them (the scenario's limits,
every DO_CHANGE_SPEED); they carry the aircraft at the true airspeed of the air density along
the route (:mod:`planner.atmosphere`), and over the ground with the wind the schedule counts on
(:attr:`VehicleSchedule.wind`: the forecast, then what the vehicles measure in flight). A
vehicle's remaining path is timed at ``speed x ground_per_eas``, the route's ground metres per
metre of equivalent airspeed from where it is (the harmonic mean of the true airspeed ratio,
with the wind triangle on each piece of the track). Each leg keeps the span it was timed
with; a loiter is timed at its true airspeed (the wind averages out over whole turns). A
loiter is ``n`` turns on a circle tangent to the path at a path point (so it adds exactly
``2 n pi r``), or, when no tangent circle fits in a buffer, on a circle in the buffer reached
by a straight out-and-back detour counted in the length.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from planner.atmosphere import (
    ISA_SEA_LEVEL_DENSITY_KG_M3,
    density_kg_m3,
    eas2tas_table,
    mean_eas2tas_from,
)
from planner.climbout import ClimbOut
from planner.flightpath import FlightPath
from planner.scenario import Scenario
from planner.timing import SPEED_STEP_M_S, TeamWindow
from planner.wind import CALM, Wind, groundspeed_m_s

FloatArray = NDArray[np.float64]
_TRACK_STEP_M = 2_000.0
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
    """True airspeed per unit of ``speed_m_s`` it was timed with."""

    @property
    def true_airspeed_m_s(self) -> float:
        return self.speed_m_s * self.tas_per_eas

    @property
    def groundspeed_m_s(self) -> float:
        """Mean speed over the ground it was timed with (the wind included), m/s."""
        span = self.t_end_s - self.t_start_s
        return (self.s_end_m - self.s_start_m) / span if span > 0.0 else self.true_airspeed_m_s

    def s_at(self, t_s: float) -> float:
        """Along-path distance at a time of the leg (its mean ground speed), m."""
        return self.s_start_m + (t_s - self.t_start_s) * self.groundspeed_m_s


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
    climb: ClimbOut | None = None
    """The takeoff's climb-out (None: flying at its start, or not worked out)."""
    wind: Wind = CALM
    """The wind its timing counts on: the forecast, then the one measured in flight."""
    via: tuple[float, float] | None = None
    """``(s_m, t_s)``: timed to pass ``s_m`` along its path at mission time ``t_s`` on its way
    to its slot (a re-plan's separation by timing, :func:`planner.replantiming.
    retime_through`): the flight aims there first. None: timed for its slot alone."""

    def alt_at(self, s_m: float) -> float:
        return float(np.interp(s_m, self.wp_s_m, self.wp_alt_m))

    def tas_per_eas(self, s_from_m: float = 0.0) -> float:
        """True per equivalent airspeed that times the path from ``s_from_m`` (ISA), from
        the path's table kept with the schedule (it is asked at every cruise speed tried
        when timing, and at every fix in flight)."""
        return mean_eas2tas_from(self._eas2tas_table, s_from_m)

    @cached_property
    def _eas2tas_table(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        return eas2tas_table(self.wp_s_m, self.wp_alt_m)

    @cached_property
    def _track(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """The path as constant-track pieces (straights whole, arcs every 5 deg): start s
        (m), length (m), track (rad) and true per equivalent airspeed at its middle."""
        pts = self.path.sample(_TRACK_STEP_M)
        d = np.hypot(np.diff(pts[:, 0]), np.diff(pts[:, 1]))
        keep = d > 1e-9
        # Each piece's chord, scaled to the path's length (arcs are a little longer).
        length = d[keep] * (self.path.length_m / max(float(d.sum()), 1e-9))
        start = np.concatenate([[0.0], np.cumsum(length)[:-1]])
        track = np.arctan2(np.diff(pts[:, 0]), np.diff(pts[:, 1]))[keep]
        alt = np.interp(start + 0.5 * length, self.wp_s_m, self.wp_alt_m)
        ratio = np.sqrt(ISA_SEA_LEVEL_DENSITY_KG_M3 / density_kg_m3(alt))
        return start, length, track, ratio

    def ground_per_eas(self, s_from_m: float, eas_m_s: float) -> float:
        """Ground metres per metre of equivalent airspeed flying the path from ``s_from_m``
        at ``eas_m_s`` in :attr:`wind`: the rest of the path takes ``remaining / (eas_m_s x
        this)`` seconds. Without wind it is :meth:`tas_per_eas`; inf where the wind stops
        the aircraft on some piece."""
        if self.wind.calm:
            return self.tas_per_eas(s_from_m)
        start, length, track, ratio = self._track
        end = start + length
        part = np.clip(end - np.maximum(start, s_from_m), 0.0, None)
        if not (part > 0.0).any():
            return self.tas_per_eas(s_from_m)
        gs = groundspeed_m_s(eas_m_s * ratio, track, self.wind)
        if (gs[part > 0.0] <= 0.0).any():
            return 0.0
        seconds = float(np.sum(part[part > 0.0] / gs[part > 0.0]))
        return float(part.sum()) / (eas_m_s * seconds)

    @property
    def climb_end_s(self) -> float:
        """When its climb-out ends (its takeoff when none is modelled), mission s."""
        return self.takeoff_s + (0.0 if self.climb is None else self.climb.duration_s)

    @property
    def climb_s_m(self) -> float:
        """Along-path distance where its climb-out ends (0 when none is modelled), m."""
        return 0.0 if self.climb is None else self.climb.s_m

    def state_at(self, t_s: float) -> tuple[str, float, float]:
        """``(phase, s_m, speed_m_s)`` at time t: phase ground, climb, leg, loiter or
        arrived (in the climb: where it is along the path, at no commanded speed)."""
        if not self.airborne_start and (not self.legs or t_s < self.takeoff_s):
            return "ground", 0.0, 0.0
        if not self.airborne_start and t_s < self.climb_end_s:
            span = max(self.climb_end_s - self.takeoff_s, 1e-9)
            return "climb", self.climb_s_m * (t_s - self.takeoff_s) / span, 0.0
        for lo in self.loiters:
            if lo.t_start_s <= t_s < lo.t_end_s:
                return "loiter", lo.s_m, lo.speed_m_s
        for leg in self.legs:
            if leg.t_start_s <= t_s < leg.t_end_s:
                return "leg", leg.s_at(t_s), leg.speed_m_s
        if t_s >= self.arrival_s:
            return "arrived", self.path.length_m, 0.0
        return "leg", self.climb_s_m, self.legs[0].speed_m_s if self.legs else 0.0

    def position_at(self, t_s: float) -> tuple[float, float] | None:
        """Horizontal position (m) at time t; None while on the ground or after arrival."""
        if t_s < self.takeoff_s or t_s > self.arrival_s:
            return None
        for lo in self.loiters:
            if lo.t_start_s <= t_s < lo.t_end_s:
                u_m = (t_s - lo.t_start_s) * lo.speed_m_s * lo.tas_per_eas
                return loiter_position(lo, u_m)
        s: float | None = None
        if not self.airborne_start and t_s < self.climb_end_s:
            s = self.state_at(t_s)[1]
        for leg in self.legs:
            if s is None and leg.t_start_s <= t_s <= leg.t_end_s:
                s = leg.s_at(t_s)
        p = self.path.end if s is None else self.path.pose_at(min(max(s, 0.0), self.path.length_m))
        return p.east_m, p.north_m


def loiter_position(lo: LoiterPlan, u_m: float) -> tuple[float, float]:
    """Where a vehicle is ``u_m`` metres into a loiter (the detour out to the circle, the turns,
    the way back to the path), m."""
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
    payload: Mapping[str, Any] = field(default_factory=dict)
    """What a program reads of it (a conflict's pair, distance and time)."""


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

"""The team schedule: takeoffs, discrete speeds and loiters on flyable paths (section 4), and
the offline replay of pop-up threats (section 5).

:func:`build_schedule` times a :class:`~planner.plan.Plan`: the team arrival time from the
vehicles' windows (eq. 1), each vehicle on the ground moved to take off on time at cruise speed
(eq. 5), the remainder trimmed by two discrete speeds (eqs. 6-7), and loiter turns in a buffer
area where the speed range cannot absorb the surplus (eqs. 8-9).

:func:`replay_popups` flies that schedule up to each pop-up threat's appearance, re-plans the
vehicles whose remaining route the threat touches from where they are, and re-times the team
for the same arrival time, or the earliest common one when that is no longer feasible.

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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from planner.atmosphere import mean_eas2tas
from planner.errors import InfeasibleError
from planner.flightpath import FlightPath, Segment
from planner.plan import Method, Plan, World, build_problem, build_world, solve_and_finish
from planner.scenario import Scenario, Simultaneous, Spaced, Vehicle, Windows
from planner.threats import ThreatZone, active, build_threats
from planner.timing import (
    SPEED_STEP_M_S,
    TIME_TOL_S,
    ArrivalWindow,
    LoiterSite,
    Piece,
    SpeedLimits,
    Timing,
    flyable_loiter_radius_m,
    takeoff_time_s,
    team_arrival,
    time_path,
    vehicle_window,
)

FloatArray = NDArray[np.float64]
Strategy = Literal["takeoff_delay", "speed", "loiter"]
SITE_STEP_M = 100.0


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

    def vehicle(self, vehicle_id: str) -> VehicleSchedule:
        for v in self.vehicles:
            if v.vehicle_id == vehicle_id:
                return v
        raise KeyError(vehicle_id)


# --- geometry helpers ------------------------------------------------------------------


def truncate_path(path: FlightPath, s_m: float) -> FlightPath | None:
    """The first ``s_m`` metres of a path (None when ``s_m`` is ~0)."""
    if s_m <= 1e-6:
        return None
    if s_m >= path.length_m:
        return path
    out: list[Segment] = []
    for start, seg in zip(path.cumulative_m(), path.segments, strict=True):
        if start >= s_m:
            break
        if start + seg.length_m <= s_m:
            out.append(seg)
        else:
            out.append(Segment(seg.start, s_m - start, seg.turn, seg.radius_m))
    return FlightPath(tuple(out))


@dataclass(frozen=True, slots=True)
class _Site:
    s_m: float
    centre: tuple[float, float]
    entry: tuple[float, float]
    clockwise: bool
    detour_m: float
    buffer_id: str


def find_loiter_site(
    scenario: Scenario,
    vehicle: Vehicle,
    path: FlightPath,
    s_from_m: float,
    radius_m: float,
    threats: Sequence[ThreatZone] = (),
) -> _Site | None:
    """Where to loiter on ``path`` after ``s_from_m``, inside a buffer the vehicle may use.

    A circle tangent to the path at a path point, entirely inside a buffer, is preferred (the
    paper keeps the added path within ``2 r_min`` of the planned one); among those, the first
    stretch of the path that allows one, at its deepest point. Otherwise a circle in the
    buffer nearest the path, reached by a straight detour from the nearest path point.
    """
    frame = scenario.frame()
    buffers = [
        (b.id, *b.center.local(frame), b.radius_m)
        for b in scenario.buffers
        if b.vehicles is None or vehicle.id in b.vehicles
    ]
    if not buffers:
        return None
    lead = max(4.0 * radius_m, 1000.0)
    lo, hi = s_from_m + lead, path.length_m - lead
    if hi <= lo:
        return None
    s_values = np.arange(lo, hi, SITE_STEP_M)

    def clear(e: float, n: float) -> bool:
        for t in threats:
            if t.forbidden and float(t.distance_m(np.array([e]), np.array([n]))[0]) < radius_m:
                return False
        return True

    best: tuple[float, _Site] | None = None
    poses = [path.pose_at(float(s)) for s in s_values]
    for s, p in zip(s_values, poses, strict=True):
        for clockwise in (True, False):
            sign = 1.0 if clockwise else -1.0
            ce = p.east_m + sign * radius_m * math.cos(p.heading_rad)
            cn = p.north_m - sign * radius_m * math.sin(p.heading_rad)
            for bid, be, bn, br in buffers:
                margin = br - radius_m - math.hypot(ce - be, cn - bn)
                if margin >= 0.0 and clear(ce, cn):
                    site = _Site(float(s), (ce, cn), (p.east_m, p.north_m), clockwise, 0.0, bid)
                    if best is None or margin > best[0]:
                        best = (margin, site)
        if best is not None and s - best[1].s_m > 4.0 * radius_m:
            break  # the first stretch that allows a tangent circle is past its deepest point
    if best is not None:
        return best[1]
    detour: _Site | None = None
    for bid, be, bn, br in buffers:
        if br < radius_m:
            continue
        d = [math.hypot(p.east_m - be, p.north_m - bn) for p in poses]
        k = int(np.argmin(d))
        p = poses[k]
        ux, uy = (p.east_m - be) / d[k], (p.north_m - bn) / d[k]
        ce, cn = be + ux * (br - radius_m), bn + uy * (br - radius_m)
        ee, en = ce + ux * radius_m, cn + uy * radius_m
        length = 2.0 * math.hypot(p.east_m - ee, p.north_m - en)
        if clear(ce, cn) and (detour is None or length < detour.detour_m):
            detour = _Site(float(s_values[k]), (ce, cn), (ee, en), True, length, bid)
    return detour


# --- timing one vehicle ----------------------------------------------------------------


def _limits(v: Vehicle, step_m_s: float) -> SpeedLimits:
    return SpeedLimits(v.speed_min_m_s, v.speed_max_m_s, v.cruise_m_s, step_m_s)


def _timeline(
    pieces: Sequence[Piece],
    *,
    s0_m: float,
    t0_s: float,
    site: _Site | None,
    radius_m: float,
    turns: int,
    tas_per_eas: float,
) -> tuple[list[Leg], list[LoiterPlan], float]:
    """Legs and loiters from timing pieces whose lengths are in metres / ``tas_per_eas``."""
    legs: list[Leg] = []
    loiters: list[LoiterPlan] = []
    s, t = s0_m, t0_s
    for p in pieces:
        dt = p.duration_s
        if p.kind == "leg":
            length = p.length_m * tas_per_eas
            legs.append(Leg(s, s + length, p.speed_m_s, t, t + dt, tas_per_eas))
            s += length
        else:
            assert site is not None
            loiters.append(
                LoiterPlan(
                    site.s_m,
                    site.centre[0],
                    site.centre[1],
                    site.entry[0],
                    site.entry[1],
                    radius_m,
                    turns,
                    site.clockwise,
                    site.detour_m,
                    p.speed_m_s,
                    t,
                    t + dt,
                    site.buffer_id,
                    tas_per_eas,
                )
            )
        t += dt
    return legs, loiters, t


@dataclass(frozen=True)
class _Retimed:
    schedule: VehicleSchedule
    adjustments: list[Adjustment]


def _retime(
    scenario: Scenario,
    v: Vehicle,
    vs: VehicleSchedule,
    *,
    now_s: float,
    target_s: float,
    step_m_s: float,
    threats: Sequence[ThreatZone],
    at: tuple[float, float] | None = None,
    loiter_margin_m_s: float = 0.0,
) -> _Retimed:
    """Re-time one vehicle from ``now_s`` to arrive at ``target_s`` on its current path.

    ``at`` = (s_m, speed_m_s) anchors the vehicle where it really is (airborne, on a leg)
    instead of where the schedule has it at ``now_s``.
    """
    limits = _limits(v, step_m_s)
    if at is None:
        phase, s0, speed_now = vs.state_at(now_s)
        kept_legs = [leg for leg in vs.legs if leg.t_end_s <= now_s + TIME_TOL_S]
        kept_loiters = [lo for lo in vs.loiters if lo.t_end_s <= now_s + TIME_TOL_S]
    else:
        phase, (s0, speed_now) = "leg", at
        kept_legs = [leg for leg in vs.legs if leg.s_end_m <= s0 + 1e-6]
        kept_loiters = [lo for lo in vs.loiters if lo.s_m < s0]
        cut = [leg for leg in vs.legs if leg.s_start_m < s0 < leg.s_end_m]
        if cut:
            kept_legs.append(replace(cut[0], s_end_m=s0, t_end_s=now_s))
    start_t = now_s
    if phase == "loiter":
        current = next(lo for lo in vs.loiters if lo.t_start_s <= now_s < lo.t_end_s)
        kept_loiters.append(current)
        start_t = current.t_end_s
    elif phase == "leg" and at is None:
        cur = [leg for leg in vs.legs if leg.t_start_s < now_s < leg.t_end_s]
        if cur:
            kept_legs.append(replace(cur[0], s_end_m=s0, t_end_s=now_s))
    adjustments: list[Adjustment] = []
    radius = flyable_loiter_radius_m(v.min_turn_radius_m)
    length = vs.path.length_m
    # The timing arithmetic runs in metres / tas_per_eas, at equivalent airspeeds.
    ratio = vs.tas_per_eas(s0)
    on_ground = phase == "ground"
    takeoff = vs.takeoff_s
    if on_ground:
        window = (max(v.takeoff_window_s[0], now_s), max(v.takeoff_window_s[1], now_s))
        takeoff = takeoff_time_s(length, target_s, limits, window, ratio)
        start_t = takeoff
        if abs(takeoff - vs.takeoff_s) > TIME_TOL_S or now_s == 0.0:
            adjustments.append(
                Adjustment(
                    now_s,
                    v.id,
                    "takeoff_delay",
                    round(takeoff, 3),
                    f"take off at {takeoff:.1f} s to arrive at {target_s:.1f} s "
                    f"(eq. 5: cruise {v.cruise_m_s:g} m/s, "
                    f"window [{window[0]:g}, {window[1]:g}] s)",
                )
            )
    remaining = length - s0
    site = find_loiter_site(scenario, v, vs.path, s0, radius, threats)
    loiter_site = None if site is None else LoiterSite(site.s_m - s0, radius, site.detour_m)
    timing: Timing = time_path(
        v.id,
        remaining,
        target_s - start_t,
        limits,
        site=loiter_site,
        current_m_s=speed_now if phase in ("leg", "loiter") and speed_now > 0.0 else None,
        loiter_margin_m_s=loiter_margin_m_s,
        tas_per_eas=ratio,
    )
    legs, loiters, arrival = _timeline(
        timing.pieces,
        s0_m=s0,
        t0_s=start_t,
        site=site,
        radius_m=radius,
        turns=timing.turns,
        tas_per_eas=ratio,
    )
    speeds = sorted({leg.speed_m_s for leg in legs})
    held = sum(lo.t_end_s - lo.t_start_s for lo in loiters)
    mean = remaining / ratio / max(target_s - start_t - held, 1e-9)
    if speeds and (phase in ("leg", "loiter") or speeds != [v.cruise_m_s]):
        adjustments.append(
            Adjustment(
                start_t,
                v.id,
                "speed",
                legs[0].speed_m_s,
                "fly "
                + ", then ".join(
                    f"{leg.speed_m_s:g} m/s for {(leg.s_end_m - leg.s_start_m) / 1000:.2f} km"
                    for leg in legs
                )
                + f" to arrive at {target_s:.1f} s (mean {mean:.2f} m/s on the path, "
                f"true airspeed x{ratio:.3f})",
            )
        )
    for lo in loiters:
        adjustments.append(
            Adjustment(
                start_t,
                v.id,
                "loiter",
                float(lo.turns),
                f"{lo.turns} turns of {lo.radius_m:g} m in buffer {lo.buffer_id} at "
                f"{lo.s_m / 1000:.1f} km along the path (+{lo.length_m:.0f} m, eq. 8): "
                f"{remaining / 1000:.1f} km at {v.speed_min_m_s:g} m/s would arrive "
                f"{target_s - start_t - remaining / ratio / v.speed_min_m_s:.1f} s early",
            )
        )
    if (
        kept_legs
        and legs
        and kept_legs[-1].speed_m_s == legs[0].speed_m_s
        and kept_legs[-1].tas_per_eas == legs[0].tas_per_eas
        and abs(kept_legs[-1].t_end_s - legs[0].t_start_s) < TIME_TOL_S
        and abs(kept_legs[-1].s_end_m - legs[0].s_start_m) < 1e-6
    ):
        last = kept_legs.pop()
        legs[0] = replace(legs[0], s_start_m=last.s_start_m, t_start_s=last.t_start_s)
    new = replace(
        vs,
        takeoff_s=takeoff,
        arrival_s=arrival,
        legs=tuple(kept_legs + legs),
        loiters=tuple(kept_loiters + loiters),
    )
    return _Retimed(new, adjustments)


class Anchor(NamedTuple):
    """Where an airborne vehicle really is: ``s_m`` along its path at ``speed_m_s``, at
    ``t_s`` (mission s; None: at the re-plan time). A coordinator in flight re-plans from a
    waypoint ahead, which the vehicle reaches at its own time."""

    s_m: float
    speed_m_s: float
    t_s: float | None = None


Anchors = Mapping[str, Anchor]
"""Vehicle id -> its :class:`Anchor`."""


def _anchor_t(at_s: float, anchor: Anchor | None) -> float:
    """When the vehicle is at its anchor (``at_s`` unless the anchor says)."""
    if anchor is not None and anchor.t_s is not None:
        return anchor.t_s
    return at_s


def _where(vs: VehicleSchedule, t_s: float, anchor: Anchor | None) -> tuple[str, float, float]:
    if anchor is None:
        return vs.state_at(t_s)
    return "leg", anchor[0], anchor[1]


def _window(
    scenario: Scenario,
    v: Vehicle,
    vs: VehicleSchedule,
    now_s: float,
    step_m_s: float,
    threats: Sequence[ThreatZone],
    anchor: Anchor | None = None,
) -> ArrivalWindow:
    phase, s0, _ = _where(vs, now_s, anchor)
    start = now_s
    if phase == "loiter":
        start = next(lo.t_end_s for lo in vs.loiters if lo.t_start_s <= now_s < lo.t_end_s)
    radius = flyable_loiter_radius_m(v.min_turn_radius_m)
    site = find_loiter_site(scenario, v, vs.path, s0, radius, threats)
    return vehicle_window(
        v.id,
        now_s=start,
        remaining_m=vs.path.length_m - s0,
        limits=_limits(v, step_m_s),
        takeoff_window_s=v.takeoff_window_s if phase == "ground" else None,
        can_loiter=site is not None,
        tas_per_eas=vs.tas_per_eas(s0),
    )


def _offsets(scenario: Scenario) -> dict[str, float]:
    arrival = scenario.arrival
    ids = [v.id for v in scenario.vehicles]
    if isinstance(arrival, Spaced):
        return {vid: k * arrival.interval_s for k, vid in enumerate(arrival.order or ids)}
    return dict.fromkeys(ids, 0.0)


def _requested(scenario: Scenario) -> float | None:
    arrival = scenario.arrival
    if isinstance(arrival, Simultaneous):
        return arrival.required_s
    if isinstance(arrival, Spaced):
        return arrival.first_s
    return None


def _targets(
    scenario: Scenario,
    windows: Sequence[ArrivalWindow],
    requested_s: float | None,
    natural_s: Mapping[str, float],
) -> tuple[dict[str, float], float | None, str]:
    """Each vehicle's target arrival, the team reference and the reason for it."""
    arrival = scenario.arrival
    if isinstance(arrival, Windows):
        own = {w.vehicle: (w.earliest_s, w.latest_s) for w in arrival.windows}
        out: dict[str, float] = {}
        for w in windows:
            lo_s, hi_s = own[w.vehicle_id]
            lo, hi = max(w.t_min_s, lo_s), min(w.t_max_s, hi_s)
            if lo > hi + TIME_TOL_S:
                short = lo - hi
                why = w.min_reason if w.t_min_s > hi_s else w.max_reason
                raise InfeasibleError(
                    f"vehicle {w.vehicle_id}: window [{lo_s:g}, {hi_s:g}] s cannot be met: "
                    f"{why}: short by {short:.1f} s"
                )
            out[w.vehicle_id] = min(max(natural_s[w.vehicle_id], lo), hi)
        return out, None, "each vehicle within its own arrival window"
    offsets = _offsets(scenario)
    ref, reason = team_arrival(windows, requested_s, offsets_s=offsets)
    return {w.vehicle_id: ref + offsets[w.vehicle_id] for w in windows}, ref, reason


def _spans(vs: VehicleSchedule) -> tuple[SpeedSpan, ...]:
    out = [SpeedSpan(leg.t_start_s, leg.t_end_s, leg.speed_m_s, "leg") for leg in vs.legs]
    out += [SpeedSpan(lo.t_start_s, lo.t_end_s, lo.speed_m_s, "loiter") for lo in vs.loiters]
    return tuple(sorted(out, key=lambda x: x.t_start_s))


def _stage(name: str, time_s: float, vehicles: Sequence[VehicleSchedule]) -> Stage:
    return Stage(name, time_s, {vs.vehicle_id: _spans(vs) for vs in vehicles})


# --- the schedule ----------------------------------------------------------------------


def build_schedule(
    scenario: Scenario,
    plan: Plan,
    *,
    step_m_s: float = SPEED_STEP_M_S,
    world: World | None = None,
) -> Schedule:
    """Time a plan: team arrival, takeoffs (eq. 5), discrete speeds and loiters.

    Parameters
    ----------
    scenario
        The scenario the plan was made for.
    plan
        Its routes (``plan.routes[i].path``: exact lengths, Dubins arcs included).
    step_m_s
        Speed quantum, m/s.
    world
        Re-used when given (threats for the loiter sites).

    Raises
    ------
    InfeasibleError
        The arrival constraint cannot be met; names the vehicle and the shortfall (s).
    """
    world = world or build_world(scenario)
    threats = active(world.threats, None)
    base: list[VehicleSchedule] = []
    for v, route in zip(scenario.vehicles, plan.routes, strict=True):
        base.append(
            VehicleSchedule(
                v.id,
                route.path,
                np.asarray(route.profile.s_m, dtype=np.float64),
                np.asarray(route.profile.alt_m, dtype=np.float64),
                0.0 if v.airborne else v.takeoff_window_s[0],
                math.nan,
                (),
                (),
                v.speed_min_m_s,
                v.speed_max_m_s,
                v.airborne,
            )
        )
    requested = _requested(scenario)
    windows = [
        _window(scenario, v, vs, 0.0, step_m_s, threats)
        for v, vs in zip(scenario.vehicles, base, strict=True)
    ]
    natural = {
        v.id: (0.0 if v.airborne else v.takeoff_window_s[0])
        + vs.path.length_m / (v.cruise_m_s * vs.tas_per_eas())
        for v, vs in zip(scenario.vehicles, base, strict=True)
    }
    targets, ref, reason = _targets(scenario, windows, requested, natural)
    events = [Event(0.0, "arrival", f"team arrival {_fmt(ref)}: {reason}")]
    # The pre-plan picture of Fig. 6b: everyone leaves at the earliest common takeoff and
    # flies the constant speed that arrives on time, in range or not.
    t0 = max((v.takeoff_window_s[0] for v in scenario.vehicles if not v.airborne), default=0.0)
    pre: dict[str, tuple[SpeedSpan, ...]] = {}
    for v, vs in zip(scenario.vehicles, base, strict=True):
        dep = 0.0 if v.airborne else t0
        need = vs.path.length_m / vs.tas_per_eas() / max(targets[v.id] - dep, 1e-9)
        pre[v.id] = (SpeedSpan(dep, targets[v.id], need, "required"),)
    stages = [Stage("pre-plan (common takeoff)", 0.0, pre)]
    timed: list[VehicleSchedule] = []
    adjustments: list[Adjustment] = []
    for v, vs in zip(scenario.vehicles, base, strict=True):
        r = _retime(
            scenario,
            v,
            vs,
            now_s=0.0,
            target_s=targets[v.id],
            step_m_s=step_m_s,
            threats=threats,
        )
        timed.append(r.schedule)
        adjustments.extend(r.adjustments)
    stages.append(_stage("takeoff and speed adjustment", 0.0, timed))
    return Schedule(
        scenario,
        requested,
        ref,
        reason,
        tuple(timed),
        tuple(adjustments),
        tuple(stages),
        tuple(events),
        step_m_s,
        _offsets(scenario),
    )


def _fmt(t: float | None) -> str:
    return "per-vehicle windows" if t is None else f"{t:.1f} s"


def _touches(vs: VehicleSchedule, s0: float, zone: ThreatZone, margin_m: float) -> bool:
    if vs.path.length_m - s0 < 1.0:
        return False
    n = max(2, int(math.ceil((vs.path.length_m - s0) / 200.0)) + 1)
    s = np.linspace(s0, vs.path.length_m, n)
    pts = np.array([[p.east_m, p.north_m] for p in (vs.path.pose_at(float(x)) for x in s)])
    alt = np.interp(s, vs.wp_s_m, vs.wp_alt_m)
    d = zone.distance_m(pts[:, 0], pts[:, 1])
    below = alt < zone.ceiling_m
    limit = margin_m if zone.forbidden else 0.0
    return bool((below & (d < limit)).any())


def _replan(
    world: World,
    threats: Sequence[ThreatZone],
    scenario: Scenario,
    schedule: Schedule,
    vehicle_ids: Sequence[str],
    now_s: float,
    method: Method,
    rng: np.random.Generator,
    anchors: Anchors,
) -> dict[str, VehicleSchedule]:
    """New paths for the vehicles from where they are at ``now_s`` (prefix kept)."""
    starts: dict[str, tuple[float, float, float]] = {}
    poses: dict[str, tuple[float, float, float]] = {}
    for vid in vehicle_ids:
        vs = schedule.vehicle(vid)
        phase, s0, _ = _where(vs, now_s, anchors.get(vid))
        if phase == "ground":
            continue
        p = vs.path.pose_at(s0)
        alt = vs.alt_at(s0)
        starts[vid] = (p.east_m, p.north_m, alt)
        poses[vid] = (s0, p.heading_rad, alt)
    problem = build_problem(world, threats=threats, starts=starts, vehicles=list(vehicle_ids))
    airborne = {vid: (alt, heading) for vid, (_, heading, alt) in poses.items()}
    _, routes = solve_and_finish(
        world, problem, method, threats=threats, rng=rng, airborne=airborne
    )
    out: dict[str, VehicleSchedule] = {}
    for vid, route in zip(vehicle_ids, routes, strict=True):
        vs = schedule.vehicle(vid)
        s0 = poses[vid][0] if vid in poses else 0.0
        prefix = truncate_path(vs.path, s0)
        path = route.path if prefix is None else FlightPath(prefix.segments + route.path.segments)
        keep = vs.wp_s_m < s0 - 1e-6
        wp_s = np.concatenate([vs.wp_s_m[keep], np.asarray(route.profile.s_m) + s0])
        wp_alt = np.concatenate([vs.wp_alt_m[keep], np.asarray(route.profile.alt_m)])
        out[vid] = replace(
            vs,
            path=path,
            wp_s_m=wp_s,
            wp_alt_m=wp_alt,
            replanned_at_s=(*vs.replanned_at_s, now_s),
        )
    return out


@dataclass(frozen=True)
class PopupOutcome:
    """The team after one pop-up threat: re-planned, re-timed, and what was decided."""

    schedule: Schedule
    affected: tuple[str, ...]
    adjustments: tuple[Adjustment, ...]
    events: tuple[Event, ...]


def apply_popup(
    current: Schedule,
    zone: ThreatZone,
    *,
    at_s: float,
    world: World,
    threats: Sequence[ThreatZone],
    method: Method = "aco",
    rng: np.random.Generator,
    anchors: Anchors | None = None,
    loiter_margin_m_s: float = 0.0,
) -> PopupOutcome:
    """Re-plan around one new threat from where the team is at ``at_s`` and re-time it.

    Parameters
    ----------
    current
        The team's schedule before the threat.
    zone
        The new threat.
    at_s
        Mission time (s) from which the new routes start (the threat's appearance offline; a
        little ahead of the vehicles in flight, so that they reach the splice point after the
        new missions are uploaded).
    world, threats
        The world and every threat in force from ``at_s`` (``zone`` included).
    anchors
        Where airborne vehicles really are (:class:`Anchor`: s_m along their path, speed m/s,
        and the time they are there, ``at_s`` unless given); the others are where the
        schedule has them at ``at_s``.
    loiter_margin_m_s
        Loiter turns leave the speed this far above the minimum when they can.

    Raises
    ------
    InfeasibleError
        A re-plan fails, or no common arrival time remains; names the vehicle.
    """
    scenario = current.scenario
    anchors = anchors or {}
    adjustments: list[Adjustment] = []
    events = [Event(at_s, "popup", f"threat {zone.id} appears")]
    stages = list(current.stages)
    affected: list[str] = []
    for v in scenario.vehicles:
        vs = current.vehicle(v.id)
        phase, s0, _ = _where(vs, at_s, anchors.get(v.id))
        if phase != "arrived" and _touches(vs, s0, zone, v.min_turn_radius_m):
            affected.append(v.id)
    if not affected:
        events.append(Event(at_s, "popup", f"{zone.id} touches no remaining route"))
        return PopupOutcome(
            replace(current, events=(*current.events, *events)), (), (), tuple(events)
        )
    events.append(Event(at_s, "replan", f"re-planning {', '.join(affected)} around {zone.id}"))
    new_paths = _replan(world, threats, scenario, current, affected, at_s, method, rng, anchors)
    vehicles = [new_paths.get(vs.vehicle_id, vs) for vs in current.vehicles]
    staged = replace(current, vehicles=tuple(vehicles))
    where = {v.id: _where(staged.vehicle(v.id), at_s, anchors.get(v.id)) for v in scenario.vehicles}
    t_at = {v.id: _anchor_t(at_s, anchors.get(v.id)) for v in scenario.vehicles}
    windows = [
        _window(
            scenario,
            v,
            staged.vehicle(v.id),
            t_at[v.id],
            current.step_m_s,
            threats,
            anchors.get(v.id),
        )
        for v in scenario.vehicles
        if where[v.id][0] != "arrived"
    ]
    natural = {vs.vehicle_id: vs.arrival_s for vs in current.vehicles}
    targets, ref, reason = _targets(scenario, windows, current.required_arrival_s, natural)
    events.append(Event(at_s, "arrival", f"team arrival {_fmt(ref)}: {reason}"))
    # Fig. 9: the constant speed each vehicle would now need, in range or not.
    need: dict[str, tuple[SpeedSpan, ...]] = {}
    for v in scenario.vehicles:
        vs = staged.vehicle(v.id)
        phase, s0, _ = where[v.id]
        t_v = t_at[v.id]
        past = tuple(sp for sp in _spans(vs) if sp.t_end_s <= t_v + TIME_TOL_S)
        if phase == "arrived" or v.id not in targets:
            need[v.id] = _spans(vs)
            continue
        dep = max(t_v, vs.takeoff_s) if phase == "ground" else t_v
        cut = tuple(
            SpeedSpan(sp.t_start_s, t_v, sp.speed_m_s, sp.kind)
            for sp in _spans(vs)
            if sp.t_start_s < t_v < sp.t_end_s
        )
        v_need = (vs.path.length_m - s0) / vs.tas_per_eas(s0) / max(targets[v.id] - dep, 1e-9)
        need[v.id] = (*past, *cut, SpeedSpan(dep, targets[v.id], v_need, "required"))
    stages.append(Stage(f"{zone.id} at {at_s:.0f} s: re-planned, required speed", at_s, need))
    retimed: list[VehicleSchedule] = []
    for v in scenario.vehicles:
        vs = staged.vehicle(v.id)
        same_time = abs(targets.get(v.id, vs.arrival_s) - vs.arrival_s) < 0.05
        if v.id not in targets or (v.id not in affected and same_time):
            retimed.append(vs)
            continue
        anchor = anchors.get(v.id)
        r = _retime(
            scenario,
            v,
            vs,
            now_s=t_at[v.id],
            target_s=targets[v.id],
            step_m_s=current.step_m_s,
            threats=threats,
            at=(anchor.s_m, anchor.speed_m_s)
            if where[v.id][0] == "leg" and anchor is not None
            else None,
            loiter_margin_m_s=loiter_margin_m_s,
        )
        retimed.append(r.schedule)
        adjustments.extend(r.adjustments)
    stages.append(_stage(f"after {zone.id}: final", at_s, retimed))
    out = replace(
        current,
        vehicles=tuple(retimed),
        required_arrival_s=ref,
        arrival_reason=reason,
        adjustments=(*current.adjustments, *adjustments),
        stages=tuple(stages),
        events=(*current.events, *events),
    )
    return PopupOutcome(out, tuple(affected), tuple(adjustments), tuple(events))


def replay_popups(
    schedule: Schedule,
    *,
    method: Method = "aco",
    rng: np.random.Generator | None = None,
    world: World | None = None,
) -> Schedule:
    """Fly the schedule through the scenario's pop-up threats (section 5, offline).

    At each pop-up's appearance (resolved from the scheduled takeoffs), the vehicles whose
    remaining route the threat touches (within ``min_turn_radius_m`` of a forbidden zone, or
    inside a costed one) are re-planned from their current position and heading; then every
    vehicle is re-timed for the same team arrival time when the windows still hold it, else
    for the earliest common time (the reason names the vehicle that forced it). Unaffected
    vehicles keep their timing when the arrival time stands.

    Raises
    ------
    InfeasibleError
        A re-plan fails, or no common arrival time remains; names the vehicle.
    """
    scenario = schedule.scenario
    rng = rng if rng is not None else np.random.default_rng(0)
    takeoffs = {vs.vehicle_id: vs.takeoff_s for vs in schedule.vehicles}
    all_threats = build_threats(scenario, takeoffs)
    world = world or build_world(scenario, takeoffs)
    world = replace(world, threats=tuple(all_threats))
    current = schedule
    for zone in popup_zones(all_threats):
        t_p = float(zone.appears_at_s or 0.0)
        current = apply_popup(
            current,
            zone,
            at_s=t_p,
            world=world,
            threats=active(all_threats, t_p),
            rng=rng,
            method=method,
        ).schedule
    return current


def popup_zones(threats: Sequence[ThreatZone]) -> list[ThreatZone]:
    """The threats that appear during the mission, in order of appearance."""
    return sorted(
        (t for t in threats if t.appears_at_s is not None and math.isfinite(t.appears_at_s)),
        key=lambda t: (t.appears_at_s or 0.0, t.id),
    )


def retime_vehicle(
    schedule: Schedule,
    vehicle_id: str,
    *,
    now_s: float,
    s_m: float,
    speed_m_s: float,
    target_s: float,
    threats: Sequence[ThreatZone],
    loiter_margin_m_s: float = 0.0,
) -> tuple[VehicleSchedule, tuple[Adjustment, ...]]:
    """Re-time one airborne vehicle from where it really is (``s_m`` along its path, flying
    ``speed_m_s``) at ``now_s`` to arrive at ``target_s``: speeds, and loiter turns in a buffer
    ahead when the speed range cannot absorb the surplus (eqs. 6-9).

    Raises
    ------
    InfeasibleError
        Too late even at top speed, or too early with no buffer ahead; names the vehicle.
    """
    v = schedule.scenario.vehicle(vehicle_id)
    r = _retime(
        schedule.scenario,
        v,
        schedule.vehicle(vehicle_id),
        now_s=now_s,
        target_s=target_s,
        step_m_s=schedule.step_m_s,
        threats=threats,
        at=(s_m, speed_m_s),
        loiter_margin_m_s=loiter_margin_m_s,
    )
    return r.schedule, tuple(r.adjustments)

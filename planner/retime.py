"""Timing the team's routes: takeoffs, discrete speeds and loiters on flyable paths (section 4).

:func:`build_schedule` times a :class:`~planner.plan.Plan`: the team arrival time from the
vehicles' windows (eq. 1), each vehicle on the ground moved to take off on time at cruise speed
(eq. 5), the remainder trimmed by two discrete speeds (eqs. 6-7), and loiter turns in a buffer
area where the speed range cannot absorb the surplus (eqs. 8-9). :func:`retime_vehicle`
re-times one airborne vehicle from where it really is. Both, and the pop-up re-plan
(:mod:`planner.popup`), time each vehicle with :func:`retime_on_path`: from a moment on, on
its current path.

The timing arithmetic is :mod:`planner.timing`'s; here it is laid on the geometry: loiter sites
in the buffers (:func:`find_loiter_site`), legs and loiter circles along the path. The model
(equivalent airspeeds, loiter circles) is described in :mod:`planner.schedule`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from planner.climbout import climb_out
from planner.deconflict import (
    Separation,
    TeamTracks,
    check_separation,
    separation,
)
from planner.dubins import Pose
from planner.errors import ArrivalTimeError, InfeasibleError
from planner.flightpath import FlightPath
from planner.layers import Lane, lanes, lift_team
from planner.loiterflight import loiter_flight
from planner.plan import Plan, World, build_world, required_arrival_s
from planner.scenario import Scenario, Spaced, Vehicle, Waves, Windows
from planner.schedule import (
    Adjustment,
    Anchor,
    Event,
    Leg,
    LoiterPlan,
    Schedule,
    SpeedSpan,
    Stage,
    VehicleSchedule,
)
from planner.sequencing import sequence_team
from planner.terrain import Terrain
from planner.threats import ThreatZone, active
from planner.timing import (
    SPEED_STEP_M_S,
    TIME_TOL_S,
    ArrivalWindow,
    LoiterSite,
    Piece,
    SpeedLimits,
    Timing,
    flyable_loiter_radius_m,
    speed_grid,
    takeoff_time_s,
    team_arrival,
    team_window,
    time_path,
    vehicle_window,
)

FloatArray = NDArray[np.float64]

SITE_STEP_M = 100.0
SiteCheck = Callable[[float, float, float], bool]
"""``(centre_east_m, centre_north_m, radius_m) -> bool``: may a loiter circle go there."""
FREE_SITE = "path"
"""The ``buffer_id`` of loiter turns on the path outside any buffer (:func:`free_loiter_site`)."""
WINDOW_MARGIN_S = 5.0
"""How far inside its arrival window a vehicle aims when its natural arrival is outside it (s;
the middle of a window narrower than twice this)."""


# --- loiter sites ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Site:
    s_m: float
    centre: tuple[float, float]
    entry: tuple[float, float]
    clockwise: bool
    detour_m: float
    buffer_id: str


def _site_s_m(path: FlightPath, s_from_m: float, radius_m: float) -> FloatArray:
    """The path distances a loiter may start at after ``s_from_m``: every ``SITE_STEP_M``,
    a lead of 4 radii (at least 1 km) clear of both ends (empty when the path is shorter)."""
    lead = max(4.0 * radius_m, 1000.0)
    return np.arange(s_from_m + lead, path.length_m - lead, SITE_STEP_M)


def _tangent_centre(pose: Pose, radius_m: float, clockwise: bool) -> tuple[float, float]:
    """The centre of the circle tangent to the path at ``pose``, turning the given way."""
    sign = 1.0 if clockwise else -1.0
    return (
        pose.east_m + sign * radius_m * math.cos(pose.heading_rad),
        pose.north_m - sign * radius_m * math.sin(pose.heading_rad),
    )


def find_loiter_site(
    scenario: Scenario,
    vehicle: Vehicle,
    path: FlightPath,
    s_from_m: float,
    radius_m: float,
    threats: Sequence[ThreatZone] = (),
    keep_clear: SiteCheck | None = None,
) -> _Site | None:
    """Where to loiter on ``path`` after ``s_from_m``, inside a buffer the vehicle may use
    (and, with ``keep_clear``, where it says the circle may go).

    A circle tangent to the path at a path point, entirely inside a buffer, is preferred (the
    paper keeps the added path within ``2 r_min`` of the planned one); among those, the first
    stretch of the path that allows one, at its deepest point. Otherwise a circle in the
    buffer nearest the path, reached by a straight detour from the nearest path point; its
    ``detour_m`` is all that ArduPlane flies there besides the whole turns (out to the circle,
    the line-up on the route's course after the turns, and back: see
    :func:`~planner.loiterflight.loiter_flight`), the way round that adds less.
    """
    frame = scenario.frame()
    buffers = [
        (b.id, *b.center.local(frame), b.radius_m)
        for b in scenario.buffers
        if b.vehicles is None or vehicle.id in b.vehicles
    ]
    if not buffers:
        return None
    s_values = _site_s_m(path, s_from_m, radius_m)
    if s_values.size == 0:
        return None

    def clear(e: float, n: float) -> bool:
        for t in threats:
            if t.forbidden and float(t.distance_m(np.array([e]), np.array([n]))[0]) < radius_m:
                return False
        return keep_clear is None or keep_clear(e, n, radius_m)

    best: tuple[float, _Site] | None = None
    poses = [path.pose_at(float(s)) for s in s_values]
    for s, p in zip(s_values, poses, strict=True):
        for clockwise in (True, False):
            ce, cn = _tangent_centre(p, radius_m, clockwise)
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
        if d[k] > 0.0:
            ux, uy = (p.east_m - be) / d[k], (p.north_m - bn) / d[k]
        else:
            ux, uy = math.cos(p.heading_rad), -math.sin(p.heading_rad)
        ce, cn = be + ux * (br - radius_m), bn + uy * (br - radius_m)
        if not clear(ce, cn):
            continue
        for clockwise in (True, False):
            # What the loiter adds as ArduPlane flies it from the waypoint at p: out to the
            # circle, the line-up on the route's course after the turns, and back.
            flight = loiter_flight(
                p.east_m, p.north_m, p.heading_rad, ce, cn, radius_m, clockwise=clockwise
            )
            length = flight.added_m
            if detour is None or length < detour.detour_m:
                at = flight.counted_from_rad
                entry = (ce + radius_m * math.sin(at), cn + radius_m * math.cos(at))
                detour = _Site(float(s_values[k]), (ce, cn), entry, clockwise, length, bid)
    return detour


def free_loiter_site(
    vehicle: Vehicle,
    vs: VehicleSchedule,
    s_from_m: float,
    radius_m: float,
    threats: Sequence[ThreatZone],
    terrain: Terrain,
    keep_clear: SiteCheck | None = None,
) -> _Site | None:
    """Where to loiter on the path after ``s_from_m`` when no buffer serves: the first circle
    tangent to the path (no detour) that keeps a radius clear of every threat zone, forbidden
    or not, and the vehicle's terrain clearance all round at the path's altitude there (and,
    with ``keep_clear``, where it says the circle may go)."""
    angles = np.linspace(0.0, 2.0 * math.pi, 36, endpoint=False)
    for s in _site_s_m(vs.path, s_from_m, radius_m):
        p = vs.path.pose_at(float(s))
        for clockwise in (True, False):
            ce, cn = _tangent_centre(p, radius_m, clockwise)
            if any(
                float(t.distance_m(np.array([ce]), np.array([cn]))[0]) < 2.0 * radius_m
                for t in threats
            ):
                continue
            ground = terrain.elevation_m(
                ce + radius_m * np.cos(angles), cn + radius_m * np.sin(angles)
            )
            if float(np.max(ground)) + vehicle.clearance_m > vs.alt_at(float(s)):
                continue
            if keep_clear is not None and not keep_clear(ce, cn, radius_m):
                continue
            return _Site(float(s), (ce, cn), (p.east_m, p.north_m), clockwise, 0.0, FREE_SITE)
    return None


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
    ground_per_eas: float,
    tas_per_eas: float,
) -> tuple[list[Leg], list[LoiterPlan], float]:
    """Legs and loiters from timing pieces whose lengths are in metres / ``ground_per_eas``
    (legs) and / ``tas_per_eas`` (loiters)."""
    legs: list[Leg] = []
    loiters: list[LoiterPlan] = []
    s, t = s0_m, t0_s
    for p in pieces:
        dt = p.duration_s
        if p.kind == "leg":
            length = p.length_m * ground_per_eas
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
class Retimed:
    schedule: VehicleSchedule
    adjustments: list[Adjustment]


def retime_on_path(
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
    terrain: Terrain | None = None,
    keep_clear: SiteCheck | None = None,
) -> Retimed:
    """Re-time one vehicle from ``now_s`` to arrive at ``target_s`` on its current path.

    ``at`` = (s_m, speed_m_s) anchors the vehicle where it really is (airborne, on a leg)
    instead of where the schedule has it at ``now_s``. With ``terrain``, a surplus that no
    buffer can absorb (none ahead, or its detour alone is longer than the time to lose) gets
    its turns on the path where the airspace and the terrain allow (:func:`free_loiter_site`).
    With ``keep_clear``, loiter circles go only where it says they may.
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
    elif phase in ("ground", "climb"):
        # Timed from where the climb-out ends: the takeoff flies the path's start by itself.
        s0 = vs.climb_s_m
        start_t = max(vs.climb_end_s, now_s)
    adjustments: list[Adjustment] = []
    radius = flyable_loiter_radius_m(v.min_turn_radius_m)
    length = vs.path.length_m
    remaining = length - s0
    # The timing arithmetic runs in metres / ground_per_eas, at equivalent airspeeds; the
    # loiters' in metres / tas_per_eas.
    tas_ratio = vs.tas_per_eas(s0)
    on_ground = phase == "ground"
    takeoff = vs.takeoff_s
    if on_ground:
        window = (max(v.takeoff_window_s[0], now_s), max(v.takeoff_window_s[1], now_s))
        takeoff = takeoff_for(v, vs, target_s, window)
        start_t = takeoff + vs.climb_end_s - vs.takeoff_s
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
    site = find_loiter_site(scenario, v, vs.path, s0, radius, threats, keep_clear)
    # In a wind the ground covered per metre of airspeed depends on the airspeed: timed at
    # the mean speed the time asks for, then again at the mean speed that timing flies.
    budget_s = max(target_s - start_t, 1e-9)
    ref_m_s = v.cruise_m_s
    ratio = vs.ground_per_eas(s0, ref_m_s)
    for _ in range(0 if vs.wind.calm else 4):
        # The speed that time asks for, in this ratio, within the range: at a limit exactly
        # the ratio the arrival window was worked out with.
        ref_m_s = min(max(remaining / ratio / budget_s, v.speed_min_m_s), v.speed_max_m_s)
        ratio = vs.ground_per_eas(s0, ref_m_s)

    def timed(at_site: _Site | None) -> Timing:
        return time_path(
            v.id,
            remaining,
            target_s - start_t,
            limits,
            site=None
            if at_site is None
            else LoiterSite(at_site.s_m - s0, radius, at_site.detour_m),
            current_m_s=speed_now if phase in ("leg", "loiter") and speed_now > 0.0 else None,
            loiter_margin_m_s=loiter_margin_m_s,
            tas_per_eas=ratio,
            loiter_tas_per_eas=tas_ratio,
        )

    def timed_here(at_site: _Site | None) -> tuple[_Site | None, Timing]:
        try:
            return at_site, timed(at_site)
        except InfeasibleError:
            free = None
            if terrain is not None and (at_site is None or at_site.detour_m > 0.0):
                free = free_loiter_site(v, vs, s0, radius, threats, terrain, keep_clear)
            if free is None or target_s - start_t < remaining / ratio / v.speed_max_m_s:
                raise
            return free, timed(free)

    chosen, timing = timed_here(site)
    if not vs.wind.calm:
        flown = [p for p in timing.pieces if p.kind == "leg"]
        if flown:
            mean_m_s = math.fsum(p.length_m for p in flown) / math.fsum(p.duration_s for p in flown)
            again = vs.ground_per_eas(s0, mean_m_s)
            if abs(again - ratio) > 1e-4 * ratio:
                ratio = again
                chosen, timing = timed_here(site)
    site = chosen
    legs, loiters, arrival = _timeline(
        timing.pieces,
        s0_m=s0,
        t0_s=start_t,
        site=site,
        radius_m=radius,
        turns=timing.turns,
        ground_per_eas=ratio,
        tas_per_eas=tas_ratio,
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
                f"true airspeed x{tas_ratio:.3f}"
                + ("" if vs.wind.calm else f", x{ratio:.3f} over the ground in the wind")
                + ")",
            )
        )
    for lo in loiters:
        adjustments.append(
            Adjustment(
                start_t,
                v.id,
                "loiter",
                float(lo.turns),
                f"{lo.turns} turns of {lo.radius_m:g} m "
                + ("on the path" if lo.buffer_id == FREE_SITE else f"in buffer {lo.buffer_id}")
                + " at "
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
        via=None,  # timed for its slot alone
    )
    return Retimed(new, adjustments)


def anchored_state(
    vs: VehicleSchedule, t_s: float, anchor: Anchor | None
) -> tuple[str, float, float]:
    """``(phase, s_m, speed_m_s)`` at time t: on a leg at the anchor when there is one, else
    where the schedule has the vehicle (:meth:`~planner.schedule.VehicleSchedule.state_at`)."""
    if anchor is None:
        return vs.state_at(t_s)
    return "leg", anchor[0], anchor[1]


def can_loiter_after(
    scenario: Scenario,
    v: Vehicle,
    vs: VehicleSchedule,
    s_from_m: float,
    threats: Sequence[ThreatZone],
    terrain: Terrain | None = None,
    keep_clear: SiteCheck | None = None,
) -> bool:
    """Whether loiter turns can be flown on the vehicle's path after ``s_from_m``: in a buffer
    it may use (:func:`find_loiter_site`), or with ``terrain`` on the path where the airspace
    and the terrain allow (:func:`free_loiter_site`), and with ``keep_clear`` where it says the
    circle may go (:func:`clear_of_team`), as :func:`retime_on_path` would put them."""
    radius = flyable_loiter_radius_m(v.min_turn_radius_m)
    if find_loiter_site(scenario, v, vs.path, s_from_m, radius, threats, keep_clear) is not None:
        return True
    return terrain is not None and (
        free_loiter_site(v, vs, s_from_m, radius, threats, terrain, keep_clear) is not None
    )


def arrival_window(
    scenario: Scenario,
    v: Vehicle,
    vs: VehicleSchedule,
    now_s: float,
    step_m_s: float,
    threats: Sequence[ThreatZone],
    anchor: Anchor | None = None,
    terrain: Terrain | None = None,
) -> ArrivalWindow:
    """The vehicle's feasible arrival window from ``now_s`` (eq. 1), from where it is (with
    ``terrain``, a vehicle with no buffer ahead may still loiter on its path where the
    airspace and the terrain allow, as :func:`retime_on_path` would)."""
    phase, s0, _ = anchored_state(vs, now_s, anchor)
    start = now_s
    climb_s = 0.0
    if phase == "loiter":
        start = next(lo.t_end_s for lo in vs.loiters if lo.t_start_s <= now_s < lo.t_end_s)
    elif phase == "ground":
        s0, climb_s = vs.climb_s_m, vs.climb_end_s - vs.takeoff_s
    elif phase == "climb":
        s0, start = vs.climb_s_m, max(vs.climb_end_s, now_s)
    can_loiter = can_loiter_after(
        scenario, v, vs, s0, threats, None if phase == "ground" else terrain
    )
    return vehicle_window(
        v.id,
        now_s=start,
        remaining_m=vs.path.length_m - s0,
        limits=_limits(v, step_m_s),
        takeoff_window_s=v.takeoff_window_s if phase == "ground" else None,
        can_loiter=can_loiter,
        tas_per_eas=lambda eas_m_s: vs.ground_per_eas(s0, eas_m_s),
        climb_s=climb_s,
    )


def arrival_targets(
    scenario: Scenario,
    windows: Sequence[ArrivalWindow],
    requested_s: float | None,
    natural_s: Mapping[str, float],
    *,
    missed_ok: bool = False,
) -> tuple[dict[str, float], float | None, str]:
    """Each vehicle's target arrival, the team reference and the reason for it.
    ``missed_ok``: a vehicle that can no longer make its own arrival window (in flight, a
    route round a zone too long for it) is timed to the nearest arrival it can make, said in
    the reason, rather than refused."""
    arrival = scenario.arrival
    if isinstance(arrival, Windows):
        own = {w.vehicle: (w.earliest_s, w.latest_s) for w in arrival.windows}
        out: dict[str, float] = {}
        missed: list[str] = []
        for w in windows:
            lo_s, hi_s = own[w.vehicle_id]
            lo, hi = max(w.t_min_s, lo_s), min(w.t_max_s, hi_s)
            if lo > hi + TIME_TOL_S and missed_ok:
                out[w.vehicle_id] = w.t_min_s if w.t_min_s > hi_s else w.t_max_s
                missed.append(f"{w.vehicle_id} (at {out[w.vehicle_id]:.1f} s)")
                continue
            if lo > hi + TIME_TOL_S:
                short = lo - hi
                why = w.min_reason if w.t_min_s > hi_s else w.max_reason
                raise InfeasibleError(
                    f"vehicle {w.vehicle_id}: window [{lo_s:g}, {hi_s:g}] s cannot be met: "
                    f"{why}: short by {short:.1f} s",
                    vehicle=w.vehicle_id,
                )
            # Aimed inside the window by a margin where it has room, not at its edge: an
            # arrival a second off its aim still meets the window.
            margin_s = min(WINDOW_MARGIN_S, max(hi - lo, 0.0) / 2.0)
            out[w.vehicle_id] = min(max(natural_s[w.vehicle_id], lo + margin_s), hi - margin_s)
        reason = "each vehicle within its own arrival window"
        if missed:
            reason += f"; cannot make its window, timed to the nearest it can: {', '.join(missed)}"
        return out, None, reason
    offsets = scenario.arrival_offsets_s()
    ref, reason = team_arrival(windows, requested_s, offsets_s=offsets)
    return {w.vehicle_id: ref + offsets[w.vehicle_id] for w in windows}, ref, reason


def speed_spans(vs: VehicleSchedule) -> tuple[SpeedSpan, ...]:
    """The vehicle's legs and loiters as speed spans, in time order."""
    out = [SpeedSpan(leg.t_start_s, leg.t_end_s, leg.speed_m_s, "leg") for leg in vs.legs]
    out += [SpeedSpan(lo.t_start_s, lo.t_end_s, lo.speed_m_s, "loiter") for lo in vs.loiters]
    return tuple(sorted(out, key=lambda x: x.t_start_s))


def speed_stage(name: str, time_s: float, vehicles: Sequence[VehicleSchedule]) -> Stage:
    """The team's speed profiles as they stand, as one stage of the story."""
    return Stage(name, time_s, {vs.vehicle_id: speed_spans(vs) for vs in vehicles})


# --- the schedule ----------------------------------------------------------------------


def takeoff_for(
    v: Vehicle, vs: VehicleSchedule, target_s: float, window_s: tuple[float, float]
) -> float:
    """Takeoff time (s) of a vehicle on the ground to arrive at ``target_s`` at its cruise
    speed (eq. 5), its climb-out and the wind counted, within ``window_s``."""
    s0 = vs.climb_s_m
    return takeoff_time_s(
        vs.path.length_m - s0,
        target_s,
        SpeedLimits(v.speed_min_m_s, v.speed_max_m_s, v.cruise_m_s),
        window_s,
        vs.ground_per_eas(s0, v.cruise_m_s),
        vs.climb_end_s - vs.takeoff_s,
    )


def earliest_from_ground_s(v: Vehicle, vs: VehicleSchedule, takeoff_s: float) -> float:
    """When a vehicle that takes off at ``takeoff_s`` arrives at the earliest: its climb-out,
    then the rest of its path at top speed in its wind, mission s."""
    s0 = vs.climb_s_m
    ratio = vs.ground_per_eas(s0, v.speed_max_m_s)
    flying_s = (vs.path.length_m - s0) / (v.speed_max_m_s * ratio) if ratio > 0.0 else math.inf
    return takeoff_s + vs.climb_end_s - vs.takeoff_s + flying_s


def with_climb(v: Vehicle, vs: VehicleSchedule, terrain: Terrain) -> VehicleSchedule:
    """``vs`` with the climb-out of its takeoff from the start of its path, in its wind (an
    airborne vehicle has none)."""
    if v.airborne:
        return replace(vs, climb=None)
    start = vs.path.start
    home = float(terrain.elevation_m(np.array([start.east_m]), np.array([start.north_m]))[0])
    climb = climb_out(
        vs.path,
        home_alt_m=home,
        start_alt_m=vs.alt_at(0.0),
        cruise_m_s=v.cruise_m_s,
        rotate_m_s=v.speed_min_m_s,
        climb_rate_m_s=v.takeoff_climb_m_s,
        turn_radius_m=v.min_turn_radius_m,
        wind=vs.wind,
    )
    return replace(vs, climb=climb)


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
        The arrival constraint cannot be met at any time; names the vehicle and the
        shortfall (s). A requested time that cannot be met is moved to the earliest feasible
        one (``required_arrival_s`` differs from ``requested_arrival_s``): a schedule to fly
        as planned must pass :func:`check_feasible`.
    """
    world = world or build_world(scenario)
    threats = active(world.threats, None)
    wind = scenario.forecast_wind()
    base: list[VehicleSchedule] = []
    for v, route in zip(scenario.vehicles, plan.routes, strict=True):
        vs = VehicleSchedule(
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
            wind=wind,
        )
        base.append(with_climb(v, vs, world.terrain))
    requested = required_arrival_s(scenario)
    windows = [
        arrival_window(scenario, v, vs, 0.0, step_m_s, threats)
        for v, vs in zip(scenario.vehicles, base, strict=True)
    ]
    natural = {
        v.id: vs.climb_end_s
        + (vs.path.length_m - vs.climb_s_m)
        / (v.cruise_m_s * vs.ground_per_eas(vs.climb_s_m, v.cruise_m_s))
        for v, vs in zip(scenario.vehicles, base, strict=True)
    }
    targets, ref, reason = arrival_targets(scenario, windows, requested, natural)
    bounds = (
        None
        if isinstance(scenario.arrival, Windows)
        else team_window(windows, offsets_s=scenario.arrival_offsets_s())
    )
    team = _time_team(scenario, base, windows, targets, step_m_s, threats)
    if team.separation.conflicts and requested is None and ref is not None and bounds is not None:
        # Those in conflict could not move at the earliest time: later, they have room. The
        # latest delay is tried first: if even that does not separate them, none will (the
        # team is refused after two timings, not six, on the one with fewer pairs too
        # close); else the least delay that does.
        pairs = len(team.separation.conflicts)
        delays = [d for d in SEPARATION_DELAYS_S if ref + d <= bounds.latest_s]
        found: tuple[float, dict[str, float], _TeamTiming] | None = None
        for delay_s in delays[-1:] + delays[:-1]:
            later = {vid: t + delay_s for vid, t in targets.items()}
            attempt = _time_team(scenario, base, windows, later, step_m_s, threats)
            if attempt.separation.conflicts:
                if found is None:
                    if len(attempt.separation.conflicts) < pairs:
                        found = (delay_s, later, attempt)
                    break  # not even the latest
                continue
            found = (delay_s, later, attempt)
            if delay_s != delays[-1]:
                break  # the least that separates them
        if found is not None:
            delay_s, targets, team = found
            left = len(team.separation.conflicts)
            goal = (
                f"where {left} pair{'s are' if left > 1 else ' is'} still too close"
                if left
                else f"to keep the {scenario.separation_m:g} m separation"
            )
            reason = (
                f"{reason}; moved {delay_s:g} s later {goal} ({pairs} pair"
                f"{'s' if pairs > 1 else ''} too close at {ref:.1f} s)"
            )
            ref += delay_s
    events = [Event(0.0, "arrival", f"team arrival {format_arrival(ref)}: {reason}")]
    events += [Event(0.0, "separation", why) for why in team.said]
    # The pre-plan picture of Fig. 6b: everyone leaves at the earliest common takeoff and
    # flies the constant speed that arrives on time, in range or not.
    t0 = max((v.takeoff_window_s[0] for v in scenario.vehicles if not v.airborne), default=0.0)
    pre: dict[str, tuple[SpeedSpan, ...]] = {}
    for v, vs in zip(scenario.vehicles, base, strict=True):
        dep = 0.0 if v.airborne else t0
        need = vs.path.length_m / vs.tas_per_eas() / max(targets[v.id] - dep, 1e-9)
        pre[v.id] = (SpeedSpan(dep, targets[v.id], need, "required"),)
    stages = [
        Stage("pre-plan (common takeoff)", 0.0, pre),
        speed_stage("takeoff and speed adjustment", 0.0, team.vehicles),
    ]
    return Schedule(
        scenario,
        requested,
        ref,
        reason,
        team.vehicles,
        team.adjustments,
        tuple(stages),
        tuple(events),
        step_m_s,
        scenario.arrival_offsets_s(),
        bounds,
    )


SEPARATION_DELAYS_S = (60.0, 120.0, 240.0, 480.0, 960.0)
"""How much later the team time may move, the least first, when the vehicles in conflict at
the earliest one cannot be separated by their own timings (a later time gives those that had
to fly at their top speed the room to move); within every vehicle's window, and not when the
operator asked for a time."""


class _Timing(NamedTuple):
    """How a vehicle's other timing for the separation was made."""

    retimed: Retimed
    cruise_m_s: float
    planned: VehicleSchedule
    """The planned schedule it timed (on the lane, if any), before it was timed."""
    lane: Lane | None = None


@dataclass(frozen=True)
class _TeamTiming:
    vehicles: tuple[VehicleSchedule, ...]
    adjustments: tuple[Adjustment, ...]
    said: tuple[str, ...]
    """One line per vehicle moved for the separation."""
    separation: Separation


def _time_team(
    scenario: Scenario,
    base: Sequence[VehicleSchedule],
    windows: Sequence[ArrivalWindow],
    targets: Mapping[str, float],
    step_m_s: float,
    threats: Sequence[ThreatZone],
) -> _TeamTiming:
    """Every vehicle timed for its target, then the team separated by timing
    (:func:`planner.sequencing.sequence_team`) and, where the scenario allows them, altitude
    layers (:func:`planner.layers.lift_team`) for the pairs timing leaves in conflict."""
    timed: list[VehicleSchedule] = []
    adjustments: list[Adjustment] = []
    for v, vs in zip(scenario.vehicles, base, strict=True):
        r = retime_on_path(
            scenario, v, vs, now_s=0.0, target_s=targets[v.id], step_m_s=step_m_s,
            threats=threats,
        )  # fmt: skip
        timed.append(r.schedule)
        adjustments.extend(r.adjustments)
    required = scenario.separation_m
    by_id = {vs.vehicle_id: vs for vs in base}

    slack = {
        v.id: 0.0
        if v.airborne
        else max(0.0, min(targets[v.id] - w.t_min_s, w.t_max_s - targets[v.id]))
        for v, w in zip(scenario.vehicles, windows, strict=True)
    }

    cruise_now = {v.id: v.cruise_m_s for v in scenario.vehicles}

    def timed_at(vid: str, vs: VehicleSchedule, cruise: float) -> Retimed | None:
        """``vs`` timed for the same arrival at ``cruise`` (its takeoff moved), or None."""
        other = scenario.vehicle(vid).model_copy(update={"cruise_speed_m_s": cruise})
        try:
            return retime_on_path(
                scenario, other, vs, now_s=0.0, target_s=targets[vid], step_m_s=step_m_s,
                threats=threats,
            )  # fmt: skip
        except InfeasibleError:
            return None

    def other_timings(vid: str) -> Iterator[tuple[VehicleSchedule, _Timing]]:
        """The vehicle at each other cruise speed, nearest its own first, for the same
        arrival (its takeoff moved); then, where the scenario allows altitude layers, at
        each cruise speed on each of its :func:`planner.layers.lanes`."""
        v = scenario.vehicle(vid)
        levels = sorted(
            speed_grid(v.speed_min_m_s, v.speed_max_m_s, step_m_s),
            key=lambda c: (abs(c - v.cruise_m_s), c),
        )
        for cruise in levels:
            if abs(cruise - v.cruise_m_s) <= 1e-9:
                continue
            r = timed_at(vid, by_id[vid], cruise)
            if r is not None:
                yield r.schedule, _Timing(r, cruise, by_id[vid])
        for up, lane in lanes(by_id[vid], v, scenario.altitude_layers_m):
            for cruise in levels:
                r = timed_at(vid, up, cruise)
                if r is not None:
                    yield r.schedule, _Timing(r, cruise, up, lane)

    said: list[str] = []
    changed: dict[str, Retimed] = {}
    vehicles = {v.id: v for v in scenario.vehicles}

    def retime_lifted(vs: VehicleSchedule) -> tuple[VehicleSchedule, Retimed] | None:
        r = timed_at(vs.vehicle_id, vs, cruise_now[vs.vehicle_id])
        return None if r is None else (r.schedule, r)

    moved, sep = sequence_team(timed, required, slack_s=slack, alternatives=other_timings)
    planned = dict(by_id)  # with the layers the timing flies
    for vid, m in moved.items():
        changed[vid], cruise_now[vid] = m.chosen.retimed, m.chosen.cruise_m_s
        other = m.conflict.b if m.conflict.a == vid else m.conflict.a
        planned[vid], lane = m.chosen.planned, m.chosen.lane
        on_lane = ""
        if lane is not None:
            on_lane = (
                f", {lane.height_m:g} m above its profile from {lane.from_m / 1000:.1f} to "
                f"{lane.to_m / 1000:.1f} km"
            )
        own = vehicles[vid].cruise_m_s
        speed = (
            f"keeps its {own:g} m/s cruise"
            if abs(cruise_now[vid] - own) <= 1e-9
            else f"cruises at {cruise_now[vid]:g} m/s instead of {own:g} m/s"
        )
        said.append(
            f"{vid} {speed}{on_lane} (takeoff at {m.schedule.takeoff_s:.1f} s): it came "
            f"{m.conflict.distance_m:.0f} m from {other} at {m.conflict.time_s:.0f} s, "
            f"under the {required:g} m separation"
        )
        timed = [m.schedule if x.vehicle_id == vid else x for x in timed]
    if sep.conflicts and scenario.altitude_layers_m:
        lifted, sep = lift_team(
            timed, planned, vehicles, scenario.altitude_layers_m, required, retime_lifted
        )
        for vid, up in lifted.items():
            changed[vid] = up.chosen
            said.append(
                f"{vid} flies "
                + ", ".join(
                    f"{h:g} m above its profile from {a / 1000:.1f} to {b / 1000:.1f} km "
                    f"(it came {d:.0f} m from {o} at {t:.0f} s)"
                    for h, a, b, o, d, t in up.spans
                )
                + f", under the {required:g} m separation; takeoff at "
                f"{up.schedule.takeoff_s:.1f} s"
            )
            timed = [up.schedule if x.vehicle_id == vid else x for x in timed]
    for vid, r in changed.items():
        why = "; ".join(w for w in said if w.startswith(f"{vid} "))
        # Said in flight with the takeoff.
        adjustments = [a for a in adjustments if a.vehicle != vid] + [
            replace(a, reason=f"{a.reason}; {why}") if a.strategy == "takeoff_delay" else a
            for a in r.adjustments
        ]
    return _TeamTiming(tuple(timed), tuple(adjustments), tuple(said), sep)


def check_arrival(schedule: Schedule) -> None:
    """Refuse a schedule whose team arrival is not the one requested.

    :func:`build_schedule` moves a requested time (``required_s``, or ``first_s`` of spaced
    arrivals) that some vehicle cannot make to the earliest feasible one; for a schedule to
    fly as planned that is infeasible. Check the schedule as built (a pop-up re-plan in
    flight may move the team time on purpose; such a schedule is refused without a vehicle
    named).

    Raises
    ------
    ArrivalTimeError
        Names the requested time, the earliest feasible one and the vehicle that forces it
        (``requested_s``, ``earliest_s``, ``latest_s``, ``vehicle``).
    """
    requested, ref = schedule.requested_arrival_s, schedule.required_arrival_s
    if requested is None or ref is None or abs(ref - requested) <= TIME_TOL_S:
        return
    arrival = schedule.scenario.arrival
    what = (
        "first arrival"
        if isinstance(arrival, Spaced)
        else "first wave's arrival"
        if isinstance(arrival, Waves)
        else "arrival"
    )
    w = schedule.team_window
    if w is not None and requested < w.earliest_s - TIME_TOL_S:
        message = (
            f"requested {what} {requested:.1f} s is too early: earliest feasible "
            f"{w.earliest_s:.1f} s, forced by vehicle {w.earliest_vehicle}: {w.earliest_reason}"
        )
        vehicle: str | None = w.earliest_vehicle
    elif w is not None and requested > w.latest_s + TIME_TOL_S:
        message = (
            f"requested {what} {requested:.1f} s is too late: latest feasible "
            f"{w.latest_s:.1f} s, forced by vehicle {w.latest_vehicle}: {w.latest_reason}; "
            f"earliest feasible {w.earliest_s:.1f} s"
        )
        vehicle = w.latest_vehicle
    else:
        # Not built by build_schedule, or moved since (a pop-up re-plan): the reason says why.
        message = (
            f"requested {what} {requested:.1f} s is not held: the team arrives at {ref:.1f} s "
            f"({schedule.arrival_reason})"
        )
        vehicle = None
    earliest = ref if w is None else w.earliest_s
    raise ArrivalTimeError(
        message,
        vehicle=vehicle,
        requested_s=requested,
        earliest_s=earliest,
        latest_s=math.inf if w is None else w.latest_s,
    )


def check_feasible(schedule: Schedule, *, allow_conflicts: bool = False) -> Separation:
    """Refuse a schedule that cannot be flown as planned: the requested team arrival moved
    (:func:`check_arrival`) or, unless ``allow_conflicts``, two vehicles closer than the
    scenario's ``separation_m`` (:func:`planner.deconflict.check_separation`).

    Returns the team's separation (computed once; conflicts listed when allowed).

    Raises
    ------
    ArrivalTimeError
        The requested arrival cannot be met (an :class:`~planner.errors.InfeasibleError`).
    SeparationError
        A pair of vehicles too close (an :class:`~planner.errors.InfeasibleError`).
    """
    check_arrival(schedule)
    sep = separation(schedule.vehicles, schedule.scenario.separation_m)
    if not allow_conflicts:
        check_separation(sep)
    return sep


def format_arrival(t: float | None) -> str:
    """The team arrival time for an event's text."""
    return "per-vehicle windows" if t is None else f"{t:.1f} s"


def clear_of_team(schedule: Schedule, vehicle_id: str, from_s: float) -> SiteCheck:
    """Where a loiter circle of ``vehicle_id`` keeps the scenario's separation from every
    place the rest of the team will fly from ``from_s`` on (:class:`~planner.deconflict.
    TeamTracks`): the check :func:`retime_vehicle` puts its turns by with ``separate``."""
    required = schedule.scenario.separation_m
    others = [x for x in schedule.vehicles if x.vehicle_id != vehicle_id]
    tracks = TeamTracks.of(others, from_s)

    def keep_clear(e: float, n: float, radius_m: float) -> bool:
        return tracks.clearance(e, n, radius_m)[0] >= required

    return keep_clear


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
    terrain: Terrain | None = None,
    separate: bool = False,
) -> tuple[VehicleSchedule, tuple[Adjustment, ...]]:
    """Re-time one airborne vehicle from where it really is (``s_m`` along its path, flying
    ``speed_m_s``) at ``now_s`` to arrive at ``target_s``: speeds, and loiter turns in a buffer
    ahead when the speed range cannot absorb the surplus (eqs. 6-9).

    With ``separate``, loiter circles keep the scenario's separation from every place the
    rest of the team will fly from ``now_s`` on (:class:`~planner.deconflict.TeamTracks`).

    Raises
    ------
    InfeasibleError
        Too late even at top speed, or too early with no buffer ahead, or (``separate``) no
        place for the turns that keeps the separation; names the vehicle.
    """
    v = schedule.scenario.vehicle(vehicle_id)
    keep_clear = clear_of_team(schedule, vehicle_id, now_s) if separate else None
    try:
        r = retime_on_path(
            schedule.scenario,
            v,
            schedule.vehicle(vehicle_id),
            now_s=now_s,
            target_s=target_s,
            step_m_s=schedule.step_m_s,
            threats=threats,
            at=(s_m, speed_m_s),
            loiter_margin_m_s=loiter_margin_m_s,
            terrain=terrain,
            keep_clear=keep_clear,
        )
    except InfeasibleError as err:
        if keep_clear is None:
            raise
        raise InfeasibleError(
            f"{err} (loiter sites within {schedule.scenario.separation_m:g} m of the team's "
            "tracks left out)",
            vehicle=err.vehicle,
            earliest_s=err.earliest_s,
        ) from None
    return r.schedule, tuple(r.adjustments)

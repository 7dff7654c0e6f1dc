"""Altitude layers: a vehicle flown a set height above its planned profile to keep ``d_s``
in 3-D from vehicles that share its corridor at the same time.

A scenario that allows it names the heights (``altitude_layers_m``). The profile as planned
keeps the terrain clearance at the least height the climb gradient allows
(:func:`planner.plan.altitude_profile`); a layer is that profile raised by the layer's height
where the vehicle may fly that high:

- never above the vehicle's ``alt_max_m`` (a layer squeezed under it is only as high as fits);
- never below the planned profile (the clearance and the threats' ceilings only gain);
- the climb-out and the first waypoint after it as planned, then up at no more than the
  climb gradient, and down at no more than it to the goal at the planned altitude (or to the
  profile where a layer kept to a stretch of the path ends);

so that the layer keeps the planned profile's gradient. It is the lesser of the raised profile,
the ceiling and the two gradient caps, and the greater of that and the profile, each of them
changing no faster than the gradient. Its waypoints are the planned ones plus those where
the lesser switches from one of them to another (found on a grid of :data:`GRID_M`): between
them it is straight, as the autopilot flies it.

Layers are used twice when the team is timed (:func:`planner.retime.build_schedule`):

- as lanes (:func:`lanes`): among each vehicle's timings the placement by timing tries
  (:func:`planner.sequencing.sequence_team`), after its cruise speeds, each speed on a layer
  over the end of its path. Vehicles sharing a corridor to neighbouring goals at one time
  cannot all be told apart by a uniform speed each (the faster overtakes the slower where
  they share it), but two lanes, each timed in trail, can hold them;
- then pair by pair for what is left (:func:`lift_team`), over the stretch where they meet.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

from planner.deconflict import Separation, TeamSamples, separation
from planner.scenario import Scenario, Vehicle
from planner.schedule import VehicleSchedule
from planner.sequencing import SEPARATION_CHECK_MARGIN

FloatArray = NDArray[np.float64]

T = TypeVar("T")

GRID_M = 100.0
"""Spacing of the grid the layer's switches are found on, m."""
LIFT_HALF_SPANS_M = (5_000.0, 20_000.0, 60_000.0)
"""A vehicle lifted to an altitude layer flies it this far either side of where it came too
close (plus the climb to it and the descent from it), the shortest that helps; else all its
path."""
LANE_STRETCHES_M = (math.inf, 20_000.0, 40_000.0, 80_000.0)
"""A vehicle timed on a layer (:func:`lanes`) flies it over the last this many metres of its
path before the goal (and the climb to it); ``inf``: all its path after the climb-out. In
this order: all of it first, then the shortest stretch."""
LAYER_STEPS = 3
"""A vehicle leaves its profile by one, two or three layer steps at most (:func:`layer_step_m`):
in flight (:mod:`gcs.coordination.vertical`), and a re-plan where the scenario names no
layers (:func:`replan_layers_m`)."""
LIFT_ROUNDS = 8
"""Passes over the team's conflicts at most (each lowers their number, or the search ends)."""


def layer_step_m(scenario: Scenario) -> float:
    """The height of one layer, m: the scenario's first altitude layer, or half its separation
    minimum without one (a pair a layer apart at one place is then as far apart vertically as
    half ``d_s``; two steps make the whole of it)."""
    layers = scenario.altitude_layers_m
    return float(layers[0]) if layers else 0.5 * scenario.separation_m


def replan_layers_m(scenario: Scenario) -> tuple[float, ...]:
    """The layers a re-plan may lift a vehicle onto, lowest first, m: the scenario's, or
    without any, :data:`LAYER_STEPS` steps of :func:`layer_step_m` (the heights the in-flight
    resolution climbs by)."""
    if scenario.altitude_layers_m:
        return tuple(float(h) for h in scenario.altitude_layers_m)
    step_m = layer_step_m(scenario)
    return tuple(k * step_m for k in range(1, LAYER_STEPS + 1))


def layer_profile(
    vs: VehicleSchedule,
    v: Vehicle,
    height_m: float,
    span_m: tuple[float, float] | None = None,
) -> tuple[FloatArray, FloatArray] | None:
    """``(wp_s_m, wp_alt_m)`` of ``vs``'s profile ``height_m`` higher (see the module), or
    None where it cannot rise at all (at its ceiling, or too short to climb and come down).

    ``span_m`` = ``(from_m, to_m)`` (along the path) keeps the layer to that stretch: the
    vehicle climbs to it from ``from_m`` and is back on its profile at ``to_m``."""
    length = vs.path.length_m
    hold_m = 0.0 if vs.climb is None else max(vs.climb.s_m, vs.climb.first_waypoint_m)
    up_m, down_m = hold_m, length
    if span_m is not None:
        up_m, down_m = max(up_m, span_m[0]), min(down_m, span_m[1])
    if not down_m > up_m:
        return None
    n = max(2, int(np.ceil(length / GRID_M)) + 1)
    s = np.unique(np.concatenate([np.linspace(0.0, length, n), vs.wp_s_m, [up_m, down_m]]))
    base = np.interp(s, vs.wp_s_m, vs.wp_alt_m)
    g = v.climb_gradient
    up_alt = float(np.interp(up_m, vs.wp_s_m, vs.wp_alt_m))
    down_alt = float(np.interp(down_m, vs.wp_s_m, vs.wp_alt_m))
    caps = np.stack(
        [
            base + height_m,
            np.full_like(s, v.alt_max_m),
            np.where(s <= up_m, base, up_alt + g * (s - up_m)),
            np.where(s >= down_m, base, down_alt + g * (down_m - s)),
        ]
    )
    active = caps.argmin(axis=0)
    layer = np.maximum(caps[active, np.arange(len(s))], base)
    active[layer <= base] = -1  # the profile itself where nothing lifts it
    if float((layer - base).max()) < 1.0:
        return None
    switch = np.flatnonzero(np.diff(active) != 0)
    marks = np.unique(np.concatenate([vs.wp_s_m, s[switch], s[switch + 1], [0.0, length]]))
    return marks, np.interp(marks, s, layer)


def lift(
    vs: VehicleSchedule,
    base: VehicleSchedule,
    v: Vehicle,
    height_m: float,
    span_m: tuple[float, float],
) -> VehicleSchedule | None:
    """``vs`` (``base``, its path as planned, or lifted already over other stretches) also on
    the layer ``height_m`` above ``base``'s profile over ``span_m``: the higher of the two
    profiles everywhere (each keeps the gradient, the ceiling and the clearance, so their
    upper envelope does). None where that lifts it nowhere by a metre. Its timing is as it
    was: time it again, the true airspeed changes with the height."""
    profile = layer_profile(base, v, height_m, span_m)
    if profile is None:
        return None
    s = np.unique(np.concatenate([vs.wp_s_m, profile[0]]))
    mine = np.interp(s, vs.wp_s_m, vs.wp_alt_m)
    layer = np.interp(s, *profile)
    if float((layer - mine).max()) < 1.0:
        return None
    return replace(vs, wp_s_m=s, wp_alt_m=np.maximum(mine, layer))


@dataclass(frozen=True)
class Lane:
    """A layer flown over the end of a vehicle's path: ``height_m`` above its profile from
    ``from_m`` along the path (climbing to it from there) to the goal."""

    height_m: float
    from_m: float
    to_m: float


def lanes(
    vs: VehicleSchedule, v: Vehicle, heights_m: Sequence[float]
) -> Iterator[tuple[VehicleSchedule, Lane]]:
    """``vs`` (as planned, before it is timed) on each layer of ``heights_m`` (lowest first)
    over each stretch of :data:`LANE_STRETCHES_M` before its goal (in that order), where
    the layer lifts it at all. Each is timed again by the caller: the timing that keeps
    vehicles sharing a corridor apart may do so on different layers (two lanes where one
    would have them overtake each other)."""
    length = vs.path.length_m
    for height in heights_m:
        seen: set[float] = set()
        for stretch_m in LANE_STRETCHES_M:
            from_m = max(0.0, length - stretch_m)
            if from_m in seen:
                continue  # a path shorter than the stretch: all of it, once
            seen.add(from_m)
            up = lift(vs, vs, v, height, (from_m, math.inf))
            if up is not None:
                yield up, Lane(height, from_m, length)


@dataclass(frozen=True)
class Lifted(Generic[T]):
    """A vehicle flown on altitude layers over stretches of its path to keep the separation."""

    schedule: VehicleSchedule
    chosen: T
    """What the caller's timing of it carried."""
    spans: tuple[tuple[float, float, float, str, float, float], ...]
    """Each stretch: ``(height_m, from_m, to_m, other_vehicle, distance_m, time_s)``, the
    vehicle it came too close to there, how close and when."""


def lift_team(
    team: Sequence[VehicleSchedule],
    planned: Mapping[str, VehicleSchedule],
    vehicles: Mapping[str, Vehicle],
    heights_m: Sequence[float],
    required_m: float,
    retime: Callable[[VehicleSchedule], tuple[VehicleSchedule, T] | None],
    *,
    from_s: float = -math.inf,
    lift_from_m: Mapping[str, float] | None = None,
    time_up: Callable[[], bool] | None = None,
) -> tuple[dict[str, Lifted[T]], Separation]:
    """Lift vehicles onto the altitude layers ``heights_m`` over the stretches where they
    come too close to another, until the team keeps ``required_m`` or no lift helps.

    Pair by pair, closest first: one of the two (either) is lifted over the stretch of its
    path round where they meet, on the lowest layer and the shortest stretch that leaves it
    too close to fewer vehicles than before (:data:`LIFT_HALF_SPANS_M`, then its whole path;
    the lifts of one vehicle add up, :func:`lift`), timed again for its arrival (``retime``
    of its planned schedule as lifted: the true airspeed changes with the height). Every
    lift lowers the number of pairs in conflict, so the search ends.

    Parameters
    ----------
    team
        The team's schedules as timed.
    planned
        Each vehicle's schedule before it was timed (its profile as planned), by id.
    vehicles
        The scenario's vehicles, by id.
    heights_m
        The layers the scenario allows, lowest first.
    required_m
        The separation minimum ``d_s``, m.
    retime
        Times a lifted planned schedule as its vehicle is timed now; None if it cannot.
    from_s
        Separation counts from this time on (a re-plan's start), and only there.
    lift_from_m
        When given, only these vehicles may be lifted, each only from this far along its
        path on (its climb to the layer included): a vehicle in flight keeps what it will
        have flown before its new mission starts.
    time_up
        Says when the caller's wall time is spent: no lift is tried after it.

    Returns
    -------
    The vehicles lifted (by id) and the team's separation as lifted.
    """
    samples = TeamSamples(team, required_m, from_s=from_s)
    if not heights_m or len(team) < 2:
        return {}, separation(team, required_m, samples)
    enough = SEPARATION_CHECK_MARGIN * required_m
    current = {vs.vehicle_id: vs for vs in team}
    profile = dict(planned)
    lifted: dict[str, Lifted[T]] = {}

    def try_lift(vid: str, other: str, distance_m: float, time_s: float) -> bool:
        if lift_from_m is not None and vid not in lift_from_m:
            return False
        floor_m = -math.inf if lift_from_m is None else lift_from_m[vid]
        v, before = vehicles[vid], samples.too_close(current[vid], enough)
        s_m = current[vid].state_at(time_s)[1]
        for height in heights_m:
            ramp_m = height / v.climb_gradient
            for half_m in (*LIFT_HALF_SPANS_M, math.inf):
                span = (max(s_m - ramp_m - half_m, floor_m), s_m + ramp_m + half_m)
                if span[1] - span[0] <= 2.0 * ramp_m:
                    continue  # no room to climb to it and back before they meet
                up = lift(profile[vid], planned[vid], v, height, span)
                if up is None:
                    continue
                timed = retime(up)
                if timed is None:
                    continue
                if len(samples.too_close(timed[0], enough)) >= len(before):
                    continue
                samples.replace(timed[0])
                current[vid], profile[vid] = timed[0], up
                done = lifted[vid].spans if vid in lifted else ()
                here = (height, max(span[0], 0.0), min(span[1], up.path.length_m), other)
                spans = (*done, (*here, distance_m, time_s))
                lifted[vid] = Lifted(timed[0], timed[1], spans)
                return True
        return False

    for _ in range(LIFT_ROUNDS):
        progress = False
        closest = {vid: samples.closest(vs, within_m=enough) for vid, vs in current.items()}
        for vid in sorted(closest, key=lambda k: closest[k][0]):
            if time_up is not None and time_up():
                break
            # Looked up again only once a lift this round may have changed it.
            near, who, when_s = (
                samples.closest(current[vid], within_m=enough) if progress else closest[vid]
            )
            if near >= enough or who is None:
                continue
            if try_lift(vid, who, near, when_s) or try_lift(who, vid, near, when_s):
                progress = True
        if not progress:
            break
    return lifted, separation([current[vs.vehicle_id] for vs in team], required_m, samples)

"""The re-plan around pop-up threats (section 5).

:func:`apply_popup` re-plans the vehicles whose remaining route a new threat touches from where
they are, and re-times the team for the same arrival time, or the earliest common one when that
is no longer feasible. :func:`replay_popups` flies a schedule through the scenario's pop-up
threats offline, applying each at its appearance.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import cache, partial

import numpy as np

from planner.aco import AcoOptions
from planner.deconflict import TeamTracks
from planner.errors import InfeasibleError
from planner.flightpath import FlightPath
from planner.plan import Method, World, build_problem, build_world, solve_and_finish
from planner.replanoffset import widened
from planner.replanseparation import separate_replan
from planner.replantiming import retime_through
from planner.retime import (
    Retimed,
    anchored_state,
    arrival_targets,
    arrival_window,
    format_arrival,
    retime_on_path,
    speed_spans,
    speed_stage,
    with_climb,
)
from planner.scenario import Scenario
from planner.schedule import (
    Adjustment,
    Anchor,
    Anchors,
    Event,
    Schedule,
    SpeedSpan,
    Stage,
    VehicleSchedule,
)
from planner.slots import ordered_targets, slot_spacing_s
from planner.threats import ThreatZone, active, build_threats
from planner.timing import TIME_TOL_S


def _anchor_t(at_s: float, anchor: Anchor | None) -> float:
    """When the vehicle is at its anchor (``at_s`` unless the anchor says)."""
    if anchor is not None and anchor.t_s is not None:
        return anchor.t_s
    return at_s


def _touches(vs: VehicleSchedule, s0: float, zone: ThreatZone, margin_m: float) -> bool:
    if vs.path.length_m - s0 < 1.0:
        return False
    n = max(2, int(math.ceil((vs.path.length_m - s0) / 200.0)) + 1)
    s = np.linspace(s0, vs.path.length_m, n)
    pts = vs.path.poses_at(s)
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
    time_up: Callable[[], bool] | None = None,
) -> dict[str, VehicleSchedule]:
    """New paths for the vehicles from where they are at ``now_s`` (prefix kept)."""
    starts: dict[str, tuple[float, float, float]] = {}
    poses: dict[str, tuple[float, float, float]] = {}
    for vid in vehicle_ids:
        vs = schedule.vehicle(vid)
        phase, s0, _ = anchored_state(vs, now_s, anchors.get(vid))
        if phase == "ground":
            continue
        if phase == "climb":
            s0 = vs.climb_s_m  # the climb-out flies on to its end whatever the route
        p = vs.path.pose_at(s0)
        alt = vs.alt_at(s0)
        starts[vid] = (p.east_m, p.north_m, alt)
        poses[vid] = (s0, p.heading_rad, alt)
    problem = build_problem(world, threats=threats, starts=starts, vehicles=list(vehicle_ids))
    airborne = {vid: (alt, heading) for vid, (_, heading, alt) in poses.items()}
    _, routes = solve_and_finish(
        world, problem, method, threats=threats, rng=rng, airborne=airborne,
        options=None if time_up is None else AcoOptions(time_up=time_up),
    )  # fmt: skip
    out: dict[str, VehicleSchedule] = {}
    for vid, route in zip(vehicle_ids, routes, strict=True):
        vs = schedule.vehicle(vid)
        s0 = poses[vid][0] if vid in poses else 0.0
        prefix = vs.path.prefix(s0)
        path = route.path if prefix is None else FlightPath(prefix.segments + route.path.segments)
        keep = vs.wp_s_m < s0 - 1e-6
        wp_s = np.concatenate([vs.wp_s_m[keep], np.asarray(route.profile.s_m) + s0])
        wp_alt = np.concatenate([vs.wp_alt_m[keep], np.asarray(route.profile.alt_m)])
        new = replace(
            vs,
            path=path,
            wp_s_m=wp_s,
            wp_alt_m=wp_alt,
            replanned_at_s=(*vs.replanned_at_s, now_s),
        )
        # Still on the ground: its takeoff climbs out along the new path's start.
        out[vid] = new if vid in poses else with_climb(scenario.vehicle(vid), new, world.terrain)
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
    time_up: Callable[[], bool] | None = None,
    others_may_stay: bool = False,
    separation_up: Callable[[], bool] | None = None,
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
    time_up
        Ends the route search with the best routes so far when it says so (asked between
        its iterations: :attr:`planner.aco.AcoOptions.time_up`); the routes are finished and
        checked as always.
    separation_up
        Ends the separation of the re-planned team (:func:`planner.replanseparation.
        separate_replan`: timing, then altitude layers) with what it has separated so far
        when it says so; the pairs left are said as always.
    others_may_stay
        In flight: when no arrival time remains common to the re-planned vehicles and the
        others (those others cannot wait as long), the re-planned ones are timed among
        themselves and the others keep their schedules, said in an ``arrival`` event. The
        coordinator then keeps the team time (the re-planned that cannot make it are
        released, each with an alarm) rather than leave them on routes into the threat.

    Raises
    ------
    InfeasibleError
        A re-plan fails, or no common arrival time remains (for the re-planned vehicles
        alone, with ``others_may_stay``); names the vehicle.
    """
    scenario = current.scenario
    anchors = anchors or {}
    # Each re-timed vehicle's adjustments: its last timing's (a lift times it again).
    adjusted: dict[str, tuple[Adjustment, ...]] = {}
    events = [Event(at_s, "popup", f"threat {zone.id} appears")]
    stages = list(current.stages)
    affected: list[str] = []
    for v in scenario.vehicles:
        vs = current.vehicle(v.id)
        phase, s0, _ = anchored_state(vs, at_s, anchors.get(v.id))
        if phase != "arrived" and _touches(vs, s0, zone, v.min_turn_radius_m):
            affected.append(v.id)
    if not affected:
        events.append(Event(at_s, "popup", f"{zone.id} touches no remaining route"))
        return PopupOutcome(
            replace(current, events=(*current.events, *events)), (), (), tuple(events)
        )
    events.append(Event(at_s, "replan", f"re-planning {', '.join(affected)} around {zone.id}"))
    new_paths = _replan(
        world, threats, scenario, current, affected, at_s, method, rng, anchors, time_up
    )
    vehicles = [new_paths.get(vs.vehicle_id, vs) for vs in current.vehicles]
    staged = replace(current, vehicles=tuple(vehicles))
    where = {
        v.id: anchored_state(staged.vehicle(v.id), at_s, anchors.get(v.id))
        for v in scenario.vehicles
    }
    t_at = {v.id: _anchor_t(at_s, anchors.get(v.id)) for v in scenario.vehicles}
    windows = [
        arrival_window(
            scenario,
            v,
            staged.vehicle(v.id),
            t_at[v.id],
            current.step_m_s,
            threats,
            anchors.get(v.id),
            world.terrain,
        )
        for v in scenario.vehicles
        if where[v.id][0] != "arrived"
    ]
    natural = {vs.vehicle_id: vs.arrival_s for vs in current.vehicles}
    spacing_s = slot_spacing_s(scenario)
    try:
        if spacing_s is None:
            targets, ref, reason = arrival_targets(
                scenario, windows, current.required_arrival_s, natural
            )
        else:
            # Ordered slots: only the slots from a vehicle that cannot make its own move.
            targets, ref, reason = ordered_targets(windows, natural, spacing_s)
    except InfeasibleError as err:
        if not others_may_stay:
            raise
        # In flight a route round the zone matters more than a window that no longer can be
        # met: the vehicle is timed to the nearest it can make (the coordinator alarms it).
        own = [w for w in windows if w.vehicle_id in affected]
        targets, ref, reason = arrival_targets(
            scenario, own, current.required_arrival_s, natural, missed_ok=True
        )
        reason = f"{reason}; with the others none remains ({err}): they keep their schedules"
    events.append(Event(at_s, "arrival", f"team arrival {format_arrival(ref)}: {reason}"))
    # Fig. 9: the constant speed each vehicle would now need, in range or not.
    need: dict[str, tuple[SpeedSpan, ...]] = {}
    for v in scenario.vehicles:
        vs = staged.vehicle(v.id)
        phase, s0, _ = where[v.id]
        t_v = t_at[v.id]
        past = tuple(sp for sp in speed_spans(vs) if sp.t_end_s <= t_v + TIME_TOL_S)
        if phase == "arrived" or v.id not in targets:
            need[v.id] = speed_spans(vs)
            continue
        dep = max(t_v, vs.takeoff_s) if phase == "ground" else t_v
        cut = tuple(
            SpeedSpan(sp.t_start_s, t_v, sp.speed_m_s, sp.kind)
            for sp in speed_spans(vs)
            if sp.t_start_s < t_v < sp.t_end_s
        )
        v_need = (vs.path.length_m - s0) / vs.tas_per_eas(s0) / max(targets[v.id] - dep, 1e-9)
        need[v.id] = (*past, *cut, SpeedSpan(dep, targets[v.id], v_need, "required"))
    stages.append(Stage(f"{zone.id} at {at_s:.0f} s: re-planned, required speed", at_s, need))
    # The re-routed first, then the rest: each one's loiter turns kept clear of every place
    # the others will fly from its re-timing on, as re-timed so far (the new routes' and
    # their turns included), as the loiters decided in flight are.
    final = {vs.vehicle_id: vs for vs in staged.vehicles}
    required = scenario.separation_m

    def retime(vs: VehicleSchedule, keep_clear: Callable[..., bool] | None) -> Retimed:
        """``vs`` timed for its vehicle's slot from where it is at the re-plan's start."""
        vid = vs.vehicle_id
        anchor = anchors.get(vid)
        at = (anchor.s_m, anchor.speed_m_s) if where[vid][0] == "leg" and anchor else None
        return retime_on_path(
            scenario, scenario.vehicle(vid), vs, now_s=t_at[vid], target_s=targets[vid],
            step_m_s=current.step_m_s, threats=threats, at=at,
            loiter_margin_m_s=loiter_margin_m_s, terrain=world.terrain, keep_clear=keep_clear,
        )  # fmt: skip

    for vid in [*affected, *(v.id for v in scenario.vehicles if v.id not in affected)]:
        v = scenario.vehicle(vid)
        vs = final[vid]
        same_time = abs(targets.get(v.id, vs.arrival_s) - vs.arrival_s) < 0.05
        if v.id not in targets or (v.id not in affected and same_time):
            continue
        # The others' tracks are made when a loiter is first tried, for those that need one.
        tracks = cache(partial(TeamTracks.of, [x for k, x in final.items() if k != vid], t_at[vid]))

        def keep_clear(
            e: float, n: float, radius_m: float, tracks: Callable[[], TeamTracks] = tracks
        ) -> bool:
            return tracks().clearance(e, n, radius_m)[0] >= required

        r: Retimed | None = None
        for check in (keep_clear, None):  # where they fit when nowhere keeps clear
            try:
                r = retime(vs, check)
                break
            except InfeasibleError:
                if check is None:
                    raise
        assert r is not None
        if check is None and any(lo.t_end_s > t_at[vid] for lo in r.schedule.loiters):
            events.append(
                Event(
                    at_s,
                    "conflict",
                    f"{vid}: no place for its loiter turns keeps {required:g} m from the "
                    "team's tracks; they are flown where they fit",
                )
            )
        final[vid] = r.schedule
        adjusted[vid] = tuple(r.adjustments)
    # Then the team, from the re-plan's start on: a pair under d_s separated by the plan's
    # means, or said before anything is installed.
    lift_from_m = {
        v.id: 0.0 if where[v.id][0] == "ground" else where[v.id][1]
        for v in scenario.vehicles
        if v.id in targets
        and where[v.id][0] != "arrived"
        and (where[v.id][0] == "ground" or not anchors or v.id in anchors)
    }

    def lifted(up: VehicleSchedule) -> Retimed | None:
        try:
            return retime(up, None)
        except InfeasibleError:
            return None

    def through(vs: VehicleSchedule, via_s_m: float, via_t_s: float) -> Retimed | None:
        vid = vs.vehicle_id
        anchor = anchors.get(vid)
        at = (anchor.s_m, anchor.speed_m_s) if where[vid][0] == "leg" and anchor else None
        try:
            return retime_through(
                scenario, scenario.vehicle(vid), vs, now_s=t_at[vid], via_s_m=via_s_m,
                via_t_s=via_t_s, target_s=targets[vid], step_m_s=current.step_m_s,
                threats=threats, at=at,
            )  # fmt: skip
        except InfeasibleError:
            return None

    def widen(vs: VehicleSchedule, by_m: float) -> Retimed | None:
        """``vs``'s vehicle routed round the zone ``by_m`` wider from where it is (the zone
        widened for its route search alone), timed for its slot."""
        wider = widened(zone, by_m)
        if wider is None:
            return None
        vid = vs.vehicle_id
        # The zone itself kept beside it: a concave one's widening need not cover it.
        around = [*threats, replace(wider, id=f"{zone.id} {by_m:g} m wider")]
        try:
            # One vehicle's way round: the exact search's shortest (a third of the colonies'
            # time here, and this is searched for each vehicle and each offset), timed after.
            path = _replan(
                world, around, scenario, current, [vid], at_s, "astar", rng, anchors,
                separation_up,
            )[vid]  # fmt: skip
        except InfeasibleError:
            return None
        return lifted(path)

    kept = separate_replan(
        scenario, final, from_s=at_s, lift_from_m=lift_from_m, rerouted=affected,
        retime=lifted, through=through, widen=widen, time_up=separation_up,
    )  # fmt: skip
    final = kept.vehicles
    adjusted.update(kept.adjustments)
    events.extend(kept.events)
    adjustments = [a for done in adjusted.values() for a in done]
    retimed = [final[v.id] for v in scenario.vehicles]
    stages.append(speed_stage(f"after {zone.id}: final", at_s, retimed))
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

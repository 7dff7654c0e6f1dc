"""schedule.json: the team schedule as data, and each vehicle's ArduPlane mission from it.

:func:`vehicle_mission` turns a vehicle's schedule into mission items with
:func:`planner.mission.compile_mission`: the path's altitude waypoints plus a waypoint at every
speed change and loiter point, a DO_CHANGE_SPEED before each waypoint whose leg changes speed,
and NAV_LOITER_TURNS after a loiter point. The takeoff time itself is not a mission item (the
coordinator arms each vehicle at its ``takeoff_s``). :func:`mission_from_json` reads the items
back for ``python -m planner export``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from planner.deconflict import Separation
from planner.errors import PlannerError
from planner.flightpath import FlightPath
from planner.mission import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    Loiter,
    MissionItem,
    SpeedChange,
    Waypoint,
    compile_mission,
)
from planner.scenario import Vehicle
from planner.schedule import Schedule, VehicleSchedule
from planner.terrain import Terrain
from planner.timing import flyable_loiter_radius_m

SCHEDULE_FORMAT = "tcgcs-schedule/1"
_MERGE_M = 1.0
_ALONG_PATH_COMMANDS = frozenset({MAV_CMD_NAV_WAYPOINT, MAV_CMD_DO_CHANGE_SPEED})
"""The items that mark the path itself; any other one at a waypoint's distance follows it."""


def _num(x: float, digits: int = 3) -> float | None:
    return round(float(x), digits) if math.isfinite(x) else None


@dataclass(frozen=True)
class PathMission:
    """Mission items and where each sits along the vehicle's path.

    ``item_s_m[k]``: a waypoint's or loiter's path distance (m); for DO_CHANGE_SPEED the start
    of the leg it governs (it runs when the previous waypoint is reached); None for home and
    the takeoff.
    """

    items: tuple[MissionItem, ...]
    item_s_m: tuple[float | None, ...]

    @property
    def first_route_seq(self) -> int:
        """The first item of the route: 2 after home and the takeoff, 1 with no takeoff."""
        return first_route_seq(self.items)


def first_route_seq(items: Sequence[MissionItem]) -> int:
    """Item 0 is home; item 1 the takeoff when there is one; the route starts after them."""
    return 2 if len(items) > 1 and items[1].command == MAV_CMD_NAV_TAKEOFF else 1


def vehicle_mission(schedule: Schedule, vs: VehicleSchedule, terrain: Terrain) -> list[MissionItem]:
    """The vehicle's mission items (home = its start on the ground, relative altitudes)."""
    return list(path_mission(schedule, vs, terrain).items)


def _split_legs(s_m: list[float], max_spacing_m: float) -> list[float]:
    """``s_m`` (ascending) with evenly spaced marks added where two are farther apart."""
    out: list[float] = []
    prev = 0.0
    for s in s_m:
        n = math.ceil((s - prev) / max_spacing_m - 1e-9)
        out.extend(prev + (s - prev) * k / n for k in range(1, n))
        out.append(s)
        prev = s
    return out


def path_mission(
    schedule: Schedule,
    vs: VehicleSchedule,
    terrain: Terrain,
    *,
    runout_m: float = 0.0,
    max_spacing_m: float | None = None,
) -> PathMission:
    """:func:`vehicle_mission` with each item's path distance.

    ``runout_m`` > 0 adds a last waypoint that far beyond the goal on the final heading, so
    that the aircraft flies through the goal rather than turning away once within its
    waypoint radius of it (ArduPlane's "reached" test).

    ``max_spacing_m`` splits longer legs with evenly spaced waypoints on the path (at the
    profile's altitude there). A coordinator in flight replaces a mission after a waypoint
    ahead of the aircraft; a 60 km leg would put the nearest such waypoint half an hour away.
    """
    if max_spacing_m is not None and not max_spacing_m > _MERGE_M:
        raise PlannerError(f"max_spacing_m must be more than {_MERGE_M:g} m, got {max_spacing_m}")
    frame = schedule.scenario.frame()
    v = schedule.scenario.vehicle(vs.vehicle_id)
    path = vs.path
    marks = {float(s) for s in vs.wp_s_m}
    marks.update(leg.s_end_m for leg in vs.legs)
    marks.update(lo.s_m for lo in vs.loiters)
    # After its takeoff the aircraft turns straight at the first waypoint: none lies inside
    # the climb-out, where it would turn back to it.
    first_m = _MERGE_M if vs.climb is None else max(vs.climb.first_waypoint_m, _MERGE_M)
    s_sorted: list[float] = []
    for s in sorted(marks):
        if s <= first_m:
            continue
        if s_sorted and s - s_sorted[-1] < _MERGE_M:
            continue
        s_sorted.append(min(s, path.length_m))
    if not s_sorted or s_sorted[-1] < path.length_m - _MERGE_M:
        s_sorted.append(path.length_m)
    else:
        s_sorted[-1] = path.length_m
    if max_spacing_m is not None:
        s_sorted = _split_legs(s_sorted, max_spacing_m)
    waypoints = []
    for s in s_sorted:
        p = path.pose_at(s)
        lat, lon = frame.to_geodetic(p.east_m, p.north_m)
        waypoints.append(Waypoint(float(lat), float(lon), vs.alt_at(s)))
    landing = schedule.scenario.landing
    if runout_m > 0.0 and landing is None:
        end = path.end
        e = end.east_m + runout_m * math.sin(end.heading_rad)
        n = end.north_m + runout_m * math.cos(end.heading_rad)
        lat, lon = frame.to_geodetic(e, n)
        waypoints.append(Waypoint(float(lat), float(lon), vs.alt_at(path.length_m)))
        s_sorted.append(path.length_m + runout_m)
    speeds: list[SpeedChange] = []
    last = math.nan
    prev_s = vs.climb_s_m  # the first leg's speed is set as the takeoff ends
    for i, s in enumerate(s_sorted):
        mid = 0.5 * (prev_s + s)
        leg = next((x for x in vs.legs if x.s_start_m <= mid <= x.s_end_m), None)
        if leg is not None and leg.speed_m_s != last:
            speeds.append(SpeedChange(i, leg.speed_m_s))
            last = leg.speed_m_s
        prev_s = s
    loiters = []
    for lo in vs.loiters:
        i = int(np.argmin([abs(s - lo.s_m) for s in s_sorted]))
        lat, lon = frame.to_geodetic(lo.centre_east_m, lo.centre_north_m)
        loiters.append(
            Loiter(
                i, float(lat), float(lon), vs.alt_at(lo.s_m), lo.turns, lo.radius_m, lo.clockwise
            )
        )
    se, sn = v.start.local(frame)
    ground = float(terrain.elevation_m(np.array([se]), np.array([sn]))[0])
    home_lat, home_lon = frame.to_geodetic(se, sn)
    home = Waypoint(float(home_lat), float(home_lon), ground)
    touchdown: Waypoint | bool = False
    if landing is not None:
        t_lat, t_lon = frame.to_geodetic(*landing.touchdown.local(frame))
        touchdown = Waypoint(float(t_lat), float(t_lon), landing.touchdown.alt_m)
    hold_radius_m = None
    if runout_m > 0.0 and landing is None:
        hold_radius_m = _clear_hold_radius_m(v, waypoints[-1], s_sorted[-1], path, terrain)
    items = compile_mission(
        home=home,
        waypoints=waypoints,
        # The climb-out's altitude (planner.climbout: the profile's start when the path's
        # first straight stretch holds the climb, else as high as fits, the route climbing
        # the rest). A vehicle taken over in the air has no takeoff.
        takeoff_alt_m=None
        if v.airborne
        else vs.climb.takeoff_alt_m
        if vs.climb is not None
        else max(vs.alt_at(0.0) - ground, 1.0),
        speeds=speeds,
        loiters=loiters,
        airspeed_limits_m_s=(v.speed_min_m_s, v.speed_max_m_s),
        land=touchdown,
        land_start=landing is not None,
        hold_radius_m=hold_radius_m,
    )
    first = first_route_seq(items)
    item_s: list[float | None] = [None] * first
    k = -1
    for it in items[first:]:
        if it.command == MAV_CMD_NAV_WAYPOINT:
            k += 1
            item_s.append(s_sorted[k])
        elif it.command == MAV_CMD_DO_CHANGE_SPEED:
            item_s.append(s_sorted[k] if k >= 0 else 0.0)
        else:
            item_s.append(s_sorted[k])
    return PathMission(tuple(items), tuple(item_s))


def _clear_hold_radius_m(
    v: Vehicle, last: Waypoint, s_last_m: float, path: FlightPath, terrain: Terrain
) -> float | None:
    """The radius of the hold after the run-out (the vehicle's flyable loiter radius), when
    its circle keeps the vehicle's terrain clearance all round at the run-out's altitude;
    else None (no hold: the mission ends as it did)."""
    radius = flyable_loiter_radius_m(v.min_turn_radius_m)
    end = path.end
    over = max(s_last_m - path.length_m, 0.0)
    e = end.east_m + over * math.sin(end.heading_rad)
    n = end.north_m + over * math.cos(end.heading_rad)
    # ArduPlane circles the point clockwise: the circle's centre is the point itself.
    angles = np.linspace(0.0, 2.0 * math.pi, 36, endpoint=False)
    ground = terrain.elevation_m(e + radius * np.cos(angles), n + radius * np.sin(angles))
    if float(np.max(ground)) + v.clearance_m > last.alt_m:
        return None
    return radius


def splice_mission(old: PathMission, keep_through_seq: int, new: PathMission) -> PathMission:
    """Old items up to a kept waypoint, then the new mission beyond that waypoint.

    The vehicle keeps flying the leg it is on (the items it has, up to ``keep_through_seq``,
    are unchanged, so an autopilot in AUTO carries on at its current index); from the kept
    waypoint it flies the new speeds, loiters and route, the turns the new mission has at the
    kept waypoint itself included (they follow it). The new mission must pass through the
    kept waypoint (re-plans start there; re-timings keep the path).

    Raises
    ------
    PlannerError
        ``keep_through_seq`` is not a waypoint of the old mission.
    """
    first = old.first_route_seq
    if not first <= keep_through_seq < len(old.items):
        raise PlannerError(
            f"splice: item {keep_through_seq} is outside the old mission's route "
            f"({first}..{len(old.items) - 1})"
        )
    kept = old.items[keep_through_seq]
    s_k = old.item_s_m[keep_through_seq]
    if kept.command != MAV_CMD_NAV_WAYPOINT or s_k is None:
        raise PlannerError(f"splice: item {keep_through_seq} is not a route waypoint")
    items = list(old.items[: keep_through_seq + 1])
    item_s: list[float | None] = list(old.item_s_m[: keep_through_seq + 1])
    tail = _tail_start(new, s_k)
    speed: MissionItem | None = None
    for it, s in zip(new.items[:tail], new.item_s_m[:tail], strict=True):
        if it.command == MAV_CMD_DO_CHANGE_SPEED and s is not None:
            speed = it
    if speed is not None:
        items.append(speed)
        item_s.append(s_k)
    items.extend(new.items[tail:])
    item_s.extend(new.item_s_m[tail:])
    return PathMission(
        tuple(replace(it, seq=i) for i, it in enumerate(items)),
        tuple(item_s),
    )


def _tail_start(new: PathMission, s_k_m: float) -> int:
    """The index of the first item of ``new`` flown after its waypoint at ``s_k_m`` (m along
    the path): a loiter (or other item) that waypoint carries, else the first item beyond it.

    A loiter sits at its waypoint's path distance: it belongs to what follows the waypoint,
    like the new speeds and route. Items are in path order, so the rest of ``new`` follows.
    """
    for k in range(new.first_route_seq, len(new.items)):
        s = new.item_s_m[k]
        if s is None:
            continue
        if s > s_k_m + _MERGE_M:
            return k
        at_waypoint = s >= s_k_m - _MERGE_M
        if at_waypoint and new.items[k].command not in _ALONG_PATH_COMMANDS:
            return k
    return len(new.items)


def _item_json(it: MissionItem) -> dict[str, Any]:
    return {
        "seq": it.seq,
        "frame": it.frame,
        "command": it.command,
        "param1": it.param1,
        "param2": it.param2,
        "param3": it.param3,
        "param4": it.param4,
        "x": it.x,
        "y": it.y,
        "z": it.z,
    }


def mission_from_json(doc: Mapping[str, Any], vehicle_id: str) -> list[MissionItem]:
    """The mission items stored for one vehicle in a schedule.json document."""
    listed = doc.get("vehicles")
    if not isinstance(listed, list):
        raise PlannerError("schedule.json: 'vehicles' is missing or not a list")
    vehicles = {v.get("id"): v for v in listed if isinstance(v, Mapping)}
    entry = vehicles.get(vehicle_id)
    if not isinstance(entry, Mapping):
        known = ", ".join(sorted(str(k) for k in vehicles))
        raise PlannerError(f"schedule.json: no vehicle {vehicle_id!r} (have {known})")
    try:
        return [
            MissionItem(
                seq=int(it["seq"]),
                frame=int(it["frame"]),
                command=int(it["command"]),
                current=0,
                autocontinue=1,
                param1=float(it["param1"]),
                param2=float(it["param2"]),
                param3=float(it["param3"]),
                param4=float(it["param4"]),
                x=int(it["x"]),
                y=int(it["y"]),
                z=float(it["z"]),
            )
            for it in entry["mission"]
        ]
    except (KeyError, TypeError, ValueError) as err:
        raise PlannerError(
            f"schedule.json: vehicle {vehicle_id}: bad mission item ({err})"
        ) from None


def schedule_json(
    schedule: Schedule,
    separation: Separation,
    terrain: Terrain,
    *,
    scenario_file: str,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The schedule.json document (contract fields plus missions, stages and events)."""
    frame = schedule.scenario.frame()
    closest = separation.minimum
    vehicles: dict[str, Any] = {}
    for vs in schedule.vehicles:
        loiters = []
        for lo in vs.loiters:
            lat, lon = frame.to_geodetic(lo.centre_east_m, lo.centre_north_m)
            loiters.append(
                {
                    "turns": lo.turns,
                    "radius_m": lo.radius_m,
                    "lat_deg": round(float(lat), 8),
                    "lon_deg": round(float(lon), 8),
                    "east_m": round(lo.centre_east_m, 2),
                    "north_m": round(lo.centre_north_m, 2),
                    "clockwise": lo.clockwise,
                    "s_m": round(lo.s_m, 2),
                    "detour_m": round(lo.detour_m, 2),
                    "added_m": round(lo.length_m, 2),
                    "speed_m_s": lo.speed_m_s,
                    "true_airspeed_m_s": round(lo.speed_m_s * lo.tas_per_eas, 3),
                    "t_start_s": round(lo.t_start_s, 3),
                    "t_end_s": round(lo.t_end_s, 3),
                    "buffer": lo.buffer_id,
                }
            )
        items = vehicle_mission(schedule, vs, terrain)
        vehicles[vs.vehicle_id] = {
            "id": vs.vehicle_id,
            "takeoff_s": round(vs.takeoff_s, 3),
            "arrival_s": round(vs.arrival_s, 3),
            "length_m": round(vs.path.length_m, 2),
            "speed_min_m_s": vs.speed_min_m_s,
            "speed_max_m_s": vs.speed_max_m_s,
            "replanned_at_s": [round(t, 3) for t in vs.replanned_at_s],
            "climb": None
            if vs.climb is None
            else {
                "takeoff_alt_m": round(vs.climb.takeoff_alt_m, 2),
                "duration_s": round(vs.climb.duration_s, 3),
                "s_m": round(vs.climb.s_m, 2),
                "first_waypoint_m": round(vs.climb.first_waypoint_m, 2),
                "climb_rate_m_s": vs.climb.climb_rate_m_s,
            },
            "legs": [
                {
                    "s_start_m": round(leg.s_start_m, 2),
                    "s_end_m": round(leg.s_end_m, 2),
                    "speed_m_s": leg.speed_m_s,
                    "true_airspeed_m_s": round(leg.true_airspeed_m_s, 3),
                    "groundspeed_m_s": round(leg.groundspeed_m_s, 3),
                    "t_start_s": round(leg.t_start_s, 3),
                    "t_end_s": round(leg.t_end_s, 3),
                }
                for leg in vs.legs
            ],
            "loiters": loiters,
            "mission": [_item_json(it) for it in items],
        }
    doc: dict[str, Any] = {
        "format": SCHEDULE_FORMAT,
        "scenario": schedule.scenario.name,
        "scenario_file": scenario_file,
        "requested_arrival_s": schedule.requested_arrival_s,
        "required_arrival_s": (
            None if schedule.required_arrival_s is None else round(schedule.required_arrival_s, 3)
        ),
        "arrival_reason": schedule.arrival_reason,
        "forecast_wind": None
        if schedule.scenario.wind is None
        else schedule.scenario.wind.model_dump(mode="json"),
        "speed_step_m_s": schedule.step_m_s,
        "separation_required_m": separation.required_m,
        "min_separation_m": _num(separation.min_separation_m, 1),
        "min_separation": None
        if closest is None
        else {
            "vehicles": [closest.a, closest.b],
            "time_s": round(closest.time_s, 2),
            "east_m": round(closest.east_m, 1),
            "north_m": round(closest.north_m, 1),
        },
        "conflicts": [
            {
                "vehicles": [p.a, p.b],
                "distance_m": round(p.distance_m, 1),
                "time_s": round(p.time_s, 2),
            }
            for p in separation.conflicts
        ],
        "adjustments": [
            {
                "time_s": round(a.time_s, 3),
                "vehicle": a.vehicle,
                "strategy": a.strategy,
                "value": a.value,
                "reason": a.reason,
            }
            for a in schedule.adjustments
        ],
        "events": [
            {"time_s": round(e.time_s, 3), "kind": e.kind, "text": e.text} for e in schedule.events
        ],
        "stages": [
            {
                "name": st.name,
                "time_s": round(st.time_s, 3),
                "vehicles": {
                    vid: [
                        [
                            round(sp.t_start_s, 2),
                            round(sp.t_end_s, 2),
                            round(sp.speed_m_s, 4),
                            sp.kind,
                        ]
                        for sp in spans
                    ]
                    for vid, spans in st.spans.items()
                },
            }
            for st in schedule.stages
        ],
        "vehicles": list(vehicles.values()),
    }
    if extra:
        doc.update(extra)
    return doc

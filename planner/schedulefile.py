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
from collections.abc import Mapping
from typing import Any

import numpy as np

from planner.deconflict import Separation
from planner.errors import PlannerError
from planner.mission import (
    Loiter,
    MissionItem,
    SpeedChange,
    Waypoint,
    compile_mission,
)
from planner.schedule import Schedule, VehicleSchedule
from planner.terrain import Terrain

SCHEDULE_FORMAT = "tcgcs-schedule/1"
_MERGE_M = 1.0


def _num(x: float, digits: int = 3) -> float | None:
    return round(float(x), digits) if math.isfinite(x) else None


def vehicle_mission(schedule: Schedule, vs: VehicleSchedule, terrain: Terrain) -> list[MissionItem]:
    """The vehicle's mission items (home = its start on the ground, relative altitudes)."""
    frame = schedule.scenario.frame()
    v = schedule.scenario.vehicle(vs.vehicle_id)
    path = vs.path
    marks = {float(s) for s in vs.wp_s_m}
    marks.update(leg.s_end_m for leg in vs.legs)
    marks.update(lo.s_m for lo in vs.loiters)
    s_sorted: list[float] = []
    for s in sorted(marks):
        if s <= _MERGE_M:
            continue
        if s_sorted and s - s_sorted[-1] < _MERGE_M:
            continue
        s_sorted.append(min(s, path.length_m))
    if not s_sorted or s_sorted[-1] < path.length_m - _MERGE_M:
        s_sorted.append(path.length_m)
    else:
        s_sorted[-1] = path.length_m
    waypoints = []
    for s in s_sorted:
        p = path.pose_at(s)
        lat, lon = frame.to_geodetic(p.east_m, p.north_m)
        waypoints.append(Waypoint(float(lat), float(lon), vs.alt_at(s)))
    speeds: list[SpeedChange] = []
    last = math.nan
    prev_s = 0.0
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
    return compile_mission(
        home=home,
        waypoints=waypoints,
        takeoff_alt_m=max(v.start.alt_m - ground, 1.0),
        speeds=speeds,
        loiters=loiters,
        airspeed_limits_m_s=(v.speed_min_m_s, v.speed_max_m_s),
    )


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
            "legs": [
                {
                    "s_start_m": round(leg.s_start_m, 2),
                    "s_end_m": round(leg.s_end_m, 2),
                    "speed_m_s": leg.speed_m_s,
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

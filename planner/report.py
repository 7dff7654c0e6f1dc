"""plan.json: the serialisable account of a plan (what operators' scripts read)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from planner.plan import Plan, PlannedRoute

PLAN_FORMAT = "tcgcs-plan/1"


def _num(x: float, digits: int = 3) -> float | None:
    return round(float(x), digits) if math.isfinite(x) else None


def route_json(plan: Plan, route: PlannedRoute) -> dict[str, Any]:
    frame = plan.scenario.frame()
    v = plan.scenario.vehicle(route.vehicle_id)
    wps = route.profile.waypoints_m
    lat, lon = frame.to_geodetic(wps[:, 0], wps[:, 1])
    return {
        "id": route.vehicle_id,
        "length_m": _num(route.length_m, 1),
        "grid_length_m": _num(route.grid_length_m, 1),
        "cost": _num(route.cost, 1),
        "optimal_cost": _num(route.optimal_cost, 1),
        "cost_ratio": _num(route.cost / route.optimal_cost, 5),
        "speed_min_m_s": v.speed_min_m_s,
        "speed_max_m_s": v.speed_max_m_s,
        "cruise_speed_m_s": v.cruise_m_s,
        "min_turn_radius_m": v.min_turn_radius_m,
        "path_min_turn_radius_m": _num(route.path.minimum_turn_radius_m(), 3),
        "min_clearance_m": _num(route.profile.min_clearance_m, 1),
        "clearance_required_m": v.clearance_m,
        "max_climb_gradient": _num(route.profile.max_gradient, 4),
        "min_forbidden_distance_m": _num(route.min_threat_distance_m, 1),
        "nearest_forbidden_zone": route.nearest_threat,
        "constraints": [
            {
                "constraint": c.constraint,
                "index": c.index,
                "value": _num(c.value),
                "limit": _num(c.limit),
                "message": c.message,
            }
            for c in route.constraints
        ],
        "waypoints": [
            {
                "lat_deg": round(float(a), 8),
                "lon_deg": round(float(o), 8),
                "alt_m": round(float(h), 1),
                "east_m": round(float(e), 2),
                "north_m": round(float(n), 2),
                "s_m": round(float(sm), 2),
            }
            for a, o, h, (e, n), sm in zip(
                np.atleast_1d(lat),
                np.atleast_1d(lon),
                route.profile.alt_m,
                wps,
                route.profile.s_m,
                strict=True,
            )
        ],
        "segments": [
            {
                "turn": seg.turn,
                "east_m": round(seg.start.east_m, 3),
                "north_m": round(seg.start.north_m, 3),
                "heading_deg": round(math.degrees(seg.start.heading_rad), 6),
                "length_m": round(seg.length_m, 3),
                "radius_m": None if seg.turn == "S" else round(seg.radius_m, 3),
            }
            for seg in route.path.segments
        ],
        "grid_route_m": [[round(float(e), 1), round(float(n), 1)] for e, n in route.simplified_m],
    }


def plan_json(
    plan: Plan, *, scenario_file: str, seed: int | None, elapsed_s: float
) -> dict[str, Any]:
    """The plan.json document."""
    s = plan.scenario
    return {
        "format": PLAN_FORMAT,
        "scenario": s.name,
        "scenario_file": scenario_file,
        "method": plan.method,
        "seed": seed,
        "status": str(plan.result.status),
        "message": plan.result.message,
        "iterations": plan.result.iterations,
        "elapsed_s": round(elapsed_s, 4),
        "origin": {"lat_deg": s.area.origin.lat_deg, "lon_deg": s.area.origin.lon_deg},
        "separation_required_m": s.separation_m,
        "min_separation_m": _num(plan.min_separation_m, 1),
        "nominal_takeoff_s": [round(float(t), 1) for t in plan.nominal_takeoff_s],
        "nominal_arrival_s": [round(float(t), 1) for t in plan.nominal_arrival_s],
        "vehicles": [route_json(plan, r) for r in plan.routes],
    }

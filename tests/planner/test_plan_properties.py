"""Safety properties of whole plans over random scenarios (hypothesis)."""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from planner.errors import InfeasibleError
from planner.plan import build_world, plan
from planner.scenario import parse_scenario


@st.composite
def scenarios(draw: st.DrawFn) -> dict[str, Any]:
    km = 1000.0
    radius = draw(st.sampled_from([100.0, 200.0, 350.0]))
    threats: list[dict[str, Any]] = []
    for k in range(draw(st.integers(0, 3))):
        threats.append(
            {
                "kind": "radar",
                "id": f"R{k}",
                "center": {
                    "east_m": draw(st.floats(5 * km, 25 * km)),
                    "north_m": draw(st.floats(5 * km, 25 * km)),
                },
                "radius_m": draw(st.floats(1.5 * km, 5 * km)),
                "forbidden": draw(st.booleans()),
            }
        )
    if draw(st.booleans()):
        e0, n0 = draw(st.floats(4 * km, 20 * km)), draw(st.floats(4 * km, 20 * km))
        w, h = draw(st.floats(2 * km, 8 * km)), draw(st.floats(2 * km, 8 * km))
        threats.append(
            {
                "kind": "no_fly",
                "id": "NFZ",
                "polygon": [
                    {"east_m": e0, "north_m": n0},
                    {"east_m": e0 + w, "north_m": n0},
                    {"east_m": e0 + w / 2, "north_m": n0 + h},
                ],
            }
        )
    vehicles = []
    for k in range(draw(st.integers(1, 2))):
        corner = draw(st.sampled_from([(1, 1), (1, 29), (29, 1)]))
        vehicles.append(
            {
                "id": f"V{k}",
                "start": {
                    "east_m": corner[0] * km + k * 500,
                    "north_m": corner[1] * km,
                    "alt_m": 900,
                },
                "goal": {"east_m": 29 * km - k * 800, "north_m": 29 * km, "alt_m": 900},
                "speed_min_m_s": 18,
                "speed_max_m_s": 30,
                "min_turn_radius_m": radius,
                "max_range_m": 500 * km,
                "alt_min_m": 200,
                "alt_max_m": 1700,
                "clearance_m": 100,
                "climb_gradient": draw(st.sampled_from([0.05, 0.1, 0.2])),
                "takeoff_window_s": [0, 1800],
            }
        )
    return {
        "area": {
            "origin": {"lat_deg": -33.0, "lon_deg": 151.0},
            "width_m": 30 * km,
            "height_m": 30 * km,
            "resolution_m": 1000,
        },
        "terrain": {
            "kind": "synthetic",
            "seed": draw(st.integers(0, 10_000)),
            "base_m": 100,
            "peak_m": draw(st.floats(0.0, 1500.0)),
            "hills": 8,
        },
        "separation_m": 200,
        "arrival": {"kind": "simultaneous"},
        "vehicles": vehicles,
        "threats": threats,
    }


REGRESSION_UNEVEN_SAMPLES: dict[str, Any] = {
    # Found by hypothesis: altitudes were once read at the wrong along-path distance.
    "area": {
        "origin": {"lat_deg": -33.0, "lon_deg": 151.0},
        "width_m": 30000.0,
        "height_m": 30000.0,
        "resolution_m": 1000,
    },
    "terrain": {"kind": "synthetic", "seed": 1098, "base_m": 100, "peak_m": 1116.0, "hills": 8},
    "separation_m": 200,
    "arrival": {"kind": "simultaneous"},
    "vehicles": [
        {
            "id": "V0",
            "start": {"east_m": 1000.0, "north_m": 1000.0, "alt_m": 900},
            "goal": {"east_m": 29000.0, "north_m": 29000.0, "alt_m": 900},
            "speed_min_m_s": 18,
            "speed_max_m_s": 30,
            "min_turn_radius_m": 100.0,
            "max_range_m": 500000.0,
            "alt_min_m": 200,
            "alt_max_m": 1700,
            "clearance_m": 100,
            "climb_gradient": 0.05,
            "takeoff_window_s": [0, 1800],
        }
    ],
    "threats": [],
}


@settings(
    max_examples=int(os.environ.get("PLAN_EXAMPLES", "40")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(scenarios(), st.sampled_from(["aco", "astar"]), st.integers(0, 3))
@example(REGRESSION_UNEVEN_SAMPLES, "aco", 0)
def test_plans_never_enter_forbidden_zones_nor_lose_clearance(
    data: dict[str, Any], method: str, seed: int
) -> None:
    scenario = parse_scenario(data)
    try:
        result = plan(scenario, method, rng=np.random.default_rng(seed))  # type: ignore[arg-type]
    except InfeasibleError as err:
        assert str(err).startswith("vehicle V")
        event(f"infeasible: {str(err).split(':')[1].split('(')[0].strip()}")
        return
    event("planned")
    world = build_world(scenario)
    forbidden = [t for t in world.threats if t.forbidden]
    for route in result.routes:
        v = scenario.vehicle(route.vehicle_id)
        path = route.path
        # Exact start and goal, never tighter than the minimum radius.
        assert math.dist((path.start.east_m, path.start.north_m), v.start.local(world.frame)) < 1e-6
        assert math.dist((path.end.east_m, path.end.north_m), v.goal.local(world.frame)) < 1e-6
        assert path.minimum_turn_radius_m() >= v.min_turn_radius_m - 1e-9
        assert route.cost >= route.optimal_cost * (1 - 1e-9)
        # The smoothed curve and the straight legs the autopilot flies stay out of every zone.
        s = np.linspace(0.0, path.length_m, int(path.length_m / 20.0) + 2)
        curve = np.array([[q.east_m, q.north_m] for q in (path.pose_at(float(x)) for x in s)])
        wps = route.profile.waypoints_m
        chords = np.concatenate([np.linspace(wps[i], wps[i + 1], 60) for i in range(len(wps) - 1)])
        for zone in forbidden:
            assert zone.distance_m(curve[:, 0], curve[:, 1]).min() > 0.0, zone.id
            assert zone.distance_m(chords[:, 0], chords[:, 1]).min() > 0.0, zone.id
        # Altitudes: straight-line climbs between waypoints keep the clearance, within limits.
        alt = np.interp(s, route.profile.s_m, route.profile.alt_m)
        ground = world.terrain.elevation_m(curve[:, 0], curve[:, 1])
        assert (alt - ground).min() >= v.clearance_m - 1.0
        chord_alt = np.concatenate(
            [
                np.linspace(route.profile.alt_m[i], route.profile.alt_m[i + 1], 60)
                for i in range(len(wps) - 1)
            ]
        )
        chord_ground = world.terrain.elevation_m(chords[:, 0], chords[:, 1])
        assert (chord_alt - chord_ground).min() >= v.clearance_m - 5.0
        assert route.profile.alt_m.max() <= v.alt_max_m + 1e-6
        assert route.profile.max_gradient <= v.climb_gradient + 1e-6


@settings(max_examples=200, deadline=None)
@given(
    shape=st.tuples(st.integers(1, 6), st.integers(1, 6)),
    seed=st.integers(0, 2**32 - 1),
    spread=st.floats(0.0, 3.0),
)
def test_the_bilinear_field_is_scipys_order_one_spline_held_at_the_edges(
    shape: tuple[int, int], seed: int, spread: float
) -> None:
    """:func:`planner.plan.bilinear` against ``scipy.ndimage.map_coordinates`` (order 1,
    ``mode="nearest"``), on fields of one row or column too, at points inside, on the edges
    and up to ``spread`` cells outside."""
    from scipy.ndimage import map_coordinates

    from planner.plan import bilinear

    rng = np.random.default_rng(seed)
    field = rng.normal(0.0, 100.0, shape)
    n = 64
    j = rng.uniform(-spread, shape[0] - 1 + spread, n)
    i = rng.uniform(-spread, shape[1] - 1 + spread, n)
    j[:4], i[:4] = [0, shape[0] - 1, 0, shape[0] - 1], [0, 0, shape[1] - 1, shape[1] - 1]
    want = map_coordinates(field, [j, i], order=1, mode="nearest")
    np.testing.assert_allclose(bilinear(field, j, i), want, rtol=1e-12, atol=1e-9)

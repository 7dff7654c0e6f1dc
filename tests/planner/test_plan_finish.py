"""Route finishing: the batched chord checks and the vectorised sampling agree exactly with
the chord-by-chord and point-by-point forms they replace."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from planner.flightpath import smooth_polyline
from planner.grid import CostMap
from planner.plan import (
    PROFILE_STEP_M,
    World,
    _grid_field,
    build_problem,
    build_world,
    plan,
    refine_corners,
    sample_by_distance,
    simplify_route,
)
from planner.problem import Problem
from planner.scenario import load_scenario, parse_scenario
from planner.search import optimal_nodes
from planner.terrain import Terrain
from planner.threats import ThreatZone, active
from tests.planner.conftest import small_scenario

ROOT = Path(__file__).resolve().parents[2]
FloatArray = NDArray[np.float64]


def _chord_by_chord(
    points_m: FloatArray,
    cmap: CostMap,
    threats: Sequence[ThreatZone],
    terrain: Terrain,
    margin_m: float,
) -> FloatArray:
    """The line-of-sight greedy with one terrain and cost look-up per chord (the reference)."""
    v = cmap.vehicle
    step = 0.25 * cmap.grid.resolution_m
    seg_len = np.hypot(*np.diff(points_m, axis=0).T)
    cost_mid = _grid_field(cmap, cmap.node_cost, 0.5 * (points_m[:-1] + points_m[1:]))
    leg_cost = np.concatenate([[0.0], np.cumsum(seg_len * cost_mid)])

    def chord_ok(i: int, j: int) -> bool:
        a, b = points_m[i], points_m[j]
        n = max(2, int(math.ceil(float(np.hypot(*(b - a))) / step)) + 1)
        pts = a + (b - a) * np.linspace(0.0, 1.0, n)[:, None]
        alt = np.maximum(terrain.elevation_m(pts[:, 0], pts[:, 1]) + v.clearance_m, v.alt_min_m)
        if float(alt.max()) > v.alt_max_m:
            return False
        cost = float(np.hypot(*(b - a))) * float(_grid_field(cmap, cmap.node_cost, pts).mean())
        if cost > leg_cost[j] - leg_cost[i] + 1e-6:
            return False
        for t in threats:
            if not t.forbidden or float(alt.min()) >= t.ceiling_m:
                continue
            if t.segment_distance_m(a[0], a[1], b[0], b[1]) < margin_m:
                return False
        return True

    keep = [0]
    i = 0
    last = len(points_m) - 1
    while i < last:
        j = i + 1
        while j + 1 <= last and chord_ok(i, j + 1):
            j += 1
        keep.append(j)
        i = j
    return np.asarray(points_m[keep], dtype=np.float64)


@pytest.fixture(scope="module")
def paper() -> tuple[World, Problem, list[ThreatZone]]:
    world = build_world(load_scenario(ROOT / "scenarios" / "paper_three_uav.yaml"))
    threats = active(world.threats, None)
    return world, build_problem(world, threats=threats), threats


def _routes(problem: Problem) -> list[FloatArray]:
    out = []
    for i in range(len(problem.tasks)):
        nodes = optimal_nodes(problem, i)
        assert nodes is not None
        out.append(problem.route_points(i, np.asarray(nodes)))
    return out


@pytest.mark.parametrize("margin_m", [0.0, 300.0, 900.0, 6000.0])
def test_simplify_route_equals_the_chord_by_chord_greedy(
    paper: tuple[World, Problem, list[ThreatZone]], margin_m: float
) -> None:
    world, problem, threats = paper
    terrain = world.terrain
    for index, pts in enumerate(_routes(problem)):
        cmap = problem.tasks[index].cost_map
        got = simplify_route(pts, cmap, threats, terrain, margin_m)
        np.testing.assert_array_equal(got, _chord_by_chord(pts, cmap, threats, terrain, margin_m))
        # A detour (the route there and back again) puts failing chords inside batches.
        detour = np.concatenate([pts, pts[-2::-1], pts[1:]])
        np.testing.assert_array_equal(
            simplify_route(detour, cmap, threats, terrain, margin_m),
            _chord_by_chord(detour, cmap, threats, terrain, margin_m),
        )


def test_sample_by_distance_equals_pose_at_point_by_point(
    paper: tuple[World, Problem, list[ThreatZone]],
) -> None:
    _, problem, _ = paper
    for pts in _routes(problem):
        path = smooth_polyline(refine_corners(pts, 300.0), 300.0)
        s, got = sample_by_distance(path, PROFILE_STEP_M)
        expected = np.array([[p.east_m, p.north_m] for p in (path.pose_at(float(x)) for x in s)])
        np.testing.assert_array_equal(got, expected)


def test_workers_give_the_same_plan() -> None:
    scenario = parse_scenario(small_scenario())
    one = plan(scenario, "aco", rng=np.random.default_rng(4))
    two = plan(scenario, "aco", rng=np.random.default_rng(4), workers=2)
    assert two.min_separation_m == one.min_separation_m
    for a, b in zip(one.routes, two.routes, strict=True):
        assert (a.vehicle_id, a.grid_nodes, a.cost) == (b.vehicle_id, b.grid_nodes, b.cost)
        np.testing.assert_array_equal(a.waypoints_m, b.waypoints_m)
        np.testing.assert_array_equal(a.profile.alt_m, b.profile.alt_m)
        assert a.path == b.path

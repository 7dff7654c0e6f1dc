from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse import csgraph

from planner.errors import InfeasibleError
from planner.grid import Grid, VehicleClass, build_cost_map
from planner.plan import build_problem, build_world, plan, solve
from planner.problem import Status
from planner.scenario import parse_scenario
from planner.threats import RadarSite, active
from tests.planner.conftest import small_scenario

FLAT = VehicleClass(clearance_m=100.0, alt_min_m=0.0, alt_max_m=3000.0, cruise_alt_m=500.0)


def test_free_space_costs_are_octile_distances() -> None:
    grid = Grid.covering(0.0, 0.0, 10000.0, 10000.0, 1000.0)
    cmap = build_cost_map(
        grid, np.zeros(grid.size), [], FLAT, threat_weight=1.0, terrain_weight=1.0
    )
    dist = csgraph.dijkstra(cmap.graph(), indices=0)
    corner = grid.nearest(10000.0, 10000.0)
    side = grid.nearest(10000.0, 3000.0)
    assert dist[corner] == pytest.approx(10 * math.sqrt(2) * 1000.0)
    assert dist[side] == pytest.approx((3 * math.sqrt(2) + 7) * 1000.0)


def test_no_edge_between_free_nodes_crosses_a_forbidden_zone() -> None:
    grid = Grid.covering(0.0, 0.0, 20000.0, 20000.0, 1000.0)
    zones = [RadarSite("S", 10300.0, 9700.0, 2600.0, 5000.0, True)]
    cmap = build_cost_map(
        grid, np.zeros(grid.size), zones, FLAT, threat_weight=1.0, terrain_weight=1.0
    )
    pts = grid.node_coords(np.arange(grid.size))
    for u, k in zip(*np.nonzero(np.isfinite(cmap.edge_cost)), strict=True):
        v = cmap.neighbors[u, k]
        a, b = pts[u], pts[v]
        assert zones[0].segment_distance_m(a[0], a[1], b[0], b[1]) > 0.0


def test_terrain_above_the_ceiling_blocks_nodes() -> None:
    grid = Grid.covering(0.0, 0.0, 4000.0, 4000.0, 1000.0)
    terrain = np.zeros(grid.size)
    terrain[grid.nearest(2000.0, 2000.0)] = 2950.0
    cmap = build_cost_map(grid, terrain, [], FLAT, threat_weight=1.0, terrain_weight=1.0)
    assert cmap.blocked.sum() == 1 and cmap.blocked[grid.nearest(2000.0, 2000.0)]


def test_exact_search_detours_around_the_forbidden_zone() -> None:
    s = parse_scenario(small_scenario())
    result = plan(s, "astar")
    assert result.result.status is Status.EXACT
    for r in result.routes:
        assert r.cost == pytest.approx(r.optimal_cost)
        assert r.min_threat_distance_m > 0.0


def test_unreachable_goal_is_an_infeasible_result() -> None:
    data = small_scenario()
    data["threats"].append(
        {
            "kind": "no_fly",
            "id": "WALL",
            "polygon": [
                {"east_m": 30000, "north_m": 0},
                {"east_m": 32000, "north_m": 0},
                {"east_m": 32000, "north_m": 40000},
                {"east_m": 30000, "north_m": 40000},
            ],
        }
    )
    s = parse_scenario(data)
    world = build_world(s)
    problem = build_problem(world, threats=active(world.threats, None))
    for method in ("astar", "aco"):
        result = solve(problem, method)  # type: ignore[arg-type]
        assert result.status is Status.INFEASIBLE
        assert result.message.startswith("vehicle A: goal unreachable")
    with pytest.raises(InfeasibleError, match="vehicle A: goal unreachable"):
        plan(s)


def test_start_inside_a_forbidden_zone_is_named() -> None:
    data = small_scenario()
    data["vehicles"][1]["start"] = {"east_m": 21000, "north_m": 19000, "alt_m": 500}
    with pytest.raises(InfeasibleError, match=r"vehicle B: start .* inside forbidden zone SAM"):
        plan(parse_scenario(data))

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planner.aco import solve_aco
from planner.plan import build_problem, build_world, plan
from planner.problem import Problem, Status
from planner.scenario import load_scenario, parse_scenario
from planner.threats import active
from tests.planner.conftest import small_scenario

ROOT = Path(__file__).resolve().parents[2]


def _problem(data: dict) -> Problem:  # type: ignore[type-arg]
    world = build_world(parse_scenario(data))
    return build_problem(world, threats=active(world.threats, None))


def test_same_seed_same_routes_other_seed_may_differ() -> None:
    problem = _problem(small_scenario())
    a = solve_aco(problem, rng=np.random.default_rng(7))
    b = solve_aco(problem, rng=np.random.default_rng(7))
    assert a.routes == b.routes and a.iterations == b.iterations


def test_paper_scenario_within_five_percent_of_optimal() -> None:
    s = load_scenario(ROOT / "scenarios" / "paper_three_uav.yaml")
    for seed in (0, 1, 2):
        p = plan(s, "aco", rng=np.random.default_rng(seed))
        assert p.result.status is Status.APPROXIMATE
        for r in p.routes:
            assert r.optimal_cost * (1 - 1e-9) <= r.cost <= 1.05 * r.optimal_cost


def test_routes_reach_their_goals_through_graph_edges() -> None:
    problem = _problem(small_scenario())
    result = solve_aco(problem, rng=np.random.default_rng(1))
    for task, route in zip(problem.tasks, result.routes, strict=True):
        assert route is not None
        assert route.nodes[0] == task.start_node and route.nodes[-1] == task.goal_node
        assert len(set(route.nodes)) == len(route.nodes)
        assert task.cost_map.path_cost(route.nodes) == pytest.approx(route.cost)


def test_separation_coupling_resolves_a_crossing_conflict() -> None:
    # A flies west to east and B south to north, equal lengths and speeds, no takeoff freedom:
    # their shortest routes cross at the centre at the same moment. The comprehensive cost
    # makes a colony pick a route that keeps d_s.
    data = small_scenario(threats=[], separation_m=300)
    for v in data["vehicles"]:
        v["takeoff_window_s"] = [0, 0]
    data["vehicles"][0]["start"] = {"east_m": 4000, "north_m": 20000, "alt_m": 500}
    data["vehicles"][0]["goal"] = {"east_m": 36000, "north_m": 20000, "alt_m": 500}
    data["vehicles"][1]["start"] = {"east_m": 20000, "north_m": 4000, "alt_m": 500}
    data["vehicles"][1]["goal"] = {"east_m": 20000, "north_m": 36000, "alt_m": 500}
    problem = _problem(data)
    from planner.search import solve_exact

    exact = solve_exact(problem)
    assert all(r is not None and r.cost == 32000.0 for r in exact.routes)
    result = solve_aco(problem, rng=np.random.default_rng(3))
    assert result.status is Status.APPROXIMATE, result.message
    assert result.min_separation_m >= 300.0
    assert sum(result.costs) > 64000.0  # someone detoured

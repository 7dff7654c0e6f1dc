from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planner.aco import (
    _BROADCAST_TABU_ANTS,
    AcoOptions,
    _Colonies,
    _count_true,
    _erase_loops,
    _in_rows,
    route_figures,
    solve_aco,
)
from planner.plan import build_problem, build_world, plan
from planner.problem import Problem, Status, polyline_length_m
from planner.scenario import load_scenario, parse_scenario
from planner.threats import active
from tests.planner.conftest import small_scenario
from tests.teams import landing_scenario

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


def test_a_search_whose_time_is_up_ends_with_the_routes_it_has() -> None:
    """``time_up`` is asked once every colony has a route: answering True at once ends the
    search after its first iteration, with a route for every vehicle through graph edges
    from its start to its goal; never True, the search runs to its caps. How many times it
    was asked is counted here."""
    problem = _problem(small_scenario())
    asked: list[bool] = []

    def at_once() -> bool:
        asked.append(True)
        return True

    cut = solve_aco(problem, rng=np.random.default_rng(1), options=AcoOptions(time_up=at_once))
    full = solve_aco(
        problem, rng=np.random.default_rng(1), options=AcoOptions(time_up=lambda: False)
    )
    assert cut.iterations == 1 and len(asked) == 1
    assert full.iterations > 1
    assert full.routes == solve_aco(problem, rng=np.random.default_rng(1)).routes
    for task, route in zip(problem.tasks, cut.routes, strict=True):
        assert route is not None
        assert route.nodes[0] == task.start_node and route.nodes[-1] == task.goal_node
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


@pytest.mark.parametrize("n_ants", [1, 36, _BROADCAST_TABU_ANTS, 1200])
def test_tabu_lookup_matches_a_plain_comparison(n_ants: int) -> None:
    rng = np.random.default_rng(n_ants)
    neighbours = rng.integers(-1, 40, (n_ants, 8))
    recent = rng.integers(-1, 40, (n_ants, 8))
    expected = [
        [int(v) in row.tolist() for v in nb] for nb, row in zip(neighbours, recent, strict=True)
    ]
    assert _in_rows(neighbours, recent).tolist() == expected


@pytest.mark.parametrize(
    ("walk", "path"),
    [
        ([1, 2, 3], [1, 2, 3]),
        ([1, 2, 3, 2, 4], [1, 2, 4]),
        ([5, 6, 5, 6, 7], [5, 6, 7]),
        ([1, 2, 3, 4, 2, 5, 3, 6], [1, 2, 5, 3, 6]),
    ],
)
def test_erase_loops_keeps_the_path_from_each_last_visit(walk: list[int], path: list[int]) -> None:
    assert _erase_loops(np.array(walk, dtype=np.int64)).tolist() == path


@pytest.mark.parametrize("landing", [False, True])
def test_route_figures_equal_the_route_by_route_measures(landing: bool) -> None:
    # With landing slots each route ends with the slot's straight final (a tail).
    problem = _problem(landing_scenario(0)[0] if landing else small_scenario())
    assert any(t.tail_m for t in problem.tasks) == landing
    colonies = _Colonies(problem, AcoOptions())
    col, walks = colonies.walk(np.arange(len(problem.tasks)), np.random.default_rng(3))
    for c in range(len(problem.tasks)):
        mine = [w for w, k in zip(walks, col.tolist(), strict=True) if k == c and w is not None]
        task = problem.tasks[c]
        # Also a single node, and a route that jumps between nodes that are not neighbours.
        mine += [np.array([task.start_node]), np.array([task.start_node, task.goal_node])]
        figures = route_figures(problem, c, mine)
        assert len(figures) == len(mine) > 2
        for nodes, (points, cost, length) in zip(mine, figures, strict=True):
            expected = problem.route_points(c, nodes)
            np.testing.assert_array_equal(points, expected)
            assert cost == task.cost_map.path_cost(nodes)
            assert length == polyline_length_m(expected)


def test_count_true_counts_each_row() -> None:
    mask = np.random.default_rng(9).random((500, 8)) < 0.4
    mask[0] = True
    mask[1] = False
    assert _count_true(mask).tolist() == mask.sum(axis=1).tolist()
    assert _count_true(mask[:, ::-1]).tolist() == mask.sum(axis=1).tolist()  # not contiguous

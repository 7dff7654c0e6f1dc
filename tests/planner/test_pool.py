"""The planner's per-vehicle work in forked workers (:mod:`planner.pool`): the cost-to-go
fields computed there, several goals to a search, are the fields each vehicle's own search
gives; a team large enough is planned on every core by default, with the same plan.

The planner forks only while its process runs no other thread, and earlier tests in the same
process may leave one running (a thread pool's worker, Ray's): the checks that must fork run
in a process of their own (:func:`_alone`)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from planner.plan import build_problem, build_world, fill_fields, plan
from planner.pool import PARALLEL_MIN_VEHICLES, default_workers, forked_map
from planner.problem import Problem, goal_fields
from planner.scenario import Scenario, load_scenario, parse_scenario
from tests.teams import ring_team

ROOT = Path(__file__).resolve().parents[2]


def _problem(scenario: Scenario) -> Problem:
    world = build_world(scenario)
    return build_problem(world, threats=world.threats)


def _mixed_team() -> Scenario:
    """Twenty-two vehicles of two classes (two cost maps): every fourth one flies lower."""
    data = ring_team(22)
    for k, v in enumerate(data["vehicles"]):
        if k % 4 == 0:
            v["alt_max_m"] = 1500
    return parse_scenario(data)


def _alone(check: str) -> None:
    """Run ``check`` (a function of this module) in a fresh process: it may fork there."""
    done = subprocess.run(
        [sys.executable, "-c", f"from tests.planner.test_pool import {check}; {check}()"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]


def test_fields_computed_in_workers_are_each_vehicles_own_search() -> None:
    _alone("check_fields_in_workers")


def check_fields_in_workers() -> None:
    assert threading.active_count() == 1
    scenario = _mixed_team()
    forked, alone = _problem(scenario), _problem(scenario)
    assert len({id(t.cost_map) for t in forked.tasks}) == 2
    fill_fields(forked, workers=2)
    assert forked.fields_missing() == []
    assert alone.fields_missing() == list(range(len(alone.tasks)))
    for i, task in enumerate(alone.tasks):
        # Each vehicle's own single-goal search, as Problem.cost_to_go runs it alone.
        ((dist, pred),) = goal_fields(task.cost_map, [task.goal_node])
        got_dist, got_pred = forked.cost_to_go(i)
        np.testing.assert_array_equal(got_dist, dist)
        np.testing.assert_array_equal(got_pred, pred)
        assert got_dist[task.goal_node] == 0.0 and np.isfinite(got_dist[task.start_node])


def test_one_worker_leaves_the_fields_to_be_computed_when_asked() -> None:
    problem = _problem(load_scenario(ROOT / "scenarios" / "paper_three_uav.yaml"))
    fill_fields(problem, workers=1)
    assert problem.fields_missing() == [0, 1, 2]
    problem.cost_to_go(1)
    assert problem.fields_missing() == [0, 2]


def test_a_large_team_is_planned_on_every_core_with_the_same_plan() -> None:
    _alone("check_default_workers_plan")


def check_default_workers_plan() -> None:
    assert threading.active_count() == 1
    assert default_workers(PARALLEL_MIN_VEHICLES - 1) == 1
    assert default_workers(PARALLEL_MIN_VEHICLES) == len(os.sched_getaffinity(0))
    scenario = _mixed_team()
    one = plan(scenario, rng=np.random.default_rng(2), workers=1)
    default = plan(scenario, rng=np.random.default_rng(2))
    assert [r.grid_nodes for r in default.routes] == [r.grid_nodes for r in one.routes]
    for a, b in zip(one.routes, default.routes, strict=True):
        np.testing.assert_array_equal(a.waypoints_m, b.waypoints_m)
        np.testing.assert_array_equal(a.profile.alt_m, b.profile.alt_m)
    assert default.min_separation_m == one.min_separation_m


def _square(offset: int, x: int) -> int:
    return offset + x * x


def test_forked_map_keeps_order_and_does_not_fork_beside_another_thread() -> None:
    _alone("check_forked_map")


def check_forked_map() -> None:
    assert threading.active_count() == 1
    assert forked_map(_square, 1, [1, 2, 3, 4, 5], workers=2) == [2, 5, 10, 17, 26]
    assert forked_map(_square, 1, [1], workers=2) is None  # one item: not worth a fork
    assert forked_map(_square, 1, [1, 2], workers=1) is None
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert forked_map(_square, 1, [1, 2, 3], workers=2) is None
    finally:
        stop.set()
        other.join()


def _fails_on_three(_: None, x: int) -> int:
    if x == 3:
        raise ValueError(f"item {x}")
    return x


def test_a_failing_item_raises_its_error_here() -> None:
    _alone("check_failing_item")


def check_failing_item() -> None:
    with pytest.raises(ValueError, match="item 3"):
        forked_map(_fails_on_three, None, [1, 2, 3, 4], workers=2)

"""Exact search: Dijkstra on the grid graph, the optimality baseline of the planner."""

from __future__ import annotations

import math

import numpy as np

from planner.problem import Problem, Route, SolveResult, Status, polyline_length_m


def optimal_nodes(problem: Problem, index: int) -> list[int] | None:
    """Nodes of an optimal route of task ``index`` (None when the goal is unreachable)."""
    task = problem.tasks[index]
    dist, pred = problem.cost_to_go(index)
    if not math.isfinite(dist[task.start_node]):
        return None
    nodes = [task.start_node]
    while nodes[-1] != task.goal_node:
        nxt = int(pred[nodes[-1]])
        if nxt < 0:
            return None
        nodes.append(nxt)
    return nodes


def solve_exact(problem: Problem) -> SolveResult:
    """Each vehicle's optimal route on its own cost map (no team coupling).

    Status is EXACT when every goal is reachable, INFEASIBLE otherwise (the message names the
    first vehicle whose goal cannot be reached).
    """
    routes: list[Route | None] = []
    unreachable: list[str] = []
    for i, task in enumerate(problem.tasks):
        nodes = optimal_nodes(problem, i)
        if nodes is None:
            routes.append(None)
            unreachable.append(task.vehicle_id)
            continue
        dist, _ = problem.cost_to_go(i)
        pts = problem.route_points(i, np.asarray(nodes))
        routes.append(
            Route(
                task.vehicle_id, tuple(nodes), float(dist[task.start_node]), polyline_length_m(pts)
            )
        )
    if unreachable:
        return SolveResult(
            Status.INFEASIBLE,
            tuple(routes),
            1,
            f"vehicle {unreachable[0]}: goal unreachable without entering a forbidden zone "
            "or exceeding alt_max_m",
        )
    return SolveResult(Status.EXACT, tuple(routes), 1, "optimal routes found")

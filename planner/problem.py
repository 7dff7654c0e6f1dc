"""The grid planning problem both solvers take, and the result both return (OMPL style).

``solve(problem, method, rng=...)`` is the single entry point: the exact search and the
multi-colony ACO look alike from outside. An approximate answer is a status, not an exception.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from planner.coupling import TimingLimits
from planner.grid import CostMap

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]


class Status(enum.StrEnum):
    EXACT = "exact"
    APPROXIMATE = "approximate"
    TIMEOUT = "timeout"
    INFEASIBLE = "infeasible"


@dataclass(frozen=True, eq=False)
class VehicleTask:
    """One vehicle's part of the problem: its nodes, cost map and timing limits."""

    vehicle_id: str
    start_node: int
    goal_node: int
    start_m: tuple[float, float]
    goal_m: tuple[float, float]
    cost_map: CostMap
    timing: TimingLimits
    tail_m: tuple[tuple[float, float], ...] = ()
    """Points flown straight after ``goal_m`` (a landing slot's final: ``goal_m`` is where
    the final begins, the last point the slot fix)."""


@dataclass(frozen=True, eq=False)
class Problem:
    """The team problem on one grid: tasks, team arrival reference and separation ``d_s``."""

    tasks: tuple[VehicleTask, ...]
    required_arrival_s: float | None
    separation_m: float
    _cost_to_go: dict[int, tuple[FloatArray, IntArray]] = field(default_factory=dict, repr=False)

    def cost_to_go(self, index: int) -> tuple[FloatArray, IntArray]:
        """Exact cost-to-go field (to the task's goal) and predecessors toward the goal.

        The graph is symmetric, so Dijkstra from the goal gives every node's cost to reach it;
        ``predecessors[u]`` is the next node from ``u`` on an optimal path.
        """
        if index not in self._cost_to_go:
            task = self.tasks[index]
            (self._cost_to_go[index],) = goal_fields(task.cost_map, [task.goal_node])
        return self._cost_to_go[index]

    def fields_missing(self) -> list[int]:
        """The tasks whose cost-to-go field is not computed yet."""
        return [i for i in range(len(self.tasks)) if i not in self._cost_to_go]

    def put_fields(
        self, indices: Sequence[int], fields: Sequence[tuple[FloatArray, IntArray]]
    ) -> None:
        """Keep cost-to-go fields computed elsewhere (:func:`task_fields`, in another process)."""
        for index, field_ in zip(indices, fields, strict=True):
            self._cost_to_go[index] = field_

    def route_points(self, index: int, nodes: Sequence[int] | IntArray) -> FloatArray:
        """Polyline (K, 2) in metres: the exact start, the grid nodes, the exact goal (and the
        task's tail after it). A first node at the start (to :func:`allclose_2d`) is the start
        itself: a re-plan's route begins exactly where the path flown so far ends."""
        task = self.tasks[index]
        pts = task.cost_map.grid.node_coords(nodes)
        start = np.array([task.start_m])
        goal = np.array([task.goal_m])
        if allclose_2d(pts[-1], task.goal_m):
            goal = goal[:0]
        if allclose_2d(pts[0], task.start_m):
            pts = pts[1:]
        tail = np.array(task.tail_m, dtype=np.float64).reshape(-1, 2)
        return np.concatenate([start, pts, goal, tail])


def goal_fields(cost_map: CostMap, goal_nodes: Sequence[int]) -> list[tuple[FloatArray, IntArray]]:
    """Cost-to-go field and predecessors towards each goal node on one cost map.

    The graph is symmetric, so Dijkstra from the goal gives every node's cost to reach it; one
    call searches from every goal (each search is its own, as if alone).
    """
    from scipy.sparse import csgraph  # a sixth of a second: only where routes are searched

    dist, pred = csgraph.dijkstra(
        cost_map.graph(), directed=True, indices=list(goal_nodes), return_predecessors=True
    )
    return [
        (np.asarray(d, dtype=np.float64), np.asarray(p, dtype=np.int64))
        for d, p in zip(np.atleast_2d(dist), np.atleast_2d(pred), strict=True)
    ]


def task_fields(problem: Problem, indices: Sequence[int]) -> list[tuple[FloatArray, IntArray]]:
    """The cost-to-go fields of tasks ``indices`` (in that order), one search per cost map
    for all of its goals: what :meth:`Problem.cost_to_go` computes for each, without keeping
    them (a worker computes them; the planning problem keeps them: :meth:`Problem.put_fields`).
    """
    out: dict[int, tuple[FloatArray, IntArray]] = {}
    by_map: dict[int, list[int]] = {}
    for i in indices:
        by_map.setdefault(id(problem.tasks[i].cost_map), []).append(i)
    for group in by_map.values():
        cost_map = problem.tasks[group[0]].cost_map
        fields = goal_fields(cost_map, [problem.tasks[i].goal_node for i in group])
        out.update(zip(group, fields, strict=True))
    return [out[i] for i in indices]


def allclose_2d(point_m: FloatArray | Sequence[float], other_m: tuple[float, float]) -> bool:
    """``np.allclose`` (default tolerances) for two 2-D points, without its array overhead.

    The ACO builds the polyline of every ant's route, so this test runs tens of thousands
    of times per plan.
    """
    return all(
        abs(float(a) - b) <= 1e-8 + 1e-5 * abs(b) for a, b in zip(point_m, other_m, strict=True)
    )


@dataclass(frozen=True)
class Route:
    """One vehicle's grid route: nodes, graph cost and polyline length."""

    vehicle_id: str
    nodes: tuple[int, ...]
    cost: float
    length_m: float


@dataclass(frozen=True)
class SolveResult:
    """What a solver returns (scipy.optimize style: status, message, iterations)."""

    status: Status
    routes: tuple[Route | None, ...]
    iterations: int
    message: str
    comprehensive_cost: float = math.nan
    time_gap_s: float = 0.0
    min_separation_m: float = math.inf

    @property
    def success(self) -> bool:
        return self.status in (Status.EXACT, Status.APPROXIMATE)

    @property
    def costs(self) -> tuple[float, ...]:
        return tuple(r.cost if r is not None else math.inf for r in self.routes)


def polyline_length_m(points_m: FloatArray) -> float:
    return float(np.hypot(*np.diff(points_m, axis=0).T).sum())

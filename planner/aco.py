"""Multi-colony ant colony optimisation (section 3.1 of the reference paper, STEP1-STEP6).

One colony per vehicle. Ants of every colony walk the grid together, vectorised with numpy.
The state transition weighs each move by pheromone ``tau ** alpha`` and visibility
``eta ** beta``, where the visibility comes from the exact cost-to-go field: a move's regret
(its edge cost plus the cost-to-go of where it leads, minus the cost-to-go of where the ant
stands) is 0 on an optimal move, so ``eta = 1 / (1 + regret / step_cost)``. With probability
``q0`` an ant takes the best-weighted move (the ACS pseudo-random proportional rule).

The colonies share knowledge through the comprehensive cost: a candidate route's own graph cost
plus penalties for (a) no common feasible arrival time given the other colonies' best routes
(eq. 1's window intersection) and (b) separation below ``d_s`` from the other vehicles' best
routes, each vehicle flown at constant speed to the team's nominal arrival. Pheromone follows
the MAX-MIN rule: evaporation, deposit on the colony's best and iteration-best nodes, bounds.

STEP5 is the inner loop (iterate a colony until its best stops improving or the cap is hit);
STEP6 is the outer loop (refresh the shared knowledge, re-evaluate every colony's best against
it, stop when the integrated cost settles).
"""

from __future__ import annotations

import itertools
import math
import mmap
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner.coupling import GridTracks, LimitArrays, positions_at, team_timing, window_gap_s
from planner.pool import PARALLEL_MIN_VEHICLES, ForkedWorkers
from planner.problem import Problem, Route, SolveResult, Status, allclose_2d
from planner.search import solve_exact

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class AcoOptions:
    """Parameters of the multi-colony ACO (defaults tuned on the paper scenario)."""

    ants: int = 12
    alpha: float = 1.0
    beta: float = 4.0
    q0: float = 0.7
    rho: float = 0.25
    tau_min: float = 0.05
    tau_max: float = 1.0
    max_iter: int = 10
    patience: int = 3
    rounds: int = 3
    tol: float = 1e-3
    tabu: int = 8
    max_steps_factor: float = 2.5
    time_penalty_m_per_s: float = 100.0
    separation_penalty: float = 20.0
    candidates: int = 4
    time_up: Callable[[], bool] | None = None
    """Asked before each iteration once every colony has a route: True ends the search there
    with the best routes so far (a re-plan in flight that must be on board before the
    vehicles reach it; the caller keeps the clock). None: the iteration caps alone."""


@dataclass(slots=True)
class _Best:
    nodes: IntArray
    points: FloatArray
    cost: float
    length_m: float
    score: float


class _Colonies:
    """Mutable search state; one instance per solve call."""

    def __init__(self, problem: Problem, opts: AcoOptions) -> None:
        self.p = problem
        self.o = opts
        tasks = problem.tasks
        grid = tasks[0].cost_map.grid
        self.neighbors = tasks[0].cost_map.neighbors
        # Neighbour indices with node 0 standing in off the grid (masked out by the cost).
        self.safe_neighbors = np.where(self.neighbors >= 0, self.neighbors, 0)
        self.step_cost = grid.resolution_m
        maps: dict[int, int] = {}
        stacks: list[FloatArray] = []
        cls: list[int] = []
        for t in tasks:
            key = id(t.cost_map)
            if key not in maps:
                maps[key] = len(stacks)
                stacks.append(t.cost_map.edge_cost)
            cls.append(maps[key])
        self.edge = np.stack(stacks)
        self.cls = np.asarray(cls, dtype=np.int64)
        self.h = np.stack([problem.cost_to_go(i)[0] for i in range(len(tasks))])
        self.start = np.array([t.start_node for t in tasks], dtype=np.int64)
        self.goal = np.array([t.goal_node for t in tasks], dtype=np.int64)
        # The pheromone lives in memory shared with forked walkers (planner.pool): they see
        # each iteration's update without it being sent.
        self._tau_map = mmap.mmap(-1, max(len(tasks) * grid.size * 8, 1))
        self.tau = np.frombuffer(self._tau_map, dtype=np.float64, count=len(tasks) * grid.size)
        self.tau = self.tau.reshape(len(tasks), grid.size)
        self.tau[:] = opts.tau_max
        hops = [
            max(
                abs(int(t.start_node % grid.n_east) - int(t.goal_node % grid.n_east)),
                abs(int(t.start_node // grid.n_east) - int(t.goal_node // grid.n_east)),
            )
            for t in tasks
        ]
        self.max_steps = int(opts.max_steps_factor * max(hops)) + 20

    def walk(
        self, colonies: IntArray, rng: np.random.Generator
    ) -> tuple[IntArray, list[IntArray | None]]:
        """All ants of the given colonies walk once, drawing from ``rng``; returns each ant's
        colony and nodes.

        One step of every walking ant is a few dozen numpy calls, whatever the number of
        ants, so a small team's walk is all call overhead: the fields are read through flat
        views (one gather each), a move off the grid or towards an unreachable node weighs
        nothing because its regret is infinite, and ``alpha`` 1 and ``beta`` 4 are products
        rather than powers.
        """
        o = self.o
        col = np.repeat(colonies, o.ants)
        n_ants = len(col)
        n_nodes = self.h.shape[1]
        h = self.h.reshape(-1)
        tau = self.tau.reshape(-1)
        edge = self.edge.reshape(-1, self.neighbors.shape[1])
        field_base = col * n_nodes  # the ant's colony's row of h and tau, flat
        edge_base = self.cls[col] * n_nodes  # the ant's cost map's rows of edge, flat
        pos = self.start[col].copy()
        goal = self.goal[col]
        trail = np.full((n_ants, self.max_steps + 1), -1, dtype=np.int64)
        trail[:, 0] = pos
        recent = np.full((n_ants, o.tabu), -1, dtype=np.int64)
        recent[:, 0] = pos
        arrived = pos == goal
        walking = ~arrived
        length = np.zeros(n_ants, dtype=np.int64)
        moves = self.neighbors.shape[1]
        for step in range(1, self.max_steps + 1):
            act = np.flatnonzero(walking)
            if act.size == 0:
                break
            u = pos[act]
            base = field_base[act]
            nb = self.neighbors[u]
            safe = self.safe_neighbors[u]
            # regret = edge + h(next) - h(here): infinite off the grid or where no route goes.
            regret = edge[edge_base[act] + u]
            regret += h[base[:, None] + safe]
            regret -= h[base + u][:, None]
            eta = 1.0 / (1.0 + regret / self.step_cost)
            w = tau[base[:, None] + safe]
            if o.alpha != 1.0:
                w **= o.alpha
            if o.beta == 4.0:
                eta *= eta
                w *= eta * eta
            else:
                w *= eta**o.beta
            w[_in_rows(nb, recent[act])] = 0.0  # tabu
            total = w.sum(axis=1)
            ok = total > 0.0
            greedy = rng.random(act.size) < o.q0
            r = rng.random(act.size) * total
            k_roulette = np.minimum(_count_true(np.cumsum(w, axis=1) < r[:, None]), moves - 1)
            k = np.where(greedy, np.argmax(w, axis=1), k_roulette)
            nxt = nb.reshape(-1)[np.arange(act.size) * moves + k]
            if not ok.all():
                walking[act[~ok]] = False  # stuck: every move tabu or closed
                act, nxt = act[ok], nxt[ok]
            pos[act] = nxt
            trail[act, step] = nxt
            recent[act, step % o.tabu] = nxt
            length[act] = step
            there = act[nxt == goal[act]]
            arrived[there] = True
            walking[there] = False
        routes: list[IntArray | None] = []
        for a in range(n_ants):
            if not arrived[a]:
                routes.append(None)
                continue
            routes.append(_erase_loops(trail[a, : length[a] + 1]))
        return col, routes


def route_figures(
    problem: Problem, index: int, walks: list[IntArray]
) -> list[tuple[FloatArray, float, float]]:
    """Polyline (m), graph cost and length (m) of many node routes of one task at once.

    The same values as ``problem.route_points``, ``cost_map.path_cost`` and
    ``polyline_length_m`` route by route (each route's sums are taken over its own slice, as
    alone), with the per-route numpy calls shared: every ant's route is measured, so this
    runs for tens of thousands of routes per plan.
    """
    if not walks:
        return []
    task = problem.tasks[index]
    cmap = task.cost_map
    nodes = np.concatenate(walks)
    coords = cmap.grid.node_coords(nodes)
    sizes = np.array([len(w) for w in walks])
    ends = np.cumsum(sizes)
    first_nodes = coords[ends - sizes].tolist()
    last_nodes = coords[ends - 1].tolist()
    node_bounds = [0, *ends.tolist()]
    start = np.array([task.start_m], dtype=np.float64)
    goal = np.array([task.goal_m], dtype=np.float64)
    tail = np.array(task.tail_m, dtype=np.float64).reshape(-1, 2)
    pieces: list[FloatArray] = []
    point_bounds = [0]
    for k, (lo, hi) in enumerate(itertools.pairwise(node_bounds)):
        first = not allclose_2d(first_nodes[k], task.start_m)
        last = not allclose_2d(last_nodes[k], task.goal_m)
        # A first node at the start is the start itself.
        pieces.extend([start, coords[lo + int(not first) : hi], goal[: int(last)], tail])
        point_bounds.append(point_bounds[-1] + int(first) + (hi - lo) + int(last) + len(tail))
    points = np.concatenate(pieces)
    step = np.diff(points, axis=0)
    leg_m = np.hypot(step[:, 0], step[:, 1])
    a, b = nodes[:-1], nodes[1:]
    match = cmap.neighbors[a] == b[:, None]
    linked = match.any(axis=1)
    edge = cmap.edge_cost[a, match.argmax(axis=1)]
    out = []
    for k, (lo, hi) in enumerate(itertools.pairwise(node_bounds)):
        p_lo, p_hi = point_bounds[k], point_bounds[k + 1]
        if hi - lo < 2:
            cost = 0.0
        elif not linked[lo : hi - 1].all():
            cost = math.inf
        else:
            cost = float(edge[lo : hi - 1].sum())
        out.append((points[p_lo:p_hi], cost, float(leg_m[p_lo : p_hi - 1].sum())))
    return out


_BITWISE_COUNT = getattr(np, "bitwise_count", None)


def _count_true(mask: NDArray[np.bool_]) -> IntArray:
    """Number of True values in each row of an (A, 8) mask (one per move of the grid).

    A row's 8 booleans are the 8 bytes of one 64-bit word, each 0 or 1, so counting the
    word's set bits counts them: a single fast pass, where a sum along the short axis is
    one of the walk's slowest steps.
    """
    if _BITWISE_COUNT is None:  # numpy before 2.0
        return np.asarray(mask.sum(axis=1), dtype=np.int64)
    words = np.ascontiguousarray(mask).view(np.uint64)
    return np.asarray(_BITWISE_COUNT(words)[:, 0], dtype=np.int64)


_BROADCAST_TABU_ANTS = 200
# Below this many walking ants one broadcast comparison is cheapest; above it, its reduction
# over a short last axis costs more than a comparison per tabu column.


def _in_rows(values: IntArray, rows: IntArray) -> NDArray[np.bool_]:
    """Whether each ``values[a, k]`` occurs in ``rows[a]`` (a short row: the tabu list)."""
    if len(values) < _BROADCAST_TABU_ANTS:
        return np.asarray((values[:, :, None] == rows[:, None, :]).any(axis=-1))
    found = np.zeros(values.shape, dtype=bool)
    for column in rows.T:
        found |= values == column[:, None]
    return found


def _erase_loops(nodes: IntArray) -> IntArray:
    """Remove cycles from a walk (keep the path from each node's last visit)."""
    ordered = np.sort(nodes)
    if not (ordered[1:] == ordered[:-1]).any():
        return nodes
    out: list[int] = []
    where: dict[int, int] = {}
    for v in nodes.tolist():
        if v in where:
            cut = where[v]
            for dropped in out[cut + 1 :]:
                del where[dropped]
            del out[cut + 1 :]
        else:
            where[v] = len(out)
            out.append(v)
    return np.asarray(out, dtype=np.int64)


class _Shared:
    """The colonies' shared knowledge: every vehicle's best route and nominal timing."""

    def __init__(self, problem: Problem, bests: list[_Best], opts: AcoOptions) -> None:
        self.problem = problem
        limits = [t.timing for t in problem.tasks]
        self.limits = limits
        self.limit_arrays = LimitArrays.of(limits)
        self.lengths = np.array([b.length_m for b in bests])
        self.timing = team_timing(self.lengths.tolist(), limits, problem.required_arrival_s)
        vmax = max(lim.speed_max_m_s for lim in limits)
        self.dt = max(problem.separation_m / (4.0 * vmax), 0.5)
        t0 = min(self.timing.takeoff_s)
        t1 = max(self.timing.arrival_s)
        self.times = np.arange(t0, t1 + self.dt, self.dt)
        self.tracks = GridTracks(
            self.times,
            np.stack([self._track(b.points, i, b.length_m) for i, b in enumerate(bests)]),
        )

    def _track(self, points: FloatArray, index: int, length_m: float) -> FloatArray:
        """Positions on the shared time grid; NaN while not airborne."""
        takeoff = self.timing.takeoff_s[index]
        speed = self.timing.speed_m_s[index]
        pos = positions_at(points, takeoff, speed, self.times)
        airborne = (self.times >= takeoff) & (self.times <= takeoff + length_m / speed)
        pos[~airborne] = np.nan
        return pos

    def update(self, index: int, best: _Best) -> None:
        """Publish a colony's new best route (timing reference kept until the next round)."""
        self.lengths[index] = best.length_m
        takeoff, speed = self.candidate_timing(index, best.length_m)
        pos = positions_at(best.points, takeoff, speed, self.times)
        airborne = (self.times >= takeoff) & (self.times <= takeoff + best.length_m / speed)
        pos[~airborne] = np.nan
        self.tracks.set(index, pos)

    def candidate_timing(self, index: int, length_m: float) -> tuple[float, float]:
        """Takeoff and speed of vehicle ``index`` flying ``length_m`` to the team reference."""
        lim = self.limits[index]
        t_min = lim.takeoff_lo_s + length_m / lim.speed_max_m_s
        t_max = lim.takeoff_hi_s + length_m / lim.speed_min_m_s
        target = min(max(self.timing.reference_s + lim.slot_offset_s, t_min), t_max)
        depart = min(max(target - length_m / lim.cruise_m_s, lim.takeoff_lo_s), lim.takeoff_hi_s)
        speed = min(
            max(length_m / max(target - depart, 1e-9), lim.speed_min_m_s), lim.speed_max_m_s
        )
        return depart, speed

    def time_gap(self, index: int, lengths_m: FloatArray) -> FloatArray:
        """Team window miss (s) for candidate lengths of vehicle ``index``, others fixed."""
        team = np.tile(self.lengths, (len(lengths_m), 1))
        team[:, index] = lengths_m
        return window_gap_s(team, self.limit_arrays, self.problem.required_arrival_s)

    def separation_shortfalls(
        self, index: int, candidates: Sequence[tuple[FloatArray, float]]
    ) -> FloatArray:
        """Per candidate route ``(points, length_m)`` of vehicle ``index``: the summed
        shortfall (m) below ``d_s`` against every other vehicle's best route."""
        if len(self.lengths) < 2:
            return np.zeros(len(candidates))
        tracks: list[tuple[FloatArray, int]] = []
        for points, length_m in candidates:
            takeoff, speed = self.candidate_timing(index, length_m)
            # The airborne steps, takeoff <= t <= landing, are one run: the grid is sorted.
            first = int(np.searchsorted(self.times, takeoff, side="left"))
            stop = max(
                int(np.searchsorted(self.times, takeoff + length_m / speed, side="right")), first
            )
            tracks.append((positions_at(points, takeoff, speed, self.times[first:stop]), first))
        shortfall = self.tracks.shortfalls_many(tracks, self.problem.separation_m, skip=index)
        # Summed over the others in vehicle order, as a plain loop over them would.
        return np.asarray(np.delete(shortfall, index, axis=1).sum(axis=1), dtype=np.float64)


def _scores(
    shared: _Shared | None,
    index: int,
    routes: Sequence[_Best | tuple[FloatArray, float, float]],
    o: AcoOptions,
    gaps_s: Sequence[float] | None = None,
) -> list[tuple[float, float, float]]:
    """Comprehensive cost, time miss (s) and separation shortfall (m) of routes of one
    vehicle: a :class:`_Best`, or ``(points, cost, length_m)``.

    ``gaps_s`` are the routes' time misses when already known (``shared.time_gap``).
    """
    figures = [(r.points, r.cost, r.length_m) if isinstance(r, _Best) else r for r in routes]
    if shared is None:
        return [(cost, 0.0, 0.0) for _, cost, _ in figures]
    if gaps_s is None:
        lengths_m = np.array([length for *_, length in figures])
        gaps_s = shared.time_gap(index, lengths_m).tolist()
    shorts = shared.separation_shortfalls(index, [(p, length) for p, _, length in figures])
    d_s = shared.problem.separation_m
    out = []
    for (_, cost, _), gap, short in zip(figures, gaps_s, shorts.tolist(), strict=True):
        # Any loss of separation costs at least a full d_s, so a small shortfall is never
        # cheap.
        sep_cost = o.separation_penalty * (short + (d_s if short > 0 else 0.0))
        out.append((cost + o.time_penalty_m_per_s * gap + sep_cost, gap, short))
    return out


WALK_BLOCKS = 4
"""A team of :data:`planner.pool.PARALLEL_MIN_VEHICLES` or more walks its colonies in this
many blocks, each with a random stream of its own (spawned from the plan's): the blocks may
walk in forked processes, and the walks, so the plan, do not depend on how many."""

_Walked = dict[int, tuple[list[IntArray], list[tuple[FloatArray, float, float]]]]
"""Per colony: its ants' distinct routes (in ant order) and their figures (route_figures)."""


def _walk_blocks(n: int, rng: np.random.Generator) -> list[tuple[IntArray, np.random.Generator]]:
    """The colonies' blocks and their random streams (one block, the plan's own stream, for
    a team under :data:`planner.pool.PARALLEL_MIN_VEHICLES`)."""
    if n < PARALLEL_MIN_VEHICLES:
        return [(np.arange(n, dtype=np.int64), rng)]
    bounds = np.linspace(0, n, WALK_BLOCKS + 1).astype(np.int64)
    streams = rng.spawn(WALK_BLOCKS)
    return [
        (np.arange(bounds[b], bounds[b + 1], dtype=np.int64), streams[b])
        for b in range(WALK_BLOCKS)
    ]


def _walk_block(
    state: _Colonies, item: tuple[IntArray, np.random.Generator]
) -> tuple[_Walked, np.random.Generator]:
    """One block's running colonies walk once (in a forked walker or here): each colony's
    distinct routes and their figures, and the block's stream as the walk left it."""
    colonies, rng = item
    col, walks = state.walk(colonies, rng)
    out: _Walked = {}
    for c in colonies.tolist():
        seen: set[bytes] = set()
        new_walks: list[IntArray] = []
        for a in np.flatnonzero(col == c).tolist():
            nodes = walks[a]
            if nodes is None or nodes.tobytes() in seen:
                continue
            seen.add(nodes.tobytes())
            new_walks.append(nodes)
        out[c] = (new_walks, route_figures(state.p, c, new_walks))
    return out, rng


def solve_aco(
    problem: Problem,
    *,
    rng: np.random.Generator,
    options: AcoOptions | None = None,
    workers: int = 1,
) -> SolveResult:
    """Plan every vehicle's route with the multi-colony ACO.

    Returns APPROXIMATE when every colony found a route meeting the team constraints,
    INFEASIBLE when a goal is unreachable, and TIMEOUT when the iteration caps ended the
    search with routes that still miss the arrival windows or the separation. ``workers`` > 1
    walks a large team's blocks of colonies (:data:`WALK_BLOCKS`) in that many forked
    processes: the same result, sooner.
    """
    o = options or AcoOptions()
    exact = solve_exact(problem)  # cost-to-go fields (visibility) and reachability
    if exact.status is Status.INFEASIBLE:
        return exact
    n = len(problem.tasks)
    state = _Colonies(problem, o)  # STEP1
    blocks = _walk_blocks(n, rng)
    with ForkedWorkers(_walk_block, state, min(workers, len(blocks))) as walkers:
        return _search(problem, o, exact, state, blocks, walkers)


def _search(
    problem: Problem,
    o: AcoOptions,
    exact: SolveResult,
    state: _Colonies,
    blocks: list[tuple[IntArray, np.random.Generator]],
    walkers: ForkedWorkers[
        _Colonies, tuple[IntArray, np.random.Generator], tuple[_Walked, np.random.Generator]
    ],
) -> SolveResult:
    """STEP2-STEP6 (:func:`solve_aco`), the colonies walking in ``walkers``."""
    n = len(problem.tasks)
    bests: list[_Best | None] = [None] * n
    shared: _Shared | None = None
    iterations = 0
    previous_total = math.inf
    gaps = np.zeros(n)
    shorts = np.zeros(n)
    stopped = False
    for _round in range(o.rounds):  # STEP2 / STEP6
        stall = np.zeros(n, dtype=np.int64)
        for _it in range(o.max_iter):  # STEP3-STEP5
            running = np.flatnonzero(stall < o.patience)
            if running.size == 0:
                break
            if o.time_up is not None and all(b is not None for b in bests) and o.time_up():
                stopped = True
                break
            iterations += 1
            todo = [
                (k, colonies[np.isin(colonies, running)]) for k, (colonies, _) in enumerate(blocks)
            ]
            todo = [(k, cols) for k, cols in todo if cols.size]
            walked: _Walked = {}
            done = walkers.map([(cols, blocks[k][1]) for k, cols in todo])
            for (k, _), (block_walked, stream) in zip(todo, done, strict=True):
                blocks[k] = (blocks[k][0], stream)  # a forked walker returns the stream moved
                walked.update(block_walked)
            iter_best: dict[int, _Best] = {}
            for c in running.tolist():
                best = bests[c]
                new_walks, figures = walked[c]
                quick = [cost for _, cost, _ in figures]
                miss_s = [0.0] * len(figures)
                if shared is not None and figures:
                    # One team-window evaluation for all of the colony's new routes.
                    lengths_m = np.array([length for *_, length in figures])
                    miss_s = shared.time_gap(c, lengths_m).tolist()
                    quick = [
                        q + o.time_penalty_m_per_s * m for q, m in zip(quick, miss_s, strict=True)
                    ]
                top = sorted(range(len(figures)), key=quick.__getitem__)[: o.candidates]
                if best is not None and shared is not None:
                    # The best route is scored again against the others' routes as they are
                    # now, with this iteration's candidates.
                    gap_s = float(shared.time_gap(c, np.array([best.length_m]))[0])
                    scored = _scores(
                        shared, c, [best, *(figures[k] for k in top)], o,
                        [gap_s, *(miss_s[k] for k in top)],
                    )  # fmt: skip
                    best.score = scored.pop(0)[0]
                else:
                    scored = _scores(
                        shared, c, [figures[k] for k in top], o, [miss_s[k] for k in top]
                    )
                for k, (score, _, _) in zip(top, scored, strict=True):
                    pts, cost, length = figures[k]
                    if c not in iter_best or score < iter_best[c].score:
                        iter_best[c] = _Best(new_walks[k], pts, cost, length, score)
                cand = iter_best.get(c)
                if cand is not None and (best is None or cand.score < best.score * (1 - o.tol)):
                    bests[c] = cand
                    stall[c] = 0
                    if shared is not None:
                        shared.update(c, cand)  # Gauss-Seidel: later colonies see it now
                else:
                    stall[c] += 1
            # STEP4: pheromone update, MAX-MIN style.
            # Row by row in place: only the running colonies' rows change, and copying the
            # selected rows out and back cost more than the update itself.
            for c in running.tolist():
                tau = state.tau[c]
                tau *= 1.0 - o.rho
                for b, share in ((bests[c], 1.0), (iter_best.get(c), 0.5)):
                    if b is not None:
                        tau[b.nodes] += o.rho * o.tau_max * share
                np.clip(tau, o.tau_min, o.tau_max, out=tau)
        if any(b is None for b in bests):
            missing = next(problem.tasks[i].vehicle_id for i, b in enumerate(bests) if b is None)
            return SolveResult(
                Status.TIMEOUT,
                tuple(None for _ in bests),
                iterations,
                f"vehicle {missing}: no ant reached the goal within the step limit",
            )
        found = [b for b in bests if b is not None]
        shared = _Shared(problem, found, o)
        total = 0.0
        for c, b in enumerate(found):
            b.score, gaps[c], shorts[c] = _scores(shared, c, [b], o)[0]
            total += b.score
        if stopped or abs(previous_total - total) <= o.tol * total:
            break
        previous_total = total
    final = [b for b in bests if b is not None]
    routes = tuple(
        Route(t.vehicle_id, tuple(int(v) for v in b.nodes), b.cost, b.length_m)
        for t, b in zip(problem.tasks, final, strict=True)
    )
    gap_s = float(gaps.max()) if n else 0.0
    short_m = float(shorts.max()) if n else 0.0
    min_sep = _min_separation(shared) if shared is not None else math.inf
    total = float(sum(b.score for b in final))
    if gap_s > 0.0 or short_m > 0.0:
        return SolveResult(
            Status.TIMEOUT,
            routes,
            iterations,
            f"{'search time' if stopped else 'iteration cap'} reached with the team constraint "
            f"missed by {gap_s:.1f} s "
            f"and separation short by {short_m:.0f} m",
            total,
            gap_s,
            min_sep,
        )
    return SolveResult(
        Status.APPROXIMATE,
        routes,
        iterations,
        "routes meet the team constraints",
        total,
        0.0,
        min_sep,
    )


def _min_separation(shared: _Shared) -> float:
    """Smallest distance (m) between any two vehicles on the shared time grid while both fly."""
    pos = shared.tracks.positions_m
    best = math.inf
    for i in range(len(pos) - 1):
        d = np.hypot(pos[i + 1 :, :, 0] - pos[i, :, 0], pos[i + 1 :, :, 1] - pos[i, :, 1])
        closest = float(np.fmin.reduce(d, axis=None))  # NaN: no two ever fly together
        if closest < best:
            best = closest
    return best


__all__ = ["AcoOptions", "solve_aco"]

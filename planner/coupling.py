"""Team coupling used while planning: arrival windows and pairwise separation (eq. 1).

Each vehicle's feasible arrival window follows from its path length, its speed range and its
allowed takeoff window: ``[takeoff_lo + L / v_max, takeoff_hi + L / v_min]``. The team
constraint asks the windows (shifted by the arrival slots for spaced arrivals, or clipped to
the per-vehicle windows) to intersect. For separation the planner assumes each vehicle flies
its path at constant speed to its nominal arrival time; the scheduler refines that later.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class TimingLimits:
    """What bounds one vehicle's arrival: speeds (m/s), takeoff window (s), slot offset (s)."""

    speed_min_m_s: float
    speed_max_m_s: float
    cruise_m_s: float
    takeoff_lo_s: float
    takeoff_hi_s: float
    slot_offset_s: float = 0.0
    window_lo_s: float = -math.inf
    window_hi_s: float = math.inf


@dataclass(frozen=True, slots=True)
class TeamTiming:
    """The team's arrival reference and each vehicle's nominal takeoff, arrival and speed."""

    gap_s: float
    reference_s: float
    takeoff_s: tuple[float, ...]
    arrival_s: tuple[float, ...]
    speed_m_s: tuple[float, ...]


@dataclass(frozen=True, eq=False)
class LimitArrays:
    """A team's timing limits as one array per field (vehicle order), built once.

    The ACO asks for the team's window miss thousands of times per plan; building these
    arrays from the limit objects on every call cost more than the arithmetic.
    """

    takeoff_lo_s: FloatArray
    takeoff_hi_s: FloatArray
    speed_min_m_s: FloatArray
    speed_max_m_s: FloatArray
    slot_offset_s: FloatArray
    window_lo_s: FloatArray
    window_hi_s: FloatArray

    @classmethod
    def of(cls, limits: Sequence[TimingLimits] | LimitArrays) -> LimitArrays:
        """The arrays of ``limits`` (returned as they are if already arrays)."""
        if isinstance(limits, LimitArrays):
            return limits
        return cls(
            np.array([lim.takeoff_lo_s for lim in limits]),
            np.array([lim.takeoff_hi_s for lim in limits]),
            np.array([lim.speed_min_m_s for lim in limits]),
            np.array([lim.speed_max_m_s for lim in limits]),
            np.array([lim.slot_offset_s for lim in limits]),
            np.array([lim.window_lo_s for lim in limits]),
            np.array([lim.window_hi_s for lim in limits]),
        )


def windows(
    lengths_m: FloatArray, limits: Sequence[TimingLimits] | LimitArrays
) -> tuple[FloatArray, FloatArray]:
    """Feasible arrival windows ``(t_min, t_max)`` (s) for path lengths ``(..., M)``."""
    arrays = LimitArrays.of(limits)
    return (
        arrays.takeoff_lo_s + lengths_m / arrays.speed_max_m_s,
        arrays.takeoff_hi_s + lengths_m / arrays.speed_min_m_s,
    )


def window_gap_s(
    lengths_m: FloatArray,
    limits: Sequence[TimingLimits] | LimitArrays,
    required_s: float | None,
) -> FloatArray:
    """Seconds by which the team constraint is missed (0 when feasible), for ``(..., M)``.

    Windows are shifted by each vehicle's slot offset and clipped to its own window; with a
    required reference time, the miss is the summed distance of that time from each window.
    """
    arrays = LimitArrays.of(limits)
    t_min, t_max = windows(lengths_m, arrays)
    offset = arrays.slot_offset_s
    own_lo = arrays.window_lo_s
    own_hi = arrays.window_hi_s
    own_gap = np.maximum(t_min - own_hi, 0.0) + np.maximum(own_lo - t_max, 0.0)
    lo = np.maximum(t_min, own_lo) - offset
    hi = np.minimum(t_max, own_hi) - offset
    if required_s is not None:
        miss = np.maximum(lo - required_s, 0.0) + np.maximum(required_s - hi, 0.0)
        return np.asarray(miss.sum(axis=-1) + own_gap.sum(axis=-1), dtype=np.float64)
    team_gap = np.maximum(lo.max(axis=-1) - hi.min(axis=-1), 0.0)
    return np.asarray(team_gap + own_gap.sum(axis=-1), dtype=np.float64)


def team_timing(
    lengths_m: Sequence[float], limits: Sequence[TimingLimits], required_s: float | None
) -> TeamTiming:
    """Nominal timing: the earliest common reference, takeoffs and constant speeds."""
    lengths = np.asarray(lengths_m, dtype=np.float64)
    gap = float(window_gap_s(lengths, limits, required_s))
    t_min, t_max = windows(lengths, limits)
    offset = np.array([lim.slot_offset_s for lim in limits])
    own_lo = np.array([lim.window_lo_s for lim in limits])
    lo = np.maximum(t_min, own_lo) - offset
    ref = float(lo.max()) if required_s is None else required_s
    takeoff, arrival, speed = [], [], []
    for length, lim, off, tmin, tmax in zip(lengths, limits, offset, t_min, t_max, strict=True):
        target = min(max(ref + off, tmin), tmax)
        if math.isfinite(lim.window_lo_s) or math.isfinite(lim.window_hi_s):
            target = min(max(target, lim.window_lo_s), lim.window_hi_s)
            target = min(max(target, tmin), tmax)
        depart = min(max(target - length / lim.cruise_m_s, lim.takeoff_lo_s), lim.takeoff_hi_s)
        v = length / max(target - depart, 1e-9)
        v = min(max(v, lim.speed_min_m_s), lim.speed_max_m_s)
        takeoff.append(depart)
        speed.append(v)
        arrival.append(depart + length / v)
    return TeamTiming(gap, ref, tuple(takeoff), tuple(arrival), tuple(speed))


def positions_at(
    points_m: FloatArray, takeoff_s: float, speed_m_s: float, times_s: FloatArray
) -> FloatArray:
    """Positions (T, 2) along a polyline flown at constant speed from ``takeoff_s``."""
    seg = np.hypot(np.diff(points_m[:, 0]), np.diff(points_m[:, 1]))
    s_knots = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.clip((times_s - takeoff_s) * speed_m_s, 0.0, s_knots[-1])
    return np.stack(
        [np.interp(s, s_knots, points_m[:, 0]), np.interp(s, s_knots, points_m[:, 1])], axis=-1
    )


def pair_min_separation(
    a_points_m: FloatArray,
    a_takeoff_s: float,
    a_speed_m_s: float,
    b_points_m: FloatArray,
    b_takeoff_s: float,
    b_speed_m_s: float,
    step_s: float,
) -> tuple[float, float]:
    """Minimum horizontal distance (m) while both fly, and its time (s); inf if never both."""
    a_len = float(np.hypot(*np.diff(a_points_m, axis=0).T).sum())
    b_len = float(np.hypot(*np.diff(b_points_m, axis=0).T).sum())
    t0 = max(a_takeoff_s, b_takeoff_s)
    t1 = min(a_takeoff_s + a_len / a_speed_m_s, b_takeoff_s + b_len / b_speed_m_s)
    if t1 <= t0:
        return math.inf, math.nan
    n = max(2, int(math.ceil((t1 - t0) / step_s)) + 1)
    t = np.linspace(t0, t1, n)
    pa = positions_at(a_points_m, a_takeoff_s, a_speed_m_s, t)
    pb = positions_at(b_points_m, b_takeoff_s, b_speed_m_s, t)
    d = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
    k = int(np.argmin(d))
    return float(d[k]), float(t[k])


TRACK_BLOCK_STEPS = 32
"""Time steps per block of :class:`GridTracks`; a block's bounding box stands for its samples
when deciding whether two tracks can come within the separation there."""
_BOX_MARGIN_M = 1.0
# Boxes this much farther apart than the separation cannot hide a closer pair of samples, even
# after round-off (which is far below a millimetre at planning coordinates).


class GridTracks:
    """Every vehicle's position on one shared time grid, and the separation each one lacks.

    Positions are NaN while a vehicle is not airborne. The time steps are grouped in blocks
    of ``TRACK_BLOCK_STEPS``, and each track keeps the bounding box of each of its blocks: a
    candidate route is compared sample by sample only in the blocks where its box comes
    within the separation of another track's box. Most vehicle pairs are kilometres apart
    most of the time, so this skips most of the ``N x T`` work; where samples are compared
    the arithmetic is the plain pairwise one, so the shortfalls are exactly those of the
    full comparison.
    """

    def __init__(self, times_s: FloatArray, positions_m: FloatArray) -> None:
        n_vehicles, n_times = positions_m.shape[:2]
        self.times_s = times_s
        n_blocks = -(-n_times // TRACK_BLOCK_STEPS)
        blocked = (n_vehicles, n_blocks, TRACK_BLOCK_STEPS)
        self.east_m = np.full(blocked, np.nan)
        self.north_m = np.full(blocked, np.nan)
        self.boxes_m = np.full((4, n_vehicles, n_blocks), np.nan)
        """Per block: least east, greatest east, least north, greatest north (m)."""
        for index in range(n_vehicles):
            self.set(index, positions_m[index])

    @property
    def positions_m(self) -> FloatArray:
        """(N, T, 2) positions on the time grid (m); NaN while not airborne."""
        n_vehicles, n_times = self.east_m.shape[0], len(self.times_s)
        east = self.east_m.reshape(n_vehicles, -1)[:, :n_times]
        north = self.north_m.reshape(n_vehicles, -1)[:, :n_times]
        return np.stack([east, north], axis=-1)

    def set(self, index: int, positions_m: FloatArray) -> None:
        """Replace one vehicle's (T, 2) positions (NaN while not airborne)."""
        n_times = len(self.times_s)
        self.east_m[index].reshape(-1)[:n_times] = positions_m[:, 0]
        self.north_m[index].reshape(-1)[:n_times] = positions_m[:, 1]
        self.boxes_m[:, index] = _block_boxes(self.east_m[index], self.north_m[index])

    def shortfalls_m(
        self, positions_m: FloatArray, first: int, separation_m: float, *, skip: int
    ) -> FloatArray:
        """Per vehicle, ``max(separation_m - closest approach, 0)`` (m) to a candidate track.

        Parameters
        ----------
        positions_m : (K, 2) candidate positions (m) at time steps ``first .. first + K - 1``,
            the span it is airborne (it is not compared elsewhere).
        first : index of the candidate's first time step.
        separation_m : the separation ``d_s`` (m).
        skip : a vehicle not compared (the candidate's own); its shortfall is 0.
        """
        many = self.shortfalls_many([(positions_m, first)], separation_m, skip=skip)
        return np.asarray(many[0], dtype=np.float64)

    def shortfalls_many(
        self,
        candidates: Sequence[tuple[FloatArray, int]],
        separation_m: float,
        *,
        skip: int,
    ) -> FloatArray:
        """:meth:`shortfalls_m` of several candidate tracks of one vehicle at once, (C, N).

        Each candidate is ``(positions_m, first)``. The candidates are laid on one span of
        blocks, so the numpy calls are shared: the ACO scores a colony's best routes
        together, and one candidate at a time was mostly call overhead.
        """
        n_vehicles = self.east_m.shape[0]
        shortfall = np.zeros((len(candidates), n_vehicles))
        flying = [(k, p, f) for k, (p, f) in enumerate(candidates) if len(p)]
        if not flying:
            return shortfall
        b_first = min(f for _, _, f in flying) // TRACK_BLOCK_STEPS
        start = b_first * TRACK_BLOCK_STEPS
        n_blocks = max(-(-(f - start + len(p)) // TRACK_BLOCK_STEPS) for _, p, f in flying)
        mine_east = np.full((len(candidates), n_blocks * TRACK_BLOCK_STEPS), np.nan)
        mine_north = np.full((len(candidates), n_blocks * TRACK_BLOCK_STEPS), np.nan)
        for k, positions_m, first in flying:
            mine_east[k, first - start : first - start + len(positions_m)] = positions_m[:, 0]
            mine_north[k, first - start : first - start + len(positions_m)] = positions_m[:, 1]
        mine_east = mine_east.reshape(-1, TRACK_BLOCK_STEPS)  # (C * blocks, steps)
        mine_north = mine_north.reshape(-1, TRACK_BLOCK_STEPS)
        boxes = _block_boxes(mine_east, mine_north).reshape(4, len(candidates), n_blocks)
        cand, vehicle, block = self._near_blocks(boxes, b_first, separation_m + _BOX_MARGIN_M)
        other = vehicle != skip
        cand, vehicle, block = cand[other], vehicle[other], block[other]
        if vehicle.size == 0:
            return shortfall
        mine = cand * n_blocks + block
        d_east = self.east_m[vehicle, b_first + block] - mine_east[mine]
        d_north = self.north_m[vehicle, b_first + block] - mine_north[mine]
        # Squared distances screen the blocks cheaply; the distances that decide a shortfall
        # are then taken exactly as the plain comparison takes them (hypot).
        within_m = separation_m + _BOX_MARGIN_M
        close = np.fmin.reduce(d_east * d_east + d_north * d_north, axis=1) <= within_m**2
        if not close.any():
            return shortfall
        pair = cand[close] * n_vehicles + vehicle[close]  # sorted: (candidate, vehicle)
        d = np.hypot(d_east[close], d_north[close])
        block_min = np.fmin.reduce(d, axis=1)  # NaN: never both airborne in the block
        first_of_pair = np.flatnonzero(np.diff(pair, prepend=-1))
        closest = np.fmin.reduceat(block_min, first_of_pair)
        closest = np.where(np.isnan(closest), np.inf, closest)
        shortfall.reshape(-1)[pair[first_of_pair]] = np.maximum(separation_m - closest, 0.0)
        return shortfall

    def _near_blocks(
        self, mine_boxes: FloatArray, b_first: int, within_m: float
    ) -> tuple[IntArray, IntArray, IntArray]:
        """(candidate, vehicle, block) triples whose boxes come within ``within_m``, sorted.

        ``mine_boxes`` is (4, candidates, blocks). The test is on each axis separately (the
        boxes grown by ``within_m`` overlap), a cheap superset of the pairs within that
        distance; NaN boxes never pass.
        """
        theirs = self.boxes_m[:, None, :, b_first : b_first + mine_boxes.shape[2]]
        mine = mine_boxes[:, :, None, :]
        near = theirs[0] <= mine[1] + within_m
        near &= theirs[1] >= mine[0] - within_m
        near &= theirs[2] <= mine[3] + within_m
        near &= theirs[3] >= mine[2] - within_m
        cand, vehicle, block = np.nonzero(near)
        return cand.astype(np.int64), vehicle.astype(np.int64), block.astype(np.int64)


def _block_boxes(east_m: FloatArray, north_m: FloatArray) -> FloatArray:
    """(4, blocks) least/greatest east and north (m) of (blocks, steps) samples, NaN ignored.

    A block with no sample gets NaN, which compares false with any distance.
    """
    return np.stack(
        [
            np.fmin.reduce(east_m, axis=1),
            np.fmax.reduce(east_m, axis=1),
            np.fmin.reduce(north_m, axis=1),
            np.fmax.reduce(north_m, axis=1),
        ]
    )


SCREEN_STEPS = 4
""":func:`team_min_separation_m` screens the pairs on a common time grid this many sampling
steps apart before it samples any pair in full."""
_LIPSCHITZ_MARGIN_M = 1.0
# Slack on the closing-speed bound, far above the round-off of positions and distances.


def team_min_separation_m(
    tracks_m: Sequence[FloatArray],
    takeoff_s: Sequence[float],
    speed_m_s: Sequence[float],
    step_s: float,
) -> float:
    """The smallest :func:`pair_min_separation` over every pair of vehicles (m).

    Exactly that minimum, without sampling every pair in full. All vehicles are first placed
    on one coarse time grid (``SCREEN_STEPS * step_s`` apart). Two vehicles close in at most
    at the sum of their speeds, so while both fly their distance stays above the smallest
    coarse distance less that speed times half the grid spacing. Pairs are then sampled in
    full, lowest bound first, until the next bound exceeds the smallest separation found; a
    pair whose bound is higher cannot hold the minimum. ``inf`` if no two vehicles fly
    together.

    Parameters
    ----------
    tracks_m : each vehicle's (K, 2) polyline (m), flown at constant speed.
    takeoff_s, speed_m_s : each vehicle's takeoff time (s) and speed (m/s).
    step_s : the largest time step between samples (s), as for ``pair_min_separation``.
    """
    n = len(tracks_m)
    if n < 2:
        return math.inf
    takeoff = np.asarray(takeoff_s, dtype=np.float64)
    speed = np.asarray(speed_m_s, dtype=np.float64)
    length = np.array([float(np.hypot(*np.diff(p, axis=0).T).sum()) for p in tracks_m])
    landing = takeoff + length / speed
    spacing_s = SCREEN_STEPS * step_s
    grid_s = np.arange(takeoff.min(), landing.max() + spacing_s, spacing_s)
    flown = zip(tracks_m, takeoff.tolist(), speed.tolist(), strict=True)
    at_grid = np.stack([positions_at(p, t, v, grid_s) for p, t, v in flown])
    bounds: list[tuple[float, int, int]] = []
    for i in range(n - 1):
        others = np.arange(i + 1, n)
        start = np.maximum(takeoff[i], takeoff[others])
        end = np.minimum(landing[i], landing[others])
        d = np.hypot(
            at_grid[others, :, 0] - at_grid[i, :, 0], at_grid[others, :, 1] - at_grid[i, :, 1]
        )
        # Grid times within half a spacing of the span both fly: every instant of the span
        # has one of them that close.
        near = (grid_s >= start[:, None] - 0.5 * spacing_s) & (
            grid_s <= end[:, None] + 0.5 * spacing_s
        )
        closest = np.where(near, d, np.inf).min(axis=1)
        slack = (speed[i] + speed[others]) * 0.5 * spacing_s + _LIPSCHITZ_MARGIN_M
        for j, bound in zip(others.tolist(), (closest - slack).tolist(), strict=True):
            if end[j - i - 1] > start[j - i - 1]:
                bounds.append((bound, i, j))
    best = math.inf
    for bound, i, j in sorted(bounds):
        if bound > best:
            break
        d_m, _ = pair_min_separation(
            tracks_m[i], takeoff_s[i], speed_m_s[i], tracks_m[j], takeoff_s[j], speed_m_s[j], step_s
        )
        best = min(best, d_m)
    return best

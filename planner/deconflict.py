"""4-D deconfliction: every vehicle's position over time along its schedule (eq. 1's
``d_ij(t) >= d_s``).

Positions come from :meth:`planner.schedule.VehicleSchedule.position_at`: legs at their
speeds along the exact path, loiter circles as flown; a vehicle counts only while airborne
(from takeoff to arrival), at its profile's altitude there (the climb-out's and the loiters'
at the profile's too). Separation is the 3-D distance, as the flight's truth measures it:
vehicles on different altitude layers (:mod:`planner.layers`) may share a corridor. The
places a loiter keeps clear of (:class:`TeamTracks`) are horizontal. The sampling step
keeps the relative motion between samples below a tenth of ``d_s``; the closest sample of
each pair is then refined on a finer grid.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from planner.errors import SeparationError
from planner.flightpath import FlightPath
from planner.memo import IdentityMemo
from planner.schedule import VehicleSchedule, loiter_position

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class PairSeparation:
    """The closest approach of two vehicles while both are airborne."""

    a: str
    b: str
    distance_m: float
    time_s: float
    east_m: float
    """Midpoint of the two positions at the closest approach, m."""
    north_m: float


@dataclass(frozen=True)
class Separation:
    """Minimum pairwise separation of the team and the pairs closer than ``d_s``."""

    required_m: float
    pairs: tuple[PairSeparation, ...]

    @property
    def minimum(self) -> PairSeparation | None:
        finite = [p for p in self.pairs if math.isfinite(p.distance_m)]
        return min(finite, key=lambda p: p.distance_m) if finite else None

    @property
    def min_separation_m(self) -> float:
        m = self.minimum
        return math.inf if m is None else m.distance_m

    @property
    def conflicts(self) -> tuple[PairSeparation, ...]:
        return tuple(p for p in self.pairs if p.distance_m < self.required_m)


def _positions(vs: VehicleSchedule, t: FloatArray) -> FloatArray:
    """``vs.position_at`` at every time of ``t``, with the profile's altitude there as a third
    column (NaN rows where it does not fly): :func:`_positions_masked`, by slices of ``t``
    where it ascends (as every time grid here does) and ``vs`` has no loiter."""
    t = np.asarray(t, dtype=np.float64)
    if vs.loiters or not _ascending(t) or not _times_known(vs):
        return _positions_masked(vs, t)
    out = np.full((len(t), 3), np.nan)
    # On ascending times each time window is a slice: where the masks of
    # _positions_masked select, found by bisection instead of compared at every sample.
    first = int(np.searchsorted(t, vs.takeoff_s, side="left"))
    stop = int(np.searchsorted(t, vs.arrival_s, side="right"))
    if stop <= first:
        return out
    flying_t = t[first:stop]
    s = _along_s_m(vs, flying_t)
    end = np.isnan(s)
    along: NDArray[np.intp] | slice
    if end.any():
        out[first + np.flatnonzero(end)] = (
            vs.path.end.east_m,
            vs.path.end.north_m,
            vs.alt_at(vs.path.length_m),
        )
        along = first + np.flatnonzero(~end)
        s = s[~end]
    else:
        along = slice(first, stop)
    if s.size:
        s_along = np.minimum(np.maximum(s, 0.0), vs.path.length_m)
        out[along, :2] = vs.path.poses_at(s_along)[:, :2]
        out[along, 2] = np.interp(s_along, vs.wp_s_m, vs.wp_alt_m)
    return out


def _ascending(t: FloatArray) -> bool:
    """Whether ``t`` holds at least two times, none NaN, none less than the one before."""
    return len(t) >= 2 and bool((t[1:] >= t[:-1]).all())


def _times_known(vs: VehicleSchedule) -> bool:
    """Whether none of the times :func:`_along_s_m` bisects at is NaN (a NaN time compares
    false at every sample, but would bisect to the end)."""
    times = [vs.takeoff_s, vs.arrival_s, vs.climb_end_s]
    times += [x for leg in vs.legs for x in (leg.t_start_s, leg.t_end_s)]
    return not any(math.isnan(x) for x in times)


def _along_s_m(vs: VehicleSchedule, t: FloatArray) -> FloatArray:
    """Along-path distance at each of the ascending times ``t`` (all while ``vs`` flies and
    no loiter), NaN after its last leg: :func:`_positions_masked`'s ``s``, the same formulas
    over the same samples, the first window that holds a sample setting it."""
    s = np.full(len(t), np.nan)
    if not vs.airborne_start:
        climbing = int(np.searchsorted(t, vs.climb_end_s, side="left"))
        span = max(vs.climb_end_s - vs.takeoff_s, 1e-9)
        s[:climbing] = vs.climb_s_m * (t[:climbing] - vs.takeoff_s) / span
        if not vs.legs:  # state_at: on the ground until it has legs
            s[:climbing] = 0.0
    for leg in vs.legs:
        lo = int(np.searchsorted(t, leg.t_start_s, side="left"))
        hi = int(np.searchsorted(t, leg.t_end_s, side="right"))
        if hi <= lo:
            continue
        part = s[lo:hi]  # a view: set in place
        free = np.isnan(part)
        if free.all():
            part[:] = leg.s_start_m + (t[lo:hi] - leg.t_start_s) * leg.groundspeed_m_s
        elif free.any():
            part[free] = leg.s_start_m + (t[lo:hi][free] - leg.t_start_s) * leg.groundspeed_m_s
    return s


def _positions_masked(vs: VehicleSchedule, t: FloatArray) -> FloatArray:
    """``vs.position_at`` at every time of ``t``, with the profile's altitude there as a third
    column (NaN rows where it does not fly): the same arithmetic on arrays, the path's poses
    looked up at once (:meth:`FlightPath.poses_at`)."""
    t = np.asarray(t, dtype=np.float64)
    out = np.full((len(t), 3), np.nan)
    flying = (t >= vs.takeoff_s) & (t <= vs.arrival_s)
    s = np.full(len(t), np.nan)
    loitering = np.zeros(len(t), dtype=bool)
    for lo in vs.loiters:
        inside = flying & ~loitering & (t >= lo.t_start_s) & (t < lo.t_end_s)
        for k in np.flatnonzero(inside):
            out[k, :2] = loiter_position(
                lo, (float(t[k]) - lo.t_start_s) * lo.speed_m_s * lo.tas_per_eas
            )
        out[inside, 2] = vs.alt_at(lo.s_m)
        loitering |= inside
    rest = flying & ~loitering
    if not vs.airborne_start:
        climbing = rest & (t < vs.climb_end_s)
        span = max(vs.climb_end_s - vs.takeoff_s, 1e-9)
        s[climbing] = vs.climb_s_m * (t[climbing] - vs.takeoff_s) / span
        if not vs.legs:  # state_at: on the ground until it has legs
            s[climbing] = 0.0
    for leg in vs.legs:
        on = rest & np.isnan(s) & (t >= leg.t_start_s) & (t <= leg.t_end_s)
        s[on] = leg.s_start_m + (t[on] - leg.t_start_s) * leg.groundspeed_m_s
    end = rest & np.isnan(s)
    if end.any():
        out[end] = (vs.path.end.east_m, vs.path.end.north_m, vs.alt_at(vs.path.length_m))
    along = rest & ~end
    if along.any():
        s_along = np.minimum(np.maximum(s[along], 0.0), vs.path.length_m)
        out[along, :2] = vs.path.poses_at(s_along)[:, :2]
        out[along, 2] = np.interp(s_along, vs.wp_s_m, vs.wp_alt_m)
    return out


def _distance_m(a: FloatArray, b: FloatArray) -> FloatArray:
    """3-D distances between positions (east, north, altitude in the last axis).

    The squares are added column by column in the order a sum over the last axis takes
    them (the same bits), which numpy does several times faster than that reduction over
    rows of three."""
    d = a - b
    d *= d
    d2 = d[..., 0] + d[..., 1]
    d2 += d[..., 2]
    out: FloatArray = np.sqrt(d2)
    return out


def _squared_gaps_m2(planes: FloatArray, mine: FloatArray) -> FloatArray:
    """Squared 3-D distances (vehicle, time) from the tracks ``planes`` (east, north and
    altitude planes of (vehicle, time) each) to one track (3, time); inf where either does
    not fly. Plane by plane, without a root: the hundred-vehicle team's hot loop."""
    d2: FloatArray = (planes[0] - mine[0]) ** 2
    d2 += (planes[1] - mine[1]) ** 2
    d2 += (planes[2] - mine[2]) ** 2
    d2[np.isnan(d2)] = np.inf
    return d2


def _closest(
    a: VehicleSchedule, b: VehicleSchedule, t0: float, t1: float, step_s: float
) -> tuple[float, float, FloatArray, FloatArray]:
    n = max(2, int(math.ceil((t1 - t0) / step_s)) + 1)
    t = np.linspace(t0, t1, n)
    pa, pb = _positions(a, t), _positions(b, t)
    d = _distance_m(pa, pb)
    if np.isnan(d).all():
        return math.inf, math.nan, pa[0], pb[0]
    k = int(np.nanargmin(d))
    return float(d[k]), float(t[k]), pa[k], pb[k]


_PAIRS: IdentityMemo[PairSeparation] = IdentityMemo(8192)
"""Pairs searched, by the two schedules and the exact step and start."""


def pair_separation(
    a: VehicleSchedule, b: VehicleSchedule, *, step_s: float, from_s: float = -math.inf
) -> PairSeparation:
    """Closest approach of two scheduled vehicles while both fly (inf if never together),
    from ``from_s`` on (a re-plan's start: what was flown before is not its to change).

    A pair searched already is not searched again: the team's separation is asked for again
    after a few of its vehicles moved (and schedules are not changed once made)."""
    return _PAIRS.get(
        (a, b),
        (float(step_s).hex(), float(from_s).hex()),
        lambda: _pair_separation(a, b, step_s, from_s),
    )


def _pair_separation(
    a: VehicleSchedule, b: VehicleSchedule, step_s: float, from_s: float
) -> PairSeparation:
    t0 = max(a.takeoff_s, b.takeoff_s, from_s)
    t1 = min(a.arrival_s, b.arrival_s)
    if not t1 > t0:
        return PairSeparation(a.vehicle_id, b.vehicle_id, math.inf, math.nan, math.nan, math.nan)
    d, t, pa, pb = _closest(a, b, t0, t1, step_s)
    if math.isfinite(d):
        lo, hi = max(t0, t - step_s), min(t1, t + step_s)
        d2, t2, pa2, pb2 = _closest(a, b, lo, hi, step_s / 50.0)
        if d2 < d:
            d, t, pa, pb = d2, t2, pa2, pb2
    mid = 0.5 * (pa[:2] + pb[:2])
    return PairSeparation(a.vehicle_id, b.vehicle_id, d, t, float(mid[0]), float(mid[1]))


def _pair_step_s(a: VehicleSchedule, b: VehicleSchedule, required_m: float) -> float:
    """Sampling of a pair's closest-approach search: a tenth of ``d_s`` at their closing
    speed (at least 50 ms)."""
    return max(required_m / (10.0 * (a.speed_max_m_s + b.speed_max_m_s)), 0.05)


def _grid_s(
    vehicles: Sequence[VehicleSchedule], step_s: float, from_s: float = -math.inf
) -> FloatArray:
    """A time grid over the team's flights from ``from_s`` on, ``step_s`` apart, with every
    takeoff and arrival after it on it (a pair's closest approach may be at either end of
    the time they fly together)."""
    t0 = max(min(v.takeoff_s for v in vehicles), from_s)
    t1 = max(max(v.arrival_s for v in vehicles), t0)
    n = max(2, int(math.ceil((t1 - t0) / step_s)) + 1)
    ends = [x for v in vehicles for x in (v.takeoff_s, v.arrival_s) if x >= t0]
    return np.unique(np.concatenate([np.linspace(t0, t1, n), ends]))


def _team_step_s(vehicles: Sequence[VehicleSchedule], required_m: float) -> float:
    """A grid step on which no pair's distance is off by more than a twentieth of
    ``required_m`` between samples (at the team's top closing speed; at least 50 ms)."""
    fastest = max(v.speed_max_m_s for v in vehicles)
    return max(required_m / (10.0 * 2.0 * fastest), 0.05)


BOX_SAMPLES = 32
"""Samples per block over which :class:`TeamSamples` keeps each vehicle's extent (on the
hundred-vehicle team's grid, about 27 s: 800 m at 30 m/s)."""


RECENT_TRACKS = 4
"""Tracks :class:`TeamSamples` keeps of the schedules it sampled last."""
_MADE_TRACKS = 4096
"""Tracks :class:`TeamSamples` remembers making (by a weak reference: not kept alive)."""


class TeamSamples:
    """The team's schedules sampled once on a common time grid, for trying one vehicle's
    other timings against the rest (:meth:`nearest`) without sampling them again."""

    def __init__(
        self,
        vehicles: Sequence[VehicleSchedule],
        required_m: float,
        *,
        from_s: float = -math.inf,
    ) -> None:
        self.required_m = required_m
        self.from_s = from_s
        """The grid starts here (a re-plan's start), or at the team's first takeoff."""
        self.ids = [v.vehicle_id for v in vehicles]
        # A timing that takes off before the team's first takeoff is alone in the air there.
        self.t_s = _grid_s(vehicles, _team_step_s(vehicles, required_m), from_s)
        self.planes = np.ascontiguousarray(
            np.stack([_positions(v, self.t_s) for v in vehicles]).transpose(2, 0, 1)
        )
        """East, north and altitude, each (vehicle, time), m."""
        self._row = {vid: k for k, vid in enumerate(self.ids)}
        self._held = list(vehicles)
        """The schedule each row of :attr:`planes` samples."""
        self._recent: list[tuple[VehicleSchedule, FloatArray]] = []
        """The tracks :meth:`track` sampled last, newest first (each with its schedule)."""
        self._made: dict[int, tuple[weakref.ref[FloatArray], FloatArray | None]] = {}
        """The tracks :meth:`track` made (by identity), each with its :meth:`_boxes` once
        they are asked for."""
        self._starts = np.arange(0, len(self.t_s), BOX_SAMPLES)
        self.boxes = np.stack([self._boxes(self.planes[:, k]) for k in range(len(self.ids))], 1)
        """Each vehicle's horizontal extent over each block of :data:`BOX_SAMPLES` samples:
        east min, east max, north min, north max of (vehicle, block), m; NaN where it does
        not fly."""

    def _boxes(self, track: FloatArray) -> FloatArray:
        with np.errstate(invalid="ignore"):
            return np.stack(
                [
                    np.fmin.reduceat(track[0], self._starts),
                    np.fmax.reduceat(track[0], self._starts),
                    np.fmin.reduceat(track[1], self._starts),
                    np.fmax.reduceat(track[1], self._starts),
                ]
            )

    def _track_boxes(self, track: FloatArray) -> FloatArray:
        """``_boxes(track)``, worked out once for a track :meth:`track` made (read-only, so
        it cannot change): a timing's track is compared with the team round after round."""
        made = self._made.get(id(track))
        if made is None or made[0]() is not track:
            return self._boxes(track)
        boxes = made[1]
        if boxes is None:
            boxes = self._boxes(track)
            self._made[id(track)] = (made[0], boxes)
        return boxes

    def _made_here(self, track: FloatArray) -> FloatArray:
        """``track``, read-only, taken down as made by :meth:`track`."""
        track.flags.writeable = False
        if len(self._made) >= _MADE_TRACKS:
            self._made.clear()  # dead tracks' entries, mostly
        self._made[id(track)] = (weakref.ref(track), None)
        return track

    def track(self, vs: VehicleSchedule) -> FloatArray:
        """``vs`` sampled on the team's grid (east, north and altitude rows; NaN where it does
        not fly): a timing to be tried more than once is sampled once.

        A schedule of the team is copied from its row; the last few others asked for are kept
        (by identity, read-only): a timing is usually tried against one vehicle, then the
        team, then taken, each asking again."""
        k = self._row.get(vs.vehicle_id)
        if k is not None and self._held[k] is vs:
            # A copy: the row changes when it is replaced.
            return self._made_here(np.array(self.planes[:, k]))
        for kept, track in self._recent:
            if kept is vs:
                return track
        track = self._made_here(np.ascontiguousarray(_positions(vs, self.t_s).T))
        self._recent = [(vs, track), *self._recent[: RECENT_TRACKS - 1]]
        return track

    def nearest(
        self,
        vs: VehicleSchedule,
        among: Sequence[str] | None = None,
        within_m: float | None = None,
    ) -> tuple[float, str | None]:
        """How close ``vs`` comes to any other vehicle of the team (or of ``among``) (on the
        grid: at most a twentieth of ``d_s`` more than the exact search finds, off the grid's
        span not compared), and to whom; ``(inf, None)`` when they never fly together."""
        best, who, _ = self.closest(vs, among, within_m)
        return best, who

    def closest(
        self,
        vs: VehicleSchedule,
        among: Sequence[str] | None = None,
        within_m: float | None = None,
    ) -> tuple[float, str | None, float]:
        """:meth:`nearest`, and when (s; NaN when they never fly together). With
        ``within_m``, only a closest approach under it is found (else ``(inf, None, NaN)``),
        the team compared only where it comes near (:meth:`_within`)."""
        wanted = None if among is None else set(among)
        if within_m is not None:
            mask = None if wanted is None else np.array([vid in wanted for vid in self.ids])
            least, where = self._within(
                self.track(vs), within_m, self._row.get(vs.vehicle_id), mask
            )
            j = int(least.argmin())
            if not math.isfinite(float(least[j])):
                return math.inf, None, math.nan
            return math.sqrt(float(least[j])), self.ids[j], float(self.t_s[where[j]])
        others = [
            k
            for k, vid in enumerate(self.ids)
            if vid != vs.vehicle_id and (wanted is None or vid in wanted)
        ]
        if not others:
            return math.inf, None, math.nan
        d2 = _squared_gaps_m2(self.planes[:, others], self.track(vs))
        k = np.unravel_index(int(d2.argmin()), d2.shape)
        best = math.sqrt(float(d2[k]))
        if not math.isfinite(best):
            return math.inf, None, math.nan
        return best, self.ids[others[k[0]]], float(self.t_s[k[1]])

    def too_close(self, vs: VehicleSchedule, below_m: float) -> frozenset[str]:
        """The others of the team ``vs`` comes within ``below_m`` of (on the grid)."""
        least, _ = self._within(self.track(vs), below_m, self._row.get(vs.vehicle_id))
        return frozenset(self.ids[k] for k in np.flatnonzero(least < below_m**2))

    def shortfall_m(self, vehicle_id: str, track: FloatArray, below_m: float) -> float:
        """How far ``track`` (:meth:`track`, for ``vehicle_id``) comes inside ``below_m`` of
        the others, summed over them: ``sum_k max(0, below_m - least distance to k)`` on the
        grid; 0 when it is clear of all."""
        least_m2, _ = self._within(track, below_m, self._row[vehicle_id])
        return float(np.maximum(0.0, below_m - np.sqrt(least_m2)).sum())

    def _within(
        self,
        track: FloatArray,
        below_m: float,
        skip: int | None,
        among: NDArray[np.bool_] | None = None,
    ) -> tuple[FloatArray, NDArray[np.intp]]:
        """Each vehicle's least squared distance (m^2) from ``track`` and the sample where it
        is, wherever that is under ``below_m``; inf (and -1) for the others, for row ``skip``
        and for the rows ``among`` (a mask, when given) leaves out.

        Only the blocks of samples where another vehicle's extent comes within ``below_m`` of
        this track's are compared sample by sample: a crowd's vehicles are near each other
        in few of them."""
        n = len(self.ids)
        least, where = np.full(n, np.inf), np.full(n, -1, dtype=np.intp)
        mine, theirs, m = self._track_boxes(track), self.boxes, below_m
        with np.errstate(invalid="ignore"):
            near = (
                (theirs[0] <= mine[1] + m)
                & (theirs[1] >= mine[0] - m)
                & (theirs[2] <= mine[3] + m)
                & (theirs[3] >= mine[2] - m)
            )  # (vehicle, block); False where either does not fly (NaN)
        if skip is not None:
            near[skip] = False
        if among is not None:
            near &= among[:, None]
        rows, blocks = np.nonzero(near)
        if len(rows) == 0:
            return least, where
        cols = np.minimum(
            self._starts[blocks][:, None] + np.arange(BOX_SAMPLES), len(self.t_s) - 1
        )  # (pair, sample); the last block's short end repeats its last sample
        d2 = (self.planes[0][rows[:, None], cols] - track[0][cols]) ** 2
        d2 += (self.planes[1][rows[:, None], cols] - track[1][cols]) ** 2
        d2 += (self.planes[2][rows[:, None], cols] - track[2][cols]) ** 2
        d2[np.isnan(d2)] = np.inf
        k = d2.argmin(axis=1)
        pair_m2, pair_col = d2[np.arange(len(rows)), k], cols[np.arange(len(rows)), k]
        order = np.lexsort((pair_m2, rows))  # by vehicle, the least first
        first = order[np.r_[True, rows[order][1:] != rows[order][:-1]]]
        inside = pair_m2[first] < below_m**2
        least[rows[first][inside]] = pair_m2[first][inside]
        where[rows[first][inside]] = pair_col[first][inside]
        return least, where

    def row(self, vehicle_id: str) -> FloatArray:
        """The team's track of ``vehicle_id`` (as :meth:`track`)."""
        out: FloatArray = self.planes[:, self._row[vehicle_id]]
        return out

    def closest_pair(self, vs: VehicleSchedule) -> PairSeparation:
        """``vs``'s closest approach to the rest of the team, on the grid."""
        best, who, t = self.closest(vs)
        if who is None:
            return PairSeparation(vs.vehicle_id, "", math.inf, math.nan, math.nan, math.nan)
        k = int(np.argmin(np.abs(self.t_s - t)))
        mid = 0.5 * (self.track(vs)[:2, k] + self.planes[:2, self._row[who], k])
        return PairSeparation(vs.vehicle_id, who, best, t, float(mid[0]), float(mid[1]))

    def replace(self, vs: VehicleSchedule, track: FloatArray | None = None) -> None:
        """Take ``vs`` as its vehicle's schedule from now on (``track``: as :meth:`track`
        sampled it, when the caller has it)."""
        k = self._row[vs.vehicle_id]
        self.planes[:, k] = self.track(vs) if track is None else track
        self._held[k] = vs
        self.boxes[:, k] = self._boxes(self.planes[:, k])


def _coarse_pairs(samples: TeamSamples) -> list[tuple[int, int, float, float, FloatArray]]:
    """Every pair's least distance on the samples' time grid, compared with array arithmetic:
    ``(i, j, distance_m, time_s, midpoint)``; inf and NaN for a pair never airborne together."""
    t, planes = samples.t_s, samples.planes  # (east/north/altitude, vehicle, time)
    out = []
    for i in range(planes.shape[1] - 1):
        d2 = _squared_gaps_m2(planes[:, i + 1 :], planes[:, i])
        best = d2.argmin(axis=1)
        for row, k in enumerate(best):
            j = i + 1 + row
            if not math.isfinite(float(d2[row, k])):
                out.append((i, j, math.inf, math.nan, np.full(2, np.nan)))
                continue
            mid = 0.5 * (planes[:2, i, k] + planes[:2, j, k])
            out.append((i, j, math.sqrt(float(d2[row, k])), float(t[k]), mid))
    return out


def separation(
    vehicles: Sequence[VehicleSchedule],
    required_m: float,
    samples: TeamSamples | None = None,
    *,
    from_s: float = -math.inf,
) -> Separation:
    """Minimum separation of every pair of scheduled vehicles.

    Every pair is first compared on one time grid fine enough that no pair's distance is off
    by more than a twentieth of ``d_s`` (:class:`TeamSamples`: each schedule sampled once,
    not once per pair); the pairs that may be close (under 1.5 ``d_s``, or within a tenth of
    ``d_s`` of the closest) are then searched exactly (:func:`pair_separation`).

    Parameters
    ----------
    vehicles
        The team's schedules.
    required_m
        The separation minimum ``d_s``, m; pairs below it are conflicts.
    samples
        These schedules sampled already (for ``required_m``), when the caller has them.
    from_s
        Only from this time on (a re-plan's start); the samples', when they are given.
    """
    if len(vehicles) < 2:
        return Separation(required_m, ())
    if samples is None:
        samples = TeamSamples(vehicles, required_m, from_s=from_s)
    from_s = samples.from_s
    assert samples.ids == [v.vehicle_id for v in vehicles], "samples of another team"
    coarse = _coarse_pairs(samples)
    closest = min(d for _, _, d, _, _ in coarse)
    search_below = max(1.5 * required_m, closest + 0.1 * required_m)
    pairs = []
    for i, j, d, t, mid in coarse:
        a, b = vehicles[i], vehicles[j]
        if d < search_below:
            step_s = _pair_step_s(a, b, required_m)
            pairs.append(pair_separation(a, b, step_s=step_s, from_s=from_s))
        else:
            pairs.append(
                PairSeparation(a.vehicle_id, b.vehicle_id, d, t, float(mid[0]), float(mid[1]))
            )
    return Separation(required_m, tuple(pairs))


TRACK_STEP_S = 2.0
"""Sampling of the team's tracks for :class:`TeamTracks`, s (60 m at 30 m/s)."""


_TRACK_CACHE_SIZE = 4096
_track_cache: dict[tuple[Any, ...], tuple[FlightPath, FloatArray, FloatArray]] = {}
"""Keyed by the path's identity and the timing (each entry keeps its path alive, so the
identity is not reused while it is cached)."""


def _track_samples(vs: VehicleSchedule) -> tuple[FloatArray, FloatArray]:
    """A schedule's positions every :data:`TRACK_STEP_S` from its takeoff to its arrival,
    sampled once per timing: every loiter decision in flight asks for the whole team's
    tracks, and the team's timings change far less often than that (a hundred vehicles'
    tracks took seconds to sample, each time, beside the coordinator's loop)."""
    key = (
        id(vs.path), vs.takeoff_s, vs.arrival_s, vs.airborne_start, vs.climb_end_s,
        vs.climb_s_m, vs.legs, vs.loiters,
    )  # fmt: skip
    hit = _track_cache.get(key)
    if hit is not None and hit[0] is vs.path:
        return hit[1], hit[2]
    t = np.append(np.arange(vs.takeoff_s, vs.arrival_s, TRACK_STEP_S), vs.arrival_s)
    p = _positions(vs, t)
    if len(_track_cache) >= _TRACK_CACHE_SIZE:
        _track_cache.clear()
    _track_cache[key] = (vs.path, t, p)
    return t, p


@dataclass(frozen=True)
class TeamTracks:
    """Every place some vehicles will be from a time on, whenever they are there (their
    schedules sampled every :data:`TRACK_STEP_S`, loiters included; time left out, as a
    schedule's times in flight are good to a minute, not to a second): what a loiter circle
    decided in flight must keep the separation from."""

    east_m: FloatArray
    north_m: FloatArray
    margin_m: FloatArray
    """Half a sample's travel at the vehicle's top speed (the track between two samples)."""
    vehicle: tuple[str, ...]

    @classmethod
    def of(cls, others: Sequence[VehicleSchedule], from_s: float) -> TeamTracks:
        east, north, margin, who = [], [], [], []
        for other in others:
            if not other.arrival_s > from_s:
                continue
            t, p = _track_samples(other)
            p = p[(t >= from_s) & ~np.isnan(p[:, 0])]
            east.append(p[:, 0])
            north.append(p[:, 1])
            margin.append(np.full(len(p), 0.5 * other.speed_max_m_s * TRACK_STEP_S))
            who += [other.vehicle_id] * len(p)
        if not who:
            return cls(np.empty(0), np.empty(0), np.empty(0), ())
        return cls(np.concatenate(east), np.concatenate(north), np.concatenate(margin), tuple(who))

    def clearance(
        self, centre_east_m: float, centre_north_m: float, radius_m: float
    ) -> tuple[float, str | None]:
        """How far a circle stays from the tracks, m, and whose track comes nearest
        (``(inf, None)`` with no tracks)."""
        if not self.vehicle:
            return math.inf, None
        gap = (
            np.hypot(self.east_m - centre_east_m, self.north_m - centre_north_m)
            - radius_m
            - self.margin_m
        )
        k = int(np.argmin(gap))
        return float(gap[k]), self.vehicle[k]


def loiter_conflict(
    vs: VehicleSchedule, others: Sequence[VehicleSchedule], required_m: float, from_s: float
) -> str | None:
    """Why the loiter circles ``vs`` flies from ``from_s`` on do not keep ``required_m`` from
    the ``others``' tracks (:class:`TeamTracks`), or None."""
    new = [lo for lo in vs.loiters if lo.t_end_s > from_s]
    if not new:
        return None
    tracks = TeamTracks.of([x for x in others if x.vehicle_id != vs.vehicle_id], from_s)
    for lo in new:
        gap_m, near = tracks.clearance(lo.centre_east_m, lo.centre_north_m, lo.radius_m)
        if gap_m < required_m:
            return f"its turns at {lo.s_m / 1000:.1f} km come {gap_m:.0f} m from {near}'s track"
    return None


def check_separation(sep: Separation) -> None:
    """Refuse a team separation with a pair closer than ``d_s``.

    Raises
    ------
    SeparationError
        Names the closest pair, when and how close (``pair``, ``time_s``, ``distance_m``,
        ``required_m``, ``conflicts``).
    """
    conflicts = sep.conflicts
    if not conflicts:
        return
    worst = min(conflicts, key=lambda p: p.distance_m)
    more = len(conflicts) - 1
    tail = f"; {more} more pair{'s' if more > 1 else ''} in conflict" if more else ""
    raise SeparationError(
        f"vehicles {worst.a} and {worst.b} come within {worst.distance_m:.1f} m of each other "
        f"at {worst.time_s:.1f} s, under the separation minimum d_s {sep.required_m:g} m{tail}",
        pair=(worst.a, worst.b),
        time_s=worst.time_s,
        distance_m=worst.distance_m,
        required_m=sep.required_m,
        conflicts=len(conflicts),
    )

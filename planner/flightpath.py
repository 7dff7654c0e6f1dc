"""Flyable 2-D routes of straight and arc segments, and the Dubins smoothing of a polyline.

Conventions are those of :mod:`planner.dubins`: ``east_m``/``north_m`` in metres, compass
headings in radians (0 = north, clockwise positive, in [0, 2*pi)), ``L`` turns
counter-clockwise, ``R`` clockwise. Straight segments carry ``radius_m = inf`` (zero
curvature), so the minimum over all segments' radii is the tightest turn of a route.

:func:`smooth_polyline` implements section 3.2 of the reference paper: each corner P_i of a
polyline is replaced by the shortest Dubins path between the midpoints of its two legs, flown
with those legs' headings. :func:`check_polyline` checks the polyline constraints of the
paper's eq. (4): minimum leg length, maximum turn angle, maximum range.
"""

from __future__ import annotations

import bisect
import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.dubins import (
    _S_REL_TOL,
    TURN_SIGN,
    GeometryError,
    Pose,
    _advance,
    _advance_arcs,
    _check_radius,
    _check_s,
    _sample_pieces,
    normalise_heading_rad,
    shortest_path,
)
from planner.memo import IdentityMemo

__all__ = [
    "FlightPath",
    "Segment",
    "Violation",
    "check_polyline",
    "leg_lengths_m",
    "smooth_polyline",
    "straight",
    "turn_angles_rad",
]

#: Segment joints may be this far apart in heading and still count as continuous, rad.
JOIN_TOL_RAD = 1e-6
# Position tolerance at joints: absolute part (m) plus a part relative to coordinate size.
_JOIN_TOL_ABS_M = 1e-6
_JOIN_TOL_REL = 1e-9
# Consecutive polyline vertices closer than this (relative to coordinate size) repeat.
_REPEAT_REL = 1e-12
COLLINEAR_RAD = 1e-9
"""Corners turning less than this (rad) are collinear and get no arc."""


def heading_diff_rad(a_rad: float, b_rad: float) -> float:
    """Absolute smallest difference between two headings, in [0, pi]."""
    return abs((a_rad - b_rad + math.pi) % (2.0 * math.pi) - math.pi)


def _join_tol_m(a: Pose, b: Pose) -> float:
    size_m = max(abs(a.east_m), abs(a.north_m), abs(b.east_m), abs(b.north_m))
    return _JOIN_TOL_ABS_M + _JOIN_TOL_REL * size_m


def _join_gap(a: Pose, b: Pose) -> tuple[float, float] | None:
    """Return (gap_m, gap_rad) if ``b`` does not continue ``a`` with G1 continuity, else None."""
    gap_m = math.hypot(b.east_m - a.east_m, b.north_m - a.north_m)
    gap_rad = heading_diff_rad(a.heading_rad, b.heading_rad)
    if gap_m > _join_tol_m(a, b) or gap_rad > JOIN_TOL_RAD:
        return gap_m, gap_rad
    return None


@dataclass(frozen=True, slots=True)
class Segment:
    """One straight (``turn="S"``) or constant-radius arc (``"L"``/``"R"``) piece of a route.

    ``radius_m`` is ``math.inf`` for straights (zero curvature) and finite, > 0, for arcs.
    ``length_m`` is the along-path length, m (>= 0); an arc turns ``length_m / radius_m`` rad.
    """

    start: Pose
    length_m: float
    turn: str
    radius_m: float = math.inf

    def __post_init__(self) -> None:
        if self.turn not in TURN_SIGN:
            raise GeometryError(f"turn must be 'S', 'L' or 'R', got {self.turn!r}")
        if not (math.isfinite(self.length_m) and self.length_m >= 0.0):
            raise GeometryError(f"length_m must be finite and >= 0, got {self.length_m!r}")
        if self.turn == "S":
            if self.radius_m != math.inf:
                raise GeometryError(f"radius_m of a straight must be inf, got {self.radius_m!r}")
        elif not (math.isfinite(self.radius_m) and self.radius_m > 0.0):
            raise GeometryError(f"radius_m of an arc must be finite and > 0, got {self.radius_m!r}")

    @property
    def end(self) -> Pose:
        """The pose at the end of the segment."""
        return self.pose_at(self.length_m)

    @property
    def heading_change_rad(self) -> float:
        """Signed heading change over the segment, rad (positive clockwise, unwrapped)."""
        if self.turn == "S":
            return 0.0
        return TURN_SIGN[self.turn] * self.length_m / self.radius_m

    @property
    def centre(self) -> tuple[float, float] | None:
        """Centre ``(east_m, north_m)`` of an arc's circle; None for a straight."""
        if self.turn == "S":
            return None
        # The centre lies on the side the segment turns to, one radius off the heading.
        sign = TURN_SIGN[self.turn]
        heading_rad = self.start.heading_rad
        return (
            self.start.east_m + sign * self.radius_m * math.cos(heading_rad),
            self.start.north_m - sign * self.radius_m * math.sin(heading_rad),
        )

    def pose_at(self, s_m: float) -> Pose:
        """Return the pose ``s_m`` metres along the segment.

        Parameters
        ----------
        s_m : float
            Distance from the segment start in [0, length_m], m; round-off overshoot is clamped.

        Returns
        -------
        Pose
            Position (m) and compass heading (rad).

        Raises
        ------
        GeometryError
            If ``s_m`` is outside [0, length_m].
        """
        s_m = _check_s(s_m, self.length_m)
        east_m, north_m, heading_rad = _advance(
            self.start.east_m,
            self.start.north_m,
            self.start.heading_rad,
            TURN_SIGN[self.turn],
            s_m,
            self.radius_m,
        )
        return Pose(east_m, north_m, heading_rad)

    def _closest(self, east_m: float, north_m: float) -> tuple[float, float]:
        """Return (distance_m, s_m) of the point of this segment closest to (east, north)."""
        start = self.start
        if self.turn == "S":
            de_m, dn_m = east_m - start.east_m, north_m - start.north_m
            along_m = de_m * math.sin(start.heading_rad) + dn_m * math.cos(start.heading_rad)
            s_m = min(max(along_m, 0.0), self.length_m)
            point = self.pose_at(s_m)
            return math.hypot(east_m - point.east_m, north_m - point.north_m), s_m
        centre = self.centre
        assert centre is not None
        ce_m, cn_m = centre
        from_centre_m = math.hypot(east_m - ce_m, north_m - cn_m)
        sign = TURN_SIGN[self.turn]
        if from_centre_m > 0.0:
            # Bearing from the centre to the start point is heading - sign * pi/2.
            bearing_rad = math.atan2(east_m - ce_m, north_m - cn_m)
            start_bearing_rad = start.heading_rad - sign * 0.5 * math.pi
            swept_rad = normalise_heading_rad(sign * (bearing_rad - start_bearing_rad))
            if swept_rad * self.radius_m <= self.length_m:
                return abs(from_centre_m - self.radius_m), swept_rad * self.radius_m
        end = self.end
        to_start_m = math.hypot(east_m - start.east_m, north_m - start.north_m)
        to_end_m = math.hypot(east_m - end.east_m, north_m - end.north_m)
        return (to_start_m, 0.0) if to_start_m <= to_end_m else (to_end_m, self.length_m)


@dataclass(frozen=True, slots=True)
class FlightPath:
    """A G1-continuous route: consecutive segments join in position and heading.

    Joints must match within ``1e-6 m + 1e-9 * |coordinates|`` and :data:`JOIN_TOL_RAD`.
    """

    segments: tuple[Segment, ...]
    _starts_m: tuple[float, ...] = field(init=False, repr=False, compare=False)
    _length_m: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        segments = tuple(self.segments)
        if not segments:
            raise GeometryError("segments must hold at least one Segment")
        for index in range(1, len(segments)):
            gap = _join_gap(segments[index - 1].end, segments[index].start)
            if gap is not None:
                raise GeometryError(
                    f"segments[{index}] starts {gap[0]:.3g} m and {gap[1]:.3g} rad "
                    f"off the end of segments[{index - 1}]"
                )
        lengths_m = [segment.length_m for segment in segments]
        object.__setattr__(self, "segments", segments)
        object.__setattr__(self, "_starts_m", (0.0, *itertools.accumulate(lengths_m[:-1])))
        object.__setattr__(self, "_length_m", math.fsum(lengths_m))

    @property
    def length_m(self) -> float:
        """Total length, m (exactly rounded sum of the segment lengths)."""
        return self._length_m

    @property
    def start(self) -> Pose:
        """The pose at the start of the route."""
        return self.segments[0].start

    @property
    def end(self) -> Pose:
        """The pose at the end of the route."""
        return self.segments[-1].end

    def cumulative_m(self) -> tuple[float, ...]:
        """Return the along-path distance at which each segment starts, m."""
        return self._starts_m

    def pose_at(self, s_m: float) -> Pose:
        """Return the pose ``s_m`` metres along the route, in O(log n).

        Parameters
        ----------
        s_m : float
            Along-path distance in [0, length_m], m; round-off overshoot is clamped.

        Returns
        -------
        Pose
            Position (m) and compass heading (rad).

        Raises
        ------
        GeometryError
            If ``s_m`` is outside [0, length_m].
        """
        s_m = _check_s(s_m, self._length_m)
        index = max(0, bisect.bisect_right(self._starts_m, s_m) - 1)
        segment = self.segments[index]
        return segment.pose_at(min(max(s_m - self._starts_m[index], 0.0), segment.length_m))

    def poses_at(self, s_m: ArrayLike) -> NDArray[np.float64]:
        """Return the poses at many along-path distances at once: :meth:`pose_at`, vectorised.

        Sampling a long route point by point costs a Python call per sample; this evaluates
        the same formulas on arrays, with the same result to the last bit.

        Parameters
        ----------
        s_m : array_like
            (N,) along-path distances in [0, length_m], m; round-off overshoot is clamped.

        Returns
        -------
        NDArray
            (N, 3) rows ``[east_m, north_m, heading_rad]``.

        Raises
        ------
        GeometryError
            If a distance is outside [0, length_m].
        """
        s = np.asarray(s_m, dtype=np.float64).reshape(-1)
        tolerance_m = _S_REL_TOL * max(1.0, self._length_m)
        # min and max are NaN when any distance is: such an array is refused too.
        if s.size and not (s.min() >= -tolerance_m and s.max() <= self._length_m + tolerance_m):
            outside = ~((s >= -tolerance_m) & (s <= self._length_m + tolerance_m))
            bad = float(s[np.flatnonzero(outside)[0]])
            raise GeometryError(f"s_m must be in [0, {self._length_m}] m, got {bad!r}")
        s = np.minimum(np.maximum(s, 0.0), self._length_m)
        table = _segment_table(self)
        index = np.maximum(np.searchsorted(table.starts_m, s, side="right") - 1, 0)
        along_m = np.minimum(np.maximum(s - table.starts_m[index], 0.0), table.length_m[index])
        # Every row as on a straight (its segment's sine and cosine looked up, not computed
        # again per row), then the rows on arcs, if any, as :func:`_advance_arcs` has them.
        out = np.empty((s.size, 3), dtype=np.float64)
        out[:, 0] = table.east_m[index] + along_m * table.sin_heading[index]
        out[:, 1] = table.north_m[index] + along_m * table.cos_heading[index]
        out[:, 2] = table.heading_rad[index]
        if table.has_arcs:
            arc = np.flatnonzero(table.sign[index] != 0.0)
            if arc.size:
                on = index[arc]
                out[arc] = _advance_arcs(
                    table.east_m[on],
                    table.north_m[on],
                    table.heading_rad[on],
                    table.sign[on],
                    along_m[arc],
                    table.radius_m[on],
                )
        return out

    def remaining_m(self, s_m: float) -> float:
        """Return the distance left to fly from ``s_m`` to the end, m.

        Parameters
        ----------
        s_m : float
            Along-path distance in [0, length_m], m.

        Returns
        -------
        float
            ``length_m - s_m``, m (>= 0).
        """
        return self._length_m - _check_s(s_m, self._length_m)

    def minimum_turn_radius_m(self) -> float:
        """Return the tightest turn radius of the route, m (``inf`` if it has no arcs)."""
        return min(segment.radius_m for segment in self.segments)

    def sample(
        self, step_m: float, *, max_arc_step_rad: float = math.radians(5.0)
    ) -> NDArray[np.float64]:
        """Sample every segment evenly, joints and both ends included.

        Parameters
        ----------
        step_m : float
            Largest along-path spacing between samples, m (> 0).
        max_arc_step_rad : float, optional
            Largest heading change between samples on arcs, rad (> 0).

        Returns
        -------
        NDArray
            (N, 3) rows ``[east_m, north_m, heading_rad]``, N >= 2.
        """
        pieces = [
            (segment.start, TURN_SIGN[segment.turn], segment.length_m, segment.radius_m)
            for segment in self.segments
        ]
        return _sample_pieces(pieces, step_m, max_arc_step_rad)

    def waypoints(self, max_arc_step_rad: float = math.radians(30.0)) -> NDArray[np.float64]:
        """Return the points an autopilot flies straight between.

        Parameters
        ----------
        max_arc_step_rad : float, optional
            Largest heading change between consecutive points along an arc, rad, in (0, pi].

        Returns
        -------
        NDArray
            (M, 2) rows ``[east_m, north_m]``: the start, every segment end and evenly spaced
            points along arcs; no two consecutive rows coincide.

        Raises
        ------
        GeometryError
            If ``max_arc_step_rad`` is outside (0, pi].
        """
        if not (0.0 < max_arc_step_rad <= math.pi):
            raise GeometryError(f"max_arc_step_rad must be in (0, pi], got {max_arc_step_rad!r}")
        points = [(self.start.east_m, self.start.north_m)]
        for segment in self.segments:
            n_steps = 1
            if segment.turn != "S":
                n_steps = max(1, math.ceil(abs(segment.heading_change_rad) / max_arc_step_rad))
            for k in range(1, n_steps + 1):
                pose = segment.pose_at(segment.length_m * k / n_steps)
                last = points[-1]
                size_m = max(abs(pose.east_m), abs(pose.north_m), 1.0)
                if math.hypot(pose.east_m - last[0], pose.north_m - last[1]) > 1e-9 * size_m:
                    points.append((pose.east_m, pose.north_m))
        return np.array(points, dtype=np.float64)

    def project(self, east_m: float, north_m: float) -> float:
        """Return the along-path distance of the route point closest to a position.

        Parameters
        ----------
        east_m, north_m : float
            Position, m (e.g. from telemetry).

        Returns
        -------
        float
            Along-path distance s, m; the smallest one if several points are equally close.
        """
        best_m, best_s_m = math.inf, 0.0
        for start_m, segment in zip(self._starts_m, self.segments, strict=True):
            distance_m, s_m = segment._closest(east_m, north_m)
            if distance_m < best_m:
                best_m, best_s_m = distance_m, start_m + s_m
        return min(best_s_m, self._length_m)

    def project_many(self, points_m: ArrayLike) -> NDArray[np.float64]:
        """Return :meth:`project` of each of many positions, with the same results.

        A segment can only hold the closest point if its bounding box (the whole circle's,
        for an arc) is no farther than the closest point found so far; the others are
        skipped, and the rest are compared in route order exactly as :meth:`project` does.

        Parameters
        ----------
        points_m : array_like
            (N, 2) positions ``[east_m, north_m]``, m.

        Returns
        -------
        NDArray
            (N,) along-path distances, m.
        """
        points = np.asarray(points_m, dtype=np.float64).reshape(-1, 2)
        boxes = np.array([_segment_box_m(segment) for segment in self.segments])
        out = np.empty(len(points), dtype=np.float64)
        for k, (east_m, north_m) in enumerate(points.tolist()):
            gap_east = np.maximum(np.maximum(boxes[:, 0] - east_m, east_m - boxes[:, 1]), 0.0)
            gap_north = np.maximum(np.maximum(boxes[:, 2] - north_m, north_m - boxes[:, 3]), 0.0)
            floor_m = np.hypot(gap_east, gap_north)
            nearest = int(np.argmin(floor_m))
            bound_m, _ = self.segments[nearest]._closest(east_m, north_m)
            best_m, best_s_m = math.inf, 0.0
            for index in np.flatnonzero(floor_m <= bound_m + _PROJECT_SLACK_M).tolist():
                distance_m, s_m = self.segments[index]._closest(east_m, north_m)
                if distance_m < best_m:
                    best_m, best_s_m = distance_m, self._starts_m[index] + s_m
            out[k] = min(best_s_m, self._length_m)
        return out

    def concat(self, other: FlightPath) -> FlightPath:
        """Return this route followed by ``other``.

        Raises
        ------
        GeometryError
            If ``other`` does not start where this route ends, with the same heading.
        """
        gap = _join_gap(self.end, other.start)
        if gap is not None:
            raise GeometryError(
                f"other starts {gap[0]:.3g} m and {gap[1]:.3g} rad off this path's end"
            )
        return FlightPath(self.segments + other.segments)

    def prefix(self, s_m: float) -> FlightPath | None:
        """The first ``s_m`` metres of this route (None when ``s_m`` is ~0)."""
        if s_m <= 1e-6:
            return None
        if s_m >= self._length_m:
            return self
        out: list[Segment] = []
        for start, seg in zip(self._starts_m, self.segments, strict=True):
            if start >= s_m:
                break
            if start + seg.length_m <= s_m:
                out.append(seg)
            else:
                out.append(Segment(seg.start, s_m - start, seg.turn, seg.radius_m))
        return FlightPath(tuple(out))


_PROJECT_SLACK_M = 1e-3
# A segment whose bounding box is farther than the best distance by this much cannot be
# closest, round-off included.


def _segment_box_m(segment: Segment) -> tuple[float, float, float, float]:
    """Least and greatest east, least and greatest north (m) bounding a segment's points."""
    centre = segment.centre
    if centre is not None:
        r = segment.radius_m
        return (centre[0] - r, centre[0] + r, centre[1] - r, centre[1] + r)
    start, end = segment.start, segment.end
    return (
        min(start.east_m, end.east_m),
        max(start.east_m, end.east_m),
        min(start.north_m, end.north_m),
        max(start.north_m, end.north_m),
    )


@dataclass(frozen=True, slots=True)
class _SegmentTable:
    """A path's segments as arrays, for :meth:`FlightPath.poses_at`."""

    starts_m: NDArray[np.float64]
    length_m: NDArray[np.float64]
    east_m: NDArray[np.float64]
    north_m: NDArray[np.float64]
    heading_rad: NDArray[np.float64]
    sin_heading: NDArray[np.float64]
    """``sin(heading_rad)``: a straight's ``_advance`` factors (the same bits as per row)."""
    cos_heading: NDArray[np.float64]
    sign: NDArray[np.float64]
    radius_m: NDArray[np.float64]
    has_arcs: bool


_TABLES: IdentityMemo[_SegmentTable] = IdentityMemo(4096)
"""Each path's :class:`_SegmentTable`, by the path (paths are immutable)."""


def _segment_table(path: FlightPath) -> _SegmentTable:
    """``path``'s :class:`_SegmentTable`, built once per path: the same path is sampled
    over and over when a team's timings are compared."""
    return _TABLES.get((path,), None, lambda: _new_segment_table(path))


def _new_segment_table(path: FlightPath) -> _SegmentTable:
    columns = np.array(
        [
            (
                seg.start.east_m,
                seg.start.north_m,
                seg.start.heading_rad,
                seg.length_m,
                TURN_SIGN[seg.turn],
                seg.radius_m,
            )
            for seg in path.segments
        ],
        dtype=np.float64,
    ).T
    table = _SegmentTable(
        starts_m=np.asarray(path._starts_m, dtype=np.float64),
        length_m=columns[3].copy(),
        east_m=columns[0].copy(),
        north_m=columns[1].copy(),
        heading_rad=columns[2].copy(),
        sin_heading=np.sin(columns[2]),
        cos_heading=np.cos(columns[2]),
        sign=columns[4].copy(),
        radius_m=columns[5].copy(),
        has_arcs=bool((columns[4] != 0.0).any()),
    )
    for array in (getattr(table, name) for name in table.__slots__ if name != "has_arcs"):
        array.flags.writeable = False
    return table


def straight(
    start_east_m: float, start_north_m: float, end_east_m: float, end_north_m: float
) -> FlightPath:
    """Return the straight route between two distinct points.

    Parameters
    ----------
    start_east_m, start_north_m : float
        Start position, m.
    end_east_m, end_north_m : float
        End position, m.

    Returns
    -------
    FlightPath
        One straight segment.

    Raises
    ------
    GeometryError
        If the end equals the start (the heading would be undefined).
    """
    de_m, dn_m = end_east_m - start_east_m, end_north_m - start_north_m
    length_m = math.hypot(de_m, dn_m)
    if length_m == 0.0:
        raise GeometryError("end_east_m/end_north_m must differ from the start position")
    start = Pose(start_east_m, start_north_m, math.atan2(de_m, dn_m))
    return FlightPath((Segment(start, length_m, "S"),))


def _as_points(points_m: ArrayLike, *, distinct: bool) -> NDArray[np.float64]:
    """Validate a polyline as a finite (N >= 2, 2) float array."""
    points = np.asarray(points_m, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2:
        raise GeometryError(f"points_m must have shape (N, 2), got {points.shape}")
    if points.shape[0] < 2:
        raise GeometryError(f"points_m must hold at least 2 points, got {points.shape[0]}")
    if not np.all(np.isfinite(points)):
        raise GeometryError("points_m must be finite")
    if distinct:
        legs_m = np.hypot(*np.diff(points, axis=0).T)
        tol_m = _REPEAT_REL * max(1.0, float(np.max(np.abs(points))))
        repeats = np.flatnonzero(legs_m <= tol_m)
        if repeats.size:
            index = int(repeats[0]) + 1
            raise GeometryError(f"points_m[{index}] repeats points_m[{index - 1}]")
    return points


def leg_lengths_m(points_m: ArrayLike) -> NDArray[np.float64]:
    """Return the length of each polyline leg.

    Parameters
    ----------
    points_m : array_like
        (N, 2) vertices ``[east_m, north_m]``, N >= 2.

    Returns
    -------
    NDArray
        (N - 1,) leg lengths, m.
    """
    points = _as_points(points_m, distinct=False)
    result: NDArray[np.float64] = np.hypot(*np.diff(points, axis=0).T)
    return result


def turn_angles_rad(points_m: ArrayLike) -> NDArray[np.float64]:
    """Return the absolute heading change at each interior vertex of a polyline.

    Parameters
    ----------
    points_m : array_like
        (N, 2) vertices ``[east_m, north_m]``, N >= 2, no two consecutive ones equal.

    Returns
    -------
    NDArray
        (N - 2,) turn angles in [0, pi], rad (0 straight on, pi a reversal).
    """
    legs = np.diff(_as_points(points_m, distinct=True), axis=0)
    incoming, outgoing = legs[:-1], legs[1:]
    cross = incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]
    dot = np.einsum("ij,ij->i", incoming, outgoing)
    result: NDArray[np.float64] = np.arctan2(np.abs(cross), dot)
    return result


@dataclass(frozen=True, slots=True)
class Violation:
    """One broken polyline constraint of eq. (4).

    ``constraint`` is the name of the limit argument (``"min_leg_m"``, ``"max_turn_rad"``,
    ``"max_range_m"``); ``index`` is the leg index, the vertex index, or for the range the
    index of the first vertex beyond ``max_range_m``. ``s_m`` is where along the path a
    violation at one point lies (m), when it has one (terrain clearance).
    """

    constraint: str
    index: int
    value: float
    limit: float
    message: str
    s_m: float | None = None


def check_polyline(
    points_m: ArrayLike, *, min_leg_m: float, max_turn_rad: float, max_range_m: float
) -> list[Violation]:
    """Check a polyline against the limits of the paper's eq. (4).

    Parameters
    ----------
    points_m : array_like
        (N, 2) vertices ``[east_m, north_m]``, N >= 2, no two consecutive ones equal.
    min_leg_m : float
        Shortest allowed leg, m (>= 0).
    max_turn_rad : float
        Largest allowed heading change at a vertex, rad, in [0, pi].
    max_range_m : float
        Largest allowed total length, m (>= 0, may be inf).

    Returns
    -------
    list[Violation]
        Short legs (by leg), sharp turns (by vertex), then the range; empty if all hold.

    Raises
    ------
    GeometryError
        If an argument is malformed.
    """
    if not min_leg_m >= 0.0:
        raise GeometryError(f"min_leg_m must be >= 0, got {min_leg_m!r}")
    if not 0.0 <= max_turn_rad <= math.pi:
        raise GeometryError(f"max_turn_rad must be in [0, pi], got {max_turn_rad!r}")
    if not max_range_m >= 0.0:
        raise GeometryError(f"max_range_m must be >= 0, got {max_range_m!r}")
    legs_m = leg_lengths_m(points_m)
    turns_rad = turn_angles_rad(points_m)
    violations: list[Violation] = []
    for leg, length_m in enumerate(legs_m.tolist()):
        if length_m < min_leg_m:
            violations.append(
                Violation(
                    "min_leg_m",
                    leg,
                    length_m,
                    min_leg_m,
                    f"leg {leg} is {length_m:.6g} m, shorter than min_leg_m={min_leg_m:.6g} m",
                )
            )
    for vertex, turn_rad in enumerate(turns_rad.tolist(), start=1):
        if turn_rad > max_turn_rad:
            violations.append(
                Violation(
                    "max_turn_rad",
                    vertex,
                    turn_rad,
                    max_turn_rad,
                    f"vertex {vertex} turns {turn_rad:.6g} rad, more than "
                    f"max_turn_rad={max_turn_rad:.6g} rad",
                )
            )
    total_m = math.fsum(legs_m.tolist())
    if total_m > max_range_m:
        beyond = int(np.searchsorted(np.cumsum(legs_m), max_range_m, side="right")) + 1
        violations.append(
            Violation(
                "max_range_m",
                min(beyond, len(legs_m)),
                total_m,
                max_range_m,
                f"polyline is {total_m:.6g} m long, more than max_range_m={max_range_m:.6g} m "
                f"(from vertex {min(beyond, len(legs_m))})",
            )
        )
    return violations


def _connect(start: Pose, end: Pose, radius_m: float) -> list[Segment]:
    """Segments from ``start`` to ``end``: a straight if ``end`` is dead ahead, else Dubins."""
    de_m, dn_m = end.east_m - start.east_m, end.north_m - start.north_m
    distance_m = math.hypot(de_m, dn_m)
    if distance_m > 0.0 and heading_diff_rad(start.heading_rad, end.heading_rad) <= COLLINEAR_RAD:
        bearing_rad = math.atan2(de_m, dn_m)
        if heading_diff_rad(bearing_rad, start.heading_rad) <= COLLINEAR_RAD:
            return [Segment(start, distance_m, "S")]
    return list(shortest_path(start, end, radius_m).segments())


def _merge_runs(segments: list[Segment]) -> list[Segment]:
    """Join runs of straights, and of arcs turning the same way at the same radius."""
    merged: list[Segment] = []
    for segment in segments:
        previous = merged[-1] if merged else None
        if (
            previous is not None
            and segment.turn != "S"
            and segment.turn == previous.turn
            and segment.radius_m == previous.radius_m
        ):
            merged[-1] = Segment(
                previous.start, previous.length_m + segment.length_m, segment.turn, segment.radius_m
            )
        elif segment.turn == "S" and previous is not None and previous.turn == "S":
            first = merged[-1].start
            end = segment.end
            de_m, dn_m = end.east_m - first.east_m, end.north_m - first.north_m
            pose = Pose(first.east_m, first.north_m, math.atan2(de_m, dn_m))
            merged[-1] = Segment(pose, math.hypot(de_m, dn_m), "S")
        else:
            merged.append(segment)
    return merged


def smooth_polyline(
    points_m: ArrayLike,
    radius_m: float,
    *,
    start_heading_rad: float | None = None,
    end_heading_rad: float | None = None,
) -> FlightPath:
    """Smooth a polyline into a flyable route by the Dubins corner method of section 3.2.

    Each interior vertex P_i is replaced by the shortest Dubins path, at ``radius_m``, from the
    midpoint of leg P_{i-1}P_i (with that leg's heading) to the midpoint of leg P_iP_{i+1}
    (with that leg's heading). The route flies straight from P_0 to the first midpoint and from
    the last midpoint to P_{N-1}, so it passes through every leg midpoint, is G1-continuous and
    never turns tighter than ``radius_m``. Collinear vertices get no arc.

    Parameters
    ----------
    points_m : array_like
        (N, 2) vertices ``[east_m, north_m]``, N >= 2, no two consecutive ones equal.
    radius_m : float
        Minimum turn radius, m (> 0).
    start_heading_rad : float, optional
        Compass heading the vehicle already has at P_0, rad. The route then begins with a
        Dubins path from (P_0, start_heading_rad) to the first leg's midpoint, or to P_1 if
        there is a single leg and no ``end_heading_rad``.
    end_heading_rad : float, optional
        Compass heading required at P_{N-1}, rad. The route then ends with a Dubins path from
        the last leg's midpoint, or from P_0 if there is a single leg and no
        ``start_heading_rad``.

    Returns
    -------
    FlightPath
        The smoothed route from P_0 to P_{N-1}.

    Raises
    ------
    GeometryError
        If ``points_m`` is malformed, has fewer than 2 or repeated consecutive points, if
        ``radius_m`` is not finite and positive, or a heading is not finite.
    """
    points = _as_points(points_m, distinct=True)
    _check_radius(radius_m)
    for name, value in (
        ("start_heading_rad", start_heading_rad),
        ("end_heading_rad", end_heading_rad),
    ):
        if value is not None and not math.isfinite(value):
            raise GeometryError(f"{name} must be finite, got {value!r}")
    legs = np.diff(points, axis=0)
    leg_headings_rad = np.arctan2(legs[:, 0], legs[:, 1]).tolist()
    midpoints = ((points[:-1] + points[1:]) / 2.0).tolist()
    n_legs = len(leg_headings_rad)

    first_e, first_n = float(points[0, 0]), float(points[0, 1])
    last_e, last_n = float(points[-1, 0]), float(points[-1, 1])
    anchors = [
        Pose(
            first_e,
            first_n,
            leg_headings_rad[0] if start_heading_rad is None else start_heading_rad,
        )
    ]
    one_heading_given = (start_heading_rad is None) != (end_heading_rad is None)
    if not (n_legs == 1 and one_heading_given):
        # With one leg and one given heading the single Dubins path spans the whole leg.
        anchors.extend(
            Pose(e_m, n_m, heading_rad)
            for (e_m, n_m), heading_rad in zip(midpoints, leg_headings_rad, strict=True)
        )
    anchors.append(
        Pose(
            last_e,
            last_n,
            leg_headings_rad[-1] if end_heading_rad is None else end_heading_rad,
        )
    )
    segments: list[Segment] = []
    for start, end in itertools.pairwise(anchors):
        pieces = _connect(start, end, radius_m)
        if segments and pieces:
            # Start exactly where the previous piece ended; the anchors agree to round-off.
            pieces = _rechain(segments[-1].end, pieces)
        segments.extend(pieces)
    return FlightPath(tuple(_merge_runs(segments)))


def _rechain(start: Pose, pieces: list[Segment]) -> list[Segment]:
    """Re-anchor consecutive segments to begin at ``start`` (removes round-off joints)."""
    out: list[Segment] = []
    pose = start
    for piece in pieces:
        segment = Segment(pose, piece.length_m, piece.turn, piece.radius_m)
        out.append(segment)
        pose = segment.end
    return out

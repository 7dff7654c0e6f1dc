"""The route as the closed loop sees it: where a fix lies along it and how long the rest
takes at an airspeed in a wind.

:class:`RouteTrack` samples the route once (every ``step_m`` metres for :meth:`RouteTrack.locate`,
and as constant-track pieces, straights whole and arcs every 5 degrees, for the timing) so that
the per-fix work is a few vectorised numpy passes; its loiters (:class:`LoiterSpec`) are flown
circles at points along it. The wind triangle is :mod:`planner.wind`'s.

Conventions: ``east_m``/``north_m`` in metres, compass angles in radians (0 = north, clockwise
positive, so a unit direction is ``(sin h, cos h)`` in (east, north)), speeds in m/s, times in
seconds on any consistent mission time base. No clock, no I/O: everything is passed in.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gcs.errors import GcsError
from planner.flightpath import FlightPath
from planner.wind import Wind

__all__ = [
    "ArrivalInputError",
    "LoiterSpec",
    "RouteTrack",
]

FloatArray = NDArray[np.float64]
AnyFloatArray = NDArray[np.floating[Any]]

TAU = 2.0 * math.pi
#: Largest heading change of one constant-track timing piece on an arc or a loiter circle, rad
#: (72 pieces per turn). The midpoint rule it amounts to is accurate to ~1e-4 of the time.
ARC_PIECE_RAD = TAU / 72.0
# Largest heading change between locate samples on arcs, rad (FlightPath.sample's default).
_LOCATE_ARC_STEP_RAD = math.radians(5.0)
# Relative slack when checking s_m against the route length (round-off of sums).
_S_REL_TOL = 1e-9
_TURN_SIGN = {"L": -1, "S": 0, "R": 1}
_ChordRow = tuple[
    float, float, float, float, float, float, float, float, float, float, float, float, float
]
"""A chord as :meth:`RouteTrack._exact` reads it: its first sample's east and north, its
segment's turn sign, centre east and north, radius, start and length, then the chord's east
and north, its inverse squared length, its first sample's s and its length along the path."""


class ArrivalInputError(GcsError, ValueError):
    """An arrival-controller input that is out of range (limits, loiters, positions)."""


def require_finite(name: str, value: float) -> float:
    if not math.isfinite(value):
        raise ArrivalInputError(f"{name} must be finite, got {value!r}")
    return float(value)


# --- the route ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class LoiterSpec:
    """A loiter flown where the route reaches ``s_m``: whole turns plus an optional detour.

    ``s_m`` is the along-path distance (m) of the path point where the loiter is entered; the
    circle (``centre_east_m``, ``centre_north_m``, ``radius_m`` in m) is flown ``turns`` times,
    clockwise or not, plus ``detour_m`` (the way out to a circle off the route, the line-up on
    the route's course after the turns and the way back), at the same airspeed.
    """

    s_m: float
    centre_east_m: float
    centre_north_m: float
    radius_m: float
    turns: int
    clockwise: bool
    detour_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("s_m", "centre_east_m", "centre_north_m"):
            require_finite(f"LoiterSpec.{name}", getattr(self, name))
        if not (math.isfinite(self.radius_m) and self.radius_m > 0.0):
            raise ArrivalInputError(f"LoiterSpec.radius_m must be > 0, got {self.radius_m!r}")
        if self.turns < 0:
            raise ArrivalInputError(f"LoiterSpec.turns must be >= 0, got {self.turns!r}")
        if not (math.isfinite(self.detour_m) and self.detour_m >= 0.0):
            raise ArrivalInputError(f"LoiterSpec.detour_m must be >= 0, got {self.detour_m!r}")

    @property
    def circle_m(self) -> float:
        """Length of the turns, m (``2 pi r turns``)."""
        return TAU * self.radius_m * self.turns

    @property
    def length_m(self) -> float:
        """Everything the loiter adds to the route, m (turns plus detour)."""
        return self.circle_m + self.detour_m


@dataclass(frozen=True, slots=True)
class Remaining:
    """What is left to fly, as constant-track pieces with the wind resolved on each."""

    length_m: FloatArray  # > 0
    along_m_s: FloatArray  # wind along the track
    cross2_m2_s2: FloatArray  # (wind across the track) squared
    still_air_m: float  # flown at airspeed, no wind correction (detours)
    tas_per_eas: float = 1.0  # true airspeed flown per unit of the airspeed asked about

    @property
    def total_m(self) -> float:
        return float(self.length_m.sum()) + self.still_air_m

    def time_s(self, airspeed_m_s: float) -> float:
        """Time to fly it all at ``airspeed_m_s``, s (inf where a piece cannot be made good)."""
        return self.time_and_slope(airspeed_m_s, slope=False)[0]

    def time_and_slope(self, airspeed_m_s: float, *, slope: bool = True) -> tuple[float, float]:
        """Time (s) and its derivative with respect to airspeed (s per m/s; nan if unknown)."""
        ratio = self.tas_per_eas
        a = airspeed_m_s * ratio
        if a <= 0.0:
            return (math.inf, math.nan) if self.total_m > 0.0 else (0.0, 0.0)
        time_s = self.still_air_m / a
        d_time = -self.still_air_m / (a * a)
        if self.length_m.size:
            disc = a * a - self.cross2_m2_s2
            if float(disc.min()) < 0.0:
                return math.inf, math.nan
            root = np.sqrt(disc)
            speed = self.along_m_s + root
            if float(speed.min()) <= 0.0:
                return math.inf, math.nan
            per_speed = self.length_m / speed
            time_s += float(per_speed.sum())
            if slope:
                if float(root.min()) <= 0.0:
                    return time_s, math.nan
                d_time -= float((per_speed / speed * (a / root)).sum())
        return time_s, d_time * ratio


def _wrap_rad(angle_rad: FloatArray) -> FloatArray:
    wrapped: FloatArray = np.mod(angle_rad, TAU)
    return wrapped


class RouteTrack:
    """A planned route (FlightPath + loiters) sampled once into numpy arrays.

    For :meth:`locate`: samples every ``step_m`` (and every 5 degrees on arcs) with east, north,
    compass track and cumulative along-path distance. For :meth:`time_to_go_s`: constant-track
    pieces (straights whole, arcs and loiter circles every 5 degrees, 72 per turn).

    Parameters
    ----------
    path : FlightPath
        The route to fly.
    loiters : sequence of LoiterSpec, optional
        Loiters on it, ordered by ``s_m`` (each within ``[0, path.length_m]``).
    step_m : float, optional
        Largest spacing of the locate samples, m (> 0), default 25 m.

    Raises
    ------
    ArrivalInputError
        If ``step_m`` is not positive, or a loiter is off the route or out of order.
    """

    def __init__(
        self, path: FlightPath, loiters: Sequence[LoiterSpec] = (), step_m: float = 25.0
    ) -> None:
        if not (math.isfinite(step_m) and step_m > 0.0):
            raise ArrivalInputError(f"step_m must be finite and > 0, got {step_m!r}")
        self.path = path
        self.step_m = float(step_m)
        self.loiters: tuple[LoiterSpec, ...] = tuple(loiters)
        self._length_m = path.length_m
        tolerance_m = _S_REL_TOL * max(1.0, self._length_m)
        previous_s_m = -math.inf
        for index, loiter in enumerate(self.loiters):
            if not (-tolerance_m <= loiter.s_m <= self._length_m + tolerance_m):
                raise ArrivalInputError(
                    f"loiters[{index}].s_m={loiter.s_m!r} is off the route [0, {self._length_m}] m"
                )
            if loiter.s_m < previous_s_m:
                raise ArrivalInputError(f"loiters must be ordered by s_m (loiters[{index}])")
            previous_s_m = loiter.s_m
        self._build_samples()
        self._build_pieces()
        self._loiter_pieces = [self._loiter_circle(loiter) for loiter in self.loiters]
        self._flight_cache: dict[int, tuple[FloatArray, FloatArray, FloatArray, FloatArray]] = {}

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled as what it is built from (its samples are 20 times that and are built
        again): a flight's checkpoint holds every vehicle's track."""
        return (RouteTrack, (self.path, self.loiters, self.step_m))

    # -- construction ------------------------------------------------------------------------

    def _build_samples(self) -> None:
        east: list[FloatArray] = []
        north: list[FloatArray] = []
        track: list[FloatArray] = []
        along: list[FloatArray] = []
        # Per chord, its segment: turn sign, centre east, centre north, radius, start s, length.
        arcs: list[FloatArray] = []
        for start_m, segment in zip(self.path.cumulative_m(), self.path.segments, strict=True):
            if segment.length_m <= 0.0:
                continue
            sign = _TURN_SIGN[segment.turn]
            centre = segment.centre or (0.0, 0.0)
            radius_m = segment.radius_m if sign else 0.0
            arc = (float(sign), centre[0], centre[1], radius_m, start_m, segment.length_m)
            n_steps = max(1, math.ceil(segment.length_m / self.step_m))
            if sign:
                turn_rad = segment.length_m / segment.radius_m
                n_steps = max(n_steps, math.ceil(turn_rad / _LOCATE_ARC_STEP_RAD))
            s_local = np.linspace(0.0, segment.length_m, n_steps + 1)[:-1]
            start = segment.start
            e, n, h = _advance_array(
                start.east_m, start.north_m, start.heading_rad, sign, s_local, segment.radius_m
            )
            east.append(e)
            north.append(n)
            track.append(h)
            along.append(start_m + s_local)
            arcs.append(np.tile(np.array(arc), (s_local.size, 1)))
        end = self.path.end
        east.append(np.array([end.east_m]))
        north.append(np.array([end.north_m]))
        track.append(np.array([end.heading_rad]))
        along.append(np.array([self._length_m]))
        self._east_m = np.concatenate(east)
        self._north_m = np.concatenate(north)
        self._track_rad = np.concatenate(track)
        self._s_m = np.concatenate(along)
        for array in (self._east_m, self._north_m, self._track_rad, self._s_m):
            array.setflags(write=False)
        self._chord_arc = np.concatenate(arcs) if arcs else np.zeros((0, 6))
        # Chords between consecutive samples, for projection.
        self._chord_east_m = np.diff(self._east_m)
        self._chord_north_m = np.diff(self._north_m)
        self._chord_s_m = np.diff(self._s_m)
        chord2 = self._chord_east_m**2 + self._chord_north_m**2
        self._chord_inv2 = np.divide(1.0, chord2, out=np.zeros_like(chord2), where=chord2 > 0.0)
        # The same as plain floats, for the per-fix work on a handful of samples (a numpy
        # call on three elements costs more than the arithmetic in Python).
        self._s_list: list[float] = self._s_m.tolist()
        self._chord_rows: list[_ChordRow] = [
            (e, n, *arc, ce, cn, inv2, s, cs)
            for e, n, arc, ce, cn, inv2, s, cs in zip(
                self._east_m[:-1].tolist(),
                self._north_m[:-1].tolist(),
                self._chord_arc.tolist(),
                self._chord_east_m.tolist(),
                self._chord_north_m.tolist(),
                self._chord_inv2.tolist(),
                self._s_list[:-1],
                self._chord_s_m.tolist(),
                strict=True,
            )
        ]

    def _build_pieces(self) -> None:
        starts: list[FloatArray] = []
        lengths: list[FloatArray] = []
        tracks: list[FloatArray] = []
        for start_m, segment in zip(self.path.cumulative_m(), self.path.segments, strict=True):
            if segment.length_m <= 0.0:
                continue
            sign = _TURN_SIGN[segment.turn]
            heading_rad = segment.start.heading_rad
            if sign == 0:
                starts.append(np.array([start_m]))
                lengths.append(np.array([segment.length_m]))
                tracks.append(np.array([heading_rad]))
                continue
            turn_rad = segment.length_m / segment.radius_m
            n_pieces = max(1, math.ceil(turn_rad / ARC_PIECE_RAD - 1e-9))
            piece_m = segment.length_m / n_pieces
            k = np.arange(n_pieces, dtype=np.float64)
            starts.append(start_m + k * piece_m)
            lengths.append(np.full(n_pieces, piece_m))
            # The chord of an arc piece points along the heading at the piece's middle.
            tracks.append(_wrap_rad(heading_rad + sign * (k + 0.5) * (turn_rad / n_pieces)))
        if not starts:  # a zero-length route: one empty piece keeps the indexing simple
            starts, lengths, tracks = [np.zeros(1)], [np.zeros(1)], [np.zeros(1)]
        self._piece_start_m = np.concatenate(starts)
        self._piece_len_m = np.concatenate(lengths)
        self._piece_end_m = self._piece_start_m + self._piece_len_m
        piece_track = np.concatenate(tracks)
        self._piece_sin = np.sin(piece_track)
        self._piece_cos = np.cos(piece_track)

    def _loiter_circle(self, loiter: LoiterSpec) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(cumulative start m, sin track, cos track) of a loiter's circle pieces."""
        n_pieces = math.ceil(loiter.circle_m / (ARC_PIECE_RAD * loiter.radius_m) - 1e-9)
        if n_pieces <= 0:
            return np.zeros(0), np.zeros(0), np.zeros(0)
        s_m = min(max(loiter.s_m, 0.0), self._length_m)
        entry = self.path.pose_at(s_m)
        de_m, dn_m = entry.east_m - loiter.centre_east_m, entry.north_m - loiter.centre_north_m
        sign = 1 if loiter.clockwise else -1
        if math.hypot(de_m, dn_m) > 1e-9 * loiter.radius_m:
            # Tangent to the circle at the entry bearing, turning the loiter's way.
            heading_rad = math.atan2(de_m, dn_m) + sign * 0.5 * math.pi
        else:
            heading_rad = entry.heading_rad
        piece_m = loiter.circle_m / n_pieces
        k = np.arange(n_pieces, dtype=np.float64)
        track = heading_rad + sign * (k + 0.5) * (piece_m / loiter.radius_m)
        return k * piece_m, np.sin(track), np.cos(track)

    # -- public ------------------------------------------------------------------------------

    @property
    def length_m(self) -> float:
        """Length of the path, m (loiters not included)."""
        return self._length_m

    @property
    def sample_east_m(self) -> FloatArray:
        """East of the locate samples, m (read-only)."""
        return self._east_m

    @property
    def sample_north_m(self) -> FloatArray:
        """North of the locate samples, m (read-only)."""
        return self._north_m

    @property
    def sample_track_rad(self) -> FloatArray:
        """Compass track of the path at the locate samples, rad (read-only)."""
        return self._track_rad

    @property
    def sample_s_m(self) -> FloatArray:
        """Along-path distance of the locate samples, m (read-only, increasing)."""
        return self._s_m

    def locate(
        self,
        east_m: float,
        north_m: float,
        hint_s_m: float | None = None,
        window_m: float = 3000.0,
    ) -> tuple[float, float]:
        """Find the route point closest to a position.

        Parameters
        ----------
        east_m, north_m : float
            Position, m (e.g. a telemetry fix in the route's local frame).
        hint_s_m : float, optional
            Where the vehicle was last located along the path, m. With a hint only the samples
            within ``+-window_m`` of it are searched (so a route that comes back near itself
            is not confused), unless the best point there is farther than ``window_m / 2``;
            then, and without a hint, the whole route is searched.
        window_m : float, optional
            Half-width of the search window, m (> 0), default 3000 m.

        Returns
        -------
        tuple[float, float]
            ``(s_m, cross_track_m)``: along-path distance of the closest point, m, in
            ``[0, length_m]`` (projected onto the chord between samples), and the distance from
            the position to it, m (>= 0, unsigned).
        """
        east_m = require_finite("east_m", east_m)
        north_m = require_finite("north_m", north_m)
        n_chords = self._chord_s_m.size
        if n_chords == 0:
            return 0.0, math.hypot(east_m - self._east_m[0], north_m - self._north_m[0])
        if hint_s_m is not None and math.isfinite(hint_s_m):
            if not (math.isfinite(window_m) and window_m > 0.0):
                raise ArrivalInputError(f"window_m must be finite and > 0, got {window_m!r}")
            # bisect on the samples' list: np.searchsorted's, without numpy's call overhead.
            first = bisect.bisect_right(self._s_list, hint_s_m - window_m) - 1
            last = bisect.bisect_left(self._s_list, hint_s_m + window_m)
            first = min(max(first, 0), n_chords - 1)
            last = min(max(last, first + 1), n_chords)
            s_m, distance_m = self._closest(east_m, north_m, first, last)
            if distance_m <= 0.5 * window_m:
                return s_m, distance_m
        return self._closest(east_m, north_m, 0, n_chords)

    def _closest(self, east_m: float, north_m: float, first: int, last: int) -> tuple[float, float]:
        """Closest point on chords ``first..last-1``: (s_m, distance_m); the earliest on ties."""
        # The projection's arithmetic in place, in the order it was written out before:
        # t = clip((de ce + dn cn) / |c|^2, 0, 1), off = d - t c, then the least |off|^2
        # (a window of some 240 chords at every fix: the temporaries cost more than the sums).
        de = east_m - self._east_m[first:last]
        dn = north_m - self._north_m[first:last]
        ce = self._chord_east_m[first:last]
        cn = self._chord_north_m[first:last]
        t = de * ce
        tmp = dn * cn
        t += tmp
        t *= self._chord_inv2[first:last]
        np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)  # np.clip's values
        de -= np.multiply(t, ce, out=tmp)
        dn -= np.multiply(t, cn, out=tmp)
        de *= de
        dn *= dn
        de += dn
        best = first + int(de.argmin())
        # Chords cut the corner of arcs, so the best chord's neighbour may hold the closest
        # point of the route itself: measure all three exactly.
        candidates = range(max(best - 1, 0), min(best + 2, self._chord_s_m.size))
        distance_m, s_m = min([self._exact(east_m, north_m, index) for index in candidates])
        return min(s_m, self._length_m), distance_m

    def _exact(self, east_m: float, north_m: float, index: int) -> tuple[float, float]:
        """(distance_m, s_m) of the route point closest to a position within chord ``index``."""
        (
            sample_east_m, sample_north_m,
            sign, centre_east_m, centre_north_m, radius_m, start_m, length_m,
            ce, cn, inv2, sample_s_m, chord_s_m,
        ) = self._chord_rows[index]  # fmt: skip
        if sign:
            # On an arc, measure the angle swept from the chord's first sample around the
            # centre: exact, where the chord projection errs by ~chord * offset / radius.
            de_m, dn_m = east_m - centre_east_m, north_m - centre_north_m
            from_centre_m = math.hypot(de_m, dn_m)
            if from_centre_m > 0.0:
                point_rad = math.atan2(de_m, dn_m)
                sample_rad = math.atan2(
                    sample_east_m - centre_east_m, sample_north_m - centre_north_m
                )
                swept_rad = (sign * (point_rad - sample_rad) + math.pi) % TAU - math.pi
                s_m = sample_s_m + swept_rad * radius_m
                if start_m <= s_m <= start_m + length_m:
                    return abs(from_centre_m - radius_m), s_m
        de_m, dn_m = east_m - sample_east_m, north_m - sample_north_m
        t = min(max((de_m * ce + dn_m * cn) * inv2, 0.0), 1.0)
        s_m = sample_s_m + t * chord_s_m
        return math.hypot(de_m - t * ce, dn_m - t * cn), s_m

    def flight_samples(self, loiters_done: int = 0) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The flight still to come as one polyline: ``(along_m, east_m, north_m)`` of the
        route's samples with the turns of every loiter from ``loiters_done`` on spliced in
        where the route reaches it (every 5 degrees, from where the route meets the circle,
        the loiter's way round; a detour as a stop at that point for its length).

        ``along_m`` is the distance flown along it: the route's own ``s_m`` up to the first
        of those loiters (a vehicle on its route before it is at its ``s_m``), then that
        plus the loiters' lengths; a vehicle in loiter ``loiters_done`` that has flown
        ``f`` m of it is at the loiter's ``s_m + f``."""
        along_m, east_m, north_m, _ = self._flight(loiters_done)
        return along_m, east_m, north_m

    def flight_route_s_m(self, loiters_done: int = 0) -> FloatArray:
        """Where along the route (its own ``s_m``) each sample of :meth:`flight_samples`
        lies: a loiter's turns at the loiter's ``s_m`` (its height is the loiter's)."""
        return self._flight(loiters_done)[3]

    def _flight(self, loiters_done: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        loiters = self.loiters[max(loiters_done, 0) :]
        if not loiters:
            return self._s_m, self._east_m, self._north_m, self._s_m
        key = len(loiters)
        if key not in self._flight_cache:  # asked at every conflict check: built once
            self._flight_cache[key] = self._splice(loiters)
        return self._flight_cache[key]

    def _splice(
        self, loiters: Sequence[LoiterSpec]
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        along, east, north, route = [], [], [], []
        shift_m, done = 0.0, 0
        for loiter in loiters:
            at_m = min(max(loiter.s_m, 0.0), self._length_m)
            k = int(np.searchsorted(self._s_m, at_m, side="right"))
            along.append(self._s_m[done:k] + shift_m)
            east.append(self._east_m[done:k])
            north.append(self._north_m[done:k])
            route.append(self._s_m[done:k])
            done = k
            entry = self.path.pose_at(at_m)
            bearing = math.atan2(
                entry.east_m - loiter.centre_east_m, entry.north_m - loiter.centre_north_m
            )
            sign = 1.0 if loiter.clockwise else -1.0
            n = max(1, math.ceil(loiter.circle_m / (ARC_PIECE_RAD * loiter.radius_m)))
            u = np.linspace(0.0, loiter.circle_m, n + 1)
            angle = bearing + sign * u / loiter.radius_m
            along.append(at_m + shift_m + np.append(u, loiter.circle_m + loiter.detour_m))
            east.append(
                np.append(loiter.centre_east_m + loiter.radius_m * np.sin(angle), entry.east_m)
            )
            north.append(
                np.append(loiter.centre_north_m + loiter.radius_m * np.cos(angle), entry.north_m)
            )
            route.append(np.full(n + 2, at_m))
            shift_m += loiter.length_m
        along.append(self._s_m[done:] + shift_m)
        east.append(self._east_m[done:])
        north.append(self._north_m[done:])
        route.append(self._s_m[done:])
        return (
            np.concatenate(along),
            np.concatenate(east),
            np.concatenate(north),
            np.concatenate(route),
        )

    def remaining_m(self, s_m: float, loiters_done: int = 0, loiter_flown_m: float = 0.0) -> float:
        """Distance still to fly from ``s_m``, m: the path after it plus the loiters not done."""
        s_m = self._check_s(s_m)
        loiters = self.loiters[max(loiters_done, 0) :]
        loiter_m = math.fsum(loiter.length_m for loiter in loiters)
        if loiters:
            loiter_m -= min(max(loiter_flown_m, 0.0), loiters[0].length_m)
        return self._length_m - s_m + loiter_m

    def time_to_go_s(
        self,
        s_m: float,
        airspeed_m_s: float,
        wind: Wind,
        loiters_done: int = 0,
        loiter_flown_m: float = 0.0,
    ) -> float:
        """Time to fly from ``s_m`` to the end of the route at a constant airspeed in the wind.

        Counts the path after ``s_m`` and every loiter with index >= ``loiters_done`` (those
        still to be flown). A loiter's circle is timed piece by piece (72 per turn, turning the
        loiter's way) with the wind; its detour at airspeed with no wind correction (out and
        back cancel to first order).

        Parameters
        ----------
        s_m : float
            Along-path distance, m, in ``[0, length_m]``.
        airspeed_m_s : float
            Constant true airspeed, m/s.
        wind : Wind
            Air-mass velocity, m/s.
        loiters_done : int, optional
            Number of loiters already flown (the first ones).
        loiter_flown_m : float, optional
            Distance already flown in loiter ``loiters_done`` (the one in progress, circle
            first, then detour), m. An extension of the contract; default 0.

        Returns
        -------
        float
            Time to go, s; ``math.inf`` if some piece cannot be made good (groundspeed 0).
        """
        return self.remaining(s_m, wind, loiters_done, loiter_flown_m).time_s(airspeed_m_s)

    # -- internals ---------------------------------------------------------------------------

    def _check_s(self, s_m: float) -> float:
        s_m = require_finite("s_m", s_m)
        tolerance_m = _S_REL_TOL * max(1.0, self._length_m)
        if not (-tolerance_m <= s_m <= self._length_m + tolerance_m):
            raise ArrivalInputError(f"s_m must be in [0, {self._length_m}] m, got {s_m!r}")
        return min(max(s_m, 0.0), self._length_m)

    def remaining(
        self, s_m: float, wind: Wind, loiters_done: int, loiter_flown_m: float
    ) -> Remaining:
        """The route from ``s_m`` on (and the loiters not yet flown) as constant-track pieces
        in ``wind``."""
        s_m = self._check_s(s_m)
        if loiters_done < 0:
            raise ArrivalInputError(f"loiters_done must be >= 0, got {loiters_done!r}")
        loiter_flown_m = require_finite("loiter_flown_m", loiter_flown_m)
        index = int(np.searchsorted(self._piece_start_m, s_m, side="right")) - 1
        index = min(max(index, 0), self._piece_len_m.size - 1)
        first_m = float(self._piece_end_m[index]) - s_m
        lengths = [self._piece_len_m[index:]]
        sins = [self._piece_sin[index:]]
        coss = [self._piece_cos[index:]]
        still_air_m = 0.0
        for number in range(loiters_done, len(self.loiters)):
            loiter = self.loiters[number]
            starts_m, sin_t, cos_t = self._loiter_pieces[number]
            flown_m = max(loiter_flown_m, 0.0) if number == loiters_done else 0.0
            still_air_m += loiter.detour_m - min(
                max(flown_m - loiter.circle_m, 0.0), loiter.detour_m
            )
            if starts_m.size == 0 or flown_m >= loiter.circle_m:
                continue
            piece_m = loiter.circle_m / starts_m.size
            skip = min(int(flown_m // piece_m), starts_m.size - 1)
            piece_lengths = np.full(starts_m.size - skip, piece_m)
            piece_lengths[0] = starts_m[skip] + piece_m - flown_m
            lengths.append(piece_lengths)
            sins.append(sin_t[skip:])
            coss.append(cos_t[skip:])
        length_m = np.concatenate(lengths) if len(lengths) > 1 else lengths[0].copy()
        length_m[0] = max(first_m, 0.0)
        sin_t = np.concatenate(sins) if len(sins) > 1 else sins[0]
        cos_t = np.concatenate(coss) if len(coss) > 1 else coss[0]
        keep = length_m > 0.0
        if not bool(keep.all()):
            length_m, sin_t, cos_t = length_m[keep], sin_t[keep], cos_t[keep]
        we, wn = wind.to_east_m_s, wind.to_north_m_s
        along = we * sin_t + wn * cos_t
        cross = we * cos_t - wn * sin_t
        return Remaining(length_m, along, cross * cross, still_air_m)


def _advance_array(
    east0: float, north0: float, heading0: float, sign: int, s_m: FloatArray, radius_m: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Positions (m) and compass headings (rad) ``s_m`` along a straight or arc from a pose."""
    if sign == 0:
        return (
            east0 + s_m * math.sin(heading0),
            north0 + s_m * math.cos(heading0),
            np.full(s_m.shape, heading0),
        )
    half_turn_rad = 0.5 * s_m / radius_m
    chord_m = 2.0 * radius_m * np.sin(half_turn_rad)
    chord_heading_rad = heading0 + sign * half_turn_rad
    return (
        east0 + chord_m * np.sin(chord_heading_rad),
        north0 + chord_m * np.cos(chord_heading_rad),
        _wrap_rad(heading0 + 2.0 * sign * half_turn_rad),
    )


# --- the controller -------------------------------------------------------------------------

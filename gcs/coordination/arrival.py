"""The arrival-time controller: sans-IO, pure arithmetic over a planned route.

Eqs. (6)-(7) of the reference paper, closed loop. On each position fix the coordinator asks
:meth:`ArrivalController.decide` which airspeed to fly: the continuous airspeed that arrives
exactly on time (the remaining route, its loiters and the wind, solved for the airspeed), then
clamped to the vehicle's range and quantised to its speed steps, with hysteresis: a level is
held until the required airspeed is a full step away from it. As the time left shrinks the
required airspeed diverges from a wrong level ever faster, so the switching behaves like a
sigma-delta modulator whose arrival error converges to about zero.

Conventions: ``east_m``/``north_m`` in metres, compass angles in radians (0 = north, clockwise
positive, so a unit direction is ``(sin h, cos h)`` in (east, north)), speeds in m/s, times in
seconds on any consistent mission time base. No clock, no I/O: everything is passed in.

:class:`RouteTrack` samples the route once (every ``step_m`` metres for :meth:`RouteTrack.locate`,
and as constant-track pieces, straights whole and arcs every 5 degrees, for the timing) so that
the per-fix work is a few vectorised numpy passes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import NDArray

from gcs.errors import GcsError
from planner.flightpath import FlightPath

__all__ = [
    "ArrivalController",
    "ArrivalInputError",
    "Decision",
    "LoiterSpec",
    "RouteTrack",
    "SpeedLimits",
    "Verdict",
    "Wind",
    "groundspeed_m_s",
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
# The airspeed solve stops when the time to go is this close to the time left (relative), or
# the bracket is this narrow, m/s.
_SOLVE_REL_TOL_S = 1e-9
_SOLVE_BRACKET_M_S = 1e-9
_SOLVE_MAX_ITER = 100
# Speeds closer than this are the same level, m/s.
_SAME_LEVEL_M_S = 1e-9
_TURN_SIGN = {"L": -1, "S": 0, "R": 1}


class ArrivalInputError(GcsError, ValueError):
    """An arrival-controller input that is out of range (limits, loiters, positions)."""


def _finite(name: str, value: float) -> float:
    if not math.isfinite(value):
        raise ArrivalInputError(f"{name} must be finite, got {value!r}")
    return float(value)


# --- wind and groundspeed -------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Wind:
    """Velocity of the air mass over the ground, m/s: the direction it blows TO."""

    to_east_m_s: float = 0.0
    to_north_m_s: float = 0.0

    def __post_init__(self) -> None:
        _finite("Wind.to_east_m_s", self.to_east_m_s)
        _finite("Wind.to_north_m_s", self.to_north_m_s)

    @classmethod
    def from_speed_from(cls, speed_m_s: float, from_deg: float) -> Wind:
        """Build a wind from the meteorological convention.

        Parameters
        ----------
        speed_m_s : float
            Wind speed, m/s (>= 0).
        from_deg : float
            Compass direction the wind blows FROM, degrees (270 = a westerly, blowing east).

        Returns
        -------
        Wind
            The air-mass velocity (blowing TO ``from_deg + 180``).
        """
        if not (math.isfinite(speed_m_s) and speed_m_s >= 0.0):
            raise ArrivalInputError(f"speed_m_s must be finite and >= 0, got {speed_m_s!r}")
        from_rad = math.radians(_finite("from_deg", from_deg))
        return cls(-speed_m_s * math.sin(from_rad), -speed_m_s * math.cos(from_rad))

    @property
    def speed_m_s(self) -> float:
        """Wind speed, m/s."""
        return math.hypot(self.to_east_m_s, self.to_north_m_s)


@overload
def groundspeed_m_s(airspeed_m_s: float, track_rad: float, wind: Wind) -> float: ...


@overload
def groundspeed_m_s(airspeed_m_s: float, track_rad: AnyFloatArray, wind: Wind) -> FloatArray: ...


def groundspeed_m_s(
    airspeed_m_s: float, track_rad: float | AnyFloatArray, wind: Wind
) -> float | FloatArray:
    """Speed made good along a ground track when flying an airspeed crabbed into the wind.

    ``g = w_along + sqrt(a**2 - w_cross**2)``, where ``w_along``/``w_cross`` are the wind's
    components along and across the track.

    Parameters
    ----------
    airspeed_m_s : float
        True airspeed, m/s (>= 0).
    track_rad : float or NDArray
        Compass ground track(s), rad.
    wind : Wind
        Air-mass velocity, m/s.

    Returns
    -------
    float or NDArray
        Groundspeed along each track, m/s; 0.0 where the track cannot be made good
        (``a**2 < w_cross**2`` or ``g <= 0``). A float for a float track.
    """
    tracks = np.asarray(track_rad, dtype=np.float64)
    sin_t, cos_t = np.sin(tracks), np.cos(tracks)
    along = wind.to_east_m_s * sin_t + wind.to_north_m_s * cos_t
    cross = wind.to_east_m_s * cos_t - wind.to_north_m_s * sin_t
    disc = airspeed_m_s * airspeed_m_s - cross * cross
    speed = along + np.sqrt(np.maximum(disc, 0.0))
    result: FloatArray = np.where((disc >= 0.0) & (speed > 0.0), speed, 0.0)
    if isinstance(track_rad, np.ndarray):
        return result
    return float(result)


# --- the route ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class LoiterSpec:
    """A loiter flown where the route reaches ``s_m``: whole turns plus an optional detour.

    ``s_m`` is the along-path distance (m) of the path point where the loiter is entered; the
    circle (``centre_east_m``, ``centre_north_m``, ``radius_m`` in m) is flown ``turns`` times,
    clockwise or not, then ``detour_m`` of straight out-and-back, at the same airspeed.
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
            _finite(f"LoiterSpec.{name}", getattr(self, name))
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
class _Remaining:
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
        east_m = _finite("east_m", east_m)
        north_m = _finite("north_m", north_m)
        n_chords = self._chord_s_m.size
        if n_chords == 0:
            return 0.0, math.hypot(east_m - self._east_m[0], north_m - self._north_m[0])
        if hint_s_m is not None and math.isfinite(hint_s_m):
            if not (math.isfinite(window_m) and window_m > 0.0):
                raise ArrivalInputError(f"window_m must be finite and > 0, got {window_m!r}")
            first = int(np.searchsorted(self._s_m, hint_s_m - window_m, side="right")) - 1
            last = int(np.searchsorted(self._s_m, hint_s_m + window_m, side="left"))
            first = min(max(first, 0), n_chords - 1)
            last = min(max(last, first + 1), n_chords)
            s_m, distance_m = self._closest(east_m, north_m, first, last)
            if distance_m <= 0.5 * window_m:
                return s_m, distance_m
        return self._closest(east_m, north_m, 0, n_chords)

    def _closest(self, east_m: float, north_m: float, first: int, last: int) -> tuple[float, float]:
        """Closest point on chords ``first..last-1``: (s_m, distance_m); the earliest on ties."""
        de = east_m - self._east_m[first:last]
        dn = north_m - self._north_m[first:last]
        ce = self._chord_east_m[first:last]
        cn = self._chord_north_m[first:last]
        t = np.clip((de * ce + dn * cn) * self._chord_inv2[first:last], 0.0, 1.0)
        off_e = de - t * ce
        off_n = dn - t * cn
        best = first + int(np.argmin(off_e * off_e + off_n * off_n))
        # Chords cut the corner of arcs, so the best chord's neighbour may hold the closest
        # point of the route itself: measure all three exactly.
        candidates = range(max(best - 1, 0), min(best + 2, self._chord_s_m.size))
        distance_m, s_m = min(self._exact(east_m, north_m, index) for index in candidates)
        return min(s_m, self._length_m), distance_m

    def _exact(self, east_m: float, north_m: float, index: int) -> tuple[float, float]:
        """(distance_m, s_m) of the route point closest to a position within chord ``index``."""
        sample_east_m = float(self._east_m[index])
        sample_north_m = float(self._north_m[index])
        sign, centre_east_m, centre_north_m, radius_m, start_m, length_m = self._chord_arc[
            index
        ].tolist()
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
                s_m = float(self._s_m[index]) + swept_rad * radius_m
                if start_m <= s_m <= start_m + length_m:
                    return abs(from_centre_m - radius_m), s_m
        ce, cn = float(self._chord_east_m[index]), float(self._chord_north_m[index])
        de_m, dn_m = east_m - sample_east_m, north_m - sample_north_m
        t = min(max((de_m * ce + dn_m * cn) * float(self._chord_inv2[index]), 0.0), 1.0)
        s_m = float(self._s_m[index]) + t * float(self._chord_s_m[index])
        return math.hypot(de_m - t * ce, dn_m - t * cn), s_m

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
        return self._remaining(s_m, wind, loiters_done, loiter_flown_m).time_s(airspeed_m_s)

    # -- internals ---------------------------------------------------------------------------

    def _check_s(self, s_m: float) -> float:
        s_m = _finite("s_m", s_m)
        tolerance_m = _S_REL_TOL * max(1.0, self._length_m)
        if not (-tolerance_m <= s_m <= self._length_m + tolerance_m):
            raise ArrivalInputError(f"s_m must be in [0, {self._length_m}] m, got {s_m!r}")
        return min(max(s_m, 0.0), self._length_m)

    def _remaining(
        self, s_m: float, wind: Wind, loiters_done: int, loiter_flown_m: float
    ) -> _Remaining:
        s_m = self._check_s(s_m)
        if loiters_done < 0:
            raise ArrivalInputError(f"loiters_done must be >= 0, got {loiters_done!r}")
        loiter_flown_m = _finite("loiter_flown_m", loiter_flown_m)
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
        return _Remaining(length_m, along, cross * cross, still_air_m)


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


@dataclass(frozen=True, slots=True)
class SpeedLimits:
    """A vehicle's airspeed range and command step, m/s.

    The levels are ``min, min + step, min + 2 step, ...`` up to ``max``, and ``max`` itself
    (always a level, even when it is not on the step grid).
    """

    airspeed_min_m_s: float
    airspeed_max_m_s: float
    step_m_s: float = 0.5
    _levels: tuple[float, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        lo, hi, step = self.airspeed_min_m_s, self.airspeed_max_m_s, self.step_m_s
        if not (math.isfinite(lo) and lo > 0.0):
            raise ArrivalInputError(f"airspeed_min_m_s must be finite and > 0, got {lo!r}")
        if not (math.isfinite(hi) and hi >= lo):
            raise ArrivalInputError(
                f"airspeed_max_m_s must be finite and >= airspeed_min_m_s={lo!r}, got {hi!r}"
            )
        if not (math.isfinite(step) and step > 0.0):
            raise ArrivalInputError(f"step_m_s must be finite and > 0, got {step!r}")
        lo, hi, step = float(lo), float(hi), float(step)
        object.__setattr__(self, "airspeed_min_m_s", lo)
        object.__setattr__(self, "airspeed_max_m_s", hi)
        object.__setattr__(self, "step_m_s", step)
        n_steps = math.floor((hi - lo) / step + 1e-9)
        levels = [min(lo + k * step, hi) for k in range(n_steps + 1)]
        if hi - levels[-1] > _SAME_LEVEL_M_S:
            levels.append(hi)
        else:
            levels[-1] = hi
        object.__setattr__(self, "_levels", tuple(levels))

    @property
    def levels_m_s(self) -> tuple[float, ...]:
        """Every level that may be commanded, ascending, m/s."""
        return self._levels

    def nearest_level_m_s(self, airspeed_m_s: float) -> float:
        """The level nearest to an airspeed (clamped to the range; ties go up), m/s."""
        lo, hi, step = self.airspeed_min_m_s, self.airspeed_max_m_s, self.step_m_s
        if not airspeed_m_s > lo:  # also nan
            return lo
        if airspeed_m_s >= hi:
            return hi
        k = min(math.floor((airspeed_m_s - lo) / step + 0.5), len(self._levels) - 1)
        candidates = self._levels[max(k - 1, 0) : k + 2]
        return min(candidates, key=lambda level: (abs(level - airspeed_m_s), -level))


Verdict = Literal["on_time", "early", "late"]


@dataclass(frozen=True, slots=True)
class Decision:
    """One decision of the arrival controller (speeds m/s, times s on the caller's base).

    ``verdict``: ``"early"`` when even at the minimum airspeed (held) the vehicle arrives more
    than the tolerance early, ``"late"`` when even at the maximum it arrives more than the
    tolerance late, else ``"on_time"``. ``command_m_s`` is the level to command now, or None
    to keep what the vehicle flies; ``level_m_s`` is what it should fly after this decision.
    ``required_m_s`` is the continuous airspeed that arrives exactly on time (may be outside
    the limits; inf if unreachable). ``eta_s`` is the arrival flying ``level_m_s``,
    ``eta_min_s`` at the maximum airspeed, ``eta_max_s`` at the minimum; ``error_s`` is
    ``eta_s - target_s``. ``reason`` is one sentence with the numbers.
    """

    verdict: Verdict
    command_m_s: float | None
    level_m_s: float
    required_m_s: float
    eta_s: float
    eta_min_s: float
    eta_max_s: float
    error_s: float
    reason: str


def _solve_airspeed(
    remaining: _Remaining, time_left_s: float, lo_m_s: float, hi_m_s: float
) -> float:
    """Airspeed (m/s) whose time to go equals ``time_left_s``, searched in [lo, hi].

    inf if even ``hi`` is too slow; ``lo`` if even ``lo`` is fast enough. Newton's method on
    ``1 / time`` (exactly linear in airspeed in still air, so one step there), safeguarded by
    bisection of the bracket.
    """
    time_hi_s = remaining.time_s(hi_m_s)
    if not time_hi_s <= time_left_s:
        return math.inf
    time_lo_s = remaining.time_s(lo_m_s)
    if time_lo_s <= time_left_s:
        return lo_m_s
    # Now time(lo) > time_left >= time(hi) >= 0, so time_left > 0 and time(hi) > 0.
    rate_lo, rate_hi = 1.0 / time_lo_s, 1.0 / time_hi_s  # 1/inf = 0 where lo cannot fly
    goal = 1.0 / time_left_s
    airspeed = lo_m_s + (goal - rate_lo) * (hi_m_s - lo_m_s) / (rate_hi - rate_lo)
    for _ in range(_SOLVE_MAX_ITER):
        if not lo_m_s < airspeed < hi_m_s:
            airspeed = 0.5 * (lo_m_s + hi_m_s)
        time_s, d_time = remaining.time_and_slope(airspeed)
        if abs(time_s - time_left_s) <= _SOLVE_REL_TOL_S * time_left_s:
            return airspeed
        if time_s > time_left_s:
            lo_m_s = airspeed
        else:
            hi_m_s = airspeed
        if hi_m_s - lo_m_s <= _SOLVE_BRACKET_M_S:
            break
        if math.isfinite(time_s) and math.isfinite(d_time) and d_time < 0.0:
            airspeed -= time_s * (time_s - time_left_s) / (time_left_s * d_time)
        else:
            airspeed = 0.5 * (lo_m_s + hi_m_s)
    return 0.5 * (lo_m_s + hi_m_s)


def _same(a_m_s: float, b_m_s: float) -> bool:
    return abs(a_m_s - b_m_s) <= _SAME_LEVEL_M_S


class ArrivalController:
    """Eqs. (6)-(7) of the reference paper, closed loop.

    Required airspeed = what flies the remaining route in the time left (solved with the
    wind), clamped to the range, quantised to the step grid, and held until it is a full step
    off.

    Parameters
    ----------
    limits : SpeedLimits
        Airspeed range and step, m/s.
    tolerance_s : float, optional
        Arrival error (s, >= 0) within which the vehicle still counts as on time when the
        range cannot do better. Default 0.5 s.
    """

    def __init__(self, limits: SpeedLimits, *, tolerance_s: float = 0.5) -> None:
        if not (math.isfinite(tolerance_s) and tolerance_s >= 0.0):
            raise ArrivalInputError(f"tolerance_s must be finite and >= 0, got {tolerance_s!r}")
        self.limits = limits
        self.tolerance_s = float(tolerance_s)

    def decide(
        self,
        track: RouteTrack,
        *,
        s_m: float,
        now_s: float,
        target_s: float,
        wind: Wind,
        current_level_m_s: float | None,
        loiters_done: int = 0,
        loiter_flown_m: float = 0.0,
        tas_per_eas: float = 1.0,
    ) -> Decision:
        """Decide the airspeed level to fly from a position fix.

        Parameters
        ----------
        track : RouteTrack
            The vehicle's route and loiters.
        s_m : float
            Where the vehicle is along the path, m (e.g. from :meth:`RouteTrack.locate`).
        now_s, target_s : float
            The time of the fix and the required arrival, s (same time base).
        wind : Wind
            Air-mass velocity, m/s.
        current_level_m_s : float, optional
            The level the vehicle was last commanded (or flies), m/s; None if unknown. A
            level outside the limits counts as unknown (it is always replaced).
        loiters_done : int, optional
            Number of loiters already flown.
        loiter_flown_m : float, optional
            Distance already flown in the loiter in progress, m (extension; default 0).
        tas_per_eas : float, optional
            True airspeed flown per unit of commanded airspeed (> 0): the limits, levels and
            commands are the autopilot's (equivalent airspeed on ArduPlane), the route is
            flown at this many times that (the atmosphere's EAS2TAS, times any bias learnt
            in flight). Default 1: commands are true airspeed.

        Returns
        -------
        Decision
            Verdict, command (or None), level, required airspeed, ETAs (s) and the reason.
        """
        limits = self.limits
        lo, hi, step = limits.airspeed_min_m_s, limits.airspeed_max_m_s, limits.step_m_s
        now_s = _finite("now_s", now_s)
        target_s = _finite("target_s", target_s)
        if not (math.isfinite(tas_per_eas) and tas_per_eas > 0.0):
            raise ArrivalInputError(f"tas_per_eas must be finite and > 0, got {tas_per_eas!r}")
        remaining = replace(
            track._remaining(s_m, wind, loiters_done, loiter_flown_m), tas_per_eas=tas_per_eas
        )
        time_left_s = target_s - now_s
        times: dict[float, float] = {}

        def eta_at(airspeed_m_s: float) -> float:
            if airspeed_m_s not in times:
                times[airspeed_m_s] = remaining.time_s(airspeed_m_s)
            return now_s + times[airspeed_m_s]

        required = _solve_airspeed(remaining, time_left_s, 0.5 * lo, 2.0 * hi)
        eta_min_s, eta_max_s = eta_at(hi), eta_at(lo)
        current = current_level_m_s
        if current is not None and not (
            math.isfinite(current) and lo - _SAME_LEVEL_M_S <= current <= hi + _SAME_LEVEL_M_S
        ):
            current = None
        over = f"over {remaining.total_m / 1000.0:.1f} km in {time_left_s:.1f} s"
        if math.isinf(required):
            ask = f"no airspeed up to {2.0 * hi:.1f} m/s arrives on time {over}"
        elif required <= 0.5 * lo:
            ask = f"required at most {required:.2f} m/s airspeed {over}"
        else:
            ask = f"required {required:.2f} m/s airspeed {over}"
        verdict: Verdict = "on_time"
        if required > hi:
            level = hi
            late_s = eta_min_s - target_s
            if late_s > self.tolerance_s:
                verdict = "late"
            reason = (
                f"{ask}: above the {hi:.1f} m/s maximum; at {hi:.1f} m/s arrives "
                f"{late_s:.1f} s late"
            )
        elif required < lo:
            level = lo
            early_s = target_s - eta_max_s
            if early_s > self.tolerance_s:
                verdict = "early"
            reason = (
                f"{ask}: below the {lo:.1f} m/s minimum; at {lo:.1f} m/s arrives "
                f"{early_s:.1f} s early"
            )
        elif current is None or abs(required - current) >= step:
            level = limits.nearest_level_m_s(required)
            reason = f"{ask}: the nearest level is {level:.1f} m/s"
        else:
            level = current
            reason = f"{ask}: within one {step:g} m/s step of {level:.1f} m/s"
        if verdict != "on_time":
            reason = f"{verdict}: {reason}"
        elif required > hi or required < lo:
            reason += f", within the {self.tolerance_s:g} s tolerance"
        command = None if current is not None and _same(level, current) else level
        if command is None and current is not None:
            level = current
        eta_s = eta_at(level)
        error_s = eta_s - target_s
        reason += (
            f"; commanding {level:.1f} m/s" if command is not None else f"; keeping {level:.1f} m/s"
        )
        reason += f", ETA error {error_s:+.2f} s"
        return Decision(
            verdict=verdict,
            command_m_s=command,
            level_m_s=level,
            required_m_s=required,
            eta_s=eta_s,
            eta_min_s=eta_min_s,
            eta_max_s=eta_max_s,
            error_s=error_s,
            reason=reason,
        )

    @staticmethod
    def period_s(time_left_s: float) -> float:
        """How long until the next decision, mission s: ``clamp(time_left / 40, 0.5, 10)``."""
        if not time_left_s > 0.0:  # also nan
            return 0.5
        return min(max(time_left_s / 40.0, 0.5), 10.0)

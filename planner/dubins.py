"""Dubins paths (shortest curvature-bounded paths) for fixed-wing UAVs in the horizontal plane.

Frame and conventions: local horizontal frame in metres, ``east_m`` (x) and ``north_m`` (y).
Headings are compass headings in radians, 0 = north, pi/2 = east, clockwise positive,
normalised to [0, 2*pi). A left turn ``L`` is counter-clockwise seen from above (heading
decreases), a right turn ``R`` clockwise (heading increases), ``S`` is straight.

Each Dubins word has one small function that computes its three segment lengths, in units of
the turn radius, from the end pose expressed in the start pose's local frame (x forward,
y to the left, angle counter-clockwise). Paths are compact values with an exact length and are
sampled only when asked.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.errors import PlannerError

if TYPE_CHECKING:
    from planner.flightpath import Segment

__all__ = [
    "TURN_SIGN",
    "WORDS",
    "DubinsPath",
    "GeometryError",
    "Pose",
    "advance",
    "all_paths",
    "normalise_heading_rad",
    "shortest_path",
]

TAU = 2.0 * math.pi
#: Heading rate sign of each segment kind: +1 right (clockwise), -1 left, 0 straight.
TURN_SIGN: dict[str, int] = {"L": -1, "S": 0, "R": 1}
# Normalised arc lengths this close to 0 or 2*pi are round-off of a zero-length arc: snapping
# them moves the end by at most 1e-10 radius and keeps degenerate words free of sliver arcs.
_ARC_SNAP = 1e-10
# End poses this close to the start (in radii and radians) are the start itself.
_COINCIDENT = 1e-10
# s_m may overshoot [0, length] by this relative amount (round-off) and is then clamped.
_S_REL_TOL = 1e-9


class GeometryError(PlannerError, ValueError):
    """A geometric argument is invalid; the message names the argument."""


def normalise_heading_rad(heading_rad: float) -> float:
    """Return ``heading_rad`` wrapped into [0, 2*pi).

    Parameters
    ----------
    heading_rad : float
        Any finite angle, radians.

    Returns
    -------
    float
        The same direction in [0, 2*pi), radians.
    """
    wrapped = heading_rad % TAU
    # x % TAU rounds to exactly TAU for tiny negative x.
    return 0.0 if wrapped >= TAU else wrapped


def _mod2pi(angle: float) -> float:
    """Wrap to [0, 2*pi) and snap round-off slivers and full circles to a zero-length arc."""
    wrapped = normalise_heading_rad(angle)
    return 0.0 if wrapped < _ARC_SNAP or wrapped > TAU - _ARC_SNAP else wrapped


@dataclass(frozen=True, slots=True)
class Pose:
    """A horizontal position and compass heading. The heading is normalised to [0, 2*pi)."""

    east_m: float
    north_m: float
    heading_rad: float

    def __post_init__(self) -> None:
        for name in ("east_m", "north_m", "heading_rad"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise GeometryError(f"Pose.{name} must be finite, got {value!r}")
            object.__setattr__(self, name, float(value))
        object.__setattr__(self, "heading_rad", normalise_heading_rad(self.heading_rad))


def advance(pose: Pose, turn: str, s_m: float, radius_m: float) -> Pose:
    """Return the pose reached after flying ``s_m`` metres of one segment kind from ``pose``.

    Parameters
    ----------
    pose : Pose
        Start pose (m, m, rad).
    turn : str
        ``"S"``, ``"L"`` or ``"R"``.
    s_m : float
        Distance flown along the segment, m (>= 0; not checked, this is the inner loop).
    radius_m : float
        Turn radius, m; ignored for ``"S"``.

    Returns
    -------
    Pose
        The pose after ``s_m`` metres.
    """
    east_m, north_m, heading_rad = _advance(
        pose.east_m, pose.north_m, pose.heading_rad, TURN_SIGN[turn], s_m, radius_m
    )
    return Pose(east_m, north_m, heading_rad)


def _advance(
    east_m: float, north_m: float, heading_rad: float, sign: int, s_m: float, radius_m: float
) -> tuple[float, float, float]:
    """Scalar pose propagation; arcs use the chord form, exact and stable for small s."""
    if sign == 0:
        return (
            east_m + s_m * math.sin(heading_rad),
            north_m + s_m * math.cos(heading_rad),
            heading_rad,
        )
    half_turn_rad = 0.5 * s_m / radius_m
    chord_m = 2.0 * radius_m * math.sin(half_turn_rad)
    chord_heading_rad = heading_rad + sign * half_turn_rad
    return (
        east_m + chord_m * math.sin(chord_heading_rad),
        north_m + chord_m * math.cos(chord_heading_rad),
        normalise_heading_rad(heading_rad + 2.0 * sign * half_turn_rad),
    )


def _advance_array(
    east_m: float,
    north_m: float,
    heading_rad: float,
    sign: int,
    s_m: NDArray[np.float64],
    radius_m: float,
) -> NDArray[np.float64]:
    """Vectorised :func:`_advance` over distances ``s_m``; returns (len(s_m), 3)."""
    if sign != 0:
        return _advance_arcs(east_m, north_m, heading_rad, sign, s_m, radius_m)
    out = np.empty((s_m.size, 3), dtype=np.float64)
    out[:, 0] = east_m + s_m * math.sin(heading_rad)
    out[:, 1] = north_m + s_m * math.cos(heading_rad)
    out[:, 2] = heading_rad
    return out


def _advance_arcs(
    east_m: float | NDArray[np.float64],
    north_m: float | NDArray[np.float64],
    heading_rad: float | NDArray[np.float64],
    sign: float | NDArray[np.float64],
    s_m: NDArray[np.float64],
    radius_m: float | NDArray[np.float64],
) -> NDArray[np.float64]:
    """:func:`_advance` along arcs over distances ``s_m``, each other argument one value or
    one per distance (each row its own start, turn and radius); (len(s_m), 3) poses.

    The operations are those of the scalar version in the same order, so the two agree
    exactly; numpy's float64 sin and cos round as the C library's do.
    """
    out = np.empty((s_m.size, 3), dtype=np.float64)
    half_turn_rad = 0.5 * s_m / radius_m
    chord_m = 2.0 * radius_m * np.sin(half_turn_rad)
    chord_heading_rad = heading_rad + sign * half_turn_rad
    out[:, 0] = east_m + chord_m * np.sin(chord_heading_rad)
    out[:, 1] = north_m + chord_m * np.cos(chord_heading_rad)
    heading = np.mod(heading_rad + 2.0 * sign * half_turn_rad, TAU)
    out[:, 2] = np.where(heading >= TAU, 0.0, heading)
    return out


def _sample_pieces(
    pieces: Sequence[tuple[Pose, int, float, float]], step_m: float, max_arc_step_rad: float
) -> NDArray[np.float64]:
    """Sample consecutive pieces ``(start, sign, length_m, radius_m)``; both ends included.

    Every piece is split evenly so that consecutive samples are at most ``step_m`` apart along
    the path and, on arcs, at most ``max_arc_step_rad`` of heading apart. Piece joints appear
    once.
    """
    if not (math.isfinite(step_m) and step_m > 0.0):
        raise GeometryError(f"step_m must be finite and > 0, got {step_m!r}")
    if not (math.isfinite(max_arc_step_rad) and max_arc_step_rad > 0.0):
        raise GeometryError(f"max_arc_step_rad must be finite and > 0, got {max_arc_step_rad!r}")
    chunks: list[NDArray[np.float64]] = []
    for start, sign, length_m, radius_m in pieces:
        n_steps = max(1, math.ceil(length_m / step_m))
        if sign != 0:
            n_steps = max(n_steps, math.ceil(length_m / radius_m / max_arc_step_rad))
        # The last point of each piece is the first of the next one: leave it out here.
        s_m = np.linspace(0.0, length_m, n_steps + 1)[:-1]
        chunks.append(
            _advance_array(start.east_m, start.north_m, start.heading_rad, sign, s_m, radius_m)
        )
    last_start, last_sign, last_length_m, last_radius_m = pieces[-1]
    end = _advance(
        last_start.east_m,
        last_start.north_m,
        last_start.heading_rad,
        last_sign,
        last_length_m,
        last_radius_m,
    )
    chunks.append(np.array([end], dtype=np.float64))
    return np.concatenate(chunks)


# --- Dubins words -------------------------------------------------------------------------
# Each word function takes the end pose in the start pose's local frame, scaled by the radius:
# start at the origin heading along +x, end at (x, y) with heading theta measured
# counter-clockwise from +x. It returns the three segment lengths in radii (arc lengths are
# turn angles), or None when the word cannot reach the end pose.
#
# Circle centres: start left (0, 1), start right (0, -1); end left (x - sin th, y + cos th),
# end right (x + sin th, y - cos th). Headings below are counter-clockwise angles in the local
# frame, so a left arc from h1 to h2 has length mod2pi(h2 - h1), a right arc mod2pi(h1 - h2).

_Lengths = tuple[float, float, float]


def _lsl(x: float, y: float, theta: float) -> _Lengths | None:
    dx, dy = x - math.sin(theta), y + math.cos(theta) - 1.0
    straight_heading = math.atan2(dy, dx)
    return (_mod2pi(straight_heading), math.hypot(dx, dy), _mod2pi(theta - straight_heading))


def _rsr(x: float, y: float, theta: float) -> _Lengths | None:
    dx, dy = x + math.sin(theta), y - math.cos(theta) + 1.0
    straight_heading = math.atan2(dy, dx)
    return (_mod2pi(-straight_heading), math.hypot(dx, dy), _mod2pi(straight_heading - theta))


def _lsr(x: float, y: float, theta: float) -> _Lengths | None:
    # Inner tangent from the start-left to the end-right circle: centres 2 radii apart across
    # the straight, so the centre-to-centre vector is (p, -2) in the straight's frame.
    dx, dy = x + math.sin(theta), y - math.cos(theta) - 1.0
    squared = dx * dx + dy * dy - 4.0
    if squared < 0.0:
        return None
    straight = math.sqrt(squared)
    straight_heading = math.atan2(dy, dx) + math.atan2(2.0, straight)
    return (_mod2pi(straight_heading), straight, _mod2pi(straight_heading - theta))


def _rsl(x: float, y: float, theta: float) -> _Lengths | None:
    # Centre-to-centre vector is (p, +2) in the straight's frame.
    dx, dy = x - math.sin(theta), y + math.cos(theta) + 1.0
    squared = dx * dx + dy * dy - 4.0
    if squared < 0.0:
        return None
    straight = math.sqrt(squared)
    straight_heading = math.atan2(dy, dx) - math.atan2(2.0, straight)
    return (_mod2pi(-straight_heading), straight, _mod2pi(theta - straight_heading))


def _ccc(
    first: tuple[float, float], last: tuple[float, float], theta: float, middle_sign: int
) -> _Lengths | None:
    """Three arcs: outer circles ``first``/``last`` turn one way, the middle one the other.

    ``middle_sign`` is -1 for a left middle arc (RLR) and +1 for a right one (LRL). The middle
    circle touches both outer circles, two radii from each; of its two possible places the one
    giving the shorter path is kept.
    """
    dx, dy = last[0] - first[0], last[1] - first[1]
    distance = math.hypot(dx, dy)
    if distance > 4.0:
        return None
    centre_heading = math.atan2(dy, dx)
    spread = math.acos(min(1.0, distance / 4.0))
    best: _Lengths | None = None
    for side in (1.0, -1.0):
        to_middle = centre_heading + side * spread
        mx, my = first[0] + 2.0 * math.cos(to_middle), first[1] + 2.0 * math.sin(to_middle)
        from_middle = math.atan2(last[1] - my, last[0] - mx)
        if middle_sign < 0:  # RLR: right, left, right
            h1 = to_middle - 0.5 * math.pi
            h2 = from_middle + 0.5 * math.pi
            lengths = (_mod2pi(-h1), _mod2pi(h2 - h1), _mod2pi(h2 - theta))
        else:  # LRL: left, right, left
            h1 = to_middle + 0.5 * math.pi
            h2 = from_middle - 0.5 * math.pi
            lengths = (_mod2pi(h1), _mod2pi(h1 - h2), _mod2pi(theta - h2))
        if best is None or sum(lengths) < sum(best):
            best = lengths
    return best


def _rlr(x: float, y: float, theta: float) -> _Lengths | None:
    return _ccc((0.0, -1.0), (x + math.sin(theta), y - math.cos(theta)), theta, -1)


def _lrl(x: float, y: float, theta: float) -> _Lengths | None:
    return _ccc((0.0, 1.0), (x - math.sin(theta), y + math.cos(theta)), theta, 1)


#: The six Dubins words and their length functions (local frame, lengths in radii).
WORDS: dict[str, Callable[[float, float, float], _Lengths | None]] = {
    "LSL": _lsl,
    "LSR": _lsr,
    "RSL": _rsl,
    "RSR": _rsr,
    "RLR": _rlr,
    "LRL": _lrl,
}


@dataclass(frozen=True, slots=True)
class DubinsPath:
    """A Dubins path: a start pose, a word, three segment lengths (m) and the turn radius (m).

    Zero-length segments are allowed (a degenerate word such as a pure arc or straight).
    """

    start: Pose
    word: str
    lengths_m: tuple[float, float, float]
    radius_m: float

    def __post_init__(self) -> None:
        if self.word not in WORDS:
            raise GeometryError(f"word must be one of {sorted(WORDS)}, got {self.word!r}")
        if len(self.lengths_m) != 3 or not all(
            math.isfinite(v) and v >= 0.0 for v in self.lengths_m
        ):
            raise GeometryError(f"lengths_m must be three finite values >= 0, got {self.lengths_m}")
        if not (math.isfinite(self.radius_m) and self.radius_m > 0.0):
            raise GeometryError(f"radius_m must be finite and > 0, got {self.radius_m!r}")

    @property
    def length_m(self) -> float:
        """Total length, m (exactly rounded sum of the segment lengths)."""
        return math.fsum(self.lengths_m)

    @property
    def end(self) -> Pose:
        """The pose at the end of the path."""
        east_m, north_m, heading_rad = self.start.east_m, self.start.north_m, self.start.heading_rad
        for letter, length_m in zip(self.word, self.lengths_m, strict=True):
            east_m, north_m, heading_rad = _advance(
                east_m, north_m, heading_rad, TURN_SIGN[letter], length_m, self.radius_m
            )
        return Pose(east_m, north_m, heading_rad)

    def pose_at(self, s_m: float) -> Pose:
        """Return the pose ``s_m`` metres along the path.

        Parameters
        ----------
        s_m : float
            Along-path distance in [0, length_m], m; round-off overshoot is clamped.

        Returns
        -------
        Pose
            Position (m) and compass heading (rad) at ``s_m``.

        Raises
        ------
        GeometryError
            If ``s_m`` is outside [0, length_m].
        """
        remaining_m = _check_s(s_m, self.length_m)
        east_m, north_m, heading_rad = self.start.east_m, self.start.north_m, self.start.heading_rad
        for letter, length_m in zip(self.word, self.lengths_m, strict=True):
            step_m = min(remaining_m, length_m)
            east_m, north_m, heading_rad = _advance(
                east_m, north_m, heading_rad, TURN_SIGN[letter], step_m, self.radius_m
            )
            remaining_m -= step_m
            if remaining_m <= 0.0:
                break
        return Pose(east_m, north_m, heading_rad)

    def sample(
        self, step_m: float, *, max_arc_step_rad: float = math.radians(5.0)
    ) -> NDArray[np.float64]:
        """Sample the path evenly per segment, both ends included.

        Parameters
        ----------
        step_m : float
            Largest along-path spacing between samples, m (> 0).
        max_arc_step_rad : float, optional
            Largest heading change between samples on arcs, rad (> 0), so plots of tight
            arcs stay round.

        Returns
        -------
        NDArray
            (N, 3) rows ``[east_m, north_m, heading_rad]``, N >= 2.
        """
        pieces: list[tuple[Pose, int, float, float]] = []
        pose = self.start
        for letter, length_m in zip(self.word, self.lengths_m, strict=True):
            if length_m > 0.0 or not pieces:
                pieces.append((pose, TURN_SIGN[letter], length_m, self.radius_m))
            pose = advance(pose, letter, length_m, self.radius_m)
        return _sample_pieces(pieces, step_m, max_arc_step_rad)

    def segments(self) -> tuple[Segment, ...]:
        """Return the non-zero-length segments as :class:`planner.flightpath.Segment` values.

        A zero-length path has no segments.
        """
        from planner.flightpath import Segment  # flightpath imports this module

        out: list[Segment] = []
        pose = self.start
        for letter, length_m in zip(self.word, self.lengths_m, strict=True):
            if length_m > 0.0:
                radius_m = math.inf if letter == "S" else self.radius_m
                segment = Segment(pose, length_m, letter, radius_m)
                out.append(segment)
                pose = segment.end
        return tuple(out)


def _check_s(s_m: float, length_m: float) -> float:
    """Return ``s_m`` clamped to [0, length_m]; raise if it is outside beyond round-off."""
    tolerance_m = _S_REL_TOL * max(1.0, length_m)
    if not (-tolerance_m <= s_m <= length_m + tolerance_m):
        raise GeometryError(f"s_m must be in [0, {length_m}] m, got {s_m!r}")
    return min(max(s_m, 0.0), length_m)


def _check_radius(radius_m: float) -> None:
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise GeometryError(f"radius_m must be finite and > 0, got {radius_m!r}")


def all_paths(start: Pose, end: Pose, radius_m: float) -> list[DubinsPath]:
    """Return the Dubins path of every feasible word from ``start`` to ``end``, shortest first.

    Parameters
    ----------
    start, end : Pose
        Start and end poses (m, m, rad compass).
    radius_m : float
        Minimum turn radius, m (> 0).

    Returns
    -------
    list[DubinsPath]
        Between two and six paths (LSL and RSR always exist), sorted by length; ties keep the
        order of :data:`WORDS`. An ``end`` within 1e-10 radius and 1e-10 rad of ``start`` is
        treated as ``start`` (zero-length LSL and RSR) rather than a full loop away.

    Raises
    ------
    GeometryError
        If ``radius_m`` is not finite and positive.
    """
    _check_radius(radius_m)
    de_m, dn_m = end.east_m - start.east_m, end.north_m - start.north_m
    sin_h, cos_h = math.sin(start.heading_rad), math.cos(start.heading_rad)
    # Start-local frame: x forward, y to the left, angles counter-clockwise, unit = radius.
    x = (de_m * sin_h + dn_m * cos_h) / radius_m
    y = (dn_m * sin_h - de_m * cos_h) / radius_m
    theta = start.heading_rad - end.heading_rad
    if (
        math.hypot(x, y) <= _COINCIDENT
        and abs(normalise_heading_rad(theta + math.pi) - math.pi) <= _COINCIDENT
    ):
        # The Dubins distance jumps from 0 to a full loop next to the start pose; an end pose
        # within round-off of the start is the start, not a loop away.
        x = y = theta = 0.0
    paths: list[DubinsPath] = []
    for word, lengths_fn in WORDS.items():
        lengths = lengths_fn(x, y, theta)
        if lengths is not None:
            lengths_m = (lengths[0] * radius_m, lengths[1] * radius_m, lengths[2] * radius_m)
            paths.append(DubinsPath(start, word, lengths_m, radius_m))
    paths.sort(key=lambda path: path.length_m)
    return paths


def shortest_path(start: Pose, end: Pose, radius_m: float) -> DubinsPath:
    """Return the shortest path from ``start`` to ``end`` turning no tighter than ``radius_m``.

    Parameters
    ----------
    start, end : Pose
        Start and end poses (m, m, rad compass).
    radius_m : float
        Minimum turn radius, m (> 0).

    Returns
    -------
    DubinsPath
        The shortest of :func:`all_paths`.

    Raises
    ------
    GeometryError
        If ``radius_m`` is not finite and positive.
    """
    return all_paths(start, end, radius_m)[0]

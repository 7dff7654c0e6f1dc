"""Tests of planner.dubins: known answers, an independent oracle and geometric invariants."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from planner.dubins import (
    WORDS,
    DubinsPath,
    GeometryError,
    Pose,
    advance,
    all_paths,
    normalise_heading_rad,
    shortest_path,
)
from planner.errors import PlannerError
from planner.flightpath import FlightPath

PI = math.pi
NORTH, EAST, SOUTH, WEST = 0.0, PI / 2, PI, 3 * PI / 2


def heading_diff(a_rad: float, b_rad: float) -> float:
    return abs((a_rad - b_rad + PI) % (2 * PI) - PI)


def scale_of(start: Pose, end: Pose, radius_m: float) -> float:
    return max(
        1.0, radius_m, abs(start.east_m), abs(start.north_m), abs(end.east_m), abs(end.north_m)
    )


def assert_pose_close(actual: Pose, expected: Pose, tol_m: float, tol_rad: float = 1e-6) -> None:
    gap_m = math.hypot(actual.east_m - expected.east_m, actual.north_m - expected.north_m)
    assert gap_m <= tol_m, f"{actual} is {gap_m} m from {expected}"
    assert heading_diff(actual.heading_rad, expected.heading_rad) <= tol_rad, (actual, expected)


# --- Independent oracle: the classic alpha/beta closed forms (Shkel & Lumelsky, LaValle) in
# the mathematical frame (angles counter-clockwise from east), which our compass-frame
# centre-based implementation must agree with on the shortest length.


def _mod(angle: float) -> float:
    wrapped = angle % (2 * PI)
    return 0.0 if wrapped > 2 * PI - 1e-10 else wrapped


def oracle_shortest_length(start: Pose, end: Pose, radius_m: float) -> float:
    dx, dy = end.east_m - start.east_m, end.north_m - start.north_m
    d = math.hypot(dx, dy) / radius_m
    phi = math.atan2(dy, dx)
    a = _mod(PI / 2 - start.heading_rad - phi)
    b = _mod(PI / 2 - end.heading_rad - phi)
    sa, sb, ca, cb, cab = math.sin(a), math.sin(b), math.cos(a), math.cos(b), math.cos(a - b)
    candidates: list[float] = []
    p2 = 2 + d * d - 2 * cab + 2 * d * (sa - sb)  # LSL
    if p2 >= -1e-9:
        tmp = math.atan2(cb - ca, d + sa - sb)
        candidates.append(_mod(-a + tmp) + math.sqrt(max(p2, 0.0)) + _mod(b - tmp))
    p2 = 2 + d * d - 2 * cab + 2 * d * (sb - sa)  # RSR
    if p2 >= -1e-9:
        tmp = math.atan2(ca - cb, d - sa + sb)
        candidates.append(_mod(a - tmp) + math.sqrt(max(p2, 0.0)) + _mod(-b + tmp))
    p2 = -2 + d * d + 2 * cab + 2 * d * (sa + sb)  # LSR
    if p2 >= -1e-9:
        p = math.sqrt(max(p2, 0.0))
        tmp = math.atan2(-ca - cb, d + sa + sb) - math.atan2(-2.0, p)
        candidates.append(_mod(-a + tmp) + p + _mod(-b + tmp))
    p2 = -2 + d * d + 2 * cab - 2 * d * (sa + sb)  # RSL
    if p2 >= -1e-9:
        p = math.sqrt(max(p2, 0.0))
        tmp = math.atan2(ca + cb, d - sa - sb) - math.atan2(2.0, p)
        candidates.append(_mod(a - tmp) + p + _mod(b - tmp))
    tmp = (6 - d * d + 2 * cab + 2 * d * (sa - sb)) / 8  # RLR
    if abs(tmp) <= 1:
        p = _mod(2 * PI - math.acos(tmp))
        t = _mod(a - math.atan2(ca - cb, d - sa + sb) + p / 2)
        candidates.append(t + p + _mod(a - b - t + p))
    tmp = (6 - d * d + 2 * cab + 2 * d * (sb - sa)) / 8  # LRL
    if abs(tmp) <= 1:
        p = _mod(2 * PI - math.acos(tmp))
        t = _mod(-a - math.atan2(ca - cb, d + sa - sb) + p / 2)
        candidates.append(t + p + _mod(b - a - t + p))
    return min(candidates) * radius_m


# --- Known answers --------------------------------------------------------------------------

# (start, end, expected length / r, allowed words, expected turn letters of non-empty segments);
# positions in units of r.
KNOWN = [
    ("straight east", (0, 0, EAST), (4, 0, EAST), 4.0, {"LSL", "RSR", "LSR", "RSL"}, "S"),
    ("left U-turn", (0, 0, EAST), (0, 2, WEST), PI, None, "L"),
    ("right U-turn", (0, 0, EAST), (0, -2, WEST), PI, None, "R"),
    ("right quarter", (0, 0, NORTH), (1, 1, EAST), PI / 2, None, "R"),
    ("left quarter", (0, 0, NORTH), (-1, 1, WEST), PI / 2, None, "L"),
    ("LSL", (0, 0, NORTH), (-5, 0, SOUTH), PI + 3, {"LSL"}, "LSL"),
    ("RSR", (0, 0, NORTH), (5, 0, SOUTH), PI + 3, {"RSR"}, "RSR"),
    ("LSR", (0, 0, NORTH), (-4, 2, NORTH), PI + 2, {"LSR"}, "LSR"),
    ("RSL", (0, 0, NORTH), (4, 2, NORTH), PI + 2, {"RSL"}, "RSL"),
    ("turn back on the spot", (0, 0, NORTH), (0, 0, SOUTH), 7 * PI / 3, {"LRL", "RLR"}, None),
    ("zero length", (3, 4, WEST), (3, 4, WEST), 0.0, None, ""),
]


@pytest.mark.parametrize("radius_m", [1.0, 37.5])
@pytest.mark.parametrize(
    ("name", "start", "end", "length_r", "words", "letters"),
    KNOWN,
    ids=[k[0] for k in KNOWN],
)
def test_known_shortest_paths(
    radius_m: float,
    name: str,
    start: tuple[float, float, float],
    end: tuple[float, float, float],
    length_r: float,
    words: set[str] | None,
    letters: str | None,
) -> None:
    r = radius_m
    start_pose = Pose(start[0] * r, start[1] * r, start[2])
    end_pose = Pose(end[0] * r, end[1] * r, end[2])
    path = shortest_path(start_pose, end_pose, r)
    assert path.length_m == pytest.approx(length_r * r, rel=1e-12, abs=1e-12)
    assert path.length_m == pytest.approx(oracle_shortest_length(start_pose, end_pose, r))
    if words is not None:
        assert path.word in words
    if letters is not None:
        assert "".join(s.turn for s in path.segments()) == letters
    assert_pose_close(path.end, end_pose, 1e-9 * r)


def test_turn_convention_right_is_clockwise_left_is_counter_clockwise() -> None:
    r = 10.0
    right = shortest_path(Pose(0, 0, NORTH), Pose(r, r, EAST), r)
    c45 = math.cos(PI / 4)
    assert_pose_close(right.pose_at(PI * r / 4), Pose(r - r * c45, r * c45, PI / 4), 1e-12)
    left = shortest_path(Pose(0, 0, NORTH), Pose(-r, r, WEST), r)
    assert_pose_close(left.pose_at(PI * r / 4), Pose(-(r - r * c45), r * c45, 7 * PI / 4), 1e-12)


def test_hand_computed_lsl_segment_lengths() -> None:
    r = 20.0
    path = shortest_path(Pose(0, 0, NORTH), Pose(-5 * r, 0, SOUTH), r)
    assert path.word == "LSL"
    assert path.lengths_m == pytest.approx((PI / 2 * r, 3 * r, PI / 2 * r), rel=1e-12)
    # First arc ends one radius west and north of the start, heading west.
    assert_pose_close(path.pose_at(PI / 2 * r), Pose(-r, r, WEST), 1e-12)


def test_end_within_round_off_of_start_is_the_start_but_just_behind_is_a_loop() -> None:
    start = Pose(0.0, 0.0, 1.0)
    assert shortest_path(start, Pose(0.0, 1.1e-14, 1.0), 1.0).length_m == 0.0
    behind = Pose(-1e-3 * math.sin(1.0), -1e-3 * math.cos(1.0), 1.0)
    loop_m = shortest_path(start, behind, 1.0).length_m
    assert loop_m == pytest.approx(oracle_shortest_length(start, behind, 1.0))
    assert loop_m > 2 * PI - 0.1


def test_all_paths_lists_each_feasible_word_once_sorted() -> None:
    # Far apart: the CCC words are infeasible, all four CSC words exist.
    paths = all_paths(Pose(0, 0, NORTH), Pose(100, 0, SOUTH), 5.0)
    assert sorted(p.word for p in paths) == ["LSL", "LSR", "RSL", "RSR"]
    lengths = [p.length_m for p in paths]
    assert lengths == sorted(lengths)
    # Close together: CCC words appear.
    near = all_paths(Pose(0, 0, NORTH), Pose(0, 0, SOUTH), 5.0)
    assert {"LRL", "RLR"} <= {p.word for p in near}


@pytest.mark.parametrize(
    ("heading", "expected"),
    [(-1e-17, 0.0), (2 * PI, 0.0), (-PI / 2, 3 * PI / 2), (5 * PI, PI), (0.25, 0.25)],
)
def test_normalise_heading(heading: float, expected: float) -> None:
    result = normalise_heading_rad(heading)
    assert 0.0 <= result < 2 * PI
    assert result == pytest.approx(expected, abs=1e-15)


def test_pose_normalises_heading_and_coerces_floats() -> None:
    pose = Pose(1, 2, -PI / 2)
    assert pose.heading_rad == pytest.approx(3 * PI / 2)
    assert isinstance(pose.east_m, float)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_bad_radius_raises_value_error_naming_it(bad: float) -> None:
    with pytest.raises(ValueError, match="radius_m") as info:
        shortest_path(Pose(0, 0, 0), Pose(10, 0, 0), bad)
    assert isinstance(info.value, PlannerError)
    assert "\n" not in str(info.value)


def test_invalid_values_raise_geometry_error_naming_the_argument() -> None:
    with pytest.raises(GeometryError, match=r"Pose\.north_m"):
        Pose(0.0, math.nan, 0.0)
    with pytest.raises(GeometryError, match="word"):
        DubinsPath(Pose(0, 0, 0), "LLL", (1.0, 1.0, 1.0), 1.0)
    with pytest.raises(GeometryError, match="lengths_m"):
        DubinsPath(Pose(0, 0, 0), "LSL", (1.0, -1.0, 1.0), 1.0)
    path = shortest_path(Pose(0, 0, NORTH), Pose(0, 10, NORTH), 1.0)
    with pytest.raises(GeometryError, match="s_m"):
        path.pose_at(10.5)
    with pytest.raises(GeometryError, match="s_m"):
        path.pose_at(-0.1)
    with pytest.raises(GeometryError, match="step_m"):
        path.sample(0.0)
    # Round-off overshoot is clamped, not an error.
    assert_pose_close(path.pose_at(10.0 + 1e-12), path.end, 1e-12)


def test_advance_matches_segment_formulae() -> None:
    pose = advance(Pose(0, 0, EAST), "L", PI * 5.0, 5.0)
    assert_pose_close(pose, Pose(0, 10, WEST), 1e-12)
    assert_pose_close(advance(Pose(1, 1, SOUTH), "S", 3.0, math.inf), Pose(1, -2, SOUTH), 1e-15)


def test_sample_includes_both_ends_and_respects_step() -> None:
    path = shortest_path(Pose(0, 0, NORTH), Pose(-50, 0, SOUTH), 10.0)
    samples = path.sample(2.0)
    assert samples.shape[1] == 3
    assert np.allclose(samples[0], [0, 0, 0])
    end = path.end
    assert np.allclose(samples[-1], [end.east_m, end.north_m, end.heading_rad], atol=1e-9)
    steps = np.hypot(*np.diff(samples[:, :2], axis=0).T)
    assert steps.max() <= 2.0 + 1e-9
    assert steps.min() > 0.0
    # A sample point on the first arc sits at the arc's pose_at.
    pose = path.pose_at(0.5 * path.lengths_m[0])
    assert np.min(np.hypot(samples[:, 0] - pose.east_m, samples[:, 1] - pose.north_m)) < 2.0


def test_segments_omit_zero_lengths_and_chain() -> None:
    path = shortest_path(Pose(0, 0, NORTH), Pose(10, 10, EAST), 10.0)
    segments = path.segments()
    assert [s.turn for s in segments] == ["R"]
    assert segments[0].radius_m == 10.0
    assert shortest_path(Pose(1, 1, 0), Pose(1, 1, 0), 3.0).segments() == ()


# --- Properties -----------------------------------------------------------------------------

coords = st.floats(-2000.0, 2000.0, allow_nan=False, allow_infinity=False)
headings = st.floats(0.0, 2 * PI, exclude_max=True, allow_nan=False)
radii = st.floats(0.5, 300.0, allow_nan=False)
poses = st.builds(Pose, coords, coords, headings)


@settings(max_examples=200, deadline=None)
@given(start=poses, end=poses, radius_m=radii)
def test_every_word_reaches_the_requested_end(start: Pose, end: Pose, radius_m: float) -> None:
    scale = scale_of(start, end, radius_m)
    paths = all_paths(start, end, radius_m)
    assert {"LSL", "RSR"} <= {p.word for p in paths}
    assert len({p.word for p in paths}) == len(paths)
    for path in paths:
        assert path.word in WORDS
        assert_pose_close(path.end, end, 1e-6 * scale)
        assert path.start == start


@settings(max_examples=200, deadline=None)
@given(start=poses, end=poses, radius_m=radii)
@example(  # the end within round-off of the start's left turning circle
    start=Pose(0.0, 0.0, 1e-05), end=Pose(0.0, 1e-05, 0.0), radius_m=1.0
)
def test_shortest_is_minimum_matches_oracle_and_beats_chord(
    start: Pose, end: Pose, radius_m: float
) -> None:
    scale = scale_of(start, end, radius_m)
    paths = all_paths(start, end, radius_m)
    best = shortest_path(start, end, radius_m)
    assert best.length_m == min(p.length_m for p in paths)
    assert [p.length_m for p in paths] == sorted(p.length_m for p in paths)
    chord_m = math.hypot(end.east_m - start.east_m, end.north_m - start.north_m)
    if chord_m > 1e-6 * scale:
        # Next to the start pose the Dubins distance jumps between 0 and a loop, so both
        # implementations are at the mercy of round-off there. Elsewhere it jumps too where
        # the end is within round-off of one of the start's turning circles (inside it, a
        # loop; outside, a short arc): there the oracle is asked with the end nudged by a
        # round-off's worth, and either side of the jump is a match.
        nudge_m = 1e-9 * scale
        oracle_m = [
            oracle_shortest_length(
                start, Pose(end.east_m + de, end.north_m + dn, end.heading_rad), radius_m
            )
            for de, dn in itertools.product((-nudge_m, 0.0, nudge_m), repeat=2)
        ]
        assert any(best.length_m == pytest.approx(o, abs=1e-9 * scale) for o in oracle_m), (
            best.length_m,
            oracle_m,
        )
    assert best.length_m >= chord_m - 1e-9 * scale
    assert best.length_m == math.fsum(best.lengths_m)


@settings(max_examples=100, deadline=None)
@given(start=poses, end=poses, radius_m=radii)
@example(
    start=Pose(-1.192092896e-07, -1.192092896e-07, 0.0),
    end=Pose(-1.192092896e-07, 0.0, 0.0),
    radius_m=3.0,
)
def test_pose_at_is_continuous_and_never_turns_tighter_than_radius(
    start: Pose, end: Pose, radius_m: float
) -> None:
    path = shortest_path(start, end, radius_m)
    n = 400
    ds = path.length_m / n
    s = [k * ds for k in range(n)] + [path.length_m]
    poses_ = [path.pose_at(v) for v in s]
    xy = np.array([[p.east_m, p.north_m] for p in poses_])
    steps = np.diff(s)
    moved = np.hypot(*np.diff(xy, axis=0).T)
    tol = 1e-9 * scale_of(start, end, radius_m)
    # Unit speed: never moves further than the arc length flown (continuity).
    assert np.all(moved <= steps + tol)
    # Headings carry round-off of order 1e-7 rad after a full loop (seen at r = 3 m with
    # start ~ end), so allow 1e-6 rad per step on top of the 1/r turn rate.
    excess = [
        heading_diff(a.heading_rad, b.heading_rad) - h * (1 + 1e-6) / radius_m
        for (a, b), h in zip(itertools.pairwise(poses_), steps, strict=True)
        if h > 0
    ]
    assert max(excess, default=0.0) <= 1e-6
    # Curvature from positions alone: turning of chord directions over the distance flown.
    chords = np.diff(xy, axis=0)
    keep = moved > 1e-6 * max(ds, 1e-12) + tol
    directions = np.arctan2(chords[keep, 0], chords[keep, 1])
    flown = steps[keep]
    if directions.size > 1:
        turn = np.abs((np.diff(directions) + PI) % (2 * PI) - PI)
        assert np.all(turn <= 0.5 * (flown[:-1] + flown[1:]) / radius_m * (1 + 1e-6) + 1e-9)


@settings(max_examples=100, deadline=None)
@given(
    start=poses,
    end=poses,
    radius_m=radii,
    k=st.floats(0.01, 100.0),
    rotation=headings,
    shift=st.tuples(coords, coords),
)
@example(  # an end within round-off of the start: its length is the chord or a loop
    start=Pose(17.0, 0.0, 0.0),
    end=Pose(17.0, 5.960464477539063e-08, 0.0),
    radius_m=1.0,
    k=1.0,
    rotation=1.5,
    shift=(0.0, 0.0),
)
def test_length_is_invariant_under_scaling_and_rigid_motion(
    start: Pose, end: Pose, radius_m: float, k: float, rotation: float, shift: tuple[float, float]
) -> None:
    chord_m = math.hypot(end.east_m - start.east_m, end.north_m - start.north_m)
    if chord_m <= 1e-6 * scale_of(start, end, radius_m):
        # Next to the start pose the length jumps between the chord and a loop at a round-off
        # of the move's arithmetic (an end 6e-8 m ahead, 1e-15 m to the side, needs a loop).
        return
    base = shortest_path(start, end, radius_m).length_m
    scaled = shortest_path(
        Pose(k * start.east_m, k * start.north_m, start.heading_rad),
        Pose(k * end.east_m, k * end.north_m, end.heading_rad),
        k * radius_m,
    ).length_m
    assert scaled == pytest.approx(
        k * base, rel=1e-9, abs=1e-9 * k * scale_of(start, end, radius_m)
    )

    def move(p: Pose) -> Pose:
        # Rotating the frame clockwise by `rotation` adds it to every compass heading.
        c, s = math.cos(rotation), math.sin(rotation)
        return Pose(
            c * p.east_m + s * p.north_m + shift[0],
            -s * p.east_m + c * p.north_m + shift[1],
            p.heading_rad + rotation,
        )

    moved = shortest_path(move(start), move(end), radius_m).length_m
    assert moved == pytest.approx(base, abs=1e-8 * scale_of(start, end, radius_m) * 4)


@settings(max_examples=100, deadline=None)
@given(start=poses, end=poses, radius_m=radii)
def test_segments_form_the_same_path(start: Pose, end: Pose, radius_m: float) -> None:
    path = shortest_path(start, end, radius_m)
    segments = path.segments()
    if not segments:
        assert path.length_m == 0.0
        return
    route = FlightPath(segments)
    scale = scale_of(start, end, radius_m)
    assert route.length_m == pytest.approx(path.length_m, rel=1e-12)
    assert_pose_close(route.end, path.end, 1e-9 * scale)
    assert route.minimum_turn_radius_m() >= radius_m
    mid = 0.5 * path.length_m
    assert_pose_close(route.pose_at(mid), path.pose_at(mid), 1e-9 * scale)
    samples = path.sample(max(path.length_m / 50, 1e-3))
    assert np.allclose(samples[-1, :2], [end.east_m, end.north_m], atol=1e-6 * scale)

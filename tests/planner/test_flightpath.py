"""Tests of planner.flightpath: segments, routes, section 3.2 smoothing and eq. (4) checks."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from planner.dubins import GeometryError, Pose, shortest_path
from planner.flightpath import (
    FlightPath,
    Segment,
    Violation,
    check_polyline,
    leg_lengths_m,
    smooth_polyline,
    straight,
    turn_angles_rad,
)

PI = math.pi
NORTH, EAST, SOUTH, WEST = 0.0, PI / 2, PI, 3 * PI / 2


def heading_diff(a_rad: float, b_rad: float) -> float:
    return abs((a_rad - b_rad + PI) % (2 * PI) - PI)


def dist(pose: Pose, east_m: float, north_m: float) -> float:
    return math.hypot(pose.east_m - east_m, pose.north_m - north_m)


def point_to_polyline_m(
    xy: NDArray[np.float64], points: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distance of each row of xy to the polyline through points."""
    a, b = points[:-1], points[1:]
    ab = b - a
    t = np.einsum("pkj,kj->pk", xy[:, None, :] - a[None], ab) / np.einsum("kj,kj->k", ab, ab)
    foot = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    result: NDArray[np.float64] = np.min(np.linalg.norm(xy[:, None, :] - foot, axis=2), axis=1)
    return result


# --- Segment --------------------------------------------------------------------------------


def test_right_arc_known_answers() -> None:
    arc = Segment(Pose(0, 0, NORTH), 10 * PI / 2, "R", 10.0)
    assert arc.centre == pytest.approx((10.0, 0.0))
    end = arc.end
    assert (end.east_m, end.north_m, end.heading_rad) == pytest.approx((10, 10, EAST))
    assert arc.heading_change_rad == pytest.approx(PI / 2)
    mid = arc.pose_at(10 * PI / 4)
    assert arc.centre is not None
    assert dist(mid, *arc.centre) == pytest.approx(10.0)


def test_left_arc_known_answers() -> None:
    arc = Segment(Pose(0, 0, EAST), 5 * PI, "L", 5.0)
    assert arc.centre == pytest.approx((0.0, 5.0))
    end = arc.end
    assert (end.east_m, end.north_m, end.heading_rad) == pytest.approx((0, 10, WEST))
    assert arc.heading_change_rad == pytest.approx(-PI)


def test_straight_segment_has_infinite_radius_and_no_centre() -> None:
    segment = Segment(Pose(1, 1, SOUTH), 3.0, "S")
    assert segment.radius_m == math.inf
    assert segment.centre is None
    assert segment.heading_change_rad == 0.0
    assert (segment.end.east_m, segment.end.north_m) == pytest.approx((1.0, -2.0))


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"length_m": 1.0, "turn": "X"}, "turn"),
        ({"length_m": -1.0, "turn": "S"}, "length_m"),
        ({"length_m": math.nan, "turn": "S"}, "length_m"),
        ({"length_m": 1.0, "turn": "S", "radius_m": 5.0}, "radius_m"),
        ({"length_m": 1.0, "turn": "L", "radius_m": math.inf}, "radius_m"),
        ({"length_m": 1.0, "turn": "R", "radius_m": 0.0}, "radius_m"),
    ],
)
def test_segment_rejects_bad_values(kwargs: dict[str, object], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        Segment(Pose(0, 0, 0), **kwargs)  # type: ignore[arg-type]


# --- FlightPath -----------------------------------------------------------------------------


def l_route() -> FlightPath:
    """100 m north, a right quarter turn of radius 10 m, 50 m east."""
    first = Segment(Pose(0, 0, NORTH), 100.0, "S")
    arc = Segment(first.end, 10 * PI / 2, "R", 10.0)
    last = Segment(arc.end, 50.0, "S")
    return FlightPath((first, arc, last))


def test_route_length_cumulative_and_pose_at_joints() -> None:
    route = l_route()
    assert route.length_m == pytest.approx(150 + 5 * PI)
    assert route.cumulative_m() == pytest.approx((0.0, 100.0, 100 + 5 * PI))
    at_arc = route.pose_at(100.0)
    assert (at_arc.east_m, at_arc.north_m, at_arc.heading_rad) == pytest.approx((0, 100, NORTH))
    end = route.pose_at(route.length_m)
    assert (end.east_m, end.north_m, end.heading_rad) == pytest.approx((60, 110, EAST))
    assert route.end == route.segments[-1].end
    assert route.start == Pose(0, 0, NORTH)
    assert route.remaining_m(100.0) == pytest.approx(50 + 5 * PI)
    assert route.remaining_m(route.length_m) == 0.0
    assert route.minimum_turn_radius_m() == 10.0
    with pytest.raises(GeometryError, match="s_m"):
        route.pose_at(route.length_m + 1.0)
    with pytest.raises(GeometryError, match="s_m"):
        route.remaining_m(-1.0)


def test_route_must_be_non_empty_and_g1_continuous() -> None:
    with pytest.raises(GeometryError, match="segments"):
        FlightPath(())
    first = Segment(Pose(0, 0, NORTH), 100.0, "S")
    with pytest.raises(GeometryError, match=r"segments\[1\]"):
        FlightPath((first, Segment(Pose(0, 100.1, NORTH), 10.0, "S")))
    with pytest.raises(GeometryError, match=r"segments\[1\]"):
        FlightPath((first, Segment(Pose(0, 100, 0.01), 10.0, "S")))
    # Within tolerance is accepted.
    FlightPath((first, Segment(Pose(0, 100 + 1e-7, 1e-7), 10.0, "S")))


def test_straight_known_answer_and_degenerate_input() -> None:
    route = straight(0.0, 0.0, 30.0, -40.0)
    assert route.length_m == 50.0
    assert route.start.heading_rad == pytest.approx(math.atan2(30, -40))
    assert route.minimum_turn_radius_m() == math.inf
    with pytest.raises(GeometryError, match="end_east_m"):
        straight(1.0, 2.0, 1.0, 2.0)


def test_concat_checks_continuity_and_joins() -> None:
    route = l_route()
    tail = straight(60.0, 110.0, 100.0, 110.0)
    joined = route.concat(tail)
    assert joined.length_m == pytest.approx(route.length_m + 40.0)
    assert joined.segments == route.segments + tail.segments
    with pytest.raises(GeometryError, match="other"):
        route.concat(straight(61.0, 110.0, 100.0, 110.0))  # 1 m gap
    with pytest.raises(GeometryError, match="other"):
        route.concat(straight(60.0, 110.0, 60.0, 150.0))  # kinks north


def test_project_known_answers() -> None:
    route = l_route()
    assert route.project(-5.0, 50.0) == pytest.approx(50.0)  # beside the first leg
    assert route.project(0.0, -20.0) == 0.0  # behind the start
    assert route.project(500.0, 110.0) == pytest.approx(route.length_m)  # past the end
    # Outside the arc at 45 degrees: the arc midpoint.
    ce, cn = 10.0, 100.0
    assert route.project(ce - 20 * math.cos(PI / 4), cn + 20 * math.sin(PI / 4)) == pytest.approx(
        100 + 10 * PI / 4
    )
    # The arc centre is equidistant from the whole arc: the earliest arc point wins.
    assert route.project(ce, cn) == pytest.approx(100.0)


def test_waypoints_known_answers() -> None:
    route = l_route()
    waypoints = route.waypoints(math.radians(30))
    c30, s30 = math.cos(PI / 6), math.sin(PI / 6)
    expected = [
        (0, 0),
        (0, 100),
        (10 - 10 * c30, 100 + 10 * s30),
        (10 - 10 * s30, 100 + 10 * c30),
        (10, 110),
        (60, 110),
    ]
    assert waypoints == pytest.approx(np.array(expected))
    assert straight(0, 0, 10, 0).waypoints().shape == (2, 2)
    with pytest.raises(GeometryError, match="max_arc_step_rad"):
        route.waypoints(0.0)


def test_sample_known_answer() -> None:
    samples = straight(0.0, 0.0, 0.0, 100.0).sample(10.0)
    assert samples.shape == (11, 3)
    assert samples[:, 1] == pytest.approx(np.arange(0.0, 101.0, 10.0))
    route_samples = l_route().sample(1000.0, max_arc_step_rad=math.radians(10))
    # Straights give their ends only; the quarter arc is split into 9 steps of 10 degrees.
    assert route_samples.shape == (1 + 1 + 9 + 1, 3)


# --- eq. (4) helpers ------------------------------------------------------------------------

SQUARE = np.array([[0.0, 0.0], [0.0, 1000.0], [1000.0, 1000.0], [1000.0, 0.0], [2000.0, 0.0]])


def test_leg_lengths_and_turn_angles_known_answers() -> None:
    assert leg_lengths_m(SQUARE) == pytest.approx([1000.0] * 4)
    assert turn_angles_rad(SQUARE) == pytest.approx([PI / 2, PI / 2, PI / 2])
    assert turn_angles_rad([[0, 0], [0, 5], [0, 10]]) == pytest.approx([0.0])
    assert turn_angles_rad([[0, 0], [0, 5], [0, 1]]) == pytest.approx([PI])
    assert turn_angles_rad([[0, 0], [0, 5], [5, 10]]) == pytest.approx([PI / 4])
    assert turn_angles_rad([[0, 0], [1, 0]]).shape == (0,)


@pytest.mark.parametrize(
    ("limits", "expected"),
    [
        ({"min_leg_m": 10.0, "max_turn_rad": PI, "max_range_m": 1e9}, []),
        (
            {"min_leg_m": 1000.5, "max_turn_rad": PI, "max_range_m": math.inf},
            [("min_leg_m", k, 1000.0, 1000.5) for k in range(4)],
        ),
        (
            {"min_leg_m": 0.0, "max_turn_rad": 1.5, "max_range_m": 4000.0},
            [("max_turn_rad", k, PI / 2, 1.5) for k in (1, 2, 3)],
        ),
        (
            {"min_leg_m": 0.0, "max_turn_rad": PI, "max_range_m": 2500.0},
            [("max_range_m", 3, 4000.0, 2500.0)],
        ),
    ],
)
def test_check_polyline_known_answers(
    limits: dict[str, float], expected: list[tuple[str, int, float, float]]
) -> None:
    violations = check_polyline(SQUARE, **limits)
    assert all(isinstance(v, Violation) for v in violations)
    assert [(v.constraint, v.index) for v in violations] == [(e[0], e[1]) for e in expected]
    for v, e in zip(violations, expected, strict=True):
        assert v.value == pytest.approx(e[2])
        assert v.limit == e[3]
        assert v.constraint in v.message


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"min_leg_m": -1.0, "max_turn_rad": 1.0, "max_range_m": 1.0}, "min_leg_m"),
        ({"min_leg_m": 1.0, "max_turn_rad": 4.0, "max_range_m": 1.0}, "max_turn_rad"),
        ({"min_leg_m": 1.0, "max_turn_rad": 1.0, "max_range_m": math.nan}, "max_range_m"),
    ],
)
def test_check_polyline_rejects_bad_limits(kwargs: dict[str, float], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        check_polyline(SQUARE, **kwargs)


# --- smooth_polyline: known answers -------------------------------------------------------


def test_two_points_give_a_straight() -> None:
    route = smooth_polyline([[0, 0], [30, 40]], 10.0)
    assert [s.turn for s in route.segments] == ["S"]
    assert route.length_m == pytest.approx(50.0)


def test_collinear_vertices_give_no_arc() -> None:
    route = smooth_polyline([[0, 0], [10, 10], [25, 25], [40, 40]], 50.0)
    assert [s.turn for s in route.segments] == ["S"]
    assert route.length_m == pytest.approx(40 * math.sqrt(2))
    # A corner of 5e-10 rad is round-off of a straight line, not a pair of sliver arcs.
    bend = 5e-10
    nearly: list[list[float]] = [
        [0, 0],
        [0, 1000],
        [1000 * math.sin(bend), 1000 + 1000 * math.cos(bend)],
    ]
    assert [s.turn for s in smooth_polyline(nearly, 50.0).segments] == ["S"]


def test_right_angle_corner_known_length() -> None:
    # Midpoints (0, 500) heading north and (500, 1000) heading east, r = 100: RSR with two
    # 45-degree arcs joined by a 400*sqrt(2) m straight between the circle centres.
    route = smooth_polyline(SQUARE[:3], 100.0)
    assert [s.turn for s in route.segments] == ["S", "R", "S", "R", "S"]
    expected_m = 500 + 2 * (100 * PI / 4) + 400 * math.sqrt(2) + 500
    assert route.length_m == pytest.approx(expected_m, rel=1e-12)
    assert route.minimum_turn_radius_m() == 100.0


def test_start_and_end_headings_known_cases() -> None:
    # Already flying along the leg: nothing to add.
    route = smooth_polyline([[0, 0], [0, 100]], 10.0, start_heading_rad=NORTH)
    assert [s.turn for s in route.segments] == ["S"]
    # Flying south at P_0 but asked to go north: a Dubins turnaround to P_1 heading north.
    route = smooth_polyline([[0, 0], [0, 100]], 10.0, start_heading_rad=SOUTH)
    expected = shortest_path(Pose(0, 0, SOUTH), Pose(0, 100, NORTH), 10.0)
    assert route.length_m == pytest.approx(expected.length_m)
    assert route.start.heading_rad == pytest.approx(SOUTH)
    # Arrive heading east at the end of a northbound leg.
    route = smooth_polyline([[0, 0], [0, 100]], 10.0, end_heading_rad=EAST)
    assert heading_diff(route.end.heading_rad, EAST) < 1e-9
    assert route.length_m == pytest.approx(
        shortest_path(Pose(0, 0, NORTH), Pose(0, 100, EAST), 10.0).length_m
    )


@pytest.mark.parametrize(
    ("points", "radius_m", "kwargs", "name"),
    [
        ([[0, 0]], 10.0, {}, "points_m"),
        ([[0, 0], [0, 10], [0, 10], [5, 5]], 10.0, {}, r"points_m\[2\] repeats points_m\[1\]"),
        ([[0, 0, 0], [1, 1, 1]], 10.0, {}, "points_m"),
        ([[0, 0], [math.nan, 1]], 10.0, {}, "points_m"),
        ([[0, 0], [0, 10]], 0.0, {}, "radius_m"),
        ([[0, 0], [0, 10]], -5.0, {}, "radius_m"),
        ([[0, 0], [0, 10]], 5.0, {"start_heading_rad": math.inf}, "start_heading_rad"),
    ],
)
def test_smooth_polyline_rejects_bad_input(
    points: list[list[float]], radius_m: float, kwargs: dict[str, float], name: str
) -> None:
    with pytest.raises(ValueError, match=name) as info:
        smooth_polyline(points, radius_m, **kwargs)
    assert "\n" not in str(info.value)


# --- smooth_polyline: properties ----------------------------------------------------------


@st.composite
def polylines(draw: st.DrawFn, max_turn_deg: float = 179.0) -> tuple[NDArray[np.float64], float]:
    """A polyline of 2..6 points with legs of 3..30 radii and turns up to max_turn_deg."""
    radius_m = draw(st.floats(5.0, 200.0))
    n_legs = draw(st.integers(1, 5))
    heading = draw(st.floats(0.0, 2 * PI))
    point = np.array([draw(st.floats(-5e3, 5e3)), draw(st.floats(-5e3, 5e3))])
    points = [point]
    for k in range(n_legs):
        if k:
            heading += math.radians(draw(st.floats(-max_turn_deg, max_turn_deg)))
        length_m = radius_m * draw(st.floats(3.0, 30.0))
        point = point + length_m * np.array([math.sin(heading), math.cos(heading)])
        points.append(point)
    return np.array(points), radius_m


def pose_of(point: NDArray[np.float64], heading_rad: float) -> Pose:
    return Pose(float(point[0]), float(point[1]), float(heading_rad))


def leg_midpoints(points: NDArray[np.float64]) -> NDArray[np.float64]:
    return (points[:-1] + points[1:]) / 2.0


def corner_precondition(points: NDArray[np.float64], radius_m: float) -> bool:
    """Each corner's arc-and-tangents fillet fits inside its two half legs."""
    legs = leg_lengths_m(points)
    turns = turn_angles_rad(points)
    return bool(np.all(np.minimum(legs[:-1], legs[1:]) / 2 >= radius_m * np.tan(turns / 2) + 1e-9))


def check_route_basics(route: FlightPath, points: NDArray[np.float64], radius_m: float) -> None:
    scale = max(1.0, float(np.max(np.abs(points))), radius_m)
    tol_m = 1e-6 * scale
    assert dist(route.start, *points[0]) <= tol_m
    assert dist(route.end, *points[-1]) <= tol_m
    assert route.minimum_turn_radius_m() >= radius_m - 1e-9
    for a, b in itertools.pairwise(route.segments):
        assert heading_diff(a.end.heading_rad, b.start.heading_rad) < 1e-6
        assert dist(a.end, b.start.east_m, b.start.north_m) <= tol_m
    samples = route.sample(route.length_m / 200)
    chords_m = math.fsum(np.hypot(*np.diff(samples[:, :2], axis=0).T).tolist())
    assert chords_m <= route.length_m + tol_m
    assert chords_m >= route.length_m * (1 - 1e-3)


@settings(max_examples=120, deadline=None)
@given(case=polylines())
def test_smoothed_route_properties(case: tuple[NDArray[np.float64], float]) -> None:
    points, radius_m = case
    route = smooth_polyline(points, radius_m)
    scale = max(1.0, float(np.max(np.abs(points))), radius_m)
    tol_m = 1e-6 * scale
    check_route_basics(route, points, radius_m)
    headings = np.arctan2(*np.diff(points, axis=0).T)
    assert heading_diff(route.start.heading_rad, float(headings[0])) < 1e-9
    assert heading_diff(route.end.heading_rad, float(headings[-1])) < 1e-9
    # The route reaches each leg midpoint, with the leg's heading, after flying exactly the
    # first half leg plus the shortest Dubins paths between earlier midpoints.
    midpoints = leg_midpoints(points)
    s_m = leg_lengths_m(points)[0] / 2
    for k, (mid, heading) in enumerate(zip(midpoints, headings, strict=True)):
        if k:
            previous = pose_of(midpoints[k - 1], headings[k - 1])
            s_m += shortest_path(previous, pose_of(mid, heading), radius_m).length_m
        pose = route.pose_at(min(s_m, route.length_m))
        assert dist(pose, *mid) <= tol_m
        assert heading_diff(pose.heading_rad, float(heading)) < 1e-6
    assert route.length_m == pytest.approx(s_m + leg_lengths_m(points)[-1] / 2, abs=tol_m)


@settings(max_examples=120, deadline=None)
@given(case=polylines(max_turn_deg=179.0))
def test_smoothing_cuts_corners_inside_the_polyline(
    case: tuple[NDArray[np.float64], float],
) -> None:
    """With room for a fillet at every corner, each corner piece is a convex curve turning
    less than pi, so it lies in the triangle (M_{i-1}, P_i, M_i) formed by its end tangents
    (the legs) and its chord. Hence the route is never longer than the polyline, and a point
    P + u (M_{i-1} - P) + v (M_i - P) of the triangle is within min(v b, u a) <= a b / (a + b)
    of the polyline, a and b being the half legs.
    """
    points, radius_m = case
    route = smooth_polyline(points, radius_m)
    scale = max(1.0, float(np.max(np.abs(points))), radius_m)
    tol_m = 1e-6 * scale
    polyline_m = float(np.sum(leg_lengths_m(points)))
    if not corner_precondition(points, radius_m):
        return
    assert route.length_m <= polyline_m + tol_m
    half = leg_lengths_m(points) / 2
    bound_m = float(np.max(half[:-1] * half[1:] / (half[:-1] + half[1:]), initial=0.0))
    xy = route.sample(route.length_m / 400)[:, :2]
    assert np.max(point_to_polyline_m(xy, points)) <= bound_m + tol_m
    # Triangle containment, corner by corner, between the midpoint arrival distances.
    midpoints = leg_midpoints(points)
    headings = np.arctan2(*np.diff(points, axis=0).T)
    s_m = half[0]
    for k in range(1, len(midpoints)):
        a = pose_of(midpoints[k - 1], headings[k - 1])
        b = pose_of(midpoints[k], headings[k])
        piece_m = shortest_path(a, b, radius_m).length_m
        corner = np.array([midpoints[k - 1], points[k], midpoints[k]])
        for s in np.linspace(s_m, s_m + piece_m, 40):
            pose = route.pose_at(min(float(s), route.length_m))
            assert in_triangle(np.array([pose.east_m, pose.north_m]), corner, tol_m)
        s_m += piece_m


def in_triangle(p: NDArray[np.float64], tri: NDArray[np.float64], tol_m: float) -> bool:
    signs = []
    for i in range(3):
        a, b = tri[i], tri[(i + 1) % 3]
        edge = b - a
        cross = edge[0] * (p[1] - a[1]) - edge[1] * (p[0] - a[0])
        signs.append(cross / max(float(np.hypot(*edge)), 1e-12))
    return all(s >= -tol_m for s in signs) or all(s <= tol_m for s in signs)


@settings(max_examples=80, deadline=None)
@given(
    case=polylines(),
    start_heading=st.one_of(st.none(), st.floats(0.0, 2 * PI)),
    end_heading=st.one_of(st.none(), st.floats(0.0, 2 * PI)),
)
def test_replanned_route_keeps_the_given_headings(
    case: tuple[NDArray[np.float64], float], start_heading: float | None, end_heading: float | None
) -> None:
    points, radius_m = case
    route = smooth_polyline(
        points, radius_m, start_heading_rad=start_heading, end_heading_rad=end_heading
    )
    check_route_basics(route, points, radius_m)
    if start_heading is not None:
        assert heading_diff(route.start.heading_rad, start_heading) < 1e-9
    if end_heading is not None:
        assert heading_diff(route.end.heading_rad, end_heading) < 1e-6
    one_given = (start_heading is None) != (end_heading is None)
    if len(points) > 2 or not one_given:
        scale = max(1.0, float(np.max(np.abs(points))), radius_m)
        for mid in leg_midpoints(points):
            assert dist(route.pose_at(route.project(*mid)), *mid) <= 1e-6 * scale


@settings(max_examples=80, deadline=None)
@given(
    case=polylines(),
    offsets=st.lists(
        st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(0, 1)), min_size=1, max_size=5
    ),
)
def test_project_finds_the_closest_route_point(
    case: tuple[NDArray[np.float64], float], offsets: list[tuple[float, float, float]]
) -> None:
    points, radius_m = case
    route = smooth_polyline(points, radius_m)
    step_m = route.length_m / 2000
    samples = route.sample(step_m, max_arc_step_rad=math.radians(1))
    scale = max(1.0, float(np.max(np.abs(points))), radius_m)
    for de, dn, fraction in offsets:
        on = route.pose_at(fraction * route.length_m)
        q = (on.east_m + 3 * radius_m * de, on.north_m + 3 * radius_m * dn)
        s_m = route.project(*q)
        assert 0.0 <= s_m <= route.length_m
        found_m = dist(route.pose_at(s_m), *q)
        sampled_m = float(np.min(np.hypot(samples[:, 0] - q[0], samples[:, 1] - q[1])))
        # Never worse than any sample, and the samples are at most step_m/2 off the optimum.
        assert found_m <= sampled_m + 1e-9 * scale
        assert found_m >= sampled_m - step_m
        assert route.remaining_m(s_m) == pytest.approx(route.length_m - s_m)


@settings(max_examples=80, deadline=None)
@given(case=polylines(), step_deg=st.floats(2.0, 90.0))
def test_waypoints_lie_on_the_route_and_chords_stay_close(
    case: tuple[NDArray[np.float64], float], step_deg: float
) -> None:
    points, radius_m = case
    route = smooth_polyline(points, radius_m)
    step_rad = math.radians(step_deg)
    waypoints = route.waypoints(step_rad)
    scale = max(1.0, float(np.max(np.abs(points))), radius_m)
    tol_m = 1e-6 * scale
    assert np.allclose(waypoints[0], points[0], atol=tol_m)
    assert np.allclose(waypoints[-1], points[-1], atol=tol_m)
    assert np.all(np.hypot(*np.diff(waypoints, axis=0).T) > 0.0)
    for e, n in waypoints:
        assert dist(route.pose_at(route.project(e, n)), e, n) <= tol_m
    # Flying straight between waypoints strays at most the sagitta of a step_rad arc.
    sagitta_m = radius_m * (1 - math.cos(step_rad / 2))
    for a, b in itertools.pairwise(waypoints):
        mid = (a + b) / 2
        assert dist(route.pose_at(route.project(*mid)), *mid) <= sagitta_m + tol_m
    # Every segment end is a waypoint.
    for segment in route.segments:
        end = segment.end
        assert np.min(np.hypot(*(waypoints - [end.east_m, end.north_m]).T)) <= tol_m


@settings(max_examples=50, deadline=None)
@given(case=polylines(), cut=st.floats(0.0, 1.0))
def test_concat_of_split_route_is_the_route(
    case: tuple[NDArray[np.float64], float], cut: float
) -> None:
    points, radius_m = case
    route = smooth_polyline(points, radius_m)
    if len(route.segments) < 2:
        return
    k = 1 + int(cut * (len(route.segments) - 2))
    head, tail = FlightPath(route.segments[:k]), FlightPath(route.segments[k:])
    assert head.concat(tail) == route
    with pytest.raises(GeometryError, match="other"):
        tail.concat(head)


@settings(max_examples=80, deadline=None)
@given(case=polylines(), fractions=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=40))
def test_poses_at_equals_pose_at_point_by_point(
    case: tuple[NDArray[np.float64], float], fractions: list[float]
) -> None:
    points, radius_m = case
    route = smooth_polyline(points, radius_m)
    s_m = [f * route.length_m for f in fractions] + [0.0, route.length_m]
    s_m += list(route.cumulative_m())  # segment joints: the index lookup's edge cases
    expected = np.array(
        [[p.east_m, p.north_m, p.heading_rad] for p in (route.pose_at(s) for s in s_m)]
    )
    # Bit for bit: the vectorised sampling must not move a profile or a clearance check.
    np.testing.assert_array_equal(route.poses_at(s_m), expected)


def test_poses_at_clamps_round_off_and_rejects_distances_off_the_route() -> None:
    route = straight(0.0, 0.0, 0.0, 100.0)
    poses = route.poses_at([-1e-9, 100.0 + 1e-9])
    np.testing.assert_array_equal(poses[:, :2], [[0.0, 0.0], [0.0, 100.0]])
    with pytest.raises(GeometryError, match="s_m must be in"):
        route.poses_at([50.0, 100.5])


@settings(max_examples=80, deadline=None)
@given(
    case=polylines(),
    offsets=st.lists(
        st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(0, 1)), min_size=1, max_size=8
    ),
)
def test_project_many_equals_project_point_by_point(
    case: tuple[NDArray[np.float64], float], offsets: list[tuple[float, float, float]]
) -> None:
    points, radius_m = case
    route = smooth_polyline(points, radius_m)
    queries = [tuple(p) for p in route.waypoints()] + [tuple(p) for p in points]
    for de, dn, fraction in offsets:
        on = route.pose_at(fraction * route.length_m)
        queries.append((on.east_m + 3 * radius_m * de, on.north_m + 3 * radius_m * dn))
    expected = [route.project(e, n) for e, n in queries]
    assert route.project_many(np.array(queries)).tolist() == expected

"""What a loiter adds to the route as ArduPlane flies it (:mod:`planner.loiterflight`): known
answers, tangent circles adding nothing, and the buffer site reached by a detour timed with
it (:func:`planner.retime.find_loiter_site`)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from planner.dubins import Pose
from planner.flightpath import straight
from planner.loiterflight import LINED_UP_RAD, loiter_flight, way_out_m
from planner.retime import _tangent_centre, find_loiter_site
from planner.scenario import parse_scenario
from tests.planner.conftest import small_scenario

R = 250.0


@given(
    heading=st.floats(-math.pi, math.pi),
    radius=st.floats(50.0, 2000.0),
    clockwise=st.booleans(),
)
def test_a_circle_tangent_to_the_route_at_its_waypoint_adds_nothing(
    heading: float, radius: float, clockwise: bool
) -> None:
    """Entered on the circle, turning the route's way: after whole turns the course is the
    route's again, so it leaves where it came in."""
    ce, cn = _tangent_centre(Pose(1000.0, -500.0, heading), radius, clockwise)
    f = loiter_flight(1000.0, -500.0, heading, ce, cn, radius, clockwise=clockwise)
    assert f.entry_m == pytest.approx(0.0, abs=1e-6 * radius)
    assert f.line_up_m == 0.0
    assert f.exit_m == pytest.approx(0.0, abs=1e-6 * radius)
    assert f.added_m == pytest.approx(0.0, abs=1e-6 * radius)


@pytest.mark.parametrize("clockwise", [True, False])
def test_a_circle_on_the_route_behind_the_waypoint_costs_out_a_three_quarter_line_up_and_back(
    clockwise: bool,
) -> None:
    """The route northwards through the circle's centre, the waypoint d past it: straight
    back to the circle (d - r), counted from its north point, three quarters of a turn less
    the tolerance to point north again (either way round), and from there, r sin(10 deg)
    short of the centre's abreast, back past the waypoint."""
    d = 1148.0
    f = loiter_flight(0.0, d, 0.0, 0.0, 0.0, R, clockwise=clockwise)
    assert f.entry_m == pytest.approx(d - R)
    assert f.counted_from_rad == pytest.approx(0.0)
    assert f.line_up_m == pytest.approx((1.5 * math.pi - LINED_UP_RAD) * R)
    assert f.exit_m == pytest.approx(d + R * math.sin(LINED_UP_RAD))
    # What the loiter used to be timed with: out to the circle and back, 1,796 m; flown,
    # 3,224 m (as the simulator flies it, within 50 m: tests/sitl_stub/test_loiter_entry.py).
    assert f.added_m == pytest.approx(3224.0, abs=1.0)
    assert f.added_m - 2.0 * (d - R) > 5.0 * R


def test_a_circle_ahead_on_the_route_is_flown_into_and_left_beside_its_centre() -> None:
    """The centre 1 km ahead: straight in to its near point, a quarter turn less the
    tolerance to point along the route, and away from beside the centre, 1 km less r
    sin(10 deg) ahead of the waypoint: the loiter adds a little over half a radius."""
    f = loiter_flight(0.0, 0.0, 0.0, 0.0, 1000.0, R, clockwise=True)
    assert f.entry_m == pytest.approx(1000.0 - R)
    assert f.line_up_m == pytest.approx((0.5 * math.pi - LINED_UP_RAD) * R)
    assert f.exit_m == pytest.approx(-(1000.0 - R * math.sin(LINED_UP_RAD)))
    tol = LINED_UP_RAD
    assert f.added_m == pytest.approx(R * (0.5 * math.pi - tol - 1.0 + math.sin(tol)))
    assert 0.5 * R < f.added_m < 0.6 * R


def test_the_waypoint_inside_the_circle_counts_from_there() -> None:
    """Inside the circle the L1 loiter law is in force at once: the turns are counted from
    where the item starts, 81 m (its turn distance at 20 m/s) short of the waypoint, 58 m past
    the centre; it flies straight out to the circle (192 m, 81 m of it instead of the route)."""
    f = loiter_flight(0.0, 139.0, 0.0, 0.0, 0.0, R, clockwise=True)
    early = 0.75 * 17.0 * 20.0 / math.pi
    assert f.entry_m == pytest.approx(R - (139.0 - early) - early, abs=1.5)
    assert f.line_up_m == pytest.approx((1.5 * math.pi - LINED_UP_RAD) * R)


def test_a_loiter_started_behind_the_centre_counts_its_way_through_it() -> None:
    """The waypoint 58 m past the centre, just off it: ArduPlane starts the item its turn
    distance (81 m at 20 m/s) before the waypoint, 23 m short of the centre; the circle law
    turns it off the centre and straight out, and the half turn the bearing swings through
    counts. It adds under a radius, not the three-quarter line-up and more (1,223 m)."""
    f = loiter_flight(0.0, 58.0, 0.0, -3.0, 0.0, R, clockwise=True)
    assert f.counted_from_rad == pytest.approx(math.pi, abs=0.2)
    assert f.entry_m == pytest.approx(191.0, abs=5.0)
    assert f.line_up_m < 0.0
    assert f.added_m == pytest.approx(86.0, abs=5.0)


def test_a_radius_must_be_positive() -> None:
    with pytest.raises(ValueError, match="radius_m"):
        loiter_flight(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, clockwise=True)


def test_a_buffer_behind_the_allowed_stretch_is_timed_as_the_loiter_is_flown() -> None:
    """The route runs north through a buffer's centre, but turns may only start 1 km past
    where the vehicle is (beyond the buffer): the circle goes in the buffer at its edge
    nearest the first allowed point, on the route behind it. Its ``detour_m`` is what the
    aircraft flies besides the turns (out to it, the line-up and back), not twice the way
    out."""
    data = small_scenario(threats=[])
    data["buffers"] = [{"id": "B", "center": {"east_m": 20000, "north_m": 20000}, "radius_m": 1250}]
    scenario = parse_scenario(data)
    vehicle = scenario.vehicle("A")
    path = straight(20000.0, 10000.0, 20000.0, 30000.0)
    s_from = 10000.0 + 1100.0 - 1000.0  # the first allowed point: 1.1 km past the centre
    site = find_loiter_site(scenario, vehicle, path, s_from, R)
    assert site is not None and site.buffer_id == "B"
    assert site.s_m == pytest.approx(11100.0)
    assert site.centre == pytest.approx((20000.0, 21000.0))
    d = 100.0  # from the centre to the waypoint
    flown = loiter_flight(20000.0, 21100.0, 0.0, 20000.0, 21000.0, R, clockwise=site.clockwise)
    assert site.detour_m == pytest.approx(flown.added_m)
    assert site.detour_m > 2.0 * d + 4.0 * R
    # Counted from where the route meets the circle.
    assert site.entry == pytest.approx((20000.0, 21000.0 + R))


def _flown_out_m(de: float, dn: float, course: float, gs: float) -> float:
    """The way out flown step by step: turning at the roll limit's rate towards the
    waypoint (the shorter way round) until headed at it, then straight on to it."""
    rho = gs**2 / (9.80665 * math.tan(math.radians(45.0)))
    step = 0.05
    e = n = flown = 0.0
    while math.hypot(de - e, dn - n) > step:
        off = math.remainder(math.atan2(de - e, dn - n) - course, 2.0 * math.pi)
        course += math.copysign(min(abs(off), step / rho), off)
        e, n = e + step * math.sin(course), n + step * math.cos(course)
        flown += step
        assert flown < 10_000.0
    return flown + math.hypot(de - e, dn - n)


@given(
    st.floats(min_value=0.0, max_value=2.0 * math.pi),
    st.floats(min_value=400.0, max_value=2_000.0),
    st.floats(min_value=0.0, max_value=2.0 * math.pi),
    st.floats(min_value=14.0, max_value=30.0),
)
def test_the_way_out_of_the_turns_is_the_turn_at_the_roll_limit_then_the_line(
    bearing: float, distance_m: float, course: float, gs: float
) -> None:
    de, dn = distance_m * math.sin(bearing), distance_m * math.cos(bearing)
    assert way_out_m(de, dn, course, gs) == pytest.approx(_flown_out_m(de, dn, course, gs), abs=1.0)

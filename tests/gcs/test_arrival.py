"""gcs.coordination.arrival: wind, route tracking, time to go, decisions and the closed loop."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.coordination.arrival import ArrivalController, Decision, SpeedLimits
from gcs.coordination.routetrack import (
    ArrivalInputError,
    LoiterSpec,
    RouteTrack,
)
from planner.dubins import Pose
from planner.flightpath import FlightPath, Segment, smooth_polyline, straight
from planner.wind import Wind, WindError, groundspeed_m_s

PI = math.pi
NORTH, EAST, SOUTH, WEST = 0.0, PI / 2, PI, 3 * PI / 2
LIMITS = SpeedLimits(18.0, 28.0, 0.5)
CALM = Wind()
# 10 km due north, for decisions with round numbers.
NORTH_10KM = RouteTrack(straight(0.0, 0.0, 0.0, 10_000.0))


def decide(
    required_m_s: float,
    current_level_m_s: float | None,
    *,
    limits: SpeedLimits = LIMITS,
    tolerance_s: float = 0.5,
) -> Decision:
    """Decide at the start of NORTH_10KM in calm air with a target that needs required_m_s."""
    controller = ArrivalController(limits, tolerance_s=tolerance_s)
    return controller.decide(
        NORTH_10KM,
        s_m=0.0,
        now_s=100.0,
        target_s=100.0 + 10_000.0 / required_m_s,
        wind=CALM,
        current_level_m_s=current_level_m_s,
    )


# --- wind and groundspeed -------------------------------------------------------------------


def test_wind_from_west_blows_east() -> None:
    wind = Wind.from_speed_from(5.0, 270.0)
    assert wind.to_east_m_s == pytest.approx(5.0)
    assert wind.to_north_m_s == pytest.approx(0.0, abs=1e-12)
    north_wind = Wind.from_speed_from(3.0, 0.0)  # from the north: blows south
    assert (north_wind.to_east_m_s, north_wind.to_north_m_s) == pytest.approx((0.0, -3.0))
    assert north_wind.speed_m_s == pytest.approx(3.0)
    with pytest.raises(WindError, match="speed_m_s"):
        Wind.from_speed_from(-1.0, 0.0)


@pytest.mark.parametrize(
    ("track_rad", "expected_m_s"),
    [
        (EAST, 30.0),  # tailwind
        (WEST, 20.0),  # headwind
        (NORTH, math.sqrt(25.0**2 - 5.0**2)),  # crosswind: crab, lose the cosine
        (SOUTH, math.sqrt(25.0**2 - 5.0**2)),
        (EAST + PI / 4, 5.0 * math.cos(PI / 4) + math.sqrt(25.0**2 - 12.5)),
    ],
)
def test_groundspeed_known_answers(track_rad: float, expected_m_s: float) -> None:
    wind = Wind(to_east_m_s=5.0)
    speed = groundspeed_m_s(25.0, track_rad, wind)
    assert isinstance(speed, float)
    assert speed == pytest.approx(expected_m_s)


def test_groundspeed_cannot_make_good_the_track() -> None:
    assert groundspeed_m_s(25.0, NORTH, Wind(to_east_m_s=30.0)) == 0.0  # crosswind > airspeed
    assert groundspeed_m_s(10.0, WEST, Wind(to_east_m_s=12.0)) == 0.0  # headwind > airspeed
    assert groundspeed_m_s(10.0, EAST, Wind(to_east_m_s=12.0)) == pytest.approx(22.0)
    tracks = np.array([NORTH, EAST, SOUTH, WEST])
    speeds = groundspeed_m_s(25.0, tracks, Wind(to_east_m_s=30.0))
    assert isinstance(speeds, np.ndarray)
    assert speeds == pytest.approx([0.0, 55.0, 0.0, 0.0])


# --- locate ---------------------------------------------------------------------------------


def hairpin(leg_m: float, radius_m: float) -> FlightPath:
    """``leg_m`` north from the origin, a right half turn of ``radius_m``, ``leg_m`` south."""
    first = Segment(Pose(0.0, 0.0, NORTH), leg_m, "S")
    arc = Segment(first.end, PI * radius_m, "R", radius_m)
    return FlightPath((first, arc, Segment(arc.end, leg_m, "S")))


def arc_route(radius_m: float = 200.0) -> FlightPath:
    """1 km north, a right half turn of ``radius_m``, 1 km south."""
    return hairpin(1000.0, radius_m)


def u_route() -> FlightPath:
    """An out-and-back U: 10 km north, a 150 m right half turn, 10 km south 300 m east."""
    return hairpin(10_000.0, 150.0)


def test_locate_on_a_straight_is_exact_and_reports_the_cross_track() -> None:
    track = RouteTrack(straight(0.0, 0.0, 0.0, 10_000.0), step_m=25.0)
    for s_m in (0.0, 12.3, 4987.6, 9999.9, 10_000.0):
        assert track.locate(0.0, s_m) == pytest.approx((s_m, 0.0), abs=1e-9)
    assert track.locate(-40.0, 1234.5) == pytest.approx((1234.5, 40.0))
    assert track.locate(3.0, -50.0) == pytest.approx((0.0, math.hypot(3.0, 50.0)))  # behind
    assert track.locate(0.0, 10_050.0) == pytest.approx((10_000.0, 50.0))  # past the end


@pytest.mark.parametrize("radius_m", [200.0, 1000.0])
@pytest.mark.parametrize("offset_m", [-60.0, -5.0, 0.0, 5.0, 60.0])
def test_locate_on_an_arc_is_accurate_well_under_a_metre(radius_m: float, offset_m: float) -> None:
    path = arc_route(radius_m)
    track = RouteTrack(path)
    centre_east_m, centre_north_m = radius_m, 1000.0
    for swept_rad in np.linspace(0.01, PI - 0.01, 37):
        true_s_m = 1000.0 + radius_m * swept_rad
        from_centre_m = radius_m + offset_m  # positive: outside the turn
        bearing_rad = 1.5 * PI + swept_rad  # start of the arc is due west of the centre
        east_m = centre_east_m + from_centre_m * math.sin(bearing_rad)
        north_m = centre_north_m + from_centre_m * math.cos(bearing_rad)
        s_m, cross_m = track.locate(east_m, north_m, hint_s_m=true_s_m)
        assert s_m == pytest.approx(true_s_m, abs=0.01)
        assert cross_m == pytest.approx(abs(offset_m), abs=0.01)


def test_locate_hint_keeps_the_leg_flown_on_an_out_and_back() -> None:
    track = RouteTrack(u_route())
    outbound_s_m = 3000.0
    # 160 m east of the outbound leg, 140 m west of the return leg.
    east_m, north_m = 160.0, outbound_s_m
    no_hint_s_m, no_hint_cross_m = track.locate(east_m, north_m)
    return_s_m = 10_000.0 + 150.0 * PI + (10_000.0 - north_m)
    assert no_hint_s_m == pytest.approx(return_s_m)
    assert no_hint_cross_m == pytest.approx(140.0)
    assert track.locate(east_m, north_m, hint_s_m=2900.0) == pytest.approx((outbound_s_m, 160.0))
    # A hint on the return leg finds the return leg.
    assert track.locate(east_m, north_m, hint_s_m=return_s_m + 50.0)[0] == pytest.approx(return_s_m)


def test_locate_searches_everywhere_when_the_window_holds_nothing_close() -> None:
    track = RouteTrack(u_route())
    # On the return leg at north 5 km, with a stale hint at the start: the window
    # (s within 3 km of 0) holds nothing nearer than 2 km, more than window_m / 2.
    s_m, cross_m = track.locate(300.0, 5000.0, hint_s_m=0.0)
    assert s_m == pytest.approx(10_000.0 + 150.0 * PI + 5000.0)
    assert cross_m == pytest.approx(0.0, abs=1e-9)
    # A narrow window: its best is kept within window_m / 2 (5 m < 10 m), else everywhere.
    assert track.locate(5.0, 590.0, hint_s_m=600.0, window_m=20.0) == pytest.approx((590.0, 5.0))
    assert track.locate(5.0, 500.0, hint_s_m=600.0, window_m=20.0) == pytest.approx((500.0, 5.0))


def test_track_exposes_read_only_samples() -> None:
    track = RouteTrack(arc_route(200.0), step_m=25.0)
    s_m = track.sample_s_m
    assert s_m[0] == 0.0
    assert s_m[-1] == pytest.approx(track.length_m)
    assert np.all(np.diff(s_m) > 0.0)
    assert np.max(np.diff(s_m)) <= 25.0 + 1e-9
    pose = track.path.pose_at(float(s_m[50]))
    assert (track.sample_east_m[50], track.sample_north_m[50]) == pytest.approx(
        (pose.east_m, pose.north_m)
    )
    assert track.sample_track_rad[50] == pytest.approx(pose.heading_rad)
    with pytest.raises(ValueError, match="read-only"):
        track.sample_s_m[0] = 1.0


# --- time to go -----------------------------------------------------------------------------


def test_time_to_go_in_calm_air_is_length_over_airspeed() -> None:
    path = arc_route(200.0)
    track = RouteTrack(path)
    assert track.time_to_go_s(0.0, 20.0, CALM) == pytest.approx(path.length_m / 20.0)
    assert track.time_to_go_s(1300.0, 25.0, CALM) == pytest.approx((path.length_m - 1300) / 25)
    assert track.time_to_go_s(path.length_m, 25.0, CALM) == 0.0


def test_time_to_go_includes_loiters_not_yet_flown() -> None:
    path = straight(0.0, 0.0, 0.0, 10_000.0)
    loiters = [
        LoiterSpec(2000.0, 300.0, 2000.0, 300.0, 2, clockwise=True),
        LoiterSpec(6000.0, -250.0, 6000.0, 250.0, 1, clockwise=False, detour_m=1000.0),
    ]
    track = RouteTrack(path, loiters)
    first_m = 2 * PI * 300.0 * 2
    second_m = 2 * PI * 250.0 + 1000.0
    assert track.time_to_go_s(0.0, 20.0, CALM) == pytest.approx(
        (10_000.0 + first_m + second_m) / 20.0
    )
    assert track.time_to_go_s(3000.0, 20.0, CALM, loiters_done=1) == pytest.approx(
        (7000.0 + second_m) / 20.0
    )
    assert track.time_to_go_s(7000.0, 20.0, CALM, loiters_done=2) == pytest.approx(3000 / 20)
    # Part of the loiter in progress flown: a turn and a half of the first, half the detour.
    assert track.time_to_go_s(
        2000.0, 20.0, CALM, loiters_done=0, loiter_flown_m=0.75 * first_m
    ) == pytest.approx((8000.0 + 0.25 * first_m + second_m) / 20.0)
    assert track.time_to_go_s(
        6000.0, 20.0, CALM, loiters_done=1, loiter_flown_m=2 * PI * 250.0 + 500.0
    ) == pytest.approx((4000.0 + 500.0) / 20.0)
    assert track.remaining_m(0.0) == pytest.approx(10_000.0 + first_m + second_m)


def test_time_to_go_in_wind_integrates_the_groundspeed() -> None:
    wind = Wind.from_speed_from(6.0, 200.0)
    airspeed_m_s = 22.0
    path = arc_route(200.0)
    loiter = LoiterSpec(500.0, 400.0, 500.0, 400.0, 3, clockwise=True, detour_m=800.0)
    track = RouteTrack(path, [loiter])
    # Reference: fine midpoint sums over the path (1 m) and the circle (0.05 degree).
    edges_m = np.linspace(0.0, path.length_m, math.ceil(path.length_m) + 1)
    middles_m = 0.5 * (edges_m[:-1] + edges_m[1:])
    tracks = np.array([path.pose_at(float(s)).heading_rad for s in middles_m])
    speeds_m_s = groundspeed_m_s(airspeed_m_s, tracks, wind)
    path_s = float(np.sum(np.diff(edges_m) / speeds_m_s))
    angles = (np.arange(7200) + 0.5) * (2 * PI / 7200)  # every heading once per turn
    circle_s = 3 * float(np.sum((2 * PI * 400.0 / 7200) / groundspeed_m_s(22.0, angles, wind)))
    expected_s = path_s + circle_s + 800.0 / airspeed_m_s
    assert track.time_to_go_s(0.0, airspeed_m_s, wind) == pytest.approx(expected_s, rel=2e-4)
    assert circle_s > 3 * 2 * PI * 400.0 / airspeed_m_s  # wind always costs time on a circle


def test_time_to_go_is_infinite_when_the_wind_is_too_strong() -> None:
    track = RouteTrack(straight(0.0, 0.0, 0.0, 1000.0))
    assert track.time_to_go_s(0.0, 20.0, Wind(to_north_m_s=-20.0)) == math.inf
    assert track.time_to_go_s(0.0, 20.0, Wind(to_east_m_s=21.0)) == math.inf
    looped = RouteTrack(
        straight(0.0, 0.0, 0.0, 1000.0), [LoiterSpec(900.0, 200.0, 900.0, 200.0, 1, True)]
    )
    assert looped.time_to_go_s(0.0, 20.0, Wind(to_north_m_s=25.0)) == math.inf  # can't turn back
    assert looped.time_to_go_s(0.0, 20.0, Wind(to_north_m_s=25.0), loiters_done=1) == (
        pytest.approx(1000.0 / 45.0)
    )


ARC_TRACK = RouteTrack(arc_route(200.0), [LoiterSpec(1000.0, 200.0, 1000.0, 200.0, 1, True)])


@settings(max_examples=50, deadline=None)
@given(
    s_m=st.floats(0.0, 2000.0 + 200.0 * PI),
    speed_m_s=st.floats(0.0, 15.0),
    from_deg=st.floats(0.0, 360.0),
    airspeed_m_s=st.floats(16.0, 30.0),
)
def test_time_to_go_decreases_with_airspeed(
    s_m: float, speed_m_s: float, from_deg: float, airspeed_m_s: float
) -> None:
    track = ARC_TRACK
    wind = Wind.from_speed_from(speed_m_s, from_deg)
    slower_s = track.time_to_go_s(s_m, airspeed_m_s, wind)
    faster_s = track.time_to_go_s(s_m, airspeed_m_s + 0.5, wind)
    assert faster_s <= slower_s


def test_route_track_rejects_bad_loiters() -> None:
    path = straight(0.0, 0.0, 0.0, 1000.0)
    with pytest.raises(ArrivalInputError, match="off the route"):
        RouteTrack(path, [LoiterSpec(1500.0, 0.0, 0.0, 100.0, 1, True)])
    with pytest.raises(ArrivalInputError, match="ordered"):
        RouteTrack(
            path,
            [LoiterSpec(600.0, 0.0, 0.0, 100.0, 1, True), LoiterSpec(500.0, 0, 0, 100.0, 1, True)],
        )
    with pytest.raises(ArrivalInputError, match="radius_m"):
        LoiterSpec(10.0, 0.0, 0.0, 0.0, 1, True)
    with pytest.raises(ArrivalInputError, match="s_m"):
        RouteTrack(path).time_to_go_s(1001.0, 20.0, CALM)


# --- speed levels ---------------------------------------------------------------------------


def test_levels_run_from_min_in_steps_and_always_include_max() -> None:
    assert SpeedLimits(18.0, 20.0, 0.5).levels_m_s == (18.0, 18.5, 19.0, 19.5, 20.0)
    assert SpeedLimits(18.2, 19.5, 0.5).levels_m_s == pytest.approx((18.2, 18.7, 19.2, 19.5))
    limits = SpeedLimits(18.0, 27.8, 0.5)
    assert limits.levels_m_s[-3:] == pytest.approx((27.0, 27.5, 27.8))
    assert limits.nearest_level_m_s(27.7) == 27.8
    assert limits.nearest_level_m_s(27.6) == 27.5
    assert limits.nearest_level_m_s(23.25) == 23.5  # ties go up
    assert limits.nearest_level_m_s(5.0) == 18.0
    assert limits.nearest_level_m_s(math.inf) == 27.8
    with pytest.raises(ArrivalInputError, match="airspeed_max_m_s"):
        SpeedLimits(20.0, 19.0)


def test_period_is_a_fortieth_of_the_time_left_within_half_a_second_and_ten() -> None:
    assert ArrivalController.period_s(4000.0) == 10.0
    assert ArrivalController.period_s(100.0) == 2.5
    assert ArrivalController.period_s(10.0) == 0.5
    assert ArrivalController.period_s(-3.0) == 0.5


# --- decisions ------------------------------------------------------------------------------


def test_required_airspeed_is_remaining_over_time_left() -> None:
    decision = decide(23.74, None)
    assert decision.required_m_s == pytest.approx(23.74, rel=1e-9)
    assert decision.eta_min_s == pytest.approx(100.0 + 10_000.0 / 28.0)
    assert decision.eta_max_s == pytest.approx(100.0 + 10_000.0 / 18.0)
    assert "required 23.74 m/s airspeed over 10.0 km" in decision.reason


def test_required_airspeed_in_wind_arrives_exactly() -> None:
    track = RouteTrack(arc_route(200.0))
    wind = Wind.from_speed_from(8.0, 30.0)
    decision = ArrivalController(LIMITS).decide(
        track, s_m=300.0, now_s=0.0, target_s=150.0, wind=wind, current_level_m_s=None
    )
    assert track.time_to_go_s(300.0, decision.required_m_s, wind) == pytest.approx(150.0)


def test_first_decision_commands_the_nearest_level() -> None:
    decision = decide(23.74, None)
    assert decision.verdict == "on_time"
    assert decision.command_m_s == decision.level_m_s == 23.5
    assert decision.eta_s == pytest.approx(100.0 + 10_000.0 / 23.5)
    assert decision.error_s == pytest.approx(10_000.0 / 23.5 - 10_000.0 / 23.74)
    assert "commanding 23.5 m/s" in decision.reason


def test_holds_the_level_while_required_is_within_a_step() -> None:
    for current_m_s in (23.5, 24.0, 24.2):
        decision = decide(23.74, current_m_s)
        assert decision.verdict == "on_time"
        assert decision.command_m_s is None
        assert decision.level_m_s == current_m_s
        assert decision.error_s == pytest.approx(10_000.0 / current_m_s - 10_000.0 / 23.74)
        assert "keeping" in decision.reason


def test_switches_to_the_nearest_level_when_a_full_step_off() -> None:
    assert decide(23.74, 23.0).command_m_s == 23.5
    assert decide(23.74, 24.5).command_m_s == 23.5
    assert decide(24.3, 23.5).command_m_s == 24.5
    assert decide(18.1, 19.0).command_m_s == 18.0
    assert decide(27.7, 26.5, limits=SpeedLimits(18.0, 27.8)).command_m_s == 27.8


def test_a_level_outside_the_limits_is_always_replaced() -> None:
    decision = decide(27.9, 28.3)
    assert decision.command_m_s == decision.level_m_s == 28.0


def test_late_when_even_max_arrives_beyond_tolerance() -> None:
    decision = decide(30.0, 24.0)
    assert decision.verdict == "late"
    assert decision.command_m_s == decision.level_m_s == 28.0
    assert decision.required_m_s == pytest.approx(30.0)
    late_s = 10_000.0 / 28.0 - 10_000.0 / 30.0
    assert decision.error_s == pytest.approx(late_s)
    assert decision.eta_s == decision.eta_min_s
    assert decision.reason.startswith("late: required 30.00 m/s")
    assert f"arrives {late_s:.1f} s late" in decision.reason
    held = decide(30.0, 28.0)
    assert held.verdict == "late"
    assert held.command_m_s is None
    assert held.level_m_s == 28.0


def test_above_max_within_tolerance_is_on_time_at_max() -> None:
    required_m_s = 10_000.0 / (10_000.0 / 28.0 - 0.3)  # max arrives 0.3 s late
    decision = decide(required_m_s, 24.0)
    assert decision.verdict == "on_time"
    assert decision.command_m_s == 28.0
    assert decision.error_s == pytest.approx(0.3)
    assert "within the 0.5 s tolerance" in decision.reason


def test_early_when_even_min_arrives_beyond_tolerance() -> None:
    decision = decide(15.0, 24.0)
    assert decision.verdict == "early"
    assert decision.command_m_s == decision.level_m_s == 18.0
    early_s = 10_000.0 / 15.0 - 10_000.0 / 18.0
    assert decision.error_s == pytest.approx(-early_s)
    assert decision.eta_s == decision.eta_max_s
    assert decision.required_m_s == pytest.approx(15.0)
    assert f"arrives {early_s:.1f} s early" in decision.reason
    # Far too early: the solve stops at half the minimum.
    very = decide(5.0, 18.0)
    assert very.verdict == "early"
    assert very.command_m_s is None
    assert very.required_m_s == 9.0


def test_a_target_in_the_past_is_unreachable_and_late() -> None:
    controller = ArrivalController(LIMITS)
    decision = controller.decide(
        NORTH_10KM, s_m=0.0, now_s=100.0, target_s=90.0, wind=CALM, current_level_m_s=20.0
    )
    assert decision.required_m_s == math.inf
    assert decision.verdict == "late"
    assert decision.command_m_s == 28.0
    assert "no airspeed up to 56.0 m/s" in decision.reason


def test_wind_too_strong_for_any_airspeed_is_late_with_infinite_eta() -> None:
    decision = ArrivalController(LIMITS).decide(
        NORTH_10KM,
        s_m=0.0,
        now_s=0.0,
        target_s=1000.0,
        wind=Wind(to_north_m_s=-60.0),
        current_level_m_s=None,
    )
    assert decision.verdict == "late"
    assert decision.required_m_s == math.inf
    assert decision.eta_s == decision.eta_min_s == math.inf


def test_arrived_on_time_and_early() -> None:
    controller = ArrivalController(LIMITS)

    def at_end(target_s: float) -> Decision:
        return controller.decide(
            NORTH_10KM,
            s_m=10_000.0,
            now_s=100.0,
            target_s=target_s,
            wind=CALM,
            current_level_m_s=20.0,
        )

    on_time = at_end(100.2)
    assert on_time.verdict == "on_time"
    assert on_time.error_s == pytest.approx(-0.2)
    assert at_end(110.0).verdict == "early"
    assert at_end(99.0).verdict == "late"


@settings(max_examples=150, deadline=None)
@given(
    lo=st.floats(10.0, 30.0),
    span=st.floats(0.0, 20.0),
    step=st.floats(0.1, 3.0),
    s_frac=st.floats(0.0, 1.0),
    time_left_s=st.floats(-100.0, 3000.0),
    wind_m_s=st.floats(0.0, 25.0),
    from_deg=st.floats(0.0, 360.0),
    current=st.one_of(st.none(), st.floats(0.0, 60.0)),
)
def test_commands_stay_on_the_grid_within_the_limits(
    lo: float,
    span: float,
    step: float,
    s_frac: float,
    time_left_s: float,
    wind_m_s: float,
    from_deg: float,
    current: float | None,
) -> None:
    limits = SpeedLimits(lo, lo + span, step)
    decision = ArrivalController(limits).decide(
        ARC_TRACK,
        s_m=s_frac * ARC_TRACK.length_m,
        now_s=1000.0,
        target_s=1000.0 + time_left_s,
        wind=Wind.from_speed_from(wind_m_s, from_deg),
        current_level_m_s=current,
    )
    hi = limits.airspeed_max_m_s
    assert lo - 1e-9 <= decision.level_m_s <= hi + 1e-9
    command = decision.command_m_s
    if command is None:
        assert current is not None
        assert decision.level_m_s == current
    else:
        assert lo <= command <= hi
        k = (command - lo) / step
        assert command == hi or abs(k - round(k)) < 1e-6
        assert current is None or command != current
    assert decision.verdict in ("on_time", "early", "late")


# --- closed loop ----------------------------------------------------------------------------

DT_S = 0.5
LAG_S = 3.0
WIND_270 = Wind.from_speed_from(5.0, 270.0)


def closed_loop_route() -> FlightPath:
    """About 40 km with three Dubins-smoothed corners."""
    points = np.array([(0.0, 0.0), (13e3, 3e3), (21e3, 17e3), (35e3, 16e3)])
    return smooth_polyline(points, 400.0)


def fly(track: RouteTrack, target_s: float, start_m_s: float = 22.0) -> float:
    """Fly the route under the controller; return the arrival time, s.

    Fixed 0.5 s steps; the airspeed follows the command with a 3 s first-order lag; the
    vehicle moves along the path (or a loiter circle) at the true wind groundspeed of its
    track; fixes are located from the true position with the last s as the hint; decisions
    come every ``period_s``.
    """
    controller = ArrivalController(LIMITS)
    path = track.path
    length_m = path.length_m
    decay = math.exp(-DT_S / LAG_S)
    mean_factor = LAG_S / DT_S * (1.0 - decay)  # mean airspeed over a step, exact for the lag
    s_m, now_s, airspeed_m_s = 0.0, 0.0, start_m_s
    command_m_s = level_m_s = start_m_s
    loiters_done, flown_m, entry_rad, in_loiter = 0, 0.0, 0.0, False
    next_decision_s, hint_s_m = 0.0, 0.0
    while now_s < 3 * target_s:
        if now_s >= next_decision_s - 1e-9:
            if not in_loiter:
                pose = path.pose_at(s_m)
                hint_s_m, _ = track.locate(pose.east_m, pose.north_m, hint_s_m=hint_s_m)
            decision = controller.decide(
                track,
                s_m=hint_s_m,
                now_s=now_s,
                target_s=target_s,
                wind=WIND_270,
                current_level_m_s=level_m_s,
                loiters_done=loiters_done,
                loiter_flown_m=flown_m,
            )
            if decision.command_m_s is not None:
                command_m_s = decision.command_m_s
            level_m_s = decision.level_m_s
            next_decision_s = now_s + controller.period_s(target_s - now_s)
        mean_m_s = command_m_s + (airspeed_m_s - command_m_s) * mean_factor
        airspeed_m_s = command_m_s + (airspeed_m_s - command_m_s) * decay
        if in_loiter:
            loiter = track.loiters[loiters_done]
            turn = (1.0 if loiter.clockwise else -1.0) / loiter.radius_m
            ahead_m = 0.5 * DT_S * groundspeed_m_s(mean_m_s, entry_rad + turn * flown_m, WIND_270)
            step_m = DT_S * groundspeed_m_s(
                mean_m_s, entry_rad + turn * (flown_m + ahead_m), WIND_270
            )
            flown_m += step_m
            if flown_m >= loiter.circle_m:
                s_m = loiter.s_m + flown_m - loiter.circle_m
                in_loiter, loiters_done, flown_m = False, loiters_done + 1, 0.0
        else:
            ahead_m = (
                0.5 * DT_S * groundspeed_m_s(mean_m_s, path.pose_at(s_m).heading_rad, WIND_270)
            )
            heading_rad = path.pose_at(min(s_m + ahead_m, length_m)).heading_rad
            speed_m_s = groundspeed_m_s(mean_m_s, heading_rad, WIND_270)
            step_m = DT_S * speed_m_s
            if (
                loiters_done < len(track.loiters)
                and s_m + step_m >= track.loiters[loiters_done].s_m
            ):
                loiter = track.loiters[loiters_done]
                flown_m, in_loiter = s_m + step_m - loiter.s_m, True
                s_m = hint_s_m = loiter.s_m
                entry_rad = path.pose_at(s_m).heading_rad  # the circle is tangent here
            elif s_m + step_m >= length_m:
                return now_s + (length_m - s_m) / speed_m_s
            else:
                s_m += step_m
        now_s += DT_S
    raise AssertionError("never arrived")


@pytest.mark.parametrize("fraction", [0.1, 0.35, 0.6, 0.9])
def test_closed_loop_arrives_on_time_in_wind(fraction: float) -> None:
    track = RouteTrack(closed_loop_route())
    earliest_s = track.time_to_go_s(0.0, LIMITS.airspeed_max_m_s, WIND_270)
    latest_s = track.time_to_go_s(0.0, LIMITS.airspeed_min_m_s, WIND_270)
    target_s = earliest_s + fraction * (latest_s - earliest_s)
    assert fly(track, target_s) == pytest.approx(target_s, abs=0.3)


def test_closed_loop_arrives_on_time_with_a_loiter() -> None:
    path = closed_loop_route()
    track = RouteTrack(path)
    latest_s = track.time_to_go_s(0.0, LIMITS.airspeed_min_m_s, WIND_270)
    # Two clockwise turns of 400 m, tangent to the middle of the long second straight.
    middle = path.segments[2]
    assert middle.turn == "S"
    s_m = path.cumulative_m()[2] + 0.5 * middle.length_m
    pose = path.pose_at(s_m)
    centre_east_m = pose.east_m + 400.0 * math.cos(pose.heading_rad)
    centre_north_m = pose.north_m - 400.0 * math.sin(pose.heading_rad)
    loiter = LoiterSpec(s_m, centre_east_m, centre_north_m, 400.0, 2, clockwise=True)
    looped = RouteTrack(path, [loiter])
    earliest_s = looped.time_to_go_s(0.0, LIMITS.airspeed_max_m_s, WIND_270)
    target_s = earliest_s + 0.85 * (
        looped.time_to_go_s(0.0, LIMITS.airspeed_min_m_s, WIND_270) - earliest_s
    )
    assert target_s > latest_s  # only the loiter makes this target
    assert fly(looped, target_s) == pytest.approx(target_s, abs=0.3)


# -- the flight ahead, loiters spliced in (for the in-flight conflict forecasts) -------------


def test_flight_samples_splice_each_loiter_s_turns_into_the_route() -> None:
    # North 10 km; 2 turns of 300 m clockwise entered at 3 km (centre 300 m east of the
    # route), 1 turn of 200 m anticlockwise with a 400 m detour at 7 km (centre to the west).
    first = LoiterSpec(3_000.0, 300.0, 3_000.0, 300.0, 2, clockwise=True)
    second = LoiterSpec(7_000.0, -200.0, 7_000.0, 200.0, 1, clockwise=False, detour_m=400.0)
    track = RouteTrack(straight(0.0, 0.0, 0.0, 10_000.0), (first, second), step_m=25.0)
    along, east, north = track.flight_samples(0)
    assert (np.diff(along) >= 0.0).all()
    assert along[-1] == pytest.approx(10_000.0 + first.length_m + second.length_m)
    # Before the first loiter the flight is the route; after both, the route shifted by them.
    before = along <= 3_000.0 - 1e-6
    assert np.allclose(east[before], 0.0) and np.allclose(north[before], along[before])
    after = along >= 7_000.0 + first.length_m + second.length_m + 1e-6
    assert np.allclose(north[after], along[after] - first.length_m - second.length_m)
    # In the first loiter's stretch every point is on its circle, going round clockwise
    # (compass bearing from the centre increasing) from the route's point west of the centre.
    u = along - 3_000.0
    on_first = (u >= 0.0) & (u <= first.circle_m)
    assert np.allclose(np.hypot(east[on_first] - 300.0, north[on_first] - 3_000.0), 300.0)
    bearing = np.unwrap(np.arctan2(east[on_first] - 300.0, north[on_first] - 3_000.0))
    assert bearing[0] == pytest.approx(-0.5 * math.pi)
    assert np.allclose(bearing - bearing[0], u[on_first] / 300.0)
    # The second loiter, anticlockwise, then its detour as a stop at the entry point.
    v = along - (7_000.0 + first.length_m)
    on_second = (v >= 0.0) & (v <= second.circle_m)
    angles = np.unwrap(np.arctan2(east[on_second] + 200.0, north[on_second] - 7_000.0))
    assert np.allclose(angles[0] - angles, v[on_second] / 200.0)
    dwell = (v > second.circle_m) & (v <= second.length_m)
    assert np.allclose(east[dwell], 0.0) and np.allclose(north[dwell], 7_000.0)
    # With the first loiter flown, the flight starts its axis at the route's own distance.
    along1, _, north1 = track.flight_samples(1)
    assert along1[-1] == pytest.approx(10_000.0 + second.length_m)
    assert np.allclose(north1[along1 <= 7_000.0], along1[along1 <= 7_000.0])
    assert track.flight_samples(2)[0] is track.sample_s_m
    # Where along the route each flight sample is (its height is the profile's there): the
    # route's own distance (here its north), and a loiter's turns and detour at the loiter.
    route = track.flight_route_s_m(0)
    assert route.shape == along.shape
    turns = on_first | (on_second | dwell)
    assert np.allclose(route[~turns], north[~turns])
    assert np.allclose(route[on_first], 3_000.0) and np.allclose(route[on_second | dwell], 7_000.0)
    assert np.allclose(track.flight_route_s_m(1)[along1 <= 7_000.0], along1[along1 <= 7_000.0])

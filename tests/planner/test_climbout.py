"""planner.climbout: where and when a takeoff's climb-out ends, against the simulated
ArduPlane flying NAV_TAKEOFF; the mission's first waypoint beyond it; the schedule timed from
it, in the forecast wind.

ArduPlane's takeoff (ArduPlane/takeoff.cpp, ArduPlane/commands_logic.cpp ``do_takeoff`` /
``verify_takeoff``): a full-throttle ground roll to the rotate speed, a climb holding the
ground course the roll started on (``steer_state.hold_course_cd``) at the cruise airspeed
until the NAV_TAKEOFF altitude, and only then a turn to the next waypoint, straight at it from
where the aircraft is (``next_WP_loc = prev_WP_loc = current_loc``). The route's
DO_CHANGE_SPEED runs when the takeoff completes (libraries/AP_Mission/AP_Mission.cpp:
``advance_current_nav_cmd`` starts the DO items between the finished NAV item and the next).
ArduPlane SITL V4.7.0-dev climbed 607-828 m in 66-88 s over about 2 km
(``docs/sitl_stub.md``); the simulator's airframe climbs at 9 m/s as it did.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from planner.climbout import MIN_TAKEOFF_ALT_M, climb_out, straight_start_m
from planner.flightpath import smooth_polyline, straight
from planner.mission import MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_WAYPOINT
from planner.plan import plan
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from planner.schedulefile import path_mission
from planner.terrain import build_terrain
from planner.wind import Wind
from sitl_stub.autopilot import Autopilot, ItemReached, Mode
from sitl_stub.items import MissionItem
from sitl_stub.model import AirframeParams, displace_deg, offset_ne_m
from sitl_stub.model import Wind as SimWind

HOME = (45.0, 8.0, 300.0)
REL = 3  # MAV_FRAME_GLOBAL_RELATIVE_ALT


def _sim_climb(height_m: float, wind_m_s: float, from_deg: float) -> tuple[float, float, float]:
    """The simulated ArduPlane's NAV_TAKEOFF to ``height_m`` heading north: when it ended
    (s after arming in AUTO), and how far north and east it was then (m)."""
    params = replace(
        AirframeParams(), airspeed_min_m_s=16.0, airspeed_cruise_m_s=24.0, airspeed_max_m_s=30.0
    )
    ap = Autopilot(
        params=params,
        home_lat_deg=HOME[0],
        home_lon_deg=HOME[1],
        home_alt_m=HOME[2],
        heading_deg=0.0,
        wind=SimWind(wind_m_s, math.radians(from_deg)),
        rng=np.random.default_rng(1),
    )
    far_lat, far_lon = displace_deg(HOME[0], HOME[1], 0.0, 60_000.0, 0.0)
    ap.replace_mission(
        [
            MissionItem(0, 0, MAV_CMD_NAV_WAYPOINT, z=HOME[2]),
            MissionItem(1, REL, MAV_CMD_NAV_TAKEOFF, z=height_m),
            MissionItem(
                2, REL, MAV_CMD_NAV_WAYPOINT, x=round(far_lat * 1e7), y=round(far_lon * 1e7),
                z=height_m,
            ),
        ]
    )  # fmt: skip
    ap.set_mode(Mode.AUTO)
    ap.arm()
    for _ in range(round(600 / 0.1)):
        if any(e == ItemReached(1) for e in ap.step(0.1)):
            break
    north, east = offset_ne_m(HOME[0], HOME[1], HOME[2], ap.state.lat_deg, ap.state.lon_deg)
    return ap.state.time_s, north, east


@pytest.mark.parametrize("height_m", [100.0, 700.0, 1500.0])
@pytest.mark.parametrize(
    ("wind_m_s", "from_deg"), [(0.0, 0.0), (8.0, 0.0), (8.0, 180.0), (7.0, 90.0)]
)
def test_the_climb_out_ends_where_and_when_the_simulated_arduplane_ends_it(
    height_m: float, wind_m_s: float, from_deg: float
) -> None:
    t_s, north_m, east_m = _sim_climb(height_m, wind_m_s, from_deg)
    climb = climb_out(
        straight(0.0, 0.0, 0.0, 60_000.0),
        home_alt_m=HOME[2],
        start_alt_m=HOME[2] + height_m,
        cruise_m_s=24.0,
        rotate_m_s=16.0,
        climb_rate_m_s=9.0,
        turn_radius_m=200.0,
        wind=Wind.from_speed_from(wind_m_s, from_deg),
    )
    assert climb.takeoff_alt_m == height_m
    assert climb.duration_s == pytest.approx(t_s, abs=0.5)
    assert climb.s_m == pytest.approx(north_m, abs=20.0 + 0.01 * north_m)
    assert abs(east_m) < 30.0  # the ground course is held in the cross wind


def test_a_known_climb_matches_arduplane_sitl() -> None:
    """About 700 m at the airframe's 9 m/s: 66-88 s and about 2 km, as ArduPlane SITL."""
    climb = climb_out(
        straight(0.0, 0.0, 0.0, 60_000.0),
        home_alt_m=500.0,
        start_alt_m=1_200.0,
        cruise_m_s=25.0,
        rotate_m_s=18.0,
        climb_rate_m_s=9.0,
        turn_radius_m=200.0,
    )
    assert 66.0 <= climb.duration_s <= 88.0
    assert 1_500.0 <= climb.s_m <= 2_500.0


def test_a_short_straight_start_lowers_the_takeoff_altitude_to_what_fits() -> None:
    """The path turns 2.5 km out: the climb-out ends short of the turn by the margin, and the
    route climbs the rest; a taller climb is not flown past the turn."""
    path = smooth_polyline(np.array([[0.0, 0.0], [0.0, 6_000.0], [6_000.0, 6_000.0]]), 300.0)
    run_m = straight_start_m(path)
    assert 2_000.0 < run_m < 3_100.0
    climb = climb_out(
        path,
        home_alt_m=0.0,
        start_alt_m=1_400.0,
        cruise_m_s=24.0,
        rotate_m_s=16.0,
        climb_rate_m_s=9.0,
        turn_radius_m=300.0,
    )
    assert MIN_TAKEOFF_ALT_M <= climb.takeoff_alt_m < 1_400.0
    assert climb.s_m < climb.first_waypoint_m <= run_m + 1.0
    assert climb.first_waypoint_m - climb.s_m >= 2 * 300.0 - 1e-6


def _high_start(wind: dict[str, float] | None = None) -> dict[str, object]:
    """One vehicle 1,200 m above flat ground at its start, 40 km due east to its goal."""
    doc: dict[str, object] = {
        "area": {
            "origin": {"lat_deg": 45.0, "lon_deg": 8.0},
            "min_east_m": 0, "min_north_m": 0, "width_m": 60_000, "height_m": 20_000,
        },
        "terrain": {"kind": "flat", "elevation_m": 200},
        "separation_m": 300,
        "arrival": {"kind": "simultaneous", "required_s": 3_000},
        "vehicles": [
            {
                "id": "A",
                "start": {"east_m": 5_000, "north_m": 10_000, "alt_m": 1_400},
                "goal": {"east_m": 45_000, "north_m": 10_000, "alt_m": 1_400},
                "speed_min_m_s": 16, "speed_max_m_s": 30, "cruise_speed_m_s": 24,
                "min_turn_radius_m": 200, "max_range_m": 200_000, "takeoff_window_s": [0, 3_000],
            }
        ],
    }  # fmt: skip
    if wind is not None:
        doc["wind"] = wind
    return doc


@pytest.mark.parametrize("wind", [None, {"speed_m_s": 8.0, "from_deg": 270.0}])
def test_the_schedule_times_the_route_from_the_end_of_the_climb_in_the_forecast_wind(
    wind: dict[str, float] | None,
) -> None:
    scenario = parse_scenario(_high_start(wind))
    schedule = build_schedule(scenario, plan(scenario, rng=np.random.default_rng(1)))
    (vs,) = schedule.vehicles
    climb = vs.climb
    assert climb is not None and climb.takeoff_alt_m == pytest.approx(1_200.0)
    first = vs.legs[0]
    assert first.s_start_m == pytest.approx(climb.s_m)
    assert first.t_start_s == pytest.approx(vs.takeoff_s + climb.duration_s)
    # The route is a straight line east: from the climb's end it flies the rest at its leg
    # speeds, true airspeed plus the tail wind (the test's own arithmetic).
    tail = 0.0 if wind is None else wind["speed_m_s"]
    t = first.t_start_s
    for leg in vs.legs:
        tas = leg.speed_m_s * leg.tas_per_eas
        t += (leg.s_end_m - leg.s_start_m) / (tas + tail)
    assert t == pytest.approx(3_000.0, abs=0.5)
    assert vs.arrival_s == pytest.approx(3_000.0, abs=1e-3)


def test_the_mission_has_no_waypoint_inside_the_climb_out() -> None:
    scenario = parse_scenario(_high_start({"speed_m_s": 8.0, "from_deg": 90.0}))
    schedule = build_schedule(scenario, plan(scenario, rng=np.random.default_rng(1)))
    (vs,) = schedule.vehicles
    assert vs.climb is not None
    mission = path_mission(schedule, vs, build_terrain(scenario))
    takeoff = mission.items[1]
    assert takeoff.command == MAV_CMD_NAV_TAKEOFF
    assert takeoff.z == pytest.approx(vs.climb.takeoff_alt_m, abs=0.01)
    first = mission.items[mission.first_route_seq :]
    s_first = next(
        s for it, s in zip(first, mission.item_s_m[mission.first_route_seq :], strict=True)
        if it.command == MAV_CMD_NAV_WAYPOINT
    )  # fmt: skip
    assert s_first is not None and s_first >= vs.climb.first_waypoint_m

"""NAV_LOITER_TURNS after a route waypoint, flown by the autopilot as ArduPlane flies it
(ArduPlane/navigation.cpp ``update_loiter``: straight at the loiter point while farther than
3 radii, then the L1 loiter; commands_logic.cpp ``verify_loiter_turns``: turns counted from
the circle; mode_loiter.cpp ``isHeadingLinedUp``: out once the course points at the next
waypoint), adds to the route what the planner times it with
(:func:`planner.loiterflight.loiter_flight`): the ground flown from the loiter's start to a
point on the route past it, less the route and the whole turns, within 150 m (7 s)."""

from __future__ import annotations

import math

import pytest

from planner.loiterflight import loiter_flight
from sitl_stub.autopilot import Autopilot, Mode
from sitl_stub.model import offset_ne_m
from tests.sitl_stub.test_autopilot import LOITER_TURNS, WP, at, home_item, item, make, run, takeoff

R = 250.0
WAYPOINT_N = 3000.0
"""The route runs north along east 0; the loiter follows its waypoint at north 3 km."""


def _north_east(ap: Autopilot) -> tuple[float, float]:
    lat, lon = at(0.0, 0.0)
    n, e = offset_ne_m(lat, lon, 0.0, ap.state.lat_deg, ap.state.lon_deg)
    return n, e


def _added_m(centre_n: float, centre_e: float, clockwise: bool, turns: int = 2) -> float:
    """Fly the mission; the ground flown from the start of the loiter item to 1 km past both
    the waypoint and the circle, less that stretch of the route and the whole turns, m."""
    ap = make()
    mission = [
        home_item(),
        takeoff(1, 60.0),
        item(2, WP, 1000.0, 0.0, 100.0),
        item(3, WP, WAYPOINT_N, 0.0, 100.0),
        item(4, LOITER_TURNS, centre_n, centre_e, 100.0, p1=turns, p3=R if clockwise else -R, p4=1),
        item(5, WP, WAYPOINT_N + 6000.0, 0.0, 100.0),
    ]
    ap.replace_mission(mission)
    assert ap.set_mode(Mode.AUTO) and ap.arm() == (True, "")
    run(ap, 600.0, until=lambda a: a.current_seq == 4)
    assert ap.current_seq == 4
    start_n, _ = here = _north_east(ap)
    end_n = max(WAYPOINT_N, centre_n + R) + 1000.0
    flown = 0.0
    for _ in range(20_000):
        run(ap, 0.5)
        now = _north_east(ap)
        flown += math.hypot(now[0] - here[0], now[1] - here[1])
        here = now
        if ap.current_seq == 5 and here[0] >= end_n:
            break
    assert ap.current_seq == 5 and here[0] >= end_n
    return flown - (end_n - start_n) - turns * 2.0 * math.pi * R


@pytest.mark.parametrize(
    ("centre_n", "centre_e", "clockwise"),
    [
        pytest.param(WAYPOINT_N - 1148.0, 0.0, True, id="on-the-route-behind"),
        pytest.param(WAYPOINT_N - 1148.0, 0.0, False, id="on-the-route-behind-ccw"),
        pytest.param(WAYPOINT_N, R, True, id="tangent"),
        pytest.param(WAYPOINT_N, -R, False, id="tangent-ccw"),
        pytest.param(WAYPOINT_N - 139.0, 0.0, True, id="waypoint-inside"),
        # The waypoint 58 m past the centre, reached 80-odd m before it: the item starts behind
        # the centre, the turns counted from there (the UAV3 loiter of the quarter-scale team).
        pytest.param(WAYPOINT_N - 58.0, -3.0, True, id="started-behind-the-centre"),
        pytest.param(WAYPOINT_N + 1000.0, 0.0, True, id="ahead"),
        pytest.param(WAYPOINT_N - 600.0, 400.0, True, id="aside-behind"),
    ],
)
def test_a_loiter_adds_what_the_planner_times_it_with(
    centre_n: float, centre_e: float, clockwise: bool
) -> None:
    model = loiter_flight(0.0, WAYPOINT_N, 0.0, centre_e, centre_n, R, clockwise=clockwise)
    assert _added_m(centre_n, centre_e, clockwise) == pytest.approx(model.added_m, abs=150.0)

"""AUTO takeoff as ArduPlane flies it: hold the roll's ground course, climb out, then turn."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from sitl_stub.autopilot import ItemReached, Text
from sitl_stub.model import AirframeParams, Wind
from tests.sitl_stub.test_autopilot import (
    REL,
    WP,
    home_item,
    item,
    make,
    run,
    takeoff,
)


def test_takeoff_holds_ground_course_and_climbs_about_9_m_s_then_turns() -> None:
    """Follows ArduPlane/takeoff.cpp and ArduPlane/commands_logic.cpp (verify_takeoff: hold
    the ground course of the takeoff roll, steer_state.hold_course_cd, until the takeoff
    altitude; then next_WP_loc = prev_WP_loc = current_loc). ArduPlane SITL V4.7.0-dev took
    66-88 s and about 2 km to climb 607-828 m: about 9 m/s."""
    ap = make(Wind(6.0, math.radians(270.0)))  # crosswind from the west on a northbound roll
    ap.replace_mission([home_item(), takeoff(1, 700.0), item(2, WP, 0.0, 6000.0, 700.0, frame=REL)])
    assert ap.set_mode(ap.mode.AUTO)
    assert ap.arm() == (True, "")
    trace = run(ap, 200.0, until=lambda a: a.current_seq == 2)
    done_s = trace.time_of(ItemReached(1))
    liftoff = next(s for s in trace.states if not s.on_ground)
    climb = [s for s in trace.states if s.time_s <= done_s]
    assert 66.0 <= done_s - liftoff.time_s <= 88.0  # 700 m at 8-10.6 m/s
    roll = [math.degrees(s.course_rad) for s in climb if s.on_ground and s.groundspeed_m_s > 5.0]
    # In the air the crosswind drifts it off at first; the course hold brings it back.
    held = [math.degrees(s.course_rad) for s in climb if s.time_s > liftoff.time_s + 15.0]
    assert max(abs((c + 180.0) % 360.0 - 180.0) for c in roll + held) < 2.0  # due north
    end = climb[-1]
    north = (end.lat_deg - liftoff.lat_deg) * 111_000.0
    assert 1500.0 <= north <= 2600.0
    assert any(t.startswith("Takeoff complete at ") for t in trace.texts())
    # Only then does it turn east, from where it is.
    later = run(ap, 30.0)
    assert math.degrees(later.states[-1].course_rad) == pytest.approx(90.0, abs=20.0)
    assert not any(isinstance(e, Text) and "Takeoff" in e.text for _, e in later.events)


def test_takeoff_climb_rate_is_a_parameter() -> None:
    """AirframeParams.takeoff_climb_rate_m_s=4 gives the previous, slower climb-out."""
    ap = make(params=replace(AirframeParams(), takeoff_climb_rate_m_s=4.0))
    ap.replace_mission([home_item(), takeoff(1, 200.0), item(2, WP, 3000.0, 0.0, 200.0)])
    assert ap.set_mode(ap.mode.AUTO)
    assert ap.arm() == (True, "")
    trace = run(ap, 200.0, until=lambda a: a.current_seq == 2)
    liftoff = next(s for s in trace.states if not s.on_ground)
    assert trace.time_of(ItemReached(1)) - liftoff.time_s > 45.0  # 200 m at <= 4 m/s

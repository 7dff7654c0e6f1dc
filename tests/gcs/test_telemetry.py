"""Telemetry reducer: pymavlink messages in, VehicleState out; known answers from pyproj."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
from typing import Any

import pyproj
import pytest
from hypothesis import assume, example, given
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.mavlink.commands import arm, set_message_interval, set_mode
from gcs.mavlink.link import Link
from gcs.mavlink.modes import mode_number
from gcs.mavlink.telemetry import (
    REBOOT_BACKSTEP_S,
    HomePosition,
    StatusText,
    TelemetryReducer,
    VehicleState,
    track_velocity_ne_m_s,
)
from sitl_stub.api import Home, SimTeam
from sitl_stub.model import Wind

GEOD = pyproj.Geod(ellps="WGS84")
APM = int(mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA)
PX4 = int(mavlink2.MAV_AUTOPILOT_PX4)
CUSTOM = int(mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
ARMED = int(mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)


def wire(msg: Any, src: tuple[int, int] = (1, 1)) -> Any:
    """``msg`` as a receiver sees it: packed by ``src`` and decoded again."""
    mav = mavlink2.MAVLink(None, srcSystem=src[0], srcComponent=src[1])
    decoded = mavlink2.MAVLink(None).parse_buffer(msg.pack(mav))
    assert decoded is not None and len(decoded) == 1
    return decoded[0]


def heartbeat(
    custom: int = 10,
    base: int = CUSTOM | ARMED,
    autopilot: int = APM,
    src: tuple[int, int] = (1, 1),
) -> Any:
    return wire(
        mavlink2.MAVLink_heartbeat_message(
            mavlink2.MAV_TYPE_FIXED_WING, autopilot, base, custom, mavlink2.MAV_STATE_ACTIVE, 3
        ),
        src,
    )


def gpi(
    t_ms: int,
    lat: float,
    lon: float,
    alt_m: float = 684.0,
    rel_m: float = 100.0,
    vn: float = 0.0,
    ve: float = 0.0,
    vd: float = 0.0,
    hdg_cdeg: int = 65535,
) -> Any:
    return wire(
        mavlink2.MAVLink_global_position_int_message(
            t_ms,
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt_m * 1000),
            round(rel_m * 1000),
            round(vn * 100),
            round(ve * 100),
            round(vd * 100),
            hdg_cdeg,
        )
    )


def vfr(
    airspeed: float = 25.0,
    groundspeed: float = 24.0,
    heading: int = 90,
    throttle: int = 50,
    climb: float = 0.5,
) -> Any:
    return wire(
        mavlink2.MAVLink_vfr_hud_message(airspeed, groundspeed, heading, throttle, 684.0, climb)
    )


def sys_status(battery: int = 80, mv: int = 12600, ca: int = 1000) -> Any:
    return wire(
        mavlink2.MAVLink_sys_status_message(0, 0, 0, 100, mv, ca, battery, 0, 0, 0, 0, 0, 0)
    )


def feed(r: TelemetryReducer, *msgs: Any, rx: float = 0.0) -> VehicleState:
    for m in msgs:
        r.update(m, rx)
    return r.state


def straight_track(
    lat: float, lon: float, bearing_deg: float, speed_m_s: float, n: int, dt_s: float = 0.5
) -> list[Any]:
    """GLOBAL_POSITION_INT fixes along a geodesic, from pyproj (independent of the code)."""
    out = []
    for i in range(n):
        lon_i, lat_i, _ = GEOD.fwd(lon, lat, bearing_deg, speed_m_s * dt_s * i)
        out.append(gpi(10_000 + round(i * dt_s * 1000), lat_i, lon_i))
    return out


# -- basics -----------------------------------------------------------------------------------


def test_fresh_state_knows_nothing() -> None:
    s = TelemetryReducer(1).state
    assert s.system_id == 1
    assert s.lat_deg is None and s.mode is None and s.armed is None
    assert s.history == () and s.statustexts == () and dict(s.rx_times) == {}
    assert (s.received, s.malformed, s.stale, s.ignored) == (0, 0, 0, 0)
    assert s.heartbeat_age_s(5.0) is None and not s.link_ok(5.0)
    assert s.vehicle_utc_s(5.0) is None
    assert s.groundspeed_along_track_m_s(5.0, 0.0) is None and s.track_speed_m_s(5.0) is None


def test_state_is_frozen_and_cached_until_next_update() -> None:
    r = TelemetryReducer(1)
    r.update(heartbeat(), 1.0)
    a = r.state
    assert r.state is a
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.mode = "MANUAL"  # type: ignore[misc]
    r.update(heartbeat(custom=5), 2.0)
    assert r.state is not a and a.mode == "AUTO" and r.state.mode == "FBWA"


def test_heartbeat_gives_mode_armed_and_ids() -> None:
    s = feed(TelemetryReducer(1), heartbeat(custom=15, base=CUSTOM | ARMED), rx=12.5)
    assert s.mode == "GUIDED" and s.armed is True
    assert (s.base_mode, s.custom_mode) == (CUSTOM | ARMED, 15)
    assert s.mav_type == mavlink2.MAV_TYPE_FIXED_WING and s.autopilot == APM
    assert s.system_status == mavlink2.MAV_STATE_ACTIVE
    assert s.last_heartbeat_rx_s == 12.5
    s2 = feed(TelemetryReducer(1), heartbeat(custom=mode_number("AUTO.RTL", PX4), autopilot=PX4))
    assert s2.mode == "AUTO.RTL"
    s3 = feed(TelemetryReducer(1), heartbeat(custom=9, base=CUSTOM))
    assert s3.mode == "MODE(9)" and s3.armed is False


def test_heartbeats_from_other_systems_components_or_non_autopilots_are_ignored() -> None:
    r = TelemetryReducer(1)
    feed(r, heartbeat(custom=10))
    s = feed(
        r,
        heartbeat(custom=0, src=(2, 1)),
        heartbeat(custom=0, src=(255, 190)),
        heartbeat(custom=0, src=(1, 154)),
        heartbeat(custom=0, autopilot=int(mavlink2.MAV_AUTOPILOT_INVALID)),
    )
    assert s.mode == "AUTO"
    assert s.ignored == 4 and s.received == 2


def test_link_health_from_heartbeat_age() -> None:
    s = feed(TelemetryReducer(1), heartbeat(), rx=100.0)
    assert s.heartbeat_age_s(101.0) == pytest.approx(1.0)
    assert s.link_ok(102.9) and s.link_ok(103.0)
    assert not s.link_ok(103.1)
    assert s.link_ok(104.0, timeout_s=5.0)


def test_mode_and_armed_are_unknown_once_the_link_is_down_and_kept_as_its_last_word() -> None:
    s = feed(TelemetryReducer(1), heartbeat(custom=11, base=CUSTOM | ARMED), rx=100.0)
    assert s.mode_now(103.0) == ("RTL", True)
    assert s.mode_now(103.1) == (None, None)  # three heartbeats missed: not known now
    assert (s.mode, s.armed) == ("RTL", True)  # what it last said
    assert s.mode_now(104.0, timeout_s=5.0) == ("RTL", True)
    assert TelemetryReducer(1).state.mode_now(0.0) == (None, None)


def test_global_position_int_units() -> None:
    s = feed(
        TelemetryReducer(1),
        gpi(5000, -35.3612345, 149.1654321, 700.25, 116.25, 12.34, -5.67, -1.5, 27099),
        rx=3.0,
    )
    assert s.lat_deg == pytest.approx(-35.3612345, abs=1e-9)
    assert s.lon_deg == pytest.approx(149.1654321, abs=1e-9)
    assert s.alt_amsl_m == pytest.approx(700.25) and s.alt_rel_m == pytest.approx(116.25)
    assert (s.vn_m_s, s.ve_m_s, s.vd_m_s) == pytest.approx((12.34, -5.67, -1.5))
    assert s.heading_deg == pytest.approx(270.99)
    assert s.position_time_boot_s == pytest.approx(5.0)
    assert s.last_position_rx_s == 3.0
    assert s.malformed == 0
    (sample,) = s.history
    assert sample.time_boot_s == pytest.approx(5.0)
    assert sample.groundspeed_m_s == pytest.approx(math.hypot(12.34, 5.67))


def test_vfr_hud_units() -> None:
    s = feed(TelemetryReducer(1), vfr(26.5, 24.25, 359, 75, -1.25))
    assert (s.airspeed_m_s, s.groundspeed_m_s, s.climb_m_s) == pytest.approx((26.5, 24.25, -1.25))
    assert s.heading_deg == 359.0 and s.throttle_pct == 75


def test_wind_direction_normalised_to_from_compass() -> None:
    s = feed(TelemetryReducer(1), wire(mavlink2.MAVLink_wind_message(-90.0, 7.5, 0.25)))
    assert s.wind_from_deg == pytest.approx(270.0)
    assert s.wind_speed_m_s == pytest.approx(7.5) and s.wind_vertical_m_s == pytest.approx(0.25)


def test_sys_status_battery() -> None:
    r = TelemetryReducer(1)
    s = feed(r, sys_status(80, 12600, 1050))
    assert s.battery_remaining_pct == 80
    assert s.voltage_v == pytest.approx(12.6) and s.current_a == pytest.approx(10.5)
    s = feed(r, sys_status(-1, 65535, -1))
    assert s.battery_remaining_pct is None and s.voltage_v is None and s.current_a is None
    assert s.malformed == 0


def test_gps_raw_int_fix_and_satellites() -> None:
    def raw(fix: int, sats: int) -> Any:
        return wire(mavlink2.MAVLink_gps_raw_int_message(0, fix, 0, 0, 0, 100, 100, 0, 0, sats))

    r = TelemetryReducer(1)
    s = feed(r, raw(3, 12))
    assert (s.gps_fix_type, s.satellites) == (3, 12)
    s = feed(r, raw(6, 255))
    assert (s.gps_fix_type, s.satellites) == (6, None)
    s = feed(r, raw(42, 9))
    assert s.gps_fix_type == 6 and s.satellites == 9 and s.malformed == 1


def test_system_time_and_vehicle_utc_extrapolation() -> None:
    r = TelemetryReducer(1)
    utc = 1_704_067_200.25
    s = feed(r, wire(mavlink2.MAVLink_system_time_message(round(utc * 1e6), 61_500)), rx=50.0)
    assert s.utc_s == pytest.approx(utc) and s.time_boot_s == pytest.approx(61.5)
    assert s.vehicle_utc_s(50.0) == pytest.approx(utc)
    assert s.vehicle_utc_s(52.75) == pytest.approx(utc + 2.75)
    s = feed(r, wire(mavlink2.MAVLink_system_time_message(0, 62_500)), rx=51.0)
    assert s.utc_s is None and s.vehicle_utc_s(51.0) is None  # no GPS time
    assert s.time_boot_s == pytest.approx(62.5)


def test_nav_controller_output() -> None:
    msg = mavlink2.MAVLink_nav_controller_output_message(0.0, 0.0, -90, 450, 1234, 0.0, 0.0, -3.5)
    s = feed(TelemetryReducer(1), wire(msg))
    assert s.nav_bearing_deg == 270.0 and s.target_bearing_deg == 90.0
    assert s.wp_dist_m == 1234.0 and s.xtrack_error_m == pytest.approx(-3.5)


def test_mission_current_and_items_reached() -> None:
    r = TelemetryReducer(1)
    s = feed(
        r,
        wire(mavlink2.MAVLink_mission_current_message(3, 7, 3, 1)),
        wire(mavlink2.MAVLink_mission_item_reached_message(1)),
        wire(mavlink2.MAVLink_mission_item_reached_message(2)),
        wire(mavlink2.MAVLink_mission_item_reached_message(2)),
    )
    assert (s.mission_current_seq, s.mission_total, s.mission_state) == (3, 7, 3)
    assert s.items_reached == frozenset({1, 2}) and s.last_reached == 2
    r.clear_reached()
    assert r.state.items_reached == frozenset() and r.state.last_reached is None


def test_home_position() -> None:
    msg = mavlink2.MAVLink_home_position_message(
        -353600000, 1491600000, 584000, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0, 0
    )
    s = feed(TelemetryReducer(1), wire(msg))
    assert s.home == HomePosition(pytest.approx(-35.36), pytest.approx(149.16), 584.0)


def test_statustexts_are_kept_bounded_and_chunks_joined() -> None:
    r = TelemetryReducer(1, statustext_len=3)
    long_text = "Mission: 7 WP " + "x" * 60  # 74 characters: two chunks
    chunks = [long_text[:50].encode(), long_text[50:].encode()]
    msgs = [wire(mavlink2.MAVLink_statustext_message(6, b"one"))]
    msgs += [wire(mavlink2.MAVLink_statustext_message(4, c, 9, i)) for i, c in enumerate(chunks)]
    s = feed(r, *msgs, rx=2.0)
    assert s.statustexts == (StatusText(6, "one", 2.0), StatusText(4, long_text, 2.0))
    for i in range(5):
        r.update(wire(mavlink2.MAVLink_statustext_message(6, f"t{i}".encode())), 3.0 + i)
    assert [t.text for t in r.state.statustexts] == ["t2", "t3", "t4"]


def test_rx_times_per_message_type() -> None:
    r = TelemetryReducer(1)
    r.update(heartbeat(), 1.0)
    r.update(vfr(), 2.0)
    r.update(wire(mavlink2.MAVLink_attitude_message(0, 0, 0, 0, 0, 0, 0)), 3.0)
    s = r.state
    assert dict(s.rx_times) == {"HEARTBEAT": 1.0, "VFR_HUD": 2.0, "ATTITUDE": 3.0}
    assert s.message_age_s("VFR_HUD", 4.5) == pytest.approx(2.5)
    assert s.message_age_s("WIND", 4.5) is None


# -- malformed and unknown values -------------------------------------------------------------


def test_nan_airspeed_keeps_previous_value_and_counts_malformed() -> None:
    r = TelemetryReducer(1)
    feed(r, vfr(airspeed=25.0, groundspeed=24.0))
    s = feed(r, vfr(airspeed=math.nan, groundspeed=30.0))
    assert s.airspeed_m_s == pytest.approx(25.0)
    assert s.groundspeed_m_s == pytest.approx(30.0)  # the valid fields still update
    assert s.malformed == 1
    s = feed(r, vfr(climb=math.inf), vfr(throttle=150), vfr(heading=-5))
    assert s.climb_m_s == pytest.approx(0.5) and s.throttle_pct == 50 and s.heading_deg == 90.0
    assert s.malformed == 4


def test_latitude_out_of_range_keeps_previous_position() -> None:
    r = TelemetryReducer(1)
    feed(r, gpi(1000, -35.0, 149.0))
    s = feed(r, gpi(1500, 95.0, 149.0, vn=3.0))
    assert (s.lat_deg, s.lon_deg) == pytest.approx((-35.0, 149.0))
    assert s.malformed == 1 and len(s.history) == 1
    assert s.vn_m_s == pytest.approx(3.0)


def test_unknown_heading_keeps_heading_from_vfr_hud() -> None:
    r = TelemetryReducer(1)
    feed(r, vfr(heading=123))
    s = feed(r, gpi(1000, -35.0, 149.0, hdg_cdeg=65535))
    assert s.heading_deg == 123.0 and s.malformed == 0
    s = feed(r, gpi(1500, -35.0, 149.0, hdg_cdeg=40000))
    assert s.heading_deg == 123.0 and s.malformed == 1


def test_zero_position_means_no_fix_yet() -> None:
    s = feed(TelemetryReducer(1), gpi(1000, 0.0, 0.0))
    assert s.lat_deg is None and s.history == () and s.malformed == 0


def test_battery_out_of_range_keeps_previous_value() -> None:
    r = TelemetryReducer(1)
    feed(r, sys_status(battery=70))
    s = feed(r, sys_status(battery=120))
    assert s.battery_remaining_pct == 70 and s.malformed == 1


def test_wind_nan_keeps_previous_value() -> None:
    r = TelemetryReducer(1)
    feed(r, wire(mavlink2.MAVLink_wind_message(45.0, 5.0, 0.0)))
    s = feed(r, wire(mavlink2.MAVLink_wind_message(math.nan, 5.0, 0.0)))
    assert s.wind_from_deg == pytest.approx(45.0) and s.malformed == 1


@given(
    airspeed=st.floats(width=32),
    groundspeed=st.floats(width=32),
    climb=st.floats(width=32),
    heading=st.integers(-32768, 32767),
    throttle=st.integers(0, 65535),
)
@example(airspeed=math.nan, groundspeed=-1.0, climb=math.inf, heading=400, throttle=101)
def test_vfr_hud_never_corrupts_state(
    airspeed: float, groundspeed: float, climb: float, heading: int, throttle: int
) -> None:
    r = TelemetryReducer(1)
    good = feed(r, vfr())
    s = feed(r, vfr(airspeed, groundspeed, heading, throttle, climb))
    for value in (s.airspeed_m_s, s.groundspeed_m_s, s.climb_m_s, s.heading_deg):
        assert value is not None and math.isfinite(value)
    assert s.airspeed_m_s is not None and s.airspeed_m_s >= 0
    assert s.heading_deg is not None and 0 <= s.heading_deg < 360
    assert s.throttle_pct is not None and 0 <= s.throttle_pct <= 100
    valid = (
        0 <= airspeed <= 1000
        and 0 <= groundspeed <= 1000
        and -1000 <= climb <= 1000
        and 0 <= heading <= 360
        and throttle <= 100
    )
    assert s.malformed == (0 if valid else 1)
    if not valid and not 0 <= airspeed <= 1000:
        assert s.airspeed_m_s == good.airspeed_m_s


@given(lat_i=st.integers(-(2**31), 2**31 - 1), lon_i=st.integers(-(2**31), 2**31 - 1))
def test_position_is_always_a_valid_coordinate(lat_i: int, lon_i: int) -> None:
    r = TelemetryReducer(1)
    msg = wire(mavlink2.MAVLink_global_position_int_message(1000, lat_i, lon_i, 0, 0, 0, 0, 0, 0))
    s = feed(r, msg)
    if s.lat_deg is not None:
        assert -90 <= s.lat_deg <= 90 and -180 <= s.lon_deg <= 180  # type: ignore[operator]
    valid = abs(lat_i) <= 900_000_000 and abs(lon_i) <= 1_800_000_000
    assert s.malformed == (0 if valid or (lat_i == 0 and lon_i == 0) else 1)


# -- ordering on the vehicle's clock ----------------------------------------------------------


def test_reordered_or_duplicated_position_is_dropped_as_stale() -> None:
    r = TelemetryReducer(1)
    feed(r, gpi(2000, -35.0, 149.0), gpi(2500, -35.001, 149.0))
    s = feed(r, gpi(2000, -35.0, 149.0), gpi(2500, -35.001, 149.0))  # late copies
    assert s.lat_deg == pytest.approx(-35.001)
    assert s.stale == 2 and len(s.history) == 2


def test_reboot_clears_history() -> None:
    r = TelemetryReducer(1)
    feed(r, *straight_track(-35.0, 149.0, 0.0, 20.0, 40))  # up to t = 29.5 s
    s = feed(r, gpi(1000, -35.1, 149.0))  # back by much more than REBOOT_BACKSTEP_S
    assert REBOOT_BACKSTEP_S < 29.5 - 1.0
    assert len(s.history) == 1 and s.lat_deg == pytest.approx(-35.1) and s.stale == 0


# -- speed estimates ---------------------------------------------------------------------------


def test_straight_track_at_25_m_s_gives_25_along_track_and_0_across() -> None:
    r = TelemetryReducer(1)
    s = feed(r, *straight_track(-35.36, 149.16, 60.0, 25.0, 21))
    assert s.groundspeed_along_track_m_s(5.0, 60.0) == pytest.approx(25.0, abs=0.01)
    assert s.groundspeed_along_track_m_s(5.0, 150.0) == pytest.approx(0.0, abs=0.01)
    assert s.groundspeed_along_track_m_s(5.0, 240.0) == pytest.approx(-25.0, abs=0.01)
    assert s.track_speed_m_s(5.0) == pytest.approx(25.0, abs=0.01)


def test_speed_estimate_uses_vehicle_time_not_receive_time() -> None:
    r = TelemetryReducer(1)
    jitter = [0.0, 0.31, 0.02, 0.45, 0.0, 0.2, 0.6, 0.05, 0.0, 0.33, 0.1]
    for i, msg in enumerate(straight_track(10.0, 20.0, 0.0, 30.0, 11)):
        r.update(msg, 100.0 + 0.5 * i + jitter[i])
    assert r.state.groundspeed_along_track_m_s(10.0, 0.0) == pytest.approx(30.0, abs=0.01)


def test_window_selects_recent_samples_only() -> None:
    r = TelemetryReducer(1)
    slow = straight_track(0.0, 0.0, 90.0, 15.0, 21)  # t = 10 .. 20 s
    last = slow[-1]
    fast = []
    for i in range(1, 21):  # then 30 m/s for 10 s, continuing east
        lon, lat, _ = GEOD.fwd(last.lon * 1e-7, last.lat * 1e-7, 90.0, 30.0 * 0.5 * i)
        fast.append(gpi(20_000 + 500 * i, lat, lon))
    s = feed(r, *slow, *fast)
    assert s.groundspeed_along_track_m_s(5.0, 90.0) == pytest.approx(30.0, abs=0.01)
    whole = s.groundspeed_along_track_m_s(100.0, 90.0)
    assert whole is not None and 15.0 < whole < 30.0


def test_track_speed_follows_a_turn_where_speed_made_good_does_not() -> None:
    r = TelemetryReducer(1)
    north = straight_track(-35.0, 149.0, 0.0, 20.0, 11)  # 100 m north in 5 s
    corner = north[-1]
    east = []
    for i in range(1, 11):  # then 100 m east in 5 s
        lon, lat, _ = GEOD.fwd(corner.lon * 1e-7, corner.lat * 1e-7, 90.0, 20.0 * 0.5 * i)
        east.append(gpi(15_000 + 500 * i, lat, lon))
    s = feed(r, *north, *east)
    assert s.track_speed_m_s(10.0) == pytest.approx(20.0, abs=0.02)
    v = s.track_velocity_ne_m_s(10.0)
    assert v is not None and math.hypot(*v) < 20.0 * 0.9


def test_too_few_samples_or_bad_window() -> None:
    r = TelemetryReducer(1)
    s = feed(r, gpi(1000, 1.0, 1.0))
    assert s.track_speed_m_s(5.0) is None
    with pytest.raises(ValueError, match="window_s"):
        s.track_speed_m_s(0.0)
    with pytest.raises(ValueError, match="window_s"):
        track_velocity_ne_m_s(s.history, math.nan)


@given(
    lat=st.floats(-70.0, 70.0),
    lon=st.floats(-180.0, 180.0),
    bearing=st.floats(0.0, 360.0, exclude_max=True),
    speed=st.floats(5.0, 60.0),
)
@example(lat=0.0, lon=179.9999, bearing=90.0, speed=30.0)  # across the antimeridian
def test_along_and_across_track_on_any_straight_track(
    lat: float, lon: float, bearing: float, speed: float
) -> None:
    assume(abs(lon) < 180.0)
    s = feed(TelemetryReducer(1), *straight_track(lat, lon, bearing, speed, 11))
    assert s.groundspeed_along_track_m_s(5.0, bearing) == pytest.approx(speed, abs=0.02)
    assert s.groundspeed_along_track_m_s(5.0, bearing + 90.0) == pytest.approx(0.0, abs=0.02)
    assert s.track_speed_m_s(5.0) == pytest.approx(speed, abs=0.02)


# -- loopback: telemetry of a live stub vehicle against its true state -------------------------


async def test_loopback_state_matches_stub_true_state() -> None:
    """The reducer's state against the simulator's truth, with the simulator's clock stopped
    once the aircraft climbs (so that the truth holds still while the last fixes arrive: how
    busy the machine is changes how long that takes, not what is compared)."""
    wind = Wind(speed_m_s=5.0, from_rad=math.radians(250.0))
    async with (
        asyncio.timeout(30.0),
        SimTeam.start(
            homes=[Home(-35.36, 149.16, 584.0, 30.0)],
            tcp_base=0,
            speedup=20,
            wind=wind,
            wind_estimate_error=False,  # WIND is then the true wind, to check it against
            run=False,
        ) as team,
        Link.open(f"tcp:127.0.0.1:{team.ports[0]}", system_id=255, component_id=190) as link,
    ):
        # The truth at every simulator step: the speeds the reducer averages over a second
        # are compared with the truth's over the same second (it accelerates as it climbs).
        flown: list[tuple[float, float, float]] = []  # (time s, ground speed m/s, course rad)

        def sample() -> None:
            t = team.vehicles[0].true_state
            flown.append((t.time_s, t.groundspeed_m_s, t.course_rad))

        team.server.add_step_listener(sample)
        clock = asyncio.create_task(team.server.run())
        reducer = TelemetryReducer(1)
        remove = link.add_listener(reducer)
        await link.wait_vehicle(system_id=1, timeout_s=5.0)
        await set_message_interval(link, 1, "GLOBAL_POSITION_INT", 0.1)
        await arm(link, 1)
        await set_mode(link, 1, "TAKEOFF")
        await team.wait_sim_time(team.sim_time_s + 15.0)  # airborne, climbing on a heading
        s = reducer.state
        assert s.link_ok(asyncio.get_running_loop().time())
        clock.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await clock
        truth = team.vehicles[0].true_state
        ap = team.vehicles[0].autopilot
        # The fixes sent up to the stop arrive: the last within 0.5 s (simulated) of the truth.
        while s.position_time_boot_s is None or truth.time_s - s.position_time_boot_s >= 0.5:
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.05)  # and any SYSTEM_TIME, WIND sent beside it
        remove()

        assert s.mode == ap.mode.name == "TAKEOFF"
        assert s.armed is True and ap.armed
        assert s.malformed == 0
        # position: extrapolate the last fix to the truth's time with the reported velocity
        assert s.lat_deg is not None
        dt = truth.time_s - s.position_time_boot_s
        assert 0 <= dt < 0.5
        assert s.vn_m_s is not None and s.ve_m_s is not None and s.lon_deg is not None
        course = math.degrees(math.atan2(s.ve_m_s, s.vn_m_s))
        lon, lat, _ = GEOD.fwd(s.lon_deg, s.lat_deg, course, math.hypot(s.vn_m_s, s.ve_m_s) * dt)
        _, _, error_m = GEOD.inv(lon, lat, truth.lon_deg, truth.lat_deg)
        assert error_m < 3.0
        assert s.alt_amsl_m == pytest.approx(truth.alt_m, abs=3.0)
        # wind: the stub reports where it comes FROM
        assert s.wind_from_deg == pytest.approx(250.0, abs=1.0)
        assert s.wind_speed_m_s == pytest.approx(5.0, abs=0.2)
        # speed estimates on the vehicle's clock against the true ground speed over the same
        # second of the vehicle's time (the fixes' last second)
        end_s = s.position_time_boot_s
        second = [(v, c) for t, v, c in flown if end_s - 1.0 <= t <= end_s]
        assert len(second) >= 5, (end_s, flown[-3:])
        true_speed = sum(v for v, _ in second) / len(second)
        assert s.track_speed_m_s(1.0) == pytest.approx(true_speed, abs=1.0)
        course_deg = math.degrees(truth.course_rad)
        along = s.groundspeed_along_track_m_s(1.0, course_deg)
        true_along = sum(v * math.cos(c - truth.course_rad) for v, c in second) / len(second)
        assert along == pytest.approx(true_along, abs=1.0)
        # vehicle UTC as the last SYSTEM_TIME said it (sent once a simulated second): within
        # one period of the simulator's
        assert s.utc_rx_s is not None
        vutc = s.vehicle_utc_s(s.utc_rx_s)
        assert vutc is not None and abs(vutc - team.utc_s) < 1.5

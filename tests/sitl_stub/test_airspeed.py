"""Equivalent airspeed as ArduPlane flies it, and an injected airspeed sensor error."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from sitl_stub.atmosphere import density_ratio, eas2tas
from sitl_stub.autopilot import Autopilot, Mode
from sitl_stub.clock import SimClock
from sitl_stub.link import FaultyLink
from sitl_stub.model import AirframeParams
from sitl_stub.vehicle import Vehicle

HOME_ALT_M = 1000.0


def isa_density_ratio(alt_m: float) -> float:
    """ISA troposphere from its textbook constants: (1 - L h / T0)^(g / (L R) - 1)."""
    lapse, t0, g, r = 0.0065, 288.15, 9.80665, 287.05287
    return float((1.0 - lapse * alt_m / t0) ** (g / (lapse * r) - 1.0))


def test_isa_known_values() -> None:
    """Follows libraries/AP_Baro/AP_Baro_atmosphere.cpp, get_air_density_for_alt_amsl and
    get_EAS2TAS_for_alt_amsl: density ratio 0.9075 and EAS2TAS 1.0497 at 1000 m."""
    assert density_ratio(0.0) == pytest.approx(1.0, abs=1e-6)
    assert density_ratio(1000.0) == pytest.approx(0.9075, abs=2e-4)
    assert eas2tas(1000.0) == pytest.approx(1.0497, abs=2e-4)
    for alt in (0.0, 500.0, 1250.0, 3000.0, 9000.0):
        # ArduPilot converts geometric to geopotential altitude first: 0.15 % at 9 km.
        assert density_ratio(alt) == pytest.approx(isa_density_ratio(alt), rel=2e-3)
    assert eas2tas(15000.0) > eas2tas(11000.0) > eas2tas(5000.0)  # stratosphere layer too


def cruising(params: AirframeParams, seconds: float = 60.0) -> Vehicle:
    ap = Autopilot(
        params=params,
        home_lat_deg=47.0,
        home_lon_deg=8.0,
        home_alt_m=HOME_ALT_M,
        rng=np.random.default_rng(0),
    )
    ap.arm()
    assert ap.set_mode(Mode.TAKEOFF)
    for _ in range(round(seconds / 0.1)):
        ap.step(0.1)
    vehicle = Vehicle(
        system_id=1,
        autopilot=ap,
        clock=SimClock(speedup=1.0),
        link=FaultyLink(np.random.default_rng(1), lambda: 0.0),
    )
    return vehicle


def test_cruise_is_equivalent_airspeed_and_vfr_hud_reports_it() -> None:
    """Follows libraries/SITL/SIM_Aircraft.cpp (update_dynamics: eas2tas from the altitude)
    and ArduPlane/GCS_Mavlink.cpp (GCS_MAVLINK_Plane::vfr_hud_airspeed: the airspeed
    sensor's equivalent airspeed)."""
    v = cruising(AirframeParams())
    s = v.autopilot.state
    expected_tas = 22.0 / math.sqrt(isa_density_ratio(s.alt_m))
    assert s.airspeed_m_s == pytest.approx(expected_tas, abs=0.2)
    assert s.airspeed_m_s > 22.0 + 0.8  # about 5 % above the EAS at 1000-1050 m
    assert v.message("VFR_HUD").airspeed == pytest.approx(22.0, abs=0.2)


def test_equivalent_airspeed_can_be_turned_off() -> None:
    v = cruising(replace(AirframeParams(), equivalent_airspeed=False))
    assert v.autopilot.state.airspeed_m_s == pytest.approx(22.0, abs=0.2)
    assert v.message("VFR_HUD").airspeed == pytest.approx(22.0, abs=0.2)


@pytest.mark.parametrize("bias", [0.05, -0.05])
def test_speed_bias_flies_faster_or_slower_than_it_reports(bias: float) -> None:
    """An airspeed sensor error: the aircraft flies (1 + bias) x the TAS it should while
    VFR_HUD shows the airspeed it believes (ArduPlane/GCS_Mavlink.cpp vfr_hud_airspeed)."""
    plain = cruising(AirframeParams()).autopilot.state
    v = cruising(replace(AirframeParams(), speed_bias=bias))
    s = v.autopilot.state
    assert s.airspeed_m_s / plain.airspeed_m_s == pytest.approx(1.0 + bias, abs=0.01)
    assert v.message("VFR_HUD").airspeed == pytest.approx(22.0, abs=0.2)
    assert v.autopilot.eas_m_s == pytest.approx(22.0 * (1.0 + bias), abs=0.3)


def test_nav_controller_output_gives_the_airspeed_error_in_centimetres_per_second() -> None:
    """ArduPlane/GCS_Mavlink.cpp send_nav_controller_output sends ``airspeed_error * 100``
    (cm/s, though MAVLink's field says m/s: "incorrect units; see PR#7933"), the demanded
    minus the measured equivalent airspeed."""
    v = cruising(AirframeParams(), seconds=20.0)
    ap = v.autopilot
    msg = v.message("NAV_CONTROLLER_OUTPUT")
    error_m_s = ap.target_airspeed_m_s - ap.eas_m_s
    assert abs(error_m_s) > 0.05  # still accelerating to the cruise airspeed: an error to see
    assert msg.aspd_error == pytest.approx(100.0 * error_m_s, rel=1e-3, abs=1e-3)

"""WIND reports an estimate with an error, as ArduPlane's EKF wind estimate has one."""

from __future__ import annotations

import math

import pytest

from sitl_stub.api import Home, SimTeam
from sitl_stub.model import Wind

HOMES = [Home(-35.36 - 0.01 * i, 149.16, 584.0) for i in range(8)]


def reported(team: SimTeam) -> list[tuple[float, float]]:
    """(speed, direction FROM) of every vehicle's WIND message now."""
    out = []
    for v in team.vehicles:
        msg = v.message("WIND")
        out.append((float(msg.speed), float(msg.direction)))
    return out


def test_still_air_reads_0_8_to_1_6_m_s_per_vehicle_deterministic_for_a_seed() -> None:
    """Follows libraries/GCS_MAVLink/GCS_Common.cpp (send_wind sends the AHRS wind estimate,
    not the simulated wind): real ArduPlane SITL reads 0.8-1.6 m/s in still air."""
    team = SimTeam.create(homes=HOMES, seed=3)
    first = reported(team)
    assert all(0.8 <= speed <= 1.6 for speed, _ in first)
    assert len({round(d) for _, d in first}) > 4  # each vehicle its own error
    assert reported(SimTeam.create(homes=HOMES, seed=3)) == first
    assert reported(SimTeam.create(homes=HOMES, seed=4)) != first
    for _ in range(600):  # a minute: the error turns slowly, its size stays
        team.server.step_once()
    later = reported(team)
    assert all(0.8 <= speed <= 1.6 for speed, _ in later)
    turned = [
        abs((b - a + 180.0) % 360.0 - 180.0) for (_, a), (_, b) in zip(first, later, strict=True)
    ]
    assert max(turned) <= 30.0 + 1e-6 and max(turned) > 0.0


def test_estimate_is_true_wind_plus_error_and_can_be_turned_off() -> None:
    wind = Wind(5.0, math.radians(270.0))
    exact = SimTeam.create(homes=HOMES[:3], wind=wind, wind_estimate_error=False)
    assert reported(exact) == [pytest.approx((5.0, 270.0))] * 3
    off_by = [
        math.hypot(
            speed * math.sin(math.radians(d)) - 5.0 * math.sin(math.radians(270.0)),
            speed * math.cos(math.radians(d)) - 5.0 * math.cos(math.radians(270.0)),
        )
        for speed, d in reported(SimTeam.create(homes=HOMES[:3], wind=wind))
    ]
    assert all(0.8 - 1e-9 <= e <= 1.6 + 1e-9 for e in off_by)

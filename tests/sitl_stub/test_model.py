"""Point-mass model: dynamics, wind, geodesy, determinism, crossing times."""

from __future__ import annotations

import math
import random
from dataclasses import FrozenInstanceError, fields, replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitl_stub import model
from sitl_stub.model import (
    GRAVITY_M_S2,
    AirframeParams,
    Controls,
    FlightState,
    NormalStream,
    Wind,
    crossing_time,
    displace_deg,
    offset_ne_m,
)

DT = 0.1
P = AirframeParams()
CALM = Wind()
GROUND = 0.0


def airborne(airspeed: float = 22.0, heading_deg: float = 0.0, lat: float = 47.0) -> FlightState:
    h = math.radians(heading_deg)
    return FlightState(
        time_s=0.0,
        lat_deg=lat,
        lon_deg=8.0,
        alt_m=500.0,
        airspeed_m_s=airspeed,
        heading_rad=h,
        vel_north_m_s=airspeed * math.cos(h),
        vel_east_m_s=airspeed * math.sin(h),
        on_ground=False,
    )


def fly(
    s: FlightState,
    controls: Controls,
    seconds: float,
    wind: Wind = CALM,
    rng: model.Rng | None = None,
    params: AirframeParams = P,
) -> list[FlightState]:
    rng = rng if rng is not None else random.Random(0)
    out = [s]
    for _ in range(round(seconds / DT)):
        s = model.step(s, controls, params, wind, DT, rng)
        out.append(s)
    return out


def level(airspeed: float = 22.0, bank: float = 0.0) -> Controls:
    return Controls(airspeed, bank, 0.0, GROUND)


def test_same_seed_same_trajectory_with_gusts() -> None:
    wind = Wind(8.0, math.radians(200), gust_m_s=2.0)
    a = fly(airborne(), level(bank=0.2), 60, wind, NormalStream(np.random.default_rng(5)))
    b = fly(airborne(), level(bank=0.2), 60, wind, NormalStream(np.random.default_rng(5)))
    c = fly(airborne(), level(bank=0.2), 60, wind, NormalStream(np.random.default_rng(6)))
    assert a == b
    assert a[-1] != c[-1]


@pytest.mark.parametrize(
    "rng", [np.random.default_rng(1), random.Random(1), NormalStream(np.random.default_rng(1))]
)
def test_every_rng_kind_gives_gusts_of_the_requested_size(rng: model.Rng) -> None:
    wind = Wind(0.0, 0.0, gust_m_s=2.0, gust_time_constant_s=1.0)
    states = fly(airborne(), level(), 600, wind, rng)
    gust_n = np.array([s.wind_north_m_s for s in states[100:]])
    assert 1.5 < gust_n.std() < 2.5
    assert abs(gust_n.mean()) < 0.5


def test_airspeed_converges_to_the_command() -> None:
    states = fly(airborne(18.0), level(25.0), 30)
    assert states[-1].airspeed_m_s == pytest.approx(25.0, abs=0.05)
    steps = np.diff([s.airspeed_m_s for s in states])
    assert steps.max() <= P.airspeed_accel_max_m_s2 * DT + 1e-9


def test_airspeed_first_order_time_constant() -> None:
    # Small step (below the acceleration limit): 63 % of the way after one time constant.
    states = fly(airborne(22.0), level(23.0), P.airspeed_time_constant_s)
    assert states[-1].airspeed_m_s - 22.0 == pytest.approx(1.0 - math.exp(-1.0), abs=0.01)


@pytest.mark.parametrize(("command", "expected"), [(40.0, 30.0), (5.0, 15.0)])
def test_airspeed_is_clamped_when_flying(command: float, expected: float) -> None:
    states = fly(airborne(22.0), level(command), 40)
    assert states[-1].airspeed_m_s == pytest.approx(expected, abs=0.05)
    assert all(15.0 - 1e-9 <= s.airspeed_m_s <= 30.0 + 1e-9 for s in states)


def test_bank_is_limited_and_rate_limited() -> None:
    states = fly(airborne(), level(bank=3.0), 10)
    rolls = [s.roll_rad for s in states]
    assert max(rolls) <= P.max_bank_rad + 1e-12
    assert rolls[-1] == pytest.approx(P.max_bank_rad, abs=1e-3)
    assert np.diff(rolls).max() <= P.roll_rate_max_rad_s * DT + 1e-12


@pytest.mark.parametrize("airspeed", [18.0, 22.0, 28.0])
def test_turn_radius_at_max_bank(airspeed: float) -> None:
    states = fly(airborne(airspeed), level(airspeed, bank=10.0), 120)[200:]
    ref = states[0]
    pts = np.array(
        [offset_ne_m(ref.lat_deg, ref.lon_deg, 0.0, s.lat_deg, s.lon_deg) for s in states]
    )
    # Least-squares circle fit (Kasa): x^2 + y^2 = 2ax + 2by + c.
    a_mat = np.column_stack([2 * pts[:, 0], 2 * pts[:, 1], np.ones(len(pts))])
    sol = np.linalg.lstsq(a_mat, (pts**2).sum(axis=1), rcond=None)[0]
    radius = math.sqrt(sol[2] + sol[0] ** 2 + sol[1] ** 2)
    expected = airspeed**2 / (GRAVITY_M_S2 * math.tan(P.max_bank_rad))
    assert radius == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize(("heading_deg", "delta"), [(90.0, +10.0), (270.0, -10.0), (0.0, 0.0)])
def test_west_wind_adds_to_eastbound_groundspeed(heading_deg: float, delta: float) -> None:
    wind = Wind(10.0, math.radians(270.0))  # from the west: blows toward the east
    states = fly(airborne(22.0, heading_deg), level(22.0), 20, wind)
    last = states[-1]
    along = last.vel_north_m_s * math.cos(last.heading_rad) + last.vel_east_m_s * math.sin(
        last.heading_rad
    )
    assert along == pytest.approx(22.0 + delta, abs=1e-6)
    assert last.wind_east_m_s == pytest.approx(10.0)
    assert last.wind_north_m_s == pytest.approx(0.0, abs=1e-9)


def test_climb_and_sink_are_limited() -> None:
    up = fly(airborne(), Controls(22.0, 0.0, 50.0, GROUND), 10)
    assert up[-1].climb_rate_m_s == pytest.approx(P.climb_rate_max_m_s, abs=1e-3)
    assert up[-1].pitch_rad == pytest.approx(math.atan2(5.0, 22.0), abs=1e-3)
    down = fly(airborne(), Controls(22.0, 0.0, -50.0, GROUND), 10)
    assert down[-1].climb_rate_m_s == pytest.approx(-P.sink_rate_max_m_s, abs=1e-3)
    # Altitude integrates the climb rate.
    assert up[-1].alt_m - 500.0 == pytest.approx(sum(s.climb_rate_m_s for s in up[1:]) * DT, 0.02)


def test_distances_are_true_on_the_ellipsoid() -> None:
    pyproj = pytest.importorskip("pyproj")
    geod = pyproj.Geod(ellps="WGS84")
    for lat, heading in [(0.0, 0.0), (47.0, 90.0), (60.0, 45.0), (-33.0, 200.0)]:
        start = replace(airborne(20.0, heading, lat), alt_m=0.0)
        end = fly(start, Controls(20.0, 0.0, 0.0, -100.0), 100)[-1]
        _, _, dist = geod.inv(start.lon_deg, start.lat_deg, end.lon_deg, end.lat_deg)
        assert dist == pytest.approx(2000.0, rel=2e-4)
        assert end.distance_flown_m == pytest.approx(2000.0, rel=1e-9)


def test_ground_roll_lifts_off_at_rotate_speed_and_climbs() -> None:
    s = FlightState(0.0, 47.0, 8.0, GROUND, 0.0, 0.0, on_ground=True)
    states = fly(s, Controls(22.0, 0.0, 4.0, GROUND), 20)
    liftoff = next(x for x in states if not x.on_ground)
    assert liftoff.airspeed_m_s == pytest.approx(P.airspeed_min_m_s, abs=P.takeoff_accel_m_s2 * DT)
    assert states[-1].alt_m > GROUND + 20.0
    assert not any(x.on_ground for x in states[states.index(liftoff) :])


def test_motor_off_on_the_ground_stays_put_even_in_wind() -> None:
    s = FlightState(0.0, 47.0, 8.0, GROUND, 0.0, 1.0, on_ground=True)
    states = fly(s, Controls(0.0, 0.0, 0.0, GROUND, motor_on=False), 30, Wind(12.0, 0.3, 3.0))
    assert (states[-1].lat_deg, states[-1].lon_deg) == (s.lat_deg, s.lon_deg)
    assert states[-1].on_ground


def test_gliding_with_motor_off_touches_down_and_stops() -> None:
    s = replace(airborne(20.0), alt_m=GROUND + 30.0)
    states = fly(s, Controls(20.0, 0.0, 0.0, GROUND, motor_on=False), 60)
    touch = next(i for i, x in enumerate(states) if x.on_ground)
    assert states[touch].alt_m == GROUND
    assert all(x.on_ground for x in states[touch:])
    assert states[-1].groundspeed_m_s == 0.0


def test_crossing_time_interpolates_the_closest_approach() -> None:
    s0 = airborne(20.0, 90.0)  # eastbound
    target_lat, target_lon = displace_deg(s0.lat_deg, s0.lon_deg, 0.0, 30.0, 403.0)
    best: tuple[float, float] | None = None
    prev = s0
    for s in fly(s0, level(20.0), 40)[1:]:
        t = crossing_time(prev, s, target_lat, target_lon, 50.0)
        if t is not None:
            miss = math.hypot(*offset_ne_m(s.lat_deg, s.lon_deg, 0.0, target_lat, target_lon))
            if best is None or miss < best[1]:
                best = (t, miss)
        prev = s
    assert best is not None
    assert best[0] == pytest.approx(403.0 / 20.0, abs=0.01)


def test_crossing_time_none_when_outside_the_radius_or_the_step() -> None:
    s0 = airborne(20.0, 90.0)
    s1 = model.step(s0, level(20.0), P, CALM, DT, random.Random(0))
    far_lat, far_lon = displace_deg(s0.lat_deg, s0.lon_deg, 0.0, 100.0, 1.0)
    assert crossing_time(s0, s1, far_lat, far_lon, 50.0) is None
    ahead_lat, ahead_lon = displace_deg(s0.lat_deg, s0.lon_deg, 0.0, 0.0, 500.0)
    assert crossing_time(s0, s1, ahead_lat, ahead_lon, 1000.0) is None


@settings(max_examples=60, deadline=None)
@given(
    lat=st.floats(-80.0, 80.0),
    lon=st.floats(-179.0, 179.0),
    north=st.floats(-5000.0, 5000.0),
    east=st.floats(-5000.0, 5000.0),
)
def test_displace_and_offset_are_inverse(lat: float, lon: float, north: float, east: float) -> None:
    lat2, lon2 = displace_deg(lat, lon, 0.0, north, east)
    n, e = offset_ne_m(lat, lon, 0.0, lat2, lon2)
    assert n == pytest.approx(north, abs=1e-6)
    assert e == pytest.approx(east, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(
    north=st.floats(-60.0, 60.0),
    east=st.floats(-60.0, 60.0),
    heading_deg=st.floats(0.0, 360.0),
)
def test_crossing_time_lies_inside_the_step(north: float, east: float, heading_deg: float) -> None:
    s0 = airborne(25.0, heading_deg)
    s1 = model.step(s0, level(25.0), P, CALM, 1.0, random.Random(0))
    lat, lon = displace_deg(s0.lat_deg, s0.lon_deg, 0.0, north, east)
    t = crossing_time(s0, s1, lat, lon, 1e6)
    if t is not None:
        assert s0.time_s <= t <= s1.time_s


def test_new_flight_state_is_the_dataclass_with_its_fields_in_order() -> None:
    values = [float(i) + 0.25 for i in range(len(fields(FlightState)))]
    values[[f.name for f in fields(FlightState)].index("on_ground")] = False
    made = model.new_flight_state(*values)  # type: ignore[arg-type]
    assert type(made) is FlightState
    assert made == FlightState(*values)  # type: ignore[arg-type]
    with pytest.raises(FrozenInstanceError):
        made.alt_m = 1.0  # type: ignore[misc]


def test_a_step_given_the_metres_per_degree_is_the_same_step() -> None:
    s = airborne(heading_deg=30.0, lat=47.3)
    wind = Wind(5.0, 1.0)
    plain = model.step_scalar(s, 25.0, 0.2, 1.0, GROUND, True, P, wind, DT, random.Random(0))
    given = model.step_scalar(
        s,
        25.0,
        0.2,
        1.0,
        GROUND,
        True,
        P,
        wind,
        DT,
        random.Random(0),
        m_per_deg=model.metres_per_degree(s.lat_deg, s.alt_m),
    )
    assert given == plain

"""Point-mass fixed-wing flight model: pure, deterministic for a seed, cheap per step.

``step(state, controls, params, wind, dt_s, rng) -> FlightState`` follows the functional-env
style: every input is a value, nothing is mutated. The hot path uses ``math`` on Python floats;
the random source is drawn only when gusts are on (``Wind.gust_m_s > 0``).

Conventions: SI units inside; compass angles (0 = north, clockwise positive, radians); the
local tangent plane is (north, east). Positions are integrated on the WGS84 ellipsoid with the
local radii of curvature, so distances flown are true distances.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

GRAVITY_M_S2 = 9.80665
WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
_DEG = math.pi / 180.0
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True, slots=True)
class AirframeParams:
    """Airframe and autopilot parameters (ArduPlane parameter names in the comments).

    Airspeeds are EQUIVALENT airspeed (as ArduPlane's) when ``equivalent_airspeed`` is True
    (the default): the aircraft flies true airspeed = EAS x EAS2TAS at its altitude
    (:mod:`sitl_stub.atmosphere`). ``speed_bias`` is an airspeed sensor error: the aircraft
    flies (1 + speed_bias) x the true airspeed it should, while it reports what it believes.
    """

    airspeed_min_m_s: float = 15.0  # ARSPD_FBW_MIN (AIRSPEED_MIN)
    airspeed_max_m_s: float = 30.0  # ARSPD_FBW_MAX (AIRSPEED_MAX)
    airspeed_cruise_m_s: float = 22.0  # TRIM_ARSPD_CM / AIRSPEED_CRUISE
    airspeed_time_constant_s: float = 3.0  # first-order response of airspeed to its demand
    airspeed_accel_max_m_s2: float = 1.5  # longitudinal acceleration limit in flight
    max_bank_rad: float = math.radians(45.0)  # LIM_ROLL_CD / ROLL_LIMIT_DEG
    roll_time_constant_s: float = 0.5  # RLL2SRV_TCONST
    roll_rate_max_rad_s: float = math.radians(75.0)  # RLL_RATE_MAX
    climb_rate_max_m_s: float = 5.0  # TECS_CLMB_MAX
    sink_rate_max_m_s: float = 5.0  # TECS_SINK_MAX
    climb_time_constant_s: float = 1.0  # response of climb rate to its demand
    alt_time_constant_s: float = 5.0  # TECS_TIME_CONST: altitude error -> climb demand
    takeoff_accel_m_s2: float = 3.0  # ground-roll acceleration at full throttle
    takeoff_rotate_speed_m_s: float = 0.0  # TKOFF_ROTATE_SPD; 0 -> airspeed_min_m_s
    # Climb rate during NAV_TAKEOFF / TAKEOFF mode. ArduPlane climbs out at TKOFF_THR_MAX with
    # the pitch TECS demands to hold airspeed (takeoff.cpp, TECS takeoff stage): the airframe's
    # full-throttle climb, not TECS_CLMB_MAX. Measured on ArduPlane SITL V4.7.0-dev: 607-828 m
    # in 66-88 s (about 9 m/s) over about 2 km.
    takeoff_climb_rate_m_s: float = 9.0
    takeoff_mode_alt_m: float = 50.0  # TKOFF_ALT: TAKEOFF mode target above home
    ground_brake_decel_m_s2: float = 2.0  # rolling/braking deceleration on the ground
    glide_ratio: float = 10.0  # motor off in the air (disarmed): sink = airspeed / ratio
    loiter_radius_m: float = 80.0  # WP_LOITER_RAD (sign: negative = counter-clockwise)
    wp_radius_m: float = 90.0  # WP_RADIUS
    l1_period_s: float = 17.0  # NAVL1_PERIOD
    l1_damping: float = 0.75  # NAVL1_DAMPING
    rtl_altitude_m: float = 100.0  # ALT_HOLD_RTL (metres above home; < 0 -> current altitude)
    min_groundspeed_m_s: float = 0.0  # MIN_GNDSPD_CM (0 = off); DO_CHANGE_SPEED type 1 sets it
    land_airspeed_m_s: float = 18.0  # TECS_LAND_ARSPD
    land_flare_alt_m: float = 3.0  # LAND_FLARE_ALT (above the landing point)
    land_flare_sink_m_s: float = 0.5  # LAND_SINK... demanded sink rate in the flare
    land_disarm_delay_s: float = 20.0  # LAND_DISARMDELAY
    max_substep_s: float = 0.1  # larger dt_s is split into sub-steps of at most this
    equivalent_airspeed: bool = True  # airspeeds are EAS (ArduPlane); False: flown as TAS
    speed_bias: float = 0.0  # flies (1 + bias) x the true airspeed it should (sensor error)


@dataclass(frozen=True, slots=True)
class Wind:
    """Mean wind plus gusts; ``from_rad`` is the compass direction the wind blows FROM."""

    speed_m_s: float = 0.0
    from_rad: float = 0.0
    gust_m_s: float = 0.0  # standard deviation of each horizontal gust component
    gust_time_constant_s: float = 3.0  # correlation time of the Ornstein-Uhlenbeck gusts

    @property
    def north_m_s(self) -> float:
        """Mean wind velocity, north component (where the air moves TO)."""
        return -self.speed_m_s * math.cos(self.from_rad)

    @property
    def east_m_s(self) -> float:
        """Mean wind velocity, east component (where the air moves TO)."""
        return -self.speed_m_s * math.sin(self.from_rad)


@dataclass(frozen=True, slots=True)
class FlightState:
    """The vehicle's state; the wind fields are the current wind including gusts."""

    time_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float  # AMSL
    airspeed_m_s: float
    heading_rad: float  # compass, where the nose points, in [0, 2*pi)
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    climb_rate_m_s: float = 0.0
    vel_north_m_s: float = 0.0  # ground velocity
    vel_east_m_s: float = 0.0
    wind_north_m_s: float = 0.0
    wind_east_m_s: float = 0.0
    on_ground: bool = True
    distance_flown_m: float = 0.0  # along the ground track

    @property
    def groundspeed_m_s(self) -> float:
        return math.hypot(self.vel_north_m_s, self.vel_east_m_s)

    @property
    def course_rad(self) -> float:
        """Ground course (compass); the heading when not moving."""
        if self.vel_north_m_s * self.vel_north_m_s + self.vel_east_m_s * self.vel_east_m_s < 0.01:
            return self.heading_rad
        return math.atan2(self.vel_east_m_s, self.vel_north_m_s) % _TWO_PI


def _slot_setter(name: str) -> Callable[[FlightState, Any], None]:
    setter: Callable[[FlightState, Any], None] = vars(FlightState)[name].__set__
    return setter


(
    _set_time_s,
    _set_lat_deg,
    _set_lon_deg,
    _set_alt_m,
    _set_airspeed_m_s,
    _set_heading_rad,
    _set_roll_rad,
    _set_pitch_rad,
    _set_climb_rate_m_s,
    _set_vel_north_m_s,
    _set_vel_east_m_s,
    _set_wind_north_m_s,
    _set_wind_east_m_s,
    _set_on_ground,
    _set_distance_flown_m,
) = (_slot_setter(f.name) for f in fields(FlightState))


def new_flight_state(
    time_s: float,
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    airspeed_m_s: float,
    heading_rad: float,
    roll_rad: float,
    pitch_rad: float,
    climb_rate_m_s: float,
    vel_north_m_s: float,
    vel_east_m_s: float,
    wind_north_m_s: float,
    wind_east_m_s: float,
    on_ground: bool,
    distance_flown_m: float,
) -> FlightState:
    """``FlightState(...)`` with every field given, for the once-a-step path.

    The frozen dataclass's ``__init__`` stores each field through ``object.__setattr__``,
    which cost a good share of a physics step; this stores them through the slots' own
    setters, in half the time. The same object with the same fields
    (``tests/sitl_stub/test_model.py`` checks the field order)."""
    state: FlightState = object.__new__(FlightState)
    _set_time_s(state, time_s)
    _set_lat_deg(state, lat_deg)
    _set_lon_deg(state, lon_deg)
    _set_alt_m(state, alt_m)
    _set_airspeed_m_s(state, airspeed_m_s)
    _set_heading_rad(state, heading_rad)
    _set_roll_rad(state, roll_rad)
    _set_pitch_rad(state, pitch_rad)
    _set_climb_rate_m_s(state, climb_rate_m_s)
    _set_vel_north_m_s(state, vel_north_m_s)
    _set_vel_east_m_s(state, vel_east_m_s)
    _set_wind_north_m_s(state, wind_north_m_s)
    _set_wind_east_m_s(state, wind_east_m_s)
    _set_on_ground(state, on_ground)
    _set_distance_flown_m(state, distance_flown_m)
    return state


@dataclass(frozen=True, slots=True)
class Controls:
    """What the autopilot asks of the airframe for one step.

    ``bank_cmd_rad`` is the demanded bank (positive = right wing down = turn right), limited
    by ``max_bank_rad``; ``climb_rate_cmd_m_s`` is limited by the climb/sink limits; with
    ``motor_on`` False the aircraft glides (in the air) or brakes to a stop (on the ground).
    On the ground with ``motor_on`` the aircraft rolls along its heading and lifts off at the
    rotate speed if ``climb_rate_cmd_m_s > 0``. ``ground_alt_m`` is the terrain height (AMSL)
    under the aircraft: on the ground its altitude follows it.
    """

    target_airspeed_m_s: float
    bank_cmd_rad: float
    climb_rate_cmd_m_s: float
    ground_alt_m: float
    motor_on: bool = True


def radii_of_curvature_m(lat_rad: float) -> tuple[float, float]:
    """WGS84 meridional (M) and prime-vertical (N) radii of curvature at a latitude."""
    s = math.sin(lat_rad)
    w2 = 1.0 - WGS84_E2 * s * s
    w = math.sqrt(w2)
    n = WGS84_A_M / w
    m = WGS84_A_M * (1.0 - WGS84_E2) / (w2 * w)
    return m, n


def metres_per_degree(lat_deg: float, alt_m: float) -> tuple[float, float]:
    """Metres per degree of latitude and of longitude at a latitude and altitude (AMSL), from
    the local radii of curvature: ``(M + alt) pi/180``, ``(N + alt) cos(lat) pi/180``."""
    lat_rad = lat_deg * _DEG
    m, n = radii_of_curvature_m(lat_rad)
    return (m + alt_m) * _DEG, (n + alt_m) * math.cos(lat_rad) * _DEG


def offset_ne_m(
    lat_deg: float, lon_deg: float, alt_m: float, to_lat_deg: float, to_lon_deg: float
) -> tuple[float, float]:
    """North/east offset (m) of a point from a reference, in the reference's tangent plane."""
    m, n = radii_of_curvature_m(lat_deg * _DEG)
    dlon = (to_lon_deg - lon_deg + 180.0) % 360.0 - 180.0
    return (
        (to_lat_deg - lat_deg) * _DEG * (m + alt_m),
        dlon * _DEG * (n + alt_m) * math.cos(lat_deg * _DEG),
    )


def displace_deg(
    lat_deg: float, lon_deg: float, alt_m: float, north_m: float, east_m: float
) -> tuple[float, float]:
    """Latitude/longitude after moving north_m/east_m from a point (short distances)."""
    m, n = radii_of_curvature_m(lat_deg * _DEG)
    lat = lat_deg + north_m / (m + alt_m) / _DEG
    lon = lon_deg + east_m / ((n + alt_m) * math.cos(lat_deg * _DEG)) / _DEG
    return lat, (lon + 180.0) % 360.0 - 180.0


class NormalStream:
    """Standard normal draws from a numpy Generator, fetched in batches (cheap per draw)."""

    __slots__ = ("_batch", "_buf", "_rng")

    def __init__(self, rng: np.random.Generator, batch: int = 512) -> None:
        self._rng = rng
        self._batch = batch
        self._buf: list[float] = []

    def gauss(self) -> float:
        buf = self._buf
        if not buf:
            buf.extend(self._rng.standard_normal(self._batch).tolist())
            buf.reverse()
        return buf.pop()


Rng = np.random.Generator | random.Random | NormalStream
"""A seeded random source: a numpy Generator, a NormalStream over one, or a random.Random."""


def _gauss(rng: Rng) -> float:
    if isinstance(rng, NormalStream):
        return rng.gauss()
    if isinstance(rng, random.Random):
        return rng.gauss(0.0, 1.0)
    return float(rng.standard_normal())


def step(
    state: FlightState,
    controls: Controls,
    params: AirframeParams,
    wind: Wind,
    dt_s: float,
    rng: Rng,
) -> FlightState:
    """Advance the point-mass model by ``dt_s`` seconds (a single step: callers keep dt small).

    In the air: airspeed first order toward the demand clamped to [min, max] (time constant,
    acceleration limit); bank first order toward the demand (time constant, roll-rate limit);
    coordinated turn (yaw rate = g tan(bank) / V); climb rate first order toward the limited
    demand; ground velocity = air velocity + wind (mean + Ornstein-Uhlenbeck gusts).
    """
    return step_scalar(
        state,
        controls.target_airspeed_m_s,
        controls.bank_cmd_rad,
        controls.climb_rate_cmd_m_s,
        controls.ground_alt_m,
        controls.motor_on,
        params,
        wind,
        dt_s,
        rng,
    )


def step_scalar(
    state: FlightState,
    target_airspeed_m_s: float,
    bank_cmd_rad: float,
    climb_rate_cmd_m_s: float,
    ground_alt_m: float,
    motor_on: bool,
    p: AirframeParams,
    wind: Wind,
    dt_s: float,
    rng: Rng,
    tas_scale: float = 1.0,
    climb_max_m_s: float = 0.0,
    m_per_deg: tuple[float, float] | None = None,
) -> FlightState:
    """``step`` with the controls unpacked (the autopilot's hot path; no Controls object).

    ``tas_scale`` is true airspeed per unit of the airframe's airspeeds (EAS2TAS x (1 + bias)):
    it scales the airspeed limits and the rotate speed; ``target_airspeed_m_s`` is true.
    ``climb_max_m_s`` > 0 replaces ``climb_rate_max_m_s`` (a full-throttle takeoff climb).
    ``m_per_deg`` is :func:`metres_per_degree` at ``state`` (its latitude and altitude), if
    the caller has it already (the autopilot navigates with it); else it is worked out here.
    """
    exp = math.exp
    cos = math.cos
    sin = math.sin
    # Wind: mean + Ornstein-Uhlenbeck gust; the gust is what the state's wind exceeds the mean.
    spd = wind.speed_m_s
    if spd != 0.0:
        mean_n = -spd * cos(wind.from_rad)
        mean_e = -spd * sin(wind.from_rad)
    else:
        mean_n = mean_e = 0.0
    if wind.gust_m_s > 0.0:
        phi = exp(-dt_s / wind.gust_time_constant_s)
        k = wind.gust_m_s * math.sqrt(1.0 - phi * phi)
        wn = mean_n + (state.wind_north_m_s - mean_n) * phi + k * _gauss(rng)
        we = mean_e + (state.wind_east_m_s - mean_e) * phi + k * _gauss(rng)
    else:
        wn = mean_n
        we = mean_e

    heading = state.heading_rad
    on_ground = state.on_ground
    lifted_off = False
    climb = state.climb_rate_m_s
    roll = state.roll_rad
    airspeed = state.airspeed_m_s

    # Limits below are written out rather than max() calls: this runs every physics step.
    if on_ground:
        # Ground roll along the heading; the ground speed is what the wheels integrate.
        ch = cos(heading)
        sh = sin(heading)
        gs = state.vel_north_m_s * ch + state.vel_east_m_s * sh
        if motor_on:
            gs += p.takeoff_accel_m_s2 * dt_s
        else:
            gs -= p.ground_brake_decel_m_s2 * dt_s
            gs = gs if gs > 0.0 else 0.0
        airspeed = gs - (wn * ch + we * sh)
        airspeed = airspeed if airspeed > 0.0 else 0.0
        rotate = (p.takeoff_rotate_speed_m_s or p.airspeed_min_m_s) * tas_scale
        roll = 0.0
        climb = state.climb_rate_m_s  # rolling up or down the ground (0 on flat ground)
        vn = gs * ch
        ve = gs * sh
        if motor_on and climb_rate_cmd_m_s > 0.0 and airspeed >= rotate:
            on_ground = False
            lifted_off = True
    else:
        # Airspeed: first order toward the (clamped) demand, acceleration-limited.
        if motor_on:
            target = target_airspeed_m_s
            if target < p.airspeed_min_m_s * tas_scale:
                target = p.airspeed_min_m_s * tas_scale
            elif target > p.airspeed_max_m_s * tas_scale:
                target = p.airspeed_max_m_s * tas_scale
        else:
            target = target_airspeed_m_s
        d = (target - airspeed) * (1.0 - exp(-dt_s / p.airspeed_time_constant_s))
        lim = p.airspeed_accel_max_m_s2 * dt_s
        airspeed += lim if d > lim else -lim if d < -lim else d
        # Bank: first order toward the limited demand, roll-rate-limited.
        lim = p.max_bank_rad
        bank_cmd = lim if bank_cmd_rad > lim else -lim if bank_cmd_rad < -lim else bank_cmd_rad
        d = (bank_cmd - roll) * (1.0 - exp(-dt_s / p.roll_time_constant_s))
        lim = p.roll_rate_max_rad_s * dt_s
        roll += lim if d > lim else -lim if d < -lim else d
        # Coordinated turn: yaw rate = g tan(bank) / V.
        speed = 1.0 if airspeed < 1.0 else airspeed  # no turn-rate blow-up at a standstill
        heading = (heading + GRAVITY_M_S2 * math.tan(roll) / speed * dt_s) % _TWO_PI
        ch = cos(heading)
        sh = sin(heading)
        if motor_on:
            climb_cmd = climb_rate_cmd_m_s
            climb_max = climb_max_m_s or p.climb_rate_max_m_s
            if climb_cmd > climb_max:
                climb_cmd = climb_max
            elif climb_cmd < -p.sink_rate_max_m_s:
                climb_cmd = -p.sink_rate_max_m_s
        else:
            climb_cmd = -airspeed / p.glide_ratio
        climb += (climb_cmd - climb) * (1.0 - exp(-dt_s / p.climb_time_constant_s))
        if climb > airspeed:
            climb = airspeed
        elif climb < -airspeed:
            climb = -airspeed
        horizontal = math.sqrt(airspeed * airspeed - climb * climb)
        vn = horizontal * ch + wn
        ve = horizontal * sh + we

    # Trapezoidal position update in the local tangent plane, then onto the ellipsoid.
    dn = 0.5 * (state.vel_north_m_s + vn) * dt_s
    de = 0.5 * (state.vel_east_m_s + ve) * dt_s
    alt = state.alt_m
    new_alt = alt + 0.5 * (state.climb_rate_m_s + climb) * dt_s
    if on_ground:
        new_alt = ground_alt_m  # the wheels follow the ground
    elif not lifted_off and new_alt <= ground_alt_m and climb <= 0.0:
        # Touchdown: wheels on the ground, keep rolling along the heading.
        on_ground = True
        new_alt = ground_alt_m
        climb = 0.0
        roll = 0.0
        gs = vn * ch + ve * sh
        vn = gs * ch
        ve = gs * sh
    if m_per_deg is None:
        m_per_deg = metres_per_degree(state.lat_deg, alt)
    m_per_deg_lat, m_per_deg_lon = m_per_deg
    lon = state.lon_deg + de / m_per_deg_lon
    if lon >= 180.0 or lon < -180.0:
        lon = (lon + 180.0) % 360.0 - 180.0
    pitch = 0.0 if on_ground else math.atan2(climb, 1.0 if airspeed < 1.0 else airspeed)

    return new_flight_state(
        state.time_s + dt_s,
        state.lat_deg + dn / m_per_deg_lat,
        lon,
        new_alt,
        airspeed,
        heading,
        roll,
        pitch,
        climb,
        vn,
        ve,
        wn,
        we,
        on_ground,
        state.distance_flown_m + math.sqrt(dn * dn + de * de),
    )


def crossing_time(
    prev: FlightState, new: FlightState, lat_deg: float, lon_deg: float, radius_m: float
) -> float | None:
    """Time of closest horizontal approach to a point during one step, if within ``radius_m``.

    The track between the two states is taken as a straight segment in ``prev``'s local tangent
    plane. Returns the interpolated time when the closest approach lies inside the step
    (including its end points) and is no farther than ``radius_m``; else None. A caller keeps
    the time whose miss distance is smallest over successive steps.
    """
    pn, pe = offset_ne_m(prev.lat_deg, prev.lon_deg, prev.alt_m, lat_deg, lon_deg)
    qn, qe = offset_ne_m(prev.lat_deg, prev.lon_deg, prev.alt_m, new.lat_deg, new.lon_deg)
    seg2 = qn * qn + qe * qe
    if seg2 <= 1e-12:
        u = 0.0
    else:
        u = (pn * qn + pe * qe) / seg2
        if u < 0.0 or u > 1.0:
            return None
    miss = math.hypot(pn - u * qn, pe - u * qe)
    if miss > radius_m:
        return None
    return prev.time_s + u * (new.time_s - prev.time_s)

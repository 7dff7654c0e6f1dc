"""The stub over terrain: the ground under each vehicle every step, TERRAIN_REPORT, a crash."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from sitl_stub.autopilot import CRASH_DETECT_DELAY_S, Autopilot, Text
from sitl_stub.items import MissionItem
from sitl_stub.model import AirframeParams, displace_deg, offset_ne_m
from sitl_stub.terrain import GridTerrain, Hill, with_hills
from tests.sitl_stub.conftest import Client
from tests.sitl_stub.test_autopilot import (
    HOME,
    REL,
    WP,
    home_item,
    item,
    run,
    takeoff,
)
from tests.sitl_stub.test_autopilot import (
    make as make_flat,
)


def make_over(ground: GridTerrain) -> Autopilot:
    """test_autopilot's vehicle, over ``ground``."""
    return Autopilot(
        params=AirframeParams(),
        home_lat_deg=HOME[0],
        home_lon_deg=HOME[1],
        home_alt_m=HOME[2],
        rng=np.random.default_rng(1),
        terrain=ground,
    )


RIDGE_NORTH_M = 3000.0
RIDGE_M = 300.0


def ridge(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """Home's plain, and an east-west ridge RIDGE_M high centred 3 km north of home."""
    north = (np.asarray(lat_deg) - HOME[0]) * math.radians(1.0) * 6_367_000.0
    return HOME[2] + RIDGE_M * np.exp(-0.5 * ((north - RIDGE_NORTH_M) / 500.0) ** 2)


def into_the_ridge() -> list[MissionItem]:
    """Take off north to 60 m, then on north at 100 m above home: into the ridge's side."""
    return [home_item(), takeoff(1, 60.0), item(2, WP, 8000.0, 0.0, 100.0, frame=REL)]


def test_grid_terrain_interpolates_the_elevation_within_a_metre() -> None:
    grid = GridTerrain(ridge)
    rng = np.random.default_rng(1)
    lat = HOME[0] + rng.uniform(0.0, 0.05, 500)
    lon = HOME[1] + rng.uniform(-0.02, 0.02, 500)
    got = np.array([grid.elevation_m(a, o) for a, o in zip(lat, lon, strict=True)])
    assert np.abs(got - ridge(lat, lon)).max() < 1.0
    assert grid.tiles_loaded >= 2  # the points span more than one tile


def test_hill_is_a_cosine_bump_and_missing_data_is_the_fallback() -> None:
    hill = Hill(HOME[0], HOME[1], radius_m=1000.0, height_m=200.0)
    flat = with_hills(lambda la, lo: np.full(np.shape(la), 400.0), [hill])
    north = [displace_deg(HOME[0], HOME[1], 0.0, d, 0.0)[0] for d in (0.0, 500.0, 1200.0)]
    assert flat(np.array(north), np.full(3, HOME[1])) == pytest.approx([600.0, 500.0, 400.0])

    def no_data(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
        raise ValueError("terrain tile N47E008.hgt not found")

    assert GridTerrain(no_data, fallback_m=123.0).elevation_m(*HOME[:2]) == 123.0


def test_flat_ground_without_terrain_is_home_altitude() -> None:
    ap = make_flat()
    ap.replace_mission(into_the_ridge())  # no ridge here: the ground is flat
    assert ap.set_mode(ap.mode.AUTO) and ap.arm() == (True, "")
    trace = run(ap, 400.0)
    assert ap.crash_time_s is None and not trace.states[-1].on_ground
    assert ap.ground_alt_m == HOME[2]


@pytest.mark.parametrize("slope", [0.01, 0.1, 0.3])
def test_a_takeoff_up_a_slope_rolls_up_it_and_climbs_out(slope: float) -> None:
    """The wheels follow the ground during the roll and their vertical speed carries into the
    climb: rising ground under the runway is no crash."""

    def rising(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
        north = (np.asarray(lat_deg) - HOME[0]) * math.radians(1.0) * 6_367_000.0
        return HOME[2] + slope * np.maximum(north, 0.0)

    ap = make_over(GridTerrain(rising))
    ap.replace_mission([home_item(), takeoff(1, 200.0), item(2, WP, 9000.0, 0.0, 1500.0)])
    assert ap.set_mode(ap.mode.AUTO) and ap.arm() == (True, "")
    trace = run(ap, 120.0, until=lambda a: a.current_seq == 2)  # the climb-out done
    assert ap.crash_time_s is None and ap.current_seq == 2
    rolled = [s for s in trace.states if s.on_ground and s.groundspeed_m_s > 1.0]
    assert rolled and all(s.alt_m > HOME[2] for s in rolled[5:])  # up the slope
    end = trace.states[-1]
    assert not end.on_ground and end.alt_m > ap.ground_alt_m + 50.0
    assert end.alt_m - HOME[2] >= 200.0  # the takeoff altitude is above home


@pytest.mark.parametrize("slope", [0.01, 0.05, 0.15])
def test_a_takeoff_down_a_slope_that_levels_out_lifts_off_level_and_climbs_out(
    slope: float,
) -> None:
    """Rolling down a slope that levels out where the aircraft lifts off: the wheels hold it
    on the ground until the wing lifts, so it leaves level, not sinking with the slope into
    the flat beyond (which was a crash 4 s after lift-off)."""

    def falling(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
        north = (np.asarray(lat_deg) - HOME[0]) * math.radians(1.0) * 6_367_000.0
        return HOME[2] - slope * np.clip(north, 0.0, 40.0)

    ap = make_over(GridTerrain(falling))
    ap.replace_mission([home_item(), takeoff(1, 200.0), item(2, WP, 9000.0, 0.0, 1500.0)])
    assert ap.set_mode(ap.mode.AUTO) and ap.arm() == (True, "")
    trace = run(ap, 120.0, until=lambda a: a.current_seq == 2)
    assert ap.crash_time_s is None and ap.current_seq == 2
    rolled = [s for s in trace.states if s.on_ground and s.groundspeed_m_s > 1.0]
    assert rolled and min(s.alt_m for s in rolled) < HOME[2] - 0.5 * slope * 40.0  # down it
    assert all(s.climb_rate_m_s >= 0.0 for s in trace.states if s.on_ground)
    end = trace.states[-1]
    assert not end.on_ground and end.alt_m > ap.ground_alt_m + 50.0


def test_flown_into_a_ridge_it_crashes_stops_and_says_so_as_arduplane() -> None:
    """ArduPlane/is_flying.cpp crash_detection_update: armed and no longer flying, after the
    is_flying() probability decays and CRASH_DETECTION_DELAY_MS of debounce it sends
    "Crash detected" at MAV_SEVERITY_EMERGENCY and, with CRASH_DETECT's disarm bit, disarms."""
    ap = make_over(GridTerrain(ridge))
    ap.replace_mission(into_the_ridge())
    assert ap.set_mode(ap.mode.AUTO) and ap.arm() == (True, "")
    trace = run(ap, 600.0, until=lambda a: a.crash_detected)
    crash_s = ap.crash_time_s
    assert crash_s is not None
    hit = next(s for s in trace.states if s.time_s >= crash_s)
    north, _ = offset_ne_m(HOME[0], HOME[1], 0.0, hit.lat_deg, hit.lon_deg)
    # On the ridge's southern side, where it rises above the 100 m the mission flies at.
    assert 1500.0 < north < RIDGE_NORTH_M
    assert hit.on_ground and hit.groundspeed_m_s == 0.0 and hit.airspeed_m_s == 0.0
    assert hit.alt_m == pytest.approx(float(ridge(np.array(hit.lat_deg), np.array(0.0))), abs=1.0)
    said = [(t, e) for t, e in trace.events if isinstance(e, Text) and "Crash" in e.text]
    assert len(said) == 1
    t_said, text = said[0]
    assert text.severity == mavlink2.MAV_SEVERITY_EMERGENCY and text.text == "Crash detected"
    assert t_said - crash_s == pytest.approx(CRASH_DETECT_DELAY_S, abs=0.11)
    assert not ap.armed
    assert ap.arm() == (False, "Arm refused: the aircraft crashed")
    # The wreck stays where it hit.
    later = run(ap, 60.0)
    assert {(s.lat_deg, s.lon_deg, s.alt_m) for s in later.states} == {
        (hit.lat_deg, hit.lon_deg, hit.alt_m)
    }


async def test_over_tcp_terrain_report_then_crash_statustext_and_emergency_heartbeat() -> None:
    """What a ground station sees, as ArduPlane sends it:

    - TERRAIN_REPORT (libraries/AP_Terrain/TerrainGCS.cpp send_terrain_report):
      terrain_height the terrain AMSL under the vehicle, current_height its height above it;
    - GLOBAL_POSITION_INT.relative_alt stays relative to HOME, not to the terrain
      (libraries/GCS_MAVLink/GCS_Common.cpp send_global_position_int: current_loc.alt minus
      home's alt);
    - after the crash, STATUSTEXT "Crash detected" at MAV_SEVERITY_EMERGENCY
      (ArduPlane/is_flying.cpp) and HEARTBEAT disarmed with system_status
      MAV_STATE_EMERGENCY (ArduPlane/GCS_Mavlink.cpp vehicle_system_status, is_crashed).
    """
    home = Home(*HOME)
    async with SimTeam.start(
        homes=[home], tcp_base=0, speedup=50.0, terrain=GridTerrain(ridge)
    ) as team:
        v = team.vehicles[0]
        c = await Client.connect(team.ports[0])
        try:
            items = tuple(into_the_ridge())
            v.mission.store(items)
            v.autopilot.replace_mission(items)
            assert v.autopilot.set_mode(v.autopilot.mode.AUTO) and v.autopilot.arm()[0]
            crash = await c.recv(
                lambda m: m.get_type() == "STATUSTEXT" and m.severity <= 2, timeout=30.0
            )
            beat = await c.recv("HEARTBEAT", timeout=5.0)
            pos = await c.recv("GLOBAL_POSITION_INT", timeout=5.0)
        finally:
            await c.close()
    assert crash.severity == mavlink2.MAV_SEVERITY_EMERGENCY and crash.text == "Crash detected"
    assert beat.system_status == mavlink2.MAV_STATE_EMERGENCY
    assert not beat.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    assert pos.vx == pos.vy == pos.vz == 0
    # Before the crash, on the way up the ridge's side.
    reports = [m for m in c.history if m.get_type() == "TERRAIN_REPORT"]
    fixes = [m for m in c.history if m.get_type() == "GLOBAL_POSITION_INT"]
    climbing = [m for m in reports if m.terrain_height > HOME[2] + 20.0 and m.current_height > 10]
    assert climbing, "no TERRAIN_REPORT over the ridge's side"
    for rep in reports:
        lat, lon = rep.lat * 1e-7, rep.lon * 1e-7
        assert rep.spacing == 100
        assert rep.terrain_height == pytest.approx(
            float(ridge(np.array(lat), np.array(lon))), abs=1
        )
    for rep in climbing:
        # The fix sent with the report (same step, same position) gives its altitude.
        fix = next(f for f in fixes if (f.lat, f.lon) == (rep.lat, rep.lon))
        alt = fix.alt * 1e-3
        assert rep.current_height == pytest.approx(alt - rep.terrain_height, abs=0.01)
        assert fix.relative_alt * 1e-3 == pytest.approx(alt - HOME[2], abs=0.002)
        assert fix.relative_alt * 1e-3 > rep.current_height + 19.0  # not above terrain


async def test_terrain_report_is_off_over_flat_ground() -> None:
    """ArduPlane with TERRAIN_ENABLE 0 sends no TERRAIN_REPORT, even when EXTRA3 is asked."""
    async with SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=50.0) as team:
        c = await Client.connect(team.ports[0])
        try:
            c.send(
                mavlink2.MAVLink_request_data_stream_message(
                    1, 1, mavlink2.MAV_DATA_STREAM_EXTRA3, 2, 1
                )
            )
            await asyncio.sleep(0.2)
            got = await c.try_recv("TERRAIN_REPORT", timeout=0.5)
        finally:
            await c.close()
    assert got is None


def test_grid_lookups_in_and_across_tiles_are_the_bilinear_interpolation_of_their_tile() -> None:
    cells = 8
    grid = GridTerrain(ridge, tile_cells=cells)
    cell = grid.cell_deg
    tile_deg = cell * cells

    def bilinear(lat: float, lon: float) -> float:
        """The lookup written plainly: the tile by floor, its samples from ``ridge``."""
        ti, tj = math.floor(lat / tile_deg), math.floor(lon / tile_deg)
        y = (lat - ti * tile_deg) / cell
        x = (lon - tj * tile_deg) / cell
        r, c = min(int(y), cells - 1), min(int(x), cells - 1)
        k = np.arange(cells + 1, dtype=np.float64) * cell
        la, lo = np.meshgrid(ti * tile_deg + k, tj * tile_deg + k, indexing="ij")
        z = ridge(la, lo)
        south = z[r, c] + (z[r, c + 1] - z[r, c]) * (x - c)
        north = z[r + 1, c] + (z[r + 1, c + 1] - z[r + 1, c]) * (x - c)
        return float(south + (north - south) * (y - r))

    rng = np.random.default_rng(2)
    lats = list(HOME[0] + rng.uniform(0.0, 0.05, 300))
    lons = list(HOME[1] + rng.uniform(-0.02, 0.02, 300))
    base_i, base_j = math.floor(HOME[0] / tile_deg), math.floor(HOME[1] / tile_deg)
    for k in range(3):  # on tile edges and a hair either side of them
        for eps in (0.0, 1e-12, -1e-12):
            lats.append((base_i + k) * tile_deg + eps)
            lons.append((base_j + k) * tile_deg - eps)
    for lat, lon in zip(lats, lons, strict=True):
        assert grid.elevation_m(lat, lon) == bilinear(lat, lon)

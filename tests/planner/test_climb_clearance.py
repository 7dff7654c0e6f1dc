"""Terrain clearance along the path as it is flown: the climb from home and the first leg.

A home on a 1 km ridge with start and goal altitudes of 485 m (a flight altitude below the
home) once gave a mission whose climb-out ended 1 m above the ridge and whose first leg went
straight down toward 485 m: the planner had checked its profile from 1179 m at the start, an
altitude the mission never climbed to. Now the climb-out ends where the profile starts, and a
climb from home into rising ground is refused, naming the vehicle and the position.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from planner.errors import InfeasibleError
from planner.mission import MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_WAYPOINT
from planner.plan import PROFILE_STEP_M, build_world, plan, sample_by_distance
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from planner.schedulefile import path_mission
from tests.planner.conftest import small_scenario
from tests.planner.test_terrain import tile_grid_deg, write_tile

ORIGIN = {"lat_deg": 45.3, "lon_deg": 7.3}
PLAIN_M = 335.0


def _ridge_scenario(
    tmp_path: Path, *, ridge_east_m: float, start_east_m: float, ridge_m: float
) -> dict[str, Any]:
    """One vehicle flying east across a north-south ridge (an SRTM tile written here)."""
    data = small_scenario(threats=[])
    data["area"].update(origin=ORIGIN, min_east_m=-20000, min_north_m=-20000)
    vehicle = data["vehicles"][0]
    vehicle["start"] = {"east_m": start_east_m, "north_m": 0.0, "alt_m": 485.0}
    vehicle["goal"] = {"east_m": 18000.0, "north_m": 0.0, "alt_m": 485.0}
    data["vehicles"] = [vehicle]
    frame = parse_scenario(data).frame()
    lat, lon = tile_grid_deg(45, 7, 1201)
    east, _north = frame.to_local(lat, lon)
    # A ridge 2 km wide (sigma 800 m) across the whole area, ridge_m above the plain.
    height = PLAIN_M + (ridge_m - PLAIN_M) * np.exp(-0.5 * ((east - ridge_east_m) / 800.0) ** 2)
    write_tile(tmp_path, 45, 7, np.round(height))
    data["terrain"] = {"kind": "srtm", "directory": str(tmp_path)}
    return data


def _flown_alt_m(items: Any, item_s: Any, home_alt_m: float) -> tuple[list[float], list[float]]:
    """The altitude the autopilot flies against path distance: the climb-out's altitude at the
    start, then straight lines between the mission's waypoints (relative frames)."""
    s_m, alt_m = [], []
    for it, s in zip(items, item_s, strict=True):
        if it.command == MAV_CMD_NAV_TAKEOFF:
            s_m.append(0.0)
            alt_m.append(home_alt_m + it.z)
        elif it.command == MAV_CMD_NAV_WAYPOINT and s is not None:
            s_m.append(s)
            alt_m.append(home_alt_m + it.z)
    return s_m, alt_m


def test_home_on_a_ridge_climbs_to_the_profile_before_the_first_leg(tmp_path: Path) -> None:
    scenario = parse_scenario(
        _ridge_scenario(tmp_path, ridge_east_m=-15000.0, start_east_m=-15000.0, ridge_m=1000.0)
    )
    world = build_world(scenario)
    p = plan(scenario, method="astar", rng=np.random.default_rng(0), world=world)
    schedule = build_schedule(scenario, p, world=world)
    vs = schedule.vehicles[0]
    mission = path_mission(schedule, vs, world.terrain)
    home_alt = mission.items[0].z
    assert home_alt > 990.0  # home is on the ridge, 500 m above the start altitude
    v = scenario.vehicles[0]
    takeoff = mission.items[1]
    assert takeoff.command == MAV_CMD_NAV_TAKEOFF
    assert takeoff.z >= v.clearance_m - 1.0
    assert home_alt + takeoff.z == pytest.approx(vs.alt_at(0.0), abs=0.01)
    # From the end of the climb-out on, the mission as flown keeps the clearance.
    s_wp, alt_wp = _flown_alt_m(mission.items, mission.item_s_m, home_alt)
    s, pts = sample_by_distance(vs.path, PROFILE_STEP_M)
    clearance = np.interp(s, s_wp, alt_wp) - world.terrain.elevation_m(pts[:, 0], pts[:, 1])
    assert clearance.min() >= v.clearance_m - 1.0, (clearance.min(), s[int(clearance.argmin())])


def test_climb_from_home_into_rising_ground_is_refused_naming_vehicle_and_place(
    tmp_path: Path,
) -> None:
    # Home on the plain 2.5 km short of a 1000 m ridge: climbing at the 0.1 gradient the
    # aircraft is 250 m above home there, below the ridge top.
    scenario = parse_scenario(
        _ridge_scenario(tmp_path, ridge_east_m=-12500.0, start_east_m=-15000.0, ridge_m=1000.0)
    )
    with pytest.raises(InfeasibleError) as err:
        plan(scenario, method="astar", rng=np.random.default_rng(0))
    msg = str(err.value)
    assert re.match(r"vehicle A: clearance: climbing from home \(34\d m\) at gradient 0\.1, ", msg)
    lat, lon = (float(x) for x in msg.split("(lat ")[1].rstrip(")").split(", lon "))
    frame = scenario.frame()
    east, north = (float(x) for x in frame.to_local(lat, lon))
    # The place named lies on the way up to the ridge, between home and the ridge line.
    assert -15000.0 < east <= -12000.0 and abs(north) < 1500.0, (east, north)


def test_a_ridge_the_climb_outclimbs_is_flown(tmp_path: Path) -> None:
    # The same ridge 12 km from home: at 0.1 the climb is 1200 m above home by then.
    scenario = parse_scenario(
        _ridge_scenario(tmp_path, ridge_east_m=-3000.0, start_east_m=-15000.0, ridge_m=1000.0)
    )
    p = plan(scenario, method="astar", rng=np.random.default_rng(0))
    route = p.routes[0]
    assert route.profile.min_clearance_m >= scenario.vehicles[0].clearance_m - 1.0
    assert math.isfinite(route.length_m)

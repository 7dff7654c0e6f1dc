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
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from planner import plan as plan_module
from planner.errors import InfeasibleError
from planner.mission import MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_WAYPOINT
from planner.plan import (
    CLIMB_OUT_CLEARANCE_FRACTION,
    PROFILE_STEP_M,
    PlannedRoute,
    build_world,
    plan,
    sample_by_distance,
)
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from planner.schedulefile import path_mission
from tests.planner.conftest import small_scenario
from tests.planner.test_terrain import tile_grid_deg, write_tile

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
from bench_planner import team_scenario  # noqa: E402  (the planner bench's generated teams)

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


def _turned_rad(route: PlannedRoute, from_m: float) -> float:
    """How much the path turns (rad, either way, summed) from ``from_m`` to its end, from
    headings sampled every 50 m."""
    s, pts = sample_by_distance(route.path, PROFILE_STEP_M)
    end = pts[s >= from_m, :2]
    heading = np.arctan2(*np.diff(end, axis=0).T)
    return float(np.abs((np.diff(heading) + np.pi) % (2 * np.pi) - np.pi).sum())


def test_a_route_whose_shortened_climb_is_too_low_is_shortened_after_the_climb(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The planner bench's 100-vehicle team once flew four routes as their grid legs, 10 km
    # longer, because their straight climb from home went too low over rising ground:
    # U014's ended in a loop round its last grid point, 340 m past its approach point, that
    # crossed its neighbours' tracks there. Alone, on the exact search, it is the same.
    data = parse_scenario(team_scenario(100, 0)).model_dump(mode="json", exclude_none=True)
    data["vehicles"] = [v for v in data["vehicles"] if v["id"] == "U014"]
    data["assign_goals"] = False  # its approach point in the team's sharing-out
    scenario = parse_scenario(data)
    v = scenario.vehicles[0]
    world = build_world(scenario)

    def routed() -> PlannedRoute:
        return plan(scenario, method="astar", world=world).routes[0]

    monkeypatch.setattr(plan_module, "CLIMB_HEAD_FACTOR", math.inf)  # grid legs or nothing
    as_grid = routed()
    monkeypatch.undo()
    route = routed()
    assert len(as_grid.simplified_m) == len(as_grid.grid_points_m)
    assert as_grid.path.length_m > as_grid.grid_length_m
    assert _turned_rad(as_grid, as_grid.path.length_m - 2000.0) > math.pi  # the loop
    # Now the grid legs are flown over the climb only: 5% shorter than the grid route, with
    # a few straight legs after the climb and no loop before the approach point.
    assert route.path.length_m < 0.96 * route.grid_length_m
    assert len(route.simplified_m) < 0.2 * len(route.grid_points_m)
    assert _turned_rad(route, route.path.length_m - 2000.0) < math.radians(45.0)
    # The climb from home, worked out here from the path, the terrain and the gradient,
    # keeps the clearance the vehicle needs climbing until it meets the profile.
    s, pts = sample_by_distance(route.path, PROFILE_STEP_M)
    ground = world.terrain.elevation_m(pts[:, 0], pts[:, 1])
    planned = np.interp(s, route.profile.s_m, route.profile.alt_m)
    flown = np.minimum(ground[0] + v.climb_gradient * s, planned)
    climbing = flown < planned
    need = np.minimum(v.clearance_m, CLIMB_OUT_CLEARANCE_FRACTION * (flown - ground[0]))
    assert climbing[1:].any()
    assert (flown - ground - need)[climbing].min() >= -1.0
    assert route.profile.min_clearance_m >= v.clearance_m - 1.0

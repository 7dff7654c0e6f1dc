"""Landing slots in the planner: each route crosses its slot fix on the approach course after
a straight final, airborne vehicles get no takeoff, and the mission goes on to the runway with
DO_LAND_START and NAV_LAND (ArduPlane: ArduPlane/commands_logic.cpp runs DO_LAND_START as a
marker; NAV_LAND glides from the previous waypoint). The checks here recompute the geometry
from the scenario, not from the planner's own figures."""

from __future__ import annotations

import copy
import math
from typing import Any

import pytest

from planner.errors import InfeasibleError, ScenarioError
from planner.mission import (
    MAV_CMD_DO_LAND_START,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
)
from planner.plan import build_world, plan
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from planner.schedulefile import path_mission
from tests.teams import landing_scenario


def _course(doc: dict[str, Any]) -> tuple[float, float]:
    c = math.radians(doc["landing"]["heading_deg"])
    return math.sin(c), math.cos(c)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_each_route_crosses_its_slot_fix_on_the_course_after_a_straight_final(seed: int) -> None:
    doc, _ = landing_scenario(seed)
    scenario = parse_scenario(doc)
    schedule = build_schedule(scenario, plan(scenario))
    ue, un = _course(doc)
    approach_m = doc["landing"]["approach_m"]
    for vs in schedule.vehicles:
        goal = next(v for v in doc["vehicles"] if v["id"] == vs.vehicle_id)["goal"]
        path = vs.path
        end = path.end
        assert math.hypot(end.east_m - goal["east_m"], end.north_m - goal["north_m"]) < 1.0
        # The last stretch is straight on the course: sampled points lie on the centreline.
        for back_m in (0.0, 0.25 * approach_m, 0.5 * approach_m):
            p = path.pose_at(path.length_m - back_m)
            across = -(p.east_m - goal["east_m"]) * un + (p.north_m - goal["north_m"]) * ue
            along = (p.east_m - goal["east_m"]) * ue + (p.north_m - goal["north_m"]) * un
            assert abs(across) < 1.0, (vs.vehicle_id, back_m, across)
            assert along == pytest.approx(-back_m, abs=1.0)
            assert math.sin(p.heading_rad) * ue + math.cos(p.heading_rad) * un > math.cos(
                math.radians(0.5)
            )
            # ... flown level at the slot fix's altitude (a stabilised final, not a climb).
            assert vs.alt_at(path.length_m - back_m) == pytest.approx(goal["alt_m"], abs=1.0)


def test_an_airborne_vehicle_mission_has_no_takeoff_and_lands_after_its_slot_fix() -> None:
    doc, _ = landing_scenario(0)
    scenario = parse_scenario(doc)
    world = build_world(scenario)
    schedule = build_schedule(scenario, plan(scenario, world=world), world=world)
    touchdown = doc["landing"]["touchdown"]
    frame = scenario.frame()
    for vs in schedule.vehicles:
        pm = path_mission(schedule, vs, world.terrain, runout_m=300.0)
        cmds = [it.command for it in pm.items]
        assert MAV_CMD_NAV_TAKEOFF not in cmds
        assert pm.first_route_seq == 1
        # The first NAV item is a waypoint (a DO_CHANGE_SPEED before it runs at the start).
        assert next(c for c in cmds[1:] if c < 100) == MAV_CMD_NAV_WAYPOINT
        # ... the slot fix, DO_LAND_START at it, NAV_LAND at the touchdown: no run-out beyond
        # the fix (the glide starts from the fix).
        assert cmds[-3:] == [MAV_CMD_NAV_WAYPOINT, MAV_CMD_DO_LAND_START, MAV_CMD_NAV_LAND]
        fix, start, land = pm.items[-3:]
        assert (start.x, start.y) == (fix.x, fix.y)
        goal = scenario.vehicle(vs.vehicle_id).goal
        glat, glon = frame.to_geodetic(goal.east_m, goal.north_m)
        assert fix.lat_deg == pytest.approx(float(glat), abs=2e-7)
        assert fix.lon_deg == pytest.approx(float(glon), abs=2e-7)
        tlat, tlon = frame.to_geodetic(touchdown["east_m"], touchdown["north_m"])
        assert land.lat_deg == pytest.approx(float(tlat), abs=2e-7)
        assert land.lon_deg == pytest.approx(float(tlon), abs=2e-7)
        assert len(pm.item_s_m) == len(pm.items)


def test_a_goal_off_the_centreline_is_refused_naming_the_vehicle() -> None:
    doc, _ = landing_scenario(0)
    bad = copy.deepcopy(doc)
    ue, un = _course(doc)
    g = bad["vehicles"][2]["goal"]
    g["east_m"], g["north_m"] = g["east_m"] + 200.0 * un, g["north_m"] - 200.0 * ue
    with pytest.raises(ScenarioError, match=r"vehicles\[2\] \(G2\)\.goal is not a slot fix"):
        parse_scenario(bad)


def test_a_goal_beyond_the_touchdown_is_refused() -> None:
    doc, _ = landing_scenario(0)
    bad = copy.deepcopy(doc)
    ue, un = _course(doc)
    t = bad["landing"]["touchdown"]
    g = bad["vehicles"][0]["goal"]
    g["east_m"], g["north_m"] = t["east_m"] + 3_000.0 * ue, t["north_m"] + 3_000.0 * un
    with pytest.raises(ScenarioError, match=r"\(G0\)\.goal is not a slot fix"):
        parse_scenario(bad)


def test_a_glide_steeper_than_the_vehicle_can_descend_is_refused() -> None:
    doc, _ = landing_scenario(0)
    bad = copy.deepcopy(doc)
    bad["vehicles"][1]["goal"]["alt_m"] = doc["landing"]["touchdown"]["alt_m"] + 900
    bad["vehicles"][1]["climb_gradient"] = 0.1
    with pytest.raises(ScenarioError, match=r"\(G1\)\.goal: alt_m .* no steeper than"):
        parse_scenario(bad)


def test_a_glide_through_a_forbidden_zone_is_refused_naming_the_vehicle_and_zone() -> None:
    doc, _ = landing_scenario(0)
    bad = copy.deepcopy(doc)
    ue, un = _course(doc)
    t = bad["landing"]["touchdown"]
    centre = {"east_m": t["east_m"] - 3_000.0 * ue, "north_m": t["north_m"] - 3_000.0 * un}
    bad["threats"] = [
        {"kind": "radar", "id": "SAM", "center": centre, "radius_m": 800, "forbidden": True}
    ]
    scenario = parse_scenario(bad)
    with pytest.raises(InfeasibleError, match=r"vehicle G0: the glide .* forbidden zone SAM"):
        plan(scenario)

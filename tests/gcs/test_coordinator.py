"""The coordinator: mission splicing and in-flight re-timing (pure), the pre-launch refusal,
the rehearsal CLI's input checks, and one full rehearsal of the paper scenario against stub
vehicles over loopback TCP (wind, 10% loss, the pop-up threat)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gcs.__main__ import main
from gcs.coordinator import Coordinator, InfeasibleRequest
from gcs.missionclock import MissionClock
from gcs.rehearse import RehearsalOptions, passed, rehearse
from planner.errors import PlannerError
from planner.mission import MAV_CMD_DO_CHANGE_SPEED, MAV_CMD_NAV_LOITER_TURNS, MAV_CMD_NAV_WAYPOINT
from planner.plan import World, build_world, plan
from planner.scenario import Scenario, load_scenario
from planner.schedule import Schedule, build_schedule, retime_vehicle
from planner.schedulefile import path_mission, splice_mission
from planner.threats import active

PAPER = Path(__file__).resolve().parents[2] / "scenarios" / "paper_three_uav.yaml"


@pytest.fixture(scope="module")
def paper() -> tuple[Scenario, World, Schedule]:
    scenario = load_scenario(PAPER)
    world = build_world(scenario)
    p = plan(scenario, rng=np.random.default_rng(1), world=world)
    return scenario, world, build_schedule(scenario, p, world=world)


def _route_waypoints(pm: object) -> list[int]:
    items = pm.items  # type: ignore[attr-defined]
    return [k for k, it in enumerate(items) if k >= 2 and it.command == MAV_CMD_NAV_WAYPOINT]


def test_runout_waypoint_lies_beyond_the_goal_on_the_final_heading(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    _, world, schedule = paper
    vs = schedule.vehicle("UAV1")
    plain = path_mission(schedule, vs, world.terrain)
    longer = path_mission(schedule, vs, world.terrain, runout_m=300.0)
    assert len(longer.items) == len(plain.items) + 1
    assert longer.item_s_m[-1] == pytest.approx(vs.path.length_m + 300.0)
    assert longer.items[:-1] == plain.items


def test_retime_in_flight_adds_loiter_with_speed_margin(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    scenario, world, schedule = paper
    vs = schedule.vehicle("UAV3")
    s_now = 20_000.0
    now = 1500.0
    late_target = vs.arrival_s + 400.0  # 400 s later than planned: speed alone cannot absorb it
    new, adjustments = retime_vehicle(
        schedule,
        "UAV3",
        now_s=now,
        s_m=s_now,
        speed_m_s=15.5,
        target_s=late_target,
        threats=active(world.threats, now),
        loiter_margin_m_s=1.0,
    )
    assert {a.strategy for a in adjustments} >= {"loiter", "speed"}
    assert new.loiters and all(lo.s_m > s_now for lo in new.loiters)
    assert new.arrival_s == pytest.approx(late_target, abs=1e-3)
    flown = sum(leg.s_end_m - leg.s_start_m for leg in new.legs if leg.s_start_m >= s_now)
    held = sum(lo.t_end_s - lo.t_start_s for lo in new.loiters)
    legs_time = late_target - now - held
    v = scenario.vehicle("UAV3")
    assert flown / legs_time >= v.speed_min_m_s + 1.0 - 0.05  # the margin left to slow down
    # every leg speed is inside the vehicle's range (no command outside its limits)
    assert all(v.speed_min_m_s <= leg.speed_m_s <= v.speed_max_m_s for leg in new.legs)


def test_splice_keeps_the_flown_prefix_and_starts_the_new_speeds_at_the_kept_waypoint(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    _, world, schedule = paper
    vs = schedule.vehicle("UAV3")
    old = path_mission(schedule, vs, world.terrain, runout_m=300.0)
    keep = _route_waypoints(old)[2]
    s_k = old.item_s_m[keep]
    assert s_k is not None
    new_vs, _ = retime_vehicle(
        schedule,
        "UAV3",
        now_s=1000.0,
        s_m=s_k,
        speed_m_s=16.0,
        target_s=vs.arrival_s + 400.0,
        threats=active(world.threats, 1000.0),
        loiter_margin_m_s=1.0,
    )
    new = path_mission(schedule, new_vs, world.terrain, runout_m=300.0)
    spliced = splice_mission(old, keep, new)
    assert spliced.items[: keep + 1] == old.items[: keep + 1]
    assert [it.seq for it in spliced.items] == list(range(len(spliced.items)))
    assert spliced.items[keep + 1].command == MAV_CMD_DO_CHANGE_SPEED
    tail = spliced.item_s_m[keep + 1 :]
    assert all(s is not None and s >= s_k for s in tail)
    assert any(it.command == MAV_CMD_NAV_LOITER_TURNS for it in spliced.items[keep + 1 :])
    # the route still ends at the same goal
    assert spliced.items[-1].x == old.items[-1].x and spliced.items[-1].y == old.items[-1].y


def test_splice_refuses_an_item_that_is_not_a_route_waypoint(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    _, world, schedule = paper
    pm = path_mission(schedule, schedule.vehicle("UAV1"), world.terrain)
    speed_item = next(k for k, it in enumerate(pm.items) if it.command == MAV_CMD_DO_CHANGE_SPEED)
    with pytest.raises(PlannerError, match=f"item {speed_item} is not a route waypoint"):
        splice_mission(pm, speed_item, pm)
    with pytest.raises(PlannerError, match="outside the old mission"):
        splice_mission(pm, len(pm.items), pm)


async def test_infeasible_request_is_refused_before_launch_naming_time_and_vehicle() -> None:
    coord = Coordinator(load_scenario(PAPER), MissionClock(), required_arrival_s=5000.0)
    with pytest.raises(InfeasibleRequest) as err:
        await coord.prepare()
    text = str(err.value)
    assert "refused before launch" in text and "5000.0 s cannot be met" in text
    assert "earliest feasible 5478.0 s" in text and "UAV2" in text
    assert not coord.members  # nothing was compiled or uploaded


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--blackout", "UAV9,100,10"], "no vehicle 'UAV9'"),
        (["--blackout", "UAV1,x,10"], "VEHICLE,START_S,DURATION_S"),
        (["--wind", "five"], "--wind"),
        (["--loss", "1.5"], "--loss"),
        (["--speedup", "0"], "--speedup"),
        (["--connect", "tcp:127.0.0.1:5760", "--wind", "5,270"], "apply to the stub"),
    ],
)
def test_rehearse_bad_input_is_exit_2_naming_the_option(
    extra: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["rehearse", str(PAPER), *extra]) == 2
    assert message in capsys.readouterr().err


def test_rehearse_missing_scenario_is_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["rehearse", str(tmp_path / "nope.yaml")]) == 2
    assert "nope.yaml" in capsys.readouterr().err


async def test_paper_rehearsal_holds_the_arrival_time(tmp_path: Path) -> None:
    """The must-show run: 200x, wind 5 m/s from 270, 10% loss, the pop-up threat."""
    out = tmp_path / "flight.json"
    record = await rehearse(
        RehearsalOptions(
            scenario_path=PAPER,
            scenario=load_scenario(PAPER),
            speedup=200.0,
            wind=(5.0, 270.0),
            loss=0.1,
            seed=1,
            json_out=out,
            quiet=True,
        )
    )
    assert out.exists()
    assert record["arrival_source"] == "simulator"
    errors = {v["id"]: v["error_s"] for v in record["vehicles"]}
    assert all(e is not None and abs(e) <= 1.0 for e in errors.values()), errors
    assert passed(record, 1.0)
    assert record["min_separation_m"] >= record["separation_m"]
    strategies = {a["strategy"] for a in record["adjustments"]}
    assert strategies >= {"takeoff_delay", "speed", "loiter"}
    # the longest-path vehicle launches first; the pop-up appeared and was re-planned around
    takeoffs = {v["id"]: v["takeoff_utc_s"] for v in record["vehicles"]}
    assert takeoffs["UAV2"] < takeoffs["UAV1"] and takeoffs["UAV2"] < takeoffs["UAV3"]
    assert [t["id"] for t in record["threats_appeared"]] == ["POPUP1"]
    kinds = {e["kind"] for e in record["events"]}
    assert {"launch", "popup", "replan", "arrived"} <= kinds
    assert math.isfinite(record["wall_s"]) and record["wall_s"] < 180.0

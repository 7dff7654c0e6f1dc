"""The flight runner's pieces: mission splicing and in-flight re-timing (pure), the
pre-launch refusal and the rehearsal CLI's input checks (the team controller is in
``test_team.py``). Whole rehearsals are in ``test_rehearsals.py``."""

from __future__ import annotations

import asyncio
import re
import threading
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gcs.__main__ import main
from gcs.coordination import actions as act
from gcs.coordination.missionclock import MissionClock
from gcs.coordination.runner import FlightRunner, InfeasibleRequest
from gcs.mavlink.link import LinkCounters
from gcs.mavlink.telemetry import TelemetryReducer
from planner.atmosphere import eas2tas
from planner.errors import InfeasibleError, PlannerError
from planner.mission import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_LOITER_TURNS,
    MAV_CMD_NAV_LOITER_UNLIM,
    MAV_CMD_NAV_WAYPOINT,
)
from planner.plan import World
from planner.popup import PopupOutcome, apply_popup, popup_zones
from planner.retime import retime_vehicle
from planner.scenario import Scenario, load_scenario
from planner.schedule import Anchor, Schedule
from planner.schedulefile import path_mission, splice_mission
from planner.threats import active, build_threats
from planner.timing import flyable_loiter_radius_m
from tests.gcs.test_telemetry import heartbeat

PAPER = Path(__file__).resolve().parents[2] / "scenarios" / "paper_three_uav.yaml"


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
    assert len(longer.items) == len(plain.items) + 2
    assert longer.items[:-2] == plain.items
    runout, hold = longer.items[-2:]
    assert runout.command == MAV_CMD_NAV_WAYPOINT
    assert longer.item_s_m[-2] == pytest.approx(vs.path.length_m + 300.0)
    # Then it holds there (NAV_LOITER_UNLIM, clockwise at its loiter radius, the run-out's
    # altitude) rather than ending the mission, which ArduPlane follows with RTL home at
    # RTL_ALTITUDE over whatever lies between.
    assert hold.command == MAV_CMD_NAV_LOITER_UNLIM
    assert (hold.x, hold.y, hold.z) == (runout.x, runout.y, runout.z)
    scenario = schedule.scenario
    assert hold.param3 == flyable_loiter_radius_m(scenario.vehicle("UAV1").min_turn_radius_m)


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
    runner = FlightRunner(load_scenario(PAPER), MissionClock(), required_arrival_s=5000.0)
    with pytest.raises(InfeasibleRequest) as err:
        await runner.prepare()
    text = str(err.value)
    assert "refused before launch" in text and "requested arrival 5000.0 s is too early" in text
    # UAV2's path at its top speed, 30 m/s equivalent airspeed: true airspeed at 435-1600 m.
    found = re.search(r"earliest feasible ([\d.]+) s\b.*UAV2 .*, ([\d.]+) km at 30 m/s", text)
    assert found, text
    earliest_s, km = float(found[1]), float(found[2])
    assert km * 1000.0 / (30.0 * eas2tas(1600.0)) <= earliest_s
    assert earliest_s <= km * 1000.0 / (30.0 * eas2tas(435.0))
    assert not runner.members  # nothing was compiled or uploaded


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--blackout", "UAV9,100,10"], "no vehicle 'UAV9'"),
        (["--blackout", "UAV1,x,10"], "VEHICLE,START_S,DURATION_S"),
        (["--wind", "five"], "--wind"),
        (["--loss", "1.5"], "--loss"),
        (["--speedup", "0"], "--speedup"),
        (["--connect", "tcp:127.0.0.1:5760", "--wind", "5,270"], "apply to the stub"),
        (["--truth", "/no/such/dir/truth.jsonl"], "directory does not exist"),
        (["--hill", "46.5,8.0,1500"], "--hill: expected LAT,LON,RADIUS_M,HEIGHT_M"),
        (["--hill", "46.5,8.0,0,600"], "RADIUS_M > 0"),
        (["--connect", "tcp:127.0.0.1:5760", "--hill", "46.5,8,1500,600"], "apply to the stub"),
        (["--stall-bound", "0"], "--stall-bound must be a positive number"),
        (["--hard-deadline", "nan"], "--hard-deadline must be a positive number"),
        (
            ["--connect", "tcp:127.0.0.1:5760", "--truth", "/no/such/dir/truth.jsonl"],
            "directory does not exist",
        ),
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


def test_long_legs_are_split_into_waypoints_no_farther_apart_than_asked(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    scenario, world, schedule = paper
    vs = schedule.vehicle("UAV2")
    plain = path_mission(schedule, vs, world.terrain, runout_m=300.0)
    split = path_mission(schedule, vs, world.terrain, runout_m=300.0, max_spacing_m=5000.0)

    def route_s(pm: object) -> list[float]:
        return [pm.item_s_m[k] for k in _route_waypoints(pm)]  # type: ignore[attr-defined]

    s_plain, s_split = route_s(plain), route_s(split)
    assert max(np.diff(s_plain[:-1])) > 20_000.0  # the planner's legs are long
    assert max(np.diff(s_split[:-1])) <= 5000.0 + 1e-6
    assert all(any(abs(a - b) < 1e-6 for b in s_split) for a in s_plain)  # none dropped
    frame = scenario.frame()
    for k in _route_waypoints(split)[:-1]:  # the last is the run-out past the goal
        s = split.item_s_m[k]
        assert s is not None
        pose = vs.path.pose_at(s)
        lat, lon = frame.to_geodetic(pose.east_m, pose.north_m)
        it = split.items[k]
        assert (it.x, it.y) == (round(float(lat) * 1e7), round(float(lon) * 1e7))
        # above home, both in ArduPilot's whole centimetres
        assert it.z == pytest.approx(vs.alt_at(s) - split.items[0].z, abs=0.021)

    def speeds(pm: object) -> list[float]:
        items = pm.items  # type: ignore[attr-defined]
        return [it.param2 for it in items if it.command == MAV_CMD_DO_CHANGE_SPEED]

    assert speeds(split) == speeds(plain)
    with pytest.raises(PlannerError, match="max_spacing_m"):
        path_mission(schedule, vs, world.terrain, max_spacing_m=0.0)


def test_popup_anchor_time_is_when_the_vehicle_reaches_the_splice_point(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    """A coordinator re-plans from a waypoint ahead; the vehicle is there at its own time,
    which sets the earliest arrival (the anchor once meant 'there at the re-plan time')."""
    scenario, world, schedule = paper
    threats = build_threats(scenario, {vs.vehicle_id: vs.takeoff_s for vs in schedule.vehicles})
    zone = popup_zones(threats)[0]
    t_p = float(zone.appears_at_s or 0.0)
    w = replace(world, threats=tuple(threats))
    ahead_s = 600.0
    where = {}
    for vid in ("UAV1", "UAV2"):
        phase, s_m, speed = schedule.vehicle(vid).state_at(t_p + ahead_s)
        assert phase == "leg"
        where[vid] = (s_m, speed)

    def outcome(with_time: bool) -> PopupOutcome:
        anchors = {
            vid: Anchor(s, v, t_p + ahead_s if with_time else None) for vid, (s, v) in where.items()
        }
        return apply_popup(
            schedule, zone, at_s=t_p, world=w, threats=active(threats, t_p),
            rng=np.random.default_rng(7), anchors=anchors,
        )  # fmt: skip

    timed, untimed = outcome(True), outcome(False)
    assert set(timed.affected) == {"UAV1", "UAV2"}
    # The earliest each can arrive: at its anchor 600 s on, then its new path at top speed.
    untimed_short = []
    for vid, (s_m, _) in where.items():
        v = scenario.vehicle(vid)
        vs = timed.schedule.vehicle(vid)
        path_m = vs.path.length_m
        fastest_m_s = v.speed_max_m_s * eas2tas(float(vs.wp_alt_m.max()))  # true airspeed
        earliest = t_p + ahead_s + (path_m - s_m) / fastest_m_s
        assert timed.schedule.vehicle(vid).arrival_s >= earliest - 1e-3, vid
        if untimed.schedule.vehicle(vid).arrival_s < earliest - 60.0:
            untimed_short.append(vid)
    assert untimed_short  # read as 'there at the re-plan time', the team time is unflyable
    for vid, (s_m, _) in where.items():
        legs = timed.schedule.vehicle(vid).legs
        first_new = next(leg for leg in legs if leg.s_start_m >= s_m - 1e-6)
        assert first_new.t_start_s == pytest.approx(t_p + ahead_s)
        _, s_then, _ = timed.schedule.vehicle(vid).state_at(t_p + ahead_s)
        assert s_then == pytest.approx(s_m, abs=1e-3)


def test_a_re_plan_whose_search_time_is_up_still_routes_round_the_zone(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    """The coordinator gives the route search a share of the planning lead in wall time;
    when that is spent at once, the re-plan takes the first routes its search found, and
    every affected vehicle's new path (sampled every 50 m, past the splice point) still keeps
    out of the zone."""
    scenario, world, schedule = paper
    threats = build_threats(scenario, {vs.vehicle_id: vs.takeoff_s for vs in schedule.vehicles})
    zone = popup_zones(threats)[0]
    t_p = float(zone.appears_at_s or 0.0)
    w = replace(world, threats=tuple(threats))
    asked: list[float] = []

    def time_up() -> bool:
        asked.append(t_p)
        return True

    out = apply_popup(
        schedule, zone, at_s=t_p, world=w, threats=active(threats, t_p),
        rng=np.random.default_rng(7), time_up=time_up,
    )  # fmt: skip
    assert out.affected and asked
    for vid in out.affected:
        vs = out.schedule.vehicle(vid)
        _, s0, _ = vs.state_at(t_p)
        s = np.arange(s0, vs.path.length_m, 50.0)
        pts = np.array([(p.east_m, p.north_m) for p in map(vs.path.pose_at, s)])
        assert float(zone.distance_m(pts[:, 0], pts[:, 1]).min()) > 0.0, vid
    assert out.schedule.vehicle(out.affected[0]).replanned_at_s == (t_p,)


@pytest.mark.parametrize("rtt_wall_s", [None, 0.0005, 0.05, 0.3])
def test_on_a_pace_clock_a_command_waits_one_to_two_seconds_of_flight_whatever_the_round_trip(
    rtt_wall_s: float | None,
) -> None:
    """In lock step a busy machine makes round trips long in wall time, not in flight time:
    five measured round trips as the reply timeout cost up to 47 s of flight at 200x when a
    launch's command was lost. The timeout stays within 1-2 s of flight; the retries cover
    0.4 s of wall time, so a busy machine does not give a command up."""
    clock = MissionClock()
    runner = FlightRunner(load_scenario(PAPER), clock)
    clock.follow(lambda: 0.0)
    clock._rate = 200.0  # what the simulator's SYSTEM_TIME shows at 200x
    counters = SimpleNamespace(rtt_s=rtt_wall_s)
    vehicle = SimpleNamespace(link=SimpleNamespace(counters=counters))
    options = runner._command(vehicle)  # type: ignore[arg-type]
    flight_s = options["timeout_s"] * 200.0
    assert 1.0 - 1e-9 <= flight_s <= 2.0 + 1e-9
    assert options["timeout_s"] * (options["retries"] + 1) >= 0.4


def test_a_re_plan_the_others_cannot_wait_for_times_the_re_planned_among_themselves(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    """UAV3 2 km short of its goal when POPUP1 appears (past its buffer: it cannot wait until
    the re-planned UAV1 and UAV2 can arrive): no common time remains, and a re-plan offline
    says so. In flight (``others_may_stay``) the re-planned two are timed among themselves,
    routed round the zone, and UAV3 keeps its schedule, said in the arrival event."""
    scenario, world, schedule = paper
    threats = build_threats(scenario, {vs.vehicle_id: vs.takeoff_s for vs in schedule.vehicles})
    zone = popup_zones(threats)[0]
    t_p = float(zone.appears_at_s or 0.0)
    w = replace(world, threats=tuple(threats))
    uav3 = schedule.vehicle("UAV3")
    anchors = {"UAV3": Anchor(uav3.path.length_m - 2_000.0, 20.0, t_p)}

    def outcome(others_may_stay: bool) -> PopupOutcome:
        return apply_popup(
            schedule, zone, at_s=t_p, world=w, threats=active(threats, t_p),
            rng=np.random.default_rng(7), anchors=anchors, others_may_stay=others_may_stay,
        )  # fmt: skip

    with pytest.raises(InfeasibleError, match="UAV3"):
        outcome(False)
    out = outcome(True)
    assert set(out.affected) == {"UAV1", "UAV2"}
    assert out.schedule.vehicle("UAV3") is uav3
    ref = out.schedule.required_arrival_s
    assert ref is not None and ref > t_p + 2_000.0 / 15.0 + 600.0  # far past UAV3's latest
    for vid in out.affected:
        vs = out.schedule.vehicle(vid)
        assert vs.arrival_s == pytest.approx(ref, abs=0.5), vid
        _, s0, _ = vs.state_at(t_p)
        s = np.arange(s0, vs.path.length_m, 50.0)
        pts = np.array([(p.east_m, p.north_m) for p in map(vs.path.pose_at, s)])
        assert float(zone.distance_m(pts[:, 0], pts[:, 1]).min()) > 0.0, vid
    (said,) = [e.text for e in out.events if e.kind == "arrival"]
    assert "they keep their schedules" in said and "UAV3" in said, said


async def test_a_vehicle_whose_reports_stopped_shows_its_mode_unknown_in_the_snapshot() -> None:
    """The snapshot's ``link`` for a vehicle the flight has judged silent (on a simulator's
    pace clock, in its time): not healthy, mode and armed null, its last word kept; the
    others as they say."""
    runner = FlightRunner(load_scenario(PAPER), MissionClock())
    await runner.prepare()
    said = TelemetryReducer(1)
    said.update(heartbeat(), 0.0)  # AUTO, armed
    for k, vid in enumerate(runner.members, start=1):
        runner.vehicles[vid] = SimpleNamespace(  # type: ignore[assignment]
            system_id=k, state=said.state, link=SimpleNamespace(counters=LinkCounters())
        )
    runner.members["UAV2"].link_silent = True
    links = {v["id"]: v["link"] for v in runner.snapshot()["vehicles"]}
    assert links["UAV2"]["healthy"] is False
    assert (links["UAV2"]["mode"], links["UAV2"]["armed"]) == (None, None)
    assert (links["UAV2"]["last_mode"], links["UAV2"]["last_armed"]) == ("AUTO", True)
    for vid in ("UAV1", "UAV3"):
        assert links[vid]["healthy"] is True
        assert (links[vid]["mode"], links[vid]["armed"]) == ("AUTO", True)


@pytest.mark.parametrize("paced", [True, False])
async def test_in_lock_step_fixes_heard_while_a_plan_is_computed_are_taken_after_its_result(
    paced: bool,
) -> None:
    """A simulator in lock step waits for a planning job, but the reports of the lead it had
    already flown still come in while the job runs, as many as the machine's load lets
    through. They reach the team after the job's result, in the order heard, so what the
    team does with them (a zone's guard holding a vehicle the re-plan routes round) does not
    depend on the load. Real vehicles do not wait: their fixes are taken as they come."""
    clock = MissionClock()
    if paced:
        clock.follow(lambda: 0.0, rate=200.0)
    runner = FlightRunner(load_scenario(PAPER), clock)
    fed: list[object] = []
    runner._feed = fed.append  # type: ignore[method-assign]
    started, go = threading.Event(), threading.Event()

    def run() -> str:
        started.set()
        go.wait(10.0)
        return "the plan"

    task = asyncio.create_task(runner._compute(act.Compute(SimpleNamespace(run=run))))  # type: ignore[arg-type]
    assert await asyncio.to_thread(started.wait, 10.0)
    fixes = [act.Fix("UAV1", 100.0 + k, 47.0, 8.0) for k in range(3)]
    for fix in fixes:
        runner._take_fix(fix)
    go.set()
    await task
    kinds = [type(i).__name__ for i in fed]
    if paced:
        assert kinds == ["Computed", "PlanningLead", "Fix", "Fix", "Fix"], kinds
        assert fed[2:] == fixes
    else:
        assert kinds == ["Fix", "Fix", "Fix", "Computed", "PlanningLead"], kinds
    assert fed[kinds.index("Computed")].result == "the plan"  # type: ignore[attr-defined]
    runner._take_fix(fixes[0])  # none running: at once
    assert fed[-1] is fixes[0]

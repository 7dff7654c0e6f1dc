"""The team controller on its own: a fake clock (mission seconds passed in), synthetic fixes
made from the planned routes, no sockets, no asyncio. Every decision it makes is checked
against a computation of its own here (the route's length and the speeds, not the
controller's figures)."""

from __future__ import annotations

import dataclasses
import itertools
import math
import pickle
import re
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from pydantic import TypeAdapter
from scipy.integrate import quad

from gcs.coordination import actions as act
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind, FlightEvent
from gcs.coordination.member import Member, VehicleState
from gcs.coordination.routetrack import LoiterSpec, RouteTrack
from gcs.coordination.separation import Position, SeparationWatch
from gcs.coordination.team import TAKEOFF_RECHECK_S, TeamController, TeamTimeRefused
from gcs.errors import GcsError
from gcs.store.repository import EventWriter, Store
from planner.flightpath import FlightPath, smooth_polyline
from planner.mission import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_LOITER_TURNS,
    MAV_CMD_NAV_WAYPOINT,
)
from planner.plan import World, build_world, plan
from planner.popup import popup_zones
from planner.retime import build_schedule
from planner.scenario import Scenario, Threat, parse_scenario
from planner.schedule import Event, Schedule
from planner.schedulefile import PathMission
from planner.threats import build_threats
from tests.gcs.conftest import START_UTC
from tests.paperbounds import time_in_wind_s
from tests.planner.test_loiterflight import _flown_out_m


def of(actions: Sequence[act.Action], kind: type) -> list:  # type: ignore[type-arg]
    return [a for a in actions if isinstance(a, kind)]


def reports(actions: Sequence[act.Action], kind: EventKind) -> list[act.Report]:
    return [a for a in actions if isinstance(a, act.Report) and a.kind is kind]


def seq_ahead(team: TeamController, vid: str, s_m: float) -> int:
    """The mission item the vehicle flies to from ``s_m``: the first waypoint beyond it."""
    pm = team.members[vid].mission
    for k, it in enumerate(pm.items):
        s_k = pm.item_s_m[k]
        is_waypoint = k >= pm.first_route_seq and it.command == MAV_CMD_NAV_WAYPOINT
        if is_waypoint and s_k is not None and s_k > s_m:
            return k
    return len(pm.items) - 1


def fix(team: TeamController, vid: str, s_m: float, t_s: float, airspeed_m_s: float) -> act.Fix:
    """A fix on the planned route at ``s_m``, flying ``airspeed_m_s`` (equivalent) in
    still air."""
    m = team.members[vid]
    pose = m.schedule.path.pose_at(s_m)
    lat, lon = team.frame.to_geodetic(pose.east_m, pose.north_m)
    gs = airspeed_m_s * m.schedule.tas_per_eas(s_m)
    h = pose.heading_rad
    return act.Fix(
        vid,
        START_UTC + t_s,
        float(lat),
        float(lon),
        alt_amsl_m=float(m.schedule.alt_at(s_m)),
        airspeed_m_s=airspeed_m_s,
        groundspeed_m_s=gs,
        heading_deg=math.degrees(h),
        ve_m_s=gs * math.sin(h),
        vn_m_s=gs * math.cos(h),
        climb_m_s=0.0,
        mission_seq=seq_ahead(team, vid, s_m),
        wind_speed_m_s=0.0,
        wind_from_deg=0.0,
    )


def on_loiter_circle(team: TeamController, base: act.Fix, lo: LoiterSpec, i: int) -> act.Fix:
    """Fix ``i`` (2 s apart after ``base``) round the loiter circle ``lo`` at ``base``'s
    ground speed."""
    gs = base.groundspeed_m_s
    assert gs is not None
    a = (1.0 if lo.clockwise else -1.0) * 2.0 * i * gs / lo.radius_m
    e = lo.centre_east_m + lo.radius_m * math.sin(a)
    n = lo.centre_north_m + lo.radius_m * math.cos(a)
    lat, lon = team.frame.to_geodetic(e, n)
    return dataclasses.replace(
        base, utc_s=base.utc_s + 2.0 * i, lat_deg=float(lat), lon_deg=float(lon)
    )


def airborne(team: TeamController, vid: str, t_s: float) -> None:
    """Launch ``vid`` at ``t_s`` (its Launch answered at once)."""
    m = team.members[vid]
    if m.phase == "ground":
        m.takeoff_s = min(m.takeoff_s, t_s)
        for launch in of(team.handle(act.Tick(), t_s), act.Launch):
            team.handle(act.Launched(launch.vehicle_id), t_s)
    assert m.launched_s is not None


def flying(team: TeamController, vid: str, after_s: float) -> tuple[Member, float]:
    """``vid`` launched at its takeoff time, and the mission time ``after_s`` later."""
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    return m, m.takeoff_s + after_s


def still_air_eta_s(team: TeamController, vid: str, s_m: float, t_s: float, eas: float) -> float:
    """When the vehicle arrives from ``s_m`` at ``eas``: the rest of the route and its
    loiters at the route's true airspeed (the test's own arithmetic)."""
    m = team.members[vid]
    tas = eas * m.schedule.tas_per_eas(s_m)
    rest = m.track.length_m - s_m
    loiter_m = sum(lo.length_m for lo in m.track.loiters if lo.s_m >= s_m)
    return t_s + (rest + loiter_m) / tas


# -- launches -----------------------------------------------------------------------------------


def test_vehicles_launch_at_their_takeoff_times_and_a_failed_launch_is_tried_again(
    team: TeamController,
) -> None:
    takeoffs = {vid: m.takeoff_s for vid, m in team.members.items()}
    first = min(takeoffs, key=lambda v: takeoffs[v])
    # Armed ahead of its takeoff time (once), so the launch has only AUTO left to send; the
    # runner is told when to tick for each.
    lead_s = FlightConfig().arm_lead_s
    assert team.next_due_s(takeoffs[first] - lead_s - 5.0) == takeoffs[first] - lead_s
    due = sorted(t for v in takeoffs.values() for t in (v, v - lead_s))
    assert team.next_due_s(due[0]) == due[1]
    assert of(team.handle(act.Tick(), takeoffs[first] - lead_s - 0.1), act.Arm) == []
    assert of(team.handle(act.Tick(), takeoffs[first] - lead_s), act.Arm) == [act.Arm(first)]
    assert of(team.handle(act.Tick(), takeoffs[first] - 0.1), act.Arm) == []
    assert of(team.handle(act.Tick(), takeoffs[first] - 0.1), act.Launch) == []
    out = team.handle(act.Tick(), takeoffs[first])
    assert of(out, act.Launch) == [act.Launch(first)]
    assert team.members[first].state is VehicleState.CLIMBING
    out = team.handle(act.Launched(first, "arm refused: PreArm: GPS"), takeoffs[first] + 1)
    assert "launch failed: arm refused" in reports(out, EventKind.LAUNCH)[0].reason
    assert team.members[first].phase == "ground"
    assert of(team.handle(act.Tick(), takeoffs[first] + 2), act.Launch) == [act.Launch(first)]
    team.handle(act.Launched(first), takeoffs[first] + 3)
    assert team.members[first].launched_s == takeoffs[first] + 3
    # on the route once its mission reaches the first route item
    out = team.handle(fix(team, first, 2000.0, takeoffs[first] + 90, 25.0), takeoffs[first] + 90)
    assert reports(out, EventKind.ROUTE)
    assert team.members[first].state is VehicleState.ON_ROUTE


# -- speed ---------------------------------------------------------------------------------------


def test_speed_is_commanded_only_when_the_required_level_changes(team: TeamController) -> None:
    vid = "UAV1"  # UAV2 sets the team time at its top speed; UAV1 has room
    m = team.members[vid]
    t0 = m.takeoff_s + 600.0
    airborne(team, vid, m.takeoff_s)
    # Held back 3 km from where its schedule has it, it must speed up.
    s0 = m.schedule.state_at(t0)[1] - 3_000.0
    out = team.handle(fix(team, vid, s0, t0, 25.0), t0)
    cmd = of(out, act.CommandSpeed)
    assert len(cmd) == 1
    level = cmd[0].airspeed_m_s
    # The level is the step nearest the speed that arrives on time from here (own arithmetic).
    tas_per_eas = m.schedule.tas_per_eas(s0)
    need = (m.track.length_m - s0) / (m.target_s - t0) / tas_per_eas
    step = m.limits.step_m_s
    assert abs(level - need) <= step / 2 + 1e-6
    team.handle(act.SpeedCommanded(vid, level, cmd[0].reason, t0), t0 + 1)
    # Flying exactly that level: later decisions keep it (no command).
    t, s = t0, s0
    for _ in range(6):
        dt = max(m.next_decision_s - t, 1.0)
        t += dt
        s += dt * level * tas_per_eas
        out = team.handle(fix(team, vid, s, t, level), t)
        assert of(out, act.CommandSpeed) == [], (t, out)
    # Held back well over a step's worth: the next decision commands a higher level.
    dt = max(m.next_decision_s - t, 1.0)
    behind_m = 3.0 * step * tas_per_eas * (m.target_s - t)
    t += dt
    s += dt * level * tas_per_eas - behind_m
    out = team.handle(fix(team, vid, s, t, level), t)
    (up,) = of(out, act.CommandSpeed)
    assert up.airspeed_m_s >= level + step
    need = (m.track.length_m - s) / (m.target_s - t) / tas_per_eas
    assert abs(up.airspeed_m_s - need) <= step / 2 + 1e-6


@pytest.mark.parametrize("slot", ["kept", "moved"])
def test_a_vehicle_timed_through_a_place_flies_there_then_for_its_slot(
    team: TeamController, slot: str
) -> None:
    """A re-plan timed UAV1 apart from another by when it passes a place 8 km ahead
    (``schedule.via``), 20 s before the speed for its slot would: it flies the speed that
    passes there then (the slot's alone flew the 60-vehicle crowd's R01 and R02 together
    again, 224 m apart), still on time for its slot; past the place, the speed for its slot.
    Once the team time has moved, the pass no longer keeps what it kept: the slot alone."""
    vid = "UAV1"
    m = team.members[vid]
    t0 = m.takeoff_s + 600.0
    airborne(team, vid, m.takeoff_s)
    s0 = m.schedule.state_at(t0)[1]
    via_s_m = s0 + 8_000.0
    tas_per_eas = m.schedule.tas_per_eas(s0)

    def left_m(s_m: float) -> float:  # the route and the loiter turns still to fly
        return m.track.length_m - s_m + sum(lo.length_m for lo in m.track.loiters if lo.s_m >= s_m)

    slot_eas = left_m(s0) / (m.target_s - t0) / tas_per_eas
    via_t_s = t0 + 8_000.0 / (slot_eas * tas_per_eas) - 20.0
    assert m.target_s == pytest.approx(m.schedule.arrival_s, abs=0.05)
    m.schedule = dataclasses.replace(m.schedule, via=(via_s_m, via_t_s))
    if slot == "moved":
        m.target_s += 5.0
    step = m.limits.step_m_s
    cmds = of(team.handle(fix(team, vid, s0, t0, slot_eas), t0), act.CommandSpeed)
    decided = team.members[vid].last_decision
    assert decided is not None and decided.verdict == "on_time"  # for its slot
    if slot == "moved":
        need = left_m(s0) / (m.target_s - t0) / tas_per_eas
        assert abs(decided.level_m_s - need) <= step / 2 + 1e-6
        assert not any("to pass" in c.reason for c in cmds)
        return
    # The test's own arithmetic: the speed that covers the 8 km by then, in still air.
    to_via = 8_000.0 / (via_t_s - t0) / tas_per_eas
    (cmd,) = cmds
    assert abs(cmd.airspeed_m_s - to_via) <= step / 2 + 1e-6 and cmd.airspeed_m_s > slot_eas
    assert "to pass" in cmd.reason and f"{via_t_s:.1f} s" in cmd.reason
    team.handle(act.SpeedCommanded(vid, cmd.airspeed_m_s, cmd.reason, t0), t0 + 1)
    # Past the place at its time: the speed for its slot from there.
    s1 = via_s_m + 100.0
    t1 = via_t_s + 100.0 / (to_via * tas_per_eas)
    (back,) = of(team.handle(fix(team, vid, s1, t1, cmd.airspeed_m_s), t1), act.CommandSpeed)
    need = left_m(s1) / (m.target_s - t1) / m.schedule.tas_per_eas(s1)
    # (Within a step: the controller takes the true airspeed's factor along the profile.)
    assert abs(back.airspeed_m_s - need) <= step and "to pass" not in back.reason
    assert back.airspeed_m_s < cmd.airspeed_m_s - step


def test_a_speed_item_the_mission_runs_inside_the_final_stretch_does_not_set_the_arrival(
    team: TeamController,
) -> None:
    """A re-timed mission may end with a short leg at a speed of its own (the planner's last
    0.5 m/s trim): its DO_CHANGE_SPEED runs when the aircraft is already inside the final
    stretch, where no speed is decided. The airspeed the coordinator last commanded is
    commanded again rather than flown to the goal at the plan's stale speed (in the 30-vehicle
    pop-up rehearsal, 18 m/s for the last 160 m instead of 22.5: a second late)."""
    vid = "UAV1"
    m, _ = flying(team, vid, 0.0)
    final_m = team.config.final_m
    pm, length = m.mission, m.track.length_m
    goal = next(k for k, s_k in enumerate(pm.item_s_m) if s_k is not None and s_k >= length)
    assert pm.items[goal].command == MAV_CMD_NAV_WAYPOINT
    # A waypoint inside the final stretch and a DO_CHANGE_SPEED to 16 m/s for the leg after it.
    s_pre = length - 0.8 * final_m
    pose = m.schedule.path.pose_at(s_pre)
    lat, lon = team.frame.to_geodetic(pose.east_m, pose.north_m)
    pre = replace(pm.items[goal], x=round(float(lat) * 1e7), y=round(float(lon) * 1e7))
    speed = replace(
        pm.items[goal], frame=2, command=MAV_CMD_DO_CHANGE_SPEED, param1=0.0, param2=16.0,
        param3=-1.0, param4=0.0, x=0, y=0, z=0.0,
    )  # fmt: skip
    items = [*pm.items[:goal], pre, speed, *pm.items[goal:]]
    m.mission = PathMission(
        tuple(replace(it, seq=k) for k, it in enumerate(items)),
        (*pm.item_s_m[:goal], s_pre, s_pre, *pm.item_s_m[goal:]),
    )
    # Commanded 24 m/s short of the stretch, then past the new waypoint inside it.
    tas = 24.0 * m.schedule.tas_per_eas(length)
    t1 = m.target_s - 2.0 * final_m / tas
    team.handle(fix(team, vid, length - 2.0 * final_m, t1, 24.0), t1)
    team.handle(act.SpeedCommanded(vid, 24.0, "on time", t1), t1)
    assert m.last_seq == goal  # flying to the new waypoint
    t2 = t1 + (1.2 * final_m) / tas
    out = team.handle(fix(team, vid, s_pre + 10.0, t2, 16.0), t2)
    assert m.last_seq == goal + 2  # past the waypoint and the speed item: to the goal
    assert [c.airspeed_m_s for c in of(out, act.CommandSpeed)] == [24.0]
    # Once back at it, nothing more (the stretch is the autopilot's).
    team.handle(act.SpeedCommanded(vid, 24.0, "kept", t2), t2)
    out = team.handle(fix(team, vid, s_pre + 40.0, t2 + 1.3, 24.0), t2 + 1.3)
    assert of(out, act.CommandSpeed) == []


def test_a_failed_speed_command_is_reported_and_decided_again(team: TeamController) -> None:
    vid = "UAV1"
    m, t0 = flying(team, vid, 600.0)
    s0 = m.schedule.state_at(t0)[1] - 3_000.0
    (cmd,) = of(team.handle(fix(team, vid, s0, t0, 25.0), t0), act.CommandSpeed)
    out = team.handle(act.SpeedCommanded(vid, cmd.airspeed_m_s, cmd.reason, t0, "no ACK"), t0)
    assert "speed command failed (no ACK)" in reports(out, EventKind.SPEED)[0].reason
    assert m.level_m_s != cmd.airspeed_m_s
    out = team.handle(fix(team, vid, s0 + 30.0, t0 + 1.0, 25.0), t0 + 1.0)
    assert len(of(out, act.CommandSpeed)) == 1  # at once, not at the next period


def test_a_speed_the_vehicle_keeps_refusing_is_an_alarm_once_and_a_success_resets_it(
    team: TeamController,
) -> None:
    vid = "UAV1"
    m, t = flying(team, vid, 600.0)
    s = m.schedule.state_at(t)[1] - 3_000.0
    alarms: list[act.Report] = []
    for k in range(5):
        (cmd,) = of(team.handle(fix(team, vid, s, t, 25.0), t), act.CommandSpeed)
        refused = "vehicle 1: MAV_CMD_DO_CHANGE_SPEED rejected with MAV_RESULT_FAILED"
        out = team.handle(act.SpeedCommanded(vid, cmd.airspeed_m_s, cmd.reason, t, refused), t)
        alarms += reports(out, EventKind.ALARM)
        assert len(alarms) == (1 if k >= 2 else 0), k
        t, s = t + 1.0, s + 25.0
    (alarm,) = alarms
    assert alarm.vehicle == vid and f"refused {cmd.airspeed_m_s:g} m/s 3 times" in alarm.reason
    assert "AIRSPEED_MAX" in alarm.reason
    (cmd,) = of(team.handle(fix(team, vid, s, t, 25.0), t), act.CommandSpeed)
    team.handle(act.SpeedCommanded(vid, cmd.airspeed_m_s, cmd.reason, t), t)
    assert m.speed_refusals == 0 and m.level_m_s == cmd.airspeed_m_s


# -- loiter turns -------------------------------------------------------------------------------


def _early(team: TeamController, vid: str) -> tuple[float, float, act.LoiterJob]:
    """``vid`` 300 s after its takeoff, 5 km along, with its slot moved 900 s later: even at
    its minimum speed it would be early, so it asks for loiter turns (the job returned)."""
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    t0, s0 = m.takeoff_s + 300.0, 5_000.0
    m.target_s += 900.0
    assert still_air_eta_s(team, vid, s0, t0, m.limits.airspeed_min_m_s) < m.target_s - 60.0
    out = team.handle(fix(team, vid, s0, t0, 20.0), t0)
    (job,) = [a.job for a in of(out, act.Compute)]
    assert isinstance(job, act.LoiterJob)
    return t0, s0, job


def test_an_early_vehicle_gets_the_fewest_loiter_turns_that_absorb_its_surplus(
    team: TeamController,
) -> None:
    vid = "UAV3"
    m = team.members[vid]
    t0, s0, job = _early(team, vid)
    v_min = m.limits.airspeed_min_m_s
    assert isinstance(job, act.LoiterJob) and job.vehicle_id == vid
    assert m.busy_mission
    # No second job while this one is out.
    assert of(team.handle(fix(team, vid, s0 + 200.0, t0 + 10, 20.0), t0 + 10), act.Compute) == []
    vs, adjustments = job.run()
    out = team.handle(act.Computed(job, (vs, adjustments)), t0 + 12)
    (up,) = of(out, act.Upload)
    assert up.keep_seq == job.keep_seq and up.in_flight
    new = [lo for lo in vs.loiters if lo.s_m >= job.s_m]
    assert new
    turns = sum(lo.turns for lo in new)
    loiter_items = [it for it in up.mission.items if it.command == MAV_CMD_NAV_LOITER_TURNS]
    assert sum(it.param1 for it in loiter_items) >= turns
    # Fewest turns (own arithmetic): the route from the splice point flown at the fastest
    # speed the loiter margin allows must fit with these turns, not with one fewer.
    lo = new[0]
    circle_m = 2.0 * math.pi * lo.radius_m
    tas_per_eas = m.schedule.tas_per_eas(job.s_m)
    v_hi = m.limits.airspeed_max_m_s * tas_per_eas
    v_lo = (v_min + job.loiter_margin_m_s) * tas_per_eas
    time_left = job.target_s - job.now_s
    rest_m = vs.path.length_m - job.s_m + lo.detour_m

    def fits(n: int) -> bool:
        d = rest_m + n * circle_m
        return d / v_hi <= time_left + 1.0 and d / v_lo >= time_left - 1.0

    assert fits(turns)
    assert not fits(turns - 1)
    # Once on board: the vehicle flies it, the adjustments are said, the next job may come.
    out = team.handle(act.Installed(up), t0 + 15)
    assert m.mission is up.mission and m.schedule is vs
    assert reports(out, EventKind.LOITER)
    assert not m.busy_mission


@pytest.mark.parametrize("told", [True, False], ids=["told", "not told"])
def test_an_upload_told_before_a_restart_is_adopted_without_telling_it_again(
    team: TeamController, store_url: str, told: bool
) -> None:
    """A worker told an upload (its event kept, its items in the uploads table) and died
    before the next checkpoint: the one taking the flight on reads the kept events back
    (``events_to_resume``), finds the pending upload told, and adopts it telling nothing
    twice. One not told yet is told."""
    vid = "UAV3"
    m = team.members[vid]
    t0, _, job = _early(team, vid)
    (up,) = of(team.handle(act.Computed(job, job.run()), t0 + 1), act.Upload)
    assert team.pending[vid] is up
    items = [dataclasses.asdict(it) for it in m.mission.items]
    initial = FlightEvent(
        START_UTC, 0.0, vid, EventKind.UPLOAD, "initial mission", seq=1,
        payload={"what": "initial mission", "items": items},
    )  # fmt: skip
    failed = FlightEvent(START_UTC + 1, 1.0, "UAV1", EventKind.UPLOAD, "upload failed", seq=3)
    said = FlightEvent(
        START_UTC + t0 + 1, t0 + 1, vid, EventKind.UPLOAD, up.what, seq=2, payload=up.payload()
    )
    store = Store.open(store_url)
    try:
        fid = store.create_flight(store.save_scenario("name: t\nvehicles: []\n", name="t"), {})
        writer = EventWriter(store, fid)
        writer.write([initial, said, failed] if told else [initial, failed])
        kept = store.events(fid)
        assert all("items" not in e.payload for e in kept)  # kept apart, in the uploads table
        events = store.events_to_resume(fid)
    finally:
        store.close()
    assert up.told_in(events) is told
    assert not up.told_in(kept)  # without its items, no upload is known for the one told
    out = team.handle(act.Installed(up, said=up.told_in(events)), t0 + 2)
    assert m.mission is up.mission and vid not in team.pending and not m.busy_mission
    ups = [r for r in of(out, act.Report) if r.kind is EventKind.UPLOAD]
    assert len(ups) == (0 if told else 1), ups


def test_a_loiter_upload_that_fails_keeps_the_old_mission_and_says_so(team: TeamController) -> None:
    vid = "UAV3"
    m = team.members[vid]
    t0, _, job = _early(team, vid)
    (up,) = of(team.handle(act.Computed(job, job.run()), t0 + 1), act.Upload)
    old = m.mission
    out = team.handle(act.Installed(up, "no MISSION_ACK"), t0 + 2)
    assert m.mission is old
    assert "upload failed (no MISSION_ACK); flying on" in reports(out, EventKind.LOITER)[0].reason
    out = team.handle(act.Installed(up, skipped=True), t0 + 3)
    assert "passed the splice waypoint; not installed" in reports(out, EventKind.UPLOAD)[0].reason


def test_loiter_turns_worked_out_on_a_route_since_replaced_are_dropped(
    team: TeamController,
) -> None:
    """A pop-up's re-plan is adopted while the loiter turns are computed on the route before
    it: spliced in, the turns would bring that route back (into the zone it avoids). They
    are dropped, said, and the vehicle is decided again on the route it flies."""
    vid = "UAV3"
    m = team.members[vid]
    t0, _, job = _early(team, vid)
    # The re-plan: a new path from the same point on (as a pop-up's would be), on board.
    rerouted = replace(m.schedule, path=FlightPath(m.schedule.path.segments))
    m.schedule = rerouted
    out = team.handle(act.Computed(job, job.run()), t0 + 5)
    assert of(out, act.Upload) == []
    (said,) = reports(out, EventKind.LOITER)
    assert "since replaced: dropped" in said.reason
    assert m.schedule is rerouted and not m.busy_mission
    assert m.next_decision_s == -math.inf


# -- lateness ------------------------------------------------------------------------------------


def test_a_late_vehicle_moves_the_team_time_with_the_reason_and_re_times_the_ground(
    team: TeamController,
) -> None:
    vid = "UAV2"
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    ground = [x for x in team.members.values() if x.phase == "ground"]
    assert ground
    old_ref = team.team_ref_s
    assert old_ref is not None
    t0 = m.takeoff_s + 600.0
    s0 = 2_000.0  # far behind: even at top speed it comes after its slot
    v_max = m.limits.airspeed_max_m_s
    earliest = still_air_eta_s(team, vid, s0, t0, v_max)
    assert earliest > m.target_s + 5.0
    out = team.handle(fix(team, vid, s0, t0, 25.0), t0)
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert moved.vehicle == vid
    assert f"{vid} cannot arrive before" in moved.reason and f"{v_max:g} m/s" in moved.reason
    new_ref = moved.value
    assert new_ref is not None and new_ref == team.team_ref_s
    assert new_ref == pytest.approx(earliest - m.offset_s + FlightConfig().late_margin_s, abs=1.0)
    for x in team.members.values():
        assert x.target_s == pytest.approx(new_ref + x.offset_s)
    retimed = {r.vehicle for r in reports(out, EventKind.TAKEOFF)}
    assert retimed == {x.vehicle_id for x in ground}
    assert team.version == 2
    cmds = of(out, act.CommandSpeed)
    assert (cmds[0].airspeed_m_s if cmds else m.level_m_s) == v_max


def _takeoff_in_wind_s(team: TeamController, vid: str, wind_to: tuple[float, float]) -> float:
    """When ``vid`` takes off to arrive on its slot at its cruise speed in this wind (m/s to
    east and north): its climb-out as scheduled, then the rest of its path by the wind
    triangle every 20 m (:func:`tests.paperbounds.time_in_wind_s`, the test's own
    arithmetic)."""
    vs = team.members[vid].schedule
    cruise = team.scenario.vehicle(vid).cruise_m_s
    flying_s = time_in_wind_s(vs.path, vs.climb_s_m, lambda s: cruise * vs.tas_per_eas(s), wind_to)
    return team.members[vid].target_s - (vs.climb_end_s - vs.takeoff_s) - flying_s


def test_a_vehicle_on_the_ground_is_re_timed_in_the_wind_measured_aloft(
    team: TeamController,
) -> None:
    """The team time moved while one vehicle flies in 10 m/s and says so: those still on the
    ground take off for their slots in that wind, not in the schedule's calm forecast (here a
    tailwind for one of them: timed in the calm it would arrive many minutes early)."""
    vid = "UAV2"
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    ground = [x.vehicle_id for x in team.members.values() if x.phase == "ground"]
    assert ground
    g = team.members[ground[0]]
    start, end = g.schedule.path.pose_at(0.0), g.schedule.path.pose_at(g.schedule.path.length_m)
    # Along the ground vehicle's way: from its start towards its goal.
    to_deg = math.degrees(math.atan2(end.east_m - start.east_m, end.north_m - start.north_m))
    wind_to = (10.0 * math.sin(math.radians(to_deg)), 10.0 * math.cos(math.radians(to_deg)))
    t0 = m.takeoff_s + 120.0
    heard = dataclasses.replace(
        fix(team, vid, 1_000.0, t0, 25.0), wind_speed_m_s=10.0, wind_from_deg=(to_deg + 180) % 360
    )
    team.handle(heard, t0)
    ref = team.team_ref_s
    assert ref is not None
    out = team.move_team_time(ref + 600.0, t0)
    (retimed,) = [r for r in reports(out, EventKind.TAKEOFF) if r.vehicle == g.vehicle_id]
    # Within 10 s, 0.2 % of its flight: eq. 5 takes one mean ratio of ground speed to airspeed
    # over the rest of the path, the test each 20 m at its own.
    want_s = _takeoff_in_wind_s(team, g.vehicle_id, wind_to)
    assert retimed.value == pytest.approx(want_s, abs=10.0)
    calm_s = _takeoff_in_wind_s(team, g.vehicle_id, (0.0, 0.0))
    assert retimed.value > calm_s + 60.0, (retimed.value, calm_s)


def test_a_vehicle_late_after_another_arrived_is_an_alarm_and_the_team_time_stays(
    team: TeamController,
) -> None:
    vid = "UAV2"
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    other = team.members["UAV1"]
    other.phase, other.arrival_s = "arrived", other.target_s  # it met its slot
    old_ref, old_target = team.team_ref_s, other.target_s
    t0 = m.takeoff_s + 600.0
    earliest = still_air_eta_s(team, vid, 2_000.0, t0, m.limits.airspeed_max_m_s)
    assert earliest > m.target_s + 5.0
    out = team.handle(fix(team, vid, 2_000.0, t0, 25.0), t0)
    assert not reports(out, EventKind.ARRIVAL)
    (alarm,) = reports(out, EventKind.ALARM)
    assert alarm.vehicle == vid and "after UAV1 arrived" in alarm.reason
    assert alarm.value == pytest.approx(earliest - m.target_s, abs=1.0)
    assert team.team_ref_s == old_ref and other.target_s == old_target
    # Said once, not on every fix.
    out = team.handle(fix(team, vid, 2_050.0, t0 + 2.0, 25.0), t0 + 2.0)
    assert not reports(out, EventKind.ALARM)


def test_the_latest_a_vehicle_can_arrive_counts_loiter_turns_only_where_they_fit(
    team: TeamController,
) -> None:
    """How late UAV3 could still arrive, for a move of the team time: without bound while
    its buffer is ahead (turns spliced in after a waypoint the shortest lead ahead); on its
    last stretch, with a waypoint that far ahead but under 2 km of path after it (no room
    for turns: a loiter starts 1 km clear of either end), its arrival at its minimum speed."""
    vid = "UAV3"
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    t0 = m.takeoff_s + 300.0
    team.handle(fix(team, vid, 5_000.0, t0, 20.0), t0)
    assert m.last_decision is not None
    assert team.latest_arrival_s(m) == math.inf
    length_m = m.track.length_m
    s1, t1 = length_m - 2_700.0, t0 + 10.0
    team.handle(fix(team, vid, s1, t1, 20.0), t1)
    keep = team._keep_seq(m, max(m.groundspeed_m_s, 10.0) * FlightConfig().min_lead_s)
    assert keep is not None
    s_keep = m.mission.item_s_m[keep]
    assert s_keep is not None and length_m - s_keep < 2_000.0
    assert m.last_decision is not None
    assert team.latest_arrival_s(m) == m.last_decision.eta_max_s < math.inf


def test_a_team_time_moved_in_the_last_seconds_keeps_a_small_margin(
    team: TeamController,
) -> None:
    vid = "UAV2"
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    v_max = m.limits.airspeed_max_m_s
    s0 = m.track.length_m - 600.0  # about 20 s from the goal at top speed
    t0 = m.target_s - 600.0 / (v_max * m.tas_per_eas(s0)) + 3.0  # 3 s late at top speed
    earliest = still_air_eta_s(team, vid, s0, t0, v_max)
    out = team.handle(fix(team, vid, s0, t0, v_max), t0)
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert moved.value is not None
    margin = moved.value + m.offset_s - earliest
    # 2 % of the ~20 s left, not the 2 s a move far from the goal keeps.
    assert 0.0 <= margin <= 0.02 * (earliest - t0) + 0.5
    assert margin < FlightConfig().late_margin_s / 2


def test_a_vehicle_off_its_route_does_not_move_the_team_time_while_it_joins(
    team: TeamController,
) -> None:
    vid = "UAV2"
    m, t0 = flying(team, vid, 600.0)
    f = fix(team, vid, 2_000.0, t0, 25.0)
    pose = m.schedule.path.pose_at(2_000.0)
    h = pose.heading_rad  # 2 km to the right of the route
    lat, lon = team.frame.to_geodetic(
        pose.east_m + 2000.0 * math.cos(h), pose.north_m - 2000.0 * math.sin(h)
    )
    out = team.handle(act.Fix(**{**f.__dict__, "lat_deg": float(lat), "lon_deg": float(lon)}), t0)
    assert m.cross_track_m == pytest.approx(2000.0, abs=50.0)
    assert team.team_ref_s == team.schedule.required_arrival_s
    assert "joining it: the team time stays" in reports(out, EventKind.ARRIVAL)[0].reason
    assert m.state is VehicleState.JOINING


def test_the_operator_moves_the_team_time_or_is_told_the_earliest_and_who_forces_it(
    team: TeamController,
) -> None:
    vid = "UAV2"
    m, t0 = flying(team, vid, 600.0)
    team.handle(fix(team, vid, 20_000.0, t0, 25.0), t0)
    ref = team.team_ref_s
    assert ref is not None
    earliest = still_air_eta_s(team, vid, 20_000.0, t0, m.limits.airspeed_max_m_s) - m.offset_s
    with pytest.raises(TeamTimeRefused) as refused:
        team.move_team_time(earliest - 30.0, t0)
    assert refused.value.vehicle_id == vid
    assert refused.value.earliest_s == pytest.approx(earliest, abs=1.0)
    assert "earliest feasible" in str(refused.value)
    assert team.team_ref_s == ref  # unchanged
    out = team.move_team_time(ref + 120.0, t0, version=1)
    assert team.team_ref_s == ref + 120.0 and team.version == 2
    assert "by the operator" in reports(out, EventKind.ARRIVAL)[0].reason
    assert all(x.target_s == pytest.approx(ref + 120.0 + x.offset_s) for x in team.members.values())
    with pytest.raises(Exception, match="version 1 is stale"):
        team.move_team_time(ref + 200.0, t0, version=1)


# -- threats ------------------------------------------------------------------------------------


def _on_schedule(team: TeamController, t_s: float) -> None:
    """Every vehicle launched and where its schedule has it at ``t_s``."""
    for vid, m in team.members.items():
        airborne(team, vid, m.takeoff_s)
        phase, s_m, speed = m.schedule.state_at(t_s)
        assert phase == "leg", vid
        team.handle(act.SpeedCommanded(vid, speed, "plan", t_s), t_s)
        team.handle(fix(team, vid, s_m, t_s, speed), t_s)
        m.next_decision_s = math.inf  # only the pop-up is looked at here


def _popup_job(team: TeamController) -> tuple[float, act.PopupJob]:
    """Every vehicle on its schedule as the scenario's pop-up appears: when, and the re-plan
    job it starts."""
    zones = build_threats(team.scenario, {vid: m.takeoff_s for vid, m in team.members.items()})
    (zone,) = popup_zones(zones)
    t_p = float(zone.appears_at_s or 0.0)
    _on_schedule(team, t_p - 1.0)
    (job,) = [a.job for a in of(team.handle(act.Tick(), t_p), act.Compute)]
    assert isinstance(job, act.PopupJob)
    return t_p, job


def test_a_popup_re_plans_the_vehicles_whose_routes_it_touches_and_no_other(
    team: TeamController,
) -> None:
    zones = build_threats(team.scenario, {vid: m.takeoff_s for vid, m in team.members.items()})
    (zone,) = popup_zones(zones)
    t_p = float(zone.appears_at_s or 0.0)
    _on_schedule(team, t_p - 1.0)
    assert of(team.handle(act.Tick(), t_p - 0.5), act.Compute) == []
    out = team.handle(act.Tick(), t_p)
    (job,) = [a.job for a in of(out, act.Compute)]
    assert isinstance(job, act.PopupJob) and job.zone.id == zone.id
    assert set(job.keeps) == set(team.members)
    # Which routes does the threat touch ahead of the splice points? (own geometry)
    cx, cy = zone.east_m, zone.north_m
    touched = set()
    for vid, m in team.members.items():
        s_k = job.anchors[vid].s_m
        for s in np.arange(s_k, m.schedule.path.length_m, 200.0):
            p = m.schedule.path.pose_at(float(s))
            if math.hypot(p.east_m - cx, p.north_m - cy) < zone.radius_m:
                touched.add(vid)
                break
    assert touched == {"UAV1", "UAV2"}
    outcome = job.run()
    out = team.handle(act.Computed(job, outcome), t_p + 1.0)
    assert set(outcome.affected) == touched
    uploads = {u.vehicle_id: u for u in of(out, act.Upload)}
    for vid, m in team.members.items():
        before = m.schedule.path
        if vid in touched:
            assert uploads[vid].schedule.path is not before
            assert uploads[vid].schedule.path.length_m > before.length_m - 1.0
        elif vid in uploads:  # re-timed for the new team time, on the same route
            assert uploads[vid].schedule.path.length_m == pytest.approx(before.length_m)
    assert all(u.keep_seq == job.keeps[u.vehicle_id] for u in uploads.values())
    assert team.team_ref_s == outcome.schedule.required_arrival_s


def test_a_re_plan_whose_vehicle_changed_mission_meanwhile_is_not_spliced_into_it(
    team: TeamController,
) -> None:
    """While the re-plan round a pop-up is worked out, one of its vehicles is given a new
    mission (loiter turns put in): the items the new route was to be spliced at are the old
    mission's, not this one's (a splice there raised in flight, or would start the route from
    the wrong waypoint). Its route is not sent, said so; the others' are."""
    t_p, job = _popup_job(team)
    outcome = job.run()
    assert "UAV1" in outcome.affected
    m = team.members["UAV1"]
    m.mission = dataclasses.replace(m.mission)  # another mission installed meanwhile
    out = team.handle(act.Computed(job, outcome), t_p + 1.0)
    uploads = {u.vehicle_id for u in of(out, act.Upload)}
    assert "UAV1" not in uploads and uploads, uploads
    (said,) = [r for r in reports(out, EventKind.POPUP) if r.vehicle == "UAV1"]
    assert "its mission changed while its new route was worked out" in said.reason


def test_a_re_plan_decided_while_a_change_was_on_its_way_is_not_spliced_once_it_lands(
    team: TeamController,
) -> None:
    """A change (loiter turns) is on its way to UAV1 when the pop-up appears: the re-plan's
    splice item is one of the mission on board then. The change lands while the route is
    worked out: that item is not the one it was, and the route is not spliced into the new
    mission (said so); nor while a change is still on its way when the route is done."""
    zones = build_threats(team.scenario, {vid: m.takeoff_s for vid, m in team.members.items()})
    (zone,) = popup_zones(zones)
    t_p = float(zone.appears_at_s or 0.0)
    _on_schedule(team, t_p - 1.0)
    m = team.members["UAV1"]
    on_its_way = act.Upload(
        "UAV1", dataclasses.replace(m.mission), m.schedule, None, "loiter inserted", True, (), t_p
    )
    team.pending["UAV1"] = on_its_way
    (job,) = [a.job for a in of(team.handle(act.Tick(), t_p), act.Compute)]
    assert isinstance(job, act.PopupJob) and job.missions["UAV1"] is m.mission
    outcome = job.run()
    assert "UAV1" in outcome.affected
    for lands in (True, False):
        if lands:
            del team.pending["UAV1"]
            m.mission = on_its_way.mission
        out = team.handle(act.Computed(job, outcome), t_p + 1.0)
        assert "UAV1" not in {u.vehicle_id for u in of(out, act.Upload)}
        (said,) = [r for r in reports(out, EventKind.POPUP) if r.vehicle == "UAV1"]
        assert "its mission changed while its new route was worked out" in said.reason
        m.mission, team.pending["UAV1"] = job.missions["UAV1"], on_its_way


def test_a_vehicle_at_the_zone_with_no_waypoint_short_of_its_hold_is_re_planned_from_there(
    team: TeamController,
) -> None:
    """The pop-up appears 200 m ahead of UAV1 on its route: the point it holds at, far enough
    outside for the hold's circle, is behind it, and the guard holds it there now. Its route
    round the zone is planned from that point, as one holding there, at once (a route from
    the first waypoint past the zone would keep out of it, leaving it held with none)."""
    zones = build_threats(team.scenario, {vid: m.takeoff_s for vid, m in team.members.items()})
    (zone,) = popup_zones(zones)
    t_p = float(zone.appears_at_s or 0.0)
    _on_schedule(team, t_p - 1.0)
    vid = "UAV1"
    m = team.members[vid]
    path = m.schedule.path
    cx, cy, r = zone.east_m, zone.north_m, zone.radius_m
    entry = next(
        float(s)
        for s in np.arange(0.0, path.length_m, 10.0)
        if math.hypot(path.pose_at(float(s)).east_m - cx, path.pose_at(float(s)).north_m - cy) < r
    )
    s_now = entry - 200.0
    team.handle(fix(team, vid, s_now, t_p - 0.5, 25.0), t_p - 0.5)
    out = team.handle(act.Tick(), t_p)
    (job,) = [a.job for a in of(out, act.Compute)]
    assert isinstance(job, act.PopupJob)
    assert vid in job.holding
    anchor = job.anchors[vid]
    p = path.pose_at(anchor.s_m)
    clearance = max(FlightConfig().hold_radius_m, team.scenario.vehicle(vid).min_turn_radius_m)
    assert anchor.s_m < s_now and math.hypot(p.east_m - cx, p.north_m - cy) - r >= clearance
    keep = job.keeps[vid]
    assert keep is None or m.mission.item_s_m[keep] <= anchor.s_m + 1e-6
    held = [a for a in out if isinstance(a, act.Hold) and a.vehicle_id == vid]
    assert held, "the guard holds it as the zone appears"


def test_a_re_plan_pair_left_under_the_separation_is_alarmed_before_any_upload(
    team: TeamController,
) -> None:
    """The re-plan says a pair it could not separate (:mod:`planner.replanseparation`): the
    coordinator reports its conflict and its alarm, with the pair, the distance and the time,
    before it sends the first of the new missions."""
    t_p, job = _popup_job(team)
    outcome = job.run()
    pair = {"pair": ["UAV1", "UAV2"], "distance_m": 212.0, "at_s": t_p + 900.0}
    said = "UAV1 and UAV2 would come within 212 m of each other"
    left = dataclasses.replace(
        outcome,
        events=(
            *outcome.events,
            Event(t_p, "conflict", said, {**pair, "resolution": None}),
            Event(t_p, "alarm", said, pair),
        ),
    )
    out = team.handle(act.Computed(job, left), t_p + 1.0)
    kinds = [(a.kind, a.vehicle) if isinstance(a, act.Report) else type(a) for a in out]
    first_upload = kinds.index(act.Upload)
    alarm = kinds.index((EventKind.ALARM, "UAV1"))
    conflict = kinds.index((EventKind.CONFLICT, "UAV1"))
    assert max(alarm, conflict) < first_upload, kinds
    report = out[alarm]
    assert isinstance(report, act.Report)
    assert report.payload == pair and report.reason == said


def test_a_popup_times_the_splice_waypoint_with_the_loiter_turns_flown_before_it(
    team: TeamController,
) -> None:
    """A vehicle with loiter turns on board short of its splice waypoint reaches the waypoint
    after flying them: the re-plan starts it there at that time, not at the path's time."""
    vid = "UAV3"
    m = team.members[vid]
    t0, s0, job = _early(team, vid)
    (up,) = of(team.handle(act.Computed(job, job.run()), t0 + 1), act.Upload)
    team.handle(act.Installed(up), t0 + 2)
    (lo,) = [x for x in m.track.loiters if x.s_m > s0]
    zones = build_threats(team.scenario, {v: x.takeoff_s for v, x in team.members.items()})
    (zone,) = popup_zones(zones)
    t_p = float(zone.appears_at_s or 0.0)
    for v, x in team.members.items():
        airborne(team, v, x.takeoff_s)
    # UAV3 2 km short of its loiter when the threat appears; the lead reaches past it.
    s1, gs = lo.s_m - 2_000.0, 17.0
    team.handle(fix(team, vid, s1, t_p - 1.0, gs / m.schedule.tas_per_eas(s1)), t_p - 1.0)
    m.next_decision_s = math.inf
    team.lead_s = (2_000.0 + 3_000.0) / gs
    out = team.handle(act.Tick(), t_p)
    (pj,) = [a.job for a in of(out, act.Compute)]
    assert isinstance(pj, act.PopupJob)
    anchor = pj.anchors[vid]
    assert anchor.s_m > lo.s_m + 1.0  # the loiter is in the kept part of the mission
    assert m.groundspeed_m_s == pytest.approx(gs, rel=1e-3)
    flown_first = (anchor.s_m - m.s_m + lo.length_m) / m.groundspeed_m_s
    assert anchor.t_s == pytest.approx(t_p - 1.0 + flown_first, abs=1.0)
    assert lo.length_m / gs > 60.0  # what the path alone would have missed


def test_a_threat_added_before_the_start_is_queued_for_its_time(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    scenario, world, schedule = paper
    team = TeamController(scenario, schedule, world)
    box = [[185_600, 203_200], [189_600, 203_200], [189_600, 207_200], [185_600, 207_200]]
    op1 = TypeAdapter(Threat).validate_python(
        {"kind": "no_fly", "id": "OP1", "polygon": [{"east_m": e, "north_m": n} for e, n in box]}
    )
    team.add_threat(op1, 0.0, at_s=2500.0)
    team.add_threat(op1.model_copy(update={"id": "OP2"}), 0.0)  # no time: at the start
    assert [(t.id, t.appears.at_s if t.appears else None) for t in team.operator_threats] == [
        ("OP1", 2500.0),
        ("OP2", 0.0),
    ]
    with pytest.raises(ValueError, match="OP1: a threat with this id is already"):
        team.add_threat(op1, 0.0)
    team.start(START_UTC)
    for m in team.members.values():
        m.takeoff_s = math.inf  # nobody launches here
    jobs = [a.job for a in of(team.handle(act.Tick(), 0.0), act.Compute)]
    assert [j.zone.id for j in jobs] == ["OP2"]
    team.handle(act.Computed(jobs[0], None, RuntimeError("not flown here")), 0.5)
    assert of(team.handle(act.Tick(), 2499.0), act.Compute) == []
    jobs = [a.job for a in of(team.handle(act.Tick(), 2500.0), act.Compute)]
    assert [j.zone.id for j in jobs] == ["OP1"]
    assert all(t.id not in {"OP1", "OP2"} for t in team.scenario.threats)
    # A removed threat never appears; removing an unknown one is named.
    team.add_threat(op1.model_copy(update={"id": "OP3"}), 2500.0, at_s=3000.0)
    team.remove_threat("OP3", 2600.0)
    assert of(team.handle(act.Tick(), 3000.0), act.Compute) == []
    with pytest.raises(KeyError, match="no threat 'OP9'"):
        team.remove_threat("OP9", 3000.0)


# -- abort ---------------------------------------------------------------------------------------


def test_abort_sends_the_aircraft_home_and_the_rest_keep_their_time(team: TeamController) -> None:
    airborne(team, "UAV2", team.members["UAV2"].takeoff_s)
    t = team.members["UAV2"].takeoff_s + 100.0
    ref = team.team_ref_s
    results, out = team.abort("UAV2", "rtl", t)
    assert results == {"UAV2": None}
    assert of(out, act.SetMode) == [act.SetMode("UAV2", "RTL")]
    assert team.members["UAV2"].state is VehicleState.ABORTED
    results, out = team.abort(None, "loiter", t + 1)
    assert results["UAV2"] == "already aborted"
    assert of(out, act.SetMode) == []  # the others are on the ground: they stay there
    assert {r.vehicle for r in reports(out, EventKind.ABORT)} == {"UAV1", "UAV3"}
    assert team.team_ref_s == ref
    assert team.finished
    assert of(team.handle(act.Tick(), t + 1000.0), act.Launch) == []
    with pytest.raises(KeyError, match="no vehicle 'UAV9'"):
        team.abort("UAV9", "rtl", t)


def test_the_loop_stops_when_the_mission_overruns(team: TeamController) -> None:
    last = max(m.target_s for m in team.members.values())
    for m in team.members.values():
        m.takeoff_s = math.inf
    out = team.handle(act.Tick(), last + FlightConfig().overrun_s + 1.0)
    assert of(out, act.Stop) and team.finished
    assert "overran" in reports(out, EventKind.ABORT)[0].reason


# -- restart ------------------------------------------------------------------------------------


def test_a_pickled_controller_decides_as_the_one_it_was_taken_from(
    team: TeamController, paper: tuple[Scenario, World, Schedule]
) -> None:
    vid = "UAV2"
    m, t0 = flying(team, vid, 600.0)
    team.handle(fix(team, vid, 20_000.0, t0, 25.0), t0)
    copy = pickle.loads(pickle.dumps(team))
    assert copy.world is None  # rebuilt from the scenario on a restart
    copy.rebind_world(paper[1])
    t1 = t0 + 400.0
    a = team.handle(fix(team, vid, 29_000.0, t1, 25.0), t1)
    b = copy.handle(fix(copy, vid, 29_000.0, t1, 25.0), t1)
    assert [type(x) for x in a] == [type(x) for x in b]
    assert of(a, act.CommandSpeed) == of(b, act.CommandSpeed)
    snap = copy.snapshot(t1)
    assert {v["id"] for v in snap["vehicles"]} == set(team.members)
    uav2 = next(v for v in snap["vehicles"] if v["id"] == vid)
    assert uav2["state"] == "on_route" and uav2["slot_s"] == pytest.approx(m.target_s)


def test_a_vehicle_that_left_its_loiter_unwatched_is_no_stall_after_a_restart(
    team: TeamController, paper: tuple[Scenario, World, Schedule]
) -> None:
    """Taken on from a checkpoint kept as it circled in a loiter: at the first fix after the
    restart it has left the loiter and is behind the farthest point it reached circling. Its
    progress is watched from that fix on, not from the checkpoint's last one."""
    vid = "UAV2"
    m, t0 = flying(team, vid, 600.0)
    team.config = dataclasses.replace(team.config, stall_bound_s=10.0)
    loiter_seq = 2
    items = list(m.mission.items)
    items[loiter_seq] = dataclasses.replace(items[loiter_seq], command=MAV_CMD_NAV_LOITER_TURNS)
    m.mission = dataclasses.replace(m.mission, items=tuple(items))
    circling = fix_at(team, vid, 20_250.0, t0)
    team.handle(act.Fix(**{**circling.__dict__, "mission_seq": loiter_seq}), t0)
    assert m.state is VehicleState.LOITERING
    copy = pickle.loads(pickle.dumps(team))
    copy.rebind_world(paper[1])
    copy.restarted()
    # 40 s later (4 x the bound), out of the loiter, 250 m behind where it circled.
    t1 = t0 + 40.0
    out = copy.handle(act.Fix(**{**fix_at(copy, vid, 20_000.0, t1).__dict__, "mission_seq": 3}), t1)
    assert not reports(out, EventKind.VEHICLE_LOST)
    # The watch goes on from there: making no progress past the bound from that fix is a stall.
    lost: list[act.Report] = []
    t = t1
    while not lost:
        t += 0.5
        f = fix_at(copy, vid, 20_000.0 - 12.5 * (t - t1), t)
        lost = reports(
            copy.handle(act.Fix(**{**f.__dict__, "mission_seq": 3}), t), EventKind.VEHICLE_LOST
        )
    assert t - t1 == pytest.approx(copy.config.stall_bound_s + 0.5, abs=0.01)
    assert f"no progress along its route for {t - t1:.1f} s" in lost[0].reason


def test_a_checkpoint_kept_before_forecasts_had_heights_is_flown_on_after_a_restart(
    team: TeamController, paper: tuple[Scenario, World, Schedule]
) -> None:
    """A checkpoint from before the forecasts carried each vehicle's height ahead holds them
    as east and north alone: taken on by a new process, the controller forecasts afresh (the
    old ones are stale anyway) and resolves the vehicles' conflicts as before, not failing on
    the first forecast."""
    _, t0 = flying(team, "UAV1", 600.0)
    airborne(team, "UAV2", t0)
    for vid in ("UAV1", "UAV2"):
        team.handle(fix(team, vid, 20_000.0, t0, 25.0), t0)
    team.forecasts._positions = team.forecasts._positions[..., :2].copy()  # the old layout
    copy = pickle.loads(pickle.dumps(team))
    copy.rebind_world(paper[1])
    copy.restarted()
    for k in range(1, 6):
        t = t0 + 2.0 * k
        for vid in ("UAV1", "UAV2"):
            copy.handle(fix(copy, vid, 20_000.0 + 50.0 * k, t, 25.0), t)
    assert copy.forecasts._positions.shape[-1] == 3 and set(copy.forecasts.ahead) >= {"UAV1"}


def test_a_re_plan_starts_from_a_pass_only_while_the_slot_it_was_timed_for_stands(
    team: TeamController,
) -> None:
    """The schedule a later re-plan starts from keeps a vehicle's pass (``via``) while its
    slot is the one the pass was timed for; once the team time has moved it is timed for its
    slot alone (else a vehicle the later re-plan leaves alone would fly the old pass again)."""
    m = team.members["UAV1"]
    m.schedule = dataclasses.replace(m.schedule, via=(30_000.0, m.target_s - 3_000.0))
    assert team.current_schedule().vehicle("UAV1").via == m.schedule.via
    assert m.via_live() == m.schedule.via
    m.target_s += 20.0  # the team time moved
    assert m.via_live() is None
    assert team.current_schedule().vehicle("UAV1").via is None


# -- supervision ---------------------------------------------------------------------------------


def _team(paper: tuple[Scenario, World, Schedule], **config: Any) -> TeamController:
    scenario, world, schedule = paper
    t = TeamController(
        scenario, schedule, world, FlightConfig(**config), rng=np.random.default_rng(3)
    )
    t.start(START_UTC)
    return t


def fix_at(team: TeamController, vid: str, s_m: float, t_s: float) -> act.Fix:
    """A fix on the route at ``s_m`` flying 25 m/s."""
    return fix(team, vid, s_m, t_s, 25.0)


@pytest.mark.parametrize("after", ["stays", "goes_back"])
def test_a_vehicle_whose_progress_stalls_past_the_bound_is_lost_and_the_others_keep_their_slots(
    team: TeamController, after: str
) -> None:
    vid = "UAV2"
    m, t0 = flying(team, vid, 600.0)
    slots = {x.vehicle_id: x.target_s for x in team.members.values()}
    ref = team.team_ref_s
    # Standing still it is lost after stopped_bound_s; flying backwards, after stall_bound_s
    # (shortened here: backwards for the default 300 s it would first be late and move the
    # team time, which is not what this test is about).
    team.config = dataclasses.replace(team.config, stall_bound_s=10.0)
    bound = team.config.stopped_bound_s if after == "stays" else team.config.stall_bound_s
    s0 = 20_000.0
    # On its route at 25 m/s, 2 fixes a second; a 30 s gap in them (a link blackout) with the
    # progress made meanwhile is no stall.
    for k in range(20):
        team.handle(fix_at(team, vid, s0 + 12.5 * k, t0 + 0.5 * k), t0 + 0.5 * k)
    s1, t1 = s0 + 12.5 * 19 + 750.0, t0 + 9.5 + 30.0
    assert not reports(team.handle(fix_at(team, vid, s1, t1), t1), EventKind.VEHICLE_LOST)
    # Then it stops (or turns back): no report until the bound has passed, one after it.
    lost: list[act.Report] = []
    k = 1
    while not lost:
        s = s1 if after == "stays" else s1 - 12.5 * k
        t = t1 + 0.5 * k
        lost = reports(team.handle(fix_at(team, vid, s, t), t), EventKind.VEHICLE_LOST)
        assert lost or t - t1 <= bound
        k += 1
    assert t - t1 == pytest.approx(bound + 0.5, abs=0.01)
    (r,) = lost
    assert r.vehicle == vid and r.t_s == t
    assert r.payload["cause"] == "stall" and r.payload["policy"] == "continue"
    if after == "stays":
        assert f"stopped: moved 0 m in {t - t1:.1f} s" in r.reason
    else:
        assert f"no progress along its route for {t - t1:.1f} s" in r.reason
    assert "the others keep their slots" in r.reason
    assert m.phase == "lost" and m.state is VehicleState.LOST and m.done
    assert team.team_ref_s == ref
    assert {x.vehicle_id: x.target_s for x in team.members.values()} == slots
    # It is not commanded or timed any more.
    assert team.handle(fix_at(team, vid, s1 + 5000.0, t + 60.0), t + 60.0) == []


def test_a_loiter_is_no_stall(team: TeamController) -> None:
    vid = "UAV2"
    m, t0 = flying(team, vid, 600.0)
    team.handle(fix_at(team, vid, 20_000.0, t0), t0)
    # Its mission's item 2 made loiter turns and flown: circling there, its s stays put.
    loiter_seq = 2
    items = list(m.mission.items)
    items[loiter_seq] = dataclasses.replace(items[loiter_seq], command=MAV_CMD_NAV_LOITER_TURNS)
    m.mission = dataclasses.replace(m.mission, items=tuple(items))
    for k in range(1, 200):
        # Circling there: it moves (back and forth along the route here), its s goes nowhere.
        f = fix_at(team, vid, 20_000.0 + 250.0 * math.sin(k * math.pi / 16), t0 + 0.5 * k)
        out = team.handle(act.Fix(**{**f.__dict__, "mission_seq": loiter_seq}), t0 + 0.5 * k)
        assert not reports(out, EventKind.VEHICLE_LOST)
    assert m.state is VehicleState.LOITERING


def test_circling_while_an_upload_is_unanswered_is_no_stall_and_the_watch_resumes_after(
    team: TeamController,
) -> None:
    """A loaded link answers an upload late: the vehicle may already fly the new mission (its
    loiter turns) while the controller measures it on the old track. Not a stall until the
    answer; after it, circling on the old track is one again after the bound."""
    vid = "UAV2"
    m, t0 = flying(team, vid, 600.0)
    team.config = dataclasses.replace(team.config, stall_bound_s=10.0)
    up = act.Upload(vid, m.mission, m.schedule, None, "loiter inserted", True)
    team.pending[vid] = up
    t = t0
    for k in range(1, 80):  # 40 s circling, 4 x the bound
        t = t0 + 0.5 * k
        f = fix_at(team, vid, 20_000.0 + 250.0 * math.sin(k * math.pi / 16), t)
        assert not reports(team.handle(f, t), EventKind.VEHICLE_LOST)
    del team.pending[vid]  # answered (as Installed does)
    lost: list[act.Report] = []
    k = 80
    while not lost and k < 200:
        t = t0 + 0.5 * k
        f = fix_at(team, vid, 20_000.0 + 250.0 * math.sin(k * math.pi / 16), t)
        lost = reports(team.handle(f, t), EventKind.VEHICLE_LOST)
        k += 1
    assert lost and "no progress along its route" in lost[0].reason
    assert t - (t0 + 40.0) >= team.config.stall_bound_s


def test_a_crash_text_loses_the_vehicle_and_retime_moves_the_team_to_the_earliest_of_the_rest(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    team = _team(paper, on_vehicle_lost="retime")
    vid = "UAV2"  # it sets the team time at its top speed: the others could arrive earlier
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    t = m.takeoff_s + 30.0
    ground = [x for x in team.members.values() if x.phase == "ground"]
    assert {x.vehicle_id for x in ground} == {"UAV1", "UAV3"}
    ref = team.team_ref_s
    assert ref is not None
    # A PreArm-like critical text is said, not taken for a crash.
    out = team.handle(act.Alarm(vid, 2, "PreArm: Compass not healthy"), t - 1.0)
    assert reports(out, EventKind.ALARM) and not reports(out, EventKind.VEHICLE_LOST)
    out = team.handle(act.Alarm(vid, 0, "Crash detected"), t)
    (alarm,) = reports(out, EventKind.ALARM)
    assert alarm.payload == {"severity": 0, "text": "Crash detected"}
    (lost,) = reports(out, EventKind.VEHICLE_LOST)
    assert lost.payload["cause"] == "crash" and "'Crash detected'" in lost.reason
    assert m.state is VehicleState.CRASHED
    # The earliest common arrival of the two still on the ground, taking off now, climbing
    # out and flying the rest at top speed (the test's own arithmetic), plus the late margin.
    v = {x.vehicle_id: team.scenario.vehicle(x.vehicle_id) for x in ground}

    def earliest_of(x: Member) -> float:
        climb = x.schedule.climb
        assert climb is not None
        rest_m = x.schedule.path.length_m - climb.s_m
        tas = v[x.vehicle_id].speed_max_m_s * x.schedule.tas_per_eas(climb.s_m)
        return max(t, v[x.vehicle_id].takeoff_window_s[0]) + climb.duration_s + rest_m / tas

    earliest = max(earliest_of(x) - x.offset_s for x in ground)
    expected = earliest + FlightConfig().late_margin_s
    assert expected < ref - 10.0
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert f"without {vid} (lost)" in moved.reason
    assert team.team_ref_s == pytest.approx(expected, abs=0.01)
    for x in ground:  # each can make its new slot from its takeoff time at top speed
        assert x.target_s == pytest.approx(expected + x.offset_s)
        top = v[x.vehicle_id].speed_max_m_s * x.schedule.tas_per_eas()
        assert x.takeoff_s + x.schedule.path.length_m / top <= x.target_s + 0.01


def test_emergency_or_disarmed_on_the_route_is_a_crash_and_abort_aborts_the_team(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    team = _team(paper, on_vehicle_lost="abort")
    vid = "UAV2"
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    t = m.takeoff_s + 5.0
    # Climbing out, an old disarmed heartbeat is no crash; armed and healthy is nothing.
    assert team.handle(act.Heartbeat(vid, armed=False, emergency=False), t) == []
    t += 600.0
    team.handle(fix_at(team, vid, 20_000.0, t), t)
    assert m.phase == "route"
    assert not reports(team.handle(act.Heartbeat(vid, True, False), t), EventKind.VEHICLE_LOST)
    out = team.handle(act.Heartbeat(vid, armed=False, emergency=False), t + 1.0)
    (lost,) = reports(out, EventKind.VEHICLE_LOST)
    assert "disarmed on its route" in lost.reason and "the team is aborted" in lost.reason
    assert m.state is VehicleState.CRASHED
    others = [x for x in team.members.values() if x.vehicle_id != vid]
    assert all(x.phase == "aborted" for x in others) and team.finished
    in_air = {x.vehicle_id for x in others if x.launched_s is not None}
    assert {a.vehicle_id for a in of(out, act.SetMode)} == in_air


def test_emergency_heartbeat_while_climbing_out_is_a_crash(team: TeamController) -> None:
    vid = "UAV2"
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    out = team.handle(act.Heartbeat(vid, armed=True, emergency=True), m.takeoff_s + 20.0)
    (lost,) = reports(out, EventKind.VEHICLE_LOST)
    assert "MAV_STATE_EMERGENCY" in lost.reason and m.state is VehicleState.CRASHED


def test_the_flight_ends_at_its_hard_deadline_whatever_the_team_time_became(
    team: TeamController,
) -> None:
    planned_last = max(m.target_s for m in team.members.values())
    cfg = FlightConfig()
    assert team.hard_deadline_s == pytest.approx(planned_last + cfg.hard_deadline_s)
    for m in team.members.values():
        m.takeoff_s = math.inf  # nobody launches here
    with pytest.raises(GcsError, match="past the flight's hard deadline"):
        team.move_team_time(team.hard_deadline_s + 1.0, 0.0)
    ref = team.team_ref_s
    assert ref is not None
    late = team.hard_deadline_s - 100.0 - (planned_last - ref)
    team.move_team_time(late, 0.0)
    overrun_at = max(m.target_s for m in team.members.values()) + cfg.overrun_s
    assert overrun_at > team.hard_deadline_s  # the overrun moved with the team; this did not
    assert of(team.handle(act.Tick(), team.hard_deadline_s - 1.0), act.Stop) == []
    out = team.handle(act.Tick(), team.hard_deadline_s + 1.0)
    (stop,) = of(out, act.Stop)
    assert stop.reason.startswith(f"hard deadline {team.hard_deadline_s:.1f} s passed")
    assert stop.reason.endswith("UAV1, UAV2, UAV3 not arrived") and team.finished


# -- separation in flight -------------------------------------------------------------------------


def fix_beside(
    team: TeamController, vid: str, beside: act.Fix, east_m: float, t_s: float
) -> act.Fix:
    """A fix of ``vid`` standing still at ``east_m``, on the north and at the height of the fix
    ``beside`` (another vehicle's)."""
    _, north_m = team.frame.to_local(beside.lat_deg, beside.lon_deg)
    lat, lon = team.frame.to_geodetic(east_m, float(north_m))
    f = fix(team, vid, 20_000.0, t_s, 25.0)
    return dataclasses.replace(
        f, lat_deg=float(lat), lon_deg=float(lon), alt_amsl_m=beside.alt_amsl_m,
        ve_m_s=0.0, vn_m_s=0.0,
    )  # fmt: skip


def test_two_vehicles_closer_than_the_separation_are_an_alarm_once_per_encounter(
    team: TeamController,
) -> None:
    """UAV1 is put where UAV2 is, 300 m beside it, then 5 km away, then beside it again: an
    alarm at each approach, the distance measured here from the two positions."""
    d_s = team.scenario.separation_m
    m1, t0 = flying(team, "UAV1", 600.0)
    m2 = team.members["UAV2"]
    airborne(team, "UAV2", t0)
    f2 = fix(team, "UAV2", 20_000.0, t0, 25.0)
    team.handle(f2, t0)
    e2, n2 = (float(x) for x in team.frame.to_local(f2.lat_deg, f2.lon_deg))

    alarms: list[act.Report] = []
    for offset, dt in [(300.0, 0.5), (250.0, 1.0), (5_000.0, 1.5), (300.0, 2.0)]:
        t = t0 + dt
        # UAV2's fix at t0, moved on along its velocity to t: where the watch expects it.
        expected = math.hypot(e2 + offset - (e2 + f2.ve_m_s * dt), n2 - (n2 + f2.vn_m_s * dt))
        got = reports(team.handle(fix_beside(team, "UAV1", f2, e2 + offset, t), t), EventKind.ALARM)
        alarms += got
        if got:
            assert got[0].value == pytest.approx(expected, abs=0.5)
            assert expected < d_s
    assert [a.vehicle for a in alarms] == ["UAV1", "UAV1"]
    assert all("from UAV2" in a.reason and f"below {d_s:g} m" in a.reason for a in alarms)
    assert m1.launched_s is not None and m2.launched_s is not None


def test_a_vehicle_past_its_slot_is_still_in_the_air_and_its_separation_still_watched(
    team: TeamController,
) -> None:
    """UAV2 has passed its goal and circles where its mission ends: no longer timed, it is
    still in the air. Its fixes still count: UAV1 coming 300 m beside it is an alarm, as
    beside any other vehicle, and so is UAV2 coming to it (the distances measured here from
    the positions), but it is predicted for no one. A vehicle lost (crashed) counts for no
    one."""
    d_s = team.scenario.separation_m
    _, t0 = flying(team, "UAV1", 600.0)
    m2 = team.members["UAV2"]
    airborne(team, "UAV2", t0)
    f2 = fix(team, "UAV2", 20_000.0, t0, 25.0)
    team.handle(f2, t0)
    m2.phase, m2.arrival_s = "arrived", t0  # past its slot
    assert m2.over
    e2, _ = (float(x) for x in team.frame.to_local(f2.lat_deg, f2.lon_deg))

    team.handle(fix_beside(team, "UAV2", f2, e2, t0 + 0.5), t0 + 0.5)  # circling: still heard
    out = team.handle(fix_beside(team, "UAV1", f2, e2 + 300.0, t0 + 1.0), t0 + 1.0)
    (alarm,) = reports(out, EventKind.ALARM)
    assert alarm.vehicle == "UAV1" and alarm.payload["other"] == "UAV2"
    assert alarm.value == pytest.approx(300.0, abs=0.5) and d_s > 300.0
    assert not reports(out, EventKind.CONFLICT)  # predicted for no one
    team.handle(fix_beside(team, "UAV1", f2, e2 + 5_000.0, t0 + 1.5), t0 + 1.5)
    out = team.handle(fix_beside(team, "UAV2", f2, e2 + 4_800.0, t0 + 2.0), t0 + 2.0)
    (alarm,) = reports(out, EventKind.ALARM)
    assert alarm.vehicle == "UAV2" and alarm.value == pytest.approx(200.0, abs=0.5)
    m2.phase = "lost"
    team.handle(
        fix_beside(team, "UAV1", f2, e2 + 10_000.0, t0 + 2.5), t0 + 2.5
    )  # apart: the encounter over
    out = team.handle(fix_beside(team, "UAV1", f2, e2 + 4_800.0, t0 + 3.0), t0 + 3.0)
    assert not reports(out, EventKind.ALARM)


def test_a_conflict_is_predicted_within_the_look_ahead_said_once_and_dropped() -> None:
    """Head-on at 25 m/s each, 2 km apart, 100 m off each other's line: they would pass 100 m
    apart in 40 s (worked out here by hand). Not within a 30 s look-ahead, then within it,
    said once; a turn away drops it; apart in height, or side by side, none."""
    w = SeparationWatch(500.0, stale_s=5.0)
    ahead = {"A": 30.0, "B": 30.0}

    def fixes(t: float, a: Position) -> None:
        w.update("B", Position(t, 2000.0 - 25.0 * t, 100.0, 500.0, ve_m_s=-25.0), ["A", "B"])
        w.update("A", a, ["A", "B"])

    fixes(0.0, Position(0.0, 0.0, 0.0, 500.0, ve_m_s=25.0))
    assert w.predict("A", ahead) == []  # in 40 s: beyond 30 s
    fixes(12.0, Position(12.0, 300.0, 0.0, 500.0, ve_m_s=25.0))
    (c,) = w.predict("A", ahead)  # 1400 m closed in 28 s
    assert (c.vehicle, c.other) == ("A", "B")
    assert c.distance_m == pytest.approx(100.0) and c.at_s == pytest.approx(40.0)
    fixes(13.0, Position(13.0, 325.0, 0.0, 500.0, ve_m_s=25.0))
    assert w.predict("A", ahead) == [] and ("A", "B") in w.predicted  # said once
    fixes(14.0, Position(14.0, 350.0, 0.0, 500.0, vn_m_s=-25.0))  # turned away
    assert w.predict("A", ahead) == [] and ("A", "B") not in w.predicted
    # The same meeting 600 m apart in height, or side by side on parallel tracks.
    high = SeparationWatch(500.0)
    high.update("B", Position(0.0, 1000.0, 100.0, 1100.0, ve_m_s=-25.0), ["A", "B"])
    high.update("A", Position(0.0, 0.0, 0.0, 500.0, ve_m_s=25.0), ["A", "B"])
    assert high.predict("A", ahead) == []
    side = SeparationWatch(500.0)
    side.update("B", Position(0.0, 0.0, 400.0, 500.0, ve_m_s=25.0), ["A", "B"])
    side.update("A", Position(0.0, 0.0, 0.0, 500.0, ve_m_s=25.0), ["A", "B"])
    assert side.predict("A", ahead) == []  # 400 m apart now: a shortfall, not a prediction


def test_the_separation_watch_skips_stale_fixes_and_clears_a_pair_once_apart() -> None:
    w = SeparationWatch(500.0, stale_s=5.0)
    w.update("A", Position(0.0, 0.0, 0.0, 100.0, ve_m_s=10.0), ["A", "B"])
    # B at 10 s: A's fix is 10 s old, past the stale bound: not compared.
    assert w.update("B", Position(10.0, 100.0, 0.0, 100.0), ["A", "B"]) == []
    # A at 11 s, 1 km west of B's fix at 10 s (B still): apart.
    assert w.update("A", Position(11.0, -900.0, 0.0, 100.0, ve_m_s=10.0), ["A", "B"]) == []
    # At 12 s A is expected at 890 m west, B at 500 m west, 300 m up: 3-D distance.
    (sf,) = w.update("B", Position(12.0, -500.0, 0.0, 400.0), ["A", "B"])
    assert (sf.vehicle, sf.other) == ("B", "A")
    assert sf.distance_m == pytest.approx(math.hypot(390.0, 300.0))
    assert w.closest[("A", "B")] == (pytest.approx(sf.distance_m), 12.0)
    # Still close, then apart by less than 1.2 d_s (no new alarm), apart, close again.
    # (A expected at 885 m west at 12.5 s, 880 m at 13 s, 875 m at 13.5 s.)
    assert w.update("B", Position(12.5, -300.0, 0.0, 100.0), ["A", "B"]) == []  # 585 m
    assert ("A", "B") in w.close
    assert w.update("B", Position(13.0, -200.0, 0.0, 100.0), ["A", "B"]) == []  # 680 m
    assert ("A", "B") not in w.close
    assert len(w.update("B", Position(13.5, -600.0, 0.0, 100.0), ["A", "B"])) == 1  # 275 m
    # A vehicle not flying (arrived) is not compared.
    assert w.update("C", Position(13.5, 200.0, 0.0, 100.0), ["C", "B"]) == []


def test_a_pair_under_the_separation_is_said_again_each_step_closer_and_checkpoints_keep_it() -> (
    None
):
    """Abreast on parallel tracks closing 10 m a second from 499 m: said at 499 m, then again
    each 100 m closer (a fifth of d_s), not in between; a checkpointed watch goes on where it
    was, and one kept before the step existed starts from its close pairs."""
    w = SeparationWatch(500.0)
    said: list[tuple[float, float | None]] = []
    for k in range(45):
        t = float(k)
        for vid, north_m in (("B", 499.0 - 10.0 * t), ("A", 0.0)):
            for sf in w.update(vid, Position(t, 0.0, north_m, 500.0), ["A", "B"]):
                said.append((round(sf.distance_m), sf.previous_m and round(sf.previous_m)))
        if k == 25:
            w = pickle.loads(pickle.dumps(w))
    assert said == [(499, None), (399, 499), (299, 399), (199, 299), (99, 199)]
    old = pickle.loads(pickle.dumps(w))
    del old.__dict__["said_m"]
    old = pickle.loads(pickle.dumps(old))  # as a checkpoint from before the step
    assert old.said_m == old.close


# -- arrival windows ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def windows_team_parts(
    paper: tuple[Scenario, World, Schedule],
) -> tuple[Scenario, World, Schedule]:
    own = {"UAV1": (5_300.0, 7_000.0), "UAV2": (5_300.0, 5_320.0), "UAV3": (5_300.0, 7_000.0)}
    arrival = {
        "kind": "windows",
        "windows": [{"vehicle": v, "earliest_s": a, "latest_s": b} for v, (a, b) in own.items()],
    }
    return _paper_arriving(paper, arrival)


def _found_behind(
    team: TeamController, vid: str, s_m: float, late_s: float
) -> tuple[list[act.Action], float, float]:
    """``vid`` launched, its first fix ``s_m`` along its route (at 25 m/s) at the time from
    which its top speed (still air, the test's own arithmetic) brings it ``late_s`` after its
    slot: the actions, that time and its earliest arrival from there."""
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    v_max = m.limits.airspeed_max_m_s
    t = m.target_s + late_s - still_air_eta_s(team, vid, s_m, 0.0, v_max)
    earliest = still_air_eta_s(team, vid, s_m, t, v_max)
    return team.handle(fix(team, vid, s_m, t, 25.0), t), t, earliest


def _paper_arriving(
    paper: tuple[Scenario, World, Schedule], arrival: dict[str, Any]
) -> tuple[Scenario, World, Schedule]:
    """The paper scenario with another arrival rule: planned and scheduled."""
    scenario, _world, _ = paper
    data = scenario.model_dump(mode="json", exclude_none=True) | {"arrival": arrival}
    scen = parse_scenario(data)
    w = build_world(scen)
    p = plan(scen, rng=np.random.default_rng(1), world=w)
    return scen, w, build_schedule(scen, p, world=w)


def test_windows_a_late_vehicle_moves_its_own_slot_within_its_window_or_alarms(
    windows_team_parts: tuple[Scenario, World, Schedule],
) -> None:
    scenario, world, schedule = windows_team_parts
    team = TeamController(scenario, schedule, world, FlightConfig(), rng=np.random.default_rng(3))
    team.start(START_UTC)
    assert team.team_ref_s is None
    slots = {v: m.target_s for v, m in team.members.items()}
    # UAV1 far enough behind to be ~200 s late at top speed: inside its wide window.
    m1 = team.members["UAV1"]
    v_max = m1.limits.airspeed_max_m_s
    out, _, earliest = _found_behind(team, "UAV1", 5_000.0, 200.0)
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert "within its window [5300, 7000] s" in moved.reason
    said = float(re.search(r"cannot arrive before ([\d.]+) s", moved.reason).group(1))  # type: ignore[union-attr]
    assert m1.target_s == pytest.approx(said + FlightConfig().late_margin_s, abs=0.05)
    # The controller times the climb profile's true airspeed leg by leg; this estimate
    # takes one ratio for the rest of the route.
    assert said == pytest.approx(earliest, abs=25.0)
    assert all(team.members[v].target_s == slots[v] for v in ("UAV2", "UAV3"))
    assert not reports(out, EventKind.ALARM)
    # UAV2 late past the end of its narrow window: an alarm, once; it flies at top speed.
    m2 = team.members["UAV2"]
    airborne(team, "UAV2", m2.takeoff_s)
    t2 = m2.takeoff_s + 600.0
    assert still_air_eta_s(team, "UAV2", 2_000.0, t2, v_max) > 5_320.0
    out = team.handle(fix(team, "UAV2", 2_000.0, t2, 25.0), t2)
    (alarm,) = reports(out, EventKind.ALARM)
    assert alarm.vehicle == "UAV2" and "misses its window [5300, 5320] s" in alarm.reason
    cmds = of(out, act.CommandSpeed)
    assert cmds and cmds[0].airspeed_m_s == m2.limits.airspeed_max_m_s
    out = team.handle(fix(team, "UAV2", 2_050.0, t2 + 2.0, 30.0), t2 + 2.0)
    assert not reports(out, EventKind.ALARM)


@pytest.mark.parametrize("lead_s", [3_000.0, 20_000.0])
def test_a_popup_whose_zone_lies_short_of_the_splice_waypoint_re_plans_from_the_hold_point(
    team: TeamController, lead_s: float
) -> None:
    """A lead so long that the waypoint it asks for lies past the zone (20,000 s: past every
    waypoint, as on a rehearsal at 200x on a loaded machine): the vehicles whose routes enter
    the zone before it are re-planned from where they will hold short of it."""
    zones = build_threats(team.scenario, {vid: m.takeoff_s for vid, m in team.members.items()})
    (zone,) = popup_zones(zones)
    t_p = float(zone.appears_at_s or 0.0)
    _on_schedule(team, t_p - 1.0)
    team.handle(act.PlanningLead(lead_s, 90.0), t_p - 0.5)
    out = team.handle(act.Tick(), t_p)
    dropped = [r.vehicle for r in reports(out, EventKind.POPUP) if "no waypoint" in r.reason]
    (job,) = [a.job for a in of(out, act.Compute)]
    assert isinstance(job, act.PopupJob)
    cx, cy, r = zone.east_m, zone.north_m, zone.radius_m
    short = set()
    for vid, m in team.members.items():
        path = m.schedule.path
        s_now = m.s_m or 0.0
        poses = [(float(s), path.pose_at(float(s))) for s in np.arange(s_now, path.length_m, 50.0)]
        inside = [s for s, q in poses if math.hypot(q.east_m - cx, q.north_m - cy) < r]
        entry = inside[0] if inside else None
        if entry is None or entry > s_now + lead_s * m.groundspeed_m_s:
            continue
        short.add(vid)
        assert vid not in dropped, vid
        anchor = job.anchors[vid]
        p = path.pose_at(anchor.s_m)
        assert s_now < anchor.s_m < entry, (vid, s_now, anchor.s_m, entry)
        clearance = max(FlightConfig().hold_radius_m, team.scenario.vehicle(vid).min_turn_radius_m)
        assert math.hypot(p.east_m - cx, p.north_m - cy) - r >= clearance, vid
        assert anchor.t_s is not None and anchor.t_s >= t_p + lead_s - 1e-6
        assert job.keeps[vid] is not None
        assert m.mission.item_s_m[job.keeps[vid]] <= anchor.s_m + 1e-6
    assert short >= {"UAV1"}, short


def test_loiter_turns_splice_at_the_loiter_lead_not_the_team_re_plan_lead(
    team: TeamController,
) -> None:
    team.handle(act.PlanningLead(3_000.0, 90.0), 0.0)
    vid = "UAV3"
    m = team.members[vid]
    _, s0, job = _early(team, vid)
    gs = m.groundspeed_m_s
    spacing = FlightConfig().waypoint_spacing_m
    assert s0 + gs * 90.0 <= job.s_m <= s0 + gs * 90.0 + spacing + 1.0


def test_loiter_turns_splice_nearer_where_the_loiter_lead_leaves_no_room_for_them(
    team: TeamController,
) -> None:
    """The waypoint the loiter lead ahead has too little path after it for turns; the one
    the shortest lead ahead has room (as the team-time check found when it let the team
    time move later): the turns are spliced after that one, not given up."""
    vid = "UAV3"
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    length_m = m.track.length_m
    gs = 20.0
    # 90 s before the last waypoint but one: that one is the shortest lead (60 s) ahead, the
    # last (4.4 km on, with 1.3 km after it) the loiter lead (120 s) ahead.
    ahead = sorted({s for s in m.mission.item_s_m if s is not None and s < length_m})
    s0 = ahead[-2] - gs * 90.0
    t0 = m.takeoff_s + 300.0
    team.handle(act.PlanningLead(3_000.0, 120.0), 0.0)
    keep = {}
    for lead_s in (FlightConfig().min_lead_s, 120.0):
        k = team._keep_seq(replace(m, s_m=s0, groundspeed_m_s=gs), gs * lead_s)
        assert k is not None
        keep[lead_s] = k
    near, far = keep[FlightConfig().min_lead_s], keep[120.0]
    s_near, s_far = m.mission.item_s_m[near], m.mission.item_s_m[far]
    assert s_near is not None and s_far is not None and s_near < s_far
    assert not team._can_loiter_after(m, s_far)
    assert team._can_loiter_after(m, s_near)
    m.target_s += 900.0
    out = team.handle(fix(team, vid, s0, t0, gs), t0)
    (job,) = [a.job for a in of(out, act.Compute)]
    assert isinstance(job, act.LoiterJob)
    assert job.keep_seq == near
    vs, _ = job.run()
    assert any(lo.s_m >= s_near for lo in vs.loiters)


def test_a_vehicle_in_its_loiter_turns_is_timed_and_a_late_one_leaves_them_and_moves_the_team_time(
    team: TeamController,
) -> None:
    """In loiter turns the vehicle is still timed (the turns left from the ground distance
    flown in them): its airspeed trimmed; when the team time comes too soon for the turns
    left even at top speed it is taken out of them now (the item after the loiter made
    current), and as the route alone is too long for it too, the team time moves now, for
    the route from where it is, not when the vehicle comes out."""
    vid = "UAV3"
    m = team.members[vid]
    t0, _, job = _early(team, vid)
    (up,) = of(team.handle(act.Computed(job, job.run()), t0 + 1), act.Upload)
    team.handle(act.Installed(up), t0 + 2)
    if m.busy_command:  # the early fix's speed command: answered
        team.handle(act.SpeedCommanded(vid, 15.0, "early", t0), t0 + 2)
    (lo,) = [x for x in m.track.loiters if x.s_m > job.s_m - 1.0]
    k_loiter = next(
        k for k, it in enumerate(m.mission.items) if it.command == MAV_CMD_NAV_LOITER_TURNS
    )
    t1 = t0 + 600.0
    base = dataclasses.replace(fix(team, vid, lo.s_m, t1, 20.0), mission_seq=k_loiter)
    for c in of(team.handle(base, t1), act.CommandSpeed):
        team.handle(act.SpeedCommanded(vid, c.airspeed_m_s, c.reason, c.decided_s), t1)
    assert m.in_loiter() and m.loiter_entered_s == t1
    m.heard_since_s = -math.inf  # the test's leap to t1 stands for fixes all along, no gap

    def on_circle(i: int) -> act.Fix:
        return on_loiter_circle(team, base, lo, i)

    # 200 s in the turns (fixes every 2 s).
    trims = []
    before = m.last_decision
    for i in range(1, 101):
        for c in of(team.handle(on_circle(i), t1 + 2.0 * i), act.CommandSpeed):
            trims.append(c.airspeed_m_s)
            team.handle(act.SpeedCommanded(vid, c.airspeed_m_s, c.reason, c.decided_s), t1 + 2 * i)
    assert m.phase == "route"
    assert m.last_decision is not before and m.next_decision_s > t1  # timed in the turns
    assert m.loiter_flown_m == pytest.approx(100 * 2.0 * base.groundspeed_m_s)
    t2 = t1 + 200.0
    left_m = lo.length_m - m.loiter_flown_m + m.track.length_m - lo.s_m
    assert left_m > 10_000.0
    # The slot moved to 60 s from now: nothing flies the turns left that fast.
    old_ref = team.team_ref_s
    assert old_ref is not None
    for x in team.members.values():
        x.target_s = t2 + 60.0 + x.offset_s
        x.next_decision_s = -math.inf
    team.team_ref_s = t2 + 60.0
    out = team.handle(on_circle(101), t2 + 2.0)
    (leave,) = of(out, act.LeaveLoiter)
    assert leave.vehicle_id == vid and leave.seq == k_loiter + 1
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert moved.vehicle == vid and "cannot arrive before" in moved.reason
    # Where it moves to, worked out here: from fix 101 (t2 + 2 s), out of the turns, the
    # way out to the waypoint after them (flown step by step from the fix's course:
    # :func:`tests.planner.test_loiterflight._flown_out_m`) and the route on from it, at the
    # top equivalent airspeed in still air, plus the late margin (the config's, or 2 % of
    # the time still to fly if that is less): as from that far back along the route from
    # the waypoint. The controller times the route at one true airspeed per equivalent: the
    # harmonic mean of the ISA ratio along it, integrated here by scipy over the route's own
    # altitude profile with the ISA worked out here (:func:`_isa_tas_per_eas`).
    v_max = m.limits.airspeed_max_m_s
    t_fix = t2 + 2.0
    here = on_circle(101)
    he, hn = team.frame.to_local(here.lat_deg, here.lon_deg)
    w = next(
        j for j in range(k_loiter + 1, len(m.mission.items)) if m.mission.items[j].command == 16
    )
    item = m.mission.items[w]
    we, wn = team.frame.to_local(item.lat_deg, item.lon_deg)
    assert here.ve_m_s is not None and here.vn_m_s is not None
    way_m = _flown_out_m(
        float(we - he),
        float(wn - hn),
        math.atan2(here.ve_m_s, here.vn_m_s),
        math.hypot(here.ve_m_s, here.vn_m_s),
    )
    s_w = m.mission.item_s_m[w]
    assert s_w is not None
    s_fix = s_w - way_m
    s_wp, alt_wp = np.asarray(m.schedule.wp_s_m), np.asarray(m.schedule.wp_alt_m)
    end_m = m.track.length_m
    route_per_eas_s = quad(
        lambda s: 1.0 / _isa_tas_per_eas(float(np.interp(s, s_wp, alt_wp))),
        s_fix,
        end_m,
        points=[s for s in s_wp if s_fix < s < end_m],
        limit=200,
    )[0]
    eta_s = t_fix + route_per_eas_s / v_max
    margin_s = min(team.config.late_margin_s, 0.02 * (eta_s - t_fix))
    # 10 ms: the integral against the route's 50 m table of the ratio, and the way out's
    # steps.
    assert moved.value == pytest.approx(eta_s - m.offset_s + margin_s, abs=0.01)
    (cmd,) = of(out, act.CommandSpeed)
    assert cmd.airspeed_m_s == m.limits.airspeed_max_m_s
    # Out of them: no longer in a loiter, its turns counted as flown, timed on its route.
    out = team.handle(act.LoiterLeft(leave), t_fix + 1.0)
    assert [r.payload["action"] for r in reports(out, EventKind.LOITER)] == ["left"]
    assert not m.in_loiter() and m.loiters_done() == 1 and m.next_decision_s == -math.inf


def _isa_tas_per_eas(alt_m: float) -> float:
    """True per equivalent airspeed at ``alt_m`` AMSL in the ISA troposphere, worked out here:
    ``sqrt(rho0 / rho)`` with ``rho / rho0 = (T / T0) ** (g / (R L) - 1)``,
    ``T = T0 - L h``."""
    t0_k, lapse_k_m, g_m_s2, r_j_kg_k = 288.15, 0.0065, 9.80665, 287.05287
    density_ratio = ((t0_k - lapse_k_m * alt_m) / t0_k) ** (g_m_s2 / (r_j_kg_k * lapse_k_m) - 1.0)
    return float(density_ratio**-0.5)


def test_passing_near_its_goal_on_the_way_round_is_not_the_arrival(team: TeamController) -> None:
    """A route re-planned round a zone may come within the arrival radius of its own goal
    long before it ends there: a fix 300 m from the goal while the vehicle is 20 km along a
    route much longer than that is no arrival; the passage at the route's end is, at the time
    the fixes put it there (worked out here from the fixes' own times)."""
    vid = "UAV1"
    m, t0 = flying(team, vid, 600.0)
    length = m.track.length_m
    team.handle(fix(team, vid, 20_000.0, t0, 25.0), t0)
    ge, gn = m.goal_en_m
    lat, lon = team.frame.to_geodetic(ge + 300.0, gn)
    near = dataclasses.replace(
        fix(team, vid, 20_010.0, t0 + 1.0, 25.0), lat_deg=float(lat), lon_deg=float(lon)
    )
    said = reports(team.handle(near, t0 + 1.0), EventKind.ARRIVED)
    said += reports(
        team.handle(fix(team, vid, 20_050.0, t0 + 2.0, 25.0), t0 + 2.0), EventKind.ARRIVED
    )
    assert said == [] and m.phase == "route"
    # Then along the route to its end, a fix every 20 m, and on past it out of the radius.
    gs = 25.0 * m.schedule.tas_per_eas(length)
    t_end = t0 + 100.0 + 1500.0 / gs  # at the goal
    for s in np.arange(length - 1500.0, length + 1.0, 20.0):
        t = t0 + 100.0 + (s - (length - 1500.0)) / gs
        said += reports(team.handle(fix(team, vid, float(s), t, 25.0), t), EventKind.ARRIVED)
    assert said == []
    end = m.schedule.path.pose_at(length)
    lat, lon = team.frame.to_geodetic(
        end.east_m + 1200.0 * math.sin(end.heading_rad),
        end.north_m + 1200.0 * math.cos(end.heading_rad),
    )
    t = t_end + 1200.0 / gs
    past = dataclasses.replace(
        fix(team, vid, length, t, 25.0), lat_deg=float(lat), lon_deg=float(lon)
    )
    said += reports(team.handle(past, t), EventKind.ARRIVED)
    assert len(said) == 1 and m.arrival_s == pytest.approx(t_end, abs=1.0)


def test_a_hook_back_into_the_goals_approach_is_not_the_arrival(team: TeamController) -> None:
    """A route re-planned round a zone may overshoot its goal and hook back into its approach
    (the 60-vehicle crowd's R05): 500 m from the goal with 1.3 km of route left, then away from
    it along the hook, is no passage (it was taken for one, 53 s early, and the vehicle was
    left at its last speed, 2 s late); the passage at the route's end is, at the time the
    fixes put it there (the test's own: 25 m/s along the route from the hook's start)."""
    vid = "UAV1"
    m, t0 = flying(team, vid, 600.0)
    team.handle(fix(team, vid, 20_000.0, t0, 25.0), t0)  # on its route
    assert m.phase == "route"
    t0 += 1.0
    ge, gn = m.goal_en_m
    hook = [(-500.0, 1_700.0), (-500.0, 30.0), (-720.0, -380.0), (-340.0, -350.0), (0.0, 0.0)]
    path = smooth_polyline([(ge + e, gn + n) for e, n in hook], 150.0)
    m.track, m.s_m = RouteTrack(path), 0.0
    m.goal_en_m = (path.end.east_m, path.end.north_m)
    # The hook: a point of the route within 600 m of the goal with over 1.2 km of it left.
    s_near = np.arange(0.0, path.length_m - 1_200.0, 10.0)
    near_m = [math.dist((p.east_m, p.north_m), m.goal_en_m) for p in map(path.pose_at, s_near)]
    assert min(near_m) < 600.0
    said: list[act.Report] = []
    gs = 25.0 * m.schedule.tas_per_eas(m.s_m or 0.0)
    s_end = path.length_m
    for s_m in np.arange(0.0, s_end + 400.0, 20.0):
        pose = path.pose_at(min(float(s_m), s_end))
        ahead = max(float(s_m) - s_end, 0.0)
        e = pose.east_m + ahead * math.sin(pose.heading_rad)
        n = pose.north_m + ahead * math.cos(pose.heading_rad)
        lat, lon = team.frame.to_geodetic(e, n)
        t = t0 + float(s_m) / gs
        f = dataclasses.replace(
            fix(team, vid, 20_000.0, t, 25.0), lat_deg=float(lat), lon_deg=float(lon),
            ve_m_s=gs * math.sin(pose.heading_rad), vn_m_s=gs * math.cos(pose.heading_rad),
            heading_deg=math.degrees(pose.heading_rad), mission_seq=None,
        )  # fmt: skip
        said += reports(team.handle(f, t), EventKind.ARRIVED)
        if m.phase == "arrived":
            break
    assert len(said) == 1 and m.arrival_s == pytest.approx(t0 + s_end / gs, abs=1.0), said


def test_a_vehicle_that_reports_its_wind_keeps_the_last_report_until_the_next_one(
    team: TeamController,
) -> None:
    """UAV2 reports a wind of 6 m/s from the west (WIND): it is timed in it. Its first fixes
    after a reconnection (or a restart: the checkpoint keeps ``Member.wind``) carry no WIND
    yet, then one whose velocity less its airspeed on its heading says calm (a crab angle, a
    stale airspeed): it is still timed in the last report, not in still air, which made a
    vehicle in a tailwind look a minute late and moved the team time on one fix."""
    vid = "UAV2"
    m, t0 = flying(team, vid, 600.0)
    s0 = 30_000.0
    west = dataclasses.replace(
        fix(team, vid, s0, t0, 25.0), wind_speed_m_s=6.0, wind_from_deg=270.0
    )
    team.handle(west, t0)
    assert m.wind_reported and m.wind is not None
    told = m.wind
    assert math.hypot(told.to_east_m_s - 6.0, told.to_north_m_s) < 1.5  # the bias is young
    silent = dataclasses.replace(
        fix(team, vid, s0 + 500.0, t0 + 20.0, 25.0),
        wind_speed_m_s=None, wind_from_deg=None, airspeed_m_s=None,
    )  # fmt: skip
    team.handle(silent, t0 + 20.0)
    assert m.wind == told
    worked_out_calm = dataclasses.replace(
        fix(team, vid, s0 + 1_000.0, t0 + 40.0, 25.0), wind_speed_m_s=None, wind_from_deg=None
    )
    team.handle(worked_out_calm, t0 + 40.0)
    assert m.wind == told
    assert m.last_decision is not None and m.bias.used >= 0


def test_a_vehicle_that_never_reports_its_wind_is_timed_in_the_one_its_fixes_give(
    team: TeamController,
) -> None:
    """No WIND from UAV1 (as from an autopilot that sends none): a fix with no airspeed leaves
    it in the schedule's forecast; one with its velocity and airspeed gives the wind as
    velocity less airspeed on the heading."""
    vid = "UAV1"
    m, t0 = flying(team, vid, 600.0)
    bare = dataclasses.replace(
        fix(team, vid, 30_000.0, t0, 25.0),
        wind_speed_m_s=None, wind_from_deg=None, airspeed_m_s=None,
    )  # fmt: skip
    team.handle(bare, t0)
    assert m.wind is None and not m.wind_reported
    f = fix(team, vid, 30_500.0, t0 + 20.0, 25.0)
    push = dataclasses.replace(
        f,
        wind_speed_m_s=None,
        wind_from_deg=None,
        ve_m_s=f.ve_m_s + 3.0,  # 3 m/s east
    )
    team.handle(push, t0 + 20.0)
    assert m.wind is not None and not m.wind_reported
    assert m.wind.to_east_m_s == pytest.approx(3.0, abs=0.75)
    assert m.wind.to_north_m_s == pytest.approx(0.0, abs=0.75)


def test_a_late_vehicle_the_others_cannot_wait_for_is_released_from_its_slot_with_an_alarm(
    team: TeamController,
) -> None:
    """UAV1 is a minute from its goal on time, with no waypoint left to splice loiter turns
    after and only seconds of slack at its minimum speed; UAV2 falls far behind. Moving the
    team time to UAV2's earliest arrival would make UAV1 early whatever it did: the team time
    stays, UAV2 alone is released from its slot with an alarm naming UAV1, said once."""
    first = team.members["UAV1"]
    airborne(team, "UAV1", first.takeoff_s)
    for vid in ("UAV2", "UAV3"):
        airborne(team, vid, team.members[vid].takeoff_s)
    v_cruise = 25.0
    s_near = first.track.length_m - 1_500.0
    # On time at 25 m/s from 1.5 km out: the slot less the time to fly it.
    t_near = first.target_s - 1_500.0 / (v_cruise * first.schedule.tas_per_eas(s_near))
    team.handle(fix(team, "UAV1", s_near, t_near, v_cruise), t_near)
    assert first.last_decision is not None
    assert team.latest_arrival_s(first) < first.target_s + 120.0
    ref, version = team.team_ref_s, team.version
    late = team.members["UAV2"]
    out = team.handle(fix(team, "UAV2", 2_000.0, t_near + 1.0, 25.0), t_near + 1.0)
    assert team.team_ref_s == ref and team.version == version
    assert not reports(out, EventKind.ARRIVAL)
    (alarm,) = reports(out, EventKind.ALARM)
    assert alarm.vehicle == "UAV2" and "the team time stays" in alarm.reason
    assert "UAV1 (at most" in alarm.reason, alarm.reason
    assert late.late_said and late.target_s == pytest.approx(ref + late.offset_s)
    # Said once; the others keep their slots.
    again = team.handle(fix(team, "UAV2", 2_100.0, t_near + 5.0, 30.0), t_near + 5.0)
    assert not reports(again, EventKind.ALARM) and team.team_ref_s == ref
    assert first.target_s == pytest.approx(ref + first.offset_s)


def test_a_team_time_move_a_vehicle_on_its_final_approach_cannot_follow_is_not_made(
    team: TeamController,
) -> None:
    """UAV1 decided on time at 25 m/s 160 m from its goal (its minimum speed from there
    would let it arrive 1.5 s later), then flies into its final approach, where no speed
    is asked any more. UAV2 is found late by 1.2 s at its top speed: moving the team time
    so would leave UAV1 early by more than the tolerance as it flies (worked out here from
    its fix), so the team time stays, and UAV2 alone is released from its slot with an
    alarm naming UAV1."""
    first = team.members["UAV1"]
    for vid in ("UAV1", "UAV2", "UAV3"):
        airborne(team, vid, team.members[vid].takeoff_s)
    v = 25.0
    length = first.track.length_m
    tas = first.schedule.tas_per_eas(length)
    t_decided = first.target_s - 160.0 / (v * tas)
    team.handle(fix(team, "UAV1", length - 160.0, t_decided, v), t_decided)
    d = first.last_decision
    assert d is not None and d.eta_max_s > first.target_s + 1.4  # room by that decision
    t = first.target_s - 100.0 / (v * tas)
    team.handle(fix(team, "UAV1", length - 100.0, t, v), t)
    assert first.last_decision is d  # no decision on the final approach
    eta_first = t + 100.0 / (v * tas)  # as it flies: the test's own arithmetic
    ref, version = team.team_ref_s, team.version
    assert ref is not None
    late = team.members["UAV2"]
    v_max = late.limits.airspeed_max_m_s
    # UAV2 where its top speed brings it 1.2 s after its slot (still air, its route's TAS).
    rest = (late.target_s + 1.2 - t) * v_max * late.schedule.tas_per_eas(late.track.length_m)
    s_late = late.track.length_m - rest
    rest = (late.target_s + 1.2 - t) * v_max * late.schedule.tas_per_eas(s_late)
    out = team.handle(fix(team, "UAV2", late.track.length_m - rest, t, v_max), t)
    assert late.last_decision is not None and late.last_decision.verdict == "late"
    would_be = late.last_decision.eta_min_s - late.offset_s
    assert would_be + first.offset_s - eta_first > team.config.tolerance_s
    assert team.team_ref_s == ref and team.version == version
    assert not reports(out, EventKind.ARRIVAL)
    (alarm,) = reports(out, EventKind.ALARM)
    assert alarm.vehicle == "UAV2" and "the team time stays" in alarm.reason
    assert "UAV1 (at most" in alarm.reason, alarm.reason
    assert first.target_s == pytest.approx(ref + first.offset_s)


def _last_heard_200_s_ago(team: TeamController, vid: str) -> tuple[Member, float]:
    """``vid`` airborne and last heard 200 s before ``t0`` (600 s after its takeoff): its
    member and ``t0``."""
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    t0 = m.takeoff_s + 600.0
    m.last_fix_s = t0 - 200.0
    return m, t0


def test_a_vehicle_heard_again_after_a_gap_moves_the_team_time_only_once_settled(
    team: TeamController,
) -> None:
    """UAV2 was last heard 200 s ago (a link gap, or the coordinator restarted) and is far
    behind on its first fix: it is found late (and flies at its top speed), but the team time
    waits until its fixes have run ``resettle_s`` (its wind and airspeed estimates re-learn
    meanwhile); late still then, it moves the team time."""
    vid = "UAV2"
    m, t0 = _last_heard_200_s_ago(team, vid)
    ref = team.team_ref_s
    cfg = FlightConfig()
    v_max = m.limits.airspeed_max_m_s
    out = team.handle(fix(team, vid, 2_000.0, t0, 25.0), t0)
    assert m.heard_since_s == t0
    assert not reports(out, EventKind.ARRIVAL) and team.team_ref_s == ref
    assert m.last_decision is not None and m.last_decision.verdict == "late"
    moved_at = None
    for k in range(1, 20):
        t = t0 + 5.0 * k
        out = team.handle(fix(team, vid, 2_000.0 + 30.0 * 5.0 * k, t, v_max), t)
        if reports(out, EventKind.ARRIVAL):
            moved_at = t
            break
    assert moved_at is not None and moved_at - t0 >= cfg.resettle_s, moved_at
    assert team.team_ref_s is not None and ref is not None and team.team_ref_s > ref


def test_a_vehicle_heard_again_moves_the_team_time_only_once_its_earliest_arrival_holds(
    team: TeamController,
) -> None:
    """Heard again after a gap, UAV2 is late at its top speed, but the headwind it reports
    grows at every fix (its estimate re-learning): its earliest arrival drifts later, and
    the team time stays however long that lasts (past ``resettle_s``). Once the wind holds,
    two decisions agree (``resettle_drift``) and the team time moves, to the earliest it
    can make then."""
    vid = "UAV2"
    m, t0 = _last_heard_200_s_ago(team, vid)
    ref = team.team_ref_s
    cfg = FlightConfig()
    v_max = m.limits.airspeed_max_m_s

    flown_m = 2_000.0

    def headwind_fix(k: int, wind_m_s: float) -> act.Fix:
        """Fix ``k`` (5 s apart), into a headwind of ``wind_m_s`` (as it reports, and as it
        flies over the ground since the fix before)."""
        nonlocal flown_m
        at_max = fix(team, vid, flown_m, t0 + 5.0 * k, v_max)
        assert at_max.groundspeed_m_s is not None and at_max.heading_deg is not None
        gs = at_max.groundspeed_m_s - wind_m_s
        h = math.radians(at_max.heading_deg)
        out = dataclasses.replace(
            at_max,
            groundspeed_m_s=gs,
            ve_m_s=gs * math.sin(h),
            vn_m_s=gs * math.cos(h),
            wind_speed_m_s=wind_m_s,
            wind_from_deg=at_max.heading_deg % 360.0,
        )
        flown_m += 5.0 * gs
        return out

    etas = []
    for k in range(40):  # 200 s, more than three times resettle_s
        out = team.handle(headwind_fix(k, 0.1 * k), t0 + 5.0 * k)
        assert not reports(out, EventKind.ARRIVAL) and team.team_ref_s == ref, k
        if m.last_decision is not None and m.eta_min_seen[-1][0] == t0 + 5.0 * k:
            etas.append(m.last_decision.eta_min_s)
    assert m.last_decision is not None and m.last_decision.verdict == "late"
    assert 3 * cfg.resettle_s < 5.0 * 40 and len(etas) > 10
    assert min(b - a for a, b in itertools.pairwise(etas)) > cfg.tolerance_s
    moved = None
    for k in range(40, 60):
        out = team.handle(headwind_fix(k, 4.0), t0 + 5.0 * k)
        if reports(out, EventKind.ARRIVAL):
            moved = k
            break
    assert moved is not None and moved <= 40 + 2 * 2, moved  # two decisions, 10 s apart at most
    assert team.team_ref_s is not None and ref is not None and team.team_ref_s > ref
    assert m.last_decision.eta_min_s < team.team_ref_s + m.offset_s


def test_the_operator_cannot_move_the_team_time_later_than_a_vehicle_can_wait(
    team: TeamController,
) -> None:
    """UAV1 is a minute from its goal with no loiter turns left to splice in: the operator's
    later team time is refused naming UAV1 and the latest it can make (its ETA at its minimum
    speed, less its offset); a move within that is taken."""
    first = team.members["UAV1"]
    for vid in ("UAV1", "UAV2", "UAV3"):
        airborne(team, vid, team.members[vid].takeoff_s)
    s_near = first.track.length_m - 1_500.0
    t_near = first.target_s - 1_500.0 / (25.0 * first.schedule.tas_per_eas(s_near))
    team.handle(fix(team, "UAV1", s_near, t_near, 25.0), t_near)
    ref = team.team_ref_s
    assert ref is not None and first.last_decision is not None
    latest = first.last_decision.eta_max_s - first.offset_s
    assert ref < latest < ref + 120.0
    with pytest.raises(TeamTimeRefused) as refused:
        team.move_team_time(ref + 300.0, t_near)
    assert refused.value.vehicle_id == "UAV1" and refused.value.earliest_s is None
    assert refused.value.latest_s == pytest.approx(latest)
    assert "latest feasible" in str(refused.value) and team.team_ref_s == ref
    within = ref + 0.5 * (latest - ref)
    team.move_team_time(within, t_near)
    assert team.team_ref_s == within


def test_windows_the_ground_vehicles_are_re_timed_in_the_wind_measured_aloft(
    windows_team_parts: tuple[Scenario, World, Schedule],
) -> None:
    """Arrival windows (no team time moves to re-time the takeoffs): one vehicle aloft says
    it flies in 10 m/s; at the next tick those still on the ground (none armed yet) take off
    for their slots in that wind, not the schedule's calm, within ``TAKEOFF_RECHECK_S``; and
    not again while it holds."""
    scenario, world, schedule = windows_team_parts
    team = TeamController(scenario, schedule, world, FlightConfig(), rng=np.random.default_rng(3))
    team.start(START_UTC)
    first = min(team.members.values(), key=lambda x: x.takeoff_s)
    airborne(team, first.vehicle_id, first.takeoff_s)
    ground = [x for x in team.members.values() if x.phase == "ground" and not x.arm_sent]
    assert ground
    g = ground[0]
    start, end = g.schedule.path.pose_at(0.0), g.schedule.path.pose_at(g.schedule.path.length_m)
    to_deg = math.degrees(math.atan2(end.east_m - start.east_m, end.north_m - start.north_m))
    wind_to = (10.0 * math.sin(math.radians(to_deg)), 10.0 * math.cos(math.radians(to_deg)))
    t0 = first.takeoff_s + 120.0
    heard = dataclasses.replace(
        fix(team, first.vehicle_id, 1_000.0, t0, 25.0),
        wind_speed_m_s=10.0,
        wind_from_deg=(to_deg + 180) % 360,
    )
    team.handle(heard, t0)
    out = team.handle(act.Tick(), t0 + TAKEOFF_RECHECK_S)
    (retimed,) = [r for r in reports(out, EventKind.TAKEOFF) if r.vehicle == g.vehicle_id]
    want_s = _takeoff_in_wind_s(team, g.vehicle_id, wind_to)
    assert retimed.value == pytest.approx(want_s, abs=10.0)
    assert g.takeoff_s == pytest.approx(retimed.value, abs=1e-3)
    calm_s = _takeoff_in_wind_s(team, g.vehicle_id, (0.0, 0.0))
    assert abs(retimed.value - calm_s) > 60.0, (retimed.value, calm_s)
    again = team.handle(act.Tick(), t0 + 2 * TAKEOFF_RECHECK_S)
    assert not [r for r in reports(again, EventKind.TAKEOFF) if r.vehicle == g.vehicle_id]


# -- waves -----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def waves_team_parts(
    paper: tuple[Scenario, World, Schedule],
) -> tuple[Scenario, World, Schedule]:
    arrival = {"kind": "waves", "gap_s": 120.0, "groups": [["UAV1", "UAV2"], ["UAV3"]]}
    return _paper_arriving(paper, arrival)


def test_waves_a_late_vehicle_moves_its_own_wave_and_not_the_one_before(
    waves_team_parts: tuple[Scenario, World, Schedule],
) -> None:
    """Two waves 120 s apart: UAV3, alone in the second, is found far behind. Its wave's slot
    moves to its earliest at top speed plus the margin (the test's own still-air arithmetic,
    within what one ratio of true airspeed leaves), the first wave keeps its slot (UAV1 and
    UAV2 together), and the event names the slots that moved. Then UAV1, in the first wave,
    is found late: its whole wave moves, and the second wave only as far as the gap needs."""
    scenario, world, schedule = waves_team_parts
    team = TeamController(scenario, schedule, world, FlightConfig(), rng=np.random.default_rng(3))
    team.start(START_UTC)
    slots = {v: m.target_s for v, m in team.members.items()}
    assert slots["UAV1"] == slots["UAV2"] == pytest.approx(slots["UAV3"] - 120.0)
    m3 = team.members["UAV3"]
    out, t3, earliest = _found_behind(team, "UAV3", 2_000.0, 150.0)
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert moved.vehicle == "UAV3" and "from place 2 on" in moved.reason
    assert set(moved.payload["slots"]) == {"UAV3"}
    assert m3.target_s == pytest.approx(earliest + FlightConfig().late_margin_s, abs=25.0)
    assert m3.target_s > slots["UAV3"] + 100.0
    assert team.members["UAV1"].target_s == team.members["UAV2"].target_s == slots["UAV1"]
    assert team.team_ref_s == slots["UAV1"]
    # UAV1 late by 30 s: the first wave moves as one; the second stays, 120 s after it at
    # least already.
    m1 = team.members["UAV1"]
    airborne(team, "UAV1", m1.takeoff_s)
    length, v1_max = m1.track.length_m, m1.limits.airspeed_max_m_s
    t1 = t3 + 10.0
    s1 = length - (m1.target_s + 30.0 - t1) * v1_max * m1.schedule.tas_per_eas(length)
    s1 = length - (m1.target_s + 30.0 - t1) * v1_max * m1.schedule.tas_per_eas(s1)
    out = team.handle(fix(team, "UAV1", s1, t1, 25.0), t1)
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert set(moved.payload["slots"]) == {"UAV1", "UAV2"}, moved
    first = team.members["UAV1"].target_s
    assert team.members["UAV2"].target_s == first and first > slots["UAV1"] + 20.0
    assert m3.target_s >= first + 120.0 - 1e-6

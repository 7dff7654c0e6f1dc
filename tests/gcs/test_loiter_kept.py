"""Loiter turns at the waypoint a new mission is spliced after are flown: the splice keeps
the NAV_LOITER_TURNS that follows that waypoint in the new mission (pure splice, and the team
controller re-timing a vehicle for a pop-up it does not cross)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from gcs.coordination import actions as act
from gcs.coordination.config import FlightConfig
from gcs.coordination.team import TeamController
from planner.mission import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_LOITER_TURNS,
    MAV_CMD_NAV_WAYPOINT,
    MissionItem,
)
from planner.plan import World
from planner.popup import popup_zones
from planner.retime import retime_vehicle
from planner.scenario import Scenario
from planner.schedule import Schedule
from planner.schedulefile import PathMission, path_mission, splice_mission
from planner.threats import active, build_threats
from tests.gcs.test_team import START_UTC, airborne, fix, of

CONFIG = FlightConfig()


def _flown_after(pm: PathMission, k: int) -> list[tuple[MissionItem, float | None]]:
    """The NAV items after item ``k``, each with the airspeed (m/s) in force on it: the last
    DO_CHANGE_SPEED before it after ``k``, else None (the one in force at ``k``)."""
    out: list[tuple[MissionItem, float | None]] = []
    speed_m_s: float | None = None
    for it in pm.items[k + 1 :]:
        if it.command == MAV_CMD_DO_CHANGE_SPEED:
            speed_m_s = it.param2
        else:
            out.append((replace(it, seq=0), speed_m_s))
    return out


def _loiter_waypoints(pm: PathMission) -> list[int]:
    """The route waypoints a NAV_LOITER_TURNS follows."""
    return [
        k
        for k in range(pm.first_route_seq, len(pm.items) - 1)
        if pm.items[k].command == MAV_CMD_NAV_WAYPOINT
        and pm.items[k + 1].command == MAV_CMD_NAV_LOITER_TURNS
    ]


def _speed_at(pm: PathMission, k: int) -> float | None:
    """The airspeed (m/s) of the last DO_CHANGE_SPEED at or before item ``k``."""
    speeds = [it.param2 for it in pm.items[: k + 1] if it.command == MAV_CMD_DO_CHANGE_SPEED]
    return speeds[-1] if speeds else None


def test_a_splice_after_any_waypoint_flies_the_new_mission_from_it_loiters_included(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    """Re-timed on its own path (as a pop-up re-times a vehicle it does not touch), with loiter
    turns on board: spliced after any waypoint, the vehicle flies from there the new mission's
    route, loiters and speeds, a loiter at the kept waypoint itself included."""
    _, world, schedule = paper
    vs = schedule.vehicle("UAV3")
    early, _ = retime_vehicle(
        schedule,
        "UAV3",
        now_s=1000.0,
        s_m=20_000.0,
        speed_m_s=16.0,
        target_s=vs.arrival_s + 400.0,
        threats=active(world.threats, 1000.0),
        loiter_margin_m_s=1.0,
    )
    assert early.loiters
    pm = path_mission(
        schedule,
        early,
        world.terrain,
        runout_m=CONFIG.runout_m,
        max_spacing_m=CONFIG.waypoint_spacing_m,
    )
    at_loiter = _loiter_waypoints(pm)
    assert at_loiter
    keeps = [
        k
        for k in range(pm.first_route_seq, len(pm.items) - 1)
        if pm.items[k].command == MAV_CMD_NAV_WAYPOINT
    ]
    for keep in keeps:
        spliced = splice_mission(pm, keep, pm)
        assert spliced.items[: keep + 1] == pm.items[: keep + 1], keep
        flown = _flown_after(spliced, keep)
        expected = _flown_after(pm, keep)
        # The speed in force from the kept waypoint on is the new mission's there.
        expected = [(it, _speed_at(pm, keep) if v is None else v) for it, v in expected]
        assert flown == expected, keep
    for keep in at_loiter:
        spliced = splice_mission(pm, keep, pm)
        (loiter,) = [
            it
            for it in spliced.items[keep + 1 : keep + 3]
            if it.command == MAV_CMD_NAV_LOITER_TURNS
        ]
        assert replace(loiter, seq=0) == replace(pm.items[keep + 1], seq=0)


def test_a_vehicle_re_timed_for_a_pop_up_keeps_the_loiter_at_its_splice_waypoint(
    paper: tuple[Scenario, World, Schedule],
) -> None:
    """An early vehicle has loiter turns on board; a pop-up it does not cross appears and it
    is re-timed from the waypoint the turns follow: the uploaded mission still has them (the
    controller counts them in its arrival time, so a vehicle without them arrives early)."""
    scenario, world, schedule = paper
    team = TeamController(scenario, schedule, world, CONFIG, rng=np.random.default_rng(3))
    team.start(START_UTC)
    vid = "UAV3"
    m = team.members[vid]
    airborne(team, vid, m.takeoff_s)
    t0, s0 = m.takeoff_s + 300.0, 5_000.0
    assert team.team_ref_s is not None
    team.move_team_time(team.team_ref_s + 900.0, t0)
    (job,) = [a.job for a in of(team.handle(fix(team, vid, s0, t0, 20.0), t0), act.Compute)]
    assert isinstance(job, act.LoiterJob)
    (up,) = of(team.handle(act.Computed(job, job.run()), t0 + 1.0), act.Upload)
    team.handle(act.Installed(up), t0 + 2.0)
    (k_lo,) = [k for k in _loiter_waypoints(m.mission) if (m.mission.item_s_m[k] or 0.0) > s0]
    s_lo = m.mission.item_s_m[k_lo]
    assert s_lo is not None
    turns = m.mission.items[k_lo + 1].param1

    zones = build_threats(team.scenario, {v: x.takeoff_s for v, x in team.members.items()})
    (zone,) = popup_zones(zones)
    t_p = float(zone.appears_at_s or 0.0)
    for v, x in team.members.items():
        airborne(team, v, x.takeoff_s)
    # UAV3 2 km short of the loiter's waypoint when the threat appears; the re-plan's lead
    # reaches just that waypoint, so the new mission is spliced after it.
    s1, gs = s_lo - 2_000.0, 17.0
    team.handle(fix(team, vid, s1, t_p - 1.0, gs / m.schedule.tas_per_eas(s1)), t_p - 1.0)
    m.next_decision_s = math.inf
    team.lead_s = (2_000.0 - 0.5) / gs
    (pj,) = [a.job for a in of(team.handle(act.Tick(), t_p), act.Compute)]
    assert isinstance(pj, act.PopupJob)
    assert pj.keeps[vid] == k_lo
    outcome = pj.run()
    assert vid not in outcome.affected
    ups = of(team.handle(act.Computed(pj, outcome), t_p + 1.0), act.Upload)
    (retimed,) = [u for u in ups if u.vehicle_id == vid]
    assert retimed.keep_seq == k_lo
    # The re-timed schedule keeps the turns at that waypoint ...
    planned = [lo for lo in retimed.schedule.loiters if abs(lo.s_m - s_lo) <= 1.0]
    assert [lo.turns for lo in planned] == [turns]
    # ... and so does the mission that goes up: right after the kept waypoint (and the speed
    # it flies them at).
    after = [it.command for it in retimed.mission.items[k_lo + 1 : k_lo + 3]]
    assert MAV_CMD_NAV_LOITER_TURNS in after, after
    loiter = next(
        it for it in retimed.mission.items[k_lo + 1 :] if it.command == MAV_CMD_NAV_LOITER_TURNS
    )
    assert loiter.param1 == pytest.approx(turns)
    team.handle(act.Installed(retimed), t_p + 2.0)
    assert len(m.track.loiters) == sum(
        1 for it in m.mission.items if it.command == MAV_CMD_NAV_LOITER_TURNS
    )

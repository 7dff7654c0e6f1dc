"""The team controller with landing slots, on its own (mission seconds passed in, fixes made
from the planned routes): airborne vehicles are put in AUTO without arming, a vehicle past its
slot fix is watched until it is down, each landing is said with its order and place on the
runway, and a vehicle not down in time ends the flight as failed with an alarm."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs.coordination import actions as act
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind
from gcs.coordination.member import VehicleState
from gcs.coordination.team import TeamController
from planner.plan import build_world, plan
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from tests.gcs.test_team import START_UTC, of, reports
from tests.teams import landing_scenario


@pytest.fixture(scope="module")
def parts():  # type: ignore[no-untyped-def]
    doc, _ = landing_scenario(0)
    scenario = parse_scenario(doc)
    world = build_world(scenario)
    schedule = build_schedule(scenario, plan(scenario, world=world), world=world)
    return doc, scenario, world, schedule


@pytest.fixture
def team(parts) -> TeamController:  # type: ignore[no-untyped-def]
    _, scenario, world, schedule = parts
    t = TeamController(scenario, schedule, world, FlightConfig(), rng=np.random.default_rng(1))
    t.start(START_UTC)
    return t


def _fix_en(team: TeamController, vid: str, e: float, n: float, t_s: float, seq: int) -> act.Fix:
    lat, lon = team.frame.to_geodetic(e, n)
    m = team.members[vid]
    return act.Fix(
        vid,
        START_UTC + t_s,
        float(lat),
        float(lon),
        alt_amsl_m=float(m.schedule.alt_at(m.schedule.path.length_m)),
        airspeed_m_s=20.0,
        groundspeed_m_s=20.0,
        heading_deg=0.0,
        ve_m_s=0.0,
        vn_m_s=20.0,
        climb_m_s=0.0,
        mission_seq=seq,
        wind_speed_m_s=0.0,
        wind_from_deg=0.0,
    )


def _through_the_fix(team: TeamController, vid: str, t_s: float) -> float:
    """Fly ``vid`` along its final and past its fix, 2 s a fix at 20 m/s; the time after."""
    m = team.members[vid]
    path = m.schedule.path
    last = len(m.mission.items) - 1
    for k in range(-10, 11):
        p = path.pose_at(path.length_m + 40.0 * min(k, 0))
        c = math.radians(team.scenario.landing.heading_deg)  # type: ignore[union-attr]
        ahead = 40.0 * max(k, 0)
        e, n = p.east_m + ahead * math.sin(c), p.north_m + ahead * math.cos(c)
        team.handle(_fix_en(team, vid, e, n, t_s, last), t_s)
        t_s += 2.0
    return t_s


def test_airborne_vehicles_are_put_in_auto_without_arming_at_the_start(
    team: TeamController,
) -> None:
    out = team.handle(act.Tick(), 0.0)
    launches = of(out, act.Launch)
    assert {a.vehicle_id for a in launches} == set(team.members)
    assert all(a.airborne for a in launches)
    vid = launches[0].vehicle_id
    (said,) = reports(team.handle(act.Launched(vid), 0.5), EventKind.LAUNCH)
    assert "taken over in the air" in said.reason and "armed" not in said.reason
    # Its route is item 1 on: the first fix in AUTO there puts it on its route.
    m = team.members[vid]
    assert m.mission.first_route_seq == 1
    team.handle(_fix_en(team, vid, m.schedule.path.start.east_m, m.schedule.path.start.north_m,
                        2.0, 1), 2.0)  # fmt: skip
    assert m.phase == "route"


def test_past_its_fix_a_vehicle_is_watched_until_down_and_each_landing_is_said_in_order(
    team: TeamController,
) -> None:
    team.handle(act.Tick(), 0.0)
    for vid in team.members:
        team.handle(act.Launched(vid), 0.0)
    order = list(team.scenario.arrival.order)  # type: ignore[union-attr]
    t = 100.0
    for vid in order[:2]:
        t = _through_the_fix(team, vid, t)
        m = team.members[vid]
        assert m.phase == "arrived" and m.landing_due and not m.over
        assert m.state is VehicleState.LANDING
    assert not team.finished
    # Down and disarmed: second first, then the first.
    td = team.scenario.landing.touchdown  # type: ignore[union-attr]
    for k, vid in enumerate(reversed(order[:2]), start=1):
        team.handle(_fix_en(team, vid, td.east_m + 300.0 * k, td.north_m, t, 9), t)
        out = team.handle(act.Heartbeat(vid, armed=False, emergency=False), t + 1.0)
        (landed,) = reports(out, EventKind.LANDED)
        assert landed.payload["order"] == k and landed.vehicle == vid
        m = team.members[vid]
        assert m.over and m.state is VehicleState.LANDED and m.landed_s == t + 1.0
        assert m.landed_en_m is not None
        t += 10.0
    assert not team.finished  # the other two have not arrived


def test_a_vehicle_not_down_in_time_is_an_alarm_and_ends_the_flight(team: TeamController) -> None:
    team.handle(act.Tick(), 0.0)
    for vid in team.members:
        team.handle(act.Launched(vid), 0.0)
    vid = team.scenario.arrival.order[0]  # type: ignore[union-attr]
    t = _through_the_fix(team, vid, 100.0)
    m = team.members[vid]
    assert m.arrival_s is not None
    bound = team.landing_bound_s(m)
    # Its own glide at its slowest airspeed, twice over, and a margin: recomputed here.
    td = team.scenario.landing.touchdown  # type: ignore[union-attr]
    glide_m = math.hypot(td.east_m - m.goal_en_m[0], td.north_m - m.goal_en_m[1])
    assert bound == pytest.approx(2 * glide_m / m.limits.airspeed_min_m_s + 120.0)
    assert of(team.handle(act.Tick(), m.arrival_s + bound - 1.0), act.Stop) == []
    out = team.handle(act.Tick(), m.arrival_s + bound + 1.0)
    (alarm,) = [r for r in reports(out, EventKind.ALARM) if r.vehicle == vid]
    assert "has not landed" in alarm.reason
    (stop,) = of(out, act.Stop)
    assert stop.reason == f"not landed: {vid}" and team.finished
    del t


def test_a_crash_while_gliding_loses_the_vehicle(team: TeamController) -> None:
    team.handle(act.Tick(), 0.0)
    for vid in team.members:
        team.handle(act.Launched(vid), 0.0)
    vid = team.scenario.arrival.order[0]  # type: ignore[union-attr]
    t = _through_the_fix(team, vid, 100.0)
    out = team.handle(act.Heartbeat(vid, armed=True, emergency=True), t)
    (lost,) = reports(out, EventKind.VEHICLE_LOST)
    m = team.members[vid]
    assert "while landing" in lost.reason and m.phase == "lost" and m.over

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
from tests.gcs.test_team import START_UTC, fix, of, reports, still_air_eta_s
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


def _on_time_at(team: TeamController, vid: str, to_go_s: float, t: float) -> float:
    """A fix of ``vid`` where 20 m/s (still air, its route's true airspeed) brings it to
    its goal in ``to_go_s``, handled at ``t``: how far along it is (m)."""
    m = team.members[vid]
    length = m.track.length_m
    s_m = length - to_go_s * 20.0 * m.schedule.tas_per_eas(length)
    team.handle(fix(team, vid, s_m, t, 20.0), t)
    assert m.phase == "route" and m.last_decision is not None
    assert m.last_decision.verdict == "on_time", m.last_decision.reason
    return s_m


def _all_launched(team: TeamController) -> list[str]:
    team.handle(act.Tick(), 0.0)
    for vid in team.members:
        team.handle(act.Launched(vid), 0.0)
    return list(team.scenario.arrival.order)  # type: ignore[union-attr]


def test_a_late_vehicle_moves_its_own_slot_and_those_after_it_but_not_the_one_ahead(
    team: TeamController,
) -> None:
    """Landing slots 90 s apart. G0 is on its final approach (no speed asked there: it
    cannot follow any move) when G1 is found late by 30 s even at its top speed. Moving the
    whole team time would leave G0 early, and G1 would be released; instead G1's slot moves
    to its earliest arrival plus the margin and each slot after it keeps the 90 s after the
    one before, while G0 keeps its own (every figure recomputed here from the fixes)."""
    g0, g1, g2, g3 = (team.members[v] for v in _all_launched(team))
    cfg = FlightConfig()
    slots = {m.vehicle_id: m.target_s for m in (g0, g1, g2, g3)}
    assert slots["G1"] - slots["G0"] == pytest.approx(90.0)
    t = g0.target_s - 5.0
    # G0 100 m from its fix at 20 m/s: on its final approach (within final_m).
    team.handle(fix(team, "G0", g0.track.length_m - 100.0, t, 20.0), t)
    assert g0.on_final(cfg.final_m)
    for vid, m in (("G2", g2), ("G3", g3)):
        _on_time_at(team, vid, m.target_s - t, t)
    ref, version = team.team_ref_s, team.version
    v_max = g1.limits.airspeed_max_m_s
    length = g1.track.length_m
    # Where its top speed brings it 30 s after its slot (still air, its route's TAS).
    s_late = length - (g1.target_s + 30.0 - t) * v_max * g1.schedule.tas_per_eas(length)
    earliest = still_air_eta_s(team, "G1", s_late, t, v_max)
    assert earliest > g1.target_s + 25.0
    # The whole team time moved so would make G0 early as it flies: the old rule's refusal.
    assert team._cannot_follow(earliest - g1.offset_s, ("G1",))[0][0] == "G0"
    out = team.handle(fix(team, "G1", s_late, t, 25.0), t)
    assert not reports(out, EventKind.ALARM) and not g1.late_said
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert moved.vehicle == "G1" and "G1 cannot arrive before" in moved.reason
    margin = min(cfg.late_margin_s, 0.02 * (earliest - t))
    assert g1.target_s == pytest.approx(earliest + margin, abs=1.0)
    assert g2.target_s == pytest.approx(max(slots["G2"], g1.target_s + 90.0))
    assert g3.target_s == pytest.approx(max(slots["G3"], g2.target_s + 90.0))
    assert g0.target_s == slots["G0"]  # ahead: it keeps its slot
    assert moved.payload["slots"] == {
        v: pytest.approx(team.members[v].target_s, abs=1e-3) for v in ("G1", "G2", "G3")
    }
    # The team time is the first slot's, still G0's; each offset follows its slot.
    assert team.team_ref_s == ref and team.version == version + 1
    for m in (g0, g1, g2, g3):
        assert m.target_s == pytest.approx(ref + m.offset_s)


def test_a_late_vehicle_the_slots_after_it_cannot_wait_for_takes_a_later_place(
    team: TeamController,
) -> None:
    """G1 is found far behind; G2, 4 km from its fix with no loiter turns left to splice
    in, cannot arrive as late as a slot 90 s after G1's new one, but at its top speed it
    makes G1's slot. G1 takes G2's place in the order (or the earliest after it it can
    make), G2 takes G1's slot, G3 is moved on to keep its 90 s after G1, and G0, ahead,
    keeps its slot."""
    g0, g1, g2, g3 = (team.members[v] for v in _all_launched(team))
    slots = {m.vehicle_id: m.target_s for m in (g0, g1, g2, g3)}
    tas = g2.schedule.tas_per_eas(g2.track.length_m)
    rest_m = 4_000.0
    t = g2.target_s - rest_m / (16.3 * tas)  # on time at 16.3 m/s
    team.handle(fix(team, "G2", g2.track.length_m - rest_m, t, 16.3), t)
    assert g2.last_decision is not None and g2.last_decision.verdict == "on_time"
    _on_time_at(team, "G3", g3.target_s - t, t)
    g2_latest = team.latest_arrival_s(g2)
    g2_earliest = still_air_eta_s(team, "G2", g2.track.length_m - rest_m, t, 28.0)
    assert g2_earliest <= slots["G1"] and math.isfinite(g2_latest)
    s_late = g1.track.length_m - 8_000.0
    earliest = still_air_eta_s(team, "G1", s_late, t, g1.limits.airspeed_max_m_s)
    assert earliest + 90.0 > g2_latest + 1.0  # G2 could not follow the slots pushed on
    out = team.handle(fix(team, "G1", s_late, t, 25.0), t)
    assert not reports(out, EventKind.ALARM) and not g1.late_said
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert "G1 takes place 3 in the order, after G2" in moved.reason, moved.reason
    assert "G2 (at most" in moved.reason
    assert g2.target_s == slots["G1"]  # one place earlier
    assert g1.target_s == pytest.approx(max(slots["G2"], earliest + 2.0), abs=1.0)
    assert g3.target_s == pytest.approx(max(slots["G3"], g1.target_s + 90.0))
    assert g0.target_s == slots["G0"]
    order = sorted(team.members.values(), key=lambda m: m.target_s)
    assert [m.vehicle_id for m in order] == ["G0", "G2", "G1", "G3"]


def test_a_late_vehicle_that_no_later_place_serves_is_released_alone_with_an_alarm(
    team: TeamController,
) -> None:
    """As before, but G2 could not make G1's slot either (on time at 20 m/s, 1.5 km out,
    no turns left): G1 alone is released from its slot with an alarm naming G2, and every
    slot stays."""
    g0, g1, g2, g3 = (team.members[v] for v in _all_launched(team))
    slots = {m.vehicle_id: m.target_s for m in (g0, g1, g2, g3)}
    t = g2.target_s - 75.0
    _on_time_at(team, "G2", 75.0, t)
    _on_time_at(team, "G3", g3.target_s - t, t)
    assert math.isfinite(team.latest_arrival_s(g2))
    version = team.version
    s_late = g1.track.length_m - 8_000.0
    out = team.handle(fix(team, "G1", s_late, t, 25.0), t)
    assert not reports(out, EventKind.ARRIVAL) and team.version == version
    (alarm,) = reports(out, EventKind.ALARM)
    assert alarm.vehicle == "G1" and "its slot stays" in alarm.reason
    assert "G2 (at most" in alarm.reason, alarm.reason
    assert g1.late_said
    assert {m.vehicle_id: m.target_s for m in (g0, g1, g2, g3)} == slots

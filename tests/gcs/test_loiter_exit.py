"""A vehicle in its loiter turns that the rest of them would make late is taken out of them
(MISSION_SET_CURRENT to the item after the NAV_LOITER_TURNS) once leaving would not make it
early, and the coordinator counts the turns as flown from then on. Through
:meth:`TeamController.handle` with a fake clock, as in ``test_team.py``."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import pytest

from gcs.coordination import actions as act
from gcs.coordination.events import EventKind
from gcs.coordination.member import Member
from gcs.coordination.replanning import MissionChanges
from gcs.coordination.routetrack import LoiterSpec
from gcs.coordination.team import TeamController
from planner.mission import MAV_CMD_NAV_LOITER_TURNS
from tests.gcs.test_team import _early, fix, of, on_loiter_circle, reports
from tests.planner.test_loiterflight import _flown_out_m

SETTLED = 40
"""Fixes round the circle (2 s apart) before a test's own."""


def _turns_installed(team: TeamController, vid: str) -> tuple[Member, LoiterSpec, int, float]:
    """``vid`` early, given loiter turns (installed): the member, its loiter, the loiter's
    item and the mission time the turns were worked out at."""
    m = team.members[vid]
    t0, _, job = _early(team, vid)
    (up,) = of(team.handle(act.Computed(job, job.run()), t0 + 1), act.Upload)
    team.handle(act.Installed(up), t0 + 2)
    if m.busy_command:
        team.handle(act.SpeedCommanded(vid, 15.0, "early", t0), t0 + 2)
    (lo,) = [x for x in m.track.loiters if x.s_m > job.s_m - 1.0]
    k = next(k for k, it in enumerate(m.mission.items) if it.command == MAV_CMD_NAV_LOITER_TURNS)
    return m, lo, k, t0


def _in_turns(
    team: TeamController, vid: str
) -> tuple[Member, LoiterSpec, int, float, Callable[[int], act.Fix]]:
    """``vid`` given loiter turns (installed) and flying them from ``t1``, settled: the
    member, its loiter, the loiter's item, ``t1`` and fix ``i`` (at ``t1 + 2 i``) round the
    circle; fixes up to :data:`SETTLED` have been handled."""
    m, lo, k, t0 = _turns_installed(team, vid)
    t1 = t0 + 600.0
    base = dataclasses.replace(fix(team, vid, lo.s_m, t1, 20.0), mission_seq=k)
    for c in of(team.handle(base, t1), act.CommandSpeed):
        team.handle(act.SpeedCommanded(vid, c.airspeed_m_s, c.reason, c.decided_s), t1)
    assert m.in_loiter()

    def on_circle(i: int) -> act.Fix:
        return on_loiter_circle(team, base, lo, i)

    # Settled in them: the test's leap to t1 stands for fixes all along, no gap (its
    # lateness moves the team time at once).
    m.heard_since_s = -math.inf
    for i in range(1, SETTLED + 1):
        _answered(team, vid, team.handle(on_circle(i), t1 + 2.0 * i), t1 + 2.0 * i)
    return m, lo, k, t1, on_circle


def _answered(team: TeamController, vid: str, out: list[act.Action], t: float) -> None:
    for c in of(out, act.CommandSpeed):
        team.handle(act.SpeedCommanded(vid, c.airspeed_m_s, c.reason, c.decided_s), t)


def _retarget(team: TeamController, ref_s: float) -> None:
    """The team time (and every slot) moved to ``ref_s``, decided again at the next fix."""
    for x in team.members.values():
        x.target_s = ref_s + x.offset_s
        x.next_decision_s = -math.inf
    team.team_ref_s = ref_s


def test_turns_that_would_make_it_late_are_left_once_leaving_is_on_time(
    team: TeamController,
) -> None:
    """The team time comes too soon for the turns left even at top speed, yet leaving at
    once would make the vehicle early even at its minimum speed: it stays in the turns,
    flying the minimum, and the team time stays. As the turns go on, leaving comes on time:
    then the item after the loiter is made current and it is said, the team time still
    where it was."""
    vid = "UAV3"
    m, lo, k, t1, on_circle = _in_turns(team, vid)
    i = SETTLED + 1
    t = t1 + 2.0 * i
    # The route after the loiter at the speed range's ends, and the turns left at the top
    # speed, worked out here in still air at the route's true airspeed per equivalent there.
    ratio = m.schedule.tas_per_eas(lo.s_m)
    v_min = m.limits.airspeed_min_m_s * ratio
    v_max = m.limits.airspeed_max_m_s * ratio
    route_m = m.track.length_m - lo.s_m
    turns_left_m = lo.length_m - i * 2.0 * m.groundspeed_m_s
    # Late by 60 s with the turns at top speed; early by more than 60 s leaving now at the
    # minimum (the turns left are long enough for both).
    ref = t + (turns_left_m + route_m) / v_max - 60.0 - m.offset_s
    assert t + route_m / v_min < ref + m.offset_s - 60.0
    _retarget(team, ref)
    out = team.handle(on_circle(i), t)
    assert of(out, act.LeaveLoiter) == [] and reports(out, EventKind.ARRIVAL) == []
    assert team.team_ref_s == ref and m.in_loiter()
    # Timed for the route after the turns: its minimum airspeed.
    d = m.last_decision
    assert d is not None and d.verdict == "early" and d.level_m_s == m.limits.airspeed_min_m_s
    _answered(team, vid, out, t)
    # On round the circle, deciding at each fix: out of the turns once leaving is not early.
    left: list[act.LeaveLoiter] = []
    while not left and i < 400:
        i += 1
        t = t1 + 2.0 * i
        m.next_decision_s = -math.inf
        out = team.handle(on_circle(i), t)
        _answered(team, vid, out, t)
        assert reports(out, EventKind.ARRIVAL) == []
        left = of(out, act.LeaveLoiter)
    (leave,) = left
    assert leave.vehicle_id == vid and leave.seq == k + 1
    (said,) = [r for r in reports(out, EventKind.LOITER) if r.payload["action"] == "leave"]
    assert said.payload["seq"] == k + 1 and "out of the turns" in said.reason
    # Leaving now is on time: from where it is, the route at the speed range's ends
    # brackets the slot (the located point is within a loiter diameter of the entry).
    d = m.last_decision
    assert d is not None and d.verdict == "on_time"
    assert team.team_ref_s == ref
    # While the command is on its way nothing more is asked.
    m.next_decision_s = -math.inf
    assert of(team.handle(on_circle(i + 1), t + 2.0), act.LeaveLoiter) == []
    out = team.handle(act.LoiterLeft(leave), t + 3.0)
    assert [r.payload["action"] for r in reports(out, EventKind.LOITER)] == ["left"]
    assert not m.in_loiter() and m.leaving_seq is None
    assert m.loiters_done() == sum(
        1 for it in m.mission.items[: k + 1] if it.command == MAV_CMD_NAV_LOITER_TURNS
    )


def test_a_vehicle_not_taken_out_of_its_turns_says_so_and_is_asked_again(
    team: TeamController,
) -> None:
    vid = "UAV3"
    m, _, k, t1, on_circle = _in_turns(team, vid)
    i = SETTLED + 1
    t = t1 + 2.0 * i
    _retarget(team, t + 30.0)  # far too soon for anything: out of the turns at once
    (leave,) = of(team.handle(on_circle(i), t), act.LeaveLoiter)
    out = team.handle(act.LoiterLeft(leave, "MISSION_SET_CURRENT timed out"), t + 1.0)
    (said,) = reports(out, EventKind.LOITER)
    assert said.payload["action"] == "leave_failed" and "timed out" in said.reason
    assert m.in_loiter() and m.leaving_seq is None
    (again,) = of(team.handle(on_circle(i + 1), t + 2.0), act.LeaveLoiter)
    assert again.seq == k + 1


def _behind_entry(team: TeamController, m: Member, lo: LoiterSpec, at: act.Fix) -> act.Fix:
    """``at`` moved to the point of ``lo``'s circle opposite the one the route enters it by
    (half a circle from its way on)."""
    p = m.schedule.path.pose_at(lo.s_m)
    e = lo.centre_east_m - lo.radius_m * math.sin(p.heading_rad)
    n = lo.centre_north_m - lo.radius_m * math.cos(p.heading_rad)
    lat, lon = team.frame.to_geodetic(e, n)
    return dataclasses.replace(at, lat_deg=float(lat), lon_deg=float(lon))


@pytest.mark.parametrize("short_m", [100.0, 0.0], ids=["100 m left", "all flown"])
def test_a_late_vehicle_whose_turns_are_as_good_as_flown(
    team: TeamController, short_m: float
) -> None:
    """Late, with its loiter flown by the coordinator's count but ``short_m`` (less what it
    flies to the fix) and the vehicle on the circle behind its entry point. With some turns
    left leaving would gain nothing (it would fly the route from there): it stays in the
    turns and the team time moves for what is left. With all of them flown it still circles,
    lining up with the route later than its count foresaw (as after a hold, when it came to
    them off its route), and staying gains nothing either: the way out at the roll limit is
    never longer than the way round the circle. So it is taken out of them, and the team
    time moves for the way out."""
    vid = "UAV3"
    m, lo, k, t1, on_circle = _in_turns(team, vid)
    i = SETTLED + 1
    m.loiter_flown_m = lo.length_m - short_m
    behind = _behind_entry(team, m, lo, on_circle(i))
    t = t1 + 2.0 * i
    _retarget(team, t + 60.0)
    out = team.handle(behind, t)
    (moved,) = reports(out, EventKind.ARRIVAL)
    assert moved.vehicle == vid and "cannot arrive before" in moved.reason
    if short_m > 0.0:
        assert of(out, act.LeaveLoiter) == [] and m.in_loiter()
        return
    (leave,) = of(out, act.LeaveLoiter)
    assert leave.seq == k + 1 and m.leaving_seq == k + 1
    (said,) = [r for r in reports(out, EventKind.LOITER) if r.payload["action"] == "leave"]
    assert "late even at" in said.reason, said.reason


def test_a_vehicle_circling_on_past_its_turns_is_timed_by_the_way_out_and_taken_out(
    team: TeamController,
) -> None:
    """All of its turns flown by the count, on the circle behind its entry point (lining up
    with the route later than the count foresaw), on time: timed from the waypoint after the
    turns it would need little speed, but the way round to it is half the circle more. Timed
    by the way out instead, it is taken out of the turns at once, and the team time stays."""
    vid = "UAV3"
    m, lo, k, t1, on_circle = _in_turns(team, vid)
    i = SETTLED + 1
    m.loiter_flown_m = lo.length_m
    behind = _behind_entry(team, m, lo, on_circle(i))
    t = t1 + 2.0 * i
    ratio = m.schedule.tas_per_eas(lo.s_m)
    v_mid = (m.limits.airspeed_min_m_s + m.limits.airspeed_max_m_s) / 2.0 * ratio
    route_m = m.track.length_m - lo.s_m
    # On time at the middle of its speeds by the way round the circle's half and the route.
    _retarget(team, t + (route_m + math.pi * lo.radius_m) / v_mid - m.offset_s)
    from_waypoint_m_s = route_m / (m.target_s - t) / ratio
    assert from_waypoint_m_s < m.limits.airspeed_max_m_s - team.config.speed_reserve_m_s - 2.0
    out = team.handle(behind, t)
    (leave,) = of(out, act.LeaveLoiter)
    assert leave.seq == k + 1
    (said,) = [r for r in reports(out, EventKind.LOITER) if r.payload["action"] == "leave"]
    assert "circles on to line up" in said.reason, said.reason
    assert reports(out, EventKind.ARRIVAL) == []


def test_a_vehicle_its_turns_would_leave_without_a_speed_reserve_is_taken_out_of_them(
    team: TeamController,
) -> None:
    """Not late, but the rest of its turns would need within ``speed_reserve_m_s`` of its top
    airspeed (no room for what the way out of the turns costs), and leaving now is not early:
    taken out of them, said with the speed it would need; the team time stays."""
    vid = "UAV3"
    m, lo, k, t1, on_circle = _in_turns(team, vid)
    ratio = m.schedule.tas_per_eas(lo.s_m)
    reserve = team.config.speed_reserve_m_s
    v_near = (m.limits.airspeed_max_m_s - reserve / 2.0) * ratio  # inside the reserve
    v_min = m.limits.airspeed_min_m_s * ratio
    route_m = m.track.length_m - lo.s_m
    step_m = 2.0 * m.groundspeed_m_s
    # Round the circle, undecided, to where 1.5 km of turns are left.
    i = SETTLED + 1
    while lo.length_m - (i + 1) * step_m > 1_500.0:
        m.next_decision_s = math.inf
        _answered(team, vid, team.handle(on_circle(i), t1 + 2.0 * i), t1 + 2.0 * i)
        i += 1
    t = t1 + 2.0 * i
    ref = t + (lo.length_m - i * step_m + route_m) / v_near - m.offset_s
    assert t + route_m / v_min > ref + m.offset_s  # leaving now is not early
    _retarget(team, ref)
    m.next_decision_s = -math.inf
    out = team.handle(on_circle(i), t)
    (leave,) = of(out, act.LeaveLoiter)
    assert leave.seq == k + 1
    (said,) = [r for r in reports(out, EventKind.LOITER) if r.payload["action"] == "leave"]
    assert "within" in said.reason and "of its top speed" in said.reason, said.reason
    assert reports(out, EventKind.ARRIVAL) == [] and team.team_ref_s == ref


def test_turns_flown_while_the_vehicle_was_not_heard_are_counted_and_keep_it_in_them(
    team: TeamController,
) -> None:
    """Heard last on its route 400 m short of its loiter, on time for its slot at the speed
    it flies, then not for 300 s (a link down, or the coordinator restarted from its
    checkpoint): heard again in the turns. It entered them 400 m / its ground speed after
    that fix and has flown round since: counted so (not as just entered, with every turn
    still ahead, which reads as late by the time it flew round meanwhile and, past what its
    speed range absorbs, takes it out of its turns), and with the turns it has left it is on
    time: neither taken out of them nor moving the team time."""
    vid = "UAV3"
    m, lo, k, t0 = _turns_installed(team, vid)
    eas_m_s = (m.limits.airspeed_min_m_s + m.limits.airspeed_max_m_s) / 2.0
    t_short = t0 + 10.0
    short = fix(team, vid, lo.s_m - 400.0, t_short, eas_m_s)
    assert short.mission_seq is not None and short.mission_seq < k
    gs = short.groundspeed_m_s
    assert gs is not None
    # The slot: the rest of the route, the turns included, at that ground speed (still air).
    route_m = m.track.length_m - lo.s_m
    ref = t_short + (400.0 + lo.length_m + route_m) / gs - m.offset_s
    _retarget(team, ref)
    _answered(team, vid, team.handle(short, t_short), t_short)
    gap_s = 300.0
    t = t_short + gap_s
    # At its true airspeed (still air here: its ground speed too) at the loiter.
    tas_m_s = eas_m_s * m.tas_per_eas(lo.s_m)
    entered_s = t_short + 400.0 / tas_m_s
    flown_m = (t - entered_s) * tas_m_s
    assert 0.0 < flown_m < lo.length_m - 2_000.0  # well inside the turns when heard again
    base = dataclasses.replace(fix(team, vid, lo.s_m, t_short, eas_m_s), mission_seq=k)
    # Heard again on the side of the circle a wind would slow it on: the ground speed there
    # says nothing of how fast it went round (its true airspeed does).
    again = dataclasses.replace(
        on_loiter_circle(team, base, lo, 0), utc_s=short.utc_s + gap_s, groundspeed_m_s=0.7 * gs
    )
    m.next_decision_s = -math.inf
    out = team.handle(again, t)
    assert m.in_loiter()
    # To the located point of the fix short of it (the route's geometry, centimetres).
    assert m.loiter_entered_s == pytest.approx(entered_s, abs=0.01)
    assert m.loiter_flown_m == pytest.approx(flown_m, abs=0.5)
    assert of(out, act.LeaveLoiter) == [], [r.reason for r in reports(out, EventKind.LOITER)]
    assert reports(out, EventKind.ARRIVAL) == [] and team.team_ref_s == ref
    d = m.last_decision
    assert d is not None and d.verdict == "on_time", d


def test_a_vehicle_in_its_turns_is_timed_to_a_splice_at_its_true_airspeed_not_one_fixs_ground_speed(
    team: TeamController,
) -> None:
    """When a re-plan times where a vehicle in its loiter turns will be (the waypoint its new
    route is spliced at): the turns it has left (less what it has flown round them) and the
    path after them at its true airspeed, not at the ground speed of the fix it was last
    heard at, which round a circle in wind is the side of the wind it is on (14 m/s on the
    upwind side for a vehicle averaging 17 m/s round it set a splice 200 s late)."""
    vid = "UAV3"
    m, lo, _, t1, on_circle = _in_turns(team, vid)
    i = SETTLED + 1
    t = t1 + 2.0 * i
    upwind = dataclasses.replace(on_circle(i), groundspeed_m_s=0.6 * on_circle(i).groundspeed_m_s)
    team.handle(upwind, t)
    assert m.in_loiter() and m.airspeed_m_s is not None
    tas_m_s = m.airspeed_m_s * m.tas_per_eas(m.s_m)
    assert m.groundspeed_m_s < 0.7 * tas_m_s  # the fix's own: the slow side
    speed = MissionChanges._speed_ahead_m_s(m)
    assert speed == pytest.approx(tas_m_s)
    s_k = m.track.length_m - 100.0
    left_m = lo.length_m - m.loiter_flown_m
    assert 0.0 < left_m < lo.length_m
    expected = t + (left_m + s_k - m.s_m) / tas_m_s
    assert MissionChanges._reaches_s(m, t, s_k, speed) == pytest.approx(expected, abs=1e-6)


def test_a_vehicle_taken_out_of_its_turns_flying_against_its_route_is_timed_with_the_turn_back(
    team: TeamController,
) -> None:
    """Taken out of its turns on the far side of the circle, flying against its route: it
    turns round towards the waypoint after the turns (at its roll limit) and flies straight
    at it before it flies the route on, and is timed so. Timed as if it flew the route on
    from the point its position is located at, it was late by what the way out costs, found
    out a few seconds at a time after it left the turns (the team time moved four times, too
    late for the others to follow)."""
    vid = "UAV3"
    m, lo, k, t1, on_circle = _in_turns(team, vid)
    assert [x.s_m for x in m.track.loiters] == [lo.s_m]  # the route after it has no turns
    i = SETTLED + 1
    t = t1 + 2.0 * i
    course = m.schedule.path.pose_at(lo.s_m).heading_rad + math.pi
    gs = on_circle(i).groundspeed_m_s
    assert gs is not None
    back = dataclasses.replace(
        on_circle(i),
        ve_m_s=gs * math.sin(course),
        vn_m_s=gs * math.cos(course),
        heading_deg=math.degrees(course) % 360.0,
    )
    _retarget(team, t + 30.0)  # far too soon for anything: out of the turns at once
    m.next_decision_s = -math.inf
    out = team.handle(back, t)
    assert of(out, act.LeaveLoiter)
    # The way out flown step by step to the waypoint after the turns, then the route from
    # it, at top speed (still air, its true airspeed there).
    w = next(j for j in range(k + 1, len(m.mission.items)) if m.mission.items[j].command == 16)
    item = m.mission.items[w]
    we, wn = team.frame.to_local(item.lat_deg, item.lon_deg)
    e, n = team.frame.to_local(back.lat_deg, back.lon_deg)
    way_m = _flown_out_m(float(we - e), float(wn - n), course, gs)
    s_w = m.mission.item_s_m[w]
    assert s_w is not None and s_w > lo.s_m
    v_max = m.limits.airspeed_max_m_s * m.tas_per_eas(s_w)
    expected_s = t + (way_m + m.track.length_m - s_w) / v_max
    d = m.last_decision
    assert d is not None and d.verdict == "late"
    assert d.eta_min_s == pytest.approx(expected_s, abs=0.5), (d.eta_min_s, expected_s)
    # More than timing it from where it is located on the route would say: the turn back.
    located_s, _ = m.track.locate(float(e), float(n), lo.s_m)
    assert d.eta_min_s > t + (m.track.length_m - located_s) / v_max + 5.0

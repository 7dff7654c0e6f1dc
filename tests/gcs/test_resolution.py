"""Predicted losses of separation resolved ahead of time by speed: the pure choice
(:func:`gcs.coordination.resolution.resolve`) on straight crossing tracks, and the team
controller flying two aircraft scheduled to cross the same point at the same moment (fixes
made here from a kinematic model of the two, their speeds answering its commands after a lag).
Every verdict is the test's own arithmetic on the positions it flew, not the code's figures."""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from gcs.coordination import actions as act
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind
from gcs.coordination.resolution import Ahead, Forecasts, Resolution, longest_hold_s, resolve
from gcs.coordination.routetrack import LoiterSpec, RouteTrack
from gcs.coordination.team import TeamController
from planner.deconflict import pair_separation
from planner.flightpath import straight
from planner.plan import build_world, plan
from planner.retime import build_schedule, retime_on_path
from planner.scenario import parse_scenario
from planner.wind import Wind
from tests.gcs.test_team import START_UTC, airborne, fix, of, reports
from tests.planner.conftest import crossing_scenario, small_scenario


def _straight(vid: str, start: tuple[float, float], heading_deg: float, **kw: Any) -> Ahead:
    """A straight route from ``start`` on ``heading_deg``, flown from its start at 25 m/s
    (still air, commanded = true airspeed) with a fix at 0 s, its slot an hour ahead: the
    route ends where its ground speed takes it by its slot (the goal its slot asks that
    speed for)."""
    h = math.radians(heading_deg)
    s = np.array([0.0, kw.get("groundspeed_m_s", 25.0) * kw.get("horizon_s", 3600.0)])
    fields: dict[str, Any] = {
        "vehicle": vid, "t_s": 0.0, "s_m": 0.0, "groundspeed_m_s": 25.0,
        "airspeed_m_s": 25.0, "tas_per_eas": 1.0, "airspeed_min_m_s": 18.0,
        "airspeed_max_m_s": 30.0, "alt_m": 500.0, "route_s_m": s,
        "route_east_m": start[0] + s * math.sin(h), "route_north_m": start[1] + s * math.cos(h),
        "horizon_s": 3600.0,
    }  # fmt: skip
    return Ahead(**(fields | kw))


def _flown_apart_m(a: Ahead, b: Ahead, speeds: dict[str, float], response_s: float) -> float:
    """Least distance of two straight flights from t = 0 to 90 s, each at its speed after
    ``response_s`` (the test's own geometry, 0.1 s steps)."""
    best = math.inf
    for t in np.arange(0.0, 90.0, 0.1):
        pos = []
        for x in (a, b):
            v = speeds.get(x.vehicle, x.airspeed_m_s)
            s = x.groundspeed_m_s * min(t, response_s) + v * max(t - response_s, 0.0)
            h = math.atan2(
                x.route_east_m[1] - x.route_east_m[0], x.route_north_m[1] - x.route_north_m[0]
            )
            pos.append((x.route_east_m[0] + s * math.sin(h), x.route_north_m[0] + s * math.cos(h)))
        best = min(best, math.dist(*pos))
    return best


def test_a_crossing_predicted_along_the_routes_is_resolved_by_the_speed_that_keeps_them_apart() -> (
    None
):
    """A east-bound and B north-bound, each 1,500 m (60 s) from the point their routes cross:
    as they fly they meet there; the resolution's speed, flown in this test's own geometry,
    keeps them 300 m apart."""
    a = _straight("A", (-1500.0, 0.0), 90.0)
    b = _straight("B", (0.0, -1500.0), 0.0)
    assert _flown_apart_m(a, b, {}, 5.0) < 1.0
    r = resolve(a, b, now_s=0.0, separation_m=300.0)
    assert r is not None
    assert r.unresolved_m < 1.0 and r.at_s == pytest.approx(60.0, abs=1.0)
    assert r.airspeed_m_s in (18.0, 30.0) and r.vehicle in ("A", "B")
    assert r.predicted_m >= 300.0
    assert _flown_apart_m(a, b, {r.vehicle: r.airspeed_m_s}, 5.0) >= 300.0 - 1.0
    assert r.until_s > r.at_s  # held past the closest approach


def test_no_resolution_for_a_pair_apart_none_possible_or_only_the_movable_one_moved() -> None:
    a = _straight("A", (-1500.0, 0.0), 90.0)
    later = _straight("B", (0.0, -2500.0), 0.0)  # 40 s behind: 1 km south when A crosses
    assert resolve(a, later, now_s=0.0, separation_m=300.0) is None
    # Head-on on one line: no speed keeps them apart, and none is asked.
    head_on = _straight("B", (3000.0, 0.0), 270.0)
    assert resolve(a, head_on, now_s=0.0, separation_m=300.0) is None
    # B on its final approach is not moved: A is, whatever would be better.
    b = _straight("B", (0.0, -1500.0), 0.0, movable=False)
    r = resolve(a, b, now_s=0.0, separation_m=300.0)
    assert r is not None and r.vehicle == "A"
    # Beyond the look-ahead nothing is predicted.
    far = _straight("B", (0.0, -1500.0), 0.0, horizon_s=30.0)
    assert (
        resolve(
            _straight("A", (-1500.0, 0.0), 90.0, horizon_s=30.0), far, now_s=0.0, separation_m=300.0
        )
        is None
    )


def test_two_abreast_already_under_the_separation_on_converging_routes_are_opened_up() -> None:
    """A and B abreast 470 m apart, their routes 10 degrees apart and crossing 2.7 km ahead,
    both at 25 m/s: as they fly they drift together to tens of metres. No speed keeps the
    whole 500 m (they are under it already), but one of them flown faster or slower opens
    their closest approach to hundreds of metres: that choice is taken and says it falls
    short. Checked in this test's own geometry."""
    a = _straight("A", (0.0, 0.0), 0.0)
    b = _straight("B", (470.0, 0.0), -10.0)
    separation_m = 500.0
    assert _flown_apart_m(a, b, {}, 5.0) < 100.0
    r = resolve(a, b, now_s=0.0, separation_m=separation_m)
    assert r is not None and not r.keeps_separation
    assert r.unresolved_m < 100.0 and r.predicted_m < separation_m
    assert r.until_s > r.at_s  # held past their meeting as they fly, not only its own closest
    flown = _flown_apart_m(a, b, {r.vehicle: r.airspeed_m_s}, 5.0)
    assert flown >= 200.0 and flown == pytest.approx(r.predicted_m, abs=25.0)
    # Head-on on one line the same choices gain nothing: none is taken.
    head_on = _straight("B", (0.0, 3000.0), 180.0)
    assert resolve(a, head_on, now_s=0.0, separation_m=separation_m) is None


def test_a_resolution_does_not_push_its_mover_into_a_third_vehicle() -> None:
    """The crossing of A and B, with C 500 m behind A on A's line at A's speed. Alone, the pair
    is resolved by A slowing down, which C would then fly into. With C given as A's neighbour
    that choice is not taken: B moves, the pair keeps the separation and A and C their 500 m
    (each checked in this test's own geometry)."""
    a = _straight("A", (-1500.0, 0.0), 90.0)
    b = _straight("B", (0.0, -1500.0), 0.0)
    c = _straight("C", (-2000.0, 0.0), 90.0)
    alone = resolve(a, b, now_s=0.0, separation_m=300.0)
    assert alone is not None and (alone.vehicle, alone.airspeed_m_s) == ("A", 18.0)
    assert _flown_apart_m(a, c, {"A": 18.0}, 5.0) < 300.0
    r = resolve(a, b, now_s=0.0, separation_m=300.0, neighbours={"A": [c], "B": []})
    assert r is not None and r.vehicle == "B" and r.keeps_separation
    assert _flown_apart_m(a, b, {"B": r.airspeed_m_s}, 5.0) >= 300.0 - 1.0
    assert _flown_apart_m(a, c, {"B": r.airspeed_m_s}, 5.0) == pytest.approx(500.0, abs=1.0)
    # A neighbour already closer than the separation may stay so, but not come closer.
    near_c = _straight("C", (-1750.0, 0.0), 90.0)  # 250 m behind A
    r = resolve(a, b, now_s=0.0, separation_m=300.0, neighbours={"A": [near_c]})
    assert r is not None and not (r.vehicle == "A" and r.airspeed_m_s < 25.0)


def test_a_resolution_near_the_goals_is_held_only_as_long_as_the_slot_can_be_made() -> None:
    """The crossing of A and B 60 s ahead, their slots 150 s ahead: at 25 m/s each arrives
    on time. Held until its closest approach has passed (as with slots an hour ahead) the
    speed would cost more than half of what the rest of the way can make up; the resolution
    is held shorter, and in this test's own arithmetic the mover still makes its slot with
    half its speed range to spare, and the pair keeps the separation as it flies it."""
    far = resolve(
        _straight("A", (-1500.0, 0.0), 90.0), _straight("B", (0.0, -1500.0), 0.0),
        now_s=0.0, separation_m=300.0,
    )  # fmt: skip
    a = _straight("A", (-1500.0, 0.0), 90.0, horizon_s=150.0)
    b = _straight("B", (0.0, -1500.0), 0.0, horizon_s=150.0)
    r = resolve(a, b, now_s=0.0, separation_m=300.0)
    assert far is not None and r is not None
    assert r.until_s < far.until_s - 5.0
    mover = a if r.vehicle == "A" else b
    # Flown at the resolution's speed from 5 s (the response) to its end, then the rest of
    # the way (what 25 m/s would fly in 150 s, less what was flown) in the time left, less
    # the 5 s its speed takes to come back.
    flown_m = 25.0 * 5.0 + r.airspeed_m_s * (r.until_s - 5.0)
    needed_m_s = (25.0 * 150.0 - flown_m - 25.0 * 5.0) / (150.0 - 5.0 - r.until_s)
    lo, hi = mover.airspeed_min_m_s, mover.airspeed_max_m_s
    assert 25.0 - 0.5 * (25.0 - lo) - 1e-6 <= needed_m_s <= 25.0 + 0.5 * (hi - 25.0) + 1e-6

    def apart_m(speed: float, until_s: float) -> float:
        """Least distance over 90 s, the mover at ``speed`` from 5 s to ``until_s``."""
        best = math.inf
        for t in np.arange(0.0, 90.0, 0.1):
            moved = 25.0 * (min(t, 5.0) + max(t - until_s, 0.0))
            moved += speed * min(max(t - 5.0, 0.0), until_s - 5.0)
            other = 25.0 * t
            ae, bn = (moved, other) if r.vehicle == "A" else (other, moved)
            best = min(best, math.hypot(-1500.0 + ae, -1500.0 + bn))
        return best

    assert apart_m(25.0, 0.0) < 1.0
    assert apart_m(r.airspeed_m_s, r.until_s) >= min(r.predicted_m, 300.0) - 1.0
    # A flying its top speed to make its slot and B its lowest: neither has room to make up
    # another speed, and nothing is asked (they meet, and the flight's alarm says so).
    late = _straight("A", (-1800.0, 0.0), 90.0, airspeed_m_s=30.0, groundspeed_m_s=30.0)
    early = _straight("B", (0.0, -1080.0), 0.0, airspeed_m_s=18.0, groundspeed_m_s=18.0)
    assert _flown_apart_m(late, early, {}, 5.0) < 1.0
    assert resolve(late, early, now_s=0.0, separation_m=300.0) is None


def test_a_vehicle_in_its_loiter_turns_is_predicted_round_them_and_the_other_one_moves() -> None:
    """L flies 8 turns of 150 m round (0, 0), clockwise, entered at the circle's west point
    from its north-bound route, at 25 m/s (37.7 s a turn): it is at the north point at 9.4 s
    and 47.1 s. M, east bound along y = 400 m, is 47.1 s (1,178 m) west of x = 0: they come
    250 m apart there. L in its turns is not moved; M is, and the test's own circle and line
    keep them apart at that speed."""
    radius, quarter_s = 150.0, 0.25 * 2.0 * math.pi * 150.0 / 25.0
    loiter = LoiterSpec(2_000.0, 0.0, 0.0, radius, 8, clockwise=True)
    track = RouteTrack(straight(-radius, -2_000.0, -radius, 10_000.0), (loiter,))
    along, east, north = track.flight_samples(0)
    lo = _straight(
        "L", (0.0, 0.0), 0.0, s_m=2_000.0, route_s_m=along, route_east_m=east,
        route_north_m=north, movable=False,
    )  # fmt: skip
    meet_s = quarter_s + 4.0 * quarter_s
    m = _straight("M", (-25.0 * meet_s, 400.0), 90.0)
    r = resolve(lo, m, now_s=0.0, separation_m=300.0)
    assert r is not None and r.vehicle == "M"
    assert r.unresolved_m == pytest.approx(250.0, abs=10.0)
    assert r.at_s == pytest.approx(meet_s, abs=2.0)

    def apart_m(m_speed: float) -> float:
        best = math.inf
        for t in np.arange(0.0, 180.0, 0.05):
            a = math.pi - 25.0 * t / radius  # from the west point, clockwise
            s = 25.0 * min(t, 5.0) + m_speed * max(t - 5.0, 0.0)
            here = (radius * math.cos(a), radius * math.sin(a))
            best = min(best, math.dist(here, (-25.0 * meet_s + s, 400.0)))
        return best

    assert apart_m(25.0) < 260.0
    assert apart_m(r.airspeed_m_s) >= 300.0 - 1.0


def _crossing_team() -> TeamController:
    """Two aircraft whose schedule crosses the middle of the map at the same moment."""
    team = timed_alike(crossing_scenario(arrival={"kind": "simultaneous", "required_s": 1500}))
    a_, b_ = team.schedule.vehicles
    assert pair_separation(a_, b_, step_s=0.1).distance_m < 1.0  # they meet, as timed
    return team


def test_a_resolution_is_made_up_before_the_final_approach_and_the_response() -> None:
    """A and B cross 60 s ahead, their slots 80 s ahead, each with a 6 s final approach (no
    speed is asked there) and 5 s for a speed to take effect. What the resolution's speed
    gains or loses until it ends is made up, in this test's own arithmetic, with half the
    speed range on the other side before the speed taken back takes effect and the final
    approach begins (held to 6 s before its slot, a crowd's mover arrived 1.7 s early)."""
    a = _straight("A", (-1500.0, 0.0), 90.0, horizon_s=80.0, final_s=6.0)
    b = _straight("B", (0.0, -1500.0), 0.0, horizon_s=80.0, final_s=6.0)
    r = resolve(a, b, now_s=0.0, separation_m=300.0)
    assert r is not None
    mover = a if r.vehicle == "A" else b
    lo, hi = mover.airspeed_min_m_s, mover.airspeed_max_m_s
    change = abs(r.airspeed_m_s - 25.0)
    recover_m_s = 0.5 * ((25.0 - lo) if r.airspeed_m_s > 25.0 else (hi - 25.0))
    assert change * (r.until_s - 5.0) <= recover_m_s * (80.0 - 6.0 - 5.0 - r.until_s) + 1e-6


def timed_alike(data: dict[str, Any]) -> TeamController:
    """The team of ``data`` (one arrival at 1500 s) started, its schedule's separation by
    timing undone (each vehicle re-timed at its own cruise speed for the same arrival), so
    that the controller must resolve in flight what a late vehicle or a re-plan could
    cause."""
    scenario = parse_scenario(data)
    world = build_world(scenario)
    schedule = build_schedule(scenario, plan(scenario, "astar", world=world), world=world)
    natural = tuple(
        retime_on_path(
            scenario, scenario.vehicle(vs.vehicle_id), vs, now_s=0.0, target_s=1500.0,
            step_m_s=schedule.step_m_s, threats=[],
        ).schedule
        for vs in schedule.vehicles
    )  # fmt: skip
    schedule = dataclasses.replace(schedule, vehicles=natural)
    team = TeamController(scenario, schedule, world, FlightConfig(), rng=np.random.default_rng(0))
    team.start(START_UTC)
    return team


def _fly(team: TeamController) -> tuple[float, list[act.Report], dict[str, float]]:
    """Fly the team from the last takeoff to the goals, fixes every 0.5 s made from this
    test's kinematics (still air; a commanded airspeed flown 3 s after its command). Returns
    the least horizontal distance of the two while both fly (from the positions flown here),
    the conflict reports, and when each crossed its goal."""
    ids = list(team.members)
    lag_s = 3.0
    t0 = max(m.schedule.climb_end_s for m in team.members.values()) + 1.0
    s, level = {}, {}
    for vid in ids:
        m = team.members[vid]
        airborne(team, vid, m.takeoff_s)
        _, s[vid], level[vid] = m.schedule.state_at(t0)  # as scheduled, on its route
    pending: list[tuple[float, str, float]] = []
    arrived: dict[str, float] = {}
    closest = math.inf
    said: list[act.Report] = []
    dt, t = 0.5, t0
    while len(arrived) < len(ids) and t < t0 + 3000.0:
        t += dt
        for p in [p for p in pending if p[0] <= t]:
            level[p[1]] = p[2]
            pending.remove(p)
        for vid in ids:
            if vid in arrived:
                continue
            m = team.members[vid]
            gs = level[vid] * m.schedule.tas_per_eas(s[vid])
            s[vid] += gs * dt
            if s[vid] >= m.track.length_m:
                arrived[vid] = t - (s[vid] - m.track.length_m) / gs  # within the step
                continue
            out = team.handle(fix(team, vid, s[vid], t, level[vid]), t)
            said += reports(out, EventKind.CONFLICT)
            for c in of(out, act.CommandSpeed):
                lim = team.members[c.vehicle_id].limits
                assert lim.airspeed_min_m_s <= c.airspeed_m_s <= lim.airspeed_max_m_s
                team.handle(act.SpeedCommanded(c.vehicle_id, c.airspeed_m_s, c.reason, t), t)
                pending.append((t + lag_s, c.vehicle_id, c.airspeed_m_s))
        if not arrived:
            a, b = (team.members[v].schedule.path.pose_at(s[v]) for v in ids)
            closest = min(closest, math.hypot(a.east_m - b.east_m, a.north_m - b.north_m))
    return closest, said, arrived


@pytest.mark.slow  # several seconds: left out of make test-quick
def test_two_aircraft_scheduled_to_meet_are_kept_apart_in_flight_and_still_arrive_on_time() -> None:
    """With the resolution off (``resolve_horizon_s=0``) the same flight brings them within
    the separation: what the resolution prevents is there."""
    team = _crossing_team()
    d_s = team.scenario.separation_m
    closest, said, arrived = _fly(team)
    resolved = [r for r in said if (r.payload or {}).get("resolution") == "speed"]
    released = [r for r in said if (r.payload or {}).get("resolution") == "released"]
    assert len(resolved) == 1 and len(released) == 1, [r.reason for r in said]
    assert resolved[0].reason.startswith(f"flies {resolved[0].payload['airspeed_m_s']:g} m/s")
    assert closest >= d_s, f"{closest:.0f} m"
    for vid, m in team.members.items():
        assert arrived[vid] == pytest.approx(m.target_s, abs=1.0), vid

    off = _crossing_team()
    off.config = FlightConfig(resolve_horizon_s=0.0)
    closest, said, arrived = _fly(off)
    assert not [r for r in said if (r.payload or {}).get("resolution")]
    assert closest < d_s


def test_the_forecast_screen_finds_the_pairs_a_pair_by_pair_prediction_finds() -> None:
    """Forecasts made at different moments (aligned on whole seconds) against each pair's own
    prediction at the time of the screen: the same vehicles under the separation, and none
    from a forecast gone stale."""
    rng = np.random.default_rng(7)
    forecasts = Forecasts([f"V{k}" for k in range(40)] + ["ME"], look_ahead_s=90.0, response_s=5.0)
    aheads = []
    for k in range(40):
        start = tuple(rng.uniform(-2500.0, 2500.0, 2))
        a = _straight(f"V{k}", start, float(rng.uniform(0, 360)), t_s=float(rng.uniform(0, 3)))
        forecasts.update(a, a.t_s)
        aheads.append(a)
    now = 3.0
    me = _straight("ME", (0.0, 0.0), 45.0, t_s=now)
    forecasts.update(me, now)
    t = np.arange(3.0, 94.0, 1.0)  # the whole seconds both forecasts cover
    mine = me.positions(t, 25.0, 5.0)
    expected = []
    for a in aheads:
        theirs = a.positions(t, 25.0, 5.0)
        ok = t <= math.ceil(a.t_s) + 90.0  # what its forecast covers
        d = np.linalg.norm(theirs[ok] - mine[ok], axis=1).min()
        if d < 300.0:
            expected.append((d, a.vehicle))
    assert expected, "the draw puts some pair under the separation"
    assert forecasts.near("ME", 300.0, now) == [v for _, v in sorted(expected)]
    assert forecasts.near("ME", 300.0, now + 10.0) == []  # every other forecast stale


def test_the_screen_for_a_change_of_height_finds_a_crossing_high_above() -> None:
    """Two routes crossing, 450 m apart in height: under the separation nowhere as they fly
    (the screen with heights finds none), but a climb of 450 m would bring them to the same
    height where they cross; the screen over the ground alone finds the other."""
    forecasts = Forecasts(["A", "B"], look_ahead_s=90.0, response_s=5.0)
    # Both reach (0, 0) at 60 s: A flying north, B east, B 450 m higher.
    a = _straight("A", (0.0, -1_500.0), 0.0)
    b = _straight("B", (-1_500.0, 0.0), 90.0, alt_m=950.0)
    for x in (a, b):
        forecasts.update(x, 0.0)
    assert forecasts.near("A", 300.0, 0.0) == []
    assert forecasts.near("A", 300.0, 0.0, heights=False) == ["B"]


def _in_wind(vid: str, corners: list[tuple[float, float]], **kw: Any) -> Ahead:
    """A route through ``corners`` (samples every 100 m or less) flown from its start at
    30 m/s in a 10 m/s wind to the east, with a fix at 0 s and the ground speed its first
    leg makes good (given as ``groundspeed_m_s``)."""
    east, north = [corners[0][0]], [corners[0][1]]
    for (e0, n0), (e1, n1) in itertools.pairwise(corners):
        k = max(1, math.ceil(math.hypot(e1 - e0, n1 - n0) / 100.0))
        east.extend(np.linspace(e0, e1, k + 1)[1:])
        north.extend(np.linspace(n0, n1, k + 1)[1:])
    e, n = np.array(east), np.array(north)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(e), np.diff(n)))])
    fields: dict[str, Any] = {
        "vehicle": vid, "t_s": 0.0, "s_m": 0.0, "groundspeed_m_s": 40.0,
        "airspeed_m_s": 30.0, "tas_per_eas": 1.0, "airspeed_min_m_s": 18.0,
        "airspeed_max_m_s": 32.0, "alt_m": 500.0, "route_s_m": s, "route_east_m": e,
        "route_north_m": n, "horizon_s": 3600.0, "wind": Wind(10.0, 0.0),
    }  # fmt: skip
    return Ahead(**(fields | kw))


def _fly_in_wind(
    a: Ahead, seconds: int, speed: Callable[[float], float], step_s: float = 0.02
) -> list[tuple[float, float]]:
    """Where ``a``'s route has it at each whole second after its fix, 0 to ``seconds``,
    flown at ``speed(t)`` (true airspeed) in a 10 m/s wind to the east: the test's own steps,
    each crabbed into the wind on the route's leg there (ground speed along +
    sqrt(v^2 - across^2))."""
    east, north = a.route_east_m, a.route_north_m
    s, out = a.s_m, []
    per_second = round(1.0 / step_s)
    for k in range(seconds * per_second + 1):
        if k % per_second == 0:
            at = min(s, a.route_s_m[-1])
            out.append(
                (float(np.interp(at, a.route_s_m, east)), float(np.interp(at, a.route_s_m, north)))
            )
        i = min(int(np.searchsorted(a.route_s_m, s, side="right")) - 1, len(east) - 2)
        de, dn = east[i + 1] - east[i], north[i + 1] - north[i]
        length = math.hypot(de, dn)
        along, across = 10.0 * de / length, 10.0 * dn / length
        v = speed(k * step_s)
        s += (along + math.sqrt(v * v - across * across)) * step_s
    return out


def test_a_forecast_in_the_wind_slows_where_the_route_turns_out_of_a_tailwind() -> None:
    """4 km east (a tailwind: 40 m/s over the ground), then 8 km north (a crosswind: 28 m/s),
    forecast against the test's own steps in the wind."""
    a = _in_wind("A", [(-4_000.0, 0.0), (0.0, 0.0), (0.0, 8_000.0)])
    times = np.array([30.0, 100.0, 200.0, 300.0])
    as_flown = a.positions(times, 30.0, 5.0)
    flown = _fly_in_wind(a, 300, lambda _t: 30.0)
    for t, got in zip(times, as_flown, strict=True):
        assert math.dist(got[:2], flown[int(t)]) < 3.0, (t, got, flown[int(t)])
    # Slowed to 20 m/s from 5 s after the fix until 150 s, at 30 m/s again after.
    slowed = a.positions(times, 20.0, 5.0, until_s=150.0)
    flown_slowed = _fly_in_wind(a, 300, lambda u: 20.0 if 5.0 <= u < 150.0 else 30.0)
    for t, got in zip(times, slowed, strict=True):
        assert math.dist(got[:2], flown_slowed[int(t)]) < 3.0, (t, got, flown_slowed[int(t)])
    # The tailwind leg's ground speed held all along would have it far up the crosswind leg.
    calm = dataclasses.replace(a, wind=None).positions(times, 30.0, 5.0)
    assert math.dist(calm[-1][:2], flown[300]) > 1_000.0


def test_a_forecast_in_the_wind_far_along_a_long_route_is_the_one_flown() -> None:
    """A 30 km zig-zag sampled every 100 m, the fix 2 km along it: forecast 15 minutes ahead
    (past the first hundreds of its samples, to its end) against the test's own steps in the
    wind, at its airspeed and slowed for a while; past its end it is at its end."""
    corners = [(0.0, 0.0), (6_000.0, 0.0), (6_000.0, 6_000.0), (0.0, 6_000.0), (0.0, 12_000.0)]
    a = dataclasses.replace(_in_wind("A", [*corners, (6_000.0, 12_000.0)]), s_m=2_000.0)
    times = np.array([10.0, 150.0, 400.0, 700.0, 950.0, 1_100.0])
    flown = _fly_in_wind(a, 1_100, lambda _t: 30.0)
    for t, got in zip(times, a.positions(times, 30.0, 5.0), strict=True):
        assert math.dist(got[:2], flown[int(t)]) < 3.0, (t, got, flown[int(t)])
    assert math.dist(flown[1_100], (6_000.0, 12_000.0)) < 1.0  # the route flown to its end
    slowed = a.positions(times, 20.0, 5.0, until_s=500.0)
    flown_slowed = _fly_in_wind(a, 1_100, lambda u: 20.0 if 5.0 <= u < 500.0 else 30.0)
    for t, got in zip(times, slowed, strict=True):
        assert math.dist(got[:2], flown_slowed[int(t)]) < 3.0, (t, got, flown_slowed[int(t)])


def test_a_forecast_in_still_air_is_the_one_at_the_present_ground_speed() -> None:
    """A vehicle making good 27 m/s at 25 m/s of airspeed (a bias, a speed not yet reached):
    forecast in a calm wind estimate as it is without one, at its speed and at another; and
    on its straight route in a steady wind, at its own speed, too (what it makes good beyond
    its airspeed at the fix is counted on every leg, and every leg is the same)."""
    a = _straight("A", (0.0, 0.0), 60.0, groundspeed_m_s=27.0)
    times = np.arange(0.0, 300.0, 10.0)
    for speed, until_s in ((25.0, math.inf), (18.0, 120.0), (30.0, 40.0)):
        calm = dataclasses.replace(a, wind=Wind()).positions(times, speed, 5.0, until_s)
        without = a.positions(times, speed, 5.0, until_s)
        assert np.allclose(calm, without, atol=1e-6), (speed, until_s)
    steady = dataclasses.replace(a, wind=Wind(5.0, -3.0)).positions(times, 25.0, 5.0)
    assert np.allclose(steady, a.positions(times, 25.0, 5.0), atol=1e-6)


def test_a_pair_resolved_in_the_wind_keeps_apart_as_flown_in_it() -> None:
    """The paper's 10 m/s case: A turns out of a crosswind into a headwind across B's way,
    and crosses 18 s ahead of B. Forecast at A's present ground speed, A would be across
    in time and nothing is resolved, and as flown they come under the separation; forecast
    in the wind, the resolution keeps them apart as flown (the test's own steps)."""
    d_s = 500.0
    gs = math.sqrt(30.0**2 - 10.0**2)  # north in a wind to the east
    a = _in_wind("A", [(0.0, -3_000.0), (0.0, 0.0), (-8_000.0, 0.0)], groundspeed_m_s=gs)
    b = _in_wind("B", [(-1_500.0, -5_630.0), (-1_500.0, 8_000.0)], groundspeed_m_s=gs)

    def least_m(res: Resolution | None) -> float:
        def speed(vid: str) -> Callable[[float], float]:
            if res is None or res.vehicle != vid:
                return lambda _u: 30.0
            return lambda u: res.airspeed_m_s if 5.0 <= u < res.until_s else 30.0

        flown = zip(_fly_in_wind(a, 400, speed("A")), _fly_in_wind(b, 400, speed("B")), strict=True)
        return min(math.dist(p, q) for p, q in flown)

    calm = [dataclasses.replace(x, wind=None) for x in (a, b)]
    assert resolve(*calm, now_s=0.0, separation_m=d_s, look_ahead_s=300.0) is None
    assert least_m(None) < d_s - 100.0
    res = resolve(a, b, now_s=0.0, separation_m=d_s, look_ahead_s=300.0, response_s=5.0)
    assert res is not None and res.keeps_separation, res
    assert least_m(res) >= d_s, res


@pytest.mark.parametrize("runout_m", [300.0, 0.0])
def test_a_pair_that_meets_in_its_run_outs_past_the_slots_is_predicted_before_them(
    runout_m: float,
) -> None:
    """A east and B west on lines 100 m apart, their goals 500 m apart either side of where
    they would meet: 500 m apart at their slots, they meet 100 m apart 250 m into the
    run-outs they fly straight on past the goals (``runout_m``). Five seconds before the
    slots the watch predicts it (its look-ahead runs through the run-outs), 10 s after the
    slots, 100 m apart (worked out here from the fixes' positions and velocities); with no
    run-out nothing is foreseen past the slots."""
    data = small_scenario(threats=[], arrival={"kind": "simultaneous", "required_s": 1500})
    for v, (e0, n0, e1, n1) in zip(
        data["vehicles"], ((2000, 20000, 19750, 20000), (38000, 20100, 20250, 20100)), strict=True
    ):
        v["start"] = {"east_m": e0, "north_m": n0, "alt_m": 500}
        v["goal"] = {"east_m": e1, "north_m": n1, "alt_m": 500}
    team = timed_alike(data)
    team.config = FlightConfig(runout_m=runout_m)
    a, b = (team.members[vid] for vid in ("A", "B"))
    for x in (a, b):
        airborne(team, x.vehicle_id, x.takeoff_s)
    t = a.target_s - 5.0
    said: list[act.Report] = []
    fixes = {}
    for x in (a, b):
        _, s_m, level = x.schedule.state_at(t)
        fixes[x.vehicle_id] = f = fix(team, x.vehicle_id, s_m, t, level)
        said += reports(team.handle(f, t), EventKind.CONFLICT)
    predicted = [r for r in said if r.reason.startswith("predicted")]
    if runout_m == 0.0:
        assert not predicted, [r.reason for r in said]
        return
    (p,) = predicted
    fa, fb = fixes["A"], fixes["B"]
    (ea, na), (eb, nb) = (team.frame.to_local(f.lat_deg, f.lon_deg) for f in (fa, fb))
    assert fa.ve_m_s is not None and fb.ve_m_s is not None
    closing = fa.ve_m_s - fb.ve_m_s
    meet_s = t + float(eb - ea) / closing
    assert meet_s > a.target_s + 5.0  # past the slots
    assert p.payload["at_s"] == pytest.approx(meet_s, abs=0.5)
    assert p.payload["distance_m"] == pytest.approx(float(nb - na), abs=1.0)


def test_a_vehicle_flying_a_resolution_is_forecast_slowing_for_its_slot_once_released() -> None:
    """B flies a resolution at 30 m/s until 20 s; its slot then asks 20 m/s (5.4 km left in
    270 s, by this test's arithmetic). Forecast as it flies, it is there at 30 m/s until its
    release and at 20 m/s after it; A, 500 m behind on B's route at 25 m/s, is forecast to
    come up behind it (at 25 - 20 m/s: within 330 m 54 s after B's release). Forecast
    at 30 m/s all along, as before, B drew away from A and the two were never screened."""
    b0 = _straight("B", (0.0, 500.0), 0.0, groundspeed_m_s=30.0, airspeed_m_s=30.0)
    b0 = dataclasses.replace(b0, horizon_s=20.0 + (6_000.0 - 20.0 * 30.0) / 20.0)
    b0 = dataclasses.replace(
        b0,
        route_s_m=np.array([0.0, 6_000.0]),
        route_east_m=np.array([0.0, 0.0]),
        route_north_m=np.array([500.0, 6_500.0]),
    )
    resume = b0.slot_airspeed_m_s(20.0)
    assert resume == pytest.approx(20.0, abs=1e-6)
    b = dataclasses.replace(b0, until_s=20.0, resume_m_s=resume)
    t = np.array([10.0, 20.0, 120.0])
    north = b.positions(t, b.airspeed_m_s, 5.0)[:, 1]
    assert north == pytest.approx([500.0 + 300.0, 500.0 + 600.0, 500.0 + 600.0 + 2_000.0])
    a = _straight("A", (0.0, 0.0), 0.0)  # 25 m/s, 500 m behind
    for forecast_b, screened in ((b, True), (b0, False)):
        screen = Forecasts(["A", "B"], look_ahead_s=240.0, response_s=5.0)
        screen.update(a, 0.0)
        screen.update(forecast_b, 0.0)
        assert (screen.near("A", 330.0, 0.0) == ["B"]) is screened


def test_a_resolution_is_held_as_long_as_the_slot_can_be_made_from_the_speed_it_asks() -> None:
    """A flies 19 m/s towards the place a re-plan timed it through; its slot, 150 s ahead
    along 3,750 m, asks 25 m/s on the mean. Held at its lowest speed (18 m/s), the rest of
    the way is flown, in this test's own arithmetic, within half the room its range leaves
    above that mean. Judged on the 19 m/s it flew (1 m/s from its lowest, 11 m/s of room
    above), it was held 127 s and was left 63 m/s to fly."""
    a = _straight("A", (0.0, 0.0), 0.0, airspeed_m_s=19.0, groundspeed_m_s=19.0, horizon_s=150.0)
    a = dataclasses.replace(a, route_s_m=np.array([0.0, 3_750.0]))
    a = dataclasses.replace(a, route_north_m=np.array([0.0, 3_750.0]))
    assert a.slot_airspeed_m_s(0.0) == pytest.approx(25.0)
    held_s = longest_hold_s(a, a.airspeed_min_m_s, 0.0)
    needed_m_s = (3_750.0 - 18.0 * held_s) / (150.0 - held_s)
    assert needed_m_s <= 25.0 + 0.5 * (30.0 - 25.0) + 1e-6
    assert held_s > 30.0  # and it is held, as long as that allows

"""ArduPlane-like autopilot: mission execution, modes and commands, on the simulated clock."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from sitl_stub.autopilot import (
    Autopilot,
    CurrentChanged,
    Event,
    ItemReached,
    Mode,
    NavStatus,
    Text,
)
from sitl_stub.items import MissionItem
from sitl_stub.model import AirframeParams, FlightState, Wind, displace_deg, offset_ne_m

DT = 0.1
HOME = (47.0, 8.0, 400.0)
REL = int(mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
AMSL = int(mav.MAV_FRAME_GLOBAL_INT)
WP = int(mav.MAV_CMD_NAV_WAYPOINT)
TAKEOFF = int(mav.MAV_CMD_NAV_TAKEOFF)
LOITER_TURNS = int(mav.MAV_CMD_NAV_LOITER_TURNS)
LOITER_TIME = int(mav.MAV_CMD_NAV_LOITER_TIME)
LAND = int(mav.MAV_CMD_NAV_LAND)
CHANGE_SPEED = int(mav.MAV_CMD_DO_CHANGE_SPEED)


def at(north_m: float, east_m: float) -> tuple[float, float]:
    return displace_deg(HOME[0], HOME[1], 0.0, north_m, east_m)


def item(
    seq: int,
    command: int,
    north_m: float = 0.0,
    east_m: float = 0.0,
    alt_m: float = 0.0,
    *,
    frame: int = REL,
    p1: float = 0.0,
    p2: float = 0.0,
    p3: float = 0.0,
    p4: float = 0.0,
) -> MissionItem:
    lat, lon = at(north_m, east_m)
    return MissionItem(
        seq, frame, command, 0, 1, p1, p2, p3, p4, round(lat * 1e7), round(lon * 1e7), alt_m
    )


def home_item() -> MissionItem:
    return item(0, WP, frame=AMSL, alt_m=HOME[2])


def takeoff(seq: int = 1, alt_m: float = 60.0) -> MissionItem:
    return MissionItem(seq, REL, TAKEOFF, z=alt_m)


def change_speed(seq: int, speed_m_s: float) -> MissionItem:
    return MissionItem(seq, REL, CHANGE_SPEED, param1=0, param2=speed_m_s, param3=-1)


def make(
    wind: Wind | None = None, seed: int = 1, params: AirframeParams | None = None
) -> Autopilot:
    return Autopilot(
        params=params or AirframeParams(),
        home_lat_deg=HOME[0],
        home_lon_deg=HOME[1],
        home_alt_m=HOME[2],
        heading_deg=0.0,
        wind=wind or Wind(),
        rng=np.random.default_rng(seed),
    )


@dataclass
class Trace:
    states: list[FlightState] = field(default_factory=list)
    seqs: list[int] = field(default_factory=list)
    events: list[tuple[float, Event]] = field(default_factory=list)

    def reached(self) -> list[int]:
        return [e.seq for _, e in self.events if isinstance(e, ItemReached)]

    def current_changes(self) -> list[int]:
        return [e.seq for _, e in self.events if isinstance(e, CurrentChanged)]

    def time_of(self, event: Event) -> float:
        return next(t for t, e in self.events if e == event)

    def texts(self) -> list[str]:
        return [e.text for _, e in self.events if isinstance(e, Text)]


def run(
    ap: Autopilot,
    seconds: float,
    until: Callable[[Autopilot], bool] | None = None,
    trace: Trace | None = None,
) -> Trace:
    trace = trace if trace is not None else Trace()
    for _ in range(round(seconds / DT)):
        for ev in ap.step(DT):
            trace.events.append((ap.state.time_s, ev))
        trace.states.append(ap.state)
        trace.seqs.append(ap.current_seq)
        if until is not None and until(ap):
            break
    return trace


def dist_m(s: FlightState, north_m: float, east_m: float) -> float:
    lat, lon = at(north_m, east_m)
    return math.hypot(*offset_ne_m(s.lat_deg, s.lon_deg, 0.0, lat, lon))


def airborne_in_auto(ap: Autopilot, mission: list[MissionItem], seq: int) -> Trace:
    ap.replace_mission(mission)
    assert ap.set_mode(Mode.AUTO)
    assert ap.arm() == (True, "")
    trace = run(ap, 600, until=lambda a: a.current_seq == seq)
    assert ap.current_seq == seq
    return trace


# ---------------------------------------------------------------------- the full mission

LOITER_CENTRE = (-1500.0, 0.0)
CORNER = (1500.0, 1500.0)
LAND_POINT = (1000.0, -1500.0)
FULL_MISSION = [
    home_item(),
    takeoff(1, 60.0),
    item(2, WP, 1500, 0, 100),
    item(3, WP, *CORNER, 100),  # 90-degree corner: east then south
    item(4, WP, 0, 1500, 120),
    change_speed(5, 28.0),
    item(6, WP, -1500, 1500, 120),
    item(7, LOITER_TURNS, *LOITER_CENTRE, 120, p1=2, p3=150),
    item(8, WP, -500, -1500, 80),
    item(9, LAND, *LAND_POINT, 0),
]


@pytest.fixture(scope="module")
def full_mission() -> tuple[Autopilot, Trace]:
    ap = make(Wind(3.0, math.radians(250.0), gust_m_s=0.5))
    ap.replace_mission(FULL_MISSION)
    assert ap.set_mode(Mode.AUTO)
    assert ap.arm() == (True, "")
    trace = run(ap, 1500, until=lambda a: not a.armed)
    return ap, trace


def test_full_mission_reaches_items_in_order(full_mission: tuple[Autopilot, Trace]) -> None:
    _, trace = full_mission
    # DO_CHANGE_SPEED (5) is reported too, as ArduPlane does; NAV_LAND never "completes".
    assert trace.reached() == [1, 2, 3, 4, 5, 6, 7, 8]
    assert trace.current_changes() == [1, 2, 3, 4, 6, 7, 8, 9]
    texts = trace.texts()
    assert "Mission: 2 WP" in texts
    assert any(t.startswith("Reached waypoint #2 dist ") for t in texts)
    assert "Mission: 5 ChangeSpeed" in texts


def test_full_mission_takeoff_reaches_its_altitude(full_mission: tuple[Autopilot, Trace]) -> None:
    _, trace = full_mission
    t = trace.time_of(ItemReached(1))
    s = next(s for s in trace.states if s.time_s >= t)
    assert s.alt_m - HOME[2] == pytest.approx(60.0, abs=2.0)
    assert not s.on_ground


def isa_tas_per_eas(alt_m: float) -> float:
    """sqrt(rho0/rho) in the ISA troposphere (T = 288.15 K - 6.5 K/km; rho ~ T^4.2559)."""
    temp_ratio = 1.0 - 6.5e-3 * alt_m / 288.15
    return float(temp_ratio ** (-4.2559 / 2.0))


def test_full_mission_speed_change_takes_effect(full_mission: tuple[Autopilot, Trace]) -> None:
    """The commanded speeds are equivalent airspeed: true airspeed is EAS x EAS2TAS."""
    _, trace = full_mission
    t = trace.time_of(ItemReached(5))
    before = next(s for s in trace.states if s.time_s >= t)
    after = next(s for s in trace.states if s.time_s >= t + 15.0)
    assert before.airspeed_m_s / isa_tas_per_eas(before.alt_m) == pytest.approx(22.0, abs=0.5)
    assert after.airspeed_m_s / isa_tas_per_eas(after.alt_m) == pytest.approx(28.0, abs=0.5)


def test_full_mission_cuts_the_corner(full_mission: tuple[Autopilot, Trace]) -> None:
    _, trace = full_mission
    t = trace.time_of(ItemReached(3))
    s = next(s for s in trace.states if s.time_s >= t)
    # Reached at the turn distance (min(WP_RADIUS, L1 distance)), before the corner ...
    assert 60.0 < dist_m(s, *CORNER) <= 91.0
    assert s.heading_rad == pytest.approx(math.pi / 2, abs=0.15)  # still eastbound
    # ... and the aircraft never flies over the corner point.
    assert min(dist_m(x, *CORNER) for x in trace.states) > 25.0


def test_full_mission_loiters_two_turns_at_150_m(full_mission: tuple[Autopilot, Trace]) -> None:
    _, trace = full_mission
    t0 = trace.time_of(CurrentChanged(7))
    t1 = trace.time_of(ItemReached(7))
    loiter = [s for s in trace.states if t0 <= s.time_s <= t1]
    radii = np.array([dist_m(s, *LOITER_CENTRE) for s in loiter])
    start = int(np.argmax(np.abs(radii - 150.0) < 0.05 * 150.0))
    on_circle = radii[start:]
    assert abs(on_circle.mean() - 150.0) < 0.1 * 150.0
    assert np.all(np.abs(on_circle - 150.0) < 0.2 * 150.0)
    headings = np.unwrap([s.heading_rad for s in loiter[start:]])
    turned = headings[-1] - headings[0]  # clockwise (param3 > 0): heading increases
    # Two full turns, then ArduPlane keeps circling until it heads for the next waypoint.
    assert 4 * math.pi - 0.3 <= turned <= 6 * math.pi + 0.3
    assert "Loiter orbit complete" in trace.texts()


def test_full_mission_lands_and_disarms(full_mission: tuple[Autopilot, Trace]) -> None:
    ap, trace = full_mission
    s = ap.state
    assert s.on_ground
    assert not ap.armed
    assert s.alt_m == HOME[2]
    assert s.groundspeed_m_s == pytest.approx(0.0, abs=0.1)
    assert ap.current_seq == 9
    assert dist_m(s, *LAND_POINT) < 500.0
    texts = trace.texts()
    assert any(t.startswith("Flare") for t in texts)
    assert "Landed" in texts


def test_full_mission_altitude_slews_between_waypoints(
    full_mission: tuple[Autopilot, Trace],
) -> None:
    _, trace = full_mission
    # Leg 8 -> 9 descends from 120 m to the runway: midway the target is about halfway down.
    t8 = trace.time_of(ItemReached(7))
    t9 = trace.time_of(ItemReached(8))
    mid = next(s for s in trace.states if s.time_s >= (t8 + t9) / 2)
    assert 85.0 < mid.alt_m - HOME[2] < 115.0


# ---------------------------------------------------------------------- determinism


def test_same_seed_same_flight_and_events() -> None:
    def go(seed: int) -> tuple[FlightState, list[tuple[float, Event]]]:
        ap = make(Wind(6.0, 1.0, gust_m_s=2.0), seed=seed)
        trace = airborne_in_auto(ap, FULL_MISSION, 3)
        run(ap, 60, trace=trace)
        return ap.state, trace.events

    assert go(7) == go(7)
    assert go(7)[0] != go(8)[0]


def test_one_big_step_equals_substeps() -> None:
    a, b = make(), make()
    for ap in (a, b):
        ap.replace_mission(FULL_MISSION)
        ap.set_mode(Mode.AUTO)
        ap.arm()
    for _ in range(50):
        a.step(1.0)
    for _ in range(500):
        b.step(0.1)
    assert a.state.time_s == pytest.approx(b.state.time_s)
    assert a.state.lat_deg == pytest.approx(b.state.lat_deg, abs=1e-9)
    assert a.state.alt_m == pytest.approx(b.state.alt_m, abs=1e-6)


# ---------------------------------------------------------------------- ground, arming


def test_disarmed_on_the_ground_stays_put() -> None:
    ap = make(Wind(10.0, 0.0, gust_m_s=3.0))
    ap.replace_mission(FULL_MISSION)
    assert ap.set_mode(Mode.AUTO)
    run(ap, 60)
    assert (ap.state.lat_deg, ap.state.lon_deg, ap.state.alt_m) == HOME
    assert ap.state.on_ground
    assert ap.current_seq == 1


def test_armed_outside_a_takeoff_does_not_move() -> None:
    ap = make()
    assert ap.arm() == (True, "")
    assert ap.arm() == (True, "")  # re-arming is accepted
    run(ap, 20)
    assert (ap.state.lat_deg, ap.state.lon_deg) == HOME[:2]


def test_disarm_refused_in_flight_unless_forced() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 2)
    ok, reason = ap.disarm()
    assert not ok
    assert reason
    assert ap.armed
    assert ap.disarm(force=True) == (True, "")
    run(ap, 300, until=lambda a: a.state.on_ground)
    assert ap.state.on_ground
    assert ap.state.alt_m == HOME[2]


# ---------------------------------------------------------------------- mission edits


def test_replace_mission_in_auto_keeps_current_seq() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 3)
    moved = list(FULL_MISSION)
    moved[3] = item(3, WP, 1500, 1800, 100)
    ap.replace_mission(moved)
    assert ap.current_seq == 3
    trace = run(ap, 300, until=lambda a: a.current_seq == 4)
    pending = [e for _, e in trace.events if isinstance(e, CurrentChanged)]
    assert pending == [CurrentChanged(4)]
    t = trace.time_of(ItemReached(3))
    s = next(s for s in trace.states if s.time_s >= t)
    assert dist_m(s, 1500, 1800) < 95.0  # the new position of item 3 was flown to


def test_replace_with_identical_mission_does_not_restart_the_loiter() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 7)
    run(ap, 70)  # well into the loiter
    before = ap.state.time_s
    ap.replace_mission(list(FULL_MISSION))
    trace = run(ap, 300, until=lambda a: a.current_seq == 8)
    assert trace.reached() == [7]
    # Two turns of ~34 s each started before the replacement: it ends well within 80 s.
    assert trace.time_of(ItemReached(7)) - before < 80.0


def test_replace_with_shorter_mission_clamps_the_index() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 6)
    ap.replace_mission(FULL_MISSION[:4])
    assert ap.current_seq == 3
    assert ap.mode == Mode.AUTO


def test_mission_end_without_land_switches_to_rtl_and_circles_home() -> None:
    ap = make()
    mission = [home_item(), takeoff(1, 50.0), item(2, WP, 1200, 0, 80)]
    ap.replace_mission(mission)
    ap.set_mode(Mode.AUTO)
    ap.arm()
    trace = run(ap, 400)
    assert trace.reached() == [1, 2]
    assert "Mission complete, changing mode to RTL" in trace.texts()
    assert ap.mode == Mode.RTL
    tail = trace.states[-600:]
    radii = [dist_m(s, 0.0, 0.0) for s in tail]
    assert max(radii) < 1.3 * ap.params.loiter_radius_m
    assert min(radii) > 0.7 * ap.params.loiter_radius_m
    assert ap.state.alt_m - HOME[2] == pytest.approx(ap.params.rtl_altitude_m, abs=3.0)


def test_set_current_jumps_and_rejects_out_of_range() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 2)
    assert not ap.set_current(10)
    assert not ap.set_current(-1)
    assert ap.set_current(6)
    assert ap.current_seq == 6
    events = ap.step(DT)
    assert CurrentChanged(6) in events
    assert Text(6, "Mission: 6 WP") in events


def test_set_current_to_a_do_item_runs_it_and_goes_to_the_next_nav() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 2)
    assert ap.set_current(5)
    events = ap.step(DT)
    assert ItemReached(5) in events
    assert ap.current_seq == 6
    assert ap.target_airspeed_m_s == 28.0


def test_set_current_when_not_in_auto_sets_the_resume_point() -> None:
    ap = make()
    ap.replace_mission(FULL_MISSION)
    assert ap.set_current(4)
    assert ap.current_seq == 4
    assert ap.step(DT) == [CurrentChanged(4)]


def test_start_mission_switches_to_auto_at_item_one() -> None:
    ap = make()
    ap.replace_mission(FULL_MISSION)
    ap.set_current(4)
    assert ap.start_mission()
    assert ap.mode == Mode.AUTO
    assert ap.current_seq == 1
    assert not make().start_mission()  # no mission


# ---------------------------------------------------------------------- speed commands


def test_change_speed_refused_outside_auto_and_guided() -> None:
    ap = make()
    for mode in (Mode.MANUAL, Mode.FBWA, Mode.LOITER, Mode.RTL, Mode.CIRCLE):
        assert ap.set_mode(mode)
        assert not ap.change_speed(0, 25.0)


def test_change_speed_in_auto() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 2)
    assert ap.change_speed(0, 26.0)
    run(ap, 20)
    assert ap.target_airspeed_m_s == 26.0
    assert ap.eas_m_s == pytest.approx(26.0, abs=0.3)
    assert ap.nav.aspd_error_m_s == pytest.approx(0.0, abs=0.3)
    assert not ap.change_speed(0, 35.0)  # outside [min, max]: refused, as ArduPlane
    assert ap.change_speed(0, -1.0)  # no change
    assert ap.target_airspeed_m_s == 26.0
    assert ap.change_speed(0, -2.0)  # back to cruise
    run(ap, 1)
    assert ap.target_airspeed_m_s == ap.params.airspeed_cruise_m_s
    assert not ap.change_speed(2, 3.0)  # climb speed: not supported


def test_change_altitude_holds_until_the_next_waypoint_brings_the_missions_back() -> None:
    """ArduPlane/GCS_Mavlink.cpp: handle_command_int_DO_CHANGE_ALTITUDE ->
    handle_change_alt_request sets next_WP_loc's altitude (and reset_offset_altitude: it is
    gone to at once, not along the leg's slope); the next NAV command starts from its own
    item, so the mission's altitude comes back at the next waypoint."""
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 3)  # on the 1.5 km leg to the corner, at 100 m
    assert ap.change_altitude(HOME[2] + 250.0)
    trace = run(ap, 400, until=lambda a: a.current_seq != 3)
    on_leg = [st.alt_m for st, seq in zip(trace.states, trace.seqs, strict=True) if seq == 3]
    assert max(on_leg) > HOME[2] + 200.0  # climbing to 250 m, not on the leg's 100 m
    assert ap.current_seq == 4
    # The next leg's item (120 m) takes over: down from the climb to it.
    back = HOME[2] + 120.0
    run(ap, 120, until=lambda a: a.current_seq != 4 or abs(a.state.alt_m - back) < 3.0)
    assert ap.current_seq == 4 and ap.state.alt_m == pytest.approx(back, abs=3.0)
    assert not ap.change_altitude(math.nan)


@pytest.mark.parametrize(("lo_m_s", "hi_m_s", "ask_m_s"), [(12, 29.2, 29.2), (15.7, 30, 15.7)])
def test_change_speed_to_a_limit_that_is_no_float32_is_accepted(
    lo_m_s: float, hi_m_s: float, ask_m_s: float
) -> None:
    """ArduPlane/commands_logic.cpp ``do_change_speed`` compares the command's float with the
    REAL32 AIRSPEED_MIN/MAX: asking for the limit itself is met, as the command arrives over
    MAVLink as that same float32 (29.2 is held as 29.2000008, 15.7 as 15.6999998)."""
    ap = make(params=replace(AirframeParams(), airspeed_min_m_s=lo_m_s, airspeed_max_m_s=hi_m_s))
    airborne_in_auto(ap, FULL_MISSION, 2)
    sent = float(np.float32(ask_m_s))  # what COMMAND_LONG's param2 decodes to
    assert sent != ask_m_s
    assert ap.change_speed(0, sent)
    assert not ap.change_speed(0, float(np.float32(hi_m_s + 0.1)))
    assert not ap.change_speed(0, float(np.float32(lo_m_s - 0.1)))


def test_mode_change_resets_the_commanded_airspeed() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 2)
    assert ap.change_speed(0, 26.0)
    assert ap.set_mode(Mode.LOITER)
    assert ap.set_mode(Mode.AUTO)
    run(ap, 1)
    assert ap.target_airspeed_m_s == ap.params.airspeed_cruise_m_s


def test_groundspeed_change_sets_a_minimum_groundspeed_into_a_headwind() -> None:
    ap = make(Wind(12.0, 0.0))  # from the north; the first legs fly north
    airborne_in_auto(ap, FULL_MISSION, 2)
    run(ap, 10)
    assert ap.state.groundspeed_m_s < 12.0
    assert ap.change_speed(1, 15.0)
    assert ap.params.min_groundspeed_m_s == 15.0
    run(ap, 25)
    assert ap.state.groundspeed_m_s == pytest.approx(15.0, abs=0.7)
    assert ap.state.airspeed_m_s == pytest.approx(27.0, abs=0.7)  # true airspeed


# ---------------------------------------------------------------------- modes


def test_unsupported_modes_are_refused() -> None:
    ap = make()
    assert not ap.set_mode(Mode.ACRO)
    assert not ap.set_mode(Mode.TRAINING)
    assert not ap.set_mode(Mode.AUTOTUNE)
    assert ap.mode == Mode.MANUAL


def test_loiter_mode_circles_the_current_position() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 3)
    s0 = ap.state
    assert ap.set_mode(Mode.LOITER)
    trace = run(ap, 200)
    radii = [
        math.hypot(*offset_ne_m(s0.lat_deg, s0.lon_deg, 0.0, s.lat_deg, s.lon_deg))
        for s in trace.states[-600:]
    ]
    r = ap.params.loiter_radius_m
    assert 0.85 * r < float(np.mean(radii)) < 1.15 * r
    assert ap.state.alt_m == pytest.approx(s0.alt_m, abs=3.0)


def test_guided_circles_the_target_and_reports_item_zero() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 2)
    lat, lon = at(500.0, -800.0)
    assert not ap.set_guided_target(lat, lon, HOME[2] + 150.0)  # not in GUIDED
    assert ap.set_mode(Mode.GUIDED)
    assert ap.set_guided_target(lat, lon, HOME[2] + 150.0)
    trace = run(ap, 250)
    assert trace.reached() == [0]
    radii = [dist_m(s, 500.0, -800.0) for s in trace.states[-500:]]
    assert max(radii) < 1.3 * ap.params.loiter_radius_m
    assert ap.state.alt_m == pytest.approx(HOME[2] + 150.0, abs=3.0)
    assert ap.change_speed(0, 25.0)


def test_rtl_mode_returns_home_at_rtl_altitude() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 4)
    assert ap.set_mode(Mode.RTL)
    run(ap, 300)
    assert dist_m(ap.state, 0.0, 0.0) < 1.3 * ap.params.loiter_radius_m
    assert ap.state.alt_m - HOME[2] == pytest.approx(100.0, abs=3.0)


def test_takeoff_mode_climbs_then_loiters() -> None:
    ap = make()
    assert ap.set_mode(Mode.TAKEOFF)
    ap.arm()
    trace = run(ap, 200)
    assert any(t.startswith("Takeoff complete") for t in trace.texts())
    assert ap.state.alt_m - HOME[2] == pytest.approx(50.0, abs=3.0)


def test_loiter_time_waits_at_least_the_time_on_the_circle() -> None:
    ap = make()
    mission = [
        home_item(),
        takeoff(1, 50.0),
        item(2, LOITER_TIME, 600, 0, 80, p1=60.0, p3=-120.0),
        item(3, WP, 600, 2000, 80),
    ]
    trace = airborne_in_auto(ap, mission, 2)
    run(ap, 400, until=lambda a: a.current_seq == 3, trace=trace)
    assert trace.reached() == [1, 2]
    t = trace.time_of(ItemReached(2)) - trace.time_of(CurrentChanged(2))
    assert 60.0 < t < 60.0 + 2 * math.pi * 120.0 / 22.0 + 60.0
    # Counter-clockwise (param3 < 0): heading decreases while circling.
    s0 = next(s for s in trace.states if s.time_s >= trace.time_of(ItemReached(2)) - 30)
    s1 = next(s for s in trace.states if s.time_s >= trace.time_of(ItemReached(2)) - 25)
    assert math.remainder(s1.heading_rad - s0.heading_rad, 2 * math.pi) < 0


def test_nav_status_reports_the_waypoint() -> None:
    ap = make()
    airborne_in_auto(ap, FULL_MISSION, 2)
    run(ap, 20)
    nav = ap.nav
    assert isinstance(nav, NavStatus)
    assert abs(math.remainder(nav.target_bearing_deg, 360.0)) < 5.0  # WP 2 is due north
    assert abs(math.remainder(nav.nav_bearing_deg, 360.0)) < 10.0
    assert 0.0 < nav.wp_dist_m < 1500.0
    assert abs(nav.xtrack_error_m) < 10.0
    assert nav.alt_error_m == pytest.approx(0.0, abs=15.0)


def test_wind_and_params_can_be_changed() -> None:
    ap = make()
    ap.set_wind(Wind(5.0, 0.0))
    assert ap.wind == Wind(5.0, 0.0)
    ap.set_params(replace(ap.params, wp_radius_m=50.0))
    assert ap.params.wp_radius_m == 50.0
    assert ap.home == HOME
    assert ap.mission == ()


def test_counters_count_arms_from_disarmed_and_changes_into_auto() -> None:
    ap = make()
    ap.replace_mission([home_item(), takeoff(1, 60.0), item(2, WP, 1500, 0, 100)])
    assert ap.arm() == (True, "") and ap.arm() == (True, "")  # the second arm is no transition
    assert ap.set_mode(Mode.AUTO) and ap.set_mode(Mode.AUTO)  # re-selecting AUTO is no change
    assert ap.start_mission(1)  # already in AUTO: restarts the mission, no mode change
    assert ap.set_mode(Mode.LOITER) and ap.start_mission(1)  # MISSION_START enters AUTO
    assert ap.counters == {"arms": 1, "auto_mode_changes": 2}
    assert ap.disarm(force=True) == (True, "") and ap.arm() == (True, "")
    assert ap.counters["arms"] == 2

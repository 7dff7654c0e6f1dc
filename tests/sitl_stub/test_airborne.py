"""Airborne starts: a vehicle already flying, in LOITER over its start, when the simulator
starts; then a mission without NAV_TAKEOFF, with DO_LAND_START before its NAV_LAND."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from pymavlink.dialects.v20 import ardupilotmega as mav

from sitl_stub.__main__ import homes_from_args, homes_from_scenario, main, parse_args
from sitl_stub.api import Home, SimTeam
from sitl_stub.autopilot import (
    CRASH_TEXT,
    SEVERITY_INFO,
    Autopilot,
    CurrentChanged,
    ItemReached,
    Mode,
    Text,
)
from sitl_stub.items import MissionItem
from sitl_stub.mission_server import MissionServer, Result, validate_item
from sitl_stub.model import AirframeParams, FlightState, Wind, offset_ne_m
from sitl_stub.storage import stored_item
from sitl_stub.truth import TruthRecorder
from tests.sitl_stub.test_autopilot import (
    AMSL,
    HOME,
    LAND,
    WP,
    Trace,
    at,
    dist_m,
    home_item,
    item,
    run,
)
from tests.sitl_stub.test_cli import PAPER, stub_cli
from tests.sitl_stub.test_mission_server import LINK, count, item_int

LAND_START = int(mav.MAV_CMD_DO_LAND_START)
AIR_ALT = HOME[2] + 300.0
FIX = (3000.0, -1000.0)  # the last waypoint: where the glide begins
FIX_HEIGHT_M = 200.0
TOUCHDOWN = (3000.0, -4000.0)  # due west of the fix


def airborne(
    wind: Wind | None = None, heading_deg: float = 90.0, params: AirframeParams | None = None
) -> Autopilot:
    return Autopilot(
        params=params or AirframeParams(),
        home_lat_deg=HOME[0],
        home_lon_deg=HOME[1],
        home_alt_m=HOME[2],
        heading_deg=heading_deg,
        airborne_alt_m=AIR_ALT,
        wind=wind or Wind(),
        rng=np.random.default_rng(7),
    )


def land_start(seq: int, north_m: float, east_m: float, alt_m: float) -> MissionItem:
    return item(seq, LAND_START, north_m, east_m, alt_m)


def landing_mission() -> list[MissionItem]:
    """No NAV_TAKEOFF: home, two waypoints, DO_LAND_START, NAV_LAND. The DO_LAND_START is
    put somewhere else (over home, low) on purpose: its location must not be flown."""
    return [
        stored_item(it)
        for it in (
            home_item(),
            item(1, WP, 2000.0, 1000.0, 300.0),
            item(2, WP, *FIX, FIX_HEIGHT_M),
            land_start(3, 0.0, 0.0, 50.0),
            item(4, LAND, *TOUCHDOWN, 0.0),
        )
    ]


def ne_of(s: FlightState) -> tuple[float, float]:
    """North/east (m) of a state from home."""
    return offset_ne_m(HOME[0], HOME[1], 0.0, s.lat_deg, s.lon_deg)


def along_across(
    s: FlightState, a: tuple[float, float], b: tuple[float, float]
) -> tuple[float, float]:
    """Fraction along a->b and signed metres across it of a state."""
    n, e = ne_of(s)
    ln, le = b[0] - a[0], b[1] - a[1]
    length = math.hypot(ln, le)
    rn, re = n - a[0], e - a[1]
    return (rn * ln + re * le) / (length * length), (rn * le - re * ln) / length


# ---------------------------------------------------------------------- the start


def test_airborne_start_is_armed_in_loiter_off_the_ground_at_cruise() -> None:
    ap = airborne()
    s = ap.state
    assert ap.armed and ap.mode == Mode.LOITER
    assert not s.on_ground
    assert (s.lat_deg, s.lon_deg, s.alt_m) == (HOME[0], HOME[1], AIR_ALT)
    assert ap.home == HOME  # home stays on the ground
    # The cruise airspeed (EAS) as true airspeed at AIR_ALT, on the start heading.
    assert ap.eas_m_s == pytest.approx(AirframeParams().airspeed_cruise_m_s)
    assert s.airspeed_m_s > ap.eas_m_s
    assert math.degrees(s.course_rad) == pytest.approx(90.0)
    # Nobody armed it: the counters count what a ground station made it do.
    assert ap.counters == {"arms": 0, "auto_mode_changes": 0}


def test_airborne_start_circles_its_start_point_holding_altitude() -> None:
    """LOITER as ArduPlane enters it in flight (ArduPlane/mode_loiter.cpp _enter:
    do_loiter_at_location): around the start point at WP_LOITER_RAD, clockwise."""
    radius = AirframeParams().loiter_radius_m
    ap = airborne(Wind(4.0, math.radians(250.0)))
    trace = run(ap, 120.0)
    assert ap.mode == Mode.LOITER and ap.armed and ap.crash_time_s is None
    circling = [s for s in trace.states if s.time_s >= 20.0]
    d = np.array([dist_m(s, 0.0, 0.0) for s in circling])
    assert np.all(np.abs(d - radius) < 0.1 * radius)
    assert abs(d.mean() - radius) < 0.03 * radius
    assert all(abs(s.alt_m - AIR_ALT) < 1.0 and not s.on_ground for s in trace.states)
    turned = np.unwrap([s.heading_rad for s in circling])
    assert turned[-1] - turned[0] > 4.0 * math.pi  # more than two clockwise circles
    assert not trace.events


def test_airborne_start_is_flying_for_disarm_and_crash_detection() -> None:
    ap = airborne()
    assert not ap.disarm()[0]  # refused in flight, as for a vehicle that took off
    # Sent into the ground, it crashes (not "lands"): wrecked, then detected and disarmed.
    assert ap.set_mode(Mode.GUIDED)
    assert ap.set_guided_target(*at(1500.0, 0.0), HOME[2] - 100.0)
    trace = run(ap, 200.0, until=lambda a: a.crash_detected)
    assert ap.crash_time_s is not None and ap.crash_detected and not ap.armed
    assert CRASH_TEXT in trace.texts()


def test_airborne_start_on_the_wire_and_in_the_truth_log() -> None:
    team = SimTeam.create(homes=[Home(*HOME, 90.0, AIR_ALT), Home(*HOME)], step_s=0.1)
    team.step(10)
    flying, parked = team.vehicles
    hb = flying.message("HEARTBEAT")
    assert hb.custom_mode == Mode.LOITER
    assert hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.system_status == mav.MAV_STATE_ACTIVE
    pos = flying.message("GLOBAL_POSITION_INT")
    assert pos.relative_alt == pytest.approx((AIR_ALT - HOME[2]) * 1000.0, abs=500.0)
    # A vehicle without an airborne altitude starts as before: on the ground, disarmed.
    hb = parked.message("HEARTBEAT")
    assert hb.custom_mode == Mode.MANUAL and not hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
    out = io.StringIO()
    recorder = TruthRecorder(out, team.vehicles, team.clock)
    recorder.record()
    recorder.flush()
    rows = [json.loads(line) for line in out.getvalue().splitlines()]
    assert [(r["armed"], r["on_ground"], r["crashed"]) for r in rows] == [
        (True, False, False),
        (False, True, False),
    ]
    assert rows[0]["alt_m"] == pytest.approx(AIR_ALT, abs=0.5)


# ---------------------------------------------------------------------- then a mission


@pytest.fixture(scope="module")
def flown() -> tuple[Autopilot, Trace, float]:
    """An airborne vehicle given the landing mission after 60 s of LOITER, then AUTO."""
    ap = airborne(Wind(5.0, math.radians(250.0)))
    run(ap, 60.0)
    ap.replace_mission(landing_mission())
    assert ap.set_mode(Mode.AUTO)
    auto_s = ap.state.time_s
    trace = run(ap, 1500.0, until=lambda a: not a.armed)
    return ap, trace, auto_s


def test_auto_from_airborne_loiter_starts_at_item_one_from_where_it_is(
    flown: tuple[Autopilot, Trace, float],
) -> None:
    """AUTO entered in flight with no takeoff in the mission: ArduPlane/mode_auto.cpp _enter
    (next_WP_loc = prev_WP_loc = current_loc; mission.start_or_resume()),
    libraries/AP_Mission/AP_Mission.cpp start (the first NAV item after home, item 1), and
    ArduPlane/commands_logic.cpp verify_nav_wp: without cross-tracking (Mode::enter sets
    next_wp_crosstrack false) it flies from where it is straight at the waypoint."""
    ap, trace, auto_s = flown
    # Reported with the first step in AUTO.
    assert trace.events[:2] == [
        (pytest.approx(auto_s + 0.1), Text(SEVERITY_INFO, "Mission: 1 WP")),
        (pytest.approx(auto_s + 0.1), CurrentChanged(1)),
    ]
    assert ap.counters == {"arms": 0, "auto_mode_changes": 1}
    leg = [s for s in trace.states if s.time_s < trace.time_of(ItemReached(1))]
    # Straight at waypoint 1 once turned towards it.
    wp1 = at(2000.0, 1000.0)
    for s in leg[300:]:
        n, e = offset_ne_m(s.lat_deg, s.lon_deg, 0.0, *wp1)
        err = (math.degrees(math.atan2(e, n) - s.course_rad) + 180.0) % 360.0 - 180.0
        assert abs(err) < 5.0


def test_first_leg_is_flown_at_the_waypoint_and_the_next_along_the_line() -> None:
    """ArduPlane/commands_logic.cpp verify_nav_wp: update_waypoint(current_loc, ...) on the
    first leg (no cross-track error), update_waypoint(prev_WP_loc, ...) on the next."""
    ap = airborne(Wind(5.0, math.radians(250.0)))
    run(ap, 30.0)
    ap.replace_mission(landing_mission())
    assert ap.set_mode(Mode.AUTO)
    xtrack: dict[int, list[float]] = {1: [], 2: []}
    for _ in range(6000):
        ap.step(0.1)
        if ap.current_seq > 2:
            break
        xtrack[ap.current_seq].append(ap.nav.xtrack_error_m)
    assert len(xtrack[1]) > 100 and all(x == 0.0 for x in xtrack[1])
    assert max(abs(x) for x in xtrack[2]) > 1.0


def test_airborne_mission_flies_the_items_in_order_and_runs_land_start_as_a_marker(
    flown: tuple[Autopilot, Trace, float],
) -> None:
    """DO_LAND_START is a no-op in AUTO (ArduPlane/commands_logic.cpp start_command: break;
    verify_command: true), reported as other DO items; NAV_LAND is never reached."""
    _, trace, _ = flown
    assert trace.reached() == [1, 2, 3]
    assert trace.current_changes() == [1, 2, 4]
    texts = trace.texts()
    assert texts.index("Mission: 2 WP") < texts.index("Mission: 3 LandStart")
    assert texts.index("Mission: 3 LandStart") < texts.index("Mission: 4 Land")
    assert trace.time_of(ItemReached(2)) == trace.time_of(ItemReached(3))


def test_airborne_mission_glides_from_the_fix_and_lands_on_the_touchdown_point(
    flown: tuple[Autopilot, Trace, float],
) -> None:
    """NAV_LAND after the fix: the glide slope runs from the fix (the previous NAV waypoint,
    ArduPlane/commands_logic.cpp do_land: set_next_WP), not from DO_LAND_START's location;
    touchdown on the fix -> touchdown course, then roll-out and disarm."""
    ap, trace, _ = flown
    t_fix = trace.time_of(ItemReached(2))
    approach = [s for s in trace.states if s.time_s > t_fix and not s.on_ground]
    assert sum(0.1 <= along_across(s, FIX, TOUCHDOWN)[0] <= 0.9 for s in approach) > 1000
    for s in approach:
        frac, across = along_across(s, FIX, TOUCHDOWN)
        if 0.1 <= frac <= 0.9:
            assert s.alt_m - HOME[2] == pytest.approx(FIX_HEIGHT_M * (1.0 - frac), abs=10.0)
        if frac >= 0.3:
            assert abs(across) < 10.0
        assert dist_m(s, 0.0, 0.0) > 2000.0  # never towards DO_LAND_START's point
    touchdown = next(s for s in trace.states if s.time_s > t_fix and s.on_ground)
    beyond_m = dist_m(touchdown, *TOUCHDOWN)
    frac, across = along_across(touchdown, FIX, TOUCHDOWN)
    assert beyond_m < 50.0 and frac > 1.0 and abs(across) < 5.0
    texts = trace.texts()
    assert any(t.startswith("Flare") for t in texts)
    assert texts[-2:] == ["Landed", "Throttle disarmed"]
    assert not ap.armed and ap.state.on_ground and ap.crash_time_s is None
    assert CRASH_TEXT not in texts


def test_loiter_then_auto_again_resumes_the_mission_at_its_item() -> None:
    """AUTO after LOITER resumes at the interrupted NAV item (AP_Mission.cpp resume)."""
    ap = airborne()
    ap.replace_mission(landing_mission())
    assert ap.set_mode(Mode.AUTO)
    run(ap, 600.0, until=lambda a: a.current_seq == 2)
    assert ap.set_mode(Mode.LOITER)
    run(ap, 60.0)
    assert ap.set_mode(Mode.AUTO)
    trace = run(ap, 5.0)
    assert ap.current_seq == 2 and trace.texts()[0] == "Mission: 2 WP"


def test_mission_start_command_in_the_air_starts_at_item_one() -> None:
    ap = airborne()
    ap.replace_mission(landing_mission())
    assert ap.start_mission()
    trace = run(ap, 1.0)
    assert ap.mode == Mode.AUTO and ap.current_seq == 1
    assert trace.current_changes() == [1]


# ---------------------------------------------------------------------- DO_LAND_START upload


def test_land_start_is_accepted_and_kept_with_its_location() -> None:
    """AP_Mission.cpp keeps DO_LAND_START's location (stored_in_location) and no params."""
    sent = MissionItem(
        5, int(mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT), LAND_START, x=471234567, y=81234567, z=250.0
    )
    assert validate_item(sent) == mav.MAV_MISSION_ACCEPTED
    kept = stored_item(sent)
    assert (kept.command, kept.x, kept.y, kept.z) == (LAND_START, 471234567, 81234567, 250.0)
    assert kept.frame == mav.MAV_FRAME_GLOBAL_RELATIVE_ALT
    assert (kept.param1, kept.param2, kept.param3, kept.param4) == (0.0, 0.0, 0.0, 0.0)
    # MAV_FRAME_MISSION (no location) is accepted too; a bad latitude or frame is not.
    no_location = MissionItem(5, int(mav.MAV_FRAME_MISSION), LAND_START)
    assert validate_item(no_location) == mav.MAV_MISSION_ACCEPTED
    assert validate_item(MissionItem(5, AMSL, LAND_START, x=910_000_000)) == (
        mav.MAV_MISSION_INVALID_PARAM5_X
    )
    assert validate_item(MissionItem(5, int(mav.MAV_FRAME_LOCAL_NED), LAND_START)) == (
        mav.MAV_MISSION_UNSUPPORTED_FRAME
    )


@pytest.mark.parametrize("ardupilot", [True, False])
def test_land_start_uploads_and_reads_back(ardupilot: bool) -> None:
    server = MissionServer(system_id=1, component_id=1, ardupilot_storage=ardupilot)
    msgs = [
        item_int(0),
        item_int(1, z=300.0),
        item_int(2, command=LAND_START, z=120.0),
        item_int(3, command=LAND, z=0.0),
    ]
    server.handle(count(len(msgs)), LINK, 0.0)
    for m in msgs:
        reaction = server.handle(m, LINK, 0.0)
    assert reaction.sends[-1].msg.type == mav.MAV_MISSION_ACCEPTED
    assert server.last_result is Result.SUCCESS
    kept = server.items(0)[2]
    assert (kept.command, kept.x, kept.y, kept.z) == (LAND_START, msgs[2].x, msgs[2].y, 120.0)
    want = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT if ardupilot else msgs[2].frame
    assert kept.frame == want


# ---------------------------------------------------------------------- the CLI


def test_home_with_an_airborne_altitude_parses() -> None:
    (home,) = homes_from_args(parse_args(["--home", "-35.36,149.16,584,90,900"]))
    assert home == Home(-35.36, 149.16, 584.0, 90.0, 900.0)
    shared = homes_from_args(parse_args(["--vehicles", "2", "--home", "-35.36,149.16,584,90,900"]))
    assert [h.airborne_alt_m for h in shared] == [900.0, 900.0]
    assert shared[1].alt_m == 584.0
    # Three or four numbers: on the ground, as before.
    assert homes_from_args(parse_args(["--home", "-35.36,149.16,584"])) == [
        Home(-35.36, 149.16, 584.0, 0.0, None)
    ]
    assert homes_from_args(parse_args(["--home", "-35.36,149.16,584,90"])) == [
        Home(-35.36, 149.16, 584.0, 90.0)
    ]


@pytest.mark.parametrize(
    ("home", "message"),
    [
        ("-35.36,149.16,584,90,500", "--home '-35.36,149.16,584,90,500': airborne altitude"),
        ("-35.36,149.16,584,90,590", "--home '-35.36,149.16,584,90,590': airborne altitude"),
        ("-35.36,149.16,584,90,nan", "--home: '-35.36,149.16,584,90,nan' has a non-finite"),
        ("-35.36,149.16,584,90,high", "--home: '-35.36,149.16,584,90,high' is not a list"),
        ("-35.36,149.16,584,90,900,1", "--home needs 3 to 5 comma-separated numbers"),
    ],
)
def test_bad_airborne_altitude_is_refused_naming_home(
    home: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["--home", home]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sitl_stub: error: ") and message in err, err


def test_home_refuses_an_airborne_altitude_under_ten_metres_up() -> None:
    assert Home(0.0, 0.0, 100.0, 0.0, 110.0).airborne_alt_m == 110.0
    for bad in (109.9, 50.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="airborne altitude"):
            Home(0.0, 0.0, 100.0, 0.0, bad)


async def test_cli_airborne_vehicle_reports_armed_loiter_in_the_air() -> None:
    from tests.sitl_stub.conftest import Client

    async with stub_cli(
        "--tcp-base", "0", "--speedup", "5", "--home", "-35.36,149.16,584,90,884"
    ) as cli:
        c = await Client.connect(cli.ports[0])
        try:
            hb = await c.recv("HEARTBEAT", timeout=10)
            pos = await c.recv("GLOBAL_POSITION_INT", timeout=10)
        finally:
            await c.close()
    assert hb.custom_mode == Mode.LOITER and hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
    assert pos.relative_alt == pytest.approx(300_000, abs=2000)
    assert pos.alt == pytest.approx(884_000, abs=2000)


# ---------------------------------------------------------------------- scenarios


def test_scenario_vehicle_marked_airborne_starts_in_the_air(tmp_path: Path) -> None:
    doc = yaml.safe_load(PAPER.read_text())
    doc["vehicles"][0]["airborne"] = True
    path = tmp_path / "airborne.yaml"
    path.write_text(yaml.safe_dump(doc))
    ground_homes = homes_from_scenario(str(PAPER), 3)
    homes = homes_from_scenario(str(path), 3)
    start_alt_m = doc["vehicles"][0]["start"]["alt_m"]
    # Home is as for a ground start (the terrain at the start, the heading to the goal) ...
    assert [(h.lat_deg, h.lon_deg, h.alt_m, h.heading_deg) for h in homes] == [
        (h.lat_deg, h.lon_deg, h.alt_m, h.heading_deg) for h in ground_homes
    ]
    # ... and the airborne one flies at its start's alt_m, the others are on the ground.
    assert [h.airborne_alt_m for h in homes] == [start_alt_m, None, None]
    assert homes[0].alt_m < start_alt_m - 100.0
    team = SimTeam.create(homes=homes)
    team.step(5)
    flying, parked, _ = team.vehicles
    assert flying.autopilot.mode == Mode.LOITER and flying.autopilot.armed
    assert not flying.true_state.on_ground
    assert flying.true_state.alt_m == pytest.approx(start_alt_m, abs=0.5)
    assert parked.true_state.on_ground and not parked.autopilot.armed

"""Tests of planner.mission: compiling a route into ArduPlane mission items."""

from __future__ import annotations

import dataclasses
import math
import struct
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from planner import mission as m
from planner.errors import PlannerError
from planner.mission import (
    Loiter,
    MissionError,
    MissionItem,
    SpeedChange,
    Waypoint,
    arduplane_loiter_radius_m,
    compile_mission,
    describe,
    items_equal,
    stored_alt_m,
)

HOME = Waypoint(-35.363261, 149.165230, 584.0)
ROUTE = (
    Waypoint(-35.350000, 149.170000, 700.0),
    Waypoint(-35.340000, 149.180000, 720.5),
    Waypoint(-35.330000, 149.190000, 750.0),
    Waypoint(-35.320000, 149.200000, 650.25),
)
WP, TAKEOFF, SPEED, LOITER, LAND = (
    m.MAV_CMD_NAV_WAYPOINT,
    m.MAV_CMD_NAV_TAKEOFF,
    m.MAV_CMD_DO_CHANGE_SPEED,
    m.MAV_CMD_NAV_LOITER_TURNS,
    m.MAV_CMD_NAV_LAND,
)
REL_INT = m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def mission(**kw: Any) -> list[MissionItem]:
    args: dict[str, Any] = {"home": HOME, "waypoints": ROUTE, "takeoff_alt_m": 60.0}
    args.update(kw)
    return compile_mission(**args)


@pytest.mark.parametrize(
    "name",
    [
        "MAV_CMD_NAV_WAYPOINT",
        "MAV_CMD_NAV_LOITER_UNLIM",
        "MAV_CMD_NAV_LOITER_TURNS",
        "MAV_CMD_NAV_LOITER_TIME",
        "MAV_CMD_NAV_RETURN_TO_LAUNCH",
        "MAV_CMD_NAV_LAND",
        "MAV_CMD_NAV_TAKEOFF",
        "MAV_CMD_DO_CHANGE_SPEED",
        "MAV_FRAME_GLOBAL",
        "MAV_FRAME_MISSION",
        "MAV_FRAME_GLOBAL_RELATIVE_ALT",
        "MAV_FRAME_GLOBAL_INT",
        "MAV_FRAME_GLOBAL_RELATIVE_ALT_INT",
        "MAV_FRAME_GLOBAL_TERRAIN_ALT",
        "MAV_FRAME_GLOBAL_TERRAIN_ALT_INT",
        "MAV_MISSION_TYPE_MISSION",
    ],
)
def test_constants_match_pymavlink_dialect(name: str) -> None:
    assert getattr(m, name) == getattr(mavlink2, name)


def test_item_order_with_two_speed_changes_and_a_loiter() -> None:
    items = mission(
        speeds=[SpeedChange(2, 26.0), SpeedChange(0, 22.0)],
        loiters=[Loiter(1, -35.341, 149.181, 720.5, turns=2, radius_m=150.0)],
    )
    assert [(it.seq, it.command, it.frame) for it in items] == [
        (0, WP, m.MAV_FRAME_GLOBAL),
        (1, TAKEOFF, REL_INT),
        (2, SPEED, m.MAV_FRAME_MISSION),
        (3, WP, REL_INT),
        (4, WP, REL_INT),
        (5, LOITER, REL_INT),
        (6, SPEED, m.MAV_FRAME_MISSION),
        (7, WP, REL_INT),
        (8, WP, REL_INT),
    ]
    assert all(it.current == 0 and it.autocontinue == 1 for it in items)
    assert all(it.mission_type == m.MAV_MISSION_TYPE_MISSION for it in items)
    assert [(it.param1, it.param2, it.param3, it.param4) for it in (items[2], items[6])] == [
        (0.0, 22.0, -1.0, 0.0),
        (0.0, 26.0, -1.0, 0.0),
    ]
    assert (items[2].x, items[2].y, items[2].z) == (0, 0, 0.0)
    assert (items[1].param1, items[1].z) == (15.0, 60.0)
    # the goal is the last NAV item; without land there is nothing after it
    assert (items[-1].x, items[-1].y) == (-353200000, 1492000000)


def test_home_is_item_zero_in_global_frame_amsl() -> None:
    home = mission()[0]
    assert home == MissionItem(
        seq=0, frame=0, command=16, current=0, autocontinue=1,
        param1=0.0, param2=0.0, param3=0.0, param4=0.0,
        x=-353632610, y=1491652300, z=584.0,
    )  # fmt: skip


def test_takeoff_lat_lon_is_home_and_alt_is_above_home() -> None:
    takeoff = mission(takeoff_alt_m=45.0, takeoff_pitch_deg=12.0)[1]
    assert (takeoff.x, takeoff.y, takeoff.z, takeoff.param1) == (-353632610, 1491652300, 45.0, 12.0)


def test_relative_altitudes_are_above_home() -> None:
    items = mission()
    assert [it.z for it in items if it.command == WP][1:] == [116.0, 136.5, 166.0, 66.25]


@pytest.mark.parametrize(
    ("frame", "takeoff_frame"),
    [(m.MAV_FRAME_GLOBAL, 3), (m.MAV_FRAME_GLOBAL_INT, 6), (m.MAV_FRAME_GLOBAL_RELATIVE_ALT, 3)],
)
def test_takeoff_uses_the_relative_frame_of_the_same_kind(frame: int, takeoff_frame: int) -> None:
    items = mission(frame=frame)
    assert items[1].frame == takeoff_frame and items[1].z == 60.0
    assert [it.frame for it in items[2:]] == [frame] * len(ROUTE)


def test_amsl_frame_carries_alt_m() -> None:
    items = mission(frame=m.MAV_FRAME_GLOBAL_INT)
    assert [it.z for it in items[2:]] == [wp.alt_m for wp in ROUTE]


def test_terrain_frame_subtracts_terrain_under_each_point() -> None:
    def ground(lat: float, lon: float) -> float:
        return 500.0 + 1000.0 * (lat + 35.0)  # 150 m at -35.35, 180 m at -35.32

    items = mission(frame=m.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, terrain_alt_m=ground)
    zs = [it.z for it in items[2:]]
    expected = [wp.alt_m - ground(wp.lat_deg, wp.lon_deg) for wp in ROUTE]
    assert zs == pytest.approx(expected, abs=1e-9)
    assert items[1].frame == REL_INT


def test_terrain_frame_without_terrain_is_an_error() -> None:
    with pytest.raises(MissionError, match="frame 11 is a terrain frame: terrain_alt_m"):
        mission(frame=m.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)


def test_lat_lon_are_rounded_to_the_nearest_1e7() -> None:
    wps = [
        Waypoint(47.00000006, 8.00000004, 600.0),
        Waypoint(-47.00000006, -8.00000004, 600.0),
        Waypoint(89.99999999, -179.99999996, 600.0),
    ]
    items = compile_mission(home=HOME, waypoints=wps, takeoff_alt_m=50.0)
    assert [(it.x, it.y) for it in items[2:]] == [
        (470000001, 80000000),
        (-470000001, -80000000),
        (900000000, -1800000000),
    ]
    assert items[2].lat_deg == pytest.approx(47.0000001, abs=1e-12)
    assert items[3].lon_deg == pytest.approx(-8.0, abs=1e-12)


@pytest.mark.parametrize(("clockwise", "sign"), [(True, 1.0), (False, -1.0)])
def test_loiter_turns_sign_is_positive_for_clockwise(clockwise: bool, sign: float) -> None:
    lo = Loiter(3, -35.321, 149.201, 700.0, turns=3, radius_m=300.0, clockwise=clockwise)
    items = mission(loiters=[lo])
    loiter = items[-1]
    assert loiter.command == LOITER and loiter.frame == REL_INT
    params = (loiter.param1, loiter.param2, loiter.param3, loiter.param4)
    assert params == (3.0, 0.0, sign * 300.0, 1.0)
    assert (loiter.x, loiter.y, loiter.z) == (-353210000, 1492010000, 116.0)
    assert items[-2].command == WP and items[-2].x == -353200000  # right after the goal


def test_land_at_home_and_at_a_point() -> None:
    at_home = mission(land=True)[-1]
    assert (at_home.command, at_home.frame, at_home.x, at_home.y, at_home.z) == (
        LAND,
        REL_INT,
        -353632610,
        1491652300,
        0.0,
    )
    at_point = mission(land=Waypoint(-35.31, 149.21, 590.0))[-1]
    assert (at_point.command, at_point.x, at_point.y, at_point.z) == (
        LAND,
        -353100000,
        1492100000,
        6.0,
    )
    assert mission(land=False)[-1].command == WP


def test_speed_change_before_the_first_waypoint_follows_takeoff() -> None:
    items = mission(speeds=[SpeedChange(0, 24.0)])
    assert [it.command for it in items[:4]] == [WP, TAKEOFF, SPEED, WP]


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        (
            {"waypoints": [*ROUTE[:3], Waypoint(95.0, 8.0, 500.0)]},
            "waypoint 3: lat_deg 95 is outside [-90, 90]",
        ),
        (
            {"waypoints": [Waypoint(45.0, 181.5, 500.0)]},
            "waypoint 0: lon_deg 181.5 is outside [-180, 180]",
        ),
        (
            {"waypoints": [Waypoint(45.0, 8.0, math.nan)]},
            "waypoint 0: alt_m nan is outside [-500, 20000]",
        ),
        ({"home": Waypoint(45.0, 8.0, 30000.0)}, "home: alt_m 30000 is outside [-500, 20000]"),
        ({"waypoints": []}, "waypoints: at least one waypoint (the goal) is required"),
        ({"takeoff_alt_m": 0.0}, "takeoff_alt_m 0 is outside (0, 20000]"),
        ({"takeoff_pitch_deg": 60.0}, "takeoff_pitch_deg 60 is outside (0, 45]"),
        ({"frame": 7}, "frame 7 is not supported; use one of 0, 3, 5, 6, 10, 11"),
        (
            {"speeds": [SpeedChange(2, 45.0)], "airspeed_limits_m_s": (20.0, 30.0)},
            "speed change before waypoint 2: airspeed 45 m/s is outside [20, 30]",
        ),
        (
            {"speeds": [SpeedChange(1, -3.0)]},
            "speed change before waypoint 1: airspeed -3 m/s must be > 0",
        ),
        (
            {"speeds": [SpeedChange(7, 25.0)]},
            "speed change 0: before_waypoint 7 is not a waypoint index in [0, 3]",
        ),
        (
            {"speeds": [SpeedChange(1, 25.0), SpeedChange(1, 24.0)]},
            "speed change before waypoint 1: a second speed change for the same waypoint",
        ),
        (
            {"airspeed_limits_m_s": (30.0, 20.0)},
            "airspeed_limits_m_s (30, 20) must satisfy 0 < min <= max",
        ),
        (
            {"loiters": [Loiter(3, -35.32, 149.2, 700.0, turns=0, radius_m=100.0)]},
            "loiter after waypoint 3: turns must be >= 1 (got 0)",
        ),
        (
            {"loiters": [Loiter(3, -35.32, 149.2, 700.0, turns=300, radius_m=100.0)]},
            "loiter after waypoint 3: turns 300 is above 255",
        ),
        (
            {"loiters": [Loiter(-1, -35.32, 149.2, 700.0, turns=1, radius_m=100.0)]},
            "loiter 0: after_waypoint -1 is not a waypoint index in [0, 3]",
        ),
        (
            {"loiters": [Loiter(2, -35.32, 149.2, 700.0, turns=1, radius_m=0.5)]},
            "loiter after waypoint 2: radius_m 0.5 must be >= 1",
        ),
        (
            {"loiters": [Loiter(2, -35.32, 149.2, 700.0, turns=1, radius_m=3000.0)]},
            "loiter after waypoint 2: radius_m 3000 is above 2550, the largest loiter radius "
            "ArduPlane stores",
        ),
        (
            {"loiters": [Loiter(2, -35.32, 149.2, 700.0, turns=1, radius_m=333.0)]},
            "loiter after waypoint 2: radius_m 333 would fly as 330 (ArduPlane stores loiter "
            "radii in 10 m steps above 255 m)",
        ),
        (
            {"loiters": [Loiter(2, -35.32, 149.2, 700.0, turns=1, radius_m=80.5)]},
            "loiter after waypoint 2: radius_m 80.5 would fly as 80 (ArduPlane stores loiter "
            "radii in whole metres)",
        ),
        (
            {"loiters": [Loiter(2, -95.0, 149.2, 700.0, turns=1, radius_m=80.0)]},
            "loiter after waypoint 2: lat_deg -95 is outside [-90, 90]",
        ),
        ({"land": Waypoint(0.0, 200.0, 0.0)}, "land: lon_deg 200 is outside [-180, 180]"),
    ],
)
def test_validation_errors_name_the_item_and_field(kw: dict[str, Any], message: str) -> None:
    with pytest.raises(MissionError) as info:
        mission(**kw)
    assert str(info.value) == message
    assert "\n" not in str(info.value)
    assert isinstance(info.value, PlannerError) and isinstance(info.value, ValueError)


def test_terrain_callable_giving_nan_is_named() -> None:
    with pytest.raises(MissionError, match=r"^waypoint 0: terrain_alt_m gave nan at the point$"):
        mission(frame=m.MAV_FRAME_GLOBAL_TERRAIN_ALT, terrain_alt_m=lambda lat, lon: math.nan)


@pytest.mark.parametrize(
    ("asked", "stored"),
    [(1.0, 1.0), (80.0, 80.0), (80.9, 80.0), (255.0, 255.0), (255.5, 250.0), (260.0, 260.0),
     (333.0, 330.0), (2550.0, 2550.0), (9000.0, 2550.0), (-120.0, 120.0)],
)  # fmt: skip
def test_arduplane_loiter_radius_packing(asked: float, stored: float) -> None:
    assert arduplane_loiter_radius_m(asked) == stored


def _f32(v: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", v))[0])


def test_items_equal_compares_as_the_wire_does() -> None:
    items = mission(speeds=[SpeedChange(1, 23.3)])
    f32 = [dataclasses.replace(it, param2=_f32(it.param2)) for it in items]
    assert f32[3].param2 != items[3].param2
    assert items_equal(items, f32)
    moved = [*items[:-1], dataclasses.replace(items[-1], x=items[-1].x + 1)]
    assert not items_equal(items, moved)
    higher = [*items[:-1], dataclasses.replace(items[-1], z=items[-1].z + 0.01)]
    assert not items_equal(items, higher)
    assert items_equal(items, higher, alt_tol_m=0.02)
    assert not items_equal(items, items[:-1])
    other_home = [dataclasses.replace(items[0], x=0, z=0.0), *items[1:]]
    assert not items_equal(items, other_home)
    assert items_equal(items, other_home, compare_home=False)
    nan_yaw = [dataclasses.replace(it, param4=math.nan) for it in items]
    assert items_equal(nan_yaw, list(nan_yaw)) and not items_equal(items, nan_yaw)


def test_items_survive_a_mavlink2_mission_item_int_round_trip() -> None:
    items = mission(
        speeds=[SpeedChange(1, 23.3)],
        loiters=[Loiter(2, -35.331, 149.191, 750.1, turns=2, radius_m=120.0, clockwise=False)],
        land=True,
    )
    sender = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    receiver = mavlink2.MAVLink(None)
    back = []
    for it in items:
        msg = mavlink2.MAVLink_mission_item_int_message(
            1, 1, it.seq, it.frame, it.command, it.current, it.autocontinue,
            it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z, it.mission_type,
        )  # fmt: skip
        (decoded,) = receiver.parse_buffer(msg.pack(sender))
        fields = {f.name: getattr(decoded, f.name) for f in dataclasses.fields(MissionItem)}
        back.append(MissionItem(**fields))
    assert items_equal(items, back)
    assert back != items  # float32 on the wire: exact equality would be the wrong test


def test_compiled_missions_pass_the_stubs_ardupilot_item_checks() -> None:
    from sitl_stub.items import MissionItem as StubItem
    from sitl_stub.mission_server import validate_item

    items = mission(
        speeds=[SpeedChange(0, 22.0), SpeedChange(3, 27.0)],
        loiters=[Loiter(1, -35.341, 149.181, 720.5, turns=4, radius_m=2000.0)],
        land=True,
    )
    results = {validate_item(StubItem(**dataclasses.asdict(it))) for it in items}
    assert results == {int(mavlink2.MAV_MISSION_ACCEPTED)}


def test_describe_is_one_line_per_item_with_a_header() -> None:
    items = mission(speeds=[SpeedChange(1, 25.0)], land=True)
    text = describe(items)
    lines = text.splitlines()
    assert len(lines) == len(items) + 1
    assert lines[1].split()[:3] == ["0", "HOME", "GLOBAL"]
    assert lines[2].split()[:3] == ["1", "NAV_TAKEOFF", "REL_ALT_INT"]
    assert "DO_CHANGE_SPEED" in lines[4] and "NAV_LAND" in lines[-1]
    assert "-35.3632610" in lines[1]


_lat = st.floats(-89.9, 89.9)
_lon = st.floats(-179.9, 179.9)
_alt = st.floats(-400.0, 19_000.0)
_points = st.builds(Waypoint, _lat, _lon, _alt)


@st.composite
def _routes(draw: st.DrawFn) -> dict[str, Any]:
    wps = draw(st.lists(_points, min_size=1, max_size=8))
    n = len(wps)
    speed_idx = draw(st.lists(st.integers(0, n - 1), unique=True, max_size=n))
    loiter_idx = draw(st.lists(st.integers(0, n - 1), unique=True, max_size=n))
    speeds = [SpeedChange(i, draw(st.floats(10.0, 40.0))) for i in speed_idx]
    loiters = [
        Loiter(
            i,
            draw(_lat),
            draw(_lon),
            draw(_alt),
            turns=draw(st.integers(1, 255)),
            radius_m=float(draw(st.integers(1, 255))),
            clockwise=draw(st.booleans()),
        )
        for i in loiter_idx
    ]
    return {
        "home": draw(_points),
        "waypoints": wps,
        "takeoff_alt_m": draw(st.floats(1.0, 500.0)),
        "speeds": speeds,
        "loiters": loiters,
        "land": draw(st.booleans()),
    }


@given(_routes())
def test_compiled_mission_structure_holds_for_any_valid_route(route: dict[str, Any]) -> None:
    items = compile_mission(**route)
    home: Waypoint = route["home"]
    wps: list[Waypoint] = route["waypoints"]
    assert [it.seq for it in items] == list(range(len(items)))
    assert len(items) == 2 + len(wps) + len(route["speeds"]) + len(route["loiters"]) + route["land"]
    nav = [it for it in items[2:] if it.command == WP]
    assert [(it.x, it.y) for it in nav] == [
        (round(w.lat_deg * 1e7), round(w.lon_deg * 1e7)) for w in wps
    ]
    # Altitudes come in the whole centimetres ArduPilot keeps (truncated towards zero).
    for it, w in zip(nav, wps, strict=True):
        want = w.alt_m - home.alt_m
        ulp = abs(want) * 2.0**-23  # float32 steps
        assert abs(it.z - want) < 0.0101 + 8 * ulp
        assert abs(it.z) <= abs(want) + 8 * ulp + 1e-6
        assert stored_alt_m(it.z) == stored_alt_m(want)  # ArduPilot keeps the same cm
    for k, it in enumerate(items):
        if it.command == SPEED:
            assert items[k + 1].command == WP
        if it.command == LOITER:
            assert items[k - 1].command == WP
            assert it.param3 != 0.0 and it.param4 == 1.0
    for it in items:
        assert abs(it.x) <= 900_000_000 and abs(it.y) <= 1_800_000_000

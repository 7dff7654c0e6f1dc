"""Mission items read back in the form ArduPilot stores them (AP_Mission.cpp)."""

from __future__ import annotations

import struct
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from sitl_stub.items import MissionItem
from sitl_stub.mission_server import MissionServer
from sitl_stub.storage import stored_item
from tests.sitl_stub.conftest import Client, wp
from tests.sitl_stub.test_mission_server import LINK, count, item_int

HOME = Home(-35.36, 149.16, 584.0)


def as_float32(v: float) -> float:
    """What a C float holds for v (via the struct module, independent of the code under test)."""
    return float(struct.unpack("<f", struct.pack("<f", v))[0])


def item(command: int, frame: int = 6, z: float = 100.0, **params: float) -> MissionItem:
    return MissionItem(
        seq=1, frame=frame, command=command, x=-353600000, y=1491600000, z=z, current=1,
        autocontinue=0, **params,
    )  # fmt: skip


def test_takeoff_known_answer_from_arduplane() -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp, mavlink_int_to_mission_cmd and
    mission_cmd_to_mavlink_int. ArduPlane V4.7.0-dev read NAV_TAKEOFF sent as frame 6,
    z 827.496 back as frame 3, z 827.49 (float32), param1 as a whole number."""
    got = stored_item(item(mavlink2.MAV_CMD_NAV_TAKEOFF, z=827.496, param1=15.7, param4=3.0))
    assert got.frame == mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT
    assert got.z == as_float32(827.49)
    assert (got.param1, got.param2, got.param3, got.param4) == (15.0, 0.0, 0.0, 0.0)
    assert (got.current, got.autocontinue) == (0, 1)
    assert (got.x, got.y) == (-353600000, 1491600000)


@pytest.mark.parametrize(
    ("z_sent", "cm"),
    [(100.0, 10000), (0.019, 1), (-0.019, -1), (12.3456, 1234), (583.999, 58399), (-7.5, -750)],
)
def test_altitude_is_whole_centimetres_truncated_toward_zero(z_sent: float, cm: int) -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp, mavlink_int_to_mission_cmd
    (``location.alt = packet.z * 100.0f``, int32) and mission_cmd_to_mavlink_int
    (``packet.z = alt * 0.01f``)."""
    got = stored_item(item(mavlink2.MAV_CMD_NAV_WAYPOINT, z=z_sent))
    assert got.z == as_float32(as_float32(cm) * as_float32(0.01))


@pytest.mark.parametrize(
    ("sent", "read"),
    [(0, 0), (2, 0), (5, 0), (6, 3), (3, 3), (10, 10), (11, 10)],
)
def test_frames_read_back_without_the_int_variant(sent: int, read: int) -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp: relative_alt / terrain_alt flags set in
    mavlink_int_to_mission_cmd, frame rebuilt from them in mission_cmd_to_mavlink_int."""
    assert stored_item(item(mavlink2.MAV_CMD_NAV_WAYPOINT, frame=sent)).frame == read


def test_waypoint_keeps_acceptance_and_pass_by_as_bytes() -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp, NAV_WAYPOINT (ArduPlane build):
    p1 = (min(255, passby) << 8) | min(255, acceptance); param1 and param4 are not stored."""
    got = stored_item(
        item(mavlink2.MAV_CMD_NAV_WAYPOINT, param1=7.0, param2=30.9, param3=400.0, param4=90.0)
    )
    assert (got.param1, got.param2, got.param3, got.param4) == (0.0, 30.0, 255.0, 0.0)


@pytest.mark.parametrize(
    ("radius", "read"),
    [(80.0, 80.0), (80.7, 80.0), (255.0, 255.0), (255.5, 250.0), (305.0, 300.0), (-300.0, -300.0),
     (3000.0, 2550.0)],
)  # fmt: skip
def test_loiter_turns_radius_whole_metres_then_ten_metre_steps(radius: float, read: float) -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp, NAV_LOITER_TURNS: turns in the low byte of
    p1, radius in the high byte (above 255 m radius * 0.1 with type_specific_bits bit 0, read
    back times 10), direction in loiter_ccw, param4 as the xtrack flag."""
    got = stored_item(
        item(mavlink2.MAV_CMD_NAV_LOITER_TURNS, param1=3.6, param3=radius, param4=0.3)
    )
    assert (got.param1, got.param2, got.param3, got.param4) == (3.0, 0.0, read, 1.0)


def test_loiter_time_keeps_seconds_and_only_the_direction() -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp, NAV_LOITER_TIME: p1 = seconds (uint16), no
    room for the radius; mission_cmd_to_mavlink_int sends param3 = -1 (ccw) or 1."""
    ccw = stored_item(item(mavlink2.MAV_CMD_NAV_LOITER_TIME, param1=45.9, param3=-120.0))
    cw = stored_item(item(mavlink2.MAV_CMD_NAV_LOITER_TIME, param1=45.0, param3=0.0, param4=1.0))
    assert (ccw.param1, ccw.param3, ccw.param4) == (45.0, -1.0, 0.0)
    assert (cw.param1, cw.param3, cw.param4) == (45.0, 1.0, 1.0)


def test_land_reads_param4_as_direction_sign() -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp, NAV_LAND: p1 = abort altitude (uint16),
    loiter_ccw = is_negative(param4) unless NaN; read back as param4 = -1 or 1."""
    neg = stored_item(item(mavlink2.MAV_CMD_NAV_LAND, param1=30.5, param4=-0.5))
    nan = stored_item(item(mavlink2.MAV_CMD_NAV_LAND, param4=float("nan")))
    assert (neg.param1, neg.param4) == (30.0, -1.0)
    assert (nan.param1, nan.param4) == (0.0, 1.0)


def test_change_speed_reads_back_frame_0_without_position() -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp, DO_CHANGE_SPEED: Change_Speed_Command
    {uint8_t speed_type; float target_ms; float throttle_pct}; not stored_in_location, so the
    frame and x/y/z read back as 0 (AP_Mission::get_item zeroes them)."""
    got = stored_item(
        item(
            mavlink2.MAV_CMD_DO_CHANGE_SPEED,
            frame=3,
            param1=0.0,
            param2=21.3,
            param3=-1.0,
            param4=5.0,
        )
    )
    assert (got.frame, got.x, got.y, got.z) == (0, 0, 0, 0.0)
    assert (got.param1, got.param2, got.param3, got.param4) == (0.0, as_float32(21.3), -1.0, 0.0)


def test_download_marks_current_where_command_id_equals_nav_index() -> None:
    """Follows libraries/GCS_MAVLink/MissionItemProtocol_Waypoints.cpp, get_item:
    ``current = (cmd.id == mission.get_current_nav_cmd().index)`` (the command ID, not seq)."""
    nav_index: list[int | None] = [None]
    server = MissionServer(system_id=1, current_nav_index=lambda: nav_index[0])
    server.handle(count(3), LINK, 0.0)
    for seq in range(3):
        server.handle(item_int(seq), LINK, 0.0)

    def current_of(seq: int) -> int:
        req = mavlink2.MAVLink_mission_request_int_message(1, 1, seq, 0)
        (send,) = server.handle(_parsed(req), LINK, 1.0).sends
        return int(send.msg.current)

    assert [current_of(s) for s in range(3)] == [0, 0, 0]
    nav_index[0] = 2
    assert [current_of(s) for s in range(3)] == [0, 0, 0]
    nav_index[0] = mavlink2.MAV_CMD_NAV_WAYPOINT
    assert [current_of(s) for s in range(3)] == [1, 1, 1]


def _parsed(msg: Any) -> Any:
    tx = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    (parsed,) = mavlink2.MAVLink(None).parse_buffer(msg.pack(tx))
    return parsed


async def test_stored_form_over_tcp_and_exact_echo_option() -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp (mavlink_int_to_mission_cmd,
    mission_cmd_to_mavlink_int), over loopback; ``ardupilot_mission_storage=False`` echoes."""
    items = [
        wp(0, HOME.lat_deg, HOME.lon_deg, 0.0),
        wp(1, -35.35, 149.16, 827.496, mavlink2.MAV_CMD_NAV_TAKEOFF, p1=12.5),
        wp(2, 0.0, 0.0, 0.0, mavlink2.MAV_CMD_DO_CHANGE_SPEED, p1=0.0, p2=23.5, p3=-1.0),
    ]
    for ardupilot in (True, False):
        async with SimTeam.start(
            homes=[HOME], tcp_base=0, ardupilot_mission_storage=ardupilot
        ) as team:
            c = await Client.connect(team.ports[0])
            try:
                assert await c.upload(items) == mavlink2.MAV_MISSION_ACCEPTED
                down = await c.download()
            finally:
                await c.close()
        takeoff, speed = down[1], down[2]
        if ardupilot:
            assert (takeoff.frame, takeoff.z, takeoff.param1) == (3, as_float32(827.49), 12.0)
            assert (speed.frame, speed.x, speed.y, speed.z, speed.param2) == (0, 0, 0, 0.0, 23.5)
        else:
            assert (takeoff.frame, takeoff.z, takeoff.param1) == (6, as_float32(827.496), 12.5)
            assert speed.frame == 6

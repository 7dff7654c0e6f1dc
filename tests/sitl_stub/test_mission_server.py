"""Behaviour of the vehicle-side mission protocol, driven with a fake clock."""

from __future__ import annotations

from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.items import MissionItem
from sitl_stub.mission_server import MissionServer, MissionStored, Reaction, Result, Step

GCS_SYS, GCS_COMP = 255, 190
LINK = 1


def from_gcs(msg: Any, sysid: int = GCS_SYS) -> Any:
    """Round-trip a message through the codec so it carries a real header."""
    tx = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=GCS_COMP)
    rx = mavlink2.MAVLink(None)
    (parsed,) = rx.parse_buffer(msg.pack(tx))
    return parsed


def item_int(seq: int, lat: float = -35.36, lon: float = 149.16, **kw: Any) -> Any:
    fields: dict[str, Any] = dict(
        target_system=1,
        target_component=1,
        seq=seq,
        frame=mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        command=mavlink2.MAV_CMD_NAV_WAYPOINT,
        current=0,
        autocontinue=1,
        param1=0.0,
        param2=0.0,
        param3=0.0,
        param4=0.0,
        x=round(lat * 1e7),
        y=round(lon * 1e7),
        z=100.0,
        mission_type=0,
    )
    fields.update(kw)
    return from_gcs(mavlink2.MAVLink_mission_item_int_message(**fields))


def count(n: int, mission_type: int = 0, sysid: int = GCS_SYS) -> Any:
    return from_gcs(mavlink2.MAVLink_mission_count_message(1, 1, n, mission_type), sysid)


def types(r: Reaction) -> list[str]:
    return [s.msg.get_type() for s in r.sends]


def upload(server: MissionServer, n: int, t: float = 0.0, mission_type: int = 0) -> Reaction:
    r = server.handle(count(n, mission_type), LINK, t)
    for i in range(n):
        r = server.handle(item_int(i, lat=-35.0 + i * 0.001, mission_type=mission_type), LINK, t)
    return r


@pytest.fixture
def server() -> MissionServer:
    return MissionServer(system_id=1, component_id=1, timeout_s=1.5, max_retries=3)


def test_count_is_answered_with_request_int_for_item_zero(server: MissionServer) -> None:
    r = server.handle(count(3), LINK, 0.0)
    (send,) = r.sends
    assert send.link == LINK
    assert send.msg.get_type() == "MISSION_REQUEST_INT"
    assert (send.msg.seq, send.msg.target_system, send.msg.target_component) == (0, 255, 190)
    assert server.step is Step.RECEIVING


def test_full_upload_is_acked_and_stored(server: MissionServer) -> None:
    r = upload(server, 4)
    assert types(r) == ["MISSION_ACK"]
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_ACCEPTED
    assert r.events == [MissionStored(0, server.items(0))]
    assert server.count() == 4
    assert server.items()[2].x == round((-35.0 + 0.002) * 1e7)
    assert server.step is Step.IDLE
    assert server.last_result is Result.SUCCESS


def test_upload_rerequests_item_after_timeout(server: MissionServer) -> None:
    server.handle(count(2), LINK, 0.0)
    server.handle(item_int(0), LINK, 0.1)
    assert server.tick(1.0).sends == []
    r = server.tick(1.7)
    assert types(r) == ["MISSION_REQUEST_INT"]
    assert r.sends[0].msg.seq == 1


def test_upload_is_cancelled_after_max_retries(server: MissionServer) -> None:
    server.handle(count(2), LINK, 0.0)
    t = 0.0
    for _ in range(3):
        t += 1.6
        assert types(server.tick(t)) == ["MISSION_REQUEST_INT"]
    r = server.tick(t + 1.6)
    assert types(r) == ["MISSION_ACK"]
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_OPERATION_CANCELLED
    assert server.last_result is Result.TIMEOUT
    assert server.step is Step.IDLE


def test_progress_resets_the_retry_counter(server: MissionServer) -> None:
    server.handle(count(3), LINK, 0.0)
    server.tick(1.6)
    server.tick(3.2)
    server.tick(4.8)
    server.handle(item_int(0), LINK, 5.0)
    for k in range(3):
        assert types(server.tick(6.6 + 1.6 * k)) == ["MISSION_REQUEST_INT"]


def test_duplicate_item_is_ignored(server: MissionServer) -> None:
    server.handle(count(3), LINK, 0.0)
    server.handle(item_int(0), LINK, 0.0)
    r = server.handle(item_int(0, lat=10.0), LINK, 0.1)
    assert r.sends == []
    r = server.handle(item_int(1), LINK, 0.2)
    assert types(r) == ["MISSION_REQUEST_INT"] and r.sends[0].msg.seq == 2


def test_out_of_order_item_is_ignored(server: MissionServer) -> None:
    server.handle(count(3), LINK, 0.0)
    assert server.handle(item_int(2), LINK, 0.0).sends == []
    assert server.step is Step.RECEIVING


def test_retransmitted_count_repeats_the_request_without_restarting(server: MissionServer) -> None:
    server.handle(count(3), LINK, 0.0)
    r = server.handle(count(3), LINK, 0.5)
    assert types(r) == ["MISSION_REQUEST_INT"] and r.sends[0].msg.seq == 0


def test_lost_final_ack_is_repeated_when_last_item_is_resent(server: MissionServer) -> None:
    upload(server, 2)
    r = server.handle(item_int(1, lat=-35.0 + 0.001), LINK, 1.0)
    assert types(r) == ["MISSION_ACK"] and r.sends[0].msg.type == mavlink2.MAV_MISSION_ACCEPTED
    assert r.events == []


def test_legacy_mission_item_is_accepted_in_upload(server: MissionServer) -> None:
    """Follows libraries/AP_Mission/AP_Mission.cpp, convert_MISSION_ITEM_to_MISSION_ITEM_INT:
    degrees * 1.0e7f in float32, so 149.5 deg (1.495e9, float32 step 128) is 1495000064."""
    server.handle(count(2), LINK, 0.0)
    server.handle(item_int(0), LINK, 0.0)
    legacy = from_gcs(
        mavlink2.MAVLink_mission_item_message(
            1, 1, 1, mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT, 16, 0, 1, 0, 0, 0, 0, -35.5, 149.5, 80
        )
    )
    r = server.handle(legacy, LINK, 0.1)
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_ACCEPTED
    assert server.items()[1].x == -355000000
    assert server.items()[1].y == 11679688 * 128


def test_legacy_mission_item_is_rounded_when_echoing_exactly() -> None:
    server = MissionServer(system_id=1, ardupilot_storage=False)
    server.handle(count(2), LINK, 0.0)
    server.handle(item_int(0), LINK, 0.0)
    legacy = from_gcs(
        mavlink2.MAVLink_mission_item_message(
            1, 1, 1, mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT, 16, 0, 1, 0, 0, 0, 0, -35.5, 149.5, 80
        )
    )
    server.handle(legacy, LINK, 0.1)
    assert server.items()[1].y == 1495000000


def test_out_of_range_latitude_gets_invalid_param5_x(server: MissionServer) -> None:
    server.handle(count(2), LINK, 0.0)
    server.handle(item_int(0), LINK, 0.0)
    r = server.handle(item_int(1, x=910_000_000), LINK, 0.0)
    assert types(r) == ["MISSION_ACK"]
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_INVALID_PARAM5_X
    assert server.last_result is Result.INVALID_ITEM


@pytest.mark.parametrize(
    ("fields", "result"),
    [
        ({"y": -1_800_000_001}, mavlink2.MAV_MISSION_INVALID_PARAM6_Y),
        ({"z": 90000.0}, mavlink2.MAV_MISSION_INVALID_PARAM7),
        ({"z": float("nan")}, mavlink2.MAV_MISSION_INVALID_PARAM7),
        ({"frame": mavlink2.MAV_FRAME_BODY_FRD}, mavlink2.MAV_MISSION_UNSUPPORTED_FRAME),
        ({"command": 31337}, mavlink2.MAV_MISSION_UNSUPPORTED),
        (
            {"command": mavlink2.MAV_CMD_NAV_LOITER_TURNS, "param1": -2.0},
            mavlink2.MAV_MISSION_INVALID_PARAM1,
        ),
        ({"param1": float("inf")}, mavlink2.MAV_MISSION_INVALID_PARAM1),
        (
            {"command": mavlink2.MAV_CMD_DO_CHANGE_SPEED, "param1": 7.0},
            mavlink2.MAV_MISSION_INVALID_PARAM1,
        ),
    ],
)
def test_impossible_item_values_get_precise_result(
    server: MissionServer, fields: dict[str, Any], result: int
) -> None:
    server.handle(count(2), LINK, 0.0)
    server.handle(item_int(0), LINK, 0.0)
    r = server.handle(item_int(1, **fields), LINK, 0.0)
    assert r.sends[0].msg.type == result


def test_legacy_item_with_out_of_range_latitude_gets_invalid_param5_x(
    server: MissionServer,
) -> None:
    server.handle(count(2), LINK, 0.0)
    server.handle(item_int(0), LINK, 0.0)
    legacy = from_gcs(
        mavlink2.MAVLink_mission_item_message(1, 1, 1, 3, 16, 0, 1, 0, 0, 0, 0, 95.0, 10.0, 80)
    )
    assert server.handle(legacy, LINK, 0.0).sends[0].msg.type == (
        mavlink2.MAV_MISSION_INVALID_PARAM5_X
    )


def test_failed_upload_keeps_the_stored_mission(server: MissionServer) -> None:
    upload(server, 3)
    before = server.items()
    server.handle(count(2), LINK, 1.0)
    server.handle(item_int(0), LINK, 1.0)
    server.handle(item_int(1, x=2_000_000_000), LINK, 1.0)
    assert server.items() == before


def test_item_zero_is_read_back_as_home(server: MissionServer) -> None:
    server.home = MissionItem(seq=0, frame=0, command=16, x=-353632610, y=1491652300, z=584.0)
    upload(server, 2)
    items = server.items()
    assert (items[0].x, items[0].y, items[0].z) == (-353632610, 1491652300, 584.0)


def test_empty_mission_downloads_as_home_only(server: MissionServer) -> None:
    r = server.handle(from_gcs(mavlink2.MAVLink_mission_request_list_message(1, 1, 0)), LINK, 0)
    assert types(r) == ["MISSION_COUNT"] and r.sends[0].msg.count == 1


def test_download_returns_count_then_items(server: MissionServer) -> None:
    upload(server, 3)
    r = server.handle(from_gcs(mavlink2.MAVLink_mission_request_list_message(1, 1, 0)), LINK, 0)
    assert r.sends[0].msg.count == 3
    r = server.handle(from_gcs(mavlink2.MAVLink_mission_request_int_message(1, 1, 2, 0)), LINK, 0)
    (send,) = r.sends
    assert send.msg.get_type() == "MISSION_ITEM_INT"
    assert send.msg.seq == 2 and send.msg.x == round((-35.0 + 0.002) * 1e7)


def test_legacy_mission_request_is_answered_with_mission_item(server: MissionServer) -> None:
    upload(server, 3)
    r = server.handle(from_gcs(mavlink2.MAVLink_mission_request_message(1, 1, 1, 0)), LINK, 0)
    (send,) = r.sends
    assert send.msg.get_type() == "MISSION_ITEM"
    assert send.msg.x == pytest.approx(-34.999, abs=1e-6)


def test_request_for_missing_seq_gets_invalid_sequence(server: MissionServer) -> None:
    r = server.handle(from_gcs(mavlink2.MAVLink_mission_request_int_message(1, 1, 9, 0)), LINK, 0)
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_INVALID_SEQUENCE


def test_fence_and_rally_are_stored_separately(server: MissionServer) -> None:
    upload(server, 3)
    server.handle(count(1, mission_type=2), LINK, 0.0)
    r = server.handle(
        item_int(0, command=mavlink2.MAV_CMD_NAV_RALLY_POINT, mission_type=2), LINK, 0.0
    )
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_ACCEPTED
    assert r.sends[0].msg.mission_type == 2
    assert server.count(0) == 3 and server.count(2) == 1 and server.count(1) == 0


def test_item_of_other_mission_type_is_ignored_during_upload(server: MissionServer) -> None:
    server.handle(count(2), LINK, 0.0)
    assert server.handle(item_int(0, mission_type=1), LINK, 0.0).sends == []
    assert server.step is Step.RECEIVING


def test_waypoint_in_fence_upload_is_unsupported(server: MissionServer) -> None:
    server.handle(count(1, mission_type=1), LINK, 0.0)
    r = server.handle(item_int(0, mission_type=1), LINK, 0.0)
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_UNSUPPORTED


def test_clear_all_empties_one_type(server: MissionServer) -> None:
    upload(server, 3)
    r = server.handle(from_gcs(mavlink2.MAVLink_mission_clear_all_message(1, 1, 0)), LINK, 0)
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_ACCEPTED
    assert server.count() == 1
    assert r.events[0].mission_type == 0


def test_partial_write_replaces_a_range(server: MissionServer) -> None:
    upload(server, 5)
    r = server.handle(
        from_gcs(mavlink2.MAVLink_mission_write_partial_list_message(1, 1, 2, 3, 0)), LINK, 0
    )
    assert r.sends[0].msg.seq == 2
    server.handle(item_int(2, lat=-36.0), LINK, 0)
    r = server.handle(item_int(3, lat=-37.0), LINK, 0)
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_ACCEPTED
    assert [it.x for it in server.items()[1:]] == [
        round(-34.999 * 1e7),
        -360000000,
        -370000000,
        round(-34.996 * 1e7),
    ]


def test_partial_write_out_of_range_gets_invalid_sequence(server: MissionServer) -> None:
    upload(server, 3)
    r = server.handle(
        from_gcs(mavlink2.MAVLink_mission_write_partial_list_message(1, 1, 2, 5, 0)), LINK, 0
    )
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_INVALID_SEQUENCE


def test_second_gcs_is_denied_while_upload_in_progress(server: MissionServer) -> None:
    server.handle(count(3), LINK, 0.0)
    r = server.handle(count(2, sysid=254), 2, 0.1)
    assert r.sends[0].link == 2
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_DENIED
    assert server.step is Step.RECEIVING


def test_message_for_other_system_is_ignored(server: MissionServer) -> None:
    msg = from_gcs(mavlink2.MAVLink_mission_count_message(7, 1, 3, 0))
    assert server.handle(msg, LINK, 0.0).sends == []


def test_too_many_items_gets_no_space(server: MissionServer) -> None:
    r = server.handle(count(60_000), LINK, 0.0)
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_NO_SPACE


def test_count_zero_clears_mission(server: MissionServer) -> None:
    upload(server, 3)
    r = server.handle(count(0), LINK, 0.0)
    assert r.sends[0].msg.type == mavlink2.MAV_MISSION_ACCEPTED
    assert server.count() == 1


def test_gcs_cancel_ends_upload(server: MissionServer) -> None:
    server.handle(count(3), LINK, 0.0)
    ack = from_gcs(
        mavlink2.MAVLink_mission_ack_message(1, 1, mavlink2.MAV_MISSION_OPERATION_CANCELLED, 0)
    )
    server.handle(ack, LINK, 0.1)
    assert server.step is Step.IDLE
    assert server.tick(10.0).sends == []


def test_legacy_requests_option_asks_with_mission_request_and_takes_item_int() -> None:
    server = MissionServer(system_id=1, legacy_requests=True, timeout_s=1.5)
    r = server.handle(count(2), LINK, 0.0)
    assert types(r) == ["MISSION_REQUEST"] and r.sends[0].msg.seq == 0
    r = server.handle(item_int(0), LINK, 0.1)
    assert types(r) == ["MISSION_REQUEST"] and r.sends[0].msg.seq == 1
    assert types(server.tick(1.7)) == ["MISSION_REQUEST"]  # re-requests are legacy too
    r = server.handle(item_int(1, lat=-35.5), LINK, 1.8)
    assert types(r) == ["MISSION_ACK"] and r.sends[0].msg.type == mavlink2.MAV_MISSION_ACCEPTED
    assert server.items()[1].x == -355000000


def test_legacy_requests_option_reaches_every_vehicle_of_a_team() -> None:
    from sitl_stub.api import SimTeam

    homes = [(-35.36, 149.16, 584.0), (-35.37, 149.16, 584.0)]
    team = SimTeam.create(homes=homes, tcp_base=0, legacy_mission_requests=True)
    assert [v.mission.legacy_requests for v in team.vehicles] == [True, True]
    assert not SimTeam.create(homes=homes, tcp_base=0).vehicles[0].mission.legacy_requests


def test_cli_has_the_legacy_mission_requests_flag() -> None:
    from sitl_stub.__main__ import parse_args

    home = ["--home", "-35.36,149.16,584"]
    assert parse_args([*home, "--legacy-mission-requests"]).legacy_mission_requests is True
    assert parse_args(home).legacy_mission_requests is False


def request_list(mission_type: int = 0, sysid: int = GCS_SYS) -> Any:
    return from_gcs(mavlink2.MAVLink_mission_request_list_message(1, 1, mission_type), sysid)


def request_int(seq: int, mission_type: int = 0, sysid: int = GCS_SYS) -> Any:
    return from_gcs(mavlink2.MAVLink_mission_request_int_message(1, 1, seq, mission_type), sysid)


def test_accepted_uploads_count_completed_uploads_only(server: MissionServer) -> None:
    upload(server, 3)
    server.handle(item_int(2), LINK, 0.0)  # the last item again: the ACK again, no new upload
    server.handle(count(3), LINK, 0.0)  # a failed upload: item 1 is not a mission command
    server.handle(item_int(0), LINK, 0.0)
    server.handle(item_int(1, command=mavlink2.MAV_CMD_NAV_FENCE_RETURN_POINT), LINK, 0.0)
    upload(server, 0, mission_type=mavlink2.MAV_MISSION_TYPE_RALLY)  # an accepted empty list
    server.handle(from_gcs(mavlink2.MAVLink_mission_clear_all_message(1, 1, 0)), LINK, 0)
    c = server.counters
    assert (c["accepted_uploads"], c["failed_uploads"], c["uploads"]) == (2, 1, 3)


def test_a_download_counts_once_every_item_was_served(server: MissionServer) -> None:
    upload(server, 3)
    for _ in range(2):  # the second time the GCS re-reads a list whose count it had
        server.handle(request_list(), LINK, 0.0)
        for seq in (0, 1, 1, 2, 2):  # repeated requests (the answer was lost or duplicated)
            server.handle(request_int(seq), LINK, 0.0)
    assert server.counters["downloads"] == 2
    server.handle(request_list(), LINK, 0.0)
    server.handle(request_int(0), LINK, 0.0)
    server.handle(request_list(), LINK, 0.0)  # a retransmitted list request: same download
    server.handle(request_int(1), LINK, 0.0)
    server.handle(request_int(2), LINK, 0.0)
    assert server.counters["downloads"] == 3


def test_a_download_that_stops_short_or_outlives_its_list_does_not_count(
    server: MissionServer,
) -> None:
    upload(server, 3)
    server.handle(request_list(), LINK, 0.0)
    server.handle(request_int(0), LINK, 0.0)
    server.handle(request_int(1), LINK, 0.0)
    server.handle(request_int(2, sysid=254), LINK, 0.0)  # another GCS's request
    server.handle(request_int(2), LINK + 1, 0.0)  # the same GCS on another link
    assert server.counters["downloads"] == 0
    upload(server, 3)  # the mission changed under the download
    server.handle(request_int(2), LINK, 0.0)
    server.handle(request_int(0), LINK, 0.0)  # without a list request first
    server.handle(request_int(1), LINK, 0.0)
    server.handle(request_list(mavlink2.MAV_MISSION_TYPE_FENCE), LINK, 0.0)  # an empty list
    assert server.counters["downloads"] == 0

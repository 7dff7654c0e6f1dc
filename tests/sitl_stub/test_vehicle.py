"""Loopback integration: a raw pymavlink-codec client against stub vehicles over real TCP."""

from __future__ import annotations

import asyncio
import itertools
import math
from collections.abc import AsyncIterator
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from sitl_stub.model import Wind, displace_deg, offset_ne_m
from tests.sitl_stub.conftest import Client, wp

HOME = Home(-35.363261, 149.165230, 584.0, 0.0)


@pytest.fixture
async def team() -> AsyncIterator[SimTeam]:
    async with SimTeam.start(homes=[HOME, HOME], tcp_base=0, speedup=20.0, seed=3) as t:
        yield t


@pytest.fixture
async def client(team: SimTeam) -> AsyncIterator[Client]:
    c = await Client.connect(team.ports[0])
    try:
        yield c
    finally:
        await c.close()


def north(dist_m: float, east_m: float = 0.0) -> tuple[float, float]:
    return displace_deg(HOME.lat_deg, HOME.lon_deg, HOME.alt_m, dist_m, east_m)


async def test_heartbeat_looks_like_arduplane_on_mavlink2(client: Client) -> None:
    hb = await client.recv("HEARTBEAT")
    assert hb.type == mavlink2.MAV_TYPE_FIXED_WING
    assert hb.autopilot == mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    assert hb.base_mode & mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not hb.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.get_msgbuf()[0] == 0xFD


async def test_each_port_serves_its_own_system_id(team: SimTeam) -> None:
    c2 = await Client.connect(team.ports[1])
    try:
        hb = await c2.recv("HEARTBEAT")
        assert hb.get_srcSystem() == 2
    finally:
        await c2.close()


async def test_two_clients_on_one_vehicle_both_get_telemetry(team: SimTeam, client: Client) -> None:
    other = await Client.connect(team.ports[0], sysid=254)
    try:
        assert (await other.recv("GLOBAL_POSITION_INT")).get_srcSystem() == 1
        assert (await client.recv("GLOBAL_POSITION_INT")).get_srcSystem() == 1
    finally:
        await other.close()


async def test_mode_change_and_arming_show_in_heartbeat(client: Client) -> None:
    assert (
        await client.command(
            mavlink2.MAV_CMD_DO_SET_MODE, mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 12
        )
        == mavlink2.MAV_RESULT_ACCEPTED
    )
    hb = await client.recv(lambda m: m.get_type() == "HEARTBEAT" and m.custom_mode == 12)
    assert hb.base_mode & mavlink2.MAV_MODE_FLAG_GUIDED_ENABLED


async def test_unknown_command_gets_unsupported(team: SimTeam, client: Client) -> None:
    assert await client.command(31999, 1.0) == mavlink2.MAV_RESULT_UNSUPPORTED
    assert team.vehicles[0].counters["unsupported_commands"] == 1


async def test_command_int_is_answered(client: Client) -> None:
    client.send(
        mavlink2.MAVLink_command_int_message(
            1,
            1,
            0,
            mavlink2.MAV_CMD_REQUEST_MESSAGE,
            0,
            0,
            mavlink2.MAVLINK_MSG_ID_HOME_POSITION,
            0,
            0,
            0,
            0,
            0,
            0,
        )
    )
    home = await client.recv("HOME_POSITION")
    assert home.latitude == round(HOME.lat_deg * 1e7)
    ack = await client.recv("COMMAND_ACK")
    assert ack.result == mavlink2.MAV_RESULT_ACCEPTED


@pytest.mark.parametrize(
    ("frame", "result"),
    [
        (mavlink2.MAV_FRAME_GLOBAL, mavlink2.MAV_RESULT_ACCEPTED),
        (mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink2.MAV_RESULT_ACCEPTED),
        (mavlink2.MAV_FRAME_LOCAL_NED, mavlink2.MAV_RESULT_DENIED),
        (mavlink2.MAV_FRAME_MISSION, mavlink2.MAV_RESULT_DENIED),
    ],
)
async def test_change_altitude_is_taken_in_a_global_frame_as_arduplane_takes_it(
    client: Client, frame: int, result: int
) -> None:
    """ArduPlane/GCS_Mavlink.cpp handle_command_int_DO_CHANGE_ALTITUDE: param1 the altitude,
    param2 its MAV_FRAME; a frame mavlink_coordinate_frame_to_location_alt_frame does not
    map (anything but GLOBAL, RELATIVE_ALT and TERRAIN_ALT, INT or not) is DENIED."""
    client.send(
        mavlink2.MAVLink_command_int_message(
            1, 1, 0, mavlink2.MAV_CMD_DO_CHANGE_ALTITUDE, 0, 0, 700.0, float(frame), 0, 0,
            0, 0, 0,
        )
    )  # fmt: skip
    ack = await client.recv("COMMAND_ACK")
    assert ack.command == mavlink2.MAV_CMD_DO_CHANGE_ALTITUDE and ack.result == result


async def test_command_for_other_system_is_ignored(client: Client) -> None:
    client.send(mavlink2.MAVLink_command_long_message(9, 1, 31999, 0, 0, 0, 0, 0, 0, 0, 0))
    assert await client.try_recv("COMMAND_ACK", 0.5) is None


async def test_garbage_and_bad_crc_are_counted_and_dropped(team: SimTeam, client: Client) -> None:
    good = mavlink2.MAVLink_command_long_message(1, 1, 31999, 0, 0, 0, 0, 0, 0, 0, 0)
    raw = bytearray(good.pack(client.mav))
    raw[-1] ^= 0xFF  # corrupt the CRC
    client.send_raw(bytes(raw))
    client.send_raw(bytes(range(256)) * 4)
    client.send_raw(b"\x00" * 300)
    await asyncio.sleep(0.2)
    assert await client.command(31999) == mavlink2.MAV_RESULT_UNSUPPORTED
    counters = team.vehicles[0].counters
    assert counters["bad_data"] > 0
    assert counters["unsupported_commands"] == 1  # the corrupted copy was not executed
    assert (await client.recv("HEARTBEAT")).get_srcSystem() == 1


async def test_request_message_sends_autopilot_version(client: Client) -> None:
    result = await client.command(
        mavlink2.MAV_CMD_REQUEST_MESSAGE, mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION
    )
    assert result == mavlink2.MAV_RESULT_ACCEPTED
    av = client_msgs = [m for m in client.history if m.get_type() == "AUTOPILOT_VERSION"]
    assert client_msgs, av
    assert av[0].capabilities & mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_INT


async def test_set_message_interval_is_in_simulated_time(team: SimTeam, client: Client) -> None:
    result = await client.command(
        mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_SYSTEM_TIME, 100_000
    )
    assert result == mavlink2.MAV_RESULT_ACCEPTED
    first = await client.recv("SYSTEM_TIME")
    times = [first]
    while times[-1].time_boot_ms - first.time_boot_ms < 5000:
        times.append(await client.recv("SYSTEM_TIME"))
    gaps = {b.time_boot_ms - a.time_boot_ms for a, b in itertools.pairwise(times)}
    assert gaps == {100}
    utc_step = times[-1].time_unix_usec - times[-2].time_unix_usec
    assert utc_step == 100_000


async def test_disabling_a_stream_stops_it(client: Client) -> None:
    await client.command(
        mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, -1
    )
    await client.recv("HEARTBEAT")
    assert await client.try_recv("GLOBAL_POSITION_INT", 0.3) is None


async def test_request_data_stream_sets_group_rate(client: Client) -> None:
    client.send(
        mavlink2.MAVLink_request_data_stream_message(1, 1, mavlink2.MAV_DATA_STREAM_EXTRA1, 10, 1)
    )
    a = await client.recv("ATTITUDE")
    a = await client.recv("ATTITUDE")
    b = await client.recv("ATTITUDE")
    assert b.time_boot_ms - a.time_boot_ms == 100


async def test_system_time_is_shared_and_advances_with_speedup(team: SimTeam) -> None:
    c1, c2 = await Client.connect(team.ports[0]), await Client.connect(team.ports[1])
    try:
        loop = asyncio.get_running_loop()
        a = await c1.recv("SYSTEM_TIME")
        w0 = loop.time()
        b = await c2.recv(
            lambda m: m.get_type() == "SYSTEM_TIME" and m.time_boot_ms > a.time_boot_ms
        )
        assert b.time_unix_usec - a.time_unix_usec == (b.time_boot_ms - a.time_boot_ms) * 1000
        later = await c1.recv(
            lambda m: m.get_type() == "SYSTEM_TIME" and m.time_boot_ms >= a.time_boot_ms + 20000
        )
        wall = loop.time() - w0
        sim = (later.time_unix_usec - a.time_unix_usec) / 1e6
        assert 10.0 < sim / wall < 40.0
    finally:
        await c1.close()
        await c2.close()


async def test_params_list_and_set(team: SimTeam, client: Client) -> None:
    client.send(mavlink2.MAVLink_param_request_list_message(1, 1))
    names = set()
    while len(names) < 6:
        names.add((await client.recv("PARAM_VALUE")).param_id)
    assert {"AIRSPEED_CRUISE", "AIRSPEED_MIN", "AIRSPEED_MAX", "WP_LOITER_RAD", "WP_RADIUS"} <= (
        names
    )
    client.send(mavlink2.MAVLink_param_set_message(1, 1, b"WP_LOITER_RAD", 120.0, 9))
    pv = await client.recv(
        lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "WP_LOITER_RAD"
    )
    assert pv.param_value == 120.0
    assert team.vehicles[0].autopilot.params.loiter_radius_m == 120.0
    client.send(mavlink2.MAVLink_param_set_message(1, 1, b"WP_RADIUS", float("nan"), 9))
    pv = await client.recv(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "WP_RADIUS")
    assert math.isfinite(pv.param_value)


async def test_uploaded_mission_reaches_autopilot_and_downloads(
    team: SimTeam, client: Client
) -> None:
    items = [wp(0, *north(0))] + [wp(i, *north(500.0 * i)) for i in range(1, 5)]
    assert await client.upload(items) == mavlink2.MAV_MISSION_ACCEPTED
    mission = team.vehicles[0].autopilot.mission
    assert [it.x for it in mission[1:]] == [m.x for m in items[1:]]
    down = await client.download()
    assert [(m.x, m.y, m.z) for m in down[1:]] == [(m.x, m.y, m.z) for m in items[1:]]
    assert down[0].x == round(HOME.lat_deg * 1e7)


async def test_out_of_range_latitude_over_tcp_gets_invalid_param5_x(client: Client) -> None:
    items = [wp(0, *north(0)), wp(1, 0.0, 0.0)]
    items[1].x = 950_000_000
    assert await client.upload(items) == mavlink2.MAV_MISSION_INVALID_PARAM5_X


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_hundred_items_round_trip_over_30_percent_loss() -> None:
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=1.0, mission_timeout_s=0.05) as t:
        t.vehicles[0].link.faults(loss=0.3)
        c = await Client.connect(t.ports[0])
        try:
            items = [wp(0, *north(0))] + [
                wp(i, *north(100.0 * i, 50.0 * (i % 3)), alt=50.0 + i) for i in range(1, 100)
            ]
            assert await c.upload(items, retry_s=0.02) == mavlink2.MAV_MISSION_ACCEPTED
            down = await c.download(retry_s=0.02)
            assert len(down) == 100
            fields = ("seq", "command", "param1", "param2", "x", "y", "z")
            for sent, got in zip(items[1:], down[1:], strict=True):
                assert [getattr(sent, f) for f in fields] == [getattr(got, f) for f in fields]
                # Stored as ArduPilot does: RELATIVE_ALT_INT (6) reads back as RELATIVE_ALT.
                assert got.frame == mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT
            assert t.vehicles[0].link.inbound.lost > 0 and t.vehicles[0].link.outbound.lost > 0
        finally:
            await c.close()


async def test_watch_crossing_gives_exact_simulated_time() -> None:
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=50.0) as t:
        c = await Client.connect(t.ports[0])
        try:
            items = [
                wp(0, *north(0)),
                wp(1, *north(300.0), command=mavlink2.MAV_CMD_NAV_TAKEOFF, alt=60.0),
                wp(2, *north(2000.0)),
                wp(3, *north(4000.0)),
            ]
            assert await c.upload(items) == mavlink2.MAV_MISSION_ACCEPTED
            target = north(2000.0)
            fut = t.watch_crossing(0, *target, radius_m=0.0)
            assert await c.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
            assert await c.command(mavlink2.MAV_CMD_MISSION_START, 0, 0) == 0
            async with asyncio.timeout(30):
                t_cross = await fut
            assert 0 < t_cross <= t.sim_time_s
            s = t.true_state(0)
            assert not s.on_ground
        finally:
            await c.close()


async def test_wind_makes_groundspeed_differ_from_airspeed() -> None:
    wind = Wind(speed_m_s=8.0, from_rad=0.0)
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=50.0, wind=wind) as t:
        c = await Client.connect(t.ports[0])
        try:
            items = [
                wp(0, *north(0)),
                wp(1, *north(300.0), command=mavlink2.MAV_CMD_NAV_TAKEOFF, alt=60.0),
                wp(2, *north(5000.0)),
                wp(3, *north(10000.0)),
            ]
            assert await c.upload(items) == mavlink2.MAV_MISSION_ACCEPTED
            assert await c.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
            assert await c.command(mavlink2.MAV_CMD_MISSION_START, 0, 0) == 0
            await c.recv(lambda m: m.get_type() == "MISSION_ITEM_REACHED" and m.seq == 1, 30)
            hud = await c.recv(
                lambda m: m.get_type() == "VFR_HUD" and m.airspeed > 15 and m.groundspeed > 1, 30
            )
            # Flying north into a wind from the north: groundspeed is lower.
            assert hud.groundspeed < hud.airspeed - 4.0
            w = await c.recv("WIND")
            # The estimate carries a 0.8-1.6 m/s error (tests/sitl_stub/test_wind_estimate.py).
            assert w.speed == pytest.approx(8.0, abs=1.7)
            assert min(w.direction, 360 - w.direction) < 13.0
        finally:
            await c.close()


async def test_flown_mission_on_the_wire() -> None:
    """Takeoff, waypoints reached in order, a speed change and loiter turns of the radius."""
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=100.0) as t:
        c = await Client.connect(t.ports[0])
        try:
            loiter_c = north(3000.0)
            items = [
                wp(0, *north(0)),
                wp(1, *north(300.0), command=mavlink2.MAV_CMD_NAV_TAKEOFF, alt=60.0),
                wp(2, *north(1500.0)),
                wp(3, 0, 0, 0, command=mavlink2.MAV_CMD_DO_CHANGE_SPEED, p1=0, p2=27.0,
                   frame=mavlink2.MAV_FRAME_MISSION),
                wp(4, *north(2500.0)),
                wp(5, *loiter_c, command=mavlink2.MAV_CMD_NAV_LOITER_TURNS, p1=2, p3=150.0),
                wp(6, *north(5000.0)),
            ]  # fmt: skip
            assert await c.upload(items) == mavlink2.MAV_MISSION_ACCEPTED
            assert await c.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
            assert await c.command(mavlink2.MAV_CMD_MISSION_START, 0, 0) == 0
            radii: list[float] = []
            reached: list[int] = []
            fast = None
            async with asyncio.timeout(60):
                while 6 not in reached:
                    m = await c.recv(
                        lambda m: (
                            m.get_type()
                            in ("MISSION_ITEM_REACHED", "GLOBAL_POSITION_INT", "VFR_HUD")
                        )
                    )
                    if m.get_type() == "MISSION_ITEM_REACHED" and (
                        not reached or reached[-1] != m.seq
                    ):
                        reached.append(m.seq)
                    elif m.get_type() == "VFR_HUD" and 4 in reached and 5 not in reached:
                        fast = max(fast or 0.0, m.airspeed)
                    elif (
                        m.get_type() == "GLOBAL_POSITION_INT"
                        and t.vehicles[0].autopilot.current_seq == 5
                    ):
                        n, e = offset_ne_m(
                            loiter_c[0], loiter_c[1], HOME.alt_m, m.lat * 1e-7, m.lon * 1e-7
                        )
                        radii.append(math.hypot(n, e))
            assert [s for s in reached if s in (1, 2, 4, 5, 6)] == [1, 2, 4, 5, 6]
            assert fast is not None and fast > 25.0
            settled = radii[len(radii) // 3 :]
            assert settled and abs(sum(settled) / len(settled) - 150.0) < 20.0
        finally:
            await c.close()


async def test_mission_replaced_while_flying_auto_continues_at_current_index() -> None:
    """As ArduPlane: a new upload in AUTO keeps the current index and flies the NEW item."""
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=100.0) as t:
        c = await Client.connect(t.ports[0])
        try:
            takeoff = mavlink2.MAV_CMD_NAV_TAKEOFF
            old = [
                wp(0, *north(0)),
                wp(1, *north(300.0), command=takeoff, alt=60.0),
                wp(2, *north(1500.0)),
                wp(3, *north(6000.0)),  # far: the upload is long done before it is reached
                wp(4, *north(7500.0)),
                wp(5, *north(9000.0)),
            ]
            new = [
                *old[:3],
                wp(3, *north(3000.0, 1200.0)),
                wp(4, *north(4000.0, 1200.0)),
                wp(5, *north(6000.0, 1200.0)),
            ]
            assert await c.upload(old) == mavlink2.MAV_MISSION_ACCEPTED
            assert await c.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
            assert await c.command(mavlink2.MAV_CMD_MISSION_START, 0, 0) == 0
            await c.recv(lambda m: m.get_type() == "MISSION_ITEM_REACHED" and m.seq == 2, 30)
            cur = await c.recv("MISSION_CURRENT", 10)
            assert cur.seq == 3

            assert await c.upload(new, deadline_s=10.0) == mavlink2.MAV_MISSION_ACCEPTED
            assert [it.y for it in t.vehicles[0].autopilot.mission] == [it.y for it in new]
            after = await c.recv("MISSION_CURRENT", 10)
            assert after.seq == 3 and after.mission_state == mavlink2.MISSION_STATE_ACTIVE
            hb = await c.recv("HEARTBEAT", 10)
            assert hb.custom_mode == 10  # still AUTO

            # The aircraft turns to the new item 3 and goes on with the new mission.
            last_pos: dict[int, Any] = {}
            reached: list[int] = []
            async with asyncio.timeout(30):
                while 4 not in reached:
                    m = await c.recv(
                        lambda m: m.get_type() in ("MISSION_ITEM_REACHED", "GLOBAL_POSITION_INT")
                    )
                    if m.get_type() == "GLOBAL_POSITION_INT":
                        last_pos[0] = m
                    elif m.seq not in reached:
                        reached.append(m.seq)
                        if m.seq == 3:
                            last_pos[3] = last_pos[0]
            assert reached == [3, 4]
            at3 = last_pos[3]
            lat, lon = at3.lat * 1e-7, at3.lon * 1e-7
            to_new = math.hypot(*offset_ne_m(lat, lon, 0.0, *north(3000.0, 1200.0)))
            to_old = math.hypot(*offset_ne_m(lat, lon, 0.0, *north(6000.0)))
            assert to_new < 150.0 < 1000.0 < to_old
        finally:
            await c.close()

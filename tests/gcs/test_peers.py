"""gcs against independent MAVLink peers: MAVProxy as a UDP router, MAVSDK as another client."""

from __future__ import annotations

import asyncio
import contextlib
import re
import struct
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.mavlink.link import Link
from gcs.mavlink.mission_client import download_mission, upload_mission
from gcs.mavlink.telemetry import TrackSample
from gcs.mavlink.vehicle import Vehicle
from planner.mission import (
    Autopilot,
    Loiter,
    MissionItem,
    SpeedChange,
    Waypoint,
    compile_mission,
    items_equal,
    stored_item,
)
from sitl_stub.api import Home, SimTeam
from tests.gcs.conftest import HOME, free_udp_port
from tests.sitl_stub.conftest import mavproxy_router, mavproxy_wp_list

DO_CHANGE_SPEED = mavlink2.MAV_CMD_DO_CHANGE_SPEED
NAV_LOITER_TURNS = mavlink2.MAV_CMD_NAV_LOITER_TURNS
HOME_E7 = (round(HOME[0] * 1e7), round(HOME[1] * 1e7))


def f32(v: float) -> float:
    """``v`` rounded to float32, as the wire carries it."""
    return float(struct.unpack("<f", struct.pack("<f", v))[0])


def route_mission(n_items: int) -> list[MissionItem]:
    """A compiled mission of exactly ``n_items``: home, takeoff, waypoints, a DO_CHANGE_SPEED
    and a NAV_LOITER_TURNS (counter-clockwise), altitudes that float32 cannot hold exactly."""
    lat0, lon0, alt0 = HOME
    waypoints = [
        Waypoint(lat0 + 0.0025 * (i + 1), lon0 + 0.0011 * (i % 3), alt0 + 80.0 + 0.37 * (i % 11))
        for i in range(n_items - 4)
    ]
    loiter = Loiter(4, lat0 + 0.0131, lon0 + 0.0017, alt0 + 95.3, turns=3, radius_m=80.0,
                    clockwise=False)  # fmt: skip
    items = compile_mission(
        home=Waypoint(lat0, lon0, alt0),
        waypoints=waypoints,
        takeoff_alt_m=45.5,
        speeds=[SpeedChange(2, 22.5)],
        loiters=[loiter],
    )
    assert len(items) == n_items
    assert {DO_CHANGE_SPEED, NAV_LOITER_TURNS} <= {it.command for it in items}
    return items


def to_mavsdk(it: MissionItem) -> Any:
    from mavsdk.asyncio.plugins.mission_raw import MissionItem as RawItem

    return RawItem(
        seq=it.seq, frame=it.frame, command=it.command, current=int(it.seq == 0),
        autocontinue=it.autocontinue, param1=it.param1, param2=it.param2, param3=it.param3,
        param4=it.param4, x=it.x, y=it.y, z=it.z, mission_type=it.mission_type,
    )  # fmt: skip


def from_mavsdk(it: Any) -> MissionItem:
    return MissionItem(
        seq=int(it.seq), frame=int(it.frame), command=int(it.command), current=int(it.current),
        autocontinue=int(it.autocontinue), param1=float(it.param1), param2=float(it.param2),
        param3=float(it.param3), param4=float(it.param4), x=int(it.x), y=int(it.y),
        z=float(it.z), mission_type=int(it.mission_type),
    )  # fmt: skip


@contextlib.asynccontextmanager
async def mavsdk_autopilot(port: int) -> AsyncIterator[Any]:
    """MAVSDK (a ground station) connected to the stub vehicle on ``port``: its System.

    Enter it inside ``SimTeam.start`` so that MAVSDK is closed before the vehicle.
    """
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"tcpout://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=10.0)
        assert system is not None
        yield system


async def test_udpin_link_through_mavproxy_discovers_and_commands_the_vehicle(
    tmp_path: Path,
) -> None:
    port = free_udp_port()
    async with (
        SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=1.0) as team,
        Link.open(f"udpin:127.0.0.1:{port}") as link,
        mavproxy_router(f"tcp:127.0.0.1:{team.ports[0]}", f"udpout:127.0.0.1:{port}", tmp_path),
    ):
        peer = await link.wait_vehicle(1, timeout_s=30.0)
        assert peer.autopilot == mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA
        cmd = mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES
        with link.subscribe({"COMMAND_ACK", "AUTOPILOT_VERSION"}, system_id=1) as sub:
            for _ in range(5):  # MAVProxy may still be starting: retry like a GCS would
                link.send(mavlink2.MAVLink_command_long_message(1, 1, cmd, 0, 1, *[0] * 6))
                ack = await sub.get(timeout_s=2.0)
                if ack is not None:
                    break
            got = {ack.get_type()} if ack is not None else set()
            while (m := await sub.get(timeout_s=1.0)) is not None:
                got.add(m.get_type())
        assert got == {"COMMAND_ACK", "AUTOPILOT_VERSION"}
        assert link.counters.crc_errors == 0


async def test_mavsdk_reads_back_our_200_item_upload_field_for_field() -> None:
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync

    items = route_mission(200)
    async with SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=1.0) as team:
        port = team.ports[0]
        async with Link.open(f"tcp:127.0.0.1:{port}") as link, asyncio.timeout(20):
            await link.wait_vehicle(1, timeout_s=10.0)
            await upload_mission(link, 1, items)
        async with mavsdk_autopilot(port) as system, asyncio.timeout(20):
            got = await MissionRawAsync(system).download_mission()
    assert len(got) == len(items)
    assert got[0].seq == 0
    assert (got[0].x, got[0].y) == HOME_E7  # the vehicle's home, not our item 0
    for sent, theirs in zip(items[1:], got[1:], strict=True):
        where = f"item {sent.seq}"
        ours = stored_item(sent, Autopilot.ARDUPILOT)  # the stub keeps items as ArduPilot
        assert (theirs.seq, theirs.frame, theirs.command) == (
            ours.seq, ours.frame, ours.command,
        ), where  # fmt: skip
        assert (theirs.x, theirs.y, theirs.autocontinue, theirs.mission_type) == (
            ours.x, ours.y, ours.autocontinue, ours.mission_type,
        ), where  # fmt: skip
        ours_f = [ours.param1, ours.param2, ours.param3, ours.param4, ours.z]
        theirs_f = [theirs.param1, theirs.param2, theirs.param3, theirs.param4, theirs.z]
        assert theirs_f == [f32(v) for v in ours_f], where
    speed = next(it for it in got if it.command == DO_CHANGE_SPEED)
    loiter = next(it for it in got if it.command == NAV_LOITER_TURNS)
    assert (speed.param1, speed.param2, speed.param3) == (0.0, 22.5, -1.0)
    assert (loiter.param1, loiter.param3, loiter.param4) == (3.0, -80.0, 1.0)


async def test_our_download_reads_back_a_mavsdk_upload_unchanged() -> None:
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync

    sent = route_mission(24)
    async with SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=1.0) as team:
        port = team.ports[0]
        async with mavsdk_autopilot(port) as system, asyncio.timeout(20):
            await MissionRawAsync(system).upload_mission([to_mavsdk(it) for it in sent])
        async with Link.open(f"tcp:127.0.0.1:{port}") as link, asyncio.timeout(20):
            await link.wait_vehicle(1, timeout_s=10.0)
            got = await download_mission(link, 1)
    # What MAVSDK sent, as planner items (item 0, home, is the vehicle's: not compared).
    expected = [from_mavsdk(to_mavsdk(it)) for it in sent]
    assert expected[0].current == 1
    assert len(got) == len(expected)
    assert items_equal(expected, got, compare_home=False, autopilot=Autopilot.ARDUPILOT), (
        got,
        expected,
    )
    assert (got[0].x, got[0].y) == HOME_E7


async def test_our_upload_and_telemetry_agree_with_mavsdk_connected_at_once() -> None:
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    items = route_mission(40)
    async with SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=10.0) as team:
        port = team.ports[0]
        async with (
            mavsdk_autopilot(port) as system,
            Link.open(f"tcp:127.0.0.1:{port}") as link,
            asyncio.timeout(30),
        ):
            await link.wait_vehicle(1, timeout_s=10.0)
            vehicle = Vehicle(link, 1)
            telemetry = TelemetryAsync(system)
            async with contextlib.aclosing(telemetry.subscribe_position()) as positions:
                # MAVSDK streams positions and reads the mission while we upload ours.
                pos = await anext(positions)
                _, theirs = await asyncio.gather(
                    vehicle.upload_mission(items, verify=True),
                    MissionRawAsync(system).download_mission(),
                )
                assert len(theirs) in (1, len(items))  # before or after our upload
                stored = team.vehicles[0].autopilot.mission
                assert [(it.command, it.x, it.y) for it in stored[1:]] == [
                    (it.command, it.x, it.y) for it in items[1:]
                ]

                # On the ground: both report the same position (home).
                await wait_for_sample(vehicle, pos.latitude_deg, pos.longitude_deg)
                state = vehicle.state
                assert state.lat_deg is not None and state.lon_deg is not None
                assert abs(state.lat_deg - pos.latitude_deg) <= 1e-5
                assert abs(state.lon_deg - pos.longitude_deg) <= 1e-5
                assert abs(pos.latitude_deg - HOME[0]) <= 1e-5

                # Flying our mission: every position MAVSDK reports, we report too.
                await vehicle.arm()
                await vehicle.start_mission()
                checked = 0
                async for pos in positions:
                    if pos.latitude_deg < HOME[0] + 2e-5:
                        continue  # still on the ground roll's first metres
                    sample = await wait_for_sample(vehicle, pos.latitude_deg, pos.longitude_deg)
                    assert sample.alt_amsl_m == pytest.approx(pos.absolute_altitude_m, abs=0.01)
                    checked += 1
                    if checked == 10:
                        break
            assert pos.latitude_deg > HOME[0] + 2e-5
            assert vehicle.state.armed is True
            assert vehicle.state.mode == "AUTO"


async def wait_for_sample(
    vehicle: Vehicle, lat_deg: float, lon_deg: float, timeout_s: float = 3.0
) -> TrackSample:
    """The position fix in our telemetry history within 1e-5 deg of (lat, lon)."""
    async with asyncio.timeout(timeout_s):
        while True:
            for sample in reversed(vehicle.state.history):
                if abs(sample.lat_deg - lat_deg) <= 1e-5 and abs(sample.lon_deg - lon_deg) <= 1e-5:
                    return sample
            await asyncio.sleep(0.02)


# MAVProxy's "wp list" line per item: command frame x y z p1..p4 current autocontinue.
_WP_LINE = re.compile(
    r"(\d+) (\d+) (-?\d+\.\d{10}) (-?\d+\.\d{10}) (-?\d+\.\d+) "
    r"p1=(\S+) p2=(\S+) p3=(\S+) p4=(\S+) cur=(\d+) auto=(\d+)"
)


async def test_mavproxy_lists_the_mission_we_uploaded(tmp_path: Path) -> None:
    items = route_mission(9)
    async with SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=1.0) as team:
        port = team.ports[0]
        async with Link.open(f"tcp:127.0.0.1:{port}") as link, asyncio.timeout(20):
            await link.wait_vehicle(1, timeout_s=10.0)
            await upload_mission(link, 1, items)
        text = await mavproxy_wp_list(f"tcp:127.0.0.1:{port}", tmp_path, len(items))
    assert f"Saved {len(items)} waypoints" in text, text
    rows = [m.groups() for m in _WP_LINE.finditer(text)]
    assert len(rows) == len(items), text
    listed = [
        (int(cmd), int(frame), round(float(x) * 1e7), round(float(y) * 1e7), float(z),
         float(p1), float(p2), float(p3), float(p4), int(auto))
        for cmd, frame, x, y, z, p1, p2, p3, p4, _cur, auto in rows
    ]  # fmt: skip
    assert listed[0][2:4] == HOME_E7
    for sent, row in zip(items[1:], listed[1:], strict=True):
        ours = stored_item(sent, Autopilot.ARDUPILOT)  # the stub keeps items as ArduPilot
        assert row[:4] == (ours.command, ours.frame, ours.x, ours.y), (ours, row)
        assert row[4] == pytest.approx(ours.z, abs=1e-4), (ours, row)
        # MAVProxy prints params with one decimal; ours have at most one.
        assert row[5:9] == (ours.param1, ours.param2, ours.param3, ours.param4), (ours, row)
        assert row[9] == ours.autocontinue


async def test_50_item_upload_and_download_through_mavproxy_router(tmp_path: Path) -> None:
    items = route_mission(50)
    port = free_udp_port()
    async with (
        SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=1.0) as team,
        Link.open(f"udpin:127.0.0.1:{port}") as link,
        mavproxy_router(f"tcp:127.0.0.1:{team.ports[0]}", f"udpout:127.0.0.1:{port}", tmp_path),
        asyncio.timeout(40),
    ):
        await link.wait_vehicle(1, timeout_s=30.0)
        await upload_mission(link, 1, items)
        stored = list(team.vehicles[0].autopilot.mission)
        got = await download_mission(link, 1)
    assert [(it.command, it.x, it.y) for it in stored[1:]] == [
        (it.command, it.x, it.y) for it in items[1:]
    ]
    assert len(got) == len(items)
    assert items_equal(items, got, compare_home=False, autopilot=Autopilot.ARDUPILOT)
    assert (got[0].x, got[0].y) == HOME_E7
    assert link.counters.crc_errors == 0

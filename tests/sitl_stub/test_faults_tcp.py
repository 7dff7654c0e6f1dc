"""Link faults over real loopback TCP, changed at run time through the Python API.

Latency, duplication and reordering act on whole MAVLink packets in both directions; the
mission protocol must still store (and give back) exactly the mission that was sent.
"""

from __future__ import annotations

import asyncio
import itertools
from collections import Counter
from collections.abc import AsyncIterator
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from sitl_stub.model import displace_deg
from tests.sitl_stub.conftest import Client, wp

HOME = Home(-35.363261, 149.165230, 584.0, 0.0)
FIELDS = ("seq", "frame", "command", "param1", "param2", "param3", "x", "y", "z")


def mission(n: int, east_m: float) -> list[Any]:
    """Home plus ``n`` waypoints 200 m apart going north, ``east_m`` east of home."""

    def at(north: float) -> tuple[float, float]:
        return displace_deg(HOME.lat_deg, HOME.lon_deg, HOME.alt_m, north, east_m)

    return [wp(0, *at(0.0))] + [wp(i, *at(200.0 * i), alt=50.0 + i) for i in range(1, n + 1)]


def stored_matches(team: SimTeam, items: list[Any]) -> bool:
    got = team.vehicles[0].autopilot.mission
    return len(got) == len(items) and all(
        (g.x, g.y, g.z, g.command, g.frame) == (s.x, s.y, s.z, s.command, s.frame)
        for g, s in zip(got[1:], items[1:], strict=True)
    )


def assert_download_matches(down: list[Any], items: list[Any]) -> None:
    assert len(down) == len(items)
    for sent, got in zip(items[1:], down[1:], strict=True):
        assert [getattr(sent, f) for f in FIELDS] == [getattr(got, f) for f in FIELDS]


async def command_rtt(c: Client) -> float:
    """Wall seconds from a COMMAND_LONG to its COMMAND_ACK."""
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    result = await c.command(
        mavlink2.MAV_CMD_REQUEST_MESSAGE, mavlink2.MAVLINK_MSG_ID_HOME_POSITION, timeout=5.0
    )
    assert result == mavlink2.MAV_RESULT_ACCEPTED
    return loop.time() - t0


async def answer_requests(c: Client, items: list[Any], *, first: Any, retry_s: float) -> int:
    """The rest of an upload whose MISSION_COUNT was taken: answer every request (copies
    too, as Client.upload does), resend the last item on silence; the ACK's result."""
    last = first
    c.send(last)
    async with asyncio.timeout(20.0):
        while True:
            msg = await c.try_recv(
                lambda m: m.get_type() in ("MISSION_REQUEST_INT", "MISSION_ACK"), retry_s
            )
            if msg is None:
                c.send(last)
            elif msg.get_type() == "MISSION_ACK":
                return int(msg.type)
            elif 0 <= msg.seq < len(items):
                last = items[msg.seq]
                c.send(last)


@pytest.fixture
async def team() -> AsyncIterator[SimTeam]:
    # A short re-request timeout: a reordered item costs 0.3 s, not 1.5 s. These tests are
    # about the link: items are kept exactly as sent (test_storage.py has ArduPilot's form).
    async with SimTeam.start(
        homes=[HOME],
        tcp_base=0,
        speedup=5.0,
        seed=11,
        mission_timeout_s=0.3,
        ardupilot_mission_storage=False,
    ) as t:
        yield t


async def test_latency_set_at_run_time_delays_both_directions(team: SimTeam) -> None:
    link = team.vehicles[0].link
    c = await Client.connect(team.ports[0])
    try:
        clean = await command_rtt(c)
        link.faults(latency_ms=120.0)
        assert not link.transparent
        delayed = await command_rtt(c)
        assert delayed >= 0.24  # 120 ms in, 120 ms out
        assert delayed > clean
        items = mission(5, 0.0)
        result = await c.upload(items, retry_s=0.6, deadline_s=20.0)
        assert result == mavlink2.MAV_MISSION_ACCEPTED
        assert stored_matches(team, items)
        link.faults(latency_ms=0.0)
        assert link.transparent
        assert await command_rtt(c) < delayed
    finally:
        await c.close()


async def test_duplication_set_at_run_time_keeps_upload_exact(team: SimTeam) -> None:
    link = team.vehicles[0].link
    link.faults(duplicate=1.0)
    c = await Client.connect(team.ports[0])
    try:
        items = mission(8, 100.0)
        # Item 0 goes out only once the vehicle has taken both copies of MISSION_COUNT (each
        # copy is answered with a request for item 0, itself duplicated: four requests per
        # COUNT sent). Under load the stub's delayed second copy can be handled after an item
        # that arrived later, and a COUNT taken after item 0 restarts the upload, after which
        # late copies of early items are accepted instead of ignored.
        counts_sent = 1
        c.send(mavlink2.MAVLink_mission_count_message(1, 1, len(items), 0))
        async with asyncio.timeout(20.0):
            while (
                sum(m.get_type() == "MISSION_REQUEST_INT" and m.seq == 0 for m in c.history)
                < 4 * counts_sent
            ):
                if await c.try_recv("MISSION_REQUEST_INT", 0.5) is None:
                    c.send(mavlink2.MAVLink_mission_count_message(1, 1, len(items), 0))
                    counts_sent += 1
        result = await answer_requests(c, items, first=items[0], retry_s=0.5)
        assert result == mavlink2.MAV_MISSION_ACCEPTED
        assert stored_matches(team, items)
        assert_download_matches(await c.download(retry_s=0.5), items)
        # Every request reached the client twice (the last copy may still be on its way when
        # the ACK is in); the vehicle ignored the second copy of each item.
        requests = Counter(m.seq for m in c.history if m.get_type() == "MISSION_REQUEST_INT")
        assert set(requests) == set(range(len(items)))
        assert all(requests[seq] >= 2 for seq in range(len(items) - 1))
        assert team.vehicles[0].mission.counters["ignored"] >= len(items) - 1
        assert link.inbound.duplicated > 0 and link.outbound.duplicated > 0
    finally:
        await c.close()


async def test_reordering_set_at_run_time_keeps_upload_exact(team: SimTeam) -> None:
    link = team.vehicles[0].link
    c = await Client.connect(team.ports[0])
    try:
        await c.recv("HEARTBEAT")
        link.faults(reorder=0.5, reorder_delay_ms=40.0)
        items = mission(8, 200.0)
        result = await c.upload(items, retry_s=0.5, deadline_s=30.0)
        assert result == mavlink2.MAV_MISSION_ACCEPTED
        assert stored_matches(team, items)
        assert_download_matches(await c.download(retry_s=0.5), items)
        # Seen on the wire: a packet arrives after one the vehicle sent later.
        seqs = [m.get_seq() for m in c.history]
        assert any((b - a) % 256 > 128 for a, b in itertools.pairwise(seqs))
        assert link.inbound.reordered > 0 and link.outbound.reordered > 0
    finally:
        await c.close()


async def test_all_faults_together_then_cleared(team: SimTeam) -> None:
    link = team.vehicles[0].link
    c = await Client.connect(team.ports[0])
    try:
        link.faults(latency_ms=30.0, duplicate=0.3, reorder=0.3, reorder_delay_ms=30.0)
        items = mission(20, 300.0)
        result = await c.upload(items, retry_s=0.4, deadline_s=40.0)
        assert result == mavlink2.MAV_MISSION_ACCEPTED
        assert stored_matches(team, items)
        assert_download_matches(await c.download(retry_s=0.4), items)
        link.clear()
        assert link.transparent
        before = link.outbound.passed + link.outbound.duplicated
        await c.recv("HEARTBEAT")
        assert link.outbound.passed + link.outbound.duplicated == before  # bypasses faults
    finally:
        await c.close()

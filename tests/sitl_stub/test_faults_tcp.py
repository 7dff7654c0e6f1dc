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


async def answer_requests(
    c: Client, items: list[Any], *, first: Any, retry_s: float
) -> tuple[int, Counter[int]]:
    """The rest of an upload whose MISSION_COUNT was taken: answer every request (copies
    too, as Client.upload does), resend the last item on silence. Returns the ACK's result
    and how many times each item was sent."""
    sent: Counter[int] = Counter()

    def send(item: Any) -> None:
        c.send(item)
        sent[item.seq] += 1

    last = first
    send(last)
    async with asyncio.timeout(20.0):
        while True:
            msg = await c.try_recv(
                lambda m: m.get_type() in ("MISSION_REQUEST_INT", "MISSION_ACK"), retry_s
            )
            if msg is None:
                send(last)
            elif msg.get_type() == "MISSION_ACK":
                return int(msg.type), sent
            elif 0 <= msg.seq < len(items):
                last = items[msg.seq]
                send(last)


async def vehicle_took(team: SimTeam, copies: int) -> None:
    """Wait until vehicle 0 has handled ``copies`` messages (delayed copies included)."""
    counters = team.vehicles[0].counters
    async with asyncio.timeout(20.0):
        while counters["received"] < copies:
            await asyncio.sleep(0.005)


def requests_seen(c: Client) -> Counter[int]:
    """How many MISSION_REQUEST_INT of each seq the client has received."""
    return Counter(m.seq for m in c.history if m.get_type() == "MISSION_REQUEST_INT")


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


async def least_rtt(c: Client, n: int = 3) -> float:
    """The quickest of ``n`` command round trips (a busy machine may slow any one of them)."""
    return min([await command_rtt(c) for _ in range(n)])


async def test_latency_set_at_run_time_delays_both_directions(team: SimTeam) -> None:
    link = team.vehicles[0].link
    c = await Client.connect(team.ports[0])
    try:
        clean = await least_rtt(c)
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
        assert await least_rtt(c) < delayed
    finally:
        await c.close()


async def test_duplication_set_at_run_time_keeps_upload_exact(team: SimTeam) -> None:
    vehicle = team.vehicles[0]
    link = vehicle.link
    link.faults(duplicate=1.0)
    c = await Client.connect(team.ports[0])
    try:
        items = mission(8, 100.0)
        # Every packet arrives twice, the copy 1 ms later. Item 0 goes out once the vehicle
        # has handled both copies of the one MISSION_COUNT, counted where it handles them:
        # the requests coming back do not tell, as the re-request timer sends them too. A
        # COUNT copy taken after the items would start a new upload that the items' delayed
        # copies, arriving in order, complete: accepted, not ignored.
        c.send(mavlink2.MAVLink_mission_count_message(1, 1, len(items), 0))
        await vehicle_took(team, 2)
        result, sent = await answer_requests(c, items, first=items[0], retry_s=0.5)
        assert result == mavlink2.MAV_MISSION_ACCEPTED
        # The COUNT and every item sent reached the vehicle twice; wait for the last copies.
        packets = 1 + sum(sent.values())
        await vehicle_took(team, 2 * packets)
        assert vehicle.counters["received"] == 2 * packets
        assert link.inbound.passed == link.inbound.duplicated == packets
        assert stored_matches(team, items)
        # One upload: the first copy of each item was taken, every other copy of an item
        # before the last was ignored (those of the last item are answered with the ACK).
        last = len(items) - 1
        assert set(sent) == set(range(len(items)))
        assert vehicle.mission.counters["uploads"] == 1
        assert vehicle.mission.counters["ignored"] == sum(
            2 * n - 1 for seq, n in sent.items() if seq != last
        )
        assert_download_matches(await c.download(retry_s=0.5), items)
        # Every request reached the client twice, both COUNT copies were answered (read on
        # until the last delayed copies are in).
        async with asyncio.timeout(20.0):
            while not ((r := requests_seen(c))[0] >= 4 and all(r[seq] >= 2 for seq in sent)):
                await c.try_recv(lambda m: False, 0.05)
        assert set(requests_seen(c)) == set(range(len(items)))
        assert link.outbound.duplicated > 0
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

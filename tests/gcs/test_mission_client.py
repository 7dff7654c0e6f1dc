"""The asyncio mission runner: over an in-memory link to the stub's MissionServer, then over
loopback TCP against the stub (SimTeam) with loss, a blackout, legacy requests and NACKs."""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Collection, Iterator
from dataclasses import replace
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.mavlink.link import Link
from gcs.mavlink.mission_client import (
    DEFAULT_WINDOW,
    clear_mission,
    download_mission,
    run_transfer,
    set_current_item,
    upload_mission,
)
from gcs.mavlink.mission_errors import (
    MissionDenied,
    MissionError,
    MissionInputError,
    MissionMismatch,
    MissionTimeout,
    MissionUnsupported,
)
from gcs.mavlink.mission_protocol import Clear, Upload
from planner.mission import (
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    Autopilot,
    MissionItem,
    Waypoint,
    compile_mission,
    items_equal,
)
from sitl_stub import items as stub_items
from sitl_stub.api import Home, SimTeam
from sitl_stub.mission_server import MissionServer

HOME = Home(-35.363261, 149.165230, 584.0, 0.0)
GCS_SYS, GCS_COMP = 255, 190
SPEEDUP = 20.0
# Loopback answers in about a millisecond: short protocol timeouts keep lossy runs quick.
FAST_S = 0.05
FENCE_VERTEX = int(mavlink2.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION)
RALLY_POINT = int(mavlink2.MAV_CMD_NAV_RALLY_POINT)


def home_item() -> MissionItem:
    return MissionItem(
        seq=0, frame=MAV_FRAME_GLOBAL, command=MAV_CMD_NAV_WAYPOINT, current=0, autocontinue=1,
        param1=0.0, param2=0.0, param3=0.0, param4=0.0,
        x=round(HOME.lat_deg * 1e7), y=round(HOME.lon_deg * 1e7), z=HOME.alt_m,
    )  # fmt: skip


def waypoints(n: int) -> list[MissionItem]:
    """Home and ``n - 1`` NAV_WAYPOINTs on a spiral within about 2 km of it."""
    items = [home_item()]
    for k in range(1, n):
        north_m, east_m = 10.0 * k * math.cos(0.3 * k), 10.0 * k * math.sin(0.3 * k)
        lat = HOME.lat_deg + north_m / 111_320.0
        lon = HOME.lon_deg + east_m / (111_320.0 * math.cos(math.radians(HOME.lat_deg)))
        wp = replace(home_item(), seq=k, frame=MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
        items.append(replace(wp, x=round(lat * 1e7), y=round(lon * 1e7), z=100.0 + 0.5 * k))
    return items


def geofence_items(n: int, mission_type: int, command: int) -> list[MissionItem]:
    return [
        replace(it, command=command, param1=float(n), mission_type=mission_type, frame=5)
        for it in waypoints(n)
    ]


def stored(team: SimTeam, mission_type: int = 0) -> list[MissionItem]:
    return [_planner(it) for it in team.vehicles[0].mission.items(mission_type)]


def _planner(it: stub_items.MissionItem) -> MissionItem:
    return MissionItem(
        seq=it.seq, frame=it.frame, command=it.command, current=it.current,
        autocontinue=it.autocontinue, param1=it.param1, param2=it.param2, param3=it.param3,
        param4=it.param4, x=it.x, y=it.y, z=it.z, mission_type=it.mission_type,
    )  # fmt: skip


# -- an in-memory link to the stub's sans-IO server ---------------------------------------


class _Sub:
    def __init__(self, types: frozenset[str] | None, system_id: int | None) -> None:
        self.types, self.system_id = types, system_id
        self.queue: asyncio.Queue[Any] = asyncio.Queue()

    async def get(self, timeout_s: float | None = None) -> Any | None:
        try:
            async with asyncio.timeout(timeout_s):
                return await self.queue.get()
        except TimeoutError:
            return None


class MemoryLink:
    """The part of gcs.mavlink.link.Link the runner uses, wired to a MissionServer in memory."""

    system_id, component_id = GCS_SYS, GCS_COMP

    def __init__(self, server: MissionServer) -> None:
        self.server = server
        self.subs: list[_Sub] = []
        self.listeners: list[Any] = []
        self.sent: list[Any] = []
        self.alter_download: Any = None
        self.deaf = False  # drop everything the GCS sends
        self._tx = mavlink2.MAVLink(None, srcSystem=GCS_SYS, srcComponent=GCS_COMP)
        self._vehicle = mavlink2.MAVLink(None, srcSystem=server.system_id, srcComponent=1)

    @contextlib.contextmanager
    def subscribe(
        self, types: Collection[str] | None = None, system_id: int | None = None
    ) -> Iterator[_Sub]:
        sub = _Sub(None if types is None else frozenset(types), system_id)
        self.subs.append(sub)
        try:
            yield sub
        finally:
            self.subs.remove(sub)

    def add_listener(self, callback: Any) -> Any:
        self.listeners.append(callback)
        return lambda: self.listeners.remove(callback)

    def _deliver(self, reply: Any) -> None:
        # Like a socket: replies arrive on a later pass of the event loop, never inside send().
        now = asyncio.get_running_loop().time()
        for listener in list(self.listeners):
            listener(reply, now)
        for sub in self.subs:
            if (sub.types is None or reply.get_type() in sub.types) and (
                sub.system_id in (None, reply.get_srcSystem())
            ):
                sub.queue.put_nowait(reply)

    def send(self, msg: Any) -> bool:
        self.sent.append(msg)
        if self.deaf:
            return True
        (parsed,) = mavlink2.MAVLink(None).parse_buffer(msg.pack(self._tx))
        now = asyncio.get_running_loop().time()
        for s in self.server.handle(parsed, 1, now).sends:
            out = s.msg
            if out.get_type() == "MISSION_ITEM_INT" and self.alter_download is not None:
                out = self.alter_download(out)
            (reply,) = mavlink2.MAVLink(None).parse_buffer(out.pack(self._vehicle))
            asyncio.get_running_loop().call_soon(self._deliver, reply)
        return True


def memory_link(system_id: int = 1) -> MemoryLink:
    home = stub_items.MissionItem(seq=0, frame=0, command=16, x=home_item().x, y=home_item().y)
    return MemoryLink(MissionServer(system_id=system_id, home=replace(home, z=HOME.alt_m)))


async def test_upload_then_download_over_a_memory_link_reports_progress() -> None:
    link = memory_link()
    items = waypoints(30)
    seen: list[tuple[int, int]] = []
    await upload_mission(link, 1, items, progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (30, 30) and all(t == 30 for _, t in seen)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)
    down = await download_mission(link, 1)
    assert items_equal(items, down, autopilot=Autopilot.ARDUPILOT)
    assert link.sent[-1].get_type() == "MISSION_ACK"  # the download's closing ACK


async def test_verify_passes_when_the_vehicle_gives_the_items_back() -> None:
    link = memory_link()
    await upload_mission(link, 1, waypoints(5), verify=True)
    assert [m.get_type() for m in link.sent].count("MISSION_REQUEST_LIST") == 1


async def test_verify_names_the_first_item_that_came_back_different() -> None:
    link = memory_link()

    def shift(msg: Any) -> Any:
        if msg.seq == 3:
            msg.x += 1
        return msg

    link.alter_download = shift
    with pytest.raises(MissionMismatch, match="mission upload verification failed at item 3") as e:
        await upload_mission(link, 1, waypoints(5), verify=True)
    assert e.value.seq == 3 and "read back NAV_WAYPOINT" in str(e.value)


async def test_bad_items_are_refused_before_anything_is_sent() -> None:
    link = memory_link()
    items = waypoints(3)
    items[2] = replace(items[2], seq=7)
    with pytest.raises(MissionInputError, match="item 2: seq is 7"):
        await upload_mission(link, 1, items)
    assert link.sent == []


async def test_transfers_with_one_vehicle_take_turns() -> None:
    link = memory_link()
    a, b = waypoints(20), waypoints(10)
    async with asyncio.timeout(10):
        await asyncio.gather(upload_mission(link, 1, a), upload_mission(link, 1, b))
    counts = [m.count for m in link.sent if m.get_type() == "MISSION_COUNT"]
    assert counts == [20, 10]
    assert len(link.server.items()) == 10


async def test_silent_vehicle_ends_in_mission_timeout_not_a_hang() -> None:
    link = memory_link(system_id=1)
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    async with asyncio.timeout(5):
        with pytest.raises(MissionTimeout) as e:
            await download_mission(link, 9, timeout_s=FAST_S, retries=3)
    # It asked four times (the first and three retries), each time waiting its timeout out:
    # counted from what it sent, and at least as long as the four timeouts (a busy machine
    # only makes it longer; the 5 s bound above is the hang it must not be).
    sent = [m.get_type() for m in link.sent]
    assert sent == ["MISSION_REQUEST_LIST"] * 4 + ["MISSION_ACK"], sent  # the ACK: given up
    assert loop.time() - t0 >= 4 * FAST_S - 1e-3
    assert str(e.value) == (
        "vehicle 9: mission download timed out waiting for MISSION_COUNT after 3 retries"
    )
    assert isinstance(e.value, TimeoutError)


async def test_a_cancelled_upload_tells_the_vehicle() -> None:
    link = memory_link()
    link.deaf = True
    with pytest.raises(TimeoutError):
        async with asyncio.timeout(0.2):
            await upload_mission(link, 1, waypoints(3), timeout_s=1.0)
    assert [m.get_type() for m in link.sent] == ["MISSION_COUNT", "MISSION_ACK"]
    assert link.sent[-1].type == mavlink2.MAV_MISSION_OPERATION_CANCELLED
    link.deaf = False
    await upload_mission(link, 1, waypoints(3))  # the lock was released


async def test_the_watchdog_ends_a_transfer_that_never_moves() -> None:
    class Stuck(Clear):
        def tick(self, now_s: float) -> list[Any]:
            return []  # a broken state machine: never resends, never gives up

    link = memory_link()
    link.deaf = True
    stuck = Stuck(target_system=1, timeout_s=0.01, retries=1)
    async with asyncio.timeout(2):
        with pytest.raises(MissionTimeout, match="vehicle 1: mission clear timed out: no prog"):
            await run_transfer(link, stuck)


async def test_denied_clear_while_another_gcs_uploads_is_typed() -> None:
    link = memory_link()
    other = mavlink2.MAVLink(None, srcSystem=250, srcComponent=190)
    (count,) = mavlink2.MAVLink(None).parse_buffer(
        mavlink2.MAVLink_mission_count_message(1, 1, 5, 0).pack(other)
    )
    link.server.handle(count, 2, 0.0)  # another GCS, on another link, starts an upload
    with pytest.raises(MissionDenied, match="vehicle 1: mission clear denied"):
        await clear_mission(link, 1)


# -- over loopback against the stub ------------------------------------------------------


@contextlib.asynccontextmanager
async def stub_and_link(**team_kw: Any) -> AsyncIterator[tuple[SimTeam, Link]]:
    team_kw.setdefault("mission_timeout_s", FAST_S)
    async with (
        SimTeam.start(homes=[HOME], tcp_base=0, speedup=SPEEDUP, **team_kw) as team,
        Link.open(f"tcp:127.0.0.1:{team.ports[0]}") as link,
    ):
        await link.wait_vehicle(1, timeout_s=5.0)
        yield team, link


@pytest.mark.parametrize("loss", [0.0, 0.3])
async def test_200_item_mission_round_trips_unchanged(loss: float) -> None:
    """200 items, 30 % loss both ways: about 100 lost exchanges each way, so 10 ms timeouts
    (loopback answers in about 1 ms) keep this to a few seconds. Five retries are not enough
    at this loss (see the protocol tests' outcome counts): 50 silent timeouts in a row,
    0.5 s, are what gives up here."""
    items = waypoints(200)
    async with stub_and_link(mission_timeout_s=0.03) as (team, link), asyncio.timeout(40):
        team.vehicles[0].link.faults(loss=loss)
        await upload_mission(link, 1, items, timeout_s=0.01, retries=50)
        assert items_equal(items, stored(team), autopilot=Autopilot.ARDUPILOT)
        down = await download_mission(link, 1, timeout_s=0.01, retries=50)
        assert items_equal(items, down, autopilot=Autopilot.ARDUPILOT)
        if loss:
            assert team.vehicles[0].link.inbound.lost > 10
            assert team.vehicles[0].link.outbound.lost > 10


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_upload_outlasting_a_5_s_blackout_completes() -> None:
    """The blackout lasts 5 s of wall time, as the timeouts that must outlast it are counted
    (a blackout of simulated seconds lasts longer in wall time the slower a busy machine runs
    the simulation)."""
    items = waypoints(60)

    def black_out_midway(done: int, total: int) -> None:
        if done == 30:
            vehicle_link = team.vehicles[0].link
            vehicle_link.blackout(1e6)
            asyncio.get_running_loop().call_later(5.0, vehicle_link.clear)

    # Six silent 1.5 s timeouts (9 s) outlast the 5 s blackout; so do the stub's re-requests.
    async with stub_and_link(mission_timeout_s=1.5) as (team, link), asyncio.timeout(60):
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        await upload_mission(link, 1, items, progress=black_out_midway)
        assert loop.time() - t0 >= 4.5
        assert team.vehicles[0].link.inbound.blacked_out > 0
        assert not team.vehicles[0].link.in_blackout
        assert items_equal(items, stored(team), autopilot=Autopilot.ARDUPILOT)


async def test_upload_into_a_blackout_with_short_timeouts_raises_mission_timeout() -> None:
    items = waypoints(60)
    blackout_at: list[float] = []

    def black_out_midway(done: int, total: int) -> None:
        if done == 30 and not blackout_at:
            team.vehicles[0].link.blackout(5.0 * SPEEDUP)
            blackout_at.append(asyncio.get_running_loop().time())

    async with stub_and_link(mission_timeout_s=1.5) as (team, link), asyncio.timeout(10):
        with pytest.raises(MissionTimeout) as e:
            await upload_mission(
                link, 1, items, timeout_s=0.2, retries=4, progress=black_out_midway
            )
        # Bounded by the retries, not by the blackout: given up while it still runs (100 s
        # of simulation, 5 s of wall time at least; the retries wait 1 s).
        assert blackout_at and team.vehicles[0].link.in_blackout
        # Items already sent ahead of the requests (the window) may get through before it.
        assert e.value.seq is not None and 30 <= e.value.seq <= 32 + DEFAULT_WINDOW
        assert f"timed out waiting for a request for item {e.value.seq} after 4 retries" in (
            str(e.value)
        )
        assert stored(team) != items  # the stub keeps the old mission


async def test_legacy_mission_request_flow_round_trips() -> None:
    items = waypoints(50)
    async with stub_and_link(legacy_mission_requests=True) as (team, link), asyncio.timeout(20):
        up = Upload(items, target_system=1, own_system=GCS_SYS, own_component=GCS_COMP)
        await run_transfer(link, up)
        assert up.counters["legacy_requests"] >= 50  # the vehicle asked with MISSION_REQUEST
        assert items_equal(items, stored(team), autopilot=Autopilot.ARDUPILOT)
        assert items_equal(items, await download_mission(link, 1), autopilot=Autopilot.ARDUPILOT)


async def test_download_gives_the_vehicles_home_at_item_zero() -> None:
    compiled = compile_mission(
        home=Waypoint(HOME.lat_deg + 0.01, HOME.lon_deg, 600.0),  # not the vehicle's home
        waypoints=[Waypoint(HOME.lat_deg + 0.02, HOME.lon_deg, 700.0)],
        takeoff_alt_m=50.0,
    )
    async with stub_and_link() as (_team, link), asyncio.timeout(20):
        await upload_mission(link, 1, compiled, verify=True)  # verify skips home
        down = await download_mission(link, 1)
    assert down[0].x == round(HOME.lat_deg * 1e7) and down[0].y == round(HOME.lon_deg * 1e7)
    assert down[0].z == pytest.approx(HOME.alt_m)
    assert down[0].frame == MAV_FRAME_GLOBAL
    assert items_equal(compiled, down, compare_home=False, autopilot=Autopilot.ARDUPILOT)
    assert not items_equal(compiled, down, autopilot=Autopilot.ARDUPILOT)


async def test_unsupported_command_is_refused_naming_the_item() -> None:
    items = waypoints(50)
    items[37] = replace(items[37], command=int(mavlink2.MAV_CMD_DO_SET_SERVO))
    async with stub_and_link() as (team, link), asyncio.timeout(20):
        await upload_mission(link, 1, waypoints(5))
        with pytest.raises(MissionUnsupported) as e:
            await upload_mission(link, 1, items)
        assert str(e.value) == (
            "vehicle 1: mission upload rejected item 37: MAV_MISSION_UNSUPPORTED "
            "(command not supported)"
        )
        assert (e.value.seq, e.value.result, e.value.vehicle) == (37, 3, 1)
        assert items_equal(
            waypoints(5), stored(team), autopilot=Autopilot.ARDUPILOT
        )  # the stored mission is kept


@pytest.mark.parametrize(("mission_type", "command"), [(1, FENCE_VERTEX), (2, RALLY_POINT)])
async def test_fence_and_rally_round_trip_beside_the_mission(
    mission_type: int, command: int
) -> None:
    items = geofence_items(8, mission_type, command)
    async with stub_and_link() as (team, link), asyncio.timeout(20):
        await upload_mission(link, 1, waypoints(4))
        await upload_mission(link, 1, items, mission_type=mission_type, verify=True)
        assert items_equal(
            items,
            await download_mission(link, 1, mission_type=mission_type),
            autopilot=Autopilot.ARDUPILOT,
        )
        assert items_equal(
            waypoints(4), stored(team), autopilot=Autopilot.ARDUPILOT
        )  # the flown mission is untouched
        await clear_mission(link, 1, mission_type=mission_type)
        assert await download_mission(link, 1, mission_type=mission_type) == []
        assert len(stored(team)) == 4


async def test_clear_and_empty_upload_leave_home_only() -> None:
    async with stub_and_link() as (team, link), asyncio.timeout(20):
        await upload_mission(link, 1, waypoints(6))
        await clear_mission(link, 1)
        assert len(await download_mission(link, 1)) == 1
        await upload_mission(link, 1, waypoints(6))
        await upload_mission(link, 1, [], verify=True)
        assert len(stored(team)) == 1


async def test_set_current_item_is_confirmed_and_a_refused_one_times_out() -> None:
    async with stub_and_link() as (team, link), asyncio.timeout(20):
        await upload_mission(link, 1, waypoints(10))
        await set_current_item(link, 1, 4)
        assert team.vehicles[0].autopilot.current_seq == 4
        with pytest.raises(MissionTimeout) as e:
            await set_current_item(link, 1, 40, timeout_s=0.2, retries=2)
        assert "waiting for MISSION_CURRENT with seq 40 after 2 retries" in str(e.value)
        assert "(the vehicle last reported current item 4" in str(e.value)


async def test_vehicle_that_is_not_there_times_out_quickly() -> None:
    async with stub_and_link() as (_team, link), asyncio.timeout(5):
        with pytest.raises(MissionTimeout, match="vehicle 7: mission upload timed out"):
            await upload_mission(link, 7, waypoints(3), timeout_s=FAST_S, retries=2)


def test_errors_are_gcs_errors() -> None:
    from gcs.errors import GcsError

    assert issubclass(MissionError, GcsError) and issubclass(MissionTimeout, TimeoutError)

"""gcs.mavlink.link over loopback: TCP (stub and hand-driven vehicles), UDP, serial (pty)."""

from __future__ import annotations

import asyncio
import contextlib
import os
from collections.abc import AsyncIterator
from typing import Any

import pytest
from pymavlink.dialects.v20 import all as mavlink_all
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.errors import ConnectionStringError, LinkTimeout
from gcs.mavlink.endpoints import Endpoint, Kind, parse_connection
from gcs.mavlink.link import Link
from gcs.mavlink.signing import SigningConfig, apply_signing, key_from_passphrase
from gcs.mavlink.status import status_line
from gcs.mavlink.telemetry import VehicleState
from sitl_stub.api import Home, SimTeam
from tests.gcs.conftest import HOME, Packer, TcpVehicle, free_udp_port, heartbeat


async def until(pred: Any, timeout_s: float = 5.0, step_s: float = 0.01) -> None:
    async with asyncio.timeout(timeout_s):
        while not pred():
            await asyncio.sleep(step_s)


# -- connection strings --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("tcp:127.0.0.1:5760", Endpoint(Kind.TCP, host="127.0.0.1", port=5760)),
        ("udpin:0.0.0.0:14550", Endpoint(Kind.UDPIN, host="0.0.0.0", port=14550)),
        ("udp:127.0.0.1:14550", Endpoint(Kind.UDPIN, host="127.0.0.1", port=14550)),
        ("udpout:10.0.0.2:14550", Endpoint(Kind.UDPOUT, host="10.0.0.2", port=14550)),
        ("serial:/dev/ttyUSB0:115200", Endpoint(Kind.SERIAL, device="/dev/ttyUSB0", baud=115200)),
        ("serial:/dev/ttyACM0", Endpoint(Kind.SERIAL, device="/dev/ttyACM0", baud=57600)),
        ("/dev/ttyACM0,921600", Endpoint(Kind.SERIAL, device="/dev/ttyACM0", baud=921600)),
        ("TCP:localhost:5762", Endpoint(Kind.TCP, host="localhost", port=5762)),
    ],
)
def test_connection_strings_parse(text: str, expected: Endpoint) -> None:
    assert parse_connection(text) == expected


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("", "empty"),
        ("tcp:127.0.0.1", "HOST:PORT"),
        ("tcp:127.0.0.1:http", "'http' is not a number"),
        ("udpin:127.0.0.1:70000", "outside 1..65535"),
        ("serial:/dev/ttyUSB0:fast", "baud rate 'fast'"),
        ("bluetooth:aa:bb", "expected tcp:HOST:PORT"),
    ],
)
def test_bad_connection_strings_name_the_problem(text: str, words: str) -> None:
    with pytest.raises(ConnectionStringError, match=words):
        parse_connection(text)


# -- against the stub ----------------------------------------------------------------------


async def test_discovers_vehicles_sends_heartbeat_and_measures_rtt() -> None:
    async with (
        SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=5.0) as team,
        Link.open(f"tcp:127.0.0.1:{team.ports[0]}", timesync_period_s=1.0) as link,
    ):
        peer = await link.wait_vehicle(1, timeout_s=5.0)
        assert (peer.system_id, peer.component_id) == (1, 1)
        assert peer.mav_type == mavlink2.MAV_TYPE_FIXED_WING
        assert peer.autopilot == mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA
        await until(lambda: link.counters.rtt_s is not None, timeout_s=5.0)
        assert link.counters.rtt_s is not None and 0.0 <= link.counters.rtt_s < 0.5
        assert link.counters.seq_lost == 0 and link.counters.crc_errors == 0
        with pytest.raises(LinkTimeout, match="no HEARTBEAT from vehicle 7"):
            await link.wait_vehicle(7, timeout_s=0.3)


async def test_fan_out_gives_every_subscriber_the_same_reply() -> None:
    async with (
        SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=5.0) as team,
        Link.open(f"tcp:127.0.0.1:{team.ports[0]}") as link,
    ):
        await link.wait_vehicle(1)
        seen: list[str] = []
        remove = link.add_listener(lambda m, _t: seen.append(m.get_type()))
        with (
            link.subscribe({"COMMAND_ACK"}, system_id=1) as a,
            link.subscribe({"COMMAND_ACK"}) as b,
            link.subscribe({"COMMAND_ACK"}, system_id=2) as other,
        ):
            cmd = mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES
            assert link.send(mavlink2.MAVLink_command_long_message(1, 1, cmd, 0, 1, *[0] * 6))
            ack_a = await a.get(timeout_s=3.0)
            ack_b = await b.get(timeout_s=3.0)
            assert ack_a is not None and ack_b is not None
            assert ack_a.command == ack_b.command == cmd
            assert other.get_nowait() is None
        remove()
        assert "COMMAND_ACK" in seen
        n = len(seen)
        await asyncio.sleep(0.3)
        assert len(seen) == n  # the removed listener hears nothing more


async def test_stream_rate_request_raises_position_rate() -> None:
    async with SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=1.0) as team:
        port = team.ports[0]
        counts: dict[str, int] = {}

        def count(m: Any, _t: float) -> None:
            counts[m.get_type()] = counts.get(m.get_type(), 0) + 1

        # Counted on the vehicle's own clock (each message's time_boot_ms), not the wall's: a
        # busy machine delays the messages, it does not change their rate.
        boot_ms: dict[str, list[int]] = {}

        def stamp(m: Any, _t: float) -> None:
            if m.get_type() in ("GLOBAL_POSITION_INT", "SYSTEM_TIME"):
                boot_ms.setdefault(m.get_type(), []).append(int(m.time_boot_ms))

        rates = {"GLOBAL_POSITION_INT": 10.0}
        async with Link.open(f"tcp:127.0.0.1:{port}", message_rates_hz=rates) as link:
            await link.wait_vehicle(1)
            link.add_listener(count)
            link.add_listener(stamp)
            for _ in range(600):  # 30 s of wall at most, however busy the machine
                if len(boot_ms.get("GLOBAL_POSITION_INT", ())) >= 40:
                    break
                await asyncio.sleep(0.05)
        # The stub's default is 2 Hz; the request asks for 10 Hz: the last 20 (the request
        # took effect well before: the first come within the first 2 s of its clock).
        fixes = boot_ms["GLOBAL_POSITION_INT"][-21:]
        span_s = (fixes[-1] - fixes[0]) / 1000.0
        assert (len(fixes) - 1) / span_s == pytest.approx(10.0, rel=0.15), (len(fixes), span_s)
        clock = [t for t in boot_ms.get("SYSTEM_TIME", []) if fixes[0] <= t <= fixes[-1]]
        assert len(clock) <= span_s * 1.0 + 1, (clock, span_s)  # its own 1 Hz, unchanged
        assert counts["GLOBAL_POSITION_INT"] >= len(fixes)


# -- hand-driven vehicles: reconnect, garbage, sequence gaps ---------------------------------


@contextlib.asynccontextmanager
async def _linked(**options: Any) -> AsyncIterator[tuple[TcpVehicle, Link]]:
    """A TCP vehicle on a free loopback port and a link connected to it (``options`` for
    :meth:`Link.open`); the vehicle is stopped after."""
    vehicle = TcpVehicle()
    port = await vehicle.start()
    try:
        async with Link.open(f"tcp:127.0.0.1:{port}", **options) as link:
            await link.wait_connected(2.0)
            yield vehicle, link
    finally:
        await vehicle.stop()


async def test_reconnects_with_backoff_after_the_connection_drops() -> None:
    async with _linked(reconnect_min_s=0.05) as (vehicle, link):
        vehicle.send(Packer(1).pack(heartbeat()))
        await link.wait_vehicle(1, timeout_s=2.0)
        vehicle.drop_clients()
        await until(lambda: vehicle.connections == 2, timeout_s=3.0)
        await link.wait_connected(2.0)
        assert link.counters.reconnects == 1
        # The new connection carries traffic both ways.
        with link.subscribe({"HEARTBEAT"}) as sub:
            vehicle.send(Packer(1).pack(heartbeat()))
            assert await sub.get(timeout_s=2.0) is not None
        await until(lambda: len(vehicle.of_type("HEARTBEAT")) >= 2, timeout_s=3.0)


async def test_connect_failures_retry_until_the_vehicle_appears() -> None:
    vehicle = TcpVehicle()
    port = await vehicle.start()
    await vehicle.stop()  # nobody listens on the port yet
    conn = f"tcp:127.0.0.1:{port}"
    async with Link.open(conn, reconnect_min_s=0.05, reconnect_max_s=0.2) as link:
        await until(lambda: link.counters.connect_failures >= 2, timeout_s=3.0)
        assert not link.connected
        assert link.send(heartbeat()) is False
        assert link.counters.send_dropped >= 1
        await vehicle.start(port)
        try:
            await link.wait_connected(3.0)
        finally:
            await vehicle.stop()


def _corrupt_crc(frame: bytes) -> bytes:
    b = bytearray(frame)
    b[-1] ^= 0xFF
    return bytes(b)


async def test_garbage_crc_errors_and_unknown_systems_are_counted_and_dropped() -> None:
    bad, good = TcpVehicle(), TcpVehicle()
    bad_port, good_port = await bad.start(), await good.start()
    try:
        async with (
            Link.open(f"tcp:127.0.0.1:{bad_port}", system_ids={1}) as link,
            Link.open(f"tcp:127.0.0.1:{good_port}") as other,
        ):
            await link.wait_connected(2.0)
            await other.wait_connected(2.0)
            got: list[Any] = []
            link.add_listener(lambda m, _t: got.append(m))
            v1, v9, v0 = Packer(1), Packer(9), Packer(0)
            pos = mavlink2.MAVLink_global_position_int_message(
                1, -353632610, 1491652300, 584000, 0, 0, 0, 0, 0
            )
            stream = b"".join(
                [
                    b"\x00\x13garbage bytes\xff",
                    v1.pack(heartbeat()),
                    _corrupt_crc(v1.pack(pos)),
                    v9.pack(heartbeat()),  # not in system_ids
                    v0.pack(pos),  # system id 0 is never a sender
                    bytes(range(1, 40)),
                    v1.pack(pos),
                ]
            )
            # Split the stream at awkward places: framing must survive partial reads.
            for i in range(0, len(stream), 7):
                bad.send(stream[i : i + 7])
                await asyncio.sleep(0)
            good.send(Packer(2).pack(heartbeat()))
            await until(lambda: len(got) == 2, timeout_s=3.0)
            await asyncio.sleep(0.1)
            c = link.counters
            assert [m.get_type() for m in got] == ["HEARTBEAT", "GLOBAL_POSITION_INT"]
            assert c.crc_errors == 1
            assert c.garbage_bytes >= 15
            assert c.unknown_system == 1
            assert c.malformed >= 1
            assert set(link.vehicles) == {1}
            await other.wait_vehicle(2, timeout_s=2.0)
            assert other.counters.crc_errors == other.counters.garbage_bytes == 0
            assert link.connected and other.connected
    finally:
        await bad.stop()
        await good.stop()


async def test_sequence_gaps_count_lost_packets() -> None:
    async with _linked() as (vehicle, link):
        p = Packer(1)
        frames = [p.pack(heartbeat()) for _ in range(10)]
        for i in (0, 1, 2, 5, 6, 9):  # 3, 4, 7, 8 lost
            vehicle.send(frames[i])
        await until(lambda: link.counters.received == 6, timeout_s=2.0)
        assert link.counters.seq_lost == 4
        assert link.counters.seq_out_of_order == 0
        vehicle.send(frames[7])  # late arrival: reordering, not loss
        await until(lambda: link.counters.received == 7, timeout_s=2.0)
        assert link.counters.seq_lost == 4
        assert link.counters.seq_out_of_order == 1


def _undecodable(seq: int) -> bytes:
    """A MAVLink 2 frame from system 1 with sequence ``seq`` carrying a message of the full
    dialect (pymavlink's ``all``: MISSION_CHECKSUM, id 53, from ``development.xml``, which
    PX4 sends) that ArduPilot's dialect, the link's, does not have."""
    mav = mavlink_all.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.seq = seq
    assert 53 not in mavlink2.mavlink_map
    msg = mavlink_all.mavlink_map[53](0, 0)
    return bytes(msg.pack(mav))


async def test_messages_the_dialect_cannot_decode_are_unknown_not_lost() -> None:
    async with _linked() as (vehicle, link):
        p = Packer(1)
        frames = [p.pack(heartbeat()) for _ in range(6)]
        frames[2] = _undecodable(2)  # a PX4 message in the sequence
        frames[4] = _undecodable(4)
        for frame in frames:
            vehicle.send(frame)
        await until(lambda: link.counters.received == 4, timeout_s=2.0)
        await until(lambda: link.counters.unknown_message == 2, timeout_s=2.0)
        assert link.counters.seq_lost == 0
        assert link.counters.seq_out_of_order == 0
        assert link.counters.malformed == link.counters.crc_errors == 0
        line = status_line(VehicleState(system_id=1), link.counters, 0.0)
        assert "lost 0 rtt" in line and line.endswith("unknown 2"), line


async def test_slow_subscriber_keeps_the_newest_messages() -> None:
    async with _linked() as (vehicle, link):
        p = Packer(1)
        with link.subscribe({"SYSTEM_TIME"}, maxsize=3) as sub:
            times = [mavlink2.MAVLink_system_time_message(i, i) for i in range(10)]
            vehicle.send(b"".join(p.pack(m) for m in times))
            await until(lambda: link.counters.received == 10, timeout_s=2.0)
            kept = [sub.get_nowait().time_boot_ms for _ in range(3)]
            assert kept == [7, 8, 9]
            assert sub.dropped == 7 and link.counters.subscriber_overflow == 7


# -- UDP: several vehicles on one port; through MAVProxy -----------------------------------


class UdpVehicle(asyncio.DatagramProtocol):
    def __init__(self, sysid: int) -> None:
        self.packer = Packer(sysid)
        self.parser = mavlink2.MAVLink(None)
        self.received: list[Any] = []
        self.transport: asyncio.DatagramTransport | None = None
        self.last_addr: Any = None

    def connection_made(self, transport: Any) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.last_addr = addr
        self.received.extend(self.parser.parse_buffer(data) or [])

    def send(self, msg: Any, addr: Any = None) -> None:
        assert self.transport is not None
        self.transport.sendto(self.packer.pack(msg), addr)


async def test_udpin_serves_two_vehicles_and_routes_replies_by_system_id() -> None:
    loop = asyncio.get_running_loop()
    port = free_udp_port()
    async with Link.open(f"udpin:127.0.0.1:{port}") as link:
        await link.wait_connected(2.0)
        vehicles = []
        for sysid in (3, 4):
            _, proto = await loop.create_datagram_endpoint(
                lambda s=sysid: UdpVehicle(s), local_addr=("127.0.0.1", 0)
            )
            vehicles.append(proto)
        try:
            for v in vehicles:
                v.send(heartbeat(), ("127.0.0.1", port))
            await link.wait_vehicle(3, timeout_s=2.0)
            await link.wait_vehicle(4, timeout_s=2.0)
            cmd = mavlink2.MAV_CMD_COMPONENT_ARM_DISARM
            link.send(mavlink2.MAVLink_command_long_message(4, 1, cmd, 0, 1, *[0] * 6))
            await until(lambda: any(m.get_type() == "COMMAND_LONG" for m in vehicles[1].received))
            await asyncio.sleep(0.1)
            assert not any(m.get_type() == "COMMAND_LONG" for m in vehicles[0].received)

            # Broadcasts (the GCS heartbeat) reach both.
            def all_heard() -> bool:
                return all(any(m.get_type() == "HEARTBEAT" for m in v.received) for v in vehicles)

            await until(all_heard)
        finally:
            for v in vehicles:
                assert v.transport is not None
                v.transport.close()


async def test_udpout_talks_to_a_listening_vehicle() -> None:
    loop = asyncio.get_running_loop()
    transport, vehicle = await loop.create_datagram_endpoint(
        lambda: UdpVehicle(1), local_addr=("127.0.0.1", 0)
    )
    port = transport.get_extra_info("sockname")[1]
    try:
        async with Link.open(f"udpout:127.0.0.1:{port}") as link:
            # We speak first (heartbeat on connect); the vehicle answers to our address.
            await until(lambda: any(m.get_type() == "HEARTBEAT" for m in vehicle.received))
            with link.subscribe({"HEARTBEAT"}, system_id=1) as sub:
                vehicle.send(heartbeat(), vehicle.last_addr)
                assert await sub.get(timeout_s=2.0) is not None
            assert set(link.vehicles) == {1}
    finally:
        transport.close()


# -- serial over a pseudo-terminal -----------------------------------------------------------


async def test_serial_link_over_a_pty() -> None:
    master, slave = os.openpty()
    path = os.ttyname(slave)
    try:
        async with Link.open(f"serial:{path}:115200") as link:
            await link.wait_connected(2.0)
            os.write(master, Packer(1).pack(heartbeat()))
            await link.wait_vehicle(1, timeout_s=2.0)
            parser = mavlink2.MAVLink(None)
            loop = asyncio.get_running_loop()
            got: list[Any] = []

            def readable() -> None:
                got.extend(parser.parse_buffer(os.read(master, 4096)) or [])

            loop.add_reader(master, readable)
            try:
                await until(lambda: any(m.get_type() == "HEARTBEAT" for m in got), timeout_s=3.0)
            finally:
                loop.remove_reader(master)
            hb = next(m for m in got if m.get_type() == "HEARTBEAT")
            assert hb.type == mavlink2.MAV_TYPE_GCS
            assert (hb.get_srcSystem(), hb.get_srcComponent()) == (255, 190)
    finally:
        os.close(master)
        os.close(slave)


# -- signing ---------------------------------------------------------------------------------


async def test_signing_rejects_unsigned_and_forged_without_locking_out_the_vehicle() -> None:
    key = key_from_passphrase("correct horse")
    vehicle = TcpVehicle()
    port = await vehicle.start()
    config = SigningConfig(secret_key=key, link_id=1)
    apply_signing(vehicle.parser, SigningConfig(secret_key=key), outgoing=False)
    try:
        async with Link.open(f"tcp:127.0.0.1:{port}", signing=config) as link:
            await link.wait_connected(2.0)
            signed, unsigned, wrong = Packer(1), Packer(1), Packer(1)
            apply_signing(signed.mav, SigningConfig(secret_key=key), outgoing=True)
            other_key = SigningConfig(secret_key=key_from_passphrase("x"))
            apply_signing(wrong.mav, other_key, outgoing=True)
            wrong.mav.signing.timestamp += 10**9  # a forged packet from far in the future
            vehicle.send(unsigned.pack(heartbeat()))
            vehicle.send(wrong.pack(heartbeat()))
            radio = mavlink2.MAVLink_radio_status_message(200, 190, 80, 30, 20, 0, 0)
            vehicle.send(unsigned.pack(radio))  # SiK radios inject this unsigned: allowed
            vehicle.send(signed.pack(heartbeat()))
            await link.wait_vehicle(1, timeout_s=2.0)
            await until(lambda: link.counters.received == 2)
            assert link.counters.bad_signature == 2
            # Our own messages are signed with the key: the vehicle's checking parser accepts them.
            await until(lambda: len(vehicle.of_type("HEARTBEAT")) >= 1)
            assert all(m._signed for m in vehicle.received)
    finally:
        await vehicle.stop()


def test_signing_config_rejects_bad_keys() -> None:
    with pytest.raises(ValueError, match="32 bytes"):
        SigningConfig(secret_key=b"short")
    with pytest.raises(ValueError, match="unknown MAVLink message 'NOPE'"):
        SigningConfig(secret_key=bytes(32), allow_unsigned={"NOPE"})


def test_signing_timestamp_is_in_10us_units_since_2015() -> None:
    from gcs.mavlink.signing import signing_timestamp

    assert signing_timestamp(1420070400.0) == 0
    assert signing_timestamp(1420070401.5) == 150_000

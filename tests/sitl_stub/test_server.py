"""Batched writes of the TCP transport, with a recording transport (no sockets)."""

from __future__ import annotations

import asyncio
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from sitl_stub.server import MAX_WRITE_BUFFER_BYTES, VehiclePort

HOME = Home(-35.363261, 149.165230, 584.0, 0.0)


class RecordingTransport(asyncio.Transport):
    def __init__(self) -> None:
        super().__init__()
        self.writes: list[bytes] = []
        self.buffered = 0
        self.closed = False

    def write(self, data: bytes | bytearray | memoryview) -> None:
        self.writes.append(bytes(data))

    def get_write_buffer_size(self) -> int:
        return self.buffered

    def is_closing(self) -> bool:
        return self.closed

    def close(self) -> None:
        self.closed = True


def connect(port: VehiclePort) -> RecordingTransport:
    transport = RecordingTransport()
    port.new_connection().connection_made(transport)
    return transport


def decode(data: bytes) -> list[Any]:
    parser = mavlink2.MAVLink(None)
    return list(parser.parse_buffer(data) or [])


async def test_packets_of_one_loop_pass_go_out_in_one_write_in_order() -> None:
    team = SimTeam.create(homes=[HOME, HOME])
    ports = team.server.ports
    t1, t2, t3 = connect(ports[0]), connect(ports[0]), connect(ports[1])
    team.step(10)  # one simulated second: every stream of both vehicles
    assert not t1.writes and not t3.writes  # nothing is written until the loop runs
    await asyncio.sleep(0)
    assert len(t1.writes) == 1 and t2.writes == t1.writes  # same bytes to every client
    msgs = decode(t1.writes[0])
    assert len(msgs) >= 13 and {m.get_srcSystem() for m in msgs} == {1}
    assert [m.get_seq() for m in msgs] == list(range(len(msgs)))
    assert len(t3.writes) == 1 and {m.get_srcSystem() for m in decode(t3.writes[0])} == {2}
    team.step(5)
    await asyncio.sleep(0)
    assert len(t1.writes) == 2


async def test_a_client_that_does_not_read_loses_packets_not_memory() -> None:
    team = SimTeam.create(homes=[HOME])
    port = team.server.ports[0]
    t = connect(port)
    t.buffered = MAX_WRITE_BUFFER_BYTES + 1
    team.step(10)
    await asyncio.sleep(0)
    assert t.writes == []
    assert port.dropped_backpressure > 10
    t.buffered = 0
    team.step(10)
    await asyncio.sleep(0)
    assert len(t.writes) == 1


async def test_close_writes_what_is_queued_first() -> None:
    team = SimTeam.create(homes=[HOME])
    port = team.server.ports[0]
    t = connect(port)
    team.step(1)
    await port.close()
    assert len(t.writes) == 1 and t.writes[0][0] == 0xFD
    assert t.closed

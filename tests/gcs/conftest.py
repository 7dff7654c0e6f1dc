"""Shared helpers for gcs tests: free ports and a hand-driven MAVLink vehicle over TCP/UDP."""

from __future__ import annotations

import asyncio
import socket
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

HOME = (-35.363261, 149.165230, 584.0)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def heartbeat(autopilot: int = mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA) -> Any:
    return mavlink2.MAVLink_heartbeat_message(
        mavlink2.MAV_TYPE_FIXED_WING, autopilot, 0, 0, mavlink2.MAV_STATE_STANDBY, 3
    )


class Packer:
    """Frames messages as system ``sysid`` would (its own sequence numbers)."""

    def __init__(self, sysid: int, compid: int = 1) -> None:
        self.mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)

    def pack(self, msg: Any) -> bytes:
        data = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        return data


class TcpVehicle:
    """A TCP server that plays a vehicle by hand: records what the GCS sends, sends bytes."""

    def __init__(self) -> None:
        self.server: asyncio.Server | None = None
        self.writers: list[asyncio.StreamWriter] = []
        self.parser = mavlink2.MAVLink(None)
        self.parser.robust_parsing = True
        self.received: list[Any] = []
        self.connections = 0

    async def start(self, port: int = 0) -> int:
        self.server = await asyncio.start_server(self._serve, "127.0.0.1", port)
        return int(self.server.sockets[0].getsockname()[1])

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.connections += 1
        self.writers.append(writer)
        while data := await reader.read(65536):
            for m in self.parser.parse_buffer(data) or []:
                if m.get_type() != "BAD_DATA":
                    self.received.append(m)

    def send(self, data: bytes) -> None:
        for w in self.writers:
            if not w.is_closing():
                w.write(data)

    def drop_clients(self) -> None:
        for w in self.writers:
            w.close()
        self.writers.clear()

    async def stop(self) -> None:
        self.drop_clients()
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()

    def of_type(self, name: str) -> list[Any]:
        return [m for m in self.received if m.get_type() == name]

"""A raw pymavlink-codec TCP client for loopback tests against the stub."""

from __future__ import annotations

import asyncio
import contextlib
import sys
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.service.stubs import free_tcp_base

Pred = Callable[[Any], bool]


def free_port_base(n: int = 1, stride: int = 10) -> int:
    """A base port with ``n`` free ports at ``stride`` spacing, the service's own choice
    (:func:`gcs.service.stubs.free_tcp_base`: below the ephemeral range, at random)."""
    return free_tcp_base(n, stride)


class Client:
    """A GCS-side MAVLink 2 endpoint over one TCP connection (no background tasks)."""

    def __init__(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, sysid: int
    ) -> None:
        self.reader = reader
        self.writer = writer
        self.mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=190)
        self.parser = mavlink2.MAVLink(None)
        self.parser.robust_parsing = True
        self.history: list[Any] = []
        self._pending: list[Any] = []

    @classmethod
    async def connect(cls, port: int, sysid: int = 255) -> Client:
        async with asyncio.timeout(5):
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
        return cls(reader, writer, sysid)

    async def close(self) -> None:
        self.writer.close()
        try:
            async with asyncio.timeout(2):
                await self.writer.wait_closed()
        except (OSError, TimeoutError):
            pass

    def send(self, msg: Any) -> None:
        self.writer.write(msg.pack(self.mav))

    def send_raw(self, data: bytes) -> None:
        self.writer.write(data)

    async def recv(self, match: str | Pred, timeout: float = 5.0) -> Any:
        """The next new message matching a type name or predicate."""
        pred: Pred = (lambda m: m.get_type() == match) if isinstance(match, str) else match
        async with asyncio.timeout(timeout):
            while True:
                while self._pending:
                    msg = self._pending.pop(0)
                    if pred(msg):
                        return msg
                data = await self.reader.read(65536)
                if not data:
                    raise ConnectionError("vehicle closed the connection")
                msgs = self.parser.parse_buffer(data) or []
                self.history.extend(msgs)
                self._pending.extend(msgs)

    async def try_recv(self, match: str | Pred, timeout: float) -> Any | None:
        try:
            return await self.recv(match, timeout)
        except TimeoutError:
            return None

    async def command(
        self, command: int, *params: float, sysid: int = 1, timeout: float = 5.0
    ) -> int:
        p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
        self.send(mavlink2.MAVLink_command_long_message(sysid, 1, command, 0, *p))
        ack = await self.recv(
            lambda m: m.get_type() == "COMMAND_ACK" and m.command == command, timeout
        )
        return int(ack.result)

    async def upload(
        self,
        items: list[Any],
        *,
        sysid: int = 1,
        mission_type: int = 0,
        retry_s: float = 0.3,
        deadline_s: float = 60.0,
    ) -> int:
        """Upload MISSION_ITEM_INT messages, resending on timeout; return the ACK result."""
        last: Any = mavlink2.MAVLink_mission_count_message(sysid, 1, len(items), mission_type)
        self.send(last)

        def reply(m: Any) -> bool:
            return (
                m.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK")
                and m.get_srcSystem() == sysid
                and m.mission_type == mission_type
            )

        async with asyncio.timeout(deadline_s):
            while True:
                msg = await self.try_recv(reply, retry_s)
                if msg is None:
                    self.send(last)
                    continue
                if msg.get_type() == "MISSION_ACK":
                    return int(msg.type)
                if 0 <= msg.seq < len(items):
                    last = items[msg.seq]
                    self.send(last)

    async def download(
        self, *, sysid: int = 1, mission_type: int = 0, retry_s: float = 0.3
    ) -> list[Any]:
        """Download with MISSION_REQUEST_INT, retrying each request on timeout."""
        req = mavlink2.MAVLink_mission_request_list_message(sysid, 1, mission_type)
        async with asyncio.timeout(60):
            count = None
            while count is None:
                self.send(req)
                count = await self.try_recv(
                    lambda m: m.get_type() == "MISSION_COUNT" and m.get_srcSystem() == sysid,
                    retry_s,
                )
            items: list[Any] = []
            for seq in range(count.count):
                got = None
                while got is None:
                    self.send(
                        mavlink2.MAVLink_mission_request_int_message(sysid, 1, seq, mission_type)
                    )
                    got = await self.try_recv(
                        lambda m, s=seq: m.get_type() == "MISSION_ITEM_INT" and m.seq == s,
                        retry_s,
                    )
                items.append(got)
            self.send(mavlink2.MAVLink_mission_ack_message(sysid, 1, 0, mission_type))
            return items


def wp(
    seq: int,
    lat: float,
    lon: float,
    alt: float = 100.0,
    command: int = mavlink2.MAV_CMD_NAV_WAYPOINT,
    *,
    sysid: int = 1,
    p1: float = 0.0,
    p2: float = 0.0,
    p3: float = 0.0,
    frame: int = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
) -> Any:
    return mavlink2.MAVLink_mission_item_int_message(
        sysid, 1, seq, frame, command, 0, 1, p1, p2, p3, 0.0,
        round(lat * 1e7), round(lon * 1e7), alt, 0,
    )  # fmt: skip


async def stop_process(proc: asyncio.subprocess.Process) -> None:
    """Terminate a peer process, kill it if it has not gone after 10 s, and reap it."""
    if proc.returncode is None:
        proc.terminate()
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(10):
            await proc.wait()
    if proc.returncode is None:
        proc.kill()
        await proc.wait()


async def mavproxy_wp_list(master: str, workdir: Path, count: int, timeout_s: float = 30.0) -> str:
    """MAVProxy's output for "wp list" typed once the vehicle is online, up to "Saved N"."""
    mavproxy = Path(sys.executable).with_name("mavproxy.py")
    proc = await asyncio.create_subprocess_exec(
        sys.executable, str(mavproxy), "--master", master, "--state-basedir", str(workdir),
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
        cwd=workdir,
    )  # fmt: skip
    out: list[str] = []
    try:
        assert proc.stdout is not None and proc.stdin is not None
        async with asyncio.timeout(timeout_s):
            while line := (await proc.stdout.readline()).decode(errors="replace"):
                out.append(line)
                if "online system" in line:
                    # --cmd runs before the vehicle is seen; type the command instead.
                    proc.stdin.write(b"wp list\n")
                    await proc.stdin.drain()
                if f"Saved {count} waypoints" in line:
                    break
    finally:
        if proc.stdin is not None:
            proc.stdin.close()
        await stop_process(proc)
    return "".join(out)


@contextlib.asynccontextmanager
async def mavproxy_router(master: str, out: str, workdir: Path, *extra: str) -> AsyncIterator[None]:
    """MAVProxy between a vehicle (``master``) and us (``out``), non-interactive."""
    mavproxy = Path(sys.executable).with_name("mavproxy.py")
    proc = await asyncio.create_subprocess_exec(
        sys.executable, str(mavproxy), "--master", master, "--out", out,
        "--state-basedir", str(workdir), "--daemon", "--non-interactive", *extra,
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.DEVNULL,
        cwd=workdir,
    )  # fmt: skip
    try:
        yield
    finally:
        await stop_process(proc)

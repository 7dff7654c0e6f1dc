"""gcs against independent MAVLink peers: MAVProxy as a UDP router, MAVSDK as another client."""

from __future__ import annotations

import asyncio
import contextlib
import sys
from collections.abc import AsyncIterator
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.link import Link
from sitl_stub.api import Home, SimTeam
from tests.gcs.conftest import HOME, free_udp_port


@contextlib.asynccontextmanager
async def mavproxy_router(master: str, out: str, workdir: Path) -> AsyncIterator[None]:
    """MAVProxy between a vehicle (``master``) and us (``out``), non-interactive."""
    mavproxy = Path(sys.executable).with_name("mavproxy.py")
    proc = await asyncio.create_subprocess_exec(
        sys.executable, str(mavproxy), "--master", master, "--out", out,
        "--state-basedir", str(workdir), "--daemon", "--non-interactive",
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.DEVNULL,
        cwd=workdir,
    )  # fmt: skip
    try:
        yield
    finally:
        if proc.returncode is None:
            proc.terminate()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(10):
                await proc.wait()
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


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

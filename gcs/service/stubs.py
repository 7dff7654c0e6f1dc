"""Bundled simulator vehicles on request: ``python -m sitl_stub`` in a child process.

:meth:`StubProcess.start` picks free TCP ports in ArduPilot SITL's layout (vehicle ``i`` at
``base + 10 i``), starts the simulator with the arguments given and waits for its ready line;
:meth:`StubProcess.stop` interrupts it (and kills it if it does not stop).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import secrets
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from gcs.coordination.missionclock import MissionClock
from gcs.errors import GcsError
from sitl_stub.lockstep import Lockstep

__all__ = [
    "DEFAULT_SPEEDUP",
    "IDLE_EXIT_S",
    "StubProcess",
    "follow_lockstep",
    "free_tcp_base",
]

DEFAULT_SPEEDUP = 200.0
"""Simulated seconds per wall second of bundled simulator vehicles unless told otherwise
(``rehearse --speedup``, a flight's ``rehearsal.speedup``, the demo)."""
IDLE_EXIT_S = 120.0
"""A bundled simulator with no client for this long (wall s) stops: its ground station died
and did not come back (a service restarted within it reaches the vehicles again)."""


PORT_RANGE = (10_000, 32_000)
"""Where a simulator's ports are looked for: below Linux's ephemeral range (32768-60999), so
that no outgoing connection of this machine (a client, a link, a database session) is given
one of them between the look and the simulator's bind; a random base in it, so that two
processes looking at once (two flights, parallel tests) rarely pick the same."""


def free_tcp_base(n: int, stride: int = 10) -> int:
    """A base port with ``n`` free ports at ``stride`` (10: the SITL layout), each checked by
    binding it on loopback."""
    lo, hi = PORT_RANGE
    for _ in range(200):
        base = lo + secrets.randbelow(hi - lo - stride * n)
        ok = True
        for i in range(n):
            with socket.socket() as sock:
                try:
                    sock.bind(("127.0.0.1", base + stride * i))
                except OSError:
                    ok = False
                    break
        if ok:
            return base
    raise GcsError(f"no {n} free TCP ports at stride {stride} in {lo}-{hi}")


@dataclass
class StubProcess:
    """A running simulator of ``count`` vehicles on ``base``, ``base + 10``, ..."""

    proc: asyncio.subprocess.Process
    base: int
    count: int

    @property
    def connections(self) -> list[str]:
        return [f"tcp:127.0.0.1:{self.base + 10 * i}" for i in range(self.count)]

    @classmethod
    async def start(
        cls, count: int, args: Sequence[str], *, control: bool = False, timeout_s: float = 30.0
    ) -> StubProcess:
        """``python -m sitl_stub --vehicles COUNT --tcp-base BASE ARGS``, ready; with
        ``control`` its control input is open (``--control-stdin``) for :meth:`control`."""
        base = free_tcp_base(count)
        cmd = [sys.executable, "-m", "sitl_stub", "--vehicles", str(count), "--tcp-base", str(base)]
        cmd += list(args)
        # A simulator whose ground station died and did not come back stops by itself.
        cmd += ["--idle-exit", str(IDLE_EXIT_S)]
        if control:
            cmd.append("--control-stdin")
        proc = await asyncio.create_subprocess_exec(
            *cmd,
            stdin=subprocess.PIPE if control else subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        stub = cls(proc, base, count)
        try:
            await stub._wait_ready(timeout_s)
        except BaseException:
            await stub.stop()
            raise
        return stub

    async def _wait_ready(self, timeout_s: float) -> None:
        proc = self.proc
        assert proc.stdout is not None
        async with asyncio.timeout(timeout_s):
            while True:
                line = await proc.stdout.readline()
                if not line:
                    err = b""
                    if proc.stderr is not None:
                        err = await proc.stderr.read()
                    raise GcsError(f"sitl_stub exited before it was ready: {err.decode().strip()}")
                if b"ready" in line:
                    return

    def control(self, line: str) -> None:
        """One line on the simulator's control input (e.g. ``blackout I START_S DURATION_S``)."""
        if self.proc.stdin is None:
            raise GcsError("the simulator was started without its control input")
        self.proc.stdin.write(line.rstrip("\n").encode() + b"\n")

    async def stop(self) -> None:
        """Interrupt the simulator; kill it if it has not stopped within 10 s."""
        proc = self.proc
        if proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGINT)
            try:
                async with asyncio.timeout(10.0):
                    await proc.wait()
            except TimeoutError:
                proc.kill()
                await proc.wait()


async def stop_pid(pid: int, timeout_s: float = 10.0) -> None:
    """Interrupt a simulator this process did not start (one an earlier service process
    left flying, known by its pid) and wait until it has gone, its files closed; kill it if
    it has not stopped within ``timeout_s`` (wall)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.kill(pid, signal.SIGINT)
        deadline = time.monotonic() + timeout_s
        while _running(pid):
            if time.monotonic() > deadline:
                os.kill(pid, signal.SIGKILL)
                return
            await asyncio.sleep(0.02)


def _running(pid: int) -> bool:
    """Whether ``pid`` runs: it exists and is not a zombie left for its parent to reap."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True
    return stat.rsplit(")", 1)[-1].split()[0] != "Z"


def follow_lockstep(
    path: Path, clock: MissionClock, on_overrun: Callable[[float], None] | None = None
) -> asyncio.Task[None]:
    """Lock step with the simulator that keeps ``path`` (``sitl_stub --lockstep``): the
    mission clock runs on its pace clock, and a task acknowledges the flight as the event
    loop turns, every millisecond of wall time, so the simulator waits for this process
    (cancel the task to let it run on by itself).

    An event loop held longer than the lock step waits for (:data:`sitl_stub.lockstep.
    STALE_WALL_S`) lets the simulator fly on without this process: ``on_overrun`` is then
    called, once the loop turns again, with the flight seconds it ran beyond the lead. While
    the clock holds the flight (:meth:`MissionClock.hold`: a planning job) nothing past that
    pace time is acknowledged, nor ever past the newest report of a vehicle still talking
    (:meth:`MissionClock.heard_pace_s`: one behind a router that falls behind is waited
    for)."""
    pace = Lockstep(path)
    clock.follow(pace.pace_s, pace.lead_s, pace.speedup)
    return asyncio.create_task(_acknowledge(pace, clock, on_overrun))


OVERRUN_SAID_S = 1.0
"""Flight seconds beyond the lead that are said (a simulator step or two past it is not)."""


async def _acknowledge(
    pace: Lockstep, clock: MissionClock, on_overrun: Callable[[float], None] | None
) -> None:
    # The furthest pace time acknowledged: the simulator may have flown to its lead (an
    # acknowledgement taken back, when a backlog of reports comes in, holds it from there).
    furthest_s = -math.inf
    try:
        while True:
            seen_s = pace.pace_s()
            if math.isfinite(furthest_s) and on_overrun is not None:
                beyond_s = (seen_s - furthest_s) * pace.speedup - pace.lead_s
                if beyond_s > OVERRUN_SAID_S:
                    on_overrun(beyond_s)
                    furthest_s = seen_s - pace.lead_s / pace.speedup  # said: counted once
            held_s = clock.held_pace_s
            if held_s is not None:
                seen_s = min(seen_s, held_s)
            seen_s = min(seen_s, clock.heard_pace_s(time.monotonic(), pace.speedup))
            pace.acknowledge(seen_s)
            furthest_s = max(furthest_s, seen_s)
            await asyncio.sleep(0.001)
    finally:
        pace.release()
        pace.close()

"""``python -m gcs serve`` in a child process on a free loopback port, as an operator's client
(the demo, the tests) reaches it: started, ready (``/v1/health`` answers), stopped after."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import socket
import sys
from collections.abc import AsyncIterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import httpx

from gcs.errors import GcsError

__all__ = ["ServiceProcess", "free_port", "running_service", "wait_ready"]


@dataclass
class ServiceProcess:
    url: str
    proc: asyncio.subprocess.Process
    stderr: bytes = b""
    """What the service wrote on its standard error (read when it has stopped)."""


def free_port() -> int:
    """A free TCP port on the loopback address."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.asynccontextmanager
async def running_service(
    data_dir: Path,
    tokens: Mapping[str, Sequence[str]],
    *,
    database_url: str | None = None,
    settings: Mapping[str, str] | None = None,
    ready_within_s: float = 120.0,
    stop_within_s: float = 30.0,
) -> AsyncIterator[ServiceProcess]:
    """The service on ``data_dir`` (its SQLite file there unless ``database_url``) with these
    tokens and any other ``settings`` (``TCGCS_*`` variables); interrupted on exit (killed if
    it has not stopped within ``stop_within_s``).

    Raises
    ------
    GcsError
        It exited, or did not answer ``/v1/health`` within ``ready_within_s``.
    """
    port = free_port()
    env = {
        **os.environ,
        "TCGCS_DATA_DIR": str(data_dir),
        "TCGCS_TOKENS": json.dumps({t: list(s) for t, s in tokens.items()}),
    }
    env.pop("TCGCS_DATABASE_URL", None)
    if database_url is not None:
        env["TCGCS_DATABASE_URL"] = database_url
    env.update(settings or {})
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "gcs", "serve", "--port", str(port), env=env,
        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    service = ServiceProcess(f"http://127.0.0.1:{port}", proc)
    try:
        await wait_ready(service, ready_within_s)
        yield service
    finally:
        if proc.returncode is None:
            proc.send_signal(signal.SIGINT)
        try:
            async with asyncio.timeout(stop_within_s):
                _, err = await proc.communicate()
        except TimeoutError:
            proc.kill()
            _, err = await proc.communicate()
        service.stderr = err or b""


async def wait_ready(service: ServiceProcess, within_s: float) -> None:
    """Until the service answers ``/v1/health``.

    Raises
    ------
    GcsError
        It exited, or did not answer within ``within_s``.
    """
    proc = service.proc
    loop = asyncio.get_running_loop()
    until = loop.time() + within_s
    async with httpx.AsyncClient(base_url=service.url) as client:
        while loop.time() < until:
            if proc.returncode is not None:
                err = b"" if proc.stderr is None else await proc.stderr.read()
                raise GcsError(f"the service did not start: {err.decode()[-2000:]}")
            with contextlib.suppress(httpx.TransportError):
                if (await client.get("/v1/health")).status_code == 200:
                    return
            await asyncio.sleep(0.1)
    raise GcsError(f"the service did not answer /v1/health within {within_s:g} s")

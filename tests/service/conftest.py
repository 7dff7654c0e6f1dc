"""The service as an operator reaches it: ``python -m gcs serve`` in its own process on a free
loopback port, an embedded SQLite (or PostgreSQL) in a temporary data directory."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import socket
import sys
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

TOKEN = "service-test-admin-token"


@dataclass
class Service:
    url: str
    data_dir: Path
    proc: asyncio.subprocess.Process

    def client(self, token: str = TOKEN) -> httpx.AsyncClient:
        return httpx.AsyncClient(
            base_url=self.url, headers={"Authorization": f"Bearer {token}"}, timeout=60.0
        )


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.asynccontextmanager
async def serve(data_dir: Path, database_url: str | None = None) -> AsyncIterator[Service]:
    port = _free_port()
    env = {
        **os.environ,
        "TCGCS_DATA_DIR": str(data_dir),
        "TCGCS_TOKENS": json.dumps({TOKEN: ["admin"]}),
    }
    env.pop("TCGCS_DATABASE_URL", None)
    if database_url is not None:
        env["TCGCS_DATABASE_URL"] = database_url
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "gcs", "serve", "--port", str(port), env=env,
        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}"
    try:
        async with httpx.AsyncClient(base_url=url) as client:
            async with asyncio.timeout(30):
                while True:
                    assert proc.returncode is None, "the service exited"
                    with contextlib.suppress(httpx.TransportError):
                        if (await client.get("/v1/health")).status_code == 200:
                            break
                    await asyncio.sleep(0.1)
        yield Service(url, data_dir, proc)
    finally:
        if proc.returncode is None:
            proc.send_signal(signal.SIGINT)
        async with asyncio.timeout(30):
            _, err = await proc.communicate()
        assert b"Traceback" not in err, err.decode()[-3000:]


@pytest.fixture
async def service(tmp_path: Path) -> AsyncIterator[Service]:
    async with serve(tmp_path / "data") as s:
        yield s

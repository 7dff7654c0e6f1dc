"""The service as an operator reaches it: ``python -m gcs serve`` in its own process on a free
loopback port, an embedded SQLite (or PostgreSQL) in a temporary data directory."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from gcs.api.process import running_service

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


@contextlib.asynccontextmanager
async def serve(
    data_dir: Path, database_url: str | None = None, settings: Mapping[str, str] | None = None
) -> AsyncIterator[Service]:
    async with running_service(
        data_dir, {TOKEN: ["admin"]}, database_url=database_url, settings=settings
    ) as svc:
        yield Service(svc.url, data_dir, svc.proc)
    assert b"Traceback" not in svc.stderr, svc.stderr.decode()[-3000:]


@pytest.fixture
async def service(tmp_path: Path) -> AsyncIterator[Service]:
    async with serve(tmp_path / "data") as s:
        yield s

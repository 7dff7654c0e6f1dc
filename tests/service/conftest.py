"""The service as an operator reaches it: ``python -m gcs serve`` in its own process on a free
loopback port, an embedded SQLite (or PostgreSQL) in a temporary data directory."""

from __future__ import annotations

import asyncio
import contextlib
import subprocess
import sys
from collections.abc import AsyncIterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from gcs.api.process import running_service

TOKEN = "service-test-admin-token"


def proc_stat(pid: int) -> list[str]:
    """A process's fields in /proc/PID/stat after its name (the kernel's field 3 on: state,
    ppid, ... nice is the 17th here)."""
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()


def nice_of(pid: int) -> int:
    """A process's ``nice``, read by the kernel's account (/proc/PID/stat, field 19)."""
    return int(proc_stat(pid)[16])


def may_raise_priority() -> bool:
    """Whether a process of this user may run ahead of the default priority (CAP_SYS_NICE)."""
    probe = subprocess.run([sys.executable, "-c", "import os; os.nice(-1)"], check=False)
    return probe.returncode == 0


@dataclass
class Service:
    url: str
    data_dir: Path
    proc: asyncio.subprocess.Process

    def spare_workers(self) -> list[int]:
        """The pids of the flight workers it keeps loaded, waiting for a flight (its children
        run as ``gcs.service.worker --standby``)."""
        found = []
        for proc in Path("/proc").glob("[0-9]*"):
            try:
                ppid = int(proc_stat(int(proc.name))[1])
                argv = (proc / "cmdline").read_bytes().split(b"\0")
            except (OSError, IndexError, ValueError):
                continue  # gone meanwhile
            if ppid == self.proc.pid and b"--standby" in argv:
                found.append(int(proc.name))
        return found

    def client(self, token: str = TOKEN) -> httpx.AsyncClient:
        return httpx.AsyncClient(
            base_url=self.url, headers={"Authorization": f"Bearer {token}"}, timeout=60.0
        )


@contextlib.asynccontextmanager
async def serve(
    data_dir: Path,
    database_url: str | None = None,
    settings: Mapping[str, str] | None = None,
    *,
    spare_worker: bool = False,
) -> AsyncIterator[Service]:
    """``gcs serve`` on ``data_dir``; without the spare flight worker it keeps loaded by
    default (``spare_worker``: the tests that kill a worker keep it, as an operator would; the
    others would start one process more each and never use it)."""
    env = {"TCGCS_SPARE_WORKER": str(spare_worker).lower(), **(settings or {})}
    async with running_service(
        data_dir, {TOKEN: ["admin"]}, database_url=database_url, settings=env
    ) as svc:
        yield Service(svc.url, data_dir, svc.proc)
    assert b"Traceback" not in svc.stderr, svc.stderr.decode()[-3000:]


@pytest.fixture
async def service(tmp_path: Path) -> AsyncIterator[Service]:
    async with serve(tmp_path / "data") as s:
        yield s


@pytest.fixture
async def spare_service(tmp_path: Path) -> AsyncIterator[Service]:
    """The service keeping its spare flight worker loaded (its default): for the tests that
    kill a worker."""
    async with serve(tmp_path / "data", spare_worker=True) as s:
        yield s

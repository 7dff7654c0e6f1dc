"""Shared helpers for the API tests: one token per scope, the app on a store (SQLite, and
PostgreSQL where a test touches what is kept), an in-process client with the app's lifespan
run."""

from __future__ import annotations

import asyncio
import secrets
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi import FastAPI

from gcs.api.app import create_app
from gcs.api.settings import SCOPES, Settings
from tests.gcs.conftest import PAPER, store_url

__all__ = [
    "PAPER",
    "TOKENS",
    "app_with",
    "auth",
    "job_until",
    "problem",
    "running",
    "settings_for",
    "store_url",
]

TOKENS: dict[str, str] = {scope: f"tcgcs-{scope}-{secrets.token_hex(16)}" for scope in SCOPES}
"""scope -> a token holding only that scope (fresh each run, so a leak is that string)."""


def auth(scope: str = "admin") -> dict[str, str]:
    """The ``Authorization`` header of the token for ``scope``."""
    return {"Authorization": f"Bearer {TOKENS[scope]}"}


def settings_for(data_dir: Path, database_url: str | None, *, tokens: bool = True) -> Settings:
    table = {token: [scope] for scope, token in TOKENS.items()} if tokens else {}
    # No spare flight worker kept loaded: these tests kill none, and each would start one.
    return Settings(data_dir=data_dir, database_url=database_url, tokens=table, spare_worker=False)


@pytest.fixture
def db_url(tmp_path: Path) -> str:
    """The store of the app: SQLite (a module whose tests touch what is kept overrides it
    with ``store_url``, SQLite and PostgreSQL)."""
    return f"sqlite:///{tmp_path / 'tcgcs.db'}"


def app_with(tmp_path: Path, **settings: Any) -> FastAPI:
    """The app on a SQLite file in ``tmp_path``, a token for every scope, with these
    settings changed (limits, folders)."""
    base = settings_for(tmp_path / "data", f"sqlite:///{tmp_path / 'tcgcs.db'}")
    return create_app(base.model_copy(update=settings))


async def job_until(client: httpx.AsyncClient, job_id: str, *states: str) -> dict[str, Any]:
    """Poll a job until it is in one of ``states``."""
    for _ in range(6000):
        job: dict[str, Any] = (await client.get(f"/v1/jobs/{job_id}", headers=auth())).json()
        if job["state"] in states:
            return job
        await asyncio.sleep(0.02)
    raise AssertionError(f"job {job_id} never reached {states}: {job}")


async def running(app: FastAPI) -> AsyncIterator[httpx.AsyncClient]:
    """A client of ``app`` in process, the app's lifespan (engine, store) around it."""
    transport = httpx.ASGITransport(app=app)
    async with (
        app.router.lifespan_context(app),
        httpx.AsyncClient(transport=transport, base_url="http://tcgcs.test") as client,
    ):
        yield client


@pytest.fixture
def app(tmp_path: Path, db_url: str) -> FastAPI:
    """The app on ``db_url``, with a token for every scope."""
    return create_app(settings_for(tmp_path / "data", db_url))


@pytest.fixture
async def client(app: FastAPI) -> AsyncIterator[httpx.AsyncClient]:
    async for c in running(app):
        yield c


def problem(r: httpx.Response, status: int) -> dict[str, Any]:
    """The error body of ``r``, which has ``status``."""
    assert r.status_code == status, (r.status_code, r.text)
    assert r.headers["content-type"].startswith("application/json"), r.headers
    body: dict[str, Any] = r.json()
    assert isinstance(body.get("detail"), str), body
    return body

"""A live vehicle whose link goes down is shown as such: ``link.healthy`` false, its mode and
armed state unknown (null) rather than the last ones it sent, which are kept as
``last_mode`` and ``last_armed``; while the link is up the two agree."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import httpx
from fastapi import FastAPI

from gcs.service.stubs import free_tcp_base
from tests.api.conftest import PAPER, auth, running
from tests.gcs.conftest import start_stub


async def _view(client: httpx.AsyncClient, vid: str) -> dict[str, Any]:
    r = await client.get(f"/v1/vehicles/{vid}", headers=auth())
    assert r.status_code == 200, r.text
    view: dict[str, Any] = r.json()
    return view


async def _until(client: httpx.AsyncClient, vid: str, healthy: bool) -> dict[str, Any]:
    """The vehicle's view once its link is (or is no longer) healthy; at most a minute."""
    for _ in range(600):
        view = await _view(client, vid)
        if view["link"]["healthy"] is healthy and (not healthy or view["mode"] is not None):
            return view
        await asyncio.sleep(0.1)
    raise AssertionError(f"vehicle {vid}: link never became healthy={healthy}: {view}")


async def test_a_vehicle_whose_link_is_down_shows_no_mode_and_keeps_its_last_word(
    app: FastAPI, tmp_path: Path
) -> None:
    base = free_tcp_base(1, 10)
    stub = await start_stub(PAPER, base, tmp_path / "truth.jsonl", vehicles=1)
    try:
        async for client in running(app):
            r = await client.post(
                "/v1/vehicles", json={"connection": f"tcp:127.0.0.1:{base}"}, headers=auth()
            )
            assert r.status_code == 201, r.text
            vid = r.json()["id"]
            up = await _until(client, vid, healthy=True)
            assert up["mode"] == up["last_mode"] and up["mode"] is not None, up
            assert up["armed"] is up["last_armed"] is False, up  # on the ground, disarmed
            stub.kill()
            await stub.wait()
            down = await _until(client, vid, healthy=False)
            assert down["link"]["heartbeat_age_s"] > 3.0, down
            assert down["mode"] is None and down["armed"] is None, down
            assert (down["last_mode"], down["last_armed"]) == (up["mode"], up["armed"]), down
    finally:
        if stub.returncode is None:
            stub.kill()
            await stub.wait()

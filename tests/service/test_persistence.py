"""What the service keeps, on an embedded SQLite and on the PostgreSQL server at
127.0.0.1:5432 (a fresh schema; in CI a server that cannot be reached is a failure)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml
from sqlalchemy import text

from gcs.api.demo import sse_messages
from gcs.store.repository import Store
from tests.gcs.conftest import PAPER, postgres_schema
from tests.service.conftest import serve
from tests.teams import compact_paper


@pytest.fixture(params=["sqlite", "postgresql"])
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'kept.db'}"
    else:
        yield from postgres_schema()


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_scenarios_flights_and_their_events_are_kept_in_the_database(
    database_url: str, tmp_path: Path
) -> None:
    async with serve(tmp_path / "data", database_url) as service, service.client() as client:
        body = PAPER.read_text(encoding="utf-8")
        r = await client.post(
            "/v1/scenarios", content=body, headers={"Content-Type": "application/yaml"}
        )
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        again = await client.post(
            "/v1/scenarios", content=body, headers={"Content-Type": "application/yaml"}
        )
        assert again.json()["id"] == sid  # content-hashed: the same text is the same scenario
        job = (await client.post("/v1/schedules", json={"scenario_id": sid, "seed": 1})).json()
        while job["state"] in ("queued", "running"):
            job = (await client.get(f"/v1/jobs/{job['id']}")).json()
        assert job["state"] == "succeeded", job
        r = await client.post(
            "/v1/flights",
            json={"schedule_id": job["result"]["id"], "rehearsal": {"speedup": 50.0}},
        )
        assert r.status_code == 201, r.text
        fid = r.json()["flight_id"]
        r = await client.post(f"/v1/flights/{fid}/upload")
        assert r.status_code == 202, r.text
        while (await client.get(f"/v1/flights/{fid}")).json()["state"] in ("planned", "uploading"):
            await asyncio.sleep(0.05)
    # After the service stopped, the database holds what it did.
    store = Store.open(database_url)
    try:
        assert store.scenario(sid).body == body
        flight = store.flight(fid)
        # Ready, until the service stopped and its simulator vehicles with it.
        assert flight.state == "failed"
        assert set(flight.vehicles) == {"UAV1", "UAV2", "UAV3"}
        events = store.events(fid)
        kinds = [e.kind for e in events]
        assert kinds.count("upload") == 3
        states = [e.payload.get("state") for e in events if e.kind == "flight"]
        assert states == ["uploading", "ready", "failed"], states
        assert "the service stopped" in [e for e in events if e.kind == "flight"][-1].reason
        assert store.last_upload(fid, "UAV2")  # the items sent, item for item
    finally:
        store.close()


async def _ok(r: Any, status: int = 200) -> Any:
    assert r.status_code == status, (r.status_code, r.text)
    return r.json() if "json" in r.headers.get("content-type", "") else r.content


async def _stream(client: httpx.AsyncClient, fid: str, after_seq: int) -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    async for kind, data in sse_messages(
        client, f"/v1/flights/{fid}/stream", {"after_seq": after_seq}
    ):
        out.append((kind, data))
        if kind == "end":
            break
    return out


async def _schedule_answers(client: httpx.AsyncClient, sid: str) -> dict[str, Any]:
    return {
        "schedule": await _ok(await client.get(f"/v1/schedules/{sid}")),
        "mission": await _ok(await client.get(f"/v1/schedules/{sid}/missions/UAV2.waypoints")),
    }


async def _flight_answers(client: httpx.AsyncClient, fid: str) -> dict[str, Any]:
    return {
        what: await _ok(await client.get(f"/v1/flights{path}"))
        for what, path in [
            ("snapshot", f"/{fid}"),
            ("record", f"/{fid}/record"),
            ("events", f"/{fid}/events?limit=5000"),
            ("map", f"/{fid}/map"),
            ("team time", f"/{fid}/team-time"),
            ("report", f"/{fid}/report/arrivals.md"),
            ("list", ""),
        ]
    }


@pytest.mark.slow  # a flight and two service starts: left out of make test-quick
async def test_schedules_ended_flights_and_idempotency_keys_are_answered_the_same_after_a_restart(
    database_url: str, tmp_path: Path
) -> None:
    data = tmp_path / "data"
    plan = {"scenario_id": "", "seed": 1}
    key = {"Idempotency-Key": "plan-compact"}
    async with serve(data, database_url) as service, service.client() as client:
        body = yaml.safe_dump(compact_paper(), sort_keys=False)
        headers = {"Content-Type": "application/yaml"}
        plan["scenario_id"] = (
            await _ok(await client.post("/v1/scenarios", content=body, headers=headers), 201)
        )["id"]
        first = await client.post("/v1/schedules", json=plan, headers=key)
        job = await _ok(first, 202)
        while job["state"] in ("queued", "running"):
            await asyncio.sleep(0.1)
            job = await _ok(await client.get(f"/v1/jobs/{job['id']}"))
        assert job["state"] == "succeeded", job
        sid = job["result"]["id"]
        before = await _schedule_answers(client, sid)
        r = await client.post("/v1/flights", json={"schedule_id": sid, "rehearsal": {}})
        fid = (await _ok(r, 201))["flight_id"]
        await _ok(await client.post(f"/v1/flights/{fid}/upload"), 202)
        while (await _ok(await client.get(f"/v1/flights/{fid}")))["state"] != "ready":
            await asyncio.sleep(0.1)
        await _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
        while (await _ok(await client.get(f"/v1/flights/{fid}")))["state"] != "running":
            await asyncio.sleep(0.05)
        # Ended at once (the whole team sent home): a record and a report all the same.
        await _ok(await client.post(f"/v1/flights/{fid}/abort", json={"mode": "rtl"}))
        while not (snap := await _ok(await client.get(f"/v1/flights/{fid}")))["record_ready"]:
            await asyncio.sleep(0.1)
        assert snap["state"] == "aborted", snap["state"]
        # Its simulator vehicles leave the service's vehicles with their simulator.
        async with asyncio.timeout(30.0):
            while vehicles := await _ok(await client.get("/v1/vehicles")):
                assert all(v["flight_id"] in (None, fid) for v in vehicles), vehicles
                await asyncio.sleep(0.05)
        # What this process answers about the ended flight (its final snapshot is what
        # it will keep: asked once it has written its record).
        before |= await _flight_answers(client, fid)
        # A request with an unknown token and a key: 401 each time, and nothing kept.
        stranger = {"Authorization": "Bearer not-a-token", **key}
        for _ in range(2):
            assert (
                await client.post("/v1/schedules", json=plan, headers=stranger)
            ).status_code == 401
    async with serve(data, database_url) as service, service.client() as client:
        after = await _schedule_answers(client, sid) | await _flight_answers(client, fid)
        assert after == before
        assert after["list"] == [{"id": fid, "state": "aborted", "schedule_id": sid}]
        # Its stream: the snapshot, every event after the one asked for, the end.
        seqs = [e["seq"] for e in before["events"]["events"]]
        told = await _stream(client, fid, seqs[10])
        assert told[0] == ("snapshot", before["snapshot"])
        assert [d["seq"] for k, d in told if k == "event"] == seqs[11:]
        assert told[-1] == ("end", {"state": "aborted"})
        # The key answers the same, for the same request written otherwise (canonical JSON).
        retried = await client.post(
            "/v1/schedules",
            content=json.dumps({"seed": 1, "scenario_id": plan["scenario_id"]}, indent=3),
            headers={"Content-Type": "application/json", **key},
        )
        assert (retried.status_code, retried.content) == (first.status_code, first.content)
        assert retried.headers["idempotent-replayed"] == "true"
        # A schedule kept before the restart flies: a flight is made on it.
        r = await client.post("/v1/flights", json={"schedule_id": sid, "rehearsal": {}})
        await _ok(r, 201)
    store = Store.open(database_url)
    try:
        with store.engine.connect() as conn:
            keys = conn.execute(text("select count(*) from idempotency_keys")).scalar_one()
        assert keys == 1  # the 401s took no place
    finally:
        store.close()

"""What the service keeps, on an embedded SQLite and on the PostgreSQL server at
127.0.0.1:5432 (a fresh schema; in CI a server that cannot be reached is a failure)."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path

import pytest

from gcs.store.repository import Store
from tests.gcs.conftest import PAPER, postgres_schema
from tests.service.conftest import serve


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

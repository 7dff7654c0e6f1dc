"""Bounded work: bodies over the size limit are 413, scenarios over the service's limits 422
before any planning, a token past its job quota 429 with Retry-After; planning jobs run in
processes of their own, report progress, stop at their time limit and are cancelled by
``DELETE /v1/jobs/{id}`` with their process (and any it started) gone before the answer."""

from __future__ import annotations

import json
import os
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from tests.api.conftest import PAPER, app_with, auth, job_until, problem, running
from tests.procs import goes, gone
from tests.teams import ring_team

PAPER_TEXT = PAPER.read_text(encoding="utf-8")


@pytest.fixture
async def small(tmp_path: Path) -> AsyncIterator[httpx.AsyncClient]:
    """A service with small limits: 64 KiB bodies, 2 vehicles, 50,000 grid nodes (the
    paper's map has 40,401), 20 hills (it has 18)."""
    app = app_with(
        tmp_path,
        max_body_bytes=65_536,
        max_vehicles=2,
        max_grid_nodes=50_000,
        max_hills=20,
    )
    async for c in running(app):
        yield c


async def _scenario(client: httpx.AsyncClient, doc: dict[str, Any]) -> str:
    r = await client.post("/v1/scenarios", content=json.dumps(doc), headers=auth("plan") | _JSON)
    assert r.status_code == 201, r.text
    sid: str = r.json()["id"]
    return sid


_JSON = {"content-type": "application/json"}


def _two() -> dict[str, Any]:
    """The paper scenario with UAV1 and UAV2 only (UAV3's buffer dropped)."""
    doc: dict[str, Any] = yaml.safe_load(PAPER_TEXT)
    doc["vehicles"] = doc["vehicles"][:2]
    doc["buffers"] = [b for b in doc.get("buffers", []) if "UAV3" not in b.get("vehicles", [])]
    return doc


async def test_a_body_over_the_size_limit_is_413_whether_its_length_is_said_or_not(
    small: httpx.AsyncClient,
) -> None:
    big = b"# " + b"x" * 70_000 + b"\n" + PAPER_TEXT.encode()
    body = problem(await small.post("/v1/scenarios", content=big, headers=auth("plan")), 413)
    assert f"{len(big)} bytes, over the limit of 65536" in body["detail"]

    async def chunks() -> AsyncIterator[bytes]:
        for k in range(0, len(big), 8192):
            yield big[k : k + 8192]

    r = await small.post("/v1/scenarios", content=chunks(), headers=auth("plan"))
    assert "content-length" not in r.request.headers
    assert "65536" in problem(r, 413)["detail"]
    # The same through a JSON route, and the service still answers.
    huge = {"scenario_id": "x" * 70_000}
    r = await small.post("/v1/schedules", json=huge, headers=auth("plan"))
    assert "65536" in problem(r, 413)["detail"]
    assert (await small.get("/v1/health")).json() == {"status": "ok"}


@pytest.mark.parametrize(
    ("change", "field", "what"),
    [
        (lambda d: d, "vehicles", "3 vehicles, over this service's limit of 2"),
        (
            lambda d: d["area"].update(resolution_m=500.0),
            "area.resolution_m",
            "500 m gives 160801 grid nodes, over this service's limit of 50000",
        ),
        (
            lambda d: d["terrain"].update(hills=21),
            "terrain.hills",
            "21 hills, over this service's limit of 20",
        ),
    ],
    ids=["vehicles", "grid", "hills"],
)
async def test_a_scenario_over_the_service_limits_is_422_naming_the_field(
    small: httpx.AsyncClient, change: Any, field: str, what: str
) -> None:
    doc = yaml.safe_load(PAPER_TEXT) if field == "vehicles" else _two()
    change(doc)
    r = await small.post("/v1/scenarios", content=json.dumps(doc), headers=auth("plan") | _JSON)
    detail = problem(r, 422)["detail"]
    assert detail.startswith(f"scenario: {field}: ") and what in detail, detail


async def test_a_token_past_its_job_quota_gets_429_with_retry_after_and_a_cancel_frees_it(
    tmp_path: Path,
) -> None:
    app = app_with(tmp_path, jobs_running=1, jobs_per_token=2)
    async for client in running(app):
        body = {"scenario_id": await _scenario(client, ring_team(1000))}
        jobs = []
        for _ in range(2):
            r = await client.post("/v1/schedules", json=body, headers=auth("plan"))
            assert r.status_code == 202, r.text
            jobs.append(r.json())
        # One runs (minutes of work), one queues behind it (one job at a time): both count.
        r = await client.post("/v1/schedules", json=body, headers=auth("plan"))
        assert "2 jobs queued or running" in problem(r, 429)["detail"]
        assert int(r.headers["Retry-After"]) > 0
        # Another token has its own quota.
        r = await client.post("/v1/schedules", json=body, headers=auth("admin"))
        assert r.status_code == 202, r.text
        jobs.append(r.json())
        # The queued one cancelled never starts; the quota has room again.
        await job_until(client, jobs[0]["id"], "running")
        cancelled = await client.delete(f"/v1/jobs/{jobs[1]['id']}", headers=auth("plan"))
        assert cancelled.status_code == 200 and cancelled.json()["state"] == "cancelled"
        assert cancelled.json()["started_utc_s"] is None
        r = await client.post("/v1/schedules", json=body, headers=auth("plan"))
        assert r.status_code == 202, r.text
        jobs.append(r.json())
        for job in jobs:
            r = await client.delete(f"/v1/jobs/{job['id']}", headers=auth("admin"))
            assert r.json()["state"] == "cancelled"


async def test_a_job_reports_its_progress_and_times(small: httpx.AsyncClient) -> None:
    doc = _two()
    r = await small.post(
        "/v1/schedules", json={"scenario_id": await _scenario(small, doc)}, headers=auth("plan")
    )
    done = await job_until(small, r.json()["id"], "succeeded", "failed")
    assert done["state"] == "succeeded" and done["progress"] == 1.0 and done["stage"] == "done"
    assert done["created_utc_s"] <= done["started_utc_s"] <= done["finished_utc_s"]
    assert [v["id"] for v in done["result"]["vehicles"]] == ["UAV1", "UAV2"]


async def test_a_running_thousand_vehicle_job_is_cancelled_with_its_process_gone(
    tmp_path: Path,
) -> None:
    app = app_with(tmp_path)
    async for client in running(app):
        sid = await _scenario(client, ring_team(1000))
        r = await client.post("/v1/schedules", json={"scenario_id": sid}, headers=auth("plan"))
        job = r.json()
        running_job = await job_until(client, job["id"], "running")
        assert running_job["stage"] != "queued"
        work = app.state.engine.planning.work
        pid = work.running_pid(job["id"])
        assert pid is not None and pid != os.getpid() and not gone(pid)
        r = await client.delete(f"/v1/jobs/{job['id']}", headers=auth("plan"))
        assert r.status_code == 200, r.text
        ended = r.json()
        assert ended["state"] == "cancelled" and ended["result"] is None
        assert ended["error"] == {"status": 409, "detail": "cancelled"}
        # Killed before the answer, and reaped: the job's process and any worker it had
        # started (a killed process takes a moment to exit).
        assert work.running_pid(job["id"]) is None and goes(pid)
        # Cancelling again answers the same; a job that is not there is 404.
        again = await client.delete(f"/v1/jobs/{job['id']}", headers=auth("plan"))
        assert again.json()["state"] == "cancelled"
        problem(await client.delete("/v1/jobs/nope", headers=auth("plan")), 404)
        # Observe tokens read jobs but do not cancel them.
        problem(await client.delete(f"/v1/jobs/{job['id']}", headers=auth("observe")), 403)


async def test_a_job_past_its_time_limit_is_stopped_and_failed(tmp_path: Path) -> None:
    app = app_with(tmp_path, job_time_limit_s=0.5)
    async for client in running(app):
        sid = await _scenario(client, ring_team(1000))
        r = await client.post("/v1/schedules", json={"scenario_id": sid}, headers=auth("plan"))
        failed = await job_until(client, r.json()["id"], "failed", "succeeded")
        assert failed["state"] == "failed"
        assert failed["error"] == {
            "status": 422,
            "detail": "stopped: ran longer than its 0.5 s limit",
        }

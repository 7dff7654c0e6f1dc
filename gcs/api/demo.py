"""``python -m gcs demo``: the paper flight through the service, as an operator's client flies
one: scenario, schedule (a job), flight on bundled simulator vehicles, upload, launch, the
stream printed as progress, the arrival table, the report. Without ``--url`` it starts the
service itself (``python -m gcs serve`` on a free loopback port, an embedded SQLite in a
temporary directory) and stops it at the end.

Only HTTP is used: nothing here imports the engine.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import tempfile
import uuid
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from gcs.api.process import running_service
from gcs.errors import GcsError
from gcs.service.stubs import DEFAULT_SPEEDUP

__all__ = ["DemoOptions", "run_demo", "sse_messages"]

PAPER = Path(__file__).resolve().parents[2] / "scenarios" / "paper_three_uav.yaml"


@dataclass
class DemoOptions:
    scenario: Path = PAPER
    url: str | None = None
    token: str | None = None
    speedup: float = DEFAULT_SPEEDUP
    wind: tuple[float, float] | None = (5.0, 270.0)
    loss: float = 0.1
    seed: int = 1
    report_dir: Path | None = None
    tolerance_s: float = 1.0
    quiet: bool = False


@contextlib.asynccontextmanager
async def _service(token: str) -> AsyncIterator[str]:
    """The service in a child process on an embedded SQLite in a temporary directory."""
    with tempfile.TemporaryDirectory(prefix="tcgcs-demo-") as tmp:
        async with running_service(Path(tmp), {token: ["admin"]}, stop_within_s=20.0) as svc:
            yield svc.url


def _check(r: httpx.Response, what: str) -> Any:
    if r.status_code >= 400:
        try:
            detail = r.json().get("detail", r.text)
        except ValueError:
            detail = r.text
        raise GcsError(f"{what}: HTTP {r.status_code}: {detail}")
    return r.json() if r.content else None


async def sse_messages(
    client: httpx.AsyncClient, path: str, params: dict[str, Any] | None = None
) -> AsyncIterator[tuple[str, dict[str, Any]]]:
    """``(type, data)`` of each server-sent event on ``path``."""
    headers = {"Accept": "text/event-stream"}
    async with client.stream("GET", path, params=params, headers=headers, timeout=None) as r:
        if r.status_code != 200:
            await r.aread()
            _check(r, f"stream {path}")
        kind, data = "message", ""
        async for line in r.aiter_lines():
            if line.startswith("event:"):
                kind = line[6:].strip()
            elif line.startswith("data:"):
                data += line[5:].strip()
            elif not line and data:
                yield kind, json.loads(data)
                kind, data = "message", ""


def _key() -> dict[str, str]:
    """A fresh ``Idempotency-Key``: a retried request is the same request, never a second."""
    return {"Idempotency-Key": uuid.uuid4().hex}


def _progress(ev: dict[str, Any]) -> str | None:
    if ev["kind"] in ("upload", "state"):
        return None
    who = f"{ev['vehicle']:>6}" if ev["vehicle"] else "  team"
    return f"{ev['t_s']:9.1f} s {who} {ev['kind']:<8} {ev['reason']}"


async def fly(client: httpx.AsyncClient, opts: DemoOptions) -> dict[str, Any]:
    """The operator's steps; returns the flight record."""

    def say(text: str) -> None:
        if not opts.quiet:
            print(text, flush=True)

    body = opts.scenario.read_text(encoding="utf-8")
    media = "application/json" if opts.scenario.suffix == ".json" else "application/yaml"
    scenario = _check(
        await client.post("/v1/scenarios", content=body, headers={"Content-Type": media}),
        "scenario",
    )
    say(f"demo: scenario {scenario['name']} kept as {scenario['id'][:12]}")
    job = _check(
        await client.post("/v1/schedules", json={"scenario_id": scenario["id"], "seed": opts.seed}),
        "schedule",
    )
    while job["state"] in ("queued", "running"):
        await asyncio.sleep(0.2)
        job = _check(await client.get(f"/v1/jobs/{job['id']}"), "job")
    if job["state"] != "succeeded":
        raise GcsError(f"schedule failed: {job['error']}")
    schedule = job["result"]
    say(
        f"demo: planned {len(schedule['vehicles'])} vehicles in {schedule['plan_wall_s']:.1f} s;"
        f" team arrival {schedule['required_arrival_s']:.1f} s"
    )
    rehearsal: dict[str, Any] = {"speedup": opts.speedup, "loss": opts.loss, "seed": opts.seed}
    if opts.wind is not None:
        rehearsal |= {"wind_m_s": opts.wind[0], "wind_from_deg": opts.wind[1]}
    flight = _check(
        await client.post(
            "/v1/flights",
            json={"schedule_id": schedule["id"], "rehearsal": rehearsal},
            headers=_key(),
        ),
        "flight",
    )
    fid = flight["flight_id"]
    say(f"demo: flight {fid} on {len(flight['vehicles'])} simulator vehicles")
    _check(await client.post(f"/v1/flights/{fid}/upload", headers=_key()), "upload")
    snap = flight
    while snap["state"] in ("planned", "uploading"):
        await asyncio.sleep(0.2)
        snap = _check(await client.get(f"/v1/flights/{fid}"), "flight")
    if snap["state"] != "ready":
        raise GcsError(f"upload failed: {snap['uploads']}")
    _check(await client.post(f"/v1/flights/{fid}/launch", json={}, headers=_key()), "launch")
    last_line = 0.0
    async for kind, data in sse_messages(client, f"/v1/flights/{fid}/stream"):
        if kind == "event":
            line = _progress(data)
            if line:
                say(line)
        elif kind == "telemetry":
            loop = asyncio.get_running_loop()
            if loop.time() - last_line >= 5.0:
                last_line = loop.time()
                parts = [
                    f"{v['id']} {v['state']}"
                    + ("" if v["error_s"] is None else f" eta {v['error_s']:+.1f}s")
                    for v in data["vehicles"]
                ]
                say(f"{data['t_s']:9.1f} s  | " + " | ".join(parts))
        elif kind == "end":
            break
    record: dict[str, Any] = _check(await client.get(f"/v1/flights/{fid}/record"), "record")
    if opts.report_dir is not None:
        opts.report_dir.mkdir(parents=True, exist_ok=True)
        for name in ("index.html", "arrivals.md", "paths.png", "speeds.png", "timeline.png"):
            r = await client.get(f"/v1/flights/{fid}/report/{name}")
            if r.status_code == 200:
                (opts.report_dir / name).write_bytes(r.content)
        (opts.report_dir / "flight.json").write_text(json.dumps(record, indent=1) + "\n")
    return record


async def run_demo(opts: DemoOptions) -> dict[str, Any]:
    token = opts.token or uuid.uuid4().hex
    async with contextlib.AsyncExitStack() as stack:
        url = opts.url if opts.url else await stack.enter_async_context(_service(token))
        headers = {"Authorization": f"Bearer {token}"}
        async with httpx.AsyncClient(base_url=url, headers=headers, timeout=60.0) as client:
            return await fly(client, opts)
    raise AssertionError("unreachable")

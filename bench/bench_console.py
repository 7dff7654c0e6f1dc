"""Benchmark: the operator console with a large team, in headless Chromium.

A team of N vehicles (:func:`arc_team`: the paper's map, launch sites on the west and south
edges, goals on an arc around the paper target) is planned and flown through the service's
REST API on bundled simulator vehicles (rehearsal options: speed-up, wind, loss); the console
is opened on the flight (``/ui/?flight=ID``) and the page measures itself (``window.tcgcs.perf``):

- frame time: the deltas between ``requestAnimationFrame`` callbacks (the map redraws in them);
- event-to-paint lag: a telemetry batch's receipt (the WebSocket message) to the end of the
  next frame, which has drawn it.

While it measures, an operator pans the map (a drag) and zooms (the wheel) every 2 s, so the
frames include full redraws besides the telemetry ones. The service runs as ``python -m gcs
serve`` in a child process on loopback (``gcs.api.demo``).

    .venv/bin/python bench/bench_console.py --vehicles 30 --speedup 200
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import platform
import statistics
import sys
import time
import uuid
from collections import Counter
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from playwright.async_api import Page, async_playwright

from gcs.api.demo import _service

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the generated teams live with the tests
from tests.teams import arc_team  # noqa: E402

CHROMIUM = "/usr/bin/chromium"


def _ok(r: httpx.Response) -> Any:
    if r.status_code >= 400:
        raise SystemExit(f"{r.request.method} {r.request.url}: HTTP {r.status_code}: {r.text}")
    return r.json() if r.content else None


async def _schedule(client: httpx.AsyncClient, args: argparse.Namespace) -> tuple[str, int, float]:
    """A schedule of the team: its id, the plan's seed and the planning wall s. Should a pair
    come under the separation minimum the job fails: the next seed is tried (``args.tries``)."""
    body = json.dumps(arc_team(args.vehicles))
    for seed in range(args.seed, args.seed + args.tries):
        headers = {"Content-Type": "application/json"}
        sc = _ok(await client.post("/v1/scenarios", content=body, headers=headers))
        t0 = time.perf_counter()
        job = _ok(await client.post("/v1/schedules", json={"scenario_id": sc["id"], "seed": seed}))
        while job["state"] in ("queued", "running"):
            await asyncio.sleep(0.5)
            job = _ok(await client.get(f"/v1/jobs/{job['id']}"))
        if job["state"] == "succeeded":
            return job["result"]["id"], seed, time.perf_counter() - t0
        print(f"seed {seed}: {job['error']['detail']}", file=sys.stderr)
    raise SystemExit(f"no schedule in {args.tries} tries")


async def _flight(client: httpx.AsyncClient, args: argparse.Namespace) -> tuple[str, int, float]:
    """Schedule, flight on simulator vehicles, upload: the flight's id, the team's seed and
    the planning wall s."""
    schedule_id, seed, plan_s = await _schedule(client, args)
    rehearsal: dict[str, Any] = {"speedup": args.speedup, "loss": args.loss, "seed": seed}
    if args.wind:
        rehearsal |= {"wind_m_s": args.wind, "wind_from_deg": 270.0}
    flight = _ok(
        await client.post("/v1/flights", json={"schedule_id": schedule_id, "rehearsal": rehearsal})
    )
    fid = flight["flight_id"]
    _ok(await client.post(f"/v1/flights/{fid}/upload"))
    snap = flight
    while snap["state"] in ("planned", "uploading"):
        await asyncio.sleep(0.2)
        snap = _ok(await client.get(f"/v1/flights/{fid}"))
    if snap["state"] != "ready":
        raise SystemExit(f"upload failed: {snap['uploads']}")
    return fid, seed, plan_s


async def _operate(page: Page, stop: asyncio.Event) -> int:
    """Pan and zoom the map every 2 s until ``stop``; how many gestures."""
    box = await page.locator("#map").bounding_box()
    assert box is not None
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    n = 0
    while not stop.is_set():
        d = 60 if n % 2 == 0 else -60
        await page.mouse.move(cx, cy)
        await page.mouse.down()
        await page.mouse.move(cx + d, cy + d / 2, steps=8)
        await page.mouse.up()
        await page.mouse.wheel(0, -200 if n % 4 < 2 else 200)
        n += 1
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), 2.0)
    return n


async def _health(url: str, stop: asyncio.Event) -> list[float]:
    """The service's answer time to ``/v1/health`` every 0.5 s until ``stop`` (its event
    loop's latency, apart from the page's)."""
    out: list[float] = []
    async with httpx.AsyncClient(base_url=url, timeout=60.0) as client:
        while not stop.is_set():
            t = time.perf_counter()
            await client.get("/v1/health")
            out.append(time.perf_counter() - t)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), 0.5)
    return out


async def _over(client: httpx.AsyncClient, fid: str) -> None:
    """Leave no flight running behind the service's shutdown: abort it (all home) and wait
    until it is over and its record kept."""
    snap = _ok(await client.get(f"/v1/flights/{fid}"))
    if snap["state"] not in ("completed", "failed", "aborted"):
        await client.post(f"/v1/flights/{fid}/abort", json={"mode": "rtl"})
    for _ in range(240):
        snap = _ok(await client.get(f"/v1/flights/{fid}"))
        if snap["record_ready"]:
            return
        await asyncio.sleep(0.25)


def _pct(xs: list[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, max(0, round(q / 100 * (len(s) - 1))))]


async def run(args: argparse.Namespace) -> dict[str, Any]:
    token = uuid.uuid4().hex
    async with _service(token) as url, async_playwright() as pw:
        headers = {"Authorization": f"Bearer {token}"}
        async with httpx.AsyncClient(base_url=url, headers=headers, timeout=120.0) as client:
            fid, seed, plan_s = await _flight(client, args)
            browser = await pw.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
            page = await browser.new_page(viewport={"width": 1600, "height": 1000})
            await page.add_init_script(f"sessionStorage.setItem('tcgcs.token', {token!r})")
            await page.goto(f"{url}/ui/?flight={fid}")
            await page.wait_for_function("() => tcgcs.stream && tcgcs.stream.state === 'open'")
            _ok(await client.post(f"/v1/flights/{fid}/launch", json={}))
            await page.wait_for_function("() => tcgcs.telemetry && tcgcs.telemetry.t_s > 0")
            await page.evaluate("tcgcs.perf.reset()")
            stop = asyncio.Event()
            gestures = asyncio.create_task(_operate(page, stop))
            health = asyncio.create_task(_health(url, stop))
            t0 = time.perf_counter()
            # Until the flight is over (all arrived: the load ends) or the wall time is up.
            over = "tcgcs.stream.state === 'ended' || ['completed', 'failed', 'aborted']"
            over += ".includes(tcgcs.state.flightState)"
            clock: list[tuple[float, float]] = []  # (wall s, the page's mission s)
            while time.perf_counter() - t0 < args.wall:
                if await page.evaluate(over):
                    break
                clock.append((time.perf_counter(), await page.evaluate("tcgcs.telemetry.t_s")))
                await asyncio.sleep(0.5)
            stop.set()
            n_gestures = await gestures
            answers = await health
            wall = time.perf_counter() - t0
            got = await page.evaluate(
                "({frames: tcgcs.perf.frames, lags: tcgcs.perf.lags, at: tcgcs.perf.receipts,"
                " t: tcgcs.telemetry.t_s, states: tcgcs.telemetry.vehicles.map(v => v.state),"
                " rate: tcgcs.clock.rate, events: tcgcs.events.length,"
                " state: tcgcs.state.flightState, n: tcgcs.state.order.length})"
            )
            await browser.close()
            await _over(client, fid)
    frames, lags = got["frames"], got["lags"]
    gaps = [(b - a) / 1000 for a, b in zip(got["at"], got["at"][1:], strict=False)]
    # Mission seconds per wall second while the flight ran (the page's clock, sampled).
    rate = float(np.polyfit(*zip(*clock, strict=True), 1)[0]) if len(clock) > 2 else 0.0
    return {
        "vehicles": got["n"],
        "plan_seed": seed,
        "speedup": args.speedup,
        "achieved_rate": rate,
        "plan_s": plan_s,
        "wall_s": wall,
        "mission_s": got["t"],
        "flight_state": got["state"],
        "vehicle_states": dict(Counter(got["states"])),
        "events": got["events"],
        "gestures": n_gestures,
        "frames": len(frames),
        "frame_p50_ms": statistics.median(frames),
        "frame_p99_ms": _pct(frames, 99),
        "frame_max_ms": max(frames),
        "long_frames": sum(1 for f in frames if f > 50.0),
        "batches": len(lags),
        "lag_p50_ms": statistics.median(lags),
        "lag_p99_ms": _pct(lags, 99),
        "lag_max_ms": max(lags),
        "batch_gap_p50_s": statistics.median(gaps),
        "batch_gap_max_s": max(gaps),
        "health_p50_s": statistics.median(answers),
        "health_max_s": max(answers),
    }


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--vehicles", type=int, default=30)
    parser.add_argument("--speedup", type=float, default=200.0)
    parser.add_argument("--seed", type=int, default=0, help="the plan's seed")
    parser.add_argument("--tries", type=int, default=3, help="seeds to try for a schedule")
    parser.add_argument("--wind", type=float, default=5.0, help="m/s from the west (0: none)")
    parser.add_argument("--loss", type=float, default=0.0)
    parser.add_argument("--wall", type=float, default=120.0, help="measure at most this long")
    args = parser.parse_args()
    r = asyncio.run(run(args))
    print(
        f"machine: {platform.machine()}, nproc {os.cpu_count()}, {_cpu()}, "
        f"{platform.python_implementation()} {platform.python_version()}"
    )
    print(json.dumps(r, indent=1))
    print(
        "| vehicles | speed-up (achieved) | measured wall s | frames | frame p50 ms | p99 ms "
        "| max ms | frames > 50 ms | batches (gap p50 / max s) | lag p50 ms | p99 ms | max ms "
        "| service /v1/health p50 / max s |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---|")
    print(
        f"| {r['vehicles']} | {r['speedup']:.0f}x ({r['achieved_rate']:.0f}x) | "
        f"{r['wall_s']:.1f} | {r['frames']} | {r['frame_p50_ms']:.1f} | "
        f"{r['frame_p99_ms']:.1f} | {r['frame_max_ms']:.1f} | {r['long_frames']} | "
        f"{r['batches']} ({r['batch_gap_p50_s']:.2f} / {r['batch_gap_max_s']:.2f}) | "
        f"{r['lag_p50_ms']:.1f} | {r['lag_p99_ms']:.1f} | {r['lag_max_ms']:.1f} | "
        f"{r['health_p50_s']:.2f} / {r['health_max_s']:.2f} |"
    )


if __name__ == "__main__":
    main()

"""Benchmark: 200-item mission upload and download with default options on a lossy link.

One stub vehicle per row, in a child process at 1x (its mission timers are in simulated time:
at 1x its 1.5 s re-request is ArduPilot's, where at 20x it would re-request every 75 ms, five
times in a 400 ms round trip), our ``gcs.mavlink.link.Link`` over loopback TCP in this one. Each run
uploads a new 200-item mission with the default options, checks what the download gives back
against it in ArduPilot's stored form, and times both. Rows: 30 % loss each way, the same with
200 ms added each way, 50 % loss.

    python bench/bench_gcs_mission_loss.py [--runs 20] [--latency-runs 5] [--loss50-runs 10]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import statistics
import time
from dataclasses import replace
from typing import Any

from bench_gcs_mission import HOME, mission

from gcs.mavlink.link import Link
from gcs.mavlink.mission_client import download_mission, upload_mission
from gcs.mavlink.mission_errors import MissionError
from planner.mission import Autopilot, items_equal
from sitl_stub.api import SimTeam

SPEEDUP = 1.0


def stub(loss: float, latency_ms: float, out: mp.Queue, stop: Any) -> None:  # type: ignore[type-arg]
    async def run() -> None:
        async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=SPEEDUP) as team:
            team.vehicles[0].link.faults(loss=loss, latency_ms=latency_ms)
            out.put(team.ports[0])
            while not stop.is_set():
                await asyncio.sleep(0.1)

    asyncio.run(run())


async def runs(port: int, n: int, count: int) -> list[tuple[bool, float, float]]:
    """(intact, upload s, download s) per run; a failed transfer is (False, time, nan)."""
    out = []
    async with Link.open(f"tcp:127.0.0.1:{port}") as link:
        await link.wait_vehicle(1, timeout_s=30.0)
        for r in range(count):
            items = [replace(it, current=0) for it in mission(n, 10.0 * r)]
            t0 = time.perf_counter()
            try:
                await upload_mission(link, 1, items)
                t_up = time.perf_counter() - t0
                t0 = time.perf_counter()
                got = await download_mission(link, 1)
                t_down = time.perf_counter() - t0
            except MissionError as err:
                print(f"  run {r}: {err}", flush=True)
                out.append((False, time.perf_counter() - t0, float("nan")))
                continue
            ok = items_equal(items, got, autopilot=Autopilot.ARDUPILOT, compare_home=False)
            out.append((ok, t_up, t_down))
    return out


def row(n: int, loss: float, latency_ms: float, count: int) -> str:
    ctx = mp.get_context("spawn")
    q: mp.Queue = ctx.Queue()  # type: ignore[type-arg]
    stop = ctx.Event()
    proc = ctx.Process(target=stub, args=(loss, latency_ms, q, stop))
    proc.start()
    try:
        results = asyncio.run(runs(q.get(timeout=60), n, count))
    finally:
        stop.set()
        proc.join(timeout=30)
    good = [r for r in results if r[0]]
    up = [r[1] for r in good]
    down = [r[2] for r in good]

    def fig(xs: list[float]) -> str:
        return f"{statistics.median(xs):.2f} / {max(xs):.2f}" if xs else "-"

    return (
        f"| {n} | {loss:.0%} | {latency_ms:.0f} ms | {len(good)} of {count} | {fig(up)} "
        f"| {fig(down)} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--items", type=int, default=200)
    ap.add_argument("--runs", type=int, default=20, help="runs at 30 %% loss")
    ap.add_argument("--latency-runs", type=int, default=5, help="runs at 30 %% loss + 200 ms")
    ap.add_argument("--loss50-runs", type=int, default=10, help="runs at 50 %% loss")
    args = ap.parse_args()
    print(
        "| items | loss each way | added latency each way | intact | upload median / max (s) "
        "| download median / max (s) |"
    )
    print("|---|---|---|---|---|---|")
    for loss, latency_ms, count in (
        (0.3, 0.0, args.runs),
        (0.3, 200.0, args.latency_runs),
        (0.5, 0.0, args.loss50_runs),
    ):
        if count > 0:
            print(row(args.items, loss, latency_ms, count), flush=True)


if __name__ == "__main__":
    main()

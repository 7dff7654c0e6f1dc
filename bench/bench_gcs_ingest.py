"""Benchmark: one gcs process ingesting N stub vehicles at 10 Hz position telemetry.

The stub vehicles run at 1x in a child process (one TCP link each). This process opens one
``gcs.mavlink.link.Link`` per vehicle, asks for GLOBAL_POSITION_INT at 10 Hz (SET_MESSAGE_INTERVAL),
and folds every message into a ``gcs.mavlink.telemetry.TelemetryReducer``. For each position message
the lag is the wall time (UTC) at which the reducer's state holds it, minus the time the
vehicle stamped it with: the stub's step time ``time_boot_ms``, mapped to UTC through the
wall time at which the stub's clock started (the child reports it). The stub writes a step's
messages at the earliest on its next event-loop pass, so the figure includes the stub's own
scheduling delay: it is an upper bound on the GCS's part. CPU is this process's CPU time over
the measurement window, as a share of one core.

    python bench/bench_gcs_ingest.py --vehicles 100 --seconds 20
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import statistics
import time
from typing import Any

from gcs.mavlink.link import Link
from gcs.mavlink.telemetry import TelemetryReducer
from sitl_stub.api import Home, SimTeam


def stub(n: int, seconds: float, out: mp.Queue, stop: Any) -> None:  # type: ignore[type-arg]
    async def run() -> None:
        homes = [Home(-35.36 + 0.001 * i, 149.16, 584.0) for i in range(n)]
        async with SimTeam.start(homes=homes, tcp_base=0, speedup=1.0) as team:
            loop = asyncio.get_running_loop()
            await asyncio.sleep(0.2)
            # UTC of the stub clock's zero (sim time 0), from its own wall-clock bookkeeping.
            boot_utc = time.time() - team.clock.stats(loop.time()).wall_elapsed_s
            out.put((team.ports, boot_utc))
            while not stop.is_set():
                await asyncio.sleep(0.2)
            stats = team.clock.stats(loop.time())
            out.put((stats.rate_fraction, stats.slipped_sim_s))

    asyncio.run(run())


async def ingest(ports: list[int], boot_utc: float, seconds: float) -> dict[str, Any]:
    lags: list[float] = []
    measuring = False
    reducers = [TelemetryReducer(i + 1) for i in range(len(ports))]

    def listener(reducer: TelemetryReducer) -> Any:
        update = reducer.update

        def on_message(msg: Any, rx_s: float) -> None:
            update(msg, rx_s)
            if measuring and msg.get_type() == "GLOBAL_POSITION_INT":
                lags.append(time.time() - (boot_utc + msg.time_boot_ms * 1e-3))

        return on_message

    links = [
        Link(f"tcp:127.0.0.1:{p}", message_rates_hz={"GLOBAL_POSITION_INT": 10.0}) for p in ports
    ]
    for link, reducer in zip(links, reducers, strict=True):
        link.add_listener(listener(reducer))
        await link.start()
    try:
        await asyncio.gather(*(link.wait_vehicle(i + 1, 10.0) for i, link in enumerate(links)))
        await asyncio.sleep(2.0)  # let the rate requests take effect
        measuring = True
        w0, c0 = time.monotonic(), time.process_time()
        r0 = sum(link.counters.received for link in links)
        await asyncio.sleep(seconds)
        wall, cpu = time.monotonic() - w0, time.process_time() - c0
        measuring = False
    finally:
        for link in links:
            await link.close()
    lags.sort()
    received = sum(link.counters.received for link in links) - r0
    return {
        "positions": len(lags),
        "wall_s": wall,
        "cpu": cpu / wall,
        "p50_ms": 1e3 * statistics.median(lags),
        "p99_ms": 1e3 * lags[int(0.99 * (len(lags) - 1))],
        "max_ms": 1e3 * lags[-1],
        "received": received,
        "seq_lost": sum(link.counters.seq_lost for link in links),
        "fresh": sum(1 for r in reducers if r.state.lat_deg is not None),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--vehicles", type=int, default=100)
    ap.add_argument("--seconds", type=float, default=20.0)
    args = ap.parse_args()
    ctx = mp.get_context("spawn")
    out: mp.Queue = ctx.Queue()  # type: ignore[type-arg]
    stop = ctx.Event()
    proc = ctx.Process(target=stub, args=(args.vehicles, args.seconds, out, stop))
    proc.start()
    try:
        ports, boot_utc = out.get(timeout=60)
        r = asyncio.run(ingest(ports, boot_utc, args.seconds))
    finally:
        stop.set()
    rate_fraction, slipped_s = out.get(timeout=30)
    proc.join(timeout=30)
    n = args.vehicles
    print(
        "| vehicles | position msgs/s per vehicle | all msgs/s | lag p50 (ms) | lag p99 (ms) "
        "| lag max (ms) | gcs CPU (one core) | seq lost | stub rate / slipped s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    print(
        f"| {n} | {r['positions'] / r['wall_s'] / n:.1f} | {r['received'] / r['wall_s']:.0f} "
        f"| {r['p50_ms']:.1f} | {r['p99_ms']:.1f} | {r['max_ms']:.1f} | {r['cpu']:.0%} "
        f"| {r['seq_lost']} | {rate_fraction:.1%} / {slipped_s:.1f} |"
    )
    assert r["fresh"] == n, f"only {r['fresh']} of {n} vehicles have a position"


if __name__ == "__main__":
    main()

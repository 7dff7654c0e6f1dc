"""Benchmark: a flight worker killed mid-flight, and how long its flight is without control.

``python -m gcs serve`` runs in a child process (as in ``bench_service.py``). Over HTTP only,
this process flies the paper's team at a quarter of its size (``tests.teams.compact_paper``)
on bundled simulator vehicles (200x, lock step, seed 3), and at ``--kill-at`` mission seconds
kills the flight's worker (SIGKILL, its pid from the snapshot's ``worker``). The service
starts another on the flight's checkpoint. Timed on the wall clock from the kill: until the
new worker is ready (its pid in the snapshot), and until it has found every vehicle holding
its mission (the three ``resumed`` events): from then on the flight is under control again.

Target: control back within 2 s of the kill.

    python bench/bench_failover.py [--kills 3] [--kill-at 700] [--json OUT]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import statistics
import sys
import time
import uuid
from pathlib import Path
from typing import Any

import httpx
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the compact team lives with the tests

from bench.bench_service import ok, prepare, service  # noqa: E402
from tests.teams import compact_paper  # noqa: E402


def _once(c: httpx.Client, schedule_id: str, kill_at_s: float) -> dict[str, float]:
    rehearsal = {"speedup": 200.0, "wind_m_s": 4.0, "seed": 3}
    flight = ok(
        c.post("/v1/flights", json={"schedule_id": schedule_id, "rehearsal": rehearsal}), "flight"
    )
    fid = flight["flight_id"]
    ok(c.post(f"/v1/flights/{fid}/upload"), "upload")
    while ok(c.get(f"/v1/flights/{fid}"), "snapshot")["state"] != "ready":
        time.sleep(0.1)
    ok(c.post(f"/v1/flights/{fid}/launch", json={}), "launch")
    while (snap := ok(c.get(f"/v1/flights/{fid}"), "snapshot"))["t_s"] < kill_at_s:
        time.sleep(0.02)
    pid = snap["worker"]["pid"]
    last_seq = snap["last_seq"]
    t0 = time.perf_counter()
    os.kill(pid, signal.SIGKILL)
    ready_s = resumed_s = float("nan")
    while True:
        snap = ok(c.get(f"/v1/flights/{fid}"), "snapshot")
        now = time.perf_counter() - t0
        if snap.get("worker", {}).get("pid") not in (None, pid) and ready_s != ready_s:
            ready_s = now
        page = c.get(f"/v1/flights/{fid}/events", params={"after_seq": last_seq})
        events = ok(page, "events")["events"]
        found = [e for e in events if e["kind"] == "flight" and e["reason"].startswith("resumed")]
        if len(found) >= 3:
            resumed_s = now
            break
        if now > 60.0:
            raise SystemExit(f"flight {fid}: not resumed within 60 s of the kill")
        time.sleep(0.01)
    while ok(c.get(f"/v1/flights/{fid}"), "snapshot")["state"] not in (
        "completed",
        "failed",
        "aborted",
    ):
        time.sleep(0.5)
    return {"ready_s": round(ready_s, 3), "resumed_s": round(resumed_s, 3)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=3)
    ap.add_argument("--kill-at", type=float, default=700.0)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    token = uuid.uuid4().hex
    runs: list[dict[str, Any]] = []
    with (
        service(token) as (url, _pid),
        httpx.Client(
            base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=120.0
        ) as c,
    ):
        text = yaml.safe_dump(compact_paper(), sort_keys=False)
        schedule_id = asyncio.run(prepare(url, token, text))
        for _ in range(args.kills):
            runs.append(_once(c, schedule_id, args.kill_at))
            print(json.dumps(runs[-1]))
    out = {
        "runs": runs,
        "ready_s_median": statistics.median(r["ready_s"] for r in runs),
        "resumed_s_median": statistics.median(r["resumed_s"] for r in runs),
        "resumed_s_max": max(r["resumed_s"] for r in runs),
    }
    print(json.dumps(out, indent=1))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

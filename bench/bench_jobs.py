"""Benchmark: planning jobs cancelled, and the service's memory after many of them.

``python -m gcs serve`` runs in a child process (as in ``bench_service.py``: a free loopback
port, a temporary data directory and SQLite, one admin token). Over HTTP only, this process
keeps a 1,000-vehicle scenario (``tests.teams.ring_team(1000)``: minutes of planning), then
``--jobs`` times in sequence: schedules it, waits until the job is ``running`` and has worked
for ``--work-s`` seconds, and cancels it (``DELETE /v1/jobs/{id}``), timing the DELETE (the
process killed and reaped before the answer) and checking that the job's process group is gone.
The service's resident memory (``/proc``, the service process alone: jobs run in processes of
their own) is read before the first job and after the last.

Targets: each cancel answered within 1 s; the service's RSS after the jobs within 300 MB of
where it started.

    python bench/bench_jobs.py [--jobs 20] [--work-s 3] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import uuid
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the generated teams live with the tests

from bench.bench_service import ok, service  # noqa: E402
from bench.procstat import rss_mib  # noqa: E402
from tests.procs import goes  # noqa: E402
from tests.teams import ring_team  # noqa: E402


def _job_pid(service_pid: int) -> int | None:
    """The running job's process: the newest process under the service that leads a
    process group of its own (a job does; the forkserver and the simulators do not)."""
    proc = Path("/proc")
    newest: tuple[float, int] | None = None
    for d in proc.iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        pgid, start = int(stat[2]), float(stat[19])
        leads = pgid == int(d.name) != service_pid and _descends(pgid, service_pid)
        if leads and (newest is None or start > newest[0]):
            newest = (start, pgid)
    return None if newest is None else newest[1]


def _group(pid: int) -> int | None:
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[2])
    except (OSError, ValueError, IndexError):
        return None


def _descends(pid: int, ancestor: int) -> bool:
    while pid > 1:
        try:
            pid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except OSError:
            return False
        if pid == ancestor:
            return True
    return False


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=20)
    ap.add_argument("--work-s", type=float, default=3.0)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    token = uuid.uuid4().hex
    head = {"Authorization": f"Bearer {token}"}
    cancels: list[float] = []
    with service(token) as (url, pid):
        c = httpx.Client(base_url=url, headers=head, timeout=60.0)
        body = json.dumps(ring_team(1000))
        sid = ok(
            c.post("/v1/scenarios", content=body, headers={"content-type": "application/json"}),
            "keep the scenario",
        )["id"]
        rss0 = rss_mib(pid) or 0.0
        for k in range(args.jobs):
            job = ok(c.post("/v1/schedules", json={"scenario_id": sid}), "schedule")
            while ok(c.get(f"/v1/jobs/{job['id']}"), "job")["state"] != "running":
                time.sleep(0.05)
            time.sleep(args.work_s)
            child = _job_pid(pid)
            t0 = time.perf_counter()
            ended = ok(c.delete(f"/v1/jobs/{job['id']}"), "cancel")
            cancels.append(time.perf_counter() - t0)
            if ended["state"] != "cancelled":
                raise SystemExit(f"job {k}: {ended['state']} after the cancel")
            if child is not None and not goes(child):
                left = [
                    f"{d.name}: {(d / 'cmdline').read_bytes().replace(bytes(1), b' ')[:120]!r}"
                    for d in Path("/proc").iterdir()
                    if d.name.isdigit() and _group(int(d.name)) == child
                ]
                raise SystemExit(f"job {k}: its process group {child} outlived the cancel: {left}")
            print(f"job {k + 1}: cancelled in {cancels[-1] * 1000:.0f} ms", flush=True)
        time.sleep(1.0)
        rss1 = rss_mib(pid) or 0.0
    out = {
        "jobs": args.jobs,
        "cancel_ms_median": round(statistics.median(cancels) * 1000, 1),
        "cancel_ms_max": round(max(cancels) * 1000, 1),
        "service_rss_mib_before": round(rss0, 1),
        "service_rss_mib_after": round(rss1, 1),
        "service_rss_growth_mib": round(rss1 - rss0, 1),
    }
    print(json.dumps(out, indent=1))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    met = max(cancels) <= 1.0 and rss1 - rss0 <= 300.0
    print("targets (cancel <= 1 s, RSS growth <= 300 MB):", "met" if met else "NOT met")
    return 0 if met else 1


if __name__ == "__main__":
    raise SystemExit(main())

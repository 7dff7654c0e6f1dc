"""Benchmark: one coordinator flying a large generated team, with its CPU and memory.

The team is :func:`tests.teams.arc_team` (the paper's map, launch sites along the west and
south edges, goals on an arc 20 km around the paper target, in bearing order so that no two
routes cross). It is rehearsed with ``python -m gcs rehearse`` in a child process: planned,
scheduled (refused if a pair comes under the separation minimum), uploaded to the bundled
simulator and flown in lock step (the simulator waits for the coordinator, so the speed-up it
achieves is what this machine holds with both on it). Meanwhile the coordinator's and the
simulator's processes are sampled from ``/proc`` every 0.5 s: CPU time and resident memory.

Reported: planning and flight wall time, the achieved speed-up (mission seconds flown per
wall second in flight), CPU as a share of one core and peak resident memory of each process,
and what the flight record says from the simulator's truth log: every arrival's error
against its slot and the least 3-D distance between any two vehicles.

    .venv/bin/python bench/bench_swarm.py --vehicles 100 --speedup 50
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the generated teams live with the tests
from procstat import children, cpu_s, rss_mib  # noqa: E402  (bench/, beside this script)

from tests.teams import arc_team  # noqa: E402


class _Process:
    """CPU and peak memory of one process, sampled."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.cpu_first_s: float | None = None
        self.cpu_last_s: float | None = None
        self.wall_first_s = 0.0
        self.wall_last_s = 0.0
        self.peak_rss_mib = 0.0

    def sample(self, wall_s: float) -> None:
        cpu, rss = cpu_s(self.pid), rss_mib(self.pid)
        if cpu is None or rss is None:
            return
        if self.cpu_first_s is None:
            self.cpu_first_s, self.wall_first_s = cpu, wall_s
        self.cpu_last_s, self.wall_last_s = cpu, wall_s
        self.peak_rss_mib = max(self.peak_rss_mib, rss)

    def core_share(self) -> float | None:
        if self.cpu_first_s is None or self.cpu_last_s is None:
            return None
        span = self.wall_last_s - self.wall_first_s
        return None if span <= 0 else (self.cpu_last_s - self.cpu_first_s) / span


def run(args: argparse.Namespace) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as scratch:
        tmp = args.keep or scratch
        Path(tmp).mkdir(parents=True, exist_ok=True)
        scenario = Path(tmp) / f"arc{args.vehicles}.yaml"
        scenario.write_text(yaml.safe_dump(arc_team(args.vehicles)), encoding="utf-8")
        record_path = Path(tmp) / "record.json"
        cmd = [
            sys.executable, "-m", "gcs", "rehearse", str(scenario),
            "--speedup", str(args.speedup), "--seed", str(args.seed), "--quiet",
            "--json", str(record_path), "--truth", str(Path(tmp) / "truth.jsonl"),
        ]  # fmt: skip
        if args.wind:
            cmd += ["--wind", f"{args.wind},270"]
        wall0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=ROOT)
        coordinator = _Process(proc.pid)
        simulator: _Process | None = None
        while proc.poll() is None:
            now = time.perf_counter() - wall0
            coordinator.sample(now)
            if simulator is None:
                # The simulator is the coordinator's child once the plan is made.
                kids = children(proc.pid)
                if kids:
                    simulator = _Process(kids[0])
                    coordinator = _Process(proc.pid)  # from the flight on, not the planning
            if simulator is not None:
                simulator.sample(now)
            time.sleep(0.5)
        wall_s = time.perf_counter() - wall0
        sim_wall_s = None if simulator is None else wall_s - simulator.wall_first_s
        if proc.returncode != 0 and not record_path.exists():
            raise SystemExit(f"rehearse exited {proc.returncode} with no flight record")
        record = json.loads(record_path.read_text(encoding="utf-8"))
    errors = [v["error_s"] for v in record["vehicles"] if v.get("error_s") is not None]
    # Simulated time flown (the events' UTC is the simulator's) per wall second it ran.
    utcs = [e["utc_s"] for e in record["events"]]
    achieved = None if not sim_wall_s else (max(utcs) - min(utcs)) / sim_wall_s
    return {
        "vehicles": args.vehicles,
        "speedup_asked": args.speedup,
        "exit": proc.returncode,
        "state": record["state"],
        "wall_s": round(wall_s, 1),
        "simulator_wall_s": None if sim_wall_s is None else round(sim_wall_s, 1),
        "speedup_achieved": None if achieved is None else round(achieved, 1),
        "team_arrival_s": record.get("required_arrival_s"),
        "arrived": len(errors),
        "error_min_s": min(errors, default=None),
        "error_max_s": max(errors, default=None),
        "min_separation_m": record.get("min_separation_m"),
        "separation_m": record.get("separation_m"),
        # Conflicts said in flight (the record keeps the events' text): predicted in straight
        # flight, and resolved ahead of time by speed.
        "conflicts_predicted": sum(
            1
            for e in record["events"]
            if e["kind"] == "conflict" and e["reason"].startswith("predicted")
        ),
        "conflicts_resolved": sum(
            1
            for e in record["events"]
            if e["kind"] == "conflict" and e["reason"].startswith("flies")
        ),
        "coordinator_core_share": coordinator.core_share(),
        "coordinator_peak_rss_mib": round(coordinator.peak_rss_mib, 1),
        "simulator_core_share": None if simulator is None else simulator.core_share(),
        "simulator_peak_rss_mib": None if simulator is None else round(simulator.peak_rss_mib, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--speedup", type=float, default=50.0)
    parser.add_argument("--seed", type=int, default=0, help="planner and simulator seed")
    parser.add_argument("--wind", type=float, default=5.0, help="m/s from the west (0: none)")
    parser.add_argument(
        "--keep", metavar="DIR", help="keep the scenario, flight record and truth log there"
    )
    result = run(parser.parse_args())
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()

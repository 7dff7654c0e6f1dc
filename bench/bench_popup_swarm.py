"""Benchmark: a crowd re-planned round a pop-up zone where its routes bunch, kept apart in
flight, judged from the simulator's truth log.

The team is :func:`tests.teams.ring_team` (``--vehicles`` straight routes converging on a
target, 18 km -> 5 km out, 300 m separation). A forbidden zone pops up at 95 s of mission
across the routes ``--zone-out-m`` from the target on bearing ``--zone-bearing-deg``: the
re-plan routes the vehicles it covers round it, where they and their neighbours bunch. The
flight is rehearsed on the bundled simulator in lock step at ``--speedup`` (``--seed``: the
simulator's noise and wind errors), and judged by :func:`tests.verdict.judge` from the truth
log: every pair's least 3-D distance for the whole flight (re-plans and loiters included),
every arrival against its slot, the zone. Printed: that verdict, and what the coordinator
did (re-planned vehicles, the conflicts it said and how it resolved them).

    .venv/bin/python bench/bench_popup_swarm.py --vehicles 60 --zone-out-m 8000 --zone-radius-m 2000
"""

from __future__ import annotations

import argparse
import asyncio
import math
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the generated teams live with the tests

from gcs.coordination.config import FlightConfig  # noqa: E402
from gcs.rehearsal.rehearse import RehearsalOptions, rehearse  # noqa: E402
from planner.scenario import load_scenario  # noqa: E402
from tests.teams import ring_team  # noqa: E402
from tests.verdict import judge  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, default=30)
    ap.add_argument("--zone-out-m", type=float, default=9_000.0)
    ap.add_argument("--zone-radius-m", type=float, default=2_500.0)
    ap.add_argument("--zone-bearing-deg", type=float, default=0.0)
    ap.add_argument("--speedup", type=float, default=100.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, help="keep the flight record (tcgcs-flight/1) here")
    ap.add_argument("--truth", type=Path, help="keep the simulator's truth log (JSON lines) here")
    args = ap.parse_args()
    data = ring_team(args.vehicles)
    b = math.radians(args.zone_bearing_deg)
    centre = {
        "east_m": 30_000.0 + args.zone_out_m * math.sin(b),
        "north_m": 30_000.0 + args.zone_out_m * math.cos(b),
    }
    data["threats"].append(
        {"kind": "radar", "id": "POP", "forbidden": True, "center": centre,
         "radius_m": args.zone_radius_m, "appears": {"at_s": 95.0}}
    )  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="tcgcs-popup-swarm-") as tmp:
        path, truth = Path(tmp) / "scenario.yaml", Path(tmp) / "truth.jsonl"
        path.write_text(yaml.safe_dump(data), encoding="utf-8")
        t0 = time.perf_counter()
        record = asyncio.run(
            rehearse(
                RehearsalOptions(
                    scenario_path=path, scenario=load_scenario(path), speedup=args.speedup,
                    seed=args.seed, truth=truth, quiet=True, config=FlightConfig(seed=args.seed),
                    json_out=args.json,
                )
            )
        )  # fmt: skip
        wall_s = time.perf_counter() - t0
        verdict = judge(record, truth, tolerance_s=1.0, team_shift_max_s=600.0, together_min_s=60.0)
        if args.truth is not None:
            shutil.copyfile(truth, args.truth)
    events = record["events"]
    replanned = sorted(
        {v for e in events if e["kind"] == "replan" for v in e["reason"].split(" around ")[0].
         removeprefix("re-planning ").split(", ")}
    )  # fmt: skip
    said = Counter(
        (e["kind"], (e.get("payload") or {}).get("resolution") or "-")
        for e in events
        if e["kind"] in ("conflict", "alarm")
    )
    errors = verdict.errors_s()
    worst = max((abs(x) for x in errors.values() if x is not None), default=math.nan)
    print(f"{args.vehicles} vehicles, zone {args.zone_radius_m:g} m at {args.zone_out_m:g} m "
          f"bearing {args.zone_bearing_deg:g} deg, {args.speedup:g}x, seed {args.seed}: "
          f"{record['state']} in {wall_s:.0f} s wall")  # fmt: skip
    print(f"re-planned ({len(replanned)}): {', '.join(replanned)}")
    print(f"least 3-D separation (truth): {verdict.separation}; d_s {verdict.separation_m:g} m")
    print(f"worst arrival error (truth): {worst:.2f} s; never arrived: "
          f"{[v for v, x in errors.items() if x is None]}")  # fmt: skip
    print("conflict and alarm events: " + ", ".join(f"{k}/{r} {n}" for (k, r), n in said.items()))
    problems = verdict.problems()
    print("problems: " + ("; ".join(problems) if problems else "none"))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())

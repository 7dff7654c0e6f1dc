"""Benchmark: the paper's flight (its pop-up re-plan included) in a strong wind from each
quarter, judged from the simulator's truth log.

The paper scenario (``scenarios/paper_three_uav.yaml``) is scheduled in its own (calm)
forecast and flown on the bundled simulator in lock step at ``--speedup`` in a mean wind of
``--wind-m-s`` from each of ``--from-deg``. Each flight is judged by
:func:`tests.verdict.judge` from the truth log alone: every pair's least 3-D distance for the
whole flight (the re-plan round POPUP1 and the loiters included) against the scenario's 500 m,
every goal passage against the slot set before launch moved by the team time (within
``--tolerance-s``), the team time's move within what the wind and the pop-up can cost
(:func:`tests.paperbounds.team_time_move_max_s`), the zones from the flown track. Printed:
one line per wind with that verdict and what the coordinator said of conflicts.

    .venv/bin/python bench/bench_paper_winds.py --wind-m-s 10 --from-deg 0 90 180 270
"""

from __future__ import annotations

import argparse
import asyncio
import math
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the oracle lives with the tests

from gcs.coordination.config import FlightConfig  # noqa: E402
from gcs.rehearsal.rehearse import RehearsalOptions, rehearse  # noqa: E402
from planner.scenario import load_scenario  # noqa: E402
from tests.paperbounds import team_time_move_max_s, widest_offset_m  # noqa: E402
from tests.verdict import judge  # noqa: E402

PAPER = ROOT / "scenarios" / "paper_three_uav.yaml"


def fly(wind_m_s: float, from_deg: float, args: argparse.Namespace) -> list[str]:
    """One flight in that wind: its line, and its problems (none when it held)."""
    with tempfile.TemporaryDirectory(prefix="tcgcs-paper-wind-") as tmp:
        truth = Path(tmp) / "truth.jsonl"
        t0 = time.perf_counter()
        record = asyncio.run(
            rehearse(
                RehearsalOptions(
                    scenario_path=PAPER, scenario=load_scenario(PAPER), speedup=args.speedup,
                    wind=(wind_m_s, from_deg), seed=args.seed, truth=truth, quiet=True,
                    config=FlightConfig(seed=args.seed),
                )
            )
        )  # fmt: skip
        wall_s = time.perf_counter() - t0
        verdict = judge(
            record,
            truth,
            tolerance_s=args.tolerance_s,
            team_shift_max_s=team_time_move_max_s(
                wind_m_s, from_deg, offset_m=widest_offset_m(record)
            ),
            together_min_s=1_800.0,  # UAV3 up within 300 s, UAV1 from 300 s, arrivals after 5,000 s
        )
    said = Counter(
        (e["kind"], (e.get("payload") or {}).get("resolution") or "-")
        for e in record["events"]
        if e["kind"] in ("conflict", "alarm")
    )
    errors = verdict.errors_s()
    worst = max((abs(x) for x in errors.values() if x is not None), default=math.nan)
    problems = verdict.problems()
    line = (
        f"{wind_m_s:g} m/s from {from_deg:03.0f}: {record['state']}, least 3-D separation "
        f"{verdict.separation} (d_s {verdict.separation_m:g} m), worst arrival error "
        f"{worst:.2f} s, team time moved {verdict.shift_s:+.1f} s, "
        f"conflict/alarm events {dict(said) or 'none'}, {wall_s:.0f} s wall: "
        + ("held" if not problems else "; ".join(problems))
    )
    print(line, flush=True)
    return problems


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wind-m-s", type=float, default=10.0)
    ap.add_argument("--from-deg", type=float, nargs="+", default=[0.0, 90.0, 180.0, 270.0])
    ap.add_argument("--speedup", type=float, default=200.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--tolerance-s", type=float, default=1.0)
    args = ap.parse_args()
    failed = [d for d in args.from_deg if fly(args.wind_m_s, d, args)]
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

"""Command line: ``python -m planner plan|plot|schema``."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from planner.errors import PlannerError


def _cmd_plan(args: argparse.Namespace) -> int:
    import numpy as np

    from planner.plan import plan
    from planner.report import plan_json
    from planner.scenario import load_scenario

    t0 = time.perf_counter()
    scenario = load_scenario(args.scenario)
    result = plan(scenario, args.method, rng=np.random.default_rng(args.seed))
    elapsed = time.perf_counter() - t0
    doc = plan_json(
        result, scenario_file=str(Path(args.scenario)), seed=args.seed, elapsed_s=elapsed
    )
    out = Path(args.out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    except OSError as err:
        raise PlannerError(f"{out}: cannot write plan ({err.strerror})") from None
    for v in doc["vehicles"]:
        print(
            f"{v['id']}: {v['length_m'] / 1000:.1f} km, cost {v['cost']:.0f} "
            f"({v['cost_ratio']:.4f} x optimal), {len(v['waypoints'])} waypoints, "
            f"min clearance {v['min_clearance_m']:.0f} m"
        )
    print(f"{doc['status']} in {elapsed:.2f} s -> {out}")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from planner.plot import plot_plan

    plot_plan(Path(args.plan), Path(args.out))
    print(f"plot -> {args.out}")
    return 0


def _cmd_schema(args: argparse.Namespace) -> int:
    from planner.scenario import json_schema

    text = json.dumps(json_schema(), indent=2) + "\n"
    if args.out:
        Path(args.out).write_text(text, encoding="utf-8")
    else:
        sys.stdout.write(text)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m planner", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("plan", help="plan flyable routes for a scenario")
    p.add_argument("scenario", help="scenario file (.yaml or .json)")
    p.add_argument("--method", choices=("aco", "astar"), default="aco")
    p.add_argument("--seed", type=int, default=0, help="seed of the ACO's random generator")
    p.add_argument("--out", required=True, help="plan.json to write")
    p.set_defaults(func=_cmd_plan)
    q = sub.add_parser("plot", help="plot a plan: terrain, threats, paths")
    q.add_argument("plan", help="plan.json")
    q.add_argument("--out", required=True, help="PNG file to write")
    q.set_defaults(func=_cmd_plot)
    r = sub.add_parser("schema", help="print the scenario JSON Schema")
    r.add_argument("--out", help="file to write instead of standard output")
    r.set_defaults(func=_cmd_schema)
    args = parser.parse_args(argv)
    try:
        code: int = args.func(args)
    except PlannerError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    return code


if __name__ == "__main__":
    sys.exit(main())

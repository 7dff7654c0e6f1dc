"""Command line: ``python -m planner plan|plot|schedule|export|schema``."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from planner.errors import PlannerError


def _write_json(out: Path, doc: object, what: str) -> Path:
    """Write a JSON document; an unwritable path is one PlannerError naming it."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    except OSError as err:
        raise PlannerError(f"{out}: cannot write {what} ({err.strerror})") from None
    return out


def _cmd_plan(args: argparse.Namespace) -> int:
    from planner.scenario import load_scenario

    t0 = time.perf_counter()
    scenario = load_scenario(args.scenario)  # refused before the planner is loaded

    import numpy as np

    from planner.plan import plan
    from planner.report import plan_json

    result = plan(scenario, args.method, rng=np.random.default_rng(args.seed))
    elapsed = time.perf_counter() - t0
    doc = plan_json(
        result, scenario_file=str(Path(args.scenario)), seed=args.seed, elapsed_s=elapsed
    )
    out = _write_json(Path(args.out), doc, "plan")
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


def _cmd_schedule(args: argparse.Namespace) -> int:
    from planner.scenario import load_scenario, parse_wind

    t0 = time.perf_counter()
    scenario = load_scenario(args.scenario)  # refused before the planner is loaded
    if args.wind is not None:
        scenario = scenario.with_forecast_wind(parse_wind(args.wind, "--wind"))

    import numpy as np

    from planner.deconflict import check_separation, separation
    from planner.errors import SeparationError
    from planner.plan import build_world, plan
    from planner.popup import replay_popups
    from planner.retime import build_schedule, check_feasible
    from planner.schedulefile import schedule_json

    rng = np.random.default_rng(args.seed)
    world = build_world(scenario)
    planned = plan(scenario, args.method, rng=rng, world=world)
    schedule = build_schedule(scenario, planned, world=world)
    try:
        # The schedule as planned: the requested arrival held, and (unless allowed) d_s.
        sep = check_feasible(schedule, allow_conflicts=args.allow_conflicts)
        if args.popup:
            schedule = replay_popups(schedule, method=args.method, rng=rng, world=world)
            sep = separation(schedule.vehicles, scenario.separation_m)
            if not args.allow_conflicts:
                check_separation(sep)
    except SeparationError as err:
        raise PlannerError(f"{err} (--allow-conflicts writes the schedule anyway)") from None
    elapsed = time.perf_counter() - t0
    doc = schedule_json(
        schedule,
        sep,
        world.terrain,
        scenario_file=str(Path(args.scenario)),
        extra={"method": args.method, "seed": args.seed, "popup": bool(args.popup)},
    )
    out = _write_json(Path(args.out), doc, "schedule")
    for e in doc["events"]:
        print(f"{e['time_s']:8.1f} s  {e['kind']}: {e['text']}")
    for a in doc["adjustments"]:
        print(f"{a['time_s']:8.1f} s  {a['vehicle']} {a['strategy']} {a['value']:g}: {a['reason']}")
    for v in doc["vehicles"]:
        vid = v["id"]
        speeds = "/".join(f"{x['speed_m_s']:g}" for x in v["legs"])
        turns = sum(lo["turns"] for lo in v["loiters"])
        print(
            f"{vid}: takeoff {v['takeoff_s']:.1f} s, arrival {v['arrival_s']:.1f} s, "
            f"{v['length_m'] / 1000:.1f} km, speeds {speeds} m/s, loiter turns {turns}"
        )
    print(
        f"arrival {doc['required_arrival_s']} s, min separation {doc['min_separation_m']} m "
        f"(d_s {doc['separation_required_m']:g} m) in {elapsed:.2f} s -> {out}"
    )
    for c in sep.conflicts:
        print(
            f"conflict allowed: {c.a} and {c.b} within {c.distance_m:.1f} m at {c.time_s:.1f} s "
            f"(d_s {sep.required_m:g} m)"
        )
    if args.plot:
        from planner.speedplot import plot_speeds

        plot_speeds(doc, Path(args.plot))
        print(f"speed plot -> {args.plot}")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from planner.missionfile import to_qgc_plan, to_wpl
    from planner.schedulefile import mission_from_json

    src = Path(args.schedule)
    try:
        doc = json.loads(src.read_text(encoding="utf-8"))
    except OSError as err:
        raise PlannerError(f"{src}: cannot read schedule ({err.strerror})") from None
    except json.JSONDecodeError as err:
        raise PlannerError(f"{src}: line {err.lineno}: invalid JSON: {err.msg}") from None
    if not isinstance(doc, dict):
        raise PlannerError(f"{src}: the top level must be an object")
    items = mission_from_json(doc, args.vehicle)
    if args.format == "wpl":
        text = to_wpl(items)
    else:
        text = json.dumps(to_qgc_plan(items), indent=4, allow_nan=False) + "\n"
    out = Path(args.out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8", newline="\n")
    except OSError as err:
        raise PlannerError(f"{out}: cannot write mission ({err.strerror})") from None
    print(f"{args.vehicle}: {len(items)} mission items ({args.format}) -> {out}")
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
    sc = sub.add_parser("schedule", help="time a plan: takeoffs, speeds, loiters, separation")
    sc.add_argument("scenario", help="scenario file (.yaml or .json)")
    sc.add_argument("--popup", action="store_true", help="replay the pop-up threats")
    sc.add_argument("--method", choices=("aco", "astar"), default="aco")
    sc.add_argument("--seed", type=int, default=0, help="seed of the ACO's random generator")
    sc.add_argument("--out", required=True, help="schedule.json to write")
    sc.add_argument("--plot", help="PNG of the speed profiles to write")
    sc.add_argument(
        "--wind",
        metavar="SPEED_M_S,FROM_DEG",
        help="forecast wind to time the schedule in (instead of the scenario's wind)",
    )
    sc.add_argument(
        "--allow-conflicts",
        action="store_true",
        help="write a schedule whose vehicles come closer than separation_m (else exit 1)",
    )
    sc.set_defaults(func=_cmd_schedule)
    ex = sub.add_parser("export", help="write one vehicle's mission from a schedule.json")
    ex.add_argument("schedule", help="schedule.json")
    ex.add_argument("--vehicle", required=True, help="vehicle id")
    ex.add_argument("--format", choices=("qgc", "wpl"), required=True)
    ex.add_argument("--out", required=True, help="mission file to write")
    ex.set_defaults(func=_cmd_export)
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

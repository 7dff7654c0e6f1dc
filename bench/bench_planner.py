"""Planner benchmark: 3, 10, 30 and 100 UAVs on the paper's 200 km map.

For each team size: wall time of the full plan (world, grid, exact search, ACO, smoothing,
profiles, checks), the worst and mean ACO cost ratio to the exact optimum on the same graph,
and the peak traced memory; then the schedule's (takeoffs and speeds, pairs separated by
timing) wall time and its minimum separation with every pair searched. Run:
``.venv/bin/python bench/bench_planner.py [--sizes 3 10]``. The per-vehicle work (cost-to-go
fields, route finishing) runs where ``plan()`` puts it by default: every core from 20
vehicles on, one process below; ``--workers 1`` keeps it in one process (the same plans).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from procstat import TreeMemory  # bench/, beside this script

from planner.backend import Backend, RayBackend
from planner.deconflict import separation
from planner.plan import build_world, plan
from planner.retime import build_schedule
from planner.scenario import load_scenario, parse_scenario
from planner.terrain import build_terrain

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "scenarios" / "paper_three_uav.yaml"


def team_scenario(
    n: int,
    seed: int = 0,
    *,
    assign_goals: bool = True,
    altitude_layers_m: tuple[float, ...] = (600.0,),
) -> dict[str, Any]:
    """The paper's map and static threats with ``n`` vehicles from the west and south edges.

    Goals sit on rings 3-15 km around the target at (200, 200) km, at least 800 m apart (for
    more than 100 vehicles, 800 m x sqrt(100 / n) apart: the ring holds about 260 goals 800 m
    apart, and a team that large is a planning load, not one the airspace could hold). They
    are approach points any vehicle may take (``assign_goals``); ``assign_goals=False``
    keeps each vehicle on the point drawn for it. The airspace allows a layer 600 m above the
    planned profiles, under the paper vehicles' 1,600 m ceiling (``altitude_layers_m``).
    """
    spacing_m = 800.0 * min(1.0, math.sqrt(100.0 / n))
    base = load_scenario(PAPER).model_dump(mode="json", exclude_none=True)
    base["threats"] = [t for t in base["threats"] if "appears" not in t]
    rng = np.random.default_rng(seed)
    terrain = build_terrain(parse_scenario(base))
    template = base["vehicles"][0]
    vehicles: list[dict[str, Any]] = []
    goals: list[tuple[float, float]] = []
    while len(vehicles) < n:
        k = len(vehicles)
        if k % 2 == 0:
            start = (60_000.0, float(rng.uniform(60_000, 240_000)))
        else:
            start = (float(rng.uniform(60_000, 240_000)), 60_000.0)
        ground = terrain.elevation_m(np.array([start[0]]), np.array([start[1]]))
        if float(ground[0]) > 900.0:  # launch sites in the lowlands
            continue
        r, a = float(rng.uniform(3_000, 15_000)), float(rng.uniform(math.pi, 1.5 * math.pi))
        goal = (200_000 + r * math.cos(a), 200_000 + r * math.sin(a))
        if any(math.dist(goal, g) < spacing_m for g in goals):
            continue
        goals.append(goal)
        v = dict(template)
        v["id"] = f"U{k:03d}"
        v["start"] = {"east_m": start[0], "north_m": start[1], "alt_m": 1000}
        v["goal"] = {"east_m": goal[0], "north_m": goal[1], "alt_m": 1000}
        vehicles.append(v)
    base["vehicles"] = vehicles
    base["buffers"] = []
    base["assign_goals"] = assign_goals
    base["altitude_layers_m"] = list(altitude_layers_m)
    return base


def run(
    n: int,
    seed: int,
    workers: int | None = None,
    ray_address: str | None = None,
    schedule: bool = True,
    layers_m: tuple[float, ...] = (600.0,),
) -> dict[str, Any]:
    """Plan one team (in this process) and return the figures. With ``ray_address`` the routes
    are finished on Ray (``"local"``: a Ray started here, its start-up not timed);
    ``layers_m``: the generated teams' altitude layers."""
    scenario = (
        parse_scenario(team_scenario(n, seed, altitude_layers_m=layers_m))
        if n != 3
        else load_scenario(PAPER)
    )
    backend: Backend | None = None
    if ray_address is not None:
        backend = RayBackend(None if ray_address == "local" else ray_address)
    t0 = time.perf_counter()
    world = build_world(scenario)
    result = plan(
        scenario, "aco", rng=np.random.default_rng(seed), world=world, workers=workers,
        backend=backend,
    )  # fmt: skip
    wall = time.perf_counter() - t0
    if isinstance(backend, RayBackend):
        backend.close()
    ratios = [r.cost / r.optimal_cost for r in result.routes]
    # The schedule's timing (takeoffs, speeds; pairs separated by takeoff and speed where one
    # starts on the ground) and its separation, every pair searched: what a flight is refused
    # or flown on.
    figures = {
        "uavs": n,
        "wall_s": wall,
        "iterations": result.result.iterations,
        "ratio_max": max(ratios),
        "ratio_mean": float(np.mean(ratios)),
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "status": str(result.result.status),
        "min_separation_m": result.min_separation_m,
    }
    if not schedule:
        return figures
    t0 = time.perf_counter()
    timed = build_schedule(scenario, result, world=world)
    sep = separation(timed.vehicles, scenario.separation_m)
    schedule_wall = time.perf_counter() - t0
    return figures | {
        "schedule_s": schedule_wall,
        "schedule_min_separation_m": sep.min_separation_m,
        "schedule_conflicts": len(sep.conflicts),
        "separated": sum(1 for e in timed.events if e.kind == "separation"),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=int, nargs="*", default=[3, 10, 30, 100])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--workers",
        type=int,
        help="processes for the per-vehicle work (default: plan()'s, every core from 20 "
        "vehicles on)",
    )
    parser.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="finish the routes on Ray: 'local' starts one here, else ray.init(address=ADDRESS)",
    )
    parser.add_argument(
        "--no-schedule", action="store_true", help="plan only (no schedule, no separation search)"
    )
    parser.add_argument(
        "--layers",
        type=float,
        nargs="*",
        default=[600.0],
        metavar="M",
        help="the generated teams' altitude layers, m above the profiles (default 600; "
        "none given: no layers)",
    )
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one is not None:
        # Peak memory of this process and all it starts (Ray's processes included).
        with TreeMemory() as memory:
            figures = run(
                args.one, args.seed, args.workers, args.ray, not args.no_schedule,
                tuple(args.layers),
            )  # fmt: skip
        print(json.dumps(figures | {"tree_peak_rss_mib": memory.peak_mib}))
        return
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, "
        f"{platform.python_implementation()} {platform.python_version()}, numpy {np.__version__}, "
        + (f"{args.workers} worker(s)" if args.workers else "plan()'s default workers")
        + (f", routes finished on Ray ({args.ray})" if args.ray else "")
        + f", altitude layers {args.layers or 'none'}"
    )
    print(
        "| UAVs | wall (s) | ACO iterations | cost / optimal, max | mean "
        "| peak RSS (MiB) | with child processes (MiB) | status | min separation (m) "
        "| schedule (s) | separated by timing | schedule min separation (m) | pairs under d_s |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|")
    for n in args.sizes:
        # A fresh process per size, so peak RSS is that size's own.
        out = subprocess.run(
            [
                sys.executable,
                __file__,
                "--one",
                str(n),
                "--seed",
                str(args.seed),
                *(["--workers", str(args.workers)] if args.workers else []),
                *(["--ray", args.ray] if args.ray else []),
                *(["--no-schedule"] if args.no_schedule else []),
                "--layers",
                *(str(h) for h in args.layers),
            ],
            capture_output=True,
            text=True,
            check=True,
        )
        r = json.loads(out.stdout.strip().splitlines()[-1])
        timed = (
            f"{r['schedule_s']:.2f} | {r['separated']} | {r['schedule_min_separation_m']:.0f} | "
            f"{r['schedule_conflicts']}"
            if "schedule_s" in r
            else "- | - | - | -"
        )
        print(
            f"| {r['uavs']} | {r['wall_s']:.2f} | {r['iterations']} | {r['ratio_max']:.4f} | "
            f"{r['ratio_mean']:.4f} | {r['peak_rss_mib']:.0f} | {r['tree_peak_rss_mib']:.0f} | "
            f"{r['status']} | {r['min_separation_m']:.0f} | {timed} |",
            flush=True,
        )


if __name__ == "__main__":
    main()

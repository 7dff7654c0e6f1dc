"""Benchmark: the re-plan after a pop-up threat, for a team of N converging on a target.

Two teams: ``ring`` is :func:`tests.teams.ring_team` (N routes converging on one target from a
ring, 50 km across) with a forbidden disc that appears across the northernmost routes 11 km
out (the 30-vehicle pop-up rehearsal's zone); ``paper`` is the planner bench's team (the
paper's 200 km map and static threats, launch sites on the west and south edges, goals
3-15 km from the target) with a disc of 4 km that appears at 1,500 s where the vehicle
nearest the team's middle will be at 3,000 s (``--zone-at-s``: across the routes that funnel
together there). The team is planned and scheduled, then the re-plan the coordinator runs
when the threat appears (:func:`planner.popup.apply_popup`: the routes it touches planned
again from where the vehicles will be, the team re-timed, and checked in 4-D from then on:
pairs under d_s timed apart, routed round the zone wider, lifted onto altitude layers, or
said) is timed, several times, each from its own seed. The re-plan is what stands between
the threat and the uploads: the coordinator starts them as soon as it returns.

    .venv/bin/python bench/bench_replan.py --vehicles 30 [--team ring|paper] [--radius-m M]
        [--zone-at-s S]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the generated teams live with the tests
from bench_planner import team_scenario  # noqa: E402  (bench/, beside this script)

from planner.plan import build_world, plan  # noqa: E402
from planner.popup import apply_popup, popup_zones  # noqa: E402
from planner.retime import build_schedule  # noqa: E402
from planner.scenario import parse_scenario  # noqa: E402
from planner.threats import active, build_threats  # noqa: E402
from tests.teams import ring_team  # noqa: E402


def _crowded_point(data: dict[str, Any], t_s: float) -> tuple[float, float]:
    """Where the vehicle nearest the team's middle is at ``t_s`` as scheduled (no pop-up)."""
    scenario = parse_scenario(data)
    schedule = build_schedule(scenario, plan(scenario, rng=np.random.default_rng(0)))
    points = np.array([p for v in schedule.vehicles if (p := v.position_at(t_s)) is not None])
    middle = points.mean(axis=0)
    east, north = points[np.argmin(np.hypot(*(points - middle).T))]
    return float(east), float(north)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vehicles", type=int, default=30)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--team", choices=["ring", "paper"], default="paper")
    parser.add_argument(
        "--radius-m", type=float, default=None, help="the zone's radius (default 2.5 / 4 km)"
    )
    parser.add_argument(
        "--zone-at-s",
        type=float,
        default=3_000.0,
        help="paper: the zone is centred where the vehicle nearest the team's middle is then",
    )
    args = parser.parse_args()
    if args.team == "ring":
        data = ring_team(args.vehicles)
        centre, radius_m, at_s = (30_000.0, 41_000.0), 2_500.0, 150.0
    else:
        data = team_scenario(args.vehicles)
        centre, radius_m, at_s = _crowded_point(data, args.zone_at_s), 4_000.0, 1_500.0
    radius_m = args.radius_m or radius_m
    data["threats"].append(
        {
            "kind": "radar", "id": "POP", "forbidden": True,
            "center": {"east_m": centre[0], "north_m": centre[1]}, "radius_m": radius_m,
            "appears": {"at_s": at_s},
        }
    )  # fmt: skip
    scenario = parse_scenario(data)
    world = build_world(scenario)
    t0 = time.perf_counter()
    schedule = build_schedule(scenario, plan(scenario, rng=np.random.default_rng(0), world=world))
    print(f"plan and schedule: {time.perf_counter() - t0:.2f} s")
    (zone,) = popup_zones(build_threats(scenario))
    threats = active(world.threats, at_s)
    walls = []
    for seed in range(args.runs):
        t0 = time.perf_counter()
        outcome = apply_popup(
            schedule, zone, at_s=at_s, world=world, threats=threats,
            rng=np.random.default_rng(seed),
        )  # fmt: skip
        walls.append(time.perf_counter() - t0)
        replanned = [e.text for e in outcome.events if e.kind == "replan"]
        pairs = [e.payload for e in outcome.events if e.kind == "conflict" and "pair" in e.payload]
        timed = sum(1 for p in pairs if p.get("resolution") == "timing")
        wider = sum(1 for p in pairs if p.get("resolution") == "offset")
        lifted = sum(1 for p in pairs if p.get("resolution") == "altitude")
        left = sum(1 for e in outcome.events if e.kind == "alarm" and "pair" in e.payload)
        print(
            f"seed {seed}: {walls[-1]:.2f} s; {len(outcome.affected)} re-planned; "
            f"{timed} timed apart, {wider} routed wider, {lifted} lifted onto a layer, "
            f"{left} pairs left under d_s; "
            f"{'; '.join(replanned)}"
        )
    print(
        f"{args.vehicles} vehicles, re-plan wall s: median {statistics.median(walls):.2f}, "
        f"max {max(walls):.2f} over {len(walls)} runs"
    )


if __name__ == "__main__":
    main()

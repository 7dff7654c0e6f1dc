"""Teams generated for rehearsals and benchmarks (not hand-tuned files)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from planner.plan import build_terrain
from planner.scenario import load_scenario, parse_scenario

PAPER = Path(__file__).resolve().parents[1] / "scenarios" / "paper_three_uav.yaml"
TARGET = (200_000.0, 200_000.0)


def arc_team(n: int, radius_m: float = 20_000.0) -> dict[str, Any]:
    """The paper's map with ``n`` vehicles: launch sites spread evenly along the west and
    south edges (lowland points only, as ``bench_planner.team_scenario`` picks them), goals
    evenly on an arc ``radius_m`` around the paper target from north-west to south-east,
    given in the order of the sites' bearings from the target so that no two routes cross.

    Unlike the planner bench's team this one can be flown by the service, which refuses a
    schedule with a pair under the separation minimum (500 m): routes are not drawn along
    the same valleys (terrain weight 0, ``alt_max_m`` over the peaks), the only threat kept
    is SAM1 (the radars and NFZ1 funnel neighbours into one corridor) and the takeoff windows
    are wide ([0, 9000] s) so the short routes wait on the ground.
    """
    base = load_scenario(PAPER).model_dump(mode="json", exclude_none=True)
    base["threats"] = [t for t in base["threats"] if t["id"] == "SAM1"]
    base["buffers"] = []
    base["weights"] = {"threat": 4.0, "terrain": 0.0}
    terrain = build_terrain(parse_scenario(base))
    edge = [(60_000.0, float(n_)) for n_ in np.arange(240_000.0, 60_000.0, -2_000.0)]
    edge += [(float(e), 60_000.0) for e in np.arange(62_000.0, 240_001.0, 2_000.0)]
    ground = terrain.elevation_m(np.array([p[0] for p in edge]), np.array([p[1] for p in edge]))
    sites = [p for p, z in zip(edge, ground, strict=True) if float(z) <= 900.0]
    picked = [sites[int(i)] for i in np.linspace(0, len(sites) - 1, n).round()]
    tx, ty = TARGET
    picked.sort(key=lambda p: math.atan2(p[1] - ty, p[0] - tx) % (2 * math.pi))
    template = base["vehicles"][0]
    vehicles = []
    for k, (se, sn) in enumerate(picked):
        a = math.radians(135.0 + 180.0 * k / max(1, n - 1))
        v = dict(template)
        v["id"] = f"U{k:03d}"
        v["start"] = {"east_m": se, "north_m": sn, "alt_m": 1000}
        v["goal"] = {
            "east_m": tx + radius_m * math.cos(a),
            "north_m": ty + radius_m * math.sin(a),
            "alt_m": 1000,
        }
        v["takeoff_window_s"] = [0, 9000]
        v["alt_max_m"] = 3000
        vehicles.append(v)
    base["vehicles"] = vehicles
    return base

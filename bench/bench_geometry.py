"""Benchmark: the two geometry kernels a flight and its report lean on, against their targets.

- a synthetic terrain's elevation over a 200 x 200 grid of points (the planner's grid and the
  simulator's tiles ask for arrays of this size): target under 20 ms;
- the least 3-D separation of three vehicles' truth tracks of 20,000 samples each (a
  2 h 47 min flight at 2 Hz), as the flight record measures it: target under 1 s.

The best of ``--rounds`` of each is kept (the least disturbed by other work on the machine).

    .venv/bin/python bench/bench_geometry.py [--rounds 5]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time
from collections.abc import Callable

import numpy as np

from gcs.coordination.tracks import TruthSample, min_separation
from planner.geo import LocalFrame
from planner.terrain import SyntheticTerrain

TERRAIN_TARGET_S = 0.020
SEPARATION_TARGET_S = 1.0


def _best_s(work: Callable[[], object], rounds: int) -> float:
    best = math.inf
    for _ in range(rounds):
        t0 = time.perf_counter()
        work()
        best = min(best, time.perf_counter() - t0)
    return best


def terrain_s(rounds: int) -> float:
    terrain = SyntheticTerrain.generate(
        seed=11, min_east_m=-5e4, max_east_m=5e4, min_north_m=-4e4, max_north_m=6e4
    )
    east, north = np.meshgrid(np.linspace(-5e4, 5e4, 200), np.linspace(-4e4, 6e4, 200))
    return _best_s(lambda: terrain.elevation_m(east, north), rounds)


def separation_s(rounds: int) -> float:
    frame = LocalFrame(46.0, 8.0)
    n = 20_000
    t = np.arange(n) * 0.5
    tracks = {}
    for i in range(1, 4):
        east, north = 25.0 * t * math.cos(i), 25.0 * t * math.sin(i) + 300.0 * i
        lat, lon = frame.to_geodetic(east, north)
        tracks[i] = [
            TruthSample(1.8e9 + float(u), float(a), float(o), 500.0, 22.0, 22.0, True, False)
            for u, a, o in zip(t, lat, lon, strict=True)
        ]
    return _best_s(lambda: min_separation(tracks), rounds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, "
        f"{platform.python_implementation()} {platform.python_version()}, numpy {np.__version__}"
    )
    print("| kernel | best of rounds (ms) | target (ms) | met |")
    print("|---|---:|---:|---|")
    kernels = (
        ("synthetic terrain, 200 x 200 points", terrain_s, TERRAIN_TARGET_S),
        ("3-D separation, 3 tracks of 20,000 samples", separation_s, SEPARATION_TARGET_S),
    )
    for name, measure, target in kernels:
        best = measure(args.rounds)
        met = "yes" if best < target else "NO"
        print(f"| {name} | {1e3 * best:.1f} | {1e3 * target:.0f} | {met} |")


if __name__ == "__main__":
    main()

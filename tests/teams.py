"""Teams generated for rehearsals and benchmarks (not hand-tuned files)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from planner.plan import build_world, plan
from planner.retime import build_schedule
from planner.scenario import load_scenario, parse_scenario
from planner.schedule import Schedule
from planner.terrain import build_terrain

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


def ring_team(n: int) -> dict[str, Any]:
    """``n`` vehicles evenly on a ring 18 km around a target over flat ground, each flying in
    to a goal 5 km short of the target on its own bearing (so that no two routes cross and
    the goals are 2 pi 5 / n km apart), 500 m above the ground; no threats, a simultaneous
    arrival, takeoff windows wide enough for the team to wait on the ground. About 13 km of
    route each: a crowd whose flight lasts minutes, not an hour."""
    tx, ty = 30_000.0, 30_000.0
    vehicles = []
    for k in range(n):
        bearing = 2.0 * math.pi * k / n
        ue, un = math.sin(bearing), math.cos(bearing)
        v = _vehicle(
            k,
            (tx + 18_000.0 * ue, ty + 18_000.0 * un),
            (tx + 5_000.0 * ue, ty + 5_000.0 * un),
            800.0,
        )
        v["id"] = f"R{k:02d}"
        v["takeoff_window_s"] = [0, 900]
        vehicles.append(v)
    return {
        "name": f"ring of {n}",
        "area": {
            "origin": {"lat_deg": 46.0, "lon_deg": 8.0},
            "min_east_m": 0, "min_north_m": 0, "width_m": 60_000, "height_m": 60_000,
        },
        "terrain": {"kind": "flat", "elevation_m": 300},
        "separation_m": 300,
        "weights": {"threat": 4.0, "terrain": 0.0},
        "arrival": {"kind": "simultaneous"},
        "threats": [],
        "vehicles": vehicles,
    }  # fmt: skip


ARRIVAL_KINDS = ("simultaneous", "spaced", "waves", "windows")


def generated_scenario(seed: int, kind: str) -> tuple[dict[str, Any], tuple[float, float]]:
    """A scenario drawn from ``seed`` with the arrival ``kind``, and a wind (m/s, from deg).

    3-8 vehicles on a ring 14-20 km around a target over synthetic hills (or flat ground),
    each starting 0-1,500 m above its launch point, with speed limits, turn radii and takeoff
    windows of their own; goals 1.5-2.5 km short of the target on each vehicle's bearing, so
    the routes do not cross. The wind is 0-10 m/s from any direction; the scenario's forecast
    is it rounded (1 m/s, 10 deg).
    """
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 9))
    tx, ty = 30_000.0, 30_000.0
    if rng.random() < 0.75:
        terrain: dict[str, Any] = {
            "kind": "synthetic",
            "seed": int(rng.integers(0, 1000)),
            "base_m": round(float(rng.uniform(100.0, 600.0))),
            "peak_m": round(float(rng.uniform(400.0, 1400.0))),
            "hills": int(rng.integers(5, 30)),
        }
    else:
        terrain = {"kind": "flat", "elevation_m": round(float(rng.uniform(0.0, 800.0)))}
    doc: dict[str, Any] = {
        "name": f"generated {seed} ({kind}, {n} vehicles)",
        "area": {
            "origin": {"lat_deg": 45.0 + float(rng.uniform(-5, 5)), "lon_deg": 8.0},
            "min_east_m": 0, "min_north_m": 0, "width_m": 60_000, "height_m": 60_000,
        },
        "terrain": terrain,
        "separation_m": 300,
        "weights": {"threat": 4.0, "terrain": 0.0},
    }  # fmt: skip
    probe = {**doc, "arrival": {"kind": "simultaneous"}}
    ground = build_terrain(parse_scenario({**probe, "vehicles": [_vehicle(0, (0, 0), (1, 1), 0)]}))
    first = float(rng.uniform(0.0, 360.0))
    vehicles = []
    for k in range(n):
        bearing = math.radians(first + 360.0 * k / n + float(rng.uniform(-8.0, 8.0)))
        r0, r1 = float(rng.uniform(14_000.0, 20_000.0)), float(rng.uniform(1_500.0, 2_500.0))
        start = (tx + r0 * math.sin(bearing), ty + r0 * math.cos(bearing))
        goal = (tx + r1 * math.sin(bearing), ty + r1 * math.cos(bearing))
        z0 = float(ground.elevation_m(np.array([start[0]]), np.array([start[1]]))[0])
        v = _vehicle(k, start, goal, z0 + float(rng.uniform(0.0, 1_500.0)))
        v["goal"]["alt_m"] = round(z0 + 600.0)
        v["speed_min_m_s"] = round(float(rng.uniform(14.0, 18.0)), 1)
        v["speed_max_m_s"] = round(float(rng.uniform(26.0, 32.0)), 1)
        v["min_turn_radius_m"] = round(float(rng.uniform(150.0, 260.0)))
        v["takeoff_window_s"] = [0, int(rng.integers(900, 2400))]
        vehicles.append(v)
    doc["vehicles"] = vehicles
    ids = [v["id"] for v in vehicles]
    if kind == "simultaneous":
        doc["arrival"] = {"kind": "simultaneous"}
    elif kind == "spaced":
        doc["arrival"] = {"kind": "spaced", "interval_s": int(rng.integers(30, 91))}
    elif kind == "waves":
        first_wave = int(rng.integers(1, n))
        doc["arrival"] = {
            "kind": "waves",
            "gap_s": int(rng.integers(60, 181)),
            "sizes": [first_wave, n - first_wave],
        }
    elif kind == "windows":
        t0 = 1_000.0  # after every earliest arrival, before every latest (no buffers)
        doc["arrival"] = {
            "kind": "windows",
            "windows": [
                {"vehicle": vid, "earliest_s": t0 + 60.0 * k, "latest_s": t0 + 60.0 * k + 40.0}
                for k, vid in enumerate(rng.permutation(ids).tolist())
            ],
        }
    else:
        raise ValueError(f"unknown arrival kind {kind!r}")
    wind = (round(float(rng.uniform(0.0, 10.0)), 1), round(float(rng.uniform(0.0, 360.0))))
    # The forecast the schedule is timed in: the simulator's wind to the nearest metre per
    # second and ten degrees (the vehicles measure the rest in flight).
    doc["wind"] = {"speed_m_s": float(round(wind[0])), "from_deg": float(round(wind[1], -1) % 360)}
    return doc, wind


def _vehicle(
    k: int, start: tuple[float, float], goal: tuple[float, float], alt_m: float
) -> dict[str, Any]:
    return {
        "id": f"G{k}",
        "start": {"east_m": round(start[0]), "north_m": round(start[1]), "alt_m": round(alt_m)},
        "goal": {"east_m": round(goal[0]), "north_m": round(goal[1]), "alt_m": round(alt_m)},
        "speed_min_m_s": 16, "speed_max_m_s": 28, "min_turn_radius_m": 200,
        "max_range_m": 200_000, "alt_max_m": 4_000, "takeoff_window_s": [0, 1200],
    }  # fmt: skip


def landing_scenario(seed: int, n: int = 4) -> tuple[dict[str, Any], tuple[float, float]]:
    """Landing slots drawn from ``seed``: ``n`` aircraft already flying (``airborne``) on the
    approach side of a runway, 15-30 km out, 600-1,500 m above it, landing 90 s apart in a
    given order (the farther out, the later); each goal is the slot fix 6 km short of the
    touchdown on the extended centreline, 300 m above the runway, crossed after a 2.5 km
    straight final. Flat ground; a wind (m/s, from deg) of 0-6 m/s.
    """
    rng = np.random.default_rng(seed)
    elevation = round(float(rng.uniform(0.0, 600.0)))
    heading = round(float(rng.uniform(0.0, 360.0)))
    tx, ty = 30_000.0, 30_000.0
    ue, un = math.sin(math.radians(heading)), math.cos(math.radians(heading))
    fix = (tx - 6_000.0 * ue, ty - 6_000.0 * un)
    vehicles = []
    for k in range(n):
        # Spread across the approach side, the later slots farther out.
        off = math.radians(float(rng.uniform(-60.0, 60.0)))
        back = math.atan2(-ue, -un) + off
        r = 15_000.0 + 2_200.0 * k + float(rng.uniform(0.0, 800.0))
        start = (fix[0] + r * math.sin(back), fix[1] + r * math.cos(back))
        v = _vehicle(k, start, fix, elevation + float(rng.uniform(600.0, 1_500.0)))
        v["goal"]["alt_m"] = elevation + 300
        v["airborne"] = True
        v["takeoff_window_s"] = [0, 0]
        v["min_turn_radius_m"] = round(float(rng.uniform(150.0, 220.0)))
        vehicles.append(v)
    doc: dict[str, Any] = {
        "name": f"landing slots {seed} ({n} vehicles, runway {heading} deg)",
        "area": {
            "origin": {"lat_deg": 45.0 + float(rng.uniform(-5, 5)), "lon_deg": 8.0},
            "min_east_m": 0, "min_north_m": 0, "width_m": 60_000, "height_m": 60_000,
        },
        "terrain": {"kind": "flat", "elevation_m": elevation},
        "separation_m": 300,
        "weights": {"threat": 4.0, "terrain": 0.0},
        "arrival": {"kind": "spaced", "interval_s": 90, "order": [v["id"] for v in vehicles]},
        "landing": {
            "touchdown": {"east_m": tx, "north_m": ty, "alt_m": elevation},
            "heading_deg": heading,
            "approach_m": 2_500,
        },
        "vehicles": vehicles,
    }  # fmt: skip
    wind = (round(float(rng.uniform(0.0, 6.0)), 1), round(float(rng.uniform(0.0, 360.0))))
    return doc, wind


async def rehearse_doc(
    doc: dict[str, Any], wind: tuple[float, float], seed: int, directory: Path
) -> tuple[dict[str, Any], Path]:
    """Rehearse a generated scenario at 200x with 5 % packet loss in ``wind`` (lock step):
    the record and the simulator's truth log (``truth.jsonl`` in ``directory``). The record
    is kept as ``flight.json`` beside them for a failure's post-mortem."""
    from gcs.rehearsal.rehearse import RehearsalOptions, rehearse

    path = directory / "generated.yaml"
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    truth = directory / "truth.jsonl"
    options = RehearsalOptions(
        scenario_path=path,
        scenario=load_scenario(path),
        speedup=200.0,
        wind=wind,
        loss=0.05,
        seed=seed,
        truth=truth,
        json_out=directory / "flight.json",
        quiet=True,
    )
    return await rehearse(options), truth


def compact_paper(scale: float = 0.25) -> dict[str, Any]:
    """The paper's scenario drawn ``scale`` times as large about its target: the same three
    vehicles, threats, pop-up and holding areas, in an area ``scale`` as wide, so the flight
    lasts about ``scale`` as long (some 1,300 s at 0.25, against 5,500 s).

    Kept at full size: the goals (1.5-2 km short of the target, so that a simultaneous
    arrival keeps d_s), the speeds and turn radii, the altitudes. Scaled: the launch sites,
    the area and its grid, the hills' heights (the slopes stay the paper's), the zones, the
    holding areas (not under 1.2 km across, for a loiter of 300 m), the takeoff windows and the
    pop-up's delay. At this scale POPUP1 lies across UAV2's route only.
    """
    doc = yaml.safe_load(PAPER.read_text(encoding="utf-8"))
    tx, ty = TARGET

    def scaled(p: dict[str, Any]) -> dict[str, Any]:
        east, north = tx + (p["east_m"] - tx) * scale, ty + (p["north_m"] - ty) * scale
        return {**p, "east_m": round(east), "north_m": round(north)}

    area = doc["area"]
    area["min_east_m"] = round(tx - (tx - area["min_east_m"]) * scale)
    area["min_north_m"] = round(ty - (ty - area["min_north_m"]) * scale)
    for key in ("width_m", "height_m", "resolution_m"):
        area[key] = round(area[key] * scale)
    doc["terrain"]["peak_m"] = round(doc["terrain"]["peak_m"] * scale)
    for v in doc["vehicles"]:
        v["start"] = scaled(v["start"])
        v["takeoff_window_s"] = [round(t * scale) for t in v["takeoff_window_s"]]
    for z in doc["threats"]:
        if "center" in z:
            z["center"] = scaled(z["center"])
            z["radius_m"] = round(z["radius_m"] * scale)
        if "polygon" in z:
            z["polygon"] = [scaled(p) for p in z["polygon"]]
        if "appears" in z:
            z["appears"]["delay_s"] = round(z["appears"]["delay_s"] * scale)
    for b in doc["buffers"]:
        b["center"] = scaled(b["center"])
        b["radius_m"] = max(1_200, round(b["radius_m"] * scale))
    doc["name"] = f"paper_three_uav at {scale:g} scale"
    return doc


def box_across(
    doc: dict[str, Any],
    vid: str,
    along: float,
    across_m: float,
    depth_m: float,
    appears: float,
    clear_m: float,
) -> tuple[dict[str, Any], Schedule]:
    """An operator's no-fly box (``OP1``) across the route the scenario's schedule plans for
    ``vid``, at ``along`` of its length, ``across_m`` wide and ``depth_m`` along it, appearing
    ``appears`` of the way through its flight (from its takeoff to its slot, as planned);
    and the schedule. Asserted (the test's own check of its scenario): every other vehicle's
    planned route stays ``clear_m`` from it, so that only ``vid`` meets it."""
    scenario = parse_scenario(doc)
    world = build_world(scenario)
    schedule = build_schedule(scenario, plan(scenario, world=world), world=world)
    held = schedule.vehicle(vid)
    appears_s = held.takeoff_s + appears * (held.arrival_s - held.takeoff_s)
    path = held.path
    pose = path.pose_at(along * path.length_m)
    ue, un = math.sin(pose.heading_rad), math.cos(pose.heading_rad)
    corners = [
        (
            pose.east_m + a * depth_m / 2.0 * ue + c * across_m / 2.0 * un,
            pose.north_m + a * depth_m / 2.0 * un - c * across_m / 2.0 * ue,
        )
        for a, c in ((-1, -1), (1, -1), (1, 1), (-1, 1))
    ]
    centre = np.array([pose.east_m, pose.north_m])
    reach_m = math.hypot(across_m, depth_m) / 2.0
    for vs in schedule.vehicles:
        if vs.vehicle_id == vid:
            continue
        s = np.linspace(0.0, vs.path.length_m, 400)
        en = np.array([[p.east_m, p.north_m] for p in map(vs.path.pose_at, s)])
        gap_m = float(np.min(np.hypot(*(en - centre).T))) - reach_m
        assert gap_m > clear_m, (vs.vehicle_id, gap_m)
    box = {
        "kind": "no_fly",
        "id": "OP1",
        "polygon": [{"east_m": round(e, 1), "north_m": round(n, 1)} for e, n in corners],
        "appears": {"at_s": round(appears_s, 1)},
    }
    return box, schedule


def headwind_loss_s(vehicle: dict[str, Any], wind_m_s: float) -> float:
    """What a wind the scenario does not forecast can cost a vehicle planned at its top speed
    in still air: ``L (1 / (v - w) - 1 / v)``, its whole route ``L`` (under 1.2 times the
    straight line to its goal) flown at its top airspeed ``v`` (equivalent; the true airspeed
    aloft is higher, and the delay less) straight into the wind ``w`` (s)."""
    straight_m = math.hypot(
        vehicle["goal"]["east_m"] - vehicle["start"]["east_m"],
        vehicle["goal"]["north_m"] - vehicle["start"]["north_m"],
    )
    top_m_s = float(vehicle["speed_max_m_s"])
    return 1.2 * straight_m * (1.0 / (top_m_s - wind_m_s) - 1.0 / top_m_s)

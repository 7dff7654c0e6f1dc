"""Thirty aircraft and a forbidden zone that pops up across some of their routes, with every
re-plan made 2 s of wall time late at 100x (200 s of mission, waited in mission time in lock
step: the aircraft reach the zone's edge about 55 s after it appears): no aircraft is ever
inside the zone (the simulator's truth log, checked here against the zone's own geometry),
those that reach it first hold short of it with an alarm, and the flight completes. The team
is generated (:func:`tests.teams.ring_team`: thirty routes converging on a target), not a
hand-tuned file."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from gcs.coordination.config import FlightConfig
from tests.flightstory import story
from tests.rehearsing import rehearse_data
from tests.teams import ring_team

pytestmark = pytest.mark.slow  # about 40 s of wall time

# Across the northernmost route and its two neighbours, 11 km out, when they are 15 km out.
POP = {"east_m": 30_000.0, "north_m": 41_000.0, "radius_m": 2_500.0, "at_s": 150.0}


async def test_thirty_aircraft_keep_out_of_a_pop_up_zone_whatever_the_re_plan_latency(
    tmp_path: Path,
) -> None:
    data = ring_team(30)
    data["threats"].append(
        {
            "kind": "radar", "id": "POP30", "forbidden": True,
            "center": {"east_m": POP["east_m"], "north_m": POP["north_m"]},
            "radius_m": POP["radius_m"], "appears": {"at_s": POP["at_s"]},
        }
    )  # fmt: skip
    record, scenario, truth = await rehearse_data(
        data, tmp_path, config=FlightConfig(seed=0, replan_delay_wall_s=2.0)
    )
    events = story(record["events"])
    assert record["state"] == "completed", f"{record['state_reason']}\n{events}"
    assert all(v["state"] == "arrived" for v in record["vehicles"]), events
    # The truth log against the disc, from the time it appeared.
    frame = scenario.frame()
    appeared = next(t["utc_s"] for t in record["threats_appeared"] if t["id"] == "POP30")
    closest = math.inf
    n = 0
    for line in truth.read_text().splitlines()[1:]:
        r = json.loads(line)
        if r["utc_s"] < appeared:
            continue
        e, nn = frame.to_local(r["lat_deg"], r["lon_deg"])
        d = math.hypot(float(e) - POP["east_m"], float(nn) - POP["north_m"]) - POP["radius_m"]
        closest = min(closest, d)
        n += 1
    assert n > 1000
    assert closest > 0.0, f"{closest:.0f} m\n{events}"
    assert record["zone_entries"] == []
    # The routes it touched were re-planned around it or held short of it, and said so.
    touched = [e for e in record["events"] if e["kind"] == "replan" and "POP30" in e["reason"]]
    held = [a for a in record["alarms"] if "enters POP30" in a["reason"]]
    assert touched or held, events
    assert record["min_separation_m"] >= record["separation_m"], events

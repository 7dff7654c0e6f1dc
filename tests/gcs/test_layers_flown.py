"""Two aircraft asked to arrive at the earliest time they can, on routes that cross in the
middle: timing cannot part them (both take off at once at their top speed), so one is lifted
onto the altitude layer the scenario allows over the crossing (planner.layers). Flown on the
bundled simulator at 100x, the crossing is kept apart by height, and both arrive on time.

Judged from the simulator's truth log: every common sample of the two aircraft in 3-D, the
height between them where they come closest horizontally, and each goal passage against the
team time the schedule chose."""

from __future__ import annotations

import asyncio
import math
from typing import Any

import numpy as np
import pytest

from gcs.rehearsal.truth import closest_approach, read_truth
from planner.plan import plan
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from tests.flightstory import story
from tests.planner.conftest import crossing_scenario
from tests.rehearsing import rehearse_data

# One flight for the module (about 20 s of wall time), flown on one worker under pytest -n.
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("layers_flown")]

LAYER_M = 400.0
GOAL_PASS_M = 150.0


def _scenario() -> dict[str, Any]:
    data = crossing_scenario(arrival={"kind": "simultaneous"})
    for v in data["vehicles"]:
        v["takeoff_window_s"] = [0, 600]
    free = parse_scenario(data)
    window = build_schedule(free, plan(free, "astar")).team_window
    assert window is not None
    data["arrival"] = {"kind": "simultaneous", "required_s": math.ceil(window.earliest_s)}
    data["altitude_layers_m"] = [LAYER_M]
    return data


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], Any, Any]:
    directory = tmp_path_factory.mktemp("layers_flown")
    record, scenario, truth = asyncio.run(rehearse_data(_scenario(), directory))
    return record, scenario, read_truth(truth)


def test_the_crossing_is_flown_on_two_layers_with_the_separation_kept(
    flown: tuple[dict[str, Any], Any, Any],
) -> None:
    record, scenario, truth = flown
    told = story(record["events"])
    assert record["state"] == "completed", told
    frame = scenario.frame()
    tracks = {}
    for v in record["vehicles"]:
        samples = [s for s in truth[v["system_id"]] if s.armed and not s.on_ground]
        east, north = frame.to_local(
            np.array([s.lat_deg for s in samples]), np.array([s.lon_deg for s in samples])
        )
        tracks[v["id"]] = {
            round(s.utc_s, 3): (float(e), float(n), s.alt_m)
            for s, e, n in zip(samples, np.atleast_1d(east), np.atleast_1d(north), strict=True)
        }
    a, b = tracks["A"], tracks["B"]
    common = sorted(set(a) & set(b))
    assert len(common) > 1000
    pa = np.array([a[t] for t in common])
    pb = np.array([b[t] for t in common])
    distance = np.sqrt(((pa - pb) ** 2).sum(axis=1))
    horizontal = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
    d_s = scenario.separation_m
    assert distance.min() >= d_s, (float(distance.min()), told)
    # They did cross: the height kept them apart where the tracks met.
    k = int(horizontal.argmin())
    assert horizontal[k] < d_s
    assert abs(pa[k, 2] - pb[k, 2]) >= math.sqrt(d_s**2 - horizontal[k] ** 2), told
    # The operator is told at the takeoff why that one climbs.
    said = [e["reason"] for e in record["events"] if e["kind"] == "plan"]
    lifted = [r for r in said if "above its profile" in r]
    assert len(lifted) == 1 and f"{LAYER_M:g} m above its profile from" in lifted[0], told


def test_both_arrive_on_time_by_the_simulator_s_truth(
    flown: tuple[dict[str, Any], Any, Any],
) -> None:
    record, scenario, truth = flown
    frame = scenario.frame()
    target = record["start_utc_s"] + record["required_arrival_s"]
    for v in record["vehicles"]:
        glat, glon = frame.to_geodetic(*scenario.vehicle(v["id"]).goal.local(frame))
        passage = closest_approach(truth[v["system_id"]], float(glat), float(glon), GOAL_PASS_M)
        assert passage is not None, v["id"]
        assert abs(passage[0] - target) <= 1.0, (v["id"], passage[0] - target)

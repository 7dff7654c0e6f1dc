"""Two aircraft asked to arrive at the earliest time they can, on routes that cross in the
middle: timing cannot part them (both take off at once at their top speed), so one is lifted
onto the altitude layer the scenario allows over the crossing (planner.layers). Flown on the
bundled simulator at 100x, the crossing is kept apart by height, and both arrive on time.

Judged by :mod:`tests.oracle` (:func:`tests.verdict.judge`) from the simulator's truth log
and the scenario, not from the coordinator's figures: every common sample of the two aircraft
in 3-D, the whole flight long, the height between them where they come closest horizontally,
and each goal passage against the slot set before launch (the team time requested: nothing
should move it much, a bound stated here)."""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from planner.plan import plan
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from tests.flightstory import story
from tests.planner.conftest import crossing_scenario
from tests.rehearsing import rehearse_data
from tests.verdict import Verdict, judge

# One flight for the module (about 20 s of wall time), flown on one worker under pytest -n.
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("layers_flown")]

LAYER_M = 400.0
TOLERANCE_S = 1.0
TEAM_SHIFT_MAX_S = 30.0
"""How far the team time may move, and only later: it is the earliest the two can make,
rounded up to the second (both at their top speed from a takeoff together), so the climb-outs
may cost them some seconds and move it; nothing else should."""
TOGETHER_MIN_S = 1_000.0
"""The two fly their 36 km together: over 20 minutes."""


@dataclass(frozen=True)
class Flown:
    record: dict[str, Any]
    verdict: Verdict


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
def flown(tmp_path_factory: pytest.TempPathFactory) -> Flown:
    directory = tmp_path_factory.mktemp("layers_flown")
    data = _scenario()
    record, _, truth = asyncio.run(rehearse_data(data, directory))
    verdict = judge(
        record,
        truth,
        scenario=data,
        tolerance_s=TOLERANCE_S,
        team_shift_max_s=TEAM_SHIFT_MAX_S,
        together_min_s=TOGETHER_MIN_S,
    )
    return Flown(record, verdict)


def test_the_crossing_is_flown_on_two_layers_with_the_separation_kept(flown: Flown) -> None:
    record, verdict = flown.record, flown.verdict
    told = story(record["events"])
    assert record["state"] == "completed", told
    d_s = verdict.separation_m
    # Every common airborne sample in 3-D, the whole flight long.
    assert verdict.separation.compared > 2_000 and verdict.together_s >= TOGETHER_MIN_S
    assert verdict.separation.least_m >= d_s, f"{verdict.separation}\n{told}"
    # They did cross: the height kept them apart where the tracks met.
    a, b = verdict.tracks["A"], verdict.tracks["B"]
    at_a, at_b = np.round(a.utc_s, 3), np.round(b.utc_s, 3)
    _, ka, kb = np.intersect1d(at_a, at_b, return_indices=True)
    both = a.airborne[ka] & b.airborne[kb]
    ka, kb = ka[both], kb[both]
    (ea, na), (eb, nb) = verdict.ground.local(a), verdict.ground.local(b)
    horizontal = np.hypot(ea[ka] - eb[kb], na[ka] - nb[kb])
    k = int(horizontal.argmin())
    height = abs(float(a.alt_m[ka[k]] - b.alt_m[kb[k]]))
    print(f"closest horizontally {horizontal[k]:.0f} m, {height:.0f} m apart in height")
    assert horizontal[k] < d_s
    assert height >= math.sqrt(d_s**2 - horizontal[k] ** 2), told
    # The operator is told at the takeoff why that one climbs.
    said = [e["reason"] for e in record["events"] if e["kind"] == "plan"]
    lifted = [r for r in said if "above its profile" in r]
    assert len(lifted) == 1 and f"{LAYER_M:g} m above its profile from" in lifted[0], told


def test_both_arrive_on_time_by_the_simulator_s_truth(flown: Flown) -> None:
    """Each goal passage against the team time set before launch, moved by no more than
    :data:`TEAM_SHIFT_MAX_S`, and no zone entered (the scenario has none forbidden: checked
    all the same)."""
    verdict = flown.verdict
    verdict.check()
    assert verdict.shift_s >= 0.0, verdict

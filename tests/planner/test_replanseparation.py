"""A re-plan is deconflicted in 4-D before it is installed (:mod:`planner.replanseparation`).

Thirty vehicles converge on a target from a ring (:func:`tests.teams.ring_team`, 300 m
apart at their goals' arc); a forbidden disc appears across the northernmost routes 11 km out,
and R00, R01 and R29 are routed round it. R29's route round the disc's west side runs along
R28's, and re-timed for the same arrival the pair would come within about 230 m (d_s 300 m).

Each verdict is the test's own: every schedule is sampled here, second by second from the
re-plan's start, at its position along its path (:meth:`VehicleSchedule.state_at`) and the
altitude its profile has there, and every pair's least 3-D distance taken from those samples,
not from :mod:`planner.deconflict`.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest

from planner.plan import build_world, plan
from planner.popup import PopupOutcome, apply_popup, popup_zones
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from planner.schedule import Schedule, VehicleSchedule
from planner.threats import active, build_threats
from tests.teams import ring_team

AT_S = 150.0
STEP_S = 0.25
"""Sampling of the test's own closest approaches: two vehicles close at 60 m/s at most, 15 m
between samples."""


def _flown(data: dict[str, Any]) -> tuple[Schedule, PopupOutcome]:
    data["threats"].append(
        {
            "kind": "radar", "id": "POP", "forbidden": True,
            "center": {"east_m": 30_000.0, "north_m": 41_000.0}, "radius_m": 2_500.0,
            "appears": {"at_s": AT_S},
        }
    )  # fmt: skip
    scenario = parse_scenario(data)
    world = build_world(scenario)
    schedule = build_schedule(scenario, plan(scenario, rng=np.random.default_rng(0), world=world))
    (zone,) = popup_zones(build_threats(scenario))
    outcome = apply_popup(
        schedule, zone, at_s=AT_S, world=world, threats=active(world.threats, AT_S),
        rng=np.random.default_rng(0),
    )  # fmt: skip
    return schedule, outcome


def _track(vs: VehicleSchedule, t_s: np.ndarray) -> np.ndarray:
    """East, north and altitude (m) at each time of ``t_s``; NaN where it does not fly."""
    out = np.full((len(t_s), 3), np.nan)
    for k, t in enumerate(t_s):
        if not vs.takeoff_s <= t <= vs.arrival_s:
            continue
        p = vs.position_at(float(t))
        if p is None:
            continue
        s_m = vs.state_at(float(t))[1]
        out[k] = (p[0], p[1], float(np.interp(s_m, vs.wp_s_m, vs.wp_alt_m)))
    return out


def _closest_pairs(schedule: Schedule, from_s: float) -> dict[tuple[str, str], tuple[float, float]]:
    """Every pair's least 3-D distance (m) from ``from_s`` on, and when (s)."""
    end_s = max(vs.arrival_s for vs in schedule.vehicles)
    t_s = np.arange(from_s, end_s + STEP_S, STEP_S)
    tracks = {vs.vehicle_id: _track(vs, t_s) for vs in schedule.vehicles}
    out = {}
    for a, b in itertools.combinations(sorted(tracks), 2):
        d = np.linalg.norm(tracks[a] - tracks[b], axis=1)
        if np.isnan(d).all():
            continue
        k = int(np.nanargmin(d))
        out[(a, b)] = (float(d[k]), float(t_s[k]))
    return out


@pytest.fixture(scope="module")
def without_layers() -> tuple[Schedule, PopupOutcome]:
    return _flown(ring_team(30))


@pytest.fixture(scope="module")
def with_layers() -> tuple[Schedule, PopupOutcome]:
    data = ring_team(30)
    data["altitude_layers_m"] = [150.0, 300.0]
    return _flown(data)


def test_a_re_plan_no_layer_can_separate_is_alarmed_with_the_pair_the_time_and_the_distance(
    without_layers: tuple[Schedule, PopupOutcome],
) -> None:
    _, outcome = without_layers
    required = outcome.schedule.scenario.separation_m
    under = {
        pair: seen
        for pair, seen in _closest_pairs(outcome.schedule, AT_S).items()
        if seen[0] < required - 2.0 * STEP_S * 60.0
    }
    assert under, "the re-plan puts no pair under d_s: nothing to show"
    alarms = [e for e in outcome.events if e.kind == "alarm"]
    conflicts = [e for e in outcome.events if e.kind == "conflict" and "pair" in e.payload]
    said = {tuple(sorted(e.payload["pair"])): e for e in alarms}
    # Every pair the test finds under d_s is alarmed, with its distance and time as found here.
    for pair, (distance_m, at_s) in under.items():
        assert pair in said, (pair, distance_m, [e.text for e in alarms])
        e = said[pair]
        assert e.payload["distance_m"] == pytest.approx(distance_m, abs=5.0)
        assert e.payload["at_s"] == pytest.approx(at_s, abs=2.0)
        assert f"{e.payload['distance_m']:.0f} m" in e.text and "no altitude layers" in e.text
        assert e.time_s == AT_S  # said at the re-plan, before anything is installed
    assert {tuple(sorted(e.payload["pair"])) for e in conflicts} == set(said)
    # And nothing is alarmed that the test does not find close.
    found = _closest_pairs(outcome.schedule, AT_S)
    for pair in said:
        assert found[pair][0] < required, (pair, found[pair])


def test_a_re_plan_is_separated_on_an_altitude_layer_past_the_splice_and_keeps_its_slots(
    with_layers: tuple[Schedule, PopupOutcome],
    without_layers: tuple[Schedule, PopupOutcome],
) -> None:
    _, outcome = with_layers
    _, flat = without_layers
    scenario = outcome.schedule.scenario
    required = scenario.separation_m
    assert not [e for e in outcome.events if e.kind == "alarm"], [e.text for e in outcome.events]
    closest = _closest_pairs(outcome.schedule, AT_S)
    worst = min(closest.items(), key=lambda kv: kv[1][0])
    assert worst[1][0] >= required - 15.0, worst  # to the test's own sampling (15 m)
    lifts = [e for e in outcome.events if e.payload.get("resolution") == "altitude"]
    assert lifts, [e.text for e in outcome.events]
    for e in lifts:
        vid = e.payload["pair"][0]
        v = scenario.vehicle(vid)
        up = outcome.schedule.vehicle(vid)
        level = flat.schedule.vehicle(vid)  # the same routes, no layer (same seed)
        assert up.path.length_m == pytest.approx(level.path.length_m)
        s = np.linspace(0.0, up.path.length_m, 4001)
        z_up = np.interp(s, up.wp_s_m, up.wp_alt_m)
        z_level = np.interp(s, level.wp_s_m, level.wp_alt_m)
        # Never lower than its profile (terrain clearance only gains), never above its
        # ceiling, at most the layers' highest above it, and as it was up to where it is at
        # the re-plan's start (what it flies before its new mission is not changed).
        assert (z_up >= z_level - 1e-6).all()
        assert (z_up <= v.alt_max_m + 1e-6).all()
        assert float((z_up - z_level).max()) <= max(scenario.altitude_layers_m) + 1e-6
        assert float((z_up - z_level).max()) > 100.0
        s_start = up.state_at(AT_S)[1]
        assert np.allclose(z_up[s <= s_start], z_level[s <= s_start])
        # Still on its slot: the team's arrival time.
        assert up.arrival_s == pytest.approx(level.arrival_s, abs=0.5)
        assert outcome.schedule.required_arrival_s is not None
        assert up.arrival_s == pytest.approx(outcome.schedule.required_arrival_s, abs=0.5)
    # The others as they were.
    lifted = {e.payload["pair"][0] for e in lifts}
    for vs in outcome.schedule.vehicles:
        if vs.vehicle_id not in lifted:
            other = flat.schedule.vehicle(vs.vehicle_id)
            assert np.array_equal(vs.wp_alt_m, other.wp_alt_m)
            assert math.isclose(vs.arrival_s, other.arrival_s, abs_tol=1e-6)

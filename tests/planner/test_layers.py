"""Altitude layers (planner.layers): a vehicle lifted above its planned profile over the
stretch where it meets another, and the team's separation measured in 3-D.

The verdicts are the test's own arithmetic: the profiles sampled every few metres, the
pair's positions from :meth:`VehicleSchedule.position_at` and the altitude flown there."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from planner.errors import ScenarioError, SeparationError
from planner.layers import LANE_STRETCHES_M, lanes, layer_profile, lift
from planner.plan import plan
from planner.retime import build_schedule, check_feasible
from planner.scenario import Scenario, parse_scenario
from planner.schedule import Schedule, VehicleSchedule
from planner.schedulefile import vehicle_mission
from planner.terrain import build_terrain
from tests.planner.conftest import crossing_scenario, small_scenario


def _crossing(layers: list[float] | None = None, **arrival: Any) -> dict[str, Any]:
    """A east, B north, crossing the middle; both may take off in [0, 600] s."""
    data = crossing_scenario(arrival={"kind": "simultaneous", **arrival})
    for v in data["vehicles"]:
        v["takeoff_window_s"] = [0, 600]
    if layers is not None:
        data["altitude_layers_m"] = layers
    return data


def _at_requested_time(layers: list[float] | None) -> tuple[Scenario, Schedule]:
    """The crossing pair asked to arrive at the earliest time: both take off at once at top
    speed and meet in the middle; timing cannot part them."""
    free = parse_scenario(_crossing())
    first = build_schedule(free, plan(free, "astar"))
    assert first.team_window is not None
    asked = parse_scenario(_crossing(layers, required_s=math.ceil(first.team_window.earliest_s)))
    return asked, build_schedule(asked, plan(asked, "astar"))


NAV_WAYPOINT = 16
RELATIVE_FRAMES = (3, 6)  # MAV_FRAME_GLOBAL_RELATIVE_ALT(_INT): metres above home


def _track(vs: VehicleSchedule, t: np.ndarray) -> np.ndarray:
    """(east, north, altitude) at each time, NaN where it does not fly."""
    out = np.full((len(t), 3), np.nan)
    for k, tk in enumerate(t):
        p = vs.position_at(float(tk))
        if p is None:
            continue
        s_m = vs.state_at(float(tk))[1]
        out[k] = (p[0], p[1], vs.alt_at(s_m))
    return out


def _closest_3d(a: VehicleSchedule, b: VehicleSchedule) -> tuple[float, float, float]:
    """Least 3-D distance every 0.25 s while both fly, with the horizontal distance and
    the height between them then."""
    t = np.arange(max(a.takeoff_s, b.takeoff_s), min(a.arrival_s, b.arrival_s), 0.25)
    pa, pb = _track(a, t), _track(b, t)
    d = np.sqrt(((pa - pb) ** 2).sum(axis=1))
    k = int(np.nanargmin(d))
    return float(d[k]), float(np.hypot(*(pa[k, :2] - pb[k, :2]))), float(pa[k, 2] - pb[k, 2])


def test_a_pair_timing_cannot_part_flies_the_crossing_on_two_layers() -> None:
    scenario, s = _at_requested_time([400.0])
    check_feasible(s)
    a, b = s.vehicles
    d, horizontal, height = _closest_3d(a, b)
    assert d >= scenario.separation_m
    assert horizontal < scenario.separation_m  # they do cross: the height parts them
    assert abs(height) >= math.sqrt(scenario.separation_m**2 - horizontal**2) - 1.0
    said = [e.text for e in s.events if e.kind == "separation"]
    assert len(said) == 1 and "400 m above its profile from" in said[0], said
    # Both still arrive at the time asked, each within its speed range.
    assert a.arrival_s == pytest.approx(b.arrival_s, abs=1e-6) == s.required_arrival_s
    for vs in s.vehicles:
        assert all(vs.speed_min_m_s - 1e-9 <= leg.speed_m_s <= vs.speed_max_m_s for leg in vs.legs)


def test_without_layers_the_same_pair_is_refused_naming_it() -> None:
    _, s = _at_requested_time(None)
    with pytest.raises(SeparationError) as info:
        check_feasible(s)
    assert set(info.value.pair) == {"A", "B"}


def test_the_lifted_vehicle_s_mission_flies_the_layer_and_comes_back_down() -> None:
    scenario, s = _at_requested_time([400.0])
    lifted = [vs for vs in s.vehicles if float(np.ptp(vs.wp_alt_m)) > 300.0]
    assert len(lifted) == 1
    home_m = 100.0  # the flat terrain's elevation, where it takes off
    items = vehicle_mission(s, lifted[0], build_terrain(scenario))
    alts = [
        it.z + (home_m if it.frame in RELATIVE_FRAMES else 0.0)
        for it in items
        if it.command == NAV_WAYPOINT
    ]
    assert max(alts) == pytest.approx(500.0 + 400.0, abs=1.0)
    assert alts[-1] == pytest.approx(500.0, abs=1.0)  # at the goal's own altitude again


# -- the profile ---------------------------------------------------------------------------


def _profile_case() -> tuple[Scenario, VehicleSchedule]:
    scenario = parse_scenario(small_scenario(threats=[]))
    s = build_schedule(scenario, plan(scenario, "astar"))
    return scenario, s.vehicles[0]


@pytest.mark.parametrize("span", [None, (8_000.0, 30_000.0)])
@pytest.mark.parametrize("alt_max_m", [3000.0, 800.0])
def test_a_layer_keeps_above_the_profile_under_the_ceiling_within_the_gradient(
    span: tuple[float, float] | None, alt_max_m: float
) -> None:
    scenario, vs = _profile_case()
    v = scenario.vehicles[0].model_copy(update={"alt_max_m": alt_max_m})
    got = layer_profile(vs, v, 600.0, span)
    assert got is not None
    s = np.linspace(0.0, vs.path.length_m, 20_001)
    base = np.interp(s, vs.wp_s_m, vs.wp_alt_m)
    layer = np.interp(s, *got)
    assert (layer >= base - 1e-6).all()
    assert (layer <= max(alt_max_m, float(base.max())) + 1e-6).all()
    slope = np.abs(np.diff(layer)) / np.diff(s)
    assert slope.max() <= v.climb_gradient + 1e-6
    assert layer[-1] == pytest.approx(base[-1])  # down to the goal's altitude
    assert vs.climb is not None
    hold = max(vs.climb.s_m, vs.climb.first_waypoint_m)
    assert np.allclose(layer[s <= hold], base[s <= hold])  # the climb-out as planned
    top = min(base.max() + 600.0, alt_max_m)
    assert layer.max() == pytest.approx(top, abs=1.0)
    if span is not None:
        outside = (s <= span[0]) | (s >= span[1])
        assert np.allclose(layer[outside], base[outside])


def test_lifts_add_up_and_a_lift_that_lifts_nothing_is_none() -> None:
    scenario, vs = _profile_case()
    v = scenario.vehicles[0]
    one = lift(vs, vs, v, 600.0, (8_000.0, 15_000.0))
    assert one is not None
    two = lift(one, vs, v, 600.0, (30_000.0, 40_000.0))
    assert two is not None
    s = np.linspace(0.0, vs.path.length_m, 5_001)
    first = np.interp(s, one.wp_s_m, one.wp_alt_m)
    second = np.interp(s, *layer_profile(vs, v, 600.0, (30_000.0, 40_000.0)))  # type: ignore[misc]
    both = np.interp(s, two.wp_s_m, two.wp_alt_m)
    assert np.allclose(both, np.maximum(first, second), atol=1e-6)
    assert lift(two, vs, v, 300.0, (8_000.0, 15_000.0)) is None  # under what it flies there
    at_ceiling = v.model_copy(update={"alt_max_m": float(vs.wp_alt_m.max())})
    assert layer_profile(vs, at_ceiling, 600.0) is None


def test_lanes_are_the_layers_over_the_end_of_the_path_each_stretch_once() -> None:
    """Each layer over the last 20, 40 and 80 km and over all the path: the profile as planned
    up to where the lane begins, above it after, back at the goal's altitude; a stretch as
    long as the path is offered once."""
    scenario, vs = _profile_case()
    v = scenario.vehicles[0].model_copy(update={"alt_max_m": 3000.0})
    length = vs.path.length_m
    got = list(lanes(vs, v, [300.0, 600.0]))
    expected = [(h, max(0.0, length - k)) for h in (300.0, 600.0) for k in LANE_STRETCHES_M]
    expected = list(dict.fromkeys(expected))  # a path under 80 km: the whole path once
    assert [(lane.height_m, lane.from_m) for _, lane in got] == expected
    s = np.linspace(0.0, length, 20_001)
    base = np.interp(s, vs.wp_s_m, vs.wp_alt_m)
    for up, lane in got:
        alt = np.interp(s, up.wp_s_m, up.wp_alt_m)
        assert lane.to_m == pytest.approx(length)
        assert np.allclose(alt[s <= lane.from_m], base[s <= lane.from_m]), lane
        assert (alt >= base - 1e-6).all() and alt[-1] == pytest.approx(base[-1])
        assert (alt - base).max() == pytest.approx(lane.height_m, abs=1.0), lane
        assert (up.path is vs.path) and up.takeoff_s == vs.takeoff_s  # to be timed again


# -- the scenario field --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("layers", "message"),
    [
        ([600.0, 300.0], "must rise"),
        ([300.0, 300.0], "must rise"),
        ([0.0], "altitude_layers_m"),
        ([-100.0], "altitude_layers_m"),
    ],
)
def test_layers_must_be_positive_and_rise(layers: list[float], message: str) -> None:
    with pytest.raises(ScenarioError, match=message):
        parse_scenario(small_scenario(altitude_layers_m=layers))


def test_layers_are_refused_with_landing_slots() -> None:
    data = small_scenario(threats=[], altitude_layers_m=[500])
    data["landing"] = {
        "touchdown": {"east_m": 39000, "north_m": 39000, "alt_m": 100},
        "heading_deg": 45,
    }
    with pytest.raises(ScenarioError, match="altitude_layers_m: not with landing slots"):
        parse_scenario(data)

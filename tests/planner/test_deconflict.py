"""Deconfliction: closest approach of scheduled vehicles, loiters included."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from planner.deconflict import (
    _distance_m,
    _positions,
    _positions_masked,
    pair_separation,
    separation,
)
from planner.flightpath import straight
from planner.plan import build_world, plan
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from planner.schedule import Leg, LoiterPlan, VehicleSchedule
from tests.planner.conftest import small_scenario


def _vs(
    vid: str, e0: float, n0: float, e1: float, n1: float, v: float, t0: float
) -> VehicleSchedule:
    path = straight(e0, n0, e1, n1)
    length = path.length_m
    return VehicleSchedule(
        vid,
        path,
        np.array([0.0, length]),
        np.array([500.0, 500.0]),
        t0,
        t0 + length / v,
        (Leg(0.0, length, v, t0, t0 + length / v),),
        (),
        v - 5,
        v + 5,
        False,
    )


def test_crossing_paths_known_answer() -> None:
    # A flies east along n = 0, B flies north along e = 10 km; both reach (10 km, 0) at 500 s
    # unless B leaves 20 s later: then B is 400 m short of the crossing when A passes it.
    a = _vs("A", 0, 0, 20_000, 0, 20.0, 0.0)
    b = _vs("B", 10_000, -10_000, 10_000, 10_000, 20.0, 20.0)
    sep = separation([a, b], 500.0)
    pair = sep.pairs[0]
    # Closest approach of two perpendicular tracks with a 400 m lag: 400 / sqrt(2).
    assert pair.distance_m == pytest.approx(400 / math.sqrt(2), abs=1.0)
    assert pair.time_s == pytest.approx(510.0, abs=0.5)
    assert sep.conflicts == (pair,)


def test_not_airborne_together_is_no_conflict() -> None:
    a = _vs("A", 0, 0, 20_000, 0, 20.0, 0.0)
    b = _vs("B", 0, 0, 20_000, 0, 20.0, 2000.0)
    assert separation([a, b], 500.0).min_separation_m == math.inf


def _loitering() -> tuple[VehicleSchedule, LoiterPlan]:
    """A, 20 km east at 20 m/s, with two turns of 300 m half way."""
    a = _vs("A", 0, 0, 20_000, 0, 20.0, 0.0)
    r = 300.0
    lo = LoiterPlan(
        10_000,
        10_000,
        -r,
        10_000,
        0.0,
        r,
        2,
        True,
        0.0,
        20.0,
        500.0,
        500.0 + 2 * math.pi * r * 2 / 20,
        "H",
    )
    dur = lo.t_end_s - lo.t_start_s
    legs = (
        Leg(0.0, 10_000.0, 20.0, 0.0, 500.0),
        Leg(10_000.0, 20_000.0, 20.0, lo.t_end_s, lo.t_end_s + 500.0),
    )
    vs = VehicleSchedule(
        "A", a.path, a.wp_s_m, a.wp_alt_m, 0.0, 1000.0 + dur, legs, (lo,), 15, 25, False
    )
    return vs, lo


def test_loiter_positions_stay_on_the_circle() -> None:
    vs, lo = _loitering()
    r = lo.radius_m
    for t in np.linspace(lo.t_start_s, lo.t_end_s - 1e-6, 50):
        p = vs.position_at(float(t))
        assert p is not None
        assert math.hypot(p[0] - 10_000, p[1] + r) == pytest.approx(r)
    p = vs.position_at(lo.t_end_s + 100.0)
    assert p is not None and p == pytest.approx((12_000.0, 0.0))


def test_the_team_separation_matches_every_pair_searched_on_its_own() -> None:
    """The one-grid comparison of every pair (each schedule sampled once) against the exact
    search of each pair on its own: the same conflicts and the same closest pair and distance;
    every other pair within a twentieth of d_s of its own search."""
    rng = np.random.default_rng(4)
    team = []
    for k in range(12):
        bearing = rng.uniform(0.0, 2 * math.pi)
        e0, n0 = 15_000 * math.sin(bearing), 15_000 * math.cos(bearing)
        e1, n1 = rng.uniform(-3_000, 3_000, size=2)
        team.append(_vs(f"V{k}", e0, n0, e1, n1, rng.uniform(18, 30), rng.uniform(0, 300)))
    required = 500.0
    sep = separation(team, required)
    exact = {}
    for i in range(len(team)):
        for j in range(i + 1, len(team)):
            a, b = team[i], team[j]
            step = max(required / (10.0 * (a.speed_max_m_s + b.speed_max_m_s)), 0.05)
            exact[(a.vehicle_id, b.vehicle_id)] = pair_separation(a, b, step_s=step)
    assert [(p.a, p.b) for p in sep.pairs] == list(exact)
    assert {(p.a, p.b) for p in sep.conflicts} == {
        k for k, p in exact.items() if p.distance_m < required
    }
    assert sep.conflicts  # the draw has conflicts: the comparison means something
    best = min(exact.values(), key=lambda p: p.distance_m)
    assert (sep.minimum.a, sep.minimum.b, sep.min_separation_m) == (best.a, best.b, best.distance_m)  # type: ignore[union-attr]
    for p in sep.pairs:
        want = exact[(p.a, p.b)].distance_m
        if math.isinf(want):
            assert math.isinf(p.distance_m)
        else:
            assert want - 1e-6 <= p.distance_m <= want + required / 20.0, (p, want)


def test_positions_by_slices_are_the_masked_ones_to_the_last_bit() -> None:
    """On ascending times ``_positions`` finds each window by bisection: the same bits as
    comparing every sample, the windows' own ends among the times, repeated times too."""
    scenario = parse_scenario(small_scenario(arrival={"kind": "simultaneous", "required_s": 2600}))
    s = build_schedule(scenario, plan(scenario, "astar"), world=build_world(scenario))
    a = _vs("A", 0, 0, 20_000, 0, 20.0, 0.0)
    gappy = replace(  # airborne, two legs apart, and at the path's end before its arrival
        a,
        arrival_s=1200.0,
        legs=(Leg(0.0, 10_000.0, 20.0, 0.0, 500.0), Leg(10_000.0, 20_000.0, 20.0, 600.0, 1100.0)),
        airborne_start=True,
    )
    joined = replace(  # the second leg starts at the first's end: that time is the first's
        a,
        arrival_s=1000.0,
        legs=(Leg(0.0, 10_000.0, 20.0, 0.0, 500.0), Leg(10_000.0, 20_000.0, 20.0, 500.0, 1000.0)),
    )
    rng = np.random.default_rng(0)
    for vs in [*s.vehicles, a, gappy, joined]:
        ends = [vs.takeoff_s, vs.arrival_s, vs.climb_end_s]
        ends += [x for leg in vs.legs for x in (leg.t_start_s, leg.t_end_s)]
        grids = [
            np.linspace(vs.takeoff_s - 50.0, vs.arrival_s + 50.0, 3001),
            np.sort(np.concatenate([rng.uniform(vs.takeoff_s, vs.arrival_s, 500), ends, ends])),
            np.linspace(vs.takeoff_s + 10.0, vs.takeoff_s + 11.0, 101),
            np.linspace(vs.arrival_s + 1.0, vs.arrival_s + 2.0, 5),
        ]
        for t in grids:
            got, want = _positions(vs, t), _positions_masked(vs, t)
            assert got.tobytes() == want.tobytes(), vs.vehicle_id


def test_distances_added_column_by_column_are_the_row_sums_to_the_last_bit() -> None:
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(2, 5000, 3)) * rng.choice([1e-3, 1.0, 1e4, 1e7], size=(2, 5000, 3))
    a[:50], b[25:75, 1], a[100:110] = np.nan, -0.0, b[100:110]
    want = np.sqrt(((a - b) ** 2).sum(axis=-1))
    assert _distance_m(a, b).tobytes() == want.tobytes()


def test_positions_sampled_at_once_are_the_schedule_s_own_at_every_time() -> None:
    """The team's tracks are sampled on arrays: the same positions as the schedule's own
    ``position_at``, time by time, through the climb-out, the legs, a loiter and the end, at
    the profile's altitude where the schedule has it (``state_at``)."""
    scenario = parse_scenario(small_scenario(arrival={"kind": "simultaneous", "required_s": 2600}))
    s = build_schedule(scenario, plan(scenario, "astar"), world=build_world(scenario))
    assert all(vs.climb is not None for vs in s.vehicles)
    for vs in [*s.vehicles, _loitering()[0]]:
        t = np.linspace(vs.takeoff_s - 50.0, vs.arrival_s + 50.0, 3001)
        got = _positions(vs, t)
        for k, tk in enumerate(t):
            want = vs.position_at(float(tk))
            if want is None:
                assert np.isnan(got[k]).all(), (vs.vehicle_id, tk)
            else:
                assert tuple(got[k, :2]) == want, (vs.vehicle_id, tk, got[k], want)
                alt = vs.alt_at(vs.state_at(float(tk))[1])
                assert got[k, 2] == pytest.approx(alt, abs=1e-6), (vs.vehicle_id, tk)

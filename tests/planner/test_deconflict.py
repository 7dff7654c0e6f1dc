"""Deconfliction: closest approach of scheduled vehicles, loiters included."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.deconflict import separation
from planner.flightpath import straight
from planner.schedule import Leg, LoiterPlan, VehicleSchedule


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


def test_loiter_positions_stay_on_the_circle() -> None:
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
    for t in np.linspace(lo.t_start_s, lo.t_end_s - 1e-6, 50):
        p = vs.position_at(float(t))
        assert p is not None
        assert math.hypot(p[0] - 10_000, p[1] + r) == pytest.approx(r)
    p = vs.position_at(lo.t_end_s + 100.0)
    assert p is not None and p == pytest.approx((12_000.0, 0.0))

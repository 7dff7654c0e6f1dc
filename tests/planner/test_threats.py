from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from planner.threats import NoFlyZone, RadarSite, active, exposure, forbidden_mask

SQUARE = NoFlyZone("NFZ", ((0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)), 1000.0, True)
RADAR = RadarSite("R", 0.0, 0.0, 100.0, 500.0, False)

coord = st.floats(-50.0, 60.0, allow_nan=False, allow_subnormal=False)


def test_polygon_contains_known_points() -> None:
    e = np.array([5.0, -1.0, 11.0, 9.99, 5.0])
    n = np.array([5.0, 5.0, 5.0, 0.01, 10.5])
    assert SQUARE.contains(e, n).tolist() == [True, False, False, True, False]


def test_polygon_signed_distance() -> None:
    d = SQUARE.distance_m(np.array([5.0, 13.0, 5.0]), np.array([5.0, 14.0, -2.0]))
    assert np.allclose(d, [-5.0, 5.0, 2.0])


@settings(max_examples=200, deadline=None)
@given(coord, coord, coord, coord)
def test_segment_distance_is_the_minimum_over_samples(
    e0: float, n0: float, e1: float, n1: float
) -> None:
    for zone in (SQUARE, RadarSite("R", 5.0, 5.0, 4.0, 1000.0, True)):
        exact = zone.segment_distance_m(e0, n0, e1, n1)
        t = np.linspace(0.0, 1.0, 2001)
        d = zone.distance_m(e0 + (e1 - e0) * t, n0 + (n1 - n0) * t)
        if d.min() <= 0.0:  # a touch on the boundary counts as entering
            assert exact <= 1e-9
        else:
            step = math.hypot(e1 - e0, n1 - n0) / 2000
            assert exact <= d.min() + 1e-9
            assert exact >= d.min() - step - 1e-9


def test_radar_exposure_falls_to_zero_at_its_radius() -> None:
    e = np.array([0.0, 50.0, 100.0, 150.0])
    ex = exposure([RADAR], e, np.zeros(4), np.zeros(4))
    assert ex.tolist() == [1.0, 0.75, 0.0, 0.0]


def test_threats_act_only_below_their_ceiling() -> None:
    ex = exposure([RADAR], np.zeros(2), np.zeros(2), np.array([400.0, 600.0]))
    assert ex.tolist() == [1.0, 0.0]
    mask = forbidden_mask([SQUARE], np.full(2, 5.0), np.full(2, 5.0), np.array([900.0, 1100.0]))
    assert mask.tolist() == [True, False]


def test_popup_threats_are_inactive_until_they_appear() -> None:
    popup = RadarSite("P", 0.0, 0.0, 10.0, 100.0, True, appears_at_s=600.0)
    assert active([RADAR, popup], None) == [RADAR]
    assert active([RADAR, popup], 599.0) == [RADAR]
    assert active([RADAR, popup], 600.0) == [RADAR, popup]

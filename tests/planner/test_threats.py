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
        step = math.hypot(e1 - e0, n1 - n0) / 2000
        if d.min() < -1e-9:  # a sample inside: the segment enters (up to round-off)
            assert exact <= 1e-9
        if exact > 0.0:  # clear: no sample comes closer, and one comes within a step
            assert d.min() >= exact - 1e-9
            assert d.min() <= exact + step + 1e-9
        else:  # enters or touches: the samples reach the boundary within a step
            assert d.min() <= step + 1e-9


def test_a_segment_through_two_vertices_enters_the_polygon() -> None:
    # Diagonally across the square, through its corners: no proper edge crossing.
    assert SQUARE.segment_distance_m(31.0, 31.0, -1.0, -1.0) < 0.0
    assert SQUARE.segment_distance_m(-5.0, 0.0, 15.0, 0.0) <= 0.0  # along an edge: no margin
    assert SQUARE.segment_distance_m(-1.0, 11.0, 11.0, 23.0) > 0.0


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

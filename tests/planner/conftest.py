"""Small scenarios built in code, shared by the planner tests."""

from __future__ import annotations

import copy
from typing import Any

import pytest


def small_scenario(**overrides: Any) -> dict[str, Any]:
    """A 40 x 40 km, 1 km grid, two-vehicle scenario as plain data (what a YAML file holds)."""
    base: dict[str, Any] = {
        "name": "small",
        "area": {
            "origin": {"lat_deg": 45.0, "lon_deg": 7.0},
            "width_m": 40000,
            "height_m": 40000,
            "resolution_m": 1000,
        },
        "terrain": {"kind": "flat", "elevation_m": 100},
        "separation_m": 300,
        "arrival": {"kind": "simultaneous"},
        "vehicles": [
            {
                "id": "A",
                "start": {"east_m": 2000, "north_m": 2000, "alt_m": 500},
                "goal": {"east_m": 37000, "north_m": 36000, "alt_m": 500},
                "speed_min_m_s": 18,
                "speed_max_m_s": 28,
                "min_turn_radius_m": 200,
                "max_range_m": 200000,
                "alt_max_m": 3000,
                "takeoff_window_s": [0, 1200],
            },
            {
                "id": "B",
                "start": {"east_m": 36000, "north_m": 3000, "alt_m": 500},
                "goal": {"east_m": 38000, "north_m": 38000, "alt_m": 500},
                "speed_min_m_s": 18,
                "speed_max_m_s": 28,
                "min_turn_radius_m": 200,
                "max_range_m": 200000,
                "alt_max_m": 3000,
                "takeoff_window_s": [0, 1200],
            },
        ],
        "threats": [
            {
                "kind": "radar",
                "id": "SAM",
                "center": {"east_m": 20000, "north_m": 20000},
                "radius_m": 6000,
                "forbidden": True,
            }
        ],
    }
    out = copy.deepcopy(base)
    out.update(overrides)
    return out


def _two_lines(
    overrides: dict[str, Any],
    a: tuple[float, float, float, float],
    b: tuple[float, float, float, float],
) -> dict[str, Any]:
    """:func:`small_scenario` without threats, A and B each flying from ``(east, north)`` to
    ``(east, north)`` (the four numbers, m) at 500 m."""
    data = small_scenario(**({"threats": []} | overrides))
    for v, (e0, n0, e1, n1) in zip(data["vehicles"], (a, b), strict=True):
        v["start"] = {"east_m": e0, "north_m": n0, "alt_m": 500}
        v["goal"] = {"east_m": e1, "north_m": n1, "alt_m": 500}
    return data


def crossing_scenario(**overrides: Any) -> dict[str, Any]:
    """A flying east and B north across the middle of the map, 36 km each: timed alike they
    cross the middle at the same moment."""
    return _two_lines(overrides, (2000, 20000, 38000, 20000), (20000, 2000, 20000, 38000))


def head_on_scenario(**overrides: Any) -> dict[str, Any]:
    """A flying east and B west on lines 100 m apart, at one height: timed alike for one
    arrival they meet head-on half way, and no timing keeps them apart."""
    return _two_lines(overrides, (2000, 20000, 38000, 20000), (38000, 20100, 2000, 20100))


@pytest.fixture
def small() -> dict[str, Any]:
    return small_scenario()

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


def crossing_scenario(**overrides: Any) -> dict[str, Any]:
    """:func:`small_scenario` without threats, A flying east and B north across the middle of
    the map, 36 km each: timed alike they cross the middle at the same moment."""
    data = small_scenario(**({"threats": []} | overrides))
    a, b = data["vehicles"]
    a["start"], a["goal"] = (
        {"east_m": 2000, "north_m": 20000, "alt_m": 500},
        {"east_m": 38000, "north_m": 20000, "alt_m": 500},
    )
    b["start"], b["goal"] = (
        {"east_m": 20000, "north_m": 2000, "alt_m": 500},
        {"east_m": 20000, "north_m": 38000, "alt_m": 500},
    )
    return data


@pytest.fixture
def small() -> dict[str, Any]:
    return small_scenario()

"""A route re-planned in flight starts where the vehicle is, with its heading: often on a
straight line through grid nodes, just short of or past the node the search snaps it to, or a
little off that line. Its smoothed path begins exactly there and neither repeats a point nor
loops."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from planner.flightpath import FlightPath, leg_lengths_m, smooth_polyline
from planner.plan import (
    MIN_PIECE_M,
    ONTO_ROUTE_REACH,
    World,
    build_problem,
    build_world,
    finish_route,
    onto_route,
    refine_corners,
)
from planner.scenario import parse_scenario
from planner.search import optimal_nodes
from planner.threats import ThreatZone, active
from tests.planner.conftest import small_scenario

RADIUS_M = 300.0
NORTH_EAST = math.pi / 4.0


def total_turn_rad(path: FlightPath) -> float:
    return sum(s.length_m / s.radius_m for s in path.segments if s.turn != "S")


def test_a_start_on_a_row_of_grid_nodes_repeats_no_point() -> None:
    # A hold point on a straight route along a grid diagonal, as the path gives it: the turn
    # at the next node is round-off only (some 5e-12 rad).
    points = np.array(
        [
            [194198.71666093674, 192198.71666093956],
            [194500.0, 192500.0],
            [194750.0, 192750.0],
            [194750.0, 193500.0],
        ]
    )
    refined = refine_corners(points, RADIUS_M, NORTH_EAST)
    assert leg_lengths_m(refined).min() >= MIN_PIECE_M
    path = smooth_polyline(refined, RADIUS_M, start_heading_rad=NORTH_EAST)
    assert total_turn_rad(path) < math.radians(50.0)  # the one corner, no loop


@pytest.mark.parametrize("turn_deg", [1e-7, 1e-3, 0.05, 0.1])
def test_refine_corners_leaves_no_piece_shorter_than_the_minimum(turn_deg: float) -> None:
    turn = math.radians(turn_deg)
    points = np.array(
        [[0.0, 0.0], [0.0, 1000.0], [1000.0 * math.sin(turn), 1000.0 * (1 + math.cos(turn))]]
    )
    refined = refine_corners(points, RADIUS_M)
    assert leg_lengths_m(refined).min() >= MIN_PIECE_M
    smooth_polyline(refined, RADIUS_M)


def test_refine_corners_measures_a_corner_along_the_straight_run_beside_it() -> None:
    # A 48 degree corner, then grid nodes in a row 250 m apart: the fillet needs 140 m of
    # the leg after the corner, more than half a node spacing.
    points = np.array([[-700.0, -630.0], [0.0, 0.0], [0.0, 250.0], [0.0, 500.0], [0.0, 1500.0]])
    path = smooth_polyline(refine_corners(points, RADIUS_M), RADIUS_M)
    assert total_turn_rad(path) == pytest.approx(math.atan2(700.0, 630.0), abs=1e-6)


@pytest.mark.parametrize(
    ("start", "heading_deg", "kept"),
    [
        # 48 m short of a node where the route turns 14 degrees: too near to turn there.
        ((-24.6, -41.6), 30.65, [[250.0, 250.0], [2000.0, 2000.0]]),
        # 69 m past the node it was snapped to: the node is behind it.
        ((69.7, 69.7), 45.0, [[250.0, 250.0], [2000.0, 2000.0]]),
        # Heading east, the route 59 degrees to its left 290 m on, and 52 degrees 640 m on.
        ((-148.3, -250.0), 90.0, [[2000.0, 2000.0]]),
        # Far enough for both turns: nothing left out.
        ((-500.0, -500.0), 45.0, [[0.0, 0.0], [250.0, 250.0], [2000.0, 2000.0]]),
    ],
)
def test_onto_route_leaves_out_the_vertices_too_near_to_turn_at(
    start: tuple[float, float], heading_deg: float, kept: list[list[float]]
) -> None:
    grid_route = np.array([start, [0.0, 0.0], [250.0, 250.0], [2000.0, 2000.0]])
    heading = math.radians(heading_deg)
    out = onto_route(grid_route, RADIUS_M, heading)
    np.testing.assert_array_equal(out[0], start)
    np.testing.assert_array_equal(out[1:], kept)
    path = smooth_polyline(
        refine_corners(out, RADIUS_M, heading), RADIUS_M, start_heading_rad=heading
    )
    assert total_turn_rad(path) < math.pi  # the turns it needs; no loop


def test_onto_route_keeps_the_last_vertex_and_far_ones() -> None:
    behind = np.array([[0.0, 0.0], [0.0, -100.0]])
    np.testing.assert_array_equal(onto_route(behind, RADIUS_M, 0.0), behind)
    # A hairpin farther than the reach is the route's own.
    far = ONTO_ROUTE_REACH * RADIUS_M + 1.0
    hairpin = np.array([[0.0, 0.0], [0.0, far], [50.0, 0.0], [50.0, -5000.0]])
    np.testing.assert_array_equal(onto_route(hairpin, RADIUS_M, 0.0), hairpin)


def _sam_scenario() -> dict[str, Any]:
    """The paper's SAM1 at 1/4 scale, 7.5 km east and 10 km north of the area's corner, and
    one vehicle flying north-east past it along a grid diagonal, some 250 m from its edge."""
    data = small_scenario(
        area={
            "origin": {"lat_deg": 45.0, "lon_deg": 7.0},
            "width_m": 25000,
            "height_m": 25000,
            "resolution_m": 250,
        },
        threats=[
            {
                "kind": "radar",
                "id": "SAM",
                "center": {"east_m": 7500, "north_m": 10000},
                "radius_m": 3000,
                "forbidden": True,
            }
        ],
    )
    vehicle = data["vehicles"][0]
    vehicle["min_turn_radius_m"] = RADIUS_M
    vehicle["goal"] = {"east_m": 20000, "north_m": 18000, "alt_m": 500}
    data["vehicles"] = [vehicle]
    return data


@pytest.fixture(scope="module")
def sam_world() -> tuple[World, list[ThreatZone]]:
    world = build_world(parse_scenario(_sam_scenario()))
    return world, list(active(world.threats, None))


@pytest.mark.parametrize(
    ("start", "heading_deg"),
    [
        ((9319.6798707503, 7319.67987075166), 45.0),  # just past its node, on the diagonal
        ((9319.6798707503, 7319.67987075166), 30.65),  # and off it
        ((8975.36168643017, 6958.42284585274), 30.65),  # 48 m short of a 14 degree turn
        ((9069.0, 7069.0), 30.65),
        ((9100.0, 7000.0), 45.0),  # off the row of nodes
        ((9000.0005, 7000.0002), 45.0),  # within round-off of a node
    ],
)
def test_a_route_replanned_near_a_zone_starts_where_the_vehicle_is_and_does_not_loop(
    sam_world: tuple[World, list[ThreatZone]], start: tuple[float, float], heading_deg: float
) -> None:
    world, threats = sam_world
    problem = build_problem(world, threats=threats, starts={"A": (*start, 500.0)}, vehicles=["A"])
    nodes = optimal_nodes(problem, 0)
    assert nodes is not None
    route = finish_route(
        world, problem, 0, nodes, 0.0, threats=threats, start_alt_m=500.0,
        start_heading_rad=math.radians(heading_deg),
    )  # fmt: skip
    assert (route.path.start.east_m, route.path.start.north_m) == start
    assert route.min_threat_distance_m >= 0.0
    assert total_turn_rad(route.path) < math.pi

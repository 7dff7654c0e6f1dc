"""How far a flight of the paper scenario (``scenarios/paper_three_uav.yaml``, or its compact
form, :func:`tests.teams.compact_paper`: ``scenario_name="compact"``) may move its team time
later, worked out here for the flight tests that fly it in a wind
(tests/service, tests/web, tests/gcs/test_restart.py): a test states this bound and asserts
the move against it, so a coordinator that moved the team time to cover a late vehicle
would not pass on the oracle's slots moved by as much.

The schedule sets the team time before launch in still air; in flight it moves later only
when a vehicle cannot make it even at its top speed:

- the wind: each vehicle's planned route flown at its top airspeed in the rehearsal's wind,
  against the same in still air (the test's own plan of the scenario, seed 1 as the flights
  are planned; the top equivalent airspeed taken as the true one, which only overstates what
  a headwind costs);
- the pop-up (POPUP1, a 15 km disc across UAV1's and UAV2's routes; 3.75 km across UAV2's in
  the compact form): going round the disc instead of across it is at most half its
  circumference instead of its diameter, (pi - 2) x its radius, flown at the slowest top speed
  of the vehicles whose planned routes it crosses, straight into the wind; a re-plan that
  routed a vehicle round it wider to keep the separation (a ``conflict`` event of resolution
  ``offset``, :func:`widest_offset_m`) goes round a disc that much wider;
- ``SLACK_S`` for the late margin a moved team time keeps and the ETA estimates' error.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from planner.flightpath import FlightPath
from planner.plan import build_world, plan
from planner.retime import build_schedule
from planner.scenario import Radar, Scenario, load_scenario, parse_scenario
from planner.schedule import Schedule
from tests.gcs.conftest import PAPER
from tests.teams import compact_paper

POPUP = "POPUP1"
SLACK_S = 60.0
"""The late margin (2 s a move) and the arrival estimates' error over the flight."""


@functools.cache
def paper_schedule(seed: int = 1, scenario_name: str = "paper") -> tuple[Scenario, Schedule]:
    """The paper scenario (``scenario_name`` "paper", or "compact") and its schedule as the
    service plans it with ``seed``."""
    if scenario_name == "compact":
        scenario = parse_scenario(compact_paper())
    else:
        assert scenario_name == "paper", scenario_name
        scenario = load_scenario(PAPER)
    world = build_world(scenario)
    p = plan(scenario, rng=np.random.default_rng(seed), world=world)
    return scenario, build_schedule(scenario, p, world=world)


def time_in_wind_s(
    path: FlightPath,
    from_m: float,
    tas_m_s: Callable[[float], float],
    wind_to_m_s: tuple[float, float],
) -> float:
    """How long (s) ``path`` takes from ``from_m`` to its end at the true airspeed
    ``tas_m_s(s)`` in a steady wind (m/s to the east and to the north): every 20 m of it at
    the ground speed the wind triangle gives on its heading there (crabbed into the wind:
    sqrt(v^2 - across^2) + along)."""
    length_m = path.length_m
    edges = np.linspace(from_m, length_m, int((length_m - from_m) / 20.0) + 2)
    ds = np.diff(edges)
    middle = edges[:-1] + ds / 2
    heading = np.array([path.pose_at(float(s)).heading_rad for s in middle])
    tas = np.array([tas_m_s(float(s)) for s in middle])
    we, wn = wind_to_m_s
    along = we * np.sin(heading) + wn * np.cos(heading)
    cross = we * np.cos(heading) - wn * np.sin(heading)
    return float((ds / (np.sqrt(tas**2 - cross**2) + along)).sum())


def wind_cost_s(
    vehicle_id: str, wind_m_s: float, wind_from_deg: float, scenario_name: str = "paper"
) -> float:
    """How much longer (s; negative: shorter) the vehicle's planned route takes at its top
    airspeed in the wind than in still air (:func:`time_in_wind_s`)."""
    scenario, schedule = paper_schedule(1, scenario_name)
    vs = schedule.vehicle(vehicle_id)
    assert vs is not None, vehicle_id
    v_m_s = scenario.vehicle(vehicle_id).speed_max_m_s
    to_rad = math.radians(wind_from_deg + 180.0)
    wind_to = (wind_m_s * math.sin(to_rad), wind_m_s * math.cos(to_rad))
    return time_in_wind_s(vs.path, 0.0, lambda _s: v_m_s, wind_to) - vs.path.length_m / v_m_s


def popup_crossed(scenario_name: str = "paper") -> tuple[float, list[str]]:
    """POPUP1's radius (m) and the vehicles whose planned routes (seed 1) enter its disc."""
    scenario, schedule = paper_schedule(1, scenario_name)
    (zone,) = [z for z in scenario.threats if z.id == POPUP]
    assert isinstance(zone, Radar), zone
    crossed = []
    for vs in schedule.vehicles:
        s_m = np.linspace(0.0, vs.path.length_m, 2000)
        poses = [vs.path.pose_at(float(s)) for s in s_m]
        near_m = min(
            math.hypot(q.east_m - zone.center.east_m, q.north_m - zone.center.north_m)
            for q in poses
        )
        if near_m < zone.radius_m:
            crossed.append(vs.vehicle_id)
    return zone.radius_m, crossed


def widest_offset_m(record: Mapping[str, Any]) -> float:
    """How much wider (m) than the zone a flight's re-plans routed a vehicle round it, by its
    record's ``conflict`` events of resolution ``offset`` (0 when none was)."""
    return max(
        (
            float(e["payload"]["offset_m"])
            for e in record["events"]
            if e["kind"] == "conflict" and (e.get("payload") or {}).get("resolution") == "offset"
        ),
        default=0.0,
    )


def team_time_move_max_s(
    wind_m_s: float = 0.0,
    wind_from_deg: float = 0.0,
    scenario_name: str = "paper",
    offset_m: float = 0.0,
) -> float:
    """The most the team time may move later in a flight of the paper scenario (or the
    compact one) in this wind, its re-plan routed round POPUP1 ``offset_m`` wider (the
    module's list)."""
    scenario, _ = paper_schedule(1, scenario_name)
    wind = max(
        0.0,
        *(wind_cost_s(v.id, wind_m_s, wind_from_deg, scenario_name) for v in scenario.vehicles),
    )
    radius_m, crossed = popup_crossed(scenario_name)
    v_m_s = min(scenario.vehicle(v).speed_max_m_s for v in crossed)
    popup = (math.pi - 2.0) * (radius_m + offset_m) / (v_m_s - wind_m_s)
    return wind + popup + SLACK_S

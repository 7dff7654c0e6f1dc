"""A re-planned vehicle timed through a place (:func:`planner.replantiming.retime_through`):
refused where the way left to its slot cannot make up what a change of speed there costs
while the true airspeed follows its command, as ArduPlane's TECS limits it (AP_TECS.cpp,
update_speed: the speed demand's rate at most 0.5 * CLMB_MAX * g / TAS faster and 0.5 *
SINK_MIN * g / TAS slower, their defaults 5 and 2 m/s)."""

from __future__ import annotations

import pytest

from planner.errors import InfeasibleError
from planner.plan import build_world, plan
from planner.replantiming import retime_through
from planner.retime import Retimed, build_schedule
from planner.scenario import parse_scenario
from tests.planner.conftest import head_on_scenario

G_M_S2 = 9.80665
SINK_MIN_M_S = 2.0


def _ground_gained_slowing_m(from_m_s: float, to_m_s: float, dt_s: float = 0.01) -> float:
    """How much further a vehicle goes while it slows from ``from_m_s`` to ``to_m_s`` (true
    airspeed) at TECS's rate, than at ``to_m_s`` from the start: stepped, the rate taken at
    the speed it has."""
    v, gained_m = from_m_s, 0.0
    while v > to_m_s:
        gained_m += (v - to_m_s) * dt_s
        v -= 0.5 * SINK_MIN_M_S * G_M_S2 / v * dt_s
    return gained_m


def test_a_pass_too_near_the_goal_to_slow_after_is_refused_and_one_with_room_is_not() -> None:
    data = head_on_scenario(arrival={"kind": "simultaneous", "required_s": 1500})
    scenario = parse_scenario(data)
    world = build_world(scenario)
    schedule = build_schedule(scenario, plan(scenario, "astar", world=world), world=world)
    vs = schedule.vehicles[0]
    v = scenario.vehicle(vs.vehicle_id)
    tas = vs.legs[-1].tas_per_eas
    goal_m = vs.path.length_m

    def through(before_goal_m: float, tail_m_s: float) -> Retimed:
        """Timed to fly the last ``before_goal_m`` at ``tail_m_s`` (EAS) into its slot."""
        via_t_s = vs.arrival_s - before_goal_m / (tail_m_s * tas)
        return retime_through(
            scenario, v, vs, now_s=vs.climb_end_s + 10.0, via_s_m=goal_m - before_goal_m,
            via_t_s=via_t_s, target_s=vs.arrival_s, step_m_s=schedule.step_m_s, threats=[],
        )  # fmt: skip

    # 0.7 km before the goal, from about 26 m/s to 0.5 m/s over its minimum: it goes some
    # 70 m further while it slows, and its minimum over the 37 s left makes up 19 m of it.
    slow_m_s = v.speed_min_m_s + 0.5
    tail_s = 700.0 / (slow_m_s * tas)
    head_m_s = (goal_m - 700.0 - vs.climb_s_m) / (vs.arrival_s - tail_s - vs.climb_end_s) / tas
    gained_m = _ground_gained_slowing_m(head_m_s * tas, slow_m_s * tas)
    assert gained_m > 0.5 * tas * tail_s * 2.0
    with pytest.raises(InfeasibleError, match="cannot make up"):
        through(700.0, slow_m_s)
    # The same pass at 22 m/s, 4 m/s of room above the minimum: taken, and it passes there
    # at 22 m/s.
    made = through(700.0, 22.0)
    assert made.schedule.legs[-1].speed_m_s == pytest.approx(22.0, abs=0.5)
    assert _ground_gained_slowing_m(head_m_s * tas, 22.0 * tas) < 4.0 * tas * 700.0 / 22.0
    # Slowed to near its minimum 5 km before the goal: over four minutes it makes it up.
    through(5_000.0, slow_m_s)
    tail_s = 5_000.0 / (slow_m_s * tas)
    assert _ground_gained_slowing_m(head_m_s * tas, slow_m_s * tas) < 0.5 * tas * tail_s

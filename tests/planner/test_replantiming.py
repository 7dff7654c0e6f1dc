"""A re-planned vehicle timed through a place (:func:`planner.replantiming.retime_through`):
refused where the way left to its slot cannot make up what a change of speed there costs
while the airspeed follows its command (ArduPlane's TECS: about 1 m/s^2, AP_TECS.cpp
update_speed)."""

from __future__ import annotations

import pytest

from planner.errors import InfeasibleError
from planner.plan import build_world, plan
from planner.replantiming import retime_through
from planner.retime import Retimed, build_schedule
from planner.scenario import parse_scenario
from tests.planner.conftest import head_on_scenario

ACCEL_M_S2 = 1.0


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

    # 0.7 km before the goal, from about 26 m/s to 0.5 m/s over its minimum: slowing takes
    # (26 - 18.5)^2 / 2 = 28 m more than the timing counts, and flying its minimum over the
    # 37 s left makes up 0.5 x 37 = 19 m of it.
    slow_m_s = v.speed_min_m_s + 0.5
    tail_s = 700.0 / (slow_m_s * tas)
    head_m_s = (goal_m - 700.0 - vs.climb_s_m) / (vs.arrival_s - tail_s - vs.climb_end_s) / tas
    assert (head_m_s - slow_m_s) ** 2 / (2.0 * ACCEL_M_S2) > 0.5 * tail_s
    with pytest.raises(InfeasibleError, match="cannot make up"):
        through(700.0, slow_m_s)
    # The same pass at 22 m/s, 4 m/s of room above the minimum: taken, and it passes there
    # at 22 m/s.
    made = through(700.0, 22.0)
    assert made.schedule.legs[-1].speed_m_s == pytest.approx(22.0, abs=0.5)
    # Slowed to near its minimum 5 km before the goal: over 4 minutes it makes up the change.
    through(5_000.0, slow_m_s)

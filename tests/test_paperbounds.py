"""The team-time bound the paper flights are held to (:mod:`tests.paperbounds`): no wind costs
nothing, a wind from ahead of UAV2 (which flies north-north-east) costs it time and one from
behind saves it, never more than the whole route flown straight into the wind would cost; and
the bound grows with a headwind."""

from __future__ import annotations

import pytest

from tests.paperbounds import paper_schedule, team_time_move_max_s, wind_cost_s


def test_the_wind_costs_uav2_time_from_ahead_saves_it_from_behind_and_nothing_in_calm() -> None:
    scenario, schedule = paper_schedule()
    vs = schedule.vehicle("UAV2")
    assert vs is not None
    v_m_s, length_m = scenario.vehicle("UAV2").speed_max_m_s, vs.path.length_m
    assert wind_cost_s("UAV2", 0.0, 0.0) == pytest.approx(0.0, abs=1e-6)
    ahead, behind = wind_cost_s("UAV2", 4.0, 20.0), wind_cost_s("UAV2", 4.0, 200.0)
    assert ahead > 0.0 > behind
    # Straight into the wind the whole way (the most it can cost) and straight before it.
    assert ahead < length_m / (v_m_s - 4.0) - length_m / v_m_s
    assert behind > length_m / (v_m_s + 4.0) - length_m / v_m_s
    assert team_time_move_max_s(4.0, 20.0) > team_time_move_max_s() + ahead

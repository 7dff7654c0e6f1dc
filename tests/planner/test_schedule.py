"""The schedule on the paper scenario (section 5's story) and on small scenarios."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from planner.atmosphere import eas2tas, mean_eas2tas
from planner.deconflict import separation
from planner.errors import InfeasibleError
from planner.plan import build_world, plan
from planner.popup import replay_popups
from planner.retime import build_schedule
from planner.scenario import load_scenario, parse_scenario
from planner.schedule import Schedule
from tests.planner.conftest import small_scenario

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def paper() -> tuple[Schedule, Schedule]:
    scenario = load_scenario(ROOT / "scenarios" / "paper_three_uav.yaml")
    rng = np.random.default_rng(1)
    planned = plan(scenario, "aco", rng=rng)
    world = build_world(scenario)
    before = build_schedule(scenario, planned, world=world)
    after = replay_popups(before, method="aco", rng=rng)
    return before, after


def _check_consistent(s: Schedule) -> None:
    assert s.required_arrival_s is not None
    for vs in s.vehicles:
        assert abs(vs.arrival_s - (s.required_arrival_s + s.offsets_s[vs.vehicle_id])) < 0.1
        for leg in vs.legs:
            assert vs.speed_min_m_s <= leg.speed_m_s <= vs.speed_max_m_s
            assert abs(leg.speed_m_s * 2 - round(leg.speed_m_s * 2)) < 1e-9
        assert vs.legs[-1].s_end_m == pytest.approx(vs.path.length_m, abs=1e-6)


def test_longest_path_takes_off_first(paper: tuple[Schedule, Schedule]) -> None:
    before, _ = paper
    _check_consistent(before)
    longest = max(before.vehicles, key=lambda v: v.path.length_m)
    first = min(before.vehicles, key=lambda v: v.takeoff_s)
    assert longest.vehicle_id == first.vehicle_id
    assert all(v.takeoff_s > longest.takeoff_s for v in before.vehicles if v is not longest)
    # It sets the earliest common arrival (eq. 1) and flies at its top speed, as UAV2 does in
    # the paper once its takeoff is moved.
    assert before.requested_arrival_s is None
    assert f"earliest common arrival: {longest.vehicle_id} cannot" in before.arrival_reason
    assert {leg.speed_m_s for leg in longest.legs} == {longest.speed_max_m_s}


def test_popup_story(paper: tuple[Schedule, Schedule]) -> None:
    before, after = paper
    _check_consistent(after)
    popup = next(e for e in after.events if e.kind == "popup")
    replanned = [v.vehicle_id for v in after.vehicles if v.replanned_at_s]
    assert sorted(replanned) == ["UAV1", "UAV2"]
    later = [a for a in after.adjustments if a.time_s >= popup.time_s]
    for vid in replanned:
        assert any(a.vehicle == vid and a.strategy == "speed" for a in later)
    # The detour makes the old arrival infeasible; the unaffected vehicle's required speed falls
    # below its minimum, so it loiters, with the fewest turns.
    assert after.required_arrival_s is not None and before.required_arrival_s is not None
    assert after.required_arrival_s > before.required_arrival_s
    loiterers = [v for v in after.vehicles if v.loiters]
    assert [v.vehicle_id for v in loiterers] == ["UAV3"]
    uav3 = loiterers[0]
    _, s0, _ = before.vehicle("UAV3").state_at(popup.time_s)
    # Equivalent airspeeds carry the aircraft at the true airspeed of its altitudes: time in
    # metres of still air per unit of EAS.
    ratio = mean_eas2tas(uav3.wp_s_m, uav3.wp_alt_m, s_from_m=s0)
    assert 1.02 < ratio < 1.1
    remaining = (uav3.path.length_m - s0) / ratio
    time_left = after.required_arrival_s - popup.time_s
    assert remaining / time_left < uav3.speed_min_m_s  # required speed below vmin
    lo = uav3.loiters[0]
    assert lo.tas_per_eas == pytest.approx(ratio)
    per_turn = 2 * math.pi * lo.radius_m / ratio
    assert (remaining + lo.turns * per_turn) / uav3.speed_min_m_s >= time_left
    assert (remaining + (lo.turns - 1) * per_turn) / uav3.speed_min_m_s < time_left
    assert any(a.vehicle == "UAV3" and a.strategy == "loiter" for a in later)
    sep = separation(after.vehicles, after.scenario.separation_m)
    assert sep.min_separation_m >= after.scenario.separation_m
    assert not sep.conflicts


def test_loiter_circle_is_inside_its_buffer(paper: tuple[Schedule, Schedule]) -> None:
    _, after = paper
    frame = after.scenario.frame()
    for vs in after.vehicles:
        for lo in vs.loiters:
            b = next(b for b in after.scenario.buffers if b.id == lo.buffer_id)
            be, bn = b.center.local(frame)
            d = math.hypot(lo.centre_east_m - be, lo.centre_north_m - bn)
            assert d + lo.radius_m <= b.radius_m + 1e-6
            # Tangent to the path at the loiter point: the centre is one radius from it.
            p = vs.path.pose_at(lo.s_m)
            assert math.hypot(p.east_m - lo.centre_east_m, p.north_m - lo.centre_north_m) == (
                pytest.approx(lo.radius_m)
            )


def _small(**over: Any) -> Schedule:
    scenario = parse_scenario(small_scenario(**over))
    return build_schedule(scenario, plan(scenario, "astar"))


def test_small_scenario_meets_the_request() -> None:
    s = _small(arrival={"kind": "simultaneous", "required_s": 2200})
    assert s.required_arrival_s == 2200
    _check_consistent(s)


def test_spaced_arrivals() -> None:
    s = _small(arrival={"kind": "spaced", "interval_s": 120, "first_s": 2200})
    _check_consistent(s)
    assert s.vehicle("B").arrival_s - s.vehicle("A").arrival_s == pytest.approx(120, abs=0.1)


def test_windows_arrivals_stay_in_their_windows() -> None:
    windows = [
        {"vehicle": "A", "earliest_s": 2000, "latest_s": 2300},
        {"vehicle": "B", "earliest_s": 1900, "latest_s": 2000},
    ]
    s = _small(arrival={"kind": "windows", "windows": windows})
    assert 2000 - 0.1 <= s.vehicle("A").arrival_s <= 2300 + 0.1
    assert 1900 - 0.1 <= s.vehicle("B").arrival_s <= 2000 + 0.1


def test_unreachable_window_names_vehicle_and_shortfall() -> None:
    windows = [
        {"vehicle": "A", "earliest_s": 100, "latest_s": 200},
        {"vehicle": "B", "earliest_s": 1900, "latest_s": 2000},
    ]
    with pytest.raises(InfeasibleError, match=r"vehicle A: .*short by \d+\.\d s"):
        _small(arrival={"kind": "windows", "windows": windows})


def test_airborne_vehicle_that_cannot_wait_names_itself_and_the_shortfall() -> None:
    data = small_scenario(arrival={"kind": "simultaneous", "required_s": 9000})
    data["vehicles"][0]["airborne"] = True
    data["vehicles"][1]["takeoff_window_s"] = [8000, 9000]
    scenario = parse_scenario(data)
    with pytest.raises(InfeasibleError, match=r"vehicle A: .*no buffer.*short by \d+\.\d s"):
        build_schedule(scenario, plan(scenario, "astar"))


def test_airborne_vehicle_loiters_in_a_buffer_on_its_path() -> None:
    data = small_scenario(arrival={"kind": "simultaneous", "required_s": 3000})
    for v in data["vehicles"]:
        v["airborne"] = True
    # A large buffer around the middle of the map covers both routes somewhere.
    data["buffers"] = [{"id": "H", "center": {"east_m": 30000, "north_m": 20000}, "radius_m": 9000}]
    scenario = parse_scenario(data)
    s = build_schedule(scenario, plan(scenario, "astar"))
    _check_consistent(s)
    assert all(v.loiters for v in s.vehicles)
    assert all(a.strategy != "takeoff_delay" for a in s.adjustments)


def test_legs_are_timed_at_the_true_airspeed_of_their_altitudes(
    paper: tuple[Schedule, Schedule],
) -> None:
    """A leg commanded at an equivalent airspeed covers ground at the ISA true airspeed of
    the route's altitudes (1,000-1,250 m here: 5-6 % faster than commanded)."""
    before, _ = paper
    for vs in before.vehicles:
        lo_ratio = eas2tas(float(vs.wp_alt_m.min()))
        hi_ratio = eas2tas(float(vs.wp_alt_m.max()))
        assert lo_ratio > 1.02
        for leg in vs.legs:
            flown = (leg.s_end_m - leg.s_start_m) / (leg.t_end_s - leg.t_start_s)
            assert lo_ratio - 1e-6 <= flown / leg.speed_m_s <= hi_ratio + 1e-6

"""The schedule on the paper scenario (section 5's story) and on small scenarios."""

from __future__ import annotations

import math
import pickle
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from planner.atmosphere import eas2tas, mean_eas2tas
from planner.deconflict import loiter_conflict, pair_separation, separation
from planner.errors import ArrivalTimeError, InfeasibleError, SeparationError
from planner.flightpath import straight
from planner.plan import build_world, plan
from planner.popup import replay_popups
from planner.retime import (
    WINDOW_MARGIN_S,
    arrival_targets,
    build_schedule,
    can_loiter_after,
    check_arrival,
    check_feasible,
    clear_of_team,
    retime_vehicle,
)
from planner.scenario import load_scenario, parse_scenario
from planner.schedule import Leg, Schedule, VehicleSchedule
from planner.timing import ArrivalWindow
from tests.planner.conftest import crossing_scenario, small_scenario

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


def test_a_vehicle_whose_natural_arrival_is_outside_its_window_aims_inside_it_by_a_margin() -> None:
    # Both would arrive before their windows at cruise speed (A at about 2167 s, B at about
    # 1496 s): aimed at the earliest edge, any second early in flight would miss the window.
    windows = [
        {"vehicle": "A", "earliest_s": 2200, "latest_s": 2500},
        {"vehicle": "B", "earliest_s": 1900, "latest_s": 1906},
    ]
    s = _small(arrival={"kind": "windows", "windows": windows})
    assert s.vehicle("A").arrival_s == pytest.approx(2200 + WINDOW_MARGIN_S, abs=0.1)
    assert s.vehicle("B").arrival_s == pytest.approx(1903, abs=0.1)  # the narrow window's middle


def test_unreachable_window_names_vehicle_and_shortfall() -> None:
    windows = [
        {"vehicle": "A", "earliest_s": 100, "latest_s": 200},
        {"vehicle": "B", "earliest_s": 1900, "latest_s": 2000},
    ]
    with pytest.raises(InfeasibleError, match=r"vehicle A: .*short by \d+\.\d s"):
        _small(arrival={"kind": "windows", "windows": windows})


def test_in_flight_a_window_that_cannot_be_made_is_timed_to_the_nearest_arrival() -> None:
    """A re-plan in flight (``missed_ok``): A can no longer arrive before 250 s, after its
    window [100, 200] s: it is timed to 250 s and named in the reason; B keeps its window.
    Before launch (the default) the same is refused, naming A."""
    windows = [
        {"vehicle": "A", "earliest_s": 100, "latest_s": 200},
        {"vehicle": "B", "earliest_s": 1900, "latest_s": 2000},
    ]
    scenario = parse_scenario(small_scenario(arrival={"kind": "windows", "windows": windows}))
    reach = [
        ArrivalWindow("A", 250.0, 900.0, "A at its top speed", "A at its slowest"),
        ArrivalWindow("B", 1500.0, 2500.0, "B at its top speed", "B at its slowest"),
    ]
    natural = {"A": 400.0, "B": 1950.0}
    targets, ref, reason = arrival_targets(scenario, reach, None, natural, missed_ok=True)
    assert targets == {"A": 250.0, "B": 1950.0} and ref is None
    assert "cannot make its window, timed to the nearest it can: A (at 250.0 s)" in reason
    with pytest.raises(InfeasibleError, match=r"vehicle A: window \[100, 200\] s cannot be met"):
        arrival_targets(scenario, reach, None, natural)


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


# --- feasibility: the requested arrival and the separation minimum ----------------------


def test_too_early_request_is_moved_by_build_schedule_and_refused_by_check_arrival() -> None:
    s = _small(arrival={"kind": "simultaneous", "required_s": 10})
    # build_schedule keeps its contract: the reference moves to the earliest feasible time.
    assert s.requested_arrival_s == 10
    assert s.required_arrival_s is not None and s.required_arrival_s > 1000
    with pytest.raises(ArrivalTimeError) as info:
        check_arrival(s)
    err = info.value
    assert isinstance(err, InfeasibleError)
    assert err.requested_s == 10
    assert err.earliest_s == pytest.approx(s.required_arrival_s)
    assert err.latest_s >= err.earliest_s
    longest = max(s.vehicles, key=lambda v: v.path.length_m)
    assert err.vehicle == longest.vehicle_id  # the same speed limits: the longest path
    assert str(err).startswith(
        f"requested arrival 10.0 s is too early: earliest feasible {err.earliest_s:.1f} s, "
        f"forced by vehicle {err.vehicle}: {err.vehicle} cannot arrive before"
    )
    with pytest.raises(ArrivalTimeError):
        check_feasible(s)


def test_too_late_request_names_the_vehicle_that_cannot_wait() -> None:
    # No buffer area to loiter in: the latest arrival is the slowest flight of the latest
    # takeoff.
    s = _small(arrival={"kind": "simultaneous", "required_s": 50000})
    with pytest.raises(ArrivalTimeError) as info:
        check_arrival(s)
    err = info.value
    assert err.requested_s == 50000 and err.latest_s < 50000
    assert err.vehicle in ("A", "B") and math.isfinite(err.latest_s)
    assert str(err).startswith(
        f"requested arrival 50000.0 s is too late: latest feasible {err.latest_s:.1f} s, "
        f"forced by vehicle {err.vehicle}: {err.vehicle} cannot arrive after"
    )


def test_too_early_first_spaced_slot_is_refused() -> None:
    s = _small(arrival={"kind": "spaced", "interval_s": 120, "first_s": 100})
    with pytest.raises(ArrivalTimeError, match=r"^requested first arrival 100\.0 s is too early"):
        check_arrival(s)


def test_feasible_request_passes_with_the_team_separation() -> None:
    s = _small(arrival={"kind": "simultaneous", "required_s": 2200})
    check_arrival(s)
    sep = check_feasible(s)
    assert not sep.conflicts and sep.min_separation_m > s.scenario.separation_m
    assert s.team_window is not None
    assert s.team_window.earliest_s <= 2200 <= s.team_window.latest_s


def test_earliest_common_arrival_without_a_request_passes() -> None:
    check_arrival(_small())
    assert _small(arrival={"kind": "windows", "windows": _own_windows()}).team_window is None


def _own_windows() -> list[dict[str, Any]]:
    return [
        {"vehicle": "A", "earliest_s": 2000, "latest_s": 2300},
        {"vehicle": "B", "earliest_s": 1900, "latest_s": 2000},
    ]


def test_same_goal_is_a_separation_error_naming_pair_time_and_distance() -> None:
    data = small_scenario()
    data["vehicles"][1]["goal"] = dict(data["vehicles"][0]["goal"])
    scenario = parse_scenario(data)
    s = build_schedule(scenario, plan(scenario, "astar"))
    with pytest.raises(SeparationError) as info:
        check_feasible(s)
    err = info.value
    assert isinstance(err, InfeasibleError)
    assert err.pair == ("A", "B") and err.required_m == 300 and err.conflicts == 1
    assert err.distance_m < 1.0
    assert s.required_arrival_s is not None
    assert err.time_s == pytest.approx(s.required_arrival_s, abs=1.0)
    assert str(err) == (
        f"vehicles A and B come within {err.distance_m:.1f} m of each other at "
        f"{err.time_s:.1f} s, under the separation minimum d_s 300 m"
    )
    # The operator's override: the conflicts are returned instead.
    sep = check_feasible(s, allow_conflicts=True)
    assert [(c.a, c.b) for c in sep.conflicts] == [("A", "B")]


def test_routes_that_cross_at_the_same_time_are_separated_by_a_takeoff_and_speed() -> None:
    """A flies east and B north across the middle of the map, both 36 km to goals they reach
    together at 1500 s: as timed at cruise speed they cross the middle at the same moment. One
    of them is flown at another cruise speed, taking off earlier or later for the same
    arrival, and the schedule says so; the pair's closest approach, searched on its own,
    keeps d_s."""
    data = crossing_scenario(arrival={"kind": "simultaneous", "required_s": 1500})
    scenario = parse_scenario(data)
    s = build_schedule(scenario, plan(scenario, "astar"))
    (said,) = [e for e in s.events if e.kind == "separation"]
    moved = said.text.split()[0]
    assert moved in ("A", "B") and "under the 300 m separation" in said.text, said.text
    takeoffs = {v.vehicle_id: v.takeoff_s for v in s.vehicles}
    assert takeoffs["A"] != pytest.approx(takeoffs["B"], abs=1.0)  # staggered
    va, vb = s.vehicles
    step = 300.0 / (10.0 * (va.speed_max_m_s + vb.speed_max_m_s))
    assert pair_separation(va, vb, step_s=step).distance_m >= 300.0
    assert va.arrival_s == pytest.approx(vb.arrival_s, abs=1e-6)
    check_feasible(s)
    (takeoff,) = [a for a in s.adjustments if a.vehicle == moved and a.strategy == "takeoff_delay"]
    assert takeoff.reason.endswith(said.text)  # said in flight with the takeoff


@pytest.mark.parametrize("name", ["paper_three_uav.yaml", "paper_spaced_60s.yaml"])
def test_paper_scenarios_are_feasible_as_planned(name: str) -> None:
    scenario = load_scenario(ROOT / "scenarios" / name)
    world = build_world(scenario)
    s = build_schedule(scenario, plan(scenario, "aco", rng=np.random.default_rng(1)), world=world)
    sep = check_feasible(s)
    assert sep.min_separation_m > 1400 and scenario.separation_m == 500


def test_infeasibility_errors_survive_pickling() -> None:
    errors: list[InfeasibleError] = [
        ArrivalTimeError("a", vehicle="A", requested_s=1.0, earliest_s=2.0, latest_s=math.inf),
        SeparationError("b", pair=("A", "B"), time_s=3.0, distance_m=4.0, required_m=5.0),
        InfeasibleError("c", vehicle="C"),
    ]
    for err in errors:
        back = pickle.loads(pickle.dumps(err))
        assert type(back) is type(err) and str(back) == str(err)
        assert back.__dict__ == err.__dict__


def test_team_time_moved_after_the_build_is_refused_without_blaming_a_vehicle(
    paper: tuple[Schedule, Schedule],
) -> None:
    """A schedule whose team time a pop-up re-plan moved no longer holds a request."""
    _, after = paper
    assert after.required_arrival_s is not None
    requested = after.required_arrival_s - 100.0
    assert after.team_window is not None and after.team_window.earliest_s <= requested
    moved = replace(after, requested_arrival_s=requested)
    with pytest.raises(ArrivalTimeError) as info:
        check_arrival(moved)
    assert info.value.vehicle is None and info.value.requested_s == requested
    assert str(info.value).startswith(
        f"requested arrival {requested:.1f} s is not held: the team arrives at "
        f"{after.required_arrival_s:.1f} s ("
    )


def _airborne_surplus(data: dict[str, Any]) -> tuple[Schedule, float, float, Any]:
    """Vehicle A 3 km along its route at 1000 s, with 600 s more than its minimum speed
    takes to the goal: ``(schedule, s_m, target_s, world)``."""
    scenario = parse_scenario(data)
    world = build_world(scenario)
    s = build_schedule(scenario, plan(scenario, "astar"), world=world)
    vs = s.vehicle("A")
    s0 = 3_000.0
    slowest = (vs.path.length_m - s0) / vs.tas_per_eas(s0) / scenario.vehicle("A").speed_min_m_s
    return s, s0, 1_000.0 + slowest + 600.0, world


def test_a_surplus_no_buffer_absorbs_gets_turns_on_the_path_clear_of_threats_and_terrain() -> None:
    s, s0, target, world = _airborne_surplus(small_scenario())
    zones = list(world.threats)
    with pytest.raises(InfeasibleError, match="no buffer"):
        retime_vehicle(
            s, "A", now_s=1_000.0, s_m=s0, speed_m_s=20.0, target_s=target, threats=zones
        )
    # Ground 10 km high west of 9 km east: no circle may reach over it.
    wall = _Wall(9_000.0)
    vs, adjustments = retime_vehicle(
        s, "A", now_s=1_000.0, s_m=s0, speed_m_s=20.0, target_s=target, threats=zones,
        terrain=wall,
    )  # fmt: skip
    (lo,) = vs.loiters
    assert lo.buffer_id == "path" and lo.detour_m == 0.0
    assert vs.arrival_s == pytest.approx(target, abs=0.5)
    assert any("on the path" in a.reason for a in adjustments if a.strategy == "loiter")
    # The circle, checked here: tangent to the path, 2 radii clear of the SAM disc, and the
    # ground under it (72 points) at least the clearance below the loiter's altitude.
    p = vs.path.pose_at(lo.s_m)
    assert math.hypot(p.east_m - lo.centre_east_m, p.north_m - lo.centre_north_m) == (
        pytest.approx(lo.radius_m)
    )
    assert math.hypot(lo.centre_east_m - 20_000.0, lo.centre_north_m - 20_000.0) >= (
        6_000.0 + 2.0 * lo.radius_m
    )
    assert lo.centre_east_m - lo.radius_m >= 9_000.0
    a = np.linspace(0.0, 2.0 * math.pi, 72)
    ground = wall.elevation_m(
        lo.centre_east_m + lo.radius_m * np.cos(a), lo.centre_north_m + lo.radius_m * np.sin(a)
    )
    clearance = s.scenario.vehicle("A").clearance_m
    assert float(ground.max()) + clearance <= vs.alt_at(lo.s_m) + 1.0
    # On flat ground the first clear point after the lead is taken: nearer.
    flat, _ = retime_vehicle(
        s, "A", now_s=1_000.0, s_m=s0, speed_m_s=20.0, target_s=target, threats=zones,
        terrain=world.terrain,
    )  # fmt: skip
    assert flat.loiters[0].s_m < lo.s_m


def _parked(vehicle_id: str, east_m: float, north_m: float) -> VehicleSchedule:
    """A team member at one point the whole time (a metre of path over 5,000 s)."""
    path = straight(east_m, north_m, east_m + 1.0, north_m)
    leg = Leg(0.0, 1.0, 20.0, 0.0, 5_000.0)
    return VehicleSchedule(
        vehicle_id, path, np.array([0.0, 1.0]), np.array([500.0, 500.0]), 0.0, 5_000.0,
        (leg,), (), 18.0, 30.0, True,
    )  # fmt: skip


def test_loiter_turns_in_flight_keep_the_separation_from_the_team() -> None:
    """Turns whose circle would come within the separation of where another team member will
    be go elsewhere on the path (checked here from the circle's geometry); with nowhere left,
    the re-time is refused and says why."""
    s, s0, target, world = _airborne_surplus(small_scenario())
    zones = list(world.threats)
    kw: dict[str, Any] = {
        "now_s": 1_000.0, "s_m": s0, "speed_m_s": 20.0, "target_s": target, "threats": zones,
        "terrain": world.terrain,
    }  # fmt: skip
    alone, _ = retime_vehicle(s, "A", **kw)
    (first,) = alone.loiters
    # Someone at the far side of that circle.
    ux = first.centre_east_m - first.entry_east_m
    uy = first.centre_north_m - first.entry_north_m
    parked = _parked("X", first.centre_east_m + ux, first.centre_north_m + uy)
    crowded = replace(s, vehicles=(*s.vehicles, parked))  # type: ignore[arg-type]
    required = s.scenario.separation_m
    assert loiter_conflict(alone, [parked], required, 1_000.0) is not None
    unseparated, _ = retime_vehicle(crowded, "A", **kw)
    assert unseparated.loiters[0].s_m == first.s_m  # without separate, the same place
    vs, _ = retime_vehicle(crowded, "A", separate=True, **kw)
    (lo,) = vs.loiters
    spot = parked.path.start
    gap = math.hypot(lo.centre_east_m - spot.east_m, lo.centre_north_m - spot.north_m)
    assert gap - lo.radius_m >= required
    assert loiter_conflict(vs, [parked], required, 1_000.0) is None
    assert vs.arrival_s == pytest.approx(target, abs=0.5)
    # Members every 500 m along the path: no circle tangent to it keeps 300 m from them all.
    poses = [vs.path.pose_at(float(d)) for d in np.arange(0.0, vs.path.length_m, 500.0)]
    everywhere = [_parked(f"X{k}", p.east_m, p.north_m) for k, p in enumerate(poses)]
    jammed = replace(s, vehicles=(*s.vehicles, *everywhere))  # type: ignore[arg-type]
    with pytest.raises(InfeasibleError, match=r"A.*team's tracks left out") as info:
        retime_vehicle(jammed, "A", separate=True, **kw)
    assert info.value.vehicle == "A"


class _Wall:
    """Terrain 10 km high west of ``east_m``, at 100 m east of it."""

    def __init__(self, east_m: float) -> None:
        self.east_m = east_m

    def elevation_m(self, east_m: Any, north_m: Any) -> Any:
        e = np.asarray(east_m, dtype=np.float64)
        return np.where(e < self.east_m, 10_000.0, 100.0) + 0.0 * np.asarray(north_m)


def test_no_turns_on_the_path_where_a_threat_covers_it() -> None:
    s, s0, target, world = _airborne_surplus(small_scenario())
    # A radar disc (not forbidden) over the whole map: nowhere 2 radii clear of it to circle.
    data = small_scenario()
    data["threats"] = [
        {"kind": "radar", "id": "WIDE", "center": {"east_m": 20000, "north_m": 20000},
         "radius_m": 30000, "forbidden": False},
    ]  # fmt: skip
    wide = list(build_world(parse_scenario(data)).threats)
    with pytest.raises(InfeasibleError, match="no buffer"):
        retime_vehicle(
            s, "A", now_s=1_000.0, s_m=s0, speed_m_s=20.0, target_s=target, threats=wide,
            terrain=world.terrain,
        )  # fmt: skip


def test_where_loiter_turns_fit_is_judged_as_the_loiter_job_puts_them(
    paper: tuple[Schedule, Schedule],
) -> None:
    """How late a vehicle could still arrive, for a move of the team time, depends on whether
    loiter turns fit ahead of it (:func:`can_loiter_after`): judged with the same keep-clear
    check the loiter job (:func:`retime_vehicle` with ``separate``) puts its circles by, the
    two agree along every path; with a check that refuses every circle, no turns fit (a move
    of the team time was once accepted that the loiter job then could not follow: it left out
    the sites near the team's tracks, the judgement did not)."""
    before, _ = paper
    scenario = before.scenario
    world = build_world(scenario)
    for vs in before.vehicles:
        v = scenario.vehicle(vs.vehicle_id)
        for f in np.linspace(0.05, 0.95, 7):
            now_s = vs.climb_end_s + f * (vs.arrival_s - vs.climb_end_s)
            _, s_m, _ = vs.state_at(now_s)
            clear = clear_of_team(before, vs.vehicle_id, now_s)
            fits = can_loiter_after(scenario, v, vs, s_m, [], world.terrain, clear)
            try:
                retime_vehicle(
                    before, vs.vehicle_id, now_s=now_s, s_m=s_m, speed_m_s=v.cruise_m_s,
                    target_s=vs.arrival_s + 300.0, threats=[], terrain=world.terrain,
                    separate=True,
                )  # fmt: skip
                flown = True
            except InfeasibleError:
                flown = False
            assert fits == flown, (vs.vehicle_id, f, fits, flown)
            assert not can_loiter_after(
                scenario, v, vs, s_m, [], world.terrain, lambda e, n, r: False
            )

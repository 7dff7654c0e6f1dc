"""Timing: windows, team arrival, discrete speeds and loiter turns (section 4)."""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from planner.errors import InfeasibleError
from planner.timing import (
    MIN_PIECE_M,
    ArrivalWindow,
    LoiterSite,
    SpeedLimits,
    Timing,
    flyable_loiter_radius_m,
    speed_grid,
    split_speeds,
    takeoff_time_s,
    team_arrival,
    time_path,
    vehicle_window,
)

LIM = SpeedLimits(20.0, 30.0, 25.0)


def _on_grid(v: float, step: float = 0.5) -> bool:
    return abs(v / step - round(v / step)) < 1e-9


def test_speed_grid_holds_both_ends_and_the_steps() -> None:
    assert speed_grid(15.0, 17.0, 0.5) == (15.0, 15.5, 16.0, 16.5, 17.0)
    assert speed_grid(15.2, 16.0, 0.5) == (15.2, 15.5, 16.0)


def test_cruise_time_is_one_leg() -> None:
    timing = time_path("A", 25_000.0, 1000.0, LIM)
    assert [(p.length_m, p.speed_m_s) for p in timing.pieces] == [(25_000.0, 25.0)]
    assert timing.turns == 0


def test_two_adjacent_speeds_hit_the_time_exactly() -> None:
    pieces = split_speeds(25_000.0, 990.0, LIM)
    assert sorted({p.speed_m_s for p in pieces}) == [25.0, 25.5]
    assert math.fsum(p.duration_s for p in pieces) == pytest.approx(990.0, abs=1e-6)
    assert math.fsum(p.length_m for p in pieces) == pytest.approx(25_000.0)


def test_first_piece_keeps_the_speed_nearer_the_current_one() -> None:
    assert split_speeds(25_000.0, 990.0, LIM, current_m_s=26.0)[0].speed_m_s == 25.5
    assert split_speeds(25_000.0, 990.0, LIM, current_m_s=24.0)[0].speed_m_s == 25.0


def test_loiter_known_answer() -> None:
    # 20 km in 1100 s: at 20 m/s the vehicle is 100 s early = 2000 m to add; r = 300 m turns
    # add 1885 m each, so 2 turns (1 would leave 115 m for the speed range to absorb: no).
    site = LoiterSite(at_m=10_000.0, radius_m=300.0)
    timing = time_path("A", 20_000.0, 1100.0, LIM, site=site)
    assert timing.turns == 2
    assert timing.added_m == pytest.approx(2 * 2 * math.pi * 300.0)
    assert timing.duration_s == pytest.approx(1100.0, abs=1e-6)


def test_too_little_time_names_vehicle_and_shortfall() -> None:
    with pytest.raises(InfeasibleError, match=r"vehicle UAV2: .*short by 100\.0 s"):
        time_path("UAV2", 30_000.0, 900.0, LIM)


def test_too_much_time_without_buffer_names_vehicle_and_shortfall() -> None:
    with pytest.raises(InfeasibleError, match=r"vehicle UAV3: .*no buffer.*short by 250\.0 s"):
        time_path("UAV3", 20_000.0, 1250.0, LIM)


def test_loiter_radius_is_one_ardupilot_stores() -> None:
    assert flyable_loiter_radius_m(250.0) == 250.0
    assert flyable_loiter_radius_m(250.2) == 251.0
    assert flyable_loiter_radius_m(301.0) == 310.0


def test_takeoff_by_eq5_clipped_to_window() -> None:
    assert takeoff_time_s(50_000.0, 3000.0, LIM, (0.0, 3600.0)) == 1000.0
    assert takeoff_time_s(100_000.0, 3000.0, LIM, (0.0, 3600.0)) == 0.0


def test_window_on_ground_airborne_and_with_loiter() -> None:
    w = vehicle_window("A", now_s=0.0, remaining_m=30_000.0, limits=LIM, takeoff_window_s=(0, 600))
    assert (w.t_min_s, w.t_max_s) == (1000.0, 2100.0)
    w = vehicle_window("A", now_s=100.0, remaining_m=30_000.0, limits=LIM)
    assert (w.t_min_s, w.t_max_s) == (1100.0, 1600.0)
    w = vehicle_window("A", now_s=100.0, remaining_m=30_000.0, limits=LIM, can_loiter=True)
    assert w.t_max_s == math.inf


def _w(vid: str, lo: float, hi: float) -> ArrivalWindow:
    return ArrivalWindow(vid, lo, hi, f"{vid} early", f"{vid} late")


def test_team_arrival_keeps_a_feasible_request() -> None:
    t, reason = team_arrival([_w("A", 100, 300), _w("B", 150, 400)], 200.0)
    assert t == 200.0 and "feasible" in reason


def test_team_arrival_moves_to_the_earliest_common_time_naming_the_vehicle() -> None:
    t, reason = team_arrival([_w("A", 100, 300), _w("B", 250, 400)], 200.0)
    assert t == 250.0 and "B early" in reason


def test_spaced_arrivals_shift_the_windows() -> None:
    t, _ = team_arrival([_w("A", 100, 300), _w("B", 250, 400)], None, offsets_s={"B": 100.0})
    assert t == 150.0


def test_disjoint_windows_name_the_vehicle_and_shortfall() -> None:
    with pytest.raises(InfeasibleError, match=r"vehicle A: .*short by 50\.0 s"):
        team_arrival([_w("A", 100, 200), _w("B", 250, 400)], None)


def _fewest_timed_turns(
    length_m: float, duration_s: float, limits: SpeedLimits, site: LoiterSite
) -> int | None:
    """The fewest loiter turns that two grid speeds fly with the path in ``duration_s``, by
    trying every speed pair at every turn count that fits the speed range; None if none can.

    The path is flown at one speed up to a change point and at the other after it; the
    loiter (and its detour) at the speed of the path leading to it, so the change comes
    after the loiter point or at least ``MIN_PIECE_M`` before it. The time is linear in the
    change point, so each pair reaches the times between those at the ends of its range.
    """
    grid = speed_grid(limits.speed_min_m_s, limits.speed_max_m_s, limits.step_m_s)
    tol_s = 1e-9
    per_turn_m = 2 * math.pi * site.radius_m
    turns = 1
    while length_m + site.detour_m + turns * per_turn_m <= duration_s * limits.speed_max_m_s:
        loiter_m = site.detour_m + turns * per_turn_m
        if (length_m + loiter_m) / limits.speed_min_m_s < duration_s - tol_s:
            turns += 1
            continue
        for first_m_s in grid:
            for second_m_s in grid:
                # Change at or after the loiter point: the loiter at the first speed.
                ranges_m = [(site.at_m, length_m, first_m_s)]
                if site.at_m >= MIN_PIECE_M:
                    # Change before it: the loiter at the second speed.
                    ranges_m.append((0.0, site.at_m - MIN_PIECE_M, second_m_s))
                for lo_m, hi_m, loiter_m_s in ranges_m:
                    times_s = [
                        change_m / first_m_s
                        + (length_m - change_m) / second_m_s
                        + loiter_m / loiter_m_s
                        for change_m in (lo_m, hi_m)
                    ]
                    if min(times_s) - tol_s <= duration_s <= max(times_s) + tol_s:
                        return turns
        turns += 1
    return None


def _check_timing(timing: Timing, length_m: float, duration_s: float, limits: SpeedLimits) -> None:
    """Flies ``duration_s`` within 0.1 s and the whole path, every speed on the grid."""
    assert abs(timing.duration_s - duration_s) < 0.1
    legs_m = math.fsum(p.length_m for p in timing.pieces if p.kind == "leg")
    assert legs_m == pytest.approx(length_m)
    for p in timing.pieces:
        assert limits.speed_min_m_s <= p.speed_m_s <= limits.speed_max_m_s
        assert _on_grid(p.speed_m_s)


def test_one_more_turn_when_the_fewest_cannot_be_timed() -> None:
    # 3.1 km in 855 s at 10-11 m/s, loiters of 100 m radius 900 m along. 9 turns (5655 m)
    # are the fewest: flown at 10 m/s with the first 900 m and the rest at 11 m/s they take
    # 855.5 s at the least; at 10.5 m/s with only the first 895 m at 10 m/s, 838.1 s at the
    # most. 10 turns: the loiter at 11 m/s, some of the first 895 m at 10.5 m/s.
    limits = SpeedLimits(10.0, 11.0, 10.5)
    site = LoiterSite(at_m=900.0, radius_m=100.0)
    assert _fewest_timed_turns(3100.0, 855.0, limits, site) == 10
    timing = time_path("V", 3100.0, 855.0, limits, site=site)
    assert timing.turns == 10
    assert timing.added_m == pytest.approx(10 * 2 * math.pi * 100.0)
    _check_timing(timing, 3100.0, 855.0, limits)


def test_no_turn_count_times_a_loiter_part_way_along() -> None:
    # 3142 m in 609 s at 10-11 m/s, loiters of 100 m radius 1500 m along: 5 turns (3142 m,
    # no longer than the path) take at least 613.4 s at 10 m/s (the 1642 m after the loiter
    # at 11 m/s) and at most 605.6 s at 10.5 m/s (the first 1495 m at 10 m/s); 6 turns would
    # need 6912 m in 609 s, above 11 m/s.
    limits = SpeedLimits(10.0, 11.0, 10.5)
    site = LoiterSite(at_m=1500.0, radius_m=100.0)
    assert _fewest_timed_turns(3142.0, 609.0, limits, site) is None
    with pytest.raises(
        InfeasibleError, match=r"vehicle V: no pair of discrete speeds flies 5 loiter turns"
    ):
        time_path("V", 3142.0, 609.0, limits, site=site)


@st.composite
def _cases(draw: st.DrawFn) -> tuple[SpeedLimits, float, float, LoiterSite | None]:
    vmin = draw(st.integers(20, 40)) * 0.5
    vmax = vmin + draw(st.integers(2, 30)) * 0.5
    limits = SpeedLimits(vmin, vmax, 0.5 * (vmin + vmax))
    length = draw(st.floats(2_000.0, 200_000.0))
    # Anything from the fastest time to three times the slowest.
    duration = draw(st.floats(length / vmax, 3.0 * length / vmin))
    site = None
    if draw(st.booleans()) or duration > length / vmin:
        site = LoiterSite(
            at_m=draw(st.floats(0.0, length)),
            radius_m=draw(st.floats(100.0, 600.0)),
            detour_m=draw(st.sampled_from([0.0, 1500.0])),
        )
    return limits, length, duration, site


@settings(max_examples=300, deadline=None)
@given(_cases())
@example((SpeedLimits(10.0, 11.0, 10.5), 3142.0, 609.0, LoiterSite(1500.0, 100.0)))
@example((SpeedLimits(10.0, 11.0, 10.5), 3100.0, 855.0, LoiterSite(900.0, 100.0)))
def test_timing_properties(case: tuple[SpeedLimits, float, float, LoiterSite | None]) -> None:
    limits, length, duration, site = case
    try:
        timing = time_path("V", length, duration, limits, site=site)
    except InfeasibleError as err:
        assert site is not None
        # The loiter is flown at one speed and only the legs trim the time: no turn count
        # that fits the speed range can be flown in the duration at two grid speeds.
        assert _fewest_timed_turns(length, duration, limits, site) is None
        if "no pair of discrete speeds" not in str(err):
            # Whole turns overshoot the speed range.
            per_turn = 2 * math.pi * site.radius_m
            lo = (duration * limits.speed_min_m_s - length - site.detour_m) / per_turn
            hi = (duration * limits.speed_max_m_s - length - site.detour_m) / per_turn
            assert math.floor(hi) < max(1, math.ceil(lo))
        return
    _check_timing(timing, length, duration, limits)
    slowest = length / limits.speed_min_m_s
    # Loiter only when the speed range cannot absorb the surplus ...
    assert (timing.turns > 0) == (duration > slowest + 1e-6)
    if timing.turns:
        assert site is not None
        # ... with the fewest turns two grid speeds can fly in the duration.
        assert timing.turns == _fewest_timed_turns(length, duration, limits, site)

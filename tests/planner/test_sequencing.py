"""Separation for crowds at plan time: approach points shared out (planner.goals), the team
placed in time one vehicle at a time (planner.sequencing) and the team time moved later when
the vehicles in conflict have no room at the earliest one (planner.retime.build_schedule).

Every verdict on separation is the pair's own closest-approach search
(:func:`planner.deconflict.pair_separation`), not the grid the scheduler decides on."""

from __future__ import annotations

import itertools
import math
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from planner import layers, sequencing
from planner.deconflict import TeamSamples, pair_separation
from planner.errors import ScenarioError, SeparationError
from planner.goals import assign_goals
from planner.plan import Plan, build_world, plan
from planner.retime import build_schedule, check_feasible
from planner.scenario import Scenario, parse_scenario
from planner.schedule import Schedule
from tests.planner.conftest import crossing_scenario, small_scenario

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
from bench_planner import team_scenario  # noqa: E402  (the planner bench's generated teams)


def _min_pair_separation_m(s: Schedule) -> tuple[float, tuple[str, str]]:
    """Every pair searched on its own, at a tenth of d_s of relative motion per sample."""
    best, pair = math.inf, ("", "")
    d_s = s.scenario.separation_m
    for a, b in itertools.combinations(s.vehicles, 2):
        step = d_s / (10.0 * (a.speed_max_m_s + b.speed_max_m_s))
        d = pair_separation(a, b, step_s=step).distance_m
        if d < best:
            best, pair = d, (a.vehicle_id, b.vehicle_id)
    return best, pair


@pytest.mark.parametrize("seed", range(5))
def test_shared_goals_are_the_least_sum_of_squares_and_routes_flown_in_step_keep_apart(
    seed: int,
) -> None:
    """Against every permutation of 6 goals; and, for 30 vehicles, straight routes flown in
    step (each at the same fraction of its route) never come closer than the smallest start
    or goal spacing over sqrt(2) (CAPT's guarantee), sampled in time."""
    rng = np.random.default_rng(seed)
    starts = [tuple(p) for p in rng.uniform(0, 50_000, (6, 2))]
    goals = [tuple(p) for p in rng.uniform(0, 50_000, (6, 2))]
    order = assign_goals(starts, goals)
    assert sorted(order) == list(range(6))

    def cost(perm: tuple[int, ...] | list[int]) -> float:
        return sum(math.dist(starts[i], goals[k]) ** 2 for i, k in enumerate(perm))

    assert cost(order) == pytest.approx(min(cost(p) for p in itertools.permutations(range(6))))

    s = rng.uniform(0, 100_000, (30, 2))
    g = rng.uniform(40_000, 60_000, (30, 2))
    spacing = min(min(math.dist(p, q) for p, q in itertools.combinations(pts, 2)) for pts in (s, g))
    order = assign_goals([tuple(p) for p in s], [tuple(p) for p in g])
    f = np.linspace(0.0, 1.0, 2001)[:, None, None]
    pos = (1 - f) * s[None] + f * g[order][None]  # (time, vehicle, xy)
    d = np.linalg.norm(pos[:, :, None, :] - pos[:, None, :, :], axis=-1)
    d[:, np.arange(30), np.arange(30)] = np.inf
    assert d.min() >= spacing / math.sqrt(2) - 1e-6
    # As drawn (each start to the goal of its index), some such pair comes closer.
    drawn = (1 - f) * s[None] + f * g[None]
    d = np.linalg.norm(drawn[:, :, None, :] - drawn[:, None, :, :], axis=-1)
    d[:, np.arange(30), np.arange(30)] = np.inf
    assert d.min() < spacing / math.sqrt(2)


def test_a_scenario_with_assigned_goals_plans_the_goals_shared_out_the_same_on_reading_again() -> (
    None
):
    data = team_scenario(12, seed=3)
    drawn = [(v["goal"]["east_m"], v["goal"]["north_m"]) for v in data["vehicles"]]
    scenario = parse_scenario(data)
    got = [(v.goal.east_m, v.goal.north_m) for v in scenario.vehicles]
    assert sorted(got) == sorted(drawn)  # the same points
    assert got != drawn  # shared out otherwise than drawn
    again = parse_scenario(scenario.model_dump(mode="json", exclude_none=True))
    assert [v.goal for v in again.vehicles] == [v.goal for v in scenario.vehicles]
    fixed = parse_scenario(team_scenario(12, seed=3, assign_goals=False))
    assert [(v.goal.east_m, v.goal.north_m) for v in fixed.vehicles] == drawn
    # The flag as the field reads it: "true" or 1 share the goals out as true does.
    for flag in ("true", 1):
        loose = parse_scenario(team_scenario(12, seed=3) | {"assign_goals": flag})
        assert loose.assign_goals and [v.goal for v in loose.vehicles] == [
            v.goal for v in scenario.vehicles
        ]


def test_assigned_goals_are_refused_with_landing_slots() -> None:
    data = small_scenario(threats=[], assign_goals=True)
    data["landing"] = {
        "touchdown": {"east_m": 39000, "north_m": 39000, "alt_m": 100},
        "heading_deg": 45,
    }
    with pytest.raises(ScenarioError, match="assign_goals: not with landing slots"):
        parse_scenario(data)


def _crossing(**arrival: Any) -> dict[str, Any]:
    """A flies east and B north, 36 km each, crossing in the middle; both may take off in
    [0, 600] s."""
    data = crossing_scenario(arrival={"kind": "simultaneous", **arrival})
    for v in data["vehicles"]:
        v["takeoff_window_s"] = [0, 600]
    return data


def test_a_pair_with_no_room_at_the_earliest_time_is_separated_by_a_later_team_time() -> None:
    """At the earliest common arrival both take off at once at their top speed and cross the
    middle together: neither can move. The team time moves a minute later, one of them flies
    another speed, and the arrival reason says why."""
    scenario = parse_scenario(_crossing())
    s = build_schedule(scenario, plan(scenario, "astar"))
    assert s.required_arrival_s is not None and s.team_window is not None
    assert "s later to keep the 300 m separation (1 pair too close at" in s.arrival_reason
    assert [e for e in s.events if e.kind == "separation"]
    d, _ = _min_pair_separation_m(s)
    assert d >= 300.0
    a, b = s.vehicles
    assert a.arrival_s == pytest.approx(b.arrival_s, abs=1e-6) == s.required_arrival_s
    assert s.required_arrival_s == pytest.approx(s.team_window.earliest_s + 60.0, abs=1e-6)
    check_feasible(s)


def test_a_requested_time_is_not_moved_for_the_separation_and_the_pair_is_refused() -> None:
    scenario = parse_scenario(_crossing())
    first = build_schedule(scenario, plan(scenario, "astar"))
    assert first.required_arrival_s is not None
    earliest = float(first.team_window.earliest_s) if first.team_window else math.nan
    asked = parse_scenario(_crossing(required_s=math.ceil(earliest)))
    s = build_schedule(asked, plan(asked, "astar"))
    assert s.required_arrival_s == pytest.approx(math.ceil(earliest))
    with pytest.raises(SeparationError) as info:
        check_feasible(s)
    assert set(info.value.pair) == {"A", "B"}


@pytest.mark.slow  # several seconds: left out of make test-quick
@pytest.mark.parametrize(("n", "assign"), [(10, True), (30, True), (30, False)])
def test_the_planner_bench_teams_are_separated_with_their_approach_points_shared_out(
    n: int, assign: bool
) -> None:
    """The teams of ``bench/bench_planner.py`` (launch sites on the west and south edges,
    approach points on rings around the target; no altitude layer): with the points shared
    out, every pair keeps d_s; with each vehicle held to the point drawn for it, routes cross
    next to the goals (where simultaneous arrivals cannot be told apart by time) and the
    schedule is refused naming a pair."""
    data = team_scenario(n, seed=0, assign_goals=assign, altitude_layers_m=())
    scenario = parse_scenario(data)
    world = build_world(scenario)
    planned = plan(scenario, "aco", rng=np.random.default_rng(0), world=world)
    s = build_schedule(scenario, planned, world=world)
    d, pair = _min_pair_separation_m(s)
    if assign:
        assert d >= scenario.separation_m, pair
        check_feasible(s)
    else:
        assert d < scenario.separation_m
        with pytest.raises(SeparationError, match="under the separation minimum"):
            check_feasible(s)


def test_a_pair_that_met_before_a_re_plans_start_is_not_timed_again() -> None:
    """Timed for a requested time, A and B cross the middle together. From a start after
    they have met, the timing sees no conflict and asks for no other timing; from a start
    before it, it does."""
    scenario = parse_scenario(_crossing())
    first = build_schedule(scenario, plan(scenario, "astar"))
    earliest = float(first.team_window.earliest_s) if first.team_window else math.nan
    asked = parse_scenario(_crossing(required_s=math.ceil(earliest)))
    a, b = build_schedule(asked, plan(asked, "astar")).vehicles
    met = pair_separation(a, b, step_s=0.1)
    assert met.distance_m < 300.0
    asked_for: list[str] = []

    def alternatives(vid: str) -> list[tuple[Any, None]]:
        asked_for.append(vid)
        return []

    slack = {"A": 60.0, "B": 60.0}
    moved, sep = sequencing.sequence_team(
        [a, b], 300.0, slack_s=slack, alternatives=alternatives, from_s=met.time_s + 120.0
    )
    assert not moved and not sep.conflicts and not asked_for
    moved, sep = sequencing.sequence_team(
        [a, b], 300.0, slack_s=slack, alternatives=alternatives, from_s=met.time_s - 120.0
    )
    assert [(p.a, p.b) for p in sep.conflicts] == [("A", "B")] and asked_for


def _separated_only_with(
    monkeypatch: pytest.MonkeyPatch,
    scenario: Scenario,
    switch_off: Callable[[pytest.MonkeyPatch], None],
    *,
    seed: int,
) -> tuple[Schedule, Schedule, Plan]:
    """The team planned, then timed with a part of the search switched off (``switch_off``)
    and some pair under d_s; then timed with it (the switch undone) and every pair keeping
    d_s, feasible, each vehicle arriving at the team time, taking off in its window, at
    speeds in its range. Both schedules, and the plan."""
    world = build_world(scenario)
    planned = plan(scenario, "aco", rng=np.random.default_rng(seed), world=world)
    switch_off(monkeypatch)
    partial = build_schedule(scenario, planned, world=world)
    d, pair = _min_pair_separation_m(partial)
    assert d < scenario.separation_m, pair
    monkeypatch.undo()
    s = build_schedule(scenario, planned, world=world)
    d, pair = _min_pair_separation_m(s)
    assert d >= scenario.separation_m, pair
    check_feasible(s)
    assert s.required_arrival_s is not None
    for v, vs in zip(scenario.vehicles, s.vehicles, strict=True):
        assert vs.arrival_s == pytest.approx(s.required_arrival_s, abs=0.5), v.id
        assert vs.takeoff_s >= v.takeoff_window_s[0] - 1e-6, v.id
        for leg in vs.legs:
            assert v.speed_min_m_s - 1e-9 <= leg.speed_m_s <= v.speed_max_m_s + 1e-9, v.id
    return partial, s, planned


@pytest.mark.slow  # several seconds: left out of make test-quick
def test_the_first_pass_leaves_a_crowd_in_conflict_and_the_repair_separates_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """30 vehicles of the planner bench (seed 1, no altitude layer): placed in one pass, some
    pairs stay under d_s; the local search after it moves vehicles to their other timings
    until every pair keeps d_s. Each still arrives at the team time, at speeds in its range."""
    scenario = parse_scenario(team_scenario(30, seed=1, altitude_layers_m=()))
    one_pass, s, _ = _separated_only_with(
        monkeypatch, scenario, lambda m: m.setattr(sequencing, "REPAIR_ROUNDS", 0), seed=1
    )
    moved = [e.text for e in s.events if e.kind == "separation"]
    assert len(moved) > len([e for e in one_pass.events if e.kind == "separation"])


@pytest.mark.slow  # several seconds: left out of make test-quick
def test_a_crowd_the_pairwise_lifts_leave_too_close_is_timed_on_lanes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """50 vehicles of the planner bench (seed 1, the bench's 600 m layer): timed on their
    own profiles and lifted pair by pair afterwards, some pairs stay under d_s; with each
    vehicle's timings on the layer (over the end of its path) among those the placement
    tries, every pair keeps d_s in 3-D. The lanes keep above the planned profiles and under
    the ceiling, and every vehicle arrives at the team time at speeds in its range."""
    scenario = parse_scenario(team_scenario(50, seed=1))
    _, s, planned = _separated_only_with(
        monkeypatch, scenario, lambda m: m.setattr(layers, "LANE_STRETCHES_M", ()), seed=1
    )
    on_lanes = [  # said with the speed it is timed at (a lift pair by pair "flies")
        e.text
        for e in s.events
        if "600 m above its profile from" in e.text and e.text.split()[1] in ("cruises", "keeps")
    ]
    assert on_lanes, [e.text for e in s.events if e.kind == "separation"]
    for v, vs, route in zip(scenario.vehicles, s.vehicles, planned.routes, strict=True):
        profile = np.interp(vs.wp_s_m, route.profile.s_m, route.profile.alt_m)
        assert (vs.wp_alt_m >= profile - 1e-6).all(), v.id
        assert (vs.wp_alt_m <= max(v.alt_max_m, float(profile.max())) + 1e-6).all(), v.id


@pytest.mark.parametrize("below_m", [550.0, 5_000.0, 50_000.0])
def test_a_tracks_shortfall_from_the_team_is_the_sum_over_every_sample(below_m: float) -> None:
    """:meth:`TeamSamples.shortfall_m`, ``closest(within_m=)`` and ``too_close`` compare sample
    by sample only where the blocks' extents come near: the same figures as every sample of
    every other vehicle compared."""
    scenario = parse_scenario(team_scenario(10, seed=0))
    s = build_schedule(scenario, plan(scenario, "aco", rng=np.random.default_rng(0)))
    samples = TeamSamples(s.vehicles, scenario.separation_m)
    for k, vs in enumerate(s.vehicles):
        track = samples.track(vs)
        gaps = np.sqrt(((samples.planes - track[:, None, :]) ** 2).sum(axis=0))
        gaps = np.where(np.isnan(gaps), np.inf, gaps).min(axis=1)
        gaps[k] = np.inf
        expected = float(np.maximum(0.0, below_m - gaps).sum())
        assert samples.shortfall_m(vs.vehicle_id, track, below_m) == pytest.approx(
            expected, rel=1e-9, abs=1e-6
        )
        if below_m > 5_000.0:
            assert expected > 0.0  # the test compares something
        # The closest approach under below_m, and who comes that near, as every sample finds.
        d, who, t = samples.closest(vs, within_m=below_m)
        j = int(gaps.argmin())
        if gaps[j] < below_m:
            assert (d, who) == (pytest.approx(gaps[j]), samples.ids[j])
            i = int(np.argmin(np.abs(samples.t_s - t)))
            assert np.linalg.norm(samples.planes[:, j, i] - track[:, i]) == pytest.approx(d)
        else:
            assert (d, who) == (math.inf, None)
        assert samples.too_close(vs, below_m) == {
            samples.ids[i] for i in np.flatnonzero(gaps < below_m)
        }


def test_a_vehicles_alternatives_asked_again_are_made_once_and_come_in_the_same_order() -> None:
    """The first pass asks for a vehicle's timings until one is clear, the repair for all of
    them: each timing is made once (a re-plan's is a re-timing), as many as are reached, and
    both see them in the caller's order."""
    made: list[tuple[str, int]] = []

    def alternatives(vid: str) -> Iterator[tuple[Any, int]]:
        for k in range(4):
            made.append((vid, k))
            yield object(), k

    remembered = sequencing._Remembered(alternatives)
    first = remembered("A")
    assert [next(first)[1], next(first)[1]] == [0, 1]  # the first pass stops at a clear one
    assert made == [("A", 0), ("A", 1)]
    again = [chosen for _, chosen in remembered("A")]
    assert again == [0, 1, 2, 3] and made == [("A", k) for k in range(4)]
    assert [chosen for _, chosen in remembered("A")] == [0, 1, 2, 3] and len(made) == 4
    assert next(remembered("B"))[1] == 0 and made[-1] == ("B", 0)
    objects = [o for o, _ in remembered("A")]
    assert objects == [o for o, _ in remembered("A")]  # the very same timings

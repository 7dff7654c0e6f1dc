"""Tests of planner.coupling's team-wide separation and arrival-window figures.

The fast forms (block-pruned shortfalls, coarse-then-fine pair minimum, limit arrays) must
give exactly what the plain loops give: the ACO's choices and the plan's reported minimum
separation depend on those numbers to the last bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.coupling import (
    TRACK_BLOCK_STEPS,
    GridTracks,
    LimitArrays,
    TimingLimits,
    pair_min_separation,
    team_min_separation_m,
    window_gap_s,
)

FloatArray = np.typing.NDArray[np.float64]


def _converging_tracks(
    rng: np.random.Generator, n_vehicles: int, n_times: int
) -> tuple[FloatArray, FloatArray]:
    """(N, T, 2) tracks that meet near the origin, NaN outside a random airborne span."""
    times = np.arange(n_times, dtype=np.float64)
    angle = rng.uniform(0, 2 * math.pi, n_vehicles)
    reach = rng.uniform(0.0, 1500.0, n_vehicles)
    start = 4_000.0 * np.stack([np.sin(angle), np.cos(angle)], axis=-1)
    end = reach[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    frac = (times / (n_times - 1))[None, :, None]
    tracks = start[:, None, :] + (end - start)[:, None, :] * frac
    tracks += rng.normal(0.0, 20.0, tracks.shape)
    for k in range(n_vehicles):
        first = int(rng.integers(0, n_times // 3))
        last = int(rng.integers(2 * n_times // 3, n_times + 1))
        tracks[k, :first] = np.nan
        tracks[k, last:] = np.nan
    return times, tracks


def _plain_shortfalls(
    tracks: FloatArray, mine: FloatArray, first: int, separation_m: float, skip: int
) -> FloatArray:
    """The reference: every sample of every other vehicle against the candidate."""
    full = np.full(tracks.shape[1:], np.nan)
    full[first : first + len(mine)] = mine
    d = np.hypot(tracks[..., 0] - full[None, :, 0], tracks[..., 1] - full[None, :, 1])
    d = np.where(np.isnan(d), np.inf, d)
    out = np.maximum(separation_m - d.min(axis=1), 0.0)
    out[skip] = 0.0
    return np.asarray(out, dtype=np.float64)


@pytest.mark.parametrize("seed", range(12))
def test_shortfalls_equal_a_plain_pairwise_loop(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_times = int(rng.integers(TRACK_BLOCK_STEPS // 2, 8 * TRACK_BLOCK_STEPS))
    times, tracks = _converging_tracks(rng, int(rng.integers(2, 25)), n_times)
    team = GridTracks(times, tracks)
    np.testing.assert_array_equal(team.positions_m, tracks)
    separation_m = float(rng.uniform(100.0, 1500.0))
    seen_shortfall = False
    for _ in range(10):
        skip = int(rng.integers(0, len(tracks)))
        first = int(rng.integers(0, n_times))
        stop = int(rng.integers(first, n_times + 1))
        mine = tracks[int(rng.integers(0, len(tracks))), first:stop].copy()
        mine = np.where(np.isnan(mine), 0.0, mine) + rng.normal(0.0, 100.0, mine.shape)
        got = team.shortfalls_m(mine, first, separation_m, skip=skip)
        np.testing.assert_array_equal(
            got, _plain_shortfalls(tracks, mine, first, separation_m, skip)
        )
        seen_shortfall |= bool(got.any())
        # Replacing a track keeps the blocks' boxes in step with the samples.
        team.set(skip, tracks[(skip + 1) % len(tracks)])
        tracks[skip] = tracks[(skip + 1) % len(tracks)]
    assert seen_shortfall  # the comparison must meet real losses of separation


@pytest.mark.parametrize(("offset_m", "expected_m"), [(499.5, 0.5), (500.0, 0.0), (520.0, 0.0)])
def test_shortfall_at_the_edge_of_the_separation(offset_m: float, expected_m: float) -> None:
    n_times = 3 * TRACK_BLOCK_STEPS
    still = np.zeros((n_times, 2))
    tracks = np.stack([still, still + np.array([0.0, 5_000.0])])
    mine = still[TRACK_BLOCK_STEPS:] + np.array([offset_m, 0.0])
    team = GridTracks(np.arange(n_times, dtype=np.float64), tracks)
    got = team.shortfalls_m(mine, TRACK_BLOCK_STEPS, 500.0, skip=1)
    assert got.tolist() == [expected_m, 0.0]


def test_shortfalls_of_a_candidate_never_airborne_are_zero() -> None:
    times, tracks = _converging_tracks(np.random.default_rng(0), 4, 100)
    got = GridTracks(times, tracks).shortfalls_m(np.empty((0, 2)), 0, 500.0, skip=0)
    np.testing.assert_array_equal(got, np.zeros(4))


@pytest.mark.parametrize("seed", range(8))
def test_team_min_separation_equals_the_smallest_pair_separation(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 9))
    angle = rng.uniform(0, 2 * math.pi, n)
    tracks = []
    for a in angle:
        knots = int(rng.integers(2, 40))
        start = 20_000.0 * np.array([math.sin(a), math.cos(a)])
        end = rng.normal(0.0, 800.0, 2)
        frac = np.linspace(0.0, 1.0, knots)[:, None]
        tracks.append(start + (end - start) * frac + rng.normal(0.0, 150.0, (knots, 2)))
    takeoff = rng.uniform(0.0, 200.0, n).tolist()
    speed = rng.uniform(18.0, 30.0, n).tolist()
    step_s = float(rng.uniform(0.5, 5.0))
    expected = math.inf
    for i in range(n):
        for j in range(i + 1, n):
            d, _ = pair_min_separation(
                tracks[i], takeoff[i], speed[i], tracks[j], takeoff[j], speed[j], step_s
            )
            expected = min(expected, d)
    assert team_min_separation_m(tracks, takeoff, speed, step_s) == expected


def test_team_min_separation_is_inf_when_no_two_fly_together() -> None:
    track = np.array([[0.0, 0.0], [1000.0, 0.0]])
    assert team_min_separation_m([track, track], [0.0, 500.0], [10.0, 10.0], 1.0) == math.inf


def _limits(rng: np.random.Generator, n: int) -> list[TimingLimits]:
    out = []
    for _ in range(n):
        own = (rng.uniform(3000, 5000), rng.uniform(6000, 9000)) if rng.random() < 0.3 else ()
        out.append(
            TimingLimits(
                float(rng.uniform(15, 20)),
                float(rng.uniform(25, 35)),
                22.0,
                float(rng.uniform(0, 300)),
                float(rng.uniform(300, 3600)),
                float(rng.uniform(0, 100)),
                *(float(x) for x in own),
            )
        )
    return out


@pytest.mark.parametrize("required_s", [None, 6500.0])
def test_window_gap_of_many_candidates_equals_one_at_a_time(required_s: float | None) -> None:
    rng = np.random.default_rng(5)
    for n in (2, 9, 40):
        limits = _limits(rng, n)
        team = np.tile(rng.uniform(1e5, 2e5, n), (12, 1))
        team[:, n // 2] = rng.uniform(1e5, 2e5, 12)
        many = window_gap_s(team, LimitArrays.of(limits), required_s)
        one_by_one = [window_gap_s(row, limits, required_s) for row in team]
        np.testing.assert_array_equal(many, one_by_one)

"""The per-fix paths kept cheap give what their plain forms give: the loiters done counted from
the mission flown now (read once per mission), the clock's median, the windowed locate against
a search of every chord, the screen's nearest against a pair-by-pair reckoning."""

from __future__ import annotations

import dataclasses
import math
import statistics

import numpy as np
import pytest

from gcs.coordination.missionclock import _median
from gcs.coordination.resolution import Ahead, Forecasts
from gcs.coordination.team import TeamController
from planner.mission import MAV_CMD_NAV_LOITER_TURNS


def _counted(team: TeamController, vid: str) -> int:
    m = team.members[vid]
    seq = m.last_seq or 0
    return sum(
        1
        for k, it in enumerate(m.mission.items)
        if it.command == MAV_CMD_NAV_LOITER_TURNS and k < seq
    )


def test_loiters_done_follow_the_mission_flown_now(team: TeamController) -> None:
    vid = next(iter(team.members))
    m = team.members[vid]
    items = m.mission.items
    # A mission with loiter items at a few places, as an installed one would have.
    loiter = dataclasses.replace(items[-1], command=MAV_CMD_NAV_LOITER_TURNS)
    looped = tuple(
        dataclasses.replace(loiter, seq=k) if k in (3, 5, 6) else it for k, it in enumerate(items)
    )
    for mission in (m.mission, dataclasses.replace(m.mission, items=looped), m.mission):
        m.mission = mission
        for seq in (None, 0, 1, 3, 4, 5, 6, 7, len(items) - 1, len(items) + 3):
            m.last_seq = seq
            assert m.loiters_done() == _counted(team, vid)


@pytest.mark.parametrize("n", [1, 2, 3, 14, 15, 16])
def test_the_clock_median_is_the_statistics_median(n: int) -> None:
    rng = np.random.default_rng(n)
    for _ in range(50):
        xs = rng.normal(size=n).tolist()
        assert _median(xs) == statistics.median(xs)


def test_locate_in_its_window_finds_the_closest_point_of_all_chords(team: TeamController) -> None:
    rng = np.random.default_rng(5)
    for m in team.members.values():
        track = m.track
        for _ in range(300):
            k = int(rng.integers(0, track.sample_s_m.size))
            e = float(track.sample_east_m[k] + rng.normal() * 200.0)
            n = float(track.sample_north_m[k] + rng.normal() * 200.0)
            hint = float(track.sample_s_m[k] + rng.normal() * 300.0)
            s_m, d_m = track.locate(e, n, hint)
            # The window's closest is never closer than the route's, and is it when the
            # route's closest lies well inside the window.
            whole_s, whole_d = track.locate(e, n)
            assert d_m >= whole_d - 1e-9
            if abs(whole_s - hint) < 2000.0:
                assert (s_m, d_m) == (whole_s, whole_d)


def test_the_screen_finds_the_pairs_a_pairwise_reckoning_finds() -> None:
    rng = np.random.default_rng(9)
    along = np.linspace(0.0, 20_000.0, 81)
    for _ in range(100):
        ids = ["A", "B", "C", "D"]
        forecasts = Forecasts(ids, 60.0, 5.0)
        now = 100.0 + float(rng.uniform(0.0, 3.0))
        ahead = {}
        for vid in ids:
            heading = float(rng.uniform(0.0, 2.0 * math.pi))
            e0, n0 = rng.uniform(-3000.0, 3000.0, size=2)
            a = Ahead(
                vid, now - float(rng.uniform(0.0, 2.0)), float(rng.uniform(0.0, 5000.0)),
                float(rng.uniform(15.0, 30.0)), 20.0, 1.0, 15.0, 30.0,
                float(rng.uniform(500.0, 700.0)), along,
                e0 + along * math.sin(heading), n0 + along * math.cos(heading),
                horizon_s=float(rng.choice([10.0, 40.0, 600.0])),
                # Some lifted over part of the way ahead, as a re-plan lifts them.
                route_rise_m=rng.choice([0.0, 150.0, 450.0]) * (along > rng.uniform(0, 9e3)),
            )  # fmt: skip
            ahead[vid] = a
            forecasts.update(a, a.t_s)
        for vid in ids:
            got = forecasts.near(vid, 1500.0, now)
            want = []
            for other in ids:
                if other == vid:
                    continue
                t0 = max(math.ceil(ahead[vid].t_s), math.ceil(ahead[other].t_s))
                t = t0 + np.arange(forecasts.steps - abs(
                    math.ceil(ahead[vid].t_s) - math.ceil(ahead[other].t_s)
                ), dtype=np.float64)  # fmt: skip
                pa = ahead[vid].positions(t, 20.0, 5.0)
                pb = ahead[other].positions(t, 20.0, 5.0)
                d2 = ((pa[:, :2] - pb[:, :2]) ** 2).sum(axis=1)
                if np.isnan(d2).all():
                    continue
                dz = pa[:, 2] - pb[:, 2]
                least = math.sqrt(float(np.nanmin(d2 + dz * dz)))
                if least < 1500.0:
                    want.append((least, other))
            assert got == [o for _, o in sorted(want)]

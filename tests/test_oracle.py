"""The flight tests' judge (:mod:`tests.oracle`) fed truth logs made here: a team that keeps its
slots, its separation and out of a zone passes; the same team with one vehicle 2 s late, a pair
100 m apart or one sample inside a zone fails, by the amount made. The logs are written with
the planner's own frame (:class:`planner.geo.LocalFrame`), which the oracle does not use: a
passage found where it was put also says the two frames agree."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pyproj import Geod

from planner.geo import LocalFrame
from tests import oracle

ORIGIN = (46.0, 8.0)
START_UTC = 1_800_000_000.0
SPEED = 25.0
ARRIVE_S = 400.0
PERIOD_S = 0.5
GOALS = {"A": (20_000.0, 25_000.0), "B": (25_000.0, 20_000.0), "C": (20_000.0, 15_000.0)}
"""Each flies in on a straight line from 10 km west of its goal, 1,000 m AMSL, and on past it
for a minute (as a run-out waypoint takes it): they pass their goals at ``ARRIVE_S``."""


def _scenario(arrival: dict[str, Any] | None = None) -> dict[str, Any]:
    return {
        "area": {"origin": {"lat_deg": ORIGIN[0], "lon_deg": ORIGIN[1]}},
        "arrival": arrival or {"kind": "simultaneous"},
        "vehicles": [
            {"id": v, "goal": {"east_m": g[0], "north_m": g[1], "alt_m": 1000}}
            for v, g in GOALS.items()
        ],
    }


def _record(planned: dict[str, float], team_s: float | None = ARRIVE_S) -> dict[str, Any]:
    return {
        "start_utc_s": START_UTC,
        "planned_arrival_s": team_s,
        "vehicles": [
            {"id": v, "system_id": k + 1, "planned_arrival_s": t}
            for k, (v, t) in enumerate(planned.items())
        ],
    }


def _write_truth(
    path: Path,
    *,
    late_s: dict[str, float] | None = None,
    offset_m: dict[str, tuple[float, float, float]] | None = None,
    extra: Sequence[tuple[str, float, float, float]] = (),
) -> Path:
    """Every vehicle from 10 km out to a minute past its goal: ``late_s`` delays one's whole
    track, ``offset_m`` moves it (east, north, up). ``extra`` adds a sample (vehicle, mission
    s, east, north) at 1,000 m."""
    frame = LocalFrame(*ORIGIN)
    late_s, offset_m = late_s or {}, offset_m or {}
    rows = []
    for k, (vid, (ge, gn)) in enumerate(GOALS.items()):
        de, dn, du = offset_m.get(vid, (0.0, 0.0, 0.0))
        for t in np.arange(0.0, ARRIVE_S + 60.0 + PERIOD_S / 2, PERIOD_S):
            along = SPEED * (t - late_s.get(vid, 0.0) - ARRIVE_S)  # m past the goal
            rows.append((t, k + 1, ge + along + de, gn + dn, 1000.0 + du))
    for vid, t, e, n in extra:
        rows.append((t, list(GOALS).index(vid) + 1, e, n, 1000.0))
    lines = [json.dumps({"format": oracle.TRUTH_FORMAT, "vehicles": len(GOALS)})]
    for t, sysid, e, n, alt in sorted(rows):
        lat, lon = frame.to_geodetic(e, n)
        lines.append(
            json.dumps(
                {
                    "utc_s": START_UTC + t, "i": sysid - 1, "sysid": sysid,
                    "lat_deg": lat, "lon_deg": lon, "alt_m": alt,
                    "airspeed_m_s": SPEED, "groundspeed_m_s": SPEED,
                    "armed": True, "on_ground": False, "terrain_m": 300.0, "crashed": False,
                }
            )
        )  # fmt: skip
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _judge(truth: Path, scenario: dict[str, Any], record: dict[str, Any]) -> dict[str, Any]:
    tracks = oracle.tracks_by_vehicle(truth, record)
    passed = oracle.passages(
        tracks, oracle.Ground.of(scenario), oracle.goals(scenario), record["start_utc_s"]
    )
    return oracle.arrival_misses(passed, oracle.planned_slots(scenario, record), tolerance_s=1.0)


def test_a_team_on_its_slots_passes_and_a_vehicle_two_seconds_late_fails(tmp_path: Path) -> None:
    scenario, record = _scenario(), _record(dict.fromkeys(GOALS, ARRIVE_S))
    on_time = _write_truth(tmp_path / "on_time.jsonl")
    tracks = oracle.tracks_by_vehicle(on_time, record)
    passed = oracle.passages(tracks, oracle.Ground.of(scenario), oracle.goals(scenario), START_UTC)
    assert all(abs(t - ARRIVE_S) < 0.01 for t in passed.values() if t is not None), passed
    assert _judge(on_time, scenario, record) == {}
    late = _judge(_write_truth(tmp_path / "late.jsonl", late_s={"B": 2.0}), scenario, record)
    assert list(late) == ["B"] and late["B"] == pytest.approx(2.0, abs=0.01)
    # Early by as much, too.
    early = _judge(_write_truth(tmp_path / "early.jsonl", late_s={"C": -2.0}), scenario, record)
    assert list(early) == ["C"] and early["C"] == pytest.approx(-2.0, abs=0.01)
    # A team time allowed to move moves every slot: 2 s later, and only B is on it.
    shifted = oracle.arrival_misses(passed, {v: (ARRIVE_S, ARRIVE_S) for v in GOALS},
                                    tolerance_s=1.0, shift_s=2.0)  # fmt: skip
    assert set(shifted) == set(GOALS)


def test_a_vehicle_that_misses_its_goal_by_more_than_the_radius_never_passed_it(
    tmp_path: Path,
) -> None:
    scenario, record = _scenario(), _record(dict.fromkeys(GOALS, ARRIVE_S))
    # 160 m north of its goal all the way: outside the 150 m passage radius.
    wide = _write_truth(tmp_path / "wide.jsonl", offset_m={"A": (0.0, 160.0, 0.0)})
    assert _judge(wide, scenario, record) == {"A": None}
    near = _write_truth(tmp_path / "near.jsonl", offset_m={"A": (0.0, 140.0, 0.0)})
    assert _judge(near, scenario, record) == {}


def test_a_pair_100_m_apart_in_3d_is_found_and_the_team_apart_is_not(tmp_path: Path) -> None:
    record = _record(dict.fromkeys(GOALS, ARRIVE_S))
    apart = oracle.separation(oracle.tracks_by_vehicle(_write_truth(tmp_path / "a.jsonl"), record))
    # A and C fly 10 km apart, B 7.1 km from both (5 km ahead of them, between their lines).
    assert apart.least_m > 4_000.0
    assert apart.compared == 3 * int((ARRIVE_S + 60.0) / PERIOD_S + 1)
    # C moved to 60 m east and 80 m above A's line... seen 100 m from A where A is, in 3-D.
    g = GOALS
    close = _write_truth(
        tmp_path / "close.jsonl",
        offset_m={"C": (g["A"][0] - g["C"][0] + 60.0, g["A"][1] - g["C"][1], 80.0)},
    )
    found = oracle.separation(oracle.tracks_by_vehicle(close, record))
    assert found.pair == ("A", "C")
    assert found.least_m == pytest.approx(100.0, abs=0.5)


def test_separation_counts_the_whole_flight_after_a_goal_is_passed_too(tmp_path: Path) -> None:
    """A and C come within 50 m of each other 30 s after they pass their goals (one sample
    each, as a hold after arrival would): found."""
    record = _record(dict.fromkeys(GOALS, ARRIVE_S))
    t = ARRIVE_S + 30.0
    at = (GOALS["A"][0] + SPEED * 30.0, GOALS["A"][1])
    truth = _write_truth(
        tmp_path / "hold.jsonl", extra=[("A", t + 0.25, *at), ("C", t + 0.25, at[0] + 50.0, at[1])]
    )
    found = oracle.separation(oracle.tracks_by_vehicle(truth, record))
    assert found.pair == ("A", "C") and found.least_m == pytest.approx(50.0, abs=0.5)
    assert found.utc_s == pytest.approx(START_UTC + t + 0.25)


def test_the_3d_distance_agrees_with_a_geodesic_one(tmp_path: Path) -> None:
    """A pair at one altitude: the ECEF chord against PROJ's geodesic (Karney) on WGS84."""
    record = _record(dict.fromkeys(GOALS, ARRIVE_S))
    tracks = oracle.tracks_by_vehicle(_write_truth(tmp_path / "t.jsonl"), record)
    found = oracle.separation(tracks)
    a, b = (tracks[v] for v in found.pair)
    k = int(np.flatnonzero(np.isclose(a.utc_s, found.utc_s))[0])
    _, _, geodesic_m = Geod(ellps="WGS84").inv(
        a.lon_deg[k], a.lat_deg[k], b.lon_deg[k], b.lat_deg[k]
    )
    # The chord of a 7 km arc at 1 km up is shorter than the arc by under a centimetre; the
    # height scales the arc by (R + h) / R.
    assert found.least_m == pytest.approx(geodesic_m * (1 + 1000.0 / 6.371e6), rel=2e-5)


def test_a_sample_inside_a_zone_once_it_is_there_and_below_its_ceiling_is_an_entry(
    tmp_path: Path,
) -> None:
    record = _record(dict.fromkeys(GOALS, ARRIVE_S))
    ground = oracle.Ground.of(_scenario())
    # One sample of B 100 m inside a disc 2 km off its line (at 200 s), the rest outside.
    disc = {"kind": "radar", "id": "D", "center": {"east_m": 20_000.0, "north_m": 22_000.0},
            "radius_m": 1_000.0, "forbidden": True}  # fmt: skip
    truth = _write_truth(tmp_path / "in.jsonl", extra=[("B", 200.25, 20_000.0, 21_100.0)])
    tracks = oracle.tracks_by_vehicle(truth, record)
    zone = oracle.Zone.of(disc, START_UTC)
    assert oracle.zone_entries(tracks, ground, [zone]) == [("B", "D", START_UTC + 200.25)]
    # Not there yet at 200 s, or flown over (a ceiling under 1,000 m): no entry.
    assert oracle.zone_entries(tracks, ground, [oracle.Zone.of(disc, START_UTC + 300.0)]) == []
    low = oracle.Zone.of({**disc, "ceiling_m": 900}, START_UTC)
    assert oracle.zone_entries(tracks, ground, [low]) == []
    # A polygon (a square about the same point) by the even-odd rule, and the clean log.
    square = {"kind": "no_fly", "id": "P", "polygon": [
        {"east_m": e, "north_m": n}
        for e, n in ((19_900, 21_000), (20_100, 21_000), (20_100, 21_200), (19_900, 21_200))
    ]}  # fmt: skip
    poly = oracle.Zone.of(square, START_UTC)
    assert oracle.zone_entries(tracks, ground, [poly]) == [("B", "P", START_UTC + 200.25)]
    clean = oracle.tracks_by_vehicle(_write_truth(tmp_path / "out.jsonl"), record)
    assert oracle.zone_entries(clean, ground, [zone, poly]) == []


def test_planned_slots_must_follow_the_scenario_arrival_rule() -> None:
    spaced = _scenario({"kind": "spaced", "interval_s": 60})
    ok = oracle.planned_slots(spaced, _record({"B": 400.0, "A": 460.0, "C": 520.0}))
    assert ok == {"B": (400.0, 400.0), "A": (460.0, 460.0), "C": (520.0, 520.0)}
    with pytest.raises(AssertionError, match="spaced"):
        oracle.planned_slots(spaced, _record({"B": 400.0, "A": 450.0, "C": 520.0}))
    ordered = _scenario({"kind": "spaced", "interval_s": 60, "order": ["A", "B", "C"]})
    with pytest.raises(AssertionError, match="spaced"):
        oracle.planned_slots(ordered, _record({"B": 400.0, "A": 460.0, "C": 520.0}))
    waves = _scenario({"kind": "waves", "gap_s": 90, "sizes": [1, 2]})
    ok = oracle.planned_slots(waves, _record({"A": 400.0, "B": 490.0, "C": 490.0}))
    assert ok["C"] == (490.0, 490.0)
    with pytest.raises(AssertionError, match="waves"):
        oracle.planned_slots(waves, _record({"A": 400.0, "B": 400.0, "C": 490.0}))
    windows = _scenario(
        {"kind": "windows", "windows": [
            {"vehicle": v, "earliest_s": 300.0, "latest_s": 340.0} for v in GOALS
        ]}
    )  # fmt: skip
    ok = oracle.planned_slots(windows, _record(dict.fromkeys(GOALS, 320.0), None))
    assert ok["A"] == (300.0, 340.0)
    with pytest.raises(AssertionError, match="windows"):
        oracle.planned_slots(windows, _record({"A": 320.0, "B": 350.0, "C": 320.0}, None))


def test_a_truth_log_that_is_not_one_says_which_line(tmp_path: Path) -> None:
    good = _write_truth(tmp_path / "t.jsonl")
    lines = good.read_text(encoding="utf-8").split("\n")
    lines[5] = '{"utc_s": 1, "sysid": 1}'
    bad = tmp_path / "bad.jsonl"
    bad.write_text("\n".join(lines), encoding="utf-8")
    with pytest.raises(ValueError, match="line 6"):
        oracle.read_tracks(bad)
    other = tmp_path / "other.jsonl"
    other.write_text('{"format": "something/2"}\n', encoding="utf-8")
    with pytest.raises(ValueError, match="format"):
        oracle.read_tracks(other)
    # A last line still being written is left out.
    cut = tmp_path / "cut.jsonl"
    cut.write_text(good.read_text(encoding="utf-8") + '{"utc_s": 1', encoding="utf-8")
    assert len(oracle.read_tracks(cut)[1]) == len(oracle.read_tracks(good)[1])
    assert math.isfinite(float(oracle.read_tracks(good)[1].terrain_m[0]))

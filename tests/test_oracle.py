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
from tests import oracle, verdict

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
            {
                "id": v,
                "system_id": k + 1,
                "planned_arrival_s": t,
                "target_arrival_utc_s": START_UTC + t,
            }
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
    # Or each slot its own move (ordered slots move apart): B's and C's 2 s, A's none.
    moves = {"A": 0.0, "B": 2.0, "C": 2.0}
    apart = oracle.arrival_misses(passed, {v: (ARRIVE_S, ARRIVE_S) for v in GOALS},
                                  tolerance_s=1.0, shift_s=moves)  # fmt: skip
    assert set(apart) == {"B", "C"} and apart["B"] == pytest.approx(-2.0, abs=0.01)


def test_slots_moved_apart_are_held_to_the_arrival_rule() -> None:
    """Spaced: any order (a vehicle may take a later place), never closer than the
    interval; waves: one slot a wave, the gap between waves; simultaneous: one slot."""
    spaced = {"arrival": {"kind": "spaced", "interval_s": 90.0, "order": ["A", "B", "C"]}}
    assert oracle.slot_rule_breaks(spaced, {"A": 100.0, "B": 230.0, "C": 320.0}) == []
    assert oracle.slot_rule_breaks(spaced, {"A": 100.0, "B": 280.0, "C": 190.0}) == []
    (close,) = oracle.slot_rule_breaks(spaced, {"A": 100.0, "B": 230.0, "C": 300.0})
    assert "['B'] and ['C'] on slots 70.000 s apart" in close
    waves = {"arrival": {"kind": "waves", "gap_s": 60.0, "groups": [["A", "B"], ["C"]]}}
    assert oracle.slot_rule_breaks(waves, {"A": 100.0, "B": 100.0, "C": 175.0}) == []
    split, near = oracle.slot_rule_breaks(waves, {"A": 100.0, "B": 120.0, "C": 150.0})
    assert "one wave on slots 100.000-120.000 s" in split and "50.000 s apart" in near
    together = {"arrival": {"kind": "simultaneous"}}
    assert oracle.slot_rule_breaks(together, {"A": 100.0, "B": 100.0}) == []
    assert oracle.slot_rule_breaks(together, {"A": 100.0, "B": 101.0})
    windows = {"arrival": {"kind": "windows", "windows": []}}
    assert oracle.slot_rule_breaks(windows, {"A": 100.0, "B": 100.5}) == []


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


def test_a_point_placed_by_the_planner_s_frame_is_found_where_it_was_put() -> None:
    """Local points 30 km apart placed with :class:`planner.geo.LocalFrame` come back within a
    millimetre, and back again; a point 1 m off comes back 1 m off."""
    ground, frame = oracle.Ground(*ORIGIN), LocalFrame(*ORIGIN)
    east, north = np.array([0.0, 20_000.0, -15_000.0]), np.array([0.0, 25_000.0, 7_500.0])
    lat, lon = frame.to_geodetic(east, north)
    e, n = ground.to_local(lat, lon)
    assert np.abs(e - east).max() < 1e-3 and np.abs(n - north).max() < 1e-3
    lat2, lon2 = ground.to_geodetic(e, n)
    assert np.abs(lat2 - lat).max() < 1e-10 and np.abs(lon2 - lon).max() < 1e-10
    lat_off, lon_off = frame.to_geodetic(20_001.0, 25_000.0)
    e1, n1 = ground.to_local(lat_off, lon_off)
    assert float(e1) - 20_000.0 == pytest.approx(1.0, abs=1e-3)
    assert float(n1) == pytest.approx(25_000.0, abs=1e-3)


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


def test_a_zone_that_appears_after_a_takeoff_is_there_from_the_true_takeoff_on(
    tmp_path: Path,
) -> None:
    """A disc that appears 200 s after A leaves the ground (by the truth: its first airborne
    sample, at 0 s here), and one sample of B inside it at 200.25 s: an entry; the same disc
    300 s after a takeoff of A at 0 s, or after a vehicle that never took off, is not there
    then."""
    record = _record(dict.fromkeys(GOALS, ARRIVE_S))
    ground = oracle.Ground.of(_scenario())
    truth = _write_truth(tmp_path / "in.jsonl", extra=[("B", 200.25, 20_000.0, 21_100.0)])
    tracks = oracle.tracks_by_vehicle(truth, record)
    took_off = oracle.takeoffs(tracks)
    assert took_off == dict.fromkeys(GOALS, START_UTC)
    disc = {"kind": "radar", "id": "D", "center": {"east_m": 20_000.0, "north_m": 22_000.0},
            "radius_m": 1_000.0, "forbidden": True,
            "appears": {"after_takeoff_of": "A", "delay_s": 200.0}}  # fmt: skip
    scenario = {**_scenario(), "threats": [disc]}
    with pytest.raises(ValueError, match="A's takeoff"):
        oracle.scenario_zones(scenario, START_UTC)
    zones = oracle.scenario_zones(scenario, START_UTC, took_off)
    assert [z.from_utc_s for z in zones] == [START_UTC + 200.0]
    assert oracle.zone_entries(tracks, ground, zones) == [("B", "D", START_UTC + 200.25)]
    later = {**disc, "appears": {"after_takeoff_of": "A", "delay_s": 300.0}}
    zones = oracle.scenario_zones({**scenario, "threats": [later]}, START_UTC, took_off)
    assert oracle.zone_entries(tracks, ground, zones) == []
    never = oracle.scenario_zones(scenario, START_UTC, {**took_off, "A": None})
    assert never == []


def test_planned_slots_must_follow_the_scenario_arrival_rule() -> None:
    # Spaced with no order: the scenario's vehicles in the order given (A, B, C).
    spaced = _scenario({"kind": "spaced", "interval_s": 60})
    ok = oracle.planned_slots(spaced, _record({"A": 400.0, "B": 460.0, "C": 520.0}))
    assert ok == {"A": (400.0, 400.0), "B": (460.0, 460.0), "C": (520.0, 520.0)}
    with pytest.raises(AssertionError, match="spaced"):
        oracle.planned_slots(spaced, _record({"A": 400.0, "B": 450.0, "C": 520.0}))
    with pytest.raises(AssertionError, match="spaced"):
        oracle.planned_slots(spaced, _record({"B": 400.0, "A": 460.0, "C": 520.0}))
    ordered = _scenario({"kind": "spaced", "interval_s": 60, "order": ["B", "A", "C"]})
    ok = oracle.planned_slots(ordered, _record({"B": 400.0, "A": 460.0, "C": 520.0}))
    assert ok["A"] == (460.0, 460.0)
    with pytest.raises(AssertionError, match="spaced"):
        oracle.planned_slots(ordered, _record({"A": 400.0, "B": 460.0, "C": 520.0}))
    waves = _scenario({"kind": "waves", "gap_s": 90, "sizes": [1, 2]})
    ok = oracle.planned_slots(waves, _record({"A": 400.0, "B": 490.0, "C": 490.0}))
    assert ok["C"] == (490.0, 490.0)
    with pytest.raises(AssertionError, match="waves"):
        oracle.planned_slots(waves, _record({"A": 400.0, "B": 400.0, "C": 490.0}))
    # Waves by name: each vehicle in its own group's slot.
    groups = _scenario({"kind": "waves", "gap_s": 90, "groups": [["B", "C"], ["A"]]})
    ok = oracle.planned_slots(groups, _record({"A": 490.0, "B": 400.0, "C": 400.0}))
    assert ok == {"A": (490.0, 490.0), "B": (400.0, 400.0), "C": (400.0, 400.0)}
    with pytest.raises(AssertionError, match="waves"):
        oracle.planned_slots(groups, _record({"A": 400.0, "B": 490.0, "C": 400.0}))
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


def _moved(
    record: dict[str, Any], team_s: float, own_s: dict[str, float] | None = None
) -> dict[str, Any]:
    """``record`` with its team time moved ``team_s`` later and every slot with it, or each
    slot by its own ``own_s``."""
    own_s = own_s or {}
    vehicles = [
        {**v, "target_arrival_utc_s": v["target_arrival_utc_s"] + own_s.get(v["id"], team_s)}
        for v in record["vehicles"]
    ]
    return {**record, "required_arrival_s": record["required_arrival_s"] + team_s,
            "vehicles": vehicles}  # fmt: skip


def test_the_flight_verdict_says_every_way_a_flight_failed(tmp_path: Path) -> None:
    """:func:`tests.verdict.judge` on the logs made here: the team on its slots, apart and out
    of the zones has no problem; a team time moved past its bound, a vehicle 2 s late, a pair
    100 m apart, a sample in a zone and too short a flight together each is one, by the
    amount made."""
    scenario = {**_scenario(), "separation_m": 300.0}
    record = {
        **_record(dict.fromkeys(GOALS, ARRIVE_S)),
        "required_arrival_s": ARRIVE_S,
        "scenario": scenario,
        "events": [],
    }
    kw: dict[str, Any] = {"tolerance_s": 1.0, "team_shift_max_s": 0.0, "together_min_s": 400.0}
    clean = _write_truth(tmp_path / "clean.jsonl")
    judged = verdict.judge(record, clean, **kw)
    assert judged.problems() == []
    judged.check()
    assert judged.together_s == pytest.approx(ARRIVE_S + 60.0 + PERIOD_S)
    # The team time moved 3 s later: past a bound of 0 s, and everyone 3 s early for it.
    moved = verdict.judge(_moved(record, 3.0), clean, **kw)
    (shifted, slots, early) = moved.problems()
    assert "moved +3.0 s" in shifted and "'A': -3.0" in early
    assert slots == "slots moved by (s) {'A': 3.0, 'B': 3.0, 'C': 3.0} (allowed 0)"
    with pytest.raises(AssertionError, match="moved"):
        moved.check()
    # Allowed to move 3 s and every one on it: no problem.
    late = _write_truth(tmp_path / "late.jsonl", late_s=dict.fromkeys(GOALS, 3.0))
    assert verdict.judge(_moved(record, 3.0), late,
                         **{**kw, "team_shift_max_s": 3.0}).problems() == []  # fmt: skip
    # Only B's slot moved, in a simultaneous arrival: the rule is broken, B on its slot.
    b_only = _moved(record, 0.0, {"B": 3.0})
    b_late = _write_truth(tmp_path / "b_late.jsonl", late_s={"B": 3.0})
    (broken,) = verdict.judge(b_only, b_late, **{**kw, "team_shift_max_s": 3.0}).problems()
    assert "break the arrival rule" in broken and "simultaneous" in broken
    # One 2 s late; a pair 100 m apart; a sample in a disc; too short together.
    b_late = verdict.judge(record, _write_truth(tmp_path / "b.jsonl", late_s={"B": 2.0}), **kw)
    assert b_late.problems() == ["off their slots by (s, None: never passed): {'B': 2.0}"]
    g = GOALS
    near = {"C": (g["A"][0] - g["C"][0] + 60.0, g["A"][1] - g["C"][1], 80.0)}
    close = verdict.judge(record, _write_truth(tmp_path / "c.jsonl", offset_m=near), **kw)
    (c_never, lost) = close.problems()  # C flies A's line: it never passes its own goal
    assert c_never.endswith("{'C': None}") and lost.startswith("separation lost: 100 m (A, C")
    disc = {"kind": "radar", "id": "D", "center": {"east_m": 20_000.0, "north_m": 22_000.0},
            "radius_m": 1_000.0, "forbidden": True}  # fmt: skip
    inside = _write_truth(tmp_path / "in.jsonl", extra=[("B", 200.25, 20_000.0, 21_100.0)])
    entered = verdict.judge(record, inside, **kw, extra_zones=[oracle.Zone.of(disc, START_UTC)])
    assert entered.problems() == [f"inside a forbidden zone: ('B', 'D', {START_UTC + 200.25})"]
    short = verdict.judge(record, clean, **{**kw, "together_min_s": 600.0})
    assert short.problems() == [f"a pair flew together only {ARRIVE_S + 60.0 + PERIOD_S:.0f} s"]


def test_the_routes_a_disc_lies_across_are_found_between_their_waypoints() -> None:
    """Two routes 1.5 km either side of a disc's centre, their waypoints 5 km from it: inside
    a 1.6 km disc, not a 1.4 km one; a later route of B's through the centre, by its label."""
    record = {"vehicles": [
        {"id": "A", "planned_paths": [{"label": "initial", "en_m": [[0, 0], [10_000, 0]]}]},
        {"id": "B", "planned_paths": [
            {"label": "initial", "en_m": [[0, 3_000], [10_000, 3_000]]},
            {"label": "after X", "en_m": [[5_000, -5_000], [5_000, 8_000]]},
        ]},
    ]}  # fmt: skip
    centre = (5_000.0, 1_500.0)
    assert verdict.routes_into_disc(record, "initial", centre, 1_600.0) == {"A", "B"}
    assert verdict.routes_into_disc(record, "initial", centre, 1_400.0) == set()
    assert verdict.routes_into_disc(record, "after X", centre, 100.0) == {"B"}

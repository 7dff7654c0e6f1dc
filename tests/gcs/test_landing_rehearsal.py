"""Landing slots flown end to end (:func:`tests.teams.landing_scenario`): aircraft already in
the air (taken over in AUTO, no takeoff) cross their slot fixes on the approach course 90 s
apart, within 1 s of their slots, then glide down and land on the runway in the slot order.

Everything is recomputed here from the simulator's truth track in the flight record: the
crossing of each fix (the time the track passes the line through the fix square to the
course), the course flown there, the touchdown point and order; the slots come from the
scenario's own order and the team time the run chose.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

from tests.flightstory import story
from tests.teams import landing_scenario, rehearse_doc

pytestmark = pytest.mark.slow

SEEDS = [0, 1]


def _crossing(track: list[list[float]], fix: tuple[float, float], u: tuple[float, float]):
    """(utc_s, course unit vector flown, cross-track m) where the track first passes the
    line through ``fix`` square to the course ``u``, interpolated between two samples."""

    def along(row: list[float]) -> float:
        return (row[1] - fix[0]) * u[0] + (row[2] - fix[1]) * u[1]

    for a, b in itertools.pairwise(track):
        da, db = along(a), along(b)
        near = math.hypot(a[1] - fix[0], a[2] - fix[1]) < 2_000.0
        if near and da < 0.0 <= db:
            f = -da / (db - da)
            t = a[0] + f * (b[0] - a[0])
            e, n = a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])
            de, dn = b[1] - a[1], b[2] - a[2]
            norm = math.hypot(de, dn)
            across = -(e - fix[0]) * u[1] + (n - fix[1]) * u[0]
            return t, (de / norm, dn / norm), across
    return None


def _touchdown(track: list[list[float]], runway_alt_m: float, after_utc_s: float):
    """The first sample after ``after_utc_s`` on the runway (within 2 m of its elevation)."""
    return next((r for r in track if r[0] > after_utc_s and r[3] <= runway_alt_m + 2.0), None)


@pytest.mark.parametrize("seed", SEEDS)
async def test_landing_slots_cross_the_fix_on_course_90_s_apart_and_land_in_order(
    tmp_path: Path, seed: int
) -> None:
    doc, wind = landing_scenario(seed)
    record = await rehearse_doc(doc, wind, seed, tmp_path)
    told = story(record["events"])
    assert record["state"] == "completed", f"{record['state_reason']}\n{told}"
    assert record["arrival_source"] == "simulator"
    landing = doc["landing"]
    c = math.radians(landing["heading_deg"])
    u = (math.sin(c), math.cos(c))
    td = (landing["touchdown"]["east_m"], landing["touchdown"]["north_m"])
    runway_alt = landing["touchdown"]["alt_m"]
    order = doc["arrival"]["order"]
    start = record["start_utc_s"]
    ref = record["required_arrival_s"]
    by_id = {v["id"]: v for v in record["vehicles"]}
    goals = {v["id"]: (v["goal"]["east_m"], v["goal"]["north_m"]) for v in doc["vehicles"]}
    landed: list[tuple[float, str]] = []
    for k, vid in enumerate(order):
        v = by_id[vid]
        crossed = _crossing(v["track"], goals[vid], u)
        assert crossed is not None, f"{vid}\n{told}"
        t_utc, flown, across = crossed
        slot = ref + 90.0 * k
        assert t_utc - start == pytest.approx(slot, abs=1.0), (
            f"{(vid, t_utc - start, slot)}\n{told}"
        )
        # On the approach course, on the centreline.
        assert flown[0] * u[0] + flown[1] * u[1] > math.cos(math.radians(10.0)), (vid, flown)
        assert abs(across) < 50.0, (vid, across)
        # Down on the runway: on the centreline, past the touchdown point by no more than
        # the roll-out, and disarmed (the coordinator saw it land).
        down = _touchdown(v["track"], runway_alt, t_utc)
        assert down is not None, f"{vid}\n{told}"
        de, dn = down[1] - td[0], down[2] - td[1]
        along_m, across_m = de * u[0] + dn * u[1], -de * u[1] + dn * u[0]
        assert -150.0 <= along_m <= 1_000.0, (vid, along_m)
        assert abs(across_m) < 30.0, (vid, across_m)
        assert v["landed_utc_s"] is not None and v["landed_utc_s"] >= down[0], vid
        landed.append((down[0], vid))
    assert [vid for _, vid in sorted(landed)] == order
    # Separation in 4-D on the tracks, the glides included (until each was down).
    assert record["min_separation_m"] >= record["separation_m"], told
    said = [e for e in record["events"] if e["kind"] == "landed"]
    assert [e["vehicle"] for e in said] == order

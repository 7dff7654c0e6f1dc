"""Landing slots flown end to end (:func:`tests.teams.landing_scenario`): aircraft already in
the air (taken over in AUTO, no takeoff) cross their slot fixes on the approach course 90 s
apart, within 1 s of their slots, then glide down and land on the runway in the slot order.

Everything is judged here from the simulator's truth log (:mod:`tests.oracle`, every sample)
and the scenario: :func:`tests.verdict.assert_flown` holds each fix passage to the slot the
schedule set before launch (the scenario's order, 90 s apart) and the team's separation in 3-D
until each is down; here, the crossing of each fix (the time the track passes the line through
the fix square to the course), the course flown there, the touchdown point and order.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests import oracle
from tests.flightstory import story
from tests.teams import headwind_loss_s, landing_scenario, rehearse_doc
from tests.verdict import assert_flown

pytestmark = pytest.mark.slow

SEEDS = [0, 1]

TOLERANCE_S = 1.0
TOGETHER_MIN_S = 200.0
"""Every pair is in the air together at least until the first is down: 15 km or more of
approach at under 30 m/s, past 500 s."""


TAKEOVER_S = 20.0
"""What taking an aircraft over in the air may cost the first in beyond the wind: it is
found circling at its cruise airspeed on its start heading, and turns onto its route and
speeds up to its top airspeed."""


def _team_shift_max_s(doc: dict[str, Any], wind_m_s: float) -> float:
    """How far the slots may move in flight, and only later. The scenario forecasts no wind:
    the first in, planned at its top speed in calm air, is late by the wind it meets and the
    slots move with it: by at most its :func:`tests.teams.headwind_loss_s` in the
    simulator's wind, plus :data:`TAKEOVER_S`."""
    first = next(v for v in doc["vehicles"] if v["id"] == doc["arrival"]["order"][0])
    return headwind_loss_s(first, wind_m_s) + TAKEOVER_S


def _crossing(
    utc_s: np.ndarray, en_m: np.ndarray, fix: tuple[float, float], u: tuple[float, float]
) -> tuple[float, tuple[float, float], float] | None:
    """(utc_s, course unit vector flown, cross-track m) where the track (times, east/north
    rows) first passes the line through ``fix`` square to the course ``u`` within 2 km of the
    fix, interpolated between two samples."""
    along = (en_m[:, 0] - fix[0]) * u[0] + (en_m[:, 1] - fix[1]) * u[1]
    near = np.hypot(en_m[:, 0] - fix[0], en_m[:, 1] - fix[1]) < 2_000.0
    for k, j in itertools.pairwise(range(len(utc_s))):
        if near[k] and along[k] < 0.0 <= along[j]:
            f = -along[k] / (along[j] - along[k])
            t = utc_s[k] + f * (utc_s[j] - utc_s[k])
            e, n = en_m[k] + f * (en_m[j] - en_m[k])
            de, dn = en_m[j] - en_m[k]
            norm = math.hypot(de, dn)
            across = -(e - fix[0]) * u[1] + (n - fix[1]) * u[0]
            return float(t), (float(de / norm), float(dn / norm)), float(across)
    return None


@pytest.mark.parametrize("seed", SEEDS)
async def test_landing_slots_cross_the_fix_on_course_90_s_apart_and_land_in_order(
    tmp_path: Path, seed: int
) -> None:
    doc, wind = landing_scenario(seed)
    record, truth = await rehearse_doc(doc, wind, seed, tmp_path)
    told = story(record["events"])
    assert record["state"] == "completed", f"{record['state_reason']}\n{told}"
    # Each fix passed on its slot, the team apart until each is down, by the truth.
    verdict = assert_flown(
        record,
        truth,
        scenario=doc,
        tolerance_s=TOLERANCE_S,
        team_shift_max_s=_team_shift_max_s(doc, wind[0]),
        together_min_s=TOGETHER_MIN_S,
    )
    assert min(verdict.slot_moves_s.values()) > -1e-3, f"a slot moved earlier: {verdict}"
    landing = doc["landing"]
    c = math.radians(landing["heading_deg"])
    u = (math.sin(c), math.cos(c))
    td = (landing["touchdown"]["east_m"], landing["touchdown"]["north_m"])
    runway_alt = landing["touchdown"]["alt_m"]
    order = doc["arrival"]["order"]
    start = verdict.start_utc_s
    by_id = {v["id"]: v for v in record["vehicles"]}
    goals = oracle.goals(doc)
    landed: list[tuple[float, str]] = []
    for vid in order:
        track = verdict.tracks[vid]
        east, north = verdict.ground.local(track)
        en = np.column_stack([east, north])
        crossed = _crossing(track.utc_s, en, goals[vid], u)
        assert crossed is not None, f"{vid}\n{told}"
        t_utc, flown, across = crossed
        (slot, _) = verdict.slots_s[vid]
        moved = slot + verdict.slot_moves_s[vid]
        assert t_utc - start == pytest.approx(moved, abs=TOLERANCE_S), (
            f"{(vid, t_utc - start, slot)}\n{told}"
        )
        # On the approach course, on the centreline.
        assert flown[0] * u[0] + flown[1] * u[1] > math.cos(math.radians(10.0)), (vid, flown)
        assert abs(across) < 50.0, (vid, across)
        # Down on the runway (the first true sample after the fix within 2 m of its
        # elevation): on the centreline, past the touchdown point by no more than the
        # roll-out, and disarmed (the coordinator saw it land, after it was down).
        down = np.flatnonzero((track.utc_s > t_utc) & (track.alt_m <= runway_alt + 2.0))
        assert down.size, f"{vid} never down\n{told}"
        k = int(down[0])
        de, dn = en[k, 0] - td[0], en[k, 1] - td[1]
        along_m, across_m = de * u[0] + dn * u[1], -de * u[1] + dn * u[0]
        assert -150.0 <= along_m <= 1_000.0, (vid, along_m)
        assert abs(across_m) < 30.0, (vid, across_m)
        down_utc = float(track.utc_s[k])
        assert not track.airborne[-1], f"{vid} still in the air at the end of the log"
        v = by_id[vid]
        assert v["landed_utc_s"] is not None and v["landed_utc_s"] >= down_utc, vid
        landed.append((down_utc, vid))
    assert [vid for _, vid in sorted(landed)] == order
    said = [e for e in record["events"] if e["kind"] == "landed"]
    assert [e["vehicle"] for e in said] == order

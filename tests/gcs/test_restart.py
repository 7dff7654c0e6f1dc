"""Restart safety: the engine's process is killed (SIGKILL) mid-flight, after the pop-up
re-plan, and started again on the same SQLite file. The simulator runs on its own throughout
and keeps its own counters. The resumed flight keeps the team time and its version the
killed one had kept; the arrivals, the separation and the zones are the oracle's, from the
simulator's truth log against the slots set before launch (:func:`tests.verdict.assert_flown`),
nothing taken from the coordinator's own figures.

The team is the paper's at a quarter of its size (:func:`tests.teams.compact_paper`: some
1,300 s of flight instead of 5,500 s): the same three vehicles, threats, pop-up and holding
areas, POPUP1 appearing 300 s after UAV1's takeoff (some 560 s into the flight) across UAV2's
route only."""

from __future__ import annotations

import asyncio
import json
import pickle
import signal
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
import yaml

from gcs.coordination.team import TeamController
from gcs.store.repository import Store
from sitl_stub.lockstep import Lockstep
from tests.flightstory import story_of_lines
from tests.gcs.conftest import hold_while_away, start_stub
from tests.paperbounds import team_time_move_max_s
from tests.sitl_stub.conftest import free_port_base
from tests.teams import compact_paper
from tests.verdict import assert_flown

pytestmark = pytest.mark.slow  # about 12 s of wall time (32 s at full size)

TOLERANCE_S = 2.0
"""The arrival tolerance the engine is run with (``--tolerance``), and the one judged: a
goal passage (the truth's) within it of the planned slot moved by the team time's move."""
AWAY_S = 300.0
"""How long (flight s) the engine is away: the simulator flies this far past the kill and
waits for the engine started again (:func:`tests.gcs.conftest.hold_while_away`), however long
its start takes on a busy machine."""
RESUMED_MOVE_MAX_S = 30.0
"""How far the team time may move after the restart. The vehicle that sets it (UAV2, on the
longest route and late by then) had been commanded its top speed, or a step under it, before
the kill, and flew on at that unwatched: the gap (:data:`AWAY_S` of flight, and the lead)
costs it at most one step (1 m/s of 30), under 15 s; 30 s leaves as much again for its
arrival estimate. A team time lost in the restart (the one set before launch taken up again)
is caught by its version, which the pop-up had moved on (:data:`WIND`): the resumed flight's
must be the kept one's, one more for each team arrival said since. The simulator's WIND
reports the true wind here: its default error (up to 1.6 m/s, turning up to 0.5 deg/s) swings
UAV2's earliest arrival, some 700 s of flight out at the kill, by up to 1.6 / 30 of that,
37 s, within a few minutes whether or not the engine restarts, and the team time follows the
swings later (the other flights against the simulator fly with that error)."""
WIND = (5.0, 290.0)
"""The simulator's wind (m/s, from deg), and the one the team time's move is bounded for
(:func:`tests.paperbounds.team_time_move_max_s`): the pop-up must move the team time (a new
version for the restart to keep). At a quarter of the size the route round POPUP1 is some
0.5 km (18 s at 30 m/s) longer than UAV2's, and a wind from 270 (the full-size test's), behind
UAV2 on its north-north-eastward route, gives it back 77 s over it at its top speed
(:func:`tests.paperbounds.wind_cost_s`), 43 s of them on the 14 km left at the pop-up: the
pop-up does not move the team time (seen). From 290 the 14 km left give back 21 s, the 24 km
before them cost 11 s, and the pop-up moves the team time some 20 s (21-22 s seen). The bound
is 231 s from 270 or 290: the pop-up's 171 s and the 60 s slack, no vehicle's route taking
longer in either wind."""
ROUTED = "UAV2"
"""The vehicle the pop-up re-routes (:func:`tests.paperbounds.popup_crossed`: at a quarter of
the size POPUP1 lies across UAV2's planned route only). UAV1 and UAV3 get an "after POPUP1"
upload in the same round only to be re-timed to the moved team time, and UAV1 may get loiter
turns seconds later (early at the moved time): the kill waits for the checkpoint to hold every
vehicle's last mission (:data:`SETTLED_S`)."""
VEHICLES = ("UAV1", "UAV2", "UAV3")
CHECKPOINT_WITHIN_S = 200.0
"""Flight seconds (one wall second at 200x) within which the engine keeps an installed
mission in its checkpoint (an upload is checkpointed at once)."""
SETTLED_S = 20.0
"""Flight seconds with no new upload kept before the kill, the checkpoint holding every
vehicle's last mission and none under way: the kill falls between uploads, not in one. The
pop-up round's follow-ups come seconds after it (loiter turns for a vehicle the moved team
time leaves early: decided at its next speed decision, a second on, then worked out and sent
while the simulator waits, kept 3-5 s of flight after the round): the kill is to test a
resume from a settled flight, the vehicles each holding the mission the checkpoint has."""
TOGETHER_MIN_S = 800.0
"""Every pair must be airborne together this long (the separation judged over it): UAV1, the
last up, takes off at its planned 258 s or later, moved with the team time, and the three pass
their goals together at the team time, 1,260 s or later: some 1,000 s (1,090-1,270 s seen, the
truth going on past the goals until the simulator stops)."""


def _compact(directory: Path) -> Path:
    """The compact paper scenario (:func:`tests.teams.compact_paper`) as ``compact.yaml`` in
    ``directory``: the simulator's and both engines' scenario."""
    path = directory / "compact.yaml"
    path.write_text(yaml.safe_dump(compact_paper(), sort_keys=False), encoding="utf-8")
    return path


def _engine_cmd(scenario: Path, base: int, truth: Path, db: str, *extra: str) -> list[str]:
    conns = [f"tcp:127.0.0.1:{base + 10 * i}" for i in range(3)]
    return [
        sys.executable, "-m", "gcs", "rehearse", str(scenario), "--connect", *conns,
        "--truth", str(truth), "--db", db, "--seed", "1", "--tolerance", "2",
        "--lockstep", str(truth.parent / "pace"), *extra,
    ]  # fmt: skip


async def _lines(proc: asyncio.subprocess.Process, into: list[str]) -> None:
    assert proc.stdout is not None
    while line := await proc.stdout.readline():
        into.append(line.decode())


def _carried_on(at_kill: tuple[float, int], said: list[float]) -> tuple[float, int]:
    """The team time and its version a flight resumed with ``at_kill`` has after the team
    arrivals it said since (``said``, in order): each new time is one version more."""
    team_s, version = at_kill
    for t in said:
        if abs(t - team_s) > 1e-3:
            team_s, version = t, version + 1
    return team_s, version


def _kept_team(store: Store, flight_id: str) -> TeamController | None:
    """The team in the checkpoint the store keeps (what a restart resumes from)."""
    blob = store.checkpoint(flight_id)
    if blob is None:
        return None
    team: TeamController = pickle.loads(blob)["team"]
    return team


def _holds_installed(store: Store, flight_id: str) -> bool:
    """The kept checkpoint has every vehicle flying the last mission the store says was
    installed on it, and no upload under way."""
    team = _kept_team(store, flight_id)
    return (
        team is not None
        and not team.pending
        and all(
            list(team.members[v].mission.items) == store.last_upload(flight_id, v) for v in VEHICLES
        )
    )


def _uploads(store: Store, flight_id: str) -> int:
    """How many mission uploads the store has kept for the flight."""
    return sum(e.kind == "upload" for e in store.events(flight_id))


async def test_engine_killed_after_the_popup_resumes_on_the_same_database(tmp_path: Path) -> None:
    base = free_port_base(3)
    truth, counters = tmp_path / "truth.jsonl", tmp_path / "counters.json"
    db = f"sqlite:///{tmp_path / 'tcgcs.db'}"
    away: asyncio.Task[None] | None = None
    scenario = _compact(tmp_path)
    stub = await start_stub(
        scenario, base, truth, "--counters", str(counters), "--wind", f"{WIND[0]:g},{WIND[1]:g}",
        "--loss", "0.05", "--seed", "2", "--lockstep", str(tmp_path / "pace"),
        "--true-wind-estimate",
    )  # fmt: skip
    try:
        first = await asyncio.create_subprocess_exec(
            *_engine_cmd(scenario, base, truth, db),
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
        out: list[str] = []
        reader = asyncio.create_task(_lines(first, out))
        flight_id = None
        store = Store.open(db)
        try:
            # Until the route round the pop-up is on board (its upload kept in the store).
            async with asyncio.timeout(120):
                while True:
                    await asyncio.sleep(0.05)
                    if flight_id is None:
                        said = [x for x in out if " kept in " in x]
                        if not said:
                            continue
                        flight_id = said[0].split("flight ")[1].split()[0]
                    events = store.events(flight_id)
                    if any(
                        e.kind == "upload"
                        and e.vehicle == ROUTED
                        and e.reason.startswith("after POPUP1")
                        for e in events
                    ):
                        last = max(e.seq for e in events)
                        break
            # Until the kept checkpoint has every vehicle's installed mission (its writer runs
            # after the event's) and the round's uploads have settled (:data:`SETTLED_S`):
            # bounded in flight seconds, on the simulator's lock-step clock.
            pace = Lockstep(tmp_path / "pace")
            seen_s = quiet_from_s = pace.pace_s() * pace.speedup
            uploads = _uploads(store, flight_id)
            while True:
                now_s = pace.pace_s() * pace.speedup
                if (n := _uploads(store, flight_id)) != uploads:
                    uploads, quiet_from_s = n, now_s
                if now_s - quiet_from_s >= SETTLED_S and _holds_installed(store, flight_id):
                    break
                flown_s = now_s - seen_s
                assert flown_s <= CHECKPOINT_WITHIN_S + SETTLED_S, (
                    "the checkpoint lacks the installed missions, or uploads went on, "
                    f"{flown_s:.0f} s of flight on"
                )
                await asyncio.sleep(0.02)
            pace.close()
            first.send_signal(signal.SIGKILL)
            await first.wait()
            away = asyncio.create_task(hold_while_away(tmp_path / "pace", AWAY_S))
            await reader
        finally:
            store.close()
        assert first.returncode == -signal.SIGKILL
        before = Store.open(db)
        kept = before.flight(flight_id)
        assert kept.state == "running"
        events_before = before.events(flight_id)
        team = _kept_team(before, flight_id)
        before.close()
        # The team time and its version at the kill, as kept: the pop-up moved it (a new
        # version). The flight's row follows the events as their writer keeps them, and the
        # checkpoint is written apart: the kill may fall between a move's checkpoint and its
        # event, so the row holds the last team time whose event was kept, the checkpoint
        # that or the next.
        assert team is not None and team.team_ref_s is not None
        killed_at = (team.team_ref_s, team.version)
        written = [e.value for e in events_before if e.kind == "arrival" and e.value is not None]
        assert team.version > 1 and written, (killed_at, written)
        assert kept.team_time_s == pytest.approx(written[-1]), (kept.team_time_s, written)
        assert team.team_ref_s >= written[-1] - 1e-3, (killed_at, written)
        assert events_before[-1].seq >= last

        # Started again on the same file: it resumes the flight and flies it home.
        second = await asyncio.create_subprocess_exec(
            *_engine_cmd(
                scenario, base, truth, db, "--resume", flight_id, "--json", str(tmp_path / "r.json")
            ),
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
        async with asyncio.timeout(150):
            stdout, stderr = await second.communicate()
        async with asyncio.timeout(30):
            await away  # ended when the second engine took the simulator's clock over
        assert second.returncode == 0, (story_of_lines(stdout.decode()), stderr.decode()[-3000:])
    finally:
        if away is not None:
            away.cancel()
        if stub.returncode is None:
            stub.send_signal(signal.SIGINT)
        async with asyncio.timeout(20):
            await stub.communicate()

    record: dict[str, Any] = json.loads((tmp_path / "r.json").read_text())
    assert record["flight_id"] == flight_id
    # The team time and its version survived the restart: the resumed flight went on from
    # them (each team arrival it said after the restart one version more, and the last its
    # team time), moving it little. Before, the wind and the pop-up moved it later by no more
    # than they can (tests.paperbounds).
    store = Store.open(db)
    events = store.events(flight_id)
    flight = store.flight(flight_id)
    store.close()
    after = [e for e in events if e.seq > events_before[-1].seq]
    said = [e.value for e in after if e.kind == "arrival" and e.value is not None]
    final = (record["required_arrival_s"], record["snapshot"]["team_time_version"])
    carried = _carried_on(killed_at, said)
    assert final == (pytest.approx(carried[0], abs=1e-3), carried[1]), (killed_at, said, final)
    assert -1e-3 <= final[0] - killed_at[0] <= RESUMED_MOVE_MAX_S, (killed_at, final)  # to 1 ms
    move_max_s = team_time_move_max_s(*WIND, scenario_name="compact")  # the simulator's wind
    moved_s = killed_at[0] - record["planned_arrival_s"]
    assert 0.0 <= moved_s <= move_max_s, (moved_s, move_max_s)
    # Every vehicle on its slot, apart by the scenario's separation and out of its zones
    # the whole flight (before the kill, while the engine was away and after), by the truth.
    assert_flown(
        record,
        truth,
        tolerance_s=TOLERANCE_S,
        team_shift_max_s=move_max_s + RESUMED_MOVE_MAX_S,
        together_min_s=TOGETHER_MIN_S,
    )
    # The resumed run found each vehicle holding the kept mission and launched nobody.
    assert flight.state == "completed"
    seqs = [e.seq for e in events]
    assert seqs == sorted(set(seqs))  # numbered on from the first run, none twice
    resumed = [e for e in after if e.kind == "flight" and e.reason.startswith("resumed")]
    assert {e.vehicle for e in resumed} == {"UAV1", "UAV2", "UAV3"}
    assert all("holds the" in e.reason for e in resumed), [e.reason for e in resumed]
    assert not [e for e in after if e.kind == "launch"]
    # The simulator's own counters: one arm each, and one AUTO each besides the resumes the
    # flight said (a vehicle held short of the pop-up zone when its re-plan came too late for
    # the splice, and resumed AUTO once its route around was on board); every mission it
    # accepted is one the store kept (none sent twice), and the restart read each mission once.
    doc = json.loads(counters.read_text())
    uploads = Counter(e.vehicle for e in events if e.kind == "upload")
    resumes = Counter(
        e.vehicle for e in events if e.kind == "fallback" and "resumed AUTO" in e.reason
    )
    for v, ids in zip(doc["vehicles"], ("UAV1", "UAV2", "UAV3"), strict=True):
        assert v["arms"] == 1, (ids, v)
        assert v["auto_mode_changes"] == 1 + resumes[ids], (ids, v, resumes)
        assert v["mission_uploads"] == uploads[ids], (ids, v, uploads)
        assert v["mission_downloads"] >= 2, (ids, v)  # the first upload's verify, the restart

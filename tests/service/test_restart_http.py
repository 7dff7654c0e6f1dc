"""The service killed (SIGKILL) mid-flight and started again on the same data directory:
the flight is flown on from its checkpoint on the same simulator vehicles (which kept flying
meanwhile), nothing launched twice, the team time and its version as they were when the
service died, and the arrivals still held: judged by the oracle from the simulator's truth
log against the slots set before launch (:func:`tests.verdict.assert_flown`).

The team is the paper's at a quarter of its size (:func:`tests.teams.compact_paper`: some
1,450 s of flight in this wind instead of 5,500 s): the same three vehicles, threats, pop-up
and holding areas, POPUP1 appearing 300 s after UAV1's takeoff across UAV2's route only."""

from __future__ import annotations

import asyncio
import contextlib
import os
import pickle
import signal
from pathlib import Path
from typing import Any

import httpx
import pytest

from gcs.store.repository import Store
from tests.flightstory import story
from tests.gcs.conftest import hold_while_away
from tests.paperbounds import team_time_move_max_s
from tests.service.conftest import serve
from tests.service.test_flights_http import (
    ARRIVAL_TOLERANCE_S,
    _all_events,
    _flight,
    _ok,
    _until,
    truth_log,
)
from tests.verdict import assert_flown

pytestmark = pytest.mark.slow  # about 14 s of wall time (37 s at full size)

AWAY_S = 300.0
"""How long (flight s) the service is away: its simulator flies this far past the kill and
waits for the service started again (:func:`tests.gcs.conftest.hold_while_away`), however
long its start takes on a busy machine."""
RESUMED_MOVE_MAX_S = 30.0
"""How far the team time may move after the restart. The vehicle that sets it (UAV2, on the
longest route and late by then) had been commanded its top speed, or a step under it, before
the kill, and flew on at that unwatched: the gap (:data:`AWAY_S` of flight) costs it at most
one step (1 m/s of 30), under 15 s; 30 s leaves as much again for its arrival estimate. A team
time lost in the restart (the one set before launch taken up again) is caught by its version,
which the wind and the pop-up had moved on: the resumed flight's must be the kept one's, one
more for each team arrival said since. The arrivals are then judged as in test_flights_http:
the resumed coordinator has some 380 s of flight (from some 1,070 s to the team time, some
1,450 s) to correct what the gap cost."""
POPUP_NOT_BEFORE_S = 558.0
"""Mission seconds before which POPUP1 does not appear: 300 s (1,200 s at full size) after
UAV1's takeoff, which is at its planned 258 s or later (its slot moves with the team time,
only later). The test looks for the re-plan from there; here it comes at some 730 s: before
UAV1 took off, the north wind had moved the team time, and the takeoff with it, 170 s later."""
TOGETHER_MIN_S = 800.0
"""Every pair must be airborne together this long (the separation judged over it): UAV1, the
last up, takes off at its planned 258 s or later (some 430 s here), moved with the team time,
and the three pass their goals together at the team time (some 1,450 s here): some 1,000 s
(1,012-1,018 s seen, the truth going on past the goals until the simulator stops)."""
CHECKPOINT_WITHIN_S = 200.0
"""Flight seconds (one wall second at 200x) within which the service keeps a team time it
has said in its checkpoint (a team-time move is checkpointed at once)."""


def _stop_orphans(data: Path) -> None:
    """The simulators the killed service started (they outlive it) are stopped whatever
    the test found."""
    for pid_file in data.glob("flights/*/stub.pid"):
        with contextlib.suppress(ValueError, OSError):
            os.kill(int(pid_file.read_text()), signal.SIGINT)


async def test_a_killed_service_flies_its_flight_on_when_started_again(tmp_path: Path) -> None:
    data = tmp_path / "data"
    try:
        await _kill_and_restart(data)
    finally:
        _stop_orphans(data)


def _carried_on(
    said: tuple[float, int], events: list[dict[str, Any]], after_seq: int, until_seq: int
) -> tuple[float, int]:
    """The team time and its version a flight that said ``said`` (at event ``after_seq``) has
    at event ``until_seq``: each team arrival said with a new time in between is one
    version more."""
    team_s, version = said
    moves = [
        e["value"] for e in events if after_seq < e["seq"] <= until_seq and e["kind"] == "arrival"
    ]
    for t in moves:
        if t is not None and abs(t - team_s) > 1e-3:
            team_s, version = t, version + 1
    return team_s, version


async def _team_time(client: httpx.AsyncClient, fid: str) -> tuple[tuple[float, int], int]:
    """The team time (mission s) and its version the service says (its snapshot, with the
    last event it had said then), checked against its team-time resource and ETag."""
    snap = _ok(await client.get(f"/v1/flights/{fid}"))
    r = await client.get(f"/v1/flights/{fid}/team-time")
    body = _ok(r)
    assert r.headers["ETag"] == f'"{body["version"]}"', (r.headers, body)
    said = (float(snap["team_time_s"]), int(snap["team_time_version"]))
    if (body["team_time_s"], body["version"]) != said:  # moved between the two reads
        return await _team_time(client, fid)
    return said, int(snap["last_seq"])


def _kept_team_time(data: Path, fid: str) -> tuple[float, int] | None:
    """The team time and its version in the checkpoint the service keeps for ``fid`` (what a
    restart resumes from; None before the first)."""
    store = Store.open(f"sqlite:///{data / 'tcgcs.db'}", migrate=False)
    try:
        blob = store.checkpoint(fid)
    finally:
        store.close()
    if blob is None:
        return None
    team = pickle.loads(blob)["team"]
    return float(team.team_ref_s), int(team.version)


async def _kill_and_restart(data: Path) -> None:
    async with serve(data) as first, first.client() as client:
        fid, _ = await _flight(
            client, {"speedup": 200.0, "wind_m_s": 4.0, "seed": 3}, scenario_name="compact"
        )
        _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
        await _until(client, fid, POPUP_NOT_BEFORE_S)  # launched, and up to the pop-up
        before = await _all_events(client, fid)
        while not any(e["kind"] == "replan" for e in before):
            await asyncio.sleep(0.05)
            before = await _all_events(client, fid)
        # The team time the service says, once its checkpoint holds it too (the kill must
        # not race the checkpoint's writer): bounded in flight seconds.
        said_at = _ok(await client.get(f"/v1/flights/{fid}"))["t_s"]
        while True:
            said, said_seq = await _team_time(client, fid)
            kept = await asyncio.to_thread(_kept_team_time, data, fid)
            if kept == said:
                break
            now = _ok(await client.get(f"/v1/flights/{fid}"))["t_s"]
            assert now - said_at <= CHECKPOINT_WITHIN_S, (
                f"the checkpoint holds {kept}, the service says {said} (team time, version) "
                f"{now - said_at:.0f} s of flight later"
            )
            await asyncio.sleep(0.05)
        first.proc.send_signal(signal.SIGKILL)
        await first.proc.wait()
        away = asyncio.create_task(hold_while_away(data / "flights" / fid / "pace", AWAY_S))
    try:
        assert {e["kind"] for e in before} >= {"launch", "replan"}
        await _resumed(data, fid, said, said_seq, before)
    finally:
        away.cancel()


async def _resumed(
    data: Path,
    fid: str,
    said: tuple[float, int],
    said_seq: int,
    before: list[dict[str, Any]],
) -> None:
    """The service started again on ``data``: it resumes flight ``fid`` (killed when it had
    said team time ``said`` at event ``said_seq``, events ``before``) and flies it home."""
    async with serve(data) as second, second.client() as client:
        flights = _ok(await client.get("/v1/flights"))
        assert [f["id"] for f in flights] == [fid]
        # The team time and its version survived the restart: the resumed flight's first
        # snapshot has the ones the first service said, moved on by any team arrival said
        # since (up to the snapshot's last event).
        resumed, resumed_seq = await _team_time(client, fid)
        kept_events = await _all_events(client, fid)
        while kept_events[-1]["seq"] < resumed_seq:  # the store's writer is behind
            await asyncio.sleep(0.05)
            kept_events = await _all_events(client, fid)
        assert resumed == _carried_on(said, kept_events, said_seq, resumed_seq), (said, resumed)
        while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["state"] not in (
            "completed", "failed", "aborted",
        ):  # fmt: skip
            await asyncio.sleep(0.2)
        assert snap["state"] == "completed", snap
        while (r := await client.get(f"/v1/flights/{fid}/record")).status_code == 404:
            await asyncio.sleep(0.2)
        record: dict[str, Any] = _ok(r)
        after = await _all_events(client, fid)
        truth = truth_log(second, fid)
    print(story(after, limit=200))  # shown when the test fails
    # The team time: the wind and the pop-up moved it later by no more than they can
    # (tests.paperbounds), and the resumed flight carried it (and its version) on to the
    # end, moving it little.
    final = (record["required_arrival_s"], record["snapshot"]["team_time_version"])
    carried = _carried_on(said, after, said_seq, after[-1]["seq"])
    assert final == (pytest.approx(carried[0], abs=1e-3), carried[1]), (said, final)
    assert -1e-3 <= final[0] - said[0] <= RESUMED_MOVE_MAX_S, (said, final)  # kept to 1 ms
    # The rehearsal's wind, from the north (the default), on the compact team.
    move_max_s = team_time_move_max_s(4.0, 0.0, scenario_name="compact")
    moved_s = said[0] - record["planned_arrival_s"]
    assert 0.0 <= moved_s <= move_max_s, (moved_s, move_max_s)
    # Every vehicle on its slot, apart by the scenario's separation and out of the zones, the
    # whole flight (before the kill, while the service was away and after), by the truth.
    assert_flown(
        record,
        truth,
        tolerance_s=ARRIVAL_TOLERANCE_S,
        team_shift_max_s=move_max_s + RESUMED_MOVE_MAX_S,
        together_min_s=TOGETHER_MIN_S,
    )
    # The events go on from the first process's, numbered on; nobody was launched again and
    # each vehicle was found holding its mission.
    seqs = [e["seq"] for e in after]
    assert seqs == sorted(set(seqs)) and seqs[: len(before)] == [e["seq"] for e in before]
    later = after[len(before) :]
    assert not [e for e in later if e["kind"] == "launch"]
    found = [e for e in later if e["kind"] == "flight" and e["reason"].startswith("resumed")]
    assert len(found) == 3 and all("holds the" in e["reason"] for e in found), found

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
import json
import os
import pickle
import signal
import sqlite3
import time
from collections import Counter
from pathlib import Path
from typing import Any

import httpx
import pytest

from gcs.store.repository import Store
from tests.flightstory import story
from tests.gcs.conftest import hold_while_away
from tests.paperbounds import team_time_move_max_s
from tests.service.conftest import may_raise_priority, nice_of, serve
from tests.service.test_flights_http import (
    ARRIVAL_TOLERANCE_S,
    _all_events,
    _flight,
    _ok,
    _paused,
    _taken_on,
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
SIGNAL_AT_S = 850.0
"""The mission second at which a worker is killed or hung: the rehearsal paused there (past
the re-plan round POPUP1, at some 730 s), so that where the flight is when its worker goes, and
so how long it has left once taken on, is the same on any machine. Signalled as the flight
ran on, under load it went as late as 1,075 s: taken on 34 s before the team time, a vehicle
at its top speed could not make up what it had lost unwatched."""
CHECKPOINT_WITHIN_S = 200.0
"""Flight seconds (one wall second at 200x) within which the service keeps a team time it
has said in its checkpoint (a team-time move is checkpointed at once)."""


def _gone_within(pid: int, wall_s: float) -> bool:
    """Process ``pid`` has exited (or is a zombie its parent has not reaped) within
    ``wall_s``."""
    deadline = time.monotonic() + wall_s
    while time.monotonic() < deadline:
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            return True
        if stat.rsplit(")", 1)[1].split()[0] == "Z":
            return True
        time.sleep(0.05)
    return False


def _stop_orphans(data: Path) -> None:
    """The simulators and flight workers a killed service started (they outlive it) are
    stopped whatever the test found."""
    for pid_file in [*data.glob("flights/*/stub.pid"), *data.glob("flights/*/worker.pid")]:
        with contextlib.suppress(ValueError, OSError):
            os.kill(int(pid_file.read_text()), signal.SIGINT)


HUNG_WORKER = {"TCGCS_WORKER_SILENCE_S": "2", "TCGCS_WORKER_ANSWER_S": "2"}
"""The service's watch on its workers in these tests: a worker that says nothing for 2 s of
wall time, and does not answer within 2 s more, is hung (a healthy one says the flight's state
four times a second; one slowed by a busy machine and asked answers, and is followed again)."""
WORKER_NICE = -2
"""The workers' priority asked for (``TCGCS_WORKER_NICE``) where a test checks it."""


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGSTOP], ids=["killed", "hung"])
async def test_a_killed_or_hung_flight_worker_is_flown_on_from_its_checkpoint(
    tmp_path: Path, how: signal.Signals
) -> None:
    """The flight's worker killed (SIGKILL) or hung (SIGSTOP: alive, silent) after the
    re-plan: the service starts another on its checkpoint (the hung one killed first: never two
    on one flight's vehicles), which finds the vehicles (flown on by the simulator,
    :data:`AWAY_S` of flight past the signal) holding their missions and flies them home."""
    data = tmp_path / "data"
    settings = {**HUNG_WORKER, "TCGCS_WORKER_NICE": str(WORKER_NICE)}
    try:
        async with (
            serve(data, settings=settings, spare_worker=True) as svc,
            svc.client() as client,
        ):
            fid, said, said_seq, before = await _past_the_replan(
                client, data, pause_at_s=SIGNAL_AT_S
            )
            worker = _ok(await client.get(f"/v1/flights/{fid}"))["worker"]
            pid = worker["pid"]
            spare = svc.spare_workers()
            assert len(spare) == 1, spare  # started when the flight's worker was
            # TCGCS_WORKER_NICE: the workers (the spare too) ahead of the service, where the
            # privilege allows (else they say so and run at the service's).
            nice = WORKER_NICE if may_raise_priority() else nice_of(svc.proc.pid)
            assert worker["nice"] == nice_of(pid) == nice_of(spare[0]) == nice, worker
            assert nice_of(svc.proc.pid) == os.getpriority(os.PRIO_PROCESS, 0)
            os.kill(pid, how)
            away = asyncio.create_task(hold_while_away(data / "flights" / fid / "pace", AWAY_S))
            try:
                taken = await _taken_on(client, fid, pid)
                assert taken["worker"]["pid"] == spare[0], (taken["worker"], spare)
                gone = await asyncio.to_thread(_gone_within, pid, 5.0)
                assert gone, f"the old worker (pid {pid}) still runs beside the new one"
                # The new worker keeps the pause, where the simulator had got to: resumed.
                while not (snap := _ok(await client.get(f"/v1/flights/{fid}")))["pause"]["paused"]:
                    assert snap["state"] in ("ready", "running"), snap["state"]
                    await asyncio.sleep(0.05)
                assert snap["t_s"] > SIGNAL_AT_S, snap["t_s"]  # flown on unwatched meanwhile
                _ok(await client.post(f"/v1/flights/{fid}/resume"))
                await _flown_on(client, svc, fid, said, said_seq, before, restarted=True)
            finally:
                away.cancel()
    finally:
        _stop_orphans(data)


async def test_a_killed_service_leaves_its_flight_flying_and_the_next_one_follows_it(
    tmp_path: Path,
) -> None:
    """The service killed (SIGKILL) after the re-plan: the flight's worker flies on (the
    same process throughout); the service started again lists the flight, and its stream
    from the last event seen before the kill loses none."""
    data = tmp_path / "data"
    try:
        async with serve(data) as first, first.client() as client:
            fid, said, said_seq, before = await _past_the_replan(client, data)
            pid = _ok(await client.get(f"/v1/flights/{fid}"))["worker"]["pid"]
            first.proc.send_signal(signal.SIGKILL)
            await first.proc.wait()
        async with serve(data) as second, second.client() as client:
            streamed = await _streamed(second, fid, before[-1]["seq"])
            assert [e["seq"] for e in streamed] == list(
                range(before[-1]["seq"] + 1, before[-1]["seq"] + 1 + len(streamed))
            )
            await _flown_on(client, second, fid, said, said_seq, before, restarted=False)
            snap = _ok(await client.get(f"/v1/flights/{fid}"))
            assert snap["worker"]["pid"] == pid, "the flight changed workers"
            after = await _all_events(client, fid)
            assert streamed == after[len(before) :]
    finally:
        _stop_orphans(data)


async def _streamed(svc: Any, fid: str, after_seq: int) -> list[dict[str, Any]]:
    """The flight's events after ``after_seq`` from its stream (SSE), until its end."""
    events = []
    async with svc.client() as client, client.stream(
        "GET", f"/v1/flights/{fid}/stream", params={"after_seq": after_seq},
        headers={"Accept": "text/event-stream"}, timeout=None,
    ) as r:  # fmt: skip
        kind = None
        async for line in r.aiter_lines():
            if line.startswith("event: "):
                kind = line[len("event: ") :]
            elif line.startswith("data: ") and kind == "event":
                events.append(json.loads(line[len("data: ") :]))
            elif line.startswith("data: ") and kind == "end":
                break
    return events


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


async def _past_the_replan(
    client: httpx.AsyncClient, data: Path, *, pause_at_s: float | None = None
) -> tuple[str, tuple[float, int], int, list[dict[str, Any]]]:
    """A flight launched and flown past its re-plan round POPUP1 (and paused at
    ``pause_at_s``, a mission second past it, if given): its id, the team time and version it
    says (kept in its checkpoint too), the last event it had said then, and its events so
    far."""
    fid, _ = await _flight(
        client, {"speedup": 200.0, "wind_m_s": 4.0, "seed": 3}, scenario_name="compact"
    )
    if pause_at_s is not None:
        _ok(await client.post(f"/v1/flights/{fid}/pause", json={"at_s": pause_at_s}))
    _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
    if pause_at_s is not None:
        await _paused(client, fid, pause_at_s)
    else:
        await _until(client, fid, POPUP_NOT_BEFORE_S)  # launched, and up to the pop-up
    before = await _all_events(client, fid)
    while not any(e["kind"] == "replan" for e in before):
        assert pause_at_s is None, f"no re-plan round POPUP1 by {pause_at_s} s"
        await asyncio.sleep(0.05)
        before = await _all_events(client, fid)
    # The team time the service says, once its checkpoint holds it too (the kill must not
    # race the checkpoint's writer): bounded in flight seconds.
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
    before = await _all_events(client, fid)
    assert {e["kind"] for e in before} >= {"launch", "replan"}
    return fid, said, said_seq, before


async def _flown_on(
    client: httpx.AsyncClient,
    second: Any,
    fid: str,
    said: tuple[float, int],
    said_seq: int,
    before: list[dict[str, Any]],
    *,
    restarted: bool,
) -> None:
    """Flight ``fid`` (which had said team time ``said`` at event ``said_seq``, events
    ``before``, when its worker or its service was killed) flown home: on its checkpoint by a
    new worker (``restarted``), or by the same one."""
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
    while (r := await client.get(f"/v1/flights/{fid}/record")).status_code == 404:
        await asyncio.sleep(0.2)
    record: dict[str, Any] = _ok(r)
    after = await _all_events(client, fid)
    print(story(after, limit=200))  # shown when the test fails
    assert snap["state"] == "completed", (snap["state"], snap.get("state_reason"))
    truth = truth_log(second, fid)
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
    if restarted:
        assert len(found) == 3 and all("holds the" in e["reason"] for e in found), found
    else:
        assert not found, found
    # The simulator's own counters: one arm each, and one AUTO each besides the resumes the
    # flight said; every mission it accepted is one the flight said it uploaded (none sent
    # twice), and a restart read each mission back.
    doc = json.loads((second.data_dir / "flights" / fid / "counters.json").read_text())
    uploads = Counter(e["vehicle"] for e in after if e["kind"] == "upload")
    resumes = Counter(
        e["vehicle"] for e in after if e["kind"] == "fallback" and "resumed AUTO" in e["reason"]
    )
    for v, ids in zip(doc["vehicles"], ("UAV1", "UAV2", "UAV3"), strict=True):
        assert v["arms"] == 1, (ids, v)
        assert v["auto_mode_changes"] == 1 + resumes[ids], (ids, v, resumes)
        assert v["mission_uploads"] == uploads[ids], (ids, v, uploads)
        assert v["mission_downloads"] >= 1 + restarted, (ids, v)


async def test_a_worker_killed_before_the_launch_leaves_its_flight_ready_to_launch(
    tmp_path: Path,
) -> None:
    """A worker killed with its flight uploaded but not launched: another takes it on from its
    checkpoint, finds each vehicle holding its mission (nothing sent again), and the flight,
    ready again, is launched and flown home on its slots."""
    data = tmp_path / "data"
    try:
        async with serve(data, spare_worker=True) as svc, svc.client() as client:
            fid, _ = await _flight(client, {"speedup": 200.0, "seed": 5}, scenario_name="compact")
            pid = _ok(await client.get(f"/v1/flights/{fid}"))["worker"]["pid"]
            os.kill(pid, signal.SIGKILL)
            snap = await _taken_on(client, fid, pid)
            assert snap["state"] == "ready", snap["state"]
            _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
            while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["state"] not in (
                "completed", "failed", "aborted",
            ):  # fmt: skip
                await asyncio.sleep(0.2)
            assert snap["state"] == "completed", snap["state"]
            while (r := await client.get(f"/v1/flights/{fid}/record")).status_code == 404:
                await asyncio.sleep(0.2)
            record = _ok(r)
            events = await _all_events(client, fid)
        print(story(events, limit=200))  # shown when the test fails
        found = [e for e in events if e["kind"] == "flight" and e["reason"].startswith("resumed")]
        assert len(found) == 3 and all("holds the" in e["reason"] for e in found), found
        assert_flown(
            record,
            truth_log(svc, fid),
            tolerance_s=ARRIVAL_TOLERANCE_S,
            team_shift_max_s=team_time_move_max_s(scenario_name="compact"),
            together_min_s=TOGETHER_MIN_S,
        )
        # The simulator's counters: one arm each; every mission it accepted is one the flight
        # said it uploaded, and none between the restart and the launch (none sent again).
        doc = json.loads((data / "flights" / fid / "counters.json").read_text())
        uploads = Counter(e["vehicle"] for e in events if e["kind"] == "upload")
        running = next(e["seq"] for e in events if e["payload"].get("state") == "running")
        assert not [
            e for e in events if e["kind"] == "upload" and found[0]["seq"] < e["seq"] < running
        ]
        for v, vid in zip(doc["vehicles"], ("UAV1", "UAV2", "UAV3"), strict=True):
            assert v["arms"] == 1 and v["mission_uploads"] == uploads[vid], (vid, v, uploads)
            assert v["mission_downloads"] >= 1, v
    finally:
        _stop_orphans(data)


async def test_a_flight_no_worker_can_fly_on_fails_and_says_so(tmp_path: Path) -> None:
    """A worker killed when its flight's checkpoint is gone (nothing to fly on from): the
    flight fails, said by a ``flight`` event and an alarm, and kept so (a service started
    again shows it failed); its simulator is stopped; a launch is refused."""
    data = tmp_path / "data"
    try:
        async with serve(data, spare_worker=True) as svc, svc.client() as client:
            fid, _ = await _flight(client, {"speedup": 200.0, "seed": 5}, scenario_name="compact")
            pid = _ok(await client.get(f"/v1/flights/{fid}"))["worker"]["pid"]
            stub_pid = int((data / "flights" / fid / "stub.pid").read_text())
            # Stopped (it writes no checkpoint again) when it holds no lock on the store.
            await asyncio.to_thread(_stop_and_drop_checkpoint, pid, data, fid)
            os.kill(pid, signal.SIGKILL)
            while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["state"] == "ready":
                await asyncio.sleep(0.05)
            assert snap["state"] == "failed", snap["state"]
            refused = await client.post(f"/v1/flights/{fid}/launch", json={})
            assert refused.status_code == 409, refused.text
            assert await asyncio.to_thread(_gone_within, stub_pid, 30.0), "its simulator runs on"
            while len(events := await _all_events(client, fid)) < 2 or (
                events[-1]["kind"] != "alarm"
            ):
                await asyncio.sleep(0.05)
        said = events[-2:]
        assert [e["kind"] for e in said] == ["flight", "alarm"], said
        assert said[0]["payload"] == {"state": "failed", "was": "ready"}, said
        assert f"worker (pid {pid}) died" in said[1]["reason"], said
        assert "no checkpoint to fly on from" in said[1]["reason"], said  # why, said too
        async with serve(data) as again, again.client() as client:
            assert _ok(await client.get(f"/v1/flights/{fid}"))["state"] == "failed"
            assert (await _all_events(client, fid))[-2:] == said
    finally:
        _stop_orphans(data)


def _stop_and_drop_checkpoint(pid: int, data: Path, fid: str) -> None:
    """Stop the worker ``pid`` (SIGSTOP) and drop the flight's checkpoint from the service's
    store (SQLite). Stopped in the middle of a write, it holds the store's lock until it runs
    again: it is let go on a little and stopped again."""
    for _ in range(100):
        os.kill(pid, signal.SIGSTOP)
        try:
            with contextlib.closing(sqlite3.connect(data / "tcgcs.db", timeout=0.5)) as db, db:
                db.execute("update flights set checkpoint = null where id = ?", (fid,))
            return
        except sqlite3.OperationalError as err:
            if "locked" not in str(err):
                raise
            os.kill(pid, signal.SIGCONT)
            time.sleep(0.1)
    raise AssertionError(f"the worker (pid {pid}) always held the store's lock")

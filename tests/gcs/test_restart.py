"""Restart safety: the engine's process is killed (SIGKILL) mid-flight, after the pop-up
re-plan, and started again on the same SQLite file. The simulator runs on its own throughout
and keeps its own counters; the arrivals are read from its truth log here."""

from __future__ import annotations

import asyncio
import json
import signal
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from gcs.coordination.tracks import closest_approach
from gcs.rehearsal.truth import read_truth
from gcs.store.repository import Store
from planner.scenario import load_scenario
from tests.flightstory import story_of_lines
from tests.gcs.conftest import PAPER, start_stub
from tests.sitl_stub.conftest import free_port_base

pytestmark = pytest.mark.slow  # about 45 s of wall time


def _engine_cmd(base: int, truth: Path, db: str, *extra: str) -> list[str]:
    conns = [f"tcp:127.0.0.1:{base + 10 * i}" for i in range(3)]
    return [
        sys.executable, "-m", "gcs", "rehearse", str(PAPER), "--connect", *conns,
        "--truth", str(truth), "--db", db, "--seed", "1", "--tolerance", "2",
        "--lockstep", str(truth.parent / "pace"), *extra,
    ]  # fmt: skip


async def _lines(proc: asyncio.subprocess.Process, into: list[str]) -> None:
    assert proc.stdout is not None
    while line := await proc.stdout.readline():
        into.append(line.decode())


async def test_engine_killed_after_the_popup_resumes_on_the_same_database(tmp_path: Path) -> None:
    base = free_port_base(3)
    truth, counters = tmp_path / "truth.jsonl", tmp_path / "counters.json"
    db = f"sqlite:///{tmp_path / 'tcgcs.db'}"
    stub = await start_stub(
        PAPER, base, truth, "--counters", str(counters), "--wind", "5,270", "--loss", "0.05",
        "--seed", "2", "--lockstep", str(tmp_path / "pace"),
    )  # fmt: skip
    try:
        first = await asyncio.create_subprocess_exec(
            *_engine_cmd(base, truth, db),
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
        out: list[str] = []
        reader = asyncio.create_task(_lines(first, out))
        flight_id = None
        store = Store.open(db)
        try:
            # Until the re-planned routes are on board (kept in the store) and checkpointed.
            async with asyncio.timeout(120):
                while True:
                    await asyncio.sleep(0.05)
                    if flight_id is None:
                        said = [x for x in out if " kept in " in x]
                        if not said:
                            continue
                        flight_id = said[0].split("flight ")[1].split()[0]
                    events = store.events(flight_id)
                    installed = {
                        e.vehicle
                        for e in events
                        if e.kind == "upload" and e.reason.startswith("after POPUP1")
                    }
                    if {"UAV1", "UAV2"} <= installed and store.checkpoint(flight_id):
                        last = max(e.seq for e in events)
                        break
            await asyncio.sleep(0.3)  # the checkpoint of the last install is written
            first.send_signal(signal.SIGKILL)
            await first.wait()
            await reader
        finally:
            store.close()
        assert first.returncode == -signal.SIGKILL
        before = Store.open(db)
        kept = before.flight(flight_id)
        assert kept.state == "running"
        events_before = before.events(flight_id)
        before.close()
        assert events_before[-1].seq >= last

        # Started again on the same file: it resumes the flight and flies it home.
        second = await asyncio.create_subprocess_exec(
            *_engine_cmd(
                base, truth, db, "--resume", flight_id, "--json", str(tmp_path / "r.json")
            ),
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
        async with asyncio.timeout(150):
            stdout, stderr = await second.communicate()
        assert second.returncode == 0, (story_of_lines(stdout.decode()), stderr.decode()[-3000:])
    finally:
        if stub.returncode is None:
            stub.send_signal(signal.SIGINT)
        async with asyncio.timeout(20):
            await stub.communicate()

    record: dict[str, Any] = json.loads((tmp_path / "r.json").read_text())
    assert record["flight_id"] == flight_id
    # Every arrival within 2 s of the team time, read from the simulator's truth log here.
    scenario = load_scenario(PAPER)
    frame = scenario.frame()
    samples = read_truth(truth)
    for i, v in enumerate(record["vehicles"]):
        goal = scenario.vehicles[i].goal
        lat, lon = frame.to_geodetic(goal.east_m, goal.north_m)
        ca = closest_approach(samples[i + 1], float(lat), float(lon), 1000.0)
        assert ca is not None, v["id"]
        assert abs(ca[0] - v["target_arrival_utc_s"]) <= 2.0, (v["id"], ca[0], v)
    # The resumed run found each vehicle holding the kept mission and launched nobody.
    store = Store.open(db)
    events = store.events(flight_id)
    flight = store.flight(flight_id)
    store.close()
    assert flight.state == "completed"
    seqs = [e.seq for e in events]
    assert seqs == sorted(set(seqs))  # numbered on from the first run, none twice
    after = [e for e in events if e.seq > events_before[-1].seq]
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

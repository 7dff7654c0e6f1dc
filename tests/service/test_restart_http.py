"""The service killed (SIGKILL) mid-flight and started again on the same data directory:
the flight is flown on from its checkpoint on the same simulator vehicles (which kept flying
meanwhile), nothing launched twice, and the arrivals still held (the simulator's truth)."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
from pathlib import Path

import pytest

from tests.flightstory import story
from tests.service.conftest import serve
from tests.service.test_flights_http import _all_events, _flight, _ok, _until

pytestmark = pytest.mark.slow  # about 45 s of wall time


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


async def _kill_and_restart(data: Path) -> None:
    async with serve(data) as first, first.client() as client:
        fid, _ = await _flight(client, {"speedup": 200.0, "wind_m_s": 4.0, "seed": 3})
        _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
        await _until(client, fid, 2000.0)  # launched, and past the pop-up re-plan
        before = await _all_events(client, fid)
        while not any(e["kind"] == "replan" for e in before):
            await asyncio.sleep(0.05)
            before = await _all_events(client, fid)
        first.proc.send_signal(signal.SIGKILL)
        await first.proc.wait()
    assert {e["kind"] for e in before} >= {"launch", "replan"}
    async with serve(data) as second, second.client() as client:
        flights = _ok(await client.get("/v1/flights"))
        assert [f["id"] for f in flights] == [fid]
        while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["state"] not in (
            "completed", "failed", "aborted",
        ):  # fmt: skip
            await asyncio.sleep(0.2)
        assert snap["state"] == "completed", snap
        while (r := await client.get(f"/v1/flights/{fid}/record")).status_code == 404:
            await asyncio.sleep(0.2)
        record = _ok(r)
        after = await _all_events(client, fid)
    # Every arrival within 2 s of its slot, read from the simulator's truth log.
    assert record["arrival_source"] == "simulator"
    print(story(after, limit=200))  # shown when the test fails
    for v in record["vehicles"]:
        assert v["error_s"] is not None and abs(v["error_s"]) <= 2.0, (
            v["id"], v["error_s"], story(after),
        )  # fmt: skip
    # The events go on from the first process's, numbered on; nobody was launched again and
    # each vehicle was found holding its mission.
    seqs = [e["seq"] for e in after]
    assert seqs == sorted(set(seqs)) and seqs[: len(before)] == [e["seq"] for e in before]
    later = after[len(before) :]
    assert not [e for e in later if e["kind"] == "launch"]
    found = [e for e in later if e["kind"] == "flight" and e["reason"].startswith("resumed")]
    assert len(found) == 3 and all("holds the" in e["reason"] for e in found), found

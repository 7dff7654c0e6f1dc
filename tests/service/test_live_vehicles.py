"""Registered vehicles (``POST /v1/vehicles``), not a rehearsal: three vehicles of a simulator
the test starts on its own (as an operator's autopilots are), flown through the service. The
flight's worker takes their links over (the service closes its own) and gives them back when
the flight ends; every arrival is judged by the simulator's truth log.

The simulator, started apart at 200x, keeps a lock-step file that the flight joins
(``lockstep`` in ``POST /v1/flights``, from the service's ``TCGCS_LOCKSTEP_DIR``): it waits for
the flight's worker, so a busy machine slows the flight instead of making it late. The paper's
team drawn at a quarter of its size (:func:`tests.teams.compact_paper`): some 1,450 s of
flight."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest
import yaml

from sitl_stub.lockstep import Lockstep
from tests.gcs.conftest import start_stub
from tests.service.conftest import proc_stat, serve
from tests.service.test_flights_http import _ok, _scheduled
from tests.sitl_stub.conftest import free_port_base
from tests.teams import compact_paper
from tests.verdict import assert_flown

pytestmark = pytest.mark.slow  # some 30 s of wall time

SPEEDUP = 200.0
TOLERANCE_S = 1.0
"""The bound for a flight on registered vehicles."""


async def test_registered_vehicles_are_flown_by_the_flight_worker_and_given_back(
    tmp_path: Path,
) -> None:
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(yaml.safe_dump(compact_paper(), sort_keys=False))
    truth = tmp_path / "truth.jsonl"
    pace = tmp_path / "sim" / "pace"
    pace.parent.mkdir()
    base = free_port_base(3)
    stub = await start_stub(scenario, base, truth, "--lockstep", str(pace), speedup=SPEEDUP)
    settings = {"TCGCS_LOCKSTEP_DIR": str(pace.parent)}
    try:
        async with (
            serve(tmp_path / "data", settings=settings) as service,
            service.client() as client,
        ):
            ids = []
            for i in range(3):
                conn = f"tcp:127.0.0.1:{base + 10 * i}"
                ids.append(
                    _ok(await client.post("/v1/vehicles", json={"connection": conn}), 201)["id"]
                )
            job = await _scheduled(client, scenario.read_text())
            names = [v["id"] for v in job["result"]["vehicles"]]
            body = {
                "schedule_id": job["result"]["id"],
                "vehicles": dict(zip(names, ids, strict=True)),
                "lockstep": str(pace),
            }
            fid = _ok(await client.post("/v1/flights", json=body), 201)["flight_id"]
            # In the flight: shown as its worker sees them.
            held = {v["id"]: v for v in _ok(await client.get("/v1/vehicles"))}
            assert {held[i]["flight_id"] for i in ids} == {fid}, held
            _ok(await client.post(f"/v1/flights/{fid}/upload"), 202)
            while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["state"] != "ready":
                assert snap["state"] in ("planned", "uploading"), snap["uploads"]
                await asyncio.sleep(0.1)
            _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
            flown_by: set[int] = set()
            while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["state"] not in (
                "completed", "failed", "aborted",
            ):  # fmt: skip
                if snap["state"] == "running":
                    pid = snap["worker"]["pid"]
                    # A worker process of the service's, not the service itself.
                    assert isinstance(pid, int) and pid != service.proc.pid, snap["worker"]
                    assert int(proc_stat(pid)[1]) == service.proc.pid, pid
                    flown_by.add(pid)
                await asyncio.sleep(0.5)
            assert snap["state"] == "completed", snap["state_reason"]
            assert flown_by, "never seen running"
            while (r := await client.get(f"/v1/flights/{fid}/record")).status_code == 404:
                await asyncio.sleep(0.2)
            record: dict[str, Any] = _ok(r)
            # Given back: the service holds their links again, in no flight.
            async with asyncio.timeout(30):
                while True:
                    views = {v["id"]: v for v in _ok(await client.get("/v1/vehicles"))}
                    if all(
                        views[i]["flight_id"] is None and views[i]["link"]["healthy"] for i in ids
                    ):
                        break
                    await asyncio.sleep(0.2)
        # The flight's worker kept the lock step: it acknowledged the flight to its end.
        joined = Lockstep(pace)
        try:
            assert joined.acknowledged_s() * SPEEDUP > record["required_arrival_s"], (
                joined.acknowledged_s(), record["required_arrival_s"],
            )  # fmt: skip
        finally:
            joined.close()
    finally:
        stub.terminate()
        await stub.wait()
    assert_flown(record, truth, tolerance_s=TOLERANCE_S, team_shift_max_s=300.0, together_min_s=0.0)

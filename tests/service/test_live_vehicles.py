"""Registered vehicles (``POST /v1/vehicles``), not a rehearsal: three vehicles of a simulator
the test starts on its own (as an operator's autopilots are), flown through the service. The
flight's worker takes their links over (the service closes its own) and gives them back when
the flight ends; every arrival is judged by the simulator's truth log.

The simulator runs on the wall clock (as real vehicles do, no lock step) at 40x, the paper's
team drawn at a quarter of its size (:func:`tests.teams.compact_paper`): some 1,450 s of
flight, under a minute of wall time."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.gcs.conftest import start_stub
from tests.service.conftest import Service
from tests.service.test_flights_http import _ok, _scheduled
from tests.sitl_stub.conftest import free_port_base
from tests.teams import compact_paper
from tests.verdict import assert_flown

pytestmark = pytest.mark.slow  # some 60 s of wall time

SPEEDUP = 40.0
TOLERANCE_S = 1.0
"""The issue's bound for a flight on the wall clock."""


async def test_registered_vehicles_are_flown_by_the_flight_worker_and_given_back(
    service: Service, tmp_path: Path
) -> None:
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(yaml.safe_dump(compact_paper(), sort_keys=False))
    truth = tmp_path / "truth.jsonl"
    base = free_port_base(3)
    stub = await start_stub(scenario, base, truth, speedup=SPEEDUP)
    try:
        async with service.client() as client:
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
            while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["state"] not in (
                "completed", "failed", "aborted",
            ):  # fmt: skip
                await asyncio.sleep(0.5)
            assert snap["state"] == "completed", snap["state_reason"]
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
    finally:
        stub.terminate()
        await stub.wait()
    assert_flown(record, truth, tolerance_s=TOLERANCE_S, team_shift_max_s=300.0, together_min_s=0.0)

"""A rehearsal paused over HTTP (``POST /v1/flights/{id}/pause`` and ``/resume``): its
simulator, in lock step with the flight, waits at the mission second asked for, however long
the operator takes, and flies on when resumed; a flight whose vehicles cannot wait refuses."""

from __future__ import annotations

import asyncio
import os
import signal

import pytest
import yaml

from tests.gcs.conftest import hold_while_away
from tests.service.conftest import Service
from tests.service.test_flights_http import _flight, _ok, _paused, _scheduled, _taken_on
from tests.teams import compact_paper

pytestmark = pytest.mark.slow  # some 10 s of wall time

PAUSE_AT_S = 100.0
"""Mission seconds: the first vehicle is up and climbing out."""


async def test_a_paused_rehearsal_waits_where_asked_until_resumed(service: Service) -> None:
    async with service.client() as client:
        fid, _ = await _flight(client, {"speedup": 200.0, "seed": 4}, scenario_name="compact")
        said = _ok(await client.post(f"/v1/flights/{fid}/pause", json={"at_s": PAUSE_AT_S}))
        assert said == {"pausable": True, "paused": False, "at_s": [PAUSE_AT_S]}
        bad = await client.post(f"/v1/flights/{fid}/pause", json={"at_s": -1.0})
        assert bad.status_code == 422 and "at_s" in bad.text, bad.text
        _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
        first = await _paused(client, fid, PAUSE_AT_S)
        # Held: a wall second is 200 s of flight at 200x, and none of it passes.
        await asyncio.sleep(1.0)
        held = _ok(await client.get(f"/v1/flights/{fid}"))
        assert held["pause"] == {"pausable": True, "paused": True, "at_s": [PAUSE_AT_S]}
        assert held["t_s"] == pytest.approx(first["t_s"], abs=1.0), (first["t_s"], held["t_s"])
        assert held["state"] == "running"
        passed = await client.post(f"/v1/flights/{fid}/pause", json={"at_s": 50.0})
        assert passed.status_code == 409 and "50.0 has passed" in passed.text, passed.text
        flown_on = _ok(await client.post(f"/v1/flights/{fid}/resume"))
        assert flown_on == {"pausable": True, "paused": False, "at_s": []}
        again = await client.post(f"/v1/flights/{fid}/resume")
        assert again.status_code == 409 and "not paused" in again.text, again.text
        while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["t_s"] < PAUSE_AT_S + 50.0:
            assert snap["state"] == "running", snap["state"]
            await asyncio.sleep(0.05)


async def test_a_paused_flight_whose_worker_died_is_paused_again_by_the_next(
    spare_service: Service,
) -> None:
    """Paused, with a later pause asked for, when its worker is killed: the worker that takes
    the flight on from its checkpoint keeps both, holds the flight (where its simulator had
    got to: on its own the simulator flies on once no ground station has acknowledged it for
    seconds, :data:`sitl_stub.lockstep.STALE_WALL_S`; here the test holds it meanwhile), and
    flies on when resumed, to its later pause."""
    later_s = PAUSE_AT_S + 150.0
    async with spare_service.client() as client:
        fid, _ = await _flight(client, {"speedup": 200.0, "seed": 4}, scenario_name="compact")
        for at_s in (PAUSE_AT_S, later_s):
            _ok(await client.post(f"/v1/flights/{fid}/pause", json={"at_s": at_s}))
        _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
        first = await _paused(client, fid, PAUSE_AT_S)
        pid = first["worker"]["pid"]
        os.kill(pid, signal.SIGKILL)
        # Until the next worker acknowledges it, the simulator is held where it is (a ground
        # station away for no flight at all), however long a busy machine takes to start it.
        away = asyncio.create_task(
            hold_while_away(spare_service.data_dir / "flights" / fid / "pace", 0.0)
        )
        await _taken_on(client, fid, pid)
        await away
        while not (snap := _ok(await client.get(f"/v1/flights/{fid}")))["pause"]["paused"]:
            assert snap["state"] in ("ready", "running"), snap["state"]  # ready: taking it on
            await asyncio.sleep(0.05)
        assert snap["pause"]["at_s"] == [PAUSE_AT_S, later_s], snap["pause"]
        await asyncio.sleep(1.0)
        held = _ok(await client.get(f"/v1/flights/{fid}"))
        assert held["pause"]["paused"] and held["state"] == "running", held["pause"]
        assert held["t_s"] == pytest.approx(snap["t_s"], abs=1.0), (snap["t_s"], held["t_s"])
        assert PAUSE_AT_S <= held["t_s"] < later_s, held["t_s"]
        flown_on = _ok(await client.post(f"/v1/flights/{fid}/resume"))
        assert flown_on["at_s"] == [later_s], flown_on
        await _paused(client, fid, later_s)


async def test_a_flight_whose_vehicles_cannot_wait_refuses_a_pause(service: Service) -> None:
    """A simulator on the wall clock (``lockstep`` false) flies on as real vehicles do."""
    async with service.client() as client:
        job = await _scheduled(client, yaml.safe_dump(compact_paper(), sort_keys=False))
        body = {"schedule_id": job["result"]["id"], "rehearsal": {"lockstep": False}}
        fid = _ok(await client.post("/v1/flights", json=body), 201)["flight_id"]
        r = await client.post(f"/v1/flights/{fid}/pause", json={})
        assert r.status_code == 409 and "lock step" in r.text, r.text
        assert _ok(await client.get(f"/v1/flights/{fid}"))["pause"] == {
            "pausable": False, "paused": False, "at_s": [],
        }  # fmt: skip

"""A flight flown while another process loads the service (:mod:`tests.isolation`: uploads of
20 MB, 1,000-vehicle planning jobs started and cancelled, readers of the health, the snapshot
and the map, stream clients): its worker keeps every slot, by the simulator's truth log, and
the service answers no request with a 5xx. The flight flies in lock step, so the verdict is the
same on a busy machine; how long the worker's loop was held under such a load on the wall
clock (free run at 20x) is ``bench/bench_isolation.py``'s figure."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from gcs.service.workers import WORKERS_AHEAD
from tests.isolation import Load, loaded
from tests.paperbounds import team_time_move_max_s
from tests.service.conftest import TOKEN, Service, may_raise_priority, nice_of
from tests.service.test_flights_http import (
    ARRIVAL_TOLERANCE_S,
    COMPACT_TOGETHER_MIN_S,
    _flight,
    _ok,
    truth_log,
)
from tests.verdict import assert_flown

pytestmark = pytest.mark.slow  # some 20 s of wall time

LOAD = Load(
    uploads=2, big_jobs=2, big_work_s=1.0, readers=20, read_s=10.0, streams=10, answer_s=None
)
"""Each part of the issue's load, smaller (two cores run the suite three tests at a time);
every request waits for its answer however long a busy machine takes to give it."""


async def test_a_flight_under_client_load_keeps_its_slots_and_no_request_gets_a_5xx(
    service: Service,
) -> None:
    async with service.client() as client:
        fid, _ = await _flight(client, {"speedup": 200.0, "seed": 2}, scenario_name="compact")
        _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
        with loaded(service.url, TOKEN, fid, LOAD) as load:
            while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["state"] not in (
                "completed", "failed", "aborted",
            ):  # fmt: skip
                await asyncio.sleep(0.2)
            seen = await asyncio.to_thread(load.result)
        while (r := await client.get(f"/v1/flights/{fid}/record")).status_code == 404:
            await asyncio.sleep(0.2)
        record: dict[str, Any] = _ok(r)
    assert not seen.server_errors, seen.server_errors[:5]
    assert seen.statuses[413] == LOAD.uploads, seen.statuses
    assert seen.cancelled == LOAD.big_jobs, seen.statuses
    assert seen.health_ms and seen.streamed >= LOAD.streams, (len(seen.health_ms), seen.streamed)
    assert snap["state"] == "completed", snap["state_reason"]
    assert snap["worker"]["loop_stall_max_ms"] >= 0.0  # the worker's own measure, reported
    # Unset TCGCS_WORKER_NICE: the worker ahead of the service where it may be.
    service_nice = nice_of(service.proc.pid)
    ahead = max(-20, service_nice - WORKERS_AHEAD) if may_raise_priority() else service_nice
    assert snap["worker"]["nice"] == ahead, (snap["worker"], service_nice)
    move_max_s = team_time_move_max_s(scenario_name="compact")
    assert_flown(
        record,
        truth_log(service, fid),
        tolerance_s=ARRIVAL_TOLERANCE_S,
        team_shift_max_s=move_max_s,
        together_min_s=COMPACT_TOGETHER_MIN_S,
    )

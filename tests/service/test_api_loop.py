"""``python -m gcs serve`` keeps what it started with out of the garbage collector's passes
once it serves (a full pass over it held a loaded service's requests 140-160 ms), and watches
its own event loop: both in ``/metrics``."""

from __future__ import annotations

import asyncio

from tests.service.conftest import Service

STARTED_WITH_MIN = 100_000
"""Objects a serving process starts with at least (its modules, the app's routes and schemas:
some 170,000 here)."""


def _figure(text: str, name: str) -> float:
    (line,) = [x for x in text.splitlines() if x.startswith(f"{name} ")]
    return float(line.split()[1])


async def test_a_serving_process_keeps_its_start_up_out_of_the_collector_and_watches_its_loop(
    service: Service,
) -> None:
    async with service.client() as client:
        for _ in range(100):  # settled a moment after it first answers
            r = await client.get("/metrics")
            assert r.status_code == 200, r.text
            if "tcgcs_api_loop_stall_max_seconds" in r.text:
                break
            await asyncio.sleep(0.05)
        frozen = _figure(r.text, "tcgcs_gc_frozen_objects")
        assert frozen >= STARTED_WITH_MIN, r.text
        stall_s = _figure(r.text, "tcgcs_api_loop_stall_max_seconds")
        assert 0.0 <= stall_s < 60.0, stall_s

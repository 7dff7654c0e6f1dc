"""The stream's own loop, on a bus with a backlog: telemetry batches come when they are due,
events or not (a client always behind on events still sees the vehicles move)."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace
from typing import Any

from gcs.api.routes.flights import TELEMETRY_WALL_S, stream
from gcs.coordination.bus import EventBus
from gcs.coordination.events import EventKind, FlightEvent
from gcs.coordination.runner import FlightState


class _Engine:
    def __init__(self, bus: EventBus) -> None:
        runner = SimpleNamespace(bus=bus, state=FlightState.RUNNING)
        self.handle = SimpleNamespace(runner=runner, record=None)

    def flight(self, flight_id: str) -> Any:
        return self.handle

    def snapshot(self, flight_id: str, *, max_age_s: float = 0.0) -> dict[str, Any]:
        return {"t_s": 0.0, "state": "running", "team_time_s": 1.0, "team_time_version": 1,
                "vehicles": []}  # fmt: skip


async def test_telemetry_comes_when_due_while_a_backlog_of_events_is_read() -> None:
    bus = EventBus()
    n = 2000
    for k in range(n):
        bus.publish(FlightEvent(1.0, float(k), "UAV1", EventKind.SPEED, f"event {k}"))
    kinds: list[str] = []
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    async for msg in stream(_Engine(bus), "f", 0):  # type: ignore[arg-type]
        kinds.append(msg["type"])
        if kinds.count("event") == n:
            break
        await asyncio.sleep(0.001)  # a slow client: the backlog lasts over a second
    assert loop.time() - t0 > 2 * TELEMETRY_WALL_S
    first_event = kinds.index("event")
    batches = [i for i, k in enumerate(kinds) if k == "telemetry" and i > first_event]
    assert batches and batches[0] < len(kinds) - 1, "no telemetry until the backlog was read"
    assert len(batches) >= int((loop.time() - t0) / TELEMETRY_WALL_S) - 1

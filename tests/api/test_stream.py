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
        self.flight = SimpleNamespace(bus=bus, state=FlightState.RUNNING, over=False)

    def known(self, flight_id: str) -> Any:
        return self.flight

    def snapshot(self, flight_id: str) -> dict[str, Any]:
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


async def test_a_stream_resumed_after_the_flight_ended_replays_every_event_it_missed() -> None:
    """A client that read 20 events and came back after the flight ended (with ``after_seq``
    20) gets every later event, then the end: none is cut off by the end."""
    bus = EventBus()
    n = 100
    for k in range(n):
        bus.publish(FlightEvent(1.0, float(k), "UAV1", EventKind.SPEED, f"event {k}"))
    engine = _Engine(bus)
    engine.flight.state = FlightState.COMPLETED
    engine.flight.over = True  # its record and last snapshot kept
    seqs: list[int] = []
    kinds: list[str] = []
    async for msg in stream(engine, "f", 20):  # type: ignore[arg-type]
        kinds.append(msg["type"])
        if msg["type"] == "event":
            seqs.append(msg["data"]["seq"])
    assert seqs == list(range(21, n + 1)), seqs[:5]
    assert kinds[0] == "snapshot" and kinds[-1] == "end", kinds

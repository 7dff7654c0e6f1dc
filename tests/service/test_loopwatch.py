"""The flight worker's watch on its own event loop (:class:`gcs.service.loopwatch.LoopWatch`):
how long the loop was held, and where, said in its log."""

from __future__ import annotations

import asyncio
import logging
import time

import pytest

from gcs.coordination.bus import EventBus
from gcs.coordination.events import EventKind, FlightEvent
from gcs.service.loopwatch import STALL_SAID_S, LoopWatch


def _held(seconds: float) -> None:
    """Holds the loop's thread for ``seconds`` of wall time."""
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def _held_in_the_project(seconds: float) -> None:
    """Holds the loop's thread for ``seconds`` inside the project's code: an event bus
    handing an event to its listener, which holds it (wherever the watch looks during the
    hold, the bus's frames are on the stack)."""
    bus = EventBus()
    bus.add_listener(lambda _: _held(seconds))
    bus.publish(FlightEvent(0.0, 0.0, None, EventKind.FLIGHT, "held"))


async def test_a_held_loop_is_measured_and_said_with_where_it_was_held(
    caplog: pytest.LogCaptureFixture,
) -> None:
    watch = LoopWatch()
    watch.start()
    try:
        await asyncio.sleep(0.05)
        with caplog.at_level(logging.WARNING, logger="gcs.service.worker"):
            _held_in_the_project(3.0 * STALL_SAID_S)
            await asyncio.sleep(0.05)
    finally:
        watch.stop()
    assert watch.stall_max_s >= 3.0 * STALL_SAID_S - watch.period_s
    (said,) = [r.getMessage() for r in caplog.records if "event loop was held" in r.getMessage()]
    assert "bus.publish" in said, said


async def test_holds_once_the_flight_is_over_are_not_counted() -> None:
    over = False
    watch = LoopWatch(counting=lambda: not over)
    watch.start()
    try:
        await asyncio.sleep(0.05)
        over = True
        _held(3.0 * STALL_SAID_S)
        await asyncio.sleep(0.05)
    finally:
        watch.stop()
    assert watch.stall_max_s < STALL_SAID_S

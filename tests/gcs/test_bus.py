"""The flight event bus: numbering, history, bounded subscribers that cannot stall it."""

from __future__ import annotations

import asyncio

import pytest

from gcs.coordination.bus import EventBus
from gcs.coordination.events import EventKind, FlightEvent


def _event(k: int, kind: EventKind = EventKind.SPEED) -> FlightEvent:
    return FlightEvent(1_700_000_000.0 + k, float(k), "UAV1", kind, f"event {k}")


def test_events_are_numbered_from_one_in_order() -> None:
    bus = EventBus()
    out = [bus.publish(_event(k)) for k in range(5)]
    assert [e.seq for e in out] == [1, 2, 3, 4, 5]
    assert bus.last_seq == 5 and bus.published == 5
    assert [e.reason for e in bus.since(3)] == ["event 3", "event 4"]


def test_an_unknown_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="sped"):
        FlightEvent(0.0, 0.0, None, "sped", "typo")  # type: ignore[arg-type]
    assert FlightEvent(0.0, 0.0, None, "speed", "ok").kind is EventKind.SPEED  # type: ignore[arg-type]


def test_a_subscriber_that_never_reads_only_counts_drops() -> None:
    bus = EventBus()
    stalled = bus.subscribe(maxsize=10)
    reader = bus.subscribe(maxsize=10_000)
    for k in range(1000):
        bus.publish(_event(k))
    assert stalled.dropped == 990 and bus.dropped == 990
    got = []
    while (e := reader.get_nowait()) is not None:
        got.append(e.seq)
    assert got == list(range(1, 1001)) and reader.dropped == 0


def test_a_resumed_subscriber_gets_every_event_exactly_once() -> None:
    bus = EventBus()
    first = bus.subscribe()
    for k in range(10):
        bus.publish(_event(k))
    seen = []
    for _ in range(4):
        e = first.get_nowait()
        assert e is not None
        seen.append(e.seq)
    first.close()  # disconnected after event 4
    for k in range(10, 15):
        bus.publish(_event(k))
    again = bus.subscribe(after_seq=seen[-1])
    for k in range(15, 20):
        bus.publish(_event(k))
    while (e := again.get_nowait()) is not None:
        seen.append(e.seq)
    assert seen == list(range(1, 21))


def test_history_is_bounded_and_since_gives_what_it_holds() -> None:
    bus = EventBus(history=5)
    for k in range(12):
        bus.publish(_event(k))
    assert [e.seq for e in bus.since(0)] == [8, 9, 10, 11, 12]


async def test_async_iteration_ends_when_closed() -> None:
    bus = EventBus()
    sub = bus.subscribe()

    async def produce() -> None:
        for k in range(3):
            await asyncio.sleep(0)
            bus.publish(_event(k))
        await asyncio.sleep(0)
        sub.close()

    task = asyncio.create_task(produce())
    got = [e.seq async for e in sub]
    await task
    assert got == [1, 2, 3]


def test_listeners_run_on_publish_and_can_be_removed() -> None:
    bus = EventBus()
    heard: list[int] = []
    remove = bus.add_listener(lambda e: heard.append(e.seq))
    bus.publish(_event(0))
    remove()
    bus.publish(_event(1))
    assert heard == [1]


def test_a_mirror_takes_events_with_their_numbers_and_rebases_after_a_loss() -> None:
    """A bus mirroring another process's (a flight worker's): each event kept under its own
    number, an old one refused, and the next publish numbered on after the newest. When that
    process died with events it had not kept, the mirror forgets them and numbers on from the
    last kept, closing its subscriptions."""
    source = EventBus()
    said = [source.publish(_event(k)) for k in range(5)]
    mirror = EventBus(first_seq=3)
    assert [mirror.take(e) for e in said[2:]] == [True, True, True]
    assert not mirror.take(said[3])
    assert [e.seq for e in mirror.since(0)] == [3, 4, 5]
    sub = mirror.subscribe(after_seq=0)
    mirror.rebase(3)
    assert sub.closed and [e.seq for e in mirror.since(0)] == [3]
    assert mirror.publish(_event(9)).seq == 4

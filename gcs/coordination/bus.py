"""A bounded publish/subscribe bus for one flight's events, that never blocks its publisher.

The control loop publishes; the progress printer, the flight record, the store and the live
stream subscribe. Publishing numbers the event (``seq`` from 1, per bus) and appends it to a
bounded history, then offers it to every subscriber. A subscriber has a bounded queue of its
own: when it is full the new event is not queued for it and its :attr:`Subscription.dropped`
counts it, so a subscriber that stops reading costs the loop nothing but a counter. A
subscriber that fell behind (or reconnects) asks for what it missed with
:meth:`EventBus.since`, by sequence number, as far back as the history goes.

Sans-IO at heart: :meth:`Subscription.get_nowait` and the queues are plain deques; the only
asyncio is the wake-up of :meth:`Subscription.get`.
"""

from __future__ import annotations

import asyncio
import itertools
from collections import deque
from collections.abc import AsyncIterator, Callable
from dataclasses import replace

from gcs.coordination.events import FlightEvent

__all__ = ["EventBus", "Subscription"]

DEFAULT_HISTORY = 100_000
DEFAULT_QUEUE = 1_000


class Subscription:
    """One subscriber's queue on an :class:`EventBus`; close it (or use ``with``) when done."""

    def __init__(self, bus: EventBus, maxsize: int) -> None:
        if maxsize < 1:
            raise ValueError(f"maxsize must be at least 1, got {maxsize}")
        self._bus = bus
        self._queue: deque[FlightEvent] = deque()
        self.maxsize = maxsize
        self.dropped = 0
        """Events not queued because the queue was full."""
        self.closed = False
        self._wake: asyncio.Event | None = None

    def _offer(self, event: FlightEvent) -> None:
        if len(self._queue) >= self.maxsize:
            self.dropped += 1
            return
        self._queue.append(event)
        if self._wake is not None:
            self._wake.set()

    def get_nowait(self) -> FlightEvent | None:
        """The next queued event, or None."""
        return self._queue.popleft() if self._queue else None

    async def get(self) -> FlightEvent | None:
        """The next event, waiting for one; None once closed and drained."""
        while not self._queue:
            if self.closed:
                return None
            if self._wake is None:
                self._wake = asyncio.Event()
            self._wake.clear()
            await self._wake.wait()
        return self._queue.popleft()

    async def get_within(self, timeout_s: float) -> FlightEvent | None:
        """The next event, waiting at most ``timeout_s`` (None: none came, or closed)."""
        event = self.get_nowait()
        if event is not None or self.closed or timeout_s <= 0.0:
            return event
        try:
            async with asyncio.timeout(timeout_s):
                return await self.get()
        except TimeoutError:
            return None

    def __aiter__(self) -> AsyncIterator[FlightEvent]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[FlightEvent]:
        while (event := await self.get()) is not None:
            yield event

    def close(self) -> None:
        """Stop receiving; what is queued can still be read."""
        if not self.closed:
            self.closed = True
            self._bus._subscribers.discard(self)
            if self._wake is not None:
                self._wake.set()

    def __enter__(self) -> Subscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class EventBus:
    """Numbers a flight's events, keeps the latest ``history`` and fans them out."""

    def __init__(self, history: int = DEFAULT_HISTORY, *, first_seq: int = 1) -> None:
        """``first_seq``: the number of the first event (a flight resumed after a restart
        goes on from its last kept event)."""
        self._history: deque[FlightEvent] = deque(maxlen=history)
        self._seq = itertools.count(first_seq)
        self._first_seq = first_seq
        self._subscribers: set[Subscription] = set()
        self._listeners: list[Callable[[FlightEvent], None]] = []
        self.published = 0

    def publish(self, event: FlightEvent) -> FlightEvent:
        """Number the event, keep it and offer it to every subscriber; never blocks."""
        return self._offer(replace(event, seq=next(self._seq)))

    def take(self, event: FlightEvent) -> bool:
        """Keep and offer an event numbered elsewhere (another process's bus, mirrored here)
        with its own number; the next :meth:`publish` goes on after it. One not numbered
        after the newest here is not taken (False)."""
        if event.seq <= self.last_seq:
            return False
        self._seq = itertools.count(event.seq + 1)
        self._offer(event)
        return True

    def rebase(self, last_seq: int) -> None:
        """Forget the events after ``last_seq`` and number on from it (the process that
        numbered them died before they were kept, and its successor numbers from the last one
        kept); every subscription is closed, so its reader starts again from what it saw."""
        while self._history and self._history[-1].seq > last_seq:
            self._history.pop()
        self._seq = itertools.count(last_seq + 1)
        if not self._history:
            self._first_seq = last_seq + 1
        for sub in tuple(self._subscribers):
            sub.close()

    def _offer(self, numbered: FlightEvent) -> FlightEvent:
        self._history.append(numbered)
        self.published += 1
        for listener in self._listeners:
            listener(numbered)
        for sub in tuple(self._subscribers):
            sub._offer(numbered)
        return numbered

    def subscribe(
        self, *, maxsize: int = DEFAULT_QUEUE, after_seq: int | None = None
    ) -> Subscription:
        """A new subscription; with ``after_seq``, the kept events after it are queued first
        (a resumed stream loses nothing the history still holds)."""
        sub = Subscription(self, maxsize)
        if after_seq is not None:
            for event in self.since(after_seq):
                sub._offer(event)
        self._subscribers.add(sub)
        return sub

    def add_listener(self, listener: Callable[[FlightEvent], None]) -> Callable[[], None]:
        """Call ``listener`` on every event as it is published (it must be quick: it runs in
        the publisher); returns a function that removes it."""
        self._listeners.append(listener)
        return lambda: self._listeners.remove(listener)

    def since(self, after_seq: int) -> list[FlightEvent]:
        """The kept events with ``seq > after_seq``, in order."""
        return [e for e in self._history if e.seq > after_seq]

    @property
    def first_kept_seq(self) -> int:
        """The sequence number of the oldest event still kept (the next one's, before any)."""
        return self._history[0].seq if self._history else self._first_seq

    @property
    def last_seq(self) -> int:
        """The sequence number of the newest event (0 before any)."""
        return self._history[-1].seq if self._history else self._first_seq - 1

    @property
    def dropped(self) -> int:
        """Events the current subscribers could not take, summed."""
        return sum(sub.dropped for sub in self._subscribers)

"""Link faults of one vehicle (both directions), sans-IO.

:meth:`FaultyLink.schedule` takes one packet (a packed MAVLink message going out, or a parsed
message coming in) and returns when to deliver each copy: none (lost or blacked out), one, or
two (duplicated). Latency and reordering are in wall milliseconds (a transport property);
a blackout is in SIMULATED seconds, so "out of contact for 60 s of flight" means the same at
any speed-up. The random draws come from a seeded ``numpy.random.Generator`` (``random()``,
drawn a batch at a time: the link should be its only user).
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import Generic, TypeVar

import numpy as np

T = TypeVar("T")

_UNIFORM_BATCH = 256


@dataclass(frozen=True, slots=True)
class Faults:
    """Fault settings, applied independently to each packet in each direction."""

    loss: float = 0.0
    latency_ms: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    reorder_delay_ms: float = 50.0

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder"):
            p = getattr(self, name)
            if not (math.isfinite(p) and 0.0 <= p <= 1.0):
                raise ValueError(f"{name} must be a probability in [0, 1], got {p!r}")
        for name in ("latency_ms", "reorder_delay_ms"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be >= 0 ms, got {v!r}")

    @property
    def clean(self) -> bool:
        return self == _NO_FAULTS


_NO_FAULTS = Faults()
FAULT_NAMES = tuple(f.name for f in fields(Faults))


@dataclass(slots=True)
class LinkCounters:
    passed: int = 0
    lost: int = 0
    blacked_out: int = 0
    duplicated: int = 0
    reordered: int = 0


class FaultyLink:
    """Fault model for one vehicle's links (applied to both directions)."""

    def __init__(
        self,
        rng: np.random.Generator,
        sim_time_s: Callable[[], float],
        faults: Faults | None = None,
    ) -> None:
        self._rng = rng
        self._uniforms: list[float] = []  # the next draws of rng.random(), last one first
        self._sim_time_s = sim_time_s
        self._faults = faults or Faults()
        self._clean = self._faults.clean  # cached: checked for every packet
        self._blackout_until_sim_s = -math.inf
        self.inbound = LinkCounters()
        self.outbound = LinkCounters()

    def faults(self, **changes: float) -> Faults:
        """Change some fault settings (by name, see :class:`Faults`); return the settings."""
        unknown = set(changes) - set(FAULT_NAMES)
        if unknown:
            raise TypeError(f"unknown fault setting(s): {', '.join(sorted(unknown))}")
        if changes:
            self._faults = replace(self._faults, **changes)
            self._clean = self._faults.clean
        return self._faults

    def clear(self) -> None:
        """Remove all faults and end any blackout."""
        self._faults = _NO_FAULTS
        self._clean = True
        self._blackout_until_sim_s = -math.inf

    def blackout(self, duration_s: float) -> None:
        """Drop every packet, both ways, for ``duration_s`` simulated seconds from now."""
        if not (math.isfinite(duration_s) and duration_s >= 0):
            raise ValueError(f"blackout duration must be >= 0 s, got {duration_s!r}")
        self._blackout_until_sim_s = self._sim_time_s() + duration_s

    @property
    def blackout_until_sim_s(self) -> float:
        """When the current (or last) blackout ends, simulated seconds (-inf: none)."""
        return self._blackout_until_sim_s

    @property
    def in_blackout(self) -> bool:
        until = self._blackout_until_sim_s
        return until != -math.inf and self._sim_time_s() < until

    @property
    def transparent(self) -> bool:
        """No fault configured: packets may bypass scheduling."""
        return self._clean and not self.in_blackout

    def _random(self) -> float:
        """The next ``rng.random()`` draw, fetched in batches: the same sequence of numbers,
        for a fraction of the cost of one numpy call per packet."""
        uniforms = self._uniforms
        if not uniforms:
            uniforms.extend(self._rng.random(_UNIFORM_BATCH).tolist())
            uniforms.reverse()
        return uniforms.pop()

    def schedule(self, now_wall_s: float, outbound: bool) -> list[float]:
        """Wall delivery times for the copies of one packet (empty: dropped)."""
        c = self.outbound if outbound else self.inbound
        if self.in_blackout:
            c.blacked_out += 1
            return []
        f = self._faults
        if self._clean:
            c.passed += 1
            return [now_wall_s]
        draw = self._random
        if f.loss > 0 and draw() < f.loss:
            c.lost += 1
            return []
        at = now_wall_s + f.latency_ms / 1000.0
        if f.reorder > 0 and draw() < f.reorder:
            c.reordered += 1
            at += f.reorder_delay_ms / 1000.0 * (0.5 + draw())
        c.passed += 1
        times = [at]
        if f.duplicate > 0 and draw() < f.duplicate:
            c.duplicated += 1
            times.append(at + 0.001)
        return times


class DelayQueue(Generic[T]):
    """Packets waiting for their wall delivery time (stable for equal times)."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, T]] = []
        self._seq = itertools.count()

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, at_s: float, item: T) -> None:
        heapq.heappush(self._heap, (at_s, next(self._seq), item))

    def pop_due(self, now_s: float) -> list[T]:
        out: list[T] = []
        while self._heap and self._heap[0][0] <= now_s:
            out.append(heapq.heappop(self._heap)[2])
        return out

    def next_due(self) -> float | None:
        return self._heap[0][0] if self._heap else None

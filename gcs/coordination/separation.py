"""Separation in flight: every fix is compared with the other flying vehicles' last fixes
(moved on to its time along their velocity), in 3-D as the rehearsal's truth check measures
it. A pair closer than the scenario's ``separation_m`` is a shortfall, said once until the
pair is apart again by ``clear_factor`` times the separation (pure: no clock, no I/O)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class Position:
    t_s: float
    east_m: float
    north_m: float
    alt_m: float
    ve_m_s: float = 0.0
    vn_m_s: float = 0.0

    def at(self, t_s: float) -> tuple[float, float, float]:
        dt = t_s - self.t_s
        return self.east_m + self.ve_m_s * dt, self.north_m + self.vn_m_s * dt, self.alt_m


@dataclass(frozen=True, slots=True)
class Shortfall:
    vehicle: str
    other: str
    distance_m: float
    t_s: float


@dataclass
class SeparationWatch:
    separation_m: float
    stale_s: float = 5.0
    """A fix older than this is not extrapolated (the vehicle's link is silent)."""
    clear_factor: float = 1.2
    positions: dict[str, Position] = field(default_factory=dict)
    close: dict[tuple[str, str], float] = field(default_factory=dict)
    """Pairs (sorted ids) below the separation now: the least distance seen, m."""
    closest: dict[tuple[str, str], tuple[float, float]] = field(default_factory=dict)
    """Every pair's least distance in flight and when: ``(distance_m, t_s)``."""

    def update(self, vehicle: str, pos: Position, flying: Iterable[str]) -> list[Shortfall]:
        """The vehicle's new fix; ``flying`` the other vehicles that count (airborne, not
        arrived). Returns the pairs that have just fallen below the separation."""
        self.positions[vehicle] = pos
        here = (pos.east_m, pos.north_m, pos.alt_m)
        out: list[Shortfall] = []
        for other in flying:
            if other == vehicle:
                continue
            p = self.positions.get(other)
            if p is None or pos.t_s - p.t_s > self.stale_s:
                continue
            d = math.dist(here, p.at(pos.t_s))
            key = (vehicle, other) if vehicle < other else (other, vehicle)
            best = self.closest.get(key)
            if best is None or d < best[0]:
                self.closest[key] = (d, pos.t_s)
            if d < self.separation_m:
                if key not in self.close:
                    self.close[key] = d
                    out.append(Shortfall(vehicle, other, d, pos.t_s))
                else:
                    self.close[key] = min(self.close[key], d)
            elif key in self.close and d > self.clear_factor * self.separation_m:
                del self.close[key]
        return out

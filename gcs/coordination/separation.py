"""Separation in flight: every fix is compared with the other flying vehicles' last fixes
(moved on to its time along their velocity), in 3-D as the rehearsal's truth check measures
it. A pair closer than the scenario's ``separation_m`` is a shortfall, said once until the
pair is apart again by ``clear_factor`` times the separation, and said again each time it
comes ``closer_step_fraction`` of the separation closer than when last said (a pair a metre
under the separation that then drifts to tens of metres is not left at the first word).
Ahead of that, a pair whose straight flight at their present velocities brings them under
the separation within a look ahead (each vehicle's no further than its own slot: its route
turns into the goal there) is a predicted conflict, said once until the prediction no longer
holds (pure: no clock, no I/O)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
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
    previous_m: float | None = None
    """The distance last said for this encounter (None: its first word)."""


@dataclass(frozen=True, slots=True)
class Conflict:
    """Two vehicles predicted to come ``distance_m`` apart, under the separation, at ``at_s``."""

    vehicle: str
    other: str
    distance_m: float
    at_s: float
    t_s: float
    """When it was predicted."""


@dataclass
class SeparationWatch:
    separation_m: float
    stale_s: float = 5.0
    """A fix older than this is not extrapolated (the vehicle's link is silent)."""
    clear_factor: float = 1.2
    closer_step_fraction: float = 0.2
    """A pair under the separation is said again each time it is this fraction of the
    separation closer than when last said."""
    positions: dict[str, Position] = field(default_factory=dict)
    close: dict[tuple[str, str], float] = field(default_factory=dict)
    """Pairs (sorted ids) below the separation now: the least distance seen, m."""
    said_m: dict[tuple[str, str], float] = field(default_factory=dict)
    """Pairs below the separation now: the distance last said, m."""
    closest: dict[tuple[str, str], tuple[float, float]] = field(default_factory=dict)
    """Every pair's least distance in flight and when: ``(distance_m, t_s)``."""
    predicted: dict[tuple[str, str], float] = field(default_factory=dict)
    """Pairs (sorted ids) predicted to come under the separation: when, mission s."""

    def __setstate__(self, state: dict[str, object]) -> None:
        """A watch checkpointed before :attr:`said_m` existed: its close pairs as last said."""
        self.__dict__.update(state)
        self.__dict__.setdefault("said_m", dict(self.close))

    def update(self, vehicle: str, pos: Position, flying: Iterable[str]) -> list[Shortfall]:
        """The vehicle's new fix; ``flying`` the other vehicles that count (in the air, past
        their slots too). Returns the pairs that have just fallen below the separation, or a step
        closer than when last said."""
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
                    self.close[key] = self.said_m[key] = d
                    out.append(Shortfall(vehicle, other, d, pos.t_s))
                else:
                    self.close[key] = min(self.close[key], d)
                    said = self.said_m[key]
                    if d <= said - self.closer_step_fraction * self.separation_m:
                        self.said_m[key] = d
                        out.append(Shortfall(vehicle, other, d, pos.t_s, said))
            elif key in self.close and d > self.clear_factor * self.separation_m:
                del self.close[key]
                del self.said_m[key]
        return out

    def predict(self, vehicle: str, look_ahead_s: Mapping[str, float]) -> list[Conflict]:
        """Conflicts of ``vehicle`` (at its last fix) with the others in ``look_ahead_s``
        (each with how far ahead of that fix its straight flight may be extrapolated): the
        closest point of approach at their present velocities, in 3-D with their present
        heights. Returns the pairs newly predicted; a pair's prediction that no longer holds
        (or that has come true: :meth:`update` says that) is dropped."""
        pos = self.positions.get(vehicle)
        if pos is None or vehicle not in look_ahead_s:
            return []
        out: list[Conflict] = []
        for other, other_ahead_s in look_ahead_s.items():
            p = self.positions.get(other)
            if other == vehicle or p is None or pos.t_s - p.t_s > self.stale_s:
                continue
            key = (vehicle, other) if vehicle < other else (other, vehicle)
            horizon = min(look_ahead_s[vehicle], other_ahead_s)
            hit = self._closest_approach(pos, p, horizon)
            if hit is None or key in self.close:
                self.predicted.pop(key, None)
                continue
            distance_m, in_s = hit
            if key not in self.predicted:
                out.append(Conflict(vehicle, other, distance_m, pos.t_s + in_s, pos.t_s))
            self.predicted[key] = pos.t_s + in_s
        return out

    def _closest_approach(
        self, a: Position, b: Position, horizon_s: float
    ) -> tuple[float, float] | None:
        """``(distance_m, in_s)`` of the closest approach within ``horizon_s`` when it is under
        the separation and still ahead (not now: that is a shortfall), else None."""
        be, bn, _ = b.at(a.t_s)
        de, dn, dz = a.east_m - be, a.north_m - bn, a.alt_m - b.alt_m
        ve, vn = a.ve_m_s - b.ve_m_s, a.vn_m_s - b.vn_m_s
        closing = ve * ve + vn * vn
        if closing < 1e-6 or horizon_s <= 0.0:
            return None
        in_s = -(de * ve + dn * vn) / closing
        if not 0.0 < in_s <= horizon_s:
            return None
        d = math.sqrt((de + ve * in_s) ** 2 + (dn + vn * in_s) ** 2 + dz * dz)
        return (d, in_s) if d < self.separation_m else None

"""4-D deconfliction: every vehicle's position over time along its schedule (eq. 1's
``d_ij(t) >= d_s``).

Positions come from :meth:`planner.schedule.VehicleSchedule.position_at`: legs at their
speeds along the exact path, loiter circles as flown; a vehicle counts only while airborne
(from takeoff to arrival). Separation is horizontal (the team flies at similar altitudes).
The sampling step keeps the relative motion between samples below a tenth of ``d_s``; the
closest sample of each pair is then refined on a finer grid.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner.errors import SeparationError
from planner.schedule import VehicleSchedule

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class PairSeparation:
    """The closest approach of two vehicles while both are airborne."""

    a: str
    b: str
    distance_m: float
    time_s: float
    east_m: float
    """Midpoint of the two positions at the closest approach, m."""
    north_m: float


@dataclass(frozen=True)
class Separation:
    """Minimum pairwise separation of the team and the pairs closer than ``d_s``."""

    required_m: float
    pairs: tuple[PairSeparation, ...]

    @property
    def minimum(self) -> PairSeparation | None:
        finite = [p for p in self.pairs if math.isfinite(p.distance_m)]
        return min(finite, key=lambda p: p.distance_m) if finite else None

    @property
    def min_separation_m(self) -> float:
        m = self.minimum
        return math.inf if m is None else m.distance_m

    @property
    def conflicts(self) -> tuple[PairSeparation, ...]:
        return tuple(p for p in self.pairs if p.distance_m < self.required_m)


def _positions(vs: VehicleSchedule, t: FloatArray) -> FloatArray:
    out = np.full((len(t), 2), np.nan)
    for k, tk in enumerate(t):
        p = vs.position_at(float(tk))
        if p is not None:
            out[k] = p
    return out


def _closest(
    a: VehicleSchedule, b: VehicleSchedule, t0: float, t1: float, step_s: float
) -> tuple[float, float, FloatArray, FloatArray]:
    n = max(2, int(math.ceil((t1 - t0) / step_s)) + 1)
    t = np.linspace(t0, t1, n)
    pa, pb = _positions(a, t), _positions(b, t)
    d = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
    if np.isnan(d).all():
        return math.inf, math.nan, pa[0], pb[0]
    k = int(np.nanargmin(d))
    return float(d[k]), float(t[k]), pa[k], pb[k]


def pair_separation(a: VehicleSchedule, b: VehicleSchedule, *, step_s: float) -> PairSeparation:
    """Closest approach of two scheduled vehicles while both fly (inf if never together)."""
    t0 = max(a.takeoff_s, b.takeoff_s)
    t1 = min(a.arrival_s, b.arrival_s)
    if not t1 > t0:
        return PairSeparation(a.vehicle_id, b.vehicle_id, math.inf, math.nan, math.nan, math.nan)
    d, t, pa, pb = _closest(a, b, t0, t1, step_s)
    if math.isfinite(d):
        lo, hi = max(t0, t - step_s), min(t1, t + step_s)
        d2, t2, pa2, pb2 = _closest(a, b, lo, hi, step_s / 50.0)
        if d2 < d:
            d, t, pa, pb = d2, t2, pa2, pb2
    mid = 0.5 * (pa + pb)
    return PairSeparation(a.vehicle_id, b.vehicle_id, d, t, float(mid[0]), float(mid[1]))


def separation(vehicles: Sequence[VehicleSchedule], required_m: float) -> Separation:
    """Minimum separation of every pair of scheduled vehicles.

    Parameters
    ----------
    vehicles
        The team's schedules.
    required_m
        The separation minimum ``d_s``, m; pairs below it are conflicts.
    """
    pairs = []
    for i in range(len(vehicles)):
        for j in range(i + 1, len(vehicles)):
            a, b = vehicles[i], vehicles[j]
            closing = a.speed_max_m_s + b.speed_max_m_s
            step = max(required_m / (10.0 * closing), 0.05)
            pairs.append(pair_separation(a, b, step_s=step))
    return Separation(required_m, tuple(pairs))


TRACK_STEP_S = 2.0
"""Sampling of the team's tracks for :class:`TeamTracks`, s (60 m at 30 m/s)."""


@dataclass(frozen=True)
class TeamTracks:
    """Every place some vehicles will be from a time on, whenever they are there (their
    schedules sampled every :data:`TRACK_STEP_S`, loiters included; time left out, as a
    schedule's times in flight are good to a minute, not to a second): what a loiter circle
    decided in flight must keep the separation from."""

    east_m: FloatArray
    north_m: FloatArray
    margin_m: FloatArray
    """Half a sample's travel at the vehicle's top speed (the track between two samples)."""
    vehicle: tuple[str, ...]

    @classmethod
    def of(cls, others: Sequence[VehicleSchedule], from_s: float) -> TeamTracks:
        east, north, margin, who = [], [], [], []
        for other in others:
            t = np.arange(max(from_s, other.takeoff_s), other.arrival_s, TRACK_STEP_S)
            if t.size == 0:
                continue
            p = _positions(other, np.append(t, other.arrival_s))
            p = p[~np.isnan(p[:, 0])]
            east.append(p[:, 0])
            north.append(p[:, 1])
            margin.append(np.full(len(p), 0.5 * other.speed_max_m_s * TRACK_STEP_S))
            who += [other.vehicle_id] * len(p)
        if not who:
            return cls(np.empty(0), np.empty(0), np.empty(0), ())
        return cls(np.concatenate(east), np.concatenate(north), np.concatenate(margin), tuple(who))

    def clearance(
        self, centre_east_m: float, centre_north_m: float, radius_m: float
    ) -> tuple[float, str | None]:
        """How far a circle stays from the tracks, m, and whose track comes nearest
        (``(inf, None)`` with no tracks)."""
        if not self.vehicle:
            return math.inf, None
        gap = (
            np.hypot(self.east_m - centre_east_m, self.north_m - centre_north_m)
            - radius_m
            - self.margin_m
        )
        k = int(np.argmin(gap))
        return float(gap[k]), self.vehicle[k]


def loiter_conflict(
    vs: VehicleSchedule, others: Sequence[VehicleSchedule], required_m: float, from_s: float
) -> str | None:
    """Why the loiter circles ``vs`` flies from ``from_s`` on do not keep ``required_m`` from
    the ``others``' tracks (:class:`TeamTracks`), or None."""
    new = [lo for lo in vs.loiters if lo.t_end_s > from_s]
    if not new:
        return None
    tracks = TeamTracks.of([x for x in others if x.vehicle_id != vs.vehicle_id], from_s)
    for lo in new:
        gap_m, near = tracks.clearance(lo.centre_east_m, lo.centre_north_m, lo.radius_m)
        if gap_m < required_m:
            return f"its turns at {lo.s_m / 1000:.1f} km come {gap_m:.0f} m from {near}'s track"
    return None


def check_separation(sep: Separation) -> None:
    """Refuse a team separation with a pair closer than ``d_s``.

    Raises
    ------
    SeparationError
        Names the closest pair, when and how close (``pair``, ``time_s``, ``distance_m``,
        ``required_m``, ``conflicts``).
    """
    conflicts = sep.conflicts
    if not conflicts:
        return
    worst = min(conflicts, key=lambda p: p.distance_m)
    more = len(conflicts) - 1
    tail = f"; {more} more pair{'s' if more > 1 else ''} in conflict" if more else ""
    raise SeparationError(
        f"vehicles {worst.a} and {worst.b} come within {worst.distance_m:.1f} m of each other "
        f"at {worst.time_s:.1f} s, under the separation minimum d_s {sep.required_m:g} m{tail}",
        pair=(worst.a, worst.b),
        time_s=worst.time_s,
        distance_m=worst.distance_m,
        required_m=sep.required_m,
        conflicts=len(conflicts),
    )

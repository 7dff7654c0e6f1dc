"""Vertical resolution: a predicted loss of separation that no speed resolves is resolved by
one of the pair leaving its height by a layer and coming back once past (pure: no clock, no
I/O).

Two aircraft funnelled onto one track, or meeting head-on on one line, cannot be kept apart
by speed (:func:`gcs.coordination.resolution.resolve` returns nothing, or a choice short of
the separation). As TCAS II and ACAS Xu do first, one of them then moves vertically: it climbs
or descends by ``layer_m`` (or by as many layers, up to ``max_layers``, as the separation
needs: it is a 3-D distance, and on one line the height alone keeps it) at ``rate_m_s``
from ``response_s`` after the decision, holds that
height until ``release_after_s`` past the last moment their tracks come under the separation
horizontally, and returns to its profile at the same rate.

Who moves, and which way (the priority rule), among the choices that keep the whole
separation in 3-D over the encounter, judged on the pair's predicted tracks (each along its
own route at its present speed, :class:`~gcs.coordination.resolution.Ahead`) and within the
mover's room (its ceiling, and its floor: the terrain under the stretch it flies meanwhile
plus its clearance, :class:`Room`):

1. one whose mover still makes its slot within its speed range (:func:`_keeps_slot`: a
   height changes its true airspeed; its arrival controller makes that up);
2. the fewest layers;
3. the one with more time to its slot (the other flies on untouched);
4. the sense that widens the height between them as it is (the higher climbs, the lower
   descends), so that a late or partial manoeuvre still helps;
5. a climb before a descent (away from the terrain);
6. the smaller vehicle id.

None when no choice keeps the separation (an alarm, as when nothing at all resolves it): one
that keeps it but not the mover's slot is still taken, as separation comes first.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from gcs.coordination.resolution import Ahead
from planner.atmosphere import eas2tas
from planner.layers import LAYER_STEPS

FloatArray = NDArray[np.float64]

__all__ = ["Held", "Room", "VerticalResolution", "height_profile", "resolve_vertical"]


@dataclass(frozen=True)
class Room:
    """How far a vehicle may leave its height over the next minutes: AMSL, m."""

    ceiling_m: float
    """Its ``alt_max_m``."""
    floor_m: float
    """The highest ground under the stretch it may fly meanwhile, plus its clearance."""


@dataclass(frozen=True)
class VerticalResolution:
    """``vehicle`` goes to ``alt_m`` (its height ``offset_m`` away) from ``start_s`` until
    ``until_s``, then back, to keep the separation from ``other``."""

    vehicle: str
    other: str
    offset_m: float
    """Up (+) or down (-), m."""
    alt_m: float
    """The height it is asked, AMSL, m."""
    start_s: float
    until_s: float
    """When it is asked back to its profile."""
    predicted_m: float
    """The pair's closest approach so resolved (3-D), m."""
    unresolved_m: float
    """Their closest approach as they fly, m."""
    at_s: float
    """When that would be."""


@dataclass(frozen=True)
class Held:
    """A height resolution a vehicle flies already, as a new one for it must respect."""

    sense: float
    """+1 up, -1 down: the new one moves on this way, away from the pair it resolves."""
    until_s: float
    """The new one holds its height at least until then."""


def height_profile(
    alt_m: float,
    offset_m: float,
    t_s: FloatArray,
    *,
    start_s: float,
    until_s: float,
    rate_m_s: float,
) -> FloatArray:
    """The height (m) at the times ``t_s`` of a vehicle at ``alt_m`` that leaves it by
    ``offset_m`` at ``rate_m_s`` from ``start_s`` and comes back at the same rate from
    ``until_s``."""
    away = np.clip((t_s - start_s) * rate_m_s, 0.0, abs(offset_m))
    back = np.clip((t_s - until_s) * rate_m_s, 0.0, abs(offset_m))
    return alt_m + math.copysign(1.0, offset_m) * np.maximum(away - back, 0.0)


def resolve_vertical(
    a: Ahead,
    b: Ahead,
    *,
    now_s: float,
    separation_m: float,
    layer_m: float,
    rate_m_s: float,
    room: Mapping[str, Room],
    look_ahead_s: float = 90.0,
    step_s: float = 1.0,
    response_s: float = 5.0,
    release_after_s: float = 10.0,
    max_layers: int = LAYER_STEPS,
    neighbours: Mapping[str, Sequence[Ahead]] | None = None,
    fast_rate_m_s: float | None = None,
    held: Mapping[str, Held] | None = None,
) -> VerticalResolution | None:
    """The vertical manoeuvre that keeps ``a`` and ``b`` ``separation_m`` apart in 3-D if
    their tracks as they fly bring them closer within ``look_ahead_s`` (None if they do not,
    or if no choice keeps them apart: see the module for the rule). ``neighbours``: by
    vehicle, the others near it; a choice that brings its mover under the separation of one
    of them, or closer than it comes as it flies, is not taken. ``fast_rate_m_s``: the
    fastest the mover may climb or sink when asked (its autopilot's limit); each choice is
    judged with the mover anywhere between its heights at that rate and at ``rate_m_s``.
    ``held``: by vehicle, the height resolution it flies already: it moves only on in its
    sense, and holds the new height at least as long."""
    bound = min(a.t_s + a.horizon_s, b.t_s + b.horizon_s)
    end_s = min(bound, now_s + look_ahead_s)
    if end_s <= now_s:
        return None
    # A conflict within the look-ahead is resolved as judged over twice it: a pair screened
    # as it comes under the separation at the look-ahead's end meets beyond it (a manoeuvre
    # sized for where it stood then left a head-on pair 180 m apart).
    t = np.arange(now_s, min(bound, now_s + 2.0 * look_ahead_s) + step_s, step_s)
    pa = a.positions(t, a.airspeed_m_s, response_s)
    pb = b.positions(t, b.airspeed_m_s, response_s)
    flat = np.sqrt(((pa[:, :2] - pb[:, :2]) ** 2).sum(axis=1))
    as_flown = np.sqrt(flat**2 + (pa[:, 2] - pb[:, 2]) ** 2)
    within = as_flown[t <= end_s]
    if np.isnan(within).all() or not np.nanmin(within) < separation_m:
        return None
    k = int(np.nanargmin(as_flown))
    unresolved_m, at_s = float(as_flown[k]), float(t[k])
    inside = np.flatnonzero(np.nan_to_num(flat, nan=np.inf) < separation_m)
    until = float(t[inside[-1]]) + release_after_s
    start = now_s + response_s
    choices = []
    for mover, other in ((a, b), (b, a)):
        if not mover.movable:
            continue
        r = room.get(mover.vehicle)
        if r is None:
            continue
        others = (neighbours or {}).get(mover.vehicle, ())
        around = _around(pa if mover is a else pb, t, others, response_s)
        other_m = (pb if mover is a else pa)[:, 2]
        flying = (held or {}).get(mover.vehicle)
        hold_s = until if flying is None else max(until, flying.until_s)
        slot_m_s = mover.slot_groundspeed_m_s(now_s)
        for layers, sense in itertools.product(range(1, max_layers + 1), (1.0, -1.0)):
            if flying is not None and sense * flying.sense < 0.0:
                continue
            offset = sense * layers * layer_m
            target = mover.alt_m + offset
            if target > r.ceiling_m or target < r.floor_m:
                continue
            band = [
                height_profile(mover.alt_m, offset, t, start_s=start, until_s=hold_s, rate_m_s=r)
                for r in (rate_m_s, max(fast_rate_m_s or rate_m_s, rate_m_s))
            ]
            lo, hi = np.minimum(*band), np.maximum(*band)
            d = np.sqrt(flat**2 + _gap_m(lo, hi, other_m) ** 2)
            least = float(np.nanmin(d))
            if least < separation_m or not _clear_of(around, lo, hi, separation_m):
                continue
            widens = (mover.alt_m - other.alt_m) * sense > 0.0 or (
                mover.alt_m == other.alt_m and sense > 0.0
            )
            slot_left_s = mover.t_s + mover.horizon_s - now_s
            late = not _keeps_slot(mover, slot_m_s, target, start, hold_s, now_s)
            rank = (late, layers, -slot_left_s, not widens, sense < 0.0, mover.vehicle)
            choices.append((rank, mover, other, offset, target, hold_s, least))
    if not choices:
        return None
    _, mover, other, offset, target, hold_s, least = min(choices, key=lambda c: c[0])
    return VerticalResolution(
        mover.vehicle,
        other.vehicle,
        offset,
        target,
        start,
        hold_s,
        least,
        unresolved_m,
        at_s,
    )


def _keeps_slot(
    mover: Ahead,
    wanted_m_s: float | None,
    alt_m: float,
    start_s: float,
    until_s: float,
    now_s: float,
) -> bool:
    """Whether ``mover`` still makes its slot within its speed range if it flies at
    ``alt_m`` from ``start_s`` to ``until_s``: there its true airspeed per unit of airspeed
    differs by the ratio of the two heights' EAS-to-TAS, and the wind it makes good against
    (its true airspeed less its ground speed at its fix) stays, so the airspeed that makes
    ``wanted_m_s``, the mean ground speed its slot asks from ``now_s`` (:meth:`~gcs.
    coordination.resolution.Ahead.slot_groundspeed_m_s`; None: none), changes over the share
    of the time to its slot it flies there. A descent of 450 m held until a few seconds
    before its slot, flown at its top speed already, left the crowd's R00 2.3 s late."""
    if wanted_m_s is None:
        return True
    end_s = mover.t_s + mover.horizon_s
    share = max(min(until_s, end_s) - start_s, 0.0) / max(end_s - now_s, 1e-9)
    per_eas = mover.tas_per_eas * (1.0 + share * (eas2tas(alt_m) / eas2tas(mover.alt_m) - 1.0))
    against_m_s = mover.airspeed_m_s * mover.tas_per_eas - mover.groundspeed_m_s
    airspeed_m_s = (wanted_m_s + against_m_s) / per_eas
    return mover.airspeed_min_m_s - 1e-6 <= airspeed_m_s <= mover.airspeed_max_m_s + 1e-6


def _around(
    mine: FloatArray, t: FloatArray, others: Sequence[Ahead], response_s: float
) -> list[tuple[FloatArray, FloatArray, float]]:
    """For each other vehicle near the mover (``mine``: its positions and heights at the
    times ``t`` as it flies): their horizontal distance at those times, its heights, and the
    least 3-D distance of the two as they fly."""
    out = []
    for o in others:
        theirs = o.positions(t, o.airspeed_m_s, response_s)
        flat = np.sqrt(((mine[:, :2] - theirs[:, :2]) ** 2).sum(axis=1))
        if np.isnan(flat).all():
            continue
        as_flown = float(np.nanmin(np.sqrt(flat**2 + (mine[:, 2] - theirs[:, 2]) ** 2)))
        out.append((flat, theirs[:, 2], as_flown))
    return out


def _gap_m(lo: FloatArray, hi: FloatArray, alt_m: FloatArray) -> FloatArray:
    """The height between ``alt_m`` and a vehicle anywhere from ``lo`` to ``hi`` (0 within),
    at each time."""
    return np.maximum(0.0, np.maximum(lo - alt_m, alt_m - hi))


def _clear_of(
    around: Sequence[tuple[FloatArray, FloatArray, float]],
    lo: FloatArray,
    hi: FloatArray,
    d_m: float,
) -> bool:
    """Whether the mover, anywhere from the heights ``lo`` to ``hi`` at each time, stays
    ``d_m`` from each other vehicle, or no closer than it comes to it as it flies."""
    for flat, alt_m, as_flown in around:
        least = float(np.nanmin(np.sqrt(flat**2 + _gap_m(lo, hi, alt_m) ** 2)))
        if least < min(d_m, as_flown):
            return False
    return True

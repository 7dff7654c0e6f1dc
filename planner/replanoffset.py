"""Offsetting a re-plan apart: a re-routed vehicle goes round the zone wider, on a track beside
the one it shares with another, and still arrives at its slot.

The route search takes each vehicle round a pop-up zone as close as it may
(:func:`planner.popup.apply_popup`): two vehicles sent round the same side fly one track along
its edge, and where their slots bring them there together no timing keeps them apart in the
time the re-plan leaves (the 60-vehicle crowd's R01 and R02, 162 m apart along the zone's east
edge). One of them is then routed round the zone :data:`OFFSETS` ``d_s`` wider (the zone
widened for its route search alone: :func:`widened`) and timed for its slot
(:func:`planner.sequencing.sequence_team` places the team, each vehicle in conflict taking the
first of its wider routes that keeps clear of the others).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from planner.deconflict import Separation
from planner.retime import Retimed
from planner.schedule import VehicleSchedule
from planner.sequencing import Moved, sequence_team
from planner.threats import NoFlyZone, RadarSite, ThreatZone

__all__ = ["OFFSETS", "Offset", "Widen", "offset_apart", "widened"]

OFFSETS = (1.5, 3.0)
"""How much wider (in ``d_s``) a re-routed vehicle may go round the zone, the least first:
beside the shared track with room for the route search's grid, or one track further out."""

Widen = Callable[[VehicleSchedule, float], Retimed | None]
"""``(schedule, by_m)``: the vehicle routed round the zone ``by_m`` wider from where it is at
the re-plan's start and timed for its slot; None when it cannot be."""


@dataclass(frozen=True)
class Offset:
    """A re-routed vehicle's wider route."""

    by_m: float
    """How much wider it goes round the zone, m."""
    retimed: Retimed


def widened(zone: ThreatZone, by_m: float) -> ThreatZone | None:
    """``zone`` grown by at least ``by_m`` all round: a radar's disc by its radius; a
    polygon scaled about its vertices' centroid by as much as moves its nearest edge
    ``by_m`` out (every edge of a convex polygon moves at least that far). None for a
    polygon whose centroid is outside it (not convex enough to be grown so)."""
    if isinstance(zone, RadarSite):
        return replace(zone, radius_m=zone.radius_m + by_m)
    v = np.asarray(zone.vertices_m, dtype=np.float64)
    ce, cn = (float(x) for x in v.mean(axis=0))
    if not bool(zone.contains(np.array([ce]), np.array([cn]))[0]):
        return None
    w = np.roll(v, -1, axis=0)
    edge = w - v
    # The centroid's distance to each edge's line.
    cross = np.abs(edge[:, 0] * (cn - v[:, 1]) - edge[:, 1] * (ce - v[:, 0]))
    nearest_m = float((cross / np.hypot(edge[:, 0], edge[:, 1])).min())
    if not nearest_m > 0.0:
        return None
    f = 1.0 + by_m / nearest_m
    grown = tuple((ce + f * (e - ce), cn + f * (n - cn)) for e, n in zone.vertices_m)
    return NoFlyZone(zone.id, grown, zone.ceiling_m, zone.forbidden, zone.appears_at_s)


def offset_apart(
    team: Sequence[VehicleSchedule],
    required_m: float,
    *,
    from_s: float,
    movable: Collection[str],
    widen: Widen,
    time_up: Callable[[], bool],
) -> tuple[dict[str, Moved[Offset]], Separation]:
    """Route the ``movable`` vehicles of ``team`` that come under ``required_m`` of another
    from ``from_s`` on round the zone wider (:data:`OFFSETS`), each timed for its slot, so
    that the team keeps ``required_m`` from then on.

    Parameters
    ----------
    team
        Every vehicle's schedule as re-planned and re-timed.
    required_m
        The separation minimum ``d_s``, m.
    from_s
        Mission time (s) the re-plan starts from: separation counts from then on.
    movable
        The vehicles that may be routed wider (those routed round the zone).
    widen
        Routes a schedule's vehicle round the zone wider and times it (:data:`Widen`).
    time_up
        Says when the re-plan's wall time is spent: no other route is searched after it.

    Returns
    -------
    The vehicles routed wider (by id) and the team's separation so, from ``from_s`` on.
    """
    by_id = {vs.vehicle_id: vs for vs in team}

    def alternatives(vid: str) -> Iterator[tuple[VehicleSchedule, Offset]]:
        # A route search each, made once: the placement's repair asks again for those made.
        for k in OFFSETS:
            if time_up():
                return
            by_m = k * required_m
            r = widen(by_id[vid], by_m)
            if r is not None:
                yield r.schedule, Offset(by_m, r)

    slack = {vid: 1.0 for vid in movable if vid in by_id}
    return sequence_team(team, required_m, slack_s=slack, alternatives=alternatives, from_s=from_s)

"""Separation by timing: the team placed in the airspace one vehicle at a time.

Routes that share a corridor or cross are kept ``d_s`` apart by when each vehicle passes
(eq. 1 by the takeoff staggering of eq. 5): a vehicle on the ground flies another cruise speed
and takes off earlier or later for the same arrival, so that it passes the shared place at
another time. :func:`sequence_team` is prioritised planning in time: the vehicles in no
conflict are placed as they are; the others follow, those with the least room to move first
(airborne, then by their timing slack), each keeping its timing if it is clear of every
vehicle placed so far, else taking the first of its other timings (its caller's order:
nearest its own cruise speed first) that is. A vehicle none of whose timings is clear keeps
its own, and the conflict is left to altitude layers where the scenario allows them
(:func:`planner.layers.lift_team`), else for :func:`planner.retime.check_feasible` to refuse.

Each placement compares one vehicle with the team on the grid of
:class:`~planner.deconflict.TeamSamples` (the team sampled once): a hundred vehicles, each
with a score of other timings, cost seconds rather than minutes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

from planner.deconflict import PairSeparation, Separation, TeamSamples, separation
from planner.schedule import VehicleSchedule

SEPARATION_CHECK_MARGIN = 1.1
"""A timing tried for separation is kept when it comes no closer than this many ``d_s`` to
the vehicles placed on the sampling grid (whose distances may be up to a tenth of ``d_s`` too
long)."""

T = TypeVar("T")


@dataclass(frozen=True)
class Moved(Generic[T]):
    """A vehicle flown on another timing to keep the separation."""

    schedule: VehicleSchedule
    chosen: T
    """What the caller's alternative carried (how the timing was made)."""
    conflict: PairSeparation
    """The closest pair it was in before it moved."""


def sequence_team(
    timed: Sequence[VehicleSchedule],
    required_m: float,
    *,
    slack_s: Mapping[str, float],
    alternatives: Callable[[str], Iterable[tuple[VehicleSchedule, T]]],
) -> tuple[dict[str, Moved[T]], Separation]:
    """Re-time the vehicles in conflict so that the team keeps ``required_m``.

    Parameters
    ----------
    timed
        The team's schedules as timed without regard to each other.
    required_m
        The separation minimum ``d_s``, m.
    slack_s
        Each vehicle's room to move its timing, s (0 for one that cannot: airborne, or the
        vehicle that sets the team's time); the least is placed first.
    alternatives
        A vehicle's other timings, best first, each with what made it; produced lazily (a
        vehicle clear with its first is not asked for the rest).

    Returns
    -------
    The vehicles moved (by id) and the team's separation as re-timed.
    """
    if len(timed) < 2:
        return {}, separation(timed, required_m)
    samples = TeamSamples(timed, required_m)
    first = separation(timed, required_m, samples)
    if not first.conflicts:
        return {}, first
    worst: dict[str, PairSeparation] = {}
    for pair in sorted(first.conflicts, key=lambda p: p.distance_m, reverse=True):
        worst[pair.a] = worst[pair.b] = pair
    current = {vs.vehicle_id: vs for vs in timed}
    placed = [vs.vehicle_id for vs in timed if vs.vehicle_id not in worst]
    enough = SEPARATION_CHECK_MARGIN * required_m
    moved: dict[str, Moved[T]] = {}
    for vid in sorted(worst, key=lambda v: (slack_s.get(v, 0.0), v)):
        near, who = samples.nearest(current[vid], placed)
        if near < enough and slack_s.get(vid, 0.0) > 0.0:
            for schedule, chosen in alternatives(vid):
                if who is not None and samples.nearest(schedule, (who,))[0] < enough:
                    continue  # most timings do not even clear the vehicle it met
                if samples.nearest(schedule, placed)[0] >= enough:
                    samples.replace(schedule)
                    current[vid] = schedule
                    moved[vid] = Moved(schedule, chosen, worst[vid])
                    break
        placed.append(vid)
    team = [current[vs.vehicle_id] for vs in timed]
    return moved, separation(team, required_m, samples)

"""Separation by timing: the team placed in the airspace one vehicle at a time.

Routes that share a corridor or cross are kept ``d_s`` apart by when each vehicle passes
(eq. 1 by the takeoff staggering of eq. 5): a vehicle on the ground flies another cruise speed
and takes off earlier or later for the same arrival, so that it passes the shared place at
another time (its caller may also offer timings on an altitude layer:
:func:`planner.layers.lanes`). :func:`sequence_team` is prioritised planning in time: the
vehicles in no conflict are placed as they are; the others follow, those with the least
room to move first (airborne, then by their timing slack), each keeping its timing if it is
clear of every vehicle placed so far, else taking the first of its other timings (its
caller's order: nearest its own cruise speed first) that is. A vehicle none of whose timings
is clear keeps its own.

One pass in that order leaves a crowd in conflict where the vehicles placed early took the
times the later ones needed. Such a pass is then repaired by local search (min-conflicts):
round by round, each vehicle with room that is still inside the separation of others takes,
of its own timing and all its others, the one that comes least far inside it (summed over the
team), if that is less than now; until the team is clear, or a round changes nothing, or
after :data:`REPAIR_ROUNDS`. What is left goes to altitude layers where the scenario allows
them (:func:`planner.layers.lift_team`), else for :func:`planner.retime.check_feasible` to
refuse.

Each placement compares one vehicle with the team on the grid of
:class:`~planner.deconflict.TeamSamples` (the team sampled once): a hundred vehicles, each
with a score of other timings, cost seconds rather than minutes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

from planner.deconflict import PairSeparation, Separation, TeamSamples, separation
from planner.schedule import VehicleSchedule

FloatArray = NDArray[np.float64]

SEPARATION_CHECK_MARGIN = 1.1
"""A timing tried for separation is kept when it comes no closer than this many ``d_s`` to
the vehicles placed on the sampling grid (whose distances may be up to a tenth of ``d_s`` too
long)."""

REPAIR_ROUNDS = 6
"""Rounds of the local search after the first pass. On the planner bench's 100-vehicle team
the last rounds move one vehicle each; each round tries every timing of every vehicle in
conflict against the team."""

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
    repair_rounds: int | None = None,
    from_s: float = -math.inf,
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
    repair_rounds
        Rounds of local search after the first pass (0: the first pass alone; default
        :data:`REPAIR_ROUNDS`).
    from_s
        Separation counts from this time on (a re-plan's start), and only there: what was
        flown before it is not the timing's to change.

    Returns
    -------
    The vehicles moved (by id) and the team's separation as re-timed.
    """
    if len(timed) < 2:
        return {}, separation(timed, required_m, from_s=from_s)
    alternatives = _Remembered(alternatives)  # the first pass's, again in the repair
    samples = TeamSamples(timed, required_m, from_s=from_s)
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
        near, who = samples.nearest(current[vid], placed, enough)
        if near < enough and slack_s.get(vid, 0.0) > 0.0:
            for schedule, chosen in alternatives(vid):
                if who is not None and samples.nearest(schedule, (who,), enough)[0] < enough:
                    continue  # most timings do not even clear the vehicle it met
                if samples.nearest(schedule, placed, enough)[0] >= enough:
                    samples.replace(schedule)
                    current[vid] = schedule
                    moved[vid] = Moved(schedule, chosen, worst[vid])
                    break
        placed.append(vid)
    placed_sep = separation([current[vs.vehicle_id] for vs in timed], required_m, samples)
    if not placed_sep.conflicts:
        return moved, placed_sep  # the search would only widen what keeps d_s already
    own = {vs.vehicle_id: vs for vs in timed}
    was: TeamSamples | None = None  # the team as first timed, for a vehicle's pair then
    repaired_timings = _repair(
        samples,
        current,
        slack_s,
        alternatives,
        enough,
        REPAIR_ROUNDS if repair_rounds is None else repair_rounds,
    )
    if not repaired_timings:
        return moved, placed_sep
    for vid, (repaired, made) in repaired_timings.items():
        current[vid] = repaired
        if made is None:  # back to where the search started
            continue
        if vid in moved or vid in worst:
            conflict = worst[vid] if vid in worst else moved[vid].conflict
        else:
            was = was or TeamSamples(timed, required_m, from_s=from_s)
            conflict = was.closest_pair(own[vid])
        moved[vid] = Moved(repaired, made, conflict)
    team = [current[vs.vehicle_id] for vs in timed]
    return moved, separation(team, required_m, samples)


class _Remembered(Generic[T]):
    """A vehicle's alternatives made once: asked again, those made already come back as
    they were, and the rest are made as they are reached (each may be a re-timing)."""

    def __init__(self, make: Callable[[str], Iterable[tuple[VehicleSchedule, T]]]) -> None:
        self._make = make
        self._made: dict[str, tuple[list[tuple[VehicleSchedule, T]], Iterator[Any]]] = {}

    def __call__(self, vid: str) -> Iterator[tuple[VehicleSchedule, T]]:
        if vid not in self._made:
            self._made[vid] = ([], iter(self._make(vid)))
        made, rest = self._made[vid]
        i = 0
        while True:
            if i == len(made):
                item = next(rest, None)
                if item is None:
                    return
                made.append(item)
            yield made[i]
            i += 1


def _repair(
    samples: TeamSamples,
    current: Mapping[str, VehicleSchedule],
    slack_s: Mapping[str, float],
    alternatives: Callable[[str], Iterable[tuple[VehicleSchedule, T]]],
    enough_m: float,
    rounds: int,
) -> dict[str, tuple[VehicleSchedule, T | None]]:
    """The local search after the first pass, on ``samples`` (updated as vehicles move): the
    timings it changed, with what made each (None: the vehicle's timing when the search
    began)."""
    search = _Search(samples, current, alternatives, enough_m)
    movable = [vid for vid in samples.ids if slack_s.get(vid, 0.0) > 0.0]
    for _ in range(rounds):
        if search.move_each(movable) == 0:
            break
    return search.changed


_Timing = tuple[VehicleSchedule, T | None, FloatArray]


class _Search(Generic[T]):
    """A vehicle's timings tried against the team on the samples: the moves of
    :func:`_repair`. The measure is how far inside ``enough_m`` a vehicle comes of the
    others, summed (:meth:`TeamSamples.shortfall_m`); a move is taken when it lessens it."""

    def __init__(
        self,
        samples: TeamSamples,
        current: Mapping[str, VehicleSchedule],
        alternatives: Callable[[str], Iterable[tuple[VehicleSchedule, T]]],
        enough_m: float,
    ) -> None:
        self.samples, self.enough_m = samples, enough_m
        self._start, self._alternatives = current, alternatives
        self._timings: dict[str, list[_Timing[T]]] = {}
        self.changed: dict[str, tuple[VehicleSchedule, T | None]] = {}

    def timings(self, vid: str) -> list[_Timing[T]]:
        """The vehicle's timing when the search began, then its others, each sampled."""
        if vid not in self._timings:
            start = self._start[vid]
            self._timings[vid] = [(start, None, self.samples.track(start))] + [
                (schedule, chosen, self.samples.track(schedule))
                for schedule, chosen in self._alternatives(vid)
            ]
        return self._timings[vid]

    def inside_m(self, vid: str, track: FloatArray | None = None) -> float:
        """How far the vehicle (on ``track``, else as it is now) comes inside ``enough_m``
        of the others, summed over them."""
        row = self.samples.row(vid) if track is None else track
        return self.samples.shortfall_m(vid, row, self.enough_m)

    def _take(self, vid: str, timing: _Timing[T]) -> None:
        self.samples.replace(timing[0], timing[2])
        self.changed[vid] = (timing[0], timing[1])

    def move_each(self, movable: Sequence[str]) -> int:
        """Each vehicle inside the separation, the deepest first, to its timing that comes
        least far inside (if less than now); how many moved."""
        inside = {vid: x for vid in movable if (x := self.inside_m(vid)) > 0.0}
        moves = 0
        for vid in sorted(inside, key=lambda v: (-inside[v], v)):
            least, pick = self.inside_m(vid), None  # others have moved since
            for timing in self.timings(vid) if least > 0.0 else ():
                x = self.inside_m(vid, timing[2])
                if x < least - 1e-6:
                    least, pick = x, timing
                    if x <= 0.0:
                        break
            if pick is not None:
                self._take(vid, pick)
                moves += 1
        return moves

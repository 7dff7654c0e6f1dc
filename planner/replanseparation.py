"""Separation of a re-planned team from the re-plan's start on (eq. 1's ``d_ij(t) >= d_s``
kept in flight).

A re-plan (a pop-up threat, an operator's zone) routes the vehicles it touches round the zone
and re-times the team (:func:`planner.popup.apply_popup`). Before anything is installed, the
team is checked in 4-D from the re-plan's start on: every pair, each as it will fly from then
(the new routes and timings, the others' as they stand), by the 3-D distance the plan and the
flight's truth measure (:func:`planner.deconflict.separation`).

A pair under ``d_s`` is separated by the plan-time means, in stages, each only for the pairs
the ones before it leave under ``d_s``, while the re-plan's wall time lasts:

1. timing (:func:`planner.replantiming.time_apart`): a re-routed vehicle passes the place
   where it would come too close earlier or later, and still arrives at its slot;
2. altitude layers (:func:`planner.layers.lift_team`): one of the pair flies a layer higher
   over the stretch where they meet, only where its new mission flies (past the waypoint it
   is spliced at), timed again for its slot. The scenario's layers, or without any, the
   heights the in-flight resolution climbs by (:func:`planner.layers.replan_layers_m`);
3. a lateral offset (:func:`planner.replanoffset.offset_apart`): a re-routed vehicle goes
   round the zone wider, beside the track it shares with another, timed for its slot. It is
   the last means as it is the dearest: a route search for each vehicle it tries (of 14
   routes re-planned round one zone, 12 were searched wider for one taken), where a lift
   is a re-timing.

What none of them separates is said before it is installed: a ``conflict`` event with the
pair, when and how close, and an ``alarm``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from typing import Any

from planner.deconflict import PairSeparation, separation
from planner.layers import Lifted, lift_team, replan_layers_m
from planner.replanoffset import Widen, offset_apart
from planner.replantiming import Through, time_apart
from planner.retime import Retimed
from planner.scenario import Scenario
from planner.schedule import Adjustment, Event, VehicleSchedule
from planner.sequencing import Moved

__all__ = ["ReplanSeparation", "separate_replan"]


@dataclass(frozen=True)
class ReplanSeparation:
    """The re-planned team as separated, and what was done and left."""

    vehicles: dict[str, VehicleSchedule]
    """Every vehicle's schedule, by id (a re-timed or lifted one's new, the others' as
    given)."""
    adjustments: dict[str, tuple[Adjustment, ...]]
    """The timing adjustments of each vehicle re-timed or lifted, by id."""
    timed: tuple[str, ...]
    """The vehicles timed to pass earlier or later to keep the separation."""
    offset: tuple[str, ...]
    """The vehicles routed round the zone wider to keep the separation."""
    lifted: tuple[str, ...]
    """The vehicles flown on a layer to keep the separation."""
    conflicts: tuple[PairSeparation, ...]
    """The pairs still under ``d_s`` from the re-plan's start on."""
    events: tuple[Event, ...]


def _pair_payload(p: PairSeparation) -> dict[str, object]:
    return {
        "pair": [p.a, p.b],
        "distance_m": round(p.distance_m, 1),
        "at_s": round(p.time_s, 1),
        "east_m": round(p.east_m, 1),
        "north_m": round(p.north_m, 1),
    }


def _take(
    vid: str,
    moved: Moved[Any],
    said: str,
    how: dict[str, object],
    current: dict[str, VehicleSchedule],
    adjustments: dict[str, tuple[Adjustment, ...]],
    from_s: float,
) -> Event:
    """``vid`` flies ``moved``'s schedule (its timing's adjustments kept); the event that
    says so (``said``, then the pair it was separated from and ``how``)."""
    current[vid] = moved.schedule
    adjustments[vid] = tuple(moved.chosen.retimed.adjustments)
    p = moved.conflict
    other = p.b if p.a == vid else p.a
    return Event(
        from_s,
        "conflict",
        f"{said} and keeps its slot: after the re-plan {other} would come within "
        f"{p.distance_m:.0f} m of it at {p.time_s:.0f} s",
        {**_pair_payload(p), "pair": [vid, other], **how},
    )


def separate_replan(
    scenario: Scenario,
    team: Mapping[str, VehicleSchedule],
    *,
    from_s: float,
    lift_from_m: Mapping[str, float],
    rerouted: Collection[str],
    retime: Callable[[VehicleSchedule], Retimed | None],
    through: Through,
    widen: Widen | None = None,
    time_up: Callable[[], bool] | None = None,
) -> ReplanSeparation:
    """Check the re-planned ``team`` from ``from_s`` on and separate what it can.

    Parameters
    ----------
    scenario
        The team's scenario (its vehicles, ``separation_m`` and ``altitude_layers_m``).
    team
        Every vehicle's schedule as re-planned and re-timed, by id.
    from_s
        Mission time (s) the re-plan starts from: separation counts from then on.
    lift_from_m
        The vehicles that get a new mission, each with the distance along its path (m) its
        new mission starts at (0 for one still on the ground): only these may be lifted,
        and only past that point.
    rerouted
        The vehicles routed round the zone: of those of ``lift_from_m``, only these may be
        timed to pass earlier or later.
    retime
        Times a lifted schedule again for its vehicle's slot, from where it is; None when
        it cannot.
    through
        Times a schedule for its slot through a place at a time (:data:`~planner.
        replantiming.Through`).
    widen
        Routes a re-routed vehicle round the zone wider and times it for its slot
        (:data:`~planner.replanoffset.Widen`); without it, no offset is tried.
    time_up
        Says when the re-plan's wall time is spent: a stage is not begun after it, and the
        one under way ends with what it has.
    """
    required = scenario.separation_m
    order = [v.id for v in scenario.vehicles]
    vehicles = {v.id: v for v in scenario.vehicles}
    up = time_up or (lambda: False)
    current = dict(team)
    adjustments: dict[str, tuple[Adjustment, ...]] = {}
    events: list[Event] = []
    sep = separation([current[vid] for vid in order], required, from_s=from_s)
    movable = [vid for vid in order if vid in rerouted and vid in lift_from_m]
    timed: list[str] = []
    if sep.conflicts and not up():
        moved, sep = time_apart(
            [current[vid] for vid in order], required, from_s=from_s, movable=movable,
            through=through, time_up=up,
        )  # fmt: skip
        for vid, m in moved.items():
            shift = m.chosen.shift_s
            said = (
                f"{vid} passes {m.chosen.via_s_m / 1000.0:.1f} km along its route "
                f"{abs(shift):g} s {'later' if shift > 0 else 'earlier'} than timed"
            )
            how = {"resolution": "timing", "shift_s": shift}
            events.append(_take(vid, m, said, how, current, adjustments, from_s))
            timed.append(vid)
    layers_m = replan_layers_m(scenario)
    lifted: dict[str, Lifted[Retimed]] = {}
    if sep.conflicts and not up():

        def timed_again(vs: VehicleSchedule) -> tuple[VehicleSchedule, Retimed] | None:
            r = retime(vs)
            return None if r is None else (r.schedule, r)

        lifted, sep = lift_team(
            [current[vid] for vid in order], current, vehicles, layers_m, required,
            timed_again, from_s=from_s, lift_from_m=lift_from_m, time_up=up,
        )  # fmt: skip
    for vid, lift in lifted.items():
        current[vid] = lift.schedule
        adjustments[vid] = tuple(lift.chosen.adjustments)
        for height_m, a_m, b_m, other, distance_m, time_s in lift.spans:
            events.append(
                Event(
                    from_s,
                    "conflict",
                    f"{vid} flies {height_m:g} m above its profile from {a_m / 1000.0:.1f} "
                    f"to {min(b_m, current[vid].path.length_m) / 1000.0:.1f} km along its "
                    f"route after the re-plan: {other} would come within {distance_m:.0f} m "
                    f"of it at {time_s:.0f} s",
                    {
                        "pair": [vid, other],
                        "distance_m": round(distance_m, 1),
                        "at_s": round(time_s, 1),
                        "resolution": "altitude",
                        "height_m": height_m,
                    },
                )
            )
    offset: list[str] = []
    if sep.conflicts and widen is not None and not up():
        wider, sep = offset_apart(
            # A lifted vehicle keeps its layer: its other still may go round wider.
            [current[vid] for vid in order], required, from_s=from_s,
            movable=[vid for vid in movable if vid not in lifted], widen=widen, time_up=up,
        )  # fmt: skip
        for vid, o in wider.items():
            by_m = o.chosen.by_m
            said = f"{vid} goes round the zone {by_m:.0f} m wider"
            how = {"resolution": "offset", "offset_m": by_m}
            events.append(_take(vid, o, said, how, current, adjustments, from_s))
            offset.append(vid)
    conflicts = tuple(p for p in sep.conflicts if math.isfinite(p.distance_m))
    for p in conflicts:
        why = (
            "the re-plan's time ran out before they were separated"
            if up()
            else "neither timing, a wider way round nor an altitude layer keeps them apart"
        )
        said = (
            f"{p.a} and {p.b} would come within {p.distance_m:.0f} m of each other at "
            f"{p.time_s:.0f} s after the re-plan (d_s {required:g} m): {why}"
        )
        events.append(Event(from_s, "conflict", said, {**_pair_payload(p), "resolution": None}))
        events.append(Event(from_s, "alarm", said, _pair_payload(p)))
    return ReplanSeparation(
        {vid: current[vid] for vid in order},
        adjustments,
        tuple(timed),
        tuple(offset),
        tuple(lifted),
        conflicts,
        tuple(events),
    )

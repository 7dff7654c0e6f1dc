"""Separation of a re-planned team from the re-plan's start on (eq. 1's ``d_ij(t) >= d_s``
kept in flight).

A re-plan (a pop-up threat, an operator's zone) routes the vehicles it touches round the zone
and re-times the team (:func:`planner.popup.apply_popup`). Before anything is installed, the
team is checked in 4-D from the re-plan's start on: every pair, each as it will fly from then
(the new routes and timings, the others' as they stand), by the 3-D distance the plan and the
flight's truth measure (:func:`planner.deconflict.separation`).

A pair under ``d_s`` is separated by the plan-time means the scenario allows:

- altitude layers (``altitude_layers_m``, :func:`planner.layers.lift_team`): one of the pair
  flies a layer higher over the stretch where they meet, only where its new mission flies
  (past the waypoint it is spliced at), timed again for its slot;

What none of them separates is said before it is installed: a ``conflict`` event with the
pair, when and how close, and an ``alarm``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from planner.deconflict import PairSeparation
from planner.layers import lift_team
from planner.scenario import Scenario
from planner.schedule import Event, VehicleSchedule

__all__ = ["ReplanSeparation", "separate_replan"]


@dataclass(frozen=True)
class ReplanSeparation:
    """The re-planned team as separated, and what was done and left."""

    vehicles: dict[str, VehicleSchedule]
    """Every vehicle's schedule, by id (a lifted one's new, the others' as given)."""
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


def separate_replan(
    scenario: Scenario,
    team: Mapping[str, VehicleSchedule],
    *,
    from_s: float,
    lift_from_m: Mapping[str, float],
    retime: Callable[[VehicleSchedule], VehicleSchedule | None],
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
    retime
        Times a lifted schedule again for its vehicle's slot, from where it is; None when
        it cannot.
    """
    required = scenario.separation_m
    order = [v.id for v in scenario.vehicles]
    vehicles = {v.id: v for v in scenario.vehicles}

    def timed(up: VehicleSchedule) -> tuple[VehicleSchedule, None] | None:
        r = retime(up)
        return None if r is None else (r, None)

    lifted, sep = lift_team(
        [team[vid] for vid in order],
        team,
        vehicles,
        scenario.altitude_layers_m,
        required,
        timed,
        from_s=from_s,
        lift_from_m=lift_from_m,
    )
    out = {vid: lifted[vid].schedule if vid in lifted else team[vid] for vid in order}
    events: list[Event] = []
    for vid, lift in lifted.items():
        for height_m, a_m, b_m, other, distance_m, time_s in lift.spans:
            events.append(
                Event(
                    from_s,
                    "conflict",
                    f"{vid} flies {height_m:g} m above its profile from {a_m / 1000.0:.1f} "
                    f"to {min(b_m, out[vid].path.length_m) / 1000.0:.1f} km along its route "
                    f"after the re-plan: {other} would come within {distance_m:.0f} m of it at "
                    f"{time_s:.0f} s",
                    {
                        "pair": [vid, other],
                        "distance_m": round(distance_m, 1),
                        "at_s": round(time_s, 1),
                        "resolution": "altitude",
                        "height_m": height_m,
                    },
                )
            )
    conflicts = tuple(p for p in sep.conflicts if math.isfinite(p.distance_m))
    for p in conflicts:
        why = (
            "no altitude layer keeps them apart"
            if scenario.altitude_layers_m
            else "the scenario has no altitude layers to keep them apart"
        )
        said = (
            f"{p.a} and {p.b} would come within {p.distance_m:.0f} m of each other at "
            f"{p.time_s:.0f} s after the re-plan (d_s {required:g} m): {why}"
        )
        events.append(Event(from_s, "conflict", said, {**_pair_payload(p), "resolution": None}))
        events.append(Event(from_s, "alarm", said, _pair_payload(p)))
    return ReplanSeparation(out, tuple(lifted), conflicts, tuple(events))

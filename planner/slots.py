"""Ordered arrival slots (spaced arrivals, landing slots, waves) as they move in flight: a
slot moves only when a vehicle in it cannot make it, and then each slot after it only as far
as its spacing after the one before needs; the slots before it stay. Pure: the coordinator's
team time (:mod:`gcs.coordination.teamtime`) and a re-plan's (:mod:`planner.popup`) both move
them so."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from planner.errors import InfeasibleError
from planner.scenario import Scenario, Spaced, Waves
from planner.timing import TIME_TOL_S, ArrivalWindow

__all__ = ["SAME_SLOT_S", "ordered_targets", "pushed", "slot_groups", "slot_spacing_s"]

SAME_SLOT_S = 1e-6
"""Slots closer than this (s) are one (a wave's vehicles share theirs)."""


def slot_spacing_s(scenario: Scenario) -> float | None:
    """How far apart the scenario's slots are kept (s): the spacing of spaced arrivals, the
    gap between waves; None where the slots are not ordered (one team time, windows)."""
    arrival = scenario.arrival
    if isinstance(arrival, Spaced):
        return arrival.interval_s
    if isinstance(arrival, Waves):
        return arrival.gap_s
    return None


def slot_groups(slots_s: Mapping[str, float]) -> list[list[str]]:
    """The vehicles by slot, in time order (a wave's vehicles share theirs)."""
    groups: list[list[str]] = []
    last_s = -math.inf
    for vid in sorted(slots_s, key=lambda v: (slots_s[v], v)):
        if groups and slots_s[vid] - last_s < SAME_SLOT_S:
            groups[-1].append(vid)
        else:
            groups.append([vid])
            last_s = slots_s[vid]
    return groups


def pushed(
    slots_s: Mapping[str, float], earliest_s: Mapping[str, float], spacing_s: float
) -> dict[str, float]:
    """Each vehicle's slot (mission s) moved no earlier than the earliest its group can make
    (``earliest_s``; a vehicle not in it has no bound) and no closer than ``spacing_s`` after
    the slot before it as moved; a slot that need not move stays."""
    out: dict[str, float] = {}
    before_s = -math.inf
    for group in slot_groups(slots_s):
        need_s = max(
            slots_s[group[0]],
            before_s + spacing_s,
            *(earliest_s.get(v, -math.inf) for v in group),
        )
        for vid in group:
            out[vid] = need_s
        before_s = need_s
    return out


def ordered_targets(
    windows: Sequence[ArrivalWindow], slots_s: Mapping[str, float], spacing_s: float
) -> tuple[dict[str, float], float, str]:
    """The slots of a team in flight after a change of routes: :func:`pushed` from the slots
    as they stand (``slots_s``, every vehicle's) by the earliest each can now arrive
    (``windows``, each vehicle's reachable arrivals; one without has arrived, and its slot
    cannot move). Each target (the vehicles with a window), the first slot, and the reason.

    Raises
    ------
    InfeasibleError
        A vehicle cannot arrive as late as its slot would move to (named, with why).
    """
    win = {w.vehicle_id: w for w in windows}
    new = pushed(slots_s, {vid: w.t_min_s for vid, w in win.items()}, spacing_s)
    for vid, slot_s in new.items():
        w = win.get(vid)
        latest_s = slots_s[vid] if w is None else w.t_max_s
        # Only a slot that moves is checked: one that stays is no worse than it was (a
        # vehicle that will be early for its own slot, say, whatever the move).
        if slot_s > slots_s[vid] + TIME_TOL_S and slot_s > latest_s + TIME_TOL_S:
            why = "it has arrived" if w is None else w.max_reason
            raise InfeasibleError(
                f"vehicle {vid} cannot arrive as late as {slot_s:.1f} s ({why})", vehicle=vid
            )
    in_order = [vid for group in slot_groups(slots_s) for vid in group if vid in win]
    late = [vid for vid in in_order if win[vid].t_min_s > slots_s[vid] + TIME_TOL_S]
    if late:
        w = win[late[0]]
        reason = (
            f"the slots from {late[0]}'s on moved as far as their spacing needs: {late[0]} "
            f"cannot arrive before {w.t_min_s:.1f} s ({w.min_reason})"
        )
    else:
        reason = "every vehicle keeps its slot"
    return {vid: new[vid] for vid in win}, min(new.values()), reason

"""A flight's story for a failed assertion: its events without the routine ones (speed
commands, link gaps and the states they toggle, clock offsets), one line each, so a CI log
shows why a flight missed."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

ROUTINE = frozenset({"speed", "link", "clock"})


def _routine(e: Mapping[str, Any]) -> bool:
    """Routine kinds, and a vehicle's state going to or from ``link_silent`` (said by the
    link events anyway, and dozens of them on a loaded machine)."""
    return e["kind"] in ROUTINE or (e["kind"] == "state" and "link_silent" in e["reason"])


def story(events: Iterable[Mapping[str, Any]], *, limit: int = 120) -> str:
    lines = [
        f"{e.get('t_s') or 0.0:9.1f} s {e.get('vehicle') or 'team':5} {e['kind']:9} {e['reason']}"
        for e in events
        if not _routine(e)
    ]
    if len(lines) > limit:
        lines = [*lines[: limit // 2], "...", *lines[-limit // 2 :]]
    return "\n".join(lines)


def routine_story(events: Iterable[Mapping[str, Any]], vehicle: str, *, limit: int = 80) -> str:
    """The routine events :func:`story` leaves out (speed commands and their outcomes, link
    gaps, clock offsets) of one vehicle, the last ``limit`` of them: for a vehicle that missed
    its slot, what it was told and what came of it."""
    lines = [
        f"{e.get('t_s') or 0.0:9.1f} s {vehicle:5} {e['kind']:9} {e['reason']}"
        for e in events
        if e.get("vehicle") == vehicle and _routine(e)
    ]
    return "\n".join(lines[-limit:])


def story_of_lines(text: str, *, limit: int = 120) -> str:
    """The same for ``rehearse``'s printed log (``  t s   VEHICLE kind  reason`` lines)."""
    kept = [
        ln
        for ln in text.splitlines()
        if not any(f" {k} " in ln[:32] for k in ROUTINE) and "link_silent" not in ln
    ]
    if len(kept) > limit:
        kept = [*kept[: limit // 2], "...", *kept[-limit // 2 :]]
    return "\n".join(kept)

"""Separation events: every conflict a flight met, what was done about it, and how close the
pair truly came.

The coordinator says a conflict in its events (``conflict`` and ``alarm``, each with its
payload); :func:`separation_kind` reads one as a separation event, and
:func:`separation_events` makes the flight record's ``separation_events`` of them, each with
the pair's least 3-D distance between flown positions over the encounter (the simulator's
truth when it is ours, else telemetry: :func:`gcs.coordination.tracks.min_separation`, the
one measure the plan, the flight's watch and the report share).

Kinds:

- ``predicted``: their present velocities bring the pair under the separation within the
  look-ahead (an alarm follows if it comes true);
- ``resolved``: one of the pair flies another speed until past the other (``speed``), leaves
  its height by a layer or more until past it (``altitude``, signed), or a re-plan lifts it
  onto an altitude layer (``altitude``);
- ``released``: a speed or height resolution is over;
- ``unresolved``: a re-plan left the pair under the separation (said before its missions
  were sent, with an alarm), or in flight no speed or height of either parts a pair
  forecast under it (said once, with an alarm);
- ``loss``: the pair came under the separation (the alarm).

Pure: no clock, no I/O.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from gcs.coordination.events import EventKind, FlightEvent
from gcs.coordination.tracks import TruthSample, min_separation

__all__ = ["ENCOUNTER_AFTER_S", "SeparationEvent", "separation_events", "separation_kind"]

ENCOUNTER_AFTER_S = 60.0
"""An encounter is measured from the event to this long (mission s) past the time the event
expects the pair closest (its prediction, or the end of its resolution)."""


@dataclass(frozen=True, slots=True)
class SeparationEvent:
    """One event of a flight read as a separation event."""

    kind: str
    vehicle: str
    other: str
    action: str
    """What was done: ``none``, ``alarm``, ``speed`` (with the airspeed), ``altitude``
    (with the height), ``released``."""
    said_m: float | None
    """The distance the event gave (its prediction, or the distance measured), m."""
    until_s: float
    """Mission time (s) the encounter is measured to."""


def separation_kind(ev: FlightEvent) -> SeparationEvent | None:
    """``ev`` as a separation event, or None when it is not one."""
    p: Mapping[str, Any] = ev.payload
    said = p.get("distance_m")
    said_m = None if said is None else float(said)
    at_s = float(p.get("at_s", ev.t_s))
    if ev.kind is EventKind.ALARM:
        if "other" not in p or said_m is None or ev.vehicle is None:
            return None  # not a separation alarm, or a re-plan's (its conflict event says it)
        end = ev.t_s + ENCOUNTER_AFTER_S
        return SeparationEvent("loss", ev.vehicle, str(p["other"]), "alarm", said_m, end)
    if ev.kind is not EventKind.CONFLICT:
        return None
    if "pair" in p:
        a, b = (str(x) for x in p["pair"])
        if p.get("resolution") == "altitude":
            action = f"altitude +{float(p.get('height_m', 0.0)):g} m"
            return SeparationEvent("resolved", a, b, action, said_m, at_s + ENCOUNTER_AFTER_S)
        if p.get("resolution") == "timing":
            action = f"timing {float(p.get('shift_s', 0.0)):+g} s"
            return SeparationEvent("resolved", a, b, action, said_m, at_s + ENCOUNTER_AFTER_S)
        if p.get("resolution") == "offset":
            action = f"offset {float(p.get('offset_m', 0.0)):g} m"
            return SeparationEvent("resolved", a, b, action, said_m, at_s + ENCOUNTER_AFTER_S)
        return SeparationEvent("unresolved", a, b, "alarm", said_m, at_s + ENCOUNTER_AFTER_S)
    if "other" not in p or ev.vehicle is None:
        return None  # a re-plan's note without a pair
    other = str(p["other"])
    resolution = p.get("resolution")
    if resolution == "speed":
        until = max(at_s, float(p.get("until_s", at_s))) + ENCOUNTER_AFTER_S
        action = f"speed {float(p['airspeed_m_s']):g} m/s"
        return SeparationEvent("resolved", ev.vehicle, other, action, said_m, until)
    if resolution == "altitude":
        until = max(at_s, float(p.get("until_s", at_s))) + ENCOUNTER_AFTER_S
        action = f"altitude {float(p.get('offset_m', 0.0)):+g} m"
        return SeparationEvent("resolved", ev.vehicle, other, action, said_m, until)
    if resolution == "released":
        end = ev.t_s + ENCOUNTER_AFTER_S
        return SeparationEvent("released", ev.vehicle, other, "released", None, end)
    return SeparationEvent("predicted", ev.vehicle, other, "none", said_m, at_s + ENCOUNTER_AFTER_S)


def _window(
    samples: Sequence[TruthSample], times: Sequence[float], from_utc: float, to_utc: float
) -> list[TruthSample]:
    """The samples (their ``times``) from ``from_utc`` to ``to_utc``."""
    return list(samples[bisect.bisect_left(times, from_utc) : bisect.bisect_right(times, to_utc)])


def separation_events(
    events: Iterable[FlightEvent],
    tracks: Mapping[str, Sequence[TruthSample]],
    start_utc_s: float,
) -> list[dict[str, Any]]:
    """The flight record's ``separation_events``: one per separation event of ``events``, in
    their order, with the pair's least 3-D distance over the encounter from ``tracks``
    (by vehicle id, each in time order) from the event (``utc_s``) to ``until_utc_s``:
    ``closest_m`` and ``closest_utc_s``, None when the tracks do not hold the pair flying
    together then."""
    out: list[dict[str, Any]] = []
    times: dict[str, list[float]] = {}  # each track's sample times, listed once
    for ev in events:
        sep = separation_kind(ev)
        if sep is None:
            continue
        # The window the entry states (to the millisecond), so that whoever measures it again
        # from the same samples finds the same closest distance.
        from_utc = round(start_utc_s + ev.t_s, 3)
        to_utc = round(start_utc_s + sep.until_s, 3)
        pair = {}
        for k, vid in enumerate((sep.vehicle, sep.other)):
            track = tracks.get(vid, ())
            if vid not in times:
                times[vid] = [s.utc_s for s in track]
            pair[k] = _window(track, times[vid], from_utc, to_utc)
        closest = min_separation(pair)
        out.append(
            {
                "kind": sep.kind,
                "pair": [sep.vehicle, sep.other],
                "t_s": round(ev.t_s, 3),
                "utc_s": from_utc,
                "until_utc_s": to_utc,
                "seq": ev.seq,
                "action": sep.action,
                "said_m": sep.said_m,
                "closest_m": None if closest is None else round(closest[0], 1),
                "closest_utc_s": None if closest is None else round(closest[3], 3),
                "reason": ev.reason,
            }
        )
    return out

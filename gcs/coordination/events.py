"""Typed flight events: what the coordinator decided or saw, in order.

Every event has a kind from :class:`EventKind`, a sequence number within its flight (assigned
by the :class:`~gcs.coordination.bus.EventBus` it is published on), mission time and UTC, the
vehicle it concerns (None: the team), and for a time adjustment its strategy and value. The
store, the stream, the progress printer and the flight record read the same record.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["EventKind", "FlightEvent"]


class EventKind(enum.StrEnum):
    """What an event is about (the string is what the flight record and the store keep)."""

    PLAN = "plan"
    """The schedule's own decisions before launch (takeoff delays, speeds, loiters)."""
    START = "start"
    """The mission starts: its UTC and the team arrival."""
    UPLOAD = "upload"
    """A mission was uploaded to a vehicle."""
    LAUNCH = "launch"
    """A vehicle was armed and put in AUTO (or failed to be)."""
    ROUTE = "route"
    """A vehicle finished its climb-out and is timed on its route."""
    SPEED = "speed"
    """An airspeed command (or its failure)."""
    LOITER = "loiter"
    """Loiter turns inserted (or not possible)."""
    TAKEOFF = "takeoff"
    """A vehicle on the ground got a new takeoff time."""
    ARRIVAL = "arrival"
    """The team arrival time moved, or a vehicle is late while joining its route."""
    ARRIVED = "arrived"
    """A vehicle passed its goal."""
    LANDED = "landed"
    """A vehicle touched down and disarmed after its slot fix (``payload``: ``order``,
    ``along_m`` and ``across_m`` from the touchdown point on the runway heading), or did not
    land in time (an alarm says so)."""
    POPUP = "popup"
    """A threat appeared, and what it touches."""
    REPLAN = "replan"
    """Vehicles re-planned around a threat."""
    LINK = "link"
    """A vehicle's telemetry stopped or came back."""
    CLOCK = "clock"
    """A vehicle keeps a UTC of its own, or none."""
    ABORT = "abort"
    """A vehicle (or the team) was aborted, or the loop stopped before every vehicle arrived
    (the overrun, or the flight's hard deadline)."""
    CONFLICT = "conflict"
    """Two flying vehicles predicted to come under the separation within the look-ahead at
    their present velocities (``payload``: ``other``, ``distance_m``, ``at_s``); an alarm
    follows if they do. Also a pair predicted along their routes resolved ahead of time
    (``payload``: ``resolution`` ``speed``, ``other``, ``airspeed_m_s``, ``until_s``,
    ``distance_m``, ``resolved_m``, ``at_s``) and the resolution over (``resolution``
    ``released``, ``other``)."""
    ALARM = "alarm"
    """A vehicle said something critical (STATUSTEXT at MAV_SEVERITY_CRITICAL or worse;
    ``payload``: ``severity``, ``text``), or its route enters a forbidden zone that appeared
    in flight and no route around it is on board in time (``payload``: ``zone``,
    ``entry_s``, ``time_to_entry_s``, ``why``, ``action``), or a re-plan overran its lead,
    or the coordinator's event loop was held while a lock-step simulator flew on without it
    (``payload``: ``unwatched_s``, flight seconds)."""
    VEHICLE_LOST = "vehicle_lost"
    """A vehicle is lost to the team (``payload``: ``cause`` ``crash`` or ``stall``, ``t_s``
    mission time, ``why``): it reported a crash (STATUSTEXT "Crash ...", HEARTBEAT
    MAV_STATE_EMERGENCY, disarmed on its route), or its progress along its route stalled for
    longer than ``stall_bound_s``. The reason says what the team does (``on_vehicle_lost``)."""
    FALLBACK = "fallback"
    """A vehicle's safe fallback short of a forbidden zone it would otherwise enter: a hold
    taken or refused, and the resumption of AUTO on the route installed since (``payload``:
    ``zone``, ``action`` hold, resume or failed)."""
    STATE = "state"
    """A vehicle's state changed (``payload``: ``state``, ``was``;
    :class:`~gcs.coordination.member.VehicleState` values)."""
    FLIGHT = "flight"
    """The flight's own state changed (``payload``: ``state``; planned, uploading, ready,
    running, completed, aborted, failed), or it was resumed after a restart."""


@dataclass(frozen=True)
class FlightEvent:
    """One decision or observation of a flight (times in s; ``seq`` from the bus, 0 before)."""

    utc_s: float
    t_s: float
    vehicle: str | None
    kind: EventKind
    reason: str
    strategy: str | None = None
    value: float | None = None
    seq: int = 0
    payload: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", EventKind(self.kind))

    def to_json(self, start_utc_s: float | None = None) -> dict[str, Any]:
        """The event as the stream, the API and the flight record give it: times rounded to
        the millisecond; a UTC not known when it happened (NaN: before the clock was synced)
        is the mission start plus ``t_s`` when ``start_utc_s`` is given, else null; the
        payload without an upload's items (kept in the store)."""
        utc: float | None = self.utc_s
        if math.isnan(self.utc_s):
            utc = None if start_utc_s is None else start_utc_s + self.t_s
        return {
            "seq": self.seq,
            "kind": self.kind.value,
            "t_s": round(self.t_s, 3),
            "utc_s": None if utc is None else round(utc, 3),
            "vehicle": self.vehicle,
            "strategy": self.strategy,
            "value": self.value,
            "reason": self.reason,
            "payload": {k: v for k, v in self.payload.items() if k != "items"},
        }

    def to_wire(self) -> dict[str, Any]:
        """The event whole for another process (:meth:`from_wire`): unrounded, a UTC not
        known as null; an upload's items left out (they are in the store)."""
        return {
            "seq": self.seq,
            "utc_s": None if math.isnan(self.utc_s) else self.utc_s,
            "t_s": self.t_s,
            "vehicle": self.vehicle,
            "kind": self.kind.value,
            "reason": self.reason,
            "strategy": self.strategy,
            "value": self.value,
            "payload": {k: v for k, v in self.payload.items() if k != "items"},
        }

    @classmethod
    def from_wire(cls, doc: Mapping[str, Any]) -> FlightEvent:
        """The event :meth:`to_wire` gave."""
        utc = doc["utc_s"]
        return cls(
            utc_s=math.nan if utc is None else float(utc),
            t_s=float(doc["t_s"]),
            vehicle=doc["vehicle"],
            kind=EventKind(doc["kind"]),
            reason=doc["reason"],
            strategy=doc["strategy"],
            value=doc["value"],
            seq=int(doc["seq"]),
            payload=doc["payload"],
        )

"""Vertical resolutions as flown: the altitude commands that take a vehicle off its height and
back (pure: no clock, no I/O; the team controller feeds it and sends what it returns).

A :class:`~gcs.coordination.vertical.VerticalResolution` is flown with
MAV_CMD_DO_CHANGE_ALTITUDE (:class:`~gcs.coordination.actions.CommandAltitude`), which
ArduPlane applies to the waypoint it flies to now; the next waypoint brings the mission's
altitude back (ArduPlane/GCS_Mavlink.cpp, handle_command_int_DO_CHANGE_ALTITUDE and
handle_change_alt_request). So the height is asked again each time the vehicle starts a new
mission item while the resolution lasts, and at its end the item flown to then is asked its
own altitude: the vehicle is back on its profile without waiting for the next waypoint.

Meanwhile the vehicle is still timed for its slot (its arrival controller makes up what the
height changes in true airspeed). Its room (:class:`~gcs.coordination.vertical.Room`) is its
ceiling and the highest ground under the stretch it flies meanwhile plus its clearance.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gcs.coordination import actions as act
from gcs.coordination.events import EventKind
from gcs.coordination.member import Member
from gcs.coordination.vertical import Room, VerticalResolution
from gcs.mavlink.dialect import mavlink2
from planner.scenario import Vehicle
from planner.terrain import Terrain

__all__ = ["Manoeuvre", "VerticalFlight", "room_ahead"]

_ABOVE_HOME_FRAMES = frozenset(
    {mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
)
"""A mission item's z above home (our missions' frame)."""
_AMSL_FRAMES = frozenset({mavlink2.MAV_FRAME_GLOBAL, mavlink2.MAV_FRAME_GLOBAL_INT})


def room_ahead(
    m: Member, v: Vehicle, terrain: Terrain, from_s: float, until_s: float
) -> Room | None:
    """How far ``m`` may leave its height from ``from_s`` to ``until_s`` (mission s): its
    ``alt_max_m``, and the highest ground under its route over that stretch (at its present
    ground speed, a kilometre more on each side) plus its clearance, or its ``alt_min_m`` if
    higher. None without a position on its route."""
    if m.s_m is None:
        return None
    along_m, east_m, north_m = m.track.flight_samples(m.loiters_done())
    ahead_m = max(m.groundspeed_m_s, m.limits.airspeed_max_m_s) * max(until_s - from_s, 0.0)
    margin_m = 1000.0
    near = (along_m >= m.s_m - margin_m) & (along_m <= m.s_m + ahead_m + margin_m)
    if not near.any():
        return None
    ground = np.asarray(terrain.elevation_m(east_m[near], north_m[near]), dtype=np.float64)
    floor_m = max(float(np.max(ground)) + v.clearance_m, v.alt_min_m)
    return Room(ceiling_m=v.alt_max_m, floor_m=floor_m)


@dataclass
class Manoeuvre:
    """One vehicle's vertical resolution as it is flown."""

    resolution: VerticalResolution
    also: tuple[str, ...] = ()
    """The others it took the height for before (a resolution that replaced theirs): it is
    over only once past them too."""
    asked_seq: int | None = None
    """The mission item the height was last asked for (None: to be asked)."""
    busy: bool = False
    """An altitude command is on its way."""
    refusals: int = 0


class VerticalFlight:
    """The vertical resolutions the team flies, one per vehicle at most."""

    def __init__(self) -> None:
        self.flying: dict[str, Manoeuvre] = {}

    def __contains__(self, vehicle_id: str) -> bool:
        return vehicle_id in self.flying

    def start(self, m: Member, res: VerticalResolution, t_s: float, out: list[act.Action]) -> None:
        """``m`` flies ``res`` from now: said, and its height asked (in place of one it
        flies, whose others it must still pass)."""
        before = self.flying.get(m.vehicle_id)
        also = () if before is None else (*before.also, before.resolution.other)
        also = tuple(dict.fromkeys(o for o in also if o != res.other))
        self.flying[m.vehicle_id] = Manoeuvre(res, also)
        sense = "climbs" if res.offset_m > 0.0 else "descends"
        out.append(
            act.Report(
                EventKind.CONFLICT,
                f"{sense} {abs(res.offset_m):.0f} m to {res.alt_m:.0f} m AMSL until "
                f"{res.until_s:.1f} s to keep the separation from {res.other} (no speed keeps "
                f"it): {res.unresolved_m:.0f} m apart at {res.at_s:.1f} s as they fly, "
                f"{res.predicted_m:.0f} m so",
                m.vehicle_id,
                value=round(res.predicted_m, 1),
                t_s=t_s,
                payload={
                    "other": res.other,
                    "resolution": "altitude",
                    "offset_m": round(res.offset_m, 1),
                    "alt_m": round(res.alt_m, 1),
                    "until_s": round(res.until_s, 1),
                    "distance_m": round(res.unresolved_m, 1),
                    "resolved_m": round(res.predicted_m, 1),
                    "keeps_separation": True,
                    "at_s": round(res.at_s, 1),
                },
            )
        )
        self.fly(m, t_s, lambda _res: None, out)  # its height asked: not over yet

    def fly(
        self,
        m: Member,
        t_s: float,
        over: Callable[[VerticalResolution], str | None],
        out: list[act.Action],
    ) -> None:
        """At each fix of a vehicle flying a manoeuvre: its height asked again on a new
        mission item; once its end has come and it is ``over`` (the pair past each other as
        they fly now: the encounter predicted minutes ahead may come later than foreseen; or
        its height without room ahead, said in an alarm), the item's own altitude asked and
        the manoeuvre over."""
        man = self.flying.get(m.vehicle_id)
        if man is None or man.busy:
            return
        res = man.resolution
        why = over(res) if t_s >= res.until_s else None
        if why is not None and why != "past":
            out.append(
                act.Report(
                    EventKind.ALARM,
                    f"{m.vehicle_id} back to its profile before it is past {res.other}: {why}",
                    m.vehicle_id,
                    t_s=t_s,
                    payload={"other": res.other, "why": "no room to hold the height"},
                )
            )
        if why is not None:
            del self.flying[m.vehicle_id]
            back = self._profile(m)
            if back is not None:
                alt_m, above_home = back
                out.append(
                    act.CommandAltitude(
                        m.vehicle_id, alt_m, above_home, f"past {res.other}: back", t_s
                    )
                )
            out.append(
                act.Report(
                    EventKind.CONFLICT,
                    f"{'past' if why == 'past' else 'not yet past'} {res.other}: back to its "
                    "profile",
                    m.vehicle_id,
                    t_s=t_s,
                    payload={"other": res.other, "resolution": "released"},
                )
            )
            return
        if man.asked_seq is not None and man.asked_seq == m.last_seq:
            return
        man.busy = True
        man.asked_seq = m.last_seq
        out.append(
            act.CommandAltitude(m.vehicle_id, res.alt_m, False, f"clear of {res.other}", t_s)
        )

    def commanded(self, r: act.AltitudeCommanded, out: list[act.Action]) -> None:
        """The outcome of an altitude command: a refusal is said, and asked again at the
        next fix (an alarm at the third in a row)."""
        man = self.flying.get(r.vehicle_id)
        if man is None:
            if r.error is not None:
                out.append(
                    act.Report(
                        EventKind.ALARM,
                        f"{r.vehicle_id} refused its profile's altitude {r.alt_m:.0f} m "
                        f"({r.error}): it returns to it at its next waypoint",
                        r.vehicle_id,
                        t_s=r.decided_s,
                        payload={"action": "none", "why": "altitude command refused"},
                    )
                )
            return
        man.busy = False
        if r.error is None:
            man.refusals = 0
            return
        man.asked_seq = None
        man.refusals += 1
        kind = EventKind.ALARM if man.refusals == 3 else EventKind.CONFLICT
        out.append(
            act.Report(
                kind,
                f"{r.vehicle_id} refused {r.alt_m:.0f} m ({r.error}) {man.refusals} time(s) "
                f"in a row: the separation from {man.resolution.other} is not kept by height",
                r.vehicle_id,
                t_s=r.decided_s,
                payload={"action": "none", "why": "altitude command refused"},
            )
        )

    @staticmethod
    def _profile(m: Member) -> tuple[float, bool] | None:
        """The altitude of the mission item ``m`` flies to now, and whether above home."""
        seq = m.last_seq
        items = m.mission.items
        if seq is None or not 0 <= seq < len(items):
            return None
        item = items[seq]
        if item.frame in _ABOVE_HOME_FRAMES:
            return float(item.z), True
        if item.frame in _AMSL_FRAMES:
            return float(item.z), False
        return None

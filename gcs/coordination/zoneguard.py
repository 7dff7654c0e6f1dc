"""The safe fallback for a forbidden zone that appears in flight.

A re-plan around a pop-up threat (or a zone the operator adds) may come back too late, fail,
or fail to be installed. Whatever happened, a vehicle whose remaining route enters such a zone
is watched on its own geometry: when it is due at its hold point (the last point of its route
short of the zone, outside it by the hold circle plus a margin) and no route around the zone
is on board, an alarm says so and the vehicle is told to hold there (:class:`~actions.Hold`).
Once a route that keeps out of the zone is installed, it resumes AUTO on it
(:class:`~actions.Resume`); while it holds with none coming, it asks for a re-plan from its
hold point.

:class:`ZoneGuard` is the part of :class:`~gcs.coordination.team.TeamController` that does
this (on top of :class:`~gcs.coordination.replanning.MissionChanges`); its state is the
controller's ``guarded`` zones and ``exposures``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from gcs.coordination import actions as act
from gcs.coordination.events import EventKind
from gcs.coordination.member import Member
from gcs.coordination.replanning import MissionChanges
from gcs.coordination.routetrack import RouteTrack
from planner.geo import LocalFrame
from planner.mission import MAV_CMD_NAV_LOITER_TURNS, MAV_CMD_NAV_WAYPOINT
from planner.threats import ThreatZone

__all__ = ["Exposure", "ZoneGuard", "route_entry_m"]

SAMPLE_M = 100.0
"""Route sampling step (m) for where it enters a zone and where it can hold short of it."""
RESUME_AHEAD_M = 50.0
"""A resumed vehicle continues at the first mission item this far beyond its hold point."""

ExposureState = Literal["watching", "commanding", "holding", "resuming"]


@dataclass
class Exposure:
    """One vehicle's route entering one forbidden zone, and what is done about it."""

    vehicle_id: str
    zone: ThreatZone
    track: RouteTrack | None = None
    """The track ``entry_s_m`` and the hold point were found on (a new one: found again)."""
    entry_s_m: float | None = None
    """Where the route enters the zone (m along it), None when it keeps out."""
    hold_s_m: float = 0.0
    hold_en_m: tuple[float, float] = (0.0, 0.0)
    hold_alt_m: float = 0.0
    hold_clear_m: float = 0.0
    """How far the hold point is outside the zone (m)."""
    state: ExposureState = "watching"
    problem: str | None = None
    """Why no route around the zone is on board, when something said so."""
    next_replan_s: float = -math.inf


def route_entry_m(
    m: Member, zone: ThreatZone, s_from_m: float, step_m: float = SAMPLE_M
) -> float | None:
    """Where the vehicle's planned path, from ``s_from_m`` on, first enters the zone below its
    ceiling (m along the path), or None."""
    path = m.schedule.path
    if path.length_m - s_from_m < 1.0:
        return None
    n = max(2, int(math.ceil((path.length_m - s_from_m) / step_m)) + 1)
    s = np.linspace(s_from_m, path.length_m, n)
    e, nn, alt = _samples(m, s)
    inside = (zone.distance_m(e, nn) < 0.0) & (alt < zone.ceiling_m)
    if not inside.any():
        return None
    return float(s[int(np.argmax(inside))])


def _samples(m: Member, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    poses = m.schedule.path.poses_at(s)
    alt = np.interp(s, m.schedule.wp_s_m, m.schedule.wp_alt_m)
    return poses[:, 0], poses[:, 1], alt


class ZoneGuard(MissionChanges):
    """Watch routes that enter zones appearing in flight; hold short of them; resume."""

    frame: LocalFrame
    guarded: list[ThreatZone]
    """Forbidden zones that appeared in flight (the plan avoided the others)."""
    exposures: dict[str, dict[str, Exposure]]
    """Per vehicle, per zone id: its route's entry into the zone and what is done about it."""

    # -- zones ------------------------------------------------------------------------------

    def _guard_zone(self, zone: ThreatZone) -> None:
        """A zone appeared: the routes entering it are watched from now on (forbidden only)."""
        if zone.forbidden and zone.id not in {z.id for z in self.guarded}:
            self.guarded.append(zone)

    def remove_threat(self, threat_id: str, now_s: float) -> list[act.Action]:
        out = super().remove_threat(threat_id, now_s)
        self._unguard_zone(threat_id, now_s, out)
        return out

    def _unguard_zone(self, zone_id: str, now: float, out: list[act.Action]) -> None:
        """A zone was lifted: nothing is held short of it any more."""
        self.guarded = [z for z in self.guarded if z.id != zone_id]
        for vid, exps in self.exposures.items():
            exp = exps.get(zone_id)
            if exp is None:
                continue
            if exp.state == "holding":
                exp.entry_s_m = None
                self._resume(self.members[vid], exp, now, out)
            else:
                del exps[zone_id]
                self.members[vid].hold_zone = None

    def hold_anchor_s_m(self, m: Member, zone_id: str) -> float | None:
        """Where a vehicle holding short of the zone holds (m along its path), else None."""
        exp = self.exposures.get(m.vehicle_id, {}).get(zone_id)
        if exp is None or exp.state != "holding":
            return None
        return exp.hold_s_m

    def _no_route(self, vehicle_id: str, problem: str, now: float, zone_id: str | None) -> None:
        """Something said no route around a zone will come for now (the re-plan failed, the
        upload failed or was skipped): kept for the alarm; a holding vehicle asks again after
        ``hold_replan_every_s``."""
        for zid, exp in self.exposures.get(vehicle_id, {}).items():
            if zone_id is None or zid == zone_id:
                exp.problem = problem
                if exp.state == "holding":
                    exp.next_replan_s = now + self.config.hold_replan_every_s

    def _replan_now(self, vehicle_id: str, zone_id: str) -> None:
        exp = self.exposures.get(vehicle_id, {}).get(zone_id)
        if exp is not None:
            exp.next_replan_s = -math.inf

    # -- watching ---------------------------------------------------------------------------

    def _guard_tick(self, now: float, out: list[act.Action]) -> None:
        """Every flying vehicle at where it should be now (its last fix moved on at its ground
        speed): a vehicle whose fixes stop is still held in time."""
        if not self.guarded:
            return
        self._overdue_replans(now, out)
        for m in self.members.values():
            if m.phase != "route" or m.s_m is None or m.last_fix_s is None:
                continue
            ahead = max(m.groundspeed_m_s, 10.0) * max(0.0, now - m.last_fix_s)
            s = min(m.s_m + ahead, m.track.length_m)
            self._guard(m, now, s, out)

    def _overdue_replans(self, now: float, out: list[act.Action]) -> None:
        """A re-plan not finished by its lead is not waited for: said once; the vehicles whose
        routes enter the zone hold short of it in time on their own geometry."""
        for zid in sorted(self.popups_running):
            due = self.replan_due.get(zid)
            if due is None or now <= due or zid in self.replan_overdue:
                continue
            self.replan_overdue.add(zid)
            out.append(
                act.Report(
                    EventKind.ALARM,
                    f"re-plan around {zid} not done within its lead (due at {due:.1f} s): not "
                    "waited for; vehicles whose routes enter it hold short of it in time",
                    t_s=now,
                    payload={"zone": zid, "action": "hold", "why": "re-plan overran its lead"},
                )
            )

    def _guard(self, m: Member, t: float, s_now: float, out: list[act.Action]) -> None:
        """One vehicle at ``s_now`` along its route at mission time ``t``, for each zone."""
        for zone in self.guarded:
            exps = self.exposures.setdefault(m.vehicle_id, {})
            exp = exps.get(zone.id)
            if exp is None:
                exp = exps[zone.id] = Exposure(m.vehicle_id, zone)
            if exp.track is not m.track:
                self._locate(m, exp, s_now)
            if exp.entry_s_m is None:
                # Kept while its route keeps out (found again only when the route changes).
                if exp.state == "holding" and self._may_leave(m, t):
                    self._resume(m, exp, t, out)
                continue
            if exp.state == "watching":
                if self.holds_now(m, exp.hold_s_m, s_now):
                    gs = max(m.groundspeed_m_s, 10.0)
                    self._hold(m, exp, t, t + (exp.entry_s_m - s_now) / gs, out)
            elif (
                exp.state == "holding"
                and t >= exp.next_replan_s
                and zone.id not in self.popups_running
                and m.vehicle_id not in self.pending
            ):
                exp.next_replan_s = t + self.config.hold_replan_every_s
                self._popup(
                    zone, t, self.lead_s, out,
                    why=f"{m.vehicle_id} holds short of it with no route around it",
                    from_hold=True,
                )  # fmt: skip

    @staticmethod
    def _may_leave(m: Member, t: float) -> bool:
        """Whether a vehicle holding with a route that keeps out on board may leave its hold
        point now: not before the route has it leave (it was planned from there at that time;
        gone sooner, it would be early by the rest of the re-plan's lead)."""
        return m.leave_hold_s is None or t >= m.leave_hold_s

    def _locate(self, m: Member, exp: Exposure, s_now: float) -> None:
        """Where the vehicle's route (from where it is, or from its hold point while it holds)
        enters the zone, and the hold point short of it."""
        exp.track = m.track
        s_from = exp.hold_s_m if exp.state in ("holding", "commanding") else s_now
        exp.entry_s_m = route_entry_m(m, exp.zone, s_from)
        if exp.entry_s_m is None or exp.state in ("holding", "commanding"):
            return
        s_k, en, alt, clear = self._hold_point(m, exp.zone, exp.entry_s_m)
        exp.hold_s_m, exp.hold_en_m, exp.hold_alt_m, exp.hold_clear_m = s_k, en, alt, clear

    def _hold_point(
        self, m: Member, zone: ThreatZone, entry_s_m: float
    ) -> tuple[float, tuple[float, float], float, float]:
        """The last point short of the entry (the route flown so far included) far enough
        outside the zone for the circle the autopilot flies round it: ``(s_m, (east_m,
        north_m), alt_m, clearance_m)``."""
        v = self.scenario.vehicle(m.vehicle_id)
        clearance = max(self.config.hold_radius_m, v.min_turn_radius_m) + self.config.hold_margin_m
        n = max(2, int(math.ceil(entry_s_m / SAMPLE_M)) + 1)
        s = np.linspace(entry_s_m, 0.0, n)
        e, nn, alt = _samples(m, s)
        d = zone.distance_m(e, nn)
        ok = d >= clearance
        k = int(np.argmax(ok)) if ok.any() else int(np.argmax(d))
        return float(s[k]), (float(e[k]), float(nn[k])), float(alt[k]), float(d[k])

    def holds_now(self, m: Member, s_hold_m: float, s_now_m: float) -> bool:
        """Whether the vehicle at ``s_now_m`` is within ``hold_guard_s`` of its hold point at
        ``s_hold_m`` along its path, at its ground speed: it is held there now."""
        gs = max(m.groundspeed_m_s, 10.0)
        return (s_hold_m - s_now_m) / gs <= self.config.hold_guard_s

    def hold_short_s_m(self, m: Member, zone: ThreatZone, before_s_m: float) -> float | None:
        """Where the vehicle would hold short of a forbidden zone its route enters ahead of
        it, short of ``before_s_m`` (m along its path), else None. So near the zone that no
        point ahead of it is far enough outside for the hold's circle, the point is behind it
        (the guard flies it back there)."""
        if not zone.forbidden:
            return None
        entry = route_entry_m(m, zone, m.s_m or 0.0)
        if entry is None or entry >= before_s_m:
            return None
        return self._hold_point(m, zone, entry)[0]

    # -- the fallback ------------------------------------------------------------------------

    def _why_unprotected(self, m: Member, exp: Exposure, t: float) -> str:
        zid = exp.zone.id
        if zid in self.popups_running:
            due = self.replan_due.get(zid, t)
            late = f", {t - due:.0f} s past its lead" if t > due else ""
            return f"its re-plan around {zid} is still running{late}"
        if m.vehicle_id in self.pending:
            return "the upload of its new route is still under way"
        return exp.problem or f"the route it has on board still enters {zid}"

    def _hold(
        self, m: Member, exp: Exposure, t: float, entry_t_s: float, out: list[act.Action]
    ) -> None:
        """Alarm, and the hold short of the zone."""
        zid = exp.zone.id
        exp.state = "commanding"
        m.hold_zone = zid
        lat, lon = self.frame.to_geodetic(*exp.hold_en_m)
        why = self._why_unprotected(m, exp, t)
        to_entry = entry_t_s - t
        out.append(
            act.Report(
                EventKind.ALARM,
                f"its route enters {zid} in {to_entry:.0f} s (at {entry_t_s:.1f} s) and no route "
                f"around it is on board ({why}): holding {exp.hold_clear_m:.0f} m outside "
                f"{zid}, at {exp.hold_s_m:.0f} m along its route",
                m.vehicle_id,
                t_s=t,
                payload={
                    "zone": zid,
                    "entry_s": round(entry_t_s, 3),
                    "time_to_entry_s": round(to_entry, 3),
                    "why": why,
                    "action": "hold",
                    "hold_lat_deg": float(lat),
                    "hold_lon_deg": float(lon),
                    "hold_clearance_m": round(exp.hold_clear_m, 1),
                },
            )
        )
        out.append(act.Hold(m.vehicle_id, float(lat), float(lon), exp.hold_alt_m, zid, t))

    def _hold_taken(self, r: act.HoldTaken, now: float, out: list[act.Action]) -> None:
        h = r.hold
        m = self.members[h.vehicle_id]
        exp = self.exposures.get(h.vehicle_id, {}).get(h.zone_id)
        if exp is None or exp.state != "commanding":
            return
        if r.error is not None:
            exp.state = "watching"  # commanded again at its next fix: it is due
            why = f"hold short of {h.zone_id} not taken ({r.error}); commanding it again"
            out.append(_fallback(m, h.zone_id, "failed", why, now))
            return
        exp.state = "holding"
        exp.next_replan_s = now
        m.level_m_s = None  # GUIDED: the airspeed of the last DO_CHANGE_SPEED is dropped
        what = (
            f"holding at {h.lat_deg:.5f}, {h.lon_deg:.5f} ({exp.hold_clear_m:.0f} m outside "
            f"{h.zone_id}) until a route around it is on board"
        )
        out.append(_fallback(m, h.zone_id, "hold", what, now))
        if exp.track is not m.track:
            self._locate(m, exp, exp.hold_s_m)
        if exp.entry_s_m is None and self._may_leave(m, now):
            self._resume(m, exp, now, out)

    def _resume(self, m: Member, exp: Exposure, t: float, out: list[act.Action]) -> None:
        """Back to AUTO at the first item of the route installed since that the aircraft can
        fly to straight from its hold point without entering the zone: beyond the hold point
        when the new route passes through it (a re-plan from the hold), else from the first
        item after the splice waypoint (the new route starts behind it)."""
        items, item_s = m.mission.items, m.mission.item_s_m
        e0, n0 = exp.hold_en_m
        s_new, cross_m = m.track.locate(e0, n0, exp.hold_s_m)
        if cross_m <= self.config.hold_radius_m:
            start, after_s = m.mission.first_route_seq, s_new + RESUME_AHEAD_M
        else:
            start, after_s = max(m.mission.first_route_seq, (m.splice_seq or 0) + 1), -math.inf
        seq = len(items) - 1
        for k in range(start, len(items)):
            it, s_k = items[k], item_s[k]
            if it.command not in (MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LOITER_TURNS):
                continue
            if s_k is None or s_k <= after_s:
                continue
            e1, n1 = self.frame.to_local(it.lat_deg, it.lon_deg)
            if exp.zone.segment_distance_m(e0, n0, float(e1), float(n1)) > 0.0:
                seq = k
                break
        exp.state = "resuming"
        out.append(act.Resume(m.vehicle_id, seq, exp.zone.id, t))

    def _resumed(self, r: act.Resumed, now: float, out: list[act.Action]) -> None:
        up = r.resume
        m = self.members[up.vehicle_id]
        exps = self.exposures.get(up.vehicle_id, {})
        exp = exps.get(up.zone_id)
        if exp is None or exp.state != "resuming":
            return
        if r.error is not None:
            exp.state = "holding"
            why = (
                f"AUTO at item {up.seq} not taken ({r.error}); still holding short of "
                f"{up.zone_id}, asking again"
            )
            out.append(_fallback(m, up.zone_id, "failed", why, now))
            self._resume(m, exp, now, out)
            return
        del exps[up.zone_id]
        m.hold_zone = None
        m.leave_hold_s = None
        # Back in AUTO it flies its cruise airspeed until told another: ArduPlane drops a
        # DO_CHANGE_SPEED airspeed on every mode change (ArduPlane/mode.cpp Mode::enter,
        # new_airspeed_cm = -1), and the next decision commands one.
        m.level_m_s = None
        # It jumps to the item: those before it in the new mission (the route's first speed
        # among them) were never run.
        m.last_seq = up.seq
        m.rejoin_seq = up.seq
        m.next_decision_s = -math.inf
        m.progress = None
        what = f"route around {up.zone_id} on board: resumed AUTO at item {up.seq}; re-timed"
        out.append(_fallback(m, up.zone_id, "resume", what, now, seq=up.seq))


def _fallback(
    m: Member, zone_id: str, action: str, reason: str, t: float, **more: object
) -> act.Report:
    """A ``fallback`` event: the hold taken or refused, the resumption (``action``)."""
    payload = {"zone": zone_id, "action": action, **more}
    return act.Report(EventKind.FALLBACK, reason, m.vehicle_id, t_s=t, payload=payload)

"""Mission changes in flight: loiter turns for an early vehicle and re-plans around pop-up
threats, each handed out as a planning job and installed by splicing the new mission in after
a waypoint far enough ahead; and the threats of the mission (the operator's included).

:class:`MissionChanges` is the part of :class:`~gcs.coordination.team.TeamController` that
does this; it holds no state of its own.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from dataclasses import replace

import numpy as np

from gcs.coordination import actions as act
from gcs.coordination.arrival import Decision
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind
from gcs.coordination.member import Member, path_en, route_track
from gcs.coordination.teamtime import names_of
from planner.deconflict import loiter_conflict
from planner.errors import InfeasibleError
from planner.mission import MAV_CMD_NAV_WAYPOINT
from planner.plan import World
from planner.popup import PopupOutcome, popup_zones
from planner.retime import can_loiter_after, clear_of_team
from planner.scenario import Appearance, Scenario, Threat
from planner.schedule import Adjustment, Anchor, Schedule, VehicleSchedule
from planner.schedulefile import PathMission, path_mission, splice_mission
from planner.slots import slot_spacing_s
from planner.threats import ThreatZone, active, build_threats
from planner.wind import CALM, Wind

__all__ = ["MissionChanges"]


class MissionChanges:
    """Loiter insertion, pop-up re-plans, installs and the mission's threats."""

    scenario: Scenario
    schedule: Schedule
    world: World
    config: FlightConfig
    rng: np.random.Generator
    members: dict[str, Member]
    team_ref_s: float | None
    version: int
    lead_s: float
    loiter_lead_s: float
    extra_threats: list[Threat]
    removed_threats: set[str]
    _zones_built: tuple[Scenario, object, list[ThreatZone]] | None
    """:meth:`zones` as last built, with the scenario and what it was built from."""
    popups_done: set[str]
    popups_running: set[str]
    pending: dict[str, act.Upload]
    replan_due: dict[str, float]
    replan_overdue: set[str]
    _cannot_follow: Callable[[float, Collection[str]], list[tuple[str, float]]]
    """The team-time part's (:meth:`gcs.coordination.teamtime.TeamTime._cannot_follow`)."""
    _slots_cannot_follow: Callable[[dict[str, float], Collection[str]], list[tuple[str, float]]]
    """The team-time part's (:meth:`gcs.coordination.teamtime.TeamTime._slots_cannot_follow`)."""
    _set_slots: Callable[[dict[str, float]], None]
    """The team-time part's (:meth:`gcs.coordination.teamtime.TeamTime._set_slots`)."""

    def hold_anchor_s_m(self, m: Member, zone_id: str) -> float | None:
        """Where the vehicle holds short of the zone (m along its path); None: not holding
        (:class:`~gcs.coordination.zoneguard.ZoneGuard` holds vehicles)."""
        return None

    def hold_short_s_m(self, m: Member, zone: ThreatZone, before_s_m: float) -> float | None:
        """Where the vehicle would hold short of the zone, its route entering it ahead of it
        and short of ``before_s_m``; None: it does not, or no zone guard."""
        return None

    def holds_now(self, m: Member, s_hold_m: float, s_now_m: float) -> bool:
        """Whether the guard holds the vehicle at ``s_now_m`` (m along its path) now, short of
        a zone it would hold at ``s_hold_m``; False with no zone guard."""
        return False

    def _no_route(self, vehicle_id: str, problem: str, now: float, zone_id: str | None) -> None:
        """No route around a zone (or any, ``zone_id`` None) will come for the vehicle now."""

    def _replan_now(self, vehicle_id: str, zone_id: str) -> None:
        """A vehicle holding short of the zone is re-planned from its hold point at once."""

    # -- loiter turns --------------------------------------------------------------------------

    def _keep_seq(self, m: Member, lead_m: float) -> int | None:
        """The first route waypoint at least ``lead_m`` ahead of the vehicle."""
        s_now = m.s_m or 0.0
        seq = max(m.last_seq or m.mission.first_route_seq, m.mission.first_route_seq)
        for k in range(seq, len(m.mission.items)):
            it = m.mission.items[k]
            s = m.mission.item_s_m[k]
            if s is not None and s >= m.track.length_m:
                return None  # the run-out past the goal: nothing to splice after
            if it.command == MAV_CMD_NAV_WAYPOINT and s is not None and s >= s_now + lead_m:
                return k
        return None

    def _can_loiter_after(self, m: Member, s_m: float) -> bool:
        """Whether loiter turns can be flown on the vehicle's path after ``s_m``: where its
        loiter job would look for them, clear of the zones in force at its last fix and of
        the rest of the team's tracks from then on (:class:`act.LoiterJob` keeps them so)."""
        now_s = m.last_fix_s or 0.0
        return can_loiter_after(
            self.scenario,
            self.scenario.vehicle(m.vehicle_id),
            m.schedule,
            s_m,
            self.in_force(now_s),
            self.world.terrain,
            clear_of_team(self.current_schedule(still_air=True), m.vehicle_id, now_s),
        )

    def _speed_now(self, m: Member) -> float:
        return float(m.level_m_s or self.scenario.vehicle(m.vehicle_id).cruise_m_s)

    def _loiter_keep_seq(self, m: Member) -> int | None:
        """The waypoint to splice loiter turns after: the first the loiter lead allows, or,
        with nothing that far ahead (a short route, a long lead on a fast rehearsal) or no
        room for turns after it, the nearest the shortest lead allows and with room after
        it, as :meth:`latest_arrival_s` looks when it lets the team time move later."""
        gs = max(m.groundspeed_m_s, 10.0)
        far = self._keep_seq(m, gs * self.loiter_lead_s)
        if self.loiter_lead_s <= self.config.min_lead_s:
            return far
        near = self._keep_seq(m, gs * self.config.min_lead_s)
        if far is None or near is None or near == far:
            return near if far is None else far
        s_far = m.mission.item_s_m[far] or 0.0
        if self._can_loiter_after(m, s_far):
            return far
        return near if self._can_loiter_after(m, m.mission.item_s_m[near] or 0.0) else far

    def _loiter(
        self, m: Member, d: Decision, t: float, s: float, wind: Wind, out: list[act.Action]
    ) -> None:
        gs = max(m.groundspeed_m_s, 10.0)
        keep = self._loiter_keep_seq(m)
        if keep is None:
            out.append(
                act.Report(
                    EventKind.LOITER,
                    f"early by {m.target_s - d.eta_max_s:.1f} s at its minimum speed, and no "
                    f"waypoint at least {self.config.min_lead_s:.0f} s ahead to splice loiter "
                    "turns after",
                    m.vehicle_id,
                    t_s=t,
                )
            )
            return
        s_k = m.mission.item_s_m[keep]
        assert s_k is not None
        t_k = t + (s_k - s) / gs
        # The planner's loiter arithmetic (eq. 8) is in still air at the ISA true airspeed;
        # give it the surplus the wind- and bias-aware ETA found, as a still-air target from
        # the splice waypoint. The new mission replaces the loiters after that waypoint, so
        # their time is kept too.
        v_min = m.limits.airspeed_min_m_s
        tas_min = v_min * m.tas_per_eas(s_k)
        surplus = m.target_s - d.eta_max_s
        track = m.track
        before = sum(1 for lo in track.loiters if lo.s_m < s_k)
        held_s = track.time_to_go_s(s_k, tas_min, wind, before) - track.time_to_go_s(
            s_k, tas_min, wind, len(track.loiters)
        )
        planner_tas_min = v_min * m.schedule.tas_per_eas(s_k)
        target_still_air = t_k + (track.length_m - s_k) / planner_tas_min + held_s + surplus
        m.busy_mission = True
        job = act.LoiterJob(
            m.vehicle_id,
            self.current_schedule(still_air=True),
            keep,
            t_k,
            s_k,
            self._speed_now(m),
            target_still_air,
            tuple(self.in_force(t)),
            self.config.loiter_margin_m_s,
            t,
            self.world.terrain,
        )
        out.append(act.Compute(job))

    def _loiter_computed(self, job: act.LoiterJob, r: act.Computed, out: list[act.Action]) -> None:
        m = self.members[job.vehicle_id]
        t = job.decided_s
        if r.error is not None:
            m.busy_mission = False
            out.append(
                act.Report(EventKind.LOITER, f"no loiter possible: {r.error}", m.vehicle_id, t_s=t)
            )
            return
        vs, adjustments = r.result
        if job.schedule.vehicle(m.vehicle_id).path is not m.schedule.path:
            # A re-plan (a pop-up's, a hold's) was adopted while these turns were worked out
            # on the route before it: spliced in, they would bring that route back, into the
            # zone it went around. Decided again on the route flown now.
            m.busy_mission = False
            m.next_decision_s = -math.inf
            out.append(
                act.Report(
                    EventKind.LOITER,
                    "loiter turns worked out on a route since replaced: dropped, deciding again",
                    m.vehicle_id,
                    t_s=t,
                )
            )
            return
        if m.done or not vs.loiters or all(lo.s_m < job.s_m for lo in vs.loiters):
            m.busy_mission = False
            return
        # The team as it will fly: each vehicle's schedule, or the one on its way up.
        others = [
            self.pending[x.vehicle_id].schedule if x.vehicle_id in self.pending else x
            for x in self.current_schedule(still_air=True).vehicles
            if x.vehicle_id != m.vehicle_id
        ]
        clash = loiter_conflict(vs, others, self.scenario.separation_m, t)
        if clash is not None:
            # Another vehicle's route or turns changed while these were worked out (turns
            # decided together do not see each other): decided again against the team now.
            m.busy_mission = False
            m.next_decision_s = -math.inf
            out.append(
                act.Report(
                    EventKind.LOITER,
                    f"loiter turns worked out while the team's plans changed: {clash}; "
                    "dropped, deciding again",
                    m.vehicle_id,
                    t_s=t,
                )
            )
            return
        out.append(
            act.Upload(
                m.vehicle_id,
                self._spliced(m, vs, job.keep_seq),
                vs,
                job.keep_seq,
                "loiter inserted",
                True,
                tuple(adjustments),
                t,
            )
        )

    # -- missions -------------------------------------------------------------------------------

    def _path_mission(self, vs: VehicleSchedule) -> PathMission:
        return path_mission(
            self.schedule,
            vs,
            self.world.terrain,
            runout_m=self.config.runout_m,
            max_spacing_m=self.config.waypoint_spacing_m,
        )

    def _spliced(self, m: Member, vs: VehicleSchedule, keep: int | None) -> PathMission:
        new = self._path_mission(vs)
        return new if keep is None else splice_mission(m.mission, keep, new)

    def _installed(self, r: act.Installed, now: float, out: list[act.Action]) -> None:
        up = r.upload
        m = self.members[up.vehicle_id]
        m.busy_mission = False
        if self.pending.get(up.vehicle_id) is up:
            del self.pending[up.vehicle_id]
        if up.in_flight and (r.skipped or r.error is not None):
            problem = (
                "it passed the splice waypoint of its new route"
                if r.skipped
                else f"the upload of its new route failed ({r.error})"
            )
            self._no_route(m.vehicle_id, problem, now, None)
        if r.skipped:
            out.append(
                act.Report(
                    EventKind.UPLOAD,
                    f"{up.what}: the vehicle passed the splice waypoint; not installed",
                    m.vehicle_id,
                )
            )
            return
        if r.error is not None:
            kind = EventKind.LOITER if up.what == "loiter inserted" else EventKind.UPLOAD
            flying = "; flying on" if up.in_flight else ""
            out.append(
                act.Report(
                    kind, f"{up.what}: upload failed ({r.error}){flying}", m.vehicle_id,
                    t_s=up.decided_s if up.in_flight else None,
                )
            )  # fmt: skip
            return
        if not r.said:
            out.append(
                act.Report(
                    EventKind.UPLOAD,
                    f"{up.what}: {len(up.mission.items)} items",
                    m.vehicle_id,
                    payload=up.payload(),
                )
            )
        if up.keep_seq is None and not up.in_flight:
            return  # the initial mission: nothing changes
        self._adopt(m, up, now)
        if not r.said:
            out.extend(self._adjustment(a, up.decided_s) for a in up.adjustments)

    def _adopt(self, m: Member, up: act.Upload, now: float) -> None:
        """The vehicle flies ``up``'s mission now."""
        vs = up.schedule
        m.mission = up.mission
        m.schedule = vs
        m.track = route_track(vs)
        m.via_track = None
        m.next_decision_s = -math.inf
        keep = up.keep_seq
        m.splice_seq = keep
        m.leave_hold_s = up.leave_hold_s
        s_k = 0.0 if keep is None else (m.mission.item_s_m[keep] or 0.0)
        m.loiter_log = [x for x in m.loiter_log if x["s_m"] < s_k]
        for lo in vs.loiters:
            if lo.s_m >= s_k:
                m.loiter_log.append(
                    {
                        "s_m": lo.s_m,
                        "centre_east_m": lo.centre_east_m,
                        "centre_north_m": lo.centre_north_m,
                        "radius_m": lo.radius_m,
                        "turns": lo.turns,
                        "buffer_id": lo.buffer_id,
                        "t_s": now,
                    }
                )
        self.schedule = replace(
            self.schedule,
            vehicles=tuple(
                vs if x.vehicle_id == m.vehicle_id else x for x in self.schedule.vehicles
            ),
        )

    @staticmethod
    def _adjustment(a: Adjustment, t: float) -> act.Report:
        if a.strategy == "loiter":
            return act.Report(EventKind.LOITER, a.reason, a.vehicle, "loiter", a.value, t_s=t)
        if a.strategy == "takeoff_delay":
            return act.Report(
                EventKind.TAKEOFF, a.reason, a.vehicle, "takeoff_delay", a.value, t_s=t
            )
        return act.Report(EventKind.PLAN, a.reason, a.vehicle, None, a.value, t_s=t)

    def current_schedule(self, *, still_air: bool = False) -> Schedule:
        """The schedule with today's targets as its arrival times and each vehicle's wind the
        one it measures (the forecast until it has; none with ``still_air``, for a target
        already worked out in the wind)."""
        vehicles = tuple(
            replace(
                m.schedule,
                arrival_s=m.target_s,
                wind=CALM if still_air else m.schedule.wind if m.wind is None else m.wind,
                via=m.via_live(),  # timed for another slot: its slot alone
            )
            for m in (self.members[vs.vehicle_id] for vs in self.schedule.vehicles)
        )
        return replace(self.schedule, vehicles=vehicles, required_arrival_s=self.team_ref_s)

    # -- threats --------------------------------------------------------------------------------

    @property
    def operator_threats(self) -> tuple[Threat, ...]:
        """The threats added in flight (:meth:`add_threat`), with the time they appear."""
        return tuple(t for t in self.extra_threats if t.id not in self.removed_threats)

    def add_threat(self, threat: Threat, now_s: float, at_s: float | None = None) -> None:
        """A threat for the mission: re-planned around when it appears.

        It appears at mission time ``at_s`` if given, else when its own ``appears`` says (a
        mission time, or a delay after a vehicle's takeoff), else now; a time already past is
        now. Before the mission starts (``now_s`` 0) it is queued. Until it appears no plan
        avoids it.

        Raises
        ------
        ValueError
            A threat with this id is already in the mission.
        """
        if threat.id in {t.id for t in (*self.scenario.threats, *self.extra_threats)}:
            raise ValueError(f"threat {threat.id}: a threat with this id is already in the mission")
        now = max(0.0, now_s)
        if at_s is not None or threat.appears is None:
            when = now if at_s is None else max(now, at_s)
            threat = threat.model_copy(update={"appears": Appearance(at_s=when)})
        elif threat.appears.at_s is not None and threat.appears.at_s < now:
            threat = threat.model_copy(update={"appears": Appearance(at_s=now)})
        self.extra_threats.append(threat)

    def remove_threat(self, threat_id: str, now_s: float) -> list[act.Action]:
        """Lift a threat: a queued one never appears; one in force no longer constrains a
        re-plan (routes already flown around it are kept).

        Raises
        ------
        KeyError
            No threat with this id in the mission (named).
        """
        ids = {t.id for t in (*self.scenario.threats, *self.extra_threats)}
        if threat_id not in ids or threat_id in self.removed_threats:
            raise KeyError(f"no threat {threat_id!r} in the mission")
        self.removed_threats.add(threat_id)
        was = "in force" if threat_id in self.popups_done else "queued"
        return [act.Report(EventKind.POPUP, f"threat {threat_id} removed ({was})", t_s=now_s)]

    def _takeoffs_s(self) -> dict[str, float]:
        """Mission time of each launch so far (pop-ups may be timed from them)."""
        return {
            m.vehicle_id: m.launched_s for m in self.members.values() if m.launched_s is not None
        }

    def zones(self) -> list[ThreatZone]:
        """Every threat of the mission, the operator's included, timed from the launches.
        Built again only when one of those changes (it is asked at every tick)."""
        takeoffs = self._takeoffs_s()
        # The extra threats are only ever appended: their ids stay theirs while listed.
        key = (
            tuple(id(t) for t in self.extra_threats),
            frozenset(self.removed_threats),
            tuple(sorted(takeoffs.items())),
        )
        built = self._zones_built
        if built is None or built[0] is not self.scenario or built[1] != key:
            threats = [
                t
                for t in (*self.scenario.threats, *self.extra_threats)
                if t.id not in self.removed_threats
            ]
            scenario = self.scenario.model_copy(update={"threats": threats})
            built = (self.scenario, key, build_threats(scenario, takeoffs))
            self._zones_built = built
        return list(built[2])

    def in_force(self, t: float) -> list[ThreatZone]:
        return list(active(self.zones(), t))

    def _due_popups(self, now: float) -> list[ThreatZone]:
        out = []
        for z in popup_zones(self.zones()):
            appears_s = math.inf if z.appears_at_s is None else z.appears_at_s
            if z.id not in self.popups_done and appears_s <= now:
                out.append(z)
        return out

    def _popup(
        self,
        zone: ThreatZone,
        t: float,
        lead: float,
        out: list[act.Action],
        why: str | None = None,
        *,
        from_hold: bool = False,
    ) -> None:
        """Hand out the re-plan around a new threat from waypoints ``lead`` s ahead (a vehicle
        holding short of it: from its hold point); ``from_hold``: asked for by a vehicle
        holding short of it with no route around it."""
        at_s = t + lead
        anchors: dict[str, Anchor] = {}
        keeps: dict[str, int | None] = {}
        holding: set[str] = set()
        for m in self.members.values():
            if m.done:
                continue
            if m.phase == "ground" and m.takeoff_s > at_s:
                keeps[m.vehicle_id] = None
                continue
            s_hold = self.hold_anchor_s_m(m, zone.id)
            if s_hold is not None:
                # Its new route starts where it holds; the mission is kept up to the last
                # waypoint short of that point (it flies on from there once resumed), or,
                # with none short of it, replaced whole: holding, it flies no mission item.
                anchors[m.vehicle_id] = Anchor(s_hold, self._speed_now(m), at_s)
                keeps[m.vehicle_id] = self._keep_behind(m, s_hold)
                holding.add(m.vehicle_id)
                continue
            gs = self._speed_ahead_m_s(m)
            keep = self._keep_seq(m, gs * lead) if m.phase == "route" else None
            s_k = m.track.length_m if keep is None else m.mission.item_s_m[keep]
            assert s_k is not None
            s_short = self.hold_short_s_m(m, zone, s_k) if m.phase == "route" else None
            keep_short = None if s_short is None else self._keep_behind(m, s_short)
            if s_short is not None and keep_short is not None and keep_short >= (m.last_seq or 0):
                # It reaches the zone before that waypoint (or, with no waypoint that far
                # ahead, at all): its new route starts where it will hold short of the zone
                # (held there by the guard until it is on board).
                t_hold = max(self._reaches_s(m, t, s_short, gs), at_s)
                anchors[m.vehicle_id] = Anchor(s_short, self._speed_now(m), t_hold)
                keeps[m.vehicle_id] = keep_short
                continue
            if s_short is not None and self.holds_now(m, s_short, m.s_m or 0.0):
                # No waypoint between it and where it will hold, and so near that the guard
                # holds it there now: re-planned from that point, as one holding there (a
                # route from the waypoint past the zone would keep out of it, and it would be
                # held with none on board and re-planned again).
                anchors[m.vehicle_id] = Anchor(s_short, self._speed_now(m), at_s)
                keeps[m.vehicle_id] = keep_short
                holding.add(m.vehicle_id)
                continue
            if keep is None:
                out.append(
                    act.Report(
                        EventKind.POPUP,
                        f"{zone.id}: no waypoint far enough ahead to re-plan from",
                        m.vehicle_id,
                        t_s=t,
                    )
                )
                continue
            # The vehicle reaches the splice waypoint at its own time, not at t + lead: the
            # waypoint is the first one at least that far ahead and may be much farther, with
            # loiter turns of the kept mission before it.
            t_k = self._reaches_s(m, t, s_k, gs)
            anchors[m.vehicle_id] = Anchor(s_k, self._speed_now(m), t_k)
            keeps[m.vehicle_id] = keep
        threats = self.in_force(t)
        if zone.id not in {z.id for z in threats}:
            threats.append(zone)
        world = replace(self.world, threats=tuple(threats))
        said = f"threat {zone.id} appears" if why is None else f"{zone.id}: {why}"
        out.append(
            act.Report(EventKind.POPUP, f"{said}; re-planning from {lead:.0f} s ahead", t_s=t)
        )
        self.popups_running.add(zone.id)
        self.replan_due[zone.id] = at_s
        job = act.PopupJob(
            zone,
            self.current_schedule(),
            world,
            tuple(threats),
            anchors,
            keeps,
            self.config.method,
            self.rng,
            self.config.loiter_margin_m_s,
            t,
            lead,
            frozenset(holding),
            from_hold,
            {vid: self.members[vid].mission for vid in keeps},
        )
        out.append(act.Compute(job))

    @staticmethod
    def _speed_ahead_m_s(m: Member) -> float:
        """The speed (m/s) the vehicle is taken to fly on at: its ground speed on its route;
        in loiter turns, or circling where it holds short of a zone, its true airspeed (round
        a circle the ground speed of one fix is the side of the wind it is on: 14 m/s upwind
        for one averaging 17 m/s round its circle set a splice 200 s late, and the team time
        moved for it; one holding short of another zone was taken to fly on at 10 m/s, and the
        slots after it moved 370 s)."""
        circling = m.in_loiter() or m.hold_zone is not None
        tas_m_s = m.tas_m_s(m.s_m or 0.0) if circling else None
        return max(m.groundspeed_m_s if tas_m_s is None else tas_m_s, 10.0)

    @staticmethod
    def _reaches_s(m: Member, t: float, s_k: float, gs_m_s: float) -> float:
        """When the vehicle reaches ``s_k`` along its route, at ``gs_m_s``: the path from
        where it is plus the loiters still to fly short of ``s_k`` (the one it is in less
        what it has flown round it); a loiter at ``s_k`` itself belongs to what is
        replaced."""
        path_m = max(s_k - (m.s_m or 0.0), 0.0)
        done = m.loiters_done()
        loiter_m = 0.0
        for i, lo in enumerate(m.track.loiters):
            if i < done or lo.s_m >= s_k - 1.0:
                continue
            length = lo.length_m
            if i == done and m.in_loiter():
                length = max(length - m.loiter_flown_m, 0.0)
            loiter_m += length
        return t + (path_m + loiter_m) / gs_m_s

    def _keep_behind(self, m: Member, s_m: float) -> int | None:
        """The last route waypoint at or short of ``s_m`` along the vehicle's mission."""
        found = None
        for k in range(m.mission.first_route_seq, len(m.mission.items)):
            s_k = m.mission.item_s_m[k]
            if s_k is None or s_k > s_m:
                break
            if m.mission.items[k].command == MAV_CMD_NAV_WAYPOINT:
                found = k
        return found

    def _popup_computed(self, job: act.PopupJob, r: act.Computed, out: list[act.Action]) -> None:
        zone, t, lead = job.zone, job.decided_s, job.lead_s
        err = r.error
        self.replan_due.pop(zone.id, None)
        self.replan_overdue.discard(zone.id)
        if err is not None:
            self.popups_running.discard(zone.id)
            for vid in job.keeps:
                self._no_route(vid, f"its re-plan around {zone.id} failed: {err}", t, zone.id)
            retry = (
                isinstance(err, InfeasibleError)
                and "inside forbidden zone" in str(err)
                and lead > self.config.min_lead_s
            )
            if not retry:
                out.append(
                    act.Report(EventKind.POPUP, f"re-plan around {zone.id} failed: {err}", t_s=t)
                )
                return
            lead = max(self.config.min_lead_s, lead / 2.0)
            out.append(
                act.Report(EventKind.POPUP, f"{err}; re-planning from {lead:.0f} s ahead", t_s=t)
            )
            self._popup(zone, t, lead, out)
            return
        self.popups_running.discard(zone.id)
        outcome: PopupOutcome = r.result
        new_ref = outcome.schedule.required_arrival_s
        stuck = []
        # Ordered slots (spaced, landing slots, waves) move apart: each vehicle's its own.
        slots: dict[str, float] | None = None
        if new_ref is not None and slot_spacing_s(self.scenario) is not None:
            slots = {
                m.vehicle_id: outcome.schedule.vehicle(m.vehicle_id).arrival_s
                for m in self.members.values()
                if not m.done
            }
            stuck = self._slots_cannot_follow(slots, outcome.affected)
        elif new_ref is not None and self.team_ref_s is not None and new_ref > self.team_ref_s:
            stuck = self._cannot_follow(new_ref, outcome.affected)
        for ev in outcome.events:
            if stuck and ev.kind == EventKind.ARRIVAL:
                continue  # said below: the team time does not move
            # The re-timed team arrival is said with its time (the store keeps it).
            value = new_ref if ev.kind == EventKind.ARRIVAL else None
            payload = dict(ev.payload)
            pair = payload.get("pair")
            vehicle = pair[0] if isinstance(pair, list) and pair else None
            out.append(
                act.Report(
                    EventKind(ev.kind), ev.text, vehicle, value=value, t_s=t, payload=payload
                )
            )
        if stuck:
            # The re-planned vehicles' routes are longer than the others can wait for (no
            # slower speed or loiter turns left to them): the team time stays, and the
            # re-planned vehicles that cannot make it are released from their slots when
            # their own decisions find them late (an alarm each).
            assert self.team_ref_s is not None and new_ref is not None
            out.append(
                act.Report(
                    EventKind.ARRIVAL,
                    f"team arrival stays {self.team_ref_s:.1f} s after {zone.id}: the route "
                    f"round it would need {new_ref:.1f} s, and {names_of(stuck)} cannot "
                    "arrive as late",
                    value=self.team_ref_s,
                    t_s=t,
                )
            )
            new_ref = self.team_ref_s
            slots = None if slots is None else {}
        if slots is not None:
            self._set_slots(slots)
        elif (
            new_ref is not None
            and self.team_ref_s is not None
            and abs(new_ref - self.team_ref_s) > 1e-3
        ):
            self.team_ref_s = new_ref
            self.version += 1
        for a in outcome.adjustments:
            out.append(self._adjustment(a, t))
        for m in self.members.values():
            vs = outcome.schedule.vehicle(m.vehicle_id)
            if new_ref is not None and slots is None:
                m.target_s = new_ref + m.offset_s
            m.next_decision_s = -math.inf
            if vs is m.schedule or m.vehicle_id not in job.keeps or m.done:
                continue
            if stuck and m.vehicle_id not in outcome.affected:
                continue  # re-timed to a team time that does not come
            if job.missions.get(m.vehicle_id) is not m.mission or m.vehicle_id in self.pending:
                # Its mission changed while the route was worked out (loiter turns put in), or
                # a change is on its way to it: the item the route was to be spliced at (an
                # item of the mission on board when the re-plan was decided) is not, or may
                # not stay, the one it was.
                out.append(
                    act.Report(
                        EventKind.POPUP,
                        f"{zone.id}: its mission changed while its new route was worked out; "
                        "not sent: it flies on as it is (held short of the zone if it "
                        "crosses a forbidden one, and re-planned from there)",
                        m.vehicle_id,
                        t_s=t,
                    )
                )
                self._no_route(m.vehicle_id, "its mission changed during its re-plan", t, None)
                self._replan_now(m.vehicle_id, zone.id)
                continue
            if m.vehicle_id in outcome.affected:
                m.planned_paths.append({"label": f"after {zone.id}", "t_s": t, "en_m": path_en(vs)})
            if m.phase == "ground":
                m.takeoff_s = vs.takeoff_s
            keep = job.keeps[m.vehicle_id]
            s_hold = self.hold_anchor_s_m(m, zone.id)
            s_keep = None if keep is None else m.mission.item_s_m[keep]
            if s_hold is not None and m.vehicle_id not in job.holding and (s_keep or 0.0) < s_hold:
                # It holds past the waypoint this route starts from: flying back to it would
                # waste the hold; it is re-planned from where it holds instead.
                self._no_route(m.vehicle_id, "its new route starts behind where it holds", t, None)
                self._replan_now(m.vehicle_id, zone.id)
                continue
            m.busy_mission = True
            out.append(
                act.Upload(
                    m.vehicle_id,
                    self._spliced(m, vs, keep),
                    vs,
                    keep,
                    f"after {zone.id}",
                    m.phase != "ground",
                    (),
                    t,
                    holding=m.vehicle_id in job.holding or m.hold_zone is not None,
                    leave_hold_s=self._leaves_hold_s(job, m.vehicle_id),
                )
            )

    @staticmethod
    def _leaves_hold_s(job: act.PopupJob, vehicle_id: str) -> float | None:
        """When a vehicle re-planned from where it holds leaves its hold point on the new
        route (its anchor's time: the re-plan's lead ahead of when it was decided), else
        None."""
        if vehicle_id not in job.holding:
            return None
        return job.anchors[vehicle_id].t_s

    def _computed(self, r: act.Computed, now: float, out: list[act.Action]) -> None:
        if isinstance(r.job, act.LoiterJob):
            self._loiter_computed(r.job, r, out)
        else:
            self._popup_computed(r.job, r, out)

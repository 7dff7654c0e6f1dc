"""The team controller: one flight's arrival-time policy, with no I/O.

It is driven by :meth:`TeamController.handle` with an input and the mission time now (seconds
since the mission start, from whatever clock the caller keeps) and returns the actions to carry
out (:mod:`gcs.coordination.actions`). Operator requests are methods: :meth:`add_threat`,
:meth:`remove_threat`, :meth:`move_team_time`, :meth:`abort`. Nothing here reads a clock,
touches a socket or waits; planning work is handed out as :class:`~actions.Compute` jobs and
comes back as :class:`~actions.Computed`.

The policy: launches at the takeoff times (the takeoff strategy); closed-loop speed control on
the remaining route (eqs. 6-7, wind from telemetry, quantised airspeed, commanded only on a
level change); loiter turns when a vehicle would be early even at its minimum speed (eqs. 8-9,
the fewest turns that fit, by replacing its mission after a waypoint ahead); a later team
arrival when one would be late even at its maximum speed; pop-up threats re-planned for the
vehicles whose routes they touch, from waypoints ahead, and the team re-timed. A vehicle whose
route enters a forbidden zone that appeared in flight, and that has no route around it on
board in time (the re-plan late or failed, the upload failed or skipped), is held short of it
with an alarm and resumed once one is installed (:mod:`gcs.coordination.zoneguard`).

Supervision: a vehicle that reports a crash (a STATUSTEXT "Crash ...", HEARTBEAT
MAV_STATE_EMERGENCY in the air, disarmed on its route) or whose progress along its route
stalls for ``stall_bound_s`` is lost (:data:`EventKind.VEHICLE_LOST`), and the rest continue,
re-time without it or abort, as ``on_vehicle_lost`` says. The flight ends at its hard deadline
(the planned latest arrival plus ``hard_deadline_s``) whatever the team time became.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace
from typing import Any

import numpy as np

from gcs.coordination import actions as act
from gcs.coordination.arrival import ArrivalController, Decision, SpeedLimits
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind
from gcs.coordination.member import Lost, LostCause, Member, path_en, route_track
from gcs.coordination.resolution import Ahead, Forecasts, Resolution, closest_m, resolve
from gcs.coordination.separation import Position, SeparationWatch
from gcs.coordination.teamtime import TeamTime, TeamTimeRefused
from gcs.coordination.tracks import TruthSample, closest_approach
from gcs.coordination.vertical import Held, Room, VerticalResolution, resolve_vertical
from gcs.coordination.verticalflight import VerticalFlight, room_ahead
from gcs.coordination.zoneguard import Exposure, ZoneGuard
from planner.atmosphere import eas2tas
from planner.layers import layer_step_m
from planner.loiterflight import way_out_m
from planner.mission import MAV_CMD_DO_CHANGE_SPEED, MAV_CMD_NAV_WAYPOINT
from planner.plan import World
from planner.popup import popup_zones
from planner.scenario import Scenario, Threat, Windows
from planner.schedule import Schedule
from planner.threats import ThreatZone
from planner.wind import Wind

__all__ = ["PROGRESS_M", "TeamController", "TeamTimeRefused", "is_crash_text"]

PROGRESS_M = 1.0
"""Along-route distance (m) a fix must gain on the farthest one yet to count as progress."""
STOPPED_FIXES = 8
"""Fixes in a row, over ``stopped_bound_s``, that find a vehicle where it was."""
SPEED_REFUSALS_ALARM = 3
"""Speed commands refused in a row that make an alarm: the speed is not under control."""
GOAL_ALONG_SLACK_M = 500.0
"""A fix counts towards the arrival only when the route left (as last located) is within
the arrival radius and this much more (a fix or two of travel); one going away from the goal
is its passage only with no more than this of its route left."""


RESOLVED_MARGIN = 1.1
"""Pairs are screened for conflicts at this many separations, and a resolution is counted on
only if it keeps the pair that far apart as predicted; a speed resolution short of it gives
way to one by height."""
HOLD_ROOM_S = 60.0
"""A height resolution held on past its end (the pair not yet past) keeps its height only while
it has room over the ground it flies this far ahead (flight s)."""
SPEED_CHANGING_M_S = 1.0
"""A vehicle whose airspeed at a fix is this far or farther from the one it was asked is
still changing speed: forecast at the ground speed the airspeed asked makes good (m/s)."""
RETURNING_M_S = 1.0
"""A vehicle off its profile that closes on it this fast or faster (m/s: its climb or sink
less the profile's own where it is) is forecast back on it at that rate (:attr:`~gcs.
coordination.resolution.Ahead.off_profile_m`); slower, it is forecast keeping its height off
it (as its profile climbs or falls)."""
PROFILE_SLOPE_STEP_M = 25.0
"""Its profile's slope where it is is taken over this far on either side, m."""
NEIGHBOUR_SEPARATIONS = 2.0
"""A conflict's resolution is judged against the vehicles forecast within this many
screening separations (:data:`RESOLVED_MARGIN` separations each) of either of the pair too
(:func:`gcs.coordination.resolution.resolve`)."""
TAKEOFF_RECHECK_S = 30.0
"""How often (mission s) the vehicles still on the ground are timed again in the wind the
ones aloft measure, with arrival windows (where no team time moves to re-time them):
scheduled in a still-air forecast and flown into 7 m/s, a vehicle that took off as planned
could no longer make its 40 s window even at its top speed."""
LANDING_MARGIN_S = 120.0
"""Flare, roll-out and the disarm delay, on top of the glide (see ``landing_bound_s``)."""
POPUP_SEEN_LATE_S = 5.0
"""A pop-up threat's re-plan is counted from its appearance when its tick saw it at most this
late (mission s; :meth:`TeamController._popup_lead_s`)."""
VIA_REACHED_M = 50.0
"""Within this of the place (m along its route) the pass is made: timed for its slot on."""


def is_crash_text(text: str) -> bool:
    """A STATUSTEXT saying the vehicle crashed: ArduPlane's crash detection sends "Crash
    detected" (or "Crash detected. No action taken"; ArduPlane/is_flying.cpp), ArduCopter's
    "Crash: Disarming" (ArduCopter/crash_check.cpp). A hard landing is not one."""
    return text.lstrip().lower().startswith("crash")


def _resolving(r: Resolution) -> str:
    """What a resolution is, for its event and its speed command."""
    aim = (
        f"to keep the separation from {r.other}"
        if r.keeps_separation
        else f"to open the distance from {r.other} (no speed keeps the separation)"
    )
    return (
        f"flies {r.airspeed_m_s:g} m/s until {r.until_s:.1f} s {aim}: predicted "
        f"{r.unresolved_m:.0f} m apart at {r.at_s:.1f} s as they fly, {r.predicted_m:.0f} m so"
    )


def reported_wind(fix: act.Fix) -> Wind | None:
    """The vehicle's wind estimate (WIND), else ground velocity minus true airspeed; None when
    the fix carries neither (the first fixes from a vehicle heard again)."""
    if fix.wind_speed_m_s is not None and fix.wind_from_deg is not None:
        return Wind.from_speed_from(fix.wind_speed_m_s, fix.wind_from_deg)
    if (
        fix.airspeed_m_s is not None
        and fix.heading_deg is not None
        and fix.vn_m_s is not None
        and fix.ve_m_s is not None
    ):
        h = math.radians(fix.heading_deg)
        tas = fix.airspeed_m_s * eas2tas(fix.alt_amsl_m or 0.0)
        return Wind(fix.ve_m_s - tas * math.sin(h), fix.vn_m_s - tas * math.cos(h))
    return None


class TeamController(ZoneGuard, TeamTime):
    """The policy of one flight: members, the team arrival time, threats, decisions.

    Build it from a schedule (:meth:`__init__`), take :meth:`initial_uploads`, then
    :meth:`start` at a UTC and feed inputs with :meth:`handle`.
    """

    next_takeoff_check_s: float = -math.inf
    """When the vehicles on the ground are next timed again in the measured wind
    (:data:`TAKEOFF_RECHECK_S`)."""

    def __init__(
        self,
        scenario: Scenario,
        schedule: Schedule,
        world: World,
        config: FlightConfig | None = None,
        *,
        rng: np.random.Generator | None = None,
    ) -> None:
        self.scenario = scenario
        self.schedule = schedule
        self.world = world
        self.config = config or FlightConfig()
        self.rng = rng if rng is not None else np.random.default_rng(self.config.seed)
        self.frame = scenario.frame()
        self.team_ref_s: float | None = schedule.required_arrival_s
        self.planned_ref_s = self.team_ref_s
        """The team time as the schedule set it before launch."""
        self.start_utc_s: float | None = None
        self.lead_s = self.config.min_lead_s
        self.loiter_lead_s = self.config.min_lead_s
        self.members: dict[str, Member] = {}
        self.extra_threats: list[Threat] = []
        self.removed_threats: set[str] = set()
        self._zones_built: tuple[Scenario, object, list[ThreatZone]] | None = None
        self.popups_done: set[str] = set()
        self.popups_running: set[str] = set()
        self.threats_appeared: list[dict[str, Any]] = []
        self.stopped: str | None = None
        self.guarded: list[ThreatZone] = []
        self.exposures: dict[str, dict[str, Exposure]] = {}
        self.replan_due: dict[str, float] = {}
        self.replan_overdue: set[str] = set()
        self.pending: dict[str, act.Upload] = {}
        """Uploads handed out and not yet answered, per vehicle (a restart compares the
        vehicle's mission with these too)."""
        self.version = 1
        """Moves with every change of the team time (an operator's stale move is refused)."""
        self.hard_deadline_s = 0.0
        """Mission time the flight ends at, failed, if it has not before (never moves)."""
        self.separation = SeparationWatch(scenario.separation_m)
        """Every fix against the other flying vehicles' (an alarm below the separation)."""
        self.forecasts = Forecasts(
            [vs.vehicle_id for vs in schedule.vehicles],
            self._screen_horizon_s(),
            self.config.resolve_response_s,
        )
        """Each vehicle's flight ahead along its route, for resolving conflicts."""
        self.vertical = VerticalFlight()
        """The vertical resolutions being flown."""
        self.unresolved: set[frozenset[str]] = set()
        """The pairs forecast under the separation that neither speed nor height resolves,
        said once (until they are no longer forecast so, or one of them is resolved)."""
        for vs in schedule.vehicles:
            v = scenario.vehicle(vs.vehicle_id)
            limits = SpeedLimits(v.speed_min_m_s, v.speed_max_m_s, schedule.step_m_s)
            offset = schedule.offsets_s.get(v.id, 0.0)
            target = vs.arrival_s if self.team_ref_s is None else self.team_ref_s + offset
            goal = vs.path.end
            m = Member(
                v.id,
                limits,
                offset,
                vs,
                self._path_mission(vs),
                route_track(vs),
                ArrivalController(limits, tolerance_s=self.config.tolerance_s),
                target,
                vs.takeoff_s,
                target,
                goal_en_m=(goal.east_m, goal.north_m),
            )
            m.planned_paths.append({"label": "initial", "t_s": 0.0, "en_m": path_en(vs)})
            self.members[v.id] = m
        self.hard_deadline_s = (
            max(m.target_s for m in self.members.values()) + self.config.hard_deadline_s
        )

    # -- set-up --------------------------------------------------------------------------------

    def initial_uploads(self) -> list[act.Upload]:
        return [
            act.Upload(m.vehicle_id, m.mission, m.schedule, None, "initial mission", False)
            for m in self.members.values()
        ]

    def start(self, start_utc_s: float) -> list[act.Action]:
        """The mission starts at this UTC (mission time 0)."""
        self.start_utc_s = start_utc_s
        reason = self.schedule.arrival_reason
        return [
            act.Report(
                EventKind.START,
                f"mission start at UTC {start_utc_s:.1f}; team arrival {self.fmt_ref()} ({reason})",
                t_s=0.0,
            )
        ]

    def fmt_ref(self) -> str:
        return "per-vehicle" if self.team_ref_s is None else f"{self.team_ref_s:.1f} s"

    @property
    def finished(self) -> bool:
        return self.stopped is not None or all(m.over for m in self.members.values())

    def next_due_s(self, now_s: float) -> float:
        """The next mission time after ``now_s`` at which a tick has work (a vehicle to arm or
        to launch, a pop-up threat appearing); inf when none. The runner ticks then rather
        than up to a second late."""
        lead_s = self.config.arm_lead_s
        times = [
            t
            for m in self.members.values()
            if m.phase == "ground"
            for t in (m.takeoff_s, m.takeoff_s - lead_s)
            if t > now_s
        ]
        times += [
            z.appears_at_s
            for z in popup_zones(self.zones())
            if z.id not in self.popups_done and z.appears_at_s is not None
            if z.appears_at_s > now_s
        ]
        return min(times, default=math.inf)

    def _popup_lead_s(self, zone: ThreatZone, now: float) -> float:
        """The re-plan's lead counted from the zone's appearance, not from the tick that saw
        it: in lock step that tick comes up to the lock step's lead of flight late, more on a
        busy machine, and the waypoints the new routes start from (the first each vehicle
        reaches after the lead) moved with the load (seen: decided 100.1-101.9 s for a zone
        at 100 s; two vehicles then re-planned from 4 km farther on, one from its hold point,
        and the pair lost separation). A zone seen more than :data:`POPUP_SEEN_LATE_S` late (a
        flight resumed after it) gets the whole lead from now."""
        if zone.appears_at_s is None:
            return self.lead_s
        late = now - zone.appears_at_s
        return self.lead_s - late if 0.0 < late <= POPUP_SEEN_LATE_S else self.lead_s

    def _t(self, utc_s: float) -> float:
        assert self.start_utc_s is not None, "the mission has not started"
        return utc_s - self.start_utc_s

    # -- inputs ---------------------------------------------------------------------------------

    def handle(self, event: act.Input, now_s: float) -> list[act.Action]:
        """Take one input at mission time ``now_s``; return what to do."""
        out: list[act.Action] = []
        match event:
            case act.Tick():
                self._tick(now_s, out)
            case act.Fix():
                self._fix(event, out)
            case act.Heartbeat():
                self._heartbeat(event, now_s, out)
            case act.Alarm():
                self._alarm(event, now_s, out)
            case act.LinkSilent(vehicle_id=vid):
                self.members[vid].link_silent = True
            case act.LinkBack(vehicle_id=vid):
                m = self.members[vid]
                m.link_silent = False
                m.next_decision_s = -math.inf
            case act.Launched():
                self._launched(event, now_s, out)
            case act.SpeedCommanded():
                self._speed_commanded(event, out)
            case act.AltitudeCommanded():
                self.vertical.commanded(event, out)
            case act.Installed():
                self._installed(event, now_s, out)
            case act.Computed():
                self._computed(event, now_s, out)
            case act.HoldTaken():
                self._hold_taken(event, now_s, out)
            case act.Resumed():
                self._resumed(event, now_s, out)
            case act.LoiterLeft():
                self._loiter_left(event, now_s, out)
            case act.PlanningLead(lead_s=lead, loiter_lead_s=loiter_lead):
                self.lead_s = max(self.config.min_lead_s, lead)
                self.loiter_lead_s = max(
                    self.config.min_lead_s, lead if loiter_lead is None else loiter_lead
                )
        # A fix changes only its own vehicle's state, and so does a heartbeat that changed
        # nothing else (a lost vehicle may re-time the rest); anything else may change any.
        only = None
        if isinstance(event, act.Fix) or (isinstance(event, act.Heartbeat) and not out):
            only = event.vehicle_id
        self._states(out, now_s, only)
        for a in out:
            if isinstance(a, act.Upload):
                self.pending[a.vehicle_id] = a
        return out

    def _states(self, out: list[act.Action], now_s: float, only: str | None = None) -> None:
        """Say each vehicle's state (or vehicle ``only``'s) when it changes."""
        for m in self.members.values() if only is None else (self.members[only],):
            state = m.current_state(self.config.off_route_m)
            if state is not m.state:
                old, m.state = m.state, state
                out.append(
                    act.Report(
                        EventKind.STATE,
                        f"{old.value} -> {state.value}",
                        m.vehicle_id,
                        t_s=now_s,
                        payload={"state": state.value, "was": old.value},
                    )
                )

    def _deadline(self) -> tuple[float, str]:
        """When the loop gives up (mission s), and why: the overrun past the latest target, or
        the hard deadline, whichever is first."""
        overrun = max(m.target_s for m in self.members.values()) + self.config.overrun_s
        if overrun <= self.hard_deadline_s:
            return overrun, f"mission overran its last target by {self.config.overrun_s:g} s"
        return self.hard_deadline_s, (
            f"hard deadline {self.hard_deadline_s:.1f} s passed (the planned arrival plus "
            f"{self.config.hard_deadline_s:g} s)"
        )

    def _tick(self, now: float, out: list[act.Action]) -> None:
        if self.finished:
            return
        deadline, why = self._deadline()
        if now > deadline:
            late = ", ".join(m.vehicle_id for m in self.members.values() if not m.done)
            self.stopped = f"{why}: {late} not arrived"
            out.append(act.Report(EventKind.ABORT, f"{self.stopped}; stopping the loop", t_s=now))
            out.append(act.Stop(self.stopped))
            return
        if now >= self.next_takeoff_check_s and isinstance(self.scenario.arrival, Windows):
            # Windows: no team time moves, which re-times the takeoffs for the others.
            self.next_takeoff_check_s = now + TAKEOFF_RECHECK_S
            if self._measured_wind() is not None:
                for m in self.members.values():
                    if m.phase == "ground" and not m.arm_sent and not m.schedule.airborne_start:
                        self._retime_takeoff(m, now, out)
        for m in self.members.values():
            arm_due = now >= m.takeoff_s - self.config.arm_lead_s
            if m.phase == "ground" and arm_due and not (m.schedule.airborne_start or m.arm_sent):
                m.arm_sent = True
                out.append(act.Arm(m.vehicle_id))
            if m.phase == "ground" and now >= m.takeoff_s:
                m.phase = "takeoff"
                out.append(act.Launch(m.vehicle_id, m.schedule.airborne_start))
        self._watch_landings(now, out)
        if self.stopped is not None:
            return
        for zone in self._due_popups(now):
            self.popups_done.add(zone.id)
            self.threats_appeared.append({"id": zone.id, "t_s": now})
            self._guard_zone(zone)
            self._popup(zone, now, self._popup_lead_s(zone, now), out)
        self._guard_tick(now, out)

    def _launched(self, r: act.Launched, now: float, out: list[act.Action]) -> None:
        m = self.members[r.vehicle_id]
        if r.error is not None:
            if m.phase == "takeoff":
                m.phase = "ground"  # launched again at the next tick
            out.append(
                act.Report(
                    EventKind.LAUNCH,
                    f"launch failed: {r.error}; retrying",
                    m.vehicle_id,
                    payload={"ok": False},
                )
            )
            return
        m.launched_s = now
        what = (
            f"AUTO at {now:.1f} s (taken over in the air)"
            if m.schedule.airborne_start
            else f"armed and AUTO at {now:.1f} s (scheduled takeoff {m.takeoff_s:.1f} s)"
        )
        out.append(
            act.Report(
                EventKind.LAUNCH,
                what,
                m.vehicle_id,
                payload={"ok": True},
            )
        )

    # -- fixes ----------------------------------------------------------------------------------

    def _fix(self, fix: act.Fix, out: list[act.Action]) -> None:
        m = self.members.get(fix.vehicle_id)
        if m is None or self.start_utc_s is None or m.phase == "lost":
            return
        t = self._t(fix.utc_s)
        if m.last_fix_s is not None and t <= m.last_fix_s:
            return
        dt_s = 0.0 if m.last_fix_s is None else t - m.last_fix_s
        if m.last_fix_s is not None and dt_s > self.config.resettle_gap_s:
            m.heard_since_s = t  # heard again after a gap (a link gap, a restart)
        m.last_fix_s = t
        e, n = self.frame.to_local(fix.lat_deg, fix.lon_deg)
        e, n = float(e), float(n)
        m.east_m, m.north_m, m.alt_amsl_m = e, n, fix.alt_amsl_m
        m.climb_m_s = (
            fix.climb_m_s if fix.climb_m_s is not None and math.isfinite(fix.climb_m_s) else 0.0
        )
        if m.over:
            # Past its slot (circling where its mission ends) or aborted (flying home): no
            # longer timed, but still in the air, so its fixes still count for the separation
            # (an alarm when a pair comes under it).
            self._watch_separation(m, t, fix, out)
            return
        m.airspeed_m_s, m.heading_deg = fix.airspeed_m_s, fix.heading_deg
        m.groundspeed_m_s = fix.groundspeed_m_s or 0.0
        if not m.track_log or fix.utc_s - m.track_log[-1][0] >= 2.0:
            m.track_log.append(
                [
                    round(fix.utc_s, 3),
                    round(e, 1),
                    round(n, 1),
                    round(fix.alt_amsl_m or 0.0, 1),
                    round(fix.airspeed_m_s or 0.0, 2),
                    round(fix.groundspeed_m_s or 0.0, 2),
                ]
            )
        self._watch_separation(m, t, fix, out)
        if m.landing_due:
            return  # past its slot fix: watched until it is down, no longer timed
        seq = fix.mission_seq
        if m.phase == "takeoff":
            if m.launched_s is not None and seq is not None and seq >= m.mission.first_route_seq:
                m.phase = "route"
                out.append(
                    act.Report(
                        EventKind.ROUTE, f"climb-out done at {t:.1f} s, on the route", m.vehicle_id
                    )
                )
            else:
                if self.guarded and m.launched_s is not None:
                    # Climbing out, not yet timed, but watched for a zone across its route as
                    # one on it is: a box that appeared while a vehicle climbed (its re-plan
                    # had no waypoint far enough ahead) was flown into, 248 m deep.
                    self._guard(m, t, m.track.locate(e, n)[0], out)
                return
        if m.phase != "route":
            return
        seq_changed = seq != m.last_seq
        item_speed = False
        if seq_changed and seq is not None:
            item_speed = self._passed_items(m, m.last_seq, seq)
            m.last_seq = seq
            if m.in_loiter():
                m.loiter_entered_s, m.loiter_flown_m = self._loiter_entry(m, t, dt_s, fix)
        elif m.in_loiter():
            m.loiter_flown_m += (fix.groundspeed_m_s or 0.0) * dt_s
        self._watch_goal(m, fix, e, n, out)
        if m.phase != "route":
            return
        s, m.cross_track_m = m.track.locate(e, n, m.s_m)
        m.s_m = s
        self._learn_bias(m, t, fix)
        if m.cross_track_m <= self.config.off_route_m:
            m.joining = False
            m.joined = True
        self._watch_progress(m, t, s, out)
        if m.phase != "route":
            return
        if self.guarded:
            self._guard(m, t, s, out)
        if m.hold_zone is not None:
            return  # holding short of a zone: timed again once it resumes
        if m.busy_mission:
            return
        self._resolve_conflicts(m, t, out)
        if m.resolving is not None:
            return  # flying a resolution: timed for its slot again once released
        if m.in_loiter():
            if t >= m.next_decision_s:
                self._decide_in_loiter(m, t, fix, out)
            return
        if not seq_changed and t < m.next_decision_s:
            return
        if m.on_final(self.config.final_m):
            if item_speed:
                self._keep_commanded_speed(m, t, out)
            return
        self._decide(m, t, s, fix, out)

    # -- supervision ----------------------------------------------------------------------------

    def _watch_separation(self, m: Member, t: float, fix: act.Fix, out: list[act.Action]) -> None:
        """An alarm when the vehicle comes closer than the separation to another one flying
        (once per encounter, and again each time it comes a step closer), and a conflict
        event when their straight flight is predicted to bring them that close within the
        look-ahead (:class:`SeparationWatch`)."""
        if m.launched_s is None or m.east_m is None or m.north_m is None or fix.alt_amsl_m is None:
            return
        watch = self.separation
        pos = Position(t, m.east_m, m.north_m, fix.alt_amsl_m, fix.ve_m_s or 0.0, fix.vn_m_s or 0.0)
        # Every vehicle in the air counts, those past their slots or aborted too (they are
        # predicted for no one: they fly no route that is timed).
        flying = [
            x.vehicle_id
            for x in self.members.values()
            if x.launched_s is not None and x.phase != "lost"
        ]
        shortfalls = watch.update(m.vehicle_id, pos, flying)
        ahead = {
            vid: min(self.config.conflict_horizon_s, max(x.target_s - t, 0.0) + self._runout_s(x))
            for vid in flying
            if not (x := self.members[vid]).over and not x.in_loiter() and x.hold_zone is None
        }
        for c in watch.predict(m.vehicle_id, ahead):
            out.append(
                act.Report(
                    EventKind.CONFLICT,
                    f"predicted {c.distance_m:.0f} m from {c.other} at {c.at_s:.1f} s (in "
                    f"{c.at_s - t:.0f} s at their present velocities), below "
                    f"{watch.separation_m:g} m",
                    m.vehicle_id,
                    value=round(c.distance_m, 1),
                    t_s=t,
                    payload={
                        "other": c.other,
                        "distance_m": round(c.distance_m, 1),
                        "at_s": round(c.at_s, 1),
                    },
                )
            )
        for sf in shortfalls:
            closer = "" if sf.previous_m is None else f" (down from {sf.previous_m:.0f} m)"
            out.append(
                act.Report(
                    EventKind.ALARM,
                    f"separation {sf.distance_m:.0f} m from {sf.other} at {t:.1f} s, below "
                    f"{watch.separation_m:g} m{closer}",
                    m.vehicle_id,
                    value=round(sf.distance_m, 1),
                    t_s=t,
                    payload={"other": sf.other, "distance_m": round(sf.distance_m, 1)},
                )
            )

    def _runout_s(self, m: Member) -> float:
        """How long the vehicle flies on past its goal before its hold (its mission's run-out,
        straight on: none with a landing), at its ground speed: two run into adjacent goals
        from either side, head-on, come closest there, after their slots."""
        if self.scenario.landing is not None:
            return 0.0
        return self.config.runout_m / max(m.groundspeed_m_s or m.level_m_s or 1.0, 1.0)

    def _ahead(
        self, m: Member, *, strengthening: bool = False, released_s: float | None = None
    ) -> Ahead | None:
        """The member's flight ahead for resolving conflicts, if it is predictable: on its
        route, joined, timed (not holding or being re-planned), with a fresh fix, its loiter
        turns still to fly on the way (:meth:`RouteTrack.flight_samples`); movable unless in
        its turns, on its final approach or flying a resolution (but for ``strengthening``
        the one it flies). Flying a speed resolution, it flies for its slot once released:
        at ``released_s`` when given, else at the resolution's end, or, held on past it, as
        late as its slot allows."""
        if (
            m.phase != "route"
            or m.over
            or m.landing_due
            or not m.joined
            or m.s_m is None
            or m.last_fix_s is None
            or m.level_m_s is None
            or m.alt_amsl_m is None
            or m.hold_zone is not None
            or m.busy_mission
        ):
            return None
        track = m.track
        done = m.loiters_done()
        along_m, east_m, north_m = track.flight_samples(done)
        turning = m.in_loiter() and done < len(track.loiters)
        at_m = here_m = m.s_m  # along its flight, and along its route (for its height)
        if turning:
            lo = track.loiters[done]
            at_m = lo.s_m + min(m.loiter_flown_m, lo.length_m)
            here_m = lo.s_m
        climbing = self.vertical.flying.get(m.vehicle_id)
        # Its profile's changes of height ahead (a re-plan's lift among them), and, if it is
        # climbing or sinking back to it (from a height resolution), its way back at that
        # rate; flying one, it holds the height it was asked until the resolution's end, and
        # is back on its profile after it at the fastest rate it is asked.
        vs = m.schedule
        profile_m = vs.alt_at(here_m)
        rise_m = np.interp(track.flight_route_s_m(done), vs.wp_s_m, vs.wp_alt_m)
        rise_m -= profile_m
        hold_until_s = None
        if climbing is not None:
            off_m = climbing.resolution.alt_m - profile_m
            closing_m_s = self.config.vertical_rate_max_m_s
            hold_until_s = max(climbing.resolution.until_s, m.last_fix_s)
        else:
            off_m = m.alt_amsl_m - profile_m
            # How fast it closes on its profile: its climb less the profile's own there.
            step_m = PROFILE_SLOPE_STEP_M
            slope = (vs.alt_at(here_m + step_m) - vs.alt_at(here_m - step_m)) / (2.0 * step_m)
            closing_m_s = -math.copysign(1.0, off_m) * (m.climb_m_s - slope * m.groundspeed_m_s)
            if closing_m_s < RETURNING_M_S:
                off_m = 0.0  # level off it, or not closing on it: kept off it as it is
        flies_m_s = m.level_m_s if m.resolving is None else m.resolving.airspeed_m_s
        gs_m_s = m.groundspeed_m_s
        if m.airspeed_m_s is not None and abs(flies_m_s - m.airspeed_m_s) >= SPEED_CHANGING_M_S:
            # Not yet at the airspeed it was asked (a resolution's, just commanded): forecast
            # at the ground speed that airspeed makes good, not at the one its fix measured on
            # the way to it (sped from 22.8 to 30 m/s, one was forecast a second later at its
            # old ground speed 270 m from the other, and said unresolved: flown, 660 m).
            gs_m_s += (flies_m_s - m.airspeed_m_s) * m.tas_per_eas(m.s_m)
        ahead = Ahead(
            m.vehicle_id,
            m.last_fix_s,
            at_m,
            gs_m_s,
            flies_m_s,
            m.tas_per_eas(m.s_m),
            m.limits.airspeed_min_m_s,
            m.limits.airspeed_max_m_s,
            # Flying a height resolution: where it is going (what the others must keep clear).
            m.alt_amsl_m if climbing is None else climbing.resolution.alt_m,
            along_m,
            east_m,
            north_m,
            horizon_s=max(m.target_s - m.last_fix_s, 0.0),
            movable=not turning
            and not m.on_final(self.config.final_m)
            and (strengthening or self._resolving_from(m) is None),
            # (a fix without a ground speed: its airspeed)
            final_s=self.config.final_m / max(m.groundspeed_m_s or m.level_m_s, 1.0),
            route_rise_m=rise_m,
            off_profile_m=off_m,
            return_rate_m_s=min(closing_m_s, self.config.vertical_rate_max_m_s),
            hold_until_s=hold_until_s,
            wind=m.schedule.wind if m.wind is None else m.wind,
        )
        r = m.resolving
        if r is None:
            return ahead
        if released_s is not None:
            return self._released(ahead, released_s)
        # Released, it flies for its slot again: at its end, or held on past it as late as its
        # slot allows if, released then, it would come near the other again (:meth:`_past`;
        # forecast released at the end, one held on 76 s past it was flown into).
        at_end = self._released(ahead, max(r.until_s, m.last_fix_s))
        if (
            self._apart_m(at_end, r.other, at_end.until_s)
            >= RESOLVED_MARGIN * self.scenario.separation_m
        ):
            return at_end
        return self._released(ahead, r.hold_end_s)

    @staticmethod
    def _released(ahead: Ahead, at_s: float) -> Ahead:
        """``ahead`` flying its resolution until ``at_s``, then for its slot."""
        return replace(ahead, until_s=at_s, resume_m_s=ahead.slot_airspeed_m_s(at_s))

    def _resolve_conflicts(self, m: Member, t: float, out: list[act.Action]) -> None:
        """Keep a resolution flown until it is over; every ``resolve_period_s``, forecast
        the vehicle along its route for the others (flying a resolution too: it is one of
        their pairs, not to be moved), and if it flies none, predict its pairs and resolve
        the first that comes under the separation (:func:`gcs.coordination.resolution.
        resolve`, or by height)."""
        cfg = self.config
        r = m.resolving
        released = False
        if r is not None:
            if t >= r.until_s and (self._past(m, t, r.other) or t >= r.hold_end_s):
                m.resolving = None
                m.next_decision_s = -math.inf
                released = True
                out.append(
                    act.Report(
                        EventKind.CONFLICT,
                        f"past {r.other}: timed for its slot again",
                        m.vehicle_id,
                        t_s=t,
                        payload={"other": r.other, "resolution": "released"},
                    )
                )
            else:
                self._fly_resolution(m, t, out)
        if m.vehicle_id in self.vertical:
            self.vertical.fly(m, t, functools.partial(self._manoeuvre_over, m, t), out)
        busy = self._resolving_from(m) is not None
        if released:
            # Screened again at its next fix, once it is timed for its slot: screened now, it
            # is forecast at its resolution's speed (one was said to meet another it was
            # slowing away from).
            m.next_resolve_s = -math.inf
            return
        if cfg.resolve_horizon_s <= 0.0 or t < m.next_resolve_s:
            return
        m.next_resolve_s = t + cfg.resolve_period_s
        forecasts = self.forecasts
        horizon_s = self._screen_horizon_s()
        if (forecasts.look_ahead_s, forecasts.response_s) != (horizon_s, cfg.resolve_response_s):
            forecasts = self.forecasts = Forecasts(
                list(self.members), horizon_s, cfg.resolve_response_s
            )
        mine = self._ahead(m)
        if mine is None:
            forecasts.drop(m.vehicle_id)
            return
        forecasts.update(mine, t)
        if busy:
            self._strengthen(m, t, out)
            self._screen_busy(m, t, out)
            return
        # Screened and resolved with the margin a forecast minutes ahead needs (a pair
        # forecast 5-10 % over the separation came under it as flown).
        d_s = RESOLVED_MARGIN * self.scenario.separation_m
        near = forecasts.near(m.vehicle_id, d_s, t)
        self.unresolved -= {p for p in self.unresolved if m.vehicle_id in p} - {
            frozenset((m.vehicle_id, other)) for other in near
        }
        for other in near:
            x = self.members[other]
            if x.over or self._resolving_from(x) == m.vehicle_id:
                continue  # over, or resolving this very pair already
            theirs = forecasts.ahead[other]
            pair = (m.vehicle_id, other)
            # The vehicles a speed change could bring either of the pair near.
            neighbours = _neighbours(forecasts, pair, NEIGHBOUR_SEPARATIONS * d_s, t)
            res = resolve(
                mine, theirs, now_s=t, separation_m=d_s, look_ahead_s=cfg.resolve_horizon_s,
                response_s=cfg.resolve_response_s, neighbours=neighbours,
            )  # fmt: skip
            waits = False  # for a speed that keeps them apart, flown once within its horizon
            if not self._keeps(res) and cfg.vertical_horizon_s > 0.0:
                # Would a speed keep them apart over the longer horizon? Then it is flown once
                # they are within the speed's; else one of them changes height now.
                later = resolve(
                    mine, theirs, now_s=t, separation_m=d_s,
                    look_ahead_s=cfg.vertical_horizon_s, response_s=cfg.resolve_response_s,
                    neighbours=neighbours,
                ) if res is None else res  # fmt: skip
                up = None
                waits = res is None and self._keeps(later)
                if not waits:
                    up = self._resolve_vertically(mine, theirs, t)
                if up is not None:
                    self._fly_height(up, t, out)
                    return
            if res is None:
                if not waits:
                    self._say_unresolved(mine, theirs, t, out)
                continue
            self.unresolved.discard(frozenset(pair))
            mover = self.members[res.vehicle]
            mover.resolving = res
            out.append(
                act.Report(
                    EventKind.CONFLICT,
                    _resolving(res),
                    res.vehicle,
                    value=round(res.predicted_m, 1),
                    t_s=t,
                    payload={
                        "other": res.other,
                        "resolution": "speed",
                        "airspeed_m_s": res.airspeed_m_s,
                        "until_s": round(res.until_s, 1),
                        "distance_m": round(res.unresolved_m, 1),
                        "resolved_m": round(res.predicted_m, 1),
                        "keeps_separation": res.keeps_separation,
                        "at_s": round(res.at_s, 1),
                    },
                )
            )
            self._fly_resolution(mover, t, out)
            self._forecast_again(mover, t)
            return

    def _screen_busy(self, m: Member, t: float, out: list[act.Action]) -> None:
        """``m`` flies a resolution: the pairs no one else screens are screened here, those
        with the others that fly one too, of another pair (neither screens the other: two
        resolved from a third each, at their top speeds, closed to 83 m unseen), and its
        own pair if it flies a speed resolution from it (one resolved at its top speed
        from another that was held on at its own, past the release it was forecast, came
        101 m apart). One forecast under the separation is resolved by height (a speed
        resolution is flown on at the height asked; one flying a height resolution moves
        on in its sense, held as long as it was to be), else said."""
        d_s = RESOLVED_MARGIN * self.scenario.separation_m
        for other in self.forecasts.near(m.vehicle_id, d_s, t):
            x = self.members[other]
            theirs_from = self._resolving_from(x)
            if x.over or theirs_from == m.vehicle_id:
                continue  # over, or it resolves from this one: screened at its fixes
            if theirs_from is None and self._resolving_from(m) != other:
                continue  # it screens the pair itself
            if m.resolving is None and self._resolving_from(m) == other:
                continue  # a height resolution from it: strengthened (_strengthen)
            pair = (m.vehicle_id, other)
            mine, theirs = (self._ahead(v, strengthening=True) for v in (m, x))
            if mine is None or theirs is None:
                continue
            up = self._resolve_vertically(mine, theirs, t)
            if up is None:
                self._say_unresolved(mine, theirs, t, out)
                continue
            self.unresolved.discard(frozenset(pair))
            self._fly_height(up, t, out)
            return

    def _say_unresolved(self, a: Ahead, b: Ahead, t: float, out: list[act.Action]) -> None:
        """A pair forecast under the separation that no speed or height parts: said (a
        conflict event and an alarm), once (one such was left in silence for 40 s, until it
        came under the separation)."""
        pair = frozenset((a.vehicle, b.vehicle))
        if pair in self.unresolved:
            return
        self.unresolved.add(pair)
        cfg = self.config
        # Over twice the screen's horizon, as resolutions are judged: where they meet.
        times = np.arange(t, t + 2.0 * self._screen_horizon_s() + 1.0)
        d, when = closest_m(a, b, times, a.airspeed_m_s, b.airspeed_m_s, cfg.resolve_response_s)
        text = (
            f"{a.vehicle} and {b.vehicle} forecast {d:.0f} m apart at {when:.1f} s "
            f"(d_s {self.scenario.separation_m:g} m): no speed or height of either keeps them "
            "apart"
        )
        payload = {
            "pair": [a.vehicle, b.vehicle],
            "resolution": "none",
            "distance_m": round(d, 1),
            "at_s": round(when, 1),
        }
        for kind in (EventKind.CONFLICT, EventKind.ALARM):
            out.append(act.Report(kind, text, a.vehicle, t_s=t, payload=payload))

    def _strengthen(self, m: Member, t: float, out: list[act.Action]) -> None:
        """``m`` flies a height resolution, and the pair is forecast to come under the
        separation all the same (a forecast minutes ahead knows nothing of the speeds the
        slots will ask on the way: a pair resolved to pass 343 m apart came 282 m apart):
        a layer more, for it or for the other if that one flies no resolution of its own
        (TCAS's strengthened advisory)."""
        man = self.vertical.flying.get(m.vehicle_id)
        if man is None or self.config.vertical_horizon_s <= 0.0:
            return
        other = man.resolution.other
        x = self.members.get(other)
        theirs = self.forecasts.ahead.get(other)
        if x is None or x.over or theirs is None:
            return
        if other not in self.forecasts.near(m.vehicle_id, self.scenario.separation_m, t):
            return
        mine = self._ahead(m, strengthening=True)
        if mine is None:
            return
        # Its height is held until it is past the other (:meth:`VerticalFlight.fly`), not
        # only until the resolution's end.
        mine = replace(mine, hold_until_s=math.inf)
        up = self._resolve_vertically(mine, theirs, t)
        if up is None or (up.vehicle == other and self._resolving_from(x) is not None):
            return
        self._fly_height(up, t, out)

    def _fly_height(self, up: VerticalResolution, t: float, out: list[act.Action]) -> None:
        """Its mover flies the height resolution ``up`` from now, forecast so for the others."""
        mover = self.members[up.vehicle]
        self.vertical.start(mover, up, t, out)
        self._forecast_again(mover, t)

    def _keeps(self, res: Resolution | None) -> bool:
        """Whether a speed resolution keeps the pair apart with :data:`RESOLVED_MARGIN` to
        spare (one held short by its mover's slot, predicted to pass at the separation
        itself, came 130 m under it as flown)."""
        return (
            res is not None
            and res.keeps_separation
            and res.predicted_m >= RESOLVED_MARGIN * self.scenario.separation_m
        )

    def _manoeuvre_over(self, m: Member, t: float, res: VerticalResolution) -> str | None:
        """Why ``m``'s height resolution, its end come, is over (None: held on): the pair is
        past each other (and ``m`` past those it took a height for before), or the height it
        holds has no room over the ground it flies next (checked over the minute ahead: the
        manoeuvre's own room was checked only as far as it was foreseen to last)."""
        man = self.vertical.flying.get(m.vehicle_id)
        also = () if man is None else man.also
        if all(self._past(m, t, o) for o in (res.other, *also)):
            return "past"
        if self.world is None:
            return None
        room = room_ahead(
            m, self.scenario.vehicle(m.vehicle_id), self.world.terrain, t, t + HOLD_ROOM_S
        )
        if room is not None and not room.floor_m <= res.alt_m <= room.ceiling_m:
            return (
                f"{res.alt_m:.0f} m AMSL is outside its room over the ground ahead "
                f"({room.floor_m:.0f}-{room.ceiling_m:.0f} m)"
            )
        return None

    def _past(self, m: Member, t: float, other: str) -> bool:
        """``m`` is past ``other`` as they fly now (the separation watch's latest positions and
        velocities): apart horizontally by :data:`RESOLVED_MARGIN` separations and not
        closing, nor forecast along their routes to come that near over the ground within
        the forecasts' look-ahead (a pair released as apart and not closing came 270 m
        apart 50 s later, its mover back at its profile's height); or ``other`` no longer
        flying its mission (arrived, lost, aborted) or never heard."""
        x = self.members.get(other)
        if x is None or x.over:
            return True
        pos = self.separation.positions
        a, b = pos.get(m.vehicle_id), pos.get(other)
        if a is None or b is None:
            return True
        ae, an, _ = a.at(t)
        be, bn, _ = b.at(t)
        de, dn = be - ae, bn - an
        closing = de * (b.ve_m_s - a.ve_m_s) + dn * (b.vn_m_s - a.vn_m_s) < 0.0
        d_s = RESOLVED_MARGIN * self.scenario.separation_m
        if closing or math.hypot(de, dn) < d_s:
            return False
        return self._forecast_apart_m(m, t, other) >= d_s

    def _forecast_apart_m(self, m: Member, t: float, other: str) -> float:
        """How near ``m``, released from its resolution now (flying for its slot), and
        ``other`` as forecast come over the ground within the forecasts' look-ahead, m (inf
        when either is not forecast: off its route, or its forecast stale)."""
        mine = self._ahead(m, released_s=t)
        return math.inf if mine is None else self._apart_m(mine, other, t)

    def _apart_m(self, mine: Ahead, other: str, t: float) -> float:
        """How near ``mine`` and ``other`` as forecast come over the ground from ``t`` on,
        within the forecasts' look-ahead, m (inf when ``other`` is not forecast, or its
        forecast is stale)."""
        forecasts = self.forecasts
        theirs = forecasts.ahead.get(other)
        if theirs is None or t - theirs.t_s > forecasts.stale_s + max(t - mine.t_s, 0.0):
            return math.inf
        times = math.ceil(t) + np.arange(forecasts.steps, dtype=np.float64)
        response = forecasts.response_s
        pa = mine.positions(times, mine.airspeed_m_s, response)
        pb = theirs.positions(times, theirs.airspeed_m_s, response)
        apart = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
        return float(np.nanmin(apart)) if not np.isnan(apart).all() else math.inf

    def _resolving_from(self, m: Member) -> str | None:
        """The vehicle ``m`` flies a resolution (speed or height) to keep apart from."""
        if m.resolving is not None:
            return m.resolving.other
        climbing = self.vertical.flying.get(m.vehicle_id)
        return None if climbing is None else climbing.resolution.other

    def _forecast_again(self, m: Member, t: float) -> None:
        """``m`` has just been given a resolution: its forecast for the others is its flight
        as resolved (not movable), from now."""
        ahead = self._ahead(m)
        if ahead is not None:
            self.forecasts.update(ahead, t)

    def _resolve_vertically(self, a: Ahead, b: Ahead, t: float) -> VerticalResolution | None:
        """What no speed resolves, by height (:func:`gcs.coordination.vertical.
        resolve_vertical`): each of the pair within its room over the look-ahead, climbing or
        descending no steeper than the slower of the two may, and not into its neighbours
        (those a change of height could bring either near: near over the ground, whatever
        their heights; one 450 m above was 21 m once climbed to)."""
        cfg = self.config
        if self.world is None:
            return None
        d_s = self.scenario.separation_m
        neighbours = _neighbours(
            self.forecasts,
            (a.vehicle, b.vehicle),
            NEIGHBOUR_SEPARATIONS * (RESOLVED_MARGIN * d_s),
            t,
            heights=False,
        )
        layer_m = cfg.vertical_layer_m or layer_step_m(self.scenario)
        # One off its height already (for this pair or a third) moves on in its sense, as
        # long at least as it was to hold it (two resolved from a third each onto heights
        # 70 m apart came 233 m apart, neither moved again).
        held = {
            vid: Held(math.copysign(1.0, man.resolution.offset_m), man.resolution.until_s)
            for vid in (a.vehicle, b.vehicle)
            if (man := self.vertical.flying.get(vid)) is not None
        }
        rooms: dict[str, Room] = {}
        rates: list[float] = []
        for ahead in (a, b):
            v = self.scenario.vehicle(ahead.vehicle)
            room = room_ahead(  # over all the manoeuvre may last (judged over twice it)
                self.members[ahead.vehicle],
                v,
                self.world.terrain,
                t,
                t + 2.0 * cfg.vertical_horizon_s,
            )
            if room is not None:
                rooms[ahead.vehicle] = room
            rates.append(v.climb_gradient * ahead.airspeed_m_s)
        return resolve_vertical(
            a, b, now_s=t, separation_m=RESOLVED_MARGIN * d_s, layer_m=layer_m,
            rate_m_s=min(rates), room=rooms,
            look_ahead_s=cfg.vertical_horizon_s, response_s=cfg.resolve_response_s,
            neighbours=neighbours, fast_rate_m_s=cfg.vertical_rate_max_m_s,
            held=held or None,
        )  # fmt: skip

    def _screen_horizon_s(self) -> float:
        """How far ahead pairs are forecast for resolution: the speed's horizon, or the
        height's when longer (none when nothing is resolved)."""
        cfg = self.config
        if cfg.resolve_horizon_s <= 0.0:
            return cfg.resolve_horizon_s
        return max(cfg.resolve_horizon_s, cfg.vertical_horizon_s)

    @staticmethod
    def _fly_resolution(m: Member, t: float, out: list[act.Action]) -> None:
        """Command the speed of the resolution the member flies, unless it flies it already or
        a command is on its way (then at a later fix)."""
        r = m.resolving
        if r is not None and m.level_m_s != r.airspeed_m_s and not m.busy_command:
            m.busy_command = True
            out.append(act.CommandSpeed(m.vehicle_id, r.airspeed_m_s, _resolving(r), t))

    def _watch_progress(self, m: Member, t: float, s: float, out: list[act.Action]) -> None:
        """Lose a vehicle that stops (moves less than ``stopped_m`` in ``stopped_bound_s``), or
        whose progress along its route stalls (or goes backwards) for longer than
        ``stall_bound_s``: watched once it has joined its route, not in a loiter, nor while a
        mission upload to it is unanswered."""
        if m.rejoin_seq is not None and (m.last_seq or 0) > m.rejoin_seq:
            m.rejoin_seq = None
        cfg = self.config
        e, n, still = m.east_m or 0.0, m.north_m or 0.0, m.still
        moved_m = math.inf if still is None else math.hypot(e - still[0], n - still[1])
        if still is None or moved_m > cfg.stopped_m:
            m.still, still = (e, n, t, 0), None
        else:
            m.still = still = (still[0], still[1], still[2], still[3] + 1)
        # Standing still on fixes all along the bound (one late fix after a gap says nothing).
        if still is not None and t - still[2] > cfg.stopped_bound_s and still[3] >= STOPPED_FIXES:
            self._lose(
                m,
                "stall",
                f"stopped: moved {moved_m:.0f} m in {t - still[2]:.1f} s (at {s:.0f} m of "
                f"{m.track.length_m:.0f} m)",
                t,
                out,
            )
            return
        ref = m.progress
        if (
            ref is None
            or ref[0] is not m.track
            or s > ref[1] + PROGRESS_M
            or not m.joined
            or m.in_loiter()
            or m.hold_zone is not None
            or m.rejoin_seq is not None
            # An upload not yet answered: the vehicle may fly the new mission already (its
            # loiter turns, say) while its progress is measured on the old one's track.
            or m.vehicle_id in self.pending
        ):
            m.progress = (m.track, s, t)
            return
        stalled = t - ref[2]
        if stalled > self.config.stall_bound_s:
            self._lose(
                m,
                "stall",
                f"no progress along its route for {stalled:.1f} s (at {s:.0f} m of "
                f"{m.track.length_m:.0f} m, farthest {ref[1]:.0f} m at {ref[2]:.1f} s)",
                t,
                out,
            )

    def _heartbeat(self, hb: act.Heartbeat, now: float, out: list[act.Action]) -> None:
        """In the air, MAV_STATE_EMERGENCY is a crash (ArduPlane says it once it has detected
        one); on its route, disarmed is one too (its climb-out ended armed and in AUTO, so
        an old heartbeat from before the launch cannot be taken for it)."""
        m = self.members.get(hb.vehicle_id)
        if m is not None and m.landing_due:
            self._landing_heartbeat(m, hb, now, out)
            return
        if m is None or m.phase not in ("takeoff", "route"):
            return
        if hb.emergency:
            self._lose(m, "crash", "HEARTBEAT system_status MAV_STATE_EMERGENCY", now, out)
        elif not hb.armed and m.phase == "route":
            self._lose(m, "crash", "disarmed on its route", now, out)

    def _alarm(self, alarm: act.Alarm, now: float, out: list[act.Action]) -> None:
        """Say what a vehicle says at MAV_SEVERITY_CRITICAL or worse; a crash loses it."""
        m = self.members.get(alarm.vehicle_id)
        if m is None:
            return
        out.append(
            act.Report(
                EventKind.ALARM,
                f"says {alarm.text!r} (MAV_SEVERITY {alarm.severity})",
                m.vehicle_id,
                t_s=now,
                payload={"severity": alarm.severity, "text": alarm.text},
            )
        )
        if (m.phase in ("takeoff", "route") or m.landing_due) and is_crash_text(alarm.text):
            m.landing_due = False
            self._lose(m, "crash", f"it says {alarm.text!r}", now, out)

    def _lose(
        self, m: Member, cause: LostCause, why: str, now: float, out: list[act.Action]
    ) -> None:
        """The vehicle leaves the team (it is neither commanded nor timed any more) and the
        rest do what ``on_vehicle_lost`` says."""
        m.phase = "lost"
        m.lost = Lost(cause, now, why)
        policy = self.config.on_vehicle_lost
        then = {
            "continue": "the others keep their slots",
            "retime": "the team is re-timed without it",
            "abort": "the team is aborted",
        }[policy]
        out.append(
            act.Report(
                EventKind.VEHICLE_LOST,
                f"lost at {now:.1f} s ({cause}: {why}); {then}",
                m.vehicle_id,
                t_s=now,
                payload={"cause": cause, "t_s": round(now, 3), "why": why, "policy": policy},
            )
        )
        if policy == "retime":
            self._retime_without(m, now, out)
        elif policy == "abort":
            out.extend(self.abort(None, "rtl", now)[1])

    def _passed_items(self, m: Member, old: int | None, new: int) -> bool:
        """DO_CHANGE_SPEED items the vehicle ran set the airspeed it flies (True: one did)."""
        lo = m.mission.first_route_seq if old is None else old
        ran = False
        for k in range(lo, min(new, len(m.mission.items))):
            it = m.mission.items[k]
            if it.command == MAV_CMD_DO_CHANGE_SPEED and it.param2 > 0:
                m.level_m_s = float(it.param2)
                m.next_decision_s = -math.inf
                ran = True
        return ran

    def _keep_commanded_speed(self, m: Member, t: float, out: list[act.Action]) -> None:
        """A DO_CHANGE_SPEED item run inside the final stretch, where no speed is decided: the
        airspeed last commanded is commanded again. The item carries the plan's speed for a
        short last leg (its final trim), which the closed loop has long since replaced."""
        if not m.commanded or m.busy_command:
            return
        level = float(m.commanded[-1][1])
        if level == m.level_m_s:
            return
        m.busy_command = True
        out.append(
            act.CommandSpeed(
                m.vehicle_id,
                level,
                f"its mission set {m.level_m_s:g} m/s inside the final {self.config.final_m:g} m: "
                f"back to the {level:g} m/s commanded",
                t,
            )
        )

    def _wind(self, m: Member, fix: act.Fix) -> Wind:
        """The wind to time with: the vehicle's estimate plus the error learnt in flight.

        A vehicle that reports its wind (WIND) is timed with its latest report; until its
        first one after a restart or a reconnection, with the one it last had (kept in the
        checkpoint). Worked out from a single fix instead (ground velocity less true airspeed
        on the heading), a crab angle or a stale airspeed there made a vehicle in a tailwind
        look a minute late and moved the team time on one fix. A vehicle that never reports
        its wind is timed with that working-out, and with the schedule's forecast until a fix
        allows it."""
        if fix.wind_speed_m_s is not None and fix.wind_from_deg is not None:
            m.wind_reported = True
            m.wind = m.bias.corrected(Wind.from_speed_from(fix.wind_speed_m_s, fix.wind_from_deg))
        elif not m.wind_reported:
            worked_out = reported_wind(fix)
            if worked_out is not None:
                m.wind = m.bias.corrected(worked_out)
        return m.schedule.wind if m.wind is None else m.wind

    def _learn_bias(self, m: Member, t: float, fix: act.Fix) -> None:
        """Feed one fix to the airspeed-scale and wind-error estimate: predicted from the
        airspeed the autopilot reports, only when it was reported at the moment of the fix
        (a stale one, or one taken while a new speed settles, would teach a bias that is not
        there)."""
        if (
            m.level_m_s is None
            or not fix.airspeed_fresh
            or fix.ve_m_s is None
            or fix.vn_m_s is None
            or fix.heading_deg is None
            or fix.alt_amsl_m is None
            or fix.airspeed_m_s is None
        ):
            return
        m.bias.update(
            t,
            ve_m_s=fix.ve_m_s,
            vn_m_s=fix.vn_m_s,
            heading_rad=math.radians(fix.heading_deg),
            predicted_tas_m_s=fix.airspeed_m_s * eas2tas(fix.alt_amsl_m),
            wind=reported_wind(fix) or m.schedule.wind,
            airspeed_m_s=fix.airspeed_m_s,
            commanded_m_s=m.level_m_s,
            climb_m_s=fix.climb_m_s or 0.0,
        )

    def _decide(self, m: Member, t: float, s: float, fix: act.Fix, out: list[act.Action]) -> None:
        inputs: dict[str, Any] = {
            "s_m": s,
            "now_s": t,
            "target_s": m.target_s,
            "wind": self._wind(m, fix),
            "current_level_m_s": m.level_m_s,
            "loiters_done": m.loiters_done(),
            "tas_per_eas": m.tas_per_eas(s),
        }
        d = m.controller.decide(m.track, **inputs)
        if d.verdict == "on_time":
            d = self._through_via(m, d, inputs)
        self._apply_decision(m, d, t, out)
        time_left = m.target_s - t
        cfg = self.config
        if d.verdict == "late" and m.cross_track_m > cfg.off_route_m:
            if not m.joining:
                m.joining = True
                out.append(
                    act.Report(
                        EventKind.ARRIVAL,
                        f"late by {d.eta_min_s - m.target_s:.1f} s at top speed, but "
                        f"{m.cross_track_m:.0f} m off the route and joining it: the team time "
                        "stays until it is on the route",
                        m.vehicle_id,
                        t_s=t,
                    )
                )
        elif d.verdict == "late":
            self._late(m, d, t, out)
        elif time_left > cfg.loiter_min_time_left_s and t - m.last_loiter_s > cfg.loiter_hold_off_s:
            # Early, or so little above the minimum speed that the last minutes would have no
            # room to slow down: loiter turns now, while a buffer is ahead (judged as if the
            # minimum were higher by the reserve; the turns leave the loiter margin above it).
            reserve = cfg.speed_reserve_m_s
            lo, hi = m.limits.airspeed_min_m_s, m.limits.airspeed_max_m_s
            if d.verdict != "early" and reserve > 0.0 and d.required_m_s < min(lo + reserve, hi):
                held = SpeedLimits(min(lo + reserve, hi), hi, m.limits.step_m_s)
                d = ArrivalController(held, tolerance_s=cfg.tolerance_s).decide(m.track, **inputs)
            if d.verdict == "early":
                m.last_loiter_s = t
                self._loiter(m, d, t, s, inputs["wind"], out)

    def _through_via(self, m: Member, d: Decision, inputs: dict[str, Any]) -> Decision:
        """``d`` (on time for its slot) flying the speed that passes the place its schedule
        times it through at that time (a re-plan's separation by timing: the speed for the
        slot alone flew the pair together again), while it has still to pass it, its slot is
        the one it was so timed for, and that speed makes it there; else ``d``."""
        via = m.via_live()
        if via is None or m.in_loiter() or inputs["s_m"] > via[0] - VIA_REACHED_M:
            return d
        via_s_m, via_t_s = via
        if m.via_track is None:
            m.via_track = route_track(m.schedule, via_s_m)
        v = m.controller.decide(m.via_track, **(inputs | {"target_s": via_t_s}))
        if v.verdict != "on_time":
            return d
        why = (
            f"to pass {via_s_m / 1000.0:.1f} km along its route at {via_t_s:.1f} s, as the "
            f"re-plan timed it: {v.reason}"
        )
        return replace(d, command_m_s=v.command_m_s, level_m_s=v.level_m_s, reason=why)

    def _decide_in_loiter(self, m: Member, t: float, fix: act.Fix, out: list[act.Action]) -> None:
        """In loiter turns: the rest of the turns (those flown counted from the ground
        distance since it entered them) and the route after, timed as anywhere else; its
        airspeed is trimmed (ArduPlane flies the turns at the commanded airspeed).

        One that the rest of its turns would make late even at top speed is taken out of them
        (:meth:`_leave_loiter`) once leaving would not make it early at its minimum speed
        (until then it flies the turns at the speed the route after them asks for); one late
        even leaving now moves the team time now, for the route without the turns, while the
        others can still follow (for the turns left, when leaving would gain nothing).

        One that has flown all of its loiter by the count yet still circles (it lines up with
        the route later than its entry let the count foresee: one that came to its turns from
        a hold, off its route) is timed by the way out, and taken out of them unless that
        makes it early: the way out at the roll limit is never longer than the way round the
        circle to the same waypoint."""
        if m.leaving_seq is not None:
            return  # being taken out of the turns: timed again once it is
        k = m.loiters_done()
        if k >= len(m.track.loiters):
            return
        lo = m.track.loiters[k]
        wind = self._wind(m, fix)
        d = m.controller.decide(
            m.track,
            s_m=lo.s_m,
            now_s=t,
            target_s=m.target_s,
            wind=wind,
            current_level_m_s=m.level_m_s,
            loiters_done=k,
            loiter_flown_m=min(m.loiter_flown_m, lo.length_m),
            tas_per_eas=m.tas_per_eas(lo.s_m),
        )
        top_m_s = m.limits.airspeed_max_m_s - self.config.speed_reserve_m_s
        # Its turns flown by the count, it circles on only to line up with the route: the
        # timing with no turns left (from the waypoint after them) does not count that way
        # round, the way out does (a spaced team's UAV3, timed so for 20 s, left 16 s later
        # than that timing had it and arrived 1.04 s off its slot).
        circling_on = m.loiter_flown_m >= lo.length_m
        if not circling_on and d.verdict != "late" and d.required_m_s <= top_m_s:
            self._apply_decision(m, d, t, out)
            return
        # Late, or the rest of the turns would need it within the speed reserve of its top
        # speed (no room left for what the way out of them costs). Out of the turns now, it
        # flies from where it is to the waypoint after them (turning at its roll limit from
        # the course it has on the circle, then straight), and the route on from there:
        # timed as from that far back along the route from the waypoint (else from its
        # position located on the route).
        s = lo.s_m if m.s_m is None else m.s_m
        way_out = self._way_out(m, fix)
        left = m.controller.decide(
            m.track,
            s_m=s if way_out is None else max(0.0, way_out),
            now_s=t,
            target_s=m.target_s,
            wind=wind,
            current_level_m_s=m.level_m_s,
            loiters_done=k + 1,
            tas_per_eas=m.tas_per_eas(s),
        )
        if left.eta_min_s >= d.eta_min_s and not circling_on:
            # Nothing to gain by leaving (its turns are as good as flown): late as anywhere.
            self._apply_decision(m, d, t, out)
            if d.verdict == "late":
                self._late(m, d, t, out)
            return
        self._apply_decision(m, left, t, out)
        if left.verdict != "early":
            self._leave_loiter(m, d, left, t, out)
        if left.verdict == "late":
            self._late(m, left, t, out)

    def _way_out(self, m: Member, fix: act.Fix) -> float | None:
        """Where along its route a vehicle taken out of its turns now is, counted back from
        the waypoint after them by the way there (:func:`planner.loiterflight.way_out_m`);
        None when that is not known (no course, or no waypoint after the turns)."""
        seq, e, n = m.last_seq, m.east_m, m.north_m
        ve, vn = fix.ve_m_s, fix.vn_m_s
        if seq is None or e is None or n is None or ve is None or vn is None:
            return None
        gs_m_s = math.hypot(ve, vn)
        items, item_s = m.mission.items, m.mission.item_s_m
        k = next(
            (
                k
                for k in range(seq + 1, len(items))
                if items[k].command == MAV_CMD_NAV_WAYPOINT and item_s[k] is not None
            ),
            None,
        )
        if k is None or gs_m_s < 1.0:
            return None
        we, wn = self.frame.to_local(items[k].lat_deg, items[k].lon_deg)
        s_k = item_s[k]
        assert s_k is not None
        return s_k - way_out_m(float(we) - e, float(wn) - n, math.atan2(ve, vn), gs_m_s)

    def _leave_loiter(
        self, m: Member, d: Decision, left: Decision, t: float, out: list[act.Action]
    ) -> None:
        """Take the vehicle out of its loiter turns: the item after the NAV_LOITER_TURNS made
        current (ArduPlane leaves the circle for it at once). ``d`` timed it with the turns
        left, ``left`` without them."""
        seq = m.last_seq
        if seq is None or seq + 1 >= len(m.mission.items) or not m.in_loiter():
            return
        m.leaving_seq = seq + 1
        hi = m.limits.airspeed_max_m_s
        rest = (
            f"still {left.eta_min_s - m.target_s:.1f} s late at {hi:g} m/s"
            if left.verdict == "late"
            else f"on time from there, {left.required_m_s:.2f} m/s required"
        )
        if d.verdict == "late":
            stay = f"the rest of its loiter would make it {d.eta_min_s - m.target_s:.1f} s late "
            stay += f"even at {hi:g} m/s"
        elif d.required_m_s > hi - self.config.speed_reserve_m_s:
            stay = f"the rest of its loiter would need {d.required_m_s:.2f} m/s, within "
            stay += f"{self.config.speed_reserve_m_s:g} m/s of its top speed"
        else:
            stay = "its turns flown, it circles on to line up with the route"
        why = f"{stay}: out of the turns at {t:.1f} s, on to item {seq + 1} ({rest})"
        out.append(
            act.Report(
                EventKind.LOITER,
                why,
                m.vehicle_id,
                t_s=t,
                payload={
                    "action": "leave",
                    "seq": seq + 1,
                    "late_s": round(d.eta_min_s - m.target_s, 1),
                    "loiter_flown_m": round(m.loiter_flown_m, 1),
                },
            )
        )
        out.append(act.LeaveLoiter(m.vehicle_id, seq + 1, why, t))

    def _loiter_left(self, r: act.LoiterLeft, now: float, out: list[act.Action]) -> None:
        """The vehicle flies the item after its loiter (or it was not taken out: asked again
        at its next decision). Its turns count as flown: it is timed on its route again."""
        leave = r.leave
        m = self.members[leave.vehicle_id]
        m.leaving_seq = None
        m.next_decision_s = -math.inf
        if r.error is not None:
            out.append(
                act.Report(
                    EventKind.LOITER,
                    f"not taken out of its turns ({r.error}); deciding again",
                    m.vehicle_id,
                    t_s=now,
                    payload={"action": "leave_failed", "seq": leave.seq},
                )
            )
            return
        if m.last_seq is not None and m.last_seq < leave.seq:
            m.last_seq = leave.seq
        m.loiter_entered_s, m.loiter_flown_m = None, 0.0
        m.progress = None
        out.append(
            act.Report(
                EventKind.LOITER,
                f"out of its turns: flying item {leave.seq} on, timed on its route",
                m.vehicle_id,
                t_s=now,
                payload={"action": "left", "seq": leave.seq},
            )
        )

    def _apply_decision(self, m: Member, d: Decision, t: float, out: list[act.Action]) -> None:
        """Keep the decision, time the next one, and command the airspeed it asks for (one
        command at a time)."""
        m.last_decision = d
        m.eta_min_seen = (*m.eta_min_seen[-1:], (t, d.eta_min_s))
        m.next_decision_s = t + ArrivalController.period_s(m.target_s - t)
        if d.command_m_s is not None and not m.busy_command:
            m.busy_command = True
            out.append(act.CommandSpeed(m.vehicle_id, d.command_m_s, d.reason, t))

    def _speed_commanded(self, r: act.SpeedCommanded, out: list[act.Action]) -> None:
        m = self.members[r.vehicle_id]
        m.busy_command = False
        if r.error is not None:
            m.speed_refusals += 1
            out.append(
                act.Report(
                    EventKind.SPEED, f"speed command failed ({r.error}); will retry", m.vehicle_id
                )
            )
            if m.speed_refusals == SPEED_REFUSALS_ALARM:
                lim = m.limits
                out.append(
                    act.Report(
                        EventKind.ALARM,
                        f"{m.vehicle_id} refused {r.airspeed_m_s:g} m/s {m.speed_refusals} times "
                        f"in a row ({r.error}): its speed is not under control; check its "
                        f"AIRSPEED_MIN and AIRSPEED_MAX against [{lim.airspeed_min_m_s:g}, "
                        f"{lim.airspeed_max_m_s:g}] m/s",
                        m.vehicle_id,
                        t_s=r.decided_s,
                        payload={"action": "none", "why": "speed command refused"},
                    )
                )
            m.next_decision_s = -math.inf
            return
        m.speed_refusals = 0
        m.level_m_s = r.airspeed_m_s
        assert self.start_utc_s is not None
        m.commanded.append([round(self.start_utc_s + r.decided_s, 3), r.airspeed_m_s, "command"])
        out.append(
            act.Report(
                EventKind.SPEED, r.reason, m.vehicle_id, "speed", r.airspeed_m_s, t_s=r.decided_s
            )
        )

    # -- arrival --------------------------------------------------------------------------------

    @staticmethod
    def _loiter_entry(m: Member, t: float, dt_s: float, fix: act.Fix) -> tuple[float, float]:
        """When a vehicle first seen in loiter turns (its mission item) entered them, and how
        far round it has flown since (m): from where along the route it was at its previous
        fix, ``dt_s`` before, at its true airspeed (round a circle the ground speed swings
        with the wind either side of it; a fix's own is the side it is on). Fixes a second or
        two apart make that about now and nothing; after a gap (a link down, the coordinator
        restarted from its checkpoint) the turns flown meanwhile are counted, not taken for
        none: a vehicle believed to have every turn still ahead reads as late and is taken
        out of them."""
        done = m.loiters_done()
        if dt_s <= 0.0 or m.s_m is None or done >= len(m.track.loiters):
            return t, 0.0
        lo = m.track.loiters[done]
        tas_m_s = m.tas_m_s(lo.s_m)  # the fix's own airspeed is the member's by now
        if tas_m_s is None or tas_m_s <= 0.0:
            return t, 0.0
        to_entry_m = max(lo.s_m - m.s_m, 0.0)
        entered_s = min(t, t - dt_s + to_entry_m / tas_m_s)
        return entered_s, (t - entered_s) * tas_m_s

    def _watch_goal(
        self, m: Member, fix: act.Fix, e: float, n: float, out: list[act.Action]
    ) -> None:
        radius = self.config.arrival_radius_m
        d = math.hypot(e - m.goal_en_m[0], n - m.goal_en_m[1])
        # Near its goal along its route too (as last located, loiter turns ahead included): a
        # route that passes near its own goal on the way round (a re-plan around a zone), or
        # a loiter circle that comes near it, is not arriving there. Nor is one that leaves
        # its goal behind with its route still ahead: a hook back into the goal's approach
        # (the 60-vehicle crowd's R05, taken for its passage 53 s early).
        along_m = math.inf
        if m.s_m is not None and not m.in_loiter():
            along_m = m.track.remaining_m(m.s_m, m.loiters_done())
        if along_m > radius + GOAL_ALONG_SLACK_M:
            m.near_goal.clear()
            return
        past = along_m <= GOAL_ALONG_SLACK_M
        if d > radius:
            if m.near_goal and past:
                self._arrive(m, out)
            elif not past:
                m.near_goal.clear()  # out of the radius on its way round
            return
        m.near_goal.append(
            TruthSample(
                fix.utc_s,
                fix.lat_deg,
                fix.lon_deg,
                fix.alt_amsl_m or 0.0,
                fix.airspeed_m_s or 0.0,
                fix.groundspeed_m_s or 0.0,
                True,
            )
        )
        if len(m.near_goal) >= 3:
            prev = m.near_goal[-2]
            pe, pn = self.frame.to_local(prev.lat_deg, prev.lon_deg)
            d_prev = math.hypot(float(pe) - m.goal_en_m[0], float(pn) - m.goal_en_m[1])
            if d > d_prev + 1.0 and past:
                self._arrive(m, out)

    def _arrive(self, m: Member, out: list[act.Action]) -> None:
        glat, glon = self.frame.to_geodetic(*m.goal_en_m)
        ca = closest_approach(m.near_goal, float(glat), float(glon), self.config.arrival_radius_m)
        utc = ca[0] if ca is not None else m.near_goal[-1].utc_s
        t = self._t(utc)
        m.arrival_s = t
        m.phase = "arrived"
        m.landing_due = self.scenario.landing is not None
        out.append(
            act.Report(
                EventKind.ARRIVED,
                f"passed the goal at {t:.2f} s (target {m.target_s:.2f} s, "
                f"error {t - m.target_s:+.2f} s; telemetry)",
                m.vehicle_id,
                value=round(t - m.target_s, 3),
                t_s=t,
            )
        )

    # -- landing slots ------------------------------------------------------------------------

    def landing_bound_s(self, m: Member) -> float:
        """How long after its slot fix a vehicle may take to be down and disarmed: the glide
        at its slowest airspeed twice over, plus the flare, roll-out and disarm delay."""
        landing = self.scenario.landing
        assert landing is not None
        te, tn = landing.touchdown.local(self.frame)
        glide_m = math.hypot(te - m.goal_en_m[0], tn - m.goal_en_m[1])
        return 2.0 * glide_m / m.limits.airspeed_min_m_s + LANDING_MARGIN_S

    def _landing_heartbeat(
        self, m: Member, hb: act.Heartbeat, now: float, out: list[act.Action]
    ) -> None:
        """Gliding after its slot: MAV_STATE_EMERGENCY is a crash; disarmed is down (ArduPlane
        disarms LAND_DISARMDELAY after the touchdown)."""
        if hb.emergency:
            m.landing_due = False
            self._lose(m, "crash", "HEARTBEAT MAV_STATE_EMERGENCY while landing", now, out)
            return
        if hb.armed:
            return
        m.landing_due = False
        m.landed_s = now
        landing = self.scenario.landing
        assert landing is not None
        order = sum(1 for x in self.members.values() if x.landed_s is not None)
        te, tn = landing.touchdown.local(self.frame)
        c = math.radians(landing.heading_deg)
        e = te if m.east_m is None else m.east_m
        n = tn if m.north_m is None else m.north_m
        de, dn = e - te, n - tn
        along, across = de * math.sin(c) + dn * math.cos(c), -de * math.cos(c) + dn * math.sin(c)
        m.landed_en_m = (e, n)
        out.append(
            act.Report(
                EventKind.LANDED,
                f"down and disarmed at {now:.1f} s, {order} to land, {along:+.0f} m along and "
                f"{across:+.0f} m across the runway from the touchdown point",
                m.vehicle_id,
                value=order,
                t_s=now,
                payload={"order": order, "along_m": round(along, 1), "across_m": round(across, 1)},
            )
        )

    def _watch_landings(self, now: float, out: list[act.Action]) -> None:
        """A vehicle not down within :meth:`landing_bound_s` of its slot fix is an alarm and
        ends the flight as failed (it is still in the air, off its plan)."""
        late = [
            m
            for m in self.members.values()
            if m.landing_due
            and m.arrival_s is not None
            and now > m.arrival_s + self.landing_bound_s(m)
        ]
        if not late:
            return
        for m in late:
            m.landing_due = False
            out.append(
                act.Report(
                    EventKind.ALARM,
                    f"not down {now - (m.arrival_s or 0.0):.0f} s after its slot fix "
                    f"(bound {self.landing_bound_s(m):.0f} s): it has not landed",
                    m.vehicle_id,
                    t_s=now,
                )
            )
        self.stopped = f"not landed: {', '.join(m.vehicle_id for m in late)}"
        out.append(act.Report(EventKind.ABORT, f"{self.stopped}; stopping the loop", t_s=now))
        out.append(act.Stop(self.stopped))

    # -- abort ----------------------------------------------------------------------------------

    def abort(
        self, vehicle_id: str | None, mode: act.AbortMode, now_s: float
    ) -> tuple[dict[str, str | None], list[act.Action]]:
        """Abort one vehicle (or every one): it leaves the team and flies home (``rtl``) or
        circles where it is (``loiter``); one still on the ground stays there. Returns per
        vehicle None (aborting) or why not, and the actions (a :class:`~actions.SetMode` per
        vehicle in the air; its outcome comes back through :meth:`abort_done`).

        Raises
        ------
        KeyError
            No such vehicle in the flight (named).
        """
        if vehicle_id is not None and vehicle_id not in self.members:
            raise KeyError(f"no vehicle {vehicle_id!r} in the flight")
        chosen = [self.members[vehicle_id]] if vehicle_id else list(self.members.values())
        results: dict[str, str | None] = {}
        out: list[act.Action] = []
        for m in chosen:
            if m.done:
                results[m.vehicle_id] = f"already {m.phase}"
                continue
            on_ground = m.phase == "ground"
            m.phase = "aborted"
            results[m.vehicle_id] = None
            if on_ground:
                why = "aborted on the ground: it will not take off"
                out.append(act.Report(EventKind.ABORT, why, m.vehicle_id, t_s=now_s))
                continue
            out.append(act.SetMode(m.vehicle_id, "RTL" if mode == "rtl" else "LOITER"))
        self._states(out, now_s)
        return results, out

    def abort_done(self, vehicle_id: str, mode: str, error: str | None, now_s: float) -> act.Report:
        if error is not None:
            return act.Report(
                EventKind.ABORT,
                f"aborted, but {mode} was not taken: {error}",
                vehicle_id,
                t_s=now_s,
            )
        what = "returning home (RTL)" if mode == "RTL" else "circling where it is (LOITER)"
        return act.Report(
            EventKind.ABORT, f"aborted: {what}; the others keep their time", vehicle_id, t_s=now_s
        )

    # -- what a UI shows --------------------------------------------------------------------------

    def snapshot(self, now_s: float) -> dict[str, Any]:
        """A serialisable view of the flight: the team time, every vehicle's position, state,
        ETA and error against its slot, strategy in use, threats in force."""
        vehicles = []
        for m in self.members.values():
            d = m.last_decision
            eta = None if d is None else d.eta_s
            if m.arrival_s is not None:
                eta = m.arrival_s
            if m.phase == "ground":
                strategy = {"kind": "takeoff_wait", "takeoff_s": round(m.takeoff_s, 3)}
            elif m.hold_zone is not None:
                strategy = {"kind": "hold", "zone": m.hold_zone}
            elif m.in_loiter() or m.loiter_turns_left() > 0:
                strategy = {"kind": "loiter", "turns_left": m.loiter_turns_left()}
            else:
                strategy = {"kind": "speed", "level_m_s": m.level_m_s}
            vehicles.append(
                {
                    "id": m.vehicle_id,
                    "phase": m.phase,
                    "state": m.state.value,
                    "east_m": None if m.east_m is None else round(m.east_m, 1),
                    "north_m": None if m.north_m is None else round(m.north_m, 1),
                    "alt_amsl_m": m.alt_amsl_m,
                    "heading_deg": m.heading_deg,
                    "s_m": None if m.s_m is None else round(m.s_m, 1),
                    "route_length_m": round(m.track.length_m, 1),
                    "slot_s": round(m.target_s, 3),
                    "eta_s": None if eta is None else round(eta, 3),
                    "error_s": None if eta is None else round(eta - m.target_s, 3),
                    "strategy": strategy,
                    "commanded_m_s": m.level_m_s,
                    "airspeed_m_s": m.airspeed_m_s,
                    "groundspeed_m_s": m.groundspeed_m_s,
                    "link_silent": m.link_silent,
                    "last_fix_age_s": None
                    if m.last_fix_s is None
                    else round(max(0.0, now_s - m.last_fix_s), 2),
                    "arrival_s": m.arrival_s,
                    "lost": None
                    if m.lost is None
                    else {"cause": m.lost.cause, "t_s": round(m.lost.t_s, 3), "why": m.lost.why},
                }
            )
        return {
            "t_s": round(now_s, 3),
            "start_utc_s": self.start_utc_s,
            "team_time_s": self.team_ref_s,
            "team_time_version": self.version,
            "hard_deadline_s": round(self.hard_deadline_s, 3),
            "arrival_reason": self.schedule.arrival_reason,
            "vehicles": vehicles,
            "threats_in_force": sorted(z.id for z in self.in_force(now_s)),
            "threats_queued": sorted(
                t.id for t in self.operator_threats if t.id not in self.popups_done
            ),
        }

    # -- restart ----------------------------------------------------------------------------------

    def __getstate__(self) -> dict[str, Any]:
        """Everything but the world (rebuilt from the scenario on a restart)."""
        state = dict(self.__dict__)
        state["world"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        """A checkpoint kept before a part of the controller existed gets that part new."""
        self.__dict__.update(state)
        self.__dict__.setdefault("separation", SeparationWatch(self.scenario.separation_m))
        self.__dict__.setdefault("loiter_lead_s", self.lead_s)
        self.__dict__.setdefault("vertical", VerticalFlight())

    def rebind_world(self, world: World) -> None:
        self.world = world

    def restarted(self) -> None:
        """Taken on from a checkpoint by a new process: what was under way when the old one died
        is gone (commands, uploads and re-plans are decided again), and what it had watched is
        out of date (the vehicles flew on unwatched meanwhile)."""
        for m in self.members.values():
            m.busy_command = m.busy_mission = False
            m.leaving_seq = None
            m.link_silent = False
            # The progress and standing-still watches start again at the first fix: the time
            # since the checkpoint's last fix is no time seen without progress (a vehicle that
            # finished a loiter meanwhile is behind the farthest point it reached circling).
            m.progress = m.still = None
        self.popups_done -= self.popups_running
        self.popups_running.clear()
        # Forecasts made before the restart are stale (and a checkpoint kept before they had
        # heights holds them in another layout).
        old = self.forecasts
        self.forecasts = Forecasts(list(self.members), old.look_ahead_s, old.response_s)


def _neighbours(
    forecasts: Forecasts, pair: tuple[str, str], within_m: float, t: float, *, heights: bool = True
) -> dict[str, list[Ahead]]:
    """For each of ``pair``, the others forecast within ``within_m`` of it
    (:meth:`Forecasts.near`): what a resolution of the pair must keep clear of."""
    return {
        vid: [
            forecasts.ahead[n]
            for n in forecasts.near(vid, within_m, t, heights=heights)
            if n not in pair
        ]
        for vid in pair
    }

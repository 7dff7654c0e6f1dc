"""The team's arrival time: who moves it and how. A vehicle late even at its top speed moves
it later (to its earliest arrival plus a margin), unless another has already arrived, or
another could not arrive that late (its minimum speed, and no loiter turns left to splice in
before its goal; or on its final approach, where no speed is asked): then the late vehicle
alone is released from its slot, with an alarm, and the others keep theirs. Ordered slots
(spaced arrivals, landing slots, waves) move from the late vehicle's on: the slots before it
stay, those after it move only as far as their spacing needs, and a spaced vehicle that the
ones after it cannot wait for takes a later place in the order if one serves. With arrival
windows a late vehicle's own slot moves within its window. A lost vehicle can bring it
earlier; the operator moves it (refused with the earliest feasible time). Ground vehicles
re-time their takeoff, in the wind the airborne ones measure once one does (the schedule's
forecast until then).

:class:`TeamTime` is the part of :class:`~gcs.coordination.team.TeamController` that does
this; it holds no state of its own.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import replace

from gcs.coordination import actions as act
from gcs.coordination.arrival import Decision
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind
from gcs.coordination.member import Member
from gcs.errors import GcsError
from planner.retime import earliest_from_ground_s, takeoff_for
from planner.scenario import Scenario, Spaced, Waves, Windows
from planner.schedule import VehicleSchedule
from planner.slots import SAME_SLOT_S, pushed, slot_groups, slot_spacing_s
from planner.wind import Wind

__all__ = ["TeamTime", "TeamTimeRefused", "names_of"]

ON_FINAL = "on its final approach, at the speed it flies"
"""Why a vehicle on its final approach arrives when it does (:meth:`TeamTime.on_final_eta_s`)."""


class TeamTimeRefused(GcsError):
    """A team arrival time that some vehicle cannot make: names the earliest feasible time
    (too early) or the latest (too late) and the vehicle that forces it."""

    def __init__(
        self,
        requested_s: float,
        earliest_s: float | None,
        vehicle_id: str,
        why: str,
        *,
        latest_s: float | None = None,
    ) -> None:
        if latest_s is None:
            assert earliest_s is not None
            text = (
                f"team arrival {requested_s:.1f} s refused: {vehicle_id} cannot arrive before "
                f"{earliest_s + 0.0:.1f} s ({why}); earliest feasible {earliest_s:.1f} s"
            )
        else:
            text = (
                f"team arrival {requested_s:.1f} s refused: {vehicle_id} cannot arrive after "
                f"{latest_s + 0.0:.1f} s ({why}); latest feasible {latest_s:.1f} s"
            )
        super().__init__(text)
        self.requested_s = requested_s
        self.earliest_s = earliest_s
        self.latest_s = latest_s
        self.vehicle_id = vehicle_id


def names_of(stuck: list[tuple[str, float]], shown: int = 5) -> str:
    """``R02 (at most 571.8 s), ... and 22 more``: the vehicles that cannot follow a move."""
    names = ", ".join(f"{vid} (at most {follow:.1f} s)" for vid, follow in stuck[:shown])
    return names + (f" and {len(stuck) - shown} more" if len(stuck) > shown else "")


class TeamTime:
    """Late vehicles, lost ones and the operator's moves of the team time."""

    scenario: Scenario
    config: FlightConfig
    members: dict[str, Member]
    team_ref_s: float | None
    version: int
    hard_deadline_s: float

    def _states(self, out: list[act.Action], now_s: float, only: str | None = None) -> None:
        """Say the states that changed (the controller's)."""
        raise NotImplementedError

    def _keep_seq(self, m: Member, lead_m: float) -> int | None:
        """The first route waypoint at least ``lead_m`` ahead (the re-planning part's)."""
        raise NotImplementedError

    def _can_loiter_after(self, m: Member, s_m: float) -> bool:
        """Whether loiter turns can be flown on the vehicle's path after ``s_m`` (the
        re-planning part's)."""
        raise NotImplementedError

    def latest_arrival_s(self, m: Member) -> float:
        """The latest a vehicle still flying to its slot can arrive (mission s): unbounded on
        the ground (its takeoff moves) or while loiter turns can still be spliced in ahead of
        it (a waypoint the shortest lead ahead, and room for the turns after it), else its
        ETA at its minimum speed from its last decision."""
        if m.phase == "ground" or m.last_decision is None:
            return math.inf
        gs_m_s = max(m.groundspeed_m_s, 10.0)
        keep = self._keep_seq(m, gs_m_s * self.config.min_lead_s)
        if keep is not None and self._can_loiter_after(m, m.mission.item_s_m[keep] or 0.0):
            return math.inf
        return m.last_decision.eta_max_s

    def on_final_eta_s(self, m: Member) -> float | None:
        """When a vehicle on its final approach (within ``final_m`` of its goal, where no
        speed is asked any more) arrives: its last fix plus the rest at its ground speed; None
        for one that is not on it. It follows no move of the team time: a move 0.66 s later,
        8 s before the slot, left one that was to fly its minimum speed by its last decision
        1.07 s early."""
        if m.phase != "route" or m.s_m is None or m.last_fix_s is None or m.in_loiter():
            return None
        if not m.on_final(self.config.final_m):
            return None
        return m.last_fix_s + max(m.track.length_m - m.s_m, 0.0) / max(m.groundspeed_m_s, 1.0)

    def _latest_s(self, other: Member, slot_s: float) -> float | None:
        """None if ``other`` can still arrive at ``slot_s`` (mission s, later than its slot),
        else the latest it can (one on its final approach: its arrival as it flies; one that
        has arrived: then)."""
        if other.arrival_s is not None:
            return other.arrival_s
        tolerance_s = self.config.tolerance_s
        final_s = self.on_final_eta_s(other)
        if final_s is not None:
            return None if slot_s <= final_s + tolerance_s else final_s
        d = other.last_decision
        slower_s = math.inf if other.phase == "ground" or d is None else d.eta_max_s
        if slot_s <= slower_s + tolerance_s:
            return None  # it follows (flying slower; room for turns is not looked for)
        follow_s = self.latest_arrival_s(other)
        return None if slot_s <= follow_s + tolerance_s else follow_s

    def _cannot_follow(self, new_ref: float, movers: Collection[str]) -> list[tuple[str, float]]:
        """The vehicles other than ``movers`` (the late ones) that a team time of ``new_ref``
        would make early whatever they do, each with the latest team time it can follow (one
        on its final approach: its arrival as it flies)."""
        out = []
        for other in self.members.values():
            if other.vehicle_id in movers or other.done:
                continue
            latest_s = self._latest_s(other, new_ref + other.offset_s)
            if latest_s is not None:
                out.append((other.vehicle_id, latest_s - other.offset_s))
        return out

    def _retime_without(self, lost: Member, now: float, out: list[act.Action]) -> None:
        """The team time moves to the earliest the vehicles still flying to their slots can
        make together (plus the late margin), if that is earlier than it is."""
        ref = self.team_ref_s
        if ref is None or all(m.done for m in self.members.values()):
            return
        earliest, vid, why = self.earliest_team_time_s(now)
        margin_s = self._late_margin_s(earliest, now)
        new_ref = earliest + margin_s
        if new_ref >= ref - self.config.tolerance_s:
            out.append(
                act.Report(
                    EventKind.ARRIVAL,
                    f"team arrival stays {ref:.1f} s without {lost.vehicle_id}: {vid} cannot "
                    f"arrive before {earliest:.1f} s ({why})",
                    t_s=now,
                )
            )
            return
        self._set_team_time(
            new_ref,
            now,
            f"team arrival moved {ref:.1f} -> {new_ref:.1f} s without {lost.vehicle_id} "
            f"(lost): the earliest {vid} can make ({why}) plus {margin_s:.1f} s",
            None,
            out,
        )

    def _late_margin_s(self, earliest_s: float, now_s: float) -> float:
        """The margin a moved team time keeps past the earliest arrival: ``late_margin_s``,
        less in the last minutes (2 % of the time still to fly), where the others have no
        room left to absorb more than the late vehicle needs."""
        return min(self.config.late_margin_s, 0.02 * max(earliest_s - now_s, 0.0))

    def _late_in_window(self, m: Member, d: Decision, t: float, out: list[act.Action]) -> None:
        """Arrival windows: no team time; the late vehicle's own slot moves to the earliest it
        can make (plus the margin) while that is in its window, else to the window's end with
        an alarm, once, and it flies at top speed."""
        arrival = self.scenario.arrival
        assert isinstance(arrival, Windows)
        w = next(x for x in arrival.windows if x.vehicle == m.vehicle_id)
        new = d.eta_min_s + self._late_margin_s(d.eta_min_s, t)
        if new <= m.target_s:
            return
        old = m.target_s
        if new <= w.latest_s:
            m.target_s = new
            out.append(
                act.Report(
                    EventKind.ARRIVAL,
                    f"slot moved {old:.1f} -> {new:.1f} s within its window "
                    f"[{w.earliest_s:g}, {w.latest_s:g}] s: it cannot arrive before "
                    f"{d.eta_min_s:.1f} s even at {m.limits.airspeed_max_m_s:g} m/s",
                    m.vehicle_id,
                    value=round(new, 3),
                    t_s=t,
                )
            )
        else:
            # Its slot stays the window's end, the nearest it can come: flown at its top
            # speed, its arrival is judged (and a rehearsal passed) against the window.
            m.target_s = w.latest_s
            self._say_late(
                m,
                f"misses its window [{w.earliest_s:g}, {w.latest_s:g}] s: it cannot arrive "
                f"before {d.eta_min_s:.1f} s even at {m.limits.airspeed_max_m_s:g} m/s",
                d.eta_min_s - w.latest_s,
                t,
                out,
            )
        m.next_decision_s = -math.inf

    @staticmethod
    def _say_late(m: Member, reason: str, late_s: float, t: float, out: list[act.Action]) -> None:
        """A lateness the team time cannot follow: an alarm, said once per vehicle."""
        if m.late_said:
            return
        m.late_said = True
        out.append(act.Report(EventKind.ALARM, reason, m.vehicle_id, value=round(late_s, 3), t_s=t))

    def _settled(self, m: Member, t: float) -> bool:
        """Its lateness may move the team time: never heard again after a gap, or heard
        again for ``resettle_s`` with its earliest arrival as on the decision before
        (``resettle_drift``). Meanwhile it flies at its top speed, its estimates re-learning."""
        if m.heard_since_s == -math.inf:
            return True
        cfg = self.config
        if t - m.heard_since_s < cfg.resettle_s or len(m.eta_min_seen) < 2:
            return False
        (before_s, eta_before_s), (now_s, eta_now_s) = m.eta_min_seen
        if before_s < m.heard_since_s or now_s != t:
            return False
        drift_s = abs(eta_now_s - eta_before_s)
        return drift_s <= max(cfg.tolerance_s, cfg.resettle_drift * (now_s - before_s))

    def _late(self, m: Member, d: Decision, t: float, out: list[act.Action]) -> None:
        if not self._settled(m, t):
            return
        ref = self.team_ref_s
        if ref is None:
            if isinstance(self.scenario.arrival, Windows):
                self._late_in_window(m, d, t, out)
            return
        if isinstance(self.scenario.arrival, Spaced | Waves):
            self._late_in_order(m, d, t, out)
            return
        new_ref = d.eta_min_s - m.offset_s + self._late_margin_s(d.eta_min_s, t)
        if new_ref <= ref:
            return
        arrived = sorted(x.vehicle_id for x in self.members.values() if x.arrival_s is not None)
        if arrived:
            # Moving the team time now would only make the arrived ones miss it: the late
            # vehicle is late, and said so.
            self._say_late(
                m,
                f"late by {d.eta_min_s - m.target_s:.1f} s at top speed after "
                f"{', '.join(arrived)} arrived: the team time stays {ref:.1f} s",
                d.eta_min_s - m.target_s,
                t,
                out,
            )
            return
        if m.late_said:
            return  # released from its slot already
        stuck = self._cannot_follow(new_ref, (m.vehicle_id,))
        if stuck:
            # Moving the team time would make the others early, with no slower speed or loiter
            # turns left to them: the late vehicle alone is released from its slot.
            self._say_late(
                m,
                f"late by {d.eta_min_s - m.target_s:.1f} s at top speed: the team time stays "
                f"{ref:.1f} s, as {names_of(stuck)} cannot arrive as late as "
                f"{new_ref:.1f} s",
                d.eta_min_s - m.target_s,
                t,
                out,
            )
            return
        self._set_team_time(
            new_ref,
            t,
            f"team arrival moved {ref:.1f} -> {new_ref:.1f} s: {m.vehicle_id} cannot arrive "
            f"before {d.eta_min_s:.1f} s even at {m.limits.airspeed_max_m_s:g} m/s",
            m.vehicle_id,
            out,
        )

    def _timed(self) -> list[Member]:
        """The vehicles that have a slot: still flying to it, or arrived (not lost or
        aborted)."""
        return [x for x in self.members.values() if not x.done or x.arrival_s is not None]

    def _slots(self) -> list[list[Member]]:
        """The team's slots in their order, each with the vehicles that arrive in it (one
        each when spaced, a wave's; :func:`planner.slots.slot_groups`)."""
        groups = slot_groups({x.vehicle_id: x.target_s for x in self._timed()})
        return [[self.members[vid] for vid in group] for group in groups]

    def _pushed(
        self, slots: list[list[Member]], first_s: float, mover: Member
    ) -> tuple[dict[str, float], list[tuple[str, float]]]:
        """``mover``'s slot (the first of ``slots``; its wave's) moved to ``first_s``, each
        slot after it as far as its spacing after the one before needs (:func:`planner.
        slots.pushed`): the new slots of those that move, by vehicle, and the vehicles other
        than ``mover`` that cannot follow, each with the latest it can arrive."""
        spacing_s = slot_spacing_s(self.scenario)
        assert spacing_s is not None
        now = {x.vehicle_id: x.target_s for slot in slots for x in slot}
        new = pushed(now, {mover.vehicle_id: first_s}, spacing_s)
        moves = {
            vid: slot_s
            for vid, slot_s in new.items()
            if vid == mover.vehicle_id or slot_s > now[vid] + SAME_SLOT_S
        }
        stuck = []
        for vid, slot_s in moves.items():
            latest_s = (
                None if vid == mover.vehicle_id else self._latest_s(self.members[vid], slot_s)
            )
            if latest_s is not None:
                stuck.append((vid, latest_s))
        return moves, stuck

    def _earliest_s(self, m: Member, now_s: float) -> tuple[float, str]:
        """The earliest a vehicle still flying to its slot can arrive (mission s), and why."""
        if m.phase == "ground":
            v = self.scenario.vehicle(m.vehicle_id)
            t0 = max(now_s, v.takeoff_window_s[0])
            earliest = earliest_from_ground_s(v, self._from_ground(m), t0)
            return earliest, (
                f"on the ground: taking off at {t0:.0f} s, climbing out and flying at top speed"
            )
        if (final_s := self.on_final_eta_s(m)) is not None:
            return final_s, ON_FINAL
        if m.last_decision is not None:
            # The ETA at top speed from its last decision, moved on to now.
            return (
                m.last_decision.eta_min_s,
                f"at {m.limits.airspeed_max_m_s:g} m/s from where it is",
            )
        return m.target_s, "still climbing out"  # no estimate yet: it keeps its slot

    def _later_place(
        self, slots: list[list[Member]], k: int, wanted_s: float, now_s: float
    ) -> tuple[dict[str, float], int] | None:
        """Spaced arrivals: the first later place the late vehicle of slot ``k`` can take (it
        goes after the vehicle of slot ``j``, each of those it lets by one place earlier,
        which each must make; the slots after its new one pushed as far as their spacing
        needs, which each must follow): the new slots by vehicle and ``j``; None if there is
        none."""
        mover = slots[k][0]
        tolerance_s = self.config.tolerance_s
        earlier: dict[str, float] = {}
        for j in range(k + 1, len(slots)):
            (passed,) = slots[j]
            place_s = slots[j - 1][0].target_s
            if (
                passed.arrival_s is not None
                or self._earliest_s(passed, now_s)[0] > place_s + tolerance_s
            ):
                return None  # it cannot be let by, nor any after it
            earlier[passed.vehicle_id] = place_s
            moves, stuck = self._pushed(
                [[mover], *slots[j + 1 :]], max(wanted_s, passed.target_s), mover
            )
            if not stuck:
                return earlier | moves, j
        return None

    def _late_in_order(self, m: Member, d: Decision, t: float, out: list[act.Action]) -> None:
        """Ordered slots (spaced arrivals and landing slots, waves): the late vehicle's slot
        (its whole wave's) moves to the earliest it can make plus the margin, and each slot
        after it only as far as its spacing after the one before needs; the slots before it
        stay, and so do those of the vehicles that have arrived. Where one that would move
        cannot follow, a spaced vehicle takes the first later place it can make, the vehicles
        it lets by each one place earlier; failing that it alone is released from its slot,
        with an alarm naming those that cannot follow."""
        wanted_s = d.eta_min_s + self._late_margin_s(d.eta_min_s, t)
        if wanted_s <= m.target_s or m.late_said:
            return
        slots = self._slots()
        k = next(i for i, slot in enumerate(slots) if any(x is m for x in slot))
        why = (
            f"{m.vehicle_id} cannot arrive before {d.eta_min_s:.1f} s even at "
            f"{m.limits.airspeed_max_m_s:g} m/s"
        )
        moves, stuck = self._pushed(slots[k:], wanted_s, m)
        if not stuck:
            self._move_slots(moves, t, f"slots moved from place {k + 1} on: {why}", m, out)
            return
        if isinstance(self.scenario.arrival, Spaced) and all(len(s) == 1 for s in slots):
            later = self._later_place(slots, k, wanted_s, t)
            if later is not None:
                moves, j = later
                let_by = ", ".join(x[0].vehicle_id for x in slots[k + 1 : j + 1])
                self._move_slots(
                    moves,
                    t,
                    f"{m.vehicle_id} takes place {j + 1} in the order, after {let_by} (each "
                    f"one place earlier): {why}, and {names_of(stuck)} cannot arrive as late "
                    f"as its place needs",
                    m,
                    out,
                )
                return
        self._say_late(
            m,
            f"late by {d.eta_min_s - m.target_s:.1f} s at top speed: its slot stays "
            f"{m.target_s:.1f} s, as {names_of(stuck)} cannot arrive as late as the slots "
            "after it would need",
            d.eta_min_s - m.target_s,
            t,
            out,
        )

    def _set_slots(self, slots: dict[str, float]) -> None:
        """Give each vehicle of ``slots`` its slot (mission s; re-decided at its next fix):
        the team time is the first slot's again, each vehicle's offset from it kept; a new
        version if any moved."""
        moved = False
        for vid, slot_s in slots.items():
            x = self.members[vid]
            moved = moved or abs(x.target_s - slot_s) > 1e-3
            x.target_s = slot_s
            x.next_decision_s = -math.inf
        self.team_ref_s = min(x.target_s for x in self._timed())
        for x in self.members.values():
            x.offset_s = x.target_s - self.team_ref_s
        if moved:
            self.version += 1

    def _slots_cannot_follow(
        self, slots: dict[str, float], movers: Collection[str]
    ) -> list[tuple[str, float]]:
        """The vehicles other than ``movers`` that the new ``slots`` (mission s) would make
        early whatever they do, each with the latest it can arrive."""
        out = []
        for vid, slot_s in slots.items():
            x = self.members[vid]
            if vid in movers or x.done or slot_s <= x.target_s + 1e-6:
                continue
            latest_s = self._latest_s(x, slot_s)
            if latest_s is not None:
                out.append((vid, latest_s))
        return out

    def _move_slots(
        self, moves: dict[str, float], t: float, reason: str, m: Member, out: list[act.Action]
    ) -> None:
        """Give each vehicle of ``moves`` its new slot (mission s): the team time is the first
        slot's again, each vehicle's offset from it kept; one event with the reason, the late
        vehicle's new slot and every slot that moved."""
        self._set_slots(moves)
        out.append(
            act.Report(
                EventKind.ARRIVAL,
                reason,
                m.vehicle_id,
                value=round(moves[m.vehicle_id], 3),
                t_s=t,
                payload={"slots": {vid: round(s, 3) for vid, s in moves.items()}},
            )
        )
        for vid in moves:
            x = self.members[vid]
            if x.phase == "ground":
                self._retime_takeoff(x, t, out)

    def _set_team_time(
        self, new_ref: float, t: float, reason: str, vehicle: str | None, out: list[act.Action]
    ) -> None:
        self.team_ref_s = new_ref
        self.version += 1
        out.append(act.Report(EventKind.ARRIVAL, reason, vehicle, value=new_ref, t_s=t))
        for other in self.members.values():
            if other.arrival_s is not None:
                continue  # its slot was the one it met
            other.target_s = new_ref + other.offset_s
            other.next_decision_s = -math.inf
            if other.phase == "ground":
                self._retime_takeoff(other, t, out)

    def _measured_wind(self) -> Wind | None:
        """The wind the vehicles in the air measure (the mean of their estimates); None while
        none does."""
        aloft = (x for x in self.members.values() if x.phase != "ground")
        winds = [x.wind for x in aloft if x.wind is not None]
        if not winds:
            return None
        return Wind(
            sum(w.to_east_m_s for w in winds) / len(winds),
            sum(w.to_north_m_s for w in winds) / len(winds),
        )

    def _from_ground(self, m: Member) -> VehicleSchedule:
        """The schedule a vehicle on the ground is timed with: its own, in the wind measured
        aloft once there is one (scheduled in a calm forecast, the paper's UAV1 took off 349 s
        too late for the 10 m/s its team was already flying in)."""
        wind = self._measured_wind()
        return m.schedule if wind is None else replace(m.schedule, wind=wind)

    def _retime_takeoff(self, m: Member, t: float, out: list[act.Action]) -> None:
        v = self.scenario.vehicle(m.vehicle_id)
        window = (max(v.takeoff_window_s[0], t), max(v.takeoff_window_s[1], t))
        new = takeoff_for(v, self._from_ground(m), m.target_s, window)
        if abs(new - m.takeoff_s) > 0.5:
            m.takeoff_s = new
            out.append(
                act.Report(
                    EventKind.TAKEOFF,
                    f"take off at {new:.1f} s to arrive at {m.target_s:.1f} s (eq. 5)",
                    m.vehicle_id,
                    "takeoff_delay",
                    round(new, 3),
                    t_s=t,
                )
            )

    def earliest_team_time_s(self, now_s: float) -> tuple[float, str, str]:
        """The earliest team arrival every vehicle can still make: ``(time_s, vehicle,
        why)``, the vehicle being the one that forces it."""
        best: tuple[float, str, str] | None = None
        for m in self.members.values():
            if m.done:
                continue
            earliest, why = self._earliest_s(m, now_s)
            earliest -= m.offset_s
            if best is None or earliest > best[0]:
                best = (earliest, m.vehicle_id, why)
        if best is None:
            raise GcsError("no vehicle of the team is still flying to its slot")
        return best

    def move_team_time(
        self, arrival_s: float, now_s: float, *, version: int | None = None
    ) -> list[act.Action]:
        """The operator moves the team arrival to ``arrival_s`` (mission s).

        Raises
        ------
        TeamTimeRefused
            A vehicle cannot arrive by then (the earliest feasible time and that vehicle), or
            a vehicle cannot wait that long (the latest feasible time and that vehicle).
        GcsError
            ``version`` is not the current one (someone moved it first), or the team has no
            common arrival time (per-vehicle windows).
        """
        if self.team_ref_s is None:
            raise GcsError("this flight's arrivals are per-vehicle windows: no team time to move")
        if version is not None and version != self.version:
            raise GcsError(f"team time version {version} is stale (now {self.version})")
        if not math.isfinite(arrival_s):
            raise GcsError(f"team arrival must be a number of seconds, got {arrival_s!r}")
        if arrival_s > self.hard_deadline_s:
            raise GcsError(
                f"team arrival {arrival_s:.1f} s is past the flight's hard deadline "
                f"{self.hard_deadline_s:.1f} s"
            )
        earliest, vid, why = self.earliest_team_time_s(now_s)
        if arrival_s < earliest - 1e-6:
            raise TeamTimeRefused(arrival_s, earliest, vid, why)
        stuck = self._cannot_follow(arrival_s, ()) if arrival_s > self.team_ref_s else []
        if stuck:
            vid, latest = min(stuck, key=lambda x: x[1])
            why = (
                ON_FINAL
                if self.on_final_eta_s(self.members[vid]) is not None
                else "at its minimum speed, with no loiter turns left to splice in before its goal"
            )
            raise TeamTimeRefused(arrival_s, None, vid, why, latest_s=latest)
        out: list[act.Action] = []
        old = self.team_ref_s
        self._set_team_time(
            arrival_s, now_s, f"team arrival moved {old:.1f} -> {arrival_s:.1f} s by the operator",
            None, out,
        )  # fmt: skip
        self._states(out, now_s)
        return out

"""Timing a re-plan apart: a re-planned vehicle passes the place where it would come too
close to another earlier or later, and still arrives at its slot.

A vehicle in flight has one timing for its slot at a steady speed (:func:`planner.retime.
retime_on_path`); it has others that fly the path to some place faster and the rest slower,
or the other way round. :func:`retime_through` is one of them: the vehicle timed to pass
``via_s_m`` along its path at ``via_t_s``, then for its slot from there (two timings joined,
each at its pair of discrete speeds, with loiter turns where the speed range cannot absorb
the time). :func:`time_apart` places the re-planned team in time from the re-plan's start
(:func:`planner.sequencing.sequence_team`, ``from_s``): only the vehicles given a new
mission move, each passing the place of its closest approach by one of
:data:`TIMING_SHIFTS_S`, the least first.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from planner.atmosphere import GRAVITY_M_S2
from planner.deconflict import Separation, TeamSamples
from planner.errors import InfeasibleError
from planner.retime import Retimed, retime_on_path
from planner.scenario import Scenario, Vehicle
from planner.schedule import VehicleSchedule
from planner.sequencing import SEPARATION_CHECK_MARGIN, Moved, sequence_team
from planner.threats import ThreatZone

__all__ = ["TIMING_SHIFTS_S", "Shift", "Through", "retime_through", "time_apart"]

TIMING_SHIFTS_S = (15.0, -15.0, 30.0, -30.0, 60.0, -60.0, 120.0, -120.0)
"""How much later (+) or earlier (-) than timed a re-planned vehicle may pass the place of its
closest approach, s, the least first: 15 s is 300 m or more at the speeds flown, ``d_s`` of
the generated teams."""

TECS_CLMB_MAX_M_S = 5.0
TECS_SINK_MIN_M_S = 2.0
"""ArduPlane's TECS_CLMB_MAX and TECS_SINK_MIN (their defaults), m/s: its TECS limits the rate
of its speed demand to half the specific energy rate they allow over its true airspeed
(AP_TECS.cpp, update_speed: velRateMax = 0.5 * _STEdot_max / TAS, velRateMin = 0.5 *
_STEdot_min / TAS, _STEdot_max = CLMB_MAX * g, _STEdot_min = -SINK_MIN * g): at 25 m/s about
1 m/s^2 faster and 0.4 m/s^2 slower (:func:`speed_change_m_s2`)."""

PLACES = 3
"""A re-planned vehicle is timed through the places of its closest approaches to this many
others at most (the closest first)."""

Through = Callable[[VehicleSchedule, float, float], Retimed | None]
"""``(schedule, via_s_m, via_t_s)``: the schedule timed from where its vehicle is at the
re-plan's start to pass ``via_s_m`` along its path at ``via_t_s`` (mission s), then to arrive
at its slot (:func:`retime_through`); None when it cannot."""


@dataclass(frozen=True)
class Shift:
    """A re-planned vehicle's other timing: where it passes earlier or later, and how."""

    via_s_m: float
    """Along its path, m."""
    shift_s: float
    """Later (+) or earlier (-) than it was timed to pass there, s."""
    retimed: Retimed


def retime_through(
    scenario: Scenario,
    v: Vehicle,
    vs: VehicleSchedule,
    *,
    now_s: float,
    via_s_m: float,
    via_t_s: float,
    target_s: float,
    step_m_s: float,
    threats: Sequence[ThreatZone],
    at: tuple[float, float] | None = None,
) -> Retimed:
    """``vs`` timed from ``now_s`` to pass ``via_s_m`` (m along its path) at ``via_t_s`` and
    arrive at ``target_s`` (mission s): :func:`planner.retime.retime_on_path` to ``via_s_m``
    on the path cut there, then from there on the whole path.

    ``at`` = (s_m, speed_m_s) anchors the vehicle where it really is, as for
    :func:`~planner.retime.retime_on_path`.

    Raises
    ------
    InfeasibleError
        Either part cannot be flown in its time within the vehicle's speed range (or loiter
        turns); or ``via_s_m`` is not ahead of where the vehicle is.
    """
    head_path = vs.path.prefix(via_s_m)
    if head_path is None or via_s_m >= vs.path.length_m or via_s_m <= vs.climb_s_m:
        raise InfeasibleError(f"{v.id}: {via_s_m:.0f} m is not on its path ahead", vehicle=v.id)
    below = vs.wp_s_m < via_s_m
    head = retime_on_path(
        scenario,
        v,
        replace(
            vs,
            path=head_path,
            wp_s_m=np.append(vs.wp_s_m[below], via_s_m),
            wp_alt_m=np.append(vs.wp_alt_m[below], vs.alt_at(via_s_m)),
        ),
        now_s=now_s,
        target_s=via_t_s,
        step_m_s=step_m_s,
        threats=threats,
        at=at,
    )
    flown = head.schedule
    if not flown.legs or flown.legs[-1].s_end_m < via_s_m - 1e-6:
        raise InfeasibleError(f"{v.id}: it is past {via_s_m:.0f} m already", vehicle=v.id)
    tail = retime_on_path(
        scenario,
        v,
        replace(flown, path=vs.path, wp_s_m=vs.wp_s_m, wp_alt_m=vs.wp_alt_m),
        now_s=via_t_s,
        target_s=target_s,
        step_m_s=step_m_s,
        threats=threats,
        at=(via_s_m, flown.legs[-1].speed_m_s),
    )
    _absorbs_the_change(v, flown, tail.schedule, via_s_m)
    passes = f"to pass {via_s_m / 1000.0:.1f} km along its path at {via_t_s:.1f} s"
    said = [
        replace(a, reason=a.reason.replace(f"to arrive at {via_t_s:.1f} s", passes))
        for a in head.adjustments
    ]
    return Retimed(replace(tail.schedule, via=(via_s_m, via_t_s)), [*said, *tail.adjustments])


def speed_change_m_s2(tas_m_s: float, faster: bool) -> float:
    """How fast ArduPlane's true airspeed follows a new command (:data:`TECS_CLMB_MAX_M_S`),
    m/s^2."""
    rate_m_s = TECS_CLMB_MAX_M_S if faster else TECS_SINK_MIN_M_S
    return 0.5 * rate_m_s * GRAVITY_M_S2 / max(tas_m_s, 1.0)


def _absorbs_the_change(
    v: Vehicle, head: VehicleSchedule, tail: VehicleSchedule, via_s_m: float
) -> None:
    """Raise unless the speed range left over the way from ``via_s_m`` to the slot (no loiter
    turns on it) makes up the ground a change of speed there gains or loses while the true
    airspeed follows its command (:func:`speed_change_m_s2`): a vehicle timed to pass 0.7 km
    before its goal at 27.5 m/s and to fly the rest at 16.2 m/s, its minimum 16, went on
    while it slowed and arrived 3.3 s early."""
    after = [leg for leg in tail.legs if leg.s_start_m >= via_s_m - 1e-6]
    if not head.legs or not after or any(lo.s_m >= via_s_m - 1e-6 for lo in tail.loiters):
        return
    span_s = after[-1].t_end_s - after[0].t_start_s
    if span_s <= 0.0:
        return
    last, first = head.legs[-1], after[0]
    was_m_s, now_m_s = last.true_airspeed_m_s, first.true_airspeed_m_s
    faster = now_m_s > was_m_s
    lag_m = (was_m_s - now_m_s) ** 2 / (2.0 * speed_change_m_s2(now_m_s, faster))
    mean_m_s = sum(leg.speed_m_s * (leg.t_end_s - leg.t_start_s) for leg in after) / span_s
    spare_m_s = v.speed_max_m_s - mean_m_s if faster else mean_m_s - v.speed_min_m_s
    if spare_m_s * first.tas_per_eas * span_s < lag_m:
        raise InfeasibleError(
            f"{v.id}: from {last.speed_m_s:.1f} to {first.speed_m_s:.1f} m/s at "
            f"{via_s_m / 1000.0:.1f} km, {lag_m:.0f} m gained or lost while its airspeed "
            f"follows, which {span_s:.0f} s to its slot cannot make up",
            vehicle=v.id,
        )


def time_apart(
    team: Sequence[VehicleSchedule],
    required_m: float,
    *,
    from_s: float,
    movable: Collection[str],
    through: Through,
    time_up: Callable[[], bool],
) -> tuple[dict[str, Moved[Shift]], Separation]:
    """Re-time the ``movable`` vehicles of ``team`` that come under ``required_m`` of another
    from ``from_s`` on, each for its slot through the place of its closest approach
    (:data:`TIMING_SHIFTS_S`), so that the team keeps ``required_m`` from then on.

    Parameters
    ----------
    team
        Every vehicle's schedule as re-planned and re-timed.
    required_m
        The separation minimum ``d_s``, m.
    from_s
        Mission time (s) the re-plan starts from: separation counts from then on.
    movable
        The vehicles that may be timed again (given a new mission by the re-plan).
    through
        Times a schedule through a place at a time for its slot (:data:`Through`).
    time_up
        Says when the re-plan's wall time is spent: no other timing is made after it.

    Returns
    -------
    The vehicles re-timed (by id) and the team's separation as re-timed, from ``from_s`` on.
    """
    first = TeamSamples(team, required_m, from_s=from_s)
    enough = SEPARATION_CHECK_MARGIN * required_m
    by_id = {vs.vehicle_id: vs for vs in team}

    def alternatives(vid: str) -> Iterator[tuple[VehicleSchedule, Shift]]:
        vs = by_id[vid]
        places = _close_places(first, vs, enough)
        for shift_s in TIMING_SHIFTS_S:
            for when_s in places:
                if time_up():
                    return
                via_s_m = vs.state_at(when_s)[1]
                r = through(vs, via_s_m, when_s + shift_s)
                if r is not None:
                    yield r.schedule, Shift(via_s_m, shift_s, r)

    slack = {vid: 1.0 for vid in movable}
    return sequence_team(team, required_m, slack_s=slack, alternatives=alternatives, from_s=from_s)


def _close_places(samples: TeamSamples, vs: VehicleSchedule, within_m: float) -> list[float]:
    """When (mission s) ``vs`` comes closest to each vehicle it comes within ``within_m`` of,
    the closest first, at most :data:`PLACES` of them."""
    out: list[tuple[float, float]] = []
    others = list(samples.too_close(vs, within_m))
    for who in others:
        near, _, when_s = samples.closest(vs, (who,), within_m)
        out.append((near, when_s))
    return [when_s for _, when_s in sorted(out)[:PLACES]]

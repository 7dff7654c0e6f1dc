"""The knobs of a flight's closed loop."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from planner.plan import Method

__all__ = ["FlightConfig", "LostPolicy"]

LostPolicy = Literal["continue", "retime", "abort"]
"""What the rest of a team does when one of its vehicles is lost (see
:attr:`FlightConfig.on_vehicle_lost`)."""


@dataclass(frozen=True)
class FlightConfig:
    """Knobs of the closed loop (mission seconds unless named otherwise)."""

    tolerance_s: float = 0.5
    """An ETA within this of the target needs no loiter and no new team time."""
    loiter_margin_m_s: float = 2.0
    """Loiter turns leave the speed this far above the minimum (room to slow down after)."""
    late_margin_s: float = 2.0
    """A late vehicle moves the team time to its earliest arrival plus this."""
    arm_lead_s: float = 10.0
    """A vehicle on the ground is armed this long before its takeoff time: at the takeoff
    time only the AUTO command's round trip is left (on a lossy link each retry of a command
    is a second of flight lost)."""
    min_lead_s: float = 60.0
    """Mission changes start at a waypoint at least this far ahead (more at high clock rates:
    the planning and upload wall time scaled by the rate)."""
    loiter_min_time_left_s: float = 300.0
    """No loiter is inserted closer than this to the arrival (the speed trims the rest)."""
    loiter_hold_off_s: float = 120.0
    """At most one loiter insertion per vehicle this often."""
    speed_reserve_m_s: float = 1.0
    """Farther than ``loiter_min_time_left_s`` from the arrival, a vehicle whose required
    airspeed is less than this above its minimum gets loiter turns as if it were early: its
    last minutes keep room to slow down (a pop-up re-plan, timed in still air, can leave it
    at the minimum in wind)."""
    arrival_radius_m: float = 1000.0
    """Goal passages are looked for within this distance of the goal."""
    resettle_gap_s: float = 10.0
    """A gap this long (mission s) in a vehicle's fixes (a link gap, a restart of the
    coordinator) makes it settle again before its lateness moves the team time..."""
    resettle_s: float = 60.0
    """...for this long after it is heard again (its wind and airspeed-scale estimates
    re-learn over about a minute, :class:`~gcs.coordination.speedbias.BiasConfig`): meanwhile
    a late verdict commands its top speed but moves nothing. On the first fix after a
    restart a vehicle was seen 47 s late, and on time 40 s later; the team time had moved..."""
    resettle_drift: float = 0.1
    """...and from then on, until the flight ends, only when its earliest arrival holds: on
    two decisions in a row that agree within ``tolerance_s`` or this many seconds per second
    between them (6 s over the estimates' minute). Re-learning what it had flown unwatched
    (a new route taken on just before a restart), a vehicle's earliest arrival drifted 4-5 s
    later at each decision, 10 s apart, for three minutes, and back: eleven moves put the
    team time 47 s past the one it could make."""
    link_silence_s: float = 3.0
    """A vehicle silent this long (mission s) is reported; its mission keeps it flying."""
    link_silence_wall_s: float = 0.025
    """...and at least this long in wall time: at 200x, 3 s of mission is 15 ms, less than a
    busy two-core machine's scheduling jitter (25 ms wall is 5 s of mission at 200x). On a
    pace clock (lock step) this floor is taken at the clock's rate, in mission time (5 s at
    200x), and wall time is not read: the simulator waits for the coordinator."""
    conflict_horizon_s: float = 30.0
    """Separation is predicted this far ahead of each fix (no further than either vehicle's
    slot), from the two vehicles' present velocities (straight flight: not for a vehicle in a
    loiter)."""
    resolve_horizon_s: float = 90.0
    """A pair predicted along their routes (at their present ground speeds) to come under the
    separation this far ahead is resolved by one of them flying the slowest or fastest
    airspeed of its range until they have passed (:mod:`gcs.coordination.resolution`); 0
    resolves nothing (the conflict events and alarms still say it)."""
    resolve_period_s: float = 2.0
    """Each vehicle's pairs are predicted for resolution at most this often (mission s)."""
    resolve_response_s: float = 5.0
    """The time a vehicle is assumed to take to reach a new airspeed, for the prediction."""
    allow_conflicts: bool = False
    """Launch a schedule whose plan leaves pairs under the separation (a rehearsal of the
    in-flight resolution): each pair is said before launch, a conflict and an alarm.
    Refused before launch otherwise."""
    vertical_horizon_s: float = 240.0
    """Pairs are screened this far ahead (mission s; climbing a layer takes minutes): one that
    no speed would keep apart over it is resolved by height at once (:mod:`gcs.coordination.
    vertical`), the others by speed once within ``resolve_horizon_s``; 0 resolves nothing by
    height."""
    vertical_rate_max_m_s: float = 5.0
    """The fastest an autopilot may climb or sink when asked another height (ArduPlane's
    TECS_CLMB_MAX and TECS_SINK_MAX, 5 m/s by default): a change of height is judged with the
    vehicle anywhere between this and the rate it is planned at (the slower of the pair's
    climb gradients at their airspeeds), so one that climbs faster does not pass through a
    third's height sooner than judged."""
    vertical_layer_m: float = 0.0
    """A conflict no speed resolves is resolved by one of the pair leaving its height by this
    much, or by two or three times it (:mod:`gcs.coordination.vertical`); 0: the scenario's
    first altitude layer, or half the separation without one."""
    runout_m: float = 300.0
    """A last waypoint this far past the goal, so the aircraft flies through the goal."""
    waypoint_spacing_m: float = 5000.0
    """Long legs are split into waypoints this far apart: a mission change splices in at a
    waypoint ahead, and the nearest one should not be half an hour away."""
    off_route_m: float = 500.0
    """A vehicle this far from its route is still joining it (after the climb-out, which
    heads wherever the aircraft was pointing): its ETA along the route runs late until it is
    on it, so it does not move the team time meanwhile (it is commanded its top speed)."""
    final_m: float = 150.0
    """No speed decisions closer than this to the goal (the autopilot could not act)."""
    method: Method = "aco"
    seed: int = 0
    command_retries: int = 8
    overrun_s: float = 900.0
    """Give up this long after the latest target if a vehicle has not arrived."""
    hard_deadline_s: float = 3600.0
    """The flight ends, failed, this long after the latest arrival as planned, whatever the
    team time has become since: the overrun follows the team time, which a late vehicle or the
    operator moves; this never moves, so a flight always ends."""
    stall_bound_s: float = 300.0
    """A vehicle on its route (climbed out, joined it once, not in a loiter) whose progress
    along it stalls or goes backwards for longer than this is lost: it no longer flies its
    mission. Long enough for the turns an aircraft flies on its mission (a turn back to a
    waypoint its climb-out carried it past takes minutes). Measured on its fixes' mission
    times, so a link blackout is no stall."""
    stopped_bound_s: float = 10.0
    """An airborne vehicle past its climb-out whose fixes move less than ``stopped_m`` in this
    long is lost: an aeroplane that stops moving has crashed (a loiter, a hold or a turn
    moves it)."""
    stopped_m: float = 50.0
    on_vehicle_lost: LostPolicy = "continue"
    """The operator's choice when a vehicle is lost (it reported a crash, disarmed on its
    route, or stalled): ``continue``, the others keep their slots; ``retime``, the team time
    moves to the earliest the others can still make together (the lost one no longer holds
    it back); ``abort``, every vehicle is aborted (RTL)."""
    hold_radius_m: float = 300.0
    """The circle an autopilot flies round a hold point is taken to be at most this big
    (ArduPlane's WP_LOITER_RAD, 60 m by default; the stub's 80 m), plus the vehicle's own
    turn radius when that is larger."""
    hold_margin_m: float = 300.0
    """A hold point is at least this far outside the zone beyond that circle."""
    hold_guard_s: float = 60.0
    """The hold is commanded this long (mission s) before the vehicle would reach its hold
    point: room for the command's round trip and a busy machine's scheduling gaps."""
    hold_replan_every_s: float = 60.0
    """A vehicle holding with no route around its zone asks for a re-plan from its hold
    point at most this often."""
    replan_delay_wall_s: float = 0.0
    """Test hook: wall seconds added to every pop-up re-plan job but those a vehicle holding
    short of the zone asks for (a re-plan that comes back too late); not counted in the
    planning time that sets the lead. On a pace clock it is this many wall seconds at the
    clock's rate, waited in mission time, so that a busy machine does not shorten the stretch
    of flight it covers."""

"""Where a vehicle launched from the ground is when its takeoff ends, and when.

ArduPlane flies NAV_TAKEOFF (ArduPlane/takeoff.cpp, commands_logic.cpp ``verify_takeoff``)
as a ground roll at full throttle to the rotate speed, then a full-throttle climb that holds
the ground course the roll started on (``steer_state.hold_course_cd``) at the cruise airspeed
(AIRSPEED_CRUISE: the route's DO_CHANGE_SPEED runs only once the takeoff is done) until the
takeoff altitude; only then does it turn to the next waypoint, straight at it from where it
is. A route whose first waypoints lie inside that climb is flown backwards after it: the
aircraft turns back to them. So the planner places the climb-out on the path's first straight
stretch (the path starts on the takeoff heading) and times the rest of the route from where
the climb ends; the mission's first waypoint after the takeoff lies beyond it
(:func:`climb_out`'s ``first_waypoint_m``).

The climb takes ``roll + h / climb_rate + lag`` seconds whatever the wind; the wind moves
where it ends (the course is held, the aircraft crabs). Pure arithmetic: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from planner.atmosphere import eas2tas
from planner.flightpath import FlightPath
from planner.wind import CALM, Wind, groundspeed_m_s

__all__ = [
    "CLIMB_LAG_S",
    "MIN_TAKEOFF_ALT_M",
    "ROLL_ACCEL_M_S2",
    "ClimbOut",
    "climb_out",
    "straight_start_m",
]

ROLL_ACCEL_M_S2 = 3.0
"""Ground-roll acceleration at full throttle, m/s^2 (a small airframe's, as the simulator's)."""
CLIMB_LAG_S = 1.0
"""The climb rate builds up over about this long after lift-off (TECS's pitch response): the
height comes that much later than at the full rate from the rotate, s."""
AIRSPEED_LAG_S = 3.0
"""The airspeed builds up from the rotate speed to the cruise one with about this time
constant (the throttle is already full): the distance lost to it is the difference times it."""
MIN_TAKEOFF_ALT_M = 30.0
"""The lowest NAV_TAKEOFF altitude given when the straight stretch is short (ArduPlane's
TKOFF_ALT default is 50 m): the rest of the climb is flown along the route."""
MARGIN_TURN_RADII = 2.0
"""The mission's first waypoint lies at least this many turn radii beyond the planned end of
the climb (and at least :data:`MARGIN_FRACTION` of the climb's length), so that a climb that
ends a little late, in a stronger tail wind than forecast, still turns ahead."""
MARGIN_FRACTION = 0.15


@dataclass(frozen=True, slots=True)
class ClimbOut:
    """A takeoff as the autopilot flies it: how high, how long, how far along the path."""

    takeoff_alt_m: float
    """NAV_TAKEOFF altitude above home, m."""
    duration_s: float
    """From arming in AUTO to the takeoff altitude, s."""
    s_m: float
    """Along-path distance where the climb ends (on the path's first straight stretch), m."""
    first_waypoint_m: float
    """No mission waypoint before this along-path distance, m: the first one after the
    takeoff is ahead of the aircraft when it turns to it."""
    climb_rate_m_s: float
    """The full-throttle climb rate it was timed with, m/s."""


def straight_start_m(path: FlightPath) -> float:
    """Length of the path's first straight stretch, m (0 when it starts with a turn)."""
    run = 0.0
    for seg in path.segments:
        if seg.turn != "S":
            break
        run += seg.length_m
    return run


def climb_out(
    path: FlightPath,
    *,
    home_alt_m: float,
    start_alt_m: float,
    cruise_m_s: float,
    rotate_m_s: float,
    climb_rate_m_s: float,
    turn_radius_m: float,
    wind: Wind = CALM,
) -> ClimbOut:
    """Time and place the climb-out of a vehicle that takes off at the start of ``path``.

    Parameters
    ----------
    path
        The route, which starts at home on the takeoff heading.
    home_alt_m
        Ground elevation at home, m AMSL.
    start_alt_m
        The route's altitude at its start, m AMSL: the takeoff climbs to it when the path's
        first straight stretch is long enough, else as high as fits (at least
        :data:`MIN_TAKEOFF_ALT_M`) and the route climbs the rest.
    cruise_m_s, rotate_m_s
        Cruise airspeed (flown in the climb) and rotate speed (lift-off), equivalent, m/s.
    climb_rate_m_s
        The airframe's full-throttle climb rate, m/s (> 0).
    turn_radius_m
        The vehicle's turn radius, m: the margin before the first waypoint counts in it.
    wind
        Forecast wind: moves the climb along the heading (its time does not change).
    """
    if not (math.isfinite(climb_rate_m_s) and climb_rate_m_s > 0.0):
        raise ValueError(f"climb_rate_m_s must be a positive number, got {climb_rate_m_s!r}")
    heading = path.start.heading_rad
    along = wind.to_east_m_s * math.sin(heading) + wind.to_north_m_s * math.cos(heading)
    # Ground roll: the wheels roll until the air over the wing reaches the rotate speed.
    rotate_tas = rotate_m_s * eas2tas(home_alt_m)
    roll_gs = max(rotate_tas + along, 0.0)
    roll_s = roll_gs / ROLL_ACCEL_M_S2
    roll_m = 0.5 * roll_gs * roll_s

    def climb(height_m: float) -> tuple[float, float]:
        """Duration (s) and ground distance (m) of the climb of ``height_m`` after lift-off."""
        tas = cruise_m_s * eas2tas(home_alt_m + 0.5 * height_m)
        level = math.sqrt(max(tas * tas - climb_rate_m_s * climb_rate_m_s, 1.0))
        gs = float(groundspeed_m_s(level, heading, wind))
        lost_m = max(tas - rotate_tas, 0.0) * AIRSPEED_LAG_S
        climb_s = height_m / climb_rate_m_s + CLIMB_LAG_S
        return climb_s, max(gs * climb_s - lost_m, 0.0)

    full_m = max(start_alt_m - home_alt_m, 1.0)
    straight = straight_start_m(path)
    climb_s, climb_m = climb(full_m)
    height = full_m
    margin = max(MARGIN_TURN_RADII * turn_radius_m, MARGIN_FRACTION * (roll_m + climb_m))
    if roll_m + climb_m + margin > straight and full_m > MIN_TAKEOFF_ALT_M:
        # As high as fits the straight stretch with the margin; the route climbs the rest.
        lo, hi = MIN_TAKEOFF_ALT_M, full_m
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            _, m = climb(mid)
            need = max(MARGIN_TURN_RADII * turn_radius_m, MARGIN_FRACTION * (roll_m + m))
            lo, hi = (mid, hi) if roll_m + m + need <= straight else (lo, mid)
        height = lo
        climb_s, climb_m = climb(height)
        margin = max(MARGIN_TURN_RADII * turn_radius_m, MARGIN_FRACTION * (roll_m + climb_m))
    s_m = min(roll_m + climb_m, path.length_m)
    return ClimbOut(
        takeoff_alt_m=height,
        duration_s=roll_s + climb_s,
        s_m=s_m,
        first_waypoint_m=min(s_m + margin, path.length_m),
        climb_rate_m_s=climb_rate_m_s,
    )

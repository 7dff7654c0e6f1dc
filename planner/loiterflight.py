"""How ArduPlane flies a NAV_LOITER_TURNS spliced after a route waypoint, as lengths.

The mission puts the loiter right after the route waypoint at its entry point (``s_m`` on the
path). ArduPlane starts the item there (ArduPlane/navigation.cpp ``update_loiter``): farther
than 3 radii from the loiter point it flies straight at it, then the L1 loiter law
(``AP_L1_Control::update_loiter``) captures the circle; it counts the turns from where it is
on the circle (``reached_loiter_target``, commands_logic.cpp ``verify_loiter_turns``), and
after them keeps circling until its ground course points at the next waypoint within 10
degrees (mode_loiter.cpp ``isHeadingLinedUp``), then leaves on that course. So besides its
whole turns a loiter adds:

* the entry: from the waypoint to the circle, straight at the loiter point (nothing when the
  circle is tangent to the route at the waypoint, as in the paper's buffer loiters);
* the line-up: the arc after the turns until the course points along the route, up to most
  of a turn when the circle was entered from a detour (a circle entered from straight out
  lines up on the course away from it three quarters of a turn later);
* the exit: from where it leaves the circle back to abreast of the waypoint (negative when
  it leaves ahead of it).

A waypoint inside the circle (a buffer's circle centred near the route) is reached at its
turn distance, min(WP_RADIUS, the L1 distance), before it: the item starts there, near the
centre, and the turns are counted from that bearing. Heading at the centre, the loiter law
turns the aircraft against the loiter's direction at the roll limit until it heads straight
out, and the bearing it sweeps on the way through the centre counts towards the turns
(ArduPlane's ``loiter_angle_update``): the loiter then adds the way out, less the route it
cuts short and the part of the turns counted on the way (so its line-up may be negative).

The route after the waypoint is taken as straight along its heading there and the next
waypoint as far (its bearing from the circle is the route's heading); the turn onto the
entry line at the waypoint, flown at the autopilot's roll limit, is left out. Conventions:
metres, compass radians (0 = north, clockwise), a unit direction ``(sin h, cos h)`` in
(east, north). Pure arithmetic: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from planner.atmosphere import GRAVITY_M_S2

__all__ = ["LINED_UP_RAD", "LoiterFlight", "loiter_flight", "way_out_m"]

_TAU = 2.0 * math.pi
WP_RADIUS_M = 90.0
"""ArduPlane's default WP_RADIUS, m."""
L1_PERIOD_S = 17.0
L1_DAMPING = 0.75
"""ArduPlane's default NAVL1_PERIOD, s, and NAVL1_DAMPING."""
ROLL_LIMIT_RAD = math.radians(45.0)
"""ArduPlane's default roll limit (ROLL_LIMIT_DEG)."""
LINED_UP_RAD = math.radians(10.0)
"""How far off the next waypoint's bearing the course may be for ArduPlane to leave the
circle after its turns (``isHeadingLinedUp``: 10 degrees, wider only after a whole circle of
line-up)."""


@dataclass(frozen=True, slots=True)
class LoiterFlight:
    """What a loiter adds to the route besides its whole turns, m; and where it is flown."""

    entry_m: float
    """From the waypoint to the circle, where the turns are counted from."""
    line_up_m: float
    """On the circle after the whole turns, until the course points along the route."""
    exit_m: float
    """From where it leaves the circle to abreast of the waypoint along the route (negative:
    it leaves ahead of it)."""
    counted_from_rad: float
    """Compass bearing from the centre of the point the turns are counted from."""
    leaves_at_rad: float
    """Compass bearing from the centre of the point it leaves the circle at."""

    @property
    def added_m(self) -> float:
        """Everything it adds besides the whole turns (never negative), m."""
        return max(self.entry_m + self.line_up_m + self.exit_m, 0.0)


def loiter_flight(
    entry_east_m: float,
    entry_north_m: float,
    heading_rad: float,
    centre_east_m: float,
    centre_north_m: float,
    radius_m: float,
    *,
    clockwise: bool,
    ground_speed_m_s: float = 20.0,
) -> LoiterFlight:
    """How ArduPlane flies a loiter entered at a route waypoint (see the module docstring).

    Parameters
    ----------
    entry_east_m, entry_north_m
        The waypoint the loiter follows, m.
    heading_rad
        The route's compass heading there (and on after it), rad.
    centre_east_m, centre_north_m, radius_m
        The loiter circle, m (radius > 0).
    clockwise
        Its way round.

    Returns
    -------
    LoiterFlight
        Its entry, line-up and exit lengths, m (the turns themselves are ``2 pi r`` each).
    """
    if not radius_m > 0.0:
        raise ValueError(f"radius_m must be > 0, got {radius_m!r}")
    sign = 1.0 if clockwise else -1.0
    de, dn = entry_east_m - centre_east_m, entry_north_m - centre_north_m
    d = math.hypot(de, dn)
    if d < radius_m * (1.0 - 1e-6):
        return _from_inside(de, dn, heading_rad, radius_m, sign, ground_speed_m_s)
    # Straight at the centre from outside.
    entry_m = d - radius_m
    counted = math.atan2(de, dn)
    sweep, leaves = _line_up(counted, heading_rad, sign)
    along_m = _along(de, dn, heading_rad, radius_m, leaves)
    return LoiterFlight(entry_m, sweep * radius_m, -along_m, _wrap(counted), _wrap(leaves))


def way_out_m(de: float, dn: float, course_rad: float, ground_speed_m_s: float) -> float:
    """How far an aircraft taken out of its turns flies to the waypoint it is sent to, m.

    ArduPlane made to fly the item after its NAV_LOITER_TURNS (MISSION_SET_CURRENT) leaves
    the circle at once and flies at the waypoint: from its course, it turns towards it at the
    roll limit (the L1 law asks more than the limit allows for a large heading error), then
    flies straight. ``(de, dn)``: the waypoint from the aircraft, m; ``course_rad``: its
    ground course. A waypoint inside both turning circles (nearer than one can reach
    turning) is counted as half a turn more than the straight line.
    """
    rho = _turn_radius_m(ground_speed_m_s)
    straight_m = math.hypot(de, dn)
    if rho <= 0.0:
        return straight_m
    best = math.inf
    for sign in (1.0, -1.0):  # clockwise (right), anticlockwise (left)
        # The turn's centre, to that side of the course.
        ce = sign * rho * math.cos(course_rad)
        cn = -sign * rho * math.sin(course_rad)
        we, wn = de - ce, dn - cn
        d = math.hypot(we, wn)
        if d < rho:
            continue
        # Bearing (from the centre) of where it starts on the circle, and of where the line
        # to the waypoint leaves it tangentially.
        start = course_rad - sign * 0.5 * math.pi
        leave = math.atan2(we, wn) - sign * math.acos(rho / d)
        turn = (sign * (leave - start)) % _TAU
        if turn > _TAU - 1e-9:  # round-off of no turn at all
            turn = 0.0
        best = min(best, rho * turn + math.sqrt(d * d - rho * rho))
    return best if math.isfinite(best) else straight_m + math.pi * rho


def _turn_radius_m(ground_speed_m_s: float) -> float:
    """The radius of a turn at the roll limit, m."""
    return ground_speed_m_s**2 / (GRAVITY_M_S2 * math.tan(ROLL_LIMIT_RAD))


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def _line_up(counted: float, heading_rad: float, sign: float) -> tuple[float, float]:
    """The arc (rad) after the whole turns, counted from ``counted``, until the course is
    within the tolerance of the route's; and the bearing it leaves the circle at."""
    course = counted + sign * 0.5 * math.pi
    ahead = (sign * (heading_rad - course)) % _TAU
    sweep = 0.0 if ahead <= LINED_UP_RAD or ahead >= _TAU - LINED_UP_RAD else ahead - LINED_UP_RAD
    return sweep, counted + sign * sweep


def _along(de: float, dn: float, heading_rad: float, radius_m: float, at_rad: float) -> float:
    """How far along the route the circle's point at bearing ``at_rad`` is past the point
    (de, dn) off the centre, m."""
    xe = radius_m * math.sin(at_rad) - de
    xn = radius_m * math.cos(at_rad) - dn
    return xe * math.sin(heading_rad) + xn * math.cos(heading_rad)


def _from_inside(
    de: float, dn: float, heading_rad: float, radius_m: float, sign: float, ground_speed_m_s: float
) -> LoiterFlight:
    """The waypoint (de, dn) off the centre, inside the circle (see the module docstring)."""
    ue, un = math.sin(heading_rad), math.cos(heading_rad)
    # Where the item starts: the waypoint is reached its turn distance before it.
    to_centre = math.atan2(-de, -dn) if math.hypot(de, dn) > 1e-9 * radius_m else heading_rad
    turn = abs(math.remainder(to_centre - heading_rad, _TAU))
    l1_m = L1_DAMPING * L1_PERIOD_S * ground_speed_m_s / math.pi
    early_m = min(WP_RADIUS_M, l1_m) * min(turn, 0.5 * math.pi) / (0.5 * math.pi)
    pe, pn = de - early_m * ue, dn - early_m * un
    if math.hypot(pe, pn) <= 1e-9 * radius_m:
        counted = heading_rad - sign * 0.5 * math.pi
    else:
        counted = math.atan2(pe, pn)
    # Headed at the centre, the circle law turns it against the loiter's way round at the roll
    # limit until it heads straight out: the centre passes on the loiter's side.
    rho = _turn_radius_m(ground_speed_m_s)
    course, way_m, gained, bearing = heading_rad, 0.0, 0.0, counted
    step = min(1.0, 0.02 * rho)
    toward = pe * math.sin(course) + pn * math.cos(course) < 0.0
    # Until it heads out (or, just past the centre, turning would only head it farther off).
    while (
        toward
        and way_m < _TAU * rho
        and (
            pe * math.sin(course) + pn * math.cos(course) < 0.0
            or sign * math.remainder(course - math.atan2(pe, pn), _TAU) > math.radians(1.0)
        )
    ):
        pe, pn = pe + step * math.sin(course), pn + step * math.cos(course)
        course -= sign * step / rho
        way_m += step
        now = math.atan2(pe, pn)
        gained += sign * math.remainder(now - bearing, _TAU)
        bearing = now
    # Straight on to the circle.
    ce, cn = math.sin(course), math.cos(course)
    b = pe * ce + pn * cn
    out_m = max(-b + math.sqrt(max(b * b - (pe * pe + pn * pn - radius_m**2), 0.0)), 0.0)
    qe, qn = pe + out_m * ce, pn + out_m * cn
    gained += sign * math.remainder(math.atan2(qe, qn) - bearing, _TAU)
    way_m += out_m
    sweep, leaves = _line_up(counted, heading_rad, sign)
    along_m = _along(de, dn, heading_rad, radius_m, leaves)
    return LoiterFlight(
        way_m - early_m,
        (sweep - gained) * radius_m,
        -along_m,
        _wrap(counted),
        _wrap(leaves),
    )

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

The route after the waypoint is taken as straight along its heading there and the next
waypoint as far (its bearing from the circle is the route's heading); the turn onto the
entry line at the waypoint, flown at the autopilot's roll limit, is left out. Conventions:
metres, compass radians (0 = north, clockwise), a unit direction ``(sin h, cos h)`` in
(east, north). Pure arithmetic: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["LINED_UP_RAD", "LoiterFlight", "loiter_flight"]

_TAU = 2.0 * math.pi
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
    # Straight at the centre from outside; from inside the L1 circle law holds at once and
    # the turns are counted from there (the spiral out is inside the first turn).
    entry_m = max(d - radius_m, 0.0)
    # At the centre itself: counted from where the route's course is the circle's.
    on_centre = d <= 1e-9 * radius_m
    counted = heading_rad - sign * 0.5 * math.pi if on_centre else math.atan2(de, dn)
    course = counted + sign * 0.5 * math.pi
    # The arc, the loiter's way round, until the course is within the tolerance of the route.
    ahead = (sign * (heading_rad - course)) % _TAU
    sweep = 0.0 if ahead <= LINED_UP_RAD or ahead >= _TAU - LINED_UP_RAD else ahead - LINED_UP_RAD
    leaves = counted + sign * sweep
    xe = centre_east_m + radius_m * math.sin(leaves)
    xn = centre_north_m + radius_m * math.cos(leaves)
    along_m = (xe - entry_east_m) * math.sin(heading_rad) + (xn - entry_north_m) * math.cos(
        heading_rad
    )
    return LoiterFlight(
        entry_m,
        sweep * radius_m,
        -along_m,
        math.atan2(math.sin(counted), math.cos(counted)),
        math.atan2(math.sin(leaves), math.cos(leaves)),
    )

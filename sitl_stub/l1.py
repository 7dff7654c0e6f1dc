"""ArduPilot's L1 lateral navigation controller (``AP_L1_Control``), as pure functions.

Both work in a local north/east frame with the vehicle at the origin and return a lateral
acceleration demand (m/s^2, positive = turn right) that the autopilot turns into a bank
angle: :func:`l1_waypoint` tracks the line from the previous waypoint to the next one,
:func:`l1_loiter` captures and holds a circle.
"""

from __future__ import annotations

import math

_TWO_PI = 2.0 * math.pi


def wrap_pi(a: float) -> float:
    """``a`` wrapped into [-pi, pi)."""
    return (a + math.pi) % _TWO_PI - math.pi


def clamp(x: float, lo: float, hi: float) -> float:
    """``x`` limited to [lo, hi]."""
    return lo if x < lo else hi if x > hi else x


def l1_waypoint(
    an: float,
    ae: float,
    bn: float,
    be: float,
    vn: float,
    ve: float,
    heading_rad: float,
    period_s: float,
    damping: float,
) -> tuple[float, float, float]:
    """AP_L1_Control::update_waypoint with the vehicle at the origin of a local N/E frame.

    A=(an, ae) is the previous waypoint, B=(bn, be) the next. Returns (lateral acceleration
    demand m/s^2, positive = turn right; nav bearing rad; cross-track error m).
    """
    gs = math.hypot(vn, ve)
    if gs < 0.1:
        vn = 0.1 * math.cos(heading_rad)
        ve = 0.1 * math.sin(heading_rad)
        gs = 0.1
    l1 = 0.3183099 * damping * period_s * gs
    if l1 < 0.1:  # limits written out, not max()/clamp() calls: this runs every step
        l1 = 0.1
    abn = bn - an
    abe = be - ae
    ab_len = math.hypot(abn, abe)
    if ab_len < 1.0e-3:
        abn, abe = bn, be
        ab_len = math.hypot(abn, abe)
        if ab_len < 1.0e-3:
            abn, abe, ab_len = math.cos(heading_rad), math.sin(heading_rad), 1.0
    abn /= ab_len
    abe /= ab_len
    a_n = -an  # vehicle relative to A
    a_e = -ae
    wp_a_dist = math.hypot(a_n, a_e)
    along = a_n * abn + a_e * abe
    xtrack = a_n * abe - a_e * abn
    if wp_a_dist > l1 and along / max(wp_a_dist, 1.0) < -0.7071:
        un, ue = -a_n / wp_a_dist, -a_e / wp_a_dist  # toward A
        nu = math.atan2(vn * ue - ve * un, vn * un + ve * ue)
        nav_bearing = math.atan2(ue, un)
    elif along > ab_len + gs * 3.0:
        d = max(math.hypot(bn, be), 1e-6)
        un, ue = bn / d, be / d  # toward B
        nu = math.atan2(vn * ue - ve * un, vn * un + ve * ue)
        nav_bearing = math.atan2(ue, un)
    else:
        nu2 = math.atan2(vn * abe - ve * abn, vn * abn + ve * abe)
        sin_nu1 = xtrack / l1
        nu1 = math.asin(-0.7071 if sin_nu1 < -0.7071 else 0.7071 if sin_nu1 > 0.7071 else sin_nu1)
        nu = nu1 + nu2
        nav_bearing = math.atan2(abe, abn) + nu1
    nu = -1.5708 if nu < -1.5708 else 1.5708 if nu > 1.5708 else nu
    lat_acc = 4.0 * damping * damping * gs * gs / l1 * math.sin(nu)
    return lat_acc, nav_bearing, xtrack


def l1_loiter(
    cn: float,
    ce: float,
    radius_m: float,
    direction: int,
    vn: float,
    ve: float,
    heading_rad: float,
    period_s: float,
    damping: float,
) -> tuple[float, float, bool]:
    """AP_L1_Control::update_loiter; centre (cn, ce) relative to the vehicle.

    direction +1 = clockwise. Returns (lateral acceleration demand, nav bearing, on_circle).
    """
    omega = _TWO_PI / period_s
    gs = math.hypot(vn, ve)
    l1 = max(0.3183099 * damping * period_s * gs, 0.1)
    a_n = -cn
    a_e = -ce
    a_len = math.hypot(a_n, a_e)
    if a_len > 0.1:
        un, ue = a_n / a_len, a_e / a_len
    elif gs < 0.1:
        un, ue = math.cos(heading_rad), math.sin(heading_rad)
    else:
        un, ue = vn / gs, ve / gs
    xvel_cap = un * ve - ue * vn
    ltrack_cap = -(vn * un + ve * ue)
    nu = clamp(math.atan2(xvel_cap, ltrack_cap), -1.5708, 1.5708)
    lat_cap = 4.0 * damping * damping * gs * gs / l1 * math.sin(nu)
    xerr = a_len - radius_m
    pd = xerr * omega * omega + (-ltrack_cap) * 2.0 * damping * omega
    vel_tangent = xvel_cap * direction
    if ltrack_cap < 0.0 and vel_tangent < 0.0:
        pd = max(pd, 0.0)
    ctr = vel_tangent * vel_tangent / max(0.5 * radius_m, radius_m + xerr)
    circ = direction * (pd + ctr)
    nav_bearing = math.atan2(-ue, -un)
    if xerr > 0.0 and direction * lat_cap < direction * circ:
        return lat_cap, nav_bearing, False
    return circ, nav_bearing, True

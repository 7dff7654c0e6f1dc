"""Team coupling used while planning: arrival windows and pairwise separation (eq. 1).

Each vehicle's feasible arrival window follows from its path length, its speed range and its
allowed takeoff window: ``[takeoff_lo + L / v_max, takeoff_hi + L / v_min]``. The team
constraint asks the windows (shifted by the arrival slots for spaced arrivals, or clipped to
the per-vehicle windows) to intersect. For separation the planner assumes each vehicle flies
its path at constant speed to its nominal arrival time; the scheduler refines that later.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class TimingLimits:
    """What bounds one vehicle's arrival: speeds (m/s), takeoff window (s), slot offset (s)."""

    speed_min_m_s: float
    speed_max_m_s: float
    cruise_m_s: float
    takeoff_lo_s: float
    takeoff_hi_s: float
    slot_offset_s: float = 0.0
    window_lo_s: float = -math.inf
    window_hi_s: float = math.inf


@dataclass(frozen=True, slots=True)
class TeamTiming:
    """The team's arrival reference and each vehicle's nominal takeoff, arrival and speed."""

    gap_s: float
    reference_s: float
    takeoff_s: tuple[float, ...]
    arrival_s: tuple[float, ...]
    speed_m_s: tuple[float, ...]


def windows(lengths_m: FloatArray, limits: Sequence[TimingLimits]) -> tuple[FloatArray, FloatArray]:
    """Feasible arrival windows ``(t_min, t_max)`` (s) for path lengths ``(..., M)``."""
    lo = np.array([lim.takeoff_lo_s for lim in limits])
    hi = np.array([lim.takeoff_hi_s for lim in limits])
    vmax = np.array([lim.speed_max_m_s for lim in limits])
    vmin = np.array([lim.speed_min_m_s for lim in limits])
    return lo + lengths_m / vmax, hi + lengths_m / vmin


def window_gap_s(
    lengths_m: FloatArray, limits: Sequence[TimingLimits], required_s: float | None
) -> FloatArray:
    """Seconds by which the team constraint is missed (0 when feasible), for ``(..., M)``.

    Windows are shifted by each vehicle's slot offset and clipped to its own window; with a
    required reference time, the miss is the summed distance of that time from each window.
    """
    t_min, t_max = windows(lengths_m, limits)
    offset = np.array([lim.slot_offset_s for lim in limits])
    own_lo = np.array([lim.window_lo_s for lim in limits])
    own_hi = np.array([lim.window_hi_s for lim in limits])
    own_gap = np.maximum(t_min - own_hi, 0.0) + np.maximum(own_lo - t_max, 0.0)
    lo = np.maximum(t_min, own_lo) - offset
    hi = np.minimum(t_max, own_hi) - offset
    if required_s is not None:
        miss = np.maximum(lo - required_s, 0.0) + np.maximum(required_s - hi, 0.0)
        return np.asarray(miss.sum(axis=-1) + own_gap.sum(axis=-1), dtype=np.float64)
    team_gap = np.maximum(lo.max(axis=-1) - hi.min(axis=-1), 0.0)
    return np.asarray(team_gap + own_gap.sum(axis=-1), dtype=np.float64)


def team_timing(
    lengths_m: Sequence[float], limits: Sequence[TimingLimits], required_s: float | None
) -> TeamTiming:
    """Nominal timing: the earliest common reference, takeoffs and constant speeds."""
    lengths = np.asarray(lengths_m, dtype=np.float64)
    gap = float(window_gap_s(lengths, limits, required_s))
    t_min, t_max = windows(lengths, limits)
    offset = np.array([lim.slot_offset_s for lim in limits])
    own_lo = np.array([lim.window_lo_s for lim in limits])
    lo = np.maximum(t_min, own_lo) - offset
    ref = float(lo.max()) if required_s is None else required_s
    takeoff, arrival, speed = [], [], []
    for length, lim, off, tmin, tmax in zip(lengths, limits, offset, t_min, t_max, strict=True):
        target = min(max(ref + off, tmin), tmax)
        if math.isfinite(lim.window_lo_s) or math.isfinite(lim.window_hi_s):
            target = min(max(target, lim.window_lo_s), lim.window_hi_s)
            target = min(max(target, tmin), tmax)
        depart = min(max(target - length / lim.cruise_m_s, lim.takeoff_lo_s), lim.takeoff_hi_s)
        v = length / max(target - depart, 1e-9)
        v = min(max(v, lim.speed_min_m_s), lim.speed_max_m_s)
        takeoff.append(depart)
        speed.append(v)
        arrival.append(depart + length / v)
    return TeamTiming(gap, ref, tuple(takeoff), tuple(arrival), tuple(speed))


def positions_at(
    points_m: FloatArray, takeoff_s: float, speed_m_s: float, times_s: FloatArray
) -> FloatArray:
    """Positions (T, 2) along a polyline flown at constant speed from ``takeoff_s``."""
    seg = np.hypot(np.diff(points_m[:, 0]), np.diff(points_m[:, 1]))
    s_knots = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.clip((times_s - takeoff_s) * speed_m_s, 0.0, s_knots[-1])
    return np.stack(
        [np.interp(s, s_knots, points_m[:, 0]), np.interp(s, s_knots, points_m[:, 1])], axis=-1
    )


def pair_min_separation(
    a_points_m: FloatArray,
    a_takeoff_s: float,
    a_speed_m_s: float,
    b_points_m: FloatArray,
    b_takeoff_s: float,
    b_speed_m_s: float,
    step_s: float,
) -> tuple[float, float]:
    """Minimum horizontal distance (m) while both fly, and its time (s); inf if never both."""
    a_len = float(np.hypot(*np.diff(a_points_m, axis=0).T).sum())
    b_len = float(np.hypot(*np.diff(b_points_m, axis=0).T).sum())
    t0 = max(a_takeoff_s, b_takeoff_s)
    t1 = min(a_takeoff_s + a_len / a_speed_m_s, b_takeoff_s + b_len / b_speed_m_s)
    if t1 <= t0:
        return math.inf, math.nan
    n = max(2, int(math.ceil((t1 - t0) / step_s)) + 1)
    t = np.linspace(t0, t1, n)
    pa = positions_at(a_points_m, a_takeoff_s, a_speed_m_s, t)
    pb = positions_at(b_points_m, b_takeoff_s, b_speed_m_s, t)
    d = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
    k = int(np.argmin(d))
    return float(d[k]), float(t[k])

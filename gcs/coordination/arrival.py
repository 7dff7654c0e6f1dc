"""The arrival-time controller: sans-IO, pure arithmetic over a planned route.

Eqs. (6)-(7) of the reference paper, closed loop. On each position fix the coordinator asks
:meth:`ArrivalController.decide` which airspeed to fly: the continuous airspeed that arrives
exactly on time (the remaining route, its loiters and the wind, solved for the airspeed), then
clamped to the vehicle's range and quantised to its speed steps, with hysteresis: a level is
held until the required airspeed is a full step away from it. As the time left shrinks the
required airspeed diverges from a wrong level ever faster, so the switching behaves like a
sigma-delta modulator whose arrival error converges to about zero.

Conventions: ``east_m``/``north_m`` in metres, compass angles in radians (0 = north, clockwise
positive, so a unit direction is ``(sin h, cos h)`` in (east, north)), speeds in m/s, times in
seconds on any consistent mission time base. No clock, no I/O: everything is passed in.

The route, its loiters and the wind triangle are :mod:`gcs.coordination.routetrack`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from gcs.coordination.routetrack import (
    ArrivalInputError,
    Remaining,
    RouteTrack,
    require_finite,
)
from planner.wind import Wind

__all__ = [
    "ArrivalController",
    "Decision",
    "SpeedLimits",
    "Verdict",
]

FloatArray = NDArray[np.float64]
AnyFloatArray = NDArray[np.floating[Any]]

# The airspeed solve stops when the time to go is this close to the time left (relative), or
# the bracket is this narrow, m/s.
_SOLVE_REL_TOL_S = 1e-9
_SOLVE_BRACKET_M_S = 1e-9
_SOLVE_MAX_ITER = 100
# Speeds closer than this are the same level, m/s.
_SAME_LEVEL_M_S = 1e-9


@dataclass(frozen=True, slots=True)
class SpeedLimits:
    """A vehicle's airspeed range and command step, m/s.

    The levels are ``min, min + step, min + 2 step, ...`` up to ``max``, and ``max`` itself
    (always a level, even when it is not on the step grid).
    """

    airspeed_min_m_s: float
    airspeed_max_m_s: float
    step_m_s: float = 0.5
    _levels: tuple[float, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        lo, hi, step = self.airspeed_min_m_s, self.airspeed_max_m_s, self.step_m_s
        if not (math.isfinite(lo) and lo > 0.0):
            raise ArrivalInputError(f"airspeed_min_m_s must be finite and > 0, got {lo!r}")
        if not (math.isfinite(hi) and hi >= lo):
            raise ArrivalInputError(
                f"airspeed_max_m_s must be finite and >= airspeed_min_m_s={lo!r}, got {hi!r}"
            )
        if not (math.isfinite(step) and step > 0.0):
            raise ArrivalInputError(f"step_m_s must be finite and > 0, got {step!r}")
        lo, hi, step = float(lo), float(hi), float(step)
        object.__setattr__(self, "airspeed_min_m_s", lo)
        object.__setattr__(self, "airspeed_max_m_s", hi)
        object.__setattr__(self, "step_m_s", step)
        n_steps = math.floor((hi - lo) / step + 1e-9)
        levels = [min(lo + k * step, hi) for k in range(n_steps + 1)]
        if hi - levels[-1] > _SAME_LEVEL_M_S:
            levels.append(hi)
        else:
            levels[-1] = hi
        object.__setattr__(self, "_levels", tuple(levels))

    @property
    def levels_m_s(self) -> tuple[float, ...]:
        """Every level that may be commanded, ascending, m/s."""
        return self._levels

    def nearest_level_m_s(self, airspeed_m_s: float) -> float:
        """The level nearest to an airspeed (clamped to the range; ties go up), m/s."""
        lo, hi, step = self.airspeed_min_m_s, self.airspeed_max_m_s, self.step_m_s
        if not airspeed_m_s > lo:  # also nan
            return lo
        if airspeed_m_s >= hi:
            return hi
        k = min(math.floor((airspeed_m_s - lo) / step + 0.5), len(self._levels) - 1)
        candidates = self._levels[max(k - 1, 0) : k + 2]
        return min(candidates, key=lambda level: (abs(level - airspeed_m_s), -level))


Verdict = Literal["on_time", "early", "late"]


@dataclass(frozen=True, slots=True)
class Decision:
    """One decision of the arrival controller (speeds m/s, times s on the caller's base).

    ``verdict``: ``"early"`` when even at the minimum airspeed (held) the vehicle arrives more
    than the tolerance early, ``"late"`` when even at the maximum it arrives more than the
    tolerance late, else ``"on_time"``. ``command_m_s`` is the level to command now, or None
    to keep what the vehicle flies; ``level_m_s`` is what it should fly after this decision.
    ``required_m_s`` is the continuous airspeed that arrives exactly on time (may be outside
    the limits; inf if unreachable). ``eta_s`` is the arrival flying ``level_m_s``,
    ``eta_min_s`` at the maximum airspeed, ``eta_max_s`` at the minimum; ``error_s`` is
    ``eta_s - target_s``. ``reason`` is one sentence with the numbers.
    """

    verdict: Verdict
    command_m_s: float | None
    level_m_s: float
    required_m_s: float
    eta_s: float
    eta_min_s: float
    eta_max_s: float
    error_s: float
    reason: str


def _solve_airspeed(
    remaining: Remaining, time_left_s: float, lo_m_s: float, hi_m_s: float
) -> float:
    """Airspeed (m/s) whose time to go equals ``time_left_s``, searched in [lo, hi].

    inf if even ``hi`` is too slow; ``lo`` if even ``lo`` is fast enough. Newton's method on
    ``1 / time`` (exactly linear in airspeed in still air, so one step there), safeguarded by
    bisection of the bracket.
    """
    time_hi_s = remaining.time_s(hi_m_s)
    if not time_hi_s <= time_left_s:
        return math.inf
    time_lo_s = remaining.time_s(lo_m_s)
    if time_lo_s <= time_left_s:
        return lo_m_s
    # Now time(lo) > time_left >= time(hi) >= 0, so time_left > 0 and time(hi) > 0.
    rate_lo, rate_hi = 1.0 / time_lo_s, 1.0 / time_hi_s  # 1/inf = 0 where lo cannot fly
    goal = 1.0 / time_left_s
    airspeed = lo_m_s + (goal - rate_lo) * (hi_m_s - lo_m_s) / (rate_hi - rate_lo)
    for _ in range(_SOLVE_MAX_ITER):
        if not lo_m_s < airspeed < hi_m_s:
            airspeed = 0.5 * (lo_m_s + hi_m_s)
        time_s, d_time = remaining.time_and_slope(airspeed)
        if abs(time_s - time_left_s) <= _SOLVE_REL_TOL_S * time_left_s:
            return airspeed
        if time_s > time_left_s:
            lo_m_s = airspeed
        else:
            hi_m_s = airspeed
        if hi_m_s - lo_m_s <= _SOLVE_BRACKET_M_S:
            break
        if math.isfinite(time_s) and math.isfinite(d_time) and d_time < 0.0:
            airspeed -= time_s * (time_s - time_left_s) / (time_left_s * d_time)
        else:
            airspeed = 0.5 * (lo_m_s + hi_m_s)
    return 0.5 * (lo_m_s + hi_m_s)


def _same(a_m_s: float, b_m_s: float) -> bool:
    return abs(a_m_s - b_m_s) <= _SAME_LEVEL_M_S


class ArrivalController:
    """Eqs. (6)-(7) of the reference paper, closed loop.

    Required airspeed = what flies the remaining route in the time left (solved with the
    wind), clamped to the range, quantised to the step grid, and held until it is a full step
    off.

    Parameters
    ----------
    limits : SpeedLimits
        Airspeed range and step, m/s.
    tolerance_s : float, optional
        Arrival error (s, >= 0) within which the vehicle still counts as on time when the
        range cannot do better. Default 0.5 s.
    """

    def __init__(self, limits: SpeedLimits, *, tolerance_s: float = 0.5) -> None:
        if not (math.isfinite(tolerance_s) and tolerance_s >= 0.0):
            raise ArrivalInputError(f"tolerance_s must be finite and >= 0, got {tolerance_s!r}")
        self.limits = limits
        self.tolerance_s = float(tolerance_s)

    def decide(
        self,
        track: RouteTrack,
        *,
        s_m: float,
        now_s: float,
        target_s: float,
        wind: Wind,
        current_level_m_s: float | None,
        loiters_done: int = 0,
        loiter_flown_m: float = 0.0,
        tas_per_eas: float = 1.0,
    ) -> Decision:
        """Decide the airspeed level to fly from a position fix.

        Parameters
        ----------
        track : RouteTrack
            The vehicle's route and loiters.
        s_m : float
            Where the vehicle is along the path, m (e.g. from :meth:`RouteTrack.locate`).
        now_s, target_s : float
            The time of the fix and the required arrival, s (same time base).
        wind : Wind
            Air-mass velocity, m/s.
        current_level_m_s : float, optional
            The level the vehicle was last commanded (or flies), m/s; None if unknown. A
            level outside the limits counts as unknown (it is always replaced).
        loiters_done : int, optional
            Number of loiters already flown.
        loiter_flown_m : float, optional
            Distance already flown in the loiter in progress, m (extension; default 0).
        tas_per_eas : float, optional
            True airspeed flown per unit of commanded airspeed (> 0): the limits, levels and
            commands are the autopilot's (equivalent airspeed on ArduPlane), the route is
            flown at this many times that (the atmosphere's EAS2TAS, times any bias learnt
            in flight). Default 1: commands are true airspeed.

        Returns
        -------
        Decision
            Verdict, command (or None), level, required airspeed, ETAs (s) and the reason.
        """
        limits = self.limits
        lo, hi, step = limits.airspeed_min_m_s, limits.airspeed_max_m_s, limits.step_m_s
        now_s = require_finite("now_s", now_s)
        target_s = require_finite("target_s", target_s)
        if not (math.isfinite(tas_per_eas) and tas_per_eas > 0.0):
            raise ArrivalInputError(f"tas_per_eas must be finite and > 0, got {tas_per_eas!r}")
        remaining = replace(
            track.remaining(s_m, wind, loiters_done, loiter_flown_m), tas_per_eas=tas_per_eas
        )
        time_left_s = target_s - now_s
        times: dict[float, float] = {}

        def eta_at(airspeed_m_s: float) -> float:
            if airspeed_m_s not in times:
                times[airspeed_m_s] = remaining.time_s(airspeed_m_s)
            return now_s + times[airspeed_m_s]

        required = _solve_airspeed(remaining, time_left_s, 0.5 * lo, 2.0 * hi)
        eta_min_s, eta_max_s = eta_at(hi), eta_at(lo)
        current = current_level_m_s
        if current is not None and not (
            math.isfinite(current) and lo - _SAME_LEVEL_M_S <= current <= hi + _SAME_LEVEL_M_S
        ):
            current = None
        over = f"over {remaining.total_m / 1000.0:.1f} km in {time_left_s:.1f} s"
        if math.isinf(required):
            ask = f"no airspeed up to {2.0 * hi:.1f} m/s arrives on time {over}"
        elif required <= 0.5 * lo:
            ask = f"required at most {required:.2f} m/s airspeed {over}"
        else:
            ask = f"required {required:.2f} m/s airspeed {over}"
        verdict: Verdict = "on_time"
        if required > hi:
            level = hi
            late_s = eta_min_s - target_s
            if late_s > self.tolerance_s:
                verdict = "late"
            reason = (
                f"{ask}: above the {hi:.1f} m/s maximum; at {hi:.1f} m/s arrives "
                f"{late_s:.1f} s late"
            )
        elif required < lo:
            level = lo
            early_s = target_s - eta_max_s
            if early_s > self.tolerance_s:
                verdict = "early"
            reason = (
                f"{ask}: below the {lo:.1f} m/s minimum; at {lo:.1f} m/s arrives "
                f"{early_s:.1f} s early"
            )
        elif current is None or abs(required - current) >= step:
            level = limits.nearest_level_m_s(required)
            reason = f"{ask}: the nearest level is {level:.1f} m/s"
        else:
            level = current
            reason = f"{ask}: within one {step:g} m/s step of {level:.1f} m/s"
        if verdict != "on_time":
            reason = f"{verdict}: {reason}"
        elif required > hi or required < lo:
            reason += f", within the {self.tolerance_s:g} s tolerance"
        command = None if current is not None and _same(level, current) else level
        if command is None and current is not None:
            level = current
        eta_s = eta_at(level)
        error_s = eta_s - target_s
        reason += (
            f"; commanding {level:.1f} m/s" if command is not None else f"; keeping {level:.1f} m/s"
        )
        reason += f", ETA error {error_s:+.2f} s"
        return Decision(
            verdict=verdict,
            command_m_s=command,
            level_m_s=level,
            required_m_s=required,
            eta_s=eta_s,
            eta_min_s=eta_min_s,
            eta_max_s=eta_max_s,
            error_s=error_s,
            reason=reason,
        )

    @staticmethod
    def period_s(time_left_s: float) -> float:
        """How long until the next decision, mission s: ``clamp(time_left / 40, 0.5, 10)``."""
        if not time_left_s > 0.0:  # also nan
            return 0.5
        return min(max(time_left_s / 40.0, 0.5), 10.0)

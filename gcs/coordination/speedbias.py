"""What the aircraft really flies, learnt in flight: a true-airspeed scale and a wind correction.

The arrival controller predicts the groundspeed from the commanded airspeed (equivalent
airspeed times the atmosphere's EAS2TAS) and the vehicle's wind estimate. Both can be a few
per cent off: an airspeed sensor reading 5 % low makes the aircraft fly 5 % fast at every
command; ArduPlane's wind estimate reads 1-1.5 m/s in still air. Left alone, such a bias runs
the controller out of authority in the last minutes before arrival.

Each position fix gives the ground velocity ``v`` and the heading ``psi`` at one instant. With
the predicted true airspeed ``T`` and the reported wind ``w``, the air mass model is

    v - w = k * T * (sin psi, cos psi) + dw

with the airspeed scale ``k`` and the wind error ``dw`` (east, north) unknown. The error is not
taken as fixed: an autopilot's estimate drifts (ArduPlane's turns by up to half a degree a
second in still air, as the stub's does: ``sitl_stub.wind_estimate``), so ``dw`` is a line in
time, ``dw(t) = dw + (t - now) * dw_rate``, and what counts is its value now. A report that
turns while what the aircraft makes good does not is thus not believed, and one that turns
with it (the wind changing) is; a fixed error left the prediction the report's drift over
the time constant (3 % of a vehicle's minimum speed: 2.3 s early on its last minute). The
five unknowns are found by least squares over the recent fixes (exponential forgetting with
``time_constant_s``), regularised towards ``k = 1, dw = 0, dw_rate = 0`` so that a straight
leg, which cannot separate ``k`` from the wind along it, still predicts that leg right. Fixes
taken while
the airspeed is settling after a change, or while climbing or descending steeply, are not used;
on a gentler climb or descent (a final approach sinking to its goal) the horizontal speed is
``T cos(gamma)``.

Sans-IO: pure arithmetic over the samples given to :meth:`SpeedBiasEstimator.update`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.wind import Wind

__all__ = ["BiasConfig", "SpeedBiasEstimator"]


@dataclass(frozen=True, slots=True)
class BiasConfig:
    """Knobs of :class:`SpeedBiasEstimator` (mission seconds, m/s)."""

    time_constant_s: float = 60.0
    """Fixes older than this weigh 1/e of a new one."""
    max_gap_s: float = 2.0
    """A gap between two fixes used (a link gap, a restart, a stretch of unsettled airspeed)
    ages the estimate by no more than this: no fix is no news. Aged by the whole gap, what a
    vehicle had learnt in a 250 s restart fell to 1.5 % of its weight, and the first fix after
    it, pulled towards the prior, moved the team time by a minute."""
    prior_fixes: float = 4.0
    """The pull towards ``k = 1, dw = 0, dw_rate = 0``, as that many fixes' worth of evidence."""
    scale_bounds: tuple[float, float] = (0.85, 1.15)
    """The airspeed scale is kept in this range (a larger error is a fault, not a bias)."""
    max_wind_error_m_s: float = 4.0
    """The wind correction is kept within this magnitude."""
    settle_m_s: float = 0.6
    """A fix counts only when the reported airspeed is this close to the commanded one."""
    max_climb_m_s: float = 3.0
    """A fix counts only when climbing or sinking slower than this (steeper, the autopilot
    trades airspeed for height while its energy controller settles)."""


class SpeedBiasEstimator:
    """Least-squares estimate of the airspeed scale and the wind error from ground velocity."""

    def __init__(self, config: BiasConfig | None = None) -> None:
        self.config = config or BiasConfig()
        # The normal equations of theta = (k, dwe, dwn, dwe_rate, dwn_rate), each fix's rows
        # being (tas sin h, 1, 0, tau, 0) and (tas cos h, 0, 1, 0, tau), tau its time less the
        # latest fix's: their matrix and right side, decayed and moved on at each fix.
        self._normal = np.zeros((5, 5))
        self._rhs = np.zeros(5)
        self._last_t_s: float | None = None
        self._scale = 1.0
        self._wind_error = (0.0, 0.0)
        self._ref_tas_m_s = 20.0
        self.used = 0
        self.skipped = 0

    @property
    def scale(self) -> float:
        """True airspeed flown per unit of the predicted one (1.0 until learnt)."""
        return self._scale

    @property
    def wind_error(self) -> Wind:
        """What to add to the reported wind, m/s."""
        return Wind(*self._wind_error)

    def corrected(self, wind: Wind) -> Wind:
        """The reported wind plus the learnt error."""
        de, dn = self._wind_error
        return Wind(wind.to_east_m_s + de, wind.to_north_m_s + dn)

    def update(
        self,
        t_s: float,
        *,
        ve_m_s: float,
        vn_m_s: float,
        heading_rad: float,
        predicted_tas_m_s: float,
        wind: Wind,
        airspeed_m_s: float | None = None,
        commanded_m_s: float | None = None,
        climb_m_s: float | None = None,
    ) -> bool:
        """Take one fix at mission time ``t_s``; True if it was used.

        ``predicted_tas_m_s`` is the true airspeed the controller assumes for the commanded
        airspeed; ``airspeed_m_s``/``commanded_m_s`` (the autopilot's reported and commanded
        airspeed, same kind) and ``climb_m_s`` gate the fix when given.
        """
        cfg = self.config
        values = (t_s, ve_m_s, vn_m_s, heading_rad, predicted_tas_m_s)
        if not all(map(math.isfinite, values)) or predicted_tas_m_s <= 0.0:
            self.skipped += 1
            return False
        if (
            airspeed_m_s is not None
            and commanded_m_s is not None
            and abs(airspeed_m_s - commanded_m_s) > cfg.settle_m_s
        ) or (climb_m_s is not None and abs(climb_m_s) > cfg.max_climb_m_s):
            self.skipped += 1
            return False
        if self._last_t_s is not None:
            dt = min(max(t_s - self._last_t_s, 0.0), cfg.max_gap_s)
            # The fixes so far are dt older: each row's tau less dt (row @ shift).
            shift = np.eye(5)
            shift[1, 3] = shift[2, 4] = -dt
            decay = math.exp(-dt / cfg.time_constant_s)
            self._normal = decay * (shift.T @ self._normal @ shift)
            self._rhs = decay * (shift.T @ self._rhs)
        self._last_t_s = t_s
        self._ref_tas_m_s = predicted_tas_m_s
        # Along a climb or a descent the horizontal speed is the true airspeed times the cosine
        # of the flight path angle.
        climb = climb_m_s or 0.0
        tas = math.sqrt(max(predicted_tas_m_s**2 - climb**2, 0.0))
        a, b = tas * math.sin(heading_rad), tas * math.cos(heading_rad)
        re, rn = ve_m_s - wind.to_east_m_s, vn_m_s - wind.to_north_m_s
        # This fix's rows, at tau 0: (a, 1, 0, 0, 0) and (b, 0, 1, 0, 0).
        m = self._normal
        m[0, 0] += a * a + b * b
        m[0, 1] += a
        m[1, 0] += a
        m[0, 2] += b
        m[2, 0] += b
        m[1, 1] += 1.0
        m[2, 2] += 1.0
        self._rhs[:3] += (a * re + b * rn, re, rn)
        self.used += 1
        self._solve()
        return True

    def _solve(self) -> None:
        cfg = self.config
        tas = self._ref_tas_m_s
        # (normal matrix + prior) theta = rhs + prior @ (1, 0, 0, 0, 0); the prior is that many
        # fixes' worth of no bias, of no drift over a time constant and of no wind error at
        # the fixes' mean time (held at the latest fix's, it tilted a steady error by the
        # prior's pull, to that fix's cost).
        p, tc = cfg.prior_fixes, cfg.time_constant_s
        lhs = self._normal + np.diag([p * tas * tas, p, p, p * tc * tc, p * tc * tc])
        weight = self._normal[1, 1]
        mean_tau = self._normal[1, 3] / weight if weight > 0.0 else 0.0
        for error, rate in ((1, 3), (2, 4)):
            lhs[error, rate] += p * mean_tau
            lhs[rate, error] += p * mean_tau
            lhs[rate, rate] += p * mean_tau * mean_tau
        rhs = self._rhs.copy()
        rhs[0] += p * tas * tas
        k = float(np.linalg.solve(lhs, rhs)[0])
        lo, hi = cfg.scale_bounds
        self._scale = float(min(max(k, lo), hi))
        # The wind error fitted for the scale the predictions use (at its bound, if there).
        k = self._scale
        rest = np.linalg.solve(lhs[1:, 1:], rhs[1:] - lhs[1:, 0] * k)
        de, dn = float(rest[0]), float(rest[1])
        norm = math.hypot(de, dn)
        if norm > cfg.max_wind_error_m_s:
            de, dn = de * cfg.max_wind_error_m_s / norm, dn * cfg.max_wind_error_m_s / norm
        self._wind_error = (de, dn)

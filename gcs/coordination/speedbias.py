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
        # latest fix's, decayed and moved on at each fix. Their matrix is kept as its sums:
        # [[aa, a, b, a_tau, b_tau], [a, n, 0, tau, 0], [b, 0, n, 0, tau],
        #  [a_tau, tau, 0, tau2, 0], [b_tau, 0, tau, 0, tau2]]; east and north are alike but
        # for the scale's column. Its right side: (a re + b rn, re, rn, tau re, tau rn).
        self._aa = self._a = self._b = self._a_tau = self._b_tau = 0.0
        self._n = self._tau = self._tau2 = 0.0
        self._vec = [0.0, 0.0, 0.0, 0.0, 0.0]
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
            decay = math.exp(-dt / cfg.time_constant_s)
            # The fixes so far are dt older: each row's tau less dt.
            self._tau2 = decay * (self._tau2 - 2.0 * dt * self._tau + dt * dt * self._n)
            self._tau = decay * (self._tau - dt * self._n)
            self._a_tau = decay * (self._a_tau - dt * self._a)
            self._b_tau = decay * (self._b_tau - dt * self._b)
            self._aa *= decay
            self._a *= decay
            self._b *= decay
            self._n *= decay
            v = self._vec
            self._vec = [
                decay * v[0], decay * v[1], decay * v[2],
                decay * (v[3] - dt * v[1]), decay * (v[4] - dt * v[2]),
            ]  # fmt: skip
        self._last_t_s = t_s
        self._ref_tas_m_s = predicted_tas_m_s
        # Along a climb or a descent the horizontal speed is the true airspeed times the cosine
        # of the flight path angle.
        climb = climb_m_s or 0.0
        tas = math.sqrt(max(predicted_tas_m_s**2 - climb**2, 0.0))
        a, b = tas * math.sin(heading_rad), tas * math.cos(heading_rad)
        re, rn = ve_m_s - wind.to_east_m_s, vn_m_s - wind.to_north_m_s
        # This fix's rows, at tau 0: (a, 1, 0, 0, 0) and (b, 0, 1, 0, 0).
        self._aa += a * a + b * b
        self._a += a
        self._b += b
        self._n += 1.0
        v = self._vec
        v[0] += a * re + b * rn
        v[1] += re
        v[2] += rn
        self.used += 1
        self._solve()
        return True

    def _solve(self) -> None:
        cfg = self.config
        tas = self._ref_tas_m_s
        # (normal matrix + prior) theta = rhs + prior @ (1, 0, 0, 0, 0); the prior is that many
        # fixes' worth of no bias, of no drift over a time constant and of no wind error at
        # the fixes' mean time (held at the latest fix's, it tilted a steady error by the
        # prior's pull, to that fix's cost). Each of east and north is a 2x2 block
        # [[p_, q_], [q_, r_]] (its error and its rate), the same for both, joined to the
        # other only through the scale: the scale from its Schur complement, then each
        # block for that scale.
        p, tc = cfg.prior_fixes, cfg.time_constant_s
        mean_tau = self._tau / self._n if self._n > 0.0 else 0.0
        p_ = self._n + p
        q_ = self._tau + p * mean_tau
        r_ = self._tau2 + p * tc * tc + p * mean_tau * mean_tau
        det = p_ * r_ - q_ * q_

        def inv(x: tuple[float, float], y: tuple[float, float]) -> float:
            """``x`` times the block's inverse times ``y``."""
            return (r_ * x[0] * y[0] - q_ * (x[0] * y[1] + x[1] * y[0]) + p_ * x[1] * y[1]) / det

        east, north = (self._a, self._a_tau), (self._b, self._b_tau)
        v = self._vec
        east_rhs, north_rhs = (v[1], v[3]), (v[2], v[4])
        k = (v[0] + p * tas * tas - inv(east, east_rhs) - inv(north, north_rhs)) / (
            self._aa + p * tas * tas - inv(east, east) - inv(north, north)
        )
        lo, hi = cfg.scale_bounds
        self._scale = float(min(max(k, lo), hi))
        # The wind error fitted for the scale the predictions use (at its bound, if there).
        k = self._scale
        de, dn = (
            (r_ * (rhs[0] - k * col[0]) - q_ * (rhs[1] - k * col[1])) / det
            for col, rhs in ((east, east_rhs), (north, north_rhs))
        )
        norm = math.hypot(de, dn)
        if norm > cfg.max_wind_error_m_s:
            de, dn = de * cfg.max_wind_error_m_s / norm, dn * cfg.max_wind_error_m_s / norm
        self._wind_error = (de, dn)

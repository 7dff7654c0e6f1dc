"""One simulated clock per process: fixed physics steps at ``speedup`` x wall time.

The clock is sans-IO: the caller passes wall time in (``steps_due(wall_s)``), runs the due
steps and calls :meth:`SimClock.advance` after each one. If the process falls behind by more
than ``max_lag_s`` of wall time the clock slips (drops the backlog) instead of spiralling; the
achieved rate then shows it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# 2024-01-01T00:00:00Z: a fixed start for reproducible runs (the CLI uses wall time instead).
DEFAULT_EPOCH_UTC_S = 1_704_067_200.0


@dataclass(frozen=True, slots=True)
class ClockStats:
    """How well the clock kept up."""

    sim_elapsed_s: float
    wall_elapsed_s: float
    requested_speedup: float
    achieved_speedup: float
    slipped_sim_s: float

    @property
    def rate_fraction(self) -> float:
        """Achieved / requested speed-up (1.0 = kept up exactly)."""
        return self.achieved_speedup / self.requested_speedup


class SimClock:
    """Simulated time in integer steps of ``step_s``, advancing at ``speedup`` x wall time."""

    def __init__(
        self,
        *,
        speedup: float = 1.0,
        step_s: float = 0.1,
        start_utc_s: float = DEFAULT_EPOCH_UTC_S,
        max_lag_s: float = 0.25,
    ) -> None:
        if not (math.isfinite(speedup) and speedup > 0):
            raise ValueError(f"speedup must be a positive number, got {speedup!r}")
        if not (math.isfinite(step_s) and step_s > 0):
            raise ValueError(f"step_s must be a positive number, got {step_s!r}")
        self.speedup = float(speedup)
        self.step_s = float(step_s)
        self.start_utc_s = float(start_utc_s)
        self.max_lag_s = float(max_lag_s)
        self.steps = 0
        self._wall0: float | None = None
        self._slipped_steps = 0

    @property
    def sim_time_s(self) -> float:
        """Simulated seconds since start."""
        return self.steps * self.step_s

    @property
    def utc_s(self) -> float:
        """Simulated UTC, seconds since the Unix epoch."""
        return self.start_utc_s + self.sim_time_s

    @property
    def time_boot_ms(self) -> int:
        return int(self.steps * self.step_s * 1000.0)

    @property
    def started(self) -> bool:
        return self._wall0 is not None

    def start(self, wall_s: float) -> None:
        self._wall0 = wall_s

    def steps_due(self, wall_s: float) -> int:
        """Steps to run now to catch up with ``wall_s`` (slipping any excess backlog)."""
        if self._wall0 is None:
            self._wall0 = wall_s
        target = int((wall_s - self._wall0) * self.speedup / self.step_s) - self._slipped_steps
        due = target - self.steps
        max_steps = max(1, int(self.max_lag_s * self.speedup / self.step_s))
        if due > max_steps:
            self._slipped_steps += due - max_steps
            due = max_steps
        return max(0, due)

    def wall_until_next_step(self, wall_s: float) -> float:
        """Wall seconds until the next step falls due (0 if one is due now)."""
        if self._wall0 is None:
            return 0.0
        next_wall = (
            self._wall0 + (self.steps + 1 + self._slipped_steps) * self.step_s / self.speedup
        )
        return max(0.0, next_wall - wall_s)

    def advance(self) -> None:
        self.steps += 1

    def stats(self, wall_s: float) -> ClockStats:
        wall = 0.0 if self._wall0 is None else wall_s - self._wall0
        achieved = self.sim_time_s / wall if wall > 0 else 0.0
        return ClockStats(
            sim_elapsed_s=self.sim_time_s,
            wall_elapsed_s=wall,
            requested_speedup=self.speedup,
            achieved_speedup=achieved,
            slipped_sim_s=self._slipped_steps * self.step_s,
        )

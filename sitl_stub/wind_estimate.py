"""The error of an autopilot's wind estimate: what WIND reports is not the true wind.

ArduPlane's WIND message carries the EKF's wind estimate (libraries/GCS_MAVLink/GCS_Common.cpp,
send_wind: ``AP::ahrs().wind_estimate()``); it is never exact. Real ArduPlane SITL in still air
reports 0.8-1.6 m/s. The stub adds a per-vehicle error vector of that size that turns slowly,
drawn once from the vehicle's seed, so a run is repeatable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ERROR_MIN_M_S = 0.8
ERROR_MAX_M_S = 1.6
TURN_RATE_MAX_RAD_S = math.radians(0.5)


@dataclass(frozen=True, slots=True)
class WindEstimateError:
    """An error vector of fixed size whose direction turns at a fixed rate.

    ``north_east_m_s(t)`` is the error at simulated time t (seconds): add it to the true wind
    to get what the autopilot reports.
    """

    speed_m_s: float
    direction_rad: float
    turn_rate_rad_s: float

    @classmethod
    def draw(cls, rng: np.random.Generator) -> WindEstimateError:
        """One vehicle's error: size in [0.8, 1.6] m/s, any direction, turning <= 0.5 deg/s."""
        return cls(
            speed_m_s=float(rng.uniform(ERROR_MIN_M_S, ERROR_MAX_M_S)),
            direction_rad=float(rng.uniform(0.0, 2.0 * math.pi)),
            turn_rate_rad_s=float(rng.uniform(-TURN_RATE_MAX_RAD_S, TURN_RATE_MAX_RAD_S)),
        )

    def north_east_m_s(self, time_s: float) -> tuple[float, float]:
        a = self.direction_rad + self.turn_rate_rad_s * time_s
        return self.speed_m_s * math.cos(a), self.speed_m_s * math.sin(a)

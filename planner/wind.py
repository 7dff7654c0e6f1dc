"""The wind triangle: the air mass's velocity and the speed it leaves over the ground.

A fixed-wing aircraft flies an airspeed through an air mass that itself moves; holding a
ground track, it crabs into the cross wind and makes good ``w_along + sqrt(a**2 - w_cross**2)``
along the track. The planner times routes with a forecast wind (a scenario's ``wind``, or
one the operator gives); the coordinator in flight with the wind the vehicles measure.

Conventions: compass angles in radians (0 = north, clockwise positive, so a unit direction is
``(sin h, cos h)`` in (east, north)); speeds in m/s; the meteorological "from" direction only
at the edges (:meth:`Wind.from_speed_from`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
from numpy.typing import NDArray

from planner.errors import PlannerError

__all__ = ["CALM", "Wind", "WindError", "groundspeed_m_s"]

FloatArray = NDArray[np.float64]
AnyFloatArray = NDArray[np.floating[Any]]


class WindError(PlannerError, ValueError):
    """A wind or an airspeed that is out of range (not finite, negative)."""


def _finite(name: str, value: float) -> float:
    if not math.isfinite(value):
        raise WindError(f"{name} must be finite, got {value!r}")
    return float(value)


@dataclass(frozen=True, slots=True)
class Wind:
    """Velocity of the air mass over the ground, m/s: the direction it blows TO."""

    to_east_m_s: float = 0.0
    to_north_m_s: float = 0.0

    def __post_init__(self) -> None:
        _finite("Wind.to_east_m_s", self.to_east_m_s)
        _finite("Wind.to_north_m_s", self.to_north_m_s)

    @classmethod
    def from_speed_from(cls, speed_m_s: float, from_deg: float) -> Wind:
        """Build a wind from the meteorological convention.

        Parameters
        ----------
        speed_m_s : float
            Wind speed, m/s (>= 0).
        from_deg : float
            Compass direction the wind blows FROM, degrees (270 = a westerly, blowing east).

        Returns
        -------
        Wind
            The air-mass velocity (blowing TO ``from_deg + 180``).
        """
        if not (math.isfinite(speed_m_s) and speed_m_s >= 0.0):
            raise WindError(f"speed_m_s must be finite and >= 0, got {speed_m_s!r}")
        from_rad = math.radians(_finite("from_deg", from_deg))
        return cls(-speed_m_s * math.sin(from_rad), -speed_m_s * math.cos(from_rad))

    @property
    def speed_m_s(self) -> float:
        """Wind speed, m/s."""
        return math.hypot(self.to_east_m_s, self.to_north_m_s)

    @property
    def from_deg(self) -> float:
        """Compass direction the wind blows FROM, degrees in [0, 360)."""
        return math.degrees(math.atan2(-self.to_east_m_s, -self.to_north_m_s)) % 360.0

    @property
    def calm(self) -> bool:
        return self.to_east_m_s == 0.0 and self.to_north_m_s == 0.0


CALM = Wind()
"""Still air."""


@overload
def groundspeed_m_s(airspeed_m_s: float, track_rad: float, wind: Wind) -> float: ...


@overload
def groundspeed_m_s(
    airspeed_m_s: float | AnyFloatArray, track_rad: AnyFloatArray, wind: Wind
) -> FloatArray: ...


def groundspeed_m_s(
    airspeed_m_s: float | AnyFloatArray, track_rad: float | AnyFloatArray, wind: Wind
) -> float | FloatArray:
    """Speed made good along a ground track when flying an airspeed crabbed into the wind.

    ``g = w_along + sqrt(a**2 - w_cross**2)``, where ``w_along``/``w_cross`` are the wind's
    components along and across the track.

    Parameters
    ----------
    airspeed_m_s : float or NDArray
        True airspeed(s), m/s (>= 0): one for every track, or one per track.
    track_rad : float or NDArray
        Compass ground track(s), rad.
    wind : Wind
        Air-mass velocity, m/s.

    Returns
    -------
    float or NDArray
        Groundspeed along each track, m/s; 0.0 where the track cannot be made good
        (``a**2 < w_cross**2`` or ``g <= 0``). A float for a float track.
    """
    tracks = np.asarray(track_rad, dtype=np.float64)
    sin_t, cos_t = np.sin(tracks), np.cos(tracks)
    along = wind.to_east_m_s * sin_t + wind.to_north_m_s * cos_t
    cross = wind.to_east_m_s * cos_t - wind.to_north_m_s * sin_t
    disc = airspeed_m_s * airspeed_m_s - cross * cross
    speed = along + np.sqrt(np.maximum(disc, 0.0))
    result: FloatArray = np.where((disc >= 0.0) & (speed > 0.0), speed, 0.0)
    if isinstance(track_rad, np.ndarray):
        return result
    return float(result)

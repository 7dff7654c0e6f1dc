"""The International Standard Atmosphere, for converting equivalent to true airspeed.

ArduPlane flies *equivalent* airspeed (EAS): its AIRSPEED_MIN/CRUISE/MAX parameters and every
DO_CHANGE_SPEED are EAS, because lift and stall depend on dynamic pressure. What carries the
aircraft over the ground is *true* airspeed (TAS), higher by ``sqrt(rho0 / rho)``: about 5 %
at 1,000 m, 10 % at 2,000 m. Timing a route flown at a commanded airspeed therefore needs the
air density along it; this module gives it for the ISA troposphere (up to 11 km), optionally
with a sea-level temperature offset (ISA+dT days).

Pure functions of altitude (m above mean sea level); SI units.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "GRAVITY_M_S2",
    "ISA_LAPSE_K_M",
    "ISA_SEA_LEVEL_DENSITY_KG_M3",
    "ISA_SEA_LEVEL_PRESSURE_PA",
    "ISA_SEA_LEVEL_TEMPERATURE_K",
    "density_kg_m3",
    "eas2tas",
    "eas2tas_table",
    "mean_eas2tas",
    "mean_eas2tas_from",
]

ISA_SEA_LEVEL_PRESSURE_PA = 101_325.0
ISA_SEA_LEVEL_TEMPERATURE_K = 288.15
ISA_SEA_LEVEL_DENSITY_KG_M3 = 1.225
ISA_LAPSE_K_M = 0.0065
"""Temperature lapse rate of the troposphere, K/m."""
_GAS_CONSTANT_J_KG_K = 287.05287
GRAVITY_M_S2 = 9.80665
"""Standard gravity, m/s^2."""
_EXPONENT = GRAVITY_M_S2 / (_GAS_CONSTANT_J_KG_K * ISA_LAPSE_K_M)  # 5.2559
_TROPOPAUSE_M = 11_000.0
_FLOOR_M = -1_000.0


def _alt(alt_m: ArrayLike) -> NDArray[np.float64]:
    alt = np.asarray(alt_m, dtype=np.float64)
    if not bool(np.isfinite(alt).all()):
        raise ValueError("altitude must be a finite number of metres")
    return np.clip(alt, _FLOOR_M, _TROPOPAUSE_M)


def density_kg_m3(alt_m: ArrayLike, *, isa_offset_k: float = 0.0) -> NDArray[np.float64]:
    """Air density (kg/m^3) at altitudes AMSL (m), ISA troposphere with a temperature offset.

    Pressure follows the standard lapse (the offset does not change the pressure at an
    altitude to first order); the temperature is the ISA one plus ``isa_offset_k``. Altitudes
    are clamped to [-1000, 11000] m.
    """
    alt = _alt(alt_m)
    temp_isa = ISA_SEA_LEVEL_TEMPERATURE_K - ISA_LAPSE_K_M * alt
    pressure = ISA_SEA_LEVEL_PRESSURE_PA * (temp_isa / ISA_SEA_LEVEL_TEMPERATURE_K) ** _EXPONENT
    result: NDArray[np.float64] = pressure / (_GAS_CONSTANT_J_KG_K * (temp_isa + isa_offset_k))
    return result


def eas2tas(alt_m: float, *, isa_offset_k: float = 0.0) -> float:
    """True airspeed per unit of equivalent airspeed at an altitude AMSL (m): ``sqrt(rho0/rho)``.

    1.0 at sea level on a standard day, about 1.0497 at 1,000 m.
    """
    if not math.isfinite(alt_m):
        raise ValueError(f"altitude must be a finite number of metres, got {alt_m!r}")
    # density_kg_m3 on one float (the per-fix path: numpy on a scalar costs ten times this).
    alt = min(max(float(alt_m), _FLOOR_M), _TROPOPAUSE_M)
    temp_isa = ISA_SEA_LEVEL_TEMPERATURE_K - ISA_LAPSE_K_M * alt
    pressure = ISA_SEA_LEVEL_PRESSURE_PA * (temp_isa / ISA_SEA_LEVEL_TEMPERATURE_K) ** _EXPONENT
    rho = pressure / (_GAS_CONSTANT_J_KG_K * (temp_isa + isa_offset_k))
    return math.sqrt(ISA_SEA_LEVEL_DENSITY_KG_M3 / rho)


def eas2tas_table(
    s_m: ArrayLike, alt_m: ArrayLike, *, isa_offset_k: float = 0.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """A route's EAS-to-TAS ratio tabulated for :func:`mean_eas2tas_from`.

    ``s_m``/``alt_m`` are the route's altitude profile (along path distance ascending, m;
    altitude AMSL, m), linearly interpolated. Returns the grid along the path (m: its whole
    length about every 50 m, at most 2000 points), ``1 / r`` at each grid point and the
    integral of ``ds / r`` from the route's start to each grid point (m, trapezoids).
    """
    s = np.asarray(s_m, dtype=np.float64)
    alt = np.asarray(alt_m, dtype=np.float64)
    if s.ndim != 1 or s.shape != alt.shape or s.size == 0:
        raise ValueError("s_m and alt_m must be 1-D arrays of the same non-zero length")
    start, end = float(s[0]), float(s[-1])
    n = max(2, min(2000, int((end - start) / 50.0) + 2))
    grid = np.linspace(start, end, n)
    inv = np.sqrt(
        density_kg_m3(np.interp(grid, s, alt), isa_offset_k=isa_offset_k)
        / ISA_SEA_LEVEL_DENSITY_KG_M3
    )
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(grid))])
    return grid, inv, cum


def mean_eas2tas_from(
    table: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    s_from_m: float = 0.0,
) -> float:
    """The EAS-to-TAS ratio that times the route of ``table`` (:func:`eas2tas_table`) exactly
    at a constant EAS from ``s_from_m`` on: ``L / integral(ds / r)``, the harmonic mean of
    ``r`` along the rest of the path (at the end of the path, ``r`` there)."""
    grid, inv, cum = table
    end = float(grid[-1])
    start = min(max(s_from_m, float(grid[0])), end)
    if end - start <= 1e-9:
        return 1.0 / float(np.interp(start, grid, inv))
    return (end - start) / (float(cum[-1]) - float(np.interp(start, grid, cum)))


def mean_eas2tas(
    s_m: ArrayLike, alt_m: ArrayLike, *, s_from_m: float = 0.0, isa_offset_k: float = 0.0
) -> float:
    """The EAS-to-TAS ratio that times a route exactly at a constant EAS.

    Flying ``ds`` at equivalent airspeed ``v`` takes ``ds / (v * r(s))``; the whole route
    from ``s_from_m`` takes ``L / (v * R)`` with ``R = L / integral(ds / r)`` (the harmonic
    mean of ``r`` along the path). ``s_m``/``alt_m`` are the route's altitude profile (along
    path distance ascending, m; altitude AMSL, m), linearly interpolated. Asked often of one
    route, keep its :func:`eas2tas_table` and use :func:`mean_eas2tas_from`.
    """
    return mean_eas2tas_from(eas2tas_table(s_m, alt_m, isa_offset_k=isa_offset_k), s_from_m)

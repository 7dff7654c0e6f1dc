"""The 1976 U.S. Standard Atmosphere as ArduPilot's SITL uses it for true airspeed.

ArduPlane's airspeeds (AIRSPEED_MIN/CRUISE/MAX, DO_CHANGE_SPEED) are equivalent airspeed (EAS);
the simulated aircraft flies true airspeed TAS = EAS * EAS2TAS at its altitude. This follows
libraries/AP_Baro/AP_Baro_atmosphere.cpp, ``get_air_density_for_alt_amsl`` and
``get_EAS2TAS_for_alt_amsl`` (what libraries/SITL/SIM_Aircraft.cpp ``update_dynamics`` sets
``eas2tas`` from): geometric altitude to geopotential, the layer's temperature, density from the
layer's base density, ``EAS2TAS = sqrt(rho0 / rho)``. Written here in double precision.
"""

from __future__ import annotations

import math

GRAVITY_M_S2 = 9.80665
SSL_AIR_DENSITY_KG_M3 = 1.225
# The 1976 model's constants (they differ slightly from today's values on purpose).
EARTH_RADIUS_1976_M = 6356.766e3
R_SPECIFIC_1976 = 287.053072

# Layer base: geopotential altitude (m'), temperature (K), density (kg/m^3), lapse (K/m').
_LAYERS: tuple[tuple[float, float, float, float], ...] = (
    (-5000.0, 320.650, 1.930467, -6.5e-3),
    (11000.0, 216.650, 0.363918, 0.0),
    (20000.0, 216.650, 8.80349e-2, 1e-3),
    (32000.0, 228.650, 1.32250e-2, 2.8e-3),
    (47000.0, 270.650, 1.42753e-3, 0.0),
    (51000.0, 270.650, 8.61606e-4, -2.8e-3),
    (71000.0, 214.650, 6.42110e-5, -2.0e-3),
    (84852.0, 186.946, 6.95788e-6, 0.0),
)


def air_density_kg_m3(alt_amsl_m: float) -> float:
    """Air density (kg/m^3) at a geometric altitude AMSL (AP_Baro get_air_density_for_alt_amsl)."""
    h = EARTH_RADIUS_1976_M * alt_amsl_m / (EARTH_RADIUS_1976_M + alt_amsl_m)
    base_h, base_t, base_rho, lapse = _LAYERS[0]
    for layer in _LAYERS[1:]:
        if h < layer[0]:
            break
        base_h, base_t, base_rho, lapse = layer
    if lapse == 0.0:
        return base_rho * math.exp(-GRAVITY_M_S2 / (base_t * R_SPECIFIC_1976) * (h - base_h))
    temp = base_t + lapse * (h - base_h)
    fac = GRAVITY_M_S2 / (lapse * R_SPECIFIC_1976)
    return float(base_rho * (temp / base_t) ** -(fac + 1.0))


def density_ratio(alt_amsl_m: float) -> float:
    """rho / rho0 at a geometric altitude AMSL (1 at sea level)."""
    return air_density_kg_m3(alt_amsl_m) / SSL_AIR_DENSITY_KG_M3


def eas2tas(alt_amsl_m: float) -> float:
    """True / equivalent airspeed at a geometric altitude AMSL (get_EAS2TAS_for_alt_amsl)."""
    return math.sqrt(SSL_AIR_DENSITY_KG_M3 / max(0.00001, air_density_kg_m3(alt_amsl_m)))

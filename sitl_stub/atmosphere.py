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


# Per layer, what the density formula needs: base altitude (m'), temperature (K), density,
# lapse (K/m'), and the exponent: -g / (T R) for an isothermal layer (times h - base_h),
# else -(g / (lapse R) + 1) (of T / base_t). Worked out once, as the formula below would.
_LAYER_CONSTANTS: tuple[tuple[float, float, float, float, float], ...] = tuple(
    (
        base_h,
        base_t,
        base_rho,
        lapse,
        -GRAVITY_M_S2 / (base_t * R_SPECIFIC_1976)
        if lapse == 0.0
        else -(GRAVITY_M_S2 / (lapse * R_SPECIFIC_1976) + 1.0),
    )
    for base_h, base_t, base_rho, lapse in _LAYERS
)
_FIRST_LAYER = _LAYER_CONSTANTS[0]
_HIGHER_LAYERS = _LAYER_CONSTANTS[1:]


def air_density_kg_m3(alt_amsl_m: float) -> float:
    """Air density (kg/m^3) at a geometric altitude AMSL (AP_Baro get_air_density_for_alt_amsl).

    Isothermal layer: ``rho_b exp(-g / (T_b R) (h - h_b))``; else ``rho_b (T / T_b)^-(g / (L R)
    + 1)`` with ``T = T_b + L (h - h_b)`` (h geopotential; layer base b, lapse L).
    """
    h = EARTH_RADIUS_1976_M * alt_amsl_m / (EARTH_RADIUS_1976_M + alt_amsl_m)
    base_h, base_t, base_rho, lapse, exponent = _FIRST_LAYER
    for layer in _HIGHER_LAYERS:
        if h < layer[0]:
            break
        base_h, base_t, base_rho, lapse, exponent = layer
    if lapse == 0.0:
        return base_rho * math.exp(exponent * (h - base_h))
    temp = base_t + lapse * (h - base_h)
    return float(base_rho * (temp / base_t) ** exponent)


def density_ratio(alt_amsl_m: float) -> float:
    """rho / rho0 at a geometric altitude AMSL (1 at sea level)."""
    return air_density_kg_m3(alt_amsl_m) / SSL_AIR_DENSITY_KG_M3


def eas2tas(alt_amsl_m: float) -> float:
    """True / equivalent airspeed at a geometric altitude AMSL (get_EAS2TAS_for_alt_amsl)."""
    rho = air_density_kg_m3(alt_amsl_m)
    return math.sqrt(SSL_AIR_DENSITY_KG_M3 / (rho if rho > 0.00001 else 0.00001))

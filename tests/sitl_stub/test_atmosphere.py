"""The 1976 standard atmosphere of the simulated airspeeds, against its layer formulas."""

from __future__ import annotations

import math

import numpy as np

from sitl_stub.atmosphere import (
    _LAYERS,
    EARTH_RADIUS_1976_M,
    GRAVITY_M_S2,
    R_SPECIFIC_1976,
    SSL_AIR_DENSITY_KG_M3,
    air_density_kg_m3,
    eas2tas,
)


def density_from_the_layers(alt_amsl_m: float) -> float:
    """AP_Baro get_air_density_for_alt_amsl, written out as it reads."""
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


def test_density_and_eas2tas_are_the_layer_formulas_to_the_bit() -> None:
    alts = np.concatenate([np.linspace(-5000.0, 90000.0, 20001), [0.0, 11000.0, 20000.0]])
    for alt in alts.tolist():
        rho = density_from_the_layers(alt)
        assert air_density_kg_m3(alt) == rho
        assert eas2tas(alt) == math.sqrt(SSL_AIR_DENSITY_KG_M3 / max(0.00001, rho))

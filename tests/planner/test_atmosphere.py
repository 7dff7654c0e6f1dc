"""ISA densities against the standard's published table, and route-mean EAS-to-TAS ratios."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.atmosphere import (
    ISA_SEA_LEVEL_DENSITY_KG_M3,
    density_kg_m3,
    eas2tas,
    eas2tas_table,
    mean_eas2tas,
    mean_eas2tas_from,
)


@pytest.mark.parametrize(
    ("alt_m", "rho_kg_m3"),
    # ICAO standard atmosphere (Doc 7488) densities.
    [
        (0.0, 1.2250),
        (500.0, 1.1673),
        (1000.0, 1.1117),
        (2000.0, 1.0066),
        (5000.0, 0.7364),
        (11000.0, 0.3639),
    ],
)
def test_density_matches_the_standard_atmosphere_table(alt_m: float, rho_kg_m3: float) -> None:
    assert float(density_kg_m3(alt_m)) == pytest.approx(rho_kg_m3, abs=6e-4)


def test_eas2tas_at_1000_m_is_about_five_percent() -> None:
    assert eas2tas(0.0) == pytest.approx(1.0, abs=1e-7)
    assert eas2tas(1000.0) == pytest.approx(1.0497, abs=2e-4)


def test_a_warmer_day_means_thinner_air_and_more_true_airspeed() -> None:
    assert eas2tas(1000.0, isa_offset_k=15.0) > eas2tas(1000.0) * 1.02


def test_non_finite_altitude_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match="altitude"):
        eas2tas(math.nan)


def test_mean_ratio_times_a_climbing_route_like_summing_its_pieces() -> None:
    s = np.array([0.0, 10_000.0, 30_000.0])
    alt = np.array([600.0, 1800.0, 1800.0])
    ratio = mean_eas2tas(s, alt)
    # Independent: time of each metre at 1 m/s EAS, summed finely.
    grid = np.linspace(0.0, 30_000.0, 300_001)
    per_m = 1.0 / np.array([eas2tas(a) for a in np.interp(grid[::100], s, alt)])
    time_s = float(np.mean(per_m)) * 30_000.0
    assert ratio == pytest.approx(30_000.0 / time_s, rel=2e-4)
    assert eas2tas(600.0) < ratio < eas2tas(1800.0)


def test_mean_ratio_from_a_point_uses_only_what_is_left() -> None:
    s = np.array([0.0, 10_000.0, 20_000.0])
    alt = np.array([0.0, 0.0, 3000.0])
    assert mean_eas2tas(s, alt, s_from_m=20_000.0) == pytest.approx(eas2tas(3000.0))
    assert mean_eas2tas(s, alt, s_from_m=10_000.0) > mean_eas2tas(s, alt)


@pytest.mark.parametrize("s_from_m", [0.0, 3_333.3, 10_000.0, 24_567.8, 29_990.0])
def test_the_table_times_the_rest_of_a_route_from_anywhere_on_it(s_from_m: float) -> None:
    """From any point (the in-flight use: every fix), against the time of the rest of the
    route at 1 m/s EAS integrated here by scipy, piece by piece of the profile."""
    from scipy.integrate import quad

    s = np.array([0.0, 7_000.0, 18_000.0, 30_000.0])
    alt = np.array([400.0, 2_200.0, 900.0, 1_500.0])
    table = eas2tas_table(s, alt)
    time_s = 0.0
    for a, b, za, zb in zip(s[:-1], s[1:], alt[:-1], alt[1:], strict=True):
        lo = max(a, s_from_m)
        if lo < b:
            time_s += quad(lambda x, a=a, b=b, za=za, zb=zb: 1.0 / eas2tas(
                za + (zb - za) * (x - a) / (b - a)), lo, b)[0]  # fmt: skip
    # The rest of the route at 1 m/s EAS as the table times it: within a millionth, or a
    # millisecond when little is left.
    assert (30_000.0 - s_from_m) / mean_eas2tas_from(table, s_from_m) == pytest.approx(
        time_s, rel=1e-6, abs=1e-3
    )
    assert mean_eas2tas(s, alt, s_from_m=s_from_m) == mean_eas2tas_from(table, s_from_m)


@pytest.mark.parametrize("isa_offset_k", [-20.0, 0.0, 15.0])
def test_the_scalar_ratio_is_the_density_profile_s(isa_offset_k: float) -> None:
    """``eas2tas`` on one altitude is ``sqrt(rho0 / rho)`` of :func:`density_kg_m3`, clamped
    alike below -1,000 m and above the tropopause."""
    alts = np.array([-3000.0, -1000.0, 0.0, 457.0, 1000.0, 2500.5, 8000.0, 11_000.0, 15_000.0])
    rho = density_kg_m3(alts, isa_offset_k=isa_offset_k)
    expected = np.sqrt(ISA_SEA_LEVEL_DENSITY_KG_M3 / rho)
    got = [eas2tas(float(a), isa_offset_k=isa_offset_k) for a in alts]
    assert got == pytest.approx(expected.tolist(), rel=1e-12)

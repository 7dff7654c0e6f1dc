"""WGS84 geodetic coordinates <-> a local east/north plane about a scenario origin.

The local plane is an ellipsoidal Transverse Mercator projection (Krüger series to sixth order
in the third flattening, as in Karney 2011, "Transverse Mercator with an accuracy of a few
nanometers", J. Geodesy 85:475-485) whose central meridian passes through the origin, with unit
scale on that meridian and offsets that put the origin at (0, 0). The series is accurate to a
few nanometres within thousands of kilometres of the central meridian, so a 300 km planning area
round-trips far below a millimetre. Altitude is not projected: planning is 2.5-D and altitudes
stay AMSL metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "WGS84_A_M",
    "WGS84_F",
    "LocalFrame",
    "geodesic_distance_m",
]

WGS84_A_M: float = 6378137.0
"""WGS84 semi-major axis (m)."""
WGS84_F: float = 1.0 / 298.257223563
"""WGS84 flattening (dimensionless)."""

_MAX_ORIGIN_LAT_DEG = 89.0
_NEWTON_ITERATIONS = 6

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class _TmSeries:
    """Constants of the Krüger series for one ellipsoid (lengths in m)."""

    e: float
    """First eccentricity."""
    rectifying_radius_m: float
    """A in Karney (2011): meridian arc length per radian of rectifying latitude."""
    alpha: tuple[float, ...]
    """Forward series coefficients alpha_1..alpha_6."""
    beta: tuple[float, ...]
    """Reverse series coefficients beta_1..beta_6."""


def _tm_series(a_m: float, f: float) -> _TmSeries:
    """Series constants of Karney (2011), eqs (14), (35) and (36), to order n**6."""
    n = f / (2.0 - f)
    n2, n3, n4, n5, n6 = n**2, n**3, n**4, n**5, n**6
    rectifying_radius_m = a_m / (1.0 + n) * (1.0 + n2 / 4.0 + n4 / 64.0 + n6 / 256.0)
    alpha = (
        n / 2 - 2 * n2 / 3 + 5 * n3 / 16 + 41 * n4 / 180 - 127 * n5 / 288 + 7891 * n6 / 37800,
        13 * n2 / 48 - 3 * n3 / 5 + 557 * n4 / 1440 + 281 * n5 / 630 - 1983433 * n6 / 1935360,
        61 * n3 / 240 - 103 * n4 / 140 + 15061 * n5 / 26880 + 167603 * n6 / 181440,
        49561 * n4 / 161280 - 179 * n5 / 168 + 6601661 * n6 / 7257600,
        34729 * n5 / 80640 - 3418889 * n6 / 1995840,
        212378941 * n6 / 319334400,
    )
    beta = (
        n / 2 - 2 * n2 / 3 + 37 * n3 / 96 - n4 / 360 - 81 * n5 / 512 + 96199 * n6 / 604800,
        n2 / 48 + n3 / 15 - 437 * n4 / 1440 + 46 * n5 / 105 - 1118711 * n6 / 3870720,
        17 * n3 / 480 - 37 * n4 / 840 - 209 * n5 / 4480 + 5569 * n6 / 90720,
        4397 * n4 / 161280 - 11 * n5 / 504 - 830251 * n6 / 7257600,
        4583 * n5 / 161280 - 108847 * n6 / 3991680,
        20648693 * n6 / 638668800,
    )
    return _TmSeries(
        e=math.sqrt(f * (2.0 - f)),
        rectifying_radius_m=rectifying_radius_m,
        alpha=alpha,
        beta=beta,
    )


_WGS84_SERIES = _tm_series(WGS84_A_M, WGS84_F)


def _conformal_tau(tau: FloatArray, e: float) -> FloatArray:
    """tan of the conformal latitude from tau = tan(geodetic latitude), Karney eq (7).

    ``sqrt(1 + x**2)`` stands for ``hypot(1, x)``: the same to an ulp for any latitude
    (|tau| < 1e17) and several times cheaper in numpy.
    """
    sqrt_1_tau2 = np.sqrt(1.0 + tau * tau)
    sigma = np.sinh(e * np.arctanh(e * tau / sqrt_1_tau2))
    result: FloatArray = tau * np.sqrt(1.0 + sigma * sigma) - sigma * sqrt_1_tau2
    return result


def _geodetic_tau(tau_prime: FloatArray, e: float) -> FloatArray:
    """Invert _conformal_tau by Newton's method, Karney eqs (19)-(21)."""
    one_minus_e2 = 1.0 - e * e
    tau = tau_prime.copy()
    for _ in range(_NEWTON_ITERATIONS):
        tau_i_prime = _conformal_tau(tau, e)
        d_tau = (
            (tau_prime - tau_i_prime)
            / np.hypot(1.0, tau_i_prime)
            * (1.0 + one_minus_e2 * tau * tau)
            / (one_minus_e2 * np.hypot(1.0, tau))
        )
        tau = tau + d_tau
    return tau


def _gauss_schreiber(
    series: _TmSeries, lat_rad: FloatArray, dlon_rad: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The spherical (Gauss-Schreiber) TM of the conformal sphere, Karney eqs (7)-(10):
    (xi', eta', tau, hypot(tau', cos l)); the last two are what the scale factor needs."""
    tau = np.tan(lat_rad)
    tau_p = _conformal_tau(tau, series.e)
    cos_l = np.cos(dlon_rad)
    hypot_tau_p_cos_l = np.hypot(tau_p, cos_l)
    xi_p = np.arctan2(tau_p, cos_l)
    eta_p = np.arcsinh(np.sin(dlon_rad) / hypot_tau_p_cos_l)
    return xi_p, eta_p, tau, hypot_tau_p_cos_l


def _sin_cos_2zeta(
    xi_p: FloatArray, eta_p: FloatArray
) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """sin(2 zeta') and 2 cos(2 zeta') for zeta' = xi' + i eta' (complex arrays)."""
    cos_2xi = np.cos(2.0 * xi_p)
    sin_2xi = np.sin(2.0 * xi_p)
    cosh_2eta = np.cosh(2.0 * eta_p)
    sinh_2eta = np.sinh(2.0 * eta_p)
    sin_2zeta = np.empty(xi_p.shape, dtype=np.complex128)
    sin_2zeta.real = sin_2xi * cosh_2eta
    sin_2zeta.imag = cos_2xi * sinh_2eta
    two_cos_2zeta = np.empty(xi_p.shape, dtype=np.complex128)
    two_cos_2zeta.real = 2.0 * cos_2xi * cosh_2eta
    two_cos_2zeta.imag = -2.0 * sin_2xi * sinh_2eta
    return sin_2zeta, two_cos_2zeta


def _clenshaw(
    two_cos_2zeta: NDArray[np.complex128], coefficients: tuple[float, ...]
) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """Clenshaw's recurrence for a series in the multiples 2 j zeta' (j = 1..len), with
    coefficients c_j: ``b_j = c_j + 2 cos(2 zeta') b_(j+1) - b_(j+2)``, down to (b_1, b_2).

    Then ``sum_j c_j sin(2 j zeta') = b_1 sin(2 zeta')`` and
    ``sum_j c_j cos(2 j zeta') = b_1 cos(2 zeta') - b_2`` (as GeographicLib sums Krüger's
    series: four trigonometric and hyperbolic functions per point, not four per term).
    """
    b1 = np.zeros_like(two_cos_2zeta)
    b2 = np.zeros_like(two_cos_2zeta)
    for c_j in reversed(coefficients):
        b1, b2 = two_cos_2zeta * b1 - b2 + c_j, b1
    return b1, b2


def _tm_forward(
    series: _TmSeries, lat_rad: FloatArray, dlon_rad: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Unit-scale TM: (x_m, y_m, k) for latitude and longitude from the central meridian.

    y is measured from the equator; k is the point scale factor (Karney eq (25)).
    """
    xi_p, eta_p, tau, hypot_tau_p_cos_l = _gauss_schreiber(series, lat_rad, dlon_rad)
    sin_2zeta, two_cos_2zeta = _sin_cos_2zeta(xi_p, eta_p)
    # zeta = zeta' + sum_j alpha_j sin(2 j zeta'), Karney eq (11).
    b1, _ = _clenshaw(two_cos_2zeta, series.alpha)
    zeta_sum = sin_2zeta * b1
    # p - i q = 1 + sum_j 2 j alpha_j cos(2 j zeta'), Karney eq (26).
    c1, c2 = _clenshaw(two_cos_2zeta, tuple(2 * j * a for j, a in enumerate(series.alpha, 1)))
    p_minus_iq = 1.0 + 0.5 * two_cos_2zeta * c1 - c2
    big_a = series.rectifying_radius_m
    sqrt_1me2 = math.sqrt(1.0 - series.e**2)
    k = big_a / WGS84_A_M * np.hypot(1.0, sqrt_1me2 * tau) * np.abs(p_minus_iq) / hypot_tau_p_cos_l
    return big_a * (eta_p + zeta_sum.imag), big_a * (xi_p + zeta_sum.real), k


def _tm_forward_xy(
    series: _TmSeries, lat_rad: FloatArray, dlon_rad: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """:func:`_tm_forward` without the scale factor: (x_m, y_m), all a projection needs."""
    xi_p, eta_p, _, _ = _gauss_schreiber(series, lat_rad, dlon_rad)
    sin_2zeta, two_cos_2zeta = _sin_cos_2zeta(xi_p, eta_p)
    b1, _ = _clenshaw(two_cos_2zeta, series.alpha)
    zeta_sum = sin_2zeta * b1
    big_a = series.rectifying_radius_m
    return big_a * (eta_p + zeta_sum.imag), big_a * (xi_p + zeta_sum.real)


def _tm_forward_point(series: _TmSeries, lat_rad: float, dlon_rad: float) -> tuple[float, float]:
    """:func:`_tm_forward` for one point in plain floats (x_m, y_m): the per-fix and
    per-step path of the coordinator and the simulator, where numpy's per-call cost on
    0-d arrays was most of the time."""
    tau = math.tan(lat_rad)
    e = series.e
    sigma = math.sinh(e * math.atanh(e * tau / math.hypot(1.0, tau)))
    tau_p = tau * math.hypot(1.0, sigma) - sigma * math.hypot(1.0, tau)
    cos_l = math.cos(dlon_rad)
    xi_p = math.atan2(tau_p, cos_l)
    eta_p = math.asinh(math.sin(dlon_rad) / math.hypot(tau_p, cos_l))
    xi, eta = xi_p, eta_p
    for j, alpha_j in enumerate(series.alpha, start=1):
        xi += alpha_j * math.sin(2 * j * xi_p) * math.cosh(2 * j * eta_p)
        eta += alpha_j * math.cos(2 * j * xi_p) * math.sinh(2 * j * eta_p)
    big_a = series.rectifying_radius_m
    return big_a * eta, big_a * xi


def _tm_reverse(
    series: _TmSeries, x_m: FloatArray, y_m: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Invert _tm_forward: (lat_rad, dlon_rad) from unit-scale TM x, y (y from the equator)."""
    xi = y_m / series.rectifying_radius_m
    eta = x_m / series.rectifying_radius_m
    xi_p = xi.copy()
    eta_p = eta.copy()
    for j, beta_j in enumerate(series.beta, start=1):
        xi_p = xi_p - beta_j * np.sin(2 * j * xi) * np.cosh(2 * j * eta)
        eta_p = eta_p - beta_j * np.cos(2 * j * xi) * np.sinh(2 * j * eta)
    sinh_eta_p = np.sinh(eta_p)
    cos_xi_p = np.cos(xi_p)
    tau_p = np.sin(xi_p) / np.hypot(sinh_eta_p, cos_xi_p)
    dlon_rad = np.arctan2(sinh_eta_p, cos_xi_p)
    lat_rad = np.arctan(_geodetic_tau(tau_p, series.e))
    return lat_rad, dlon_rad


def _as_float_arrays(
    name_a: str, a: ArrayLike, name_b: str, b: ArrayLike
) -> tuple[FloatArray, FloatArray, bool]:
    """Broadcast two inputs to float64 arrays; flag whether both were scalars."""
    arr_a = np.asarray(a, dtype=np.float64)
    arr_b = np.asarray(b, dtype=np.float64)
    for name, arr in ((name_a, arr_a), (name_b, arr_b)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite")
    try:
        arr_a, arr_b = np.broadcast_arrays(arr_a, arr_b)
    except ValueError:
        raise ValueError(
            f"{name_a} shape {arr_a.shape} and {name_b} shape {arr_b.shape} do not broadcast"
        ) from None
    return arr_a, arr_b, arr_a.ndim == 0


def _wrap_deg(angle_deg: FloatArray) -> FloatArray:
    """Wrap angles to [-180, 180) degrees."""
    wrapped: FloatArray = (angle_deg + 180.0) % 360.0 - 180.0
    return wrapped


@dataclass(frozen=True)
class LocalFrame:
    """Local east/north plane (m) about a geodetic origin on the WGS84 ellipsoid.

    The plane is a Transverse Mercator projection with the central meridian through the origin
    and unit scale on it; the origin maps to (0, 0), east is +x and north is +y on the central
    meridian. Distances in the plane exceed ellipsoidal distances by the point scale factor
    ``k`` (see `scale_factor`), about 1 + east_m**2 / (2 R**2): 0.11 % at 300 km from the
    central meridian.

    Parameters
    ----------
    origin_lat_deg : float
        Geodetic latitude of the origin (deg), within +-89.
    origin_lon_deg : float
        Longitude of the origin (deg), within [-180, 180].

    Notes
    -----
    Methods accept floats or numpy arrays (broadcast together); two scalars give floats back,
    otherwise arrays of the broadcast shape.
    """

    origin_lat_deg: float
    origin_lon_deg: float
    _origin_y_m: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not math.isfinite(self.origin_lat_deg) or abs(self.origin_lat_deg) > (
            _MAX_ORIGIN_LAT_DEG
        ):
            raise ValueError(
                f"origin_lat_deg must be within +-{_MAX_ORIGIN_LAT_DEG:g} deg, "
                f"got {self.origin_lat_deg}"
            )
        if not math.isfinite(self.origin_lon_deg) or abs(self.origin_lon_deg) > 180.0:
            raise ValueError(
                f"origin_lon_deg must be within [-180, 180] deg, got {self.origin_lon_deg}"
            )
        _, y_m, _ = _tm_forward(
            _WGS84_SERIES,
            np.array(math.radians(self.origin_lat_deg)),
            np.array(0.0),
        )
        object.__setattr__(self, "_origin_y_m", float(y_m))

    @overload
    def to_local(self, lat_deg: float, lon_deg: float) -> tuple[float, float]: ...
    @overload
    def to_local(
        self, lat_deg: FloatArray, lon_deg: FloatArray | float
    ) -> tuple[FloatArray, FloatArray]: ...
    @overload
    def to_local(self, lat_deg: float, lon_deg: FloatArray) -> tuple[FloatArray, FloatArray]: ...
    def to_local(
        self, lat_deg: FloatArray | float, lon_deg: FloatArray | float
    ) -> tuple[FloatArray, FloatArray] | tuple[float, float]:
        """Project geodetic coordinates into the local plane.

        Parameters
        ----------
        lat_deg : float or ndarray
            Geodetic latitude (deg), within +-90.
        lon_deg : float or ndarray
            Longitude (deg); any value, wrapped about the origin's meridian.

        Returns
        -------
        east_m, north_m : float or ndarray
            Local plane coordinates (m) relative to the origin.

        Raises
        ------
        ValueError
            If an input is not finite or a latitude is outside +-90 deg.
        """
        if isinstance(lat_deg, float | int) and isinstance(lon_deg, float | int):
            if not (math.isfinite(lat_deg) and math.isfinite(lon_deg)):
                raise ValueError(
                    f"{'lat_deg' if not math.isfinite(lat_deg) else 'lon_deg'} must be finite"
                )
            if abs(lat_deg) > 90.0:
                raise ValueError("lat_deg must be within +-90 deg")
            dlon_deg = (lon_deg - self.origin_lon_deg + 180.0) % 360.0 - 180.0
            east, y = _tm_forward_point(
                _WGS84_SERIES, math.radians(lat_deg), math.radians(dlon_deg)
            )
            return east, y - self._origin_y_m
        lat, lon, scalar = _as_float_arrays("lat_deg", lat_deg, "lon_deg", lon_deg)
        if np.any(np.abs(lat) > 90.0):
            raise ValueError("lat_deg must be within +-90 deg")
        x_m, y_m = _tm_forward_xy(
            _WGS84_SERIES,
            np.radians(lat),
            np.radians(_wrap_deg(lon - self.origin_lon_deg)),
        )
        north_m = y_m - self._origin_y_m
        if scalar:
            return float(x_m), float(north_m)
        return x_m, north_m

    @overload
    def to_geodetic(self, east_m: float, north_m: float) -> tuple[float, float]: ...
    @overload
    def to_geodetic(
        self, east_m: FloatArray, north_m: FloatArray | float
    ) -> tuple[FloatArray, FloatArray]: ...
    @overload
    def to_geodetic(self, east_m: float, north_m: FloatArray) -> tuple[FloatArray, FloatArray]: ...
    def to_geodetic(
        self, east_m: FloatArray | float, north_m: FloatArray | float
    ) -> tuple[FloatArray, FloatArray] | tuple[float, float]:
        """Convert local plane coordinates back to geodetic coordinates.

        Parameters
        ----------
        east_m, north_m : float or ndarray
            Local plane coordinates (m) relative to the origin.

        Returns
        -------
        lat_deg, lon_deg : float or ndarray
            Geodetic latitude (deg) and longitude (deg, wrapped to [-180, 180)).

        Raises
        ------
        ValueError
            If an input is not finite.
        """
        x_m, north, scalar = _as_float_arrays("east_m", east_m, "north_m", north_m)
        lat_rad, dlon_rad = _tm_reverse(_WGS84_SERIES, x_m, north + self._origin_y_m)
        lat_deg = np.degrees(lat_rad)
        lon_deg = _wrap_deg(np.degrees(dlon_rad) + self.origin_lon_deg)
        if scalar:
            return float(lat_deg), float(lon_deg)
        return lat_deg, lon_deg

    @overload
    def scale_factor(self, east_m: float, north_m: float) -> float: ...
    @overload
    def scale_factor(self, east_m: FloatArray, north_m: FloatArray | float) -> FloatArray: ...
    @overload
    def scale_factor(self, east_m: float, north_m: FloatArray) -> FloatArray: ...
    def scale_factor(
        self, east_m: FloatArray | float, north_m: FloatArray | float
    ) -> FloatArray | float:
        """Point scale factor of the projection at local plane coordinates.

        A short ellipsoidal distance ``ds`` near the point appears as ``k * ds`` in the plane;
        ``k >= 1``, with ``k == 1`` on the origin's meridian.

        Parameters
        ----------
        east_m, north_m : float or ndarray
            Local plane coordinates (m) relative to the origin.

        Returns
        -------
        k : float or ndarray
            Scale factor (dimensionless).
        """
        x_m, north, scalar = _as_float_arrays("east_m", east_m, "north_m", north_m)
        lat_rad, dlon_rad = _tm_reverse(_WGS84_SERIES, x_m, north + self._origin_y_m)
        _, _, k = _tm_forward(_WGS84_SERIES, lat_rad, dlon_rad)
        if scalar:
            return float(k)
        return k


def geodesic_distance_m(
    lat1_deg: float, lon1_deg: float, lat2_deg: float, lon2_deg: float
) -> float:
    """Ellipsoidal distance between two points on WGS84 (Vincenty's inverse method).

    Accurate to well under a millimetre; meant for checks and tests, not hot loops.

    Parameters
    ----------
    lat1_deg, lon1_deg : float
        First point: geodetic latitude and longitude (deg).
    lat2_deg, lon2_deg : float
        Second point: geodetic latitude and longitude (deg).

    Returns
    -------
    float
        Length of the shortest geodesic (m).

    Raises
    ------
    ValueError
        If a latitude is outside +-90 deg, an input is not finite, or the points are so
        nearly antipodal that the iteration does not converge.
    """
    for name, value in (("lat1_deg", lat1_deg), ("lat2_deg", lat2_deg)):
        if not math.isfinite(value) or abs(value) > 90.0:
            raise ValueError(f"{name} must be within +-90 deg, got {value}")
    for name, value in (("lon1_deg", lon1_deg), ("lon2_deg", lon2_deg)):
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value}")
    a = WGS84_A_M
    f = WGS84_F
    b = a * (1.0 - f)
    big_l = math.radians(lon2_deg - lon1_deg)
    u1 = math.atan((1.0 - f) * math.tan(math.radians(lat1_deg)))
    u2 = math.atan((1.0 - f) * math.tan(math.radians(lat2_deg)))
    sin_u1, cos_u1 = math.sin(u1), math.cos(u1)
    sin_u2, cos_u2 = math.sin(u2), math.cos(u2)
    lam = big_l
    for _ in range(200):
        sin_lam, cos_lam = math.sin(lam), math.cos(lam)
        sin_sigma = math.hypot(cos_u2 * sin_lam, cos_u1 * sin_u2 - sin_u1 * cos_u2 * cos_lam)
        if sin_sigma == 0.0:
            return 0.0
        cos_sigma = sin_u1 * sin_u2 + cos_u1 * cos_u2 * cos_lam
        sigma = math.atan2(sin_sigma, cos_sigma)
        sin_alpha = cos_u1 * cos_u2 * sin_lam / sin_sigma
        cos2_alpha = 1.0 - sin_alpha**2
        # On the equator cos2_alpha is 0 and the term it divides drops out.
        cos_2sm = cos_sigma - 2.0 * sin_u1 * sin_u2 / cos2_alpha if cos2_alpha != 0.0 else 0.0
        c = f / 16.0 * cos2_alpha * (4.0 + f * (4.0 - 3.0 * cos2_alpha))
        lam_prev = lam
        lam = big_l + (1.0 - c) * f * sin_alpha * (
            sigma + c * sin_sigma * (cos_2sm + c * cos_sigma * (-1.0 + 2.0 * cos_2sm**2))
        )
        # Relative test: the trig values above belong to lam_prev, and on short lines lam is
        # tiny, so an absolute tolerance would leave a large relative error in the distance.
        if abs(lam - lam_prev) <= 1e-14 * abs(lam):
            break
    else:
        raise ValueError(
            "geodesic_distance_m did not converge: points are nearly antipodal "
            f"({lat1_deg}, {lon1_deg}) -> ({lat2_deg}, {lon2_deg})"
        )
    u_sq = cos2_alpha * (a * a - b * b) / (b * b)
    big_a = 1.0 + u_sq / 16384.0 * (4096.0 + u_sq * (-768.0 + u_sq * (320.0 - 175.0 * u_sq)))
    big_b = u_sq / 1024.0 * (256.0 + u_sq * (-128.0 + u_sq * (74.0 - 47.0 * u_sq)))
    delta_sigma = (
        big_b
        * sin_sigma
        * (
            cos_2sm
            + big_b
            / 4.0
            * (
                cos_sigma * (-1.0 + 2.0 * cos_2sm**2)
                - big_b / 6.0 * cos_2sm * (-3.0 + 4.0 * sin_sigma**2) * (-3.0 + 4.0 * cos_2sm**2)
            )
        )
    )
    return b * big_a * (sigma - delta_sigma)

"""Tests of planner.geo: local Transverse Mercator frame and Vincenty distances."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planner import geo
from planner.geo import WGS84_A_M, WGS84_F, LocalFrame, geodesic_distance_m

ORIGIN_LATS_DEG = (0.0, 37.0, 60.0, -45.0)
AREA_RADIUS_M = 300_000.0

UTM_K0 = 0.9996
UTM_FALSE_EASTING_M = 500_000.0
UTM_FALSE_NORTHING_SOUTH_M = 10_000_000.0


def dms(deg: float, minutes: float, seconds: float) -> float:
    """Degrees from degrees, minutes, seconds (sign taken from deg)."""
    sign = -1.0 if deg < 0 else 1.0
    return sign * (abs(deg) + minutes / 60.0 + seconds / 3600.0)


def utm(lat_deg: float, lon_deg: float, zone: int) -> tuple[float, float]:
    """UTM easting and northing (m) built from the same series with UTM constants.

    A frame whose origin is on the equator at the zone's central meridian is the unit-scale
    Transverse Mercator of that zone; UTM scales it by k0 and adds the false origin.
    """
    central_lon_deg = -183.0 + 6.0 * zone
    east_m, north_m = LocalFrame(0.0, central_lon_deg).to_local(lat_deg, lon_deg)
    northing = UTM_K0 * north_m + (UTM_FALSE_NORTHING_SOUTH_M if lat_deg < 0 else 0.0)
    return UTM_FALSE_EASTING_M + UTM_K0 * east_m, northing


def points_in_area(rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Uniform random local points (m) in the disc of AREA_RADIUS_M about the origin."""
    radius_m = AREA_RADIUS_M * np.sqrt(rng.uniform(0.0, 1.0, count))
    bearing_rad = rng.uniform(0.0, 2.0 * math.pi, count)
    return radius_m * np.sin(bearing_rad), radius_m * np.cos(bearing_rad)


origin_lats = st.sampled_from(ORIGIN_LATS_DEG)
origin_lons = st.floats(min_value=-180.0, max_value=180.0)
offsets_m = st.floats(
    min_value=-AREA_RADIUS_M / math.sqrt(2), max_value=AREA_RADIUS_M / math.sqrt(2)
)


# --- constants and frame basics -------------------------------------------------------------


def test_wgs84_constants() -> None:
    assert WGS84_A_M == 6378137.0
    assert pytest.approx(298.257223563, abs=1e-9) == 1.0 / WGS84_F


@pytest.mark.parametrize("origin_lat_deg", ORIGIN_LATS_DEG)
def test_origin_maps_to_zero(origin_lat_deg: float) -> None:
    frame = LocalFrame(origin_lat_deg, 12.5)
    east_m, north_m = frame.to_local(origin_lat_deg, 12.5)
    assert east_m == pytest.approx(0.0, abs=1e-9)
    assert north_m == pytest.approx(0.0, abs=1e-9)
    assert frame.to_geodetic(0.0, 0.0) == pytest.approx((origin_lat_deg, 12.5), abs=1e-12)


@pytest.mark.parametrize("origin_lat_deg", ORIGIN_LATS_DEG)
def test_axes_point_east_and_north(origin_lat_deg: float) -> None:
    frame = LocalFrame(origin_lat_deg, -70.0)
    east_m, north_m = frame.to_local(origin_lat_deg + 0.01, -70.0)
    assert east_m == pytest.approx(0.0, abs=1e-9)
    assert north_m > 1000.0
    east_m, north_m = frame.to_local(origin_lat_deg, -69.99)
    assert east_m > 500.0
    # Parallels curve towards the pole in a transverse projection, but only slightly.
    assert abs(north_m) < 1e-3 * east_m


@pytest.mark.parametrize("origin_lat_deg", ORIGIN_LATS_DEG)
def test_north_along_central_meridian_is_the_meridian_arc(origin_lat_deg: float) -> None:
    # On the central meridian the projection is true to scale, so north_m is the ellipsoidal
    # distance along the meridian; Vincenty gives that independently.
    frame = LocalFrame(origin_lat_deg, 3.0)
    for dlat_deg in (-2.5, -0.7, 0.3, 2.5):
        lat_deg = origin_lat_deg + dlat_deg
        east_m, north_m = frame.to_local(lat_deg, 3.0)
        arc_m = geodesic_distance_m(origin_lat_deg, 3.0, lat_deg, 3.0)
        assert east_m == pytest.approx(0.0, abs=1e-9)
        assert north_m == pytest.approx(math.copysign(arc_m, dlat_deg), abs=1e-4)


# --- round trips ----------------------------------------------------------------------------


@settings(max_examples=200, deadline=None)
@given(origin_lats, origin_lons, offsets_m, offsets_m)
def test_round_trip_local_geodetic_local(
    origin_lat_deg: float, origin_lon_deg: float, east_m: float, north_m: float
) -> None:
    frame = LocalFrame(origin_lat_deg, origin_lon_deg)
    lat_deg, lon_deg = frame.to_geodetic(east_m, north_m)
    east2_m, north2_m = frame.to_local(lat_deg, lon_deg)
    assert math.hypot(east2_m - east_m, north2_m - north_m) < 1e-3


@pytest.mark.parametrize("origin_lat_deg", ORIGIN_LATS_DEG)
def test_round_trip_vectorised_300_km_all_directions(origin_lat_deg: float) -> None:
    frame = LocalFrame(origin_lat_deg, -122.0)
    rng = np.random.default_rng(7)
    east_m, north_m = points_in_area(rng, 20_000)
    # Include the extreme points of the area exactly, in every direction.
    bearings = np.linspace(0.0, 2.0 * math.pi, 16, endpoint=False)
    east_m = np.concatenate([east_m, AREA_RADIUS_M * np.sin(bearings)])
    north_m = np.concatenate([north_m, AREA_RADIUS_M * np.cos(bearings)])
    lat_deg, lon_deg = frame.to_geodetic(east_m, north_m)
    east2_m, north2_m = frame.to_local(lat_deg, lon_deg)
    error_m = np.hypot(east2_m - east_m, north2_m - north_m)
    assert error_m.max() < 1e-3
    # In practice the series is far better than required.
    assert error_m.max() < 1e-6


@settings(max_examples=100, deadline=None)
@given(
    origin_lats,
    st.floats(min_value=-2.0, max_value=2.0),
    st.floats(min_value=-3.5, max_value=3.5),
)
def test_round_trip_geodetic_local_geodetic(
    origin_lat_deg: float, dlat_deg: float, dlon_deg: float
) -> None:
    frame = LocalFrame(origin_lat_deg, 100.0)
    lat_deg, lon_deg = origin_lat_deg + dlat_deg, 100.0 + dlon_deg
    lat2_deg, lon2_deg = frame.to_geodetic(*frame.to_local(lat_deg, lon_deg))
    assert geodesic_distance_m(lat_deg, lon_deg, lat2_deg, lon2_deg) < 1e-3


def test_longitude_wraps_across_the_antimeridian() -> None:
    frame = LocalFrame(0.0, 179.9)
    east_m, north_m = frame.to_local(0.0, -179.9)
    # The same as 0.2 deg east of any other meridian, and about 0.2 deg of equator.
    expected_m, _ = LocalFrame(0.0, 0.0).to_local(0.0, 0.2)
    assert east_m == pytest.approx(expected_m, abs=1e-9)
    assert east_m == pytest.approx(WGS84_A_M * math.radians(0.2), rel=1e-5)
    assert north_m == pytest.approx(0.0, abs=1e-6)
    lat_deg, lon_deg = frame.to_geodetic(east_m, north_m)
    assert lat_deg == pytest.approx(0.0, abs=1e-12)
    assert lon_deg == pytest.approx(-179.9, abs=1e-9)


# --- known answers --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("lat_deg", "lon_deg", "zone", "easting_m", "northing_m", "tol_m"),
    [
        # GeographicLib GeoConvert documentation: "33.3 44.4" -> 38n 444140.54 3684706.36.
        (33.3, 44.4, 38, 444140.54, 3684706.36, 0.006),
        # AGI STK Connect "Convert MapGridPoint" example: 33.5 74.75 -> 43S 476779 3706747.
        (33.5, 74.75, 43, 476779.0, 3706747.0, 0.6),
        # Flinders Peak (GDA Technical Manual, MGA zone 55; GRS80 differs from WGS84 by
        # well under a millimetre here): E 273741.297 N 5796489.777.
        (dms(-37, 57, 3.72030), dms(144, 25, 29.52440), 55, 273741.297, 5796489.777, 0.002),
    ],
)
def test_utm_known_answers(
    lat_deg: float, lon_deg: float, zone: int, easting_m: float, northing_m: float, tol_m: float
) -> None:
    east_m, north_m = utm(lat_deg, lon_deg, zone)
    assert east_m == pytest.approx(easting_m, abs=tol_m)
    assert north_m == pytest.approx(northing_m, abs=tol_m)


def test_vincenty_flinders_peak_to_buninyong() -> None:
    # Vincenty (1975) / GDA Technical Manual worked example.
    flinders = (dms(-37, 57, 3.72030), dms(144, 25, 29.52440))
    buninyong = (dms(-37, 39, 10.15610), dms(143, 55, 35.38390))
    assert geodesic_distance_m(*flinders, *buninyong) == pytest.approx(54972.271, abs=1e-3)
    assert geodesic_distance_m(*buninyong, *flinders) == pytest.approx(54972.271, abs=1e-3)


@pytest.mark.parametrize(
    ("lat1", "lon1", "lat2", "lon2", "expected_m"),
    [
        # A quarter of the equator: a * pi / 2.
        (0.0, 0.0, 0.0, 90.0, WGS84_A_M * math.pi / 2.0),
        # WGS84 quarter meridian (equator to pole).
        (0.0, 0.0, 90.0, 0.0, 10001965.729),
        (0.0, 0.0, -90.0, 45.0, 10001965.729),
        # Coincident points.
        (37.0, -122.0, 37.0, -122.0, 0.0),
    ],
)
def test_vincenty_known_answers(
    lat1: float, lon1: float, lat2: float, lon2: float, expected_m: float
) -> None:
    assert geodesic_distance_m(lat1, lon1, lat2, lon2) == pytest.approx(expected_m, abs=1e-3)


def ecef_m(lat_deg: float, lon_deg: float) -> tuple[float, float, float]:
    """Earth-centred Cartesian coordinates (m) of a point on the WGS84 ellipsoid."""
    e2 = WGS84_F * (2.0 - WGS84_F)
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    n_m = WGS84_A_M / math.sqrt(1.0 - e2 * math.sin(lat) ** 2)
    return (
        n_m * math.cos(lat) * math.cos(lon),
        n_m * math.cos(lat) * math.sin(lon),
        n_m * (1.0 - e2) * math.sin(lat),
    )


@pytest.mark.parametrize("lat_deg", [0.0, 37.0, 60.0, -45.0, 85.0])
@pytest.mark.parametrize("bearing_deg", [0.0, 45.0, 90.0, 160.0])
@pytest.mark.parametrize("length_m", [1.0, 20.0, 100.0])
def test_vincenty_short_lines_match_the_chord(
    lat_deg: float, bearing_deg: float, length_m: float
) -> None:
    # Below 100 m the geodesic and the straight 3-D chord differ by < 1e-9 m.
    dlat_deg = length_m * math.cos(math.radians(bearing_deg)) / 111_000.0
    dlon_deg = (
        length_m
        * math.sin(math.radians(bearing_deg))
        / (111_000.0 * math.cos(math.radians(lat_deg)))
    )
    a = (lat_deg, 8.0)
    b = (lat_deg + dlat_deg, 8.0 + dlon_deg)
    chord_m = math.dist(ecef_m(*a), ecef_m(*b))
    assert geodesic_distance_m(*a, *b) == pytest.approx(chord_m, abs=1e-8)


def test_vincenty_nearly_antipodal_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="antipodal"):
        geodesic_distance_m(0.0, 0.0, 0.5, 179.7)


# --- scale factor and distance distortion ---------------------------------------------------


@pytest.mark.parametrize("origin_lat_deg", ORIGIN_LATS_DEG)
def test_scale_factor_is_one_on_central_meridian_and_grows_east_west(
    origin_lat_deg: float,
) -> None:
    frame = LocalFrame(origin_lat_deg, 0.0)
    north_m = np.linspace(-AREA_RADIUS_M, AREA_RADIUS_M, 7)
    np.testing.assert_allclose(frame.scale_factor(np.zeros(7), north_m), 1.0, atol=1e-12)
    # k ~ 1 + x^2 / (2 R^2) with R the Gaussian mean radius at the point's latitude.
    for east_m in (50_000.0, -150_000.0, 300_000.0):
        lat_rad = math.radians(frame.to_geodetic(east_m, 0.0)[0])
        e2 = WGS84_F * (2.0 - WGS84_F)
        radius_m = WGS84_A_M * math.sqrt(1.0 - e2) / (1.0 - e2 * math.sin(lat_rad) ** 2)
        expected = 1.0 + east_m**2 / (2.0 * radius_m**2)
        assert frame.scale_factor(east_m, 0.0) == pytest.approx(expected, abs=2e-6)


@pytest.mark.parametrize("origin_lat_deg", ORIGIN_LATS_DEG)
def test_scale_factor_matches_local_distance_ratio(origin_lat_deg: float) -> None:
    # Point scale: a short step centred on the point, d metres long in the plane, covers
    # d / k metres on the ellipsoid.
    frame = LocalFrame(origin_lat_deg, 20.0)
    for east_m, north_m in ((0.0, 0.0), (250_000.0, 100_000.0), (-120_000.0, -280_000.0)):
        k = frame.scale_factor(east_m, north_m)
        for step_e, step_n in ((20.0, 0.0), (0.0, 20.0), (14.0, -14.0)):
            a = frame.to_geodetic(east_m - step_e / 2.0, north_m - step_n / 2.0)
            b = frame.to_geodetic(east_m + step_e / 2.0, north_m + step_n / 2.0)
            ratio = math.hypot(step_e, step_n) / geodesic_distance_m(*a, *b)
            assert ratio == pytest.approx(k, abs=1e-8)


@settings(max_examples=150, deadline=None)
@given(origin_lats, offsets_m, offsets_m, offsets_m, offsets_m)
def test_plane_distance_within_scale_factor_bound(
    origin_lat_deg: float, e1_m: float, n1_m: float, e2_m: float, n2_m: float
) -> None:
    frame = LocalFrame(origin_lat_deg, -45.0)
    plane_m = math.hypot(e2_m - e1_m, n2_m - n1_m)
    lat1, lon1 = frame.to_geodetic(e1_m, n1_m)
    lat2, lon2 = frame.to_geodetic(e2_m, n2_m)
    geo_m = geodesic_distance_m(lat1, lon1, lat2, lon2)
    if geo_m < 1.0:
        return
    k1, k2 = frame.scale_factor(e1_m, n1_m), frame.scale_factor(e2_m, n2_m)
    ratio = plane_m / geo_m
    # k >= 1 everywhere and is largest at the ends of the segment (farthest east/west).
    assert 1.0 - 1e-6 <= ratio <= max(k1, k2) + 1e-6
    # Tighter: the line scale factor by Simpson's rule over the segment.
    k_mid = frame.scale_factor((e1_m + e2_m) / 2.0, (n1_m + n2_m) / 2.0)
    line_scale = 6.0 / (1.0 / k1 + 4.0 / k_mid + 1.0 / k2)
    assert ratio == pytest.approx(line_scale, abs=1e-6)


# --- independent reference ------------------------------------------------------------------


@pytest.mark.parametrize("origin_lat_deg", ORIGIN_LATS_DEG)
def test_matches_proj_tmerc(origin_lat_deg: float) -> None:
    pyproj = pytest.importorskip("pyproj")
    origin_lon_deg = 151.2
    frame = LocalFrame(origin_lat_deg, origin_lon_deg)
    proj = pyproj.Transformer.from_crs(
        "EPSG:4326",
        f"+proj=tmerc +lat_0={origin_lat_deg} +lon_0={origin_lon_deg} +k_0=1 "
        "+x_0=0 +y_0=0 +ellps=WGS84 +units=m",
        always_xy=True,
    )
    east_m, north_m = points_in_area(np.random.default_rng(3), 2000)
    lat_deg, lon_deg = frame.to_geodetic(east_m, north_m)
    proj_east_m, proj_north_m = proj.transform(lon_deg, lat_deg)
    np.testing.assert_allclose(proj_east_m, east_m, atol=1e-6)
    np.testing.assert_allclose(proj_north_m, north_m, atol=1e-6)
    proj_lon_deg, proj_lat_deg = proj.transform(east_m, north_m, direction="INVERSE")
    np.testing.assert_allclose(proj_lat_deg, lat_deg, atol=1e-11)
    np.testing.assert_allclose(proj_lon_deg, lon_deg, atol=1e-11)
    # Plain floats take their own path (the per-fix one): as close to PROJ.
    for k in range(0, 2000, 7):
        e, n = frame.to_local(float(lat_deg[k]), float(lon_deg[k]))
        assert type(e) is float and type(n) is float
        assert (e, n) == pytest.approx((proj_east_m[k], proj_north_m[k]), abs=1e-6)


def test_vincenty_matches_proj_geod() -> None:
    pyproj = pytest.importorskip("pyproj")
    geod = pyproj.Geod(ellps="WGS84")
    rng = np.random.default_rng(11)
    for _ in range(200):
        lat1, lat2 = rng.uniform(-80.0, 80.0, 2)
        lon1, lon2 = rng.uniform(-180.0, 180.0, 2)
        if abs(lat1 + lat2) < 5.0 and abs(abs(lon1 - lon2) - 180.0) < 5.0:
            continue  # nearly antipodal: Vincenty is not expected to converge
        _, _, expected_m = geod.inv(lon1, lat1, lon2, lat2)
        assert geodesic_distance_m(lat1, lon1, lat2, lon2) == pytest.approx(expected_m, abs=1e-4)


# --- shapes and validation ------------------------------------------------------------------


def test_scalars_give_floats_and_arrays_keep_shape() -> None:
    frame = LocalFrame(37.0, -122.0)
    east_m, north_m = frame.to_local(37.1, -122.1)
    assert type(east_m) is float
    assert type(north_m) is float
    assert type(frame.scale_factor(1000.0, 0.0)) is float
    lat = np.full((3, 4), 37.2)
    lon = np.linspace(-122.5, -121.5, 4)
    east_a, north_a = frame.to_local(lat, lon)
    assert east_a.shape == north_a.shape == (3, 4)
    lat_a, lon_a = frame.to_geodetic(east_a, 0.0)
    assert lat_a.shape == lon_a.shape == (3, 4)
    assert frame.scale_factor(east_a, north_a).shape == (3, 4)
    # Element-wise equal to scalar calls.
    assert east_a[1, 2] == pytest.approx(frame.to_local(37.2, float(lon[2]))[0], abs=1e-9)


@pytest.mark.parametrize(
    ("origin_lat_deg", "origin_lon_deg", "field"),
    [
        (89.5, 0.0, "origin_lat_deg"),
        (-90.0, 0.0, "origin_lat_deg"),
        (math.nan, 0.0, "origin_lat_deg"),
        (10.0, 181.0, "origin_lon_deg"),
        (10.0, math.inf, "origin_lon_deg"),
    ],
)
def test_invalid_origin_names_the_field(
    origin_lat_deg: float, origin_lon_deg: float, field: str
) -> None:
    with pytest.raises(ValueError, match=field):
        LocalFrame(origin_lat_deg, origin_lon_deg)


def test_invalid_inputs_name_the_argument() -> None:
    frame = LocalFrame(10.0, 10.0)
    with pytest.raises(ValueError, match="lat_deg"):
        frame.to_local(90.5, 10.0)
    with pytest.raises(ValueError, match="lat_deg"):
        frame.to_local(np.array([10.0, -91.0]), 10.0)
    with pytest.raises(ValueError, match="lon_deg"):
        frame.to_local(10.0, math.nan)
    with pytest.raises(ValueError, match="north_m"):
        frame.to_geodetic(0.0, math.inf)
    with pytest.raises(ValueError, match="east_m"):
        frame.scale_factor(math.nan, 0.0)
    with pytest.raises(ValueError, match="do not broadcast"):
        frame.to_local(np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match="lat2_deg"):
        geodesic_distance_m(0.0, 0.0, 95.0, 0.0)
    with pytest.raises(ValueError, match="lon1_deg"):
        geodesic_distance_m(0.0, math.nan, 5.0, 0.0)


def test_frame_is_a_frozen_value() -> None:
    frame = LocalFrame(37.0, -122.0)
    assert frame == LocalFrame(37.0, -122.0)
    assert frame != LocalFrame(37.0, -121.0)
    assert hash(frame) == hash(LocalFrame(37.0, -122.0))
    with pytest.raises(AttributeError):
        frame.origin_lat_deg = 38.0  # type: ignore[misc]


def _tm_forward_term_by_term(
    lat_rad: np.ndarray, dlon_rad: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Karney (2011) eqs (7)-(11), (25)-(26) with the Krüger series summed term by term."""
    series = geo._WGS84_SERIES
    e = series.e
    tau = np.tan(lat_rad)
    sigma = np.sinh(e * np.arctanh(e * tau / np.hypot(1.0, tau)))
    tau_p = tau * np.hypot(1.0, sigma) - sigma * np.hypot(1.0, tau)
    xi_p = np.arctan2(tau_p, np.cos(dlon_rad))
    eta_p = np.arcsinh(np.sin(dlon_rad) / np.hypot(tau_p, np.cos(dlon_rad)))
    xi, eta, p, q = xi_p.copy(), eta_p.copy(), np.ones_like(xi_p), np.zeros_like(xi_p)
    for j, alpha_j in enumerate(series.alpha, start=1):
        xi += alpha_j * np.sin(2 * j * xi_p) * np.cosh(2 * j * eta_p)
        eta += alpha_j * np.cos(2 * j * xi_p) * np.sinh(2 * j * eta_p)
        p += 2 * j * alpha_j * np.cos(2 * j * xi_p) * np.cosh(2 * j * eta_p)
        q += 2 * j * alpha_j * np.sin(2 * j * xi_p) * np.sinh(2 * j * eta_p)
    big_a = series.rectifying_radius_m
    k = (
        big_a
        / WGS84_A_M
        * np.hypot(1.0, math.sqrt(1.0 - e * e) * tau)
        * np.hypot(p, q)
        / np.hypot(tau_p, np.cos(dlon_rad))
    )
    return big_a * eta, big_a * xi, k


def test_clenshaw_summation_is_the_series_summed_term_by_term() -> None:
    rng = np.random.default_rng(3)
    lat_rad = np.radians(rng.uniform(-85.0, 85.0, 20000))
    dlon_rad = np.radians(rng.uniform(-40.0, 40.0, 20000))
    x_m, y_m, k = geo._tm_forward(geo._WGS84_SERIES, lat_rad, dlon_rad)
    x_ref, y_ref, k_ref = _tm_forward_term_by_term(lat_rad, dlon_rad)
    assert np.abs(x_m - x_ref).max() < 1e-8  # metres: a few ulps of 1e7 m
    assert np.abs(y_m - y_ref).max() < 1e-8
    assert np.abs(k - k_ref).max() < 1e-14
    x_only, y_only = geo._tm_forward_xy(geo._WGS84_SERIES, lat_rad, dlon_rad)
    assert np.array_equal(x_only, x_m) and np.array_equal(y_only, y_m)

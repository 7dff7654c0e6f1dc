"""Tests of planner.terrain: synthetic hills, SRTM tiles, clearance."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from planner.errors import TerrainError
from planner.geo import LocalFrame
from planner.terrain import (
    SRTM_VOID,
    GaussianHill,
    SrtmTerrain,
    SyntheticTerrain,
    Terrain,
    clearance_m,
    min_clearance_along,
    srtm_tile_name,
)

AREA = {
    "min_east_m": -50_000.0,
    "max_east_m": 50_000.0,
    "min_north_m": -40_000.0,
    "max_north_m": 60_000.0,
}

# --- helpers: synthetic SRTM tiles ----------------------------------------------------------

# A plane in degrees whose value is an integer at every 3" (and 1") sample, so the int16 tile
# stores it exactly and bilinear interpolation must reproduce it exactly.
PLANE_M_PER_DEG_LAT = 2.0 * 1200.0
PLANE_M_PER_DEG_LON = 3.0 * 1200.0
PLANE_BASE_M = 100.0
PLANE_LAT0_DEG = 37.0
PLANE_LON0_DEG = -123.0


def plane_m(lat_deg: np.ndarray | float, lon_deg: np.ndarray | float) -> np.ndarray:
    """Reference elevation (m) of the test tiles."""
    return np.asarray(
        PLANE_BASE_M
        + PLANE_M_PER_DEG_LAT * (np.asarray(lat_deg) - PLANE_LAT0_DEG)
        + PLANE_M_PER_DEG_LON * (np.asarray(lon_deg) - PLANE_LON0_DEG),
        dtype=np.float64,
    )


def tile_grid_deg(
    lat_south_deg: int, lon_west_deg: int, samples: int
) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude (deg) of every sample, in SRTM order: rows north to south."""
    lat = lat_south_deg + 1.0 - np.arange(samples) / (samples - 1)
    lon = lon_west_deg + np.arange(samples) / (samples - 1)
    lat_grid, lon_grid = np.meshgrid(lat, lon, indexing="ij")
    return lat_grid, lon_grid


def write_tile(directory: Path, lat_south_deg: int, lon_west_deg: int, values: np.ndarray) -> Path:
    """Write an SRTM .hgt tile: big-endian int16, row 0 is the northern edge."""
    path = directory / srtm_tile_name(lat_south_deg, lon_west_deg)
    np.asarray(values).astype(">i2").tofile(path)
    return path


def write_plane_tile(
    directory: Path,
    lat_south_deg: int,
    lon_west_deg: int,
    samples: int = 1201,
    plane: Callable[[np.ndarray, np.ndarray], np.ndarray] = plane_m,
) -> Path:
    lat_grid, lon_grid = tile_grid_deg(lat_south_deg, lon_west_deg, samples)
    return write_tile(directory, lat_south_deg, lon_west_deg, np.rint(plane(lat_grid, lon_grid)))


@pytest.fixture(scope="module")
def plane_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2x2 neighbouring 3" tiles N37..N38 x W123..W122 holding the reference plane."""
    directory = tmp_path_factory.mktemp("srtm_plane")
    for lat_south in (37, 38):
        for lon_west in (-123, -122):
            write_plane_tile(directory, lat_south, lon_west)
    return directory


@pytest.fixture(scope="module")
def plane_terrain(plane_dir: Path) -> SrtmTerrain:
    return SrtmTerrain(plane_dir, LocalFrame(38.0, -122.0))


# --- SyntheticTerrain -----------------------------------------------------------------------


def test_synthetic_same_seed_same_terrain() -> None:
    a = SyntheticTerrain.generate(seed=42, **AREA)
    b = SyntheticTerrain.generate(seed=42, **AREA)
    assert a == b
    east, north = np.meshgrid(np.linspace(-5e4, 5e4, 31), np.linspace(-4e4, 6e4, 29))
    np.testing.assert_array_equal(a.elevation_m(east, north), b.elevation_m(east, north))


def test_synthetic_different_seeds_differ() -> None:
    east, north = np.meshgrid(np.linspace(-5e4, 5e4, 31), np.linspace(-4e4, 6e4, 29))
    a = SyntheticTerrain.generate(seed=1, **AREA).elevation_m(east, north)
    b = SyntheticTerrain.generate(seed=2, **AREA).elevation_m(east, north)
    assert np.abs(a - b).max() > 100.0


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    base_m=st.floats(min_value=-100.0, max_value=3000.0),
    peak_m=st.floats(min_value=0.0, max_value=5000.0),
    hills=st.integers(min_value=0, max_value=60),
)
def test_synthetic_values_within_base_and_peak(
    seed: int, base_m: float, peak_m: float, hills: int
) -> None:
    terrain = SyntheticTerrain.generate(
        seed=seed, base_m=base_m, peak_m=peak_m, hills=hills, **AREA
    )
    rng = np.random.default_rng(seed)
    # Also far outside the area, where only the base plane remains.
    east = rng.uniform(-2e5, 2e5, 2000)
    north = rng.uniform(-2e5, 2e5, 2000)
    elevation = terrain.elevation_m(east, north)
    assert np.all(np.isfinite(elevation))
    assert np.all(elevation >= base_m - 1e-6)
    assert np.all(elevation <= base_m + peak_m + 1e-6)
    assert terrain.elevation_m(1e7, -1e7) == pytest.approx(base_m, abs=1e-6)


def test_synthetic_default_relief_is_substantial() -> None:
    # With the defaults the hills reach a good part of peak_m, so planning has work to do.
    terrain = SyntheticTerrain.generate(seed=3, **AREA)
    east, north = np.meshgrid(np.linspace(-5e4, 5e4, 201), np.linspace(-4e4, 6e4, 201))
    elevation = terrain.elevation_m(east, north)
    assert len(terrain.hills) == 40
    assert elevation.min() >= 200.0
    assert elevation.max() > 200.0 + 0.5 * 1800.0
    assert elevation.max() < 200.0 + 1800.0
    for hill in terrain.hills:
        assert AREA["min_east_m"] <= hill.east_m <= AREA["max_east_m"]
        assert AREA["min_north_m"] <= hill.north_m <= AREA["max_north_m"]
        assert hill.sigma_major_m >= hill.sigma_minor_m > 0.0


def test_synthetic_single_ridge_known_values() -> None:
    # A ridge running north (major axis at 90 deg from east) centred at (1000, 2000).
    hill = GaussianHill(
        east_m=1000.0,
        north_m=2000.0,
        height_m=600.0,
        sigma_major_m=4000.0,
        sigma_minor_m=1000.0,
        major_axis_rad=math.pi / 2.0,
    )
    terrain = SyntheticTerrain(base_m=100.0, peak_m=1000.0, hills=(hill,))

    def expected(bump: float) -> float:
        return 100.0 + 1000.0 * math.tanh(600.0 * bump / 1000.0)

    east = np.array([1000.0, 1000.0, 2000.0, 1000.0 + 1000.0 / math.sqrt(2), 5000.0])
    north = np.array([2000.0, 6000.0, 2000.0, 2000.0 + 4000.0 / math.sqrt(2), 2000.0])
    bumps = [1.0, math.exp(-0.5), math.exp(-0.5), math.exp(-0.5), math.exp(-8.0)]
    np.testing.assert_allclose(
        terrain.elevation_m(east, north), [expected(b) for b in bumps], atol=1e-3
    )


def test_synthetic_diagonal_ridge_orientation() -> None:
    hill = GaussianHill(0.0, 0.0, 500.0, 3000.0, 500.0, math.pi / 4.0)
    terrain = SyntheticTerrain(base_m=0.0, peak_m=2000.0, hills=(hill,))
    along = terrain.elevation_m(np.array([2000.0]), np.array([2000.0]))
    across = terrain.elevation_m(np.array([2000.0]), np.array([-2000.0]))
    assert along[0] > 100.0 * across[0]


def test_synthetic_no_hills_is_flat() -> None:
    terrain = SyntheticTerrain.generate(seed=0, hills=0, base_m=321.0, **AREA)
    np.testing.assert_array_equal(terrain.elevation_m(np.zeros(5), np.arange(5.0)), 321.0)


def test_synthetic_shapes_broadcast() -> None:
    terrain = SyntheticTerrain.generate(seed=9, **AREA)
    assert terrain.elevation_m(np.zeros((3, 4)), np.zeros((3, 4))).shape == (3, 4)
    assert terrain.elevation_m(np.zeros((3, 1)), np.zeros(4)).shape == (3, 4)
    assert terrain.elevation_m(np.zeros((2, 3, 4)), 0.0).shape == (2, 3, 4)
    assert terrain.elevation_m(np.zeros(0), np.zeros(0)).shape == (0,)
    single = terrain.elevation_m(1234.0, -567.0)
    assert single.shape == ()
    grid = terrain.elevation_m(np.full((2, 2), 1234.0), np.full((2, 2), -567.0))
    np.testing.assert_allclose(grid, float(single), rtol=0.0, atol=1e-9)
    assert terrain.elevation_m(np.zeros(3), np.zeros(3)).dtype == np.float64


def test_synthetic_is_smooth() -> None:
    # No float32 rounding noise visible at 1 m steps: slopes stay physically plausible.
    terrain = SyntheticTerrain.generate(seed=5, **AREA)
    east = np.arange(-20_000.0, 20_000.0, 1.0)
    elevation = terrain.elevation_m(east, np.full_like(east, 1000.0))
    slope = np.diff(elevation)
    curvature = np.diff(slope)
    assert np.abs(slope).max() < 2.0
    assert np.abs(curvature).max() < 1e-2


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"min_east_m": 10.0, "max_east_m": 10.0}, "min_east_m"),
        ({"min_north_m": 5.0, "max_north_m": -5.0}, "min_north_m"),
        ({"max_north_m": math.nan}, "min_north_m"),
        ({"peak_m": -1.0}, "peak_m"),
        ({"base_m": math.inf}, "base_m"),
        ({"hills": -1}, "hills"),
    ],
)
def test_synthetic_invalid_arguments_name_the_field(kwargs: dict[str, float], field: str) -> None:
    args: dict[str, float] = {**AREA, **kwargs}
    with pytest.raises(TerrainError, match=field):
        SyntheticTerrain.generate(seed=0, **args)  # type: ignore[arg-type]


def test_terrains_satisfy_the_protocol(plane_terrain: SrtmTerrain) -> None:
    terrains: list[Terrain] = [SyntheticTerrain.generate(seed=0, **AREA), plane_terrain]
    for terrain in terrains:
        assert terrain.elevation_m(np.zeros(2), np.zeros(2)).shape == (2,)


# --- SRTM tiles -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("lat", "lon", "name"),
    [
        (37, -123, "N37W123.hgt"),
        (-1, 10, "S01E010.hgt"),
        (0, 0, "N00E000.hgt"),
        (-1, -1, "S01W001.hgt"),
        (-56, 179, "S56E179.hgt"),
        (5, -180, "N05W180.hgt"),
    ],
)
def test_tile_names_name_the_south_west_corner(lat: int, lon: int, name: str) -> None:
    assert srtm_tile_name(lat, lon) == name


@settings(max_examples=200, deadline=None)
@given(
    lat=st.floats(min_value=37.0, max_value=39.0),
    lon=st.floats(min_value=-123.0, max_value=-121.0),
)
def test_srtm_bilinear_reproduces_plane(plane_terrain: SrtmTerrain, lat: float, lon: float) -> None:
    assert float(plane_terrain.elevation_at_deg(lat, lon)) == pytest.approx(
        float(plane_m(lat, lon)), abs=1e-6
    )


def test_srtm_seamless_across_tile_edges_and_corners(plane_terrain: SrtmTerrain) -> None:
    eps = 1e-9
    # Either side of the shared parallel 38 N, the shared meridian 122 W, and the corner.
    lat = np.array([38.0 - eps, 38.0, 38.0 + eps, 37.5, 37.5, 37.5, 38.0, 38.0 - eps, 38 + eps])
    lon = np.array(
        [
            -122.7,
            -122.7,
            -122.7,
            -122.0 - eps,
            -122.0,
            -122.0 + eps,
            -122.0,
            -122.0 - eps,
            -122 + eps,
        ]
    )
    np.testing.assert_allclose(
        plane_terrain.elevation_at_deg(lat, lon), plane_m(lat, lon), atol=1e-4
    )
    # The outer edges and corners of the 2x2 block are covered too.
    outer_lat = np.array([37.0, 39.0, 37.0, 39.0, 39.0])
    outer_lon = np.array([-123.0, -123.0, -121.0 - eps, -121.0 - eps, -122.5])
    np.testing.assert_allclose(
        plane_terrain.elevation_at_deg(outer_lat, outer_lon),
        plane_m(outer_lat, outer_lon),
        atol=1e-4,
    )


def test_srtm_elevation_in_local_frame(plane_terrain: SrtmTerrain) -> None:
    frame = plane_terrain.frame
    east, north = np.meshgrid(np.linspace(-80e3, 80e3, 41), np.linspace(-100e3, 100e3, 37))
    lat, lon = frame.to_geodetic(east, north)
    elevation = plane_terrain.elevation_m(east, north)
    assert elevation.shape == (37, 41)
    np.testing.assert_allclose(elevation, plane_m(lat, lon), atol=1e-6)


def test_srtm_edge_points_served_by_the_tile_that_has_them(tmp_path: Path) -> None:
    # Only N37W123 exists: its north and east edges (38 N, 122 W) nominally belong to the
    # missing neighbours but are shared samples, so they are answered from this tile.
    write_plane_tile(tmp_path, 37, -123)
    terrain = SrtmTerrain(tmp_path, LocalFrame(37.5, -122.5))
    lat = np.array([38.0, 37.5, 38.0, 37.0])
    lon = np.array([-122.5, -122.0, -122.0, -122.0])
    np.testing.assert_allclose(terrain.elevation_at_deg(lat, lon), plane_m(lat, lon), atol=1e-9)
    with pytest.raises(TerrainError, match=r"N38W123\.hgt"):
        terrain.elevation_at_deg(38.0 + 1e-9, -122.5)


def test_srtm_first_row_is_the_northern_edge(tmp_path: Path) -> None:
    values = np.zeros((1201, 1201))
    values[0, 0] = 1000.0  # north-west corner
    values[1200, 1200] = 2000.0  # south-east corner
    values[0, 1200] = 3000.0  # north-east corner
    write_tile(tmp_path, 10, 20, values)
    terrain = SrtmTerrain(tmp_path, LocalFrame(10.5, 20.5))
    np.testing.assert_array_equal(
        terrain.elevation_at_deg([11.0, 10.0, 11.0, 10.0], [20.0, 21.0, 21.0, 20.0]),
        [1000.0, 2000.0, 3000.0, 0.0],
    )
    # Half a sample south of the north-west corner: halfway down to the next row.
    half_sample_deg = 0.5 / 1200.0
    assert float(terrain.elevation_at_deg(11.0 - half_sample_deg, 20.0)) == pytest.approx(500.0)


def test_srtm_southern_and_eastern_hemisphere_tiles(tmp_path: Path) -> None:
    def plane(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
        return np.asarray(500.0 + 1200.0 * (lat + 1.0) - 2400.0 * (lon - 10.0))

    write_plane_tile(tmp_path, -1, 10, plane=plane)
    terrain = SrtmTerrain(tmp_path, LocalFrame(-0.5, 10.5))
    lat = np.array([-0.5, -0.999, -0.001, -0.123456])
    lon = np.array([10.5, 10.001, 10.999, 10.654321])
    np.testing.assert_allclose(terrain.elevation_at_deg(lat, lon), plane(lat, lon), atol=1e-6)


def test_srtm_one_arc_second_tile_detected_by_size(tmp_path: Path) -> None:
    def plane(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
        return np.asarray(10.0 + 3600.0 * (lat - 45.0) + 2.0 * 3600.0 * (lon - 7.0))

    path = write_plane_tile(tmp_path, 45, 7, samples=3601, plane=plane)
    assert path.stat().st_size == 3601 * 3601 * 2
    terrain = SrtmTerrain(tmp_path, LocalFrame(45.5, 7.5))
    rng = np.random.default_rng(4)
    lat = rng.uniform(45.0, 46.0, 500)
    lon = rng.uniform(7.0, 8.0, 500)
    np.testing.assert_allclose(terrain.elevation_at_deg(lat, lon), plane(lat, lon), atol=1e-6)


def test_srtm_one_arc_second_resolution_is_used(tmp_path: Path) -> None:
    values = np.zeros((3601, 3601))
    values[1800, 1801] = 900.0  # a one-sample spike 1" east of the tile centre
    write_tile(tmp_path, 45, 7, values)
    terrain = SrtmTerrain(tmp_path, LocalFrame(45.5, 7.5))
    one_sec = 1.0 / 3600.0
    spike = terrain.elevation_at_deg([45.5, 45.5, 45.5], [7.5 + one_sec, 7.5, 7.5 + 0.5 * one_sec])
    np.testing.assert_allclose(spike, [900.0, 0.0, 450.0])


def test_srtm_rejects_other_file_sizes(tmp_path: Path) -> None:
    path = tmp_path / "N37W123.hgt"
    path.write_bytes(b"\x00" * 1000)
    terrain = SrtmTerrain(tmp_path, LocalFrame(37.5, -122.5))
    with pytest.raises(TerrainError, match=r"N37W123\.hgt has 1000 bytes"):
        terrain.elevation_at_deg(37.5, -122.5)


def test_srtm_voids_are_filled_from_valid_neighbours(tmp_path: Path) -> None:
    lat_grid, lon_grid = tile_grid_deg(37, -123, 1201)
    values = np.rint(plane_m(lat_grid, lon_grid))
    values[500:520, 600:640] = SRTM_VOID  # a void block
    values[0, :] = SRTM_VOID  # the whole northern edge row
    values[1200, 1200] = SRTM_VOID  # a corner sample
    write_tile(tmp_path, 37, -123, values)
    terrain = SrtmTerrain(tmp_path, LocalFrame(37.5, -122.5))
    block_lat, block_lon = tile_grid_deg(37, -123, 1201)
    lat = np.concatenate([block_lat[495:525, 595:645].ravel(), block_lat[0, :], [37.0]])
    lon = np.concatenate([block_lon[495:525, 595:645].ravel(), block_lon[0, :], [-122.0]])
    elevation = terrain.elevation_at_deg(lat, lon)
    # Nothing of -32768 leaks; every filled value comes from nearby valid samples, which
    # differ from the plane by at most the block's half-width times the plane's step.
    assert elevation.min() > 0.0
    max_step_m = (10 + 1) * (PLANE_M_PER_DEG_LAT + PLANE_M_PER_DEG_LON) / 1200.0
    np.testing.assert_allclose(elevation, plane_m(lat, lon), atol=max_step_m)
    # Valid samples are untouched.
    assert float(terrain.elevation_at_deg(37.5, -122.5)) == pytest.approx(
        float(plane_m(37.5, -122.5))
    )


def test_srtm_all_void_tile_reads_as_sea_level(tmp_path: Path) -> None:
    write_tile(tmp_path, 0, 0, np.full((1201, 1201), SRTM_VOID))
    terrain = SrtmTerrain(tmp_path, LocalFrame(0.5, 0.5))
    np.testing.assert_array_equal(terrain.elevation_m(np.zeros(3), np.array([-1e3, 0.0, 1e3])), 0.0)


def test_srtm_tiles_are_cached(tmp_path: Path) -> None:
    path = write_plane_tile(tmp_path, 37, -123)
    terrain = SrtmTerrain(tmp_path, LocalFrame(37.5, -122.5))
    first = terrain.elevation_at_deg(37.25, -122.75)
    path.unlink()  # a second read would fail
    np.testing.assert_array_equal(terrain.elevation_at_deg(37.25, -122.75), first)


def test_srtm_lowercase_file_names_accepted(tmp_path: Path) -> None:
    path = write_plane_tile(tmp_path, 37, -123)
    path.rename(tmp_path / path.name.lower())
    terrain = SrtmTerrain(tmp_path, LocalFrame(37.5, -122.5))
    assert float(terrain.elevation_at_deg(37.5, -122.5)) == pytest.approx(
        float(plane_m(37.5, -122.5))
    )


def test_require_area_passes_when_tiles_present(plane_terrain: SrtmTerrain) -> None:
    plane_terrain.require_area(-80e3, 80e3, -100e3, 100e3)
    assert plane_terrain.tiles_for_area(-80e3, 80e3, -100e3, 100e3) == [
        (37, -123),
        (37, -122),
        (38, -123),
        (38, -122),
    ]
    assert plane_terrain.tiles_for_area(-10e3, -5e3, 5e3, 10e3) == [(38, -123)]


def test_require_area_names_the_first_missing_tile(plane_dir: Path, tmp_path: Path) -> None:
    for name in ("N37W123.hgt", "N38W123.hgt", "N38W122.hgt"):
        (tmp_path / name).write_bytes((plane_dir / name).read_bytes())
    terrain = SrtmTerrain(tmp_path, LocalFrame(38.0, -122.0))
    with pytest.raises(TerrainError) as info:
        terrain.require_area(-50e3, 50e3, -50e3, 50e3)
    assert str(info.value) == f"terrain tile N37W122.hgt not found in {tmp_path}"
    # The area west of 122 W needs only tiles that are present.
    terrain.require_area(-50e3, -1e3, -50e3, 50e3)


def test_require_area_counts_further_missing_tiles(tmp_path: Path) -> None:
    terrain = SrtmTerrain(tmp_path, LocalFrame(38.0, -122.0))
    with pytest.raises(TerrainError) as info:
        terrain.require_area(-50e3, 50e3, -50e3, 50e3)
    message = str(info.value)
    assert message.startswith(f"terrain tile N37W123.hgt not found in {tmp_path}")
    assert "4 of 4 tiles" in message
    assert "\n" not in message


def test_require_area_finds_a_tile_clipped_only_in_the_middle_of_an_edge(tmp_path: Path) -> None:
    # In the local plane the parallel 38 N bows northwards away from the central meridian, so a
    # box whose top edge lies 1 mm north of the parallel's lowest point enters tile N38W123
    # only in a sliver about 260 m long in the middle of that edge, between the corners and
    # between the nodes of the coarse interior sampling grid.
    frame = LocalFrame(37.9, -122.5)
    _, parallel_north_m = frame.to_local(38.0, -122.5)
    top_m = parallel_north_m + 1e-3
    assert frame.to_geodetic(0.0, top_m)[0] > 38.0
    assert frame.to_geodetic(250.0, top_m)[0] < 38.0
    assert frame.to_geodetic(-250.0, top_m)[0] < 38.0
    terrain = SrtmTerrain(tmp_path, frame)
    tiles = terrain.tiles_for_area(-19_750.0, 20_250.0, top_m - 10_000.0, top_m)
    assert tiles == [(37, -123), (38, -123)]


def test_tiles_for_area_includes_tiles_wholly_inside(tmp_path: Path) -> None:
    # A 300 km square about 38.5 N 122.5 W: tile N38W123 lies inside, away from every edge.
    terrain = SrtmTerrain(tmp_path, LocalFrame(38.5, -122.5))
    tiles = terrain.tiles_for_area(-150e3, 150e3, -150e3, 150e3)
    assert tiles == [(lat, lon) for lat in (37, 38, 39) for lon in range(-125, -120)]


@pytest.mark.parametrize(
    ("origin_lat_deg", "origin_lon_deg"), [(38.5, -122.5), (60.0, 179.5), (-45.0, 170.2)]
)
def test_tiles_for_area_matches_a_dense_grid(
    tmp_path: Path, origin_lat_deg: float, origin_lon_deg: float
) -> None:
    frame = LocalFrame(origin_lat_deg, origin_lon_deg)
    bounds = (-300e3, 250e3, -200e3, 300e3)
    east, north = np.meshgrid(np.linspace(*bounds[:2], 551), np.linspace(*bounds[2:], 501))
    lat, lon = frame.to_geodetic(east.ravel(), north.ravel())
    expected = sorted({(int(a), int(b)) for a, b in zip(np.floor(lat), np.floor(lon), strict=True)})
    assert SrtmTerrain(tmp_path, frame).tiles_for_area(*bounds) == expected


def test_srtm_query_of_missing_tile_is_a_terrain_error(plane_terrain: SrtmTerrain) -> None:
    with pytest.raises(TerrainError, match=r"terrain tile N40W122\.hgt not found in "):
        plane_terrain.elevation_at_deg([38.5, 40.5], [-121.5, -121.5])


def test_require_area_rejects_inverted_bounds(plane_terrain: SrtmTerrain) -> None:
    with pytest.raises(TerrainError, match="min_east_m"):
        plane_terrain.require_area(10.0, -10.0, 0.0, 1.0)
    with pytest.raises(TerrainError, match="min_north_m"):
        plane_terrain.require_area(0.0, 1.0, 10.0, -10.0)


def test_srtm_query_validation(plane_terrain: SrtmTerrain) -> None:
    with pytest.raises(TerrainError, match="lat_deg"):
        plane_terrain.elevation_at_deg(95.0, 0.0)
    with pytest.raises(TerrainError, match="finite"):
        plane_terrain.elevation_at_deg(math.nan, 0.0)
    with pytest.raises(TerrainError, match="east_m"):
        plane_terrain.elevation_m(np.array([math.inf]), np.array([0.0]))


# --- clearance ------------------------------------------------------------------------------


def test_clearance_is_altitude_minus_elevation() -> None:
    flat = SyntheticTerrain(base_m=250.0, peak_m=1000.0, hills=())
    np.testing.assert_array_equal(
        clearance_m(flat, np.zeros(3), np.zeros(3), np.array([300.0, 250.0, 100.0])),
        [50.0, 0.0, -150.0],
    )
    # Altitude broadcasts against the coordinates.
    assert clearance_m(flat, np.zeros((2, 3)), np.zeros((2, 3)), 1000.0).shape == (2, 3)


def test_min_clearance_along_finds_the_lowest_point_over_a_ridge() -> None:
    ridge = GaussianHill(0.0, 0.0, 800.0, 20_000.0, 1000.0, math.pi / 2.0)
    terrain = SyntheticTerrain(base_m=100.0, peak_m=2000.0, hills=(ridge,))
    east = np.linspace(-5000.0, 5000.0, 101)  # crosses the ridge crest at index 50
    north = np.zeros_like(east)
    alt = np.full_like(east, 1200.0)
    clearance, index = min_clearance_along(terrain, east, north, alt)
    assert index == 50
    assert clearance == pytest.approx(1200.0 - (100.0 + 2000.0 * math.tanh(0.4)), abs=1e-3)
    # Climbing before the ridge moves the minimum to the start of the path.
    clearance, index = min_clearance_along(terrain, east, north, np.linspace(400.0, 2000.0, 101))
    assert index == 0
    assert clearance == pytest.approx(400.0 - float(terrain.elevation_m(-5000.0, 0.0)), abs=1e-6)


def test_min_clearance_along_rejects_empty_and_non_path_inputs() -> None:
    flat = SyntheticTerrain(base_m=0.0, peak_m=0.0, hills=())
    with pytest.raises(ValueError, match="no samples"):
        min_clearance_along(flat, np.zeros(0), np.zeros(0), np.zeros(0))
    with pytest.raises(ValueError, match="1-D"):
        min_clearance_along(flat, np.zeros((2, 2)), np.zeros((2, 2)), 0.0)


def _relief_hill_by_hill(
    terrain: SyntheticTerrain, east: NDArray[np.float64], north: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The reference: each hill's float32 bump added to a float64 sum in turn."""
    relief = np.zeros(east.shape)
    for hill in terrain.hills:
        c, s = math.cos(hill.major_axis_rad), math.sin(hill.major_axis_rad)
        inv_a2 = 0.5 / hill.sigma_major_m**2
        inv_b2 = 0.5 / hill.sigma_minor_m**2
        de = (east - hill.east_m).astype(np.float32)
        dn = (north - hill.north_m).astype(np.float32)
        q = de * np.float32(c * c * inv_a2 + s * s * inv_b2)
        q += dn * np.float32(2.0 * c * s * (inv_a2 - inv_b2))
        q *= de
        q += dn * dn * np.float32(s * s * inv_a2 + c * c * inv_b2)
        relief += np.exp(-q) * np.float32(hill.height_m)
    out: NDArray[np.float64] = terrain.base_m + terrain.peak_m * np.tanh(relief / terrain.peak_m)
    return out


@pytest.mark.parametrize("n_points", [1, 7, 4095, 4096, 4097, 9000])
@pytest.mark.parametrize("hills", [0, 1, 40])
def test_all_hills_at_once_equal_hill_by_hill(n_points: int, hills: int) -> None:
    terrain = SyntheticTerrain.generate(seed=hills + n_points, hills=hills, **AREA)
    rng = np.random.default_rng(n_points)
    east = rng.uniform(-60_000.0, 60_000.0, n_points)
    north = rng.uniform(-50_000.0, 50_000.0, n_points)
    # Bit for bit, and independent of how many points one call takes.
    expected = _relief_hill_by_hill(terrain, east, north)
    np.testing.assert_array_equal(terrain.elevation_m(east, north), expected)
    np.testing.assert_array_equal(terrain.elevation_m(east[:1], north[:1]), expected[:1])

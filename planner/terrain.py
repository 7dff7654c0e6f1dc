"""Terrain elevation AMSL (m) in the local east/north frame: synthetic hills and SRTM tiles."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.errors import TerrainError
from planner.geo import LocalFrame
from planner.scenario import FlatTerrain, Scenario, SrtmTerrainSpec, SyntheticTerrainSpec

__all__ = [
    "SRTM_VOID",
    "GaussianHill",
    "SrtmTerrain",
    "SyntheticTerrain",
    "Terrain",
    "build_terrain",
    "clearance_m",
    "min_clearance_along",
    "srtm_tile_name",
]

FloatArray = NDArray[np.float64]

SRTM_VOID = -32768
"""Sample value that marks a void (no data) in an SRTM tile."""

_SRTM_SAMPLES_BY_SIZE = {1201 * 1201 * 2: 1201, 3601 * 3601 * 2: 3601}
# Spacing of the samples along an area's edges that find the tiles the area touches.
_EDGE_STEP_M = 50.0


class Terrain(Protocol):
    """Anything that gives terrain elevation AMSL (m) at local plane coordinates."""

    def elevation_m(self, east_m: FloatArray, north_m: FloatArray) -> FloatArray:
        """Elevation AMSL (m) at local coordinates (m); inputs broadcast, any shape."""
        ...


@dataclass(frozen=True)
class GaussianHill:
    """One elliptical Gaussian bump; a ridge when one axis is much longer than the other.

    Attributes
    ----------
    east_m, north_m : float
        Centre in the local frame (m).
    height_m : float
        Height above the base plane before saturation (m).
    sigma_major_m, sigma_minor_m : float
        Standard deviations along the long and short axes (m).
    major_axis_rad : float
        Direction of the long axis, counter-clockwise from east (rad).
    """

    east_m: float
    north_m: float
    height_m: float
    sigma_major_m: float
    sigma_minor_m: float
    major_axis_rad: float


@dataclass(frozen=True)
class SyntheticTerrain:
    """Seeded analytic terrain: a base plane plus a sum of Gaussian hills and ridges.

    ``elevation = base_m + peak_m * tanh(sum_of_hills / peak_m)``: the saturation keeps every
    elevation in ``[base_m, base_m + peak_m)`` however hills overlap, while isolated low hills
    keep their shape.

    Attributes
    ----------
    base_m : float
        Elevation AMSL of the plain between hills (m).
    peak_m : float
        Upper bound of the relief above ``base_m`` (m).
    hills : tuple of GaussianHill
        The bumps, in local frame coordinates.
    """

    base_m: float
    peak_m: float
    hills: tuple[GaussianHill, ...]

    @classmethod
    def generate(
        cls,
        *,
        seed: int,
        min_east_m: float,
        max_east_m: float,
        min_north_m: float,
        max_north_m: float,
        base_m: float = 200.0,
        peak_m: float = 1800.0,
        hills: int = 40,
    ) -> SyntheticTerrain:
        """Draw hills and ridges over a rectangle of the local frame.

        Parameters
        ----------
        seed : int
            Seed of the numpy Generator; the same seed gives the same terrain.
        min_east_m, max_east_m, min_north_m, max_north_m : float
            Rectangle (m) in which hill centres are drawn; the terrain is defined everywhere.
        base_m : float
            Elevation AMSL of the plain (m).
        peak_m : float
            Relief above the plain (m); elevations stay below ``base_m + peak_m``.
        hills : int
            Number of hills and ridges (about a third are ridges).

        Returns
        -------
        SyntheticTerrain

        Raises
        ------
        TerrainError
            If the rectangle is empty, ``peak_m`` is negative or ``hills`` is negative.
        """
        if not (math.isfinite(min_east_m) and math.isfinite(max_east_m)) or not (
            min_east_m < max_east_m
        ):
            raise TerrainError(
                f"synthetic terrain needs min_east_m < max_east_m, got {min_east_m}, {max_east_m}"
            )
        if not (math.isfinite(min_north_m) and math.isfinite(max_north_m)) or not (
            min_north_m < max_north_m
        ):
            raise TerrainError(
                "synthetic terrain needs min_north_m < max_north_m, "
                f"got {min_north_m}, {max_north_m}"
            )
        if not math.isfinite(base_m):
            raise TerrainError(f"synthetic terrain base_m must be finite, got {base_m}")
        if not (math.isfinite(peak_m) and peak_m >= 0.0):
            raise TerrainError(f"synthetic terrain peak_m must be >= 0, got {peak_m}")
        if hills < 0:
            raise TerrainError(f"synthetic terrain hills must be >= 0, got {hills}")
        rng = np.random.default_rng(seed)
        span_m = min(max_east_m - min_east_m, max_north_m - min_north_m)
        east = rng.uniform(min_east_m, max_east_m, hills)
        north = rng.uniform(min_north_m, max_north_m, hills)
        height = peak_m * rng.uniform(0.15, 1.3, hills)
        sigma_minor = span_m * rng.uniform(0.02, 0.08, hills)
        is_ridge = rng.random(hills) < 1.0 / 3.0
        aspect = np.where(is_ridge, rng.uniform(3.0, 8.0, hills), rng.uniform(1.0, 1.8, hills))
        axis = rng.uniform(0.0, math.pi, hills)
        return cls(
            base_m=float(base_m),
            peak_m=float(peak_m),
            hills=tuple(
                GaussianHill(
                    east_m=float(east[i]),
                    north_m=float(north[i]),
                    height_m=float(height[i]),
                    sigma_major_m=float(sigma_minor[i] * aspect[i]),
                    sigma_minor_m=float(sigma_minor[i]),
                    major_axis_rad=float(axis[i]),
                )
                for i in range(hills)
            ),
        )

    @cached_property
    def _table(self) -> _HillTable:
        return _HillTable.of(self.hills)

    def _relief_m(self, east_m: FloatArray, north_m: FloatArray) -> FloatArray:
        """Summed hill heights (m) at (N,) points, before saturation.

        The per-hill work runs in float32 (SIMD-wide, about 3x faster): offsets from a hill
        centre and the exponent need only relative precision, and the float32 rounding changes
        the relief by well under a millimetre. All hills are evaluated in one (hills x points)
        pass, which costs a few numpy calls instead of a dozen per hill; the sum is kept in
        float64 and taken hill by hill in order, so the result does not depend on how the
        points are batched.
        """
        t = self._table
        shape = (len(t.height_m), east_m.size)
        de = np.empty(shape, dtype=np.float32)
        dn = np.empty(shape, dtype=np.float32)
        np.subtract(east_m, t.east_m, out=de, casting="same_kind")
        np.subtract(north_m, t.north_m, out=dn, casting="same_kind")
        q = de * t.q_ee
        tmp = dn * t.q_en
        q += tmp
        q *= de
        np.multiply(dn, dn, out=tmp)
        tmp *= t.q_nn
        q += tmp
        np.negative(q, out=q)
        np.exp(q, out=q)
        q *= t.height_m
        relief = np.zeros(east_m.size, dtype=np.float64)
        for row in q:
            relief += row
        return relief

    def elevation_m(self, east_m: ArrayLike, north_m: ArrayLike) -> FloatArray:
        """Elevation AMSL (m) at local coordinates.

        Parameters
        ----------
        east_m, north_m : array_like
            Local plane coordinates (m); broadcast together, any shape.

        Returns
        -------
        ndarray
            Elevation AMSL (m), float64, of the broadcast shape.
        """
        east, north = np.broadcast_arrays(
            np.asarray(east_m, dtype=np.float64), np.asarray(north_m, dtype=np.float64)
        )
        flat_east, flat_north = east.reshape(-1), north.reshape(-1)
        flat_relief = np.zeros(flat_east.shape, dtype=np.float64)
        for lo in range(0, flat_east.size, _HILL_CHUNK_POINTS):
            hi = lo + _HILL_CHUNK_POINTS
            flat_relief[lo:hi] = self._relief_m(flat_east[lo:hi], flat_north[lo:hi])
        relief: FloatArray = flat_relief.reshape(east.shape)
        if self.peak_m > 0.0:
            relief = self.peak_m * np.tanh(relief / self.peak_m)
        result: FloatArray = self.base_m + relief
        return result


_HILL_CHUNK_POINTS = 4096
# Points evaluated against all hills at once: large enough that numpy's per-call cost is
# small, small enough that the (hills x points) float32 temporaries stay in cache.


@dataclass(frozen=True)
class _HillTable:
    """Per-hill constants of :class:`SyntheticTerrain`, as (hills, 1) columns."""

    east_m: FloatArray
    north_m: FloatArray
    q_ee: NDArray[np.float32]
    q_en: NDArray[np.float32]
    q_nn: NDArray[np.float32]
    height_m: NDArray[np.float32]

    @classmethod
    def of(cls, hills: tuple[GaussianHill, ...]) -> _HillTable:
        rows = []
        for hill in hills:
            # Exponent of the rotated ellipse, 0.5 (u/s_major)^2 + 0.5 (v/s_minor)^2, written
            # as q_ee de^2 + q_en de dn + q_nn dn^2.
            c, s = math.cos(hill.major_axis_rad), math.sin(hill.major_axis_rad)
            inv_a2 = 0.5 / hill.sigma_major_m**2
            inv_b2 = 0.5 / hill.sigma_minor_m**2
            rows.append(
                (
                    c * c * inv_a2 + s * s * inv_b2,
                    2.0 * c * s * (inv_a2 - inv_b2),
                    s * s * inv_a2 + c * c * inv_b2,
                )
            )
        q = np.array(rows, dtype=np.float64).reshape(-1, 3).astype(np.float32)
        return cls(
            np.array([[h.east_m] for h in hills], dtype=np.float64).reshape(-1, 1),
            np.array([[h.north_m] for h in hills], dtype=np.float64).reshape(-1, 1),
            q[:, 0:1],
            q[:, 1:2],
            q[:, 2:3],
            np.array([[h.height_m] for h in hills], dtype=np.float32).reshape(-1, 1),
        )


def srtm_tile_name(lat_south_deg: int, lon_west_deg: int) -> str:
    """File name of the SRTM tile whose south-west corner is at the given integer degrees.

    Parameters
    ----------
    lat_south_deg, lon_west_deg : int
        Latitude and longitude (deg) of the tile's south-west corner.

    Returns
    -------
    str
        For example ``N37W123.hgt`` or ``S01E010.hgt``.
    """
    ns = "N" if lat_south_deg >= 0 else "S"
    ew = "E" if lon_west_deg >= 0 else "W"
    return f"{ns}{abs(lat_south_deg):02d}{ew}{abs(lon_west_deg):03d}.hgt"


def _fill_voids(samples: NDArray[np.int16]) -> NDArray[np.int16]:
    """Replace void samples with the value of the nearest valid sample (0 if all are void)."""
    void = samples == SRTM_VOID
    if not void.any():
        return samples
    if void.all():
        return np.zeros_like(samples)
    from scipy import ndimage  # only for SRTM tiles with voids

    # For every sample, the indices of the nearest non-void sample.
    indices = ndimage.distance_transform_edt(void, return_distances=False, return_indices=True)
    filled: NDArray[np.int16] = samples[indices[0], indices[1]]
    return filled


def _load_tile(path: Path) -> NDArray[np.int16]:
    """Read one .hgt tile into a (n, n) native int16 array, rows north to south, voids filled."""
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise TerrainError(f"terrain tile {path} cannot be read: {exc.strerror}") from None
    samples_per_side = _SRTM_SAMPLES_BY_SIZE.get(size)
    if samples_per_side is None:
        raise TerrainError(
            f"terrain tile {path} has {size} bytes; expected 2884802 (1201x1201, 3 arc-second) "
            "or 25934402 (3601x3601, 1 arc-second)"
        )
    try:
        raw = np.fromfile(path, dtype=">i2")
    except OSError as exc:
        raise TerrainError(f"terrain tile {path} cannot be read: {exc.strerror}") from None
    if raw.size != samples_per_side * samples_per_side:
        raise TerrainError(f"terrain tile {path} changed size while being read")
    samples = raw.astype(np.int16).reshape(samples_per_side, samples_per_side)
    return _fill_voids(samples)


class SrtmTerrain:
    """Elevation from SRTM ``.hgt`` tiles in a directory, bilinearly interpolated.

    Tiles are one degree square, named by their south-west corner (``N37W123.hgt``), hold
    1201x1201 (3 arc-second) or 3601x3601 (1 arc-second) big-endian int16 samples in metres,
    rows from north to south and columns from west to east; neighbouring tiles share their edge
    rows and columns, so interpolating inside each tile is seamless across tile edges. Tiles are
    read when first needed and cached; voids are filled from the nearest valid sample.

    Parameters
    ----------
    directory : Path
        Directory that holds the tiles (file names as above; lower case also accepted).
    frame : LocalFrame
        Local frame in which `elevation_m` takes its coordinates.
    """

    def __init__(self, directory: Path, frame: LocalFrame) -> None:
        self._directory = Path(directory)
        self._frame = frame
        self._tiles: dict[tuple[int, int], NDArray[np.int16]] = {}

    @property
    def directory(self) -> Path:
        """Directory that holds the tiles."""
        return self._directory

    @property
    def frame(self) -> LocalFrame:
        """Local frame of `elevation_m`."""
        return self._frame

    def _tile_path(self, lat_south_deg: int, lon_west_deg: int) -> Path | None:
        name = srtm_tile_name(lat_south_deg, lon_west_deg)
        for candidate in (name, name.lower()):
            path = self._directory / candidate
            if path.is_file():
                return path
        return None

    def _missing_error(self, lat_south_deg: int, lon_west_deg: int) -> TerrainError:
        name = srtm_tile_name(lat_south_deg, lon_west_deg)
        return TerrainError(f"terrain tile {name} not found in {self._directory}")

    def _tile_if_present(self, lat_south_deg: int, lon_west_deg: int) -> NDArray[np.int16] | None:
        key = (lat_south_deg, lon_west_deg)
        tile = self._tiles.get(key)
        if tile is None:
            path = self._tile_path(lat_south_deg, lon_west_deg)
            if path is None:
                return None
            tile = _load_tile(path)
            self._tiles[key] = tile
        return tile

    def elevation_at_deg(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> FloatArray:
        """Elevation AMSL (m) at geodetic coordinates, bilinear within each tile.

        Parameters
        ----------
        lat_deg, lon_deg : array_like
            Geodetic latitude and longitude (deg); broadcast together, any shape.

        Returns
        -------
        ndarray
            Elevation AMSL (m), float64, of the broadcast shape.

        Raises
        ------
        TerrainError
            If a needed tile is missing (naming the first one, south to north then west to
            east) or unreadable, or a coordinate is out of range.
        """
        lat, lon = np.broadcast_arrays(
            np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64)
        )
        if not (np.all(np.isfinite(lat)) and np.all(np.isfinite(lon))):
            raise TerrainError("terrain query lat_deg/lon_deg must be finite")
        if np.any(np.abs(lat) > 90.0):
            raise TerrainError("terrain query lat_deg must be within +-90 deg")
        flat_lat = lat.ravel()
        flat_lon = _wrap_lon_deg(lon.ravel())
        # Each point is looked up in the tile whose south-west corner is at its floor (the
        # north pole and the antimeridian in the tile below/left of them). A point on that
        # tile's south or west edge also lies on the neighbours sharing the edge, which serve
        # it if the first tile is missing (the area's data may stop exactly there).
        primary_lat = np.minimum(np.floor(flat_lat), 89.0).astype(np.int64)
        primary_lon = np.minimum(np.floor(flat_lon), 179.0).astype(np.int64)
        on_south_edge = (flat_lat == primary_lat) & (primary_lat > -90)
        on_west_edge = flat_lon == primary_lon
        out = np.empty(flat_lat.shape, dtype=np.float64)
        unresolved = np.ones(flat_lat.shape, dtype=bool)
        for step_lat, step_lon in ((0, 0), (-1, 0), (0, -1), (-1, -1)):
            eligible = unresolved.copy()
            if step_lat:
                eligible &= on_south_edge
            if step_lon:
                eligible &= on_west_edge
            pending = np.flatnonzero(eligible)
            if pending.size == 0:
                continue
            tile_lat = primary_lat[pending] + step_lat
            tile_lon = (primary_lon[pending] + step_lon + 180) % 360 - 180
            keys, inverse = np.unique(
                np.stack([tile_lat, tile_lon], axis=1), axis=0, return_inverse=True
            )
            inverse = inverse.ravel()
            for key_index, (lat_south, lon_west) in enumerate(keys.tolist()):
                tile = self._tile_if_present(int(lat_south), int(lon_west))
                if tile is None:
                    continue
                members = pending[inverse == key_index]
                out[members] = _bilinear(
                    tile,
                    flat_lat[members] - lat_south,
                    _wrap_lon_deg(flat_lon[members] - lon_west),
                )
                unresolved[members] = False
        if unresolved.any():
            stuck = np.flatnonzero(unresolved)
            missing = np.unique(np.stack([primary_lat[stuck], primary_lon[stuck]], axis=1), axis=0)
            raise self._missing_error(int(missing[0, 0]), int(missing[0, 1]))
        return out.reshape(lat.shape)

    def elevation_m(self, east_m: ArrayLike, north_m: ArrayLike) -> FloatArray:
        """Elevation AMSL (m) at local coordinates.

        Parameters
        ----------
        east_m, north_m : array_like
            Local plane coordinates (m) in `frame`; broadcast together, any shape.

        Returns
        -------
        ndarray
            Elevation AMSL (m), float64, of the broadcast shape.

        Raises
        ------
        TerrainError
            If a needed tile is missing or unreadable.
        """
        east, north = np.broadcast_arrays(
            np.asarray(east_m, dtype=np.float64), np.asarray(north_m, dtype=np.float64)
        )
        try:
            lat_deg, lon_deg = self._frame.to_geodetic(east, north)
        except ValueError as exc:
            raise TerrainError(f"terrain query: {exc}") from None
        return self.elevation_at_deg(lat_deg, lon_deg)

    def tiles_for_area(
        self, min_east_m: float, max_east_m: float, min_north_m: float, max_north_m: float
    ) -> list[tuple[int, int]]:
        """South-west corners (lat, lon in deg) of the tiles a local rectangle touches.

        A tile touches the rectangle if it crosses the rectangle's edges, sampled every 50 m,
        or lies inside it (latitude and longitude take their extremes on the edges, so the
        candidates are few). A tile that only clips a sliver narrower than 50 m between two
        edge samples can be missed; an elevation query there still raises `TerrainError`.

        Parameters
        ----------
        min_east_m, max_east_m, min_north_m, max_north_m : float
            Rectangle in the local frame (m).

        Returns
        -------
        list of (int, int)
            Tile corners, sorted by latitude, then longitude.

        Raises
        ------
        TerrainError
            If the rectangle is inverted or not finite.
        """
        bounds = (min_east_m, max_east_m, min_north_m, max_north_m)
        if not all(math.isfinite(v) for v in bounds):
            raise TerrainError(f"terrain area bounds must be finite, got {bounds}")
        if min_east_m > max_east_m:
            raise TerrainError(
                f"terrain area needs min_east_m <= max_east_m, got {min_east_m}, {max_east_m}"
            )
        if min_north_m > max_north_m:
            raise TerrainError(
                f"terrain area needs min_north_m <= max_north_m, got {min_north_m}, {max_north_m}"
            )

        def axis(lo: float, hi: float) -> FloatArray:
            return np.linspace(lo, hi, max(2, math.ceil((hi - lo) / _EDGE_STEP_M) + 1))

        edge_e = axis(min_east_m, max_east_m)
        edge_n = axis(min_north_m, max_north_m)
        east = np.concatenate(
            [edge_e, edge_e, np.full_like(edge_n, min_east_m), np.full_like(edge_n, max_east_m)]
        )
        north = np.concatenate(
            [np.full_like(edge_e, min_north_m), np.full_like(edge_e, max_north_m), edge_n, edge_n]
        )
        try:
            lat, lon = self._frame.to_geodetic(east, north)
        except ValueError as exc:
            raise TerrainError(f"terrain area: {exc}") from None
        tile_lat = np.minimum(np.floor(lat), 89.0).astype(np.int64)
        tile_lon = np.minimum(np.floor(lon), 179.0).astype(np.int64)
        tiles = {
            (int(a), int(b)) for a, b in zip(tile_lat.tolist(), tile_lon.tolist(), strict=True)
        }
        # Tiles the edges miss lie wholly inside or wholly outside: test their centres.
        origin_lon = self._frame.origin_lon_deg
        dlon = _wrap_lon_deg(lon - origin_lon)
        candidates = [
            (lat_south, int((lon_west + 180) % 360 - 180))
            for lat_south in range(int(tile_lat.min()), int(tile_lat.max()) + 1)
            for lon_west in range(
                math.floor(origin_lon + float(dlon.min())),
                math.floor(origin_lon + float(dlon.max())) + 1,
            )
        ]
        inner = [key for key in candidates if key not in tiles]
        if inner:
            centre_lat = np.array([key[0] + 0.5 for key in inner])
            centre_lon = np.array([key[1] + 0.5 for key in inner])
            centre_e, centre_n = self._frame.to_local(centre_lat, centre_lon)
            inside = (
                (centre_e >= min_east_m)
                & (centre_e <= max_east_m)
                & (centre_n >= min_north_m)
                & (centre_n <= max_north_m)
            )
            tiles.update(
                key for key, is_inside in zip(inner, inside.tolist(), strict=True) if is_inside
            )
        return sorted(tiles)

    def require_area(
        self, min_east_m: float, max_east_m: float, min_north_m: float, max_north_m: float
    ) -> None:
        """Check up front that every tile a local rectangle needs is present.

        Only file presence is checked; tiles are still read lazily.

        Parameters
        ----------
        min_east_m, max_east_m, min_north_m, max_north_m : float
            Rectangle in the local frame (m).

        Raises
        ------
        TerrainError
            Naming the first missing tile file (by latitude, then longitude) and the
            directory, e.g. ``terrain tile N37W123.hgt not found in /data/srtm``; the same
            line counts any further missing tiles.
        """
        needed = self.tiles_for_area(min_east_m, max_east_m, min_north_m, max_north_m)
        missing = [key for key in needed if self._tile_path(*key) is None]
        if missing:
            error = self._missing_error(*missing[0])
            if len(missing) > 1:
                error = TerrainError(
                    f"{error} ({len(missing)} of {len(needed)} tiles for the area are missing)"
                )
            raise error


def _wrap_lon_deg(lon_deg: FloatArray) -> FloatArray:
    """Wrap longitudes (deg) to [-180, 180)."""
    wrapped: FloatArray = (lon_deg + 180.0) % 360.0 - 180.0
    return wrapped


def _bilinear(tile: NDArray[np.int16], dlat_deg: FloatArray, dlon_deg: FloatArray) -> FloatArray:
    """Bilinear interpolation in one tile at offsets (deg) from its south-west corner."""
    last = tile.shape[0] - 1
    # Row 0 is the northern edge, so the row coordinate grows southwards.
    row = (1.0 - dlat_deg) * last
    col = dlon_deg * last
    row0 = np.clip(np.floor(row).astype(np.int64), 0, last - 1)
    col0 = np.clip(np.floor(col).astype(np.int64), 0, last - 1)
    fr = row - row0
    fc = col - col0
    z00 = tile[row0, col0].astype(np.float64)
    z01 = tile[row0, col0 + 1].astype(np.float64)
    z10 = tile[row0 + 1, col0].astype(np.float64)
    z11 = tile[row0 + 1, col0 + 1].astype(np.float64)
    top = z00 + (z01 - z00) * fc
    bottom = z10 + (z11 - z10) * fc
    result: FloatArray = top + (bottom - top) * fr
    return result


def clearance_m(
    terrain: Terrain, east_m: ArrayLike, north_m: ArrayLike, alt_m: ArrayLike
) -> FloatArray:
    """Height above terrain (m) of points in the local frame.

    Parameters
    ----------
    terrain : Terrain
        Elevation source.
    east_m, north_m : array_like
        Local plane coordinates (m).
    alt_m : array_like
        Altitude AMSL (m); broadcast with the coordinates.

    Returns
    -------
    ndarray
        ``alt_m - elevation`` (m), negative below ground, of the broadcast shape.
    """
    east, north, alt = np.broadcast_arrays(
        np.asarray(east_m, dtype=np.float64),
        np.asarray(north_m, dtype=np.float64),
        np.asarray(alt_m, dtype=np.float64),
    )
    result: FloatArray = alt - terrain.elevation_m(east, north)
    return result


def min_clearance_along(
    terrain: Terrain, east_m: ArrayLike, north_m: ArrayLike, alt_m: ArrayLike
) -> tuple[float, int]:
    """Smallest height above terrain along a sampled path, and where it occurs.

    Parameters
    ----------
    terrain : Terrain
        Elevation source.
    east_m, north_m : array_like
        Local plane coordinates (m) of the path samples, 1-D.
    alt_m : array_like
        Altitude AMSL (m) of the samples; broadcast with the coordinates.

    Returns
    -------
    clearance_m : float
        Minimum of ``alt_m - elevation`` (m).
    index : int
        Index of the first sample that attains it.

    Raises
    ------
    ValueError
        If the path has no samples or is not 1-D.
    """
    clearance = clearance_m(terrain, east_m, north_m, alt_m)
    if clearance.ndim != 1:
        raise ValueError(f"path east_m/north_m/alt_m must be 1-D, got shape {clearance.shape}")
    if clearance.size == 0:
        raise ValueError("path east_m/north_m/alt_m has no samples")
    index = int(np.argmin(clearance))
    return float(clearance[index]), index


@dataclass(frozen=True)
class _Flat:
    elevation: float

    def elevation_m(self, east_m: FloatArray, north_m: FloatArray) -> FloatArray:
        return np.full(np.broadcast(east_m, north_m).shape, self.elevation, dtype=np.float64)


def build_terrain(scenario: Scenario) -> Terrain:
    """The scenario's terrain source; SRTM tiles are checked to cover the area up front."""
    spec = scenario.terrain
    area = scenario.area
    if isinstance(spec, FlatTerrain):
        return _Flat(spec.elevation_m)
    if isinstance(spec, SyntheticTerrainSpec):
        return SyntheticTerrain.generate(
            seed=spec.seed,
            min_east_m=area.min_east_m,
            max_east_m=area.max_east_m,
            min_north_m=area.min_north_m,
            max_north_m=area.max_north_m,
            base_m=spec.base_m,
            peak_m=spec.peak_m,
            hills=spec.hills,
        )
    assert isinstance(spec, SrtmTerrainSpec)
    terrain = SrtmTerrain(Path(spec.directory), scenario.frame())
    terrain.require_area(area.min_east_m, area.max_east_m, area.min_north_m, area.max_north_m)
    return terrain

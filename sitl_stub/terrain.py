"""The ground under a simulated vehicle: terrain elevation AMSL looked up every physics step.

:class:`GridTerrain` samples an elevation function (vectorised over numpy arrays of latitude
and longitude, e.g. a scenario's synthetic or SRTM terrain) on a grid of ``cell_deg`` cells,
computed a tile of ``tile_cells`` x ``tile_cells`` cells at a time on first use and kept (at
most ``max_tiles``), and interpolates it bilinearly in plain Python floats: one lookup is about
a microsecond, so ten vehicles at 100x cost about 1 % of a core, where one call of a 40-hill
synthetic terrain per step would cost half a core. ArduPilot's terrain library caches its
terrain the same way, in grid blocks loaded around the vehicle (libraries/AP_Terrain).

:class:`Hill` is ground the scenario does not know of (a terrain database error, an unmapped
obstacle): a cosine bump added to the simulated terrain only, for rehearsing a vehicle flown
into terrain its planner never saw.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sitl_stub.model import radii_of_curvature_m

__all__ = ["DEFAULT_CELL_DEG", "ElevationFn", "GridTerrain", "Hill"]

FloatArray = NDArray[np.float64]
ElevationFn = Callable[[FloatArray, FloatArray], FloatArray]
"""Elevation AMSL (m) at arrays of latitude and longitude (deg), any matching shape."""

DEFAULT_CELL_DEG = 1.0 / 3600.0
"""One arc-second (about 31 m north-south): SRTM1's spacing, finer than SRTM3's."""
_DEG = math.pi / 180.0


@dataclass(frozen=True, slots=True)
class Hill:
    """A hill ``height_m`` high at ``lat_deg, lon_deg``: ``h (1 + cos(pi d / r)) / 2`` within
    ``radius_m`` (d the horizontal distance), nothing beyond."""

    lat_deg: float
    lon_deg: float
    radius_m: float
    height_m: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lat_deg) and -90.0 < self.lat_deg < 90.0):
            raise ValueError(f"hill latitude {self.lat_deg!r} is outside (-90, 90)")
        if not (math.isfinite(self.lon_deg) and -180.0 <= self.lon_deg <= 180.0):
            raise ValueError(f"hill longitude {self.lon_deg!r} is outside [-180, 180]")
        if not (math.isfinite(self.radius_m) and self.radius_m > 0.0):
            raise ValueError(f"hill radius must be > 0 m, got {self.radius_m!r}")
        if not (math.isfinite(self.height_m) and self.height_m > 0.0):
            raise ValueError(f"hill height must be > 0 m, got {self.height_m!r}")

    def height_at_m(self, lat_deg: FloatArray, lon_deg: FloatArray) -> FloatArray:
        """The hill's height (m) above the terrain at arrays of latitude and longitude."""
        m, n = radii_of_curvature_m(self.lat_deg * _DEG)
        north = (lat_deg - self.lat_deg) * _DEG * m
        dlon = (lon_deg - self.lon_deg + 180.0) % 360.0 - 180.0
        east = dlon * _DEG * n * math.cos(self.lat_deg * _DEG)
        d = np.hypot(north, east)
        bump = 0.5 * self.height_m * (1.0 + np.cos(np.pi * np.minimum(d / self.radius_m, 1.0)))
        return np.asarray(bump, dtype=np.float64)


def with_hills(base: ElevationFn, hills: Sequence[Hill]) -> ElevationFn:
    """``base`` with ``hills`` added (``base`` itself when there are none)."""
    if not hills:
        return base

    def elevation(lat_deg: FloatArray, lon_deg: FloatArray) -> FloatArray:
        out = np.array(base(lat_deg, lon_deg), dtype=np.float64)
        for hill in hills:
            out += hill.height_at_m(lat_deg, lon_deg)
        return out

    return elevation


class GridTerrain:
    """Terrain elevation AMSL (m) at a point, bilinear on a lazily computed, cached grid."""

    def __init__(
        self,
        elevation: ElevationFn,
        *,
        cell_deg: float = DEFAULT_CELL_DEG,
        tile_cells: int = 128,
        max_tiles: int = 512,
        fallback_m: float = 0.0,
    ) -> None:
        """``fallback_m``: the elevation where ``elevation`` has none (it raises ``ValueError``,
        e.g. a missing SRTM tile, or gives a non-finite value): flat ground there."""
        if not (math.isfinite(cell_deg) and 0.0 < cell_deg <= 0.01):
            raise ValueError(f"cell_deg must be in (0, 0.01], got {cell_deg!r}")
        if tile_cells < 2 or max_tiles < 1:
            raise ValueError("tile_cells must be >= 2 and max_tiles >= 1")
        self._elevation = elevation
        self.fallback_m = float(fallback_m)
        self.cell_deg = cell_deg
        self.tile_cells = tile_cells
        self.max_tiles = max_tiles
        self._tile_deg = cell_deg * tile_cells
        self._side = tile_cells + 1
        self._tiles: dict[tuple[int, int], array[float]] = {}
        # The tile of the last lookup (the next one is nearly always in it): its row and
        # column of tiles (inf: none yet), its south-west corner (deg) and its samples.
        self._last_ti: float = math.inf
        self._last_tj: float = math.inf
        self._last_lat0_deg = 0.0
        self._last_lon0_deg = 0.0
        self._last_tile: array[float] = array("d")

    @property
    def tiles_loaded(self) -> int:
        return len(self._tiles)

    def elevation_m(self, lat_deg: float, lon_deg: float) -> float:
        """Elevation AMSL (m) at one point (the per-step lookup: plain floats)."""
        tile_deg = self._tile_deg
        tile_row = lat_deg / tile_deg
        tile_col = lon_deg / tile_deg
        ti = self._last_ti
        tj = self._last_tj
        # The tile is (floor(tile_row), floor(tile_col)); most lookups stay in the last one.
        if ti <= tile_row < ti + 1.0 and tj <= tile_col < tj + 1.0:
            tile = self._last_tile
        else:
            key = (math.floor(tile_row), math.floor(tile_col))
            tile = self._tiles.get(key) or self._load(key)
            self._last_tile = tile
            self._last_ti = float(key[0])  # exact: float-to-float compares are the fast ones
            self._last_tj = float(key[1])
            self._last_lat0_deg = key[0] * tile_deg
            self._last_lon0_deg = key[1] * tile_deg
        last_cell = self.tile_cells - 1
        cell_deg = self.cell_deg
        y = (lat_deg - self._last_lat0_deg) / cell_deg
        x = (lon_deg - self._last_lon0_deg) / cell_deg
        r = int(y)
        if r > last_cell:
            r = last_cell
        c = int(x)
        if c > last_cell:
            c = last_cell
        fy = y - r
        fx = x - c
        side = self._side
        k = r * side + c
        z00 = tile[k]
        z01 = tile[k + 1]
        z10 = tile[k + side]
        z11 = tile[k + side + 1]
        south = z00 + (z01 - z00) * fx
        north = z10 + (z11 - z10) * fx
        return south + (north - south) * fy

    def _load(self, key: tuple[int, int]) -> array[float]:
        ti, tj = key
        k = np.arange(self._side, dtype=np.float64) * self.cell_deg
        lat, lon = np.meshgrid(ti * self._tile_deg + k, tj * self._tile_deg + k, indexing="ij")
        try:
            values = np.broadcast_to(self._elevation(lat, lon), lat.shape).astype(np.float64)
        except ValueError:  # no data there (TerrainError is a ValueError)
            values = np.full(lat.shape, self.fallback_m)
        values = np.where(np.isfinite(values), values, self.fallback_m)
        tile = array("d")
        tile.frombytes(values.tobytes())  # float64, row-major: what the lookup indexes
        if len(self._tiles) >= self.max_tiles:
            self._tiles.pop(next(iter(self._tiles)))  # the oldest: the vehicles have moved on
        self._tiles[key] = tile
        return tile

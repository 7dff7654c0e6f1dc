"""Map tiles from a local MBTiles file (the MBTiles 1.3 spec): an SQLite database with a
``tiles`` table or view (``zoom_level``, ``tile_column``, ``tile_row`` in TMS order, counted
from the south, and ``tile_data``) and a ``metadata`` table of name/value pairs.

The file is only read: every lookup opens it read-only (``file:...?mode=ro``) and closes it, so
lookups run on any thread and a file replaced on disk is read as it is now.
"""

from __future__ import annotations

import contextlib
import math
import sqlite3
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from gcs.errors import GcsError

__all__ = [
    "MAX_ZOOM",
    "MEDIA_TYPES",
    "WEB_MERCATOR_MAX_LAT_DEG",
    "TileFormat",
    "TileSource",
    "TileSourceError",
]

TileFormat = Literal["png", "jpg", "webp"]
MEDIA_TYPES: dict[TileFormat, str] = {"png": "image/png", "jpg": "image/jpeg", "webp": "image/webp"}
MAX_ZOOM = 30
"""The deepest zoom level a tile address may name (2**30 tiles a side, about 4 cm at the
equator)."""
WEB_MERCATOR_MAX_LAT_DEG = math.degrees(math.atan(math.sinh(math.pi)))
"""The latitude of the square Web-Mercator world's edge (85.0511 deg)."""
_WORLD = (-180.0, -WEB_MERCATOR_MAX_LAT_DEG, 180.0, WEB_MERCATOR_MAX_LAT_DEG)


class TileSourceError(GcsError, ValueError):
    """A tile file that cannot be served from: the file, and what is wrong with it."""


@dataclass(frozen=True)
class TileSource:
    """A raster MBTiles file and what its metadata says (checked when it is opened)."""

    path: Path
    name: str
    format: TileFormat
    bounds: tuple[float, float, float, float]
    """West, south, east, north (deg): where the tiles are."""
    minzoom: int
    maxzoom: int
    attribution: str | None = None

    @property
    def media_type(self) -> str:
        return MEDIA_TYPES[self.format]

    @classmethod
    def open(cls, path: Path) -> TileSource:
        """The tile source of an MBTiles file; its format, bounds and zoom range from the
        ``metadata`` table (the zooms, when it has none, from the tiles).

        Raises
        ------
        TileSourceError
            Not a readable SQLite file, no ``tiles`` or ``metadata`` table, no tiles, vector
            tiles (``pbf``) or a ``format``, ``bounds`` or zoom the spec does not allow.
        """
        path = path.resolve()
        try:
            with _reading(path) as db:
                meta = {str(k): str(v) for k, v in db.execute("SELECT name, value FROM metadata")}
                zooms = db.execute("SELECT min(zoom_level), max(zoom_level) FROM tiles").fetchone()
        except sqlite3.Error as err:
            raise TileSourceError(f"{path}: not a readable MBTiles file ({err})") from None
        if zooms[0] is None:
            raise TileSourceError(f"{path}: the tiles table holds no tile")
        try:
            source = cls(
                path=path,
                name=meta.get("name") or path.stem,
                format=_format(meta.get("format")),
                bounds=_bounds(meta.get("bounds")),
                minzoom=_zoom("minzoom", meta.get("minzoom"), int(zooms[0])),
                maxzoom=_zoom("maxzoom", meta.get("maxzoom"), int(zooms[1])),
                attribution=meta.get("attribution") or None,
            )
        except ValueError as err:
            raise TileSourceError(f"{path}: metadata {err}") from None
        if source.minzoom > source.maxzoom:
            raise TileSourceError(f"{path}: minzoom {source.minzoom} > maxzoom {source.maxzoom}")
        return source

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        """The image of tile ``z/x/y`` in XYZ order (``y`` counted from the north, as web
        maps name tiles), or None when the file has no such tile.

        Raises
        ------
        sqlite3.Error
            The file can no longer be read.
        """
        tms_row = (1 << z) - 1 - y
        with _reading(self.path) as db:
            row = db.execute(
                "SELECT tile_data FROM tiles"
                " WHERE zoom_level = ? AND tile_column = ? AND tile_row = ?",
                (z, x, tms_row),
            ).fetchone()
        return None if row is None else bytes(row[0])


@contextlib.contextmanager
def _reading(path: Path) -> Iterator[sqlite3.Connection]:
    """The file opened read-only (an SQLite URI: a missing file is an error, not a new
    database), closed after."""
    db = sqlite3.connect(f"{path.as_uri()}?mode=ro", uri=True)
    try:
        yield db
    finally:
        db.close()


def _format(value: str | None) -> TileFormat:
    fmt = (value or "").strip().lower()
    for known in MEDIA_TYPES:
        if fmt == known or (known == "jpg" and fmt == "jpeg"):
            return known
    if fmt == "pbf":
        raise ValueError("format 'pbf': vector tiles; the console draws png, jpg or webp tiles")
    raise ValueError(f"format {value!r}: one of png, jpg, webp is needed")


def _bounds(value: str | None) -> tuple[float, float, float, float]:
    if not value:
        return _WORLD
    try:
        west, south, east, north = (float(p) for p in value.split(","))
    except ValueError:
        raise ValueError(f"bounds {value!r}: four numbers, 'west,south,east,north'") from None
    lim = WEB_MERCATOR_MAX_LAT_DEG
    if not (-180.0 <= west < east <= 180.0 and -90.0 <= south < north <= 90.0):
        raise ValueError(f"bounds {value!r}: west < east within +-180, south < north within +-90")
    return west, max(south, -lim), east, min(north, lim)


def _zoom(key: str, value: str | None, held: int) -> int:
    if value is None or value.strip() == "":
        return held
    try:
        zoom = int(value)
    except ValueError:
        raise ValueError(f"{key} {value!r}: a whole number") from None
    if not 0 <= zoom <= MAX_ZOOM:
        raise ValueError(f"{key} {zoom}: within 0..{MAX_ZOOM}")
    return zoom

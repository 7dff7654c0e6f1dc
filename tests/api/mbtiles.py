"""MBTiles files for the tests: solid-colour PNG tiles (zlib and struct, no image library)
kept in an SQLite file laid out as the MBTiles 1.3 spec says."""

from __future__ import annotations

import math
import sqlite3
import struct
import zlib
from collections.abc import Mapping
from pathlib import Path

__all__ = ["TILE_PX", "solid_png", "tile_of", "write_mbtiles"]

TILE_PX = 256


def solid_png(rgb: tuple[int, int, int], size: int = TILE_PX) -> bytes:
    """A ``size`` x ``size`` PNG of one colour (8-bit RGB)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    row = b"\x00" + bytes(rgb) * size  # filter type 0, then the pixels
    header = struct.pack(">IIBBBBB", size, size, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(row * size, 9))
        + chunk(b"IEND", b"")
    )


def tile_of(lat_deg: float, lon_deg: float, z: int) -> tuple[int, int]:
    """The XYZ tile (x, y counted from the north) holding a point, at zoom ``z``."""
    n = 1 << z
    x = int((lon_deg + 180.0) / 360.0 * n)
    y = int((1.0 - math.asinh(math.tan(math.radians(lat_deg))) / math.pi) / 2.0 * n)
    return x, y


def write_mbtiles(
    path: Path,
    tiles: Mapping[tuple[int, int, int], bytes],
    metadata: Mapping[str, str],
) -> Path:
    """An MBTiles file of ``tiles``, keyed by (zoom_level, tile_column, tile_row) as the file
    holds them (TMS rows, counted from the south), with a ``metadata`` table."""
    db = sqlite3.connect(path)
    try:
        db.execute("CREATE TABLE metadata (name TEXT, value TEXT)")
        db.execute(
            "CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, tile_row INTEGER,"
            " tile_data BLOB)"
        )
        db.execute("CREATE UNIQUE INDEX tile_index ON tiles (zoom_level, tile_column, tile_row)")
        db.executemany("INSERT INTO metadata VALUES (?, ?)", metadata.items())
        db.executemany(
            "INSERT INTO tiles VALUES (?, ?, ?, ?)", [(*k, data) for k, data in tiles.items()]
        )
        db.commit()
    finally:
        db.close()
    return path

"""Map tiles for the console's map, from the MBTiles file the operator configured
(``TCGCS_TILES_MBTILES``): the source's description and the tiles, in XYZ order."""

from __future__ import annotations

import asyncio
import sqlite3
from typing import Annotated

from fastapi import APIRouter, Depends, Request, Response
from fastapi import Path as PathParam

from gcs.api.auth import require
from gcs.api.routes.common import ERRORS
from gcs.api.schemas import TileSourceOut
from gcs.api.tiles import MAX_ZOOM, MEDIA_TYPES, TileSource
from gcs.service.engine import InvalidInput, NotFound, ServiceError

router = APIRouter(responses=ERRORS, dependencies=[Depends(require("observe"))], tags=["tiles"])

TILE_URL = "/v1/tiles/{z}/{x}/{y}.{ext}"
NOT_CONFIGURED = "no tile source is configured (TCGCS_TILES_MBTILES names an MBTiles file)"

Zoom = Annotated[int, PathParam(ge=0, le=MAX_ZOOM, description="zoom level")]
Index = Annotated[int, PathParam(ge=0, description="0 .. 2**z - 1; y counted from the north")]


class TileSourceUnreadable(ServiceError):
    status = 503


def source_of(request: Request) -> TileSource:
    source: TileSource | None = request.app.state.tiles
    if source is None:
        raise NotFound(NOT_CONFIGURED)
    return source


@router.get("/tiles")
async def tile_source(request: Request) -> TileSourceOut:
    """The map tile source (TileJSON): its name, format, bounds, zoom range and tile URL;
    404 when none is configured."""
    s = source_of(request)
    return TileSourceOut(
        name=s.name,
        format=s.format,
        tiles=[TILE_URL.replace("{ext}", s.format)],
        minzoom=s.minzoom,
        maxzoom=s.maxzoom,
        bounds=list(s.bounds),
        attribution=s.attribution,
    )


@router.get(
    "/tiles/{z}/{x}/{y}.{ext}",
    response_class=Response,
    responses={
        200: {
            "description": "the tile's image, as the file holds it",
            "content": {media: {} for media in MEDIA_TYPES.values()},
        },
        503: ERRORS[400],
    },
)
async def tile(z: Zoom, x: Index, y: Index, ext: str, request: Request) -> Response:
    """One tile (XYZ: ``y`` counted from the north); 404 when the file has none there, 422
    for an address outside the zoom's ``2**z`` tiles a side."""
    s = source_of(request)
    side = 1 << z
    for name, value in (("x", x), ("y", y)):
        if value >= side:
            msg = f"{name} {value} is outside the {side} tiles a side of zoom {z} (0..{side - 1})"
            raise InvalidInput(msg, [{"loc": ["path", name], "msg": msg, "type": "value_error"}])
    if ext != s.format:
        raise NotFound(
            f"the tile source's tiles are .{s.format}: {TILE_URL.replace('{ext}', s.format)}"
        )
    try:
        data = await asyncio.to_thread(s.tile, z, x, y)
    except sqlite3.Error as err:
        raise TileSourceUnreadable(
            f"the tile source {s.path.name} cannot be read ({err})"
        ) from None
    if data is None:
        held = f"zooms {s.minzoom}..{s.maxzoom}"
        raise NotFound(f"no tile {z}/{x}/{y} in the tile source {s.name!r} (it holds {held})")
    return Response(
        data, media_type=s.media_type, headers={"Cache-Control": "private, max-age=3600"}
    )

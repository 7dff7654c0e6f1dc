"""The map tile source: an MBTiles file built here (solid-colour PNG tiles in TMS rows) served
at ``/v1/tiles/{z}/{x}/{y}.png`` in XYZ order, behind the observe scope; without a file the
routes say none is configured."""

from __future__ import annotations

import sqlite3
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import httpx
import pytest
from fastapi import FastAPI
from pydantic import ValidationError

from gcs.api.app import create_app
from gcs.api.settings import Settings
from gcs.api.tiles import TileSource, TileSourceError
from tests.api.conftest import auth, problem, running, settings_for
from tests.api.mbtiles import solid_png, write_mbtiles

NORTH = solid_png((200, 30, 30))
SOUTH = solid_png((30, 30, 200))
STORED = {  # (zoom_level, tile_column, tile_row): the file's own TMS rows, counted from the south
    (1, 0, 1): NORTH,
    (1, 0, 0): SOUTH,
    (3, 6, 4): solid_png((10, 160, 40)),
    (3, 6, 5): solid_png((240, 200, 0)),
    (3, 7, 5): solid_png((0, 0, 0)),
}
META = {
    "name": "test tiles",
    "format": "png",
    "bounds": "90,0,180,60",
    "minzoom": "1",
    "maxzoom": "3",
    "attribution": "made by the test",
}


def _settings(tmp_path: Path, db_url: str, tiles: Path | None) -> Settings:
    return settings_for(tmp_path / "data", db_url).model_copy(update={"tiles_mbtiles": tiles})


@pytest.fixture
def mbtiles(tmp_path: Path) -> Path:
    return write_mbtiles(tmp_path / "area.mbtiles", STORED, META)


@pytest.fixture
def app(tmp_path: Path, db_url: str, mbtiles: Path) -> FastAPI:
    return create_app(_settings(tmp_path, db_url, mbtiles))


@pytest.fixture
async def bare(tmp_path: Path, db_url: str) -> AsyncIterator[httpx.AsyncClient]:
    """A client of the app without a tile source."""
    async for c in running(create_app(_settings(tmp_path, db_url, None))):
        yield c


async def test_a_tile_is_the_bytes_stored_at_its_flipped_row(client: httpx.AsyncClient) -> None:
    for (z, x, tms_row), data in STORED.items():
        y = (1 << z) - 1 - tms_row
        r = await client.get(f"/v1/tiles/{z}/{x}/{y}.png", headers=auth("observe"))
        assert r.status_code == 200, (z, x, y, r.text)
        assert r.headers["content-type"] == "image/png"
        assert r.content == data, (z, x, y)


async def test_row_zero_is_the_northern_tile(client: httpx.AsyncClient) -> None:
    """XYZ counts rows from the north, TMS (the file) from the south: at zoom 1 the file's
    row 1 is the northern half of the world, which XYZ calls y = 0."""
    north = await client.get("/v1/tiles/1/0/0.png", headers=auth("observe"))
    south = await client.get("/v1/tiles/1/0/1.png", headers=auth("observe"))
    assert (north.content, south.content) == (NORTH, SOUTH)


async def test_the_source_is_described_as_tilejson(client: httpx.AsyncClient) -> None:
    r = await client.get("/v1/tiles", headers=auth("observe"))
    assert r.status_code == 200, r.text
    assert r.json() == {
        "tilejson": "3.0.0",
        "name": "test tiles",
        "format": "png",
        "tiles": ["/v1/tiles/{z}/{x}/{y}.png"],
        "scheme": "xyz",
        "minzoom": 1,
        "maxzoom": 3,
        "bounds": [90.0, 0.0, 180.0, 60.0],
        "attribution": "made by the test",
    }


@pytest.mark.parametrize("path", ["/v1/tiles/3/0/0.png", "/v1/tiles/2/0/0.png"])
async def test_a_missing_tile_is_404(client: httpx.AsyncClient, path: str) -> None:
    body = problem(await client.get(path, headers=auth("observe")), 404)
    assert "no tile" in body["detail"] and "zooms 1..3" in body["detail"], body


@pytest.mark.parametrize(
    ("path", "words"),
    [
        ("/v1/tiles/3/8/0.png", "x 8 is outside the 8 tiles a side of zoom 3 (0..7)"),
        ("/v1/tiles/3/0/8.png", "y 8 is outside the 8 tiles a side of zoom 3 (0..7)"),
        ("/v1/tiles/0/0/1.png", "y 1 is outside the 1 tiles a side of zoom 0 (0..0)"),
        ("/v1/tiles/31/0/0.png", "z: Input should be less than or equal to 30"),
        ("/v1/tiles/3/-1/0.png", "x: Input should be greater than or equal to 0"),
        ("/v1/tiles/3/a/0.png", "x: Input should be a valid integer"),
    ],
)
async def test_an_address_outside_the_zoom_is_422(
    client: httpx.AsyncClient, path: str, words: str
) -> None:
    body = problem(await client.get(path, headers=auth("observe")), 422)
    assert words in body["detail"], body


async def test_another_image_format_is_404_naming_the_right_one(
    client: httpx.AsyncClient,
) -> None:
    body = problem(await client.get("/v1/tiles/1/0/0.jpg", headers=auth("observe")), 404)
    assert body["detail"] == "the tile source's tiles are .png: /v1/tiles/{z}/{x}/{y}.png", body


@pytest.mark.parametrize("path", ["/v1/tiles", "/v1/tiles/1/0/0.png"])
async def test_tiles_need_a_token(client: httpx.AsyncClient, path: str) -> None:
    r = await client.get(path)
    problem(r, 401)
    assert r.headers["www-authenticate"] == "Bearer"
    problem(await client.get(path, headers={"Authorization": "Bearer not-a-token"}), 401)


@pytest.mark.parametrize("path", ["/v1/tiles", "/v1/tiles/1/0/0.png"])
async def test_without_a_tile_file_the_routes_say_none_is_configured(
    bare: httpx.AsyncClient, path: str
) -> None:
    body = problem(await bare.get(path, headers=auth("observe")), 404)
    assert body["detail"].startswith("no tile source is configured"), body
    assert "TCGCS_TILES_MBTILES" in body["detail"], body


async def test_a_jpeg_source_serves_image_jpeg(tmp_path: Path, db_url: str) -> None:
    jpeg = b"\xff\xd8\xff\xe0 not really a picture"
    path = write_mbtiles(tmp_path / "j.mbtiles", {(0, 0, 0): jpeg}, {**META, "format": "jpeg"})
    async for c in running(create_app(_settings(tmp_path, db_url, path))):
        r = await c.get("/v1/tiles/0/0/0.jpg", headers=auth("observe"))
        assert (r.status_code, r.headers["content-type"], r.content) == (200, "image/jpeg", jpeg)


def test_a_tiles_view_is_read_like_a_table(tmp_path: Path) -> None:
    """The spec allows ``tiles`` to be a view (deduplicated images, as many tools write)."""
    path = tmp_path / "view.mbtiles"
    db = sqlite3.connect(path)
    db.executescript(
        """
        CREATE TABLE metadata (name TEXT, value TEXT);
        INSERT INTO metadata VALUES ('format', 'png');
        CREATE TABLE map (zoom_level INT, tile_column INT, tile_row INT, tile_id TEXT);
        CREATE TABLE images (tile_id TEXT, tile_data BLOB);
        INSERT INTO map VALUES (2, 1, 3, 'a'), (2, 2, 3, 'a');
        CREATE VIEW tiles AS SELECT zoom_level, tile_column, tile_row, tile_data
            FROM map JOIN images USING (tile_id);
        """
    )
    db.execute("INSERT INTO images VALUES ('a', ?)", (NORTH,))
    db.commit()
    db.close()
    source = TileSource.open(path)
    assert (source.name, source.minzoom, source.maxzoom) == ("view", 2, 2)
    assert source.tile(2, 1, 0) == source.tile(2, 2, 0) == NORTH
    assert source.tile(2, 1, 3) is None


@pytest.mark.parametrize(
    ("build", "words"),
    [
        (lambda p: p.write_bytes(b"not sqlite" * 100), "not a readable MBTiles file"),
        (lambda p: write_mbtiles(p, STORED, {**META, "format": "pbf"}), "vector tiles"),
        (lambda p: write_mbtiles(p, STORED, {**META, "format": "tiff"}), "format 'tiff'"),
        (lambda p: write_mbtiles(p, STORED, {**META, "bounds": "1,2,3"}), "bounds '1,2,3'"),
        (lambda p: write_mbtiles(p, STORED, {**META, "maxzoom": "x"}), "maxzoom 'x'"),
        (lambda p: write_mbtiles(p, STORED, {**META, "minzoom": "4"}), "minzoom 4 > maxzoom 3"),
        (lambda p: write_mbtiles(p, {}, META), "holds no tile"),
    ],
)
def test_a_bad_tile_file_stops_the_app_being_made(
    tmp_path: Path, db_url: str, build: Callable[[Path], object], words: str
) -> None:
    path = tmp_path / "bad.mbtiles"
    build(path)
    with pytest.raises(TileSourceError, match=r"bad\.mbtiles") as err:
        create_app(_settings(tmp_path, db_url, path))
    assert words in str(err.value)


def test_a_missing_tile_file_is_a_settings_error(tmp_path: Path) -> None:
    with pytest.raises(ValidationError, match="tiles_mbtiles"):
        Settings(tiles_mbtiles=tmp_path / "nowhere.mbtiles")

"""The console's tile layer in Chromium against ``python -m gcs serve`` with a tile source: an
MBTiles file of solid-colour tiles over the compact paper scenario's area
(:func:`tests.teams.compact_paper`, the flight the test plans and uploads), each tile its own
colour.
The page asks the service (and nothing else) for the tiles the view shows and draws each where
its corners fall in the scenario's local metres; the base-layer buttons switch between the
tiles and the hillshade. Where a tile lands is checked by the canvas's pixels against points
projected here (``planner.geo.LocalFrame``)."""

from __future__ import annotations

import itertools
import math
import re
from collections import Counter
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from planner.geo import LocalFrame
from planner.scenario import parse_scenario
from tests.api.mbtiles import solid_png, tile_of, write_mbtiles
from tests.service.conftest import Service, serve
from tests.service.test_flights_http import _flight
from tests.teams import compact_paper
from tests.web.conftest import Console

pytestmark = pytest.mark.slow  # a compact flight planned and uploaded: about 3 s

ZOOMS = (10, 11)
"""The tile source's zooms. The view fitted to the compact area (50 km across) is four times
as close as to the paper's (200 km), two zooms deeper: at 10 and 11 it shows as many tiles,
as large, as 8 and 9 did over the paper's area (zoom 11 drawn, 12 wanted at 1:1)."""
MARGIN_DEG = 0.075
"""Tiles beyond the area's edges, as far as the view reaches past them (0.3 deg about the
paper's area, a quarter of it about the compact one)."""
SAMPLES = (0.03, 0.25, 0.5, 0.75, 0.97)
"""Where each tile is sampled, as fractions of its side (0.03: a few pixels inside)."""
TILE_URL = re.compile(r"^http://127\.0\.0\.1:\d+/v1/tiles/(\d+)/(\d+)/(\d+)\.png$")

Rgb = tuple[int, int, int]
Tile = tuple[int, int, int]  # z, x, y (XYZ)


def _colour(k: int) -> Rgb:
    """The k-th tile's colour: little blue, which the hillshade (washed towards white) has
    everywhere more of."""
    return (60 + (k * 37) % 190, 60 + (k * 83) % 190, 10 + 10 * (k % 4))


def _tile_set() -> tuple[dict[Tile, Rgb], tuple[float, float, float, float]]:
    """A colour per tile of ZOOMS over the compact scenario's area (and a margin); the bounds."""
    area = parse_scenario(compact_paper()).area
    frame = LocalFrame(area.origin.lat_deg, area.origin.lon_deg)
    edge = [
        frame.to_geodetic(
            area.min_east_m + fx * area.width_m, area.min_north_m + fy * area.height_m
        )
        for fx, fy in itertools.product((0.0, 0.5, 1.0), repeat=2)
    ]
    west = min(lon for _, lon in edge) - MARGIN_DEG
    east = max(lon for _, lon in edge) + MARGIN_DEG
    south = min(lat for lat, _ in edge) - MARGIN_DEG
    north = max(lat for lat, _ in edge) + MARGIN_DEG
    colours: dict[Tile, Rgb] = {}
    for z in ZOOMS:
        x0, y0 = tile_of(north, west, z)
        x1, y1 = tile_of(south, east, z)
        for x, y in itertools.product(range(x0, x1 + 1), range(y0, y1 + 1)):
            colours[(z, x, y)] = _colour(len(colours))
    by_zoom = [[c for t, c in colours.items() if t[0] == z] for z in ZOOMS]
    for same in by_zoom:  # tiles of one zoom are told apart by colour
        assert all(max(abs(p - q) for p, q in zip(a, b, strict=True)) > 3
                   for a, b in itertools.combinations(same, 2))  # fmt: skip
    return colours, (west, south, east, north)


COLOURS, BOUNDS = _tile_set()


def _near(a: Rgb | None, b: Rgb) -> bool:
    return a is not None and max(abs(p - q) for p, q in zip(a, b, strict=True)) <= 1


def _tile_point(z: int, x: float, y: float) -> tuple[float, float]:
    """Latitude and longitude (deg) of a point of the XYZ grid (Web Mercator)."""
    n = 1 << z
    lat = math.degrees(math.atan(math.sinh(math.pi * (1.0 - 2.0 * y / n))))
    return lat, x / n * 360.0 - 180.0


@pytest.fixture
async def service(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> AsyncIterator[Service]:
    """The service with the tile file as its tile source (``TCGCS_TILES_MBTILES``)."""
    tiles = {(z, x, (1 << z) - 1 - y): solid_png(c) for (z, x, y), c in COLOURS.items()}
    meta = {
        "name": "compact paper area test tiles",
        "format": "png",
        "bounds": ",".join(f"{v:.6f}" for v in BOUNDS),
        "minzoom": str(min(ZOOMS)),
        "maxzoom": str(max(ZOOMS)),
        "attribution": "<b>test</b> tiles",
    }
    path = write_mbtiles(tmp_path / "area.mbtiles", tiles, meta)
    monkeypatch.setenv("TCGCS_TILES_MBTILES", str(path))
    async with serve(tmp_path / "data") as s:
        yield s


async def _samples(c: Console, zoom: int) -> list[tuple[Tile, Rgb | None, tuple[float, float]]]:
    """Per stored tile of ``zoom``, the canvas's colour at points inside it (None: off the
    canvas) and where on the canvas they are (CSS px), the points projected here into the
    scenario's local metres."""
    origin = await c.js("tcgcs.state.mapDoc.origin")
    frame = LocalFrame(origin["lat_deg"], origin["lon_deg"])
    points: list[tuple[Tile, tuple[float, float]]] = []
    for tile in (t for t in COLOURS if t[0] == zoom):
        z, x, y = tile
        for fx, fy in itertools.product(SAMPLES, repeat=2):
            points.append((tile, frame.to_local(*_tile_point(z, x + fx, y + fy))))
    rgbs = await c.js(
        """pts => { const m = tcgcs.map;
          return pts.map(([e, n]) => { const [x, y] = m.toScreen(e, n);
            if (x < 0 || y < 0 || x >= m.width || y >= m.height) return [null, x, y];
            const d = m.ctx.getImageData(Math.floor(x * m.dpr), Math.floor(y * m.dpr), 1, 1).data;
            return [[d[0], d[1], d[2]], x, y]; }); }""",
        [p for _, p in points],
    )
    return [
        (t, None if rgb is None else tuple(rgb), (x, y))
        for (t, _), (rgb, x, y) in zip(points, rgbs, strict=True)
    ]


async def _drawn(c: Console) -> None:
    """Wait for every tile the view wants to be in and drawn."""
    await c.until(
        """() => { const t = tcgcs.map.tiles;
          return t && t.zoom !== null && t.inFlight === 0 && !tcgcs.map.dirty && t.wanted.size > 0
            && [...t.wanted].every(k => (t.cache.get(k) || {}).state === "ok")
            && t.drawn.filter(d => d.z === t.zoom).length === t.wanted.size; }"""
    )


def _tile_requests(c: Console) -> list[str]:
    return [u for u in c.requests if "/v1/tiles/" in u]


async def test_the_console_draws_the_service_tiles_under_the_flight(console: Console) -> None:
    c, page = console, console.page
    async with c.service.client() as client:
        fid, _ = await _flight(client, {"speedup": 200.0, "seed": 3}, scenario_name="compact")
    await c.open(f"/ui/?flight={fid}")
    await c.login()
    await c.until("id => tcgcs.state.flightId === id && tcgcs.state.mapDoc", fid)
    await _drawn(c)
    assert await c.js("tcgcs.geometry().base") == "tiles"
    assert await page.get_attribute('#map-base [data-base="tiles"]', "class") == "active"

    # The tiles came from the service, only ones it holds; nothing left 127.0.0.1.
    asked = _tile_requests(c)
    assert asked, c.requests
    for url in asked:
        m = TILE_URL.match(url)
        assert m is not None, url
        assert tuple(int(v) for v in m.groups()) in COLOURS, url
    assert await c.js("tcgcs.map.tiles.missing") == 0
    assert not c.external(), c.external()

    # The page projects as the service does (the same Transverse Mercator about the origin).
    origin = await c.js("tcgcs.state.mapDoc.origin")
    frame = LocalFrame(origin["lat_deg"], origin["lon_deg"])
    for lat, lon in [(34.0, 108.0), (34.5, 108.6), (36.3, 110.9), (35.2, 109.7)]:
        e, n = await c.js("([a, b]) => tcgcs.map.tiles.frame.toLocal(a, b)", [lat, lon])
        want = frame.to_local(lat, lon)
        assert abs(e - want[0]) < 1e-6 and abs(n - want[1]) < 1e-6, ((lat, lon), (e, n), want)

    # Every point inside a tile shows that tile's colour, or an overlay's (a route, a threat,
    # a label): never a neighbour's, so each tile lies where its corners are.
    zoom = await c.js("tcgcs.map.tiles.zoom")
    assert zoom in ZOOMS
    seen, own = await _placed(c)
    assert len(own) >= 0.6 * len(seen), (len(own), len(seen))
    shown = Counter(t for t, _ in seen)
    unseen = [t for t, k in shown.items() if k >= 3 and t not in own]  # 3: not just a corner
    assert not unseen, [(t, rgb) for t, rgb in seen if t in unseen]
    await c.screenshot("console-tiles.png")

    # The hillshade: no tile colour is left, and no tile is asked for while it shows.
    await page.click('#map-base [data-base="hillshade"]')
    await c.until("() => tcgcs.geometry().base === 'hillshade' && !tcgcs.map.dirty")
    n_asked = len(_tile_requests(c))
    shaded = [(t, rgb) for t, rgb, _ in await _samples(c, zoom) if rgb is not None]
    assert not [t for t, rgb in shaded if _near(rgb, COLOURS[t])]
    await page.mouse.move(*(await _centre(c)))
    await page.mouse.wheel(0, -300)  # a new view: the hillshade needs no tile
    await c.until("() => !tcgcs.map.dirty")
    assert len(_tile_requests(c)) == n_asked

    # Back to the tiles, then in close: the deepest zoom's tiles magnified, still in place. The
    # view closes in on the sample nearest its centre that shows its own tile (the centre
    # itself lies in SAM1's disc, whose tint covers the one sample left in view about it).
    await page.click('#map-base [data-base="tiles"]')
    await _drawn(c)
    await c.js("([x, y]) => tcgcs.map.zoomAt(x, y, 8)", await _own_spot(c))
    await _drawn(c)
    assert await c.js("tcgcs.map.tiles.idealZoom(tcgcs.map)") > max(ZOOMS) + 2
    _, own = await _placed(c)
    assert own
    assert not c.external(), c.external()


async def _placed(c: Console) -> tuple[list[tuple[Tile, Rgb]], list[Tile]]:
    """The samples on the canvas at the zoom drawn, and the tiles of those showing their own
    colour; none shows a neighbour's."""
    zoom = await c.js("tcgcs.map.tiles.zoom")
    palette = {COLOURS[t]: t for t in COLOURS if t[0] == zoom}
    seen = [(t, rgb) for t, rgb, _ in await _samples(c, zoom) if rgb is not None]
    wrong = [
        (t, other)
        for t, rgb in seen
        for colour, other in palette.items()
        if other != t and _near(rgb, colour)
    ]
    assert not wrong, wrong[:5]
    return seen, [t for t, rgb in seen if _near(rgb, COLOURS[t])]


async def _own_spot(c: Console) -> tuple[float, float]:
    """Where on the canvas (CSS px) the sample nearest its centre that shows its own tile's
    colour is."""
    zoom = await c.js("tcgcs.map.tiles.zoom")
    size = await c.js("[tcgcs.map.width, tcgcs.map.height]")
    own = [xy for t, rgb, xy in await _samples(c, zoom) if _near(rgb, COLOURS[t])]
    assert own
    return min(own, key=lambda xy: math.dist(xy, (size[0] / 2, size[1] / 2)))


async def _centre(c: Console) -> tuple[float, float]:
    r = await c.js("(() => { const b = tcgcs.map.canvas.getBoundingClientRect();"
                   " return [b.left + b.width / 2, b.top + b.height / 2]; })()")  # fmt: skip
    return float(r[0]), float(r[1])

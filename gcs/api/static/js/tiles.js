// The tile layer: raster tiles from the service's tile source (`GET /v1/tiles`, TileJSON; the
// tiles at `/v1/tiles/{z}/{x}/{y}.png`) drawn in the map's local metres. A Web-Mercator tile is
// not a rectangle there (the local plane is a Transverse Mercator about the scenario's origin,
// where meridians converge), so each tile is drawn as a grid of pieces, each the affine image
// of its projected corners: at the zoom the view asks for, a piece is off by under 0.2 px.

import { LocalFrame } from "./geo.js";

const TILE_PX = 256;
const EQUATOR_M = 2 * Math.PI * 6378137;
const MAX_TILES = 256; // a view that needs more, at the source's least zoom, draws none
const MAX_CACHED = 512;
const MAX_IN_FLIGHT = 6;
const RETRY_MS = 10000; // a tile that failed (not a 404) is asked for again after this
const PIECES = 4; // per tile side, at the zoom the view asks for; doubled per zoom magnified
const MAX_PIECES = 32;
const ANCESTORS = 4; // lower zooms drawn in place of a tile still loading
const EDGE_SAMPLES = 4; // per side of the view, to find the latitudes and longitudes it spans

function lonToX(lonDeg, z) {
  return ((lonDeg + 180) / 360) * 2 ** z;
}

function latToY(latDeg, z) {
  const lat = (latDeg * Math.PI) / 180;
  return ((1 - Math.asinh(Math.tan(lat)) / Math.PI) / 2) * 2 ** z;
}

/** [lat_deg, lon_deg] of a point of the XYZ tile grid at zoom z (x, y fractional). */
export function tilePoint(z, x, y) {
  const n = 2 ** z;
  return [(Math.atan(Math.sinh(Math.PI * (1 - (2 * y) / n))) * 180) / Math.PI, (x / n) * 360 - 180];
}

const key = (z, x, y) => `${z}/${x}/${y}`;

export class TileLayer {
  /** `source`: the TileJSON; `fetchTile(z, x, y)` resolves to the tile's Blob or rejects
   *  (an error with `status` 404: no such tile); `onChange()` when a tile arrives. */
  constructor(source, fetchTile, onChange) {
    this.source = source;
    this.fetchTile = fetchTile;
    this.onChange = onChange || (() => {});
    this.frame = null;
    this.cache = new Map(); // "z/x/y" -> {z, x, y, state, image, grids, at}
    this.queue = [];
    this.inFlight = 0;
    this.wanted = new Set();
    this.requested = 0;
    this.loaded = 0;
    this.missing = 0;
    this.zoom = null; // the zoom of the last draw
    this.drawn = []; // the last draw's tiles: {z, x, y, corners} (corners: canvas CSS px)
    this.note = "";
  }

  /** The scenario's origin: the local frame the tiles are projected into. */
  setOrigin(origin) {
    const f = this.frame;
    if (f && f.originLatDeg === origin.lat_deg && f.originLonDeg === origin.lon_deg) return;
    this.frame = new LocalFrame(origin.lat_deg, origin.lon_deg);
    for (const entry of this.cache.values()) entry.grids = new Map();
  }

  /** The zoom whose tile pixels are nearest the view's device pixels (fractional). */
  idealZoom(map) {
    const [lat] = this.frame.toGeodetic(map.view.cx, map.view.cy);
    const metresPerTilePx = (EQUATOR_M * Math.cos((lat * Math.PI) / 180)) / TILE_PX;
    return Math.log2(metresPerTilePx * map.view.scale * map.dpr);
  }

  /** Draw what the view shows (under everything else); asks for the tiles it lacks. */
  draw(ctx, map) {
    this.drawn = [];
    this.note = "";
    this.wanted = new Set();
    if (!this.frame) return;
    const s = this.source;
    const ideal = this.idealZoom(map);
    const z = Math.min(s.maxzoom, Math.max(s.minzoom, Math.round(ideal)));
    this.zoom = z;
    const range = this._range(map, z);
    if (!range) return;
    const [x0, x1, y0, y1] = range;
    if ((x1 - x0 + 1) * (y1 - y0 + 1) > MAX_TILES) {
      this.note = `zoom in for the tiles (from zoom ${s.minzoom})`;
      return;
    }
    const cx = (x0 + x1) / 2;
    const cy = (y0 + y1) / 2;
    const view = [];
    for (let x = x0; x <= x1; x += 1) for (let y = y0; y <= y1; y += 1) view.push([x, y]);
    view.sort((a, b) => Math.hypot(a[0] - cx, a[1] - cy) - Math.hypot(b[0] - cx, b[1] - cy));
    this.wanted = new Set(view.map(([x, y]) => key(z, x, y)));
    const now = performance.now();
    const ready = [];
    const standIns = new Map();
    for (const [x, y] of view) {
      const entry = this._entry(z, x, y, now);
      if (entry.state === "ok") {
        ready.push(entry);
        continue;
      }
      for (let k = 1; k <= ANCESTORS && z - k >= s.minzoom; k += 1) {
        const up = this.cache.get(key(z - k, x >> k, y >> k));
        if (up && up.state === "ok") {
          standIns.set(key(up.z, up.x, up.y), up);
          break;
        }
      }
    }
    const order = [...standIns.values()].sort((a, b) => a.z - b.z).concat(ready);
    ctx.imageSmoothingEnabled = true;
    for (const entry of order) this._drawTile(ctx, map, entry, ideal);
    ctx.setTransform(map.dpr, 0, 0, map.dpr, 0, 0);
    this._pump();
  }

  /** The XYZ tiles [x0, x1, y0, y1] of zoom z the view covers within the source's bounds. */
  _range(map, z) {
    let [west, south, east, north] = [180, 90, -180, -90];
    for (let i = 0; i <= EDGE_SAMPLES; i += 1) {
      const f = i / EDGE_SAMPLES;
      for (const [px, py] of [
        [f * map.width, 0],
        [f * map.width, map.height],
        [0, f * map.height],
        [map.width, f * map.height],
      ]) {
        const [lat, lon] = this.frame.toGeodetic(...map.toWorld(px, py));
        if (!Number.isFinite(lat) || !Number.isFinite(lon)) continue;
        west = Math.min(west, lon);
        east = Math.max(east, lon);
        south = Math.min(south, lat);
        north = Math.max(north, lat);
      }
    }
    const [bw, bs, be, bn] = this.source.bounds;
    west = Math.max(west, bw);
    east = Math.min(east, be);
    south = Math.max(south, bs);
    north = Math.min(north, bn);
    if (west >= east || south >= north) return null;
    const last = 2 ** z - 1;
    const clamp = (v) => Math.min(last, Math.max(0, Math.floor(v)));
    return [clamp(lonToX(west, z)), clamp(lonToX(east, z)), clamp(latToY(north, z)), clamp(latToY(south, z))];
  }

  /** The cache's entry of a tile, asked for if it is not there (or failed a while ago). */
  _entry(z, x, y, now) {
    const k = key(z, x, y);
    let entry = this.cache.get(k);
    if (entry && entry.state === "failed" && now - entry.at > RETRY_MS) {
      this.cache.delete(k);
      entry = null;
    }
    if (!entry) {
      entry = { z, x, y, state: "queued", image: null, grids: new Map(), at: now };
      this.cache.set(k, entry);
      this.queue.push(k);
    }
    return entry;
  }

  _pump() {
    while (this.inFlight < MAX_IN_FLIGHT && this.queue.length) {
      const k = this.queue.shift();
      const entry = this.cache.get(k);
      if (!entry || entry.state !== "queued") continue;
      if (!this.wanted.has(k)) {
        this.cache.delete(k); // out of view by now: asked for again when it is back
        continue;
      }
      entry.state = "loading";
      this.inFlight += 1;
      this.requested += 1;
      this.fetchTile(entry.z, entry.x, entry.y)
        .then((blob) => createImageBitmap(blob))
        .then((image) => {
          entry.image = image;
          entry.state = "ok";
          this.loaded += 1;
          this._evict();
          this.onChange();
        })
        .catch((err) => {
          entry.state = err && err.status === 404 ? "missing" : "failed";
          entry.at = performance.now();
          if (entry.state === "missing") this.missing += 1;
        })
        .finally(() => {
          this.inFlight -= 1;
          this._pump();
        });
    }
  }

  /** Forget the oldest tiles out of view beyond MAX_CACHED. */
  _evict() {
    for (const [k, entry] of this.cache) {
      if (this.cache.size <= MAX_CACHED) return;
      if (this.wanted.has(k) || entry.state === "loading" || entry.state === "queued") continue;
      if (entry.image) entry.image.close();
      this.cache.delete(k);
    }
  }

  /** Local metres of an (n+1) x (n+1) grid over the tile, row by row from its north-west. */
  _grid(entry, n) {
    let grid = entry.grids.get(n);
    if (!grid) {
      grid = [];
      for (let j = 0; j <= n; j += 1) {
        for (let i = 0; i <= n; i += 1) {
          grid.push(this.frame.toLocal(...tilePoint(entry.z, entry.x + i / n, entry.y + j / n)));
        }
      }
      entry.grids.set(n, grid);
    }
    return grid;
  }

  _drawTile(ctx, map, entry, ideal) {
    const magnified = Math.max(0, Math.round(ideal) - entry.z);
    const n = Math.min(MAX_PIECES, PIECES << magnified);
    const grid = this._grid(entry, n);
    const screen = grid.map(([e, nm]) => map.toScreen(e, nm));
    const img = entry.image;
    const pw = img.width / n;
    const ph = img.height / n;
    const dpr = map.dpr;
    for (let j = 0; j < n; j += 1) {
      for (let i = 0; i < n; i += 1) {
        const p00 = screen[j * (n + 1) + i];
        const p10 = screen[j * (n + 1) + i + 1];
        const p01 = screen[(j + 1) * (n + 1) + i];
        const p11 = screen[(j + 1) * (n + 1) + i + 1];
        const xs = [p00[0], p10[0], p01[0], p11[0]];
        const ys = [p00[1], p10[1], p01[1], p11[1]];
        if (Math.max(...xs) < 0 || Math.min(...xs) > map.width) continue;
        if (Math.max(...ys) < 0 || Math.min(...ys) > map.height) continue;
        // The piece's own parallelogram, grown by half a pixel each way so neighbours overlap
        // (no hairline of the background between them).
        const u = [p10[0] - p00[0], p10[1] - p00[1]];
        const v = [p01[0] - p00[0], p01[1] - p00[1]];
        const gu = 1 + 1 / Math.max(1, Math.hypot(...u));
        const gv = 1 + 1 / Math.max(1, Math.hypot(...v));
        const ox = (p10[0] + p01[0]) / 2 - (gu * u[0] + gv * v[0]) / 2;
        const oy = (p10[1] + p01[1]) / 2 - (gu * u[1] + gv * v[1]) / 2;
        ctx.setTransform(
          (dpr * gu * u[0]) / pw,
          (dpr * gu * u[1]) / pw,
          (dpr * gv * v[0]) / ph,
          (dpr * gv * v[1]) / ph,
          dpr * ox,
          dpr * oy,
        );
        ctx.drawImage(img, i * pw, j * ph, pw, ph, 0, 0, pw, ph);
      }
    }
    const corner = (i, j) => screen[j * (n + 1) + i];
    this.drawn.push({
      z: entry.z,
      x: entry.x,
      y: entry.y,
      corners: [corner(0, 0), corner(n, 0), corner(n, n), corner(0, n)],
    });
  }
}

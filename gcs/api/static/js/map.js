// The map: a canvas in the scenario's local metres (east, north), north up. Drag pans, the
// wheel zooms about the cursor. Layers: the base (the terrain image over the area, or the
// service's map tiles when it has a tile source), threats, loiter buffers, each vehicle's
// planned route, loiter circles, goal, flown trail and live position.
// Drawing tools: a no-fly polygon (click the corners, double-click to close) and a radar disc
// (press at the centre, drag out the radius); the shape is handed to `onShape` for sending.

import { STALE_FIX_S } from "./format.js";

const CLICK_SLOP_PX = 4;
const MIN_RADIUS_PX = 4;

export class MapView {
  constructor(canvas, { onShape, onCursor, onTool } = {}) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.onShape = onShape || (() => {});
    this.onCursor = onCursor || (() => {});
    this.onTool = onTool || (() => {});
    this.doc = null;
    this.terrain = null;
    this.tiles = null; // a TileLayer when the service has a tile source
    this.base = "hillshade"; // or "tiles"
    this.vehicles = [];
    this.conflicts = []; // the encounters in progress: [{a, b, kind, said_m}]
    this.trails = new Map();
    this.colours = new Map();
    this.tool = "pan";
    this.view = { cx: 0, cy: 0, scale: 0.005 };
    this.fitted = false;
    this.width = 1;
    this.height = 1;
    this.dirty = true;
    this.vertices = []; // the no-fly polygon being drawn (world metres)
    this.disc = null; // the radar disc being drawn: {center, radius_m}
    this.pending = null; // a finished shape awaiting the operator's word
    this.hover = null;
    this._drag = null;
    this._bind();
    new ResizeObserver(() => this.resize()).observe(canvas);
    this.resize();
  }

  // -- data ------------------------------------------------------------------------------------

  setDoc(doc) {
    this.doc = doc;
    if (this.tiles) this.tiles.setOrigin(doc.origin);
    doc.vehicles.forEach((v, i) => {
      if (!this.colours.has(v.id)) this.colours.set(v.id, this._colourOf(i));
    });
    if (!this.fitted) this.fit();
    this.dirty = true;
  }

  setColourFunction(fn) {
    this._colourOf = fn;
  }

  setTerrain(image) {
    this.terrain = image;
    this.dirty = true;
  }

  setTiles(layer) {
    this.tiles = layer;
    if (layer && this.doc) layer.setOrigin(this.doc.origin);
    if (!layer) this.base = "hillshade";
    this.dirty = true;
  }

  /** The base layer: "hillshade" (the scenario's terrain) or "tiles" (the tile source). */
  setBase(base) {
    this.base = base === "tiles" && this.tiles ? "tiles" : "hillshade";
    this.dirty = true;
  }

  /** The pairs in conflict now (conflicts.js): a line between each pair as drawn. */
  setConflicts(conflicts) {
    this.conflicts = conflicts;
    this.dirty = true;
  }

  /** Telemetry vehicles (positions, headings); extends each flown trail. */
  setVehicles(vehicles) {
    this.vehicles = vehicles;
    for (const v of vehicles) {
      if (v.east_m === null || v.east_m === undefined) continue;
      let trail = this.trails.get(v.id);
      if (!trail) {
        trail = [];
        this.trails.set(v.id, trail);
      }
      const last = trail[trail.length - 1];
      if (!last || last[0] !== v.east_m || last[1] !== v.north_m) trail.push([v.east_m, v.north_m]);
    }
    this.dirty = true;
  }

  clearTrails() {
    this.trails.clear();
    this.dirty = true;
  }

  // -- the transform ---------------------------------------------------------------------------

  resize() {
    const r = this.canvas.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    this.width = Math.max(1, r.width);
    this.height = Math.max(1, r.height);
    this.canvas.width = Math.round(this.width * dpr);
    this.canvas.height = Math.round(this.height * dpr);
    this.dpr = dpr;
    if (this.doc && !this.fitted) this.fit();
    this.dirty = true;
  }

  fit() {
    if (!this.doc) return;
    const a = this.doc.area;
    this.view.scale = 0.96 * Math.min(this.width / a.width_m, this.height / a.height_m);
    this.view.cx = a.min_east_m + a.width_m / 2;
    this.view.cy = a.min_north_m + a.height_m / 2;
    this.fitted = true;
    this.dirty = true;
  }

  /** Canvas CSS pixels of a world point. */
  toScreen(e, n) {
    const v = this.view;
    return [(e - v.cx) * v.scale + this.width / 2, this.height / 2 - (n - v.cy) * v.scale];
  }

  toWorld(x, y) {
    const v = this.view;
    return [(x - this.width / 2) / v.scale + v.cx, v.cy - (y - this.height / 2) / v.scale];
  }

  /** Page (client) coordinates of a world point: where a mouse click lands on it. */
  toClient(e, n) {
    const r = this.canvas.getBoundingClientRect();
    const [x, y] = this.toScreen(e, n);
    return { x: r.left + x, y: r.top + y };
  }

  zoomAt(x, y, factor) {
    const [e, n] = this.toWorld(x, y);
    this.view.scale = Math.min(2, Math.max(1e-4, this.view.scale * factor));
    const [e2, n2] = this.toWorld(x, y);
    this.view.cx += e - e2;
    this.view.cy += n - n2;
    this.dirty = true;
  }

  // -- tools -------------------------------------------------------------------------------------

  setTool(tool) {
    this.tool = tool;
    this.vertices = [];
    this.disc = null;
    this.canvas.className = `tool-${tool}`;
    this.dirty = true;
    this.onTool(tool);
  }

  discardPending() {
    this.pending = null;
    this.dirty = true;
  }

  _finish(shape) {
    this.pending = shape;
    this.vertices = [];
    this.disc = null;
    this.dirty = true;
    this.onShape(shape);
  }

  _local(ev) {
    const r = this.canvas.getBoundingClientRect();
    return [ev.clientX - r.left, ev.clientY - r.top];
  }

  _bind() {
    const c = this.canvas;
    c.addEventListener("pointerdown", (ev) => {
      if (ev.button !== 0) return;
      const [x, y] = this._local(ev);
      c.setPointerCapture(ev.pointerId);
      if (this.tool === "radar") {
        this.disc = { center: this.toWorld(x, y), radius_m: 0, start: [x, y] };
        this._drag = { kind: "disc" };
      } else {
        this._drag = { kind: "pan", x, y, moved: 0, view: { ...this.view } };
        c.classList.add("dragging");
      }
    });
    c.addEventListener("pointermove", (ev) => {
      const [x, y] = this._local(ev);
      this.hover = [x, y];
      const [e, n] = this.toWorld(x, y);
      this.onCursor(e, n);
      const d = this._drag;
      if (d && d.kind === "pan") {
        d.moved = Math.max(d.moved, Math.hypot(x - d.x, y - d.y));
        this.view.cx = d.view.cx - (x - d.x) / this.view.scale;
        this.view.cy = d.view.cy + (y - d.y) / this.view.scale;
        this.dirty = true;
      } else if (d && d.kind === "disc") {
        const [ce, cn] = this.disc.center;
        this.disc.radius_m = Math.hypot(e - ce, n - cn);
        this.dirty = true;
      } else if (this.tool === "no_fly" && this.vertices.length) {
        this.dirty = true;
      }
    });
    c.addEventListener("pointerup", (ev) => {
      const d = this._drag;
      this._drag = null;
      c.classList.remove("dragging");
      if (!d) return;
      const [x, y] = this._local(ev);
      if (d.kind === "disc") {
        const px = Math.hypot(x - this.disc.start[0], y - this.disc.start[1]);
        if (px >= MIN_RADIUS_PX) {
          const { center, radius_m } = this.disc;
          this._finish({ kind: "radar", center, radius_m });
        } else {
          this.disc = null;
          this.dirty = true;
        }
      } else if (d.kind === "pan" && d.moved <= CLICK_SLOP_PX && this.tool === "no_fly") {
        this.vertices.push(this.toWorld(x, y));
        this.dirty = true;
      }
    });
    c.addEventListener("dblclick", (ev) => {
      if (this.tool !== "no_fly") return;
      ev.preventDefault();
      // The double-click's second click added its point again: drop the repeat.
      const vs = this.vertices;
      if (vs.length >= 2) {
        const [ax, ay] = this.toScreen(...vs[vs.length - 1]);
        const [bx, by] = this.toScreen(...vs[vs.length - 2]);
        if (Math.hypot(ax - bx, ay - by) <= 2 * CLICK_SLOP_PX) vs.pop();
      }
      if (vs.length >= 3) this._finish({ kind: "no_fly", polygon: vs.slice() });
    });
    c.addEventListener(
      "wheel",
      (ev) => {
        ev.preventDefault();
        const [x, y] = this._local(ev);
        this.zoomAt(x, y, Math.exp(-ev.deltaY * 0.0015));
      },
      { passive: false },
    );
    c.addEventListener("keydown", (ev) => {
      if (ev.key === "Escape") {
        this.vertices = [];
        this.disc = null;
        this.dirty = true;
      }
    });
    c.addEventListener("pointerleave", () => {
      this.hover = null;
      if (this.vertices.length) this.dirty = true;
    });
  }

  // -- drawing -----------------------------------------------------------------------------------

  /** Draw if anything changed; true if it drew. */
  draw() {
    if (!this.dirty) return false;
    this.dirty = false;
    const ctx = this.ctx;
    ctx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
    ctx.fillStyle = "#e9ecef";
    ctx.fillRect(0, 0, this.width, this.height);
    if (!this.doc) return true;
    this._area();
    for (const b of this.doc.buffers) this._buffer(b);
    for (const t of this.doc.threats) this._threat(t);
    for (const v of this.doc.vehicles) this._plan(v);
    for (const [id, trail] of this.trails) this._trail(id, trail);
    for (const line of this._conflictLines()) this._conflict(line);
    for (const v of this.vehicles) this._vehicle(v);
    this._drawing();
    this._furniture();
    return true;
  }

  _path(points, close = false) {
    const ctx = this.ctx;
    ctx.beginPath();
    points.forEach(([e, n], i) => {
      const [x, y] = this.toScreen(e, n);
      if (i === 0) ctx.moveTo(x, y);
      else ctx.lineTo(x, y);
    });
    if (close) ctx.closePath();
  }

  _circle(center, radius_m) {
    const [x, y] = this.toScreen(center[0], center[1]);
    this.ctx.beginPath();
    this.ctx.arc(x, y, Math.max(0.5, radius_m * this.view.scale), 0, 2 * Math.PI);
  }

  _label(text, e, n, colour = "#1d232b", dx = 0, dy = 0) {
    const ctx = this.ctx;
    const [x, y] = this.toScreen(e, n);
    ctx.font = "12px system-ui, sans-serif";
    ctx.lineWidth = 3;
    ctx.strokeStyle = "rgba(255,255,255,0.85)";
    ctx.strokeText(text, x + dx, y + dy);
    ctx.fillStyle = colour;
    ctx.fillText(text, x + dx, y + dy);
  }

  _area() {
    const a = this.doc.area;
    const ctx = this.ctx;
    const [x0, y0] = this.toScreen(a.min_east_m, a.min_north_m + a.height_m);
    const w = a.width_m * this.view.scale;
    const h = a.height_m * this.view.scale;
    if (this.base === "tiles") {
      this.tiles.draw(ctx, this);
    } else if (this.terrain) {
      ctx.imageSmoothingEnabled = true;
      ctx.drawImage(this.terrain, x0, y0, w, h);
    } else {
      ctx.fillStyle = "#f6f7f4";
      ctx.fillRect(x0, y0, w, h);
    }
    ctx.lineWidth = 1;
    ctx.strokeStyle = "#8a939c";
    ctx.setLineDash([]);
    ctx.strokeRect(x0, y0, w, h);
  }

  _buffer(b) {
    const ctx = this.ctx;
    this._circle(b.center, b.radius_m);
    ctx.setLineDash([4, 4]);
    ctx.lineWidth = 1.5;
    ctx.strokeStyle = "#1e7b34";
    ctx.stroke();
    ctx.setLineDash([]);
    this._label(b.id, b.center[0], b.center[1], "#1e5c2b", -8, 4);
  }

  _threat(t) {
    const ctx = this.ctx;
    const inForce = t.in_force;
    if (t.kind === "radar") this._circle(t.center, t.radius_m);
    else this._path(t.polygon, true);
    const red = t.forbidden;
    if (inForce) {
      ctx.fillStyle = red ? "rgba(200, 35, 30, 0.30)" : "rgba(230, 140, 0, 0.13)";
      ctx.fill();
      ctx.setLineDash([]);
    } else {
      ctx.fillStyle = red ? "rgba(200, 35, 30, 0.06)" : "rgba(230, 140, 0, 0.04)";
      ctx.fill();
      ctx.setLineDash([7, 5]);
    }
    ctx.lineWidth = inForce ? 1.6 : 1.8;
    ctx.strokeStyle = red ? "#b3261e" : "#c77700";
    ctx.stroke();
    ctx.setLineDash([]);
    const [e, n] = t.kind === "radar" ? t.center : centroid(t.polygon);
    let text = t.id;
    if (!inForce) {
      text +=
        t.appears_at_s === null || t.appears_at_s === undefined
          ? " (pop-up, not yet timed)"
          : ` appears at ${t.appears_at_s.toFixed(0)} s`;
    }
    this._label(text, e, n, red ? "#8c1d17" : "#7a4a00", -10, 4);
  }

  _plan(v) {
    const ctx = this.ctx;
    const colour = this.colours.get(v.id) || "#333";
    ctx.strokeStyle = colour;
    ctx.lineWidth = 1.6;
    ctx.globalAlpha = 0.9;
    if (v.route_en_m.length > 1) {
      this._path(v.route_en_m);
      ctx.stroke();
    }
    for (const lo of v.loiters) {
      this._circle(lo.centre, lo.radius_m);
      ctx.setLineDash([3, 3]);
      ctx.stroke();
      ctx.setLineDash([]);
      this._label(`${lo.turns}×`, lo.centre[0], lo.centre[1], colour, 8, -6);
    }
    ctx.globalAlpha = 1;
    // the start: a square; the goal: a ringed cross
    const [sx, sy] = this.toScreen(v.start[0], v.start[1]);
    ctx.fillStyle = colour;
    ctx.fillRect(sx - 3.5, sy - 3.5, 7, 7);
    const [gx, gy] = this.toScreen(v.goal[0], v.goal[1]);
    ctx.beginPath();
    ctx.arc(gx, gy, 5, 0, 2 * Math.PI);
    ctx.moveTo(gx - 8, gy);
    ctx.lineTo(gx + 8, gy);
    ctx.moveTo(gx, gy - 8);
    ctx.lineTo(gx, gy + 8);
    ctx.lineWidth = 1.5;
    ctx.stroke();
  }

  _trail(id, trail) {
    if (trail.length < 2) return;
    const ctx = this.ctx;
    ctx.strokeStyle = this.colours.get(id) || "#333";
    ctx.globalAlpha = 0.38;
    ctx.lineWidth = 5;
    ctx.lineJoin = "round";
    ctx.lineCap = "round";
    this._path(trail);
    ctx.stroke();
    ctx.globalAlpha = 1;
    ctx.lineCap = "butt";
  }

  _vehicle(v) {
    if (v.east_m === null || v.east_m === undefined) return;
    const ctx = this.ctx;
    const colour = this.colours.get(v.id) || "#333";
    const [x, y] = this.toScreen(v.east_m, v.north_m);
    const h = (((v.heading_deg || 0) % 360) * Math.PI) / 180;
    const fx = Math.sin(h);
    const fy = -Math.cos(h);
    const size = 11;
    ctx.beginPath();
    ctx.moveTo(x + fx * size, y + fy * size);
    ctx.lineTo(x - fx * size * 0.6 - fy * size * 0.55, y - fy * size * 0.6 + fx * size * 0.55);
    ctx.lineTo(x - fx * size * 0.25, y - fy * size * 0.25);
    ctx.lineTo(x - fx * size * 0.6 + fy * size * 0.55, y - fy * size * 0.6 - fx * size * 0.55);
    ctx.closePath();
    // A silent link or an old fix: drawn hollow, and the label says how old the fix is.
    const age = v.last_fix_age_s;
    const old = v.link_silent || (age !== null && age !== undefined && age > STALE_FIX_S);
    ctx.fillStyle = old ? "#ffffff" : colour;
    ctx.fill();
    ctx.lineWidth = 1.5;
    ctx.strokeStyle = old ? colour : "#ffffff";
    if (old) ctx.setLineDash([2, 2]);
    ctx.stroke();
    ctx.setLineDash([]);
    const tag = old ? `${v.id} (fix ${Math.round(age || 0)} s old)` : v.id;
    this._label(tag, v.east_m, v.north_m, colour, 10, -8);
  }

  /** Each conflict whose two vehicles are on the map: {a, b, kind, said_m, from, to}. */
  _conflictLines() {
    const at = new Map();
    for (const v of this.vehicles) {
      if (v.east_m !== null && v.east_m !== undefined) at.set(v.id, [v.east_m, v.north_m]);
    }
    return this.conflicts
      .filter((c) => at.has(c.a) && at.has(c.b))
      .map((c) => ({ a: c.a, b: c.b, kind: c.kind, said_m: c.said_m, from: at.get(c.a), to: at.get(c.b) }));
  }

  _conflict(line) {
    const ctx = this.ctx;
    const red = line.kind === "loss" || line.kind === "unresolved";
    const colour = red ? "#c0392b" : line.kind === "predicted" ? "#d68910" : "#1f6fb2";
    this._path([line.from, line.to]);
    ctx.lineWidth = 2.5;
    ctx.strokeStyle = colour;
    ctx.setLineDash(red ? [] : [6, 4]);
    ctx.stroke();
    ctx.setLineDash([]);
    const e = (line.from[0] + line.to[0]) / 2;
    const n = (line.from[1] + line.to[1]) / 2;
    const d = Math.hypot(line.to[0] - line.from[0], line.to[1] - line.from[1]);
    // What the event said (the closest it expects, or the distance it measured), and now.
    const said = line.said_m === null || line.said_m === undefined ? "" : ` ${Math.round(line.said_m)} m,`;
    this._label(`${line.kind}${said} now ${Math.round(d)} m`, e, n, colour, 6, -6);
  }

  _drawing() {
    const ctx = this.ctx;
    const shapes = [];
    if (this.pending) shapes.push(this.pending);
    if (this.disc) shapes.push({ kind: "radar", ...this.disc });
    if (this.vertices.length) {
      const pts = this.vertices.slice();
      if (this.hover) pts.push(this.toWorld(...this.hover));
      shapes.push({ kind: "no_fly", polygon: pts, open: true });
    }
    for (const s of shapes) {
      if (s.kind === "radar") this._circle(s.center, s.radius_m);
      else this._path(s.polygon, !s.open);
      ctx.fillStyle = "rgba(30, 30, 30, 0.12)";
      if (!s.open) ctx.fill();
      ctx.setLineDash([6, 4]);
      ctx.lineWidth = 2;
      ctx.strokeStyle = "#111";
      ctx.stroke();
      ctx.setLineDash([]);
      const corners = s.kind === "radar" ? [s.center] : s.polygon;
      ctx.fillStyle = "#111";
      for (const [e, n] of corners) {
        const [x, y] = this.toScreen(e, n);
        ctx.fillRect(x - 2.5, y - 2.5, 5, 5);
      }
    }
  }

  _furniture() {
    const ctx = this.ctx;
    // north arrow
    const nx = this.width - 24;
    ctx.fillStyle = "#1d232b";
    ctx.beginPath();
    ctx.moveTo(nx, 12);
    ctx.lineTo(nx - 7, 32);
    ctx.lineTo(nx + 7, 32);
    ctx.closePath();
    ctx.fill();
    ctx.font = "bold 12px system-ui, sans-serif";
    ctx.fillText("N", nx - 4, 46);
    // scale bar: a round length about 120 px long
    const target = 120 / this.view.scale;
    const p = 10 ** Math.floor(Math.log10(target));
    const len = [1, 2, 5, 10].map((k) => k * p).filter((l) => l <= target).pop() || p;
    const px = len * this.view.scale;
    const y = this.height - 16;
    ctx.fillStyle = "rgba(255,255,255,0.8)";
    ctx.fillRect(8, y - 16, px + 16, 24);
    ctx.fillStyle = "#1d232b";
    ctx.fillRect(16, y, px, 3);
    ctx.font = "12px system-ui, sans-serif";
    ctx.fillText(len >= 1000 ? `${len / 1000} km` : `${len} m`, 16, y - 4);
    if (this.base === "tiles") this._tileWords();
  }

  /** The tile source's attribution (its HTML as text) and why no tiles show, bottom right. */
  _tileWords() {
    const ctx = this.ctx;
    const s = this.tiles.source;
    const words = [this.tiles.note, (s.attribution || s.name).replace(/<[^>]*>/g, "")];
    ctx.font = "11px system-ui, sans-serif";
    ctx.textAlign = "right";
    words.filter(Boolean).forEach((text, i) => {
      const y = this.height - 8 - 15 * i;
      const w = ctx.measureText(text).width;
      ctx.fillStyle = "rgba(255,255,255,0.8)";
      ctx.fillRect(this.width - w - 12, y - 11, w + 8, 15);
      ctx.fillStyle = "#1d232b";
      ctx.fillText(text, this.width - 8, y);
    });
    ctx.textAlign = "start";
  }

  /** What is drawn, for the tests: the routes (world metres), the trails, the transform, the
   *  base layer, the lines between pairs in conflict. */
  geometry() {
    const routes = {};
    if (this.doc) for (const v of this.doc.vehicles) routes[v.id] = v.route_en_m;
    const trails = {};
    for (const [id, t] of this.trails) trails[id] = t.slice();
    return {
      routes,
      trails,
      view: { ...this.view, width: this.width, height: this.height },
      pending: this.pending,
      base: this.base,
      conflicts: this._conflictLines(),
    };
  }
}

function centroid(points) {
  let e = 0;
  let n = 0;
  for (const [pe, pn] of points) {
    e += pe;
    n += pn;
  }
  return [e / points.length, n / points.length];
}

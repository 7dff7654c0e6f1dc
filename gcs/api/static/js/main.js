// The operator console: sign in, open (or create) a flight, watch it on the map and the
// time-on-target panel, steer it. Only the public REST API and the stream are used.
// `window.tcgcs` exposes what the page draws and knows (for the operator's console and tests).

import { Api, ApiError, describeError, savedToken, saveToken } from "./api.js";
import { MissionClock } from "./clock.js";
import { Conflicts } from "./conflicts.js";
import { num, vehicleColour } from "./format.js";
import { MapView } from "./map.js";
import { Countdown, Timeline, VehicleTable } from "./panel.js";
import { FlightStream } from "./stream.js";
import { TileLayer } from "./tiles.js";

const $ = (id) => document.getElementById(id);
const RUNNING = new Set(["running"]);
const OVER = new Set(["completed", "failed", "aborted"]);
const MAP_KINDS = new Set(["replan", "upload", "popup"]);
const SNAPSHOT_KINDS = new Set(["flight", "abort", "arrival", "upload", "start", "launch", "arrived"]);
const PERF_KEEP = 20000;

// -- state ------------------------------------------------------------------------------------

const state = {
  flightId: null,
  flightState: null,
  snapshot: null,
  mapDoc: null,
  telemetry: null,
  vehicles: new Map(), // id -> the latest view (snapshot merged with telemetry)
  order: [], // vehicle ids in the scenario's order
  events: [],
  teamTimeS: null,
  teamTimeVersion: null,
  startUtcS: null,
  pause: null, // the snapshot's: pausable, paused, the pauses to come
  scenarioId: null,
  terrainUrl: null,
  ended: false,
  mapLoads: 0,
};
const clock = new MissionClock();
const perf = {
  frames: [], // requestAnimationFrame deltas, ms
  lags: [], // telemetry receipt to the end of the frame that drew it, ms
  receipts: [], // when each telemetry batch was received (performance.now(), ms)
  pending: [], // receipt times not yet drawn
  lastFrame: null,
  reset() {
    this.frames.length = 0;
    this.lags.length = 0;
    this.receipts.length = 0;
  },
};
let stream = null;
let teamTimeEdited = false;

const api = new Api((err) => signedOut(`The service refused the token: ${err.message}`));
const mapView = new MapView($("map"), {
  onShape: (shape) => shapeDrawn(shape),
  onCursor: (e, n) => {
    $("map-cursor").textContent = `E ${num(e / 1000, 2)} km  N ${num(n / 1000, 2)} km`;
  },
  onTool: (tool) => toolChanged(tool),
});
mapView.setColourFunction(vehicleColour);
const table = new VehicleTable($("vehicles").querySelector("tbody"), (id) => abortVehicle(id));
const countdown = new Countdown($("countdown"), $("team-time-line"));
const timeline = new Timeline($("events"), $("event-count"), $("timeline-filter"));
const conflicts = new Conflicts($("conflicts"));

// -- small helpers ----------------------------------------------------------------------------

function say(el, text) {
  $(el).textContent = text || "";
}

/** A confirmation: the action, in words; resolves true when the operator confirms. */
function confirmAction(text, okLabel = "Confirm") {
  const dialog = $("confirm");
  say("confirm-text", text);
  $("confirm-ok").textContent = okLabel;
  return new Promise((resolve) => {
    dialog.addEventListener("close", () => resolve(dialog.returnValue === "ok"), { once: true });
    dialog.returnValue = "";
    dialog.showModal();
  });
}

/** Run an operator's action: errors are shown in words at `errorEl`, the button is held. */
async function act(errorEl, button, fn) {
  say(errorEl, "");
  if (button) button.disabled = true;
  try {
    return await fn();
  } catch (err) {
    say(errorEl, describeError(err));
    return undefined;
  } finally {
    if (button) button.disabled = false;
    updateButtons();
  }
}

/** The open flight's route `rest`; with no flight open (signed out while confirming) an
 * error in words, so that nothing is sent for a flight the operator did not see. */
function flightPath(rest) {
  if (!state.flightId) throw new Error("no flight is open");
  return `/v1/flights/${encodeURIComponent(state.flightId)}/${rest}`;
}

function debounce(fn, ms) {
  let timer = null;
  return () => {
    clearTimeout(timer);
    timer = setTimeout(fn, ms);
  };
}

// -- sign in ----------------------------------------------------------------------------------

function showLogin(message) {
  $("login").hidden = false;
  $("console").hidden = true;
  $("logout").hidden = true;
  say("login-error", message || "");
  $("token").focus();
}

async function signIn(token) {
  saveToken(token);
  try {
    await api.get("/v1/flights", { what: "sign in" });
  } catch (err) {
    if (!(err instanceof ApiError) || err.status !== 401) showLogin(describeError(err));
    return;
  }
  $("login").hidden = true;
  $("console").hidden = false;
  $("logout").hidden = false;
  mapView.resize();
  await loadTileSource();
  await refreshFlights();
  const wanted = new URLSearchParams(location.search).get("flight");
  if (wanted) await openFlight(wanted);
}

function signedOut(message) {
  saveToken("");
  closeFlight();
  showLogin(message);
}

$("login-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  signIn($("token").value.trim());
});
$("logout").addEventListener("click", () => signedOut(""));

// -- flights ----------------------------------------------------------------------------------

async function refreshFlights() {
  let flights;
  try {
    flights = await api.get("/v1/flights", { what: "flights" });
  } catch (err) {
    say("flight-error", describeError(err));
    return;
  }
  const list = $("flight-list");
  list.replaceChildren();
  for (const f of flights) {
    const o = document.createElement("option");
    o.value = f.id;
    o.textContent = `${f.id.slice(0, 12)}  ${f.state}`;
    list.append(o);
  }
  if (!flights.length) {
    const o = document.createElement("option");
    o.value = "";
    o.textContent = "no flights yet";
    list.append(o);
  }
  if (state.flightId) list.value = state.flightId;
}

$("flight-refresh").addEventListener("click", () => refreshFlights());
$("flight-open").addEventListener("click", () => {
  const id = $("flight-list").value;
  if (id) openFlight(id);
});

function closeFlight() {
  if (stream) stream.close();
  stream = null;
  Object.assign(state, {
    flightId: null,
    flightState: null,
    snapshot: null,
    mapDoc: null,
    telemetry: null,
    events: [],
    teamTimeS: null,
    teamTimeVersion: null,
    startUtcS: null,
    ended: false,
  });
  state.vehicles.clear();
  state.order = [];
  clock.reset();
  table.clear();
  timeline.clear();
  conflicts.clear();
  mapView.setConflicts([]);
  mapView.clearTrails();
  mapView.vehicles = [];
  mapView.colours.clear();
  teamTimeEdited = false;
}

async function openFlight(id) {
  closeFlight();
  state.flightId = id;
  say("flight-title", `flight ${id}`);
  const url = new URL(location.href);
  url.searchParams.set("flight", id);
  history.replaceState(null, "", url);
  const ok = await act("flight-error", null, async () => {
    applySnapshot(await api.get(`/v1/flights/${id}`, { what: `flight ${id}` }));
    await loadMap();
    return true;
  });
  if (!ok || state.flightId !== id) return;
  $("flight-list").value = id;
  stream = new FlightStream(id, savedToken(), { message: onMessage, status: onStreamStatus });
  stream.start();
}

function mergeVehicles(list) {
  for (const v of list) {
    if (!state.vehicles.has(v.id)) {
      state.order.push(v.id);
      if (!mapView.colours.has(v.id)) mapView.colours.set(v.id, vehicleColour(state.order.length - 1));
    }
    state.vehicles.set(v.id, { ...state.vehicles.get(v.id), ...v });
  }
}

function applySnapshot(snap) {
  if (snap.flight_id && snap.flight_id !== state.flightId) return;
  state.snapshot = snap;
  state.flightState = snap.state;
  state.teamTimeS = snap.team_time_s;
  state.teamTimeVersion = snap.team_time_version;
  state.startUtcS = snap.start_utc_s;
  state.pause = snap.pause || null;
  mergeVehicles(snap.vehicles);
  mapView.setVehicles(snap.vehicles);
  if (!clock.samples.length && snap.start_utc_s !== null) clock.observe(snap.t_s, performance.now());
  const ups = Object.entries(snap.uploads || {});
  if (ups.length) {
    const words = ups.map(([v, u]) => `${v} ${u.state}${u.error ? ` (${u.error})` : ""}`);
    say("flight-note", `uploads: ${words.join(", ")}`);
  }
  renderPanel();
}

const refreshSnapshot = debounce(async () => {
  const id = state.flightId;
  if (!id) return;
  try {
    const snap = await api.get(`/v1/flights/${id}`, { what: "snapshot" });
    if (id === state.flightId) applySnapshot(snap);
  } catch (err) {
    say("flight-error", describeError(err));
  }
}, 120);

async function loadMap() {
  const id = state.flightId;
  const doc = await api.get(`/v1/flights/${id}/map`, { what: "map" });
  if (id !== state.flightId) return;
  state.mapDoc = doc;
  state.mapLoads += 1;
  mapView.setDoc(doc);
  if (doc.scenario_id !== state.scenarioId) {
    state.scenarioId = doc.scenario_id;
    const blob = await api.get(`/v1/scenarios/${doc.scenario_id}/terrain.png`, { what: "terrain" });
    if (state.terrainUrl) URL.revokeObjectURL(state.terrainUrl);
    state.terrainUrl = URL.createObjectURL(blob);
    const img = new Image();
    img.onload = () => mapView.setTerrain(img);
    img.src = state.terrainUrl;
  }
}

const refreshMap = debounce(() => {
  loadMap().catch((err) => say("flight-error", describeError(err)));
}, 150);

// -- the base layer: the hillshade, or the service's tiles ----------------------------------------

/** The service's tile source (404: none is configured, the hillshade only). */
async function loadTileSource() {
  let source = null;
  try {
    source = await api.get("/v1/tiles", { what: "tile source" });
  } catch (err) {
    if (!(err instanceof ApiError) || err.status !== 404) say("flight-error", describeError(err));
  }
  const button = document.querySelector('#map-base [data-base="tiles"]');
  button.disabled = !source;
  if (!source) {
    mapView.setTiles(null);
    setBase("hillshade");
    return;
  }
  button.title = `${source.name}: zooms ${source.minzoom} to ${source.maxzoom}`;
  const url = (z, x, y) => source.tiles[0].replace("{z}", z).replace("{x}", x).replace("{y}", y);
  const fetchTile = (z, x, y) => api.get(url(z, x, y), { what: `tile ${z}/${x}/${y}` });
  mapView.setTiles(new TileLayer(source, fetchTile, () => (mapView.dirty = true)));
  setBase("tiles");
}

function setBase(base) {
  mapView.setBase(base);
  for (const b of document.querySelectorAll("#map-base [data-base]")) {
    b.classList.toggle("active", b.dataset.base === mapView.base);
  }
}

for (const b of document.querySelectorAll("#map-base [data-base]")) {
  b.addEventListener("click", () => setBase(b.dataset.base));
}

// -- the stream -------------------------------------------------------------------------------

function onStreamStatus(kind, text) {
  const el = $("stream-status");
  el.className = kind;
  el.textContent = text;
  if (kind === "back") {
    refreshSnapshot();
    refreshMap();
  } else if (kind === "refused") {
    say("flight-error", text);
  }
}

function onMessage(type, data, received) {
  if (type === "snapshot") {
    applySnapshot(data);
  } else if (type === "telemetry") {
    state.telemetry = data;
    // A new state (planned, ready, flying) comes with new uploads and launches: the snapshot
    // says them, so the notes do not lag behind the state they explain.
    if (state.flightState !== data.state) refreshSnapshot();
    state.flightState = data.state;
    state.teamTimeS = data.team_time_s;
    if (data.team_time_version !== undefined) state.teamTimeVersion = data.team_time_version;
    if (data.pause && JSON.stringify(data.pause) !== JSON.stringify(state.pause)) {
      state.pause = data.pause;
      updateButtons();
    }
    clock.observe(data.t_s, received);
    mergeVehicles(data.vehicles);
    mapView.setVehicles(data.vehicles);
    perf.pending.push(received);
    perf.receipts.push(received);
    if (perf.receipts.length > PERF_KEEP) perf.receipts.shift();
    renderPanel();
  } else if (type === "event") {
    state.events.push(data);
    timeline.add(data);
    conflicts.add(data);
    if (MAP_KINDS.has(data.kind)) refreshMap();
    if (SNAPSHOT_KINDS.has(data.kind)) refreshSnapshot();
    if (data.kind === "flight") refreshFlights();
  } else if (type === "end") {
    state.ended = true;
    clock.frozen = true;
    say("flight-note", `flight ${data.state}: the record and the report are ready`);
    refreshSnapshot();
    refreshMap();
  } else if (type === "behind") {
    say("flight-note", `the stream fell behind after event ${data.after_seq}; resuming`);
  }
}

// -- the panel --------------------------------------------------------------------------------

function vehicleList() {
  return state.order.map((id) => state.vehicles.get(id));
}

function renderPanel() {
  const now = clock.now(performance.now());
  const tS = now ? now.t_s : null;
  table.update(vehicleList(), mapView.colours, tS, RUNNING.has(state.flightState));
  conflicts.render(tS);
  mapView.setConflicts(conflicts.active(tS));
  say("flight-state", state.flightState || "");
  const input = $("team-time");
  if (!teamTimeEdited && document.activeElement !== input && state.teamTimeS !== null) {
    input.value = state.teamTimeS.toFixed(1);
  }
  updateButtons();
}

function updateButtons() {
  const s = state.flightState;
  const open = Boolean(state.flightId);
  $("upload").disabled = !open || s !== "planned";
  $("launch").disabled = !open || s !== "ready";
  $("abort-all").disabled = !open || !RUNNING.has(s);
  const pause = state.pause;
  $("pause").disabled = !open || !s || OVER.has(s) || !(pause && pause.pausable);
  $("pause").textContent = pause && pause.paused ? "Resume" : "Pause";
  $("team-time-move").disabled = !open || OVER.has(s) || !s;
}

function renderClock() {
  const now = clock.now(performance.now());
  const vs = vehicleList();
  countdown.update({
    teamTimeS: state.teamTimeS,
    now,
    flightState: state.flightState || "–",
    startUtcS: state.startUtcS,
    arrivedAll: vs.length > 0 && vs.every((v) => v.state === "arrived" || v.state === "aborted"),
  });
  say(
    "mission-clock",
    now ? `t = ${num(now.t_s, 1)} s${now.rate ? ` (x${num(now.rate, 0)})` : ""}${now.stale ? " stale" : ""}` : "",
  );
}

// -- the frame loop ---------------------------------------------------------------------------

let lastClockText = 0;
function frame(ts) {
  if (perf.lastFrame !== null) {
    perf.frames.push(ts - perf.lastFrame);
    if (perf.frames.length > PERF_KEEP) perf.frames.shift();
  }
  perf.lastFrame = ts;
  mapView.draw();
  if (ts - lastClockText >= 100) {
    lastClockText = ts;
    renderClock();
  }
  if (perf.pending.length) {
    const done = performance.now();
    for (const r of perf.pending) perf.lags.push(done - r);
    perf.pending.length = 0;
    if (perf.lags.length > PERF_KEEP) perf.lags.splice(0, perf.lags.length - PERF_KEEP);
  }
  requestAnimationFrame(frame);
}
requestAnimationFrame(frame);

// -- operator actions -------------------------------------------------------------------------

function readNumber(id) {
  const raw = $(id).value.trim();
  return raw === "" ? null : Number(raw);
}

$("create-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const file = $("scenario-file").files[0];
  if (!file) return;
  const speedup = readNumber("rh-speedup");
  const wind = readNumber("rh-wind");
  const rehearsal = {
    speedup,
    loss: readNumber("rh-loss") || 0,
    seed: readNumber("rh-seed") || 0,
  };
  if (wind) Object.assign(rehearsal, { wind_m_s: wind, wind_from_deg: readNumber("rh-wind-from") || 0 });
  const windWords = wind ? `, wind ${wind} m/s from ${rehearsal.wind_from_deg}°` : ", no wind";
  const sure = await confirmAction(
    `Create a flight from ${file.name}: plan it, then start simulator vehicles at ${speedup}x` +
      `${windWords}, ${Math.round(rehearsal.loss * 100)}% loss?`,
    "Create",
  );
  if (!sure) return;
  await act("create-error", $("create-flight"), async () => {
    const media = /\.json$/i.test(file.name) ? "application/json" : "application/yaml";
    const scenario = (
      await api.request("POST", "/v1/scenarios", {
        body: await file.text(),
        contentType: media,
        what: "scenario",
      })
    ).data;
    say("create-progress", `scenario ${scenario.name} kept; planning…`);
    const request = { scenario_id: scenario.id, seed: readNumber("plan-seed") || 0 };
    const arrival = readNumber("plan-arrival");
    if (arrival !== null) request.required_arrival_s = arrival;
    let job = await api.post("/v1/schedules", request, { what: "schedule" });
    while (job.state === "queued" || job.state === "running") {
      say("create-progress", `planning ${scenario.vehicles.length} vehicles (${job.state})…`);
      await new Promise((r) => setTimeout(r, 300));
      job = await api.get(`/v1/jobs/${job.id}`, { what: "planning job" });
    }
    if (job.state !== "succeeded") throw new ApiError(job.error.status, job.error, "schedule");
    const schedule = job.result;
    say("create-progress", `planned: team arrival ${num(schedule.required_arrival_s, 1)} s; starting vehicles…`);
    const flight = await api.post("/v1/flights", { schedule_id: schedule.id, rehearsal }, { what: "flight" });
    say("create-progress", `flight ${flight.flight_id} created: upload the missions, then launch`);
    $("new-flight").open = false;
    await refreshFlights();
    await openFlight(flight.flight_id);
  });
});

$("upload").addEventListener("click", async () => {
  const n = state.order.length;
  if (!(await confirmAction(`Upload the missions to the ${n} vehicles of this flight?`, "Upload"))) return;
  await act("flight-error", $("upload"), async () => {
    await api.post(flightPath("upload"), undefined, { what: "upload" });
    say("flight-note", "uploading: each vehicle's result follows");
    refreshSnapshot();
  });
});

$("launch").addEventListener("click", async () => {
  const text =
    "Launch the mission? It starts in 10 s of the vehicles' time (one wall second for " +
    "simulator vehicles); each vehicle takes off at its takeoff time.";
  if (!(await confirmAction(text, "Launch"))) return;
  await act("flight-error", $("launch"), async () => {
    const out = await api.post(flightPath("launch"), {}, { what: "launch" });
    say("flight-note", `launched: the mission starts at UTC ${new Date(out.start_utc_s * 1000).toISOString()}`);
    refreshSnapshot();
  });
});

$("pause").addEventListener("click", async () => {
  const resume = Boolean(state.pause && state.pause.paused);
  await act("flight-error", $("pause"), async () => {
    const out = resume
      ? await api.post(flightPath("resume"), undefined, { what: "resume" })
      : await api.post(flightPath("pause"), {}, { what: "pause" });
    state.pause = out;
    say("flight-note", resume ? "resumed: the flight flies on" : "paused: the simulator waits here until resumed");
    updateButtons();
    refreshSnapshot();
  });
});

function abortWords(results) {
  return Object.entries(results)
    .map(([v, why]) => (why === null ? `${v}: RTL` : `${v}: not aborted (${why})`))
    .join("; ");
}

async function abortVehicle(id) {
  if (!(await confirmAction(`Abort ${id}? It leaves the team and flies home (RTL).`, `Abort ${id}`))) return;
  await act("abort-error", null, async () => {
    const out = await api.post(flightPath("abort"), { vehicle: id, mode: "rtl" }, { what: `abort ${id}` });
    const why = out.vehicles[id];
    if (why) say("abort-error", `${id} was not aborted: ${why}`);
    else say("abort-note", `${id} aborted: flying home (RTL)`);
    refreshSnapshot();
  });
}

$("abort-all").addEventListener("click", async () => {
  if (!(await confirmAction("Abort EVERY vehicle? All fly home (RTL); the flight ends.", "Abort all"))) return;
  await act("flight-error", $("abort-all"), async () => {
    const out = await api.post(flightPath("abort"), { mode: "rtl" }, { what: "abort all" });
    say("flight-note", abortWords(out.vehicles));
    refreshSnapshot();
  });
});

$("team-time").addEventListener("input", () => {
  teamTimeEdited = true;
});

$("team-time-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  say("team-time-error", "");
  say("team-time-note", "");
  const value = readNumber("team-time");
  if (value === null || Number.isNaN(value)) return;
  const from = state.teamTimeS;
  const version = state.teamTimeVersion;
  const delta = from === null ? "" : ` (${value - from >= 0 ? "+" : ""}${(value - from).toFixed(1)} s)`;
  const text = `Move the team arrival from ${num(from, 1)} s to ${value.toFixed(1)} s${delta}? Every vehicle's slot moves with it.`;
  if (!(await confirmAction(text, "Move"))) return;
  await act("team-time-error", $("team-time-move"), async () => {
    const r = await api.request("PUT", flightPath("team-time"), {
      json: { arrival_s: value },
      headers: { "If-Match": `"${version}"` },
      what: "team time",
    });
    state.teamTimeS = r.data.team_time_s;
    state.teamTimeVersion = r.data.version;
    teamTimeEdited = false;
    say("team-time-note", `team arrival moved to ${num(r.data.team_time_s, 1)} s (version ${r.data.version})`);
    refreshSnapshot();
  });
});

// -- drawing threats --------------------------------------------------------------------------

const HINTS = {
  pan: "drag to pan, wheel to zoom",
  no_fly: "click the corners; double-click to close (Esc: start again)",
  radar: "press at the centre and drag out the radius",
};

function toolChanged(tool) {
  for (const b of document.querySelectorAll("#map-tools [data-tool]")) {
    b.classList.toggle("active", b.dataset.tool === tool);
  }
  say("map-hint", HINTS[tool]);
  $("map-hint").title = HINTS[tool];
}

for (const b of document.querySelectorAll("#map-tools [data-tool]")) {
  b.addEventListener("click", () => mapView.setTool(b.dataset.tool));
}
$("map-fit").addEventListener("click", () => mapView.fit());
toolChanged("pan");

function nextThreatId() {
  const taken = new Set((state.mapDoc ? state.mapDoc.threats : []).map((t) => t.id));
  let k = 1;
  while (taken.has(`OP${k}`)) k += 1;
  return `OP${k}`;
}

function shapeDrawn(shape) {
  const form = $("draw-confirm");
  form.hidden = false;
  say("draw-error", "");
  $("draw-id").value = nextThreatId();
  $("draw-forbidden-label").hidden = shape.kind !== "radar";
  if (shape.kind === "radar") {
    say("draw-text", `Radar disc, radius ${num(shape.radius_m / 1000, 2)} km:`);
  } else {
    say("draw-text", `No-fly zone, ${shape.polygon.length} corners:`);
  }
  $("draw-send").focus();
}

function discardShape() {
  mapView.discardPending();
  $("draw-confirm").hidden = true;
}

$("draw-discard").addEventListener("click", discardShape);
$("draw-confirm").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const shape = mapView.pending;
  if (!shape) return;
  const id = $("draw-id").value.trim();
  const point = ([e, n]) => ({ east_m: Math.round(e), north_m: Math.round(n) });
  const threat =
    shape.kind === "radar"
      ? {
          kind: "radar",
          id,
          center: point(shape.center),
          radius_m: Math.round(shape.radius_m),
          forbidden: $("draw-forbidden").checked,
        }
      : { kind: "no_fly", id, polygon: shape.polygon.map(point) };
  const body = { threat };
  const at = readNumber("draw-at");
  if (at !== null) body.at_s = at;
  await act("draw-error", $("draw-send"), async () => {
    await api.post(flightPath("threats"), body, { what: `threat ${id}` });
    discardShape();
    mapView.setTool("pan");
    say("flight-note", `threat ${id} sent: the routes it touches are planned again when it appears`);
    await loadMap();
  });
});

// -- for the tests and the console ------------------------------------------------------------

window.tcgcs = {
  state,
  perf,
  clock,
  map: mapView,
  table,
  conflicts,
  get stream() {
    return stream;
  },
  get socket() {
    return stream ? stream.socket : null;
  },
  get events() {
    return state.events;
  },
  get telemetry() {
    return state.telemetry;
  },
  /** Page coordinates of a world point (east, north metres). */
  toClient: (e, n) => mapView.toClient(e, n),
  geometry: () => mapView.geometry(),
  missionNow: () => clock.now(performance.now()),
  openFlight,
};

// -- start ------------------------------------------------------------------------------------

updateButtons();
if (savedToken()) signIn(savedToken());
else showLogin("");

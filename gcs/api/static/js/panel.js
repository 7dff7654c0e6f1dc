// The time-on-target panel (the countdown, each vehicle's row) and the timeline of events.

import { hms, kindGroup, linkText, num, signed, stateText, strategyText } from "./format.js";

const TIMELINE_ROWS = 600;
const ON_TIME_S = 1.0;

function setText(el, text) {
  if (el.textContent !== text) el.textContent = text;
}

function setClass(el, name, on) {
  if (el.classList.contains(name) !== on) el.classList.toggle(name, on);
}

export class VehicleTable {
  /** `onAbort(vehicleId)` when a row's abort button is pressed. */
  constructor(tbody, onAbort) {
    this.tbody = tbody;
    this.onAbort = onAbort;
    this.rows = new Map();
  }

  clear() {
    this.tbody.replaceChildren();
    this.rows.clear();
  }

  _row(id, colour) {
    let row = this.rows.get(id);
    if (row) return row;
    const tr = document.createElement("tr");
    tr.dataset.vehicle = id;
    const cells = {};
    for (const name of ["id", "state", "mode", "eta", "error", "slot", "strategy", "speed", "link", "act"]) {
      const td = document.createElement("td");
      td.className = `c-${name}`;
      tr.append(td);
      cells[name] = td;
    }
    const swatch = document.createElement("span");
    swatch.className = "swatch";
    swatch.style.background = colour;
    cells.id.append(swatch, document.createTextNode(id));
    const button = document.createElement("button");
    button.type = "button";
    button.className = "danger abort";
    button.textContent = "Abort";
    button.title = `send ${id} home (RTL)`;
    button.addEventListener("click", () => this.onAbort(id));
    cells.act.append(button);
    this.tbody.append(tr);
    row = { tr, cells, button };
    this.rows.set(id, row);
    return row;
  }

  /** Update every row from the vehicles' merged views at mission time `tS`. */
  update(vehicles, colours, tS, flightRunning) {
    for (const v of vehicles) {
      const { cells, button } = this._row(v.id, colours.get(v.id) || "#333");
      setText(cells.state, stateText(v.state));
      setClass(cells.state, "aborted", v.state === "aborted");
      setText(cells.mode, v.link && v.link.mode ? v.link.mode : "–");
      setText(cells.eta, num(v.eta_s, 1));
      setText(cells.error, signed(v.error_s, 1));
      const e = v.error_s;
      setClass(cells.error, "late", e !== null && e !== undefined && e > ON_TIME_S);
      setClass(cells.error, "early", e !== null && e !== undefined && e < -ON_TIME_S);
      setClass(cells.error, "ontime", e !== null && e !== undefined && Math.abs(e) <= ON_TIME_S);
      setText(cells.slot, num(v.slot_s, 1));
      setText(cells.strategy, strategyText(v.strategy, tS));
      setText(cells.speed, `${num(v.commanded_m_s, 1)} / ${num(v.airspeed_m_s, 1)}`);
      const link = linkText(v);
      setText(cells.link, link.text);
      setClass(cells.link, "stale", link.stale);
      const done = ["arrived", "aborted", "failed"].includes(v.state);
      button.disabled = !flightRunning || done;
    }
  }

  /** The rows as the operator reads them (for the tests). */
  text() {
    const out = {};
    for (const [id, { cells }] of this.rows) {
      out[id] = Object.fromEntries(
        Object.entries(cells)
          .filter(([k]) => k !== "act")
          .map(([k, td]) => [k, td.textContent]),
      );
    }
    return out;
  }
}

export class Countdown {
  constructor(big, line) {
    this.big = big;
    this.line = line;
  }

  update({ teamTimeS, now, flightState, startUtcS, arrivedAll }) {
    if (teamTimeS === null || teamTimeS === undefined) {
      setText(this.big, "--");
      setText(this.line, "no team arrival time");
      return;
    }
    const at = `team arrival at ${num(teamTimeS, 1)} s mission time`;
    if (!now || startUtcS === null || startUtcS === undefined) {
      setText(this.big, "not launched");
      setText(this.line, `${at} (mission time counts from the start)`);
      setClass(this.big, "late", false);
      return;
    }
    const left = teamTimeS - now.t_s;
    const rate = now.rate ? `x${now.rate.toFixed(now.rate < 10 ? 1 : 0)}` : "rate unknown";
    const stale = now.stale ? "; no telemetry: the clock is stopped" : "";
    if (arrivedAll) {
      setText(this.big, "arrived");
    } else if (left >= 0) {
      setText(this.big, `T−${hms(left)}`);
    } else {
      setText(this.big, `T+${hms(-left)}`);
    }
    setClass(this.big, "late", left < 0 && !arrivedAll);
    setText(this.line, `${at}; now ${num(now.t_s, 1)} s (${rate}, ${flightState})${stale}`);
  }
}

export class Timeline {
  constructor(list, count, filter) {
    this.list = list;
    this.count = count;
    this.filter = filter;
    this.total = 0;
    filter.addEventListener("change", () => this._refilter());
  }

  clear() {
    this.list.replaceChildren();
    this.total = 0;
    setText(this.count, "");
  }

  _visible(group) {
    const f = this.filter.value;
    if (f === "everything") return true;
    if (f === "all") return group !== "state";
    return group === f;
  }

  _refilter() {
    for (const li of this.list.children) li.classList.toggle("hidden", !this._visible(li.dataset.group));
  }

  add(ev) {
    const group = kindGroup(ev.kind);
    const li = document.createElement("li");
    li.dataset.seq = String(ev.seq);
    li.dataset.group = group;
    li.className = `k-${group}`;
    if (!this._visible(group)) li.classList.add("hidden");
    const t = document.createElement("span");
    t.className = "t";
    t.textContent = `${num(ev.t_s, 1)} s`;
    const who = document.createElement("span");
    who.className = "who";
    who.textContent = ev.vehicle || "team";
    const kind = document.createElement("span");
    kind.className = "kind";
    kind.textContent = ev.kind;
    const reason = document.createElement("span");
    reason.className = "reason";
    reason.textContent = ev.reason;
    li.append(t, who, kind, reason);
    li.title = `event ${ev.seq}`;
    this.list.prepend(li);
    while (this.list.childElementCount > TIMELINE_ROWS) this.list.lastElementChild.remove();
    this.total += 1;
    const shown = this.list.childElementCount;
    setText(this.count, shown < this.total ? `(${this.total}; newest ${shown} listed)` : `(${this.total})`);
  }
}

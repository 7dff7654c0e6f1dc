// Conflicts between aircraft, read from the flight's events as the flight record's
// `separation_events` reads them (gcs.coordination.separationlog): predicted, resolved (by
// speed, by height, or by an altitude layer in a re-plan), released, unresolved (a re-plan's,
// or one in flight that no speed or height parts; alarmed) and loss (under the separation).
// Each encounter is shown from its event to a minute past when the event expects the pair
// closest; the map draws a line between the pair, the panel lists them.

import { num } from "./format.js";

const ENCOUNTER_AFTER_S = 60.0;

/** The separation reading of one event, or null: {kind, a, b, action, said_m, t_s, until_s}. */
export function separationOf(ev) {
  const p = ev.payload || {};
  const said = p.distance_m === undefined || p.distance_m === null ? null : Number(p.distance_m);
  const atS = p.at_s === undefined ? ev.t_s : Number(p.at_s);
  const base = { t_s: ev.t_s, said_m: said, seq: ev.seq };
  if (ev.kind === "alarm") {
    if (p.other === undefined || said === null || !ev.vehicle) return null;
    return { ...base, kind: "loss", a: ev.vehicle, b: p.other, action: "alarm", until_s: ev.t_s + ENCOUNTER_AFTER_S };
  }
  if (ev.kind !== "conflict") return null;
  if (Array.isArray(p.pair)) {
    const [a, b] = p.pair;
    const until = atS + ENCOUNTER_AFTER_S;
    if (p.resolution === "altitude") {
      return { ...base, kind: "resolved", a, b, action: `altitude +${p.height_m} m`, until_s: until };
    }
    if (p.resolution === "timing") {
      const shift = Number(p.shift_s ?? 0);
      return { ...base, kind: "resolved", a, b, action: `timing ${shift >= 0 ? "+" : ""}${shift} s`, until_s: until };
    }
    if (p.resolution === "offset") {
      return { ...base, kind: "resolved", a, b, action: `offset ${Number(p.offset_m ?? 0)} m`, until_s: until };
    }
    return { ...base, kind: "unresolved", a, b, action: "alarm", until_s: until };
  }
  if (p.other === undefined || !ev.vehicle) return null;
  if (p.resolution === "speed") {
    const until = Math.max(atS, Number(p.until_s ?? atS)) + ENCOUNTER_AFTER_S;
    return { ...base, kind: "resolved", a: ev.vehicle, b: p.other, action: `speed ${p.airspeed_m_s} m/s`, until_s: until };
  }
  if (p.resolution === "altitude") {
    const until = Math.max(atS, Number(p.until_s ?? atS)) + ENCOUNTER_AFTER_S;
    const offset = Number(p.offset_m ?? 0);
    const action = `altitude ${offset >= 0 ? "+" : ""}${offset} m`;
    return { ...base, kind: "resolved", a: ev.vehicle, b: p.other, action, until_s: until };
  }
  if (p.resolution === "released") {
    return { ...base, kind: "released", a: ev.vehicle, b: p.other, action: "released", until_s: ev.t_s };
  }
  return { ...base, kind: "predicted", a: ev.vehicle, b: p.other, action: "none", until_s: atS + ENCOUNTER_AFTER_S };
}

const pairKey = (a, b) => (a < b ? `${a}|${b}` : `${b}|${a}`);

export class Conflicts {
  constructor(list) {
    this.list = list;
    this.seen = []; // every separation event, in order
    this.byPair = new Map(); // the pair's latest encounter
  }

  clear() {
    this.seen = [];
    this.byPair.clear();
    this.list.replaceChildren();
  }

  add(ev) {
    const s = separationOf(ev);
    if (!s) return;
    this.seen.push(s);
    this.byPair.set(pairKey(s.a, s.b), s);
  }

  /** The encounters in progress at mission time `tS` (a released one is over). */
  active(tS) {
    const out = [];
    for (const s of this.byPair.values()) {
      if (s.kind === "released") continue;
      if (tS === null || tS === undefined || tS <= s.until_s) out.push(s);
    }
    return out;
  }

  /** The panel's list: the pairs in conflict now, then the last few that were. */
  render(tS) {
    const now = new Set(this.active(tS).map((s) => pairKey(s.a, s.b)));
    const rows = [...this.byPair.values()].sort((x, y) => y.t_s - x.t_s).slice(0, 8);
    this.list.replaceChildren(
      ...rows.map((s) => {
        const li = document.createElement("li");
        li.dataset.pair = pairKey(s.a, s.b);
        li.dataset.kind = s.kind;
        li.className = `sep-${s.kind}${now.has(pairKey(s.a, s.b)) ? " now" : ""}`;
        const said = s.said_m === null ? "" : ` ${num(s.said_m, 0)} m`;
        li.textContent = `${num(s.t_s, 0)} s ${s.a}–${s.b} ${s.kind}${said} · ${s.action}`;
        return li;
      }),
    );
  }
}

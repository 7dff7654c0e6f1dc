// Words and numbers as the console shows them.

const FIRST_COLOURS = ["#1f5fbf", "#d26a00", "#7b3fb5", "#0f8a7a", "#b0306f", "#5b7d00"];

/** A vehicle's colour: a fixed few, then hues spread by the golden angle. */
export function vehicleColour(index) {
  if (index < FIRST_COLOURS.length) return FIRST_COLOURS[index];
  const hue = (210 + index * 137.508) % 360;
  return `hsl(${hue.toFixed(0)}, 65%, 40%)`;
}

export function num(x, digits = 1) {
  return x === null || x === undefined || Number.isNaN(x) ? "–" : Number(x).toFixed(digits);
}

export function signed(x, digits = 1) {
  if (x === null || x === undefined) return "–";
  const s = Number(x).toFixed(digits);
  return x > 0 ? `+${s}` : s;
}

/** Mission seconds as h:mm:ss (a countdown's magnitude). */
export function hms(seconds) {
  const s = Math.max(0, Math.round(Math.abs(seconds)));
  const h = Math.floor(s / 3600);
  const m = Math.floor((s % 3600) / 60);
  const r = s % 60;
  const mm = String(m).padStart(2, "0");
  const ss = String(r).padStart(2, "0");
  return h > 0 ? `${h}:${mm}:${ss}` : `${mm}:${ss}`;
}

/** The snapshot's `strategy` in words (takeoff wait, speed level, loiter turns left). */
export function strategyText(strategy, tS) {
  if (!strategy) return "–";
  if (strategy.kind === "takeoff_wait") {
    const at = strategy.takeoff_s;
    const wait = tS === null || tS === undefined ? null : at - tS;
    return wait !== null && wait > 0
      ? `takeoff ${num(at, 0)} s (in ${hms(wait)})`
      : `takeoff ${num(at, 0)} s`;
  }
  if (strategy.kind === "loiter") {
    const n = strategy.turns_left;
    return `loiter, ${n} turn${n === 1 ? "" : "s"} left`;
  }
  if (strategy.kind === "speed") {
    return strategy.level_m_s === null || strategy.level_m_s === undefined
      ? "speed not yet set"
      : `level ${num(strategy.level_m_s, 1)} m/s`;
  }
  return strategy.kind;
}

/** A fix older than this (mission s) is shown as stale, on the map and in the table. */
export const STALE_FIX_S = 10;

/** Link health, honestly: a silent or stale link says for how long there has been no fix. */
export function linkText(v) {
  const age = v.last_fix_age_s;
  if (v.link_silent) return { text: `SILENT: no fix for ${num(age, 1)} s`, stale: true };
  if (age === null || age === undefined) return { text: "no fix yet", stale: false };
  if (age > STALE_FIX_S) return { text: `no fix for ${num(age, 0)} s`, stale: true };
  return { text: `ok, fix ${num(age, 1)} s`, stale: false };
}

export function stateText(state) {
  return (state || "–").replaceAll("_", " ");
}

const KIND_GROUP = {
  plan: "decision",
  speed: "decision",
  loiter: "decision",
  takeoff: "decision",
  route: "decision",
  launch: "decision",
  arrival: "team",
  arrived: "team",
  start: "team",
  popup: "threat",
  replan: "threat",
  link: "link",
  clock: "link",
  abort: "flight",
  flight: "flight",
  upload: "flight",
  state: "state",
};

/** The timeline's group of an event kind. */
export function kindGroup(kind) {
  return KIND_GROUP[kind] || "flight";
}

// Mission time between telemetry batches: each batch dates mission time (`t_s`); the rate the
// last batches show (mission s per wall s: the speed-up, 1 for a real flight) runs it on until
// the next one. Past MAX_RUN_MS without a batch the clock stops and says it is stale.

const KEEP = 8;
const MAX_RUN_MS = 2500;

export class MissionClock {
  constructor() {
    this.samples = []; // [wall_ms, t_s]
    this.rate = null;
    this.frozen = false;
  }

  reset() {
    this.samples = [];
    this.rate = null;
    this.frozen = false;
  }

  observe(tS, wallMs) {
    const last = this.samples[this.samples.length - 1];
    if (last && tS < last[1]) this.samples = []; // a new flight, or the clock was reset
    this.samples.push([wallMs, tS]);
    if (this.samples.length > KEEP) this.samples.shift();
    const first = this.samples[0];
    const span = wallMs - first[0];
    if (this.samples.length >= 2 && span >= 300) {
      this.rate = ((tS - first[1]) * 1000) / span;
    }
  }

  /** `{t_s, rate, stale}` at wall time `wallMs` (performance.now()), or null before a batch. */
  now(wallMs) {
    const last = this.samples[this.samples.length - 1];
    if (!last) return null;
    const since = Math.max(0, wallMs - last[0]);
    const run = this.frozen || this.rate === null ? 0 : Math.min(since, MAX_RUN_MS);
    return {
      t_s: last[1] + ((this.rate || 0) * run) / 1000,
      rate: this.rate,
      stale: !this.frozen && since > MAX_RUN_MS,
    };
  }
}

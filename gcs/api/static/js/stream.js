// The flight's stream over a WebSocket. A browser cannot set headers on one: the token goes as
// the subprotocol `bearer.<token>` offered beside `tcgcs.v1` (never in the URL, which is logged).
// When it drops the console says so and reconnects with `after_seq` = the last event's seq it
// saw: the service sends every event after it, so none is lost and none is shown twice.

const BACKOFF_MS = [250, 500, 1000, 2000, 4000];

export class FlightStream {
  /**
   * handlers: `message(type, data)` for every message but a repeated event; `status(kind,
   * text)` with kind `connecting`, `open`, `lost`, `back`, `ended`, `refused`.
   */
  constructor(flightId, token, handlers) {
    this.flightId = flightId;
    this.token = token;
    this.handlers = handlers;
    this.lastSeq = 0;
    this.socket = null;
    this.state = "idle";
    this.history = []; // [{kind, text, at_ms}] for the operator and the tests
    this.reconnects = 0;
    this.duplicates = 0; // events at or before lastSeq (none expected: the service resumes after it)
    this._closing = false;
    this._ended = false;
    this._lostAt = null;
    this._attempt = 0;
    this._timer = null;
  }

  url() {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    const q = new URLSearchParams({ after_seq: String(this.lastSeq) });
    return `${proto}//${location.host}/v1/flights/${encodeURIComponent(this.flightId)}/stream?${q}`;
  }

  start() {
    this._status("connecting", "connecting to the stream");
    this._connect();
  }

  /** Close for good (another flight opened, signed out). */
  close() {
    this._closing = true;
    clearTimeout(this._timer);
    if (this.socket) this.socket.close(1000, "closed by the operator");
    this.socket = null;
  }

  _status(kind, text) {
    this.state = kind;
    this.history.push({ kind, text, at_ms: performance.now() });
    if (this.history.length > 200) this.history.shift();
    this.handlers.status(kind, text);
  }

  _connect() {
    let ws;
    try {
      ws = new WebSocket(this.url(), ["tcgcs.v1", `bearer.${this.token}`]);
    } catch (err) {
      this._lost(`the stream could not be opened (${err.message})`);
      return;
    }
    this.socket = ws;
    let greeted = false;
    ws.onmessage = (ev) => {
      const received = performance.now();
      let msg;
      try {
        msg = JSON.parse(ev.data);
      } catch {
        return;
      }
      if (!greeted && msg.type === "snapshot") {
        greeted = true;
        this._attempt = 0;
        if (this._lostAt !== null) {
          const away = ((performance.now() - this._lostAt) / 1000).toFixed(1);
          this._status("back", `stream back after ${away} s (resumed after event ${this.lastSeq})`);
          this._lostAt = null;
        } else {
          this._status("open", "live");
        }
      }
      if (msg.type === "event") {
        const seq = msg.data.seq;
        if (seq <= this.lastSeq) {
          this.duplicates += 1;
          return;
        }
        this.lastSeq = seq;
      } else if (msg.type === "end") {
        this._ended = true;
      }
      this.handlers.message(msg.type, msg.data, received);
    };
    ws.onclose = (ev) => {
      if (this.socket !== ws) return;
      this.socket = null;
      if (this._closing) return;
      if (this._ended) {
        this._status("ended", "the flight is over; the stream has ended");
        return;
      }
      if (ev.code === 4401) {
        this._status("refused", "the stream refused the token");
        return;
      }
      if (ev.code === 4404) {
        this._status("refused", `the service has no flight ${this.flightId}`);
        return;
      }
      const why = ev.code === 1006 ? "connection lost" : `closed with code ${ev.code}`;
      this._lost(`stream lost (${why})`);
    };
  }

  _lost(text) {
    if (this._lostAt === null) this._lostAt = performance.now();
    const wait = BACKOFF_MS[Math.min(this._attempt, BACKOFF_MS.length - 1)];
    this._attempt += 1;
    this.reconnects += 1;
    const away = ((performance.now() - this._lostAt) / 1000).toFixed(1);
    this._status(
      "lost",
      `${text}; reconnecting (attempt ${this._attempt}, away ${away} s, last event ${this.lastSeq})`,
    );
    clearTimeout(this._timer);
    this._timer = setTimeout(() => {
      if (!this._closing) this._connect();
    }, wait);
  }
}

// The service's REST API, as the console uses it: every request carries the bearer token;
// an error becomes an ApiError whose message is the service's `detail`, in words.

const TOKEN_KEY = "tcgcs.token";

export function savedToken() {
  return sessionStorage.getItem(TOKEN_KEY) || "";
}

export function saveToken(token) {
  if (token) sessionStorage.setItem(TOKEN_KEY, token);
  else sessionStorage.removeItem(TOKEN_KEY);
}

export class ApiError extends Error {
  constructor(status, body, what) {
    const detail = body && typeof body.detail === "string" ? body.detail : null;
    super(detail || (status ? `HTTP ${status}` : "no answer from the service"));
    this.status = status;
    this.body = body || {};
    this.what = what;
  }
}

function idempotencyKey() {
  if (globalThis.crypto && crypto.randomUUID) return crypto.randomUUID();
  return `${Date.now().toString(16)}-${Math.random().toString(16).slice(2)}`;
}

export class Api {
  /** `onUnauthorized(error)` is called on a 401 (the token was refused). */
  constructor(onUnauthorized) {
    this.onUnauthorized = onUnauthorized;
  }

  get token() {
    return savedToken();
  }

  /** One request; resolves to `{status, data, headers}` or throws an ApiError. */
  async request(method, path, { json, body, contentType, headers = {}, what } = {}) {
    const h = { Authorization: `Bearer ${this.token}`, ...headers };
    let payload = body;
    if (json !== undefined) {
      payload = JSON.stringify(json);
      h["Content-Type"] = "application/json";
    } else if (contentType) {
      h["Content-Type"] = contentType;
    }
    if (method === "POST" && !h["Idempotency-Key"]) h["Idempotency-Key"] = idempotencyKey();
    let r;
    try {
      r = await fetch(path, { method, headers: h, body: payload, cache: "no-store" });
    } catch (err) {
      throw new ApiError(0, { detail: `the service did not answer (${err.message})` }, what);
    }
    const type = r.headers.get("content-type") || "";
    let data = null;
    if (type.includes("json")) {
      data = await r.json().catch(() => null);
    } else if (type.startsWith("image/")) {
      data = await r.blob();
    } else {
      const text = await r.text();
      data = text ? { detail: text } : null;
    }
    if (!r.ok) {
      const error = new ApiError(r.status, data, what);
      if (r.status === 401 && this.onUnauthorized) this.onUnauthorized(error);
      throw error;
    }
    return { status: r.status, data, headers: r.headers };
  }

  async get(path, opts) {
    return (await this.request("GET", path, opts)).data;
  }

  async post(path, json, opts = {}) {
    return (await this.request("POST", path, { ...opts, json })).data;
  }
}

/** An error in words for the operator: the detail, and for an infeasible time what to ask. */
export function describeError(err) {
  if (!(err instanceof ApiError)) return String(err && err.message ? err.message : err);
  const b = err.body || {};
  let text = err.message;
  if (b.earliest_feasible_s !== undefined && b.earliest_feasible_s !== null) {
    text += `\nThe earliest time every vehicle can make is ${b.earliest_feasible_s.toFixed(1)} s`;
    text += b.vehicle ? ` (${b.vehicle} forces it).` : ".";
  }
  if (b.latest_feasible_s !== undefined && b.latest_feasible_s !== null) {
    text += `\nThe latest time every vehicle can make is ${b.latest_feasible_s.toFixed(1)} s`;
    text += b.vehicle ? ` (${b.vehicle} cannot wait longer).` : ".";
  }
  if (Array.isArray(b.errors) && b.errors.length > 1) {
    text += `\n(${b.errors.length} problems; the first is shown)`;
  }
  const label = err.status ? ` (HTTP ${err.status})` : "";
  return (err.what ? `${err.what}: ` : "") + text + label;
}

"""Benchmark: the coordinator service under a reader's load during a paper rehearsal.

``python -m gcs serve`` runs in a child process on a free loopback port (a temporary data
directory and SQLite, one admin token in ``TCGCS_TOKENS``). Over HTTP only, this process keeps
the paper scenario, schedules it (seed 1), then flies two flights of that schedule one after
the other on bundled simulator vehicles (``rehearsal``: 200x, wind 5 m/s from 270 deg, 10%
loss, seed 1): the first without load, the second while a second process GETs the flight's
snapshot (``/v1/flights/{id}``) at ``--rate`` requests a second, open loop (request i is due
at i / rate; up to 16 in flight on keep-alive connections). Throughout each flight this process
follows the SSE stream and probes the snapshot itself at 20 Hz.

Stream lag: how old an event is, on the simulator's time, when it reaches a client. Events
carry ``utc_s``, the service's mission clock (the simulator's UTC, ~200x wall) when the event
was published. Each probe of the snapshot yields a pair (wall time, ``t_s``): the snapshot is
taken somewhere between the request's send and its answer, so its wall time is the midpoint,
uncertain by half the round trip. Around each stream message (+/-1.5 s wall) a straight line
is fitted through the quarter of the probes with the shortest round trips (answered while the
service's loop was idle: its clock then reads within a few ms of that line, reported as
"clock off its line"); the message's publication wall time is its mission time through that
line, and its lag is its receipt time minus that. A stamp read from a clock that is itself
behind (the service's loop late on its vehicles' reports) counts as lag: the information is
that much older. At 200x one wall millisecond is 0.2 mission seconds, so the stamps' 1 ms
rounding (5 us wall) does not matter, but a wall-clock mapping would need one within 1 ms for
each 0.2 s of simulated time: hence the probes, not the rate. Events published before the
stream was open (its backlog) are not counted.

Telemetry batches carry the ``t_s`` of the snapshot they were built from. Since each flight
flies in a worker process of its own, a snapshot is the flight's state as its worker last told
the service (every 0.25 s of wall time), not a reading taken at the request: the probes then
date the mission clock only to within that, and the lag figures are not measurements
(docs/benchmarks.md gives the GETs, the arrivals and the CPU).

    python bench/bench_service.py [--rate 200] [--speedup 200] [--json OUT]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import multiprocessing as mp
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from collections import Counter
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from gcs.api.demo import PAPER, sse_messages

PROBE_HZ = 20.0
FIT_WINDOW_S = 1.5
MAX_IN_FLIGHT = 16


def pct(values: list[float], q: float) -> float:
    """The ``q`` quantile (0..1), nearest rank; NaN for no values."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, round(q * (len(ordered) - 1))))]


# -- the service ------------------------------------------------------------------------------


@contextlib.contextmanager
def service(token: str) -> Iterator[tuple[str, int]]:
    """``python -m gcs serve`` on a free loopback port: (its URL, its pid); stopped after."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    with tempfile.TemporaryDirectory(prefix="tcgcs-bench-") as tmp:
        env = {**os.environ, "TCGCS_DATA_DIR": tmp, "TCGCS_TOKENS": json.dumps({token: ["admin"]})}
        env.pop("TCGCS_DATABASE_URL", None)
        argv = [sys.executable, "-m", "gcs", "serve", "--port", str(port)]
        proc = subprocess.Popen(argv, env=env, cwd=tmp, stdout=subprocess.DEVNULL)
        url = f"http://127.0.0.1:{port}"
        try:
            deadline = time.monotonic() + 30.0
            while True:
                if proc.poll() is not None:
                    raise SystemExit(f"the service exited ({proc.returncode}) before it answered")
                with contextlib.suppress(httpx.TransportError):
                    if httpx.get(f"{url}/v1/ready", timeout=1.0).status_code == 200:
                        break
                if time.monotonic() > deadline:
                    raise SystemExit("the service did not answer /v1/ready within 30 s")
                time.sleep(0.1)
            yield url, proc.pid
        finally:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def ok(r: httpx.Response, what: str, *, text: bool = False) -> Any:
    """The answer's JSON (its text with ``text``); an error answer ends the benchmark."""
    if r.status_code >= 400:
        raise SystemExit(f"{what}: HTTP {r.status_code}: {r.text[:500]}")
    if text:
        return r.text
    return r.json() if r.content else None


# -- the second process: GETs at a fixed rate --------------------------------------------------


def load(url: str, token: str, path: str, rate: float, stop: Any, out: Any) -> None:
    """GET ``path`` at ``rate`` a second until ``stop`` is set; put the results on ``out``."""
    out.put(asyncio.run(_load(url, token, path, rate, stop)))


async def _load(url: str, token: str, path: str, rate: float, stop: Any) -> dict[str, Any]:
    latencies: list[float] = []
    lateness: list[float] = []
    failed = 0
    slots = asyncio.Semaphore(MAX_IN_FLIGHT)
    limits = httpx.Limits(max_connections=MAX_IN_FLIGHT, max_keepalive_connections=MAX_IN_FLIGHT)
    headers = {"Authorization": f"Bearer {token}"}
    async with httpx.AsyncClient(base_url=url, headers=headers, limits=limits, timeout=30) as c:

        async def one(due: float) -> None:
            nonlocal failed
            try:
                sent = time.perf_counter()
                lateness.append(sent - due)
                r = await c.get(path)
                if r.status_code == 200:
                    latencies.append(time.perf_counter() - sent)
                else:
                    failed += 1
            except httpx.HTTPError:
                failed += 1
            finally:
                slots.release()

        tasks: set[asyncio.Task[None]] = set()
        cpu0, t0 = time.process_time(), time.perf_counter()
        i = 0
        while not stop.is_set():
            due = t0 + i / rate
            await asyncio.sleep(max(0.0, due - time.perf_counter()))
            await slots.acquire()
            task = asyncio.create_task(one(due))
            tasks.add(task)
            task.add_done_callback(tasks.discard)
            i += 1
        elapsed = time.perf_counter() - t0
        await asyncio.gather(*tasks)
    return {
        "cpu_s": time.process_time() - cpu0,
        "requests": len(latencies),
        "failed": failed,
        "elapsed_s": elapsed,
        "latencies_s": latencies,
        "late_p99_s": pct(lateness, 0.99),
    }


# -- one flight -------------------------------------------------------------------------------


@dataclass
class Probe:
    sent: float
    answered: float
    mission_s: float

    @property
    def wall(self) -> float:
        return (self.sent + self.answered) / 2

    @property
    def half_rtt(self) -> float:
        return (self.answered - self.sent) / 2


@dataclass
class Flight:
    """What one flight measured (wall times: this process's ``time.perf_counter``)."""

    label: str
    probes: list[Probe] = field(default_factory=list)
    events: list[tuple[float, float]] = field(default_factory=list)
    """(receipt wall time, mission time published: utc_s - start_utc_s) of each event."""
    telemetry: list[tuple[float, float]] = field(default_factory=list)
    stream_open: float = 0.0
    kinds: Counter[str] = field(default_factory=Counter)
    loadavg: list[float] = field(default_factory=list)
    load: dict[str, Any] | None = None
    record: dict[str, Any] = field(default_factory=dict)
    wall_s: float = 0.0
    service_cpu_s: float = 0.0
    stub_cpu: dict[int, tuple[float, float]] = field(default_factory=dict)
    """The service's children (the simulator): pid -> (CPU s at launch, CPU s last seen)."""

    def watch_children(self, pid: int) -> None:
        with contextlib.suppress(OSError):
            kids = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
            for kid in map(int, kids):
                with contextlib.suppress(OSError, IndexError, ValueError):
                    now = cpu_s(kid)
                    self.stub_cpu[kid] = (self.stub_cpu.get(kid, (now, now))[0], now)

    def fit_near(self, near: float) -> tuple[statistics.LinearRegression, float] | None:
        """The mission clock against wall time around wall ``near`` (a line through the
        quarter of the probes within FIT_WINDOW_S with the shortest round trips) and its
        uncertainty (the longest half round trip used); None without probes around it."""
        around = [p for p in self.probes if abs(p.wall - near) <= FIT_WINDOW_S]
        if len(around) < 4:
            return None
        around.sort(key=lambda p: p.half_rtt)
        best = around[: max(4, len(around) // 4)]
        fit = statistics.linear_regression([p.wall for p in best], [p.mission_s for p in best])
        if fit.slope <= 0:
            return None
        return fit, max(p.half_rtt for p in best)

    def published_wall(self, mission_s: float, near: float) -> tuple[float, float] | None:
        """The wall time at which the mission clock read ``mission_s`` (near wall ``near``),
        and the uncertainty of the fit (s)."""
        got = self.fit_near(near)
        if got is None:
            return None
        fit, err = got
        return (mission_s - fit.intercept) / fit.slope, err

    def clock_noise(self) -> list[float]:
        """How far (wall s) the mission clock's readings stray from its local line: for the
        probes with round trips in the shortest quarter, the reading's wall time through the
        line minus the probe's own."""
        quick = pct([p.half_rtt for p in self.probes], 0.25)
        out = []
        for p in self.probes:
            got = self.published_wall(p.mission_s, p.wall) if p.half_rtt <= quick else None
            if got is not None:
                out.append(abs(got[0] - p.wall))
        return out

    def lags(self, stamped: list[tuple[float, float]]) -> tuple[list[float], list[float]]:
        """Lag of each message (s) published after the stream opened, and the fits'
        uncertainties."""
        lags, errs = [], []
        for received, mission_s in stamped:
            got = self.published_wall(mission_s, received)
            if got is None or got[0] < self.stream_open:
                continue
            lags.append(received - got[0])
            errs.append(got[1])
        return lags, errs


async def probe(
    client: httpx.AsyncClient, path: str, start_utc: list[float], f: Flight, pid: int
) -> None:
    """The snapshot at PROBE_HZ: (wall, mission time) pairs once the flight is launched; the
    simulator's CPU time."""
    while True:
        f.watch_children(pid)
        sent = time.perf_counter()
        r = await client.get(path)
        answered = time.perf_counter()
        snap = r.json()
        if start_utc and snap.get("start_utc_s") is not None:
            f.probes.append(Probe(sent, answered, float(snap["t_s"])))
        await asyncio.sleep(max(0.0, sent + 1.0 / PROBE_HZ - time.perf_counter()))


async def follow(client: httpx.AsyncClient, fid: str, after_seq: int, start_utc: list[float],
                 f: Flight, opened: asyncio.Event) -> None:  # fmt: skip
    """The SSE stream until its ``end``: each event's and telemetry batch's receipt time."""
    stream: AsyncIterator[tuple[str, dict[str, Any]]] = sse_messages(
        client, f"/v1/flights/{fid}/stream", {"after_seq": after_seq}
    )
    async for kind, data in stream:
        received = time.perf_counter()
        if kind == "snapshot":
            f.stream_open = received
            opened.set()
        elif kind == "event" and data.get("utc_s") is not None and start_utc:
            f.kinds[data["kind"]] += 1
            f.events.append((received, data["utc_s"] - start_utc[0]))
        elif kind == "telemetry" and start_utc and data["state"] != "ready":
            f.telemetry.append((received, float(data["t_s"])))
        elif kind == "end":
            return


async def fly(url: str, token: str, pid: int, schedule_id: str, args: argparse.Namespace,
              with_load: bool) -> Flight:  # fmt: skip
    f = Flight("with load" if with_load else "no load")
    headers = {"Authorization": f"Bearer {token}"}
    rehearsal = {"speedup": args.speedup, "wind_m_s": 5.0, "wind_from_deg": 270.0,
                 "loss": 0.1, "seed": 1}  # fmt: skip
    async with httpx.AsyncClient(base_url=url, headers=headers, timeout=60) as client:
        flight = ok(
            await client.post(
                "/v1/flights", json={"schedule_id": schedule_id, "rehearsal": rehearsal}
            ),
            "flight",
        )
        fid = flight["flight_id"]
        path = f"/v1/flights/{fid}"
        ok(await client.post(f"{path}/upload"), "upload")
        snap = flight
        while snap["state"] in ("planned", "uploading"):
            await asyncio.sleep(0.2)
            snap = ok(await client.get(path), "snapshot")
        if snap["state"] != "ready":
            raise SystemExit(f"upload failed: {snap['uploads']}")
        start_utc: list[float] = []
        opened = asyncio.Event()
        async with httpx.AsyncClient(base_url=url, headers=headers, timeout=60) as streamer:
            stream = asyncio.create_task(
                follow(streamer, fid, snap["last_seq"], start_utc, f, opened)
            )
            await opened.wait()
            prober = asyncio.create_task(probe(client, path, start_utc, f, pid))
            stop = out = proc = None
            if with_load:
                ctx = mp.get_context("spawn")
                stop, out = ctx.Event(), ctx.Queue()
                proc = ctx.Process(target=load, args=(url, token, path, args.rate, stop, out))
                proc.start()
            f.loadavg.append(os.getloadavg()[0])
            cpu0, t0 = cpu_s(pid), time.perf_counter()
            launched = ok(await client.post(f"{path}/launch", json={}), "launch")
            start_utc.append(float(launched["start_utc_s"]))
            await stream
            f.wall_s = time.perf_counter() - t0
            f.service_cpu_s = cpu_s(pid) - cpu0
            f.loadavg.append(os.getloadavg()[0])
            prober.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await prober
            if proc is not None and stop is not None and out is not None:
                stop.set()
                f.load = out.get(timeout=60)
                proc.join(timeout=10)
        f.record = ok(await client.get(f"{path}/record"), "record")
    return f


async def prepare(url: str, token: str, body: str) -> str:
    """A scenario (its YAML text) kept and scheduled (seed 1): the schedule's id."""
    headers = {"Authorization": f"Bearer {token}"}
    async with httpx.AsyncClient(base_url=url, headers=headers, timeout=60) as client:
        kept = ok(
            await client.post(
                "/v1/scenarios", content=body, headers={"Content-Type": "application/yaml"}
            ),
            "scenario",
        )
        job = ok(await client.post("/v1/schedules", json={"scenario_id": kept["id"], "seed": 1}),
                 "schedule")  # fmt: skip
        while job["state"] in ("queued", "running"):
            await asyncio.sleep(0.2)
            job = ok(await client.get(f"/v1/jobs/{job['id']}"), "job")
        if job["state"] != "succeeded":
            raise SystemExit(f"schedule failed: {job['error']}")
        return str(job["result"]["id"])


# -- the figures ------------------------------------------------------------------------------


def summary(f: Flight) -> dict[str, Any]:
    probe_ms = [2e3 * p.half_rtt for p in f.probes]
    ev, ev_err = f.lags(f.events)
    tm, _ = f.lags(f.telemetry)
    out: dict[str, Any] = {
        "run": f.label,
        "wall_s": round(f.wall_s, 1),
        "service_cpu_share": round(f.service_cpu_s / f.wall_s, 2),
        "simulator_cpu_share": round(sum(b - a for a, b in f.stub_cpu.values()) / f.wall_s, 2),
        "probe_gets": len(probe_ms),
        "probe_p50_ms": pct(probe_ms, 0.5),
        "probe_p99_ms": pct(probe_ms, 0.99),
        "events": len(ev),
        "event_lag_p50_ms": 1e3 * pct(ev, 0.5),
        "event_lag_p99_ms": 1e3 * pct(ev, 0.99),
        "event_lag_max_ms": 1e3 * max(ev, default=float("nan")),
        "event_lag_min_ms": 1e3 * min(ev, default=float("nan")),
        "fit_uncertainty_ms": 1e3 * pct(ev_err, 0.5),
        "clock_noise_p50_ms": 1e3 * pct(f.clock_noise(), 0.5),
        "clock_noise_p99_ms": 1e3 * pct(f.clock_noise(), 0.99),
        "telemetry": len(tm),
        "telemetry_lag_p50_ms": 1e3 * pct(tm, 0.5),
        "telemetry_lag_p99_ms": 1e3 * pct(tm, 0.99),
        "telemetry_lag_min_ms": 1e3 * min(tm, default=float("nan")),
        "errors_s": {v["id"]: v["error_s"] for v in f.record["vehicles"]},
        "required_arrival_s": f.record.get("required_arrival_s"),
        "event_kinds": dict(f.kinds),
        "clock_and_link_events": [
            f"{e['t_s']:.1f} s {e['vehicle'] or 'team'}: {e['reason']}"
            for e in f.record.get("events", [])
            if e["kind"] in ("clock", "link")
        ][:12],
        "loadavg_1min": [round(x, 2) for x in f.loadavg],
    }
    if f.load is not None:
        lat_ms = [1e3 * x for x in f.load["latencies_s"]]
        out |= {
            "load_requests": f.load["requests"],
            "load_failed": f.load["failed"],
            "load_rate": f.load["requests"] / f.load["elapsed_s"],
            "load_p50_ms": pct(lat_ms, 0.5),
            "load_p99_ms": pct(lat_ms, 0.99),
            "load_late_p99_ms": 1e3 * f.load["late_p99_s"],
            "load_client_cpu_share": round(f.load["cpu_s"] / f.load["elapsed_s"], 2),
        }
    return out


def table(rows: list[dict[str, Any]]) -> str:
    ids = list(rows[0]["errors_s"])
    head = (
        "| run | GETs/s (2nd process) | GET p50 / p99 (ms) | probe GET p50 / p99 (ms) "
        "| events | event lag p50 / p99 (ms) | telemetry lag p50 / p99 (ms) | "
        + " | ".join(f"{i} error (s)" for i in ids)
        + " | CPU: service / simulator / load | wall (s) |"
    )
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        loaded = "load_rate" in r
        rate = f"{r['load_rate']:.0f} ({r['load_failed']} failed)" if loaded else "-"
        get = f"{r['load_p50_ms']:.1f} / {r['load_p99_ms']:.1f}" if loaded else "-"
        errors = " | ".join(
            "-" if r["errors_s"][i] is None else f"{r['errors_s'][i]:+.2f}" for i in ids
        )
        cpu = [r["service_cpu_share"], r["simulator_cpu_share"]]
        cpu.append(r["load_client_cpu_share"] if loaded else 0.0)
        lines.append(
            f"| {r['run']} | {rate} | {get} | {r['probe_p50_ms']:.1f} / {r['probe_p99_ms']:.1f} "
            f"| {r['events']} | {r['event_lag_p50_ms']:.1f} / {r['event_lag_p99_ms']:.1f} "
            f"| {r['telemetry_lag_p50_ms']:.1f} / {r['telemetry_lag_p99_ms']:.1f} | {errors} "
            f"| {' / '.join(f'{100 * c:.0f}%' for c in cpu)} | {r['wall_s']:.1f} |"
        )
    return "\n".join(lines)


def notes(r: dict[str, Any]) -> str:
    text = (
        f"{r['run']}: lag fit uncertainty {r['fit_uncertainty_ms']:.1f} ms (half round trip of "
        f"the probes used); mission clock off its line by {r['clock_noise_p50_ms']:.1f} ms "
        f"(p50), {r['clock_noise_p99_ms']:.1f} ms (p99); event lag min / max "
        f"{r['event_lag_min_ms']:.1f} / {r['event_lag_max_ms']:.1f} ms; "
        f"telemetry lag min {r['telemetry_lag_min_ms']:.1f} ms; "
        f"team arrival {r['required_arrival_s']:.2f} s; load average {r['loadavg_1min']}"
    )
    if "load_rate" in r:
        text += f"; load GETs late on their schedule, p99 {r['load_late_p99_ms']:.0f} ms"
    return text


async def bench(args: argparse.Namespace) -> list[dict[str, Any]]:
    token = uuid.uuid4().hex
    with service(token) as (url, pid):
        schedule_id = await prepare(url, token, Path(args.scenario).read_text(encoding="utf-8"))
        rows = []
        for with_load in (False, True):
            f = await fly(url, token, pid, schedule_id, args, with_load)
            rows.append(summary(f))
            print(f"{f.label}: done in {f.wall_s:.1f} s", file=sys.stderr, flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default=str(PAPER))
    ap.add_argument("--rate", type=float, default=200.0, help="GETs a second (the load)")
    ap.add_argument("--speedup", type=float, default=200.0)
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args()
    rows = asyncio.run(bench(args))
    print(table(rows))
    for r in rows:
        print(notes(r))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()

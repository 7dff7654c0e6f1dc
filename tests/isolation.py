"""A client load on the service while a flight flies, from a process of its own: oversized
uploads, large planning jobs started and cancelled, many readers and many stream clients
(:class:`Load`). What it saw comes back as a :class:`LoadSeen`: every status, every 5xx named,
and the latencies of ``/v1/health`` as a monitor sees them: asked every 0.1 s by a process of
its own, as a load balancer or a supervisor asks (the readers ask it too, in turn with the rest,
and the time their own crowded process takes to send and read is theirs, kept apart). Used by
``tests/service/test_isolation.py`` and ``bench/bench_isolation.py``."""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing as mp
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import httpx
import yaml

from tests.teams import ring_team

__all__ = ["Load", "LoadSeen", "loaded"]


@dataclass(frozen=True)
class Load:
    """What the load does (the issue's figures by default)."""

    uploads: int = 10
    upload_bytes: int = 20 << 20
    big_jobs: int = 5
    big_team: int = 1000
    big_work_s: float = 3.0
    """How long (wall s) each large job may work before it is cancelled."""
    readers: int = 200
    read_s: float = 60.0
    streams: int = 50
    answer_s: float | None = 60.0
    """How long (wall s) a request waits for its answer before it counts as unanswered; None:
    as long as it takes, and the stream clients follow the flight to its end (a test's
    verdict, which no machine's load may move: a busy machine runs the service's planning
    jobs, scenario parses among them, behind everything else, and may start the load's own
    process after the readers' window)."""


@dataclass
class LoadSeen:
    """What the load saw."""

    statuses: Counter[int] = field(default_factory=Counter)
    health_ms: list[float] = field(default_factory=list)
    """``/v1/health`` answer times (ms) as the monitor saw them."""
    reader_health_ms: list[float] = field(default_factory=list)
    """``/v1/health`` answer times (ms) as the readers saw them, their own process's delays
    within."""
    server_errors: list[str] = field(default_factory=list)
    """Each 5xx (or a request that got no answer): method, path, status, body."""
    streamed: int = 0
    """Messages the stream clients read."""
    cancelled: int = 0

    def percentile_ms(self, q: float, *, readers: bool = False) -> float:
        xs = sorted(self.reader_health_ms if readers else self.health_ms)
        return xs[min(len(xs) - 1, int(q * len(xs)))] if xs else float("nan")


class _Client:
    def __init__(self, client: httpx.AsyncClient, seen: LoadSeen, answer_s: float | None) -> None:
        self.c = client
        self.seen = seen
        self.answer_s = answer_s

    async def request(self, method: str, path: str, **kw: Any) -> httpx.Response | None:
        try:
            r = await self.c.request(method, path, **kw)
        except httpx.HTTPError as err:
            self.seen.server_errors.append(f"{method} {path}: {type(err).__name__}: {err}")
            return None
        self.seen.statuses[r.status_code] += 1
        if r.status_code >= 500:
            self.seen.server_errors.append(f"{method} {path}: {r.status_code} {r.text[:200]}")
        return r


async def _uploads(c: _Client, load: Load) -> None:
    await asyncio.gather(*(_oversized(c, load.upload_bytes) for _ in range(load.uploads)))


async def _oversized(c: _Client, nbytes: int) -> None:
    """POST a scenario of ``nbytes`` as a client such as curl does: the service may answer
    (413) and close before the body is all sent; the answer is read whatever the send met."""
    url = c.c.base_url
    reader, writer = await asyncio.open_connection(url.host, url.port)
    head = (
        f"POST /v1/scenarios HTTP/1.1\r\nHost: {url.host}:{url.port}\r\n"
        f"Authorization: {c.c.headers['Authorization']}\r\n"
        f"Content-Type: application/yaml\r\nContent-Length: {nbytes}\r\n"
        "Connection: close\r\n\r\n"
    )
    chunk = b"#" * (1 << 16)
    try:
        writer.write(head.encode())
        for _ in range(0, nbytes, len(chunk)):
            writer.write(chunk)
            await writer.drain()
    except ConnectionError:
        pass  # answered and closed early: read what it said
    try:
        status_line = await asyncio.wait_for(reader.readline(), c.answer_s)
        status = int(status_line.split()[1])
    except (ConnectionError, TimeoutError, IndexError, ValueError) as err:
        c.seen.server_errors.append(f"POST /v1/scenarios ({nbytes} bytes): no answer ({err!r})")
        return
    finally:
        writer.close()
    c.seen.statuses[status] += 1
    if status >= 500:
        c.seen.server_errors.append(f"POST /v1/scenarios ({nbytes} bytes): {status}")


async def _big_jobs(c: _Client, load: Load) -> None:
    text = yaml.safe_dump(ring_team(load.big_team), sort_keys=False)
    r = await c.request(
        "POST", "/v1/scenarios", content=text, headers={"Content-Type": "application/yaml"}
    )
    if r is None or r.status_code != 201:
        return
    sid = r.json()["id"]
    posted = await asyncio.gather(
        *(
            c.request("POST", "/v1/schedules", json={"scenario_id": sid})
            for _ in range(load.big_jobs)
        )
    )
    jobs = [p.json()["id"] for p in posted if p is not None and p.status_code == 202]
    await asyncio.sleep(load.big_work_s)
    for jid in jobs:
        r = await c.request("DELETE", f"/v1/jobs/{jid}")
        if r is not None and r.status_code == 200:
            c.seen.cancelled += 1


async def _reader(c: _Client, flight_id: str, until: float) -> None:
    paths = ["/v1/health", f"/v1/flights/{flight_id}", f"/v1/flights/{flight_id}/map"]
    k = 0
    while time.monotonic() < until:
        path = paths[k % len(paths)]
        k += 1
        t0 = time.perf_counter()
        r = await c.request("GET", path)
        if path == "/v1/health" and r is not None and r.status_code == 200:
            c.seen.reader_health_ms.append((time.perf_counter() - t0) * 1e3)


async def _stream(c: _Client, flight_id: str, until: float) -> None:
    """Follow the flight's stream until ``until`` (or, where requests wait for their answers
    however long, :attr:`Load.answer_s` None, to the flight's end)."""
    window = None if c.answer_s is None else max(0.0, until - time.monotonic())
    with contextlib.suppress(httpx.HTTPError, TimeoutError):
        async with asyncio.timeout(window):
            async with c.c.stream(
                "GET", f"/v1/flights/{flight_id}/stream",
                headers={"Accept": "text/event-stream"}, timeout=None,
            ) as r:  # fmt: skip
                c.seen.statuses[r.status_code] += 1
                async for line in r.aiter_lines():
                    if line.startswith("event: "):
                        c.seen.streamed += 1
                        if line == "event: end":
                            return


async def apply(url: str, token: str, flight_id: str, load: Load) -> LoadSeen:
    """The load, once each part, readers for :attr:`Load.read_s`; streams as long."""
    seen = LoadSeen()
    limits = httpx.Limits(
        max_connections=load.readers + load.streams + 20, keepalive_expiry=KEEP_ALIVE_S
    )
    headers = {"Authorization": f"Bearer {token}"}
    async with httpx.AsyncClient(
        base_url=url, headers=headers, limits=limits, timeout=load.answer_s
    ) as client:
        c = _Client(client, seen, load.answer_s)
        until = time.monotonic() + load.read_s
        await asyncio.gather(
            _uploads(c, load),
            _big_jobs(c, load),
            *(_reader(c, flight_id, until) for _ in range(load.readers)),
            *(_stream(c, flight_id, until) for _ in range(load.streams)),
        )
    return seen


def _run(url: str, token: str, flight_id: str, load: Load, out: Any) -> None:
    out.put(asyncio.run(apply(url, token, flight_id, load)))


HEALTH_EVERY_S = 0.1
"""How often (wall s) the monitor asks ``/v1/health``."""
KEEP_ALIVE_S = 2.0
"""A kept connection idle this long (wall s) is let go: under the service's 5 s (uvicorn's
default), so that no request goes out on a connection the service is closing at that moment
(a client whose own process stalled some 5 s between requests would lose that race, a read
error that is not the service's)."""


def _monitor(url: str, answer_s: float | None, stop: Any, out: Any) -> None:
    """Ask ``/v1/health`` every :data:`HEALTH_EVERY_S` on one kept connection until ``stop``
    is set; put the answer times (ms) and any failure."""
    times: list[float] = []
    failures: list[str] = []
    limits = httpx.Limits(keepalive_expiry=KEEP_ALIVE_S)
    last_s = time.perf_counter()
    with httpx.Client(base_url=url, timeout=answer_s, limits=limits) as client:
        while not stop.is_set():
            t0 = time.perf_counter()
            try:
                r = client.get("/v1/health")
            except httpx.HTTPError as err:
                failures.append(
                    f"GET /v1/health: {type(err).__name__}: {err} "
                    f"({t0 - last_s:.2f} s after the last answer, {time.perf_counter() - t0:.2f} s"
                    " asking)"
                )
            else:
                if r.status_code == 200:
                    times.append((time.perf_counter() - t0) * 1e3)
                else:
                    failures.append(f"GET /v1/health: {r.status_code} {r.text[:200]}")
            last_s = time.perf_counter()
            stop.wait(max(0.0, HEALTH_EVERY_S - (time.perf_counter() - t0)))
    out.put((times, failures))


@contextlib.contextmanager
def loaded(url: str, token: str, flight_id: str, load: Load) -> Iterator[Any]:
    """The load in a process of its own (spawned) while in the block; ``result()`` of what is
    yielded waits for it to end and gives its :class:`LoadSeen`."""
    ctx = mp.get_context("spawn")
    out, heard, stop = ctx.Queue(), ctx.Queue(), ctx.Event()
    proc = ctx.Process(target=_run, args=(url, token, flight_id, load, out), daemon=True)
    monitor = ctx.Process(target=_monitor, args=(url, load.answer_s, stop, heard), daemon=True)
    monitor.start()
    proc.start()

    class _Handle:
        def result(self, timeout_s: float = 600.0) -> LoadSeen:
            seen: LoadSeen = out.get(timeout=timeout_s)
            proc.join(10.0)
            stop.set()
            seen.health_ms, failures = heard.get(timeout=60.0)
            seen.server_errors += failures
            return seen

    try:
        yield _Handle()
    finally:
        stop.set()
        for p in (proc, monitor):
            if p.is_alive():
                p.join(timeout=1.0)
            if p.is_alive():
                p.kill()

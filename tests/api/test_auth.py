"""Bearer tokens: the routes are listed from the app itself (every HTTP and WebSocket route,
so one added later is checked too): every mutating route refuses a request without a token or
with an unknown one (401, ``WWW-Authenticate: Bearer``) and one with an observe-only token
(403); every read under /v1 but health, ready and the docs refuses one without a token; the
WebSocket stream is closed with 4401 (a token in its URL too), 4403 for another origin.
Tokens never appear in a response or a log line, the admin token made when none is configured
is kept mode 0600, and tokens are compared whole."""

from __future__ import annotations

import asyncio
import hmac
import logging
import re
import stat
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import fastapi.routing
import httpx
import pytest
import pytest_asyncio
import uvicorn
import websockets
from fastapi import FastAPI
from starlette.routing import WebSocketRoute

from gcs.api.app import create_app
from gcs.api.auth import TokenTable
from tests.api.conftest import PAPER, TOKENS, auth, running, settings_for

MUTATING = {"POST", "PUT", "PATCH", "DELETE"}
OPEN = {"/v1/health", "/v1/ready", "/v1/openapi.json", "/v1/docs"}
"""What anyone may read (the process lives, the service is ready, the API's description)."""


@dataclass(frozen=True)
class Endpoint:
    method: str  # "WS" for a WebSocket route
    path: str  # the route's path with every parameter filled in
    scope: str | None = None  # the scope its ``require`` dependency names

    def __str__(self) -> str:
        return f"{self.method} {self.path}"


def _route_contexts(app: FastAPI) -> Iterator[Any]:
    """Every route of the app, those of included routers too (FastAPI from 0.16x keeps
    included routers as one route each; before, their routes were copied into the app's)."""
    contexts = getattr(fastapi.routing, "iter_route_contexts", None)
    yield from contexts(app.routes) if contexts is not None else app.routes


def _filled(path: str) -> str:
    """A concrete path for a route's path: each ``{param}`` an id no resource has (``fmt``
    one the route accepts)."""
    return re.sub(r"{(\w+)(:\w+)?}", lambda m: "plan" if m[1] == "fmt" else f"no-{m[1]}", path)


def _required(route: Any) -> str | None:
    """The scope a route's ``require(scope)`` dependency names (its function is
    ``require_<scope>``), else None."""
    dependant = getattr(route, "dependant", None)
    for dep in [] if dependant is None else dependant.dependencies:
        name = getattr(dep.call, "__name__", "")
        if name.startswith("require_"):
            return str(name.removeprefix("require_"))
    return None


def endpoints() -> list[Endpoint]:
    """Every HTTP method and WebSocket route of the app (HEAD and OPTIONS left out)."""
    app = create_app(settings_for(Path("unused"), "sqlite://"))
    found: set[Endpoint] = set()
    for ctx in _route_contexts(app):
        route, path = ctx.original_route, ctx.path
        if path is None:
            continue  # a mount (the console's static files)
        if isinstance(route, fastapi.routing.APIWebSocketRoute | WebSocketRoute):
            found.add(Endpoint("WS", _filled(path)))
            continue
        scope = _required(route)
        for method in ctx.methods or ():
            if method not in ("HEAD", "OPTIONS"):
                found.add(Endpoint(method, _filled(path), scope))
    return sorted(found, key=str)


ENDPOINTS = endpoints()
WRITES = [e for e in ENDPOINTS if e.method in MUTATING]
READS = [
    e for e in ENDPOINTS if e.method == "GET" and e.path.startswith("/v1/") and e.path not in OPEN
]
SOCKETS = [e for e in ENDPOINTS if e.method == "WS"]


SHARED = pytest.mark.asyncio(loop_scope="module")
"""The mark of the tests on the module's one app (:func:`client`): they run in its loop."""


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def client(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[httpx.AsyncClient]:
    """One app for the module's token checks (they keep nothing: every write is refused or
    invalid), so its routes are built once rather than for each check."""
    folder = tmp_path_factory.mktemp("auth")
    async for c in running(
        create_app(settings_for(folder / "data", f"sqlite:///{folder / 'tcgcs.db'}"))
    ):
        yield c


def test_routes_listed() -> None:
    """The listing sees the routes of the included routers (so the checks below run on them)."""
    names = {str(e) for e in ENDPOINTS}
    assert "POST /v1/flights" in names
    assert "PUT /v1/flights/no-flight_id/team-time" in names
    assert "GET /v1/scenarios/no-scenario_id" in names
    assert "WS /v1/flights/no-flight_id/stream" in names
    assert len(WRITES) >= 9 and len(READS) >= 15, ENDPOINTS


def _unauthorized(r: httpx.Response) -> None:
    assert r.status_code == 401, (r.request.method, r.request.url, r.status_code, r.text)
    assert r.headers.get("www-authenticate") == "Bearer", r.headers
    assert r.json()["detail"]


@pytest.mark.parametrize("endpoint", WRITES, ids=str)
@SHARED
async def test_write_needs_a_token_with_its_scope(
    client: httpx.AsyncClient, endpoint: Endpoint
) -> None:
    async def send(headers: dict[str, str]) -> httpx.Response:
        return await client.request(endpoint.method, endpoint.path, json={}, headers=headers)

    _unauthorized(await send({}))
    _unauthorized(await send({"Authorization": "Bearer not-a-token-of-this-service"}))
    _unauthorized(await send({"Authorization": f"Basic {TOKENS['admin']}"}))
    r = await send(auth("observe"))
    assert r.status_code == 403, (endpoint, r.status_code, r.text)
    assert "scope" in r.json()["detail"]
    # The other working scope is refused too; its own scope, and admin, get past.
    assert endpoint.scope in ("plan", "operate"), endpoint
    other = "operate" if endpoint.scope == "plan" else "plan"
    assert (await send(auth(other))).status_code == 403, endpoint
    for scope in (endpoint.scope, "admin"):
        r = await send(auth(scope))
        assert r.status_code not in (401, 403), (endpoint, scope, r.status_code, r.text)


@pytest.mark.parametrize("endpoint", READS, ids=str)
@SHARED
async def test_read_needs_a_token(client: httpx.AsyncClient, endpoint: Endpoint) -> None:
    _unauthorized(await client.get(endpoint.path))
    _unauthorized(await client.get(endpoint.path, headers={"Authorization": "Bearer nope"}))
    r = await client.get(endpoint.path, headers=auth("observe"))
    assert r.status_code not in (401, 403), (endpoint, r.status_code, r.text)


@SHARED
async def test_open_routes_need_none(client: httpx.AsyncClient) -> None:
    for path in sorted(OPEN):
        r = await client.get(path)
        assert r.status_code == 200, (path, r.status_code, r.text)


async def _served(app: FastAPI) -> AsyncIterator[str]:
    """The app served by uvicorn (as ``python -m gcs serve`` does) on a free loopback port,
    in this process: a WebSocket's close code is what a client receives only through a server
    (a close before the handshake is answered becomes an HTTP 403 there)."""
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning"))
    task = asyncio.create_task(server.serve())
    try:
        async with asyncio.timeout(20):
            while not server.started:
                assert not task.done(), "the server did not start"
                await asyncio.sleep(0.01)
        port = server.servers[0].sockets[0].getsockname()[1]
        yield f"ws://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        await task


@pytest.fixture
async def server_url(app: FastAPI) -> AsyncIterator[str]:
    async for url in _served(app):
        yield url


async def _close_code(
    url: str, headers: dict[str, str] | None = None, subprotocols: list[str] | None = None
) -> int | None:
    async with websockets.connect(
        url,
        additional_headers=headers,
        subprotocols=subprotocols,  # type: ignore[arg-type]
    ) as ws:
        with pytest.raises(websockets.ConnectionClosed):
            async with asyncio.timeout(10):
                await ws.recv()
        return ws.close_code


@pytest.mark.parametrize("endpoint", SOCKETS, ids=str)
async def test_socket_needs_a_token_outside_the_url(server_url: str, endpoint: Endpoint) -> None:
    url = server_url + endpoint.path
    assert await _close_code(url) == 4401
    assert await _close_code(url, {"Authorization": "Bearer not-a-token"}) == 4401
    assert await _close_code(url, subprotocols=["tcgcs.v1", "bearer.not-a-token"]) == 4401
    bad = f"bearer.{TOKENS['admin'][:-1]}"
    assert await _close_code(url, subprotocols=["tcgcs.v1", bad]) == 4401
    # A token in the URL is refused, a good one too (a URL is logged).
    assert await _close_code(url + f"?token={TOKENS['observe']}") == 4401
    # A known token gets past, as a header or as a browser's subprotocol: the flight is then
    # the one that is missing.
    assert await _close_code(url, auth("observe")) == 4404
    good = ["tcgcs.v1", f"bearer.{TOKENS['operate']}"]
    assert await _close_code(url, subprotocols=good) == 4404
    # A page of another origin may not open it; the service's own may.
    host = server_url.removeprefix("ws://")
    assert await _close_code(url, auth("observe") | {"Origin": "http://evil.test"}) == 4403
    assert await _close_code(url, auth("observe") | {"Origin": f"http://{host}"}) == 4404


async def test_an_allowed_origin_may_open_the_stream(tmp_path: Path) -> None:
    settings = settings_for(tmp_path / "data", f"sqlite:///{tmp_path / 'db'}")
    app = create_app(settings.model_copy(update={"allowed_origins": ["https://ops.test"]}))
    async for url in _served(app):
        stream = url + "/v1/flights/nope/stream"
        assert await _close_code(stream, auth() | {"Origin": "https://ops.test"}) == 4404
        assert await _close_code(stream, auth() | {"Origin": "https://other.test"}) == 4403


# -- tokens kept secret -----------------------------------------------------------------------


async def _exercise(client: httpx.AsyncClient) -> list[httpx.Response]:
    """Requests of every kind with every token: accepted, refused, invalid, missing."""
    out: list[httpx.Response] = []
    yaml = {"Content-Type": "application/yaml"}
    for scope in TOKENS:
        h = auth(scope)
        out.append(await client.post("/v1/scenarios", content=PAPER.read_bytes(), headers=h | yaml))
        if out[-1].status_code == 201:
            kept = {"scenario_id": out[-1].json()["id"], "dry_run": True}
            out.append(await client.post("/v1/schedules", json=kept, headers=h))
        out.append(await client.post("/v1/scenarios", content=b"a: [", headers=h | yaml))
        out.append(await client.post("/v1/schedules", json={"scenario_id": "x"}, headers=h))
        out.append(await client.post("/v1/flights", json={"schedule_id": 1}, headers=h))
        out.append(await client.put("/v1/flights/f/team-time", json={}, headers=h))
        out.append(await client.get("/v1/vehicles", headers=h))
        out.append(await client.get("/v1/flights/nope", headers=h))
        out.append(await client.get("/v1/flights/nope/stream", headers=h))
        out.append(await client.get("/metrics", headers=h))
        key = {"Idempotency-Key": "k1"}
        out.append(await client.post("/v1/schedules", json={"scenario_id": "x"}, headers=h | key))
        out.append(await client.post("/v1/schedules", json={"scenario_id": "y"}, headers=h | key))
        token = h["Authorization"].removeprefix("Bearer ")
        for wrong in (token[:-1], token + "x", token.upper()):
            bad = {"Authorization": f"Bearer {wrong}"}
            out.append(await client.post("/v1/schedules", json={}, headers=bad))
    return out


def _leaks(text: str) -> list[str]:
    """Every scope whose token (or a 12-character piece of it) is in ``text``."""
    return [s for s, t in TOKENS.items() if t in text or t[-12:] in text]


@SHARED
async def test_tokens_never_in_responses_or_logs(
    client: httpx.AsyncClient, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.DEBUG):
        responses = await _exercise(client)
    assert {r.status_code for r in responses} >= {200, 201, 202, 401, 403, 404, 422}
    for r in responses:
        seen = r.text + "".join(f"{k}: {v}\n" for k, v in r.headers.items())
        assert not _leaks(seen), (r.request.method, r.request.url, r.status_code, seen)
    for rec in caplog.records:
        line = rec.getMessage() + (rec.exc_text or "")
        assert not _leaks(line), (rec.name, line)


async def test_settings_do_not_show_tokens(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, None)
    assert not _leaks(repr(settings)) and not _leaks(str(settings))


async def test_admin_token_file_when_no_tokens(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    data = tmp_path / "data"
    app = create_app(settings_for(data, f"sqlite:///{tmp_path / 'db'}", tokens=False))
    with caplog.at_level(logging.DEBUG):
        async for client in running(app):
            path = data / "admin.token"
            assert stat.S_IMODE(path.stat().st_mode) == 0o600
            token = path.read_text(encoding="utf-8").strip()
            assert len(token) >= 32
            h = {"Authorization": f"Bearer {token}"}
            r = await client.post("/v1/schedules", json={"scenario_id": "nope"}, headers=h)
            assert r.status_code == 404, r.text  # authorised as admin: the scenario is missing
            _unauthorized(await client.post("/v1/schedules", json={}))
            listed = await client.get("/v1/flights", headers=h)
            assert token not in r.text and token not in listed.text
    lines = [rec.getMessage() for rec in caplog.records]
    assert any("admin.token" in line for line in lines), lines  # where it is, said
    assert not any(token in line for line in lines), lines
    # A second start reads the same token (the file is not rewritten or widened).
    again = create_app(settings_for(data, f"sqlite:///{tmp_path / 'db'}", tokens=False))
    async for _ in running(again):
        assert again.state.tokens.scopes(token) == frozenset({"admin"})
    assert stat.S_IMODE((data / "admin.token").stat().st_mode) == 0o600


# -- compared whole, in constant time ----------------------------------------------------------


def test_token_table_compares_whole_tokens(monkeypatch: pytest.MonkeyPatch) -> None:
    table = TokenTable({"0123456789abcdef": ["admin"], "fedcba9876543210": ["observe"]})
    calls: list[tuple[bytes, bytes]] = []
    real = hmac.compare_digest

    def compare(a: bytes, b: bytes) -> bool:
        calls.append((a, b))
        return real(a, b)

    monkeypatch.setattr(hmac, "compare_digest", compare)  # as gcs.api.auth calls it
    assert table.scopes("0123456789abcdef") == frozenset({"admin"})
    assert len(calls) == 2  # every token compared, whichever matches (no early exit)
    for wrong in ("0123456789abcde", "0", "", "0123456789abcdef0", "0123456789ABCDEF"):
        assert table.scopes(wrong) is None, wrong
    assert table.scopes("fedcba9876543210") == frozenset({"observe"})
    assert all(isinstance(a, bytes) and isinstance(b, bytes) for a, b in calls)


@SHARED
async def test_token_prefix_refused(client: httpx.AsyncClient) -> None:
    admin = TOKENS["admin"]
    for wrong in (admin[:-1], admin[: len(admin) // 2], admin[:1], admin + admin[-1]):
        r = await client.post(
            "/v1/schedules", json={}, headers={"Authorization": f"Bearer {wrong}"}
        )
        _unauthorized(r)


# -- scopes nest, /metrics, security headers ---------------------------------------------------


@pytest.mark.parametrize("endpoint", READS, ids=str)
@SHARED
async def test_plan_and_operate_tokens_read_too(
    client: httpx.AsyncClient, endpoint: Endpoint
) -> None:
    for scope in ("plan", "operate"):
        r = await client.get(endpoint.path, headers=auth(scope))
        assert r.status_code not in (401, 403), (scope, endpoint, r.status_code, r.text)


@SHARED
async def test_metrics_need_a_token(client: httpx.AsyncClient) -> None:
    _unauthorized(await client.get("/metrics"))
    for scope in ("observe", "plan", "operate", "admin"):
        r = await client.get("/metrics", headers=auth(scope))
        assert r.status_code == 200 and "tcgcs_flights" in r.text, (scope, r.status_code)


def _secured(r: httpx.Response) -> None:
    h = r.headers
    assert h.get("x-frame-options") == "DENY", (r.request.url, h)
    assert h.get("x-content-type-options") == "nosniff", (r.request.url, h)
    assert h.get("referrer-policy") == "no-referrer", (r.request.url, h)
    policy = h.get("content-security-policy", "")
    assert "frame-ancestors 'none'" in policy and "default-src 'self'" in policy, policy
    assert "http" not in policy and "unsafe" not in policy, policy


@SHARED
async def test_every_response_carries_the_security_headers(client: httpx.AsyncClient) -> None:
    """Every route, answered or refused, the console's files, a 404 and a 413 alike."""
    for endpoint in [e for e in ENDPOINTS if e.method != "WS"]:
        for headers in ({}, auth("admin")):
            r = await client.request(endpoint.method, endpoint.path, json={}, headers=headers)
            _secured(r)
    for path in ("/", "/ui/", "/ui/js/main.js", "/ui/console.css", "/nowhere", "/v1/docs"):
        _secured(await client.get(path))
    big = await client.post("/v1/scenarios", content=b"x" * (5 * 2**20), headers=auth("plan"))
    assert big.status_code == 413
    _secured(big)

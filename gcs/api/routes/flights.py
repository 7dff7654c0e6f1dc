"""Flights: create, upload, launch, steer (threats, team time, abort, a rehearsal's pauses),
read (snapshot, events, record, report) and the live stream (WebSocket, or SSE with ``Accept:
text/event-stream``)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Any

from fastapi import APIRouter, Depends, Header, Query, Request, Response, WebSocket
from fastapi.responses import FileResponse, StreamingResponse
from starlette.websockets import WebSocketDisconnect

from gcs.api.auth import grants, require
from gcs.api.routes.common import ERRORS, engine_of
from gcs.api.schemas import (
    AbortIn,
    FlightIn,
    LaunchIn,
    PauseIn,
    TeamTimeIn,
    TeamTimeOut,
    ThreatIn,
)
from gcs.service.ended import EndedFlight
from gcs.service.engine import Engine, InvalidInput, NotFound, PreconditionFailed, Rehearsal

router = APIRouter(responses=ERRORS, tags=["flights"])
observe = [Depends(require("observe"))]
operate = [Depends(require("operate"))]

TELEMETRY_WALL_S = 0.5
"""The stream sends every vehicle's position, ETA and error at least this often (wall s)."""


@router.post("/flights", status_code=201, dependencies=operate)
async def create_flight(body: FlightIn, request: Request) -> dict[str, Any]:
    """A flight of a schedule on registered vehicles, or on bundled simulator vehicles
    (``rehearsal``); 409 names a vehicle already in a flight."""
    r = body.rehearsal
    rehearsal = None
    if r is not None:
        rehearsal = Rehearsal(r.speedup, r.wind_m_s, r.wind_from_deg, r.loss, r.seed, r.lockstep)
    engine = engine_of(request)
    flight = await engine.create_flight(
        body.schedule_id, body.vehicles, rehearsal, lockstep=body.lockstep
    )
    return engine.snapshot(flight.id)


@router.get("/flights", dependencies=observe)
async def flights(request: Request) -> list[dict[str, Any]]:
    return engine_of(request).flight_views()


@router.get("/flights/{flight_id}", dependencies=observe)
async def snapshot(flight_id: str, request: Request) -> dict[str, Any]:
    """Everything a UI shows: state, team time and its version, per vehicle position, state,
    ETA and error against its slot, strategy, link; threats in force."""
    return engine_of(request).snapshot(flight_id)


@router.get("/flights/{flight_id}/map", dependencies=observe)
async def flight_map(flight_id: str, request: Request) -> dict[str, Any]:
    """What the map draws, in the scenario's local metres: the area (and the terrain image of
    ``scenario_id``), threats (in force or queued, with when they appear), loiter buffers, each
    vehicle's start, goal, planned route and loiter circles as they are now."""
    return await engine_of(request).flight_map(flight_id)


@router.post("/flights/{flight_id}/upload", status_code=202, dependencies=operate)
async def upload(flight_id: str, request: Request) -> dict[str, Any]:
    """Upload every vehicle's mission (verified); per-vehicle results in the snapshot's
    ``uploads`` and in ``upload`` events."""
    return await engine_of(request).upload(flight_id)


@router.post("/flights/{flight_id}/launch", status_code=202, dependencies=operate)
async def launch(flight_id: str, request: Request, body: LaunchIn | None = None) -> dict[str, Any]:
    """Start the mission at a UTC (or ``delay_s`` from now): each vehicle is launched at its
    takeoff time and the arrivals held."""
    body = body or LaunchIn()
    return await engine_of(request).launch(flight_id, body.start_utc_s, body.delay_s)


@router.post("/flights/{flight_id}/abort", dependencies=operate)
async def abort(flight_id: str, request: Request, body: AbortIn | None = None) -> dict[str, Any]:
    """Abort one vehicle (or all): RTL or LOITER; per vehicle None or why not."""
    body = body or AbortIn()
    return await engine_of(request).abort(flight_id, body.vehicle, body.mode)


@router.post("/flights/{flight_id}/pause", dependencies=operate)
async def pause(flight_id: str, request: Request, body: PauseIn | None = None) -> dict[str, Any]:
    """A rehearsal in lock step waits at mission second ``at_s`` (default: now), before the
    launch too, until resumed: its simulator holds its vehicles where they are, and the
    flight is steered as ever meanwhile. 409: real vehicles (or a simulator on the wall
    clock) cannot wait, or ``at_s`` has passed. The snapshot's ``pause`` says whether it
    waits and the pauses to come."""
    body = body or PauseIn()
    return await engine_of(request).pause(flight_id, body.at_s)


@router.post("/flights/{flight_id}/resume", dependencies=operate)
async def resume(flight_id: str, request: Request) -> dict[str, Any]:
    """A paused rehearsal flies on (its later pauses stay); 409 when it is not paused."""
    return await engine_of(request).resume(flight_id)


@router.post("/flights/{flight_id}/threats", status_code=201, dependencies=operate)
async def add_threat(flight_id: str, body: ThreatIn, request: Request) -> dict[str, Any]:
    """A threat for the flight: re-planned around (the vehicles it touches) when it appears;
    before the launch it is queued."""
    return await engine_of(request).add_threat(flight_id, body.threat, body.at_s)


@router.delete("/flights/{flight_id}/threats/{threat_id}", status_code=204, dependencies=operate)
async def remove_threat(flight_id: str, threat_id: str, request: Request) -> Response:
    await engine_of(request).remove_threat(flight_id, threat_id)
    return Response(status_code=204)


@router.get("/flights/{flight_id}/team-time", dependencies=observe)
async def team_time(flight_id: str, request: Request, response: Response) -> TeamTimeOut:
    out = await engine_of(request).team_time(flight_id)
    response.headers["ETag"] = f'"{out["version"]}"'
    return TeamTimeOut(**out)


@router.put("/flights/{flight_id}/team-time", dependencies=operate)
async def move_team_time(
    flight_id: str,
    body: TeamTimeIn,
    request: Request,
    response: Response,
    if_match: str | None = Header(default=None),
) -> TeamTimeOut:
    """Move the team arrival (mission s). ``If-Match`` with the version read (the ETag of
    GET team-time): stale → 412; a time some vehicle cannot make → 409 with the earliest
    feasible time and that vehicle."""
    version = None
    if if_match is not None:
        try:
            version = int(if_match.strip().strip('"'))
        except ValueError:
            raise PreconditionFailed(f"If-Match: {if_match!r} is not a version") from None
    out = await engine_of(request).move_team_time(flight_id, body.arrival_s, version)
    response.headers["ETag"] = f'"{out["version"]}"'
    return TeamTimeOut(**out)


@router.get("/flights/{flight_id}/events", dependencies=observe)
async def events(
    flight_id: str,
    request: Request,
    after_seq: int = Query(default=0, ge=0, le=2**31),
    limit: int = Query(default=500, ge=1, le=5000),
) -> dict[str, Any]:
    """The flight's events after ``after_seq``, in order (page on with ``next_after_seq``)."""
    page = engine_of(request).events(flight_id, after_seq, limit)
    out = [e.to_json() for e in page]
    return {"events": out, "next_after_seq": out[-1]["seq"] if out else after_seq}


@router.get("/flights/{flight_id}/record", dependencies=observe)
async def record(flight_id: str, request: Request) -> dict[str, Any]:
    """The flight record (``tcgcs-flight/1``) once the flight is over."""
    return await engine_of(request).record(flight_id)


@router.get("/flights/{flight_id}/report/{name}", dependencies=observe)
async def report_file(flight_id: str, name: str, request: Request) -> FileResponse:
    """A file of the flight's report (index.html, arrivals.md, paths.png, ...)."""
    return FileResponse(await engine_of(request).report_file(flight_id, name))


# -- the stream ---------------------------------------------------------------------------------


async def stream(engine: Engine, flight_id: str, after_seq: int) -> AsyncIterator[dict[str, Any]]:
    """A snapshot, then every event after ``after_seq`` in order, with a telemetry batch at
    least every :data:`TELEMETRY_WALL_S`; ends after the flight has (or when this client falls
    so far behind that an event would be lost: reconnect with the last ``seq`` seen)."""
    found = engine.known(flight_id)
    if isinstance(found, EndedFlight):
        # Over before this process started: its snapshot, the events after ``after_seq``
        # from the store, the end.
        yield {"type": "snapshot", "data": found.snapshot}
        for e in engine.events(flight_id, after_seq, 100_000):
            yield {"type": "event", "data": e.to_json()}
        yield {"type": "end", "data": {"state": found.state}}
        return
    flight = found
    bus = flight.bus
    if after_seq < bus.first_kept_seq - 1:
        backlog = engine.events(flight_id, after_seq, 100_000)
    else:
        backlog = []
    yield {"type": "snapshot", "data": engine.snapshot(flight_id)}
    last = after_seq
    for e in backlog:
        last = e.seq
        yield {"type": "event", "data": e.to_json()}
    sub = bus.subscribe(maxsize=10_000, after_seq=last)
    loop = asyncio.get_running_loop()
    next_telemetry = loop.time()
    try:
        while True:
            timeout = max(0.0, next_telemetry - loop.time())
            got = await sub.get_within(timeout)
            if sub.dropped:
                yield {"type": "behind", "data": {"after_seq": last}}
                return
            if got is not None and got.seq > last:
                last = got.seq
                yield {"type": "event", "data": got.to_json()}
            if got is None and sub.closed:
                return
            if loop.time() < next_telemetry:
                continue  # a batch is due only when its time has come, events or not
            next_telemetry = loop.time() + TELEMETRY_WALL_S
            snap = engine.snapshot(flight_id)  # the worker's, told every 0.25 s
            yield {"type": "telemetry", "data": _telemetry(snap)}
            if flight.over:
                # Every event still queued goes out before the end (a stream resumed after
                # the flight is over replays all it missed).
                while (rest := sub.get_nowait()) is not None:
                    if rest.seq > last:
                        last = rest.seq
                        yield {"type": "event", "data": rest.to_json()}
                yield {"type": "end", "data": {"state": flight.state.value}}
                return
    finally:
        sub.close()


def _telemetry(snap: dict[str, Any]) -> dict[str, Any]:
    """A batch: what changes between events (the console's panel needs no snapshot polling:
    the strategy's loiter turns left and the link's mode change without an event)."""
    keys = (
        "id", "state", "east_m", "north_m", "alt_amsl_m", "heading_deg", "airspeed_m_s",
        "commanded_m_s", "eta_s", "error_s", "slot_s", "link_silent", "last_fix_age_s",
        "strategy", "link",
    )  # fmt: skip
    return {
        "t_s": snap["t_s"],
        "state": snap["state"],
        "team_time_s": snap["team_time_s"],
        "team_time_version": snap["team_time_version"],
        "pause": snap.get("pause"),
        "vehicles": [{k: v.get(k) for k in keys} for v in snap["vehicles"]],
    }


@router.get(
    "/flights/{flight_id}/stream",
    dependencies=observe,
    responses={200: {"content": {"text/event-stream": {}}, "description": "SSE"}},
)
async def stream_sse(
    flight_id: str,
    request: Request,
    after_seq: int = Query(default=0, ge=0, le=2**31),
    last_event_id: str | None = Header(default=None),
) -> StreamingResponse:
    """The stream as server-sent events (``event:`` the type, ``id:`` an event's seq)."""
    if "text/event-stream" not in request.headers.get("accept", ""):
        raise InvalidInput("stream: ask with Accept: text/event-stream, or open a WebSocket")
    engine = engine_of(request)
    engine.known(flight_id)
    if last_event_id is not None and last_event_id.isdigit():
        after_seq = max(after_seq, int(last_event_id))

    async def body() -> AsyncIterator[bytes]:
        async for msg in stream(engine, flight_id, after_seq):
            seq = msg["data"].get("seq") if msg["type"] == "event" else None
            head = f"event: {msg['type']}\n" + (f"id: {seq}\n" if seq is not None else "")
            yield (head + f"data: {json.dumps(msg['data'])}\n\n").encode()

    return StreamingResponse(body(), media_type="text/event-stream")


WS_PROTOCOL = "tcgcs.v1"
"""The WebSocket subprotocol of the stream; a browser offers its token beside it as
``bearer.<token>`` (it cannot set headers on a WebSocket)."""
_BEARER = "bearer."


def _ws_credentials(websocket: WebSocket) -> tuple[str | None, str | None]:
    """``(token, refusal)``: the bearer token from ``Authorization`` or the offered
    subprotocols, or why the handshake is refused."""
    if "token" in websocket.query_params:
        # (a close reason holds 123 bytes)
        return None, "token in the URL refused: send Authorization: Bearer, or bearer.<token>"
    scheme, _, token = websocket.headers.get("authorization", "").partition(" ")
    if scheme.lower() == "bearer" and token:
        return token.strip(), None
    for offered in websocket.scope.get("subprotocols", []):
        if offered.startswith(_BEARER):
            return offered[len(_BEARER) :], None
    return None, "a bearer token is required"


def _origin_allowed(websocket: WebSocket) -> bool:
    """A browser's page may open the stream from the service's own origin, or from one the
    settings allow; a client that sends no ``Origin`` is no browser page."""
    origin = websocket.headers.get("origin")
    if origin is None:
        return True
    allowed: tuple[str, ...] = getattr(websocket.app.state, "allowed_origins", ())
    host = websocket.headers.get("host", "")
    return origin in allowed or origin.split("://", 1)[-1] == host


@router.websocket("/flights/{flight_id}/stream")
async def stream_ws(websocket: WebSocket, flight_id: str, after_seq: int = 0) -> None:
    """The stream over a WebSocket: JSON messages ``{"type", "data"}``. The token comes as
    ``Authorization: Bearer``, or from a browser as the subprotocol ``bearer.<token>`` offered
    beside ``tcgcs.v1``; never in the URL. A page from an origin other than the service's own
    (or one the settings allow) is refused."""
    token, refusal = _ws_credentials(websocket)
    scopes = None if token is None else websocket.app.state.tokens.scopes(token)
    offered = websocket.scope.get("subprotocols", [])
    # Accepted before it is closed: a close before the handshake is answered is an HTTP 403
    # (ASGI), and the client would never see the close code.
    await websocket.accept(subprotocol=WS_PROTOCOL if WS_PROTOCOL in offered else None)
    if not _origin_allowed(websocket):
        await websocket.close(code=4403, reason="this origin may not open the stream")
        return
    if scopes is None:
        await websocket.close(code=4401, reason=refusal or "unknown token")
        return
    if not grants(scopes, "observe"):
        await websocket.close(code=4403, reason="this token lacks the 'observe' scope")
        return
    engine: Engine = websocket.app.state.engine
    try:
        engine.known(flight_id)
    except NotFound:
        await websocket.close(code=4404, reason=f"no flight {flight_id!r}")
        return
    try:
        async for msg in stream(engine, flight_id, after_seq):
            await websocket.send_text(json.dumps(msg))
        await websocket.close()
    except WebSocketDisconnect:
        return

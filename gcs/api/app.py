"""``create_app(settings)``: the FastAPI app, with a lifespan that owns the engine.

Errors are one JSON shape (:class:`~gcs.api.schemas.Problem`): the engine's errors by their
status, a body that does not validate as 422 with the field paths. ``/v1/health`` says the
process lives; ``/v1/ready`` that the database answers and the engine runs; ``/metrics`` is
Prometheus text.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Depends, FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from sqlalchemy import text
from starlette.exceptions import HTTPException as StarletteHTTPException

from gcs.api.auth import TokenTable, admin_token_file, require
from gcs.api.bodylimit import BodyLimitMiddleware
from gcs.api.headers import SecurityHeadersMiddleware
from gcs.api.idempotency import IdempotencyMiddleware
from gcs.api.metrics import metrics_text
from gcs.api.routes import flights, resources, tiles
from gcs.api.routes.common import ERRORS
from gcs.api.settings import Settings
from gcs.api.tiles import TileSource
from gcs.service.engine import Engine, Infeasible, InvalidInput, ServiceError, TooBusy
from gcs.service.planning import Limits
from gcs.service.scenariotext import ScenarioLimits
from gcs.service.workers import ahead_of_service
from gcs.store.repository import Store, StoreConflict, StoreError, StoreNotFound

__all__ = ["create_app"]

log = logging.getLogger(__name__)

STATIC = Path(__file__).with_name("static")
"""The operator console (HTML, JS, CSS): no CDN, nothing fetched from outside the service."""


DOCS_PAGE = """<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>tcgcs API</title>
<link rel="icon" href="/ui/favicon.svg">
<link rel="stylesheet" href="/ui/docs/swagger-ui.css">
</head>
<body>
<div id="swagger-ui"></div>
<script src="/ui/docs/swagger-ui-bundle.js"></script>
<script src="/ui/docs/init.js"></script>
</body>
</html>
"""


def create_app(settings: Settings | None = None) -> FastAPI:
    """The app of ``settings``; a configured tile file is checked here, so a bad one stops
    the service before it serves (:class:`~gcs.api.tiles.TileSourceError`)."""
    settings = settings or Settings()
    tile_source = TileSource.open(settings.tiles_mbtiles) if settings.tiles_mbtiles else None

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        tokens = dict(settings.tokens)
        if not tokens:
            token, path = admin_token_file(settings.data_dir)
            tokens = {token: ["admin"]}
            log.warning("no TCGCS_TOKENS: an admin token is in %s", path)
        app.state.tokens = TokenTable(tokens)
        store = Store.open(settings.db_url())
        engine = Engine(
            store,
            settings.data_dir,
            limits=_limits(settings),
            worker_silence_s=settings.worker_silence_s,
            worker_answer_s=settings.worker_answer_s,
            plan_ray=settings.plan_ray,
            spare_worker=settings.spare_worker,
            lockstep_dir=settings.lockstep_dir,
            worker_nice=_worker_nice(settings),
        )
        app.state.engine = engine
        for fid in await engine.resume_kept():
            log.warning("flight %s was running when the service stopped: flying it on", fid)
        app.state.store = store
        try:
            yield
        finally:
            await engine.close()
            store.close()

    app = FastAPI(
        title="tcgcs",
        summary="Time-coordinated ground control for teams of fixed-wing UAVs",
        version="1",
        openapi_url="/v1/openapi.json",
        docs_url=None,  # served below from the packaged Swagger UI (no CDN)
        redoc_url=None,
        lifespan=lifespan,
    )
    app.add_middleware(IdempotencyMiddleware)
    app.add_middleware(BodyLimitMiddleware, max_bytes=settings.max_body_bytes)
    app.add_middleware(SecurityHeadersMiddleware)
    app.state.tiles = tile_source
    app.state.allowed_origins = tuple(settings.allowed_origins)
    _errors(app)
    v1 = APIRouter(prefix="/v1")
    v1.include_router(resources.router)
    v1.include_router(flights.router)
    v1.include_router(tiles.router)

    @v1.get("/health", tags=["ops"])
    async def health() -> dict[str, str]:
        """The process is alive."""
        return {"status": "ok"}

    @v1.get("/ready", tags=["ops"], responses={503: ERRORS[400]})
    async def ready(request: Request) -> Response:
        """The database answers and the engine runs."""
        store: Store = request.app.state.store
        try:
            with store.engine.connect() as conn:
                conn.execute(text("select 1"))
        except Exception as err:
            return JSONResponse({"detail": f"database: {type(err).__name__}"}, 503)
        return JSONResponse({"status": "ready", "flights": len(request.app.state.engine.flights)})

    @v1.get("/docs", include_in_schema=False)
    async def docs() -> HTMLResponse:
        """The API's docs page: Swagger UI from the service's own files."""
        return HTMLResponse(DOCS_PAGE)

    app.include_router(v1)

    app.mount("/ui", StaticFiles(directory=STATIC, html=True), name="ui")

    @app.get("/", include_in_schema=False)
    async def root() -> RedirectResponse:
        return RedirectResponse("/ui/")

    @app.get(
        "/metrics",
        tags=["ops"],
        response_class=Response,
        dependencies=[Depends(require("observe"))],
        responses=ERRORS,
    )
    async def metrics(request: Request) -> Response:
        """Prometheus text: links, messages, malformed frames, commands, uploads, arrival
        errors, event-bus drops, flights (an ``observe`` token: it names vehicles' links)."""
        watch = getattr(request.app.state, "loop_watch", None)
        return Response(metrics_text(request.app.state.engine, watch), media_type="text/plain")

    return app


def _worker_nice(settings: Settings) -> int | None:
    """``TCGCS_WORKER_NICE``, or unset the workers ahead of the service where it may be."""
    if settings.worker_nice is not None:
        return settings.worker_nice
    ahead = ahead_of_service()
    if ahead is None:
        log.info(
            "flight workers run at the service's priority (running them ahead of it needs "
            "CAP_SYS_NICE)"
        )
    return ahead


def _limits(settings: Settings) -> Limits:
    return Limits(
        scenario=ScenarioLimits(
            vehicles=settings.max_vehicles,
            grid_nodes=settings.max_grid_nodes,
            hills=settings.max_hills,
            srtm_dir=settings.srtm_dir,
        ),
        jobs_running=settings.jobs_running,
        jobs_per_owner=settings.jobs_per_token,
        job_time_limit_s=settings.job_time_limit_s,
        job_niceness=settings.job_niceness,
    )


def _errors(app: FastAPI) -> None:
    def problem(status: int, detail: str, **extra: Any) -> JSONResponse:
        return JSONResponse({"detail": detail, **extra}, status_code=status)

    @app.exception_handler(ServiceError)
    async def service_error(request: Request, err: ServiceError) -> JSONResponse:
        if isinstance(err, Infeasible):
            extra = {} if err.latest_s is None else {"latest_feasible_s": err.latest_s}
            return problem(
                err.status,
                str(err),
                earliest_feasible_s=err.earliest_s,
                vehicle=err.vehicle,
                **extra,
            )
        if isinstance(err, InvalidInput):
            return problem(err.status, str(err), errors=err.errors or None)
        if isinstance(err, TooBusy):
            out = problem(err.status, str(err))
            out.headers["Retry-After"] = str(err.retry_after_s)
            return out
        return problem(err.status, str(err))

    @app.exception_handler(StoreError)
    async def store_error(request: Request, err: StoreError) -> JSONResponse:
        if isinstance(err, StoreNotFound):
            return problem(404, str(err))
        if isinstance(err, StoreConflict):
            return problem(409, str(err))
        return problem(400, str(err))

    @app.exception_handler(RequestValidationError)
    async def invalid(request: Request, err: RequestValidationError) -> JSONResponse:
        errors = [
            {
                "loc": [str(x) for x in e.get("loc", ())],
                "msg": str(e.get("msg")),
                "type": e.get("type"),
            }
            for e in err.errors()
        ]
        first = errors[0] if errors else {"loc": [], "msg": "invalid"}
        where = ".".join(first["loc"][1:] if first["loc"][:1] == ["body"] else first["loc"])
        return problem(422, f"{where or 'body'}: {first['msg']}", errors=errors)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, err: StarletteHTTPException) -> JSONResponse:
        if err.status_code == 400 and isinstance(err.__cause__, RecursionError):
            return problem(422, "body: nested too deeply to read")
        return JSONResponse(
            {"detail": str(err.detail)}, status_code=err.status_code, headers=err.headers
        )

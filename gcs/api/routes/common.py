"""What every router uses: the engine of the app, and the error responses documented."""

from __future__ import annotations

from typing import Any

from fastapi import Request

from gcs.api.schemas import Problem
from gcs.service.engine import Engine

__all__ = ["ERRORS", "engine_of"]


def engine_of(request: Request) -> Engine:
    engine: Engine = request.app.state.engine
    return engine


def _problem(text: str) -> dict[str, Any]:
    return {"model": Problem, "description": text}


ERRORS: dict[int | str, dict[str, Any]] = {
    400: _problem("the request cannot be carried out (why, in words)"),
    401: _problem("no token, or an unknown one"),
    403: _problem("the token lacks the route's scope"),
    404: _problem("no such resource (named)"),
    409: _problem("conflicts with the resource's state, or an infeasible time"),
    412: _problem("If-Match names a stale version"),
    422: _problem("a body or parameter that does not validate (the field path)"),
}

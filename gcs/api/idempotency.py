"""``Idempotency-Key`` on POST: a retried request gets the first response again and does
nothing a second time.

Keys are kept in the store (a restarted service, or another one on the same database,
answers them the same: the newest 10,000), for requests with a token the service knows only:
a request without one, or with an unknown one, is answered as if it had no key (its 401 is
never kept, nor does it take a real key's place). Keys are per token (the same key from two
clients is two keys). A request matches the first one by its meaning: its method, path and
body, a JSON body compared as canonical JSON (the same object with other whitespace or key
order is the same request). A key sent again with a different request is a 422; two requests
with one key at once wait for each other (within a process). Answers that say nothing about
the request (401, 403, 429, and 5xx) are not kept: the retry is answered afresh.
"""

from __future__ import annotations

import asyncio
import hashlib
import json

from starlette.middleware.base import BaseHTTPMiddleware, RequestResponseEndpoint
from starlette.requests import Request
from starlette.responses import Response

from gcs.api.auth import TokenTable, token_digest
from gcs.store.repository import Store

__all__ = ["MAX_KEYS", "IdempotencyMiddleware"]

MAX_KEYS = 10_000
_NOT_KEPT = frozenset({401, 403, 429})


class IdempotencyMiddleware(BaseHTTPMiddleware):
    def __init__(self, app: object) -> None:
        super().__init__(app)  # type: ignore[arg-type]
        self._locks: dict[str, tuple[asyncio.Lock, int]] = {}
        """Per key in use: its lock and how many requests hold or wait for it."""

    async def dispatch(self, request: Request, call_next: RequestResponseEndpoint) -> Response:
        key = request.headers.get("idempotency-key")
        if request.method != "POST" or not key:
            return await call_next(request)
        if len(key) > 200:
            return _problem(422, "Idempotency-Key: longer than 200 characters")
        token = _known_token(request)
        if token is None:
            return await call_next(request)  # the route answers 401 (nothing is kept)
        slot = hashlib.sha256(f"{token}\0{key}".encode()).hexdigest()
        digest = _meaning(request.method, request.url.path, await request.body())
        store: Store = request.app.state.store
        lock, users = self._locks.get(slot, (asyncio.Lock(), 0))
        self._locks[slot] = (lock, users + 1)
        try:
            async with lock:
                kept = await asyncio.to_thread(store.kept_answer, slot)
                if kept is not None:
                    if kept.digest != digest:
                        return _problem(
                            422, "Idempotency-Key: already used for a different request"
                        )
                    replayed = {k: v for k, v in kept.headers}
                    replayed["idempotent-replayed"] = "true"
                    return Response(kept.body, kept.status, headers=replayed)
                response = await call_next(request)
                chunks = [c async for c in response.body_iterator]  # type: ignore[attr-defined]
                raw = b"".join(c if isinstance(c, bytes) else c.encode() for c in chunks)
                headers = [
                    (k, v) for k, v in response.headers.items() if k.lower() != "content-length"
                ]
                status = response.status_code
                if status < 500 and status not in _NOT_KEPT:
                    await asyncio.to_thread(
                        store.keep_answer, slot, digest, status, raw, headers, max_keys=MAX_KEYS
                    )
                return Response(raw, status, headers=dict(headers))
        finally:
            lock, users = self._locks[slot]
            if users <= 1:
                del self._locks[slot]
            else:
                self._locks[slot] = (lock, users - 1)


def _known_token(request: Request) -> str | None:
    """A digest of the request's bearer token if the service knows it, else None."""
    scheme, _, token = request.headers.get("authorization", "").partition(" ")
    table: TokenTable | None = getattr(request.app.state, "tokens", None)
    if scheme.lower() != "bearer" or not token or table is None:
        return None
    if table.scopes(token.strip()) is None:
        return None
    return token_digest(token)


def _meaning(method: str, path: str, body: bytes) -> str:
    """What identifies a request: method, path and body (a JSON body as canonical JSON)."""
    try:
        canon = json.dumps(
            json.loads(body), sort_keys=True, separators=(",", ":"), ensure_ascii=False
        ).encode()
    except (ValueError, RecursionError):
        canon = body
    return hashlib.sha256(method.encode() + b"\0" + path.encode() + b"\0" + canon).hexdigest()


def _problem(status: int, detail: str) -> Response:
    return Response(json.dumps({"detail": detail}), status, media_type="application/json")

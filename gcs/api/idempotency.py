"""``Idempotency-Key`` on POST: a retried request gets the first response again and does
nothing a second time.

Keys are per token (the same key from two clients is two keys) and kept for the process's
life (the newest 10,000). A key sent again with a different request is a 422; two requests
with one key at once wait for each other.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
from collections import OrderedDict
from dataclasses import dataclass

from starlette.middleware.base import BaseHTTPMiddleware, RequestResponseEndpoint
from starlette.requests import Request
from starlette.responses import Response

__all__ = ["IdempotencyMiddleware"]

MAX_KEYS = 10_000


@dataclass(frozen=True)
class _Kept:
    digest: str
    status: int
    body: bytes
    headers: tuple[tuple[str, str], ...]


class IdempotencyMiddleware(BaseHTTPMiddleware):
    def __init__(self, app: object) -> None:
        super().__init__(app)  # type: ignore[arg-type]
        self._kept: OrderedDict[str, _Kept] = OrderedDict()
        self._locks: dict[str, asyncio.Lock] = {}

    async def dispatch(self, request: Request, call_next: RequestResponseEndpoint) -> Response:
        key = request.headers.get("idempotency-key")
        if request.method != "POST" or not key:
            return await call_next(request)
        if len(key) > 200:
            return _problem(422, "Idempotency-Key: longer than 200 characters")
        who = request.headers.get("authorization", "")
        slot = hashlib.sha256(f"{who}\0{key}".encode()).hexdigest()
        body = await request.body()
        digest = hashlib.sha256(
            request.method.encode() + b"\0" + request.url.path.encode() + b"\0" + body
        ).hexdigest()
        lock = self._locks.setdefault(slot, asyncio.Lock())
        async with lock:
            kept = self._kept.get(slot)
            if kept is not None:
                if kept.digest != digest:
                    return _problem(422, "Idempotency-Key: already used for a different request")
                headers = dict(kept.headers)
                headers["idempotent-replayed"] = "true"
                return Response(kept.body, kept.status, headers=headers)
            response = await call_next(request)
            chunks = [chunk async for chunk in response.body_iterator]  # type: ignore[attr-defined]
            raw = b"".join(c if isinstance(c, bytes) else c.encode() for c in chunks)
            kept_headers = tuple(
                (k, v) for k, v in response.headers.items() if k.lower() != "content-length"
            )
            if response.status_code < 500:
                self._kept[slot] = _Kept(digest, response.status_code, raw, kept_headers)
                while len(self._kept) > MAX_KEYS:
                    old, _ = self._kept.popitem(last=False)
                    self._locks.pop(old, None)
            return Response(raw, response.status_code, headers=dict(kept_headers))


def _problem(status: int, detail: str) -> Response:
    return Response(json.dumps({"detail": detail}), status, media_type="application/json")

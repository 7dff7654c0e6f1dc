"""Request bodies over the service's size limit are a 413, answered before they are read.

A body that says its length (``Content-Length``) over the limit is refused at once, unread; one
sent in chunks is read here, counted, and refused at the chunk that passes the limit (never
more than the limit is held). Either way no route sees it.

The refusal is sent first, then what the client goes on sending is read and dropped (up to
:data:`LINGER_BYTES`, for at most :data:`LINGER_WALL_S`) before the connection is closed: a
connection closed with a body still arriving is reset, and the client's system would then drop
the 413 it had been sent, so that the client saw a reset instead of the answer.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

__all__ = ["LINGER_BYTES", "LINGER_WALL_S", "BodyLimitMiddleware"]

LINGER_BYTES = 256 << 20
"""The most of a refused body read (and dropped) after the 413."""
LINGER_WALL_S = 30.0
"""The longest (wall s) a refused body is read (and dropped) after the 413."""


class BodyLimitMiddleware:
    """An ASGI middleware: at most ``max_bytes`` of request body."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = _content_length(scope)
        if declared is not None:
            if declared > self.max_bytes:
                await self._refuse(send, f"{declared} bytes", receive)
            else:
                await self.app(scope, receive, send)  # the server holds it to its length
            return
        # Chunked: read up to the limit here, then hand the body on whole.
        chunks: list[bytes] = []
        seen = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                return  # the client went away
            chunk = message.get("body", b"")
            seen += len(chunk)
            if seen > self.max_bytes:
                more = bool(message.get("more_body", False))
                await self._refuse(
                    send, f"more than {self.max_bytes} bytes", receive if more else None
                )
                return
            chunks.append(chunk)
            if not message.get("more_body", False):
                break
        whole: list[Message] = [{"type": "http.request", "body": b"".join(chunks)}]

        async def replay() -> Message:
            return whole.pop() if whole else await receive()

        await self.app(scope, replay, send)

    async def _refuse(self, send: Send, size: str, rest: Receive | None) -> None:
        """The 413, then the rest of the body read and dropped (``rest``: its receive)."""
        detail = f"request body too large: {size}, over the limit of {self.max_bytes} bytes"
        body = json.dumps({"detail": detail}).encode()
        headers: list[Any] = [
            (b"content-type", b"application/json"),
            (b"content-length", str(len(body)).encode()),
            (b"connection", b"close"),
        ]
        await send({"type": "http.response.start", "status": 413, "headers": headers})
        await send({"type": "http.response.body", "body": body, "more_body": rest is not None})
        if rest is None:
            return
        dropped = 0
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(LINGER_WALL_S):
                while dropped <= LINGER_BYTES:
                    message = await rest()
                    if message["type"] != "http.request":
                        break
                    dropped += len(message.get("body", b""))
                    if not message.get("more_body", False):
                        break
        await send({"type": "http.response.body", "body": b""})


def _content_length(scope: Scope) -> int | None:
    for name, value in scope.get("headers", ()):
        if name == b"content-length":
            try:
                return int(value)
            except ValueError:
                return None
    return None

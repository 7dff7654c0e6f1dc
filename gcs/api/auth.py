"""Bearer tokens with scopes: every mutating route needs one (401 without, 403 with a token
that lacks the scope); tokens are compared in constant time and never logged or returned."""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

__all__ = ["TokenTable", "admin_token_file", "grants", "require", "token_digest"]

_bearer = HTTPBearer(auto_error=False, description="a token of the service (TCGCS_TOKENS)")
_credentials = Depends(_bearer)


class TokenTable:
    """The service's tokens and their scopes."""

    def __init__(self, tokens: Mapping[str, Sequence[str]]) -> None:
        self._tokens = [(t.encode(), frozenset(s)) for t, s in tokens.items()]

    def scopes(self, token: str) -> frozenset[str] | None:
        """The token's scopes, or None for an unknown token (every token is compared, in
        constant time, whichever matches)."""
        given = token.encode()
        found: frozenset[str] | None = None
        for known, scopes in self._tokens:
            if hmac.compare_digest(known, given):
                found = scopes
        return found


def token_digest(token: str) -> str:
    """What stands for a token wherever one must be told apart from another (quotas, kept
    answers): its SHA-256 in hex, so that the token itself is kept nowhere."""
    return hashlib.sha256(token.strip().encode()).hexdigest()


def admin_token_file(data_dir: Path) -> tuple[str, Path]:
    """The admin token kept in ``DATA_DIR/admin.token`` (made, mode 0600, the first time)."""
    path = data_dir / "admin.token"
    if path.exists():
        return path.read_text(encoding="utf-8").strip(), path
    data_dir.mkdir(parents=True, exist_ok=True)
    token = secrets.token_urlsafe(32)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(token + "\n")
    return token, path


def grants(scopes: frozenset[str], scope: str) -> bool:
    """Whether a token holding ``scopes`` may do what ``scope`` allows: ``admin`` is every
    scope, and ``plan`` and ``operate`` include ``observe`` (who plans or flies reads)."""
    if scope in scopes or "admin" in scopes:
        return True
    return scope == "observe" and bool(scopes & {"plan", "operate"})


def require(scope: str) -> Callable[..., None]:
    """A route dependency: a bearer token granting ``scope`` (:func:`grants`)."""

    def check(
        request: Request, credentials: HTTPAuthorizationCredentials | None = _credentials
    ) -> None:
        if credentials is None or credentials.scheme.lower() != "bearer":
            raise HTTPException(
                401, "a bearer token is required", headers={"WWW-Authenticate": "Bearer"}
            )
        table: TokenTable = request.app.state.tokens
        scopes = table.scopes(credentials.credentials)
        if scopes is None:
            raise HTTPException(401, "unknown token", headers={"WWW-Authenticate": "Bearer"})
        if not grants(scopes, scope):
            raise HTTPException(403, f"this token lacks the {scope!r} scope")
        request.state.token_id = token_digest(credentials.credentials)  # who asks, for quotas

    check.__name__ = f"require_{scope}"
    return check

"""FastAPI dependencies: a database session per request, the caller's identity, role checks, the live state."""

from __future__ import annotations

import datetime as dt
import hashlib
import threading
import time
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request, status
from fastapi.exceptions import RequestValidationError
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from augnet.console.live import LiveState
from augnet.store import queries as q
from augnet.store.models import Role

# How long a verified token is trusted without asking the store again (see TokenCache).
TOKEN_CACHE_TTL_S = 5.0
TOKEN_CACHE_ENTRIES = 10_000  # distinct live tokens remembered (operators x browsers, with room)

# Names and codes in paths: anything printable the store could hold (NUL is refused by PostgreSQL text).
MAX_KEY_CHARS = 128
Key = Annotated[str, Path(min_length=1, max_length=MAX_KEY_CHARS, pattern=r"^[^\x00]+$")]

bearer = HTTPBearer(auto_error=False, description="API token from POST /api/auth/login")


def db(request: Request) -> Iterator[Session]:
    with request.app.state.sessions() as session:
        yield session


DB = Annotated[Session, Depends(db)]


async def live(request: Request) -> LiveState:  # async: no thread hand-off for a lookup
    return request.app.state.live


Live = Annotated[LiveState, Depends(live)]


@dataclass(frozen=True, slots=True)
class Principal:
    """Who is calling: detached from the session that looked them up."""

    name: str
    role: Role
    token: str


def unauthorized(detail: str) -> HTTPException:
    return HTTPException(status.HTTP_401_UNAUTHORIZED, detail, headers={"WWW-Authenticate": "Bearer"})


def principal_for_token(session: Session, token: str | None) -> Principal | None:
    if not token:
        return None
    op = q.operator_for_token(session, token)
    return None if op is None else Principal(op.name, op.role, token)


class TokenCache:
    """Recently verified tokens -> Principal, so a page polling every second costs no token query.

    Changes made through this console (logout, operator edits) clear it at once; a token revoked, expired or
    an operator disabled by another process stops working within TOKEN_CACHE_TTL_S. Only valid tokens are
    remembered, keyed by their SHA-256 (as the store keeps them)."""

    def __init__(self, ttl_s: float = TOKEN_CACHE_TTL_S, max_entries: int = TOKEN_CACHE_ENTRIES,
                 clock=time.monotonic) -> None:
        self.ttl_s = ttl_s
        self.clock = clock
        self.max_entries = max_entries
        self._entries: OrderedDict[str, tuple[Principal, float]] = OrderedDict()
        self._lock = threading.Lock()

    @staticmethod
    def _key(token: str) -> str:
        return hashlib.sha256(token.encode()).hexdigest()

    def get(self, token: str) -> Principal | None:
        key = self._key(token)
        with self._lock:
            hit = self._entries.get(key)
            if hit is None:
                return None
            if hit[1] < self.clock():
                del self._entries[key]
                return None
            return hit[0]

    def put(self, token: str, who: Principal) -> None:
        with self._lock:
            self._entries[self._key(token)] = (who, self.clock() + self.ttl_s)
            while len(self._entries) > self.max_entries:
                self._entries.popitem(last=False)

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()


def _lookup(sessions, token: str) -> Principal | None:
    with sessions() as session:
        return principal_for_token(session, token)


async def current_principal(request: Request,
                            creds: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)]) -> Principal:
    """The caller, from the token cache on the event loop, or from the store in a worker thread.

    Async on purpose: a cached token costs no thread hand-off, so routes that read only the live state
    answer without leaving the loop (each hand-off waits for the GIL, which the running system's
    threads hold most of the time)."""
    if creds is None:
        raise unauthorized("missing Authorization: Bearer token")
    cache: TokenCache = request.app.state.token_cache
    who = cache.get(creds.credentials)
    if who is None:
        who = await run_in_threadpool(_lookup, request.app.state.sessions, creds.credentials)
        if who is None:
            raise unauthorized("invalid or expired token")
        cache.put(creds.credentials, who)
    return who


def require(role: Role):
    """A dependency admitting callers whose role is `role` or higher (viewer < operator < admin)."""

    async def check(who: Annotated[Principal, Depends(current_principal)]) -> Principal:
        if q.ROLE_RANK[who.role] < q.ROLE_RANK[role]:
            raise HTTPException(status.HTTP_403_FORBIDDEN,
                                f"{role.value} role required; {who.name} is {who.role.value}")
        return who

    check.__name__ = f"require_{role.value}"
    return check


Viewer = Annotated[Principal, Depends(require(Role.VIEWER))]
OperatorRole = Annotated[Principal, Depends(require(Role.OPERATOR))]
Admin = Annotated[Principal, Depends(require(Role.ADMIN))]


def field_error(field: str, message: str, where: str = "body") -> RequestValidationError:
    """A 422 naming one field, shaped like FastAPI's own validation errors."""
    return RequestValidationError([{"type": "value_error", "loc": (where, field), "msg": message,
                                    "input": None}])


def utc(value: dt.datetime | None) -> dt.datetime | None:
    """SQLite hands back naive datetimes for timezone-aware columns; every time the console shows is UTC."""
    if value is None or value.tzinfo is not None:
        return value
    return value.replace(tzinfo=dt.timezone.utc)

"""FastAPI dependencies: a database session per request, the caller's identity, role checks, the live state."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request, status
from fastapi.exceptions import RequestValidationError
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from augnet.console.live import LiveState
from augnet.store import queries as q
from augnet.store.models import Role

# Names and codes in paths: anything printable the store could hold (NUL is refused by PostgreSQL text).
MAX_KEY_CHARS = 128
Key = Annotated[str, Path(min_length=1, max_length=MAX_KEY_CHARS, pattern=r"^[^\x00]+$")]

bearer = HTTPBearer(auto_error=False, description="API token from POST /api/auth/login")


def db(request: Request) -> Iterator[Session]:
    with request.app.state.sessions() as session:
        yield session


DB = Annotated[Session, Depends(db)]


def live(request: Request) -> LiveState:
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


def current_principal(session: DB,
                      creds: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)]) -> Principal:
    if creds is None:
        raise unauthorized("missing Authorization: Bearer token")
    who = principal_for_token(session, creds.credentials)
    if who is None:
        raise unauthorized("invalid or expired token")
    return who


def require(role: Role):
    """A dependency admitting callers whose role is `role` or higher (viewer < operator < admin)."""

    def check(who: Annotated[Principal, Depends(current_principal)]) -> Principal:
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

"""Log in (name + password -> API token), log out, who am I."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Request, Response, status

from augnet.console.deps import DB, Principal, current_principal, unauthorized, utc
from augnet.console.schemas import LoginIn, OperatorOut, TokenOut
from augnet.console.security import LOGIN_TOKEN_LIFETIME, authenticate
from augnet.store import queries as q

router = APIRouter(prefix="/auth", tags=["auth"])
Caller = Annotated[Principal, Depends(current_principal)]


@router.post("/login", response_model=TokenOut, responses={401: {"description": "wrong name or password"}})
def login(body: LoginIn, session: DB) -> TokenOut:
    """Exchange a name and password for a Bearer token valid LOGIN_TOKEN_LIFETIME (12 h)."""
    op = authenticate(session, body.name, body.password)
    if op is None:
        raise unauthorized("wrong name or password")
    token = q.issue_token(session, op, LOGIN_TOKEN_LIFETIME)
    q.audit(session, op.name, "operator.login", op.name)
    session.flush()
    expires = utc(op.tokens[-1].expires_at)
    session.commit()
    return TokenOut(token=token, name=op.name, role=op.role, expires_at=expires)


@router.post("/logout", status_code=status.HTTP_204_NO_CONTENT)
def logout(who: Caller, session: DB, request: Request) -> Response:
    """Revoke the token this request carries."""
    q.revoke_token(session, who.name, who.token)
    session.commit()
    request.app.state.token_cache.clear()
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get("/me", response_model=OperatorOut)
async def me(who: Caller) -> OperatorOut:
    return OperatorOut(name=who.name, role=who.role, enabled=True)

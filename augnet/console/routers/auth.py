"""Log in (name + password -> API token), trade a token for a session token, log out, who am I.

Failed logins are throttled per client address and per name (augnet.console.throttle: exponential back-off,
then 429 with Retry-After, the password not even verified) and audited without the password:
`operator.login_failed` for each wrong password, `operator.login_refused` for the first refusal of each
lock, carrying how many refusals from that address went unrecorded since the last entry (`refused`), so
the log accounts for every attempt without one row per request of a flood. Past ALARM_FAILURES failures
or ALARM_REFUSALS refusals a `console-login-failures` alarm (warning, one open per address) is raised.
The client address is the TCP peer's: a reverse proxy in front would make every operator one address
(X-Forwarded-For is not trusted).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Request, Response, status

from augnet.console.deps import DB, Principal, current_principal, unauthorized, utc
from augnet.console.schemas import LoginIn, OperatorOut, TokenOut
from augnet.console.security import LOGIN_TOKEN_LIFETIME, authenticate
from augnet.console.throttle import ALARM_FAILURES, ALARM_REFUSALS, LoginThrottle
from augnet.store import queries as q
from augnet.store.models import Severity

router = APIRouter(prefix="/auth", tags=["auth"])
Caller = Annotated[Principal, Depends(current_principal)]
ANONYMOUS = "anonymous"  # the audit actor of a failed login: nobody was authenticated
LOGIN_ALARM_KIND = "console-login-failures"


def client_address(request: Request) -> str:
    return request.client.host if request.client else "unknown"


def _alarm(session, address: str, message: str) -> None:
    """Someone is guessing passwords: an alarm on the console's page (one open alarm per address)."""
    q.raise_alarm(session, LOGIN_ALARM_KIND, address[:64], Severity.WARNING, message)


def _issue(session, op) -> TokenOut:
    token = q.issue_token(session, op, LOGIN_TOKEN_LIFETIME)
    session.flush()
    expires = utc(op.tokens[-1].expires_at)
    session.commit()
    return TokenOut(token=token, name=op.name, role=op.role, expires_at=expires)


@router.post("/login", response_model=TokenOut,
             responses={401: {"description": "wrong name or password"},
                        429: {"description": "too many failed logins from this address or for this name; "
                                             "see Retry-After"}})
def login(body: LoginIn, session: DB, request: Request) -> TokenOut:
    """Exchange a name and password for a Bearer token valid LOGIN_TOKEN_LIFETIME (12 h)."""
    throttle: LoginThrottle = request.app.state.login_throttle
    clock = request.app.state.clock
    address = client_address(request)
    verdict = throttle.admit(address, body.name, clock())
    if verdict.retry_after_s:
        if verdict.audit:
            q.audit(session, ANONYMOUS, "operator.login_refused", body.name, address=address,
                    retry_after_s=verdict.retry_after_s, refused=1 + verdict.refused_unaudited)
            if verdict.alarm:
                _alarm(session, address, f"{ALARM_REFUSALS} console logins from {address} refused by the "
                                         f"throttle: a client ignoring Retry-After")
            session.commit()
        raise HTTPException(status.HTTP_429_TOO_MANY_REQUESTS, "too many failed logins; retry later",
                            headers={"Retry-After": str(verdict.retry_after_s)})
    try:
        op = authenticate(session, body.name, body.password)
    except BaseException:
        throttle.abandon(address, body.name)
        raise
    if op is None:
        fail = throttle.failed(address, body.name, clock())
        q.audit(session, ANONYMOUS, "operator.login_failed", body.name, address=address, failures=fail.failures,
                **({"refused": fail.refused_unaudited} if fail.refused_unaudited else {}))
        if fail.alarm:
            _alarm(session, address, f"{ALARM_FAILURES} failed console logins from {address} or for one name "
                                     f"(see the audit log: operator.login_failed)")
        session.commit()
        raise unauthorized("wrong name or password")
    unaudited = throttle.succeeded(address, body.name, clock())
    q.audit(session, op.name, "operator.login", op.name, address=address,
            **({"refused": unaudited} if unaudited else {}))
    return _issue(session, op)


@router.post("/session", response_model=TokenOut,
             responses={409: {"description": "the token already expires: it is not traded for a longer one"}})
def session_token(who: Caller, session: DB) -> TokenOut:
    """A session token (LOGIN_TOKEN_LIFETIME) for a long-lived token (the bootstrap token, or one from
    `augnet console token --hours 0`): the page opened with the state file's token (`#token=`) trades it
    for one, so that logging out revokes the page's own token and never the bootstrap token. A token that
    expires is refused (409): trading it would let a stolen session token renew itself for ever."""
    row = q.token_row(session, who.token)
    if row is None or row.expires_at is not None:
        raise q.Conflict("only a long-lived token is traded for a session token; this one is used as it is")
    op = q.get_operator(session, who.name)
    q.audit(session, who.name, "token.issue", who.name, reason="session",
            lifetime_s=int(LOGIN_TOKEN_LIFETIME.total_seconds()))
    return _issue(session, op)


@router.post("/logout", status_code=status.HTTP_204_NO_CONTENT,
             responses={409: {"description": "the bootstrap token is rotated from the CLI, not logged out"}})
def logout(who: Caller, session: DB, request: Request) -> Response:
    """Revoke the token this request carries (not the bootstrap token: 409)."""
    q.revoke_token(session, who.name, who.token)
    session.commit()
    request.app.state.token_cache.clear()
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get("/me", response_model=OperatorOut)
async def me(who: Caller) -> OperatorOut:
    return OperatorOut(name=who.name, role=who.role, enabled=True)

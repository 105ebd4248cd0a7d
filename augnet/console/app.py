"""The operator console: `create_app(sessions, live)` builds the FastAPI application.

Routes (OpenAPI at /openapi.json, interactive docs at /docs):
  /                     the web page (line diagram, map, trains, alarms, history charts) and /static/*
  /api/auth/...         login (name + password -> Bearer token; throttled), session, logout, me
  /api/operators        accounts (admin)
  /api/stations         registry + live state; add / edit (admin), enable / disable (operator)
  /api/network, /api/network/baselines, /api/line
  /api/trains, /api/trains/{id}
  /api/sections, /api/sections/{id}/{up|down}, .../reorder, .../withdraw, /api/sections/admit (operator as
                        dispatcher; audited)
  /api/alarms, /api/alarms/{id}, /api/alarms/{id}/acknowledge (operator)
  /api/caster, /api/caster/mountpoints, /api/caster/clients, /api/caster/users (changes: admin)
  /api/quality, /api/history/series (the charts' downsampled quality history), /api/audit
  /api/live (websocket), /api/live/snapshot
  /metrics (Prometheus text), /healthz

Hardening (decision 0170): request bodies over MAX_BODY_BYTES get 413 before they are read; 422 answers
never quote submitted values; security headers on every answer (augnet.console.headers); failed logins
throttled and audited (routers/auth.py); the websocket refuses foreign browser origins (routers/live.py).

Roles: viewer reads everything; operator also acknowledges alarms and enables / disables stations; admin
also manages accounts, caster users, mountpoints and stations. Missing or bad token: 401; role too low: 403.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from fastapi import FastAPI, Request, status
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from sqlalchemy.orm import Session, sessionmaker

from augnet.console.deps import TokenCache
from augnet.console.headers import SecurityHeadersMiddleware
from augnet.console.limits import MAX_BODY_BYTES, BodyLimitMiddleware
from augnet.console.live import LiveState, json_safe
from augnet.console.metrics import MetricsMiddleware, RequestMetrics
from augnet.console.routers import alarms, auth, caster, history, network, operators, page, stations, trains
from augnet.console.routers import sections as section_routes
from augnet.console.routers import live as live_feed
from augnet.console.routers.page import STATIC_DIR
from augnet.console.throttle import LoginThrottle
from augnet.store import queries as q

API_PREFIX = "/api"
# Parts of a validation error not sent back: the submitted value itself, and pydantic's documentation link.
ERROR_FIELDS_DROPPED = frozenset({"input", "url"})


def create_app(sessions: sessionmaker[Session], live: LiveState | None = None, *,
               clock: Callable[[], float] = time.monotonic, max_body_bytes: int = MAX_BODY_BYTES,
               allowed_origins: tuple[str, ...] = (), bus=None, sections=None) -> FastAPI:
    """The console over a store (`augnet.store.open_store(url)`) and, when a system runs in this process,
    its live state. Without one the live sections are empty.

    `clock` times the login throttle (tests step it); `allowed_origins` are browser origins besides the
    console's own that may open the live websocket (e.g. "https://console.example.org" behind a proxy);
    `bus` (an `augnet.bus.Bus` on this app's event loop) carries caster user and mountpoint changes to the
    casters (routers/caster.py); `sections` (an `augnet.system.section_service.SectionService` on this app's
    event loop) is the running section register (routers/sections.py; without it the store's last picture)."""
    app = FastAPI(title="augnet console", version="1.0",
                  description="Operator console of the track-side GNSS augmentation network.")
    app.state.sessions = sessions
    app.state.live = live if live is not None else LiveState()
    app.state.request_metrics = RequestMetrics()
    app.state.token_cache = TokenCache()
    app.state.clock = clock
    app.state.login_throttle = LoginThrottle()
    app.state.allowed_origins = frozenset(o.rstrip("/").lower() for o in allowed_origins)
    app.state.bus = bus
    app.state.sections = sections

    for module in (auth, operators, stations, network, trains, section_routes, alarms, caster, history, live_feed):
        app.include_router(module.router, prefix=API_PREFIX)
    app.include_router(page.router)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")

    @app.exception_handler(RequestValidationError)
    async def invalid_request(_request: Request, exc: RequestValidationError) -> JSONResponse:
        """FastAPI's 422 shape (a list of errors, each with the field's loc, type and msg) without the
        submitted values: FastAPI's default quotes each offending `input`, which may be a password or a
        token (and NaN or infinity, which JSON cannot carry). `ctx` is kept: it holds the rule (a length,
        a pattern, a JSON syntax error's position), never the value."""
        errors = [{k: v for k, v in e.items() if k not in ERROR_FIELDS_DROPPED} for e in exc.errors()]
        return JSONResponse({"detail": json_safe(jsonable_encoder(errors))}, status_code=422)

    @app.exception_handler(q.NotFound)
    async def not_found(_request: Request, exc: q.NotFound) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status.HTTP_404_NOT_FOUND)

    @app.exception_handler(q.Conflict)
    async def conflict(_request: Request, exc: q.Conflict) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status.HTTP_409_CONFLICT)

    # last added is outermost: headers on every answer (413 included), metrics count the 413s
    app.add_middleware(BodyLimitMiddleware, max_bytes=max_body_bytes)
    app.add_middleware(MetricsMiddleware, metrics=app.state.request_metrics)
    app.add_middleware(SecurityHeadersMiddleware)
    return app

"""The operator console: `create_app(sessions, live)` builds the FastAPI application.

Routes (OpenAPI at /openapi.json, interactive docs at /docs):
  /                     the web page (line diagram, trains, alarms) and /static/*
  /api/auth/...         login (name + password -> Bearer token), logout, me
  /api/operators        accounts (admin)
  /api/stations         registry + live state; add / edit (admin), enable / disable (operator)
  /api/network, /api/network/baselines, /api/line
  /api/trains, /api/trains/{id}
  /api/alarms, /api/alarms/{id}, /api/alarms/{id}/acknowledge (operator)
  /api/caster, /api/caster/mountpoints, /api/caster/clients, /api/caster/users (changes: admin)
  /api/quality, /api/audit
  /api/live (websocket), /api/live/snapshot
  /metrics (Prometheus text), /healthz

Roles: viewer reads everything; operator also acknowledges alarms and enables / disables stations; admin
also manages accounts, caster users, mountpoints and stations. Missing or bad token: 401; role too low: 403.
"""

from __future__ import annotations

from fastapi import FastAPI, Request, status
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from sqlalchemy.orm import Session, sessionmaker

from augnet.console.deps import TokenCache
from augnet.console.live import LiveState, json_safe
from augnet.console.metrics import MetricsMiddleware, RequestMetrics
from augnet.console.routers import alarms, auth, caster, history, network, operators, page, stations, trains
from augnet.console.routers import live as live_feed
from augnet.console.routers.page import STATIC_DIR
from augnet.store import queries as q

API_PREFIX = "/api"


def create_app(sessions: sessionmaker[Session], live: LiveState | None = None) -> FastAPI:
    """The console over a store (`augnet.store.open_store(url)`) and, when a system runs in this process,
    its live state. Without one the live sections are empty."""
    app = FastAPI(title="augnet console", version="1.0",
                  description="Operator console of the track-side GNSS augmentation network.")
    app.state.sessions = sessions
    app.state.live = live if live is not None else LiveState()
    app.state.request_metrics = RequestMetrics()
    app.state.token_cache = TokenCache()

    for module in (auth, operators, stations, network, trains, alarms, caster, history, live_feed):
        app.include_router(module.router, prefix=API_PREFIX)
    app.include_router(page.router)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")

    @app.exception_handler(RequestValidationError)
    async def invalid_request(_request: Request, exc: RequestValidationError) -> JSONResponse:
        """FastAPI's 422 shape (a list of errors, each with the field's loc), made JSON-safe: an error may
        quote the offending input, and NaN or infinity in a body cannot be written back as JSON."""
        return JSONResponse({"detail": json_safe(jsonable_encoder(exc.errors()))}, status_code=422)

    @app.exception_handler(q.NotFound)
    async def not_found(_request: Request, exc: q.NotFound) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status.HTTP_404_NOT_FOUND)

    @app.exception_handler(q.Conflict)
    async def conflict(_request: Request, exc: q.Conflict) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status.HTTP_409_CONFLICT)

    app.add_middleware(MetricsMiddleware, metrics=app.state.request_metrics)
    return app

"""The web page (static, no external assets), `/metrics` for Prometheus and `/healthz`."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, Request, Response
from fastapi.responses import FileResponse
from starlette.concurrency import run_in_threadpool

from augnet.console import metrics

STATIC_DIR = Path(__file__).resolve().parents[1] / "static"
router = APIRouter()


@router.get("/", include_in_schema=False)
def index() -> FileResponse:
    return FileResponse(STATIC_DIR / "index.html", media_type="text/html")


@router.get("/healthz", tags=["meta"])
async def healthz() -> dict:
    return {"status": "ok"}


def _render(request: Request, caster_snapshot: dict | None) -> str:
    with request.app.state.sessions() as session:
        return metrics.render(request.app.state.request_metrics, request.app.state.live, session, caster_snapshot,
                              request.app.state.login_throttle.counters)


@router.get("/metrics", tags=["meta"], response_class=Response,
            responses={200: {"content": {metrics.CONTENT_TYPE: {}}}})
async def prometheus_metrics(request: Request) -> Response:
    """Prometheus text format: request counts and latency histogram per route, trains by fix state,
    stations, baselines, open alarms, websocket subscribers, caster clients. No authentication (as
    scrapers expect): counts and mountpoint names, no credentials."""
    snap = request.app.state.live.caster()  # on the loop, where the caster runs (see routers/caster.py)
    text = await run_in_threadpool(_render, request, snap)
    return Response(text, media_type=metrics.CONTENT_TYPE)

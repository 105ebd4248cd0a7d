"""The live feed: a websocket of events (with a snapshot first), and the same snapshot over plain HTTP for
pages that cannot keep a websocket open (the page falls back to polling it)."""

from __future__ import annotations

import asyncio
import logging

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from augnet.console.deps import Live, Viewer, principal_for_token

router = APIRouter(tags=["live"])
log = logging.getLogger(__name__)

# Websocket close codes 4000-4999 are the application's (RFC 6455 7.4.2); 4401/4403 mirror HTTP's.
WS_UNAUTHORIZED = 4401
WS_POLICY_VIOLATION = 1008  # RFC 6455 7.4.1: a message (here the handshake) violates the endpoint's policy
MAX_EVENTS_PER_MESSAGE = 500  # a burst is sent as one message of up to this many events


def origin_allowed(origin: str | None, host: str | None, ws_scheme: str, allowed: frozenset[str]) -> bool:
    """May a websocket handshake with this Origin header proceed?

    * no Origin: yes. Browsers always send one on a websocket handshake (RFC 6455 4.1, the Fetch standard),
      so its absence means a non-browser client (a script, `websockets`, curl), which no foreign page can
      drive; it still needs a valid token.
    * the console's own origin (scheme http/https matching ws/wss, host:port equal to the Host header): yes.
    * an origin listed in `allowed` (create_app's allowed_origins, e.g. behind a reverse proxy): yes.
    * anything else, "null" included (sandboxed frames, file:// pages): no - cross-site websocket hijacking.
    """
    if origin is None:
        return True
    origin = origin.strip().rstrip("/").lower()
    if origin in allowed:
        return True
    scheme, sep, netloc = origin.partition("://")
    if not sep or not host:
        return False
    expected_scheme = "https" if ws_scheme == "wss" else "http"
    default_port = {"http": ":80", "https": ":443"}[expected_scheme]
    host = host.strip().lower()
    return scheme == expected_scheme and (netloc == host or netloc + default_port == host
                                          or netloc == host.removesuffix(default_port))


@router.get("/live/snapshot", response_class=JSONResponse)
async def snapshot(who: Viewer, live: Live) -> JSONResponse:
    """Stations, baselines, trains, network summary and line, as the websocket's first message."""
    return JSONResponse(live.snapshot())  # already JSON-safe: no model validation on this hot path


def _check_token(app, token: str | None):
    with app.state.sessions() as session:
        return principal_for_token(session, token)


@router.websocket("/live")
async def live_feed(ws: WebSocket, token: str | None = None) -> None:
    """Events as JSON messages `{"events": [...]}`; the first carries one event of type "snapshot".
    The token comes as the `token` query parameter (browsers cannot set headers on a websocket);
    without a valid one the socket is closed with code 4401. A handshake from a foreign browser origin
    is refused before it is accepted (HTTP 403; see origin_allowed)."""
    if not origin_allowed(ws.headers.get("origin"), ws.headers.get("host"), ws.url.scheme,
                          ws.app.state.allowed_origins):
        await ws.close(code=WS_POLICY_VIOLATION)  # before accept: uvicorn answers the handshake 403
        return
    await ws.accept()
    who = await run_in_threadpool(_check_token, ws.app, token)
    if who is None:
        await ws.close(code=WS_UNAUTHORIZED, reason="invalid or missing token")
        return
    live = ws.app.state.live
    queue = live.subscribe()

    async def pump() -> None:
        await ws.send_json({"events": [live.snapshot()]})
        while True:
            events = [await queue.get()]
            while len(events) < MAX_EVENTS_PER_MESSAGE:
                try:
                    events.append(queue.get_nowait())
                except asyncio.QueueEmpty:
                    break
            await ws.send_json({"events": events})

    async def watch() -> None:  # client messages are ignored; this notices the client leaving
        while (await ws.receive())["type"] != "websocket.disconnect":
            pass

    tasks = [asyncio.ensure_future(pump()), asyncio.ensure_future(watch())]
    try:
        done, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in done:
            exc = task.exception()
            if exc is not None and not isinstance(exc, (WebSocketDisconnect, RuntimeError, OSError)):
                log.warning("live feed ended: %r", exc)
    finally:
        for task in tasks:
            task.cancel()
        live.unsubscribe(queue)

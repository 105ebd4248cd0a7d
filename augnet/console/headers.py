"""Security headers on every HTTP response: an ASGI middleware (outermost, so 401, 413 and 422 carry them too).

The page (static/index.html) loads one script and one stylesheet of its own, sets every value with
textContent and styles with classes: its Content-Security-Policy allows only same-origin script, style,
images and connections, no inline script or style, no framing. The websocket to the page's own host is
listed explicitly (ws:// and wss://): CSP 3 lets 'self' match it, older browsers do not.
FastAPI's interactive docs (/docs, /redoc) load Swagger UI / ReDoc from a CDN with an inline start script;
they get their own, looser policy (they hold no token unless the reader pastes one).
API responses (/api/...) carry `Cache-Control: no-store`: they carry tokens (login) or operational data
behind a token, which no browser or proxy cache should keep.
"""

from __future__ import annotations

import re

from starlette.datastructures import MutableHeaders

PAGE_CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
            "connect-src 'self'{ws}; base-uri 'none'; form-action 'self'; frame-ancestors 'none'")
DOCS_CSP = ("default-src 'none'; script-src 'self' 'unsafe-inline' https://cdn.jsdelivr.net; "
            "style-src 'self' 'unsafe-inline' https://cdn.jsdelivr.net https://fonts.googleapis.com; "
            "font-src https://fonts.gstatic.com; img-src 'self' data: https://fastapi.tiangolo.com "
            "https://cdn.redoc.ly; connect-src 'self'; worker-src blob:; base-uri 'none'; frame-ancestors 'none'")
DOCS_PATHS = ("/docs", "/redoc")
COMMON_HEADERS = {
    "X-Frame-Options": "DENY",  # for browsers without CSP frame-ancestors
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",  # the page's URL may carry #token=... (fragments are not sent, but be sure)
}
NO_STORE_PREFIX = "/api/"
# A Host header fit to be quoted in the policy (a name or an address, a port): anything else is left out.
HOST_RE = re.compile(r"^[A-Za-z0-9.-]+(:\d{1,5})?$|^\[[0-9A-Fa-f:.]+\](:\d{1,5})?$")


def content_security_policy(path: str, host: str | None) -> str:
    if path.startswith(DOCS_PATHS):
        return DOCS_CSP
    ws = f" ws://{host} wss://{host}" if host and HOST_RE.match(host) else ""
    return PAGE_CSP.format(ws=ws)


class SecurityHeadersMiddleware:
    def __init__(self, app) -> None:
        self.app = app

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        path = scope.get("path", "")
        host = next((v.decode("latin-1") for k, v in scope["headers"] if k == b"host"), None)

        async def with_headers(message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                for name, value in COMMON_HEADERS.items():
                    headers[name] = value
                headers["Content-Security-Policy"] = content_security_policy(path, host)
                if path.startswith(NO_STORE_PREFIX):
                    headers["Cache-Control"] = "no-store"
            await send(message)

        await self.app(scope, receive, with_headers)

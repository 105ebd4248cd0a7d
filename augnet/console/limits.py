"""The request body limit: an ASGI middleware answering 413 before a large body is read.

A declared Content-Length over the limit is refused before the app sees the request (nothing of the body
is read: uvicorn pauses reading the socket while the app does not consume it, and closes the connection
after the answer). A chunked body without a length is counted while it is read and refused the moment it
passes the limit, before any JSON parsing; no part of it is echoed.
"""

from __future__ import annotations

import json

from starlette.exceptions import HTTPException

# Largest request body [bytes]. The console's biggest request (a station or operator edit) is a few hundred
# bytes; 64 KiB leaves a hundredfold margin (Django refuses forms over 2.5 MiB, nginx buffers 16 KiB of a body
# in memory before spilling to disk; the console has no uploads, so it refuses instead of spilling).
MAX_BODY_BYTES = 64 * 1024
TOO_LARGE = 413


class BodyTooLarge(HTTPException):
    def __init__(self, limit: int) -> None:
        super().__init__(TOO_LARGE, f"request body over {limit} bytes")


class BodyLimitMiddleware:
    def __init__(self, app, max_bytes: int = MAX_BODY_BYTES) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def _refuse(self, send, status: int, detail: str) -> None:
        body = json.dumps({"detail": detail}).encode()
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = [v for k, v in scope["headers"] if k == b"content-length"]
        if declared:
            try:
                length = int(declared[0])
            except ValueError:
                await self._refuse(send, 400, "invalid Content-Length")
                return
            if length > self.max_bytes:
                await self._refuse(send, TOO_LARGE, f"request body over {self.max_bytes} bytes")
                return
        received = 0

        async def counted_receive():
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    raise BodyTooLarge(self.max_bytes)  # FastAPI re-raises HTTPException from body reading
            return message

        await self.app(scope, counted_receive, send)

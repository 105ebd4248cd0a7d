"""Serve the console from a background thread (for `augnet up` and tests): uvicorn on its own event loop."""

from __future__ import annotations

import threading
import time

import uvicorn
from fastapi import FastAPI

STARTUP_TIMEOUT_S = 15.0
SHUTDOWN_TIMEOUT_S = 10.0


class ConsoleThread:
    """`with ConsoleThread(app) as ct:` -> the console listening on `ct.url` (port 0 picks a free port)."""

    def __init__(self, app: FastAPI, host: str = "127.0.0.1", port: int = 0, log_level: str = "warning") -> None:
        self.host = host
        self.port = port
        self.server = uvicorn.Server(uvicorn.Config(app, host=host, port=port, log_level=log_level,
                                                    ws="auto", lifespan="off"))
        self._thread = threading.Thread(target=self.server.run, name="augnet-console", daemon=True)

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def start(self) -> "ConsoleThread":
        self._thread.start()
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        while not self.server.started:
            if not self._thread.is_alive():
                raise RuntimeError(f"console did not start on {self.host}:{self.port}")
            if time.monotonic() > deadline:
                self.stop()
                raise TimeoutError(f"console not listening after {STARTUP_TIMEOUT_S} s")
            time.sleep(0.01)
        self.port = self.server.servers[0].sockets[0].getsockname()[1]
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self._thread.join(timeout=SHUTDOWN_TIMEOUT_S)

    def __enter__(self) -> "ConsoleThread":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

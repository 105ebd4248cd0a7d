"""The one exception the NTRIP wire cores raise (it carries the HTTP status to answer with, h11 style), and
the one a stream factory raises to refuse a client (the caster and augnet's centre both import it)."""

from __future__ import annotations


class NtripProtocolError(Exception):
    """The peer broke the protocol. `status` is the HTTP status to answer with (400, 431, 501, ...)."""

    def __init__(self, status: int, reason: str) -> None:
        super().__init__(f"{status}: {reason}")
        self.status = status
        self.reason = reason


class StreamRefused(Exception):
    """A VRS stream factory will not serve this client: `reason` for the log, `data` for the client (stream
    bytes, e.g. an RTCM 1029 text message saying why)."""

    def __init__(self, reason: str, data: bytes = b"") -> None:
        super().__init__(reason)
        self.reason = reason
        self.data = data

"""The one exception the NTRIP wire cores raise: it carries the HTTP status to answer with (h11 style)."""

from __future__ import annotations


class NtripProtocolError(Exception):
    """The peer broke the protocol. `status` is the HTTP status to answer with (400, 431, 501, ...)."""

    def __init__(self, status: int, reason: str) -> None:
        super().__init__(f"{status}: {reason}")
        self.status = status
        self.reason = reason

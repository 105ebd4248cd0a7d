"""The bus interface and the subject rules both implementations share."""

from __future__ import annotations

import abc
import re
from dataclasses import dataclass

# NATS subject tokens: no whitespace, no dots inside a token; wildcards only as whole tokens.
_TOKEN = re.compile(r"^[^\s.*>]+$")


class BusError(RuntimeError):
    pass


@dataclass(frozen=True)
class Message:
    subject: str
    payload: bytes
    seq: int  # per-subscription sequence number, starting at 1 (gaps mean dropped messages)


def validate_subject(subject: str, wildcards: bool = False) -> None:
    tokens = subject.split(".")
    for i, tok in enumerate(tokens):
        if wildcards and (tok == "*" or (tok == ">" and i == len(tokens) - 1)):
            continue
        if not _TOKEN.match(tok):
            raise BusError(f"invalid subject {subject!r}: token {tok!r}")


def subject_matches(pattern: str, subject: str) -> bool:
    """NATS matching: `*` matches one token, a final `>` one or more."""
    p = pattern.split(".")
    s = subject.split(".")
    for i, tok in enumerate(p):
        if tok == ">":
            return len(s) > i
        if i >= len(s) or (tok != "*" and tok != s[i]):
            return False
    return len(p) == len(s)


class Subscription(abc.ABC):
    subject: str
    dropped: int  # messages lost because this subscriber fell behind its bound

    @abc.abstractmethod
    async def next(self, timeout: float | None = None) -> Message:
        """The next message; raises TimeoutError after timeout seconds."""

    @abc.abstractmethod
    async def close(self) -> None: ...

    def __aiter__(self):
        return self

    async def __anext__(self) -> Message:
        return await self.next()


class Bus(abc.ABC):
    @abc.abstractmethod
    async def publish(self, subject: str, payload: bytes) -> None: ...

    @abc.abstractmethod
    async def subscribe(self, subject: str, max_pending: int = 1000) -> Subscription:
        """Messages published on matching subjects from now on; past max_pending unread ones the oldest
        are dropped and counted (a slow consumer must never block the publisher)."""

    @abc.abstractmethod
    async def close(self) -> None: ...

    async def __aenter__(self):
        return self

    async def __aexit__(self, *exc):
        await self.close()

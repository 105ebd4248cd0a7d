"""The in-process bus: asyncio queues, one per subscription, for a single-process deployment."""

from __future__ import annotations

import asyncio
import collections

from augnet.bus.core import Bus, BusError, Message, Subscription, subject_matches, validate_subject


class _InProcessSubscription(Subscription):
    def __init__(self, bus: InProcessBus, subject: str, max_pending: int):
        self.subject = subject
        self.dropped = 0
        self._bus = bus
        self._pending: collections.deque[Message] = collections.deque()
        self._max_pending = max_pending
        self._seq = 0
        self._wakeup = asyncio.Event()
        self._closed = False

    def _deliver(self, subject: str, payload: bytes) -> None:
        self._seq += 1
        if len(self._pending) >= self._max_pending:
            self._pending.popleft()
            self.dropped += 1
        self._pending.append(Message(subject, payload, self._seq))
        self._wakeup.set()

    async def next(self, timeout: float | None = None) -> Message:
        while not self._pending:
            if self._closed:
                raise BusError("subscription closed")
            self._wakeup.clear()
            await asyncio.wait_for(self._wakeup.wait(), timeout)
        return self._pending.popleft()

    async def close(self) -> None:
        self._closed = True
        self._wakeup.set()
        self._bus._subs.discard(self)


class InProcessBus(Bus):
    def __init__(self) -> None:
        self._subs: set[_InProcessSubscription] = set()
        self._closed = False

    async def publish(self, subject: str, payload: bytes) -> None:
        if self._closed:
            raise BusError("bus closed")
        validate_subject(subject)
        for sub in list(self._subs):
            if subject_matches(sub.subject, subject):
                sub._deliver(subject, bytes(payload))

    async def subscribe(self, subject: str, max_pending: int = 1000) -> Subscription:
        validate_subject(subject, wildcards=True)
        sub = _InProcessSubscription(self, subject, max_pending)
        self._subs.add(sub)
        return sub

    async def close(self) -> None:
        self._closed = True
        for sub in list(self._subs):
            await sub.close()

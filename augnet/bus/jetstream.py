"""The correction bus on NATS JetStream, for several caster nodes and a national network.

Messages go into one stream (`AUGNET`, subjects `augnet.>`), kept for a short time so a caster node that
restarts can catch up; each subscription is an ephemeral ordered push consumer delivering new messages only
(a VRS stream wants the newest correction model, not history).
"""

from __future__ import annotations

import asyncio
import contextlib

import nats
from nats.js.api import DeliverPolicy, RetentionPolicy, StorageType, StreamConfig

from augnet.bus.core import Bus, BusError, Message, Subscription, validate_subject

STREAM_NAME = "AUGNET"
STREAM_SUBJECTS = ["augnet.>"]
# Correction models are worth little after a minute (rovers need them < 5 s old; network-rtk.md).
STREAM_MAX_AGE_S = 300.0
STREAM_MAX_BYTES = 512 * 1024 * 1024


class _JetStreamSubscription(Subscription):
    def __init__(self, subject: str, max_pending: int):
        self.subject = subject
        self.dropped = 0
        self._queue: asyncio.Queue[Message] = asyncio.Queue()
        self._max_pending = max_pending
        self._seq = 0
        self._sub = None

    async def _on_message(self, msg) -> None:
        self._seq += 1
        if self._queue.qsize() >= self._max_pending:
            self._queue.get_nowait()
            self.dropped += 1
        self._queue.put_nowait(Message(msg.subject, bytes(msg.data), self._seq))

    async def next(self, timeout: float | None = None) -> Message:
        return await asyncio.wait_for(self._queue.get(), timeout)

    async def close(self) -> None:
        if self._sub is not None:
            with contextlib.suppress(Exception):
                await self._sub.unsubscribe()
            self._sub = None


class JetStreamBus(Bus):
    def __init__(self, nc, js):
        self._nc = nc
        self._js = js
        self._subs: list[_JetStreamSubscription] = []

    @classmethod
    async def connect(cls, url: str, connect_timeout_s: float = 2.0) -> JetStreamBus:
        try:
            nc = await nats.connect(url, connect_timeout=connect_timeout_s, max_reconnect_attempts=3,
                                    allow_reconnect=True)
        except Exception as exc:  # nats raises several unrelated types for an unreachable server
            raise BusError(f"cannot connect to NATS at {url}: {exc}") from exc
        js = nc.jetstream()
        config = StreamConfig(name=STREAM_NAME, subjects=STREAM_SUBJECTS, retention=RetentionPolicy.LIMITS,
                              storage=StorageType.FILE, max_age=STREAM_MAX_AGE_S, max_bytes=STREAM_MAX_BYTES)
        try:
            await js.add_stream(config)
        except Exception:
            await js.update_stream(config)
        return cls(nc, js)

    async def publish(self, subject: str, payload: bytes) -> None:
        validate_subject(subject)
        if not subject.startswith("augnet."):
            raise BusError(f"subject {subject!r} is outside the augnet stream (augnet.>)")
        await self._js.publish(subject, bytes(payload))

    async def subscribe(self, subject: str, max_pending: int = 1000) -> Subscription:
        validate_subject(subject, wildcards=True)
        sub = _JetStreamSubscription(subject, max_pending)
        sub._sub = await self._js.subscribe(subject, cb=sub._on_message, ordered_consumer=True,
                                            deliver_policy=DeliverPolicy.NEW)
        self._subs.append(sub)
        return sub

    async def close(self) -> None:
        for sub in self._subs:
            await sub.close()
        with contextlib.suppress(Exception):
            await self._nc.drain()

"""Thin asyncio transports for cycle-driven RSSP-I nodes: UDP (as deployed) and length-prefixed TCP.

A *node* is anything with `cycle(now_s) -> list[bytes]` and `receive(datagram, now_s)`: CentreRbcLink,
RbcSimulator, OnboardAtpLink, AtpSimulator, or a bare adapter around an Endpoint (`EndpointNode`).
The transport owns the socket and the main-cycle clock and nothing else.

- The cycle loop keeps deadlines on a fixed grid (t0 + k * cycle), so the cycle does not drift with
  scheduling jitter; a cycle that starts more than one cycle late is counted as an overrun and run
  once (a safety protocol must not catch up with a burst of cycles: TC would run ahead of time).
- UDP: one RSSP-I frame per datagram, as in the field captures (ports 50000/50001). With `redundant`
  addresses every frame also goes out on the second network, as the captured devices do (the same
  frames from two sources on two ports); the receiver keeps the first copy and drops the other as a
  repeat. Datagrams from hosts other than the configured peers are counted and dropped before the
  protocol sees them.
- TCP: RSSP-I itself is datagram-shaped; on a stream each frame is preceded by its length as a u16,
  little-endian like RSSP-I (our choice; the field captures we have are UDP only). RSSP-I frames are
  also self-delimiting (type + SDS), but a length prefix lets a receiver skip a frame that fails its
  CRC without guessing where the next begins. A length of 0 or above MAX_FRAME_BYTES means the stream
  is out of step and the connection is closed; the client reconnects and RSSP-I resynchronises.
- Handlers never let an exception kill the loop: it is counted in `stats["handler_error"]`.
"""

from __future__ import annotations

import asyncio
import logging
import struct
import time
from collections import Counter
from typing import Callable, Protocol

from rssp1.frames import MAX_FRAME_BYTES

log = logging.getLogger(__name__)
LENGTH_PREFIX = struct.Struct("<H")
RECONNECT_DELAY_S = 0.2  # client reconnect back-off; a few cycles, so resync starts promptly


class Node(Protocol):
    def cycle(self, now_s: float) -> list[bytes]: ...

    def receive(self, datagram: bytes, now_s: float | None = None) -> None: ...


class EndpointNode:
    """Adapts a bare Endpoint: `payload()` gives each cycle's data, `on_event` sees every event."""

    def __init__(self, endpoint, payload: Callable[[], bytes | None] = lambda: b"", on_event=None) -> None:
        self.endpoint = endpoint
        self.payload = payload
        self.on_event = on_event or (lambda event, now_s: None)

    def cycle(self, now_s: float) -> list[bytes]:
        frames, events = self.endpoint.cycle(self.payload())
        for e in events:
            self.on_event(e, now_s)
        return frames

    def receive(self, datagram: bytes, now_s: float | None = None) -> None:
        for e in self.endpoint.receive(datagram):
            self.on_event(e, now_s)


class LengthPrefixedDecoder:
    """Sans-IO: bytes in, whole frames out; `feed` raises StreamOutOfStep on an impossible length."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        self._buf += data
        frames = []
        while len(self._buf) >= LENGTH_PREFIX.size:
            (n,) = LENGTH_PREFIX.unpack_from(self._buf, 0)
            if n == 0 or n > MAX_FRAME_BYTES:
                raise StreamOutOfStep(f"length prefix {n}")
            if len(self._buf) < LENGTH_PREFIX.size + n:
                break
            frames.append(bytes(self._buf[LENGTH_PREFIX.size : LENGTH_PREFIX.size + n]))
            del self._buf[: LENGTH_PREFIX.size + n]
        return frames


class StreamOutOfStep(ValueError):
    pass


def length_prefixed(frame: bytes) -> bytes:
    return LENGTH_PREFIX.pack(len(frame)) + frame


class _CycleLoop:
    def __init__(self, node: Node, cycle_s: float, clock: Callable[[], float]) -> None:
        self.node = node
        self.cycle_s = cycle_s
        self.clock = clock
        self.stats: Counter[str] = Counter()
        self._stop = asyncio.Event()

    def _receive(self, data: bytes) -> None:
        try:
            self.node.receive(bytes(data), self.clock())
            self.stats["rx"] += 1
        except Exception:  # a service never crashes on input
            self.stats["handler_error"] += 1
            log.exception("RSSP-I receive handler failed")

    async def _run(self, send: Callable[[bytes], None], cycles: int | None) -> None:
        start = self.clock()
        k = 0
        while not self._stop.is_set() and (cycles is None or k < cycles):
            now = self.clock()
            try:
                frames = self.node.cycle(now)
            except Exception:
                self.stats["handler_error"] += 1
                log.exception("RSSP-I cycle handler failed")
                frames = []
            for frame in frames:
                send(frame)
            self.stats["cycles"] += 1
            k += 1
            deadline = start + k * self.cycle_s
            now = self.clock()
            if now > deadline + self.cycle_s:  # overrun: skip to the next grid point, run once
                self.stats["overruns"] += 1
                k = int((now - start) / self.cycle_s) + 1
                deadline = start + k * self.cycle_s
            try:
                await asyncio.wait_for(self._stop.wait(), max(0.0, deadline - self.clock()))
            except asyncio.TimeoutError:
                pass

    def stop(self) -> None:
        self._stop.set()


class UdpLink(_CycleLoop, asyncio.DatagramProtocol):
    """A node on a UDP socket, cycling every `cycle_s`."""

    def __init__(self, node: Node, cycle_s: float, remote: tuple[str, int], *,
                 redundant: list[tuple[str, int]] = (), accept_from: set[str] | None = None,  # type: ignore[assignment]
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(node, cycle_s, clock)
        self.remote = remote
        self.redundant = list(redundant)
        self.accept_from = accept_from if accept_from is not None else {remote[0], *(r[0] for r in self.redundant)}
        self.transport: asyncio.DatagramTransport | None = None

    @classmethod
    async def open(cls, node: Node, cycle_s: float, local: tuple[str, int], remote: tuple[str, int], **kw) -> "UdpLink":
        loop = asyncio.get_running_loop()
        link = cls(node, cycle_s, remote, **kw)
        await loop.create_datagram_endpoint(lambda: link, local_addr=local)
        return link

    @property
    def local_address(self) -> tuple[str, int]:
        assert self.transport is not None
        return self.transport.get_extra_info("sockname")[:2]

    def connection_made(self, transport) -> None:  # type: ignore[override]
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        if addr[0] not in self.accept_from:
            self.stats["foreign_source"] += 1
            return
        self._receive(data)

    def error_received(self, exc: Exception) -> None:  # e.g. ICMP port unreachable while the peer starts
        self.stats["socket_error"] += 1

    def _send(self, frame: bytes) -> None:
        if self.transport is not None:
            for remote in (self.remote, *self.redundant):
                self.transport.sendto(frame, remote)
                self.stats["tx"] += 1

    async def run(self, cycles: int | None = None) -> None:
        await self._run(self._send, cycles)

    def close(self) -> None:
        self.stop()
        if self.transport is not None:
            self.transport.close()


class TcpLink(_CycleLoop):
    """A node over TCP with length-prefixed frames; `serve` (one peer at a time) or `connect` (reconnects)."""

    def __init__(self, node: Node, cycle_s: float, *, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(node, cycle_s, clock)
        self._writer: asyncio.StreamWriter | None = None
        self._server: asyncio.base_events.Server | None = None
        self._tasks: list[asyncio.Task] = []

    async def serve(self, host: str, port: int) -> tuple[str, int]:
        self._server = await asyncio.start_server(self._handle, host, port)
        return self._server.sockets[0].getsockname()[:2]

    async def connect(self, host: str, port: int) -> None:
        self._tasks.append(asyncio.create_task(self._connect_forever(host, port)))

    async def _connect_forever(self, host: str, port: int) -> None:
        while not self._stop.is_set():
            try:
                reader, writer = await asyncio.open_connection(host, port)
            except OSError:
                self.stats["connect_failed"] += 1
                await asyncio.sleep(RECONNECT_DELAY_S)
                continue
            await self._handle(reader, writer)
            await asyncio.sleep(RECONNECT_DELAY_S)

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self._writer is not None:  # one peer per link: a second connection is refused
            self.stats["refused_second_peer"] += 1
            writer.close()
            return
        self._writer = writer
        self.stats["connections"] += 1
        decoder = LengthPrefixedDecoder()
        try:
            while not self._stop.is_set():
                data = await reader.read(4096)
                if not data:
                    break
                for frame in decoder.feed(data):
                    self._receive(frame)
        except StreamOutOfStep:
            self.stats["stream_out_of_step"] += 1
        except (ConnectionError, OSError):
            self.stats["connection_error"] += 1
        finally:
            self._writer = None
            writer.close()

    def _send(self, frame: bytes) -> None:
        if self._writer is None or self._writer.is_closing():
            self.stats["tx_no_peer"] += 1
            return
        self._writer.write(length_prefixed(frame))
        self.stats["tx"] += 1

    async def run(self, cycles: int | None = None) -> None:
        await self._run(self._send, cycles)

    async def close(self) -> None:
        self.stop()
        for task in self._tasks:
            task.cancel()
        if self._writer is not None:
            self._writer.close()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()

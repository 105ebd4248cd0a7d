"""NTRIP client for the rover: NTRIP 2.0 with NTRIP 1.0 fallback, GGA upload, reconnect with backoff,
and a data watchdog.

Two layers, as everywhere in augnet:
  `NtripClientConnection` (sans-IO): builds the request bytes and turns received bytes into events
    (`Connected`, `Data`, `Rejected`, `SourceTable`), including HTTP/1.1 chunked transfer coding.
  `NtripClient` (asyncio): opens the TCP connection, sends the request, forwards data to a callback,
    sends a GGA line every `gga_interval_s`, and reconnects with exponential backoff when the
    connection drops, the caster rejects it, or no data arrived for `data_timeout_s` (the
    correction-age watchdog: a stalled stream is as bad as a closed one).

Fallback: the client speaks NTRIP 2.0 first.  A caster that answers "ICY 200 OK" or an HTTP/1.0
status line is an NTRIP 1.0 caster and is used as such; one that refuses the 2.0 request (400, 501
or closes without an answer) is asked again in 1.0 form on the next attempt.

References: NTRIP 2.0 (RTCM 10410.1) 3.1-3.3, NTRIP 1.0 (RTCM 10410.0) appendix B.
"""

from __future__ import annotations

import asyncio
import base64
import random
from dataclasses import dataclass, field
from typing import Awaitable, Callable, Optional, Union

from augwire.chunked import ChunkedDecoder
from augwire.errors import NtripProtocolError

USER_AGENT = "NTRIP augnet/0.1"
# Limits on what a caster may send before its data (h11 uses similar bounds): a response header
# block over 16 KiB or a chunk-size line over 64 bytes is not NTRIP.
MAX_HEADER_BYTES = 16 * 1024
MAX_CHUNK_LINE_BYTES = 64
# Default timing [s]: GGA every 5 s (casters expect 1-10 s for VRS), reconnect backoff from 1 s
# doubling to 60 s with +-20 % jitter so a fleet does not reconnect in lockstep, and the watchdog:
# corrections must stay under 5 s old (network-rtk.md), so 5 s without a byte means reconnect.
DEFAULT_GGA_INTERVAL_S = 5.0
BACKOFF_INITIAL_S = 1.0
BACKOFF_MAX_S = 60.0
BACKOFF_JITTER = 0.2
DEFAULT_DATA_TIMEOUT_S = 5.0
CONNECT_TIMEOUT_S = 10.0


_RESPONSE_PREFIXES = (b"HTTP/", b"ICY 200 OK", b"SOURCETABLE 200 OK")


class NtripError(Exception):
    """A protocol violation by the caster (unparseable response, oversized header)."""


@dataclass(frozen=True)
class Connected:
    version: int  # 1 or 2, as the caster answered
    status: str  # the status line


@dataclass(frozen=True)
class Data:
    data: bytes


@dataclass(frozen=True)
class Rejected:
    status_code: int
    status: str
    retry_as_v1: bool  # a refusal of the NTRIP 2.0 request form: ask again as NTRIP 1.0


@dataclass(frozen=True)
class SourceTable:
    text: str  # the mountpoint does not exist: the caster sent its source table


Event = Union[Connected, Data, Rejected, SourceTable]


class NtripClientConnection:
    """Sans-IO NTRIP client state machine for one connection attempt."""

    def __init__(self, host: str, port: int, mountpoint: str, user: str = "", password: str = "",
                 version: int = 2, gga: str | None = None):
        self.host, self.port, self.mountpoint = host, port, mountpoint.lstrip("/")
        self.user, self.password = user, password
        self.version = version
        self.gga = gga
        self._buf = bytearray()
        self._state = "header"  # header -> body (raw | chunked) -> done
        self._dechunk: ChunkedDecoder | None = None  # a v2 reply in chunked coding
        self._sourcetable = bytearray()

    def request(self) -> bytes:
        auth = ""
        if self.user or self.password:
            token = base64.b64encode(f"{self.user}:{self.password}".encode()).decode()
            auth = f"Authorization: Basic {token}\r\n"
        if self.version == 2:
            gga = f"Ntrip-GGA: {self.gga.strip()}\r\n" if self.gga else ""
            return (f"GET /{self.mountpoint} HTTP/1.1\r\nHost: {self.host}:{self.port}\r\n"
                    f"Ntrip-Version: Ntrip/2.0\r\nUser-Agent: {USER_AGENT}\r\n{auth}{gga}"
                    f"Connection: close\r\n\r\n").encode("ascii")
        req = f"GET /{self.mountpoint} HTTP/1.0\r\nUser-Agent: {USER_AGENT}\r\n{auth}\r\n".encode("ascii")
        if self.gga:  # NTRIP 1.0: the GGA follows the request on the same connection
            req += self.gga.strip().encode("ascii") + b"\r\n"
        return req

    def receive(self, data: bytes) -> list[Event]:
        """Bytes from the caster -> events.  Raises NtripError on a response that is not NTRIP."""
        self._buf += data
        out: list[Event] = []
        if self._state == "header":
            ev = self._parse_header()
            if ev is None:
                return out
            out.append(ev)
        if self._state == "sourcetable":
            self._sourcetable += self._buf
            self._buf.clear()
            if b"ENDSOURCETABLE" in self._sourcetable:
                out.append(SourceTable(self._sourcetable.decode("latin-1")))
                self._state = "done"
            return out
        if self._state == "body" and self._buf:
            payload = bytes(self._buf) if self._dechunk is None else self._dechunked()
            self._buf.clear()
            if payload:
                out.append(Data(payload))
        return out

    def _dechunked(self) -> bytes:
        """The data carried by the chunked bytes in the buffer; the body is done after the last chunk."""
        assert self._dechunk is not None
        try:
            payload = b"".join(self._dechunk.feed(bytes(self._buf)))
        except NtripProtocolError as exc:
            raise NtripError(exc.reason) from None
        if self._dechunk.finished:
            self._state = "done"
        return payload

    def _parse_header(self) -> Event | None:
        buf = bytes(self._buf)
        # NTRIP 1.0 casters answer a single status line "ICY 200 OK\r\n" before the data
        if buf.startswith(b"ICY 200 OK"):
            end = buf.find(b"\r\n")
            if end < 0:
                return None
            # some casters add an empty line after ICY, some do not
            body_start = end + 2
            if buf[body_start:body_start + 2] == b"\r\n":
                body_start += 2
            self._buf = bytearray(buf[body_start:])
            self._state = "body"
            return Connected(1, "ICY 200 OK")
        if buf.startswith(b"SOURCETABLE 200 OK"):
            end = buf.find(b"\r\n\r\n")
            if end < 0:
                if len(buf) > MAX_HEADER_BYTES:
                    raise NtripError("source table header too long")
                return None
            self._buf = bytearray(buf[end + 4:])
            self._state = "sourcetable"
            return None
        end = buf.find(b"\r\n\r\n")
        if end < 0:
            if len(buf) > MAX_HEADER_BYTES:
                raise NtripError("response header too long")
            if not any(buf[: len(p)] == p[: len(buf)] for p in _RESPONSE_PREFIXES):
                raise NtripError(f"not an NTRIP response: {buf[:40]!r}")
            return None
        head = buf[:end].decode("latin-1")
        lines = head.split("\r\n")
        status = lines[0]
        parts = status.split(" ", 2)
        if len(parts) < 2 or not parts[0].startswith("HTTP/") or not parts[1].isdigit():
            raise NtripError(f"not an NTRIP response: {status!r}")
        code = int(parts[1])
        headers = {}
        for ln in lines[1:]:
            if ":" in ln:
                k, v = ln.split(":", 1)
                headers[k.strip().lower()] = v.strip()
        self._buf = bytearray(buf[end + 4:])
        if code == 200:
            if headers.get("content-type", "").lower().startswith("gnss/sourcetable"):
                self._state = "sourcetable"
                return None
            if "chunked" in headers.get("transfer-encoding", "").lower():
                # Any chunk size: the client streams a chunk's data out as it comes.
                self._dechunk = ChunkedDecoder(max_chunk_bytes=None, max_size_line_bytes=MAX_CHUNK_LINE_BYTES)
            self._state = "body"
            return Connected(2 if parts[0] == "HTTP/1.1" else 1, status)
        self._state = "done"
        retry_v1 = self.version == 2 and code in (400, 405, 426, 501, 505)
        return Rejected(code, status, retry_v1)


@dataclass
class ClientStats:
    connects: int = 0
    failures: int = 0
    bytes: int = 0
    ggas_sent: int = 0
    fallbacks_to_v1: int = 0
    watchdog_timeouts: int = 0
    last_error: str = ""
    events: list[str] = field(default_factory=list)


class NtripClient:
    """Keeps a correction stream alive until `stop()`; data goes to `on_data(bytes)`."""

    def __init__(self, host: str, port: int, mountpoint: str, on_data: Callable[[bytes], Optional[Awaitable[None]]],
                 *, user: str = "", password: str = "", gga_provider: Callable[[], Optional[str]] | None = None,
                 gga_interval_s: float = DEFAULT_GGA_INTERVAL_S, data_timeout_s: float = DEFAULT_DATA_TIMEOUT_S,
                 backoff_initial_s: float = BACKOFF_INITIAL_S, backoff_max_s: float = BACKOFF_MAX_S,
                 version: int = 2, rng: random.Random | None = None):
        self.host, self.port, self.mountpoint = host, port, mountpoint
        self.user, self.password = user, password
        self.on_data = on_data
        self.gga_provider = gga_provider
        self.gga_interval_s = gga_interval_s
        self.data_timeout_s = data_timeout_s
        self.backoff_initial_s = backoff_initial_s
        self.backoff_max_s = backoff_max_s
        self.version = version
        self.stats = ClientStats()
        self._rng = rng or random.Random()
        self._stop = asyncio.Event()
        self.connected = asyncio.Event()
        self._writer: asyncio.StreamWriter | None = None

    def stop(self) -> None:
        self._stop.set()
        if self._writer is not None:
            self._writer.close()  # wakes a pending read at once

    def _log(self, msg: str) -> None:
        self.stats.events.append(msg)
        del self.stats.events[:-100]

    async def run(self) -> None:
        backoff = self.backoff_initial_s
        while not self._stop.is_set():
            ok = await self._session()
            if self._stop.is_set():
                break
            if ok:
                backoff = self.backoff_initial_s  # had a working stream: retry promptly
            delay = backoff * (1.0 + BACKOFF_JITTER * (2.0 * self._rng.random() - 1.0))
            self._log(f"reconnect in {delay:.2f} s")
            try:
                await asyncio.wait_for(self._stop.wait(), timeout=delay)
            except asyncio.TimeoutError:
                pass
            backoff = min(backoff * 2.0, self.backoff_max_s)

    async def _session(self) -> bool:
        """One connection; True if data flowed."""
        gga = self.gga_provider() if self.gga_provider else None
        conn = NtripClientConnection(self.host, self.port, self.mountpoint, self.user, self.password,
                                     self.version, gga)
        try:
            reader, writer = await asyncio.wait_for(asyncio.open_connection(self.host, self.port), CONNECT_TIMEOUT_S)
        except (OSError, asyncio.TimeoutError) as exc:
            self.stats.failures += 1
            self.stats.last_error = f"connect: {exc!r}"
            self._log(self.stats.last_error)
            return False
        got_data = False
        answered = False
        gga_task = None
        self._writer = writer
        try:
            writer.write(conn.request())
            if gga:
                self.stats.ggas_sent += 1
            await writer.drain()
            while not self._stop.is_set():
                try:
                    chunk = await asyncio.wait_for(reader.read(65536), timeout=self.data_timeout_s)
                except asyncio.TimeoutError:
                    self.stats.watchdog_timeouts += 1
                    self.stats.last_error = f"no data for {self.data_timeout_s:.1f} s"
                    self._log(self.stats.last_error)
                    break
                if not chunk:
                    if not answered and self.version == 2:
                        self._fallback("caster closed the NTRIP 2.0 request without answering")
                    self._log("caster closed the connection")
                    break
                for ev in conn.receive(chunk):
                    if isinstance(ev, Connected):
                        answered = True
                        self.stats.connects += 1
                        self.connected.set()
                        self._log(f"connected ({ev.status}, NTRIP {ev.version})")
                        if self.gga_provider and gga_task is None:
                            gga_task = asyncio.ensure_future(self._gga_loop(writer))
                    elif isinstance(ev, Data):
                        got_data = True
                        self.stats.bytes += len(ev.data)
                        r = self.on_data(ev.data)
                        if asyncio.iscoroutine(r):
                            await r
                    elif isinstance(ev, Rejected):
                        answered = True
                        self.stats.failures += 1
                        self.stats.last_error = f"rejected: {ev.status}"
                        self._log(self.stats.last_error)
                        if ev.retry_as_v1:
                            self._fallback(ev.status)
                        return got_data
                    elif isinstance(ev, SourceTable):
                        self.stats.failures += 1
                        self.stats.last_error = f"mountpoint {self.mountpoint} not in the source table"
                        self._log(self.stats.last_error)
                        return got_data
        except NtripError as exc:
            self.stats.failures += 1
            self.stats.last_error = f"protocol: {exc}"
            self._log(self.stats.last_error)
            if not answered and self.version == 2:
                self._fallback(str(exc))
        except (OSError, ConnectionError) as exc:
            self.stats.failures += 1
            self.stats.last_error = f"connection: {exc!r}"
            self._log(self.stats.last_error)
        finally:
            self._writer = None
            self.connected.clear()
            if gga_task is not None:
                gga_task.cancel()
            writer.close()
            try:
                await writer.wait_closed()
            except (OSError, ConnectionError):
                pass
        return got_data

    def _fallback(self, why: str) -> None:
        self.version = 1
        self.stats.fallbacks_to_v1 += 1
        self._log(f"falling back to NTRIP 1.0: {why}")

    async def _gga_loop(self, writer: asyncio.StreamWriter) -> None:
        try:
            while True:
                await asyncio.sleep(self.gga_interval_s)
                line = self.gga_provider() if self.gga_provider else None
                if line:
                    writer.write(line.strip().encode("ascii") + b"\r\n")
                    await writer.drain()
                    self.stats.ggas_sent += 1
        except (asyncio.CancelledError, OSError, ConnectionError):
            return

"""The sans-IO NTRIP server connection: bytes in, events out (h11 style; no sockets, no clock).

    conn = NtripServerConnection()
    for event in conn.receive_data(data):   # may raise NtripProtocolError(status)
        ...

Events, in the order a connection produces them:
  RequestReceived(request)     once, when the request head is complete
  GgaLine(line)                a client sent a GGA sentence (unparsed: the server rate-limits parsing)
  SourceData(data)             a source's payload bytes (v2 chunked bodies already de-chunked)
  SourceFinished()             a v2 source sent its last chunk

After `RequestReceived` the server decides; the connection has already switched to the role the
request asked for (client -> GGA lines, source -> data), so bytes that arrived with the head are
not lost. Responses are built by `response.py`.
"""

from __future__ import annotations

from dataclasses import dataclass

from augwire.chunked import ChunkedDecoder
from augwire.errors import NtripProtocolError

from .gga import NmeaLineSplitter
from .limits import MAX_REQUEST_HEAD_BYTES, MAX_SOURCE_CHUNK_BYTES
from .request import NtripRequest, parse_request_head


@dataclass(frozen=True, slots=True)
class RequestReceived:
    request: NtripRequest


@dataclass(frozen=True, slots=True)
class GgaLine:
    line: bytes  # '$..GGA,...*hh' without line end


@dataclass(frozen=True, slots=True)
class SourceData:
    data: bytes


@dataclass(frozen=True, slots=True)
class SourceFinished:
    pass


Event = RequestReceived | GgaLine | SourceData | SourceFinished

HEAD, CLIENT, SOURCE, CLOSED = "HEAD", "CLIENT", "SOURCE", "CLOSED"


def _head_end(buf: bytearray) -> tuple[int, int]:
    """(index where the head ends, index where the body starts) or (-1, -1). CRLF or bare LF."""
    crlf = buf.find(b"\r\n\r\n")
    lf = buf.find(b"\n\n")
    if crlf >= 0 and (lf < 0 or crlf + 1 <= lf):
        return crlf, crlf + 4
    if lf >= 0:
        return lf, lf + 2
    return -1, -1


class NtripServerConnection:
    """Protocol state of one accepted connection, as seen by the caster."""

    __slots__ = ("state", "request", "_buf", "_lines", "_dechunk", "_dechunk_max", "max_head_bytes")

    def __init__(self, max_head_bytes: int = MAX_REQUEST_HEAD_BYTES,
                 max_chunk_bytes: int = MAX_SOURCE_CHUNK_BYTES) -> None:
        self.state = HEAD
        self.request: NtripRequest | None = None
        self._buf = bytearray()
        self._lines: NmeaLineSplitter | None = None
        self._dechunk: ChunkedDecoder | None = None
        self.max_head_bytes = max_head_bytes
        self._dechunk_max = max_chunk_bytes

    @property
    def version(self) -> int:
        """NTRIP version of the request (1 until a v2 request head has been seen)."""
        return self.request.version if self.request is not None else 1

    def receive_data(self, data: bytes) -> list[Event]:
        """Feed bytes from the peer; returns the events they complete.

        Raises NtripProtocolError (400 malformed, 431 head too large, 501 unsupported, 505 version);
        the connection is then CLOSED and the caller answers with `response.error_response`.
        """
        if self.state == CLOSED or not data:
            return []
        try:
            if self.state == HEAD:
                return self._receive_head(data)
            if self.state == CLIENT:
                return self._client_lines(data)
            return self._source_data(data)
        except NtripProtocolError:
            self.state = CLOSED
            raise

    def close(self) -> None:
        self.state = CLOSED
        self._buf = bytearray()

    def _receive_head(self, data: bytes) -> list[Event]:
        buf = self._buf
        # Rescanning the whole buffer per call is bounded by max_head_bytes (8 KiB), so even a
        # byte-at-a-time sender costs at most ~8 K scans of at most 8 KiB.
        buf += data
        end, body = _head_end(buf)
        if end < 0:
            if len(buf) > self.max_head_bytes:
                raise NtripProtocolError(431, f"request head larger than {self.max_head_bytes} bytes")
            return []
        if end > self.max_head_bytes:
            raise NtripProtocolError(431, f"request head larger than {self.max_head_bytes} bytes")
        head = bytes(buf[:end])
        rest = bytes(buf[body:])
        self._buf = bytearray()
        # Tolerate leading blank lines before the request line (RFC 9112 section 2.2).
        request = parse_request_head(head.lstrip(b"\r\n"))
        self.request = request
        events: list[Event] = [RequestReceived(request)]
        if request.kind == "client":
            self.state = CLIENT
            self._lines = NmeaLineSplitter()
            if rest:
                events += self._client_lines(rest)
        else:
            self.state = SOURCE
            if request.chunked:
                self._dechunk = ChunkedDecoder(self._dechunk_max)
            if rest:
                events += self._source_data(rest)
        return events

    def _client_lines(self, data: bytes) -> list[Event]:
        assert self._lines is not None
        return [GgaLine(line) for line in self._lines.feed(data) if line[3:7] == b"GGA,"]

    def _source_data(self, data: bytes) -> list[Event]:
        if self._dechunk is None:
            return [SourceData(data)]
        events: list[Event] = [SourceData(piece) for piece in self._dechunk.feed(data)]
        if self._dechunk.finished:
            events.append(SourceFinished())
            self.state = CLOSED
        return events

"""HTTP/1.1 chunked transfer coding (RFC 9112 section 7.1), as NTRIP 2.0 uses it both ways.

Encoding: one chunk is built as one bytes object (size line, data, CRLF) so the server writes it in
one call: pygnssutils' dechunker drops data when a chunk's trailing CRLF arrives in a later read
(ntrip.md). Decoding: a sans-IO decoder for v2 sources that POST chunked bodies.
"""

from __future__ import annotations

from .errors import NtripProtocolError
from .limits import MAX_CHUNK_SIZE_LINE_BYTES, MAX_SOURCE_CHUNK_BYTES

LAST_CHUNK = b"0\r\n\r\n"


def encode_chunk(data: bytes) -> bytes:
    """One chunk carrying `data` (never empty: an empty chunk would end the stream)."""
    if not data:
        raise ValueError("an empty chunk terminates a chunked body; send LAST_CHUNK to end it")
    return b"%X\r\n%b\r\n" % (len(data), data)


class ChunkedDecoder:
    """Feed it the bytes of a chunked body; it returns the data they carry.

    Raises `NtripProtocolError(400)` on a malformed size line or missing CRLF, and on a chunk larger
    than `max_chunk` bytes. After the last chunk (size 0) `finished` is True and further bytes are
    ignored (trailers are read and discarded).
    """

    __slots__ = ("_buf", "_remaining", "_state", "max_chunk", "finished")

    _SIZE, _DATA, _DATA_CRLF, _TRAILER = range(4)

    def __init__(self, max_chunk: int = MAX_SOURCE_CHUNK_BYTES) -> None:
        self._buf = bytearray()
        self._remaining = 0
        self._state = self._SIZE
        self.max_chunk = max_chunk
        self.finished = False

    def feed(self, data: bytes) -> list[bytes]:
        if self.finished:
            return []
        self._buf += data
        out: list[bytes] = []
        buf = self._buf
        while buf:
            if self._state == self._SIZE:
                end = buf.find(b"\n")
                if end < 0:
                    if len(buf) > MAX_CHUNK_SIZE_LINE_BYTES:
                        raise NtripProtocolError(400, "chunk size line too long")
                    break
                if end + 1 > MAX_CHUNK_SIZE_LINE_BYTES:
                    raise NtripProtocolError(400, "chunk size line too long")
                line = bytes(buf[:end]).rstrip(b"\r")
                del buf[: end + 1]
                size_text = line.split(b";", 1)[0].strip()
                if not size_text or any(c not in b"0123456789abcdefABCDEF" for c in size_text):
                    raise NtripProtocolError(400, f"bad chunk size line {line[:40]!r}")
                size = int(size_text, 16)
                if size > self.max_chunk:
                    raise NtripProtocolError(400, f"chunk of {size} bytes exceeds {self.max_chunk}")
                if size == 0:
                    self._state = self._TRAILER
                else:
                    self._remaining = size
                    self._state = self._DATA
            elif self._state == self._DATA:
                take = min(self._remaining, len(buf))
                out.append(bytes(buf[:take]))
                del buf[:take]
                self._remaining -= take
                if self._remaining == 0:
                    self._state = self._DATA_CRLF
            elif self._state == self._DATA_CRLF:
                if buf[:1] == b"\n":
                    del buf[:1]
                    self._state = self._SIZE
                elif buf[:2] == b"\r\n":
                    del buf[:2]
                    self._state = self._SIZE
                elif len(buf) == 1 and buf[:1] == b"\r":
                    break
                else:
                    raise NtripProtocolError(400, "chunk data not followed by CRLF")
            else:  # trailer section: lines until an empty one
                end = buf.find(b"\n")
                if end < 0:
                    if len(buf) > MAX_CHUNK_SIZE_LINE_BYTES:
                        raise NtripProtocolError(400, "chunked trailer line too long")
                    break
                line = bytes(buf[:end]).rstrip(b"\r")
                del buf[: end + 1]
                if not line:
                    self.finished = True
                    buf.clear()
                    break
        return out

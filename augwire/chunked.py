"""HTTP/1.1 chunked transfer coding (RFC 9112 section 7.1), as NTRIP 2.0 uses it both ways.

Encoding: one chunk is built as one bytes object (size line, data, CRLF) so a writer sends it in one
call: pygnssutils' dechunker drops data when a chunk's trailing CRLF arrives in a later read
(ntrip.md). Decoding: `ChunkedDecoder`, sans-IO, for the caster's v2 sources (POST bodies) and for
the clients reading a v2 caster's replies. A bare LF ends a line as well as CRLF (RFC 9112 section 2.2
lets a recipient accept it); extensions are ignored; trailers are read and discarded.
"""

from __future__ import annotations

from augwire.errors import NtripProtocolError

LAST_CHUNK = b"0\r\n\r\n"
# Largest chunk a peer may announce (the caster's default for v2 sources). RTCM 3 frames are at most
# 1029 bytes; an epoch of a multi-constellation MSM7 station is 3-6 KB. 64 KiB leaves room for
# batching and bounds what one chunk can carry.
MAX_CHUNK_BYTES = 64 * 1024
# Longest chunk-size line (hex size + extensions + CRLF), also the bound on a trailer line. h11 allows
# chunk extensions without a separate bound; 1 KiB is far beyond anything legitimate ("400\r\n" is
# typical).
MAX_CHUNK_SIZE_LINE_BYTES = 1024
_HEX_DIGITS = b"0123456789abcdefABCDEF"
_CR, _LF = 0x0D, 0x0A
# Decoder states: a size line, chunk data, the CRLF after the data, the trailer section.
_SIZE, _DATA, _DATA_CRLF, _TRAILER = range(4)
# A plain size line is at most 16 hex digits (a 64-bit size) + CRLF: how far the one-chunk fast path
# looks for the line end.
_PLAIN_SIZE_LINE_BYTES = 18


def encode_chunk(data: bytes) -> bytes:
    """One chunk carrying `data` (never empty: an empty chunk would end the stream)."""
    if not data:
        raise ValueError("an empty chunk terminates a chunked body; send LAST_CHUNK to end it")
    return b"%X\r\n%b\r\n" % (len(data), data)


def _is_hex(text: bytes) -> bool:
    """True for a non-empty run of hex digits only (int(text, 16) alone would also take '0x', '_', '+')."""
    return bool(text) and not text.strip(_HEX_DIGITS)


def _line_end(buf: bytearray, pos: int, max_line: int, what: str) -> int:
    """Index of the LF ending the line that starts at `pos`, or -1 while it has not come; raises once
    the unfinished line is longer than `max_line` bytes."""
    end = buf.find(b"\n", pos)
    if end < 0 and len(buf) - pos > max_line:
        raise NtripProtocolError(400, f"{what} too long")
    return end


class ChunkedDecoder:
    """Feed it the bytes of a chunked body; it returns the data they carry.

    Raises `NtripProtocolError(400)` on a malformed size line or missing CRLF, on a size line longer
    than `max_size_line_bytes`, and on a chunk larger than `max_chunk_bytes` (None: no bound; the
    decoder streams a chunk's data out as it comes, never holding a whole chunk). After the last
    chunk (size 0) and its trailers, `finished` is True and further bytes are ignored.
    """

    __slots__ = ("_buf", "_remaining", "_state", "max_chunk_bytes", "max_size_line_bytes", "finished")

    def __init__(self, max_chunk_bytes: int | None = MAX_CHUNK_BYTES,
                 max_size_line_bytes: int = MAX_CHUNK_SIZE_LINE_BYTES) -> None:
        self._buf = bytearray()
        self._remaining = 0
        self._state = _SIZE
        self.max_chunk_bytes = max_chunk_bytes
        self.max_size_line_bytes = max_size_line_bytes
        self.finished = False

    def feed(self, data: bytes) -> list[bytes]:
        if self.finished:
            return []
        if self._state == _SIZE and not self._buf:
            whole = self._one_whole_chunk(data)
            if whole is not None:
                return [whole]
        buf = self._buf
        buf += data
        out: list[bytes] = []
        state, remaining = self._state, self._remaining
        max_line = self.max_size_line_bytes
        pos, n = 0, len(buf)
        while pos < n:
            if state == _DATA:
                take = min(remaining, n - pos)
                out.append(bytes(buf[pos : pos + take]))
                pos += take
                remaining -= take
                if remaining == 0:
                    state = _DATA_CRLF
            elif state == _DATA_CRLF:
                if buf[pos] == _LF:
                    pos += 1
                    state = _SIZE
                elif buf[pos] == _CR and n - pos == 1:
                    break  # the LF is still to come
                elif buf[pos] == _CR and buf[pos + 1] == _LF:
                    pos += 2
                    state = _SIZE
                else:
                    raise NtripProtocolError(400, "chunk data not followed by CRLF")
            elif state == _SIZE:
                end = _line_end(buf, pos, max_line, "chunk size line")
                if end < 0:
                    break
                if end - pos + 1 > max_line:
                    raise NtripProtocolError(400, "chunk size line too long")
                size = self._chunk_size(bytes(buf[pos:end]).rstrip(b"\r"))
                pos = end + 1
                if size == 0:
                    state = _TRAILER
                else:
                    remaining = size
                    state = _DATA
            else:  # trailer section: lines until an empty one
                end = _line_end(buf, pos, max_line, "chunked trailer line")
                if end < 0:
                    break
                empty = not bytes(buf[pos:end]).rstrip(b"\r")
                pos = end + 1
                if empty:
                    self.finished = True
                    pos = n
                    break
        del buf[:pos]
        self._state, self._remaining = state, remaining
        return out

    def _chunk_size(self, line: bytes) -> int:
        """The size a chunk-size line announces (extensions after ';' ignored), checked against the bound."""
        size_text = line.split(b";", 1)[0].strip()
        if not _is_hex(size_text):
            raise NtripProtocolError(400, f"bad chunk size line {line[:40]!r}")
        size = int(size_text, 16)
        if self.max_chunk_bytes is not None and size > self.max_chunk_bytes:
            raise NtripProtocolError(400, f"chunk of {size} bytes exceeds {self.max_chunk_bytes}")
        return size

    def _one_whole_chunk(self, data: bytes) -> bytes | None:
        """The data of `data` when it is exactly one whole non-empty chunk with a plain size line (how
        casters write: one chunk per write), else None (the general path then decodes it)."""
        end = data.find(b"\r\n", 0, _PLAIN_SIZE_LINE_BYTES)
        if end <= 0 or end + 2 > self.max_size_line_bytes:
            return None
        size_text = data[:end]
        if not _is_hex(size_text):
            return None
        size = int(size_text, 16)
        if size == 0 or len(data) != end + size + 4 or data[-2:] != b"\r\n":
            return None
        if self.max_chunk_bytes is not None and size > self.max_chunk_bytes:
            return None
        return data[end + 2 : end + 2 + size]

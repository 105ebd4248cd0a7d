"""RTCM 3 transport layer: build a frame, find frames in a byte stream, survive bad input.

Frame (RTCM 10403.3 section 4, Table 4-1):

    0xD3 | 6 reserved bits (0) + 10-bit payload length | payload (0..1023 bytes) | CRC-24Q (3 bytes)

The CRC covers preamble, length and payload. One scan (`scan_frames`) serves three users:

  RtcmStreamReader   sans-IO framer, ``feed(bytes) -> list[Frame]``: returns CRC-checked frames, counts
                     and skips garbage, false preambles, bad CRCs and truncated frames, never raises
  RtcmFrameAligner   the caster's fan-out: forwards every byte, holding back a frame not yet complete
  split_frames       the frames of a whole buffer (tests, tools)

A frame split across ``feed`` calls at any byte boundary is reassembled. On a bad CRC the scan drops
only the preamble byte and hunts again from the next byte, so a real frame that starts inside a false
candidate is still found.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from augwire.crc24q import CRC24Q_BYTES, crc24q

PREAMBLE = 0xD3  # RTCM 10403.3 Table 4-1
HEADER_BYTES = 3  # preamble + 6 reserved bits + 10-bit length
CRC_BYTES = CRC24Q_BYTES
MAX_PAYLOAD_BYTES = 1023  # 10-bit length field
FRAME_OVERHEAD_BYTES = HEADER_BYTES + CRC_BYTES
MAX_FRAME_BYTES = MAX_PAYLOAD_BYTES + FRAME_OVERHEAD_BYTES
_RESERVED_BITS_MASK = 0xFC  # the 6 reserved bits of the second header byte


class FramingError(ValueError):
    """A payload cannot be framed (too long)."""


def frame(payload: bytes) -> bytes:
    """Wrap a message payload in an RTCM 3 frame: preamble, length, payload, CRC-24Q."""
    n = len(payload)
    if n > MAX_PAYLOAD_BYTES:
        raise FramingError(f"RTCM payload of {n} bytes exceeds the 10-bit length limit of {MAX_PAYLOAD_BYTES}")
    head = bytes((PREAMBLE, n >> 8, n & 0xFF)) + payload
    return head + crc24q(head).to_bytes(CRC_BYTES, "big")


def frame_length(buf: bytes | bytearray, pos: int) -> int:
    """Bytes of the whole frame whose header starts at `pos` (header + payload + CRC), from its 10-bit
    length field; the reserved bits are not looked at."""
    return (((buf[pos + 1] & 0x03) << 8) | buf[pos + 2]) + FRAME_OVERHEAD_BYTES


def message_type(payload: bytes) -> int:
    """The 12-bit message number (DF002) at the start of a payload; 0 for a payload under 2 bytes."""
    if len(payload) < 2:
        return 0
    return (payload[0] << 4) | (payload[1] >> 4)


@dataclass(frozen=True, slots=True)
class Scan:
    """What `scan_frames` found in a buffer."""

    spans: list[tuple[int, int]]  # (start, end) of each CRC-checked frame, in order
    stop: int  # where the scan stopped: the end of the buffer, or a candidate still missing bytes
    skipped_bytes: int  # bytes before `stop` in no frame (garbage, false preambles, bad-CRC candidates)
    crc_failures: int  # candidates (preamble, length, all bytes present) whose CRC did not match


def scan_frames(buf: bytes | bytearray, reserved_bits_must_be_zero: bool = True) -> Scan:
    """Find the frames in `buf` from its start, stopping before a candidate whose bytes have not all
    arrived. With `reserved_bits_must_be_zero` a header with any reserved bit set is not a frame
    (RTCM 10403.3 Table 4-1); without it they are ignored, as RTKLIB's decoder does (rtcm3.c)."""
    spans: list[tuple[int, int]] = []
    skipped = crc_failures = 0
    pos = 0
    n = len(buf)
    view = memoryview(buf)
    try:
        while True:
            start = buf.find(PREAMBLE, pos)
            if start < 0:
                skipped += n - pos
                pos = n
                break
            skipped += start - pos
            pos = start
            if n - pos < HEADER_BYTES:
                break  # wait for the length bytes
            if reserved_bits_must_be_zero and buf[pos + 1] & _RESERVED_BITS_MASK:
                skipped += 1
                pos += 1
                continue
            end = pos + frame_length(buf, pos)
            if end > n:
                break  # partial frame: wait for more bytes
            body_end = end - CRC_BYTES
            if crc24q(view[pos:body_end]) != int.from_bytes(buf[body_end:end], "big"):
                crc_failures += 1
                skipped += 1
                pos += 1
                continue
            spans.append((pos, end))
            pos = end
    finally:
        view.release()  # the caller resizes `buf` next; an open view would forbid it
    return Scan(spans, pos, skipped, crc_failures)


@dataclass(frozen=True, slots=True)
class Frame:
    """One CRC-checked RTCM 3 frame."""

    msg_type: int  # DF002, 0 when the payload is shorter than 2 bytes
    payload: bytes
    raw: bytes  # the whole frame: header + payload + CRC


@dataclass
class StreamStats:
    frames_ok: int = 0
    crc_failures: int = 0  # candidate frames (preamble + sane length) whose CRC did not match
    bytes_skipped: int = 0  # bytes discarded while hunting for a preamble (garbage, false preambles)
    truncated_bytes: int = 0  # bytes of an incomplete frame (or garbage) left when the input ended
    by_type: dict[int, int] = field(default_factory=dict)


# Bytes the reader holds at most by default: a frame is at most MAX_FRAME_BYTES, so anything beyond
# is already decided; the bound keeps memory flat when a caller feeds a huge block of garbage.
READER_MAX_BUFFER_BYTES = 64 * 1024


class RtcmStreamReader:
    """Sans-IO RTCM 3 frame splitter: ``feed(bytes) -> list[Frame]``; never raises on input.

    Bad input is skipped and counted in `stats`. `reserved_bits_must_be_zero`: see `scan_frames`.
    """

    def __init__(self, max_buffer_bytes: int = READER_MAX_BUFFER_BYTES,
                 reserved_bits_must_be_zero: bool = True) -> None:
        self._buf = bytearray()
        self.stats = StreamStats()
        self._max_buffer = max(max_buffer_bytes, MAX_FRAME_BYTES)
        self._reserved_bits_must_be_zero = reserved_bits_must_be_zero

    @property
    def pending_bytes(self) -> int:
        """Bytes held waiting for the rest of a frame (a partial frame at the end of the input)."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[Frame]:
        self._buf += data
        return self._scan()

    def _scan(self) -> list[Frame]:
        buf = self._buf
        stats = self.stats
        found = scan_frames(buf, self._reserved_bits_must_be_zero)
        stats.bytes_skipped += found.skipped_bytes
        stats.crc_failures += found.crc_failures
        out: list[Frame] = []
        by_type = stats.by_type
        for start, end in found.spans:
            payload = bytes(buf[start + HEADER_BYTES : end - CRC_BYTES])
            mt = message_type(payload)
            out.append(Frame(mt, payload, bytes(buf[start:end])))
            by_type[mt] = by_type.get(mt, 0) + 1
        stats.frames_ok += len(out)
        del buf[: found.stop]
        if len(buf) > self._max_buffer:  # cannot happen with valid lengths; defensive bound
            drop = len(buf) - self._max_buffer
            stats.bytes_skipped += drop
            del buf[:drop]
        return out

    def close(self) -> list[Frame]:
        """End of input: return any frames still hidden behind an incomplete candidate, and count
        the rest of the buffer (a truncated frame, or a false preamble announcing more bytes than
        came) in ``stats.truncated_bytes``."""
        out: list[Frame] = []
        skipped_before = self.stats.bytes_skipped
        while self._buf:
            # The buffer starts with a candidate that cannot complete: not a frame after all.
            del self._buf[0]
            self.stats.bytes_skipped += 1
            out.extend(self._scan())
        self.stats.truncated_bytes += self.stats.bytes_skipped - skipped_before
        self.stats.bytes_skipped = skipped_before
        return out


class RtcmFrameAligner:
    """Holds back the tail of a byte stream until it ends on an RTCM 3 frame boundary.

    `feed(data)` returns the bytes that may be forwarded now: every complete frame and every byte
    that cannot start a frame (forwarded too, so the stream stays byte-identical), stopping before a
    frame whose remaining bytes have not arrived yet. The held-back tail is at most one frame.
    Reserved length bits are ignored: the caster forwards what decoders accept (RTKLIB's rtcm3.c).
    """

    __slots__ = ("_buf", "frames", "junk_bytes")

    def __init__(self) -> None:
        self._buf = bytearray()
        self.frames = 0  # complete frames seen (valid CRC)
        self.junk_bytes = 0  # bytes that were not part of a valid frame (still forwarded)

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def feed(self, data: bytes) -> bytes:
        buf = self._buf
        buf += data
        found = scan_frames(buf, reserved_bits_must_be_zero=False)
        self.frames += len(found.spans)
        self.junk_bytes += found.skipped_bytes
        out = bytes(buf[: found.stop])
        del buf[: found.stop]
        return out

    def flush(self) -> bytes:
        """Everything still held back (the source went away: forward the partial frame as-is)."""
        out = bytes(self._buf)
        self._buf.clear()
        return out


def split_frames(data: bytes) -> list[bytes]:
    """Complete, CRC-valid RTCM 3 frames in `data`, in order (junk and a partial tail skipped; reserved
    length bits ignored, as the aligner does)."""
    reader = RtcmStreamReader(reserved_bits_must_be_zero=False)
    frames = reader.feed(data)
    frames += reader.close()
    return [f.raw for f in frames]


@dataclass
class FileFrames:
    """All complete frames of a file, with the reader's counters and the size of any trailing partial frame."""

    frames: list[Frame]
    stats: StreamStats
    truncated_tail_bytes: int


# Bytes read from a file per read() call.
FILE_READ_BYTES = 65536


def read_frames(path: str | Path, chunk_bytes: int = FILE_READ_BYTES) -> FileFrames:
    """Split a whole file into frames; a partial frame at the end is reported, not raised."""
    reader = RtcmStreamReader()
    frames: list[Frame] = []
    with open(path, "rb") as fh:
        while chunk := fh.read(chunk_bytes):
            frames.extend(reader.feed(chunk))
    frames.extend(reader.close())
    return FileFrames(frames, reader.stats, reader.stats.truncated_bytes)


def iter_frames(path: str | Path, chunk_bytes: int = FILE_READ_BYTES) -> Iterator[Frame]:
    """Yield the complete frames of a file one by one (streaming; a partial tail is dropped)."""
    reader = RtcmStreamReader()
    with open(path, "rb") as fh:
        while chunk := fh.read(chunk_bytes):
            yield from reader.feed(chunk)
    yield from reader.close()

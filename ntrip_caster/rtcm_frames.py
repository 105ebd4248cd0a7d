"""RTCM 3 frame boundaries: preamble + 10-bit length + CRC-24Q, nothing more.

The caster forwards bytes untouched; it only needs to know where frames end so that a client joining
mid-stream starts on a frame boundary and so that per-mountpoint statistics count frames. The full
codec lives in `augnet.gnss.rtcm`; the caster may not import it (architecture rule), and this is all
it needs.

Frame layout (RTCM 10403.3 section 4): 0xD3, 6 reserved bits + 10-bit payload length, payload,
CRC-24Q over everything before the CRC.
"""

from __future__ import annotations

import numpy as np

RTCM3_PREAMBLE = 0xD3
RTCM3_HEADER_BYTES = 3
RTCM3_CRC_BYTES = 3
RTCM3_MAX_PAYLOAD_BYTES = 1023  # 10-bit length field
RTCM3_MAX_FRAME_BYTES = RTCM3_HEADER_BYTES + RTCM3_MAX_PAYLOAD_BYTES + RTCM3_CRC_BYTES
CRC24Q_POLY = 0x1864CFB  # Qualcomm CRC-24Q, RTCM 10403.3 section 4.2


def _crc24q_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 16
        for _ in range(8):
            crc <<= 1
            if crc & 0x1000000:
                crc ^= CRC24Q_POLY
        table.append(crc & 0xFFFFFF)
    return tuple(table)


_CRC24Q_TABLE = _crc24q_table()


def crc24q_bytewise(data: bytes | bytearray | memoryview) -> int:
    """CRC-24Q of `data` (24-bit integer), one byte at a time: the reference implementation."""
    crc = 0
    table = _CRC24Q_TABLE
    for byte in data:
        crc = ((crc << 8) & 0xFFFFFF) ^ table[(crc >> 16) ^ byte]
    return crc


# The CRC (initial value 0, no final XOR) is linear over GF(2): the CRC of a message is the XOR of
# the CRCs of each of its bytes followed by as many zero bytes as come after it. _BYTE_AT[d][b] is
# the CRC of byte b followed by d zero bytes, for every d a frame can need, so a frame's CRC is one
# numpy gather and XOR-reduce (~25x faster than the byte loop for a 1 KB frame, which matters
# because the caster checks every frame of every source before forwarding it).
_CRC_SPAN = RTCM3_HEADER_BYTES + RTCM3_MAX_PAYLOAD_BYTES
_VECTOR_MIN_BYTES = 48  # below this the byte loop is faster than numpy's call overhead


def _crc_by_position() -> np.ndarray:
    table = np.array(_CRC24Q_TABLE, dtype=np.uint32)
    rows = np.empty((_CRC_SPAN, 256), dtype=np.uint32)
    rows[0] = table  # crc of the single byte b (initial register 0)
    for d in range(1, _CRC_SPAN):
        prev = rows[d - 1]
        rows[d] = ((prev << 8) & 0xFFFFFF) ^ table[prev >> 16]
    return rows[::-1].copy()  # row i: a byte with _CRC_SPAN - 1 - i bytes after it


_BYTE_AT = _crc_by_position()
_ROWS = np.arange(_CRC_SPAN)


def crc24q(data: bytes | bytearray | memoryview) -> int:
    """CRC-24Q of `data` (24-bit integer)."""
    n = len(data)
    if n < _VECTOR_MIN_BYTES or n > _CRC_SPAN:
        return crc24q_bytewise(data)
    values = np.frombuffer(data, dtype=np.uint8)
    return int(np.bitwise_xor.reduce(_BYTE_AT[_ROWS[_CRC_SPAN - n:], values]))


def frame_rtcm3(payload: bytes) -> bytes:
    """Wrap `payload` in an RTCM 3 frame (used by tests and the load generator)."""
    if len(payload) > RTCM3_MAX_PAYLOAD_BYTES:
        raise ValueError(f"RTCM 3 payload is {len(payload)} bytes; at most {RTCM3_MAX_PAYLOAD_BYTES}")
    head = bytes((RTCM3_PREAMBLE, len(payload) >> 8, len(payload) & 0xFF)) + payload
    return head + crc24q(head).to_bytes(3, "big")


class RtcmFrameAligner:
    """Holds back the tail of a byte stream until it ends on an RTCM 3 frame boundary.

    `feed(data)` returns the bytes that may be forwarded now: every complete frame and every byte
    that cannot start a frame (forwarded too, so the stream stays byte-identical), stopping before a
    frame whose remaining bytes have not arrived yet. The held-back tail is at most one frame.
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
        pos = 0
        n = len(buf)
        while pos < n:
            if buf[pos] != RTCM3_PREAMBLE:
                nxt = buf.find(RTCM3_PREAMBLE, pos)
                end = n if nxt < 0 else nxt
                self.junk_bytes += end - pos
                pos = end
                continue
            if n - pos < RTCM3_HEADER_BYTES:
                break
            length = ((buf[pos + 1] & 0x03) << 8) | buf[pos + 2]
            total = RTCM3_HEADER_BYTES + length + RTCM3_CRC_BYTES
            if n - pos < total:
                break
            body_end = pos + RTCM3_HEADER_BYTES + length
            if crc24q(memoryview(buf)[pos:body_end]) == int.from_bytes(buf[body_end:body_end + 3], "big"):
                self.frames += 1
                pos += total
            else:  # a 0xD3 inside junk: forward it and resynchronise on the next one
                self.junk_bytes += 1
                pos += 1
        out = bytes(buf[:pos])
        del buf[:pos]
        return out

    def flush(self) -> bytes:
        """Everything still held back (the source went away: forward the partial frame as-is)."""
        out = bytes(self._buf)
        self._buf.clear()
        return out


def split_rtcm3_frames(data: bytes) -> list[bytes]:
    """Complete, CRC-valid RTCM 3 frames in `data`, in order (junk and a partial tail skipped)."""
    frames = []
    pos, n = 0, len(data)
    while True:
        pos = data.find(RTCM3_PREAMBLE, pos)
        if pos < 0 or n - pos < RTCM3_HEADER_BYTES + RTCM3_CRC_BYTES:
            return frames
        length = ((data[pos + 1] & 0x03) << 8) | data[pos + 2]
        end = pos + RTCM3_HEADER_BYTES + length + RTCM3_CRC_BYTES
        if end <= n and crc24q(data[pos:end - 3]) == int.from_bytes(data[end - 3:end], "big"):
            frames.append(data[pos:end])
            pos = end
        else:
            pos += 1

"""CRC-24Q, the checksum of every RTCM 3 frame (RTCM 10403.3 section 4.2; also SBAS).

Generator x^24 + x^23 + x^18 + x^17 + x^14 + x^11 + x^10 + x^7 + x^6 + x^5 + x^4 + x^3 + x + 1,
initial value 0, no reflection, no final XOR; check value crc24q(b"123456789") == 0xCDE703
(reveng catalogue, CRC-24/LTE-A). Three forms, all giving the same integers:

  crc24q_bytewise   the classic table-driven byte loop (the reference the others are tested on)
  crc24q            one frame: the byte loop for short input, one numpy gather + XOR-reduce otherwise
  crc24q_rows       each row of an (n, L) uint8 array at once (the batch MSM encoder's frames)

The numpy forms use linearity over GF(2): with initial value 0 and no final XOR, the CRC of a message
is the XOR over its bytes of the CRC of that byte followed by as many zero bytes as come after it.
"""

from __future__ import annotations

import numpy as np

# RTCM 10403.3 section 4.2 (Qualcomm): the generator above with its x^24 term.
CRC24Q_POLY = 0x1864CFB
CRC24Q_MASK = 0xFFFFFF
CRC24Q_BYTES = 3
# Longest input the numpy form covers: a whole RTCM 3 frame, 3 header + 1023 payload + 3 CRC bytes
# (RTCM 10403.3 Table 4-1), so that crc24q(frame) == 0 checks a frame in one call.
CRC24Q_MAX_SPAN_BYTES = 1029
# Below this many bytes the byte loop beats numpy's per-call overhead (docs/decisions/0040).
CRC24Q_NUMPY_MIN_BYTES = 48


def _crc24q_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 16
        for _ in range(8):
            crc <<= 1
            if crc & 0x1000000:
                crc ^= CRC24Q_POLY
        table.append(crc & CRC24Q_MASK)
    return tuple(table)


CRC24Q_TABLE: tuple[int, ...] = _crc24q_table()


def crc24q_bytewise(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-24Q of `data`, continuing from `crc`, one table lookup per byte."""
    table = CRC24Q_TABLE
    for b in data:
        crc = ((crc << 8) & CRC24Q_MASK) ^ table[(crc >> 16) ^ b]
    return crc


def _byte_at_position_table() -> np.ndarray:
    """Flat (CRC24Q_MAX_SPAN_BYTES * 256,) table: entry 256 * i + b is the CRC of byte b followed by
    CRC24Q_MAX_SPAN_BYTES - 1 - i zero bytes."""
    table = np.array(CRC24Q_TABLE, dtype=np.uint32)
    rows = np.empty((CRC24Q_MAX_SPAN_BYTES, 256), dtype=np.uint32)
    rows[0] = table  # the single byte b (initial register 0)
    for zeros in range(1, CRC24Q_MAX_SPAN_BYTES):
        prev = rows[zeros - 1]
        rows[zeros] = ((prev << 8) & CRC24Q_MASK) ^ table[prev >> 16]  # one more zero byte
    return rows[::-1].ravel().copy()


_BYTE_AT = _byte_at_position_table()
# 256 * i for each position i: added to the byte values it indexes _BYTE_AT in one gather.
_ROW_OFFSETS = np.arange(CRC24Q_MAX_SPAN_BYTES, dtype=np.intp) * 256


def crc24q(data: bytes | bytearray | memoryview) -> int:
    """CRC-24Q of `data` (a 24-bit integer)."""
    n = len(data)
    if n < CRC24Q_NUMPY_MIN_BYTES or n > CRC24Q_MAX_SPAN_BYTES:
        return crc24q_bytewise(data)
    index = _ROW_OFFSETS[CRC24Q_MAX_SPAN_BYTES - n:] + np.frombuffer(data, dtype=np.uint8)
    return int(np.bitwise_xor.reduce(_BYTE_AT[index]))


def crc24q_rows(rows: np.ndarray) -> np.ndarray:
    """CRC-24Q of each row of an (n, L) uint8 array, L <= CRC24Q_MAX_SPAN_BYTES, as uint32."""
    rows = np.asarray(rows, dtype=np.uint8)
    n, length = rows.shape
    if length == 0:
        return np.zeros(n, dtype=np.uint32)
    index = rows.astype(np.intp)
    index += _ROW_OFFSETS[CRC24Q_MAX_SPAN_BYTES - length:]
    return np.bitwise_xor.reduce(_BYTE_AT[index], axis=1)

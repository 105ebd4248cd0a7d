"""Compiled CRC kernels (numba): the optional fast path behind rssp1.crc.

rssp1 is standard library only. This module is imported by rssp1.crc only when numba (and so numpy)
can be imported and RSSP1_BACKEND is not "python"; everything here has a pure-Python reference in
rssp1.crc, and tests/rssp1/test_fast_paths.py checks that the two agree on random inputs.

The tables are derived here from the polynomials (not taken from rssp1.crc), and the channel CRC32s
run in their MSB-first form -- normal polynomial, input bytes as they are, the final register read
bit-reversed -- where the reference runs the reflected form over bit-reversed input bytes. The two
forms are the same code (rssp1.md "Codes"), so an equality test between them checks both.

Compiled eagerly, with the machine code cached under __pycache__ (the first frame of a link never
waits for a compiler), for the buffers frames arrive in: bytes, bytearray, and memoryviews of either
(C-contiguous, format "B"). Any other buffer raises TypeError rather than being read some other way.
"""

from __future__ import annotations

import numpy as np
from numba import njit, typeof, types

CRC16_POLY_REFLECTED = 0x8810  # rssp1.md "Codes"
CRC32_POLYS_NORMAL = (0x100D4E63, 0x8CE56011)  # rssp1.md "Codes", channels 1 and 2


def reflected_table(poly_reflected: int, dtype) -> np.ndarray:
    """256-entry table of a reflected (LSB-first) CRC, all entries at once."""
    c = np.arange(256, dtype=np.uint64)
    for _ in range(8):
        c = np.where(c & 1, (c >> np.uint64(1)) ^ np.uint64(poly_reflected), c >> np.uint64(1))
    return c.astype(dtype)


def msb_first_table(poly_normal: int) -> np.ndarray:
    """256-entry table of an MSB-first 32-bit CRC: table[b] = register after shifting in byte b."""
    c = np.arange(256, dtype=np.uint64) << np.uint64(24)
    for _ in range(8):
        c = np.where(c & np.uint64(0x80000000), ((c << np.uint64(1)) & np.uint64(0xFFFFFFFF)) ^ np.uint64(poly_normal),
                     (c << np.uint64(1)) & np.uint64(0xFFFFFFFF))
    return c.astype(np.uint32)


CRC16_TABLE = reflected_table(CRC16_POLY_REFLECTED, np.uint16)
CRC32_CH1_TABLE = msb_first_table(CRC32_POLYS_NORMAL[0])
CRC32_CH2_TABLE = msb_first_table(CRC32_POLYS_NORMAL[1])

BUFFER_TYPES = (
    typeof(b""),
    typeof(bytearray()),
    typeof(memoryview(b"")),
    typeof(memoryview(bytearray())),
)
_KERNEL = {"cache": True, "nogil": True, "boundscheck": False}


@njit(inline="always")
def reverse32(x):
    """The 32 bits of x (an int64 below 2**32) in reverse order."""
    x = ((x >> 1) & 0x55555555) | ((x & 0x55555555) << 1)
    x = ((x >> 2) & 0x33333333) | ((x & 0x33333333) << 2)
    x = ((x >> 4) & 0x0F0F0F0F) | ((x & 0x0F0F0F0F) << 4)
    x = ((x >> 8) & 0x00FF00FF) | ((x & 0x00FF00FF) << 8)
    return ((x >> 16) | (x << 16)) & 0xFFFFFFFF


@njit(inline="always")
def crc16_span(buf, start, stop):
    """RSSP-I CRC16 (reflected 0x8810, init 0) of buf[start:stop]."""
    table = CRC16_TABLE
    c = 0
    for i in range(start, stop):
        c = np.int64(table[(c ^ buf[i]) & 0xFF]) ^ (c >> 8)
    return c


@njit(inline="always")
def crc32_pair_span(buf, start, stop):
    """Both channel CRC32s of buf[start:stop], MSB-first with the registers read bit-reversed."""
    t1, t2 = CRC32_CH1_TABLE, CRC32_CH2_TABLE
    c1 = 0
    c2 = 0
    for i in range(start, stop):
        b = np.int64(buf[i])
        c1 = ((c1 << 8) & 0xFFFFFFFF) ^ np.int64(t1[(c1 >> 24) ^ b])
        c2 = ((c2 << 8) & 0xFFFFFFFF) ^ np.int64(t2[(c2 >> 24) ^ b])
    return reverse32(c1), reverse32(c2)


@njit([types.int64(t) for t in BUFFER_TYPES], **_KERNEL)
def crc16(data):
    return crc16_span(data, 0, len(data))


@njit([types.UniTuple(types.int64, 2)(t) for t in BUFFER_TYPES], **_KERNEL)
def crc32_pair(data):
    return crc32_pair_span(data, 0, len(data))

"""Compiled kernels (numba): the optional fast paths behind rssp1.crc and rssp1.batch.

rssp1 is standard library only. This module is imported only when numba (and so numpy) can be
imported and RSSP1_BACKEND is not "python"; everything here has a pure-Python reference (rssp1.crc;
for the batch kernels, rssp1.batch's loop over rssp1.frames and rssp1.checkword), and
tests/rssp1/test_fast_paths.py checks that the two agree on random inputs.

The tables are derived here from the polynomials (not taken from rssp1.crc), and the channel CRC32s
run in their MSB-first form -- normal polynomial, input bytes as they are, the final register read
bit-reversed -- where the reference runs the reflected form over bit-reversed input bytes. The two
forms are the same code (rssp1.md "Codes"), so an equality test between them checks both.

The CRC kernels are compiled eagerly at import, with the machine code cached under __pycache__ (the
first frame of a link never waits for a compiler), for the buffers frames arrive in: bytes,
bytearray, and memoryviews of either (C-contiguous, format "B"); any other buffer raises TypeError
rather than being read some other way. The batch kernels compile (or load from the cache) at their
first call. All kernels live in this one file on purpose: numba's cache is invalidated by changes
to the file a kernel is defined in, not by changes to the helpers it inlines from other files.
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
_BATCH_KERNEL = {"cache": True, "nogil": True}  # compiled at first call, for the arrays rssp1.batch makes


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


# ------------------------------------------------------------------ batch kernels (rssp1.batch)
SYS_CHK_WD_1, SYS_CHK_WD_2 = 0xAE390B5A, 0xC103589C  # rssp1.md "Codes"
# rssp1.md "Frame"; the same numbers as rssp1.frames, restated so that this module imports nothing
# from rssp1 (tests compare the results with rssp1.frames).
PREFIX_BYTES = 20  # header 10 + SDS 2 + SVC_1 4 + SVC_2 4
OVERHEAD_BYTES = 22  # prefix + CRC16
MIN_FRAME_BYTES = 20  # the shortest frame of any type (SSE)
MAX_FRAME_BYTES = 1472
TYPE_RSD_A, TYPE_RSD_B = 0x80, 0x81
OK, SHORT, LONG, NOT_RSD, LENGTH, CRC16, SVC = range(7)  # rssp1.batch.REASONS, in this order


@njit(inline="always")
def _put_u16(out, at, v):
    out[at] = v & 0xFF
    out[at + 1] = (v >> 8) & 0xFF


@njit(inline="always")
def _put_u32(out, at, v):
    out[at] = v & 0xFF
    out[at + 1] = (v >> 8) & 0xFF
    out[at + 2] = (v >> 16) & 0xFF
    out[at + 3] = (v >> 24) & 0xFF


@njit(inline="always")
def _get_u16(buf, at):
    return np.int64(buf[at]) | (np.int64(buf[at + 1]) << 8)


@njit(inline="always")
def _get_u32(buf, at):
    return (np.int64(buf[at]) | (np.int64(buf[at + 1]) << 8) | (np.int64(buf[at + 2]) << 16)
            | (np.int64(buf[at + 3]) << 24))


@njit(**_BATCH_KERNEL)
def encode_rsds(data, data_off, category, msg_type, source, destination, tc, sid, t, out, out_off):
    """Frame i = RSD of data[data_off[i]:data_off[i+1]] written to out[out_off[i]:out_off[i+1]]."""
    for i in range(len(tc)):
        start, stop = data_off[i], data_off[i + 1]
        at = out_off[i]
        c1, c2 = crc32_pair_span(data, start, stop)
        out[at] = category[i]
        out[at + 1] = msg_type[i]
        _put_u16(out, at + 2, source[i])
        _put_u16(out, at + 4, destination[i])
        _put_u32(out, at + 6, tc[i])
        _put_u16(out, at + 10, stop - start + 8)
        _put_u32(out, at + 12, c1 ^ sid[i, 0] ^ t[i, 0] ^ SYS_CHK_WD_1)
        _put_u32(out, at + 16, c2 ^ sid[i, 1] ^ t[i, 1] ^ SYS_CHK_WD_2)
        body = at + PREFIX_BYTES
        for j in range(stop - start):
            out[body + j] = data[start + j]
        end = body + stop - start
        _put_u16(out, end, crc16_span(out, at, end))


@njit(**_BATCH_KERNEL)
def verify_rsds(frames, off, sid, t, compare, code, fields):
    """Check frames[off[i]:off[i+1]] as an RSD: size, type, SDS, CRC16; then the timestamps its check
    words claim under sid[i], compared with t[i] when `compare`.

    code[i] is one of OK..SVC; fields[i] = (category, type, source, destination, TC, T_1, T_2),
    filled as far as the frame got (the T only for frames that passed CRC16).
    """
    for i in range(len(code)):
        at, stop = off[i], off[i + 1]
        n = stop - at
        if n < MIN_FRAME_BYTES:
            code[i] = SHORT
            continue
        if n > MAX_FRAME_BYTES:
            code[i] = LONG
            continue
        msg_type = np.int64(frames[at + 1])
        fields[i, 0] = frames[at]
        fields[i, 1] = msg_type
        if msg_type != TYPE_RSD_A and msg_type != TYPE_RSD_B:
            code[i] = NOT_RSD
            continue
        fields[i, 2] = _get_u16(frames, at + 2)
        fields[i, 3] = _get_u16(frames, at + 4)
        fields[i, 4] = _get_u32(frames, at + 6)
        sds = _get_u16(frames, at + 10)
        if sds < 8 or n != 12 + sds + 2:
            code[i] = LENGTH
            continue
        if crc16_span(frames, at, stop) != 0:  # the zero residue over data + stored CRC (see frames.py)
            code[i] = CRC16
            continue
        c1, c2 = crc32_pair_span(frames, at + PREFIX_BYTES, stop - 2)
        t1 = _get_u32(frames, at + 12) ^ c1 ^ sid[i, 0] ^ SYS_CHK_WD_1
        t2 = _get_u32(frames, at + 16) ^ c2 ^ sid[i, 1] ^ SYS_CHK_WD_2
        fields[i, 5] = t1
        fields[i, 6] = t2
        if compare and (t1 != t[i, 0] or t2 != t[i, 1]):
            code[i] = SVC
        else:
            code[i] = OK


@njit(**_BATCH_KERNEL)
def timestamp_run(tables, t1, t2, out):
    """out[k] = both channels' T(n + k) from T(n) = (t1, t2); tables[ch] = the cycle map's 4 byte tables."""
    for k in range(out.shape[0]):
        out[k, 0] = t1
        out[k, 1] = t2
        t1 = (np.int64(tables[0, 0, t1 & 0xFF]) ^ np.int64(tables[0, 1, (t1 >> 8) & 0xFF])
              ^ np.int64(tables[0, 2, (t1 >> 16) & 0xFF]) ^ np.int64(tables[0, 3, t1 >> 24]))
        t2 = (np.int64(tables[1, 0, t2 & 0xFF]) ^ np.int64(tables[1, 1, (t2 >> 8) & 0xFF])
              ^ np.int64(tables[1, 2, (t2 >> 16) & 0xFF]) ^ np.int64(tables[1, 3, t2 >> 24]))

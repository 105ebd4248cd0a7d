"""CRC16 of the RSSP-I frame and the two channel CRC32s of the user data.

Parameters (rssp1.md, checked against 970 captured frames and the check values below):

- CRC16: reflected polynomial 0x8810 (normal 0x0811), init 0, no final XOR, over the whole frame
  except its last two bytes, stored low byte first. Check value of b"123456789": 0x83D1.
- CRC32 channel 1: normal polynomial 0x100D4E63, channel 2: 0x8CE56011; every input byte is
  bit-reversed, then the reflected algorithm (with the bit-reversed polynomial) runs, init 0, no final
  XOR. Check values of b"123456789": 0x65A297AC and 0xC12BAA78.

Two implementations of the same functions:

- the reference, pure Python (`crc16_py`, `crc32_pair_py`): the loops eat 32 bits per iteration (two
  lookups in 65,536-entry tables, two tables per code, built once at import in a fraction of a
  second; about 2.5 MB per table). Interpreted iterations are where the time goes: a quarter of a
  byte-at-a-time loop's;
- compiled (rssp1._compiled, numba, optional): byte-at-a-time kernels, about 0.25 us a call, most
  of it the call itself.

`crc16`, `crc32_pair`, `crc32_ch1`, `crc32_ch2` are whichever backend is selected: "numba" when numba
imports, else "python"; the environment variable RSSP1_BACKEND=python forces the reference (and
RSSP1_BACKEND=numba makes a missing numba an error). `use_backend()` switches at run time (the
benchmark measures both in one process). tests/rssp1/test_fast_paths.py checks both backends agree.
See augnet/bench/rssp1.py for the figures.
"""

from __future__ import annotations

import os
import struct

CRC16_POLY_REFLECTED = 0x8810  # normal form 0x0811; rssp1.md "Codes"
CRC32_CH1_POLY_NORMAL = 0x100D4E63  # rssp1.md "Codes", channel 1
CRC32_CH2_POLY_NORMAL = 0x8CE56011  # rssp1.md "Codes", channel 2

CRC16_CHECK = 0x83D1  # CRC16(b"123456789")
CRC32_CH1_CHECK = 0x65A297AC
CRC32_CH2_CHECK = 0xC12BAA78


def reverse_bits(value: int, width: int) -> int:
    """The bit order of `value` reversed over `width` bits."""
    out = 0
    for _ in range(width):
        out = (out << 1) | (value & 1)
        value >>= 1
    return out


_BYTE_REVERSED = bytes(reverse_bits(b, 8) for b in range(256))


def _reflected_step_table(poly_reflected: int, bits: int) -> list[int]:
    """table[x] = the register after shifting `bits` zero bits through a reflected CRC holding x."""
    table = []
    for x in range(1 << bits):
        c = x
        for _ in range(bits):
            c = (c >> 1) ^ poly_reflected if c & 1 else c >> 1
        table.append(c)
    return table


def _word_table(byte_table: list[int]) -> list[int]:
    """A table consuming one little-endian 16-bit word at a time, composed from the byte table.

    A reflected CRC is linear: after XORing the word into the register's low 16 bits, two byte steps
    equal step16(low 16 bits) XOR (register >> 16); step16 is tabulated here.
    """
    out = [0] * 65536
    for w in range(65536):
        r = w
        r = byte_table[r & 0xFF] ^ (r >> 8)
        r = byte_table[r & 0xFF] ^ (r >> 8)
        out[w] = r
    return out


def _low_half_32_table(word_table: list[int]) -> list[int]:
    """table[x] = the register after 32 shifts of a reflected CRC holding x (< 2**16).

    Consuming a 32-bit little-endian word w: with x = register ^ w, the new register is
    table[x & 0xFFFF] ^ word_table[x >> 16] (the high half only sees the second 16 shifts, which is
    word_table by linearity). Two lookups per four bytes: half the interpreted iterations again.
    """
    out = [0] * 65536
    for x in range(65536):
        r = word_table[x]
        out[x] = word_table[r & 0xFFFF] ^ (r >> 16)
    return out


_CRC16_BYTE = _reflected_step_table(CRC16_POLY_REFLECTED, 8)
_CRC16_WORD = _word_table(_CRC16_BYTE)
_CRC16_LOW32 = _low_half_32_table(_CRC16_WORD)

_CRC32_CH1_BYTE = _reflected_step_table(reverse_bits(CRC32_CH1_POLY_NORMAL, 32), 8)
_CRC32_CH2_BYTE = _reflected_step_table(reverse_bits(CRC32_CH2_POLY_NORMAL, 32), 8)
_CRC32_CH1_WORD = _word_table(_CRC32_CH1_BYTE)
_CRC32_CH2_WORD = _word_table(_CRC32_CH2_BYTE)
_CRC32_CH1_LOW32 = _low_half_32_table(_CRC32_CH1_WORD)
_CRC32_CH2_LOW32 = _low_half_32_table(_CRC32_CH2_WORD)

_WORD_FORMATS: dict[int, struct.Struct] = {}


def _words32(data: bytes | memoryview, n_words: int) -> tuple[int, ...]:
    fmt = _WORD_FORMATS.get(n_words)
    if fmt is None:
        fmt = _WORD_FORMATS.setdefault(n_words, struct.Struct(f"<{n_words}I"))
    return fmt.unpack_from(data, 0)


def crc16_py(data: bytes | bytearray | memoryview) -> int:
    """RSSP-I CRC16 (reflected 0x8810, init 0, no final XOR): the pure-Python reference."""
    low, word = _CRC16_LOW32, _CRC16_WORD
    n = len(data)
    c = 0
    for w in _words32(data, n >> 2):
        x = c ^ w
        c = low[x & 0xFFFF] ^ word[x >> 16]
    i = n & ~3
    if n & 2:
        c = word[c ^ data[i] ^ (data[i + 1] << 8)]
        i += 2
    if n & 1:
        c = _CRC16_BYTE[(c ^ data[i]) & 0xFF] ^ (c >> 8)
    return c


def crc32_pair_py(data: bytes | bytearray | memoryview) -> tuple[int, int]:
    """Both channel CRC32s in one pass over the data (init 0, no final XOR): the pure-Python reference."""
    l1, w1, l2, w2 = _CRC32_CH1_LOW32, _CRC32_CH1_WORD, _CRC32_CH2_LOW32, _CRC32_CH2_WORD
    # The codes take every byte bit-reversed; bytes.translate does that in C.
    data = bytes(data).translate(_BYTE_REVERSED)
    n = len(data)
    c1 = c2 = 0
    for w in _words32(data, n >> 2):
        x = c1 ^ w
        c1 = l1[x & 0xFFFF] ^ w1[x >> 16]
        x = c2 ^ w
        c2 = l2[x & 0xFFFF] ^ w2[x >> 16]
    i = n & ~3
    if n & 2:
        w = data[i] | (data[i + 1] << 8)
        c1 = w1[(c1 ^ w) & 0xFFFF] ^ (c1 >> 16)
        c2 = w2[(c2 ^ w) & 0xFFFF] ^ (c2 >> 16)
        i += 2
    if n & 1:
        b = data[i]
        c1 = _CRC32_CH1_BYTE[(c1 ^ b) & 0xFF] ^ (c1 >> 8)
        c2 = _CRC32_CH2_BYTE[(c2 ^ b) & 0xFF] ^ (c2 >> 8)
    return c1, c2


# ------------------------------------------------------------------------------------------ backends
def _compiled_functions():
    """(crc16, crc32_pair) as numba kernels: bytes, bytearray and their memoryviews; TypeError otherwise."""
    from rssp1 import _compiled

    return _compiled.crc16, _compiled.crc32_pair


BACKENDS: dict[str, tuple] = {"python": (crc16_py, crc32_pair_py)}
unavailable: dict[str, str] = {}  # backend -> why it is not in BACKENDS
_requested = os.environ.get("RSSP1_BACKEND", "").strip().lower()
if _requested not in ("", "python", "numba"):
    raise ImportError(f"RSSP1_BACKEND={_requested!r}: expected 'python' or 'numba'")
if _requested == "python":
    unavailable["numba"] = "RSSP1_BACKEND=python"
else:
    try:
        BACKENDS["numba"] = _compiled_functions()
    except Exception as exc:  # no numba, or one that cannot compile here: the reference does the work
        if _requested == "numba":
            raise
        unavailable["numba"] = f"{type(exc).__name__}: {exc}"

backend = "numba" if "numba" in BACKENDS else "python"
crc16, crc32_pair = BACKENDS[backend]


def crc32_ch1(data: bytes | bytearray | memoryview) -> int:
    """RSSP-I channel-1 CRC32 of the user data."""
    return crc32_pair(data)[0]


def crc32_ch2(data: bytes | bytearray | memoryview) -> int:
    """RSSP-I channel-2 CRC32 of the user data."""
    return crc32_pair(data)[1]


def use_backend(name: str) -> str:
    """Select the CRC backend for every rssp1 caller from now on; returns the previous one.

    Callers in rssp1 look the functions up in this module at each call, so this takes effect
    everywhere (a name imported with `from rssp1.crc import crc16` elsewhere keeps its backend;
    both compute the same values).
    """
    global backend, crc16, crc32_pair
    if name not in BACKENDS:
        raise ValueError(f"CRC backend {name!r} not available (have: {', '.join(BACKENDS)})")
    previous, backend = backend, name
    crc16, crc32_pair = BACKENDS[name]
    return previous

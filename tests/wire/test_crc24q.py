"""CRC-24Q: published vectors, pyrtcm's computation over real frames, and the three forms agreeing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyrtcm.rtcmhelpers import calc_crc24q

from augwire.crc24q import (
    CRC24Q_MAX_SPAN_BYTES,
    CRC24Q_NUMPY_MIN_BYTES,
    crc24q,
    crc24q_bytewise,
    crc24q_rows,
)
from augwire.rtcm_framing import split_frames

# RTCM 10403.3's worked example of message 1005 (a whole frame, CRC 0x360B98 at its end).
RTCM_1005_EXAMPLE = bytes.fromhex("D300133ED7D30202980EDEEF34B4BD62AC0941986F33360B98")
CAPTURES = ("ntrip-USCL00CHL0.rtcm3", "GMSD7_20121014.rtcm3", "testglo.rtcm3")


def test_published_vectors():
    assert crc24q(b"123456789") == 0xCDE703  # CRC-24/LTE-A check value (reveng catalogue)
    assert crc24q(b"") == 0
    assert crc24q(RTCM_1005_EXAMPLE[:-3]) == 0x360B98
    assert crc24q(RTCM_1005_EXAMPLE) == 0  # a frame followed by its CRC leaves no remainder


@pytest.mark.parametrize("name", CAPTURES)
def test_real_frames_against_pyrtcm(shared_data: Path, name: str):
    frames = split_frames((shared_data / "rtcm" / name).read_bytes())
    assert len(frames) > 30
    for raw in frames:
        body = raw[:-3]
        want = calc_crc24q(body)
        assert crc24q(body) == want == crc24q_bytewise(body) == int.from_bytes(raw[-3:], "big")
        assert crc24q(raw) == 0 and calc_crc24q(raw) == 0


def test_every_length_across_the_numpy_threshold():
    rng = np.random.default_rng(24)
    data = rng.integers(0, 256, CRC24Q_MAX_SPAN_BYTES + 8, dtype=np.uint8).tobytes()
    for n in list(range(0, CRC24Q_NUMPY_MIN_BYTES + 4)) + [100, 1023, 1026, 1028, 1029, 1030, 1037]:
        assert crc24q(data[:n]) == crc24q_bytewise(data[:n]) == calc_crc24q(data[:n]), n


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=CRC24Q_MAX_SPAN_BYTES + 10))
def test_buffer_types_and_forms_agree(data: bytes):
    want = crc24q_bytewise(data)
    assert crc24q(data) == crc24q(bytearray(data)) == crc24q(memoryview(data)) == want


def test_bytewise_continues_from_a_register():
    data = b"continue the register across two calls"
    assert crc24q_bytewise(data[17:], crc24q_bytewise(data[:17])) == crc24q_bytewise(data)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, CRC24Q_MAX_SPAN_BYTES), st.integers(1, 5), st.integers(0, 2**32 - 1))
def test_rows_equal_the_byte_loop(length: int, n: int, seed: int):
    rows = np.random.default_rng(seed).integers(0, 256, (n, length), dtype=np.uint8)
    got = crc24q_rows(rows)
    assert got.dtype == np.uint32
    assert got.tolist() == [crc24q_bytewise(r.tobytes()) for r in rows]

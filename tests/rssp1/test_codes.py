"""CRC16, channel CRC32s, timestamp LFSR, check words: check values, references, the rssp1.md vector."""

from __future__ import annotations

import random

from hypothesis import given, settings
from hypothesis import strategies as st

from rssp1 import checkword
from rssp1.crc import crc16, crc32_ch1, crc32_ch2, crc32_pair
from rssp1.frames import TYPE_RSD_A, Rsd, decode_frame, encode_frame, encode_rsd
from rssp1.timestamp import (
    TIMESTAMP_CH1,
    TIMESTAMP_CH1_POLY,
    TIMESTAMP_CH2,
    TIMESTAMP_CH2_POLY,
    lfsr_shift,
    timestamp_at,
)

CHECK_INPUT = b"123456789"
VECTOR = bytes.fromhex("018029000100191e00000900e82b2a639e92baf3073a24")  # rssp1.md "Test vector"
SID_0029 = (0x311616DC, 0x07643EDE)


def bitwise_crc(data: bytes, poly_normal: int, width: int, reverse_input_bytes: bool) -> int:
    """Textbook MSB-first CRC (no tables), written independently of rssp1.crc.

    The RSSP-I reflected CRC with bit-reversed input bytes equals an MSB-first CRC of the original
    bytes whose register is then read bit-reversed; the CRC16 (no input reversal) is the reflected
    CRC of each byte's bits LSB first. Both reduce to: feed message bits in a chosen order into an
    MSB-first shift register of the normal polynomial, then reverse the register.
    """
    reg = 0
    top = 1 << (width - 1)
    for byte in data:
        bits = [(byte >> i) & 1 for i in range(8)]  # LSB first: what a reflected CRC consumes
        if reverse_input_bytes:
            bits.reverse()
        for bit in bits:
            fb = bool(reg & top) ^ bit
            reg = (reg << 1) & ((1 << width) - 1)
            if fb:
                reg ^= poly_normal
    return int(f"{reg:0{width}b}"[::-1], 2)


def test_check_values():
    assert crc16(CHECK_INPUT) == 0x83D1
    assert crc32_ch1(CHECK_INPUT) == 0x65A297AC
    assert crc32_ch2(CHECK_INPUT) == 0xC12BAA78
    assert crc32_pair(b"") == (0, 0) and crc16(b"") == 0


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=80))
def test_table_crcs_match_bitwise_reference(data):
    assert crc16(data) == bitwise_crc(data, 0x0811, 16, reverse_input_bytes=False)
    assert crc32_pair(data) == (
        bitwise_crc(data, 0x100D4E63, 32, reverse_input_bytes=True),
        bitwise_crc(data, 0x8CE56011, 32, reverse_input_bytes=True),
    )


def test_lfsr_tables_and_jumps_match_bit_serial():
    rng = random.Random(7)
    for lfsr, poly in ((TIMESTAMP_CH1, TIMESTAMP_CH1_POLY), (TIMESTAMP_CH2, TIMESTAMP_CH2_POLY)):
        for _ in range(50):
            x = rng.getrandbits(32)
            assert lfsr.step(x) == lfsr_shift(x, poly, 32)
            n = rng.randrange(0, 300)
            serial = x
            for _ in range(n):
                serial = lfsr_shift(serial, poly, 32)
            assert lfsr.advance(x, n) == serial
            assert lfsr.power_map(n)(x) == serial
    # a long jump equals jumping in two parts
    x = 0x12345678
    assert TIMESTAMP_CH1.advance(x, 100_000) == TIMESTAMP_CH1.advance(TIMESTAMP_CH1.advance(x, 60_001), 39_999)


def test_one_cycle_of_each_timestamp_lfsr_has_order_2_pow_32_minus_1():
    """M^(2^32 - 1) = I, and M^((2^32 - 1) / p) != I for each prime p of 2^32 - 1 = 3 * 5 * 17 * 257 *
    65537. So for a nonzero SINIT, TCs less than 2^32 - 1 apart have distinct T(TC) (T(TC) binds TC),
    and T(2^32) = T(1), not T(0): hence the sender restarts from SINIT when its u32 TC wraps
    (rssp1.endpoint, "TC binding")."""
    period = (1 << 32) - 1
    for lfsr in (TIMESTAMP_CH1, TIMESTAMP_CH2):
        assert lfsr.power_map(period).rows() == [1 << i for i in range(32)]
        for p in (3, 5, 17, 257, 65537):
            assert lfsr.power_map(period // p).rows() != [1 << i for i in range(32)], p


def test_vector_decodes_verifies_and_round_trips():
    frame = decode_frame(VECTOR)
    assert isinstance(frame, Rsd)
    assert (frame.category, frame.msg_type, frame.source, frame.destination, frame.tc) == (1, TYPE_RSD_A, 0x29, 1, 7705)
    assert frame.svc == (0x632A2BE8, 0xF3BA929E) and frame.data == b"\x07"
    assert VECTOR[-2:] == (0x243A).to_bytes(2, "little")
    assert encode_frame(frame) == VECTOR
    t = timestamp_at(SID_0029, 7705)  # T(0) = SID
    assert checkword.svc(b"\x07", SID_0029, t) == frame.svc
    assert encode_rsd(0x29, 1, 7705, checkword.svc(b"\x07", SID_0029, t), b"\x07") == VECTOR


def test_sse_ssr_words_recover_the_senders_timestamp():
    rng = random.Random(3)
    for _ in range(20):
        sid_a, t_a = (rng.getrandbits(32), rng.getrandbits(32)), (rng.getrandbits(32), rng.getrandbits(32))
        sid_b, t_b, dv_b = ((rng.getrandbits(32), rng.getrandbits(32)) for _ in range(3))
        enq = checkword.seqenq(sid_a, t_a)
        ini = checkword.seqini(enq, sid_b, dv_b, t_b)
        assert checkword.timestamp_from_ssr(ini, enq, sid_b, dv_b) == t_b

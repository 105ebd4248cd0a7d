"""Framing: CRC-24Q, frame(), and the stream reader's behaviour on good and bad input."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from augwire.crc24q import crc24q
from augwire.rtcm_framing import (
    MAX_PAYLOAD_BYTES,
    FramingError,
    RtcmStreamReader,
    frame,
    read_frames,
)

# Frames built from arbitrary payloads that start with a plausible 12-bit message number.
payloads = st.binary(min_size=2, max_size=300)


def test_crc24q_check_value():
    # The CRC-24Q "check" value (CRC of ASCII "123456789"), as published for the Qualcomm CRC used by
    # RTCM 3 and SBAS (e.g. reveng's catalogue: CRC-24/LTE-A, poly 0x864CFB, init 0): 0xCDE703.
    assert crc24q(b"123456789") == 0xCDE703


def test_crc24q_of_a_whole_frame_is_zero():
    raw = frame(b"\x3e\xd0\x00\x03")
    assert crc24q(raw) == 0  # a frame followed by its CRC leaves no remainder


def test_frame_layout():
    raw = frame(bytes(19))
    assert raw[0] == 0xD3 and raw[1] == 0 and raw[2] == 19 and len(raw) == 19 + 6


def test_frame_rejects_oversized_payload():
    with pytest.raises(FramingError):
        frame(bytes(MAX_PAYLOAD_BYTES + 1))


def test_frame_matches_pyrtcm_crc():
    from pyrtcm.rtcmhelpers import calc_crc24q

    for n in (2, 17, 300, 1023):
        raw = frame((bytes(range(256)) * 4)[:n])
        assert calc_crc24q(raw) == 0


def test_real_capture_frames_and_truncated_tail(shared_data):
    ff = read_frames(shared_data / "rtcm" / "GMSD7_20121014.rtcm3")
    assert ff.stats.crc_failures == 0
    assert ff.stats.frames_ok == len(ff.frames) > 1000
    # The capture was cut at 256 KiB: the last frame is partial and reported as such.
    assert ff.truncated_tail_bytes > 0
    assert ff.stats.truncated_bytes == ff.truncated_tail_bytes
    size = (shared_data / "rtcm" / "GMSD7_20121014.rtcm3").stat().st_size
    assert sum(len(f.raw) for f in ff.frames) + ff.stats.bytes_skipped + ff.truncated_tail_bytes == size


def test_ascii_preamble_lines_are_skipped(shared_data):
    # testglo.rtcm3 starts with receiver console text ("[USB1]\r\n<OK\r\n...") before the frames.
    ff = read_frames(shared_data / "rtcm" / "testglo.rtcm3")
    assert ff.stats.bytes_skipped > 0 and ff.stats.crc_failures == 0
    assert ff.stats.by_type[1004] > 100


def test_byte_at_a_time_equals_whole(shared_data):
    data = (shared_data / "rtcm" / "ntrip-USCL00CHL0.rtcm3").read_bytes()
    whole = RtcmStreamReader().feed(data)
    r = RtcmStreamReader()
    one = [f for i in range(len(data)) for f in r.feed(data[i : i + 1])]
    assert [f.raw for f in one] == [f.raw for f in whole]
    assert len(whole) == 35 and r.pending_bytes == 0


def test_bad_crc_is_counted_and_the_next_frame_recovered():
    good1, good2 = frame(b"\x3e\xd0" + bytes(10)), frame(b"\x3e\xe0" + bytes(20))
    bad = bytearray(frame(b"\x3e\xf0" + bytes(15)))
    bad[8] ^= 0x40
    r = RtcmStreamReader()
    out = r.feed(good1 + bytes(bad) + good2)
    assert [f.raw for f in out] == [good1, good2]
    assert r.stats.crc_failures == 1
    assert r.stats.frames_ok == 2
    assert r.stats.bytes_skipped == len(bad)


def test_frame_hidden_behind_false_preamble():
    # A 0xD3 in garbage announcing a long frame swallows the real one; after the CRC fails the
    # reader must step one byte and find the real frame inside the false candidate.
    good = frame(b"\x3e\xd0" + bytes(5))
    data = b"\xd3\x00\x20" + good + bytes(40)
    r = RtcmStreamReader()
    out = r.feed(data)
    assert [f.raw for f in out] == [good]
    assert r.stats.crc_failures == 1


def test_truncated_frame_waits_then_close_reports_it():
    good = frame(b"\x3e\xd0" + bytes(30))
    r = RtcmStreamReader()
    assert r.feed(good[:-5]) == []
    assert r.pending_bytes == len(good) - 5
    assert r.close() == []
    assert r.stats.truncated_bytes == len(good) - 5 and r.stats.frames_ok == 0


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=3000))
def test_random_bytes_never_raise(data):
    r = RtcmStreamReader()
    out = r.feed(data)
    out += r.close()
    for f in out:  # anything returned is a genuine frame (astronomically unlikely from noise)
        assert crc24q(f.raw) == 0
    s = r.stats
    assert s.bytes_skipped + s.truncated_bytes + sum(len(f.raw) for f in out) == len(data)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.tuples(payloads, st.binary(max_size=60)), min_size=1, max_size=12),
    st.lists(st.integers(1, 400), min_size=1, max_size=30),
)
def test_frames_interleaved_with_garbage_are_all_recovered(items, cuts):
    # Garbage without 0xD3 cannot hide a frame; garbage containing false preambles is tested by
    # the test above and by test_garbage_with_preambles.
    stream = b""
    frames = []
    for payload, junk in items:
        junk = junk.replace(b"\xd3", b"\x00")
        raw = frame(payload)
        frames.append(raw)
        stream += junk + raw
    r = RtcmStreamReader()
    out = []
    pos = 0
    for c in cuts * (len(stream) // max(1, sum(cuts)) + 1):  # split at arbitrary boundaries
        if pos >= len(stream):
            break
        out += r.feed(stream[pos : pos + c])
        pos += c
    out += r.feed(stream[pos:])
    assert [f.raw for f in out] == frames
    assert r.stats.frames_ok == len(frames) and r.stats.crc_failures == 0


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(payloads, st.binary(max_size=40)), min_size=1, max_size=10), st.integers(0, 2**31))
def test_garbage_with_preambles(items, seed):
    # Garbage that does contain 0xD3 bytes (false preambles with random lengths). A false candidate
    # can only hide a real frame when its CRC passes by chance (2^-24); every real frame comes out.
    rnd = random.Random(seed)
    stream = b""
    frames = []
    for payload, junk in items:
        junk = bytes(b if rnd.random() > 0.2 else 0xD3 for b in junk)
        raw = frame(payload)
        frames.append(raw)
        stream += junk + raw
    r = RtcmStreamReader()
    out = r.feed(stream)
    out += r.close()
    got = [f.raw for f in out]
    # every real frame is recovered, in order (extra frames would need a 2^-24 CRC coincidence)
    it = iter(got)
    assert all(any(g == f for g in it) for f in frames)
    assert len(got) == len(frames)


def test_false_preamble_before_the_last_frame_is_resolved_at_close():
    # The false candidate announces 80 bytes that never come; the live reader must wait (more bytes
    # could complete it), and at end of input the frame behind it is still delivered.
    good = frame(b"\x3e\xd0" + bytes(5))
    r = RtcmStreamReader()
    assert r.feed(b"\xd3\x00\x50" + good) == []
    assert [f.raw for f in r.close()] == [good]
    assert r.stats.truncated_bytes == 3 and r.stats.frames_ok == 1


@pytest.fixture(scope="module")
def real_frames(shared_data):
    return [f.raw for f in read_frames(shared_data / "rtcm" / "ntrip-USCL00CHL0.rtcm3").frames]


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_real_frames_survive_garbage_truncation_and_corruption(real_frames, seed):
    # Each real frame is sent intact, truncated (the rest never comes), or with one bit flipped,
    # with garbage (false preambles included) before it; fed in random chunks. Every intact frame
    # must come out, in order; every damaged one must be counted, never returned.
    rnd = random.Random(seed)
    stream = b""
    intact = []
    damaged = 0
    for raw in real_frames:
        junk = bytes(rnd.choice((0xD3, rnd.randrange(256))) for _ in range(rnd.randrange(30)))
        fate = rnd.choice(["intact", "intact", "truncated", "corrupted"])
        if fate == "intact":
            intact.append(raw)
            stream += junk + raw
        elif fate == "truncated":
            damaged += 1
            # At least 3 bytes missing: the bytes that follow then complete the frame with a valid
            # CRC-24 only by a 2^-24 chance (1 missing byte: 1/256, and the frame is really there).
            stream += junk + raw[: rnd.randrange(1, len(raw) - 3)]
        else:
            damaged += 1
            bad = bytearray(raw)
            bad[rnd.randrange(len(raw))] ^= 1 << rnd.randrange(8)
            stream += junk + bytes(bad)
    r = RtcmStreamReader()
    out = []
    pos = 0
    while pos < len(stream):
        step = rnd.randrange(1, 700)
        out += r.feed(stream[pos : pos + step])
        pos += step
    out += r.close()
    assert [f.raw for f in out] == intact
    s = r.stats
    assert s.frames_ok == len(intact)
    assert s.bytes_skipped + s.truncated_bytes + sum(len(f.raw) for f in out) == len(stream)
    if damaged:
        assert s.crc_failures + s.truncated_bytes > 0

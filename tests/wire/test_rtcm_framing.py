"""RTCM 3 framing on real captures: every split point gives the same frames and counters as the whole
input, the aligner forwards every byte, and corrupt frames are counted and skipped, never returned."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from pyrtcm import RTCMReader

from augwire.crc24q import crc24q
from augwire.rtcm_framing import (
    MAX_FRAME_BYTES,
    FramingError,
    RtcmFrameAligner,
    RtcmStreamReader,
    frame,
    frame_length,
    message_type,
    scan_frames,
    split_frames,
)


@pytest.fixture(scope="module")
def capture(shared_data: Path) -> bytes:
    # 35 frames of a real NTRIP stream (MSM, 1005, 1033...): every split point stays affordable.
    return (shared_data / "rtcm" / "ntrip-USCL00CHL0.rtcm3").read_bytes()


def _stats(reader: RtcmStreamReader) -> tuple:
    s = reader.stats
    return s.frames_ok, s.crc_failures, s.bytes_skipped, s.truncated_bytes, dict(s.by_type)


def _read(pieces: list[bytes]) -> tuple[list[bytes], tuple]:
    reader = RtcmStreamReader()
    out = [f.raw for piece in pieces for f in reader.feed(piece)]
    out += [f.raw for f in reader.close()]
    return out, _stats(reader)


def test_split_frames_equal_pyrtcm(capture: bytes):
    theirs = [raw for raw, _ in RTCMReader(io.BufferedReader(io.BytesIO(capture)))]
    assert split_frames(capture) == theirs and len(theirs) == 35


def test_every_split_point_of_a_capture(capture: bytes):
    # Garbage with a false preamble in front, a truncated frame at the end: all counters move.
    stream = b"junk\xd3\x00\x07" + capture + capture[:40]
    whole = _read([stream])
    assert len(whole[0]) == 35 and whole[1][2] > 0 and whole[1][3] == 40
    for cut in range(len(stream) + 1):
        assert _read([stream[:cut], stream[cut:]]) == whole, cut


def test_byte_by_byte_and_odd_splits(capture: bytes):
    stream = capture + b"\xd3" + capture
    whole = _read([stream])
    assert _read([stream[i:i + 1] for i in range(len(stream))]) == whole
    for step in (2, 3, 7, 1000, MAX_FRAME_BYTES, 4096):
        assert _read([stream[i:i + step] for i in range(0, len(stream), step)]) == whole, step


def test_aligner_forwards_every_byte_at_every_split_point(capture: bytes):
    stream = b"garbage\xd3\xd3" + capture
    want_frames = len(split_frames(stream))
    for cut in range(len(stream) + 1):
        a = RtcmFrameAligner()
        out = a.feed(stream[:cut]) + a.feed(stream[cut:])
        assert out == stream and a.pending == 0 and a.frames == want_frames, cut
        assert a.junk_bytes == len(b"garbage\xd3\xd3")


def test_aligner_holds_back_only_the_incomplete_frame(capture: bytes):
    frames = split_frames(capture)
    a = RtcmFrameAligner()
    assert a.feed(frames[0] + frames[1][:10]) == frames[0] and a.pending == 10
    assert a.flush() == frames[1][:10] and a.pending == 0


def test_corrupt_frames_are_counted_and_skipped(capture: bytes):
    frames = split_frames(capture)
    bad = bytearray(frames[3])
    bad[len(bad) // 2] ^= 0x10
    stream = b"".join(frames[:3]) + bytes(bad) + b"".join(frames[4:])
    got, (ok, crc_failures, skipped, truncated, _by_type) = _read([stream])
    assert got == frames[:3] + frames[4:]
    assert (ok, crc_failures, skipped, truncated) == (34, 1, len(bad), 0)
    a = RtcmFrameAligner()
    assert a.feed(stream) == stream and (a.frames, a.junk_bytes) == (34, len(bad))


def test_reserved_bits_reader_rejects_aligner_accepts():
    # RTCM 10403.3 Table 4-1 wants the 6 bits above the length zero: the reader says "not a frame";
    # the aligner ignores them as RTKLIB's decoder does, so the caster forwards the frame as a frame.
    body = bytes((0xD3, 0x04, 5)) + b"\x3e\xd0abc"  # a reserved bit set above the length 5
    odd = body + crc24q(body).to_bytes(3, "big")
    assert frame_length(odd, 0) == len(odd)
    reader = RtcmStreamReader()
    assert reader.feed(odd) + reader.close() == [] and reader.stats.frames_ok == 0
    assert reader.stats.bytes_skipped + reader.stats.truncated_bytes == len(odd)
    assert scan_frames(odd, reserved_bits_must_be_zero=False).spans == [(0, len(odd))]
    a = RtcmFrameAligner()
    assert a.feed(odd) == odd and a.frames == 1 and a.junk_bytes == 0
    assert split_frames(odd) == [odd]


def test_frame_build_and_fields():
    raw = frame(b"\x3e\xd0" + bytes(17))
    assert raw[:3] == b"\xd3\x00\x13" and frame_length(raw, 0) == len(raw) == 25
    assert message_type(raw[3:-3]) == 1005 and message_type(b"\x3e") == 0
    with pytest.raises(FramingError):
        frame(bytes(1024))
    assert isinstance(FramingError("x"), ValueError)

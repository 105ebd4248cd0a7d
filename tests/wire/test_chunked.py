"""Chunked transfer coding: the encoder, and the decoder fed whole, byte by byte and in odd splits,
on good bodies (extensions, trailers, bare LF) and bad ones (sizes, CRLF, limits)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from augwire.chunked import (
    LAST_CHUNK,
    MAX_CHUNK_BYTES,
    MAX_CHUNK_SIZE_LINE_BYTES,
    ChunkedDecoder,
    encode_chunk,
)
from augwire.errors import NtripProtocolError

PAYLOADS = [bytes(range(256)) * 3, b"x", b"\r\n0\r\n\r\n", bytes(1029)]
BODY = b"".join(encode_chunk(p) for p in PAYLOADS) + LAST_CHUNK


def _decode(pieces: list[bytes], **limits) -> tuple[bytes, bool]:
    d = ChunkedDecoder(**limits)
    data = b"".join(b"".join(d.feed(piece)) for piece in pieces)
    return data, d.finished


def _splits(body: bytes):
    yield [body]
    yield [body[i:i + 1] for i in range(len(body))]
    for step in (2, 3, 5, 7, 64, 1000):
        yield [body[i:i + step] for i in range(0, len(body), step)]
    for cut in (1, 2, 3, 4, 5, len(body) // 2, len(body) - 2, len(body) - 1):
        yield [body[:cut], body[cut:]]


def test_encoder():
    assert encode_chunk(b"x" * 1024) == b"400\r\n" + b"x" * 1024 + b"\r\n"
    assert encode_chunk(b"abc") == b"3\r\nabc\r\n"
    with pytest.raises(ValueError):
        encode_chunk(b"")
    assert LAST_CHUNK == b"0\r\n\r\n"


def test_every_split_gives_the_same_data():
    for pieces in _splits(BODY):
        assert _decode(pieces) == (b"".join(PAYLOADS), True)


def test_one_whole_chunk_per_feed_returns_it_as_one_piece():
    d = ChunkedDecoder()
    for p in PAYLOADS:
        assert d.feed(encode_chunk(p)) == [p]
    assert d.feed(LAST_CHUNK) == [] and d.finished


@pytest.mark.parametrize("body", [
    b"3;name=value\r\nabc\r\n4;a;b=\"q\"\r\ndefg\r\n0\r\n\r\n",  # chunk extensions
    b"3\r\nabc\r\n4\r\ndefg\r\n0\r\nExpires: never\r\nX-Trailer: 1\r\n\r\n",  # trailers
    b"3\nabc\n4\r\ndefg\n0\n\n",  # bare LF line ends (RFC 9112 section 2.2)
    b"03 \r\nabc\r\n04\t\r\ndefg\r\n00000\r\n\r\n",  # leading zeros, white space after the size
    b"3\r\nabc\r\n4\r\ndefg\r\n0\r\n\r\nbytes after the end are ignored",
])
def test_accepted_forms(body: bytes):
    for pieces in _splits(body):
        assert _decode(pieces) == (b"abcdefg", True)


@pytest.mark.parametrize("bad", [
    b"zz\r\n", b"-5\r\nhello\r\n", b"+5\r\nhello\r\n", b"0x5\r\nhello\r\n", b"5_0\r\n", b"\r\n",
    b";ext\r\n", b" \r\n",  # sizes int(..., 16) alone would take, or no size at all
    b"5\r\nhelloXX",  # data not followed by CRLF
    b"5\r\nhello\rX",
    b"1" * (MAX_CHUNK_SIZE_LINE_BYTES + 1),  # size line too long, no line end yet
    b"1;" + b"e" * MAX_CHUNK_SIZE_LINE_BYTES + b"\r\n",  # too long, line end present
    b"%X\r\n" % (MAX_CHUNK_BYTES + 1),  # chunk over the bound
    b"FFFFFFFF\r\n",
    b"0\r\n" + b"T" * (MAX_CHUNK_SIZE_LINE_BYTES + 1),  # trailer line too long
])
def test_rejected_forms_whatever_the_split(bad: bytes):
    for pieces in _splits(bad):
        with pytest.raises(NtripProtocolError) as err:
            _decode(pieces)
        assert err.value.status == 400


def test_limits_are_parameters():
    big = b"%X\r\n" % (MAX_CHUNK_BYTES + 1) + bytes(MAX_CHUNK_BYTES + 1) + b"\r\n" + LAST_CHUNK
    assert _decode([big], max_chunk_bytes=None) == (bytes(MAX_CHUNK_BYTES + 1), True)
    with pytest.raises(NtripProtocolError, match="too long"):
        _decode([b"3;" + b"e" * 70 + b"\r\nabc\r\n"], max_size_line_bytes=64)
    assert _decode([b"3;" + b"e" * 50 + b"\r\nabc\r\n" + LAST_CHUNK], max_size_line_bytes=64) == (b"abc", True)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.binary(min_size=1, max_size=300), st.sampled_from([b"", b";x", b";a=1;b"])),
                max_size=8),
       st.lists(st.integers(1, 50), min_size=1, max_size=20))
def test_random_bodies_in_random_splits(chunks, cuts):
    body = b"".join(b"%x%b\r\n%b\r\n" % (len(p), ext, p) for p, ext in chunks) + LAST_CHUNK
    pieces, pos, k = [], 0, 0
    while pos < len(body):
        step = cuts[k % len(cuts)]
        pieces.append(body[pos:pos + step])
        pos += step
        k += 1
    assert _decode(pieces) == (b"".join(p for p, _ in chunks), True)

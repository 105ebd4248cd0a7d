"""The sans-IO core driven with bytes: request parsing, chunking, GGA, sourcetable, RTCM frames."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyrtcm import RTCMReader

from augwire.chunked import ChunkedDecoder, encode_chunk
from augwire.crc24q import crc24q, crc24q_bytewise
from augwire.errors import NtripProtocolError
from augwire.rtcm_framing import RtcmFrameAligner
from augwire.rtcm_framing import frame as frame_rtcm3
from augwire.rtcm_framing import split_frames as split_rtcm3_frames
from ntrip_caster.connection import (CLIENT, CLOSED, GgaLine, NtripServerConnection, RequestReceived,
                                     SourceData, SourceFinished)
from ntrip_caster.gga import NmeaLineSplitter, format_gga, great_circle_m, parse_gga
from ntrip_caster.limits import MAX_NMEA_LINE_BYTES, MAX_REQUEST_HEAD_BYTES
from ntrip_caster.reposition import RepositionPolicy, choose_base
from ntrip_caster.response import error_response, sourcetable_response, stream_ok
from ntrip_caster.sourcetable import StrRecord, parse_sourcetable, render_sourcetable

from .helpers import basic

# What real clients send (ntrip.md), byte for byte.
RTKLIB_V1_CLIENT = (b"GET /BASE01 HTTP/1.0\r\nUser-Agent: NTRIP RTKLIB/2.4.3\r\n"
                    b"Authorization: Basic dHJhaW4xOnB3\r\n\r\n")
RTKLIB_V1_SOURCE = b"SOURCE pw BASE01\r\nSource-Agent: NTRIP RTKLIB/2.4.3\r\nSTR: \r\n\r\n"
BKG_V1_CLIENT = b"GET /BASE01 HTTP/1.1\r\nHost: x\r\nUser-Agent: NTRIP BNC/2.12\r\n\r\n"
GGA = format_gga(31.2, 121.4, 12.5)


def test_rtklib_v1_client_request():
    (ev,) = NtripServerConnection().receive_data(RTKLIB_V1_CLIENT)
    r = ev.request
    assert (r.kind, r.version, r.mount, r.user, r.password) == ("client", 1, "BASE01", "train1", "pw")
    assert r.user_agent == "NTRIP RTKLIB/2.4.3"


def test_version_comes_from_header_not_http_version():
    (ev,) = NtripServerConnection().receive_data(BKG_V1_CLIENT)
    assert ev.request.version == 1 and ev.request.http_version == "HTTP/1.1"
    (ev,) = NtripServerConnection().receive_data(
        b"GET /M HTTP/1.0\r\nNtrip-Version: Ntrip/2.0\r\n\r\n")
    assert ev.request.version == 2


def test_v1_source_with_and_without_slash_and_data_after_head():
    conn = NtripServerConnection()
    events = conn.receive_data(RTKLIB_V1_SOURCE + b"\xd3\x00\x00")
    assert events[0].request.kind == "source" and events[0].request.mount == "BASE01"
    assert events[0].request.password == "pw" and events[1] == SourceData(b"\xd3\x00\x00")
    (ev,) = NtripServerConnection().receive_data(b"SOURCE pw /BASE01\r\n\r\n")
    assert ev.request.mount == "BASE01"


def test_v2_post_chunked_source_split_everywhere():
    head = (b"POST /BASE01 HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\n"
            b"Authorization: " + basic("station1", "pw").encode() + b"\r\n"
            b"Ntrip-STR: STR;BASE01;x\r\nTransfer-Encoding: chunked\r\n\r\n")
    payload = bytes(range(256)) * 3
    body = encode_chunk(payload[:100]) + encode_chunk(payload[100:]) + b"0\r\n\r\n"
    wire = head + body
    for split in range(1, len(wire)):
        conn = NtripServerConnection()
        events = conn.receive_data(wire[:split]) + conn.receive_data(wire[split:])
        req = events[0].request
        assert (req.kind, req.version, req.chunked, req.user) == ("source", 2, True, "station1")
        assert req.str_record == "STR;BASE01;x"
        assert b"".join(e.data for e in events if isinstance(e, SourceData)) == payload
        assert isinstance(events[-1], SourceFinished) and conn.state == CLOSED


def test_request_fed_one_byte_at_a_time_with_gga_line():
    conn = NtripServerConnection()
    events = []
    for b in RTKLIB_V1_CLIENT + GGA + b"$GPGSV,1,1*00\r\n" + GGA:
        events += conn.receive_data(bytes([b]))
    assert isinstance(events[0], RequestReceived) and conn.state == CLIENT
    assert events[1:] == [GgaLine(GGA.strip()), GgaLine(GGA.strip())]


def test_v2_gga_header_parsed():
    (ev,) = NtripServerConnection().receive_data(
        b"GET /VRS HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\nNtrip-GGA: " + GGA + b"\r\n")
    assert ev.request.gga is not None and abs(ev.request.gga.lat_deg - 31.2) < 1e-9


@pytest.mark.parametrize("wire,status", [
    (b"\r\n\r\n", 400),
    (b"FOO /x HTTP/1.0\r\n\r\n", 400),
    (b"PUT /x HTTP/1.1\r\n\r\n", 501),
    (b"GET /x HTTP/2.0\r\n\r\n", 505),
    (b"GET /x\r\n\r\n", 400),
    (b"GET /x HTTP/1.0\r\nno colon here\r\n\r\n", 400),
    (b"GET /x HTTP/1.0\r\n folded: x\r\n\r\n", 400),
    (b"GET /x HTTP/1.0\r\nBad Name: x\r\n\r\n", 400),
    (b"SOURCE\r\n\r\n", 400),
    (b"POST / HTTP/1.1\r\n\r\n", 400),
    (b"POST /M HTTP/1.1\r\nTransfer-Encoding: gzip\r\n\r\n", 501),
    (b"GET /x HTTP/1.0\r\n" + b"A: b\r\n" * 101 + b"\r\n", 431),
    (b"GET /\x01 HTTP/1.0\r\n\r\n", 400),
])
def test_malformed_requests(wire, status):
    conn = NtripServerConnection()
    with pytest.raises(NtripProtocolError) as info:
        conn.receive_data(wire)
    assert info.value.status == status and conn.state == CLOSED
    assert conn.receive_data(b"more") == []


def test_head_size_bounded():
    conn = NtripServerConnection()
    conn.receive_data(b"GET /x HTTP/1.0\r\n")
    with pytest.raises(NtripProtocolError) as info:
        for _ in range(MAX_REQUEST_HEAD_BYTES // 10 + 2):
            conn.receive_data(b"X-Pad: 12\r")  # never a blank line
    assert info.value.status == 431


def test_invalid_mount_names_are_unknown_not_malformed():
    (ev,) = NtripServerConnection().receive_data(b"GET /a%20b HTTP/1.0\r\n\r\n")
    assert ev.request.mount == "a b" and not ev.request.valid_mount
    (ev,) = NtripServerConnection().receive_data(b"GET http://host:2101/M1 HTTP/1.0\r\n\r\n")
    assert ev.request.mount == "M1" and ev.request.valid_mount


def test_chunk_decoder_rejects_bad_input():
    for bad in (b"zz\r\n", b"5\r\nhelloXX", b"1" * 2000, b"FFFFFFFF\r\n"):
        with pytest.raises(NtripProtocolError):
            ChunkedDecoder().feed(bad)
    d = ChunkedDecoder()
    assert d.feed(b"3;ext=1\r\nabc\r\n0\r\nTrailer: x\r\n\r\nignored") == [b"abc"] and d.finished
    with pytest.raises(ValueError):
        encode_chunk(b"")
    assert encode_chunk(b"x" * 1024) == b"400\r\n" + b"x" * 1024 + b"\r\n"


def test_gga_parsing():
    fix = parse_gga(GGA)
    assert fix is not None and abs(fix.lat_deg - 31.2) < 1e-9 and abs(fix.lon_deg - 121.4) < 1e-9
    assert fix.height_m == 12.5 and fix.talker == "GN"
    assert parse_gga(format_gga(-33.9, -70.6, talker="GP")).lon_deg == pytest.approx(-70.6)
    assert parse_gga(format_gga(10, 10, talker="GB")).talker == "GB"
    bad_checksum = GGA.replace(b"*", b"*0")[:-4] + b"\r\n"
    assert parse_gga(bad_checksum) is None
    # RTKLIB 2.4.3 before it has a solution: empty position, 0 satellites
    empty = b"GNGGA,000001.00,,,,,0,00,99.99,,,,,,"
    from ntrip_caster.gga import nmea_checksum
    assert parse_gga(b"$%b*%02X" % (empty, nmea_checksum(empty))) is None
    assert parse_gga(b"$GPRMC,1,2,3*00") is None
    assert parse_gga(b"$GNGGA,1,9100.0,N,00000.0,E,1,5,1,0,M,0,M,,") is None  # lat > 90
    assert parse_gga(b"$" + b"GNGGA," * 100) is None


def test_nmea_line_splitter_bounds_lines():
    sp = NmeaLineSplitter()
    assert sp.feed(b"x" * (MAX_NMEA_LINE_BYTES + 10)) == []
    assert sp.feed(b"still the same long line\r\n" + GGA) == [GGA.strip()]


def test_great_circle_and_reposition_policy():
    assert great_circle_m(0, 0, 0, 1) == pytest.approx(111_319.5, rel=1e-4)
    p = RepositionPolicy(min_interval_s=10, max_interval_s=120, min_move_m=10)
    a, near, far = parse_gga(format_gga(31, 121)), parse_gga(format_gga(31.00005, 121)), \
        parse_gga(format_gga(31.001, 121))
    assert p.due(0, a)
    p.applied(0, a)
    assert not p.due(5, far)  # too soon
    assert not p.due(15, near)  # 5.6 m: not enough movement
    assert p.due(15, far)  # 111 m
    assert p.due(121, near)  # always after 120 s
    bases = {"A": (31.0, 121.0), "B": (31.0, 121.1)}
    assert choose_base(parse_gga(format_gga(31, 121.04)), bases, None) == "A"
    assert choose_base(parse_gga(format_gga(31, 121.052)), bases, "A") == "A"  # ~370 m nearer B
    assert choose_base(parse_gga(format_gga(31, 121.06)), bases, "A") == "B"  # ~1.9 km nearer
    assert choose_base(a, {}, None) is None


def test_responses():
    assert stream_ok(1) == b"ICY 200 OK\r\n"
    v2 = stream_ok(2)
    for h in (b"Ntrip-Version: Ntrip/2.0", b"Cache-Control: no-store,no-cache,max-age=0",
              b"Pragma: no-cache", b"Connection: close", b"Content-Type: gnss/data",
              b"Transfer-Encoding: chunked", b"Date: ", b"Server: "):
        assert h in v2
    assert error_response(1, 401).startswith(b"HTTP/1.0 401 Unauthorized\r\n")
    assert error_response(1, 401, source_v1=True) == b"ERROR - Bad Password\r\n"
    body = render_sourcetable([StrRecord("M1", latitude=31.25, longitude=121.5)])
    st = sourcetable_response(1, body)
    assert st.startswith(b"SOURCETABLE 200 OK\r\n") and st.endswith(b"\r\nENDSOURCETABLE\r\n")


def test_sourcetable_round_trip_and_sanitising():
    rec = StrRecord("M1", identifier="Bad;Name\r\n", latitude=31.25, longitude=-121.5, nmea=1,
                    solution=1, authentication="B", bitrate=9600, misc="x")
    body = render_sourcetable([rec])
    assert body.count(b"\r\n") == 2  # one record and the end line: no injected lines
    (back,) = parse_sourcetable(body)
    assert back.mountpoint == "M1" and back.identifier == "Bad,Name  " and back.latitude == 31.25
    assert len(rec.to_line().split(";")) == 19


def test_crc24q_and_frames_against_pyrtcm(shared_data: Path):
    raw = (shared_data / "rtcm" / "ntrip-USCL00CHL0.rtcm3").read_bytes()
    ours = split_rtcm3_frames(raw)
    theirs = [r for r, _ in RTCMReader(iter_stream(raw))]
    assert ours == theirs and len(ours) > 5
    assert crc24q(b"") == 0
    f = frame_rtcm3(b"\x3e\xd0abc")
    assert split_rtcm3_frames(b"junk\xd3" + f + b"\xd3\x00") == [f]


def iter_stream(raw: bytes):
    import io
    return io.BufferedReader(io.BytesIO(raw))


def test_frame_aligner_forwards_every_byte_and_holds_partial_frames(shared_data: Path):
    raw = (shared_data / "rtcm" / "testglo.rtcm3").read_bytes()[:20000]
    stream = b"garbage\xd3\xd3" + raw
    for step in (1, 7, 1000, 4096):
        a = RtcmFrameAligner()
        out = b"".join(a.feed(stream[i:i + step]) for i in range(0, len(stream), step))
        assert out + a.flush() == stream
        assert a.frames == len(split_rtcm3_frames(stream))
    a = RtcmFrameAligner()
    f = frame_rtcm3(b"\x3e\xd0" + bytes(100))
    assert a.feed(f[:50]) == b"" and a.pending == 50
    assert a.feed(f[50:] + f[:2]) == f and a.pending == 2


def test_v2_post_without_chunked_body_is_raw():
    conn = NtripServerConnection()
    events = conn.receive_data(b"POST /M HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\n\r\n\xd3\x00\x00")
    assert not events[0].request.chunked and events[1] == SourceData(b"\xd3\x00\x00")
    assert conn.receive_data(b"more") == [SourceData(b"more")]


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=0, max_size=1100))
def test_vectorised_crc24q_equals_the_byte_loop(data):
    assert crc24q(data) == crc24q_bytewise(data)
    assert crc24q(bytearray(data)) == crc24q(memoryview(data))

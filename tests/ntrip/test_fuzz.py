"""Protocol fuzzing: the core never raises anything but NtripProtocolError, splits never matter,
and the live caster answers garbage with an error (or the sourcetable) and a close, never a hang."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from augwire.errors import NtripProtocolError
from ntrip_caster.config import Limits
from ntrip_caster.connection import NtripServerConnection, RequestReceived, SourceData
from ntrip_caster.embedded import CasterThread
from ntrip_caster.gga import format_gga, parse_gga
from ntrip_caster.limits import MAX_REQUEST_HEAD_BYTES

from .helpers import basic, connect, make_config, open_client, open_v1_source, read_all, read_until

ALLOWED_STATUS = {400, 401, 404, 408, 409, 431, 501, 505}
REAL_REQUESTS = [
    b"GET /BASE01 HTTP/1.0\r\nUser-Agent: NTRIP RTKLIB/2.4.3\r\nAuthorization: "
    + basic("train1", "pw").encode() + b"\r\n\r\n" + format_gga(31, 121),
    b"GET /VRS HTTP/1.1\r\nHost: h\r\nNtrip-Version: Ntrip/2.0\r\nNtrip-GGA: "
    + format_gga(31, 121).strip() + b"\r\nConnection: close\r\n\r\n",
    b"SOURCE pw BASE01\r\nSource-Agent: NTRIP RTKLIB/2.4.3\r\nSTR: \r\n\r\n\xd3\x00\x00G\xea\x4b",
    b"POST /BASE01 HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\nTransfer-Encoding: chunked\r\n\r\n"
    b"4\r\nabcd\r\n0\r\n\r\n",
    b"GET / HTTP/1.0\r\n\r\n",
]
TOKENS = [b"GET", b"POST", b"SOURCE", b" ", b"/", b"BASE01", b"HTTP/1.1", b"HTTP/1.0", b"\r\n",
          b"\n", b":", b"Ntrip-Version: Ntrip/2.0", b"Transfer-Encoding: chunked", b"Authorization",
          b"Basic", b"%", b"?", b"\x00", b"\xff", b"$GPGGA,", b"*", b"0\r\n\r\n", b"FFFFFFFF\r\n"]


def merged(events: list) -> list:
    """Consecutive SourceData events joined: how payload bytes are cut is not meaningful."""
    out: list = []
    for e in events:
        if isinstance(e, SourceData) and out and isinstance(out[-1], SourceData):
            out[-1] = SourceData(out[-1].data + e.data)
        else:
            out.append(e)
    return out


def feed_all(pieces: list[bytes]) -> list:
    conn = NtripServerConnection()
    events = []
    try:
        for p in pieces:
            events += conn.receive_data(p)
    except NtripProtocolError as exc:
        assert exc.status in ALLOWED_STATUS, exc
        events.append(("error", exc.status))
    return merged(events)


def test_every_split_of_real_requests_gives_the_same_events():
    for wire in REAL_REQUESTS:
        whole = feed_all([wire])
        assert isinstance(whole[0], RequestReceived)
        for i in range(len(wire) + 1):
            assert feed_all([wire[:i], wire[i:]]) == whole, (wire, i)
        assert feed_all([bytes([b]) for b in wire]) == whole


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=3000), st.lists(st.integers(0, 3000), max_size=6))
def test_random_bytes_never_crash(data, cuts):
    cuts = sorted({c for c in cuts if c <= len(data)})
    pieces = [data[a:b] for a, b in zip([0] + cuts, cuts + [len(data)])]
    feed_all(pieces)


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(TOKENS), max_size=60), st.sampled_from(REAL_REQUESTS),
       st.integers(0, 200))
def test_token_soup_and_mutated_real_requests(tokens, real, pos):
    feed_all([b"".join(tokens)])
    pos = min(pos, len(real))
    feed_all([real[:pos] + b"".join(tokens) + real[pos:]])


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_gga_parser_total(data):
    parse_gga(data)
    parse_gga(b"$GNGGA," + data)


def test_live_caster_answers_garbage_and_stays_healthy():
    garbage = [
        b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03",  # a TLS ClientHello
        b"GET /BASE01 HTTP/9.9\r\n\r\n", b"DELETE / HTTP/1.1\r\n\r\n", b"\x00" * 100 + b"\r\n\r\n",
        b"GET / HTTP/1.0\r\n" + b"X: " + b"a" * (MAX_REQUEST_HEAD_BYTES + 10),
        b"POST /BASE02 HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\nTransfer-Encoding: chunked\r\n"
        b"Authorization: " + basic("station1", "station-secret").encode() + b"\r\n\r\nZZZ\r\n",
        b"SOURCE x\r\n\r\n", b"GET /%ff%fe HTTP/1.0\r\n\r\n",
    ]
    with CasterThread(make_config(limits=Limits(request_head_timeout_s=1.0))) as ct:
        src = open_v1_source(ct.port, "OPEN")
        for wire in garbage:
            s = connect(ct.port)
            try:
                s.sendall(wire)
            except OSError:
                pass
            reply = read_all(s, timeout=5)  # the caster closes: read_all returns on EOF
            first = reply.split(b"\r\n", 1)[0]
            assert (first.startswith(b"SOURCETABLE 200") or first.startswith(b"ERROR - ")
                    or first.startswith(b"HTTP/1.1 200 OK") or
                    int(first.split(b" ")[1]) in ALLOWED_STATUS), (wire[:30], reply[:80])
            if first.startswith(b"HTTP/1.1 200 OK"):  # the v2 source was accepted, then broke
                assert b"400" not in first
            s.close()
        snap = ct.snapshot(clients=False)
        assert snap["counters"].get("status_400", 0) >= 2 and snap["counters"]["status_431"] == 1
        assert snap["counters"]["status_408"] == 1 and snap["counters"]["status_501"] == 1
        c, head = open_client(ct.port, "OPEN", user=None)
        assert head == b"ICY 200 OK\r\n"
        c.close()
        src.close()


@pytest.fixture(scope="module")
def fuzz_caster():
    with CasterThread(make_config(limits=Limits(request_head_timeout_s=0.25))) as ct:
        yield ct


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(st.lists(st.sampled_from(TOKENS), max_size=40), st.binary(max_size=200))
def test_live_caster_fuzzed_requests_always_answered(fuzz_caster, tokens, tail):
    """Whatever arrives, the caster answers (an error, the sourcetable, or a stream reply) or
    closes within the head timeout; it never hangs and never dies."""
    wire = b"".join(tokens) + tail
    s = connect(fuzz_caster.port)
    try:
        s.sendall(wire)
    except OSError:
        pass
    s.settimeout(3)  # hang guard: the head timeout is 0.25 s
    reply = b""
    try:
        while True:
            data = s.recv(65536)
            if not data:
                break
            reply += data
            if reply.startswith((b"ICY 200 OK", b"HTTP/1.1 200 OK")):
                break  # a stream was granted (e.g. a valid GET on a public mount): fine
    except ConnectionResetError:
        pass
    except TimeoutError:
        pytest.fail(f"no answer and no close within 3 s: {reply[:80]!r}")
    finally:
        s.close()
    if reply:
        first = reply.split(b"\r\n", 1)[0]
        assert first.startswith((b"SOURCETABLE 200", b"ERROR - ", b"ICY 200 OK", b"HTTP/1.1 200")) \
            or int(first.split(b" ")[1]) in ALLOWED_STATUS, reply[:80]
    snap = fuzz_caster.snapshot(clients=False)
    assert snap["counters"].get("internal_errors", 0) == 0


def test_many_slow_loris_connections_do_not_starve_real_clients():
    with CasterThread(make_config(limits=Limits(request_head_timeout_s=1.0))) as ct:
        src = open_v1_source(ct.port, "OPEN")
        loris = []
        for _ in range(200):
            s = connect(ct.port)
            s.sendall(b"GET /OPEN HTTP/1.0\r\nUser-Agent: NT")  # and then a byte now and then
            loris.append(s)
        c, head = open_client(ct.port, "OPEN", user=None)
        assert head == b"ICY 200 OK\r\n"
        src.sendall(b"\xd3\x00\x00G\xeaK")
        assert read_until(c, b"G\xeaK") == b"\xd3\x00\x00G\xeaK"
        for s in loris[:20]:  # dribbling does not extend the deadline
            s.sendall(b"R")
        closed = 0
        for s in loris:
            reply = read_all(s, timeout=5)  # hang guard: the head timeout is 1 s
            closed += reply.startswith(b"HTTP/1.0 408")
            s.close()
        assert closed == 200
        assert ct.snapshot(clients=False)["counters"]["head_timeouts"] == 200
        c.close()
        src.close()

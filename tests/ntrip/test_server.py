"""The asyncio caster over real loopback sockets: sources, clients, auth, limits, timeouts, stats."""

from __future__ import annotations

import socket
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import pytest

from augwire.chunked import encode_chunk
from augwire.rtcm_framing import frame as frame_rtcm3
from ntrip_caster.config import Limits, MountConfig
from ntrip_caster.embedded import CasterThread
from ntrip_caster.gga import format_gga
from ntrip_caster.sourcetable import parse_sourcetable

from .helpers import (STATION_PW, TRAIN_PW, basic, connect, dechunk, make_config, open_client,
                      open_v1_source, open_v2_source, read_all, read_exactly, read_until,
                      rtcm_sample, wait_for)


def read_v2_body(sock: socket.socket, n: int) -> bytes:
    """De-chunked body bytes of a v2 stream until `n` bytes have arrived (or the peer closes)."""
    raw = b""
    sock.settimeout(10)
    while True:
        data = sock.recv(65536)
        raw += data
        try:
            got = dechunk(raw + b"0\r\n\r\n")
        except (ValueError, AssertionError):
            got = b""
        if len(got) >= n or not data:
            return got


def _clients_on(ct: CasterThread, mount: str, n: int) -> None:
    wait_for(lambda: ct.snapshot(clients=False)["mounts"][mount]["clients"] >= n)


def test_v1_source_reaches_v1_and_v2_clients_byte_identical(caster, shared_data):
    data = rtcm_sample(shared_data, n_bytes=60_000)
    src = open_v1_source(caster.port, "BASE01")
    c1, head1 = open_client(caster.port, "BASE01", version=1)
    c2, head2 = open_client(caster.port, "BASE01", version=2)
    assert head1 == b"ICY 200 OK\r\n"
    assert head2.startswith(b"HTTP/1.1 200 OK\r\n")
    assert b"Transfer-Encoding: chunked\r\n" in head2 and b"Content-Type: gnss/data\r\n" in head2
    _clients_on(caster, "BASE01", 2)
    with ThreadPoolExecutor(2) as pool:  # both clients read while the source writes
        r1 = pool.submit(read_exactly, c1, len(data))
        r2 = pool.submit(read_v2_body, c2, len(data))
        # Odd-sized writes: the caster must reassemble frames and still forward every byte.
        for i in range(0, len(data), 777):
            src.sendall(data[i:i + 777])
            time.sleep(0.0005)
        assert r1.result() == data
        assert r2.result() == data
    snap = caster.snapshot()
    m = snap["mounts"]["BASE01"]
    assert m["bytes_in"] == len(data) and m["frames_in"] > 50
    assert {c["version"] for c in snap["clients"]} == {1, 2}
    for s in (src, c1, c2):
        s.close()


def test_v2_chunked_post_source(caster, shared_data):
    data = rtcm_sample(shared_data, "testglo.rtcm3", n_bytes=20_000)
    src = open_v2_source(caster.port, "BASE02")
    c1, _ = open_client(caster.port, "BASE02", version=1)
    _clients_on(caster, "BASE02", 1)
    for i in range(0, len(data), 1000):
        src.sendall(encode_chunk(data[i:i + 1000]))
    assert read_exactly(c1, len(data)) == data
    src.sendall(b"0\r\n\r\n")  # end of body: the caster closes the source
    wait_for(lambda: not caster.snapshot(clients=False)["mounts"]["BASE02"]["live"])
    c1.close()
    src.close()


def test_sourcetable_v1_and_v2(caster):
    src = open_v1_source(caster.port, "BASE01")
    wait_for(lambda: caster.snapshot(clients=False)["mounts"]["BASE01"]["live"])
    s = connect(caster.port)
    s.sendall(b"GET / HTTP/1.0\r\nUser-Agent: NTRIP test\r\n\r\n")
    reply = read_all(s)
    head, _, body = reply.partition(b"\r\n\r\n")
    assert head.startswith(b"SOURCETABLE 200 OK\r\n") and b"Content-Type: text/plain" in head
    assert body.endswith(b"ENDSOURCETABLE\r\n")
    length = int(head.split(b"Content-Length: ")[1].split(b"\r\n")[0])
    assert length == len(body)
    names = [r.mountpoint for r in parse_sourcetable(body)]
    # live sources and the GGA-driven mountpoint; BASE02 and OPEN have no source
    assert names == ["BASE01", "NEAR"]
    near = [r for r in parse_sourcetable(body) if r.mountpoint == "NEAR"][0]
    assert near.nmea == 1 and near.authentication == "B"
    assert body.startswith(b"CAS;127.0.0.1;")

    s = connect(caster.port)
    s.sendall(b"GET / HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\n\r\n")
    reply = read_all(s)
    assert reply.startswith(b"HTTP/1.1 200 OK\r\n") and b"Content-Type: gnss/sourcetable" in reply
    # v2 filtering: only STR records whose identifier field... here: nmea=1
    s = connect(caster.port)
    s.sendall(b"GET /?STR;;;;;;;;;;;1 HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\n\r\n")
    body = read_all(s).partition(b"\r\n\r\n")[2]
    assert [r.mountpoint for r in parse_sourcetable(body)] == ["NEAR"]
    src.close()


def test_unknown_mount_v1_gets_sourcetable_v2_gets_404(caster):
    s = connect(caster.port)
    s.sendall(b"GET /NOPE HTTP/1.0\r\n\r\n")
    assert read_all(s).startswith(b"SOURCETABLE 200 OK\r\n")
    s = connect(caster.port)
    s.sendall(b"GET /NOPE HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\n\r\n")
    reply = read_all(s)
    assert reply.startswith(b"HTTP/1.1 404 Not Found\r\n") and b"Ntrip-Version: Ntrip/2.0" in reply
    # a configured mountpoint whose source is offline is answered the same way
    s = connect(caster.port)
    s.sendall(b"GET /BASE02 HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\n\r\n")
    assert read_all(s).startswith(b"HTTP/1.1 404")


@pytest.mark.parametrize("user,password", [(None, ""), ("train1", "wrong"), ("nobody", "x"),
                                           ("intruder", "x")])
def test_401(caster, user, password):
    src = open_v1_source(caster.port, "BASE01")
    s, head = open_client(caster.port, "BASE01", version=2, user=user, password=password)
    rest = head + read_all(s)
    assert rest.startswith(b"HTTP/1.1 401 Unauthorized\r\n")
    assert b'WWW-Authenticate: Basic realm="augnet"' in rest
    s, head = open_client(caster.port, "BASE01", version=1, user=user, password=password)
    assert (head + read_all(s)).startswith(b"HTTP/1.0 401 Unauthorized\r\n")
    src.close()


def test_public_mount_needs_no_credentials_and_cache_avoids_rehash(caster):
    src = open_v1_source(caster.port, "OPEN")
    s, head = open_client(caster.port, "OPEN", version=1, user=None)
    assert head == b"ICY 200 OK\r\n"
    src2 = open_v1_source(caster.port, "BASE01")
    before = caster.snapshot(clients=False)["auth_checks"]
    clients = [open_client(caster.port, "BASE01")[0] for _ in range(5)]
    after = caster.snapshot(clients=False)["auth_checks"]
    assert after - before == 1  # one scrypt check, then the verified-credential cache
    for c in clients + [s, src, src2]:
        c.close()


def test_source_errors(caster):
    s = connect(caster.port)
    s.sendall(b"SOURCE wrong BASE01\r\nSource-Agent: NTRIP test\r\n\r\n")
    assert read_all(s) == b"ERROR - Bad Password\r\n"
    src = open_v1_source(caster.port, "BASE01")
    s = connect(caster.port)
    s.sendall(f"SOURCE {STATION_PW} BASE01\r\n\r\n".encode())  # no leading slash (RTKLIB style)
    assert read_all(s) == b"ERROR - Mount Point Taken or Invalid\r\n"
    s = connect(caster.port)
    s.sendall(f"SOURCE {STATION_PW} /UNKNOWN\r\n\r\n".encode())
    assert read_all(s) == b"ERROR - Mount Point Taken or Invalid\r\n"
    # v2 source with a reader's credentials
    s = connect(caster.port)
    s.sendall(("POST /BASE02 HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\n"
               f"Authorization: {basic('train1', TRAIN_PW)}\r\n\r\n").encode())
    assert read_all(s).startswith(b"HTTP/1.1 401")
    src.close()


def test_limits_503():
    limits = Limits(max_clients=3, max_clients_per_mount=2, max_clients_per_ip=0)
    with CasterThread(make_config(limits=limits)) as ct:
        a = open_v1_source(ct.port, "BASE01")
        b = open_v1_source(ct.port, "BASE02")
        held = [open_client(ct.port, "BASE01")[0] for _ in range(2)]
        s, head = open_client(ct.port, "BASE01", version=2)
        assert (head + read_all(s)).startswith(b"HTTP/1.1 503 Service Unavailable")
        held.append(open_client(ct.port, "BASE02")[0])
        s, head = open_client(ct.port, "BASE02", version=1)
        assert (head + read_all(s)).startswith(b"HTTP/1.0 503")
        for x in held + [a, b]:
            x.close()
    with CasterThread(make_config(limits=Limits(max_clients_per_ip=1))) as ct:
        a = open_v1_source(ct.port, "OPEN")
        c1, head = open_client(ct.port, "OPEN", user=None)
        assert head == b"ICY 200 OK\r\n"
        c2, head = open_client(ct.port, "OPEN", version=2, user=None)
        assert (head + read_all(c2)).startswith(b"HTTP/1.1 503")
        c1.close()
        wait_for(lambda: ct.snapshot(clients=False)["clients_now"] == 0)
        c3, head = open_client(ct.port, "OPEN", user=None)
        assert head == b"ICY 200 OK\r\n"
        c3.close()
        a.close()


def test_slow_loris_and_idle_source_time_out():
    limits = Limits(request_head_timeout_s=0.3, source_idle_timeout_s=0.6)
    with CasterThread(make_config(limits=limits)) as ct:
        s = connect(ct.port)
        s.sendall(b"GET /BASE01 HTTP/1.0\r\nUser-Ag")  # ... and never finish
        reply = read_all(s, timeout=3)  # hang guard: the head timeout is 0.3 s
        assert reply.startswith(b"HTTP/1.0 408")
        src = open_v1_source(ct.port, "BASE01")
        src.sendall(frame_rtcm3(b"\x3e\xd0" + bytes(20)))
        wait_for(lambda: ct.snapshot(clients=False)["mounts"]["BASE01"]["drops"].get("source_idle"),
                 timeout=5)
        assert read_all(src, timeout=5) == b""  # closed by the caster
        # the mountpoint can be taken again
        open_v1_source(ct.port, "BASE01").close()


def test_nearest_base_follows_gga_with_hysteresis():
    limits = Limits(gga_min_interval_s=0, reposition_min_interval_s=0)
    with CasterThread(make_config(limits=limits)) as ct:
        s1 = open_v1_source(ct.port, "BASE01")  # at lon 121.00
        s2 = open_v1_source(ct.port, "BASE02")  # at lon 121.50 (~47.7 km east)
        c, head = open_client(ct.port, "NEAR", gga=None)
        assert head == b"ICY 200 OK\r\n"
        wait_for(lambda: ct.snapshot()["clients"] and ct.snapshot()["clients"][0]["waiting_for_position"])
        assert ct.snapshot(clients=False)["mounts"]["NEAR"]["waiting_for_position"] == 1
        s1.sendall(frame_rtcm3(b"\x3e\xd0" + b"one"))  # nobody subscribed yet: not delivered
        c.sendall(b"junk that is not NMEA\r\n" + format_gga(31.0, 121.45))
        wait_for(lambda: ct.snapshot()["clients"][0]["base"] == "BASE02")
        assert ct.snapshot(clients=False)["mounts"]["NEAR"]["waiting_for_position"] == 0
        f2 = frame_rtcm3(b"\x3e\xd0" + b"two")
        s2.sendall(f2)
        assert read_exactly(c, len(f2)) == f2
        # 24.3 km from BASE01 vs 23.5 km from BASE02: nearer to BASE01? no; still BASE02
        c.sendall(format_gga(31.0, 121.252))
        time.sleep(0.2)
        assert ct.snapshot()["clients"][0]["base"] == "BASE02"  # within the 500 m hysteresis
        c.sendall(format_gga(31.0, 121.10))
        wait_for(lambda: ct.snapshot()["clients"][0]["base"] == "BASE01")
        f1 = frame_rtcm3(b"\x3e\xd0" + b"three")
        s1.sendall(f1)
        assert read_exactly(c, len(f1)) == f1
        for x in (c, s1, s2):
            x.close()


class RecordingFactory:
    """A test VRS factory: records open/update/close and streams a frame naming the position."""

    def __init__(self) -> None:
        self.events: list = []
        self.sinks: dict = {}

    def open(self, client_id, mount, fix, sink):
        self.events.append(("open", client_id, mount, round(fix.lat_deg, 6), round(fix.lon_deg, 6)))
        self.sinks[client_id] = sink
        sink(frame_rtcm3(b"\x3e\xd0" + f"VRS {fix.lat_deg:.5f} {fix.lon_deg:.5f}".encode()))
        factory = self

        class Handle:
            def update_position(self, fix):
                factory.events.append(("update", client_id, round(fix.lat_deg, 6)))
                sink(frame_rtcm3(b"\x3e\xd0" + f"VRS {fix.lat_deg:.5f} {fix.lon_deg:.5f}".encode()))

            def close(self):
                factory.events.append(("close", client_id))

        return Handle()


def test_vrs_mount_waits_for_gga_then_uses_factory_with_reposition_policy():
    factory = RecordingFactory()
    vrs = MountConfig("VRS", "vrs", frozenset({"trains"}), factory="unused:unused")
    limits = Limits(gga_min_interval_s=0, reposition_min_interval_s=0.0, reposition_min_move_m=10)
    with CasterThread(make_config(limits=limits, extra_mounts=(vrs,)), {"VRS": factory}) as ct:
        c, head = open_client(ct.port, "VRS", version=2, gga=None)
        assert head.startswith(b"HTTP/1.1 200 OK")
        time.sleep(0.2)
        assert factory.events == []  # no position yet: kept connected, nothing opened
        c.sendall(format_gga(31.2, 121.3))
        first = read_until(c, b"\r\n", limit=200)
        wait_for(lambda: factory.events)
        assert factory.events[0][0] == "open" and factory.events[0][2:] == ("VRS", 31.2, 121.3)
        c.sendall(format_gga(31.20003, 121.3))  # ~3 m: below the movement threshold
        time.sleep(0.2)
        assert [e[0] for e in factory.events] == ["open"]
        c.sendall(format_gga(31.2002, 121.3))  # ~22 m: update
        wait_for(lambda: len(factory.events) == 2)
        assert factory.events[1] == ("update", factory.events[0][1], 31.2002)
        body = first + read_until(c, b"31.20020", limit=2000)
        assert b"VRS 31.20000 121.30000" in dechunk(body.split(b"\r\n\r\n", 1)[1] + b"0\r\n\r\n"
                                                   if b"\r\n\r\n" in body else body + b"0\r\n\r\n")
        c.close()
        wait_for(lambda: factory.events[-1][0] == "close")
    # v2 GGA header opens the stream at once
    factory = RecordingFactory()
    with CasterThread(make_config(limits=limits, extra_mounts=(vrs,)), {"VRS": factory}) as ct:
        c, head = open_client(ct.port, "VRS", version=2, gga=format_gga(30.5, 120.5))
        wait_for(lambda: factory.events)
        assert factory.events[0][2:] == ("VRS", 30.5, 120.5)
        c.close()


def test_graceful_shutdown_ends_v2_streams_cleanly():
    ct = CasterThread(make_config()).start()
    src = open_v1_source(ct.port, "OPEN")
    c, head = open_client(ct.port, "OPEN", version=2, user=None)
    _clients_on(ct, "OPEN", 1)
    ct.stop()
    assert read_all(c, timeout=5).endswith(b"0\r\n\r\n")
    assert read_all(src, timeout=5) == b""
    with pytest.raises(OSError):
        connect(ct.port, timeout=1)


def test_unknown_sources_allowed_when_configured():
    with CasterThread(make_config(allow_unknown_sources=True)) as ct:
        s = connect(ct.port)
        s.sendall(b"SOURCE anything NEWMOUNT\r\nSource-Agent: NTRIP x\r\n"
                  b"STR: STR;NEWMOUNT;Shanghai;RTCM 3.2;1005(10);2;GPS;NET;CHN;31.10;121.20;0;0;x;"
                  b"none;N;N;9600;\r\n\r\n")
        assert read_until(s, b"\r\n") == b"ICY 200 OK\r\n"
        c = connect(ct.port)
        c.sendall(b"GET / HTTP/1.0\r\n\r\n")
        recs = {r.mountpoint: r for r in parse_sourcetable(read_all(c).partition(b"\r\n\r\n")[2])}
        assert recs["NEWMOUNT"].identifier == "Shanghai" and recs["NEWMOUNT"].latitude == 31.1
        s.close()


def test_relay_factory_serves_vrs_clients_through_the_per_client_path(shared_data):
    from ntrip_caster.relay_factory import MountRelayFactory

    relay = MountRelayFactory("BASE01")
    vrs = MountConfig("VRS", "vrs", frozenset({"trains"}), factory="unused:unused")
    data = rtcm_sample(shared_data, n_bytes=8000)
    with CasterThread(make_config(extra_mounts=(vrs,)), {"VRS": relay}) as ct:
        src = open_v1_source(ct.port, "BASE01")
        c1, _ = open_client(ct.port, "VRS", version=1, gga=format_gga(31.0, 121.0))
        c2, _ = open_client(ct.port, "VRS", version=2, gga=format_gga(31.0, 121.1))
        wait_for(lambda: relay.opened == 2)
        src.sendall(data)
        assert read_exactly(c1, len(data)) == data
        assert read_v2_body(c2, len(data)) == data
        c1.close()
        wait_for(lambda: len(relay.sinks) == 1)  # closing a client closes its stream handle
        with pytest.raises(ValueError):
            ct.call(ct.caster.tap, "NEAR", lambda d: None)
        c2.close()
        src.close()


def test_gga_rate_limit_and_upload_flood():
    limits = Limits(gga_min_interval_s=1.0, max_client_upload_bytes_per_s=4000)
    with CasterThread(make_config(limits=limits)) as ct:
        s1 = open_v1_source(ct.port, "BASE01")
        c, head = open_client(ct.port, "NEAR")
        assert head == b"ICY 200 OK\r\n"
        for _ in range(10):  # a 10 Hz receiver: one GGA per second is processed
            c.sendall(format_gga(31.0, 121.0))
            time.sleep(0.01)
        wait_for(lambda: ct.snapshot()["clients"][0]["gga_count"] == 1)
        time.sleep(0.2)
        snap = ct.snapshot()
        assert snap["clients"][0]["gga_count"] == 1 and snap["counters"]["gga_rate_limited"] == 9
        assert snap["clients"][0]["base"] == "BASE01" and snap["clients"][0]["last_gga_at"]
        c.sendall(b"x" * 5000)  # far beyond any GGA rate: hostile, dropped
        assert read_all(c, timeout=5) == b""
        assert ct.snapshot(clients=False)["mounts"]["NEAR"]["drops"] == {"upload_flood": 1}
        s1.close()


def test_auto_mountpoints_are_bounded_and_forgotten():
    cfg = replace(make_config(allow_unknown_sources=True), limits=Limits(max_auto_mounts=2))
    with CasterThread(cfg) as ct:
        a = open_v1_source(ct.port, "AUTO1", password="any")
        b = open_v1_source(ct.port, "AUTO2", password="any")
        s = connect(ct.port)
        s.sendall(b"SOURCE any AUTO3\r\n\r\n")
        assert read_all(s) == b"ERROR - Mount Point Taken or Invalid\r\n"
        a.close()
        wait_for(lambda: "AUTO1" not in ct.snapshot(clients=False)["mounts"])
        open_v1_source(ct.port, "AUTO3", password="any").close()
        b.close()


def test_plain_asyncio_loop_works_too(shared_data):
    """uvloop is optional: the same caster on asyncio's own loop streams byte-identically."""
    data = rtcm_sample(shared_data, n_bytes=10_000)
    with CasterThread(make_config(), use_uvloop=False) as ct:
        assert "uvloop" not in type(ct.loop).__module__
        src = open_v1_source(ct.port, "OPEN")
        c1, _ = open_client(ct.port, "OPEN", version=1, user=None)
        c2, _ = open_client(ct.port, "OPEN", version=2, user=None)
        _clients_on(ct, "OPEN", 2)
        with ThreadPoolExecutor(2) as pool:
            r1 = pool.submit(read_exactly, c1, len(data))
            r2 = pool.submit(read_v2_body, c2, len(data))
            src.sendall(data)
            assert r1.result() == data and r2.result() == data
        for s in (src, c1, c2):
            s.close()


def test_stats_endpoint_for_admins_only(caster):
    src = open_v1_source(caster.port, "BASE01")
    c, _ = open_client(caster.port, "BASE01")
    _clients_on(caster, "BASE01", 1)

    def get(path: str, user: str | None, password: str = "") -> bytes:
        s = connect(caster.port)
        auth = f"Authorization: {basic(user, password)}\r\n" if user else ""
        s.sendall(f"GET {path} HTTP/1.1\r\nNtrip-Version: Ntrip/2.0\r\n{auth}\r\n".encode())
        return read_all(s)

    reply = get("/_stats", "ops", "ops-secret")
    head, _, body = reply.partition(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 200 OK") and b"Content-Type: application/json" in head
    import json

    stats = json.loads(body)
    assert stats["mounts"]["BASE01"]["clients"] == 1 and stats["clients"][0]["user"] == "train1"
    assert json.loads(get("/_stats?clients=0", "ops", "ops-secret").partition(b"\r\n\r\n")[2]
                      )["clients"] == []
    assert get("/_stats", None).startswith(b"HTTP/1.1 401")
    assert get("/_stats", "train1", TRAIN_PW).startswith(b"HTTP/1.1 401")
    c.close()
    src.close()

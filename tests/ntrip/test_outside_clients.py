"""Clients nobody here wrote, unchanged, against the caster: each must receive byte-identical RTCM
to what the source sent. RTKLIB str2str (NTRIP 1 client and `ntrips://` source), pygnssutils'
GNSSNTRIPClient Python API (NTRIP 1 and 2, with GGA), curl (NTRIP 2 chunked, `--http0.9` NTRIP 1)."""

from __future__ import annotations

import queue
import socket
import subprocess
import time
from pathlib import Path

import pytest

from augwire.rtcm_framing import frame as frame_rtcm3
from ntrip_caster.embedded import CasterThread

from .helpers import (STATION_PW, TRAIN_PW, make_config, open_client, open_v1_source,
                      read_exactly, rtcm_sample, wait_for)
from ..conftest import require_tool


PRIMING_FRAME = frame_rtcm3(b"\x3e\xd0priming")


def _clients(ct: CasterThread, mount: str) -> int:
    return ct.snapshot(clients=False)["mounts"][mount]["clients"]


def _send_paced(sock: socket.socket, data: bytes, step: int = 2000) -> None:
    """Epoch-like pacing: real sources send a few KB at a time, not a burst."""
    for i in range(0, len(data), step):
        sock.sendall(data[i:i + step])
        time.sleep(0.002)


def _wait_file(path: Path, size: int, timeout: float = 20) -> bytes:
    wait_for(lambda: path.exists() and path.stat().st_size >= size, timeout=timeout)
    return path.read_bytes()


def _stop(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@pytest.fixture
def data(shared_data) -> bytes:
    return rtcm_sample(shared_data, n_bytes=40_000)


@pytest.mark.rtklib
def test_str2str_as_ntrip1_client(caster, data, tmp_path):
    str2str = require_tool("str2str")
    src = open_v1_source(caster.port, "BASE01")
    out = tmp_path / "str2str.rtcm3"
    proc = subprocess.Popen([str2str, "-in", f"ntrip://train1:{TRAIN_PW}@127.0.0.1:{caster.port}/BASE01",
                             "-out", f"file://{out}"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: _clients(caster, "BASE01") == 1)
        time.sleep(0.3)  # str2str discards whatever arrives with the ICY line on its first read
        _send_paced(src, data)
        assert _wait_file(out, len(data)) == data
        client = caster.snapshot()["clients"][0]
        assert client["version"] == 1 and client["user"] == "train1"
    finally:
        _stop(proc)
        src.close()


@pytest.mark.rtklib
def test_str2str_as_ntrip_source(caster, data, tmp_path):
    str2str = require_tool("str2str")
    feed = socket.create_server(("127.0.0.1", 0))
    feed_port = feed.getsockname()[1]
    proc = subprocess.Popen([str2str, "-in", f"tcpcli://127.0.0.1:{feed_port}",
                             "-out", f"ntrips://:{STATION_PW}@127.0.0.1:{caster.port}/BASE02"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        feed.settimeout(10)
        conn, _ = feed.accept()
        wait_for(lambda: caster.snapshot(clients=False)["mounts"]["BASE02"]["live"])
        src = caster.snapshot(clients=False)["mounts"]["BASE02"]["source"]
        assert src["version"] == 1 and "RTKLIB" in src["agent"] and src["user"] == "station1"
        c1, head = open_client(caster.port, "BASE02", version=1)
        assert head == b"ICY 200 OK\r\n"
        wait_for(lambda: _clients(caster, "BASE02") == 1)
        _send_paced(conn, data)
        assert read_exactly(c1, len(data)) == data
        c1.close()
        conn.close()
    finally:
        _stop(proc)
        feed.close()


def _pygnssutils_client(port: int, mount: str, version: str, out: queue.Queue, gga: bool):
    from pygnssutils import GNSSNTRIPClient

    client = GNSSNTRIPClient()
    client.run(server="127.0.0.1", port=port, mountpoint=mount, version=version,
               ntripuser="train1", ntrippassword=TRAIN_PW, ggainterval=1 if gga else -1,
               ggamode=1, reflat=31.0, reflon=121.45, refalt=10.0, refsep=0.0, output=out)
    return client


@pytest.mark.parametrize("version", ["1.0", "2.0"])
def test_pygnssutils_with_gga_on_nearest_mount(caster, data, version):
    """GNSSNTRIPClient sends its GGA (v1: a line after the head, v2: Ntrip-GGA header and lines);
    the caster picks BASE02 (nearest to 121.45 E) and streams it."""
    s1 = open_v1_source(caster.port, "BASE01")
    s2 = open_v1_source(caster.port, "BASE02")
    out: queue.Queue = queue.Queue()
    client = _pygnssutils_client(caster.port, "NEAR", version, out, gga=True)
    try:
        wait_for(lambda: (cl := caster.snapshot()["clients"]) and cl[0]["base"] == "BASE02")
        info = caster.snapshot()["clients"][0]
        assert info["version"] == int(version[0]) and info["gga_count"] >= 1
        assert info["last_position"][0] == pytest.approx(31.0, abs=1e-6)
        _send_paced(s1, data[:5000])  # the other base: must not reach this client
        # pygnssutils 1.3.1 reads once after the response head and throws that read away before
        # its RTCM parser starts: give it one priming frame, then the stream under test.
        s2.sendall(PRIMING_FRAME)
        time.sleep(0.5)
        _send_paced(s2, data)
        got = b""
        deadline = time.monotonic() + 20
        while len(got) < len(data) and time.monotonic() < deadline:
            try:
                raw, _parsed = out.get(timeout=1)
            except queue.Empty:
                continue
            if not raw.startswith(b"$"):  # the client also echoes the GGA it sent
                got += raw
        assert got == data
    finally:
        client.stop()
        s1.close()
        s2.close()


def test_pygnssutils_parses_sourcetable(caster):
    s1 = open_v1_source(caster.port, "BASE01")
    wait_for(lambda: caster.snapshot(clients=False)["mounts"]["BASE01"]["live"])
    out: queue.Queue = queue.Queue()
    from pygnssutils import GNSSNTRIPClient

    GNSSNTRIPClient().run(server="127.0.0.1", port=caster.port, mountpoint="", version="2.0",
                          ntripuser="train1", ntrippassword=TRAIN_PW, output=out)
    table, (closest, dist) = out.get(timeout=10)
    assert [row[0] for row in table] == ["BASE01", "NEAR"]
    base01 = table[0]
    assert base01[7] == "" and float(base01[8]) == 31.0 and float(base01[9]) == 121.0
    assert base01[14] == "B"  # authentication: Basic
    s1.close()


def _curl(args: list[str], out: Path) -> subprocess.Popen:
    curl = require_tool("curl")
    return subprocess.Popen([curl, "-s", "-N", "-A", "NTRIP curl", "-o", str(out)] + args,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def test_curl_ntrip2_chunked(caster, data, tmp_path):
    src = open_v1_source(caster.port, "BASE01")
    out = tmp_path / "curl2.rtcm3"
    proc = _curl(["-H", "Ntrip-Version: Ntrip/2.0", "-u", f"train1:{TRAIN_PW}",
                  f"http://127.0.0.1:{caster.port}/BASE01"], out)
    try:
        wait_for(lambda: _clients(caster, "BASE01") == 1)
        assert caster.snapshot()["clients"][0]["version"] == 2
        _send_paced(src, data)
        assert _wait_file(out, len(data)) == data  # curl removed the chunk framing
    finally:
        _stop(proc)
        src.close()


def test_curl_http09_ntrip1(caster, data, tmp_path):
    src = open_v1_source(caster.port, "BASE01")
    out = tmp_path / "curl1.rtcm3"
    proc = _curl(["--http0.9", "-u", f"train1:{TRAIN_PW}", f"http://127.0.0.1:{caster.port}/BASE01"],
                 out)
    try:
        wait_for(lambda: _clients(caster, "BASE01") == 1)
        _send_paced(src, data)
        got = _wait_file(out, len(data) + 12)
        assert got == b"ICY 200 OK\r\n" + data  # HTTP/0.9 mode: the status line is body to curl
    finally:
        _stop(proc)
        src.close()


def test_curl_sees_401_404_503(tmp_path):
    from ntrip_caster.config import Limits

    curl = require_tool("curl")
    with CasterThread(make_config(limits=Limits(max_clients=1))) as ct:
        src = open_v1_source(ct.port, "BASE01")

        def status(*args: str) -> tuple[int, str]:
            r = subprocess.run([curl, "-s", "-D", "-", "-o", "/dev/null", "--max-time", "5",
                                "-H", "Ntrip-Version: Ntrip/2.0", *args], capture_output=True,
                               text=True, timeout=10)
            return int(r.stdout.split()[1]), r.stdout

        code, head = status(f"http://127.0.0.1:{ct.port}/BASE01")
        assert code == 401 and 'WWW-Authenticate: Basic realm="augnet"' in head
        assert status("-u", "train1:wrong", f"http://127.0.0.1:{ct.port}/BASE01")[0] == 401
        assert status("-u", f"train1:{TRAIN_PW}", f"http://127.0.0.1:{ct.port}/NOSUCH")[0] == 404
        held, head = open_client(ct.port, "BASE01")
        assert head == b"ICY 200 OK\r\n"
        assert status("-u", f"train1:{TRAIN_PW}", f"http://127.0.0.1:{ct.port}/BASE01")[0] == 503
        held.close()
        src.close()


@pytest.mark.rtklib
def test_str2str_sends_gga_to_the_nearest_mount(caster, data, tmp_path):
    """RTKLIB 2.4.3 `-p lat lon hgt -n ms` sends a $GNGGA (0 satellites, fixed position) a second
    or two after connecting; the caster must keep it connected until then and pick its base."""
    str2str = require_tool("str2str")
    s1 = open_v1_source(caster.port, "BASE01")
    s2 = open_v1_source(caster.port, "BASE02")
    out = tmp_path / "near.rtcm3"
    proc = subprocess.Popen([str2str, "-in", f"ntrip://train1:{TRAIN_PW}@127.0.0.1:{caster.port}/NEAR",
                             "-p", "31.0", "121.48", "10", "-n", "1000", "-out", f"file://{out}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: (cl := caster.snapshot()["clients"]) and cl[0]["base"] == "BASE02",
                 timeout=15)
        info = caster.snapshot()["clients"][0]
        assert info["last_position"][1] == pytest.approx(121.48, abs=1e-6)
        time.sleep(0.3)
        _send_paced(s1, data[:3000])
        _send_paced(s2, data)
        assert _wait_file(out, len(data)) == data
    finally:
        _stop(proc)
        s1.close()
        s2.close()

"""Issue 19 on the whole system: `augnet up demo` under a bad-password flood (300 concurrent guesses from 300
loopback addresses, then 1,000 from one address in ~10 s) while 3 readers stream a station mountpoint."""

from __future__ import annotations

import base64
import json
import os
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import pytest

from ntrip_caster.server import AUTH_FLOOD_ALARM

pytestmark = [pytest.mark.slow, pytest.mark.system]

RUN_S = 80.0  # the run: the flood starts 11 s after the state file appears and lasts ~15 s
START_TIMEOUT_S = 120.0  # a hang guard (tests/system/test_up.py's)
# Hang guard on a reader: 5 s without a byte is the age at which a train drops its corrections
# (network-rtk.md); the station streams at 1 Hz.
MAX_GAP_S = 5.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _get(port: int, mount: str, user: str, password: str, ip: str = "127.0.0.1") -> socket.socket:
    s = socket.socket()
    s.settimeout(30)
    s.bind((ip, 0))
    s.connect(("127.0.0.1", port))
    auth = base64.b64encode(f"{user}:{password}".encode()).decode()
    s.sendall(f"GET /{mount} HTTP/1.0\r\nUser-Agent: NTRIP flood\r\nAuthorization: Basic {auth}\r\n\r\n".encode())
    return s


def test_demo_under_a_bad_password_flood(tmp_path):
    port, console = _free_port(), _free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "augnet", "up", "demo", "--duration", str(RUN_S), "--no-view",
         "--db", f"sqlite:///{tmp_path / 'augnet.db'}", "--caster-port", str(port), "--console-port", str(console),
         "--state", str(tmp_path / "state.json"), "--report", str(tmp_path / "report.json")],
        cwd=tmp_path, stdout=open(tmp_path / "up.log", "w"), stderr=subprocess.STDOUT,
        env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        t0 = time.monotonic()
        while not (tmp_path / "state.json").exists():
            assert proc.poll() is None and time.monotonic() - t0 < START_TIMEOUT_S, \
                (tmp_path / "up.log").read_text()[-2000:]
            time.sleep(0.2)
        time.sleep(1.0)
        cas = json.loads((tmp_path / "state.json").read_text())["caster"]
        user, password = cas["user"], cas["password"]
        arrivals: list[list[float]] = [[] for _ in range(3)]
        stop = time.monotonic() + 45.0

        def read(k: int) -> None:
            s = _get(port, "STA1", user, password)
            assert s.recv(12) == b"ICY 200 OK\r\n"
            while time.monotonic() < stop:
                if not s.recv(65536):
                    break
                arrivals[k].append(time.monotonic())
            s.close()

        readers = [threading.Thread(target=read, args=(k,)) for k in range(3)]
        for r in readers:
            r.start()
        time.sleep(10.0)

        def guess(i: int, ip: str) -> bytes:
            try:
                s = _get(port, "STA1", user if i % 2 else f"nobody{i}", f"guess{i}", ip)
                reply = s.recv(200)
                s.close()
                return reply.split(b" ")[1] if reply else b"closed"
            except OSError as exc:
                return type(exc).__name__.encode()

        with ThreadPoolExecutor(300) as pool:
            concurrent = list(pool.map(lambda i: guess(i, f"127.0.{1 + i // 200}.{2 + i % 200}"), range(300)))
        one = []
        for i in range(1000):
            one.append(guess(i, "127.0.9.9"))
            time.sleep(0.01)
        for r in readers:
            r.join(90)
        proc.wait(RUN_S + 120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, (tmp_path / "up.log").read_text()[-3000:]
    assert set(concurrent) <= {b"401", b"429", b"503"}, concurrent
    assert set(one) <= {b"401", b"429", b"503"} and one.count(b"401") <= 10
    for a in arrivals:
        assert len(a) > 30 and max(b - x for x, b in zip(a, a[1:])) < MAX_GAP_S
    report = json.loads((tmp_path / "report.json").read_text())
    assert AUTH_FLOOD_ALARM in [a["kind"] for a in report["alarms"]]
    counters = report["caster"]["counters"]
    assert counters["auth_refused_throttled"] + counters["auth_refused_busy"] > 1000
    for train in report["trains"].values():
        assert train["errors"] == 0

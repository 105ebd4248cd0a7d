"""kill -9 of the lease holder on a 3-node JetStream cluster (loopback 14222-14224, routes 16222-16224)."""
import asyncio
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

import pytest

pytestmark = pytest.mark.slow
NATS_SERVER = shutil.which("nats-server") or "/usr/sbin/nats-server"
PORTS = (14222, 14223, 14224)
ROUTES = (16222, 16223, 16224)
TTL_S = 3.0  # lease TTL = bucket max age
HANG_S = 60  # generous bound against a hang, not a performance assert


@pytest.fixture
def cluster():
    if not os.path.exists(NATS_SERVER):
        pytest.skip("nats-server binary absent")
    d = tempfile.mkdtemp(prefix="cluster-js-")
    routes = ",".join(f"nats://127.0.0.1:{r}" for r in ROUTES)
    procs = [subprocess.Popen([NATS_SERVER, "-a", "127.0.0.1", "-p", str(p), "-js", "-sd", f"{d}/n{i}",
                               "-n", f"n{i}", "--cluster_name", "augtest", "--cluster", f"nats://127.0.0.1:{r}",
                               "--routes", routes], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for i, (p, r) in enumerate(zip(PORTS, ROUTES))]
    yield ",".join(f"nats://127.0.0.1:{p}" for p in PORTS), procs
    for p in procs:
        p.kill()
        p.wait(timeout=10)
    shutil.rmtree(d, ignore_errors=True)


def _make_bucket(urls):
    import nats

    async def run():
        deadline = time.monotonic() + 30
        while True:
            try:
                nc = await nats.connect(servers=urls.split(","), connect_timeout=2)
                try:
                    await nc.jetstream().create_key_value(bucket="leases", history=1, ttl=TTL_S, replicas=3)
                    return
                finally:
                    await nc.close()
            except Exception:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.5)
    asyncio.run(run())


def _spawn(urls, name, lines):
    p = subprocess.Popen([sys.executable, "-m", "tests.cluster.candidate", urls, name, str(TTL_S)],
                         stdout=subprocess.PIPE, text=True, env=os.environ.copy())

    def read():
        for line in p.stdout:
            lines.append((name, line.split()))
    threading.Thread(target=read, daemon=True).start()
    return p


def _wait(pred):
    end = time.monotonic() + HANG_S
    while not pred():
        assert time.monotonic() < end, "hang"
        time.sleep(0.05)


def test_kill_holder_standby_takes_over(cluster):
    urls, _ = cluster
    _make_bucket(urls)
    lines = []
    a = _spawn(urls, "a", lines)
    _wait(lambda: any(n == "a" for n, _ in lines))
    b = _spawn(urls, "b", lines)
    try:
        time.sleep(TTL_S)
        assert not any(n == "b" for n, _ in lines)
        last_a = max(int(w[1]) for n, w in lines if n == "a")
        os.kill(a.pid, signal.SIGKILL)
        t_kill = time.monotonic()
        _wait(lambda: any(n == "b" for n, _ in lines))
        first_b = next(w for n, w in lines if n == "b")
        assert int(first_b[1]) > last_a
        print(f"takeover after kill -9: {float(first_b[2]) - t_kill:.2f} s (TTL {TTL_S} s)")
    finally:
        for p in (a, b):
            p.kill()
            p.wait(timeout=10)

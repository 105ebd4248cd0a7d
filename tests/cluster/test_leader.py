"""Lease acquire/renew/fence against a single-node nats-server of the test's own (loopback port 14232)."""
import asyncio
import os
import shutil
import subprocess
import tempfile
import time

import pytest

from augnet.bus.leader import Lease

pytestmark = pytest.mark.slow
NATS_SERVER = shutil.which("nats-server") or "/usr/sbin/nats-server"
PORT = 14232  # loopback, away from the shared 4222 server


@pytest.fixture
def nats_url():
    if not os.path.exists(NATS_SERVER):
        pytest.skip("nats-server binary absent")
    d = tempfile.mkdtemp(prefix="cluster-nats-")
    p = subprocess.Popen([NATS_SERVER, "-a", "127.0.0.1", "-p", str(PORT), "-js", "-sd", d],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(0.5)
    yield f"nats://127.0.0.1:{PORT}"
    p.kill()
    p.wait(timeout=10)
    shutil.rmtree(d, ignore_errors=True)


def test_one_holder_and_stale_renewal_steps_down(nats_url):
    import nats

    async def run():
        nc = await nats.connect(nats_url, connect_timeout=5)
        try:
            kv = await nc.jetstream().create_key_value(bucket="leases", history=1, ttl=30)
            a, b = Lease(kv, "north", "a"), Lease(kv, "north", "b")
            assert await a.try_acquire()
            assert not await b.try_acquire()
            r1 = a.revision
            assert await a.renew() and a.revision > r1
            # a takes over out of band (as if a's lease had expired and b won it): a's renewal is fenced
            await kv.delete("leader.north")
            assert await b.try_acquire()
            assert not await a.renew() and not a.held
            assert b.revision > r1
        finally:
            await nc.close()

    asyncio.run(asyncio.wait_for(run(), 30))

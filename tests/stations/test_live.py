"""Live streaming to an NTRIP caster: NTRIP 2 POST, NTRIP 1 SOURCE fallback, reconnect with backoff."""

from __future__ import annotations

import asyncio

import pytest
from pyrtcm import RTCMReader

from ntrip_caster.config import CasterConfig
from ntrip_caster.embedded import CasterThread
from stations import live
from stations.scenario import load_scenario


def _short(duration=6.0):
    return load_scenario("baseline-10km").model_copy(update=dict(duration_s=duration))


async def _read_mount(port: int, mount: str, seconds: float) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(f"GET /{mount} HTTP/1.0\r\nUser-Agent: NTRIP test\r\n\r\n".encode())
    await writer.drain()
    status = await reader.readline()
    assert b"200" in status, status
    data = b""
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    while loop.time() < end:
        try:
            chunk = await asyncio.wait_for(reader.read(65536), end - loop.time())
        except asyncio.TimeoutError:
            break
        if not chunk:
            break
        data += chunk
    writer.close()
    return data


@pytest.mark.slow
def test_stations_stream_to_the_project_caster():
    with CasterThread(CasterConfig(port=0, allow_unknown_sources=True), use_uvloop=False) as ct:
        async def main():
            ready = {}
            task = asyncio.ensure_future(live.run_stations(_short(8.0), "127.0.0.1", ct.port, speed=2.0,
                                                           on_ready=ready.update))
            while not ready or not all(c.connected.is_set() for c in ready.values()):
                await asyncio.sleep(0.05)
            data = await _read_mount(ct.port, "B", 2.0)
            stats = await task
            return data, stats

        data, stats = asyncio.run(main())
    assert stats["A"].version == 2 and stats["B"].connects == 1
    assert stats["A"].epochs_sent >= 5
    import io
    ids = [(m.identity, getattr(m, "DF003", None)) for _, m in RTCMReader(io.BytesIO(data))]
    assert ("1077", 2) in ids and ("1127", 2) in ids


async def _fake_caster(handler):
    server = await asyncio.start_server(handler, "127.0.0.1", 0)
    return server, server.sockets[0].getsockname()[1]


def test_falls_back_to_ntrip1_and_reconnects(monkeypatch):
    monkeypatch.setattr(live, "BACKOFF_FIRST_S", 0.05)
    seen = []

    async def handler(reader, writer):
        line = (await reader.readline()).decode()
        while (await reader.readline()).strip():
            pass
        seen.append(line.split()[0])
        if line.startswith("POST"):
            writer.write(b"HTTP/1.1 501 Not Implemented\r\n\r\n")
            await writer.drain()
            writer.close()
            return
        writer.write(b"ICY 200 OK\r\n\r\n")
        await writer.drain()
        got = await reader.read(100)  # take a little, then drop the source: it must come back
        seen.append(len(got))
        writer.close()

    async def main():
        server, port = await _fake_caster(handler)
        stop = asyncio.Event()
        conn = live.SourceConnection("127.0.0.1", port, "A", password="pw")
        task = asyncio.ensure_future(conn.run(stop))
        for _ in range(100):
            await asyncio.sleep(0.03)
            if conn.connected.is_set():
                conn.offer(b"\xd3\x00\x00" * 50)
            if conn.stats.connects >= 2:
                break
        stop.set()
        await task
        server.close()
        return conn.stats

    stats = asyncio.run(main())
    assert seen[0] == "POST" and "SOURCE" in seen
    assert stats.version == 1 and stats.connects >= 2
    assert any("v2 refused" in h for h in stats.history)


def test_backoff_doubles_when_the_caster_is_down(monkeypatch):
    monkeypatch.setattr(live, "BACKOFF_FIRST_S", 0.02)

    async def main():
        server = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        server.close()
        await server.wait_closed()  # nothing listens there now
        stop = asyncio.Event()
        conn = live.SourceConnection("127.0.0.1", port, "A")
        task = asyncio.ensure_future(conn.run(stop))
        await asyncio.sleep(0.6)
        stop.set()
        await task
        return conn.stats

    stats = asyncio.run(main())
    # delays 0.02, 0.04, 0.08, 0.16, 0.32 (+-25 %): about five attempts in 0.6 s, not dozens
    assert 3 <= stats.failures <= 7
    assert stats.connects == 0


def test_a_late_epoch_keeps_its_station_and_ephemeris_messages():
    from augnet.gnss.rtcm import encode_frame
    from stations.live import non_observation_frames
    from stations.rtcm_stream import arp_message

    import numpy as np

    arp = encode_frame(arp_message(101, np.array([-2.2e6, 4.4e6, 4.0e6])))
    fake_msm = bytearray(encode_frame(arp_message(101, np.array([-2.2e6, 4.4e6, 4.0e6]))))
    # rewrite its type to 1077 (MSM7 GPS) and fix nothing else: the filter looks at the type only
    fake_msm[3] = (1077 >> 4) & 0xFF
    fake_msm[4] = ((1077 & 0xF) << 4) | (fake_msm[4] & 0x0F)
    blob = bytes(fake_msm) + arp + bytes(fake_msm)
    assert non_observation_frames(blob) == arp
    assert non_observation_frames(b"") == b""
    assert non_observation_frames(arp[:-2]) == b""  # a truncated frame is not passed on

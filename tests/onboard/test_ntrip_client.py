"""NTRIP client: the sans-IO core fed bytes in odd splits, and the asyncio client against fake casters on
loopback (NTRIP 2.0 chunked, NTRIP 1.0 fallback, reconnect with backoff, watchdog, GGA upload)."""

from __future__ import annotations

import asyncio
import base64

import pytest

from augnet.onboard.ntrip_client import (
    Connected,
    Data,
    NtripClient,
    NtripClientConnection,
    NtripError,
    Rejected,
    SourceTable,
)

GGA = "$GNGGA,081942.00,3508.08194070,N,13658.65452826,E,4,21,1.0,104.8596,M,0.000,M,1.2,0000*4E"
PAYLOAD = bytes(range(256)) * 20  # stands for RTCM frames: the client must pass bytes through exactly


def _feed_all(conn, data: bytes, step: int):
    events = []
    for i in range(0, len(data), step):
        events += conn.receive(data[i:i + step])
    return events


def _chunked(data: bytes, size: int = 700) -> bytes:
    out = b""
    for i in range(0, len(data), size):
        part = data[i:i + size]
        out += f"{len(part):x}\r\n".encode() + part + b"\r\n"
    return out + b"0\r\n\r\n"


def test_request_forms():
    c2 = NtripClientConnection("caster.example", 2101, "VRS1", "rail", "s3cret", version=2, gga=GGA)
    r2 = c2.request().decode()
    assert r2.startswith("GET /VRS1 HTTP/1.1\r\n")
    assert "Ntrip-Version: Ntrip/2.0\r\n" in r2 and "Host: caster.example:2101\r\n" in r2
    assert f"Authorization: Basic {base64.b64encode(b'rail:s3cret').decode()}\r\n" in r2
    assert f"Ntrip-GGA: {GGA}\r\n" in r2 and r2.endswith("\r\n\r\n")
    r1 = NtripClientConnection("c", 2101, "VRS1", version=1, gga=GGA).request().decode()
    assert r1.startswith("GET /VRS1 HTTP/1.0\r\n") and "Ntrip-Version" not in r1
    assert r1.endswith("\r\n\r\n" + GGA + "\r\n")


@pytest.mark.parametrize("step", [1, 3, 7, 64, 100000])
def test_v2_chunked_response_in_any_split(step):
    conn = NtripClientConnection("c", 1, "M")
    resp = (b"HTTP/1.1 200 OK\r\nNtrip-Version: Ntrip/2.0\r\nContent-Type: gnss/data\r\n"
            b"Transfer-Encoding: chunked\r\n\r\n" + _chunked(PAYLOAD))
    ev = _feed_all(conn, resp, step)
    assert isinstance(ev[0], Connected) and ev[0].version == 2
    assert b"".join(e.data for e in ev if isinstance(e, Data)) == PAYLOAD


@pytest.mark.parametrize("step", [1, 5, 1000])
def test_v1_icy_response(step):
    conn = NtripClientConnection("c", 1, "M", version=1)
    ev = _feed_all(conn, b"ICY 200 OK\r\n" + PAYLOAD, step)
    assert ev[0] == Connected(1, "ICY 200 OK")
    assert b"".join(e.data for e in ev if isinstance(e, Data)) == PAYLOAD


def test_rejections_sourcetable_and_garbage():
    ev = NtripClientConnection("c", 1, "M").receive(b"HTTP/1.1 401 Unauthorized\r\nWWW-Authenticate: Basic\r\n\r\n")
    assert ev == [Rejected(401, "HTTP/1.1 401 Unauthorized", False)]
    ev = NtripClientConnection("c", 1, "M").receive(b"HTTP/1.1 501 Not Implemented\r\n\r\n")
    assert ev[0].retry_as_v1
    st = b"SOURCETABLE 200 OK\r\nContent-Type: text/plain\r\n\r\nSTR;VRS;...\r\nENDSOURCETABLE\r\n"
    ev = _feed_all(NtripClientConnection("c", 1, "NOPE", version=1), st, 4)
    assert isinstance(ev[-1], SourceTable) and "STR;VRS" in ev[-1].text
    with pytest.raises(NtripError):
        NtripClientConnection("c", 1, "M").receive(b"SSH-2.0-OpenSSH\r\n")
    conn = NtripClientConnection("c", 1, "M")
    conn.receive(b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n")
    with pytest.raises(NtripError):
        conn.receive(b"zz\r\n")


class FakeCaster:
    """A loopback caster whose behaviour per connection is scripted by the test."""

    def __init__(self, handler):
        self.handler = handler
        self.requests: list[bytes] = []
        self.ggas: list[str] = []
        self.connections = 0

    async def start(self):
        self.server = await asyncio.start_server(self._client, "127.0.0.1", 0)
        self.port = self.server.sockets[0].getsockname()[1]
        return self

    async def _client(self, reader, writer):
        self.connections += 1
        head = await reader.readuntil(b"\r\n\r\n")
        self.requests.append(head)
        try:
            await self.handler(self, self.connections, head, reader, writer)
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            writer.close()

    async def read_ggas(self, reader, n):
        for _ in range(n):
            line = await reader.readuntil(b"\r\n")
            self.ggas.append(line.decode().strip())

    async def stop(self):
        self.server.close()
        await self.server.wait_closed()


async def _run_client(client, until, timeout=10.0):
    task = asyncio.ensure_future(client.run())
    try:
        await asyncio.wait_for(until(), timeout)
    finally:
        client.stop()
        await asyncio.wait_for(task, 5.0)


def test_v2_stream_with_gga_upload_and_reconnect_after_the_caster_drops():
    received = bytearray()

    async def handler(caster, n, head, reader, writer):
        writer.write(b"HTTP/1.1 200 OK\r\nNtrip-Version: Ntrip/2.0\r\nTransfer-Encoding: chunked\r\n\r\n")
        writer.write(_chunked(PAYLOAD[:1000]))
        await writer.drain()
        if n == 1:
            await caster.read_ggas(reader, 2)  # two periodic GGAs, then the caster drops us
        else:
            await asyncio.sleep(5)

    async def main():
        caster = await FakeCaster(handler).start()
        client = NtripClient("127.0.0.1", caster.port, "VRS1", received.extend, user="u", password="p",
                             gga_provider=lambda: GGA, gga_interval_s=0.05, backoff_initial_s=0.05)

        async def until():
            while len(received) < 2000:
                await asyncio.sleep(0.01)

        await _run_client(client, until)
        await caster.stop()
        return caster, client

    caster, client = asyncio.run(main())
    assert bytes(received[:1000]) == PAYLOAD[:1000] and bytes(received[1000:2000]) == PAYLOAD[:1000]
    assert caster.connections >= 2 and client.stats.connects >= 2
    assert b"Ntrip-GGA: " + GGA.encode() in caster.requests[0]
    assert caster.ggas[:2] == [GGA, GGA]
    assert client.stats.fallbacks_to_v1 == 0


def test_falls_back_to_ntrip1_when_the_caster_refuses_v2():
    received = bytearray()

    async def handler(caster, n, head, reader, writer):
        if b"Ntrip-Version: Ntrip/2.0" in head:
            writer.write(b"HTTP/1.1 400 Bad Request\r\n\r\n")
        else:
            writer.write(b"ICY 200 OK\r\n" + PAYLOAD)
            await writer.drain()
            await asyncio.sleep(5)
        await writer.drain()

    async def main():
        caster = await FakeCaster(handler).start()
        client = NtripClient("127.0.0.1", caster.port, "OLD", received.extend, backoff_initial_s=0.02)

        async def until():
            while len(received) < len(PAYLOAD):
                await asyncio.sleep(0.01)

        await _run_client(client, until)
        await caster.stop()
        return caster, client

    caster, client = asyncio.run(main())
    assert bytes(received) == PAYLOAD
    assert client.stats.fallbacks_to_v1 == 1
    assert caster.requests[-1].startswith(b"GET /OLD HTTP/1.0\r\n")


def test_watchdog_reconnects_a_stalled_stream_and_backoff_grows():
    async def handler(caster, n, head, reader, writer):
        writer.write(b"HTTP/1.1 200 OK\r\n\r\n" + b"x" * 10)
        await writer.drain()
        await asyncio.sleep(5)  # then silence: the client's watchdog must fire

    async def main():
        caster = await FakeCaster(handler).start()
        client = NtripClient("127.0.0.1", caster.port, "M", lambda b: None, data_timeout_s=0.1,
                             backoff_initial_s=0.02)

        async def until():
            while client.stats.watchdog_timeouts < 3:
                await asyncio.sleep(0.01)

        await _run_client(client, until)
        await caster.stop()
        return caster, client

    caster, client = asyncio.run(main())
    assert client.stats.watchdog_timeouts >= 3
    assert caster.connections >= 3
    assert "no data for 0.1 s" in client.stats.last_error


def test_unreachable_caster_backs_off_exponentially():
    async def main():
        srv = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
        port = srv.sockets[0].getsockname()[1]
        srv.close()
        await srv.wait_closed()  # nothing listens on `port` any more
        client = NtripClient("127.0.0.1", port, "M", lambda b: None, backoff_initial_s=0.01, backoff_max_s=0.08)

        async def until():
            while client.stats.failures < 5:
                await asyncio.sleep(0.005)

        await _run_client(client, until)
        return client

    client = asyncio.run(main())
    delays = [float(e.split()[2]) for e in client.stats.events if e.startswith("reconnect in")]
    assert len(delays) >= 4
    assert delays[3] > 2.0 * delays[0]  # doubling (with +-20 % jitter)
    assert max(delays) <= 0.08 * 1.2 + 0.005  # the log prints the delay to 10 ms (0.096 reads "0.10")

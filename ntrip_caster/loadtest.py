"""`augnet loadtest`: many NTRIP clients against one caster, per-epoch delivery latency as JSON.

One source sends an epoch every 1/rate seconds: one RTCM 3 frame of a proprietary message type
(LOADTEST_MESSAGE_TYPE) whose payload carries the epoch number and the send time
(CLOCK_MONOTONIC, shared by every process on the machine), padded to the requested size. Clients
live in several worker processes (one asyncio loop each), mix NTRIP 1 and 2, and send GGA when the
mountpoint needs it. Every received frame is checked byte for byte (the first copy of an epoch in a
process against its CRC-24Q, every other copy against that first one), and its latency is the
receive time minus the send time in the frame.

Result (JSON): requested, connected, complete (clients that got every measured epoch), lost
epochs, bad frames, latency p50/p90/p99/max in ms, the caster's CPU (% of one core over the
measured window) and peak RSS, and the settings.

The caster is either spawned here (`ntrip-caster serve`, the default) or an external one
(`--target host:port --caster-pid PID`), so other casters can face the same load.
"""

from __future__ import annotations

import asyncio
import base64
import json
import multiprocessing as mp
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Optional

import typer

from augwire.chunked import ChunkedDecoder, encode_chunk
from augwire.crc24q import crc24q
from augwire.rtcm_framing import (CRC_BYTES, FRAME_OVERHEAD_BYTES, HEADER_BYTES, MAX_PAYLOAD_BYTES,
                                  PREAMBLE, frame, frame_length)

from .gga import format_gga

# RTCM 10403.3 reserves 4001-4095 for proprietary messages; 4088 is not assigned to a vendor in
# RTKLIB's or pyrtcm's tables, so decoders skip it as unknown.
LOADTEST_MESSAGE_TYPE = 4088
# Payload: 12-bit type + 4 spare bits, epoch number (u32), send time in ns (u64), then fill.
_HEAD = struct.Struct(">HIQ")
LOADTEST_MIN_PAYLOAD = _HEAD.size
# Where the load's base station "is" (GGA mode): clients report positions within a few km of it.
LOAD_BASE_LAT_DEG = 31.2
LOAD_BASE_LON_DEG = 121.4
# Connections a worker opens concurrently; more only fills the caster's listen queue.
CONNECT_CONCURRENCY = 256
# After the last epoch, how long clients may still receive it before it counts as lost (s).
DRAIN_S = 3.0

app = typer.Typer(help="NTRIP load generator.", no_args_is_help=True, add_completion=False)


def epoch_frame(seq: int, sent_ns: int, size: int) -> bytes:
    """The RTCM 3 frame for one epoch; `size` is the payload size (bytes)."""
    size = max(LOADTEST_MIN_PAYLOAD, min(size, MAX_PAYLOAD_BYTES))
    head = _HEAD.pack(LOADTEST_MESSAGE_TYPE << 4, seq, sent_ns)
    start = seq & 0xFF  # fill byte i is (seq + i) mod 256, sliced from a precomputed pattern
    return frame(head + _FILL_PATTERN[start:start + size - len(head)])


_FILL_PATTERN = bytes(range(256)) * 6  # 1,536 bytes: any 256-aligned start leaves >= 1,023


def epoch_payload(size: int) -> int:
    return max(LOADTEST_MIN_PAYLOAD, min(size, MAX_PAYLOAD_BYTES))


@dataclass
class ClientSpec:
    host: str
    port: int
    mount: str
    version: int
    user: str | None = None
    password: str | None = None
    gga: bytes | None = None


def client_request(spec: ClientSpec) -> bytes:
    lines = [f"GET /{spec.mount} HTTP/1.1" if spec.version == 2 else f"GET /{spec.mount} HTTP/1.0",
             f"Host: {spec.host}:{spec.port}", "User-Agent: NTRIP augnet-loadtest/0.1"]
    if spec.version == 2:
        lines.append("Ntrip-Version: Ntrip/2.0")
        if spec.gga:
            lines.append("Ntrip-GGA: " + spec.gga.decode().strip())
    if spec.user is not None:
        token = base64.b64encode(f"{spec.user}:{spec.password or ''}".encode()).decode()
        lines.append(f"Authorization: Basic {token}")
    req = ("\r\n".join(lines) + "\r\n\r\n").encode()
    if spec.version == 1 and spec.gga:
        req += spec.gga
    return req


class FrameCheck:
    """Per-process memory of each epoch's first copy: later copies must equal it byte for byte."""

    def __init__(self) -> None:
        self.seen: dict[int, bytes] = {}

    def check(self, seq: int, frame: bytes) -> bool:
        first = self.seen.get(seq)
        if first is None:
            if crc24q(frame[:-CRC_BYTES]) != int.from_bytes(frame[-CRC_BYTES:], "big"):
                return False
            self.seen[seq] = frame
            return True
        return first == frame


class LoadClient(asyncio.Protocol):
    """One NTRIP client: reads the response head, then frames; records epoch -> latency (ns)."""

    def __init__(self, spec: ClientSpec, check: FrameCheck, connected: asyncio.Future) -> None:
        self.spec = spec
        self.check = check
        self.connected = connected
        self.transport: asyncio.Transport | None = None
        self.head_done = False
        self.buf = bytearray()
        self.dechunk: ChunkedDecoder | None = None  # v2 replies in chunked coding
        self.latency_ns: dict[int, int] = {}
        self.bad = 0
        self.status = ""
        self.closed = False
        self.junk = 0

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]
        transport.write(client_request(self.spec))  # type: ignore[attr-defined]

    def connection_lost(self, exc: Exception | None) -> None:
        self.closed = True
        if not self.connected.done():
            self.connected.set_result(False)

    def data_received(self, data: bytes) -> None:
        now = time.monotonic_ns()
        if not self.head_done:
            self.buf += data
            if self.spec.version == 1:
                end = self.buf.find(b"\r\n")
                if end < 0:
                    return
                self.status = self.buf[:end].decode("latin-1")
                ok = self.status == "ICY 200 OK"
                rest = bytes(self.buf[end + 2:])
            else:
                end = self.buf.find(b"\r\n\r\n")
                if end < 0:
                    return
                self.status = self.buf[:self.buf.find(b"\r\n")].decode("latin-1")
                ok = self.status.startswith("HTTP/1.1 200")
                # Some casters (Millipede) answer v2 without chunked coding: follow the reply.
                if b"transfer-encoding: chunked" in bytes(self.buf[:end]).lower():
                    # Any chunk size: the load's frames come in chunks of whatever the caster chose.
                    self.dechunk = ChunkedDecoder(max_chunk_bytes=None)
                rest = bytes(self.buf[end + 4:])
            self.buf = bytearray()
            self.head_done = True
            if not self.connected.done():
                self.connected.set_result(ok)
            if not ok:
                self.transport.close()  # type: ignore[union-attr]
                return
            if not rest:
                return
            data = rest
        if self.dechunk is not None:
            data = b"".join(self.dechunk.feed(data))
        if not self.buf and len(data) >= FRAME_OVERHEAD_BYTES and data[0] == PREAMBLE and \
                len(data) == frame_length(data, 0):
            self._frame(data, now)  # fast path: exactly one frame
            return
        self.buf += data
        self._frames(now)

    def _frame(self, frame: bytes, now: int) -> None:
        if len(frame) < FRAME_OVERHEAD_BYTES + _HEAD.size:
            self.bad += 1
            return
        mtype, seq, sent = _HEAD.unpack_from(frame, HEADER_BYTES)
        if mtype >> 4 != LOADTEST_MESSAGE_TYPE or not self.check.check(seq, frame):
            self.bad += 1
            return
        self.latency_ns[seq] = now - sent

    def _frames(self, now: int) -> None:
        buf = self.buf
        pos = 0
        n = len(buf)
        while n - pos >= FRAME_OVERHEAD_BYTES:
            if buf[pos] != PREAMBLE:  # bytes between frames (e.g. a caster's extra CRLF after ICY)
                nxt = buf.find(PREAMBLE, pos + 1)
                end = n if nxt < 0 else nxt
                self.junk += end - pos
                pos = end
                continue
            total = frame_length(buf, pos)
            if n - pos < total:
                break
            self._frame(bytes(buf[pos:pos + total]), now)
            pos += total
        del buf[:pos]


async def open_clients(specs: list[ClientSpec], concurrency: int = CONNECT_CONCURRENCY,
                       timeout: float = 30.0) -> list[LoadClient]:
    """Connect every client (bounded concurrency); returns them all, connected or not."""
    loop = asyncio.get_running_loop()
    check = FrameCheck()
    sem = asyncio.Semaphore(concurrency)
    clients: list[LoadClient] = []

    async def one(spec: ClientSpec) -> None:
        fut: asyncio.Future = loop.create_future()
        client = LoadClient(spec, check, fut)
        clients.append(client)
        async with sem:
            try:
                await asyncio.wait_for(
                    loop.create_connection(lambda: client, spec.host, spec.port), timeout)
                await asyncio.wait_for(fut, timeout)
            except (OSError, asyncio.TimeoutError) as exc:
                client.status = client.status or f"connect failed: {type(exc).__name__}"
                if not fut.done():
                    fut.set_result(False)

    await asyncio.gather(*(one(s) for s in specs))
    return clients


def client_specs(host: str, port: int, mount: str, n: int, v2_fraction: float, gga: bool,
                 user: str | None, password: str | None, offset: int = 0) -> list[ClientSpec]:
    specs = []
    n_v2 = round(n * v2_fraction)
    for i in range(n):
        g = None
        if gga:  # trains strung along ~10 km of line near the base
            g = format_gga(LOAD_BASE_LAT_DEG + ((offset + i) % 1000) * 1e-4, LOAD_BASE_LON_DEG)
        specs.append(ClientSpec(host, port, mount, 2 if i < n_v2 else 1, user, password, g))
    return specs


# --- worker processes --------------------------------------------------------------------------
def _worker(specs: list[ClientSpec], ctl: Any, use_uvloop: bool) -> None:
    """Runs in a child process: connect, report, wait for 'stop', report latencies."""
    async def main() -> None:
        clients = await open_clients(specs)
        connected = sum(1 for c in clients if c.head_done and not c.closed and (
            c.status == "ICY 200 OK" or c.status.startswith("HTTP/1.1 200")))
        statuses: dict[str, int] = {}
        for c in clients:
            statuses[c.status] = statuses.get(c.status, 0) + 1
        ctl.send(("ready", connected, statuses))
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, ctl.recv)  # "stop"
        result = [(sorted(c.latency_ns.items()), c.bad, c.junk) for c in clients]
        ctl.send(("result", result))
        for c in clients:
            if c.transport is not None:
                c.transport.abort()

    if use_uvloop:
        try:
            import uvloop
            uvloop.run(main())
            return
        except ImportError:
            pass
    asyncio.run(main())


# --- source ------------------------------------------------------------------------------------
async def open_source(host: str, port: int, mount: str, version: int, user: str | None,
                      password: str) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    reader, writer = await asyncio.open_connection(host, port)
    sock = writer.get_extra_info("socket")
    if sock is not None:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    if version == 0:  # raw TCP into a relay's input (e.g. str2str -in tcpsvr:// -out ntripc://)
        return reader, writer
    if version == 1:
        writer.write(f"SOURCE {password} /{mount}\r\nSource-Agent: NTRIP augnet-loadtest/0.1\r\n"
                     f"STR: \r\n\r\n".encode())
    else:
        token = base64.b64encode(f"{user or ''}:{password}".encode()).decode()
        writer.write(f"POST /{mount} HTTP/1.1\r\nHost: {host}\r\nNtrip-Version: Ntrip/2.0\r\n"
                     f"Authorization: Basic {token}\r\nUser-Agent: NTRIP augnet-loadtest/0.1\r\n"
                     "Transfer-Encoding: chunked\r\n\r\n".encode())
    await writer.drain()
    line = await asyncio.wait_for(reader.readline(), 10)
    if not (line.startswith(b"ICY 200") or line.startswith(b"HTTP/1.1 200")):
        raise RuntimeError(f"source refused by the caster: {line[:80]!r}")
    if version == 2:
        await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), 10)
    return reader, writer


# --- the caster under test ---------------------------------------------------------------------
def spawn_caster(use_uvloop: bool = True, backlog: int | None = None
                 ) -> tuple[subprocess.Popen, int, Path]:
    """Start `ntrip-caster serve` on a free loopback port; returns (process, port, workdir)."""
    work = Path(tempfile.mkdtemp(prefix="augnet-loadtest-"))
    cfg = work / "caster.toml"
    # Stats are written once, at shutdown: a periodic snapshot of 10,000 clients would itself
    # disturb the latency being measured.
    text = ("[caster]\nhost = \"127.0.0.1\"\nport = 0\nallow_unknown_sources = false\n"
            f"stats_path = \"{work / 'stats.json'}\"\nstats_interval_s = 3600.0\n\n"
            "[[mountpoints]]\nname = \"LOAD\"\nkind = \"source\"\nwrite = [\"*\"]\n"
            f"latitude = {LOAD_BASE_LAT_DEG}\nlongitude = {LOAD_BASE_LON_DEG}\n\n"
            "[[mountpoints]]\nname = \"NEAR\"\nkind = \"nearest\"\n\n"
            "[[mountpoints]]\nname = \"VRS\"\nkind = \"vrs\"\n"
            "factory = \"ntrip_caster.relay_factory:from_env\"\n")
    if backlog is not None:
        text = text.replace("[[mountpoints]]", f"[limits]\nmax_client_backlog_bytes = {backlog}\n\n"
                            "[[mountpoints]]", 1)
    cfg.write_text(text)
    ready = work / "port"
    cmd = [sys.executable, "-m", "ntrip_caster.cli", "serve", "-c", str(cfg), "--ready-file",
           str(ready), "--log-level", "WARNING", "--uvloop" if use_uvloop else "--no-uvloop"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=open(work / "caster.log", "wb"))
    deadline = time.monotonic() + 20
    while not ready.exists() or not ready.read_text().strip():
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            raise RuntimeError(f"caster did not start: {(work / 'caster.log').read_text()[-500:]}")
        time.sleep(0.05)
    return proc, int(ready.read_text()), work


def _percentiles(values: list[int]) -> dict[str, float | None]:
    if not values:
        return {"p50": None, "p90": None, "p99": None, "max": None}
    values = sorted(values)
    n = len(values)

    def pct(p: float) -> float:  # nearest-rank
        return round(values[min(n - 1, max(0, int(-(-p * n // 100)) - 1))] / 1e6, 3)

    return {"p50": pct(50), "p90": pct(90), "p99": pct(99), "max": round(values[-1] / 1e6, 3)}


@dataclass
class LoadSettings:
    clients: int = 1000
    epochs: int = 20
    rate_hz: float = 1.0
    size: int = 1000
    v2_fraction: float = 0.5
    processes: int = 2
    gga: bool = False
    vrs: bool = False  # clients read the VRS mountpoint (per-client streams via a factory), GGA
    mount: str = ""
    target: str = ""  # host:port of an external caster; empty = spawn ours
    caster_pid: int = 0
    source_version: int = 1
    source_user: str = ""
    source_password: str = "loadtest"
    source_mount: str = ""
    source_target: str = ""  # host:port the source connects to, when not the caster's port
    user: str = ""
    password: str = ""
    uvloop: bool = True
    warmup_epochs: int = 2
    backlog: int | None = None
    label: str = ""
    extra: dict = field(default_factory=dict)


def run_load(s: LoadSettings) -> dict[str, Any]:
    """Run one load test and return its JSON-able result."""
    import psutil

    spawned = None
    _work = Path(".")
    if s.target:
        host, _, port_text = s.target.rpartition(":")
        port = int(port_text)
        caster_pid = s.caster_pid
    else:
        spawned, port, _work = spawn_caster(s.uvloop, s.backlog)
        host, caster_pid = "127.0.0.1", spawned.pid
    gga = s.gga or s.vrs
    mount = s.mount or ("VRS" if s.vrs else "NEAR" if s.gga else "LOAD")
    source_mount = s.source_mount or "LOAD"
    caster = psutil.Process(caster_pid) if caster_pid else None
    ctx = mp.get_context("spawn")
    pipes, procs = [], []
    try:
        loop = asyncio.new_event_loop()
        src_host, src_port = host, port
        if s.source_target:
            src_host, _, src_port_text = s.source_target.rpartition(":")
            src_port = int(src_port_text)
        reader, writer = loop.run_until_complete(open_source(
            src_host, src_port, source_mount, s.source_version, s.source_user or None,
            s.source_password))
        size = epoch_payload(s.size)
        # Workers and their clients.
        per = [s.clients // s.processes + (1 if i < s.clients % s.processes else 0)
               for i in range(s.processes)]
        offset = 0
        for n in per:
            if n == 0:
                continue
            specs = client_specs(host, port, mount, n, s.v2_fraction, gga, s.user or None,
                                 s.password or None, offset)
            offset += n
            parent, child = ctx.Pipe()
            p = ctx.Process(target=_worker, args=(specs, child, s.uvloop), daemon=True)
            p.start()
            pipes.append(parent)
            procs.append(p)
        t_connect = time.monotonic()
        connected, statuses = 0, {}
        for pipe in pipes:
            if not pipe.poll(300):
                raise RuntimeError("a load worker did not report within 300 s")
            _tag, n_ok, st = pipe.recv()
            connected += n_ok
            for k, v in st.items():
                statuses[k] = statuses.get(k, 0) + v
        connect_s = time.monotonic() - t_connect

        def send(seq: int) -> None:
            frame = epoch_frame(seq, time.monotonic_ns(), size)
            writer.write(encode_chunk(frame) if s.source_version == 2 else frame)

        async def epochs() -> tuple[float, float, int]:
            period = 1.0 / s.rate_hz
            # warm-up epochs (not measured): GGA-driven clients pick their base, caches warm up
            for seq in range(s.warmup_epochs):
                send(seq)
                await writer.drain()
                await asyncio.sleep(period)
            cpu0 = sum(caster.cpu_times()[:2]) if caster else 0.0
            t0 = time.monotonic()
            rss_peak = 0
            start = loop.time()
            for k in range(s.epochs):
                await asyncio.sleep(max(0.0, start + k * period - loop.time()))
                send(s.warmup_epochs + k)
                await writer.drain()
                if caster:
                    rss_peak = max(rss_peak, caster.memory_info().rss)
            await asyncio.sleep(period)
            cpu1 = sum(caster.cpu_times()[:2]) if caster else 0.0
            t1 = time.monotonic()
            await asyncio.sleep(DRAIN_S)
            return cpu1 - cpu0, t1 - t0, rss_peak

        cpu_s, window_s, rss_peak = loop.run_until_complete(epochs())
        measured = range(s.warmup_epochs, s.warmup_epochs + s.epochs)
        lat: list[int] = []
        complete = lost = bad = junk = 0
        for pipe in pipes:
            pipe.send("stop")
        for pipe in pipes:
            if not pipe.poll(120):
                raise RuntimeError("a load worker did not return its results")
            _tag, result = pipe.recv()
            for items, n_bad, n_junk in result:
                got = dict(items)
                bad += n_bad
                junk += n_junk
                missing = sum(1 for e in measured if e not in got)
                lost += missing
                complete += missing == 0
                lat.extend(got[e] for e in measured if e in got)
        writer.close()
        loop.close()
    finally:
        for p in procs:
            p.join(timeout=10)
            if p.is_alive():
                p.kill()
        if spawned is not None:
            spawned.terminate()
            try:
                spawned.wait(timeout=10)
            except subprocess.TimeoutExpired:
                spawned.kill()
    fanout = None
    if spawned is not None:  # our caster's own view: time to hand one epoch to every client
        try:
            stats = json.loads((_work / "stats.json").read_text())
            m = stats["mounts"]["LOAD"]
            fanout = {"max_ms": m["fanout_max_ms"], "drops": m["drops"],
                      "bytes_out": m["bytes_out"]}
        except (OSError, ValueError, KeyError):
            pass
    return {
        "label": s.label or ("augnet" if spawned is not None else s.target),
        "requested": s.clients, "connected": connected, "complete": complete,
        "epochs": s.epochs, "lost_epochs": lost, "bad_frames": bad,
        "junk_bytes": junk,
        "latency_ms": _percentiles(lat), "samples": len(lat),
        "caster_cpu_percent": round(100.0 * cpu_s / window_s, 1) if caster else None,
        "caster_rss_mb": round(rss_peak / 2**20, 1) if caster else None,
        "connect_s": round(connect_s, 2), "statuses": statuses, "caster_fanout": fanout,
        "settings": {k: v for k, v in asdict(s).items() if k not in ("password", "source_password",
                                                                     "extra")},
        "cpus": os.cpu_count(),
    }


@app.command()
def run(
    clients: int = typer.Option(1000, help="Concurrent clients."),
    epochs: int = typer.Option(20, help="Measured epochs."),
    rate: float = typer.Option(1.0, help="Epochs per second."),
    size: int = typer.Option(1000, help="Bytes of RTCM payload per epoch (max 1023)."),
    v2_fraction: float = typer.Option(0.5, help="Share of clients speaking NTRIP 2 (rest NTRIP 1)."),
    processes: int = typer.Option(2, help="Client worker processes."),
    gga: bool = typer.Option(False, help="Clients send GGA to a GGA-driven mountpoint (NEAR)."),
    vrs: bool = typer.Option(False, help="Clients send GGA to the VRS mountpoint: one stream per "
                             "client through the stream factory (relaying LOAD)."),
    mount: str = typer.Option("", help="Mountpoint clients read (default LOAD, or NEAR with --gga)."),
    target: str = typer.Option("", help="host:port of an external caster (default: spawn ours)."),
    caster_pid: int = typer.Option(0, help="PID of the external caster, for CPU and memory."),
    source_version: int = typer.Option(1, help="1: SOURCE; 2: POST chunked; 0: raw TCP (no "
                                       "NTRIP handshake) to --source-target."),
    source_target: str = typer.Option("", help="host:port for the source when it is not the "
                                      "caster's port (e.g. str2str's tcpsvr input)."),
    source_user: str = typer.Option("", help="User for a v2 source."),
    source_password: str = typer.Option("loadtest", help="Source password."),
    source_mount: str = typer.Option("", help="Mountpoint the source publishes (default LOAD)."),
    user: str = typer.Option("", help="Client user (empty: no credentials)."),
    password: str = typer.Option("", help="Client password."),
    uvloop: bool = typer.Option(True, "--uvloop/--no-uvloop"),
    label: str = typer.Option("", help="Name for this run in the JSON."),
    output: Optional[Path] = typer.Option(None, "--json", help="Also write the JSON here."),
) -> None:
    """Run one load test and print its result as JSON."""
    if not 0 <= v2_fraction <= 1 or clients < 1 or epochs < 1 or rate <= 0 or processes < 1:
        typer.echo("error: need clients >= 1, epochs >= 1, rate > 0, processes >= 1, "
                   "0 <= v2-fraction <= 1", err=True)
        raise typer.Exit(2)
    result = run_load(LoadSettings(
        clients=clients, epochs=epochs, rate_hz=rate, size=size, v2_fraction=v2_fraction,
        processes=processes, gga=gga, vrs=vrs, mount=mount, target=target, caster_pid=caster_pid,
        source_version=source_version, source_user=source_user, source_password=source_password,
        source_mount=source_mount, source_target=source_target, user=user, password=password,
        uvloop=uvloop, label=label))
    text = json.dumps(result, indent=2)
    typer.echo(text)
    if output is not None:
        output.write_text(text)


@app.command()
def sweep(
    clients: str = typer.Option("1000,5000,10000", help="Comma-separated client counts."),
    epochs: int = typer.Option(20),
    rate: float = typer.Option(1.0),
    size: int = typer.Option(1000),
    v2_fraction: float = typer.Option(0.5),
    processes: int = typer.Option(2),
    gga: bool = typer.Option(False),
    target: str = typer.Option("", help="Also load this external caster (host:port) at each step."),
    caster_pid: int = typer.Option(0),
    target_label: str = typer.Option("external"),
    source_password: str = typer.Option("loadtest"),
    target_source_mount: str = typer.Option("LOAD"),
    target_mount: str = typer.Option("LOAD"),
    output: Optional[Path] = typer.Option(None, "--json"),
) -> None:
    """Several client counts against our caster (spawned) and optionally an external one, side by
    side in one run; prints a JSON list."""
    results = []
    for n in [int(x) for x in clients.split(",") if x.strip()]:
        common = dict(clients=n, epochs=epochs, rate_hz=rate, size=size, v2_fraction=v2_fraction,
                      processes=processes, gga=gga)
        results.append(run_load(LoadSettings(**common, label="augnet")))
        typer.echo(json.dumps(results[-1]), err=True)
        if target:
            results.append(run_load(LoadSettings(
                **common, target=target, caster_pid=caster_pid, label=target_label,
                source_password=source_password, source_mount=target_source_mount,
                mount=target_mount)))
            typer.echo(json.dumps(results[-1]), err=True)
    text = json.dumps(results, indent=2)
    typer.echo(text)
    if output is not None:
        output.write_text(text)


def main() -> None:
    app()


if __name__ == "__main__":
    main()

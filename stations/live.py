"""`augnet stations run`: stream every simulated receiver to an NTRIP caster as a source, live.

Each reference station pushes its RTCM 3 stream to mountpoint `<id>`, each train its raw receiver
stream to `TRAIN-<id>-RAW` (so an outside rover engine, e.g. RTKLIB rtkrcv, can be the train's
receiver).  The scenario starts at the current GPS time, and epochs leave at their own time (or
`speed` times faster).

Per source connection (one asyncio task each):
  * NTRIP 2.0 first: `POST /MOUNT HTTP/1.1` with Basic authentication and a chunked body;
  * if the caster refuses that request form (a 4xx/5xx other than 401/403, or an answer that is
    not HTTP), NTRIP 1.0: `SOURCE <password> /MOUNT`, answered `ICY 200 OK`, then raw bytes;
    the version that worked is remembered for reconnections;
  * a lost or refused connection is retried with exponential backoff (1 s doubling to 30 s, with
    jitter); while disconnected, epochs are dropped, not queued: a late correction is useless
    (network-rtk.md: under 5 s or the rover loses its fix).
"""

from __future__ import annotations

import asyncio
import base64
import collections
import math
import random
from dataclasses import dataclass, field

from augnet.gnss import time as gtime
from augwire.chunked import LAST_CHUNK, encode_chunk
from augwire.rtcm_framing import CRC_BYTES, FRAME_OVERHEAD_BYTES, HEADER_BYTES, PREAMBLE, frame_length, message_type
from stations.rtcm_stream import RtcmStreams
from stations.scenario import Scenario
from stations.world import World

USER_AGENT = "NTRIP augnet-stations/0.1"
BACKOFF_FIRST_S = 1.0
BACKOFF_MAX_S = 30.0
CONNECT_TIMEOUT_S = 10.0
RESPONSE_TIMEOUT_S = 10.0
QUEUE_EPOCHS = 5  # at most this many epochs wait for a slow link; older ones are dropped
LIVE_BLOCK_EPOCHS = 5  # simulate a few epochs ahead of the wall clock
MSM_FIRST_TYPE, MSM_LAST_TYPE = 1071, 1137  # RTCM 10403.3: MSM1-7 of GPS ... BeiDou
LATE_EPOCH_S = 1.0
# real time: the next block is simulated this long after the current block's first epoch left, between
# two epochs' bursts of work in the process that also carries the caster and the VRS (on a busy machine
# the simulation's CPU then does not land on the correction age)
PRODUCE_DELAY_S = 0.4
MAX_STANDING_BYTES = 64 * 1024  # ~100 ephemeris messages: all of three constellations, twice  # live: an epoch this far behind its GPS time is dropped, not sent late


class SourceRefused(Exception):
    def __init__(self, status: str, fallback: bool):
        super().__init__(status)
        self.status = status
        self.fallback = fallback  # try NTRIP 1 instead


def mountpoint_of(kind: str, rid: str) -> str:
    return f"TRAIN-{rid}-RAW" if kind == "train" else rid


@dataclass
class SourceStats:
    connects: int = 0
    failures: int = 0
    bytes_sent: int = 0
    epochs_sent: int = 0
    epochs_dropped: int = 0
    version: int | None = None
    history: list[str] = field(default_factory=list)


class SourceConnection:
    """One mountpoint's upload: connection, protocol version, backoff; fed epoch by epoch."""

    def __init__(self, host: str, port: int, mount: str, user: str = "", password: str = "",
                 rng_seed: int = 0):
        self.host, self.port, self.mount = host, port, mount
        self.user, self.password = user, password
        self.queue: asyncio.Queue[bytes] = asyncio.Queue(maxsize=QUEUE_EPOCHS)
        self.stats = SourceStats()
        self._writer: asyncio.StreamWriter | None = None
        self._chunked = False
        self._rng = random.Random(rng_seed)
        self.connected = asyncio.Event()
        self._standing = bytearray()  # station and ephemeris frames of dropped epochs, for the next one

    def offer(self, data: bytes) -> None:
        """Hand over one epoch's bytes; dropped when not connected or the link is backed up. A dropped
        epoch's station and ephemeris messages (which do not age) leave with the next epoch that goes: a
        caster that connected late must not wait for the periodic resend to learn the orbits."""
        if not data:
            return
        if not self.connected.is_set():
            self.stats.epochs_dropped += 1
            standing = non_observation_frames(data)
            if standing:
                if len(self._standing) + len(standing) > MAX_STANDING_BYTES:
                    self._standing.clear()  # a long outage: the newest set is the one that matters
                self._standing += standing
            return
        if self._standing:
            data = bytes(self._standing) + data
            self._standing.clear()
        if self.queue.full():
            data = non_observation_frames(self.queue.get_nowait()) + data
            self.stats.epochs_dropped += 1
        self.queue.put_nowait(data)

    def _post_request(self) -> bytes:
        lines = [f"POST /{self.mount} HTTP/1.1", f"Host: {self.host}:{self.port}", "Ntrip-Version: Ntrip/2.0",
                 f"User-Agent: {USER_AGENT}", "Transfer-Encoding: chunked", "Connection: close"]
        if self.user or self.password:
            token = base64.b64encode(f"{self.user}:{self.password}".encode()).decode()
            lines.append(f"Authorization: Basic {token}")
        return ("\r\n".join(lines) + "\r\n\r\n").encode()

    def _source_request(self) -> bytes:
        return (f"SOURCE {self.password} /{self.mount}\r\nSource-Agent: {USER_AGENT}\r\n\r\n").encode()

    async def _handshake(self, version: int):
        reader, writer = await asyncio.wait_for(asyncio.open_connection(self.host, self.port), CONNECT_TIMEOUT_S)
        try:
            writer.write(self._post_request() if version == 2 else self._source_request())
            await writer.drain()
            status = (await asyncio.wait_for(reader.readline(), RESPONSE_TIMEOUT_S)).decode("latin-1").strip()
            if version == 2:
                parts = status.split()
                if len(parts) < 2 or not parts[0].startswith("HTTP/") or not parts[1].isdigit():
                    raise SourceRefused(status or "(connection closed)", fallback=True)
                code = int(parts[1])
                if code // 100 != 2:
                    raise SourceRefused(status, fallback=code not in (401, 403, 409))
                while (await asyncio.wait_for(reader.readline(), RESPONSE_TIMEOUT_S)).strip():
                    pass  # response headers
            else:
                if not status.startswith("ICY 200"):
                    raise SourceRefused(status or "(connection closed)", fallback=False)
        except BaseException:
            writer.close()
            raise
        return reader, writer

    async def run(self, stop: asyncio.Event) -> None:
        backoff = BACKOFF_FIRST_S
        version = 2
        while not stop.is_set():
            try:
                try:
                    reader, writer = await self._handshake(version)
                except SourceRefused as exc:
                    if version == 2 and exc.fallback:
                        self.stats.history.append(f"v2 refused: {exc.status}; trying NTRIP 1")
                        version = 1
                        reader, writer = await self._handshake(version)
                    else:
                        raise
                self.stats.version = version
                self.stats.connects += 1
                self.stats.history.append(f"connected v{version}")
                self._writer, self._chunked = writer, version == 2
                backoff = BACKOFF_FIRST_S
                self.connected.set()
                await self._pump(reader, writer, stop)
            except (OSError, asyncio.TimeoutError, SourceRefused, ConnectionError) as exc:
                self.stats.failures += 1
                self.stats.history.append(f"failed: {exc!r}")
            finally:
                self.connected.clear()
                self._drain_queue()
                if self._writer is not None:
                    self._writer.close()
                    self._writer = None
            if stop.is_set():
                break
            delay = backoff * (0.75 + 0.5 * self._rng.random())
            backoff = min(backoff * 2.0, BACKOFF_MAX_S)
            try:
                await asyncio.wait_for(stop.wait(), delay)
            except asyncio.TimeoutError:
                pass

    def _drain_queue(self) -> None:
        while not self.queue.empty():
            self.queue.get_nowait()
            self.stats.epochs_dropped += 1

    async def _pump(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, stop: asyncio.Event):
        closed = asyncio.ensure_future(reader.read())  # the caster closing on us ends the upload
        try:
            while not stop.is_set():
                get = asyncio.ensure_future(self.queue.get())
                halt = asyncio.ensure_future(stop.wait())
                done, _ = await asyncio.wait({get, closed, halt}, return_when=asyncio.FIRST_COMPLETED)
                halt.cancel()
                if get not in done:
                    get.cancel()
                    if closed in done:
                        raise ConnectionError("caster closed the connection")
                    break
                data = get.result()
                payload = encode_chunk(data) if self._chunked else data
                writer.write(payload)
                await writer.drain()
                self.stats.bytes_sent += len(data)
                self.stats.epochs_sent += 1
            if self._chunked:
                writer.write(LAST_CHUNK)
                await writer.drain()
        finally:
            closed.cancel()


def non_observation_frames(blob: bytes) -> bytes:
    """The frames of an epoch's RTCM that are not observations (MSM 1071-1137): station position,
    descriptors and ephemerides, which stay valid when the epoch itself is too old to send."""
    out = bytearray()
    pos, n = 0, len(blob)
    while pos + FRAME_OVERHEAD_BYTES <= n and blob[pos] == PREAMBLE:
        end = pos + frame_length(blob, pos)
        if end > n:
            break
        msg_type = message_type(blob[pos + HEADER_BYTES : end - CRC_BYTES])
        if not MSM_FIRST_TYPE <= msg_type <= MSM_LAST_TYPE:
            out += blob[pos:end]
        pos = end
    return bytes(out)


def live_scenario(sc: Scenario) -> Scenario:
    """The scenario started at the next whole second of the current GPS time."""
    start = gtime.to_datetime(float(math.ceil(gtime.now_gpst())))
    return sc.model_copy(update=dict(start=start.replace(microsecond=0)))


async def _produce_later(loop, produce, delay_s: float):
    if delay_s > 0:
        await asyncio.sleep(delay_s)
    return await loop.run_in_executor(None, produce)


async def run_stations(sc: Scenario, host: str, port: int, *, user: str = "", password: str = "",
                       speed: float = 1.0, start_now: bool = True, stop: asyncio.Event | None = None,
                       on_ready=None, world: World | None = None, on_block=None) -> dict[str, SourceStats]:
    """Stream the scenario's receivers to the caster until the scenario ends (or `stop` is set).

    `world`: an already built World of the (live) scenario, shared with the caller (which then owns the
    start time); `on_block(blk)`: called with every simulated block before its epochs leave (truth for
    the caller's statistics)."""
    world_given = world is not None
    if world is not None:
        sc = world.scenario
    elif start_now:
        sc = live_scenario(sc)
    stop = stop or asyncio.Event()
    world = world or World(sc)
    streams = RtcmStreams(world)
    streams.keep_epochs = True
    conns = {rx.id: SourceConnection(host, port, mountpoint_of(rx.kind, rx.id), user, password, i)
             for i, rx in enumerate(world.receivers)}
    tasks = [asyncio.ensure_future(c.run(stop)) for c in conns.values()]
    if on_ready is not None:
        on_ready(conns)
    loop = asyncio.get_running_loop()
    # give the connections a moment before the first epoch (they drop data until connected)
    try:
        await asyncio.wait_for(asyncio.gather(*(c.connected.wait() for c in conns.values())), 2.0)
    except asyncio.TimeoutError:
        pass
    # Real time: each epoch leaves at its own GPS time (the scenario started "now", but building the
    # world and connecting took a moment); epochs already more than LATE_EPOCH_S in the past are
    # dropped rather than sent late. Faster than real time: relative to the first epoch.
    on_gps_clock = speed == 1.0 and (start_now or world_given)
    wall0, gps0 = loop.time(), gtime.now_gpst()
    if not on_gps_clock:
        gps0 = world.t0
    carry: collections.defaultdict[str, bytearray] = collections.defaultdict(bytearray)
    # The world simulates the next block (and encodes its RTCM) in a worker thread while the current
    # block's epochs leave: the event loop, which may also carry a caster and a centre, never waits for it.
    blocks = world.epochs(LIVE_BLOCK_EPOCHS)

    def produce():
        nxt = next(blocks, None)
        if nxt is not None:
            streams.add(nxt)
        return nxt

    pending_block = loop.run_in_executor(None, produce)
    try:
        while True:
            blk = await pending_block
            if blk is None:
                break
            pending_block = asyncio.ensure_future(_produce_later(loop, produce, PRODUCE_DELAY_S if on_gps_clock else 0.0))
            if on_block is not None:
                on_block(blk)
            for e, t in enumerate(blk.t_gpst):
                due = wall0 + (float(t) - gps0) / speed
                delay = due - loop.time()
                if on_gps_clock and delay < -LATE_EPOCH_S:
                    # too late: the observations go, the station and ephemeris messages (which do
                    # not age) still leave with the next epoch that is sent
                    for rid, pending in streams.epoch_bytes.items():
                        while pending and pending[0][0] <= float(t) + 1e-6:
                            carry[rid] += non_observation_frames(pending.pop(0)[1])
                            conns[rid].stats.epochs_dropped += 1
                    continue
                if delay > 0:
                    try:
                        await asyncio.wait_for(stop.wait(), delay)
                    except asyncio.TimeoutError:
                        pass
                if stop.is_set():
                    break
                for rid, conn in conns.items():
                    pending = streams.epoch_bytes[rid]
                    while pending and pending[0][0] <= float(t) + 1e-6:
                        conn.offer(bytes(carry.pop(rid, b"")) + pending.pop(0)[1])
            if stop.is_set():
                break
        # let the last epochs leave
        await asyncio.sleep(min(1.0, 1.0 / speed))
    finally:
        stop.set()
        await asyncio.gather(*tasks, return_exceptions=True)
    return {rid: c.stats for rid, c in conns.items()}

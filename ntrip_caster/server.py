"""The asyncio caster: accepts connections, runs the sans-IO core, fans sources out to clients.

Thin by design: protocol decisions live in `connection.py` / `request.py` / `response.py`; this
module owns sockets, time, mountpoints, sessions, limits and statistics.

Fan-out (the hot path): a source's bytes are held back to an RTCM frame boundary
(`RtcmFrameAligner`), then encoded once per protocol version -- the v1 bytes object as received,
one chunk for v2 -- and that same object is handed to every client transport. No per-client copy is
made in Python; a client whose queued output would pass the backlog bound is dropped instead of
being written to, so a slow client never slows the others.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
import os
import socket
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from typing import Any, Callable, Iterable

from augwire.chunked import LAST_CHUNK, encode_chunk
from augwire.errors import NtripProtocolError
from augwire.rtcm_framing import RtcmFrameAligner

from .auth import PUBLIC, Authenticator, User
from .config import CasterConfig, MountConfig
from .connection import (GgaLine, NtripServerConnection, RequestReceived, SourceData,
                         SourceFinished)
from .gga import GgaFix, parse_gga
from .limits import AUTH_BUSY_RETRY_S
from .reposition import RepositionPolicy, choose_base
from .request import NtripRequest
from .response import error_response, json_response, source_ok, sourcetable_response, stream_ok
from .sourcetable import CasRecord, StrRecord, filter_records, render_sourcetable
from .stream_factory import StreamFactory, StreamHandle, StreamRefused, load_factory
from .throttle import AuthThrottle, FloodAlarm

log = logging.getLogger("ntrip_caster")

# How often the housekeeping task looks for idle sources and writes the stats file (seconds).
HOUSEKEEPING_INTERVAL_S = 0.5
# Listen backlog: 10,000 trains reconnecting after a caster restart arrive within a second or two;
# Linux caps this at net.core.somaxconn (4096 on current kernels).
LISTEN_BACKLOG = 4096
# Path of the statistics document (`GET /_stats`, admin group only; `?clients=0` leaves out the
# per-client list). A leading underscore cannot clash with a station name in practice; the
# configuration refuses a mountpoint of that name.
STATS_PATH = "_stats"
# The alarm raised through `Caster.on_alarm` when failed or refused authentications pass the threshold.
AUTH_FLOOD_ALARM = "ntrip-auth-flood"


class SourceSession:
    __slots__ = ("proto", "user", "agent", "version", "connected_since", "last_data_at",
                 "bytes_in", "str_record")

    def __init__(self, proto: "CasterProtocol", req: NtripRequest, user: str | None) -> None:
        self.proto = proto
        self.user = user
        self.agent = req.user_agent
        self.version = req.version
        self.connected_since = time.time()
        self.last_data_at = time.monotonic()
        self.bytes_in = 0
        self.str_record = req.str_record


class ClientSession:
    """One connected client. `send` is the sink VRS factories write to."""

    __slots__ = ("id", "proto", "transport", "ip", "user", "mount", "version", "connected_since",
                 "bytes_out", "gga_count", "last_gga_at", "last_fix", "gga_parsed_at", "policy",
                 "handle", "base", "closed", "caster")

    def __init__(self, caster: "Caster", proto: "CasterProtocol", mount: "Mountpoint",
                 version: int, user: str | None) -> None:
        self.id = next(caster._ids)
        self.caster = caster
        self.proto = proto
        self.transport = proto.transport
        self.ip = proto.peer_ip
        self.user = user
        self.mount = mount
        self.version = version
        self.connected_since = time.time()
        self.bytes_out = 0
        self.gga_count = 0
        self.last_gga_at: float | None = None
        self.last_fix: GgaFix | None = None
        self.gga_parsed_at = -1e18
        lim = caster.limits
        self.policy = RepositionPolicy(lim.reposition_min_interval_s, lim.reposition_max_interval_s,
                                       lim.reposition_min_move_m)
        self.handle: StreamHandle | None = None
        self.base: Mountpoint | None = None  # the source mountpoint this client is subscribed to
        self.closed = False

    def send(self, data: bytes) -> None:
        """Queue stream bytes for this client (VRS sink). Drops the client past the backlog bound."""
        if self.closed or not data:
            return
        payload = data if self.version == 1 else encode_chunk(data)
        t = self.transport
        queued = t.get_write_buffer_size()
        if queued and queued + len(payload) > self.caster.limits.max_client_backlog_bytes:
            self.caster.drop_client(self, "backlog")
            return
        t.write(payload)
        self.bytes_out += len(payload)
        self.mount.bytes_out += len(payload)  # a VRS mountpoint's streams are written here, not by publish

    def stats(self) -> dict[str, Any]:
        fix = self.last_fix
        return {
            "id": self.id, "ip": self.ip, "user": self.user, "mount": self.mount.name,
            "version": self.version, "connected_since": self.connected_since,
            "bytes_out": self.bytes_out, "gga_count": self.gga_count, "last_gga_at": self.last_gga_at,
            "last_position": None if fix is None else [fix.lat_deg, fix.lon_deg, fix.height_m],
            "base": None if self.base is None else self.base.name,
            "waiting_for_position": self.mount.kind != "source" and fix is None,
            "backlog_bytes": self.transport.get_write_buffer_size() if not self.closed else 0,
        }


class Mountpoint:
    __slots__ = ("name", "kind", "cfg", "v1", "v2", "source", "aligner", "factory", "bytes_in",
                 "frames_in", "bytes_out", "clients_total", "drops", "source_sessions",
                 "created_at", "caster", "record", "auto", "fanout_last_ms", "fanout_max_ms",
                 "n_clients", "taps", "enabled")

    def __init__(self, caster: "Caster", cfg: MountConfig, factory: StreamFactory | None = None) -> None:
        self.caster = caster
        self.name = cfg.name
        self.kind = cfg.kind
        self.cfg = cfg
        self.record = cfg.str_record()
        self.v1: dict[int, ClientSession] = {}
        self.v2: dict[int, ClientSession] = {}
        self.source: SourceSession | None = None
        self.aligner = RtcmFrameAligner()
        self.factory = factory
        self.bytes_in = 0
        self.frames_in = 0
        self.bytes_out = 0
        self.clients_total = 0
        self.drops: Counter[str] = Counter()
        self.source_sessions = 0
        self.created_at = time.time()
        self.auto = False  # created by a source for a name not in the config
        self.fanout_last_ms = 0.0  # time one publish took to hand a piece to every client
        self.fanout_max_ms = 0.0
        self.n_clients = 0  # clients connected to this mountpoint (for nearest: not per base)
        self.taps: list[Callable[[bytes], None]] = []  # in-process readers (centre, relay factory)
        self.enabled = cfg.enabled

    def reconfigure(self, cfg: MountConfig) -> None:
        """Take a new configuration of the same kind (groups, STR fields, enabled flag)."""
        self.cfg = cfg
        self.record = cfg.str_record()
        self.enabled = cfg.enabled

    @property
    def live(self) -> bool:
        """Can a client be served now (sourcetable lists it, clients are accepted)? A disabled mountpoint
        is not, though its source may keep publishing (in-process taps such as the centre still read it)."""
        return self.enabled and (self.kind != "source" or self.source is not None)

    def subscribe(self, s: ClientSession) -> None:
        (self.v1 if s.version == 1 else self.v2)[s.id] = s

    def unsubscribe(self, s: ClientSession) -> None:
        (self.v1 if s.version == 1 else self.v2).pop(s.id, None)

    def publish(self, data: bytes) -> None:
        """Write one piece of the stream to every subscriber: encoded once per version."""
        t0 = time.perf_counter()
        limit = self.caster.limits.max_client_backlog_bytes
        dropped: list[ClientSession] = []
        out = 0
        for clients, payload in ((self.v1, data), (self.v2, encode_chunk(data) if self.v2 else b"")):
            if not clients:
                continue
            n = len(payload)
            room = limit - n
            for s in clients.values():
                t = s.transport
                # An empty queue always takes the piece (one publish may exceed the bound on its
                # own); otherwise queued + piece must stay within the bound.
                queued = t.get_write_buffer_size()
                if queued and queued > room:
                    dropped.append(s)
                else:
                    t.write(payload)
                    s.bytes_out += n
                    out += n
        self.bytes_out += out
        for s in dropped:
            self.caster.drop_client(s, "backlog")
        for tap in self.taps:
            try:
                tap(data)
            except Exception:  # an in-process reader's bug must not stop the stream
                log.exception("tap on %s failed", self.name)
        ms = (time.perf_counter() - t0) * 1e3
        self.fanout_last_ms = ms
        if ms > self.fanout_max_ms:
            self.fanout_max_ms = ms

    def stats(self) -> dict[str, Any]:
        src = self.source
        return {
            "name": self.name, "kind": self.kind, "live": self.live, "enabled": self.enabled,
            "clients": self.n_clients, "subscribers": len(self.v1) + len(self.v2),
            "clients_total": self.clients_total, "bytes_in": self.bytes_in,
            "frames_in": self.frames_in, "bytes_out": self.bytes_out, "drops": dict(self.drops),
            "source": None if src is None else {
                "user": src.user, "agent": src.agent, "version": src.version,
                "connected_since": src.connected_since, "bytes_in": src.bytes_in},
            "source_sessions": self.source_sessions,
            "fanout_last_ms": round(self.fanout_last_ms, 3), "fanout_max_ms": round(self.fanout_max_ms, 3),
            # GGA-driven mountpoints: connected, kept, but nothing to send until a position arrives
            "waiting_for_position": 0 if self.kind == "source" else sum(
                1 for c in self.caster.clients.values() if c.mount is self and c.last_fix is None),
        }


class CasterProtocol(asyncio.Protocol):
    """One TCP connection: feeds the sans-IO core and routes its events to the caster."""

    __slots__ = ("caster", "transport", "conn", "peer_ip", "client", "mount", "head_timer",
                 "pending", "closed", "upload_window", "upload_bytes", "pending_slot")

    def __init__(self, caster: "Caster") -> None:
        self.caster = caster
        self.transport: asyncio.Transport = None  # type: ignore[assignment]
        self.conn = NtripServerConnection(caster.limits.max_request_head_bytes,
                                          caster.limits.max_source_chunk_bytes)
        self.peer_ip = "?"
        self.client: ClientSession | None = None
        self.mount: Mountpoint | None = None  # set for an accepted source
        self.head_timer: asyncio.TimerHandle | None = None
        self.pending: list | None = None  # events held while credentials are checked
        self.closed = False
        self.upload_window = 0.0
        self.upload_bytes = 0
        self.pending_slot = False  # counted in caster.pending_per_ip (not yet a client or a source)

    # --- asyncio callbacks ---------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]
        peer = transport.get_extra_info("peername")
        self.peer_ip = peer[0] if peer else "?"
        sock = transport.get_extra_info("socket")
        if sock is not None:
            try:
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            except (OSError, AttributeError):  # uvloop's pseudo-socket; uvloop sets NODELAY itself
                pass
        self.caster._conns.add(self)
        pending = self.caster.pending_per_ip
        limit = self.caster.limits.max_pending_per_ip
        if limit and pending[self.peer_ip] >= limit:  # no request read yet: answer in HTTP/1.0, as v1 does
            self.caster.counters["refused_pending_per_ip"] += 1
            self.transport.write(error_response(1, 503, "too many connections from this address",
                                                retry_after=self.caster.limits.request_head_timeout_s))
            self.close()
            return
        pending[self.peer_ip] += 1
        self.pending_slot = True
        self.head_timer = self.caster.loop.call_later(
            self.caster.limits.request_head_timeout_s, self._head_timeout)

    def data_received(self, data: bytes) -> None:
        if self.closed:
            return
        if self.client is not None:  # upstream bytes from a client: GGA only, bounded rate
            now = time.monotonic()
            if now - self.upload_window >= 1.0:
                self.upload_window, self.upload_bytes = now, 0
            self.upload_bytes += len(data)
            if self.upload_bytes > self.caster.limits.max_client_upload_bytes_per_s:
                self.caster.drop_client(self.client, "upload_flood")
                return
        try:
            events = self.conn.receive_data(data)
        except NtripProtocolError as exc:
            self.reject(exc.status, exc.reason)
            return
        if self.pending is not None:
            self.pending.extend(events)
            return
        self._handle_safely(events)

    def _handle_safely(self, events: list) -> None:
        try:
            self.handle_events(events)
        except Exception:  # a bug must cost one connection, never the caster
            log.exception("internal error on a connection from %s; closing it", self.peer_ip)
            self.caster.counters["internal_errors"] += 1
            if self.client is not None:
                self.caster.remove_client(self.client)
            self.close()

    def connection_lost(self, exc: Exception | None) -> None:
        self.closed = True
        if self.head_timer is not None:
            self.head_timer.cancel()
        self.caster._conns.discard(self)
        self.release_pending()
        if self.client is not None:
            self.caster.remove_client(self.client)
        if self.mount is not None:
            self.caster.remove_source(self.mount, self)

    # --- routing -------------------------------------------------------------------------------
    def handle_events(self, events: list) -> None:
        for i, ev in enumerate(events):
            if self.closed:
                return
            kind = type(ev)
            if kind is SourceData:
                if self.mount is not None:
                    self.caster.on_source_data(self.mount, ev.data)
            elif kind is GgaLine:
                if self.client is not None:
                    self.caster.on_gga(self.client, ev.line)
            elif kind is RequestReceived:
                if self.head_timer is not None:
                    self.head_timer.cancel()
                    self.head_timer = None
                waiting = self.caster.on_request(self, ev.request)
                if waiting is not None:  # credentials being checked off the loop
                    self.pending = list(events[i + 1:])
                    self.transport.pause_reading()
                    waiting.add_done_callback(self._resume)
                    return
            elif kind is SourceFinished:
                self.close()

    def _resume(self, _fut: object) -> None:
        pending, self.pending = self.pending or [], None
        if self.closed:
            return
        self.transport.resume_reading()
        self._handle_safely(pending)

    def _head_timeout(self) -> None:
        self.head_timer = None
        if self.conn.state == "HEAD" and not self.closed:
            self.caster.counters["head_timeouts"] += 1
            self.reject(408, "request head not received in time")

    def release_pending(self) -> None:
        if self.pending_slot:
            self.pending_slot = False
            pending = self.caster.pending_per_ip
            pending[self.peer_ip] -= 1
            if pending[self.peer_ip] <= 0:
                del pending[self.peer_ip]

    def reject(self, status: int, reason: str, retry_after: int | None = None) -> None:
        """Answer an error in the peer's dialect and close."""
        req = self.conn.request
        version = req.version if req is not None else 1
        source_v1 = req is not None and req.kind == "source" and req.version == 1
        self.caster.counters[f"status_{status}"] += 1
        if not self.closed:
            self.transport.write(error_response(version, status, reason, realm=self.caster.config.realm,
                                                source_v1=source_v1, retry_after=retry_after))
        self.close()

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.conn.close()
            self.transport.close()


class Caster:
    """The NTRIP caster. `await start()`, then `await stop()`; `snapshot()` for statistics."""

    def __init__(self, config: CasterConfig, factories: dict[str, StreamFactory] | None = None) -> None:
        self.config = config
        self.limits = config.limits
        self.auth = Authenticator(config.users)
        self.mounts: dict[str, Mountpoint] = {}
        self.clients: dict[int, ClientSession] = {}
        self.per_ip: Counter[str] = Counter()
        self.counters: Counter[str] = Counter()
        self._ids = itertools.count(1)
        self._conns: set[CasterProtocol] = set()
        self._server: asyncio.AbstractServer | None = None
        self._housekeeping: asyncio.Task | None = None
        self.loop: asyncio.AbstractEventLoop = None  # type: ignore[assignment]
        self.started_at = 0.0
        self.port = config.port
        self.pending_per_ip: Counter[str] = Counter()
        # Password verification: a pool of its own (never the loop's default executor), a bounded queue,
        # identical credentials verified once, failures throttled per address and name (issue 19).
        self.auth_pool = ThreadPoolExecutor(max(1, self.limits.auth_workers), thread_name_prefix="ntrip-auth")
        self.auth_queued = 0  # verifications submitted and not finished
        self._verifying: dict[bytes, asyncio.Future] = {}
        self.throttle = AuthThrottle()
        self.flood_alarm = FloodAlarm()
        self.clock: Callable[[], float] = time.monotonic  # the throttle's clock; tests step it
        # on_alarm(kind, subject, severity, message, cleared): `augnet up` passes its alarm path.
        self.on_alarm: Callable[[str, str, str, str, bool], None] | None = None
        factories = dict(factories or {})
        self._factories = factories  # kept: a VRS mountpoint added at run time takes its factory from here
        for m in config.mounts:
            factory = None
            if m.kind == "vrs":
                factory = factories.get(m.name) or load_factory(m.factory or "")
            self.mounts[m.name] = Mountpoint(self, m, factory)
        for mp in list(self.mounts.values()):  # after every mountpoint exists
            attach = getattr(mp.factory, "attach", None)
            if callable(attach):  # factories that read other mountpoints get the caster
                attach(self)

    # --- life cycle ------------------------------------------------------------------------------
    async def start(self) -> int:
        """Bind and listen; returns the port (useful with port 0)."""
        self.loop = asyncio.get_running_loop()
        self._server = await self.loop.create_server(
            lambda: CasterProtocol(self), self.config.host, self.config.port,
            backlog=LISTEN_BACKLOG, reuse_address=True)
        self.port = self._server.sockets[0].getsockname()[1]
        self.started_at = time.time()
        self._housekeeping = asyncio.create_task(self._housekeep())
        log.info("caster listening on %s:%d", self.config.host, self.port)
        return self.port

    async def serve_forever(self) -> None:
        assert self._server is not None
        try:
            await self._server.serve_forever()
        except asyncio.CancelledError:
            pass

    async def stop(self) -> None:
        """Graceful shutdown: stop accepting, end every stream cleanly, let queued output drain
        (at most shutdown_drain_s), then abort what is left."""
        if self._server is not None:
            self._server.close()
        if self._housekeeping is not None:
            self._housekeeping.cancel()
        for s in list(self.clients.values()):
            if s.version == 2 and not s.closed:
                s.transport.write(LAST_CHUNK)
            self.remove_client(s)
            s.proto.close()
        for p in list(self._conns):
            p.close()
        deadline = time.monotonic() + self.limits.shutdown_drain_s
        while self._conns and time.monotonic() < deadline:
            await asyncio.sleep(0.02)
        for p in list(self._conns):
            p.transport.abort()
        if self._server is not None:
            await self._server.wait_closed()
        self.auth_pool.shutdown(wait=False, cancel_futures=True)
        if self.config.stats_path:
            self._write_stats()

    async def _housekeep(self) -> None:
        next_stats = 0.0
        while True:
            await asyncio.sleep(HOUSEKEEPING_INTERVAL_S)
            now = time.monotonic()
            if self.flood_alarm.tick(self.clock()):
                self._raise_alarm(True)
            for m in self.mounts.values():
                src = m.source
                if src is not None and now - src.last_data_at > self.limits.source_idle_timeout_s:
                    m.drops["source_idle"] += 1
                    log.info("source of %s idle for %.0f s: dropped", m.name,
                             self.limits.source_idle_timeout_s)
                    src.proto.close()
                    self.remove_source(m, src.proto)
            if self.config.stats_path and now >= next_stats:
                next_stats = now + self.config.stats_interval_s
                self._write_stats()

    def _write_stats(self) -> None:
        path = self.config.stats_path
        assert path
        tmp = f"{path}.tmp"
        try:
            with open(tmp, "w") as fh:
                json.dump(self.snapshot(), fh)
            os.replace(tmp, path)
        except OSError as exc:
            log.warning("cannot write stats to %s: %s", path, exc)

    # --- requests --------------------------------------------------------------------------------
    def on_request(self, proto: CasterProtocol, req: NtripRequest) -> asyncio.Future | None:
        """Decide a request. Returns a future when credentials must be checked first."""
        if req.kind == "source":
            return self._source_request(proto, req)
        return self._client_request(proto, req)

    def _authenticate(self, req: NtripRequest, groups: frozenset[str],
                      then: Callable[[str | None], None], *, source_password: bool = False,
                      proto: CasterProtocol | None = None) -> asyncio.Future | None:
        """Call `then(user or None)`; synchronously when the answer is cheap, else after scrypt
        ran on the verification pool (returns that future). A throttled or busy attempt is answered
        429 / 503 on `proto` here and `then` is not called."""
        if PUBLIC in groups:
            # No check needed to read; name the user only if these credentials were verified
            # before (an unverified name must not appear in the statistics).
            then(self.auth.cached_user(req.user, req.password))
            return None
        if not source_password and req.user is None:
            then(None)  # no credentials: 401 without any hash
            return None
        assert proto is not None
        address = proto.peer_ip
        name = f"\0source/{req.mount}" if source_password else (req.user or "")
        now = self.clock()
        key = None if source_password else self.auth.credential_key(req.user or "", req.password or "")
        running = self._verifying.get(key) if key is not None else None  # same credentials being verified
        revision = self.auth.revision  # a revocation while scrypt runs voids the answer (below)
        wait = self.throttle.admit(address, name, now, shared=running is not None)
        if wait:
            self.counters["auth_refused_throttled"] += 1
            self._note_bad_auth(now)
            proto.reject(429, "too many failed attempts", retry_after=wait)
            return None
        if not source_password:
            cached = self.auth.cached_user(req.user, req.password)
            if cached is not None:
                self.throttle.succeeded(address, name, now)
                then(cached)
                return None
            fut = running
            if fut is None:
                fut = self._verify(key, self.auth.check, req.user, req.password)
            else:
                self.counters["auth_coalesced"] += 1
        else:
            fut = self._verify(None, self.auth.check_source_password, req.password or "", groups)
        if fut is None:  # pool full
            self.throttle.abandon(address, name)
            self.counters["auth_refused_busy"] += 1
            self._note_bad_auth(now)
            proto.reject(503, "authentication busy", retry_after=AUTH_BUSY_RETRY_S)
            return None

        def done(f: asyncio.Future) -> None:
            ok = not f.cancelled() and f.exception() is None
            user = f.result() if ok else None
            if user is not None and self.auth.revision != revision \
                    and self.auth.cached_user(user, req.password) != user:
                user = None  # verified against credentials revoked meanwhile
            t = self.clock()
            if not ok:
                self.throttle.abandon(address, name)
            elif user is None:
                self.throttle.failed(address, name, t)
                self.counters["auth_failed"] += 1
                self._note_bad_auth(t)
            else:
                self.throttle.succeeded(address, name, t)
                self.counters["auth_succeeded"] += 1
            then(user)

        fut.add_done_callback(done)
        return fut

    def _verify(self, key: bytes | None, fn: Callable[..., str | None], *args: Any) -> asyncio.Future | None:
        """Run `fn(*args)` on the verification pool, or None when its queue is full."""
        if self.auth_queued >= self.limits.auth_queue_max:
            return None
        self.auth_queued += 1
        fut = asyncio.wrap_future(self.auth_pool.submit(fn, *args), loop=self.loop)

        def finished(_f: asyncio.Future) -> None:
            self.auth_queued -= 1
            if key is not None:
                self._verifying.pop(key, None)

        fut.add_done_callback(finished)
        if key is not None:
            self._verifying[key] = fut
        return fut

    def _note_bad_auth(self, now: float) -> None:
        if self.flood_alarm.note(now):
            self._raise_alarm(False)

    def _raise_alarm(self, cleared: bool) -> None:
        c = self.counters
        msg = (f"{self.flood_alarm.threshold}+ failed or refused NTRIP logins in "
               f"{self.flood_alarm.window_s:.0f} s (failed {c['auth_failed']}, throttled "
               f"{c['auth_refused_throttled']}, busy {c['auth_refused_busy']})")
        (log.info if cleared else log.warning)("%s %s", "cleared:" if cleared else "alarm:", msg)
        if self.on_alarm is not None:
            try:
                self.on_alarm(AUTH_FLOOD_ALARM, "caster", "warning", msg, cleared)
            except Exception:  # the alarm path's bug must not cost the request
                log.exception("caster alarm callback failed")

    def sourcetable(self, query: str = "") -> bytes:
        records: list = [CasRecord(self.config.host, self.port, self.config.identifier,
                                   self.config.operator, 0, self.config.country)]
        for m in self.mounts.values():
            if m.live:
                rec = m.record
                if m.auto and m.source is not None and m.source.str_record:
                    try:  # an unconfigured source described itself: use its STR, our name
                        rec = replace(StrRecord.from_line(m.source.str_record), mountpoint=m.name)
                    except ValueError:
                        pass
                records.append(rec)
        if query:
            records = filter_records(records, query)
        return render_sourcetable(records)

    def _client_request(self, proto: CasterProtocol, req: NtripRequest) -> asyncio.Future | None:
        if req.mount == STATS_PATH and self.config.admin_group:
            return self._stats_request(proto, req)
        mount = self.mounts.get(req.mount) if req.valid_mount else None
        if mount is None or not mount.live:
            if req.mount and req.version == 2:
                self.counters["status_404"] += 1
                proto.transport.write(error_response(2, 404, f"no mountpoint {req.mount}"))
                proto.close()
                return None
            self.counters["sourcetables"] += 1
            proto.transport.write(sourcetable_response(req.version, self.sourcetable(req.query)))
            proto.close()
            return None

        def decided(user: str | None) -> None:
            if proto.closed:
                return
            if not self.auth.allowed(user, mount.cfg.read):
                proto.reject(401, "credentials required" if req.user is None else "bad credentials")
                return
            if not mount.enabled:  # disabled while the credentials were checked
                proto.reject(404, f"no mountpoint {mount.name}")
                return
            self._admit_client(proto, req, mount, user)

        return self._authenticate(req, mount.cfg.read, decided, proto=proto)

    def _stats_request(self, proto: CasterProtocol, req: NtripRequest) -> asyncio.Future | None:
        """`GET /_stats` by a user of the admin group: the statistics snapshot as JSON."""
        group = frozenset({self.config.admin_group})

        def decided(user: str | None) -> None:
            if proto.closed:
                return
            if user is None or not self.auth.allowed(user, group):
                proto.reject(401, "statistics need an admin user")
                return
            body = json.dumps(self.snapshot(clients="clients=0" not in req.query)).encode()
            self.counters["stats_requests"] += 1
            proto.transport.write(json_response(body))
            proto.close()

        return self._authenticate(req, group, decided, proto=proto)

    def _admit_client(self, proto: CasterProtocol, req: NtripRequest, mount: Mountpoint,
                      user: str | None) -> None:
        lim = self.limits
        mount_clients = mount.n_clients
        if len(self.clients) >= lim.max_clients:
            proto.reject(503, "caster full")
            return
        if mount_clients >= lim.max_clients_per_mount:
            proto.reject(503, f"mountpoint {mount.name} full")
            return
        if lim.max_clients_per_ip and self.per_ip[proto.peer_ip] >= lim.max_clients_per_ip:
            proto.reject(503, "too many connections from this address")
            return
        s = ClientSession(self, proto, mount, req.version, user)
        proto.client = s
        proto.release_pending()
        if lim.client_send_buffer_bytes:
            sock = proto.transport.get_extra_info("socket")
            if sock is not None:
                try:
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, lim.client_send_buffer_bytes)
                except (OSError, AttributeError):
                    pass
        self.clients[s.id] = s
        self.per_ip[s.ip] += 1
        mount.clients_total += 1
        mount.n_clients += 1
        proto.transport.write(stream_ok(req.version))
        if mount.kind == "source":
            mount.subscribe(s)
            s.base = mount
        elif req.gga is not None:
            self._apply_fix(s, req.gga)
        else:
            log.debug("client %d on %s kept connected, waiting for its first GGA", s.id, mount.name)

    def _source_request(self, proto: CasterProtocol, req: NtripRequest) -> asyncio.Future | None:
        mount = self.mounts.get(req.mount) if req.valid_mount else None
        if mount is None and req.valid_mount and self.config.allow_unknown_sources \
                and req.mount != STATS_PATH:
            if sum(1 for m in self.mounts.values() if m.auto) >= self.limits.max_auto_mounts:
                proto.reject(503, "no more mountpoints can be created")
                return None
            mount = Mountpoint(self, MountConfig(req.mount, "source", write=frozenset({PUBLIC})))
            mount.auto = True
            self.mounts[req.mount] = mount
        if mount is None or mount.kind != "source":
            proto.reject(404, f"no source mountpoint {req.mount}")
            return None
        if mount.source is not None:
            proto.reject(409, f"mountpoint {mount.name} already has a source")
            return None

        def decided(user: str | None) -> None:
            if proto.closed:
                return
            if PUBLIC not in mount.cfg.write and (user is None or not (
                    self.auth.users[user].groups & mount.cfg.write)):
                proto.reject(401, "bad source credentials")
                return
            if mount.source is not None:  # another source won the race while we checked
                proto.reject(409, f"mountpoint {mount.name} already has a source")
                return
            mount.source = SourceSession(proto, req, user)
            mount.source_sessions += 1
            mount.aligner = RtcmFrameAligner()
            proto.mount = mount
            proto.release_pending()
            proto.transport.write(source_ok(req.version))
            log.info("source on %s from %s (%s)", mount.name, proto.peer_ip, req.user_agent)

        v1_password = req.version == 1 and req.user is None
        return self._authenticate(req, mount.cfg.write, decided, source_password=v1_password, proto=proto)

    # --- streams ---------------------------------------------------------------------------------
    def on_source_data(self, mount: Mountpoint, data: bytes) -> None:
        src = mount.source
        if src is None:
            return
        src.last_data_at = time.monotonic()
        src.bytes_in += len(data)
        mount.bytes_in += len(data)
        before = mount.aligner.frames
        out = mount.aligner.feed(data)
        mount.frames_in += mount.aligner.frames - before
        if out:
            mount.publish(out)

    def remove_source(self, mount: Mountpoint, proto: CasterProtocol) -> None:
        if mount.source is None or mount.source.proto is not proto:
            return
        rest = mount.aligner.flush()
        if rest:  # keep the stream byte-identical: the partial frame goes out as received
            mount.publish(rest)
        mount.source = None
        proto.mount = None
        log.info("source of %s gone", mount.name)
        if mount.auto and not (mount.v1 or mount.v2 or mount.taps) and mount.n_clients == 0:
            del self.mounts[mount.name]  # created by its source, forgotten with it

    def on_gga(self, s: ClientSession, line: bytes) -> None:
        now = time.monotonic()
        if now - s.gga_parsed_at < self.limits.gga_min_interval_s:
            self.counters["gga_rate_limited"] += 1
            return
        fix = parse_gga(line)
        if fix is None:
            self.counters["gga_unusable"] += 1
            return
        s.gga_parsed_at = now
        self._apply_fix(s, fix)

    def _apply_fix(self, s: ClientSession, fix: GgaFix) -> None:
        now = time.monotonic()
        s.gga_count += 1
        s.last_gga_at = time.time()
        s.last_fix = fix
        mount = s.mount
        if mount.kind == "source" or not s.policy.due(now, fix):
            return
        s.policy.applied(now, fix)
        if mount.kind == "vrs":
            assert mount.factory is not None
            try:
                if s.handle is None:
                    s.handle = mount.factory.open(f"{mount.name}/{s.id}", mount.name, fix, s.send)
                else:
                    s.handle.update_position(fix)
            except StreamRefused as refused:  # the factory's answer (outside its service area, say)
                log.info("client %d on %s refused: %s", s.id, mount.name, refused.reason)
                self.refuse_client(s, refused.data)
            except Exception:  # a factory bug must not take the caster down
                log.exception("stream factory failed for client %d on %s", s.id, mount.name)
                mount.drops["factory_error"] += 1
                self.drop_client(s, "factory_error")
        else:  # nearest base
            bases = {name: (m.record.latitude, m.record.longitude) for name, m in self.mounts.items()
                     if m.kind == "source" and m.source is not None and m.enabled
                     and (not mount.cfg.bases or name in mount.cfg.bases)}
            current = s.base.name if s.base is not None else None
            chosen = choose_base(fix, bases, current, self.limits.base_switch_hysteresis_m)
            if chosen != current and chosen is not None:
                if s.base is not None:
                    s.base.unsubscribe(s)
                s.base = self.mounts[chosen]
                s.base.subscribe(s)

    def drop_client(self, s: ClientSession, reason: str) -> None:
        if s.closed:
            return
        s.mount.drops[reason] += 1
        self.counters[f"drop_{reason}"] += 1
        self.remove_client(s)
        s.proto.closed = True
        s.transport.abort()  # its backlog is useless; free it now

    def refuse_client(self, s: ClientSession, data: bytes) -> None:
        """End a client's stream cleanly after `data` (the factory's reason, as stream bytes)."""
        if s.closed:
            return
        s.handle = None  # the factory has already let it go
        s.send(data)
        if s.version == 2 and not s.closed:
            s.transport.write(LAST_CHUNK)
        s.mount.drops["refused"] += 1
        self.counters["drop_refused"] += 1
        self.remove_client(s)
        s.proto.close()

    def end_client(self, s: ClientSession, reason: str) -> None:
        """End a client's stream cleanly (v2: the last chunk) and close: an operator's decision."""
        if s.closed:
            return
        if s.version == 2:
            s.transport.write(LAST_CHUNK)
        s.mount.drops[reason] += 1
        self.counters[f"drop_{reason}"] += 1
        self.remove_client(s)
        s.proto.close()

    # --- the operator's word, applied while running (decision 0180) --------------------------------
    def set_users(self, users: dict[str, User]) -> set[str]:
        """Take the whole user table (disabled users left out). Sessions of a user removed, re-passworded
        or no longer in a group the mountpoint needs are closed. Returns the names revoked."""
        revoked = self.auth.replace_users(users)
        self._enforce_access(revoked)
        return revoked

    def set_mounts(self, mounts: Iterable[MountConfig]) -> None:
        """Take the whole mountpoint table: known names are reconfigured, new ones created (a VRS one only
        with a factory given at construction), configured ones missing from the table disabled (mountpoints
        created by their own source are left alone). Readers of a disabled mountpoint are closed."""
        table = {m.name: m for m in mounts}
        for name, m in list(self.mounts.items()):
            if m.auto:
                continue
            cfg = table.pop(name, None)
            if cfg is None:
                cfg = replace(m.cfg, enabled=False)
            elif cfg.kind != m.kind:  # a live mountpoint does not change its nature: logged, left as it is
                log.warning("mountpoint %s: kind %s -> %s needs a restart; kept as %s", name, m.kind, cfg.kind, m.kind)
                cfg = replace(cfg, kind=m.kind)
            m.reconfigure(cfg)
        for name, cfg in table.items():
            if name == STATS_PATH:
                continue
            factory = None
            if cfg.kind == "vrs":
                factory = self._factories.get(name)
                if factory is None:
                    log.warning("mountpoint %s: no VRS stream factory of that name here; not created", name)
                    continue
            existing = self.mounts.get(name)
            if existing is not None and existing.auto:  # configured now: its source keeps its place
                existing.auto = False
                existing.reconfigure(cfg)
                continue
            self.mounts[name] = mp = Mountpoint(self, cfg, factory)
            attach = getattr(factory, "attach", None)
            if callable(attach):
                attach(self)
            log.info("mountpoint %s (%s) added", name, cfg.kind)
        self._enforce_access(set())

    def _enforce_access(self, revoked: set[str]) -> None:
        """Close what the current tables no longer allow: readers of disabled mountpoints, readers and
        sources whose user was revoked or left the groups a mountpoint needs."""
        auth = self.auth
        for s in list(self.clients.values()):
            read = s.mount.cfg.read
            if not s.mount.enabled:
                self.end_client(s, "mount_disabled")
            elif PUBLIC not in read and (s.user in revoked or not auth.allowed(s.user, read)):
                self.end_client(s, "revoked")
        for m in self.mounts.values():
            src = m.source
            if src is None or PUBLIC in m.cfg.write:
                continue
            record = auth.users.get(src.user) if src.user is not None else None
            if src.user in revoked or record is None or not (record.groups & m.cfg.write):
                m.drops["source_revoked"] += 1
                self.counters["drop_source_revoked"] += 1
                log.info("source of %s closed: user %s revoked", m.name, src.user)
                proto = src.proto
                proto.close()
                self.remove_source(m, proto)

    def remove_client(self, s: ClientSession) -> None:
        if s.closed:
            return
        s.closed = True
        s.mount.n_clients -= 1
        self.clients.pop(s.id, None)
        self.per_ip[s.ip] -= 1
        if self.per_ip[s.ip] <= 0:
            del self.per_ip[s.ip]
        if s.base is not None:
            s.base.unsubscribe(s)
        if s.handle is not None:
            try:
                s.handle.close()
            except Exception:
                log.exception("stream handle close failed for client %d", s.id)
            s.handle = None

    def tap(self, mount: str, callback: Callable[[bytes], None]) -> Callable[[], None]:
        """Call `callback(data)` (on the loop) with every piece of `mount`'s stream, frame-aligned,
        as clients get it. Returns a function that removes the tap. In-process readers (the
        centre's station ingest, relay factories) use this instead of an NTRIP connection."""
        m = self.mounts.get(mount)
        if m is None or m.kind != "source":
            raise ValueError(f"cannot tap {mount!r}: no source mountpoint of that name")
        m.taps.append(callback)

        def untap() -> None:
            if callback in m.taps:
                m.taps.remove(callback)

        return untap

    # --- statistics --------------------------------------------------------------------------------
    def snapshot(self, *, clients: bool = True) -> dict[str, Any]:
        """Statistics for the console: per mountpoint, per client, and caster-wide counters."""
        return {
            "started_at": self.started_at, "now": time.time(), "port": self.port,
            "clients_now": len(self.clients), "connections_now": len(self._conns),
            "counters": dict(self.counters), "auth_checks": self.auth.checks,
            "auth_queued": self.auth_queued, "auth_alarm": self.flood_alarm.raised,
            "mounts": {name: m.stats() for name, m in self.mounts.items()},
            "clients": [s.stats() for s in self.clients.values()] if clients else [],
        }

"""The control centre as a service inside `augnet up`: the sans-IO `CentreEngine` in its own process.

Why a process: one network epoch (VRS synthesis and encoding for every connected train, then the network
solve) is tens to hundreds of ms of Python and numpy. In a thread of the `augnet up` process it shared the
GIL with the event loop carrying the caster's thousands of sockets, the simulated stations, the console,
the RSSP-I link and the onboard trains: each waited for the other, and the correction age's tail grew with
it. In its own process the engine has a core to itself while the loop writes the previous epoch's bytes.

The loop side (`CentreService`, the caster's VRS stream factory) keeps only: station bytes from the caster's
taps (minus the stations an operator disabled), VRS sessions opened / moved / closed by the caster, and the
per-client bytes the centre returns, written to the caster's sinks. Everything else (decoding, epoch
alignment, network solve, VRS synthesis and RTCM encoding) runs in the child, `_CentreWorker`.

The two processes speak the typed messages of `augnet.system.centre_protocol` (its docstring is the
specification: frames, field encodings, what each message means and when it is sent) over one Unix socket
pair. A frame the loop cannot read is counted (`protocol_errors`), logged, and the centre process killed
and handled as one that died; a frame the centre cannot read is reported to the loop (`CentreError`) and
the centre exits, which the loop handles the same way.

A child that dies, or stops answering for `HANG_S` (then it is killed), is reported (log, a critical
`centre-process` alarm through `on_alarm`) and restarted with the open sessions (a fresh network
solution: its ambiguities are fixed again); the alarm clears with the new child's first solved epoch.
Shutdown sends `Stop`, waits, then terminates and kills: no orphan.
The child ignores SIGINT (Ctrl-C reaches the whole process group; the parent decides) and exits when the
parent's end of the socket closes, so it cannot outlive it.
"""

from __future__ import annotations

import asyncio
import collections
import gc
import logging
import multiprocessing as mp
import os
import select
import signal
import socket
import sys
import time
import traceback
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from augnet.blas_threads import limit_blas_threads
from augnet.centre.service_area import AreaAlarm, AreaConfig, ServiceArea, refusal_message
from augnet.centre.vrs_admission import AdmissionConfig
from augnet.gnss import time as gtime
from augnet.system.centre_protocol import (
    FROM_CENTRE, FROM_LOOP, Alive, CentreError, CloseSession, Decoder, EpochsSolved, Message, MoveSession,
    OpenSession, ProtocolError, Ready, SessionBound, StationData, StationMembership, Stop, VrsGroup, VrsWritten,
    encode)
from augnet.centre.network import station_position_problem
from augwire.errors import StreamRefused

log = logging.getLogger(__name__)

# sessions encoded at a time: a group's bytes go to the loop while the centre encodes the next (2,000 trains
# in groups of 500: the first group leaves after a quarter of the encoding, for 20 % more encoding work)
VRS_GROUP = 500
WRITTEN_WAIT_S = 0.2  # the network solve waits this long at most for the loop to write an epoch's VRS
SOCKET_BUFFER_BYTES = 4 << 20
TICK_S = 0.02  # the centre looks for timed-out epochs this often (a complete epoch is solved on arrival)
# sessions opened or moved are added to the next epoch's plan this often, in one batch (a batch costs ~1 ms
# whatever its size: 2,000 trains reporting a GGA every 5 s move 200 points a second, one or two at a time)
PLAN_UPDATE_S = 0.1
STOP_TIMEOUT_S = 5.0
HEARTBEAT_S = 1.0  # the centre sends at least this often (`Alive` when it has nothing else)
HANG_S = 20.0  # a centre silent this long is taken for hung: killed, reported and replaced
# A new centre's start-up (spawned interpreter, imports, engine) before its Ready: seconds on a quiet machine,
# over 20 s on a loaded one; HANG_S applies only once it has answered.
START_S = 120.0
MAX_DELIVERY_S = 1.0  # `delivering` stays true this long at most (an epoch whose last group never came)
RESTART_DELAY_S = 1.0
MAX_RESTARTS = 5  # per run: a centre that keeps dying stays down (its alarm stays raised)
EXIT_PROTOCOL_ERROR = 3  # the centre's exit code when the loop's bytes could not be read
_RECV = 1 << 20  # room the centre offers each read of the socket


@dataclass
class CentreTimings:
    """Per solved epoch: wall time spent [s] (for the live view and the run report)."""

    solve_s: collections.deque = field(default_factory=lambda: collections.deque(maxlen=600))
    # VRS of an epoch ready in the centre, and written to every client's socket: host clock minus the
    # epoch's GPS time [s] (the centre's share of the correction age)
    vrs_ready_s: collections.deque = field(default_factory=lambda: collections.deque(maxlen=600))
    vrs_sent_s: collections.deque = field(default_factory=lambda: collections.deque(maxlen=600))
    # per served epoch: [t_gpst, sessions, station data complete, last group ready, first group on the loop,
    # last group written] (ages, s), then the centre's synthesis and encoding (wall) and their CPU time, and
    # the loop's time writing the groups to the sinks [s], 1 when the VRS were planned ahead
    stages: collections.deque = field(default_factory=lambda: collections.deque(maxlen=3600))
    epochs: int = 0
    sessions_max: int = 0


@dataclass(frozen=True)
class CentreSpec:
    """What the child builds its engine from (plain values: it crosses the process boundary)."""

    stations: dict[str, tuple[float, float, float]]  # name -> ECEF [m]
    t_ref_gpst: float
    network_name: str = "line"
    area: AreaConfig | None = None  # the service area (default: from the stations, service_area.py)
    admission: AdmissionConfig | None = None  # when satellites enter each VRS (default: on, vrs_admission.py)
    # the centre estimates its correction-error bound (decision 0280); a session's VRS carries it (RTCM 4001)
    # only when its mountpoint opted in (`CentreService.set_bound_mounts`, decision 0281)
    estimate_correction_bound: bool = True


class _Handle:
    def __init__(self, service: "CentreService", client_id: str):
        self.service = service
        self.client_id = client_id

    def update_position(self, fix) -> None:
        self.service._move(self.client_id, fix.lat_deg, fix.lon_deg, fix.height_m)

    def close(self) -> None:
        self.service._close(self.client_id)


class _Channel(asyncio.BufferedProtocol):
    """The loop's end of the socket pair: frames in, to the service (read straight into the decoder's
    buffer: no copy of a VRS group between the socket and its decoding)."""

    def __init__(self, service: "CentreService"):
        self.service = service
        self.decoder = Decoder(FROM_CENTRE)
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport) -> None:
        self.transport = transport

    def get_buffer(self, sizehint: int) -> memoryview:
        return self.decoder.get_buffer(sizehint)

    def buffer_updated(self, nbytes: int) -> None:
        try:
            msgs = self.decoder.buffer_updated(nbytes)
        except ProtocolError as exc:  # the messages before the bad frame, then the centre is replaced
            for msg in exc.messages:
                self.service._on_message(msg)
            self.service._on_protocol_error(self, exc)
            return
        for msg in msgs:
            self.service._on_message(msg)

    def connection_lost(self, exc) -> None:
        self.service._on_lost(self)


class CentreService:
    """Stream factory for the caster's VRS mountpoint; the engine runs in a child process."""

    def __init__(self, spec: CentreSpec, loop: asyncio.AbstractEventLoop,
                 on_epoch: Callable | None = None, on_outbox: Callable[[list[tuple[str, bytes]]], None] | None = None,
                 on_alarm: Callable[[str, str, str, str, bool], None] | None = None, hang_s: float = HANG_S,
                 on_written: Callable[[float], None] | None = None, start_s: float = START_S):
        self.spec = spec
        self.on_written = on_written  # called (soon) after an epoch's last VRS group is written: on_written(t)
        self.hang_s = hang_s
        self.start_s = max(start_s, hang_s)
        self.loop = loop
        self.on_epoch = on_epoch
        self.on_outbox = on_outbox
        self.on_alarm = on_alarm
        self.timings = CentreTimings()
        self.errors = 0  # failed commands and epochs in the centre, unsendable messages, child deaths
        self.protocol_errors = 0  # unreadable frames from the centre (each also ends that centre process)
        self.restarts = 0
        self.excluded_stations: set[str] = set()
        # the network's stations now (the spec's at start, then as the store's table changes): a restarted
        # centre is built from these
        self.station_xyz: dict[str, tuple[float, float, float]] = {k: tuple(map(float, v))
                                                                   for k, v in spec.stations.items()}
        # positions are checked here, on the loop, so that a refusal reaches the client and the alarm store
        # (the centre's engine checks them again)
        self.area = ServiceArea({k: np.asarray(v, float) for k, v in spec.stations.items()}, spec.area)
        self.area_alarm = AreaAlarm(spec.network_name)
        self.last = None  # the latest EpochReport
        self.pid: int | None = None
        self._sinks: dict[str, Callable[[bytes], None]] = {}  # loop-side sinks of live sessions
        self._positions: dict[str, tuple[float, float, float]] = {}  # to re-open them in a new child
        self._mounts: dict[str, str] = {}  # live session -> the mountpoint it reads
        self.bound_mounts: frozenset[str] = frozenset()  # mountpoints whose VRS carry the 4001 bound
        self._pending: list[Message] = []
        self._flush_scheduled = False
        self._proc = None
        self._channel: _Channel | None = None
        self._stopping = False
        self._alarm_raised = False
        self._gps_minus_unix = gtime.now_gpst() - time.time()
        self._last_heard = 0.0  # loop time of the centre's last message
        self._ready = False  # the current centre process has said Ready
        self._watchdog: asyncio.Task | None = None
        self._delivering_since: float | None = None  # loop time an epoch's first group was written

    @property
    def stations(self) -> list[str]:
        return list(self.station_xyz)

    def delivering(self) -> bool:
        """True while an epoch's VRS are being written to the sinks: its first group is, its last is not yet
        (other work on the loop can wait for `on_written`; true for `MAX_DELIVERY_S` at most)."""
        since = self._delivering_since
        return since is not None and self.loop.time() - since < MAX_DELIVERY_S

    @property
    def alive(self) -> bool:
        return self._proc is not None and self._proc.is_alive() and self._channel is not None

    @property
    def ready(self) -> bool:
        """The current centre process has started and answered."""
        return self.alive and self._ready

    # --- loop side: the caster's taps and VRS mountpoint ------------------------------------------------

    def feed(self, station: str, data: bytes) -> None:
        if station in self.station_xyz and station not in self.excluded_stations:
            self._send(StationData(station, data, time.time()))

    def open(self, client_id: str, mount: str, fix, sink) -> _Handle:
        self._check_area(client_id, fix.lat_deg, fix.lon_deg, fix.height_m, sink)
        self._sinks[client_id] = sink
        self._positions[client_id] = (fix.lat_deg, fix.lon_deg, fix.height_m)
        self._mounts[client_id] = mount
        self._send(OpenSession(client_id, fix.lat_deg, fix.lon_deg, fix.height_m))
        if mount in self.bound_mounts:
            self._send(SessionBound(client_id, True))
        return _Handle(self, client_id)

    def set_bound_mounts(self, names) -> None:
        """The mountpoints whose sessions' VRS carry the correction-error bound (the store's table, decision
        0281): a live session of a mountpoint that changed is told from its next epoch, no restart."""
        new = frozenset(names)
        changed = new ^ self.bound_mounts
        self.bound_mounts = new
        if changed:
            log.info("correction bound (RTCM 4001) on mountpoints: %s", ", ".join(sorted(new)) or "none")
        for cid, mount in self._mounts.items():
            if mount in changed:
                self._send(SessionBound(cid, mount in new))

    def _move(self, client_id: str, lat: float, lon: float, h: float) -> None:
        if client_id in self._sinks:
            try:
                self._check_area(client_id, lat, lon, h, None)
            except StreamRefused:
                self._close(client_id)
                raise
            self._positions[client_id] = (lat, lon, h)
            self._send(MoveSession(client_id, lat, lon, h))

    def _check_area(self, client_id: str, lat: float, lon: float, h: float, sink) -> None:
        """Raise `StreamRefused` (the caster tells the client why) for a position the service area refuses;
        a client served at the nearest station instead is told so through `sink`. Either raises the alarm."""
        answer = self.area.check(lat, lon, h)
        if answer.kind == "inside":
            return
        log.info("VRS session %s: %s", client_id, answer.reason)
        event = self.area_alarm.refused(self.loop.time(), client_id, answer)
        if event is not None and self.on_alarm is not None:
            self.on_alarm(*event)
        if answer.refused:
            raise StreamRefused(answer.reason, refusal_message(answer.reason))
        if sink is not None:
            sink(refusal_message(answer.reason))

    def _close(self, client_id: str) -> None:
        if self._sinks.pop(client_id, None) is not None:
            self._positions.pop(client_id, None)
            self._mounts.pop(client_id, None)
            self._send(CloseSession(client_id))

    def set_station_enabled(self, station: str, enabled: bool) -> None:
        """An operator disabled (or re-enabled) a station: its data stops reaching the solution, so
        the network re-solves without it exactly as for a station that went silent."""
        if enabled:
            self.excluded_stations.discard(station)
        else:
            self.excluded_stations.add(station)

    # --- membership: the store's station table changed (`station_membership.py`) -------------------------

    def add_station(self, station: str, xyz) -> None:
        """`station` (ECEF `xyz` [m]) joins the network; ValueError (saying why) for a member or a bad position."""
        if station in self.station_xyz:
            raise ValueError(f"station {station} is already in the network")
        self._place(station, xyz, ignore=None)

    def move_station(self, station: str, xyz) -> None:
        """New coordinates for a member: its baselines restart there (the centre's `move_station`)."""
        if station not in self.station_xyz:
            raise ValueError(f"station {station} is not in the network")
        self._place(station, xyz, ignore=station)

    def _place(self, station: str, xyz, ignore: str | None) -> None:
        others = {k: np.asarray(v) for k, v in self.station_xyz.items() if k != ignore}
        problem = station_position_problem(station, xyz, others)
        if problem is not None:
            raise ValueError(problem)
        self.station_xyz[station] = tuple(float(v) for v in np.asarray(xyz, float).reshape(3))
        self._new_area()
        self._send(StationMembership(station, self.station_xyz[station]))

    def remove_station(self, station: str) -> None:
        """`station` leaves the network (its data is no longer read); ValueError for a non-member or the last one."""
        if station not in self.station_xyz:
            raise ValueError(f"station {station} is not in the network")
        if len(self.station_xyz) == 1:
            raise ValueError(f"station {station} is the network's last station: it cannot leave")
        del self.station_xyz[station]
        self.excluded_stations.discard(station)
        self._new_area()
        self._send(StationMembership(station, None))

    def _new_area(self) -> None:
        self.area = ServiceArea({k: np.asarray(v, float) for k, v in self.station_xyz.items()}, self.spec.area)

    def _send(self, cmd: Message) -> None:
        self._pending.append(cmd)
        if not self._flush_scheduled:
            self._flush_scheduled = True
            self.loop.call_soon(self._flush)

    def _flush(self) -> None:
        self._flush_scheduled = False
        ch = self._channel
        if ch is None or ch.transport is None or ch.transport.is_closing():
            if len(self._pending) > 100_000:  # no centre for a long while: station bytes are not kept
                self._pending = [c for c in self._pending if not isinstance(c, StationData)]
            return
        cmds, self._pending = self._pending, []
        frames = []
        for cmd in cmds:
            try:
                frames.append(encode(cmd))
            except ProtocolError:  # a value the protocol cannot carry: that command is dropped, the rest go
                self.errors += 1
                log.exception("centre: a command could not be encoded")
        if frames:
            ch.transport.write(b"".join(frames))

    # --- life cycle ---------------------------------------------------------------------------------------

    async def start(self) -> "CentreService":
        await self._spawn()
        self._watchdog = asyncio.ensure_future(self._watch())
        return self

    async def _watch(self) -> None:
        """A centre that stops answering (it sends at least a heartbeat a second) is killed: its death is
        then reported and it is replaced like any other."""
        while not self._stopping:
            await asyncio.sleep(min(1.0, self.hang_s / 4))
            proc = self._proc
            limit = self.hang_s if self._ready else self.start_s
            event = self.area_alarm.poll(self.loop.time())
            if event is not None and self.on_alarm is not None:
                self.on_alarm(*event)
            if (self._channel is not None and proc is not None and proc.is_alive()
                    and self.loop.time() - self._last_heard > limit):
                log.error("centre process %s has not answered for %.0f s: killed", proc.pid, limit)
                proc.kill()

    async def _spawn(self) -> None:
        ctx = mp.get_context("spawn")
        mine, theirs = socket.socketpair()
        for sock in (mine, theirs):  # room for a whole epoch of VRS in flight (capped by net.core.wmem_max)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SOCKET_BUFFER_BYTES)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER_BYTES)
        # built from the stations as they are now: membership changes queued for the last centre are in it
        spec = replace(self.spec, stations=dict(self.station_xyz))
        self._pending = [c for c in self._pending if not isinstance(c, StationMembership)]
        proc = ctx.Process(target=_child_main, args=(theirs, spec), name="augnet-centre", daemon=True)
        proc.start()
        theirs.close()
        self._proc = proc
        self.pid = proc.pid
        self._last_heard = self.loop.time()
        self._ready = False  # START_S until it answers
        _, channel = await self.loop.create_connection(lambda: _Channel(self), sock=mine)
        self._channel = channel
        # sessions the caster already has (after a restart) first, then whatever queued meanwhile
        reopen = [OpenSession(cid, *pos) for cid, pos in self._positions.items()]
        reopen += [SessionBound(cid, True) for cid in self._positions if self._mounts.get(cid) in self.bound_mounts]
        pending = [c for c in self._pending if not isinstance(c, OpenSession)] if reopen else self._pending
        self._pending = reopen + pending
        self._flush()

    async def stop(self, timeout: float = STOP_TIMEOUT_S) -> None:
        self._stopping = True
        if self._watchdog is not None:
            self._watchdog.cancel()
        proc = self._proc
        ch = self._channel
        if ch is not None and ch.transport is not None and not ch.transport.is_closing():
            self._pending.append(Stop())
            self._flush()
        if proc is not None:
            await self.loop.run_in_executor(None, proc.join, timeout)
            if proc.is_alive():
                log.warning("centre process %s did not stop within %.0f s: terminated", proc.pid, timeout)
                proc.terminate()
                await self.loop.run_in_executor(None, proc.join, 2.0)
            if proc.is_alive():
                proc.kill()
                await self.loop.run_in_executor(None, proc.join, 2.0)
        if ch is not None and ch.transport is not None:
            ch.transport.close()
        self._channel = None

    def _on_protocol_error(self, channel: _Channel, exc: ProtocolError) -> None:
        """The centre sent a frame that cannot be read: counted, logged, and the stream (which lost its
        framing) ended with the process behind it, which `_on_lost` then reports and replaces."""
        self.protocol_errors += 1
        proc = self._proc
        log.error("centre: unreadable message from the centre process %s (%s): killed", self.pid, exc)
        if channel is self._channel and proc is not None and proc.is_alive():
            proc.kill()
        if channel.transport is not None:
            channel.transport.close()

    def _on_lost(self, channel: _Channel) -> None:
        if channel is not self._channel:
            return
        self._channel = None
        self._delivering_since = None
        if self._stopping:
            return
        self.errors += 1
        code = self._proc.exitcode if self._proc is not None else None
        if self._proc is not None and code is None:
            self._proc.join(0.5)  # the socket closes a moment before the process is reaped
            code = self._proc.exitcode
        msg = f"centre process {self.pid} died (exit code {code})"
        log.error("%s; %s", msg, "restarting it" if self.restarts < MAX_RESTARTS else "not restarted again")
        self._alarm(False, msg)
        if self.restarts < MAX_RESTARTS:
            self.restarts += 1
            self.loop.call_later(RESTART_DELAY_S, lambda: asyncio.ensure_future(self._restart()))

    async def _restart(self) -> None:
        if self._stopping:
            return
        try:
            await self._spawn()
        except Exception:  # noqa: BLE001 - logged; the alarm stays raised
            self.errors += 1
            log.exception("centre process could not be restarted")

    def _alarm(self, cleared: bool, message: str) -> None:
        if cleared == (not self._alarm_raised):
            return
        self._alarm_raised = not cleared
        if self.on_alarm is not None:
            try:
                self.on_alarm("centre-process", "centre", "critical", message, cleared)
            except Exception:  # noqa: BLE001
                log.exception("centre alarm handler failed")

    # --- loop side: what the centre sends -----------------------------------------------------------------

    def _on_message(self, msg: Message) -> None:
        self._last_heard = self.loop.time()
        try:
            if isinstance(msg, VrsGroup):
                self._send_vrs(msg)
            elif isinstance(msg, EpochsSolved):
                self._deliver(msg)
            elif isinstance(msg, CentreError):
                self.errors += 1
                log.error("centre: %s", msg.text)
            elif isinstance(msg, Ready):
                self._ready = True
                log.info("centre process %s ready", msg.pid)
        except Exception:  # noqa: BLE001 - a consumer's bug must not stop the centre's output
            self.errors += 1
            log.exception("centre: handling a %s message failed", type(msg).__name__)

    def _send_vrs(self, msg: VrsGroup) -> None:
        """Every client's epoch (or a group of clients': an epoch may come in several messages) to its
        caster sink; after the last group, `VrsWritten` tells the centre it may solve the network."""
        t_gpst, ready_unix, arrival, cost, last = msg.t_gpst, msg.ready_unix_s, msg.arrival, msg.cost, msg.last
        sessions = len(msg.client_ids)
        off = self._gps_minus_unix
        on_loop = time.time() + off - t_gpst
        sinks = self._sinks
        for cid, data in zip(msg.client_ids, msg.rtcm):
            sink = sinks.get(cid)
            if sink is not None:
                sink(data)
        if last:
            self._send(VrsWritten(t_gpst))
            self._delivering_since = None
            if self.on_written is not None:
                self.loop.call_soon(self.on_written, t_gpst)
        elif self._delivering_since is None:
            self._delivering_since = self.loop.time()
        sent = time.time() + off - t_gpst
        ready = ready_unix + off - t_gpst
        cost = cost or (np.nan, np.nan, np.nan, np.nan)
        stages = self.timings.stages
        if stages and stages[-1][0] == t_gpst:  # a further group of the epoch
            rec = stages[-1]
            rec[1] += sessions
            rec[3], rec[5], rec[6:9], rec[10] = ready, sent, list(cost[:3]), cost[3]
            rec[9] += sent - on_loop
            self.timings.vrs_ready_s[-1] = ready
            self.timings.vrs_sent_s[-1] = sent
            return
        self.timings.vrs_ready_s.append(ready)
        self.timings.vrs_sent_s.append(sent)
        stages.append([t_gpst, sessions, arrival[1] + off - t_gpst if arrival else np.nan,
                       ready, on_loop, sent, *cost[:3], sent - on_loop, cost[3]])

    def _deliver(self, msg: EpochsSolved) -> None:
        """The reports of the solved epochs."""
        reports, outbox, solve_s, sessions = msg.reports, msg.outbox, msg.solve_s, msg.sessions
        done_at = time.time()
        self._gps_minus_unix = gtime.now_gpst() - done_at
        self.timings.solve_s.append(solve_s)
        self.timings.epochs += len(reports)
        self.timings.sessions_max = max(self.timings.sessions_max, sessions)
        if reports:
            self.last = reports[-1]
            self._alarm(True, "centre process running")
        if self.on_outbox is not None and outbox:
            self.on_outbox(outbox)
        if self.on_epoch is not None:
            for r in reports:
                self.on_epoch(r, done_at)

    # --- figures ------------------------------------------------------------------------------------------

    def latency_ms_p99(self, recent: int = 60) -> dict:
        """p99 over the last `recent` epochs (the live picture, not the start-up burst)."""
        out = {}
        for name in ("vrs_ready_s", "vrs_sent_s"):
            d = list(getattr(self.timings, name))[-recent:]
            out[name[:-2] + "_ms_p99"] = round(float(np.percentile(np.array(d), 99)) * 1000.0, 1) if d else None
        return out

    def stages_ms(self) -> dict:
        """Where the correction age goes, over the epochs served to the most sessions (at least half the
        peak), p50 / p90 / p99 [ms]: the epoch's age when its last station's data reached the caster,
        when its first group of VRS reached the loop, when the last group was ready in the centre and when
        it was written to the sockets; then the costs: the centre's synthesis and encoding (wall), their
        CPU, and the loop's writing to the caster's sinks."""
        recs = np.array(list(self.timings.stages), float).reshape(-1, 11)
        if not len(recs):
            return {}
        recs = recs[recs[:, 1] >= 0.5 * recs[:, 1].max()]
        out: dict = {"epochs": int(len(recs)), "sessions": int(recs[:, 1].max()),
                     "planned_ahead": round(float(np.nanmean(recs[:, 10])), 3) if np.isfinite(recs[:, 10]).any() else None}
        for k, name in ((2, "station_data"), (4, "vrs_first_on_loop"), (3, "vrs_ready"), (5, "vrs_written"),
                        (6, "synthesis"), (7, "encoding"), (8, "centre_cpu"), (9, "loop_writing")):
            d = recs[:, k][np.isfinite(recs[:, k])]
            if d.size:
                out[name] = {q: round(float(np.percentile(d, int(q[1:]))) * 1000.0, 1) for q in ("p50", "p90", "p99")}
        return out

    def solve_ms_p99(self) -> float | None:
        if not self.timings.solve_s:
            return None
        return float(np.percentile(np.array(self.timings.solve_s), 99) * 1000.0)


# --- the child process ----------------------------------------------------------------------------------


def _child_main(sock: socket.socket, spec: CentreSpec) -> None:
    # small numpy matrices: two BLAS threads would spin against the loop on two cores (the variables are
    # inherited from `augnet`; without them the running pool is limited)
    limit_blas_threads()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C: the parent stops us
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    worker = _CentreWorker(sock, spec)
    worker.run()
    if worker.protocol_error is not None:
        sys.exit(EXIT_PROTOCOL_ERROR)


class _Collector:
    """The engine's sink for one session: collects the epoch's bytes for the loop."""

    __slots__ = ("ids", "rtcm", "cid")

    def __init__(self, ids: list[str], rtcm: list[bytes], cid: str):
        self.ids = ids
        self.rtcm = rtcm
        self.cid = cid

    def __call__(self, data: bytes) -> None:
        self.ids.append(self.cid)
        self.rtcm.append(data)


class _CentreWorker:
    """The child's loop: commands in, engine ticks, VRS and reports out."""

    def __init__(self, sock: socket.socket, spec: CentreSpec):
        from augnet.centre.engine import CentreEngine

        self.sock = sock
        sock.setblocking(True)
        stations = {k: np.asarray(v, float) for k, v in spec.stations.items()}
        self.engine = CentreEngine(stations, spec.t_ref_gpst, network_name=spec.network_name, area=spec.area,
                                   admission=spec.admission, estimate_correction_bound=spec.estimate_correction_bound)
        self.engine.after_serve = self._flush_vrs  # VRS leave as soon as they exist, before the network solve
        self.engine.serve_group = VRS_GROUP
        gc.freeze()  # the engine's long-lived start-up objects: not scanned by every full collection
        self.batch_ids: list[str] = []  # the VRS group being collected: client ids and their epoch's bytes
        self.batch_rtcm: list[bytes] = []
        self.decoder = Decoder(FROM_LOOP)
        self._inbox: collections.deque = collections.deque()  # commands read, not yet applied
        self._broken = False
        self.protocol_error: ProtocolError | None = None
        self._last_sent = 0.0

    def send(self, msg: Message) -> None:
        """One message to the loop (the socket's buffer holds an epoch's VRS for thousands of trains, so
        this returns at once while the loop is still reading the previous group)."""
        self._last_sent = time.monotonic()
        data = encode(msg)
        try:
            self.sock.sendall(data)
        except OSError:
            self._broken = True  # the loop side is gone

    def run(self) -> None:
        try:
            self.send(Ready(os.getpid()))
            next_tick = next_plan_update = time.monotonic()
            while not self._broken:
                timeout = 0.0 if self._inbox else max(0.0, next_tick - time.monotonic())
                self._read(timeout)
                fed = False  # station data came: an epoch may be complete (moves alone complete none)
                while self._inbox:
                    cmd = self._inbox.popleft()
                    if isinstance(cmd, Stop):
                        return
                    fed = fed or isinstance(cmd, StationData)
                    self._apply(cmd)
                if fed or time.monotonic() >= next_tick:
                    self._tick()
                    if time.monotonic() >= next_tick:
                        next_tick = time.monotonic() + TICK_S
                if time.monotonic() >= next_plan_update:  # after the tick: never before an epoch that is ready
                    self._update_plan()
                    next_plan_update = time.monotonic() + PLAN_UPDATE_S
                if time.monotonic() - self._last_sent >= HEARTBEAT_S:
                    self.send(Alive())
        except OSError:
            return
        finally:
            self.sock.close()

    def _read(self, timeout: float) -> bool:
        """Whatever the loop sent within `timeout`, into the inbox (False: nothing came)."""
        readable, _, _ = select.select([self.sock], [], [], timeout)
        if not readable:
            return False
        with self.decoder.get_buffer(_RECV) as room:
            nbytes = self.sock.recv_into(room)
        if not nbytes:
            self._broken = True  # the loop side is gone
            self._inbox.append(Stop())
            return True
        try:
            self._inbox.extend(self.decoder.buffer_updated(nbytes))
        except ProtocolError as exc:  # the stream lost its framing: told to the loop, then this centre exits
            self._inbox.extend(exc.messages)
            self._inbox.append(Stop())
            self.protocol_error = exc
            log.error("unreadable message from the loop: %s", exc)
            self.send(CentreError(f"unreadable message from the loop: {exc}"))
            self._broken = True
        return True

    def _await_written(self, t_gpst: float) -> None:
        """Hold the network solve until the loop has written the epoch's VRS (at most `WRITTEN_WAIT_S`): on
        two cores the solve would otherwise take one from the loop and the clients while they deliver."""
        deadline = time.monotonic() + WRITTEN_WAIT_S
        seen = 0
        while not self._broken:
            for i in range(seen, len(self._inbox)):
                msg = self._inbox[i]
                if isinstance(msg, VrsWritten) and msg.t_gpst == t_gpst:
                    del self._inbox[i]
                    return
            seen = len(self._inbox)
            left = deadline - time.monotonic()
            if left <= 0 or not self._read(left):
                return

    def _apply(self, cmd: Message) -> None:
        eng = self.engine
        try:
            if isinstance(cmd, StationData):
                eng.feed(cmd.station, cmd.data, cmd.arrival_unix_s)
            elif isinstance(cmd, OpenSession):
                sink = _Collector(self.batch_ids, self.batch_rtcm, cmd.client_id)
                eng.open_session(cmd.client_id, cmd.lat_deg, cmd.lon_deg, cmd.h_m, sink)
            elif isinstance(cmd, MoveSession):
                eng.move_session(cmd.client_id, cmd.lat_deg, cmd.lon_deg, cmd.h_m)
            elif isinstance(cmd, CloseSession):
                eng.close_session(cmd.client_id)
            elif isinstance(cmd, SessionBound):
                eng.set_session_bound(cmd.client_id, cmd.send)
            elif isinstance(cmd, StationMembership):
                if cmd.xyz_m is None:
                    eng.remove_station(cmd.station)
                elif cmd.station in eng.stations:
                    eng.move_station(cmd.station, cmd.xyz_m)
                else:
                    eng.add_station(cmd.station, cmd.xyz_m)
        except Exception:  # noqa: BLE001 - bad input never stops the centre: reported, then ignored
            self._error(f"{type(cmd).__name__} failed")

    def _update_plan(self) -> None:
        """Sessions opened or moved meanwhile get their place in the next epoch's plan now, between epochs."""
        try:
            self.engine.update_plan()
        except Exception:  # noqa: BLE001 - the epoch's synthesis plans them instead
            self._error("planning moved sessions failed")

    def _tick(self) -> None:
        eng = self.engine
        try:
            t0 = time.perf_counter()
            reports = eng.tick(time.time())
            self._flush_vrs()
            if not reports:
                return
            solve_s = (time.perf_counter() - t0) / len(reports)
            self.send(EpochsSolved(reports, eng.drain_outbox(), solve_s, len(eng.sessions)))
            eng.prepare_next()  # the next epoch's VRS but for its observations, while waiting for them
        except Exception:  # noqa: BLE001 - the centre keeps serving; the error is counted and logged
            self.batch_ids.clear()
            self.batch_rtcm.clear()
            self._error("epoch failed")

    def _flush_vrs(self, last: bool = True) -> None:
        if self.batch_ids:
            ids, rtcm = list(self.batch_ids), list(self.batch_rtcm)
            self.batch_ids.clear()  # the collectors hold these lists
            self.batch_rtcm.clear()
            eng = self.engine
            t = float(eng.serving_t)
            self.send(VrsGroup(t, ids, rtcm, time.time(), eng.serving_arrival, eng.serve_cost_s, last))
            if last:
                self._await_written(t)

    def _error(self, what: str) -> None:
        text = f"{what}: {traceback.format_exc(limit=8)}"
        log.error("%s", text)
        self.send(CentreError(text))

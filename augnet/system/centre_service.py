"""The control centre as a service inside `augnet up`: the sans-IO `CentreEngine` run in a worker thread.

Why a thread: one network epoch (solve + VRS for every connected train) takes tens to hundreds of ms,
which must not stall the event loop that carries the caster's sockets. The loop side only queues:
station bytes from the caster's taps (`feed`), VRS sessions opened / moved / closed by the caster's VRS
mountpoint (`CentreService` is its stream factory). The worker applies the queue, ticks the engine
every `TICK_S`, and hands every client's RTCM back to the loop in one `call_soon_threadsafe` per epoch
(the caster's sinks must be called on its loop). Reports (network epochs, alarms, the correction model
for the bus) go to `on_epoch`, also on the loop.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from augnet.centre.engine import CentreEngine, EpochReport
from augnet.gnss import time as gtime

log = logging.getLogger(__name__)

TICK_S = 0.02  # the worker looks for complete epochs this often (stations deliver within a few ms)


@dataclass
class CentreTimings:
    """Per solved epoch: wall time spent [s] (for the live view and the run report)."""

    solve_s: collections.deque = field(default_factory=lambda: collections.deque(maxlen=600))
    # VRS of an epoch handed to the loop, and written to every client's socket: host clock minus the
    # epoch's GPS time [s] (the centre's share of the correction age)
    vrs_ready_s: collections.deque = field(default_factory=lambda: collections.deque(maxlen=600))
    vrs_sent_s: collections.deque = field(default_factory=lambda: collections.deque(maxlen=600))
    epochs: int = 0
    sessions_max: int = 0


class _Handle:
    def __init__(self, service: "CentreService", client_id: str):
        self.service = service
        self.client_id = client_id

    def update_position(self, fix) -> None:
        self.service._commands.append(("move", self.client_id, fix.lat_deg, fix.lon_deg, fix.height_m))

    def close(self) -> None:
        self.service._commands.append(("close", self.client_id))
        self.service._sinks.pop(self.client_id, None)


class CentreService:
    """Stream factory for the caster's VRS mountpoint + the engine's worker thread."""

    def __init__(self, engine: CentreEngine, loop, on_epoch: Callable[[EpochReport, float], None] | None = None,
                 on_outbox: Callable[[list[tuple[str, bytes]]], None] | None = None):
        self.engine = engine
        self.loop = loop
        self.on_epoch = on_epoch
        self.on_outbox = on_outbox
        self._inbox: collections.deque = collections.deque()  # (station, bytes, arrival wall time)
        self._commands: collections.deque = collections.deque()
        self._sinks: dict[str, Callable[[bytes], None]] = {}  # loop-side sinks of live sessions
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="augnet-centre", daemon=True)
        self.timings = CentreTimings()
        self._batch: list[tuple[str, bytes]] = []
        engine.after_serve = self._flush_vrs  # VRS leave as soon as they exist, before the network solve
        self.errors = 0
        self.excluded_stations: set[str] = set()

    # --- loop side ---------------------------------------------------------------------------------

    def feed(self, station: str, data: bytes) -> None:
        if station not in self.excluded_stations:
            self._inbox.append((station, data, time.time()))

    def open(self, client_id: str, mount: str, fix, sink) -> _Handle:
        self._sinks[client_id] = sink
        self._commands.append(("open", client_id, fix.lat_deg, fix.lon_deg, fix.height_m))
        return _Handle(self, client_id)

    def set_station_enabled(self, station: str, enabled: bool) -> None:
        """An operator disabled (or re-enabled) a station: its data stops reaching the solution, so
        the network re-solves without it exactly as for a station that went silent."""
        if enabled:
            self.excluded_stations.discard(station)
        else:
            self.excluded_stations.add(station)

    def start(self) -> "CentreService":
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    # --- worker side -------------------------------------------------------------------------------

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._step()
            except Exception:  # noqa: BLE001 - the centre keeps serving; the error is counted and logged
                self.errors += 1
                log.exception("centre step failed")
            self._stop.wait(TICK_S)

    def _step(self) -> None:
        eng = self.engine
        while self._commands:
            cmd = self._commands.popleft()
            if cmd[0] == "open":
                _, cid, lat, lon, h = cmd
                eng.open_session(cid, lat, lon, h, _Collector(self, cid))
            elif cmd[0] == "move":
                eng.move_session(*cmd[1:])
            elif cmd[0] == "close":
                eng.close_session(cmd[1])
        while self._inbox:
            station, data, at = self._inbox.popleft()
            eng.feed(station, data, at)
        t0 = time.perf_counter()
        reports = eng.tick(time.time())
        self._flush_vrs()
        if not reports:
            return
        dt = time.perf_counter() - t0
        self.timings.solve_s.append(dt / len(reports))
        self.timings.epochs += len(reports)
        self.timings.sessions_max = max(self.timings.sessions_max, len(eng.sessions))
        outbox = eng.drain_outbox()
        done_at = time.time()
        self.loop.call_soon_threadsafe(self._deliver, reports, outbox, done_at)

    def _flush_vrs(self) -> None:
        """Worker side: hand the epoch's VRS bytes to the loop in one call."""
        if self._batch:
            batch, self._batch = self._batch, []
            t = self.engine.serving_t
            self.timings.vrs_ready_s.append(gtime.now_gpst() - t)
            self.loop.call_soon_threadsafe(self._send_vrs, batch, t)

    def _send_vrs(self, batch, t_gpst: float) -> None:
        """On the loop: every client's epoch to its caster sink."""
        for cid, data in batch:
            sink = self._sinks.get(cid)
            if sink is not None:
                sink(data)
        self.timings.vrs_sent_s.append(gtime.now_gpst() - t_gpst)

    def latency_ms_p99(self, recent: int = 60) -> dict:
        """p99 over the last `recent` epochs (the live picture, not the start-up burst)."""
        out = {}
        for name in ("vrs_ready_s", "vrs_sent_s"):
            d = list(getattr(self.timings, name))[-recent:]
            out[name[:-2] + "_ms_p99"] = round(float(np.percentile(np.array(d), 99)) * 1000.0, 1) if d else None
        return out

    def _deliver(self, reports, outbox, done_at: float) -> None:
        """On the loop: the reports of the solved epochs."""
        if self.on_outbox is not None and outbox:
            self.on_outbox(outbox)
        if self.on_epoch is not None:
            for r in reports:
                self.on_epoch(r, done_at)

    def solve_ms_p99(self) -> float | None:
        if not self.timings.solve_s:
            return None
        return float(np.percentile(np.array(self.timings.solve_s), 99) * 1000.0)


class _Collector:
    """The engine's sink for one session, inside the worker: collects the epoch's bytes for the loop."""

    __slots__ = ("service", "cid")

    def __init__(self, service: CentreService, cid: str):
        self.service = service
        self.cid = cid

    def __call__(self, data: bytes) -> None:
        self.service._batch.append((self.cid, data))

"""The live picture of the running system: in memory, not persisted.

The running system (`augnet up`) writes it, from any thread; the console reads it and forwards every change
to websocket subscribers as a small event. Each subscriber has a bounded asyncio queue on its own event loop;
a slow subscriber loses its oldest events rather than holding memory or slowing the writer.

Events are JSON-ready dicts with a "type": "station", "baselines", "train", "train.removed", "network",
"line", "alarm", "station.changed", "snapshot".
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

# Events a subscriber may have queued before the oldest are dropped: a few seconds of a busy line
# (one event per train and epoch at 1 Hz for a few hundred trains).
SUBSCRIBER_QUEUE_EVENTS = 2048
log = logging.getLogger(__name__)

FIX_STATES = ("fix", "float", "dgps", "single", "none")  # train solution, best first
BASELINE_STATES = ("fixed", "float", "none")  # network baseline ambiguities


@dataclass(slots=True)
class StationLive:
    id: str  # station code, as in the store
    station_id: int  # RTCM reference station id (DF003)
    lat_deg: float
    lon_deg: float
    h_m: float
    along_km: float | None = None  # position along the line (None: not projected)
    up: bool = False  # data arriving
    enabled: bool = True
    last_data_age_s: float | None = None
    satellites: int = 0


@dataclass(slots=True)
class BaselineLive:
    a: str  # station code at one end
    b: str  # station code at the other
    length_km: float
    state: str  # "fixed" | "float" | "none"
    fixed_fraction: float  # of the double-difference ambiguities
    residual_rms_cm: float | None = None


@dataclass(slots=True)
class TrainLive:
    id: str
    lat_deg: float
    lon_deg: float
    h_m: float
    track_id: str | None = None
    along_km: float | None = None
    cross_track_m: float | None = None
    fix_state: str = "none"  # "fix" | "float" | "dgps" | "single" | "none"
    correction_age_s: float | None = None
    hpl_m: float | None = None  # horizontal protection level
    vpl_m: float | None = None  # vertical protection level
    speed_kmh: float | None = None
    updated_unix: float = 0.0


def json_safe(value: Any) -> Any:
    """JSON-safe copy: NaN and infinities become None (JSON has no such numbers)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def as_dict(obj: Any) -> dict[str, Any]:
    return json_safe(dataclasses.asdict(obj))


class _Subscriber:
    __slots__ = ("loop", "queue", "dropped")

    def __init__(self, loop: asyncio.AbstractEventLoop, maxsize: int) -> None:
        self.loop = loop
        self.queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue(maxsize)
        self.dropped = 0

    def put(self, event: dict[str, Any]) -> None:
        """Runs on the subscriber's loop: enqueue, dropping the oldest when full."""
        q = self.queue
        while q.full():
            try:
                q.get_nowait()
            except asyncio.QueueEmpty:  # pragma: no cover - a full queue is not empty
                break
            self.dropped += 1
        q.put_nowait(event)


class LiveState:
    """What the system knows now. Writers call the update methods; the console reads `snapshot()`."""

    def __init__(self, queue_events: int = SUBSCRIBER_QUEUE_EVENTS) -> None:
        self._lock = threading.RLock()
        self.stations: dict[str, StationLive] = {}
        self.baselines: list[BaselineLive] = []
        self.trains: dict[str, TrainLive] = {}
        self.network: dict[str, Any] = {}
        self.line: dict[str, Any] = {}
        self.caster_snapshot: Callable[[], dict] | None = None
        # Called after an operator's committed change, so the running system can react:
        # on_station_change(code, change); on_caster_change(kind "user" | "mountpoint", name, change).
        # They may run in a worker thread of the console: hand work to the system's loop with
        # loop.call_soon_threadsafe. caster_snapshot is called on the console's event loop.
        self.on_station_change: Callable[[str, dict], None] | None = None
        self.on_caster_change: Callable[[str, str, dict], None] | None = None
        self._queue_events = queue_events
        self._subscribers: list[_Subscriber] = []
        self.events_published = 0

    # --- writers (any thread) -------------------------------------------------------------------------

    def update_station(self, station: StationLive) -> None:
        with self._lock:
            self.stations[station.id] = station
        self.publish({"type": "station", "station": as_dict(station)})

    def remove_station(self, station_id: str) -> None:
        with self._lock:
            self.stations.pop(station_id, None)
        self.publish({"type": "station.removed", "id": station_id})

    def set_baselines(self, baselines: list[BaselineLive]) -> None:
        with self._lock:
            self.baselines = list(baselines)
        self.publish({"type": "baselines", "baselines": [as_dict(b) for b in baselines]})

    def update_train(self, train: TrainLive) -> None:
        if not train.updated_unix:
            train.updated_unix = time.time()
        with self._lock:
            self.trains[train.id] = train
        self.publish({"type": "train", "train": as_dict(train)})

    def remove_train(self, train_id: str) -> None:
        with self._lock:
            self.trains.pop(train_id, None)
        self.publish({"type": "train.removed", "id": train_id})

    def set_network(self, network: dict[str, Any]) -> None:
        with self._lock:
            self.network = dict(network)
        self.publish({"type": "network", "network": json_safe(self.network)})

    def set_line(self, line: dict[str, Any]) -> None:
        with self._lock:
            self.line = dict(line)
        self.publish({"type": "line", "line": json_safe(self.line)})

    # --- readers ------------------------------------------------------------------------------------

    def station_list(self) -> list[StationLive]:
        with self._lock:
            return list(self.stations.values())

    def baseline_list(self) -> list[BaselineLive]:
        with self._lock:
            return list(self.baselines)

    def train_list(self) -> list[TrainLive]:
        with self._lock:
            return sorted(self.trains.values(), key=lambda t: t.id)

    def network_summary(self) -> dict[str, Any]:
        with self._lock:
            return json_safe(self.network)

    def line_summary(self) -> dict[str, Any]:
        with self._lock:
            return json_safe(self.line)

    def caster(self) -> dict[str, Any] | None:
        """The caster's snapshot, or None when no caster runs in this process (or its snapshot fails:
        that is logged, and the console keeps serving)."""
        fn = self.caster_snapshot
        if fn is None:
            return None
        try:
            return fn()
        except Exception:  # the caster belongs to the running system
            log.exception("caster snapshot failed")
            return None

    def snapshot(self) -> dict[str, Any]:
        with self._lock:
            return {
                "type": "snapshot",
                "stations": [as_dict(s) for s in self.stations.values()],
                "baselines": [as_dict(b) for b in self.baselines],
                "trains": [as_dict(t) for t in sorted(self.trains.values(), key=lambda t: t.id)],
                "network": json_safe(self.network),
                "line": json_safe(self.line),
            }

    # --- websocket fan-out --------------------------------------------------------------------------

    def subscribe(self) -> asyncio.Queue[dict[str, Any]]:
        """A queue of events for the calling coroutine's loop (call from inside the loop)."""
        sub = _Subscriber(asyncio.get_running_loop(), self._queue_events)
        with self._lock:
            self._subscribers.append(sub)
        return sub.queue

    def unsubscribe(self, queue: asyncio.Queue) -> None:
        with self._lock:
            self._subscribers = [s for s in self._subscribers if s.queue is not queue]

    @property
    def subscriber_count(self) -> int:
        with self._lock:
            return len(self._subscribers)

    def dropped_events(self) -> int:
        with self._lock:
            return sum(s.dropped for s in self._subscribers)

    def publish(self, event: dict[str, Any]) -> None:
        """Send an event to every subscriber (thread-safe; never blocks the writer)."""
        with self._lock:
            subs = list(self._subscribers)
            self.events_published += 1
        dead = []
        for sub in subs:
            try:
                sub.loop.call_soon_threadsafe(sub.put, event)
            except RuntimeError:  # the subscriber's loop is closed: it is gone
                dead.append(sub)
        if dead:
            with self._lock:
                self._subscribers = [s for s in self._subscribers if s not in dead]

    def station_changed(self, code: str, change: dict[str, Any]) -> None:
        """An operator changed a station: tell the running system, then the pages."""
        with self._lock:
            live = self.stations.get(code)
            if live is not None and "enabled" in change:
                live.enabled = bool(change["enabled"])
        callback = self.on_station_change
        if callback is not None:
            callback(code, dict(change))
        self.publish({"type": "station.changed", "code": code, "change": json_safe(change)})

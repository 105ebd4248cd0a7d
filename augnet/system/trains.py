"""A simulated train inside `augnet up`: its receiver's raw stream in, the onboard core, the VRS over NTRIP.

Each train is what would ride on a real one: the GNSS receiver's raw RTCM (here the simulator's
`TRAIN-<id>-RAW` stream, read in-process from the caster as a serial line would deliver it), the
onboard positioning core (`OnboardUnit`: RTK, track map, virtual balises, protection levels), and an
NTRIP client on the centre's VRS mountpoint that uploads the train's GGA and receives its own VRS.

Pairing: a rover epoch is processed with the VRS epoch of the same time tag when that arrives within
`MAX_BASE_WAIT_S` (the centre needs a few hundred ms to solve and synthesise); otherwise with the
latest VRS epoch (the RTK filter extrapolates, and reports the age).

These trains share the event loop with the caster, and an RTK epoch is tens of ms of Python: run as soon as
their own VRS arrived (in the first group the caster writes), it held back the writing of every other
train's VRS of the epoch. `hold` (the centre service's `delivering`) defers the processing until the caster
has written the epoch's VRS to every client; `resume` then catches up. On a real train it has a computer of
its own.

A repositioned VRS (same session, same RTCM station id) keeps the filter's ambiguities: the centre keeps
the VRS phase continuous while the master station stays the same, and restarts every lock (the rover
sees a slip on every satellite) when it changes. A different station id is a new base: reset.
"""

from __future__ import annotations

import asyncio
import collections
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from augnet.onboard.balise import ListSink
from augnet.onboard.balise_timer import MAX_ESTIMATE_AGE_S, TimedBaliseDetector, TimerSink
from augnet.onboard.corrections import CorrectionDecoder
from augnet.onboard.ntrip_client import NtripClient
from augnet.onboard.observations import EpochObs
from augnet.onboard.rtk import Status
from augnet.onboard.trackmap import DEFAULT_INTEGRITY_RISK, TrackDatabase, gaussian_k
from augnet.onboard.unit import OnboardUnit, UnitOutput

MAX_BASE_WAIT_S = 1.5  # a rover epoch waits this long for its own VRS epoch before using the latest
MAX_QUEUED_ROVER_EPOCHS = 10
GGA_INTERVAL_S = 2.0  # the caster re-evaluates a VRS point at most every 10 s (reposition policy)
# The balise timer's oldest usable estimate [s]: its own 2 s (one missed 1 Hz epoch) plus the wait of a rover
# epoch for its VRS here, since the estimate of epoch t exists only once t is processed
TIMER_ESTIMATE_AGE_S = MAX_ESTIMATE_AGE_S + MAX_BASE_WAIT_S
MAX_SPEED_BASE_S = 2.0  # two matched fixes this close give the timer its speed (a 1 Hz epoch missed at most)


@dataclass
class TrainStats:
    epochs: int = 0
    by_status: collections.Counter = field(default_factory=collections.Counter)
    first_fix_s: float | None = None  # seconds from the first rover epoch
    vrs_epochs: int = 0
    base_resets: int = 0
    base_moves: int = 0
    correction_latency_s: collections.deque = field(default_factory=lambda: collections.deque(maxlen=3600))
    balises: list = field(default_factory=list)
    timer_updates: int = 0  # fused estimates given to the balise timer
    # the map match's protection levels and, in them, the centre's 4001 bound on each axis [m] (inf: unbounded)
    along_pl_m: collections.deque = field(default_factory=lambda: collections.deque(maxlen=3600))
    cross_pl_m: collections.deque = field(default_factory=lambda: collections.deque(maxlen=3600))
    correction_along_m: collections.deque = field(default_factory=lambda: collections.deque(maxlen=3600))
    errors: int = 0


class OnboardTrain:
    def __init__(self, train_id: str, nav_source, track_db: TrackDatabase | None, host: str, port: int,
                 vrs_mount: str, *, user: str = "", password: str = "", on_output=None,
                 integrity_risk: float = DEFAULT_INTEGRITY_RISK, hold: Callable[[], bool] | None = None,
                 balise_groups: list | None = None, timer_sink: TimerSink | None = None):
        self.id = train_id
        self.hold = hold  # () -> True while the caster writes an epoch's VRS: processing waits for `resume`
        self.nav_source = nav_source  # () -> NavigationData: the broadcast ephemerides the receiver decoded
        self.track_db = track_db
        self.sink = ListSink()
        self.unit: OnboardUnit | None = None
        self.rover_dec = CorrectionDecoder()
        self.base_dec = CorrectionDecoder()
        self.rover_queue: collections.deque[tuple[EpochObs, float]] = collections.deque()
        self.bases: collections.OrderedDict[float, EpochObs] = collections.OrderedDict()
        self.last_base: EpochObs | None = None
        self.base_station_id: int | None = None
        self.base_position: np.ndarray | None = None
        self.last: UnitOutput | None = None
        self.stats = TrainStats()
        self.on_output = on_output
        self.k_h = gaussian_k(integrity_risk)
        # timer-based virtual balises (balise_timer.py): passages at their predicted moment, to `timer_sink`
        # (the RSSP-I link to the train's ATP in `augnet up`, atp_link.py)
        self.timer = (TimedBaliseDetector(balise_groups, timer_sink, k=self.k_h, max_estimate_age_s=TIMER_ESTIMATE_AGE_S)
                      if balise_groups and timer_sink is not None else None)
        self._last_fix_along: tuple[float, str, float] | None = None  # (epoch, track, chainage [m])
        self._timer_handle: asyncio.TimerHandle | None = None
        self._t_first: float | None = None
        self.client = NtripClient(host, port, vrs_mount, self._on_vrs, user=user, password=password,
                                  gga_provider=self._gga, gga_interval_s=GGA_INTERVAL_S)
        self._client_task: asyncio.Task | None = None
        self._ticker: asyncio.Task | None = None

    # --- inputs (on the loop) ------------------------------------------------------------------------

    def on_rover_bytes(self, data: bytes) -> None:
        now = gtime.now_gpst()
        for ep in self.rover_dec.feed(data, now):
            self.rover_queue.append((ep, now))
            while len(self.rover_queue) > MAX_QUEUED_ROVER_EPOCHS:
                self._process(*self.rover_queue.popleft())
        self._drain(now)
        if self._client_task is None and self.last is not None and self.last.solution.status != Status.NONE:
            self._client_task = asyncio.ensure_future(self.client.run())  # GGA known: ask for a VRS

    def _on_vrs(self, data: bytes) -> None:
        now = gtime.now_gpst()
        for ep in self.base_dec.feed(data, now):
            self.stats.vrs_epochs += 1
            self.stats.correction_latency_s.append(now - ep.time)
            self.bases[round(ep.time, 3)] = ep
            while len(self.bases) > MAX_QUEUED_ROVER_EPOCHS:
                self.bases.popitem(last=False)
            self.last_base = ep
        self._drain(now)

    def resume(self) -> None:
        """The caster has written the epoch's VRS: process what waited."""
        self._drain(gtime.now_gpst())

    def _drain(self, now: float) -> None:
        if self.hold is not None and self.hold():
            return
        while self.rover_queue:
            ep, arrived = self.rover_queue[0]
            if self._base_ready(ep.time) or now - arrived >= MAX_BASE_WAIT_S:
                self.rover_queue.popleft()
                self._process(ep, arrived)
            else:
                break

    def _base_ready(self, t: float) -> bool:
        """Epoch t's VRS is here, and its 4001 bound too when the stream carries them (it follows the MSM;
        a TCP read may split them, and without it the epoch's PLs would be infinite)."""
        return round(t, 3) in self.bases and (not self.base_dec.bounds.receiving or self.base_dec.bounds.has_epoch(t))

    async def tick(self) -> None:
        """Release rover epochs whose VRS never came (centre down, no session yet)."""
        while True:
            await asyncio.sleep(0.25)
            try:
                self._drain(gtime.now_gpst())
            except Exception:  # noqa: BLE001 - one bad epoch must not stop the train
                self.stats.errors += 1

    # --- processing ----------------------------------------------------------------------------------

    def _ensure_unit(self) -> OnboardUnit | None:
        if self.unit is None:
            nav: NavigationData = self.nav_source()
            if nav is None or len(nav) == 0:
                return None
            base = self.base_dec.base_position_m
            self.unit = OnboardUnit(nav, base if base is not None else np.zeros(3), self.track_db, self.sink)
        return self.unit

    def _update_base(self, unit: OnboardUnit) -> None:
        p, sid = self.base_dec.base_position_m, self.base_dec.station_id
        if p is None:
            return
        if self.base_position is None or sid != self.base_station_id:
            if self.base_position is not None:
                self.stats.base_resets += 1
            # a new base: the filter restarts; DF141 says whether it is a VRS (its atmosphere modelled)
            unit.set_base_position(p, non_physical=self.base_dec.base_non_physical)
        elif not np.allclose(p, self.base_position, atol=1e-3):
            unit.rtk.base_position_m = np.asarray(p, float)  # the same VRS moved: ambiguities carry over
            self.stats.base_moves += 1
        self.base_position, self.base_station_id = np.asarray(p, float), sid

    def _process(self, rover: EpochObs, arrived: float) -> None:
        unit = self._ensure_unit()
        if unit is None:
            return
        try:
            self._update_base(unit)
            base = self.bases.get(round(rover.time, 3), self.last_base if self.base_position is not None else None)
            out = unit.step(rover, base, self.base_dec.bounds)  # the 4001 bounds, when its mountpoint sends them
        except Exception:  # noqa: BLE001 - the processing loop never dies on data
            self.stats.errors += 1
            return
        self.last = out
        self.stats.epochs += 1
        self.stats.by_status[out.solution.status_name] += 1
        if self._t_first is None:
            self._t_first = rover.time
        if out.solution.status == Status.FIX and self.stats.first_fix_s is None:
            self.stats.first_fix_s = rover.time - self._t_first
        self.stats.balises.extend(out.balises)
        if out.match is not None and out.match.track:
            self.stats.along_pl_m.append(out.match.along_pl_m)
            self.stats.cross_pl_m.append(out.match.cross_pl_m)
            self.stats.correction_along_m.append(out.match.correction_along_m)
        if self.timer is not None:
            self._feed_timer(out)
        if self.on_output is not None:
            self.on_output(self, out)

    # --- the balise timer (its clock: GPST, as the rover's epochs) ---------------------------------------

    def _feed_timer(self, out: UnitOutput) -> None:
        """This epoch's map-matched fix (chainage, PL) and the speed from the last one into the timer; then
        the timer acts on whatever is due by now and is set for its next moment."""
        m, t = out.match, out.solution.time
        if m is not None and m.track and math.isfinite(m.along_pl_m) and out.solution.status != Status.NONE:
            along = m.km * 1000.0
            prev = self._last_fix_along
            self._last_fix_along = (t, m.track, along)
            sigma = m.along_sigma_m  # the PL carries fault bounds: not PL / K (decision 0253)
            if prev is not None and prev[1] == m.track and 0.0 < t - prev[0] <= MAX_SPEED_BASE_S:
                dt = t - prev[0]
                # speed from two fixes, variance of their difference (as the scenario runner's timer)
                self.timer.update(t, m.track, along, (along - prev[2]) / dt, sigma ** 2, 2.0 * sigma ** 2 / dt ** 2)
                self.stats.timer_updates += 1
        self._tick_timer()

    def _tick_timer(self) -> None:
        if self.timer is None:
            return
        if self._timer_handle is not None:  # one pending moment at a time: the newest estimate's
            self._timer_handle.cancel()
            self._timer_handle = None
        now = gtime.now_gpst()
        try:
            self.timer.tick(now)
        except Exception:  # noqa: BLE001 - the train carries on; counted
            self.stats.errors += 1
        due = [d for d in self.timer.due_times() if d > now]
        if due:
            try:
                loop = asyncio.get_running_loop()
            except RuntimeError:  # not on a loop (a test stepping the train): the next epoch ticks it
                return
            self._timer_handle = loop.call_later(min(due) - now, self._tick_timer)

    def _gga(self) -> str | None:
        return self.last.gga if self.last is not None and self.last.gga else None

    # --- what the console shows -----------------------------------------------------------------------

    def protection_levels(self) -> tuple[float | None, float | None]:
        """Horizontal and vertical protection levels [m] from the solution covariance at the
        integrity risk (Gaussian overbound of the largest horizontal axis and of the vertical)."""
        if self.last is None:
            return None, None
        sol = self.last.solution
        cov = np.asarray(sol.covariance_m2, float)
        p = np.asarray(sol.position_m, float)
        if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(p))):
            return None, None
        llh = ecef_to_geodetic(p)
        r = enu_rotation(llh[0], llh[1])
        c = r @ cov @ r.T
        h = float(np.sqrt(max(np.linalg.eigvalsh(c[:2, :2])[-1], 0.0)))
        return self.k_h * h, self.k_h * float(np.sqrt(max(c[2, 2], 0.0)))

    def correction_age_s(self) -> float | None:
        """The age of the corrections the last solution used; None when it used none (before any came, or
        a single-point solution), as the GGA's age field (onboard/nmea.py), never a 0.0 that means nothing."""
        if self.last is None or self.stats.vrs_epochs == 0 or not math.isfinite(self.last.solution.age_s) \
                or self.last.solution.status not in (Status.FIX, Status.FLOAT):
            return None
        return float(self.last.solution.age_s)

    # --- life cycle ---------------------------------------------------------------------------------

    def start(self) -> None:
        self._ticker = asyncio.ensure_future(self.tick())

    async def stop(self) -> None:
        if self._timer_handle is not None:
            self._timer_handle.cancel()
            self._timer_handle = None
        self.client.stop()
        tasks = [t for t in (self._client_task, self._ticker) if t is not None]
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

"""The running network's stations follow the store's station registry (issue 19, decision 0240).

The store is the one source of truth for stations as for caster users and mountpoints (decision 0180): a
station an operator adds in the console joins the running network, one deleted leaves it, new coordinates
restart its baselines, a disabled one's data stops reaching the solution. `plan_membership` compares what
the centre runs with the registry (a pure function); `StationSync` applies the plan to the centre and to
the caster's taps (each member's mountpoint feeds the centre), on three triggers:

- `poke()`, thread-safe: the console of this process committed a station change (its route hook);
- a change event on `STATIONS_CONFIG_SUBJECT` (a console of another process, `augnet.bus.config_events`);
- every `RECONCILE_S`, the safety net for a missed event.

Applying writes nothing to the store: the console audited the change when it made it. A change the centre
refuses (a position off the Earth, the network's last station) is logged and counted, and retried at the
next reconcile, so an operator's later fix takes effect.
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import contextlib
import logging
import math
import time
from dataclasses import dataclass
from typing import Callable

from sqlalchemy.orm import Session, sessionmaker

from augnet.bus import Bus, BusError
from augnet.bus.config_events import STATIONS_CONFIG_SUBJECT, decode_change
from augnet.system import persistence
from augnet.system.persistence import StationRecord

log = logging.getLogger(__name__)

RECONCILE_S = 5.0  # a missed change event is caught up this often (one read of a small table)
MOVE_THRESHOLD_M = 1e-4  # coordinates closer than this are the same (the store keeps floats; API rounding)
APPLIED_LOG = 256  # applied changes remembered with their times (statistics, tests)
SUBSCRIPTION_PENDING = 1000  # events queued before the oldest are dropped (a reconcile catches up anyway)


@dataclass(frozen=True, slots=True)
class MembershipStep:
    action: str  # "add" | "remove" | "move" | "enable" | "disable" | "retap"
    code: str
    record: StationRecord | None  # the registry's record (None for "remove")


def plan_membership(running: dict[str, StationRecord], registry: dict[str, StationRecord]) -> list[MembershipStep]:
    """The steps that take the network from `running` to `registry`: removals first (a station re-added under
    another code at the same place must find it free), then moves, additions, enabled flags and mountpoints."""
    steps = [MembershipStep("remove", code, None) for code in sorted(running.keys() - registry.keys())]
    for code in sorted(registry):
        new, old = registry[code], running.get(code)
        if old is None:
            steps.append(MembershipStep("add", code, new))
            if not new.enabled:
                steps.append(MembershipStep("disable", code, new))
            continue
        if math.dist(new.xyz_m, old.xyz_m) > MOVE_THRESHOLD_M:
            steps.append(MembershipStep("move", code, new))
        if new.enabled != old.enabled:
            steps.append(MembershipStep("enable" if new.enabled else "disable", code, new))
        if new.mountpoint != old.mountpoint:
            steps.append(MembershipStep("retap", code, new))
    order = {"remove": 0, "move": 1, "add": 2, "enable": 3, "disable": 3, "retap": 4}
    return sorted(steps, key=lambda s: order[s.action])


@dataclass(frozen=True, slots=True)
class AppliedStep:
    step: MembershipStep
    trigger: str  # "change" (a poke or a bus event) | "reconcile"
    received_at: float  # the sync's clock when the trigger came
    applied_at: float  # ... when the centre had the step


class StationSync:
    """Keeps `centre`'s stations (a `CentreService` or anything with its membership methods) and the caster's
    taps equal to the store's registry (see the module's docstring). Runs on the caster's event loop; the
    store is read on a thread of its own."""

    def __init__(self, centre, caster, sessions: sessionmaker[Session], bus: Bus | None = None,
                 reconcile_s: float = RECONCILE_S, clock: Callable[[], float] = time.monotonic,
                 on_applied: Callable[[MembershipStep], None] | None = None):
        self.centre = centre
        self.on_applied = on_applied  # each applied step (the live state's station list follows them)
        self.caster = caster
        self.sessions = sessions
        self.bus = bus
        self.reconcile_s = reconcile_s
        self.clock = clock
        self.running: dict[str, StationRecord] = {}  # what the centre has now
        self.events = 0  # change events received
        self.bad_events = 0
        self.refreshes = 0  # registry reads applied
        self.failures = 0  # reads or steps that failed (retried at the next reconcile)
        self.applied: collections.deque[AppliedStep] = collections.deque(maxlen=APPLIED_LOG)
        self._untap: dict[str, Callable[[], None]] = {}  # member -> removes its caster tap
        self._reader = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="augnet-stations")
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wake: asyncio.Event | None = None
        self._task: asyncio.Task | None = None
        self._tasks: list[asyncio.Task] = []
        self._sub = None

    # --- the registry the centre was built from ---------------------------------------------------------

    def adopt(self, records: dict[str, StationRecord]) -> None:
        """The centre was built from `records` (its enabled flags applied too): tap each member's mountpoint."""
        self.running = dict(records)
        for code, rec in records.items():
            if not rec.enabled:
                self.centre.set_station_enabled(code, False)
            self._tap(rec)

    def read(self) -> dict[str, StationRecord]:
        with self.sessions() as s:
            return persistence.station_records(s)

    # --- applying ---------------------------------------------------------------------------------------

    def apply(self, registry: dict[str, StationRecord], trigger: str = "reconcile",
              received_at: float | None = None) -> list[MembershipStep]:
        """Take the centre to `registry`; returns the steps applied (a refused one is logged and left out)."""
        received_at = self.clock() if received_at is None else received_at
        done = []
        for step in plan_membership(self.running, registry):
            try:
                self._apply(step)
            except ValueError as exc:  # refused by the centre (a bad position, its last station): retried later
                self.failures += 1
                log.warning("station %s: %s not applied: %s", step.code, step.action, exc)
                continue
            done.append(step)
            self.applied.append(AppliedStep(step, trigger, received_at, self.clock()))
            if self.on_applied is not None:
                try:
                    self.on_applied(step)
                except Exception:  # noqa: BLE001 - what the operator sees must not undo the network's change
                    log.exception("station %s: %s applied, its observer failed", step.code, step.action)
        for code, rec in self.running.items():  # a mountpoint that was missing may exist now
            if code not in self._untap:
                self._tap(rec)
        return done

    def _apply(self, step: MembershipStep) -> None:
        c, rec = self.centre, step.record
        if step.action == "remove":
            c.remove_station(step.code)
            self._drop_tap(step.code)
            del self.running[step.code]
            log.info("station %s left the network (registry)", step.code)
            return
        if step.action == "add":
            c.add_station(step.code, rec.xyz_m)
            self.running[step.code] = rec
            self._tap(rec)
            log.info("station %s joined the network (registry)", step.code)
            return
        if step.action == "move":
            c.move_station(step.code, rec.xyz_m)
            log.warning("station %s moved (registry): its baselines restart", step.code)
        elif step.action in ("enable", "disable"):
            c.set_station_enabled(step.code, step.action == "enable")
        elif step.action == "retap":
            self._drop_tap(step.code)
            self._tap(rec)
        self.running[step.code] = rec

    def _tap(self, rec: StationRecord) -> None:
        if self.caster is None or rec.code in self._untap:
            return
        try:
            self._untap[rec.code] = self.caster.tap(rec.mountpoint,
                                                    lambda data, code=rec.code: self.centre.feed(code, data))
        except ValueError:  # no source mountpoint of that name (yet): its data does not reach the centre
            log.warning("station %s: no source mountpoint %s in the caster; its data does not reach the centre",
                        rec.code, rec.mountpoint)

    def _drop_tap(self, code: str) -> None:
        untap = self._untap.pop(code, None)
        if untap is not None:
            untap()

    async def refresh(self, trigger: str = "reconcile", received_at: float | None = None) -> bool:
        """Read the registry and apply it; False (logged, counted) when the read failed."""
        try:
            registry = await asyncio.get_running_loop().run_in_executor(self._reader, self.read)
        except Exception:  # noqa: BLE001 - a store outage leaves the network as it is
            self.failures += 1
            log.exception("station registry not read from the store")
            return False
        self.apply(registry, trigger, received_at)
        self.refreshes += 1
        return True

    # --- triggers ---------------------------------------------------------------------------------------

    def poke(self) -> None:
        """The registry changed (callable from any thread: the console's routes run on a thread pool)."""
        loop, wake = self._loop, self._wake
        if loop is None or wake is None:
            return
        with contextlib.suppress(RuntimeError):  # the loop is closed: the run is over
            loop.call_soon_threadsafe(wake.set)

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        if self.bus is not None:
            self._sub = await self.bus.subscribe(STATIONS_CONFIG_SUBJECT, max_pending=SUBSCRIPTION_PENDING)
            self._tasks.append(asyncio.ensure_future(self._events()))
        self._task = asyncio.ensure_future(self._run())

    async def _events(self) -> None:
        """Change events from the bus wake the sync (what changed is read from the store, not the event)."""
        while True:
            try:
                msg = await self._sub.next(timeout=None)
            except BusError:  # the subscription closed: the bus is going away
                return
            except (asyncio.TimeoutError, TimeoutError):
                continue
            self.events += 1
            try:
                decode_change(msg.payload)
            except ValueError as exc:
                self.bad_events += 1
                log.warning("ignored on %s: %s", STATIONS_CONFIG_SUBJECT, exc)
                continue
            self._wake.set()

    async def _run(self) -> None:
        while True:
            trigger = "reconcile"
            try:
                await asyncio.wait_for(self._wake.wait(), self.reconcile_s)
                trigger = "change"
            except asyncio.TimeoutError:
                pass
            received = self.clock()
            self._wake.clear()
            await self.refresh(trigger, received)

    async def stop(self) -> None:
        for task in [self._task, *self._tasks]:
            if task is not None:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
        if self._sub is not None:
            with contextlib.suppress(Exception):
                await self._sub.close()
        self._reader.shutdown(wait=False, cancel_futures=True)

    def stats(self) -> dict:
        return {"events": self.events, "bad_events": self.bad_events, "refreshes": self.refreshes,
                "failures": self.failures, "members": len(self.running)}

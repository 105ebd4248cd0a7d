"""The running caster's users and mountpoints, from the store (issue 19, decision 0180).

The store is the one source of truth: `caster_tables` reads it into the caster's own types (users, the
disabled ones left out; mountpoints with their enabled flag, station positions from the station registry,
the rest of each STR record from the scenario's description). `CasterAccessSync` keeps a running caster
in step: it re-reads the store on every change event the console publishes (`augnet.bus.config_events`)
and, as a safety net for a missed event, every `RECONCILE_S`. Applying writes nothing to the store: the
console audited the change when it made it.

The caster core never sees the store: it takes whole tables (`Caster.set_users`, `Caster.set_mounts`).
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import contextlib
import logging
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from augnet.bus import Bus, BusError
from augnet.bus.config_events import CASTER_CONFIG_SUBJECT, CasterChange, decode_change
from augnet.gnss.geometry import ecef_to_geodetic
from augnet.store.models import CasterUser, Mountpoint, Station
from ntrip_caster.auth import User
from ntrip_caster.config import MOUNT_KINDS, MountConfig
from ntrip_caster.server import Caster

log = logging.getLogger(__name__)

# A missed change event is caught up this often: one read of three small tables (ms for a line's
# hundreds of rows), so cheap enough to do every few seconds.
RECONCILE_S = 5.0
APPLIED_LOG = 256  # change events remembered with their receive and apply times (statistics, tests)
SUBSCRIPTION_PENDING = 1000  # events queued before the oldest are dropped (a reconcile catches up anyway)


def split_groups(value: str | None) -> frozenset[str]:
    """The store's comma-separated groups as a set ("" = no group: nobody, unless the value is "*")."""
    return frozenset(g.strip() for g in (value or "").split(",") if g.strip())


def caster_tables(s: Session, described: dict[str, MountConfig]) -> tuple[dict[str, User], list[MountConfig]]:
    """The store's caster users (enabled ones) and mountpoints, as the caster takes them. `described`:
    the scenario's mountpoints by name, for the STR fields the store does not keep (identifier, network,
    systems); a station's position comes from the station registry. A row the caster cannot take (an
    unknown kind) is logged and left out."""
    users = {u.name: User(u.name, u.password_hash, split_groups(u.groups))
             for u in s.scalars(select(CasterUser).where(CasterUser.enabled.is_(True)))}
    where = {st.mountpoint: (st.x_m, st.y_m, st.z_m) for st in s.scalars(select(Station))}
    mounts = []
    for mp in s.scalars(select(Mountpoint).order_by(Mountpoint.name)):
        if mp.kind not in MOUNT_KINDS:
            log.warning("mountpoint %s in the store has kind %r (not one of %s): not served", mp.name, mp.kind,
                        MOUNT_KINDS)
            continue
        base = described.get(mp.name)
        fields = dict(base.str_fields) if base is not None else {}
        fields["format"] = mp.format
        if mp.name in where:
            lat, lon = np.degrees(ecef_to_geodetic(np.asarray(where[mp.name], dtype=float))[:2])
            fields.update(latitude=round(float(lat), 4), longitude=round(float(lon), 4))
        mounts.append(MountConfig(mp.name, mp.kind, split_groups(mp.read_groups), split_groups(mp.write_groups),
                                  fields, base.factory if base is not None else None,
                                  base.bases if base is not None else (), bool(mp.enabled)))
    return users, mounts


def bound_mounts(s: Session) -> frozenset[str]:
    """The enabled mountpoints whose VRS streams carry the correction-error bound (RTCM 4001, decision 0281):
    the centre's business, not the caster core's, so kept out of `MountConfig`."""
    return frozenset(s.scalars(select(Mountpoint.name).where(Mountpoint.correction_bound.is_(True),
                                                              Mountpoint.enabled.is_(True))))


@dataclass(frozen=True, slots=True)
class AppliedChange:
    change: CasterChange | None  # None: a periodic reconcile
    received_at: float  # the sync's clock when the event arrived
    applied_at: float  # ... when the caster had the new tables


class CasterAccessSync:
    """Keeps `caster`'s users and mountpoints equal to the store's (see the module's docstring). Runs on
    the caster's event loop; the store is read on a thread of its own."""

    def __init__(self, caster: Caster, sessions: sessionmaker[Session], described: dict[str, MountConfig],
                 bus: Bus | None = None, reconcile_s: float = RECONCILE_S,
                 clock: Callable[[], float] = time.monotonic,
                 on_bound_mounts: Callable[[frozenset[str]], None] | None = None):
        self.caster = caster
        # told the store's correction-bound mountpoints at every apply (on the loop): the VRS stream factory
        self.on_bound_mounts = on_bound_mounts
        self.bound: frozenset[str] = frozenset()
        self.sessions = sessions
        self.described = dict(described)
        self.bus = bus
        self.reconcile_s = reconcile_s
        self.clock = clock
        self.events = 0  # change events received
        self.bad_events = 0  # payloads that were not a change event (logged, ignored)
        self.refreshes = 0  # store reads applied to the caster
        self.failures = 0  # store reads or applies that failed (the caster keeps its tables)
        self.applied: collections.deque[AppliedChange] = collections.deque(maxlen=APPLIED_LOG)
        self._reader = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="augnet-caster-access")
        self._task: asyncio.Task | None = None
        self._sub = None

    def read(self) -> tuple[dict[str, User], list[MountConfig]]:
        """The store's tables now (blocking: call it off the loop, or before the caster runs)."""
        return self._read_all()[:2]

    def _read_all(self) -> tuple[dict[str, User], list[MountConfig], frozenset[str]]:
        with self.sessions() as s:
            return (*caster_tables(s, self.described), bound_mounts(s))

    async def refresh(self) -> bool:
        """Read the store and hand the caster its tables; False (logged, counted) when the read failed."""
        try:
            users, mounts, bound = await asyncio.get_running_loop().run_in_executor(self._reader, self._read_all)
        except Exception:  # noqa: BLE001 - a store outage leaves the caster as it was, not down
            self.failures += 1
            log.exception("caster tables not read from the store")
            return False
        try:
            self.caster.set_mounts(mounts)
            revoked = self.caster.set_users(users)
            if self.on_bound_mounts is not None:
                self.on_bound_mounts(bound)
            self.bound = bound
        except Exception:  # noqa: BLE001 - a bad row or a bug must not end the sync task: logged, retried
            self.failures += 1
            log.exception("caster tables not applied")
            return False
        if revoked:
            log.info("caster users revoked: %s", ", ".join(sorted(revoked)))
        self.refreshes += 1
        return True

    async def start(self) -> None:
        """Subscribe to change events (when there is a bus) and start the apply / reconcile task."""
        if self.bus is not None:
            self._sub = await self.bus.subscribe(CASTER_CONFIG_SUBJECT, max_pending=SUBSCRIPTION_PENDING)
        self._task = asyncio.ensure_future(self._run())

    async def _next_changes(self) -> tuple[list[CasterChange], float]:
        """The change events that arrived, waiting at most `reconcile_s` ([] after a quiet period), every
        one queued taken at once (one store read applies them together); and when the first arrived."""
        if self._sub is None:
            await asyncio.sleep(self.reconcile_s)
            return [], self.clock()
        changes: list[CasterChange] = []
        first_at = None
        timeout = self.reconcile_s
        while True:
            try:
                msg = await self._sub.next(timeout=timeout)
            except (asyncio.TimeoutError, TimeoutError):
                return changes, first_at if first_at is not None else self.clock()
            if first_at is None:
                first_at = self.clock()
            self.events += 1
            try:
                changes.append(decode_change(msg.payload))
            except ValueError as exc:
                self.bad_events += 1
                log.warning("ignored on %s: %s", CASTER_CONFIG_SUBJECT, exc)
            timeout = 0  # drain what is queued, then apply

    async def _run(self) -> None:
        while True:
            try:
                changes, received = await self._next_changes()
            except BusError:  # subscription closed: the bus is going away
                return
            if await self.refresh():
                done = self.clock()
                for c in changes or [None]:
                    self.applied.append(AppliedChange(c, received, done))

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._task
        if self._sub is not None:
            with contextlib.suppress(Exception):
                await self._sub.close()
        self._reader.shutdown(wait=False, cancel_futures=True)

    def stats(self) -> dict:
        return {"events": self.events, "bad_events": self.bad_events, "refreshes": self.refreshes,
                "failures": self.failures}


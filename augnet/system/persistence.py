"""What `augnet up` writes to the store: the configuration it runs (stations, mountpoints, caster users,
trains), train sessions, alarms raised and cleared by the centre, and the network quality history.

Every write runs on one worker thread (`StoreWriter`), in order, so the event loop carrying the caster's
sockets never waits for the database; a failed write is logged and counted, never raised into the loop.
"""

from __future__ import annotations

import concurrent.futures
import datetime as dt
import logging
from dataclasses import dataclass
from typing import Callable

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from augnet.store import queries, series
from augnet.store.models import AuditEntry, CasterUser, Mountpoint, Severity, Station, Train, TrainSession, utcnow
from augnet.system.baseline_quality import quality_rows
from augwire.passwords import verify_password
from ntrip_caster.config import CasterConfig

log = logging.getLogger(__name__)

SYSTEM_ACTOR = "system"  # audit-log actor for what the running system itself records
SEED_ACTION = "caster.seed"  # the audit entry that marks a store's caster configuration as seeded
STATIONS_SEED_ACTION = "stations.seed"  # ... and its station registry
QUALITY_INTERVAL_S = 10.0  # one quality-history row per baseline this often


class StoreWriter:
    def __init__(self, sessions: sessionmaker[Session]):
        self.sessions = sessions
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="augnet-store")
        self.failures = 0
        self.writes = 0

    def submit(self, fn: Callable[[Session], object]) -> concurrent.futures.Future:
        return self._pool.submit(self._run, fn)

    def _run(self, fn: Callable[[Session], object]):
        try:
            with self.sessions.begin() as s:
                out = fn(s)
            self.writes += 1
            return out
        except Exception:  # noqa: BLE001 - the store failing must not take the system down
            self.failures += 1
            log.exception("store write failed")
            return None

    def close(self, timeout: float = 10.0) -> None:
        self._pool.shutdown(wait=True, cancel_futures=False)


# --- the running configuration -------------------------------------------------------------------------

def register_station(s: Session, code: str, name: str, xyz_m, rtcm_id: int, mountpoint: str) -> bool:
    """Add the station if the store does not know it; returns its enabled flag (an operator may have
    disabled it in an earlier run: that decision stands)."""
    st = s.scalar(select(Station).where(Station.code == code))
    if st is None:
        st = queries.add_station(s, SYSTEM_ACTOR, code, tuple(float(v) for v in xyz_m), rtcm_id, mountpoint, name)
        s.flush()  # the column default (enabled) is applied at the INSERT: before it, st.enabled is None
    return bool(st.enabled)


def join_groups(groups) -> str:
    """The store's spelling of a set of caster groups: comma separated, sorted."""
    return ",".join(sorted(groups))


def seed_caster(s: Session, cfg: CasterConfig) -> bool:
    """Seed the store's caster users and mountpoints from the scenario's `cfg`, once per store: only
    while neither table has a row and no seed was recorded (decision 0180: the store is the one source
    of truth; a row an operator changed or deleted is never rewritten or brought back). One audit entry
    under the system actor records the seed, or that a store configured before had none. True: seeded."""
    if s.scalar(select(AuditEntry.id).where(AuditEntry.action == SEED_ACTION).limit(1)) is not None:
        return False
    if s.scalar(select(CasterUser.id).limit(1)) is not None or s.scalar(select(Mountpoint.id).limit(1)) is not None:
        queries.audit(s, SYSTEM_ACTOR, SEED_ACTION, "caster", seeded=False, reason="store already configured")
        return False
    for u in cfg.users.values():
        s.add(CasterUser(name=u.name, password_hash=u.password_hash, groups=join_groups(u.groups)))
    for m in cfg.mounts:
        s.add(Mountpoint(name=m.name, kind=m.kind, format=m.str_record().format, read_groups=join_groups(m.read),
                         write_groups=join_groups(m.write)))
    queries.audit(s, SYSTEM_ACTOR, SEED_ACTION, "caster", seeded=True, users=sorted(cfg.users),
                  mountpoints=[m.name for m in cfg.mounts])
    return True


def own_account_password(s: Session, name: str, known: str | None, fresh: str, fresh_hash: str) -> str | None:
    """The password the run's own parts (its stations, its trains) log in with as caster user `name`:
    `known` (the last state file's) while the store's hash still takes it; else, when no operator ever
    changed the account (only the system wrote it), the run rotates it to `fresh` (audited under the
    system actor). None: the account is missing, or an operator changed it -- their word stands, and the
    run's parts are refused like anybody else (decision 0180)."""
    u = s.scalar(select(CasterUser).where(CasterUser.name == name))
    if u is None:
        return None
    if known is not None and verify_password(known, u.password_hash):
        return known
    touched = s.scalar(select(AuditEntry.id).where(AuditEntry.target == name, AuditEntry.actor != SYSTEM_ACTOR,
                                                   AuditEntry.action.startswith("caster_user.")).limit(1))
    if touched is not None:
        return None
    u.password_hash = fresh_hash
    queries.audit(s, SYSTEM_ACTOR, "caster_user.rotate", name, reason="password not in the state file")
    return fresh


def open_train_session(s: Session, code: str, mountpoint: str) -> int:
    tr = s.scalar(select(Train).where(Train.code == code))
    if tr is None:
        tr = Train(code=code)
        s.add(tr)
        s.flush()
    ts = TrainSession(train_id=tr.id, mountpoint=mountpoint)
    s.add(ts)
    s.flush()
    return ts.id


def close_train_session(s: Session, session_id: int, bytes_sent: int, fix_rate: float | None) -> None:
    ts = s.get(TrainSession, session_id)
    if ts is not None:
        ts.ended_at = utcnow()
        ts.bytes_sent = int(bytes_sent)
        ts.fix_rate = fix_rate


@dataclass(frozen=True, slots=True)
class StationRecord:
    """A station as the store registers it: what the running network takes from it."""

    code: str
    xyz_m: tuple[float, float, float]  # ECEF ARP [m]
    enabled: bool
    mountpoint: str  # the caster mountpoint its stream arrives on
    rtcm_station_id: int


def station_records(s: Session) -> dict[str, StationRecord]:
    """Every registered station by code."""
    return {st.code: StationRecord(st.code, (float(st.x_m), float(st.y_m), float(st.z_m)), bool(st.enabled),
                                   st.mountpoint, int(st.rtcm_station_id))
            for st in s.scalars(select(Station).order_by(Station.code))}


def seed_stations(s: Session, stations) -> bool:
    """Register the scenario's `stations` (receivers: id, ecef, rtcm_id; mountpoint named by `mountpoint_of`)
    once per store, while it has no station and no seed was recorded: afterwards the registry alone decides
    (a station an operator deleted stays deleted, even when every one was). True: seeded."""
    from stations.live import mountpoint_of

    if s.scalar(select(AuditEntry.id).where(AuditEntry.action == STATIONS_SEED_ACTION).limit(1)) is not None:
        return False
    seeded = s.scalar(select(Station.id).limit(1)) is None
    for rx in stations if seeded else ():
        register_station(s, rx.id, rx.id, rx.ecef[0], rx.rtcm_id, mountpoint_of("station", rx.id))
    queries.audit(s, SYSTEM_ACTOR, STATIONS_SEED_ACTION, "stations", seeded=seeded,
                  stations=[rx.id for rx in stations] if seeded else [])
    s.flush()
    return seeded


def record_quality_batch(s: Session, at: dt.datetime, rows: list[tuple[str, float, float | None, int]],
                         values: dict[str, float] | None = None) -> None:
    """The baselines' rows and the network's series values (augnet.store.series) of one history instant."""
    for subject, fixed, rms, sats in rows:
        queries.record_quality(s, at, subject, fixed, rms, sats)
    for subject, value in (values or {}).items():
        series.record_series(s, at, subject, value)


# --- what the running network reports ------------------------------------------------------------------

class AlarmRecorder:
    """The centre's alarms into the store: an alarm (kind, subject) is raised once and stays open until the
    centre clears it. `log` keeps every raise of the run, for the terminal view and the run report."""

    def __init__(self, writer: StoreWriter):
        self.writer = writer
        self._open: set[tuple[str, str]] = set()
        self.log: list[dict] = []

    def record(self, kind: str, subject: str, severity: str, message: str, cleared: bool,
               on_stored: Callable[[], None] | None = None) -> bool:
        """Store a raise or a clear; True when this call raised a new alarm. `on_stored()` runs on the
        store's thread once the raise or clear is committed (the console's pages then read it at once)."""
        key = (kind, subject)
        if cleared:
            if key in self._open:
                self._open.discard(key)
                self._submit(lambda db: queries.clear_alarm(db, kind, subject), on_stored)
            return False
        if key in self._open:
            return False
        self._open.add(key)
        self.log.append({"kind": kind, "subject": subject, "severity": severity, "message": message,
                         "at_utc": dt.datetime.now(dt.timezone.utc).isoformat()})
        sev = Severity(severity) if severity in {m.value for m in Severity} else Severity.WARNING
        self._submit(lambda db: queries.raise_alarm(db, kind, subject, sev, message), on_stored)
        return True

    def _submit(self, fn: Callable[[Session], object], on_stored: Callable[[], None] | None) -> None:
        def write(db: Session) -> bool:
            fn(db)
            return True  # StoreWriter returns None for a failed write: then nobody is told

        future = self.writer.submit(write)
        if on_stored is not None and future is not None:
            future.add_done_callback(lambda f: f.result() and on_stored())


class QualityHistory:
    """The network's baselines and its series (correction age p99, trains fixed, station data age: decision
    0185) into the quality history, one row each every `interval_s`."""

    def __init__(self, writer: StoreWriter, interval_s: float = QUALITY_INTERVAL_S):
        self.writer = writer
        self.interval_s = interval_s
        self._last_unix = 0.0

    def on_epoch(self, network, now_unix: float,
                 series_values: Callable[[], dict[str, float]] | None = None) -> None:
        """`network` is the epoch's `NetworkEpoch`; rows are written when `interval_s` has passed, with
        `series_values()` (asked only then) giving the series' values {subject: value}."""
        if now_unix - self._last_unix < self.interval_s:
            return
        self._last_unix = now_unix
        at = dt.datetime.fromtimestamp(now_unix, dt.timezone.utc).replace(microsecond=0, tzinfo=None)
        rows = quality_rows(network)
        values = series_values() if series_values is not None else {}
        self.writer.submit(lambda db: record_quality_batch(db, at, rows, values))

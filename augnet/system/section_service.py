"""The centre's train information per section in `augnet up`: the trains' position reports in, the
section register kept from them, its picture out to the store and to the RBC (decision 0292).

    trains --PositionReport datagrams (UDP, the train's radio link)--> SectionService.on_datagram
    SectionService --SectionRegister (insert / remove / update / admit)--> take_dirty()
    runtime, every SECTION_FLUSH_S: dirty sections -> store (section_trains) and RBC (SECTION_TRAINS)

Transitions, judged from a train's reports against the line's layout (sections between station areas):
- a train in a section whose report is past the section's exit: the exit station removes it (refused while
  another train is in front of it, retried with the next report); it is then in that station (or off the
  line at a line end);
- a train in a station whose report is inside the section beyond it, in its direction: the station
  inserts it at the section's entry;
- a train first seen inside a section (switched on there, or the centre restarted): admitted where its
  chainage puts it, on the start-of-mission authority the service is given (audited like a dispatcher's
  action); without one it waits, counted, for a dispatcher.
Here the centre acts for the stations from the trains' own reports; on a real line the station's
interlocking confirms the departure and the arrival. A refused change raises one alarm per train and rule.
"""

from __future__ import annotations

import asyncio
import collections
import dataclasses
import logging
from dataclasses import dataclass
from typing import Callable

from augnet.onboard.position_report import (DEFAULT_TRAIN_LENGTH_M, PositionReport, ReportBuilder, ReportError,
                                            decode, encode)
from augnet.system.section_register import (BOUNDARY_ZONE_M, DIRECTIONS, LINE_END, AuditRecord, Authority,
                                            LineSection, RegisterError, SectionRegister, TrainRecord, line_sections)
from rssp1.messages import UNKNOWN_U16, UNKNOWN_U32, SectionTrain, SectionTrains, TrainIntegrity

log = logging.getLogger(__name__)

SECTION_FLUSH_S = 1.0  # the register's changes reach the store and the RBC this often (one report period)
START_OF_MISSION = Authority("start-of-mission", "dispatcher")  # `augnet up`'s admission of its own trains
MAX_EVENTS = 1000  # transitions kept for the console and the run report
ALARM_KIND = "section-register-refused"


@dataclass(frozen=True)
class StationArea:
    name: str
    km_begin: float
    km_end: float


@dataclass(frozen=True)
class SectionEvent:
    time_s: float  # GPS time of the report that caused it
    train_id: str
    action: str  # insert, remove, admit
    section_id: int
    direction: str
    by: str  # the station (or line end) acting, or the authority's name


def stations_of(scenario) -> list[StationArea]:
    """A scenario line's station areas (`stations.scenario.StationArea`: name, start and end km)."""
    return [StationArea(s.name, s.start_km, s.end_km) for s in scenario.line.stations] if scenario.line else []


def record_of(r: PositionReport) -> TrainRecord:
    return TrainRecord(r.train_id, r.track, r.km, r.speed_m_s, r.length_m, r.integrity, r.correction_age_s,
                       r.along_pl_m, r.cross_pl_m, r.hpl_m, r.time_s)


class SectionService:
    def __init__(self, stations: list[StationArea], line_length_km: float, *,
                 start_authority: Authority | None = START_OF_MISSION,
                 on_audit: Callable[[AuditRecord], None] | None = None,
                 on_alarm: Callable[[str, str, str, str, bool], None] | None = None):
        self.stations = sorted(stations, key=lambda s: s.km_begin)
        self.register = SectionRegister(line_sections([(s.name, s.km_begin, s.km_end) for s in self.stations],
                                                      line_length_km))
        self.start_authority = start_authority
        self.on_audit = on_audit
        self.on_alarm = on_alarm
        self.last: dict[str, PositionReport] = {}
        self.in_station: dict[str, tuple[str, str]] = {}  # train -> (station, track)
        self.events: collections.deque[SectionEvent] = collections.deque(maxlen=MAX_EVENTS)
        self.stats: collections.Counter[str] = collections.Counter()
        self._dirty: set[tuple[int, str]] = set(self.register.queues)  # the first flush sends every section
        self._alarmed: set[tuple[str, str]] = set()  # (train, refusal code) with an open alarm
        self._held: set[str] = set()  # withdrawn by a dispatcher: only a dispatcher (or a station) puts it back

    @property
    def sections(self) -> dict[int, LineSection]:
        return self.register.sections

    def station_at(self, km: float) -> StationArea | None:
        return next((s for s in self.stations if s.km_begin <= km <= s.km_end), None)

    # --- input ---------------------------------------------------------------------------------------

    def on_datagram(self, data: bytes) -> None:
        try:
            report = decode(data)
        except ReportError as exc:
            self.stats["bad_reports"] += 1
            log.debug("position report refused: %s", exc)
            return
        self.on_report(report)

    def on_report(self, r: PositionReport) -> None:
        self.stats["reports"] += 1
        prev = self.last.get(r.train_id)
        if prev is not None and r.time_s <= prev.time_s:
            self.stats["stale_reports"] += 1  # a datagram overtaken by a newer one
            return
        self.last[r.train_id] = r
        if not r.track or r.direction not in DIRECTIONS:
            self.stats["reports_without_position"] += 1
            return
        rec = record_of(r)
        for key in self.register.release(rec):  # the track it left occupied behind it (integrity, 0293)
            self._dirty.add(key)
        at = self.register.where(r.train_id)
        if at is not None:
            q = self.register.queue(*at)
            if at[1] != r.direction:
                self._refused(RegisterError("order-conflict", f"{r.train_id} reversed inside section {at[0]}"), r)
                return
            if q.distance_to_exit_m(r.km) >= 0:
                if self._do(r, lambda: self.register.update(rec)):
                    self._dirty.add(at)
                return
            self._do(r, lambda: self.register.update(rec))  # its last place before the exit, when still near
            by = q.section.exit_station(at[1])
            if not self._do(r, lambda: self.register.remove(at[0], at[1], r.train_id, by=by)):
                return
            self._event(r, "remove", at, by)
            if by == LINE_END:
                self.in_station.pop(r.train_id, None)
                return
            self.in_station[r.train_id] = (by, r.track)
        station = self.station_at(r.km)
        if station is not None:
            self.in_station[r.train_id] = (station.name, r.track)
            return
        sec = self.register.section_at(r.km)
        if sec is None:
            self.stats["reports_off_line"] += 1
            return
        key = (sec.id, r.direction)
        entry = sec.entry_station(r.direction)
        came_from = self.in_station.get(r.train_id, (None, ""))[0]
        q = self.register.queue(*key)
        if came_from == entry or (came_from is None and entry == LINE_END
                                  and q.distance_from_entry_m(r.km) <= BOUNDARY_ZONE_M):
            if self._do(r, lambda: self.register.insert(sec.id, r.direction, rec, by=entry)):
                self.in_station.pop(r.train_id, None)
                self._held.discard(r.train_id)
                self._event(r, "insert", key, entry)
            return
        if self.start_authority is None or r.train_id in self._held:
            self.stats["waiting_for_admission"] += 1
            return
        reason = f"start of mission: first report at km {r.km:.3f} inside section {sec.id}"
        audit = self._do(r, lambda: self.register.admit(sec.id, r.direction, rec, self.start_authority, reason))
        if audit:
            self.in_station.pop(r.train_id, None)
            self._event(r, "admit", key, self.start_authority.name)
            if self.on_audit is not None:
                self.on_audit(audit)

    def _do(self, r: PositionReport, change):
        """Apply one register change; a refusal is counted and alarmed once per train and rule."""
        try:
            out = change()
        except RegisterError as exc:
            self._refused(exc, r)
            return None
        for key in [k for k in self._alarmed if k[0] == r.train_id]:
            self._alarmed.discard(key)
            if self.on_alarm is not None:
                self.on_alarm(ALARM_KIND, f"train {r.train_id}", "warning", "cleared", True)
        return out if out is not None else True

    def _refused(self, exc: RegisterError, r: PositionReport) -> None:
        self.stats[f"refused_{exc.code}"] += 1
        key = (r.train_id, exc.code)
        if key not in self._alarmed:
            self._alarmed.add(key)
            if self.on_alarm is not None:
                self.on_alarm(ALARM_KIND, f"train {r.train_id}", "warning", str(exc)[:200], False)

    def _event(self, r: PositionReport, action: str, key: tuple[int, str], by: str) -> None:
        self.events.append(SectionEvent(r.time_s, r.train_id, action, key[0], key[1], by))
        self.stats[action] += 1
        self._dirty.add(key)

    # --- dispatcher actions (the console) --------------------------------------------------------------

    def reorder(self, section_id: int, direction: str, order: list[str], authority: Authority | None,
                reason: str) -> AuditRecord:
        audit = self.register.reorder(section_id, direction, order, authority, reason)
        self._dirty.add((section_id, direction))
        return audit

    def admit(self, train_id: str, authority: Authority | None, reason: str) -> AuditRecord:
        """A train waiting for admission (reporting inside a section, in none) placed by its last report."""
        r = self.last.get(train_id)
        sec = None if r is None or r.direction not in DIRECTIONS else self.register.section_at(r.km)
        if sec is None:
            raise RegisterError("unknown-train", f"{train_id} has no report inside a section")
        audit = self.register.admit(sec.id, r.direction, record_of(r), authority, reason)
        self._held.discard(train_id)
        self.in_station.pop(train_id, None)
        self._event(r, "admit", (sec.id, r.direction), audit.actor)
        return audit

    def withdraw(self, section_id: int, direction: str, train_id: str, authority: Authority | None,
                 reason: str) -> AuditRecord:
        audit = self.register.withdraw(section_id, direction, train_id, authority, reason)
        self._held.add(train_id)
        self._dirty.add((section_id, direction))
        return audit

    def clear_behind(self, section_id: int, direction: str, train_id: str, authority: Authority | None,
                     reason: str) -> AuditRecord:
        audit = self.register.clear_behind(section_id, direction, train_id, authority, reason)
        self._dirty.add((section_id, direction))
        return audit

    def waiting(self) -> list[str]:
        """Trains reporting inside a section that the register does not hold (no start-of-mission authority,
        or withdrawn): a dispatcher admits them."""
        return sorted(t for t, r in self.last.items()
                      if self.register.where(t) is None and t not in self.in_station and r.direction in DIRECTIONS
                      and self.register.section_at(r.km) is not None and self.station_at(r.km) is None)

    # --- output ---------------------------------------------------------------------------------------

    def take_dirty(self) -> list[tuple[int, str]]:
        out, self._dirty = sorted(self._dirty), set()
        return out

    def records(self, section_id: int, direction: str) -> list[dict]:
        return [dataclasses.asdict(r) for r in self.register.trains(section_id, direction)]

    def telegram(self, section_id: int, direction: str, epoch_ms: int) -> SectionTrains:
        """The RSSP-I picture of one section and direction."""
        q = self.register.queue(section_id, direction)
        return SectionTrains(epoch_ms, section_id, DIRECTIONS.index(direction), q.version,
                             tuple(section_train(r) for r in q))

    def report(self) -> dict:
        """For the run report: counters, every transition, the final order per section and direction."""
        return {"stats": dict(self.stats), "events": [dataclasses.asdict(e) for e in self.events],
                "order": {f"{sid} {d}": list(q.ids()) for (sid, d), q in sorted(self.register.queues.items())},
                "in_station": {t: s for t, (s, _tr) in sorted(self.in_station.items())}}

    def snapshot(self) -> dict:
        return {"sections": self.register.snapshot(),
                "stations": [dataclasses.asdict(s) for s in self.stations],
                "in_station": {t: {"station": s, "track": tr} for t, (s, tr) in sorted(self.in_station.items())},
                "waiting": self.waiting(),
                "events": [dataclasses.asdict(e) for e in list(self.events)[-50:]],
                "stats": dict(self.stats)}


def _scaled(value: float | None, scale: float, unknown: int) -> int:
    return unknown if value is None else max(0, min(int(round(value * scale)), unknown - 1))


def section_train(r: TrainRecord) -> SectionTrain:
    return SectionTrain(r.train_id, r.track, int(round(r.km * 1e6)), _scaled(r.speed_m_s, 1e3, UNKNOWN_U32),
                        _scaled(r.length_m, 10, UNKNOWN_U16), TrainIntegrity[r.integrity.upper()],
                        _scaled(r.correction_age_s, 1e3, UNKNOWN_U32), _scaled(r.along_pl_m, 100, UNKNOWN_U16),
                        _scaled(r.cross_pl_m, 100, UNKNOWN_U16), _scaled(r.hpl_m, 100, UNKNOWN_U16),
                        int(round(r.time_s * 1000)))


class ReportReceiver(asyncio.DatagramProtocol):
    """The centre's end of the trains' radio link: one datagram, one report."""

    def __init__(self, service: SectionService):
        self.service = service

    def datagram_received(self, data: bytes, addr) -> None:
        try:
            self.service.on_datagram(data)
        except Exception:  # noqa: BLE001 - one bad report must not stop the receiver
            self.service.stats["errors"] += 1
            log.exception("position report failed")


class ReportSender(asyncio.DatagramProtocol):
    """A train's end: `send(bytes)` is one datagram to the centre (lost if the link is not open)."""

    def __init__(self):
        self.transport: asyncio.DatagramTransport | None = None
        self.sent = 0

    def connection_made(self, transport) -> None:
        self.transport = transport

    def send(self, data: bytes) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.sendto(data)
            self.sent += 1

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


async def open_receiver(service: SectionService, host: str = "127.0.0.1"):
    """The centre's UDP endpoint on an ephemeral port: (transport, (host, port))."""
    loop = asyncio.get_running_loop()
    transport, _ = await loop.create_datagram_endpoint(lambda: ReportReceiver(service), local_addr=(host, 0))
    return transport, transport.get_extra_info("sockname")[:2]


async def open_sender(address) -> ReportSender:
    loop = asyncio.get_running_loop()
    _t, proto = await loop.create_datagram_endpoint(ReportSender, remote_addr=address)
    return proto


REPORT_INTERVAL_S = 1.0  # a train reports its position once a second (the demo's 1 Hz PVT)


class TrainReporter:
    """A train's radio link to the centre: each output with a track position becomes one report datagram
    (at most every REPORT_INTERVAL_S of GPS time). `train` is an `OnboardTrain`, `send` one datagram."""

    def __init__(self, train, send: Callable[[bytes], None], length_m: float | None = None):
        self.train = train
        self.send = send
        self.builder = ReportBuilder(train.id, length_m or DEFAULT_TRAIN_LENGTH_M)
        self._last_t = -float("inf")
        self.sent = 0

    def on_output(self, out) -> None:
        m = out.match
        t = float(out.solution.time)
        if m is None or not m.track or t - self._last_t < REPORT_INTERVAL_S - 1e-6:
            return
        self._last_t = t
        hpl, vpl = self.train.protection_levels()
        r = self.builder.build(t, m.track, float(m.km), correction_age_s=self.train.correction_age_s(),
                               along_pl_m=m.along_pl_m, cross_pl_m=m.cross_pl_m, hpl_m=hpl, vpl_m=vpl,
                               track_confirmed=bool(m.confirmed))
        self.send(encode(r))
        self.sent += 1

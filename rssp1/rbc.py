"""The centre <-> RBC link: the library the control centre calls, and an RBC simulator.

Both are sans-IO wrappers around an RSSP-I endpoint (plain `Endpoint` on a closed network,
`SealedEndpoint` on an open bearer) and are driven once per main cycle with the caller's clock:

    link = CentreRbcLink(Endpoint(centre_cfg, rbc_cfg, timing))
    link.set_section(12, SectionStatus.DEGRADED, hpl_m=1.8)
    link.corrections_updated(epoch_ms, produced_at_s=now)
    link.raise_alarm(AlarmCode.STATION_FAILED, Severity.WARNING, text="station 7 silent")
    frames = link.cycle(now)             # send these to the RBC
    link.receive(datagram, now)          # what came back (acks)

The report is state, not events: every cycle carries the full integrity status of every section, the
exclusions and the correction age, so one lost frame loses nothing. Alarms are events: each is repeated
every cycle until the RBC acknowledges its id (RbcAck), and the RBC deduplicates by id.

The RBC simulator trusts nothing it cannot see fresh (fail-safe): while the link is down, or no
integrity report arrived within `report_timeout_cycles`, or the corrections are older than its limit
(correction-age watchdog: the age the centre reported plus the time since that report), every section
is DO_NOT_USE and an alarm is raised once per episode.
"""

from __future__ import annotations

import itertools
import secrets
from collections import Counter, OrderedDict
from dataclasses import dataclass, field
from typing import Iterable

from rssp1.endpoint import DataReceived, LinkDown, LinkUp
from rssp1.frames import MAX_RSD_DATA_BYTES
from rssp1.messages import (
    NO_SECTION,
    UNKNOWN_U16,
    Alarm,
    AlarmCode,
    CorrectionAge,
    Exclusions,
    IntegrityStatus,
    RbcAck,
    SectionIntegrity,
    SectionStatus,
    SectionTrains,
    Severity,
    decode_payload,
    encode_message,
    encode_payload,
)

DEFAULT_MAX_CORRECTION_AGE_S = 10.0  # RTK corrections older than ~10 s lose cm-level accuracy (RTCM SC-104 practice)
AGE_UNKNOWN_MS = 0xFFFFFFFF  # no correction model yet
MAX_ALARMS_PER_CYCLE = 8  # unacknowledged alarms carried per RSD; the rest wait their turn
MAX_ACKED_IDS = 16  # alarm ids an RbcAck carries (the most recent)
RECENT_ALARM_IDS = 1024  # alarm ids the RBC remembers for deduplication
# RSD room a section's train telegram leaves for the integrity report (one line's sections, exclusions, age)
# and a few alarms: a section whose telegram would not leave it is refused (split the section's trains)
SECTION_TRAINS_RESERVE_BYTES = 256


def _ms(seconds: float) -> int:
    return max(0, min(int(round(seconds * 1000)), AGE_UNKNOWN_MS - 1))


class CentreRbcLink:
    """The control centre's end of the RSSP-I link to an RBC / train-control resource manager."""

    def __init__(
        self, endpoint, *, max_correction_age_s: float = DEFAULT_MAX_CORRECTION_AGE_S, first_alarm_id: int | None = None
    ) -> None:
        self.endpoint = endpoint
        self.max_correction_age_s = max_correction_age_s
        self.sections: dict[int, SectionIntegrity] = {}
        self.satellites: tuple[str, ...] = ()
        self.stations: tuple[int, ...] = ()
        self.epoch_ms = 0
        self._produced_at_s: float | None = None
        # Ids count up from a random start: after a centre restart the RBC's duplicate filter cannot
        # mistake a new alarm for one it already has (chance 2**-32 per id).
        self._alarm_ids = itertools.count(secrets.randbits(32) if first_alarm_id is None else first_alarm_id)
        self.unacked: dict[int, Alarm] = {}
        self.report_seq = 0
        self.last_acked_report = -1
        self.stats: Counter[str] = Counter()
        self.section_trains: dict[tuple[int, int], bytes] = {}  # (section, direction) -> encoded SectionTrains
        self._trains_turn = 0  # where this cycle's round of section-train telegrams starts
        self._trains_changed: OrderedDict[tuple[int, int], None] = OrderedDict()  # sent first, oldest change first

    # -- what the centre tells us
    def set_section(self, section_id: int, status: SectionStatus, hpl_m: float | None = None) -> None:
        if not 0 <= section_id < NO_SECTION:
            raise ValueError(f"section id {section_id} out of range")
        hpl = UNKNOWN_U16 if hpl_m is None else max(0, min(int(round(hpl_m * 10)), UNKNOWN_U16 - 1))
        candidate = dict(self.sections)
        candidate[section_id] = SectionIntegrity(section_id, SectionStatus(status), hpl)
        if len(self._report(candidate, self.satellites, self.stations, 0.0, alarms=())) > MAX_RSD_DATA_BYTES:
            raise ValueError("too many line sections for one RSD; split the line over two links")
        self.sections = candidate

    def set_exclusions(self, satellites: Iterable[str] = (), stations: Iterable[int] = ()) -> None:
        self.satellites = tuple(sorted(satellites))
        self.stations = tuple(sorted(stations))

    def set_section_trains(self, msg: SectionTrains) -> None:
        """The section register's picture of one section and direction (state: the newest replaces it).
        Each cycle carries, in the RSD's room after the report, the changed pictures first (oldest change
        first), then the others in turn: a change reaches the RBC in the next cycle it fits in."""
        encoded = encode_message(msg)
        if len(encoded) > MAX_RSD_DATA_BYTES - SECTION_TRAINS_RESERVE_BYTES:
            raise ValueError(f"section {msg.section_id}: {len(msg.trains)} trains do not fit one RSD")
        key = (msg.section_id, msg.direction)
        self.section_trains[key] = encoded
        self._trains_changed[key] = None

    def corrections_updated(self, epoch_ms: int, produced_at_s: float) -> None:
        """A new correction model (epoch `epoch_ms`, GPS ms) was produced at `produced_at_s` (caller's clock)."""
        self.epoch_ms = epoch_ms
        self._produced_at_s = produced_at_s

    def raise_alarm(
        self, code: AlarmCode, severity: Severity = Severity.CRITICAL, section_id: int = NO_SECTION, text: str = ""
    ) -> int:
        alarm_id = next(self._alarm_ids) & 0xFFFFFFFF
        self.unacked[alarm_id] = Alarm(self.epoch_ms, alarm_id, AlarmCode(code), Severity(severity), section_id, text)
        self.stats["alarms_raised"] += 1
        return alarm_id

    # -- the cycle
    def _report(self, sections, satellites, stations, now_s: float, alarms) -> bytes:
        if self._produced_at_s is None:
            age_ms = AGE_UNKNOWN_MS
        else:
            age_ms = _ms(now_s - self._produced_at_s)
        messages = [
            IntegrityStatus(self.epoch_ms, self.report_seq, tuple(sections[k] for k in sorted(sections))),
            CorrectionAge(self.epoch_ms, age_ms, _ms(self.max_correction_age_s)),
        ]
        if satellites or stations:
            messages.append(Exclusions(self.epoch_ms, satellites, stations))
        messages.extend(alarms)
        return encode_payload(messages)

    def cycle(self, now_s: float) -> list[bytes]:
        """Build this cycle's report and run the RSSP-I cycle; returns the datagrams to send."""
        self.report_seq = (self.report_seq + 1) & 0xFFFFFFFF
        alarms = [self.unacked[k] for k in sorted(self.unacked)[:MAX_ALARMS_PER_CYCLE]]
        payload = self._report(self.sections, self.satellites, self.stations, now_s, alarms)
        while len(payload) > MAX_RSD_DATA_BYTES and alarms:  # long alarm texts: send fewer this cycle
            alarms.pop()
            payload = self._report(self.sections, self.satellites, self.stations, now_s, alarms)
        payload += self._section_trains_turn(MAX_RSD_DATA_BYTES - len(payload))
        frames, events = self.endpoint.cycle(payload)
        self._count(events)
        return frames

    def _section_trains_turn(self, room: int) -> bytes:
        keys = sorted(self.section_trains)
        if not keys:
            return b""
        out, sent, done = [], 0, set()
        for key in list(self._trains_changed):
            m = self.section_trains[key]
            if len(m) > room:
                break
            out.append(m)
            room -= len(m)
            done.add(key)
            del self._trains_changed[key]
        for i in range(len(keys)):
            if keys[(self._trains_turn + i) % len(keys)] in done:
                sent += 1
                continue
            m = self.section_trains[keys[(self._trains_turn + i) % len(keys)]]
            if len(m) > room:
                break
            out.append(m)
            room -= len(m)
            sent += 1
        self._trains_turn = (self._trains_turn + sent) % len(keys)
        self.stats["section_trains_sent"] += len(out)
        return b"".join(out)

    def receive(self, datagram: bytes, now_s: float | None = None) -> None:
        for event in self.endpoint.receive(datagram):
            if isinstance(event, DataReceived):
                decoded = decode_payload(event.data, self.stats)
                for msg in decoded.messages:
                    if isinstance(msg, RbcAck):
                        self.last_acked_report = msg.last_report_seq
                        for alarm_id in msg.alarm_ids:
                            if self.unacked.pop(alarm_id, None) is not None:
                                self.stats["alarms_acked"] += 1
            else:
                self._count([event])

    def _count(self, events) -> None:
        for event in events:
            if isinstance(event, LinkUp):
                self.stats["link_up"] += 1
            elif isinstance(event, LinkDown):
                self.stats["link_down"] += 1

    @property
    def is_up(self) -> bool:
        return self.endpoint.is_up


@dataclass(frozen=True)
class RbcAlarm:
    code: AlarmCode
    section_id: int
    at_s: float  # RBC clock when the alarm was raised
    at_cycle: int
    origin: str  # "centre" (an Alarm message), "status" (a section reported DO_NOT_USE), "watchdog"
    alarm_id: int = 0
    text: str = ""


@dataclass
class RbcView:
    """What the RBC currently believes, per section."""

    reported: dict[int, SectionIntegrity] = field(default_factory=dict)
    satellites: tuple[str, ...] = ()
    stations: tuple[int, ...] = ()
    correction_age_ms: int = AGE_UNKNOWN_MS
    report_cycle: int | None = None  # local cycle of the last integrity report
    section_trains: dict[tuple[int, int], SectionTrains] = field(default_factory=dict)  # (section, direction)


class RbcSimulator:
    """A train-control resource manager / RBC consuming the centre's reports (sans-IO)."""

    def __init__(
        self,
        endpoint,
        *,
        max_correction_age_s: float = DEFAULT_MAX_CORRECTION_AGE_S,
        report_timeout_cycles: int | None = None,
    ) -> None:
        self.endpoint = endpoint
        timing = endpoint.timing
        self.cycle_s = timing.cycle_s
        self.max_correction_age_ms = _ms(max_correction_age_s)
        self.report_timeout_cycles = report_timeout_cycles or timing.delay_time
        self.view = RbcView()
        self.alarms: list[RbcAlarm] = []
        self.stats: Counter[str] = Counter()
        self.local_cycle = 0
        self.now_s = 0.0
        self._seen_alarm_ids: OrderedDict[int, None] = OrderedDict()
        self._episodes: set[AlarmCode] = set()  # watchdog alarms active (raised once per episode)
        self._last_report_seq = 0
        self._dnu_alarmed: set[int] = set()  # sections reported DO_NOT_USE whose alarm is raised

    # -- the effective picture, fail-safe
    def effective_status(self, section_id: int) -> SectionStatus:
        if not self.fresh:
            return SectionStatus.DO_NOT_USE
        reported = self.view.reported.get(section_id)
        return SectionStatus.DO_NOT_USE if reported is None else reported.status

    @property
    def fresh(self) -> bool:
        return AlarmCode.LINK_LOST not in self._episodes and AlarmCode.CORRECTION_STALE not in self._episodes and (
            self.view.report_cycle is not None
        )

    def _alarm(self, code: AlarmCode, section: int, origin: str, alarm_id: int = 0, text: str = "") -> None:
        self.alarms.append(RbcAlarm(code, section, self.now_s, self.local_cycle, origin, alarm_id, text))
        self.stats[f"alarm_{code.name.lower()}"] += 1

    def _watchdog(self, code: AlarmCode, active: bool, text: str) -> None:
        if active and code not in self._episodes:
            self._episodes.add(code)
            self._alarm(code, NO_SECTION, "watchdog", text=text)
        elif not active and code in self._episodes:
            self._episodes.discard(code)
            self.stats[f"cleared_{code.name.lower()}"] += 1

    def receive(self, datagram: bytes, now_s: float | None = None) -> None:
        if now_s is not None:
            self.now_s = now_s
        for event in self.endpoint.receive(datagram):
            if isinstance(event, DataReceived):
                self._apply(event.data)
            elif isinstance(event, LinkDown):
                self._watchdog(AlarmCode.LINK_LOST, True, f"RSSP-I link down: {event.reason}")

    def _apply(self, data: bytes) -> None:
        for msg in decode_payload(data, self.stats).messages:
            if isinstance(msg, IntegrityStatus):
                # one alarm per transition to DO_NOT_USE as reported, whatever the freshness meanwhile
                reported_dnu = {s.section_id for s in msg.sections if s.status is SectionStatus.DO_NOT_USE}
                for section_id in sorted(reported_dnu - self._dnu_alarmed):
                    self._alarm(AlarmCode.SECTION_DO_NOT_USE, section_id, "status")
                self._dnu_alarmed = reported_dnu
                self.view.reported = {s.section_id: s for s in msg.sections}
                self.view.report_cycle = self.local_cycle
                self._last_report_seq = msg.report_seq
                self._watchdog(AlarmCode.LINK_LOST, False, "")
            elif isinstance(msg, CorrectionAge):
                self.view.correction_age_ms = msg.age_ms
                limit = min(self.max_correction_age_ms, msg.max_age_ms)
                what = "no corrections yet" if msg.age_ms == AGE_UNKNOWN_MS else f"corrections {msg.age_ms} ms old"
                self._watchdog(AlarmCode.CORRECTION_STALE, msg.age_ms > limit, what)
            elif isinstance(msg, Exclusions):
                self.view.satellites, self.view.stations = msg.satellites, msg.stations
            elif isinstance(msg, SectionTrains):
                key = (msg.section_id, msg.direction)
                held = self.view.section_trains.get(key)
                if held is None or msg.epoch_ms >= held.epoch_ms:  # a late frame never rolls the picture back
                    self.view.section_trains[key] = msg
                    self.stats["section_trains_received"] += 1
            elif isinstance(msg, Alarm):
                if msg.alarm_id in self._seen_alarm_ids:
                    self._seen_alarm_ids.move_to_end(msg.alarm_id)  # ack it again: our ack may be lost
                    continue
                self._seen_alarm_ids[msg.alarm_id] = None
                if len(self._seen_alarm_ids) > RECENT_ALARM_IDS:
                    self._seen_alarm_ids.popitem(last=False)
                self._alarm(msg.code, msg.section_id, "centre", msg.alarm_id, msg.text)

    def cycle(self, now_s: float) -> list[bytes]:
        self.now_s = now_s
        self.local_cycle += 1
        last = self.view.report_cycle
        # Before the first report every section is DO_NOT_USE already (not fresh); the watchdogs
        # guard a picture we once had.
        if last is not None and self.local_cycle - last > self.report_timeout_cycles:
            self._watchdog(AlarmCode.LINK_LOST, True, "no fresh integrity report")
        elif last is not None and self.view.correction_age_ms != AGE_UNKNOWN_MS:
            # the corrections keep ageing while no report comes
            aged = self.view.correction_age_ms + int((self.local_cycle - last - 1) * self.cycle_s * 1000)
            if aged > self.max_correction_age_ms:
                self._watchdog(AlarmCode.CORRECTION_STALE, True, f"corrections {aged} ms old")
        acked = list(self._seen_alarm_ids)[-MAX_ACKED_IDS:]
        frames, events = self.endpoint.cycle(encode_message(RbcAck(self._last_report_seq, tuple(acked))))
        for event in events:
            if isinstance(event, LinkDown):
                self._watchdog(AlarmCode.LINK_LOST, True, f"RSSP-I link down: {event.reason}")
        return frames

    def first_alarm(self, code: AlarmCode, section_id: int | None = None) -> RbcAlarm | None:
        return next(
            (a for a in self.alarms if a.code is code and (section_id is None or a.section_id == section_id)), None
        )

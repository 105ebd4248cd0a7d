"""Onboard -> ATP: virtual balise telegrams over RSSP-I, the onboard library end and an ATP simulator.

The onboard positioning core calls `OnboardAtpLink.report_balise(...)` when the train's estimated
position passes a virtual balise group of the track map. Each telegram carries a 32-bit id and is sent
every cycle until the ATP acknowledges that id (RbcAck.alarm_ids lists the ids it received) or it is
older than `max_age_s` (a stale passage is worse than none: it is dropped and counted). So a passage
survives lost RSDs and even an RSSP-I resynchronisation. The ATP deduplicates on the id. Ids count up
from a random start, so after an onboard restart neither a stale acknowledgement nor the ATP's
duplicate filter can mistake a new passage for an old one (chance 2**-32 per id). Between passages
both ends still send an RSD every cycle.

The ATP simulator checks every telegram against its own copy of the balise map (group known, same
track and chainage), that passages follow the direction of travel, and that the onboard integrity is
usable; anything else is counted and, when it matters for safety, raised as an alarm.
"""

from __future__ import annotations

import secrets
from collections import Counter, OrderedDict
from dataclasses import dataclass

from rssp1.endpoint import DataReceived, LinkDown
from rssp1.messages import (
    Alarm,
    AlarmCode,
    Severity,
    RbcAck,
    SectionStatus,
    VirtualBaliseTelegram,
    decode_payload,
    encode_message,
    encode_payload,
)

TELEGRAM_MAX_AGE_S = 5.0  # an unacknowledged passage older than this is dropped (train moved ~100 m+)
MAX_TELEGRAMS_PER_CYCLE = 16
RECENT_IDS = 256  # telegram ids the ATP remembers for deduplication (minutes of passages)
ACKED_IDS_PER_CYCLE = MAX_TELEGRAMS_PER_CYCLE  # so one ack covers everything one cycle can carry


@dataclass(frozen=True)
class BaliseLocation:
    track_id: int
    chainage_mm: int


class OnboardAtpLink:
    def __init__(
        self, endpoint, train_id: int, *, max_age_s: float = TELEGRAM_MAX_AGE_S, first_id: int | None = None
    ) -> None:
        self.endpoint = endpoint
        self.train_id = train_id
        self.max_age_s = max_age_s
        self._next_id = secrets.randbits(32) if first_id is None else first_id & 0xFFFFFFFF
        self._pending: list[tuple[VirtualBaliseTelegram | Alarm, float | None]] = []  # (message, first sent at)
        self.stats: Counter[str] = Counter()

    def report_balise(
        self, *, time_ms: int, balise_group: int, location: BaliseLocation, reverse: bool,
        confidence_mm: int, speed_mm_s: int, integrity: SectionStatus = SectionStatus.OK,
    ) -> VirtualBaliseTelegram:
        telegram = VirtualBaliseTelegram(
            time_ms, self.train_id, balise_group, location.track_id, location.chainage_mm, reverse,
            confidence_mm, speed_mm_s, SectionStatus(integrity), self._next_id,
        )
        self._next_id = (self._next_id + 1) & 0xFFFFFFFF
        self._pending.append((telegram, None))
        self.stats["telegrams"] += 1
        return telegram

    def request_service_brake(self, *, time_ms: int, text: str = "") -> Alarm:
        """Service-brake request (two consecutive linked groups missed); repeated until acked by id."""
        alarm = Alarm(time_ms, self._next_id, AlarmCode.SERVICE_BRAKE, Severity.CRITICAL, text=text[:200])
        self._next_id = (self._next_id + 1) & 0xFFFFFFFF
        self._pending.append((alarm, None))
        self.stats["service_brake_requests"] += 1
        return alarm

    @property
    def pending(self) -> list[VirtualBaliseTelegram | Alarm]:
        return [t for t, _ in self._pending]

    def cycle(self, now_s: float) -> list[bytes]:
        kept = []
        for telegram, first in self._pending:
            if first is not None and now_s - first > self.max_age_s:
                self.stats["expired"] += 1
            else:
                kept.append((telegram, now_s if first is None else first))
        self._pending = kept
        batch = [t for t, _ in self._pending[:MAX_TELEGRAMS_PER_CYCLE]]
        frames, _events = self.endpoint.cycle(encode_payload(batch))
        return frames

    def receive(self, datagram: bytes, now_s: float | None = None) -> None:
        for event in self.endpoint.receive(datagram):
            if isinstance(event, DataReceived):
                for msg in decode_payload(event.data, self.stats).messages:
                    if isinstance(msg, RbcAck):
                        acked = set(msg.alarm_ids)
                        before = len(self._pending)
                        self._pending = [(t, f) for t, f in self._pending if _message_id(t) not in acked]
                        self.stats["acked"] += before - len(self._pending)

    @property
    def is_up(self) -> bool:
        return self.endpoint.is_up


def _message_id(msg: VirtualBaliseTelegram | Alarm) -> int:
    return msg.telegram_id if isinstance(msg, VirtualBaliseTelegram) else msg.alarm_id


@dataclass(frozen=True)
class AtpEvent:
    kind: str  # LINK_LOST, UNKNOWN_BALISE, MAP_MISMATCH, PASSAGE_ORDER, INTEGRITY_LOST, SERVICE_BRAKE
    at_s: float
    telegram: VirtualBaliseTelegram | None = None


class AtpSimulator:
    def __init__(self, endpoint, balise_map: dict[int, BaliseLocation]) -> None:
        self.endpoint = endpoint
        self.balise_map = dict(balise_map)
        self.passages: list[VirtualBaliseTelegram] = []
        self.service_brake_requests: list[Alarm] = []
        self.alarms: list[AtpEvent] = []
        self.stats: Counter[str] = Counter()
        self.now_s = 0.0
        self._recent_ids: OrderedDict[int, None] = OrderedDict()  # telegram ids received, oldest first
        self._last_chainage: dict[int, tuple[int, int, bool]] = {}  # train -> (track, chainage, reverse)

    def receive(self, datagram: bytes, now_s: float | None = None) -> None:
        if now_s is not None:
            self.now_s = now_s
        for event in self.endpoint.receive(datagram):
            if isinstance(event, DataReceived):
                for msg in decode_payload(event.data, self.stats).messages:
                    if isinstance(msg, VirtualBaliseTelegram):
                        self._telegram(msg)
                    elif isinstance(msg, Alarm) and msg.code is AlarmCode.SERVICE_BRAKE:
                        self._service_brake(msg)
                    else:
                        self.stats["unexpected_message"] += 1
            elif isinstance(event, LinkDown):
                self._alarm(AlarmCode.LINK_LOST.name)

    def _alarm(self, kind: str, telegram: VirtualBaliseTelegram | None = None) -> None:
        self.alarms.append(AtpEvent(kind, self.now_s, telegram))
        self.stats[f"alarm_{kind.lower()}"] += 1

    def _seen(self, key: int) -> bool:
        if key in self._recent_ids:
            self._recent_ids.move_to_end(key)  # acknowledge it again: our last ack may have been lost
            self.stats["duplicate"] += 1
            return True
        self._recent_ids[key] = None
        if len(self._recent_ids) > RECENT_IDS:
            self._recent_ids.popitem(last=False)
        return False

    def _service_brake(self, a: Alarm) -> None:
        if self._seen(a.alarm_id):
            return
        self.service_brake_requests.append(a)
        self._alarm(AlarmCode.SERVICE_BRAKE.name)

    def _telegram(self, t: VirtualBaliseTelegram) -> None:
        key = t.telegram_id
        if key in self._recent_ids:
            self._recent_ids.move_to_end(key)  # acknowledge it again: our last ack may have been lost
            self.stats["duplicate"] += 1  # a repeat of a telegram already received
            return
        self._recent_ids[key] = None
        if len(self._recent_ids) > RECENT_IDS:
            self._recent_ids.popitem(last=False)
        where = self.balise_map.get(t.balise_group)
        if where is None:
            self.stats["unknown_balise"] += 1
            self._alarm("UNKNOWN_BALISE", t)
            return
        if (where.track_id, where.chainage_mm) != (t.track_id, t.chainage_mm):
            self.stats["map_mismatch"] += 1
            self._alarm("MAP_MISMATCH", t)
            return
        previous = self._last_chainage.get(t.train_id)
        if previous is not None and previous[0] == t.track_id and previous[2] == t.reverse:
            forward = t.chainage_mm > previous[1]
            if forward == t.reverse:
                self.stats["order"] += 1
                self._alarm("PASSAGE_ORDER", t)
                return
        self._last_chainage[t.train_id] = (t.track_id, t.chainage_mm, t.reverse)
        if t.integrity is SectionStatus.DO_NOT_USE:
            self._alarm(AlarmCode.INTEGRITY_LOST.name, t)
        self.passages.append(t)
        self.stats["passages"] += 1

    def cycle(self, now_s: float) -> list[bytes]:
        self.now_s = now_s
        acked = tuple(list(self._recent_ids)[-ACKED_IDS_PER_CYCLE:])
        frames, events = self.endpoint.cycle(encode_message(RbcAck(len(self.passages) & 0xFFFFFFFF, acked)))
        for event in events:
            if isinstance(event, LinkDown):
                self._alarm(AlarmCode.LINK_LOST.name)
        return frames

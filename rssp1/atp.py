"""Onboard -> ATP: virtual balise telegrams over RSSP-I, the onboard library end and an ATP simulator.

The onboard positioning core calls `OnboardAtpLink.report_balise(...)` when the train's estimated
position passes a virtual balise group of the track map. Each telegram carries a sequence number and is
sent every cycle until the ATP acknowledges it (an RbcAck message whose last_report_seq is the highest
telegram sequence taken) or it is older than `max_age_s` (a stale passage is worse than none: it is
dropped and counted). So a passage survives lost RSDs and even an RSSP-I resynchronisation. The ATP
deduplicates on the sequence number. Between passages both ends still send an RSD every cycle.

The ATP simulator checks every telegram against its own copy of the balise map (group known, same
track and chainage), that passages follow the direction of travel, and that the onboard integrity is
usable; anything else is counted and, when it matters for safety, raised as an alarm.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from rssp1.endpoint import DataReceived, LinkDown
from rssp1.messages import (
    AlarmCode,
    RbcAck,
    SectionStatus,
    VirtualBaliseTelegram,
    decode_payload,
    encode_message,
    encode_payload,
)

TELEGRAM_MAX_AGE_S = 5.0  # an unacknowledged passage older than this is dropped (train moved ~100 m+)
MAX_TELEGRAMS_PER_CYCLE = 16


@dataclass(frozen=True)
class BaliseLocation:
    track_id: int
    chainage_mm: int


class OnboardAtpLink:
    def __init__(self, endpoint, train_id: int, *, max_age_s: float = TELEGRAM_MAX_AGE_S) -> None:
        self.endpoint = endpoint
        self.train_id = train_id
        self.max_age_s = max_age_s
        self._seq = 0
        self._pending: list[tuple[VirtualBaliseTelegram, float | None]] = []  # (telegram, first sent at)
        self.stats: Counter[str] = Counter()

    def report_balise(
        self, *, time_ms: int, balise_group: int, location: BaliseLocation, reverse: bool,
        confidence_mm: int, speed_mm_s: int, integrity: SectionStatus = SectionStatus.OK,
    ) -> VirtualBaliseTelegram:
        self._seq = (self._seq + 1) & 0xFFFF
        telegram = VirtualBaliseTelegram(
            time_ms, self.train_id, balise_group, location.track_id, location.chainage_mm, reverse,
            confidence_mm, speed_mm_s, SectionStatus(integrity), self._seq,
        )
        self._pending.append((telegram, None))
        self.stats["telegrams"] += 1
        return telegram

    @property
    def pending(self) -> list[VirtualBaliseTelegram]:
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
                        acked = msg.last_report_seq & 0xFFFF
                        before = len(self._pending)
                        # serial-number arithmetic on the u16 sequence: acked covers everything up to it
                        self._pending = [(t, f) for t, f in self._pending if ((acked - t.seq) & 0xFFFF) >= 0x8000]
                        self.stats["acked"] += before - len(self._pending)

    @property
    def is_up(self) -> bool:
        return self.endpoint.is_up


@dataclass(frozen=True)
class AtpEvent:
    kind: str  # "passage" or an alarm name
    at_s: float
    telegram: VirtualBaliseTelegram | None = None


class AtpSimulator:
    def __init__(self, endpoint, balise_map: dict[int, BaliseLocation]) -> None:
        self.endpoint = endpoint
        self.balise_map = dict(balise_map)
        self.passages: list[VirtualBaliseTelegram] = []
        self.alarms: list[AtpEvent] = []
        self.stats: Counter[str] = Counter()
        self.now_s = 0.0
        self._last_seq: dict[int, int] = {}  # train -> last telegram seq
        self._last_chainage: dict[int, tuple[int, int, bool]] = {}  # train -> (track, chainage, reverse)

    def receive(self, datagram: bytes, now_s: float | None = None) -> None:
        if now_s is not None:
            self.now_s = now_s
        for event in self.endpoint.receive(datagram):
            if isinstance(event, DataReceived):
                for msg in decode_payload(event.data, self.stats).messages:
                    if isinstance(msg, VirtualBaliseTelegram):
                        self._telegram(msg)
                    else:
                        self.stats["unexpected_message"] += 1
            elif isinstance(event, LinkDown):
                self._alarm(AlarmCode.LINK_LOST.name)

    def _alarm(self, kind: str, telegram: VirtualBaliseTelegram | None = None) -> None:
        self.alarms.append(AtpEvent(kind, self.now_s, telegram))
        self.stats[f"alarm_{kind.lower()}"] += 1

    def _telegram(self, t: VirtualBaliseTelegram) -> None:
        last = self._last_seq.get(t.train_id)
        if last is not None and ((delta := (t.seq - last) & 0xFFFF) == 0 or delta >= 0x8000):
            self.stats["duplicate"] += 1  # the repeats of a passage already taken
            return
        self._last_seq[t.train_id] = t.seq
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
        # one ATP link serves one train: acknowledge the highest telegram sequence taken
        acked = max(self._last_seq.values(), default=0)
        frames, events = self.endpoint.cycle(encode_message(RbcAck(acked, ())))
        for event in events:
            if isinstance(event, LinkDown):
                self._alarm(AlarmCode.LINK_LOST.name)
        return frames

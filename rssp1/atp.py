"""Onboard -> ATP: virtual balise telegrams over RSSP-I, the onboard library end and an ATP simulator.

The onboard positioning core calls `OnboardAtpLink.report_balise(...)` when the train's estimated
position passes a virtual balise group of the track map; each telegram is repeated for
`repeat_cycles` main cycles (a lost RSD must not lose a passage) and carries a sequence number the ATP
deduplicates on. Between passages the link still sends an empty RSD every cycle to stay synchronised.

The ATP simulator checks every telegram against its own copy of the balise map (group known, same
track and chainage), that passages follow the direction of travel, and that the onboard integrity is
usable; anything else is counted and, when it matters for safety, raised as an alarm.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from rssp1.endpoint import DataReceived, LinkDown
from rssp1.messages import AlarmCode, SectionStatus, VirtualBaliseTelegram, decode_payload, encode_payload

TELEGRAM_REPEAT_CYCLES = 3  # a passage survives two lost RSDs in a row (deltaTime 3 tolerates two)
MAX_TELEGRAMS_PER_CYCLE = 16


@dataclass(frozen=True)
class BaliseLocation:
    track_id: int
    chainage_mm: int


class OnboardAtpLink:
    def __init__(self, endpoint, train_id: int, *, repeat_cycles: int = TELEGRAM_REPEAT_CYCLES) -> None:
        self.endpoint = endpoint
        self.train_id = train_id
        self.repeat_cycles = repeat_cycles
        self._seq = 0
        self._pending: list[list] = []  # [telegram, cycles left]
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
        self._pending.append([telegram, self.repeat_cycles])
        self.stats["telegrams"] += 1
        return telegram

    def cycle(self, now_s: float) -> list[bytes]:
        batch = self._pending[:MAX_TELEGRAMS_PER_CYCLE]
        frames, _events = self.endpoint.cycle(encode_payload([t for t, _ in batch]))
        for entry in batch:
            entry[1] -= 1
        self._pending = [e for e in self._pending if e[1] > 0]
        return frames

    def receive(self, datagram: bytes, now_s: float | None = None) -> None:
        self.endpoint.receive(datagram)  # the ATP sends nothing we act on; RSSP-I still needs its SSRs/RSDs

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
        frames, events = self.endpoint.cycle(b"")
        for event in events:
            if isinstance(event, LinkDown):
                self._alarm(AlarmCode.LINK_LOST.name)
        return frames

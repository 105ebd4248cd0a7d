"""The section register: per line section and direction, the trains in order (pure, no I/O).

The railway's train information management for moving block (railway.md, "Train information
management"; the seed keeps a doubly linked list): a line section is the open line between two stations
(or a station and the line's end); per direction its trains form a queue, the **front** the train nearest
the section's exit, the **rear** the one that entered last. Only three things change a queue:

- the **departing side** (the station at the section's entry for that direction) inserts a train at the
  rear, when it leaves the station into the section: `insert(..., by=<entry station>)`;
- the **receiving side** (the station at the exit) removes the front train when it arrives:
  `remove(..., by=<exit station>)`;
- a **dispatcher action** (an `Authority` with a reason), returned as an `AuditRecord` for the audit log:
  `reorder` (a new order of the same trains), `admit` (a train starting its mission inside a section,
  placed where its chainage puts it) and `withdraw` (a train that vanished).

Reports of a train already in a queue update its record (`update`) and never reorder it: a report that
would put a train past the one ahead of it, or behind the one behind it, is refused (`order-conflict`).

Loop tracks and overtaking: a loop (platform) track lies inside a station, and a station area belongs
to no line section (its interlocking routes trains across it). A train that overtakes another on a
loop is removed from the section before the station in arrival order and inserted into the section
after it in departure order; the register never reorders itself (decision 0292).

Train integrity (decision 0293): each record carries `rear_km`, the chainage down to which the train occupies
the track behind it. The register sets it: the train's front minus its length while the train reports its
integrity "confirmed"; frozen at the last confirmed rear while it reports "lost" or "unknown"; the section's
entry when it never confirmed one in this section (the whole section behind it stays occupied). A train
leaving through the exit keeps its section occupied (`left_behind`) down to that rear until a report with
confirmed integrity puts its rear past the exit (`release`) or a dispatcher clears it (`clear_behind`).

Every refused change raises `RegisterError` whose `code` says which rule it broke (`REFUSALS`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Iterable, Iterator

DIRECTIONS = ("up", "down")  # up: increasing chainage (augnet.track.topology.DIRECTIONS)
LINE_END = "line end"  # the side of a section that is the end of the line (no station there)
INTEGRITY_STATES = ("confirmed", "lost", "unknown")  # train integrity: complete, split, not monitored
DISPATCHER_ROLES = ("dispatcher", "admin")  # roles that may reorder, admit or withdraw
# How far from its boundary a train may be when a station inserts it at the entry or removes it at the
# exit [m]: 1 km is ~10 s at 350 km/h, ten 1 Hz position reports; a station acting later than that is
# an inconsistency to look at, not one to accept silently.
BOUNDARY_ZONE_M = 1000.0

REFUSALS = {
    "unknown-section": "no such line section",
    "bad-direction": "direction must be up or down",
    "not-entry-side": "only the station at the section's entry inserts a train",
    "not-exit-side": "only the station at the section's exit removes a train",
    "duplicate": "the train is already in the register",
    "middle-insert": "a train is inserted at the entry, behind the rear train",
    "not-at-exit": "only the front train is removed at the exit",
    "unknown-train": "the train is not in that section",
    "order-conflict": "a report must not move a train past its neighbours",
    "outside-section": "the position is outside the section",
    "no-authority": "the change needs a dispatcher's authority and a reason",
    "not-a-permutation": "a reorder lists exactly the trains of the section",
    "bad-record": "the record's fields are out of range",
}


class RegisterError(ValueError):
    """A refused change; `code` is a key of REFUSALS."""

    def __init__(self, code: str, detail: str):
        super().__init__(f"{code}: {REFUSALS[code]} ({detail})")
        self.code = code
        self.detail = detail


@dataclass(frozen=True)
class LineSection:
    id: int  # 1..n along increasing chainage (the RSSP-I section telegram's id)
    name: str
    km_begin: float
    km_end: float
    station_begin: str  # the station (or LINE_END) at km_begin
    station_end: str

    def entry_station(self, direction: str) -> str:
        return self.station_begin if direction == "up" else self.station_end

    def exit_station(self, direction: str) -> str:
        return self.station_end if direction == "up" else self.station_begin

    def entry_km(self, direction: str) -> float:
        return self.km_begin if direction == "up" else self.km_end

    def exit_km(self, direction: str) -> float:
        return self.km_end if direction == "up" else self.km_begin

    def contains(self, km: float, margin_m: float = 0.0) -> bool:
        return self.km_begin - margin_m / 1e3 <= km <= self.km_end + margin_m / 1e3


@dataclass(frozen=True)
class TrainRecord:
    """What the register knows of a train (from its last position report)."""

    train_id: str
    track: str
    km: float  # chainage of the train's front (its antenna) [km]
    speed_m_s: float
    length_m: float
    integrity: str  # INTEGRITY_STATES
    correction_age_s: float | None  # None: the position used no corrections
    along_pl_m: float | None  # protection levels [m]; None when the onboard unit gave none
    cross_pl_m: float | None
    hpl_m: float | None
    time_s: float = 0.0  # GPS time of the report [s]
    # chainage down to which the train occupies the track behind it [km]: set by the register (module docstring)
    rear_km: float | None = None

    def check(self) -> None:
        if not self.train_id or self.integrity not in INTEGRITY_STATES or self.length_m <= 0 or self.speed_m_s < 0:
            raise RegisterError("bad-record", f"{self.train_id!r}: integrity {self.integrity!r}, "
                                              f"length {self.length_m} m, speed {self.speed_m_s} m/s")


@dataclass(frozen=True)
class Authority:
    """Who acts: an operator's name and role (the console's authenticated operator)."""

    name: str
    role: str


@dataclass(frozen=True)
class AuditRecord:
    """A dispatcher action, for the audit log (`augnet.store.queries.audit`)."""

    actor: str
    action: str  # section.reorder, section.admit, section.withdraw
    target: str  # "section 2 up"
    reason: str
    before: tuple[str, ...]
    after: tuple[str, ...]


class _Node:
    __slots__ = ("record", "ahead", "behind")

    def __init__(self, record: TrainRecord):
        self.record = record
        self.ahead: _Node | None = None  # towards the exit
        self.behind: _Node | None = None  # towards the entry


class SectionQueue:
    """One section and direction: a doubly linked list from the front (exit) to the rear (entry)."""

    def __init__(self, section: LineSection, direction: str):
        self.section = section
        self.direction = direction
        self.front: _Node | None = None
        self.rear: _Node | None = None
        self.nodes: dict[str, _Node] = {}
        # trains that left through the exit without their rear confirmed past it: train -> rear_km
        self.left_behind: dict[str, float] = {}
        self.version = 0  # changes of membership or order (insert, remove, dispatcher actions)

    def __iter__(self) -> Iterator[TrainRecord]:
        n = self.front
        while n is not None:
            yield n.record
            n = n.behind

    def __len__(self) -> int:
        return len(self.nodes)

    def ids(self) -> tuple[str, ...]:
        return tuple(r.train_id for r in self)

    def ahead_of(self, a: float, b: float) -> bool:
        """Chainage a is strictly ahead of b in this direction of travel."""
        return a > b if self.direction == "up" else a < b

    def distance_to_exit_m(self, km: float) -> float:
        return (self.section.exit_km(self.direction) - km) * 1e3 * (1 if self.direction == "up" else -1)

    def distance_from_entry_m(self, km: float) -> float:
        return (km - self.section.entry_km(self.direction)) * 1e3 * (1 if self.direction == "up" else -1)

    def with_rear(self, record: TrainRecord, previous: TrainRecord | None) -> TrainRecord:
        """`record` with the register's `rear_km` (module docstring): confirmed -> front minus length; else the
        previous record's rear, or the section's entry."""
        if record.integrity == "confirmed":
            rear = record.km - (record.length_m / 1e3 if self.direction == "up" else -record.length_m / 1e3)
        elif previous is not None and previous.rear_km is not None:
            rear = previous.rear_km
        else:
            rear = self.section.entry_km(self.direction)
        return dataclasses.replace(record, rear_km=rear)

    def occupied_from_km(self) -> float | None:
        """The chainage farthest back (towards the entry) that a train of this queue, or one that left it,
        still occupies; None when nothing occupies the section."""
        rears = [r.rear_km for r in self if r.rear_km is not None] + list(self.left_behind.values())
        if not rears:
            return None
        return min(rears) if self.direction == "up" else max(rears)

    # -- list operations (the rules are checked by SectionRegister) --
    def _push_rear(self, record: TrainRecord) -> None:
        node = _Node(record)
        node.ahead = self.rear
        if self.rear is not None:
            self.rear.behind = node
        self.rear = node
        if self.front is None:
            self.front = node
        self.nodes[record.train_id] = node

    def _unlink(self, train_id: str) -> TrainRecord:
        node = self.nodes.pop(train_id)
        if node.ahead is not None:
            node.ahead.behind = node.behind
        else:
            self.front = node.behind
        if node.behind is not None:
            node.behind.ahead = node.ahead
        else:
            self.rear = node.ahead
        return node.record

    def _rebuild(self, records: list[TrainRecord]) -> None:
        self.front = self.rear = None
        self.nodes = {}
        for r in records:
            self._push_rear(r)


class SectionRegister:
    def __init__(self, sections: Iterable[LineSection]):
        self.sections: dict[int, LineSection] = {}
        for s in sections:
            if s.id in self.sections:
                raise ValueError(f"section {s.id} given twice")
            if not s.km_end > s.km_begin:
                raise ValueError(f"section {s.id}: km_end {s.km_end} <= km_begin {s.km_begin}")
            self.sections[s.id] = s
        self.queues: dict[tuple[int, str], SectionQueue] = {
            (sid, d): SectionQueue(s, d) for sid, s in self.sections.items() for d in DIRECTIONS}
        self._where: dict[str, tuple[int, str]] = {}

    # -- reading --
    def queue(self, section_id: int, direction: str) -> SectionQueue:
        if direction not in DIRECTIONS:
            raise RegisterError("bad-direction", repr(direction))
        q = self.queues.get((section_id, direction))
        if q is None:
            raise RegisterError("unknown-section", f"section {section_id!r}")
        return q

    def trains(self, section_id: int, direction: str) -> list[TrainRecord]:
        """Front (nearest the exit) to rear."""
        return list(self.queue(section_id, direction))

    def where(self, train_id: str) -> tuple[int, str] | None:
        return self._where.get(train_id)

    def record(self, train_id: str) -> TrainRecord | None:
        at = self._where.get(train_id)
        return None if at is None else self.queues[at].nodes[train_id].record

    def section_at(self, km: float) -> LineSection | None:
        return next((s for s in self.sections.values() if s.km_begin <= km <= s.km_end), None)

    # -- the stations' changes --
    def insert(self, section_id: int, direction: str, record: TrainRecord, by: str) -> None:
        """The departing station `by` puts the train at the rear of the section's queue."""
        q = self.queue(section_id, direction)
        record.check()
        if by != q.section.entry_station(direction):
            raise RegisterError("not-entry-side", f"{by!r} is not the entry of section {section_id} {direction} "
                                                  f"({q.section.entry_station(direction)!r})")
        self._check_new(record)
        self._check_inside(q, record)
        if q.distance_from_entry_m(record.km) > BOUNDARY_ZONE_M:
            raise RegisterError("middle-insert", f"{record.train_id} at km {record.km:.3f} is "
                                                 f"{q.distance_from_entry_m(record.km):.0f} m past the entry")
        if q.rear is not None and not q.ahead_of(q.rear.record.km, record.km):
            raise RegisterError("middle-insert", f"{record.train_id} at km {record.km:.3f} is not behind the "
                                                 f"rear train {q.rear.record.train_id} at km {q.rear.record.km:.3f}")
        q._push_rear(q.with_rear(record, None))
        q.version += 1
        self._where[record.train_id] = (section_id, direction)

    def remove(self, section_id: int, direction: str, train_id: str, by: str) -> TrainRecord:
        """The receiving station `by` takes the front train off the section's queue."""
        q = self.queue(section_id, direction)
        if by != q.section.exit_station(direction):
            raise RegisterError("not-exit-side", f"{by!r} is not the exit of section {section_id} {direction} "
                                                 f"({q.section.exit_station(direction)!r})")
        if train_id not in q.nodes:
            raise RegisterError("unknown-train", f"{train_id} in section {section_id} {direction}")
        if q.front is None or q.front.record.train_id != train_id:
            raise RegisterError("not-at-exit", f"{train_id} is behind {q.front.record.train_id}")
        if q.distance_to_exit_m(q.front.record.km) > BOUNDARY_ZONE_M:
            raise RegisterError("not-at-exit", f"{train_id} is {q.distance_to_exit_m(q.front.record.km):.0f} m "
                                               "before the exit")
        rec = q._unlink(train_id)
        if rec.rear_km is not None and q.distance_to_exit_m(rec.rear_km) > 0:
            q.left_behind[train_id] = rec.rear_km  # its rear is (or may be) still in the section
        q.version += 1
        del self._where[train_id]
        return rec

    def release(self, record: TrainRecord) -> list[tuple[int, str]]:
        """A report of a train that left sections with their track behind it still occupied: each such section
        is released once the report's integrity is confirmed and its rear (front minus length) is past the
        exit; a confirmed rear still inside moves the occupancy on. Returns the sections released or moved."""
        changed = []
        for key, q in self.queues.items():
            rear = q.left_behind.get(record.train_id)
            if rear is None or record.integrity != "confirmed":
                continue
            new_rear = q.with_rear(record, None).rear_km
            if q.distance_to_exit_m(new_rear) <= 0:
                del q.left_behind[record.train_id]
            elif q.ahead_of(new_rear, rear):
                q.left_behind[record.train_id] = new_rear
            else:
                continue
            q.version += 1
            changed.append(key)
        return changed

    def clear_behind(self, section_id: int, direction: str, train_id: str, authority: Authority | None,
                     reason: str) -> AuditRecord:
        """A dispatcher releases the track a departed train left occupied behind it (the rear part found and
        cleared, or the train's integrity confirmed by other means)."""
        q = self.queue(section_id, direction)
        self._check_authority(authority, reason)
        if train_id not in q.left_behind:
            raise RegisterError("unknown-train", f"{train_id} holds nothing behind it in section {section_id} "
                                                 f"{direction}")
        del q.left_behind[train_id]
        q.version += 1
        return AuditRecord(authority.name, "section.clear_behind", _target(section_id, direction), reason,
                           (train_id,), ())

    def update(self, record: TrainRecord) -> None:
        """A train's new report: its record changes, its place in the queue never does."""
        record.check()
        at = self._where.get(record.train_id)
        if at is None:
            raise RegisterError("unknown-train", f"{record.train_id} is in no section")
        q = self.queues[at]
        self._check_inside(q, record)
        node = q.nodes[record.train_id]
        if node.ahead is not None and not q.ahead_of(node.ahead.record.km, record.km):
            raise RegisterError("order-conflict", f"{record.train_id} at km {record.km:.3f} would pass "
                                                  f"{node.ahead.record.train_id} at km {node.ahead.record.km:.3f}")
        if node.behind is not None and not q.ahead_of(record.km, node.behind.record.km):
            raise RegisterError("order-conflict", f"{record.train_id} at km {record.km:.3f} would fall behind "
                                                  f"{node.behind.record.train_id} at km {node.behind.record.km:.3f}")
        node.record = q.with_rear(record, node.record)

    # -- dispatcher actions (each returns the audit record) --
    def reorder(self, section_id: int, direction: str, order: list[str], authority: Authority | None,
                reason: str) -> AuditRecord:
        """A new order (front first) of the section's trains, on a dispatcher's authority."""
        q = self.queue(section_id, direction)
        self._check_authority(authority, reason)
        before = q.ids()
        if sorted(order) != sorted(before) or len(set(order)) != len(order):
            raise RegisterError("not-a-permutation", f"{list(order)} for {list(before)}")
        q._rebuild([q.nodes[t].record for t in order])
        q.version += 1
        return AuditRecord(authority.name, "section.reorder", _target(section_id, direction), reason, before,
                           tuple(order))

    def admit(self, section_id: int, direction: str, record: TrainRecord, authority: Authority | None,
              reason: str) -> AuditRecord:
        """A train starting its mission inside a section, placed where its chainage puts it."""
        q = self.queue(section_id, direction)
        self._check_authority(authority, reason)
        record.check()
        self._check_new(record)
        self._check_inside(q, record)
        before = q.ids()
        records = list(q)
        if any(r.km == record.km for r in records):
            raise RegisterError("order-conflict", f"{record.train_id} at the same km as another train")
        i = sum(1 for r in records if q.ahead_of(r.km, record.km))
        q._rebuild(records[:i] + [q.with_rear(record, None)] + records[i:])
        q.version += 1
        self._where[record.train_id] = (section_id, direction)
        return AuditRecord(authority.name, "section.admit", _target(section_id, direction), reason, before, q.ids())

    def withdraw(self, section_id: int, direction: str, train_id: str, authority: Authority | None,
                 reason: str) -> AuditRecord:
        """A train taken off the register wherever it is (lost radio, train withdrawn from service)."""
        q = self.queue(section_id, direction)
        self._check_authority(authority, reason)
        if train_id not in q.nodes:
            raise RegisterError("unknown-train", f"{train_id} in section {section_id} {direction}")
        before = q.ids()
        q._unlink(train_id)
        q.version += 1
        del self._where[train_id]
        return AuditRecord(authority.name, "section.withdraw", _target(section_id, direction), reason, before,
                           q.ids())

    # -- checks --
    def _check_new(self, record: TrainRecord) -> None:
        if record.train_id in self._where:
            sid, d = self._where[record.train_id]
            raise RegisterError("duplicate", f"{record.train_id} is in section {sid} {d}")

    @staticmethod
    def _check_inside(q: SectionQueue, record: TrainRecord) -> None:
        if not q.section.contains(record.km, BOUNDARY_ZONE_M):
            raise RegisterError("outside-section", f"{record.train_id} at km {record.km:.3f}, section "
                                                   f"{q.section.id} is km {q.section.km_begin}-{q.section.km_end}")

    @staticmethod
    def _check_authority(authority: Authority | None, reason: str) -> None:
        if authority is None or authority.role not in DISPATCHER_ROLES or not authority.name:
            raise RegisterError("no-authority", f"{authority!r}")
        if not reason or not reason.strip():
            raise RegisterError("no-authority", "no reason given")

    def snapshot(self) -> list[dict]:
        """Every section and direction with its trains front to rear (JSON-friendly)."""
        out = []
        for (sid, d), q in sorted(self.queues.items(), key=lambda kv: (kv[0][0], DIRECTIONS.index(kv[0][1]))):
            s = q.section
            out.append({"section": sid, "name": s.name, "direction": d, "km_begin": s.km_begin, "km_end": s.km_end,
                        "entry": s.entry_station(d), "exit": s.exit_station(d), "version": q.version,
                        "trains": [dataclasses.asdict(r) for r in q], "left_behind": dict(q.left_behind),
                        "occupied_from_km": q.occupied_from_km()})
        return out


def _target(section_id: int, direction: str) -> str:
    return f"section {section_id} {direction}"


def line_sections(stations: Iterable[tuple[str, float, float]], line_length_km: float) -> list[LineSection]:
    """The line sections between station areas (name, start km, end km), and from the line's ends."""
    areas = sorted(stations, key=lambda a: a[1])
    out: list[LineSection] = []
    prev_name, prev_km = LINE_END, 0.0
    for name, start, end in areas:
        if start > prev_km:
            out.append(LineSection(len(out) + 1, f"{prev_name} - {name}", prev_km, start, prev_name, name))
        prev_name, prev_km = name, end
    if line_length_km > prev_km:
        out.append(LineSection(len(out) + 1, f"{prev_name} - {LINE_END}", prev_km, line_length_km, prev_name,
                               LINE_END))
    return out

"""Application messages carried in RSD user data: centre -> RBC, RBC -> centre, onboard -> ATP.

One RSD's data is a sequence of messages, each

    version u8 (=1) | type u8 | body length u16 | body

little-endian like RSSP-I. Every body has a fixed part and at most one counted list; the layouts are
declared once in MESSAGE_LAYOUTS below. Decoding checks the version, that the declared length holds the
fixed part and exactly the counted list, and value ranges; a message that fails is counted by reason
and skipped (its length field lets the decoder carry on with the next one), a header that runs past the
end stops the walk. decode_payload never raises.
"""

from __future__ import annotations

import enum
import struct
from collections import Counter
from dataclasses import dataclass, field

MESSAGE_VERSION = 1
MESSAGE_HEADER = struct.Struct("<BBH")
NO_SECTION = 0xFFFF  # section id meaning "the whole line"
UNKNOWN_U16 = 0xFFFF
UNKNOWN_U32 = 0xFFFFFFFF
TRAIN_ID_BYTES = 20  # train and track names in SECTION_TRAINS: ASCII, NUL-padded
TRACK_ID_BYTES = 16
MAX_TEXT_BYTES = 80  # alarm text, ASCII; enough for an operator line, keeps a report inside one RSD


class SectionStatus(enum.IntEnum):
    OK = 0
    DEGRADED = 1
    DO_NOT_USE = 2


class Severity(enum.IntEnum):
    INFO = 0
    WARNING = 1
    CRITICAL = 2


class AlarmCode(enum.IntEnum):
    SECTION_DO_NOT_USE = 1  # integrity monitoring flagged a line section
    STATION_FAILED = 2
    SATELLITE_EXCLUDED = 3
    CORRECTION_STALE = 4  # correction-age watchdog
    LINK_LOST = 5  # RSSP-I link down / no fresh report
    INTEGRITY_LOST = 6  # onboard integrity alarm
    OPERATOR = 7
    SERVICE_BRAKE = 8  # onboard -> ATP: two consecutive linked virtual balise groups missed


class MessageType(enum.IntEnum):
    INTEGRITY_STATUS = 0x01
    EXCLUSIONS = 0x02
    CORRECTION_AGE = 0x03
    ALARM = 0x04
    RBC_ACK = 0x05
    SECTION_TRAINS = 0x06
    VIRTUAL_BALISE = 0x10


class TrainIntegrity(enum.IntEnum):
    """Train integrity (the train is complete) as the onboard unit reports it."""

    CONFIRMED = 0
    LOST = 1
    UNKNOWN = 2  # not monitored (no rear antenna / integrity device)


@dataclass(frozen=True)
class SectionIntegrity:
    section_id: int
    status: SectionStatus
    hpl_dm: int = UNKNOWN_U16  # horizontal protection level, decimetres; 0xFFFF unknown


@dataclass(frozen=True)
class IntegrityStatus:
    epoch_ms: int  # GPS time of the correction epoch the statuses belong to, ms
    report_seq: int
    sections: tuple[SectionIntegrity, ...]


@dataclass(frozen=True)
class Exclusions:
    epoch_ms: int
    satellites: tuple[str, ...]  # "G05", "C19", "E11", "R07"
    stations: tuple[int, ...]


@dataclass(frozen=True)
class CorrectionAge:
    epoch_ms: int
    age_ms: int  # age of the newest correction model at the centre when this report left
    max_age_ms: int  # the centre's limit: beyond it corrections must not be used


@dataclass(frozen=True)
class Alarm:
    epoch_ms: int
    alarm_id: int
    code: AlarmCode
    severity: Severity
    section_id: int = NO_SECTION
    text: str = ""


@dataclass(frozen=True)
class RbcAck:
    """Acknowledgement back along a link: RBC -> centre (last report seq, ids of alarms received),
    ATP -> onboard (alarm_ids = ids of the virtual balise telegrams received)."""

    last_report_seq: int
    alarm_ids: tuple[int, ...]


@dataclass(frozen=True)
class VirtualBaliseTelegram:
    """A virtual balise passage reported by the onboard positioning core to the ATP."""

    time_ms: int
    train_id: int
    balise_group: int  # NID_BG-like id of the virtual balise group in the track map
    track_id: int
    chainage_mm: int  # along-track position of the balise reference point
    reverse: bool  # direction of travel against the track's nominal direction
    confidence_mm: int  # along-track protection level at the passage
    speed_mm_s: int
    integrity: SectionStatus
    telegram_id: int  # u32, unique per passage across onboard restarts (random start); acked by id


@dataclass(frozen=True)
class SectionTrain:
    """One train of a section's queue (the centre's section register), in order front to rear."""

    train_id: str  # ASCII, at most TRAIN_ID_BYTES
    track: str  # ASCII, at most TRACK_ID_BYTES
    chainage_mm: int  # front of the train (its antenna)
    speed_mm_s: int
    length_dm: int
    integrity: TrainIntegrity
    correction_age_ms: int = UNKNOWN_U32  # 0xFFFFFFFF: the position used no corrections
    along_pl_cm: int = UNKNOWN_U16  # protection levels, centimetres; 0xFFFF unknown
    cross_pl_cm: int = UNKNOWN_U16
    hpl_cm: int = UNKNOWN_U16
    report_ms: int = 0  # GPS time of the train's position report, ms


@dataclass(frozen=True)
class SectionTrains:
    """The trains of one line section and direction in order, front (nearest the exit) first: state, sent
    in turn every cycle; `version` counts the queue's changes of membership or order."""

    epoch_ms: int  # GPS time the register held this picture, ms
    section_id: int  # the section register's line section (between stations), not an integrity section
    direction: int  # 0 up (increasing chainage), 1 down
    version: int
    trains: tuple[SectionTrain, ...]


Message = IntegrityStatus | Exclusions | CorrectionAge | Alarm | RbcAck | SectionTrains | VirtualBaliseTelegram

# ----------------------------------------------------------------- layouts (one source of truth)
# type -> (fixed part, counted-list item or None). The fixed part's last field is the list count.
_INTEGRITY_FIXED = struct.Struct("<QIH")  # epoch_ms, report_seq, n_sections
_INTEGRITY_ITEM = struct.Struct("<HBH")  # section_id, status, hpl_dm
_EXCLUSIONS_FIXED = struct.Struct("<QBB")  # epoch_ms, n_satellites, n_stations
_EXCL_SAT = struct.Struct("<cB")  # system letter, PRN
_EXCL_STATION = struct.Struct("<H")
_AGE_FIXED = struct.Struct("<QII")
_ALARM_FIXED = struct.Struct("<QIHBHB")  # epoch_ms, alarm_id, code, severity, section_id, text length
_ACK_FIXED = struct.Struct("<IB")  # last_report_seq, n_alarm_ids
_ACK_ITEM = struct.Struct("<I")
_BALISE_FIXED = struct.Struct("<QIIHQBIIBI")
_SECTION_FIXED = struct.Struct("<QHBIB")  # epoch_ms, section_id, direction, version, n_trains
_SECTION_ITEM = struct.Struct(f"<{TRAIN_ID_BYTES}s{TRACK_ID_BYTES}sQIHBIHHHQ")  # SectionTrain's fields in order

MESSAGE_LAYOUTS: dict[MessageType, tuple[struct.Struct, struct.Struct | None]] = {
    MessageType.INTEGRITY_STATUS: (_INTEGRITY_FIXED, _INTEGRITY_ITEM),
    MessageType.EXCLUSIONS: (_EXCLUSIONS_FIXED, None),  # two lists: satellites then stations
    MessageType.CORRECTION_AGE: (_AGE_FIXED, None),
    MessageType.ALARM: (_ALARM_FIXED, None),  # then text bytes
    MessageType.RBC_ACK: (_ACK_FIXED, _ACK_ITEM),
    MessageType.SECTION_TRAINS: (_SECTION_FIXED, _SECTION_ITEM),
    MessageType.VIRTUAL_BALISE: (_BALISE_FIXED, None),
}
SATELLITE_SYSTEMS = b"GCERJ"


class MessageError(ValueError):
    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


def _frame(msg_type: MessageType, body: bytes) -> bytes:
    if len(body) > 0xFFFF:
        raise ValueError("message body too long")
    return MESSAGE_HEADER.pack(MESSAGE_VERSION, msg_type, len(body)) + body


def encode_message(msg: Message) -> bytes:
    if isinstance(msg, IntegrityStatus):
        body = _INTEGRITY_FIXED.pack(msg.epoch_ms, msg.report_seq, len(msg.sections)) + b"".join(
            _INTEGRITY_ITEM.pack(s.section_id, int(s.status), s.hpl_dm) for s in msg.sections
        )
        return _frame(MessageType.INTEGRITY_STATUS, body)
    if isinstance(msg, Exclusions):
        sats = b"".join(_EXCL_SAT.pack(s[0].encode("ascii"), int(s[1:])) for s in msg.satellites)
        stations = b"".join(_EXCL_STATION.pack(s) for s in msg.stations)
        body = _EXCLUSIONS_FIXED.pack(msg.epoch_ms, len(msg.satellites), len(msg.stations)) + sats + stations
        return _frame(MessageType.EXCLUSIONS, body)
    if isinstance(msg, CorrectionAge):
        return _frame(MessageType.CORRECTION_AGE, _AGE_FIXED.pack(msg.epoch_ms, msg.age_ms, msg.max_age_ms))
    if isinstance(msg, Alarm):
        text = msg.text.encode("ascii", "replace")[:MAX_TEXT_BYTES]
        fixed = _ALARM_FIXED.pack(msg.epoch_ms, msg.alarm_id, int(msg.code), int(msg.severity), msg.section_id, len(text))
        return _frame(MessageType.ALARM, fixed + text)
    if isinstance(msg, RbcAck):
        body = _ACK_FIXED.pack(msg.last_report_seq, len(msg.alarm_ids)) + b"".join(
            _ACK_ITEM.pack(a) for a in msg.alarm_ids
        )
        return _frame(MessageType.RBC_ACK, body)
    if isinstance(msg, SectionTrains):
        if len(msg.trains) > 0xFF or msg.direction not in (0, 1):
            raise ValueError(f"section {msg.section_id}: {len(msg.trains)} trains, direction {msg.direction}")
        body = _SECTION_FIXED.pack(msg.epoch_ms, msg.section_id, msg.direction, msg.version & 0xFFFFFFFF,
                                   len(msg.trains)) + b"".join(
            _SECTION_ITEM.pack(_ascii(t.train_id, TRAIN_ID_BYTES), _ascii(t.track, TRACK_ID_BYTES), t.chainage_mm,
                               t.speed_mm_s, t.length_dm, int(t.integrity), t.correction_age_ms, t.along_pl_cm,
                               t.cross_pl_cm, t.hpl_cm, t.report_ms)
            for t in msg.trains)
        return _frame(MessageType.SECTION_TRAINS, body)
    if isinstance(msg, VirtualBaliseTelegram):
        body = _BALISE_FIXED.pack(
            msg.time_ms, msg.train_id, msg.balise_group, msg.track_id, msg.chainage_mm, int(msg.reverse),
            msg.confidence_mm, msg.speed_mm_s, int(msg.integrity), msg.telegram_id,
        )
        return _frame(MessageType.VIRTUAL_BALISE, body)
    raise TypeError(f"not a message: {msg!r}")


def _ascii(text: str, size: int) -> bytes:
    b = text.encode("ascii")
    if len(b) > size or b"\0" in b:
        raise ValueError(f"{text!r}: at most {size} ASCII characters")
    return b


def _unpad(raw: bytes, what: str) -> str:
    try:
        return raw.rstrip(b"\0").decode("ascii")
    except UnicodeDecodeError as exc:
        raise MessageError("value", f"{what} is not ASCII") from exc


def encode_payload(messages: list[Message] | tuple[Message, ...]) -> bytes:
    return b"".join(encode_message(m) for m in messages)


def _enum(cls, value: int, what: str):
    try:
        return cls(value)
    except ValueError as exc:
        raise MessageError("value", f"{what} {value}") from exc


def _exact(body: bytes, expected: int, what: str) -> None:
    if len(body) != expected:
        raise MessageError("length", f"{what}: body {len(body)} bytes, layout needs {expected}")


def decode_message(msg_type: int, body: bytes) -> Message:
    """Decode one message body of a known type. Raises MessageError."""
    try:
        kind = MessageType(msg_type)
    except ValueError as exc:
        raise MessageError("unknown_type", f"{msg_type:#04x}") from exc
    fixed, item = MESSAGE_LAYOUTS[kind]
    if len(body) < fixed.size:
        raise MessageError("length", f"{kind.name}: body {len(body)} bytes < {fixed.size}")
    values = fixed.unpack_from(body, 0)
    rest = body[fixed.size :]
    if kind is MessageType.INTEGRITY_STATUS:
        epoch, seq, n = values
        _exact(rest, n * item.size, kind.name)  # type: ignore[union-attr]
        sections = tuple(
            SectionIntegrity(sid, _enum(SectionStatus, st, "section status"), hpl)
            for sid, st, hpl in (item.unpack_from(rest, i * item.size) for i in range(n))  # type: ignore[union-attr]
        )
        return IntegrityStatus(epoch, seq, sections)
    if kind is MessageType.EXCLUSIONS:
        epoch, n_sat, n_sta = values
        _exact(rest, n_sat * _EXCL_SAT.size + n_sta * _EXCL_STATION.size, kind.name)
        sats = []
        for i in range(n_sat):
            system, prn = _EXCL_SAT.unpack_from(rest, i * _EXCL_SAT.size)
            if system not in [bytes([c]) for c in SATELLITE_SYSTEMS] or not 1 <= prn <= 99:
                raise MessageError("value", f"satellite {system!r}{prn}")
            sats.append(f"{system.decode()}{prn:02d}")
        off = n_sat * _EXCL_SAT.size
        stations = tuple(_EXCL_STATION.unpack_from(rest, off + 2 * i)[0] for i in range(n_sta))
        return Exclusions(epoch, tuple(sats), stations)
    if kind is MessageType.CORRECTION_AGE:
        _exact(rest, 0, kind.name)
        return CorrectionAge(*values)
    if kind is MessageType.ALARM:
        epoch, alarm_id, code, severity, section, text_len = values
        _exact(rest, text_len, kind.name)
        try:
            text = rest.decode("ascii")
        except UnicodeDecodeError as exc:
            raise MessageError("value", "alarm text is not ASCII") from exc
        return Alarm(epoch, alarm_id, _enum(AlarmCode, code, "alarm code"), _enum(Severity, severity, "severity"), section, text)
    if kind is MessageType.RBC_ACK:
        last, n = values
        _exact(rest, n * _ACK_ITEM.size, kind.name)
        return RbcAck(last, tuple(_ACK_ITEM.unpack_from(rest, 4 * i)[0] for i in range(n)))
    if kind is MessageType.SECTION_TRAINS:
        epoch, section, direction, version, n = values
        _exact(rest, n * _SECTION_ITEM.size, kind.name)
        if direction not in (0, 1):
            raise MessageError("value", f"direction {direction}")
        trains = []
        for i in range(n):
            values_i = _SECTION_ITEM.unpack_from(rest, i * _SECTION_ITEM.size)
            tid, track, ch, speed, length, integ, age, apl, cpl, hpl, rep = values_i
            name = _unpad(tid, "train id")
            if not name:
                raise MessageError("value", "empty train id")
            trains.append(SectionTrain(name, _unpad(track, "track"), ch, speed, length,
                                       _enum(TrainIntegrity, integ, "train integrity"), age, apl, cpl, hpl, rep))
        return SectionTrains(epoch, section, direction, version, tuple(trains))
    _exact(rest, 0, kind.name)
    t, train, group, track, chainage, reverse, conf, speed, integrity, telegram_id = values
    if reverse not in (0, 1):
        raise MessageError("value", f"direction {reverse}")
    return VirtualBaliseTelegram(
        t, train, group, track, chainage, bool(reverse), conf, speed, _enum(SectionStatus, integrity, "integrity"), telegram_id
    )


@dataclass
class DecodeResult:
    messages: list[Message] = field(default_factory=list)
    errors: Counter[str] = field(default_factory=Counter)


def decode_payload(data: bytes | bytearray | memoryview, errors: Counter[str] | None = None) -> DecodeResult:
    """Every decodable message of an RSD's data; the rest counted in `errors` by reason."""
    result = DecodeResult(errors=errors if errors is not None else Counter())
    data = bytes(data)
    off = 0
    while off < len(data):
        if len(data) - off < MESSAGE_HEADER.size:
            result.errors["truncated"] += 1
            break
        version, msg_type, length = MESSAGE_HEADER.unpack_from(data, off)
        off += MESSAGE_HEADER.size
        if off + length > len(data):
            result.errors["truncated"] += 1
            break
        body = data[off : off + length]
        off += length
        if version != MESSAGE_VERSION:
            result.errors["version"] += 1
            continue
        try:
            result.messages.append(decode_message(msg_type, body))
        except MessageError as exc:
            result.errors[exc.reason] += 1
    return result

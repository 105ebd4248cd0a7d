"""The train's position report to the centre: its own message (not its GGA), one datagram, sans-IO codec.

    data = encode(PositionReport(...))      # bytes for one datagram on the train's radio link
    report = decode(data)                   # raises ReportError naming the field or the check

What the centre's section register needs of a train (railway.md, "Train information management": id,
position, speed, length, integrity, correction age; and the protection levels), which a GGA sentence
cannot carry: the track and chainage from the track map, the direction of travel, the train's length
(train data entry, as ETCS L_TRAIN), the train-integrity state and the protection levels.

Layout (little-endian, `REPORT_LAYOUT` is the one source of truth), then a CRC-32 (zlib, ISO-HDLC) over
everything before it, as the radio bearer gives no end-to-end check of its own:
    magic 2s b"TP" | version u8 | seq u32 | time_ms u64 (GPS time) | train_id 20s | track 16s
    | km_mm i64 | direction u8 | speed_mm_s u32 | length_cm u32 | integrity u8 | correction_age_ms u32
    | along_pl_mm u32 | cross_pl_mm u32 | hpl_mm u32 | vpl_mm u32 | track_confirmed u8 | crc32 u32
Text fields are ASCII, NUL-padded; an unknown u32 quantity is 0xFFFFFFFF.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass

MAGIC = b"TP"
VERSION = 1
UNKNOWN_U32 = 0xFFFFFFFF
DIRECTIONS = ("up", "down", "unknown")  # up: increasing chainage; unknown: standstill since switch-on
INTEGRITY_STATES = ("confirmed", "lost", "unknown")  # train integrity (augnet.system.section_register)
TRAIN_ID_BYTES = 20  # stations.scenario.Train.id: at most 20 characters
TRACK_ID_BYTES = 16  # "L1-S2-1" and railML track ids of that length
# (name, struct code) in wire order; the CRC follows
REPORT_LAYOUT = (
    ("magic", "2s"), ("version", "B"), ("seq", "I"), ("time_ms", "Q"), ("train_id", f"{TRAIN_ID_BYTES}s"),
    ("track", f"{TRACK_ID_BYTES}s"), ("km_mm", "q"), ("direction", "B"), ("speed_mm_s", "I"),
    ("length_cm", "I"), ("integrity", "B"), ("correction_age_ms", "I"), ("along_pl_mm", "I"),
    ("cross_pl_mm", "I"), ("hpl_mm", "I"), ("vpl_mm", "I"), ("track_confirmed", "B"),
)
_BODY = struct.Struct("<" + "".join(code for _n, code in REPORT_LAYOUT))
_CRC = struct.Struct("<I")
REPORT_BYTES = _BODY.size + _CRC.size
# A train must move this far along the track (and at least its along-track protection level) before its
# direction is taken from the chainage [m]: over a float solution's along-track noise (decimetres), so a
# standing train does not flip.
MIN_DIRECTION_MOVE_M = 2.0
# The train's length when no train data entry gives one [m]: a CR400AF 8-car EMU (CRRC, 209 m).
DEFAULT_TRAIN_LENGTH_M = 209.0


class ReportError(ValueError):
    pass


@dataclass(frozen=True)
class PositionReport:
    train_id: str
    seq: int
    time_s: float  # GPS time of the position [s]
    track: str  # "" off the map
    km: float  # chainage of the antenna [km]
    direction: str  # DIRECTIONS
    speed_m_s: float
    length_m: float
    integrity: str  # INTEGRITY_STATES
    correction_age_s: float | None
    along_pl_m: float | None
    cross_pl_m: float | None
    hpl_m: float | None
    vpl_m: float | None
    track_confirmed: bool


def _u32(value: float | None, scale: float) -> int:
    if value is None or not math.isfinite(value):
        return UNKNOWN_U32
    return max(0, min(int(round(value * scale)), UNKNOWN_U32 - 1))


def _opt(raw: int, scale: float) -> float | None:
    return None if raw == UNKNOWN_U32 else raw / scale


def _text(value: str, size: int, what: str) -> bytes:
    b = value.encode("ascii")
    if len(b) > size or b"\0" in b:
        raise ReportError(f"{what} {value!r}: at most {size} ASCII characters")
    return b


def encode(r: PositionReport) -> bytes:
    if r.direction not in DIRECTIONS or r.integrity not in INTEGRITY_STATES:
        raise ReportError(f"direction {r.direction!r} / integrity {r.integrity!r}")
    body = _BODY.pack(MAGIC, VERSION, r.seq & 0xFFFFFFFF, int(round(r.time_s * 1000)),
                      _text(r.train_id, TRAIN_ID_BYTES, "train_id"), _text(r.track, TRACK_ID_BYTES, "track"),
                      int(round(r.km * 1e6)), DIRECTIONS.index(r.direction), _u32(r.speed_m_s, 1e3),
                      _u32(r.length_m, 1e2), INTEGRITY_STATES.index(r.integrity), _u32(r.correction_age_s, 1e3),
                      _u32(r.along_pl_m, 1e3), _u32(r.cross_pl_m, 1e3), _u32(r.hpl_m, 1e3), _u32(r.vpl_m, 1e3),
                      int(bool(r.track_confirmed)))
    return body + _CRC.pack(zlib.crc32(body))


def decode(data: bytes) -> PositionReport:
    if len(data) != REPORT_BYTES:
        raise ReportError(f"length {len(data)} bytes, a report is {REPORT_BYTES}")
    body = data[:_BODY.size]
    if _CRC.unpack_from(data, _BODY.size)[0] != zlib.crc32(body):
        raise ReportError("crc32 mismatch")
    v = dict(zip((n for n, _c in REPORT_LAYOUT), _BODY.unpack(body)))
    if v["magic"] != MAGIC:
        raise ReportError(f"magic {v['magic']!r}")
    if v["version"] != VERSION:
        raise ReportError(f"version {v['version']}")
    for name, table in (("direction", DIRECTIONS), ("integrity", INTEGRITY_STATES)):
        if v[name] >= len(table):
            raise ReportError(f"{name} {v[name]}")
    if v["track_confirmed"] not in (0, 1):
        raise ReportError(f"track_confirmed {v['track_confirmed']}")
    try:
        tid = v["train_id"].rstrip(b"\0").decode("ascii")
        track = v["track"].rstrip(b"\0").decode("ascii")
    except UnicodeDecodeError as exc:
        raise ReportError("train_id / track not ASCII") from exc
    if not tid:
        raise ReportError("train_id empty")
    return PositionReport(tid, v["seq"], v["time_ms"] / 1000.0, track, v["km_mm"] / 1e6,
                          DIRECTIONS[v["direction"]], v["speed_mm_s"] / 1e3, v["length_cm"] / 1e2,
                          INTEGRITY_STATES[v["integrity"]], _opt(v["correction_age_ms"], 1e3),
                          _opt(v["along_pl_mm"], 1e3), _opt(v["cross_pl_mm"], 1e3), _opt(v["hpl_mm"], 1e3),
                          _opt(v["vpl_mm"], 1e3), bool(v["track_confirmed"]))


class ReportBuilder:
    """The onboard side: a report from each map-matched position, direction and speed from the chainage.

    Direction and speed come from the chainage between reports (the map's along-track axis), not from the
    GNSS velocity: the register orders trains by chainage."""

    def __init__(self, train_id: str, length_m: float, integrity: str = "unknown"):
        self.train_id = train_id
        self.length_m = length_m
        self.integrity = integrity
        self.seq = 0
        self.direction = "unknown"
        self._prev: tuple[float, float] | None = None  # time [s], km of the last report
        self._anchor_km: float | None = None  # chainage the direction was last judged from

    def build(self, time_s: float, track: str | None, km: float, *, correction_age_s, along_pl_m, cross_pl_m,
              hpl_m, vpl_m, track_confirmed: bool) -> PositionReport:
        speed = 0.0
        if self._prev is not None and time_s > self._prev[0]:
            speed = abs(km - self._prev[1]) * 1e3 / (time_s - self._prev[0])
        self._prev = (time_s, km)
        # a move smaller than the along-track protection level may be noise (a single-point solution's metres)
        threshold_m = max(MIN_DIRECTION_MOVE_M, along_pl_m if along_pl_m is not None and math.isfinite(along_pl_m)
                          else 0.0)
        if self._anchor_km is None:
            self._anchor_km = km
        elif abs(km - self._anchor_km) * 1e3 >= threshold_m:
            self.direction = "up" if km > self._anchor_km else "down"
            self._anchor_km = km
        self.seq += 1
        return PositionReport(self.train_id, self.seq, time_s, track or "", km, self.direction, speed, self.length_m,
                              self.integrity, correction_age_s, along_pl_m, cross_pl_m, hpl_m, vpl_m, track_confirmed)

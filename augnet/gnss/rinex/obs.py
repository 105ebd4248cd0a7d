"""RINEX observation files: RINEX 3.00-3.05 read, RINEX 3.04 write, RINEX 2.10/2.11 read.

Array form (`ObsData`): `times` (E,) GPST seconds of the epochs, `sats` (S,) satellite ids, and
for every observation type ('C1C', 'L1C', ... as in the header; RINEX 2 types such as 'C1', 'P2'
as they are) a float (E, S) array with NaN where missing, plus LLI and signal-strength (SSI)
digit arrays (E, S) of int8 (0 where blank).  A type is shared between systems ('C1C' of GPS and
of Galileo live in one array; each satellite's column only holds its own system's types).

Epoch flags (RINEX 3.04 Table A13): 0 OK, 1 power failure, 6 cycle-slip records are kept as
epochs; 2-5 are event records whose following header lines are skipped (counted in `events`).
Times: epochs in a GPS/GAL/QZS time-system file are GPST; in a BDT file they are shifted to GPST.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import os
from dataclasses import dataclass, field

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.rinex.errors import (
    LABEL_COLUMN,
    RinexError,
    open_text_for_write,
    parse_float,
    parse_int,
    is_ascii_digits,
    parse_sat_id,
    read_lines,
)

WRITE_VERSION = 3.04
OBS_FIELD_WIDTH = 16  # F14.3 value + I1 LLI + I1 SSI
OBS_TYPES_PER_LINE_V3 = 13  # SYS / # / OBS TYPES
OBS_TYPES_PER_LINE_V2 = 9  # # / TYPES OF OBSERV
OBS_PER_LINE_V2 = 5
SATS_PER_EPOCH_LINE_V2 = 12
MAX_OBS_VALUE = 9_999_999_999.999  # largest value F14.3 holds
MIN_OBS_VALUE = -999_999_999.999  # the sign takes a column
KEPT_FLAGS = (0, 1, 6)
SYSTEM_TIME_NAMES = {"G": "GPS", "E": "GAL", "C": "BDT", "J": "QZS", "R": "GLO", "M": "GPS", "S": "GPS", "I": "IRN"}


@dataclass
class ObsHeader:
    version: float = WRITE_VERSION
    system: str = "M"  # file's satellite system: 'M' mixed or a letter
    program: str = "augnet"
    run_by: str = ""
    date: str = ""
    marker_name: str = ""
    marker_number: str = ""
    marker_type: str = ""
    observer: str = ""
    agency: str = ""
    receiver_number: str = ""
    receiver_type: str = ""
    receiver_version: str = ""
    antenna_number: str = ""
    antenna_type: str = ""
    approx_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    antenna_delta_hen_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    obs_types: dict[str, list[str]] = field(default_factory=dict)  # system letter -> types
    signal_strength_unit: str = ""
    interval_s: float | None = None
    time_of_first_obs: float | None = None  # GPST seconds
    time_of_last_obs: float | None = None
    time_system: str = "GPS"
    leap_seconds: int | None = None
    comments: list[str] = field(default_factory=list)
    extra: list[tuple[str, str]] = field(default_factory=list)  # other header lines, verbatim


@dataclass
class ObsData:
    header: ObsHeader
    times: np.ndarray  # (E,) GPST seconds
    flags: np.ndarray  # (E,) epoch flags
    clock_offset_s: np.ndarray  # (E,) receiver clock offset from the epoch line, NaN if absent
    sats: np.ndarray  # (S,) "<U3", sorted by system letter then PRN (the reader sorts)
    obs: dict[str, np.ndarray]  # type -> (E, S) float, NaN missing
    lli: dict[str, np.ndarray]  # type -> (E, S) int8
    ssi: dict[str, np.ndarray]  # type -> (E, S) int8
    events: int = 0  # event records (flags 2-5) skipped

    def sat_index(self, sat: str) -> int:
        hits = np.flatnonzero(self.sats == sat)
        if not len(hits):
            raise KeyError(sat)
        return int(hits[0])


# --------------------------------------------------------------------------------------------
# reading


def read_obs(path: str | os.PathLike) -> ObsData:
    """Read a RINEX 3.0x or 2.1x observation file (plain or gzip)."""
    lines = read_lines(path)
    if not lines:
        raise RinexError(path, 1, "empty file")
    if lines[0][LABEL_COLUMN:].strip() != "RINEX VERSION / TYPE":
        raise RinexError(path, 1, "first line is not 'RINEX VERSION / TYPE'")
    version = parse_float(lines[0][0:9], path, 1, "RINEX version", blank=-1.0)
    if lines[0][20:21] != "O":
        raise RinexError(path, 1, f"not an observation file (file type {lines[0][20:21]!r})")
    if 3.0 <= version < 4.0:
        header, start = _read_header(lines, path, version)
        return _read_body_v3(lines, start, header, path)
    if 2.0 <= version < 3.0:
        header, start = _read_header(lines, path, version)
        return _read_body_v2(lines, start, header, path)
    raise RinexError(path, 1, f"RINEX version {version} not supported (2.1x, 3.0x)")


def _read_header(lines: list[str], path, version: float) -> tuple[ObsHeader, int]:
    first = lines[0]
    hdr = ObsHeader(version=version, system=first[40:41].strip() or "G")
    pending_sys = None  # continuation of SYS / # / OBS TYPES
    pending_count = 0
    v2_types: list[str] = []
    v2_count = 0
    for k in range(1, len(lines)):
        line = lines[k]
        ln = k + 1
        label = line[LABEL_COLUMN:].strip()
        c = line[:LABEL_COLUMN].ljust(LABEL_COLUMN)
        if label == "END OF HEADER":
            if pending_sys is not None and len(hdr.obs_types[pending_sys]) != pending_count:
                raise RinexError(path, ln, f"SYS / # / OBS TYPES of {pending_sys}: fewer types than announced")
            if version < 3.0:
                if len(v2_types) != v2_count:
                    raise RinexError(path, ln, "# / TYPES OF OBSERV: fewer types than announced")
                systems = [hdr.system] if hdr.system != "M" else ["G", "R", "E", "S", "C", "J"]
                hdr.obs_types = {s: list(v2_types) for s in systems}
            if not hdr.obs_types:
                raise RinexError(path, ln, "header has no observation types")
            return hdr, k + 1
        if label == "PGM / RUN BY / DATE":
            hdr.program, hdr.run_by, hdr.date = c[0:20].strip(), c[20:40].strip(), c[40:60].strip()
        elif label == "COMMENT":
            hdr.comments.append(c.rstrip())
        elif label == "MARKER NAME":
            hdr.marker_name = c[0:60].strip()
        elif label == "MARKER NUMBER":
            hdr.marker_number = c[0:20].strip()
        elif label == "MARKER TYPE":
            hdr.marker_type = c[0:20].strip()
        elif label == "OBSERVER / AGENCY":
            hdr.observer, hdr.agency = c[0:20].strip(), c[20:60].strip()
        elif label == "REC # / TYPE / VERS":
            hdr.receiver_number, hdr.receiver_type, hdr.receiver_version = c[0:20].strip(), c[20:40].strip(), c[40:60].strip()
        elif label == "ANT # / TYPE":
            hdr.antenna_number, hdr.antenna_type = c[0:20].strip(), c[20:40].strip()
        elif label == "APPROX POSITION XYZ":
            hdr.approx_position_m = tuple(parse_float(c[a : a + 14], path, ln, "approx position") for a in (0, 14, 28))
        elif label == "ANTENNA: DELTA H/E/N":
            hdr.antenna_delta_hen_m = tuple(parse_float(c[a : a + 14], path, ln, "antenna delta") for a in (0, 14, 28))
        elif label == "SYS / # / OBS TYPES":
            if c[0] != " ":
                if pending_sys is not None and len(hdr.obs_types[pending_sys]) != pending_count:
                    raise RinexError(path, ln, f"SYS / # / OBS TYPES of {pending_sys}: fewer types than announced")
                pending_sys = c[0]
                pending_count = parse_int(c[3:6], path, ln, "number of observation types", blank=None)
                hdr.obs_types[pending_sys] = []
            elif pending_sys is None:
                raise RinexError(path, ln, "SYS / # / OBS TYPES continuation without a system")
            # Fixed columns (1X,A3 each from column 8): some receivers write 2-character types
            # such as Septentrio's channel 'X1 ', so split by column, not by blanks.
            remaining = pending_count - len(hdr.obs_types[pending_sys])
            types = [c[7 + 4 * k : 10 + 4 * k].strip() for k in range(min(OBS_TYPES_PER_LINE_V3, remaining))]
            if "" in types:
                raise RinexError(path, ln, f"SYS / # / OBS TYPES of {pending_sys}: fewer types than announced ({pending_count})")
            for t in types:
                if not 2 <= len(t) <= 3 or not t[0].isalpha():
                    raise RinexError(path, ln, f"bad observation type {t!r}")
            hdr.obs_types[pending_sys].extend(types)
            if len(hdr.obs_types[pending_sys]) > pending_count:
                raise RinexError(path, ln, f"SYS / # / OBS TYPES of {pending_sys}: more types than announced")
        elif label == "# / TYPES OF OBSERV":
            if c[0:6].strip():
                v2_count = parse_int(c[0:6], path, ln, "number of observation types", blank=None)
            v2_types.extend(c[6:60].split())
        elif label == "SIGNAL STRENGTH UNIT":
            hdr.signal_strength_unit = c[0:20].strip()
        elif label == "INTERVAL":
            hdr.interval_s = parse_float(c[0:10], path, ln, "interval")
        elif label in ("TIME OF FIRST OBS", "TIME OF LAST OBS"):
            tsys = c[48:51].strip() or ("GPS" if hdr.system in ("G", "M") else SYSTEM_TIME_NAMES.get(hdr.system, "GPS"))
            t = _header_time(c, path, ln)
            if label == "TIME OF FIRST OBS":
                hdr.time_system = tsys
                hdr.time_of_first_obs = t
            else:
                hdr.time_of_last_obs = t
        elif label == "LEAP SECONDS":
            hdr.leap_seconds = parse_int(c[0:6], path, ln, "leap seconds")
        elif label:
            hdr.extra.append((c, label))
        elif line.strip():
            raise RinexError(path, ln, "header line without a label (END OF HEADER missing?)")
    raise RinexError(path, len(lines), "END OF HEADER not found")


def _header_time(c: str, path, ln: int) -> float:
    y = parse_int(c[0:6], path, ln, "year", blank=None)
    mo = parse_int(c[6:12], path, ln, "month", blank=None)
    d = parse_int(c[12:18], path, ln, "day", blank=None)
    h = parse_int(c[18:24], path, ln, "hour", blank=None)
    mi = parse_int(c[24:30], path, ln, "minute", blank=None)
    s = parse_float(c[30:43], path, ln, "second")
    try:
        return gtime.from_calendar(y, mo, d, h, mi, s)
    except gtime.TimeError as exc:
        raise RinexError(path, ln, str(exc)) from None


def _to_gpst(t_label: float, time_system: str) -> float:
    # A calendar label in BDT is 14 s behind GPST; GPS, GAL and QZS labels are GPST already.
    return t_label + 14.0 if time_system == "BDT" else t_label


class _Collector:
    """Gathers epochs and raw satellite records, then parses all records of a system at once.

    The values are fixed-width fields (F14.3, I1, I1): a system's records become one byte matrix
    and each type one column slice, converted by numpy, rather than 16-character slices in
    Python (several times faster on the 3.4 MB test files).  A record that does not convert is re-read
    field by field to name its line and field.
    """

    def __init__(self, obs_types: dict[str, list[str]], path, fields_per_line: int | None):
        self.obs_types = obs_types
        self.path = path
        self.fields_per_line = fields_per_line  # RINEX 2 wraps records after 5 fields
        self.times: list[float] = []
        self.flags: list[int] = []
        self.clock: list[float] = []
        self.sat_col: dict[str, int] = {}
        # per system: epoch indices, satellite columns, record texts, first line numbers
        self.records: dict[str, tuple[list[int], list[int], list[str], list[int]]] = {}

    def add(self, e_i: int, sat: str, text: str, line_no: int) -> None:
        col = self.sat_col.get(sat)
        if col is None:
            col = self.sat_col[sat] = len(self.sat_col)
        rec = self.records.get(sat[0])
        if rec is None:
            rec = self.records[sat[0]] = ([], [], [], [])
        rec[0].append(e_i)
        rec[1].append(col)
        rec[2].append(text)
        rec[3].append(line_no)

    def finish(self, header: ObsHeader, events: int) -> ObsData:
        n_e = len(self.times)
        order = sorted(self.sat_col, key=lambda s: (s[0], s[1:]))
        remap = np.empty(len(order), dtype=int)
        for new, sat in enumerate(order):
            remap[self.sat_col[sat]] = new
        n_s = len(order)
        all_types: list[str] = []
        for types in header.obs_types.values():
            for t in types:
                if t not in all_types:
                    all_types.append(t)
        obs = {t: np.full((n_e, n_s), np.nan) for t in all_types}
        lli = {t: np.zeros((n_e, n_s), dtype=np.int8) for t in all_types}
        ssi = {t: np.zeros((n_e, n_s), dtype=np.int8) for t in all_types}
        for sys_letter, (e_idx, cols, texts, line_nos) in self.records.items():
            types = header.obs_types.get(sys_letter, [])
            vals, llis, ssis = self._parse_records(texts, line_nos, len(types))
            rows = np.asarray(e_idx, dtype=int)
            s_idx = remap[np.asarray(cols, dtype=int)]
            for k, t in enumerate(types):
                obs[t][rows, s_idx] = vals[:, k]
                lli[t][rows, s_idx] = llis[:, k]
                ssi[t][rows, s_idx] = ssis[:, k]
        return ObsData(
            header,
            np.array(self.times, dtype=float),
            np.array(self.flags, dtype=np.int8),
            np.array(self.clock, dtype=float),
            np.array(order, dtype="<U3"),
            obs,
            lli,
            ssi,
            events,
        )

    def _parse_records(self, texts: list[str], line_nos: list[int], n_types: int):
        n = len(texts)
        width = n_types * OBS_FIELD_WIDTH
        vals = np.full((n, n_types), np.nan)
        llis = np.zeros((n, n_types), dtype=np.int8)
        ssis = np.zeros((n, n_types), dtype=np.int8)
        if n == 0 or n_types == 0:
            return vals, llis, ssis
        raw = "".join(t[:width].ljust(width) for t in texts).encode("latin-1")
        u8 = np.frombuffer(raw, dtype=np.uint8).reshape(n, width)
        try:
            for k in range(n_types):
                a = k * OBS_FIELD_WIDTH
                field_bytes = u8[:, a : a + 14]
                present = ~(field_bytes == 0x20).all(axis=1)
                if present.any():
                    strings = np.ascontiguousarray(field_bytes[present]).view("S14").ravel()
                    v = strings.astype(float)  # ValueError on anything float() refuses
                    if not np.isfinite(v).all():
                        raise ValueError("non-finite value")
                    vals[present, k] = v
                for out, col in ((llis, a + 14), (ssis, a + 15)):
                    c = u8[:, col].astype(np.int16)
                    blank = c == 0x20
                    digit = (c >= 0x30) & (c <= 0x39)
                    if not (blank | digit).all():
                        raise ValueError("bad flag")
                    out[:, k] = np.where(digit, c - 0x30, 0)
        except ValueError:
            for text, ln in zip(texts, line_nos):
                _parse_obs_fields(text, n_types, self.path, ln, self.fields_per_line)
            raise  # unreachable unless the two parsers disagree
        return vals, llis, ssis


def _parse_obs_fields(text: str, n_types: int, path, ln: int, fields_per_line: int | None = None):
    """One record, field by field, raising RinexError at the first bad field (its own line)."""
    vals, llis, ssis = [], [], []
    for k in range(n_types):
        at = ln + (k // fields_per_line if fields_per_line else 0)
        a = k * OBS_FIELD_WIDTH
        f = text[a : a + OBS_FIELD_WIDTH].ljust(OBS_FIELD_WIDTH)
        v = f[0:14]
        if v.strip():
            try:
                x = float(v)
            except ValueError:
                raise RinexError(path, at, f"observation {k + 1}: not a number: {v.strip()!r}") from None
            if not math.isfinite(x):
                raise RinexError(path, at, f"observation {k + 1}: not a finite number: {v.strip()!r}")
            vals.append(x)
        else:
            vals.append(math.nan)
        lc, sc = f[14], f[15]
        if lc != " " and not is_ascii_digits(lc):
            raise RinexError(path, at, f"observation {k + 1}: bad LLI {lc!r}")
        if sc != " " and not is_ascii_digits(sc):
            raise RinexError(path, at, f"observation {k + 1}: bad signal strength {sc!r}")
        llis.append(int(lc) if lc != " " else 0)
        ssis.append(int(sc) if sc != " " else 0)
    return vals, llis, ssis


def _read_body_v3(lines: list[str], start: int, header: ObsHeader, path) -> ObsData:
    col = _Collector(header.obs_types, path, None)
    known_sats: dict[str, str] = {}  # 'G05' as written -> 'G05' checked
    events = 0
    i = start
    n = len(lines)
    while i < n:
        line = lines[i]
        ln = i + 1
        if not line.strip():
            i += 1
            continue
        if line[0] != ">":
            raise RinexError(path, ln, f"expected an epoch line starting with '>', got {line[:20]!r}")
        flag = parse_int(line[31:32], path, ln, "epoch flag", blank=0)
        count = parse_int(line[32:35], path, ln, "number of satellites", blank=None)
        if count < 0:
            raise RinexError(path, ln, f"negative number of satellites {count}")
        if flag not in KEPT_FLAGS:
            if flag > 6:
                raise RinexError(path, ln, f"epoch flag {flag} outside 0-6")
            events += 1
            i += 1 + count  # special records: header lines
            if i > n:
                raise RinexError(path, n, "event record truncated")
            continue
        try:
            y, mo, d, h, mi = (int(line[a:b]) for a, b in ((2, 6), (7, 9), (10, 12), (13, 15), (16, 18)))
        except ValueError:
            raise RinexError(path, ln, f"bad epoch time {line[2:29]!r}") from None
        sec = parse_float(line[18:29], path, ln, "epoch seconds", blank=math.nan)
        if math.isnan(sec):
            raise RinexError(path, ln, "epoch seconds missing")
        try:
            t = _to_gpst(gtime.from_calendar(y, mo, d, h, mi, sec), header.time_system)
        except gtime.TimeError as exc:
            raise RinexError(path, ln, str(exc)) from None
        clk = parse_float(line[41:56], path, ln, "receiver clock offset", blank=math.nan)
        e_i = len(col.times)
        col.times.append(t)
        col.flags.append(flag)
        col.clock.append(clk)
        if i + count > n - 1:
            raise RinexError(path, n, f"epoch at line {ln} announces {count} satellites, the file ends")
        for k in range(1, count + 1):
            sl = lines[i + k]
            sat = known_sats.get(sl[0:3])
            if sat is None:
                try:
                    sat = parse_sat_id(sl[0:3], path, i + k + 1)
                except RinexError:
                    raise RinexError(path, i + k + 1, f"bad satellite id {sl[0:3]!r} (epoch at line {ln} announces {count})") from None
                if sat[0] not in header.obs_types:
                    raise RinexError(path, i + k + 1, f"satellite {sat} of a system without SYS / # / OBS TYPES")
                known_sats[sl[0:3]] = sat
            col.add(e_i, sat, sl[3:], i + k + 1)
        i += 1 + count
    return col.finish(header, events)


def _read_body_v2(lines: list[str], start: int, header: ObsHeader, path) -> ObsData:
    col = _Collector(header.obs_types, path, OBS_PER_LINE_V2)
    types = next(iter(header.obs_types.values()))
    n_types = len(types)
    lines_per_sat = max(1, math.ceil(n_types / OBS_PER_LINE_V2))
    events = 0
    i = start
    n = len(lines)
    default_sys = header.system if header.system not in ("M", "") else "G"
    while i < n:
        line = lines[i]
        ln = i + 1
        if not line.strip():
            i += 1
            continue
        flag = parse_int(line[28:29], path, ln, "epoch flag", blank=0)
        count = parse_int(line[29:32], path, ln, "number of satellites", blank=None)
        if count < 0:
            raise RinexError(path, ln, f"negative number of satellites {count}")
        if flag not in KEPT_FLAGS:
            if flag > 6:
                raise RinexError(path, ln, f"epoch flag {flag} outside 0-6")
            events += 1
            i += 1 + count
            continue
        try:
            yy, mo, d, h, mi = (int(line[a:b]) for a, b in ((1, 3), (4, 6), (7, 9), (10, 12), (13, 15)))
        except ValueError:
            raise RinexError(path, ln, f"bad epoch time {line[0:26]!r}") from None
        sec = parse_float(line[15:26], path, ln, "epoch seconds", blank=math.nan)
        if math.isnan(sec):
            raise RinexError(path, ln, "epoch seconds missing")
        year = yy + (2000 if yy < 80 else 1900)  # RINEX 2 two-digit years: 80-99 -> 19xx
        try:
            t = gtime.from_calendar(year, mo, d, h, mi, sec)
        except gtime.TimeError as exc:
            raise RinexError(path, ln, str(exc)) from None
        clk = parse_float(line[68:80], path, ln, "receiver clock offset", blank=math.nan)
        # Satellite list: 12 per line from column 33, continued on following lines.
        sats = []
        n_sat_lines = max(1, math.ceil(count / SATS_PER_EPOCH_LINE_V2))
        if i + n_sat_lines > n:
            raise RinexError(path, n, f"epoch at line {ln}: satellite list truncated")
        for m in range(n_sat_lines):
            sl = lines[i + m]
            for k in range(SATS_PER_EPOCH_LINE_V2):
                if len(sats) == count:
                    break
                s = sl[32 + 3 * k : 35 + 3 * k]
                sats.append(parse_sat_id(s, path, i + m + 1, default_system=default_sys))
        i += n_sat_lines
        e_i = len(col.times)
        col.times.append(t)
        col.flags.append(flag)
        col.clock.append(clk)
        # Writers drop trailing blank continuation lines at the end of the file; tolerate only that.
        if i + (count - 1) * lines_per_sat + 1 > n:
            raise RinexError(path, n, f"epoch at line {ln}: observations truncated")
        for sat in sats:
            text = "".join((lines[i + m] if i + m < n else "")[:80].ljust(80) for m in range(lines_per_sat))
            if sat[0] not in header.obs_types:
                header.obs_types[sat[0]] = list(types)
            col.add(e_i, sat, text, i + 1)
            i += lines_per_sat
    return col.finish(header, events)


# --------------------------------------------------------------------------------------------
# writing


def _line(content: str, label: str) -> str:
    return f"{content:<60.60}{label:<20}"


def _header_time_line(t_gpst: float, time_system: str) -> str:
    label_t = t_gpst - 14.0 if time_system == "BDT" else t_gpst
    y, mo, d, h, mi, s = gtime.to_calendar(label_t, decimals=7)
    return f"{y:6d}{mo:6d}{d:6d}{h:6d}{mi:6d}{s:13.7f}{'':5}{time_system:<3}"


def version_of_type(t: str) -> int:
    """3 for a RINEX 3 type ('C1C'), 2 for a RINEX 2 one ('C1', 'P2')."""
    return 3 if len(t) == 3 else 2


def write_obs(path: str | os.PathLike, data: ObsData) -> None:
    """Write RINEX 3.04 observations (plain, or gzip for a .gz name).

    Each satellite line carries its system's types in header order; NaN is written blank.
    Epochs with no value for any satellite are still written (as an epoch with 0 satellites).
    """
    hdr = data.header
    if not hdr.obs_types:
        raise ValueError("header has no observation types")
    for sys_letter, types in hdr.obs_types.items():
        for t in types:
            if not 2 <= len(t) <= 3 or (version_of_type(t) == 2 and t[0] != "X"):
                raise ValueError(f"observation type {t!r} of {sys_letter} is not a RINEX 3 type")
    systems = sorted({str(s)[0] for s in data.sats} | set(hdr.obs_types))
    sys_char = hdr.system if hdr.system else ("M" if len(systems) > 1 else systems[0])
    names = {"M": "MIXED", "G": "GPS", "E": "GALILEO", "C": "BEIDOU", "J": "QZSS", "R": "GLONASS"}
    now = hdr.date or _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%d %H%M%S UTC")
    tsys = hdr.time_system or "GPS"
    first = hdr.time_of_first_obs if hdr.time_of_first_obs is not None else (float(data.times[0]) if len(data.times) else None)
    out = [
        _line(f"{WRITE_VERSION:9.2f}{'':11}{'OBSERVATION DATA':<20}{sys_char} ({names.get(sys_char, '')})",
              "RINEX VERSION / TYPE"),
        _line(f"{hdr.program:<20.20}{hdr.run_by:<20.20}{now:<20.20}", "PGM / RUN BY / DATE"),
    ]
    out += [_line(c, "COMMENT") for c in hdr.comments]
    out.append(_line(hdr.marker_name, "MARKER NAME"))
    if hdr.marker_number:
        out.append(_line(hdr.marker_number, "MARKER NUMBER"))
    if hdr.marker_type:
        out.append(_line(hdr.marker_type, "MARKER TYPE"))
    out.append(_line(f"{hdr.observer:<20.20}{hdr.agency:<40.40}", "OBSERVER / AGENCY"))
    out.append(_line(f"{hdr.receiver_number:<20.20}{hdr.receiver_type:<20.20}{hdr.receiver_version:<20.20}",
                     "REC # / TYPE / VERS"))
    out.append(_line(f"{hdr.antenna_number:<20.20}{hdr.antenna_type:<20.20}", "ANT # / TYPE"))
    out.append(_line("".join(f"{v:14.4f}" for v in hdr.approx_position_m), "APPROX POSITION XYZ"))
    out.append(_line("".join(f"{v:14.4f}" for v in hdr.antenna_delta_hen_m), "ANTENNA: DELTA H/E/N"))
    for sys_letter in systems:
        types = hdr.obs_types.get(sys_letter)
        if not types:
            continue
        for k in range(0, len(types), OBS_TYPES_PER_LINE_V3):
            chunk = "".join(f" {t:<3}" for t in types[k : k + OBS_TYPES_PER_LINE_V3])
            lead = f"{sys_letter}  {len(types):3d}" if k == 0 else "      "
            out.append(_line(f"{lead}{chunk}", "SYS / # / OBS TYPES"))
    if hdr.signal_strength_unit:
        out.append(_line(hdr.signal_strength_unit, "SIGNAL STRENGTH UNIT"))
    if hdr.interval_s is not None:
        out.append(_line(f"{hdr.interval_s:10.3f}", "INTERVAL"))
    if first is not None:
        out.append(_line(_header_time_line(first, tsys), "TIME OF FIRST OBS"))
    if hdr.time_of_last_obs is not None:
        out.append(_line(_header_time_line(hdr.time_of_last_obs, tsys), "TIME OF LAST OBS"))
    if hdr.leap_seconds is not None:
        out.append(_line(f"{hdr.leap_seconds:6d}", "LEAP SECONDS"))
    for content, label in hdr.extra:
        if label in ("SYS / PHASE SHIFT", "GLONASS SLOT / FRQ #", "GLONASS COD/PHS/BIS", "ANTENNA: PHASECENTER"):
            out.append(_line(content, label))
    out.append(_line("", "END OF HEADER"))

    lines, present = _format_records(data, hdr.obs_types)
    for e_i, t in enumerate(np.asarray(data.times, dtype=float)):
        body = lines[e_i][present[e_i]].tolist()
        label_t = t - 14.0 if tsys == "BDT" else t
        y, mo, d, h, mi, s = gtime.to_calendar(label_t, decimals=7)
        flag = int(data.flags[e_i]) if len(data.flags) else 0
        clk = data.clock_offset_s[e_i] if len(data.clock_offset_s) else math.nan
        clk_txt = f"      {clk:15.12f}" if not math.isnan(clk) else ""
        out.append(f"> {y:04d} {mo:02d} {d:02d} {h:02d} {mi:02d}{s:11.7f}  {flag:1d}{len(body):3d}{clk_txt}")
        out.extend(body)
    with open_text_for_write(path) as f:
        f.write("\n".join(out) + "\n")


def _f14_3(values: np.ndarray) -> np.ndarray:
    """Fortran F14.3 text of finite values as an (..., 14) uint8 array, built with integer
    arithmetic on whole arrays (Python's per-value formatting costs ~1 us a field, this ~30 ns)."""
    scaled = np.abs(values) * 1000.0
    milli = np.floor(scaled + 0.5).astype(np.int64)
    # Near a half-millimetre the product above has rounded; printf rounds the exact binary value.
    # Those few values take printf's digits, so the text is exactly what '%14.3f' writes.
    near_tie = np.abs(scaled - np.floor(scaled) - 0.5) < 1e-6
    if near_tie.any():
        idx = np.nonzero(near_tie)
        exact = [abs(int(round(float(f"{x:.3f}") * 1000.0))) for x in values[idx].tolist()]
        milli[idx] = exact
    whole, frac = milli // 1000, milli % 1000
    out = np.full(values.shape + (14,), 0x20, dtype=np.uint8)
    for j in range(10):  # integer digits, columns 0-9, leading zeros blank (units digit kept)
        power = 10 ** (9 - j)
        digit = (whole // power) % 10
        out[..., j] = np.where((whole >= power) | (j == 9), 0x30 + digit, 0x20)
    out[..., 10] = ord(".")
    for j in range(3):
        out[..., 11 + j] = 0x30 + (frac // 10 ** (2 - j)) % 10
    negative = (values < 0) & (milli > 0)
    if negative.any():
        # The sign goes just before the first digit: column 9 - number of integer digits + 1.
        n_digits = np.maximum(1, np.floor(np.log10(np.maximum(whole, 1))).astype(int) + 1)
        idx = np.nonzero(negative)
        out[idx + (9 - n_digits[idx],)] = ord("-")
    return out


def _format_records(data: ObsData, obs_types: dict[str, list[str]]):
    """Every satellite record line, for all epochs at once: an (E, S) array of strings and the
    mask of records holding at least one value (a record of only blanks is not written)."""
    n_e, n_s = len(data.times), len(data.sats)
    sats = np.asarray(data.sats, dtype="<U3")
    lines = np.full((n_e, n_s), "", dtype=object)
    present = np.zeros((n_e, n_s), dtype=bool)
    letters = np.array([s[0] for s in sats.tolist()]) if n_s else np.array([], dtype="<U1")
    for sys_letter in sorted(set(letters.tolist())):
        cols = np.flatnonzero(letters == sys_letter)
        types = obs_types.get(sys_letter, [])
        width = 3 + OBS_FIELD_WIDTH * len(types)
        buf = np.full((n_e, len(cols), width), 0x20, dtype=np.uint8)
        ids = np.frombuffer("".join(sats[cols].tolist()).encode("ascii"), dtype=np.uint8).reshape(len(cols), 3)
        buf[:, :, 0:3] = ids[None, :, :]
        any_value = np.zeros((n_e, len(cols)), dtype=bool)
        for k, ty in enumerate(types):
            if ty not in data.obs:
                continue
            v = data.obs[ty][:, cols]
            ok = ~np.isnan(v)
            too_big = ok & ((np.nan_to_num(v) > MAX_OBS_VALUE) | (np.nan_to_num(v) < MIN_OBS_VALUE))
            if too_big.any():
                e_i, c_i = np.argwhere(too_big)[0]
                raise ValueError(f"{sats[cols][c_i]} {ty} = {v[e_i, c_i]} does not fit RINEX F14.3")
            a = 3 + OBS_FIELD_WIDTH * k
            buf[:, :, a : a + 14] = np.where(ok[..., None], _f14_3(np.where(ok, v, 0.0)), 0x20)
            for off, flags in ((14, data.lli.get(ty)), (15, data.ssi.get(ty))):
                if flags is not None:
                    f = flags[:, cols].astype(np.int16) % 10
                    buf[:, :, a + off] = np.where(ok & (f > 0), 0x30 + f, 0x20)
            any_value |= ok
        raw = buf.tobytes().decode("ascii")
        n = n_e * len(cols)
        flat = [raw[i * width : (i + 1) * width].rstrip() for i in range(n)]
        lines[:, cols] = np.array(flat, dtype=object).reshape(n_e, len(cols)) if n else lines[:, cols]
        present[:, cols] = any_value
    return lines, present


def empty_obs(header: ObsHeader, times, sats) -> ObsData:
    """An ObsData with every value NaN, ready to be filled (e.g. by a simulator or a test)."""
    times = np.asarray(times, dtype=float)
    sats = np.asarray(sats, dtype="<U3")
    types = sorted({t for ts in header.obs_types.values() for t in ts})
    shape = (len(times), len(sats))
    return ObsData(
        header,
        times,
        np.zeros(len(times), dtype=np.int8),
        np.full(len(times), np.nan),
        sats,
        {t: np.full(shape, np.nan) for t in types},
        {t: np.zeros(shape, dtype=np.int8) for t in types},
        {t: np.zeros(shape, dtype=np.int8) for t in types},
    )


# --------------------------------------------------------------------------------------------
# RINEX 2.11 observation types -> RINEX 3 types

# RINEX 2.11 (section 5.1 and Table 1) names a type by observable and band only; RINEX 3 adds the
# tracking mode.  The conventional mapping (the one gfzrnx and RTKLIB apply to 2.11 files):
# GPS C1 is C/A, P1/P2 are P(Y) (W), C2 is L2C (tracking mode unknown: X); the L2 phase goes with
# P2 (W).  GLONASS P is the P code.  Galileo and other bands have no mode information: X.
_V2_TO_V3_BY_SYSTEM: dict[str, dict[str, str]] = {
    "G": {"C1": "C1C", "P1": "C1W", "L1": "L1C", "D1": "D1C", "S1": "S1C",
          "C2": "C2X", "P2": "C2W", "L2": "L2W", "D2": "D2W", "S2": "S2W",
          "C5": "C5X", "L5": "L5X", "D5": "D5X", "S5": "S5X"},
    "R": {"C1": "C1C", "P1": "C1P", "L1": "L1C", "D1": "D1C", "S1": "S1C",
          "C2": "C2C", "P2": "C2P", "L2": "L2P", "D2": "D2P", "S2": "S2P"},
    "E": {f"{o}{b}": f"{o}{b}X" for o in "CLDS" for b in "15678"},
    "J": {"C1": "C1C", "L1": "L1C", "D1": "D1C", "S1": "S1C", "C2": "C2X", "L2": "L2X", "D2": "D2X",
          "S2": "S2X", "C5": "C5X", "L5": "L5X", "D5": "D5X", "S5": "S5X"},
    "S": {"C1": "C1C", "L1": "L1C", "D1": "D1C", "S1": "S1C", "C5": "C5X", "L5": "L5X", "D5": "D5X", "S5": "S5X"},
    "C": {"C2": "C2I", "L2": "L2I", "D2": "D2I", "S2": "S2I", "C7": "C7I", "L7": "L7I", "D7": "D7I",
          "S7": "S7I", "C6": "C6I", "L6": "L6I", "D6": "D6I", "S6": "S6I"},
}


def rinex3_type(system: str, v2_type: str) -> str | None:
    """RINEX 3 type for a RINEX 2.11 type of a system ('G', 'P2' -> 'C2W'); None if it has none."""
    return _V2_TO_V3_BY_SYSTEM.get(system, {}).get(v2_type)


def to_rinex3_types(data: ObsData) -> ObsData:
    """The same observations under RINEX 3 type names (see `rinex3_type`), per system.

    Types without a RINEX 3 equivalent for a system (e.g. GPS 'P1' of a GLONASS-only receiver is
    fine, but 'C6' for GPS) are dropped and listed in a header comment.  RINEX 3 input is
    returned unchanged.
    """
    if all(len(t) == 3 for ts in data.header.obs_types.values() for t in ts):
        return data
    n_e, n_s = len(data.times), len(data.sats)
    letters = np.array([s[0] for s in data.sats.tolist()]) if n_s else np.array([], dtype="<U1")
    new_types: dict[str, list[str]] = {}
    obs: dict[str, np.ndarray] = {}
    lli: dict[str, np.ndarray] = {}
    ssi: dict[str, np.ndarray] = {}
    dropped = []
    for sys_letter, types in data.header.obs_types.items():
        cols = letters == sys_letter
        if not cols.any():
            continue  # RINEX 2 mixed headers list one set of types for every system
        kept = []
        for t in types:
            new = rinex3_type(sys_letter, t)
            if new is None:
                dropped.append(f"{sys_letter} {t}")
                continue
            kept.append(new)
            if new not in obs:
                obs[new] = np.full((n_e, n_s), np.nan)
                lli[new] = np.zeros((n_e, n_s), dtype=np.int8)
                ssi[new] = np.zeros((n_e, n_s), dtype=np.int8)
            obs[new][:, cols] = data.obs[t][:, cols]
            lli[new][:, cols] = data.lli[t][:, cols]
            ssi[new][:, cols] = data.ssi[t][:, cols]
        if kept:
            new_types[sys_letter] = kept
    comments = list(data.header.comments)
    comments.append(f"converted from RINEX {data.header.version:.2f} observation types")
    if dropped:
        comments.append("dropped (no RINEX 3 type): " + ", ".join(dropped))
    header = dataclasses.replace(data.header, version=WRITE_VERSION, obs_types=new_types, comments=comments)
    return ObsData(header, data.times, data.flags, data.clock_offset_s, data.sats, obs, lli, ssi, data.events)

"""RINEX 3 navigation files: read (3.00-3.05, mixed) and write (3.04), GPS/Galileo/BDS/QZSS records.

Layout (RINEX 3.04 Tables A6-A16): a record is one epoch line (satellite, toc as a calendar time
in the satellite's own time scale, af0 af1 af2) and broadcast-orbit lines of 4 x D19.12 after 4
blanks; 7 orbit lines for GPS/Galileo/BDS/QZSS/IRNSS, 3 for GLONASS and SBAS.  GLONASS, SBAS and
IRNSS records are recognised and skipped (counted in `NavFile.skipped`), never an error.
"""

from __future__ import annotations

import datetime as _dt
import os
from dataclasses import dataclass, field
from typing import Iterable

from augnet.gnss import time as gtime
from augnet.gnss.constants import BDS_WEEK_OFFSET_FROM_GPS, GAL_WEEK_OFFSET_FROM_GPS, SECONDS_PER_WEEK
from augnet.gnss.ephemeris import Ephemeris
from augnet.gnss.rinex.errors import (
    LABEL_COLUMN,
    RinexError,
    is_ascii_digits,
    open_text_for_write,
    parse_float,
    parse_sat_id,
    read_lines,
)

ORBIT_LINES = {"G": 7, "E": 7, "C": 7, "J": 7, "I": 7, "R": 3, "S": 3}
# RINEX 2: one system per file, named by the file type letter (RINEX 2.11 Tables A3, A10, A16).
V2_NAV_TYPES = {"N": "G", "G": "R", "H": "S"}
V2_ORBIT_LINES = {"G": 7, "R": 3, "S": 3}
V2_FIRST_LINE_DATA_COLUMN = 22
V2_ORBIT_DATA_COLUMN = 3
KEPLER_SYSTEMS = ("G", "E", "C", "J")
FIELD_WIDTH = 19  # D19.12
FIRST_LINE_DATA_COLUMN = 23
ORBIT_DATA_COLUMN = 4
WRITE_VERSION = 3.04


@dataclass
class NavHeader:
    version: float = WRITE_VERSION
    system: str = "M"  # 'M' mixed, or a system letter
    program: str = "augnet"
    run_by: str = ""
    date: str = ""
    leap_seconds: int | None = None
    # Header lines kept verbatim (IONOSPHERIC CORR, TIME SYSTEM CORR, ...): (content, label).
    extra: list[tuple[str, str]] = field(default_factory=list)
    comments: list[str] = field(default_factory=list)


@dataclass
class NavFile:
    header: NavHeader
    ephemerides: list[Ephemeris]
    skipped: dict[str, int] = field(default_factory=dict)  # system letter -> records not kept

    def __iter__(self):
        return iter(self.ephemerides)

    def __len__(self) -> int:
        return len(self.ephemerides)


# --------------------------------------------------------------------------------------------
# reading


def _label(line: str) -> str:
    return line[LABEL_COLUMN:].strip()


def read_nav(path: str | os.PathLike) -> NavFile:
    """Read a RINEX navigation file (plain or gzip): 3.00-3.05 mixed, or 2.xx GPS ('N'); RINEX 2
    GLONASS ('G') and SBAS ('H') files read as all-skipped."""
    lines = read_lines(path)
    header, body_start = _read_header(lines, path)
    if header.version < 3.0:
        return _read_body_v2(lines, body_start, header, path)
    ephs: list[Ephemeris] = []
    skipped: dict[str, int] = {}
    i = body_start
    n = len(lines)
    while i < n:
        line = lines[i]
        if not line.strip():
            i += 1
            continue
        sys_letter = line[0]
        if sys_letter == " ":
            raise RinexError(path, i + 1, "orbit line where a record's epoch line was expected")
        n_orbit = ORBIT_LINES.get(sys_letter)
        if n_orbit is None:
            raise RinexError(path, i + 1, f"unknown satellite system {sys_letter!r} in {line[:3]!r}")
        # A record runs until the next line that starts in column 1 (orbit lines start blank).
        # GLONASS has a 4th orbit line from RINEX 3.05 on, so skipped systems take what is there.
        j = i + 1
        while j < n and lines[j][:1] == " " and lines[j].strip():
            j += 1
        block = lines[i:j]
        sat = line[:3].strip()
        if sys_letter in KEPLER_SYSTEMS:
            if len(block) - 1 != n_orbit:
                raise RinexError(path, j if j < n else n, f"record of {sat}: {len(block) - 1} orbit lines, expected {n_orbit}")
            ephs.append(_decode_record(block, path, i + 1))
        else:
            if len(block) - 1 < n_orbit:
                raise RinexError(path, j if j < n else n, f"record of {sat}: {len(block) - 1} orbit lines, expected {n_orbit}")
            _check_epoch_line(block[0], path, i + 1)
            skipped[sys_letter] = skipped.get(sys_letter, 0) + 1
        i = j
    return NavFile(header, ephs, skipped)


def _read_header(lines: list[str], path) -> tuple[NavHeader, int]:
    if not lines:
        raise RinexError(path, 1, "empty file")
    first = lines[0]
    if _label(first) != "RINEX VERSION / TYPE":
        raise RinexError(path, 1, "first line is not 'RINEX VERSION / TYPE'")
    version = parse_float(first[0:9], path, 1, "RINEX version", blank=-1.0)
    if not 2.0 <= version < 4.0:
        raise RinexError(path, 1, f"RINEX version {version} not supported (2.xx, 3.00-3.05)")
    file_type = first[20:21]
    if file_type != "N" and not (version < 3.0 and file_type in V2_NAV_TYPES):
        raise RinexError(path, 1, f"not a navigation file (file type {file_type!r})")
    # RINEX 2: the file type letter says the system (N GPS, G GLONASS, H SBAS); 3: column 41.
    system = V2_NAV_TYPES[file_type] if version < 3.0 else (first[40:41].strip() or "M")
    hdr = NavHeader(version=version, system=system)
    for k in range(1, len(lines)):
        line = lines[k]
        label = _label(line)
        content = line[:LABEL_COLUMN]
        if label == "END OF HEADER":
            return hdr, k + 1
        if label == "PGM / RUN BY / DATE":
            hdr.program, hdr.run_by, hdr.date = content[0:20].strip(), content[20:40].strip(), content[40:60].strip()
        elif label == "COMMENT":
            hdr.comments.append(content.rstrip())
        elif label == "LEAP SECONDS":
            hdr.leap_seconds = int(parse_float(content[0:6], path, k + 1, "leap seconds"))
            hdr.extra.append((content, label))
        elif label:
            hdr.extra.append((content, label))
        else:
            raise RinexError(path, k + 1, "header line without a label (END OF HEADER missing?)")
    raise RinexError(path, len(lines), "END OF HEADER not found")


def _check_epoch_line(line: str, path, line_no: int) -> float:
    """Parse 'Snn yyyy mm dd hh mm ss' and return the calendar time (seconds since 1980-01-06,
    read in the satellite system's own scale)."""
    parse_sat_id(line[0:3], path, line_no)
    if len(line) < FIRST_LINE_DATA_COLUMN:
        raise RinexError(path, line_no, f"short epoch line: {line!r}")
    parts = line[4:23].split()
    if len(parts) != 6 or not all(is_ascii_digits(p) for p in parts):
        raise RinexError(path, line_no, f"bad epoch {line[4:23]!r} (year month day hour minute second)")
    y, mo, d, h, mi, s = (int(p) for p in parts)
    try:
        return gtime.from_calendar(y, mo, d, h, mi, s)
    except gtime.TimeError as exc:
        raise RinexError(path, line_no, str(exc)) from None


def _fields(line: str, start: int, count: int, path, line_no: int) -> list[float]:
    out = []
    for k in range(count):
        a = start + k * FIELD_WIDTH
        out.append(parse_float(line[a : a + FIELD_WIDTH], path, line_no, f"field {k + 1}"))
    return out


def _decode_record(block: list[str], path, line_no: int) -> Ephemeris:
    head = block[0]
    toc_label = _check_epoch_line(head, path, line_no)
    system = head[0]
    prn = int(parse_sat_id(head[0:3], path, line_no)[1:])
    d = _fields(head, FIRST_LINE_DATA_COLUMN, 3, path, line_no)
    for k, line in enumerate(block[1:], start=1):
        d.extend(_fields(line, ORBIT_DATA_COLUMN, 4, path, line_no + k))
    return _ephemeris_from_fields(system, prn, toc_label, d, path, line_no)


def _read_body_v2(lines: list[str], start: int, header: NavHeader, path) -> NavFile:
    """RINEX 2.xx: 'PRN yy mm dd hh mm ss.s' (I2, 5I3, F5.1) then 3 D19.12 from column 23, and
    orbit lines of 3X, 4D19.12.  A PRN below 10 starts with a blank, so records are counted, not
    recognised by their first column."""
    per_record = 1 + V2_ORBIT_LINES[header.system]
    ephs: list[Ephemeris] = []
    skipped: dict[str, int] = {}
    i = start
    n = len(lines)
    while i < n:
        if not lines[i].strip():
            i += 1
            continue
        if i + per_record > n:
            raise RinexError(path, n, f"record starting at line {i + 1} truncated: expected {per_record} lines")
        block = lines[i : i + per_record]
        head = block[0]
        prn_text = head[0:2].strip()
        parts = head[2:22].split()
        if not is_ascii_digits(prn_text) or len(parts) != 6 or not all(is_ascii_digits(p) for p in parts[:5]):
            raise RinexError(path, i + 1, f"bad record start {head[:22]!r} (PRN yy mm dd hh mm ss.s)")
        sec = parse_float(parts[5], path, i + 1, "epoch seconds")
        yy, mo, dd, hh, mi = (int(p) for p in parts[:5])
        year = yy + (2000 if yy < 80 else 1900)  # RINEX 2 two-digit years: 80-99 -> 19xx
        try:
            toc_label = gtime.from_calendar(year, mo, dd, hh, mi, sec)
        except gtime.TimeError as exc:
            raise RinexError(path, i + 1, str(exc)) from None
        if header.system != "G":
            skipped[header.system] = skipped.get(header.system, 0) + 1
            i += per_record
            continue
        d = _fields(head, V2_FIRST_LINE_DATA_COLUMN, 3, path, i + 1)
        for k, line in enumerate(block[1:], start=1):
            if line[:3].strip():
                raise RinexError(path, i + 1 + k, f"expected an orbit line, got {line[:22]!r}")
            d.extend(_fields(line, V2_ORBIT_DATA_COLUMN, 4, path, i + 1 + k))
        ephs.append(_ephemeris_from_fields("G", int(prn_text), toc_label, d, path, i + 1))
        i += per_record
    return NavFile(header, ephs, skipped)


def _ephemeris_from_fields(system: str, prn: int, toc_label: float, d: list[float], path, line_no: int) -> Ephemeris:
    """The record's numbers in RINEX order -> Ephemeris (per-system meaning of orbits 5-7)."""
    # d[] indices follow the RINEX order: 0-2 clock, 3-6 orbit 1, ..., 27-30 orbit 7.
    if d[10] <= 0.0:
        raise RinexError(path, line_no + 2, f"{system}{prn:02d}: sqrt(A) must be positive, got {d[10]}")
    if system == "C":
        toc_week_seconds = toc_label - BDS_WEEK_OFFSET_FROM_GPS * SECONDS_PER_WEEK  # BDT weeks
    elif system == "E":
        toc_week_seconds = toc_label - GAL_WEEK_OFFSET_FROM_GPS * SECONDS_PER_WEEK  # GST weeks
    else:
        toc_week_seconds = toc_label
    # The week of toe: the one that puts toe within half a week of the toc epoch.  Derived from
    # the calendar, not the week field: writers disagree on Galileo's (GPS-aligned per RINEX 3,
    # GST in some files) and GPS 10-bit roll-overs appear in old ones.  RTKLIB does the same.
    week = int(round((toc_week_seconds - d[11]) / SECONDS_PER_WEEK))
    toc = float((toc_week_seconds - week * SECONDS_PER_WEEK) % SECONDS_PER_WEEK)
    common = dict(
        system=system, prn=prn, week=week, toe=d[11], toc=toc, af0=d[0], af1=d[1], af2=d[2],
        iode=int(d[3]), crs=d[4], delta_n=d[5], m0=d[6], cuc=d[7], e=d[8], cus=d[9], sqrt_a=d[10],
        cic=d[12], omega0=d[13], cis=d[14], i0=d[15], crc=d[16], omega=d[17], omega_dot=d[18],
        idot=d[19], accuracy_m=d[23], health=int(d[24]), transmission_time=d[27],
    )
    if system in ("G", "J"):
        return Ephemeris(**common, codes_on_l2=int(d[20]), l2p_data_flag=int(d[22]), tgd=d[25],
                         iodc=int(d[26]), fit_interval_h=d[28])
    if system == "E":
        return Ephemeris(**common, data_sources=int(d[20]), bgd_e5a_e1=d[25], bgd_e5b_e1=d[26])
    return Ephemeris(**common, tgd1=d[25], tgd2=d[26], iodc=int(d[28]))


# --------------------------------------------------------------------------------------------
# writing


def _d19(x: float) -> str:
    s = f"{x:19.12E}"
    if len(s) != FIELD_WIDTH:
        raise ValueError(f"{x!r} does not fit a D19.12 field")
    return s


def _line(content: str, label: str) -> str:
    return f"{content:<60.60}{label:<20}"


def write_nav(path: str | os.PathLike, ephemerides: Iterable[Ephemeris], header: NavHeader | None = None) -> None:
    """Write a RINEX 3.04 navigation file (mixed unless all records are of one system)."""
    ephs = list(ephemerides)
    hdr = header or NavHeader()
    systems = {e.system for e in ephs}
    sys_char = next(iter(systems)) if len(systems) == 1 else "M"
    names = {"G": "GPS", "E": "Galileo", "C": "BeiDou", "J": "QZSS", "M": "Mixed"}
    now = hdr.date or _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%d %H%M%S UTC")
    out = [
        _line(f"{WRITE_VERSION:9.2f}{'':11}{'N: GNSS NAV DATA':<20}{sys_char}: {names.get(sys_char, '')}",
              "RINEX VERSION / TYPE"),
        _line(f"{hdr.program:<20.20}{hdr.run_by:<20.20}{now:<20.20}", "PGM / RUN BY / DATE"),
    ]
    out += [_line(c, "COMMENT") for c in hdr.comments]
    leap_written = False
    for content, label in hdr.extra:
        if label in ("IONOSPHERIC CORR", "TIME SYSTEM CORR", "LEAP SECONDS"):
            out.append(_line(content, label))
            leap_written |= label == "LEAP SECONDS"
    if hdr.leap_seconds is not None and not leap_written:
        out.append(_line(f"{hdr.leap_seconds:6d}", "LEAP SECONDS"))
    out.append(_line("", "END OF HEADER"))
    for e in ephs:
        out.extend(_encode_record(e))
    with open_text_for_write(path) as f:
        f.write("\n".join(out) + "\n")


def _encode_record(e: Ephemeris) -> list[str]:
    if e.system not in KEPLER_SYSTEMS:
        raise ValueError(f"cannot write a {e.system!r} record")
    toc_sow = float(gtime.resolve_tow(e.toc, e.toe))
    if e.system == "C":
        week_file, base = e.week, BDS_WEEK_OFFSET_FROM_GPS
    elif e.system == "E":
        week_file, base = e.week + GAL_WEEK_OFFSET_FROM_GPS, GAL_WEEK_OFFSET_FROM_GPS
    else:
        week_file, base = e.week, 0
    toc_label = (base + e.week) * SECONDS_PER_WEEK + toc_sow
    y, mo, d, h, mi, s = gtime.to_calendar(toc_label, decimals=0)
    first = f"{e.sat} {y:04d} {mo:02d} {d:02d} {h:02d} {mi:02d} {int(s):02d}" + "".join(
        _d19(v) for v in (e.af0, e.af1, e.af2)
    )
    if e.system in ("G", "J"):
        o5 = (e.idot, e.codes_on_l2, week_file, e.l2p_data_flag)
        o6 = (e.accuracy_m, e.health, e.tgd, e.iodc)
        o7 = (e.transmission_time, e.fit_interval_h)
    elif e.system == "E":
        o5 = (e.idot, e.data_sources, week_file, 0.0)
        o6 = (e.accuracy_m, e.health, e.bgd_e5a_e1, e.bgd_e5b_e1)
        o7 = (e.transmission_time,)
    else:
        o5 = (e.idot, 0.0, week_file, 0.0)
        o6 = (e.accuracy_m, e.health, e.tgd1, e.tgd2)
        o7 = (e.transmission_time, e.iodc)
    orbits = [
        (e.iode, e.crs, e.delta_n, e.m0),
        (e.cuc, e.e, e.cus, e.sqrt_a),
        (e.toe, e.cic, e.omega0, e.cis),
        (e.i0, e.crc, e.omega, e.omega_dot),
        o5,
        o6,
        o7,
    ]
    return [first] + ["    " + "".join(_d19(float(v)) for v in row) for row in orbits]

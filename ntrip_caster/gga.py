"""NMEA GGA sentences from NTRIP clients: extraction from the upstream byte stream, parsing, distance.

v2 clients may send the first GGA in the `Ntrip-GGA:` header, v1 clients as a line after the request
head, and both send later updates as raw lines on the same socket (ntrip.md). Any talker is accepted
(`$GPGGA`, `$GNGGA`, `$GBGGA`, ...). A sentence with a bad checksum, no fix or any field out of its
range (NMEA 0183 bounds below; positions by `augwire.positions`) yields nothing; it never raises. What
the caster and the centre answer for each class of GGA: docs/gga.md.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from augwire.positions import MAX_GEOID_SEPARATION_M, MAX_HEIGHT_M, MIN_HEIGHT_M, position_problem

from .limits import MAX_NMEA_LINE_BYTES

# WGS 84 equatorial radius; the caster only needs distances to ~1 m over a few hundred km.
EARTH_RADIUS_M = 6_378_137.0


@dataclass(frozen=True, slots=True)
class GgaFix:
    """A client position from one GGA sentence."""

    lat_deg: float
    lon_deg: float
    height_m: float  # orthometric height + geoid separation (ellipsoidal), 0 when absent
    quality: int  # GGA fix quality: 0 invalid, 1 SPS, 2 DGPS, 4 RTK fixed, 5 RTK float, ...
    num_sats: int
    talker: str  # "GP", "GN", "GB", ...
    sentence: bytes  # the sentence as received, without line end
    hdop: float | None = None  # None when the field is empty
    age_s: float | None = None  # age of the receiver's differential corrections, None when empty

    def distance_m(self, other: "GgaFix | tuple[float, float]") -> float:
        lat, lon = (other.lat_deg, other.lon_deg) if isinstance(other, GgaFix) else other
        return great_circle_m(self.lat_deg, self.lon_deg, lat, lon)


def great_circle_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Haversine distance on a sphere of the WGS 84 equatorial radius (metres)."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dp, dl = p2 - p1, math.radians(lon2 - lon1)
    a = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2 * EARTH_RADIUS_M * math.asin(min(1.0, math.sqrt(a)))


def nmea_checksum(body: bytes) -> int:
    """XOR of the bytes between '$' and '*'."""
    c = 0
    for b in body:
        c ^= b
    return c


# NMEA 0183 (v4.1) GGA field bounds; a sentence with any field outside them is refused whole.
MAX_GGA_QUALITY = 8  # 0 invalid, 1 GPS, 2 DGPS, 3 PPS, 4 RTK fixed, 5 RTK float, 6 dead reckoning, 7 manual, 8 sim
MAX_GGA_SATS = 99  # two digits (the standard says 00-12; multi-GNSS receivers report more)
MAX_GGA_HDOP = 99.99  # receivers without a solution report 99.99 (u-blox, RTKLIB)
MAX_GGA_AGE_S = 999.9  # age of differential data, x.x s; older corrections are no corrections
MAX_GGA_STATION_ID = 1023  # differential reference station id, 0000-1023
MAX_GGA_FIELDS = 15  # talker+type, 14 data fields (the checksum is split off before)

# Plain decimal numbers only: Python's float() would take "nan", "inf", "1e308", "1_0" and spaces.
_DECIMAL = re.compile(rb"-?[0-9]{1,7}(?:\.[0-9]{0,10})?")
_UNSIGNED = re.compile(rb"[0-9]{1,7}(?:\.[0-9]{0,10})?")
_LAT = re.compile(rb"([0-9]{2})([0-9]{2}(?:\.[0-9]{0,10})?)")
_LON = re.compile(rb"([0-9]{3})([0-9]{2}(?:\.[0-9]{0,10})?)")
_UTC = re.compile(rb"([0-9]{2})([0-9]{2})([0-9]{2}(?:\.[0-9]{0,6})?)")
_INT = re.compile(rb"[0-9]{1,4}")


def _coord(value: bytes, hemi: bytes, pattern: re.Pattern, positive: bytes, negative: bytes,
           limit: float) -> float | None:
    m = pattern.fullmatch(value)
    if m is None or hemi not in (positive, negative):
        return None
    deg, minutes = int(m.group(1)), float(m.group(2))
    out = deg + minutes / 60.0
    if minutes >= 60.0 or out > limit:
        return None
    return -out if hemi == negative else out


def _number(value: bytes, pattern: re.Pattern, low: float, high: float) -> float | None:
    """The field as a float within [low, high], or None (an absent field is the caller's business)."""
    if pattern.fullmatch(value) is None:
        return None
    v = float(value)
    return v if low <= v <= high else None


def check_gga(line: bytes) -> str | GgaFix:
    """The `GgaFix` of one GGA sentence, or why it is not a usable one (the classes of the table in
    docs/gga.md: "malformed", "checksum", "no fix", "out of range: <field>")."""
    line = line.strip()
    if len(line) > MAX_NMEA_LINE_BYTES or not line.startswith(b"$"):
        return "malformed: not an NMEA sentence"
    star = line.rfind(b"*")
    if star >= 0:
        body, check = line[1:star], line[star + 1:]
        if len(check) != 2 or not all(c in b"0123456789ABCDEFabcdef" for c in check):
            return "checksum: not two hex digits"
        if int(check, 16) != nmea_checksum(body):
            return "checksum: mismatch"
    else:
        body = line[1:]
    fields = body.split(b",")
    if len(fields) < 10 or len(fields) > MAX_GGA_FIELDS or len(fields[0]) != 5 or fields[0][2:] != b"GGA" \
            or not fields[0][:2].isalpha():
        return "malformed: not a GGA sentence"
    fields += [b""] * (MAX_GGA_FIELDS - len(fields))
    utc, lat_f, ns, lon_f, ew, q, sats, hdop, alt, alt_unit, sep, sep_unit, age, station = fields[1:15]
    if utc:
        m = _UTC.fullmatch(utc)
        if m is None or int(m.group(1)) > 23 or int(m.group(2)) > 59 or float(m.group(3)) >= 61.0:
            return "out of range: time"
    if _INT.fullmatch(q or b"0") is None or int(q or b"0") > MAX_GGA_QUALITY:
        return "out of range: quality"
    quality = int(q or b"0")
    if quality == 0 or not lat_f or not lon_f:
        return "no fix"
    if sats and (_INT.fullmatch(sats) is None or int(sats) > MAX_GGA_SATS):
        return "out of range: satellites"
    lat = _coord(lat_f, ns, _LAT, b"N", b"S", 90.0)
    if lat is None:
        return "out of range: latitude"
    lon = _coord(lon_f, ew, _LON, b"E", b"W", 180.0)
    if lon is None:
        return "out of range: longitude"
    if hdop and _number(hdop, _UNSIGNED, 0.0, MAX_GGA_HDOP) is None:
        return "out of range: hdop"
    if alt_unit not in (b"", b"M") or sep_unit not in (b"", b"M"):
        return "malformed: height unit is not M"
    h = _number(alt, _DECIMAL, MIN_HEIGHT_M, MAX_HEIGHT_M) if alt else 0.0
    if h is None:
        return "out of range: altitude"
    n = _number(sep, _DECIMAL, -MAX_GEOID_SEPARATION_M, MAX_GEOID_SEPARATION_M) if sep else 0.0
    if n is None:
        return "out of range: geoid separation"
    if position_problem(lat, lon, h + n) is not None:
        return "out of range: altitude"
    if age and _number(age, _UNSIGNED, 0.0, MAX_GGA_AGE_S) is None:
        return "out of range: age"
    if station and (_INT.fullmatch(station) is None or int(station) > MAX_GGA_STATION_ID):
        return "out of range: station id"
    return GgaFix(lat, lon, h + n, quality, int(sats or b"0"), fields[0][:2].decode("ascii"), line,
                  float(hdop) if hdop else None, float(age) if age else None)


def parse_gga(line: bytes) -> GgaFix | None:
    """A `GgaFix` from one GGA sentence (line ends optional), or None if it is not a usable GGA
    (`check_gga` says why).

    Requires a valid checksum when one is present (every real receiver sends one); a sentence
    without '*hh' is accepted, as RTKLIB and BKG's caster do.
    """
    out = check_gga(line)
    return out if isinstance(out, GgaFix) else None


def format_gga(lat_deg: float, lon_deg: float, height_m: float = 0.0, *, quality: int = 1,
               num_sats: int = 12, talker: str = "GN", utc: str = "000000.00") -> bytes:
    """A GGA sentence with checksum and CRLF (for tests, the load generator and demo rovers)."""
    alat, alon = abs(lat_deg), abs(lon_deg)
    lat_d, lon_d = int(alat), int(alon)
    body = (f"{talker}GGA,{utc},{lat_d:02d}{(alat - lat_d) * 60:010.7f},{'N' if lat_deg >= 0 else 'S'},"
            f"{lon_d:03d}{(alon - lon_d) * 60:010.7f},{'E' if lon_deg >= 0 else 'W'},{quality},"
            f"{num_sats:02d},1.0,{height_m:.3f},M,0.000,M,,").encode()
    return b"$%b*%02X\r\n" % (body, nmea_checksum(body))


class NmeaLineSplitter:
    """Splits a client's upstream bytes into lines, bounded: an over-long line is discarded whole.

    Clients send GGA lines, sometimes with stray bytes between them (RTKLIB may send nothing, or a
    GGA with no fix). Only lines starting with '$' are returned.
    """

    __slots__ = ("_buf", "_discarding")

    def __init__(self) -> None:
        self._buf = bytearray()
        self._discarding = False

    def feed(self, data: bytes) -> list[bytes]:
        lines: list[bytes] = []
        buf = self._buf
        start = 0
        n = len(data)
        while start < n:
            end = data.find(b"\n", start)
            if end < 0:
                piece = data[start:]
                if self._discarding:
                    pass
                elif len(buf) + len(piece) > MAX_NMEA_LINE_BYTES:
                    buf.clear()
                    self._discarding = True
                else:
                    buf += piece
                break
            piece = data[start:end]
            start = end + 1
            if self._discarding:
                self._discarding = False
                continue
            if len(buf) + len(piece) > MAX_NMEA_LINE_BYTES:
                buf.clear()
                continue
            buf += piece
            line = bytes(buf).strip()
            buf.clear()
            dollar = line.find(b"$")
            if dollar >= 0:
                lines.append(line[dollar:])
        return lines

"""NMEA GGA sentences from NTRIP clients: extraction from the upstream byte stream, parsing, distance.

v2 clients may send the first GGA in the `Ntrip-GGA:` header, v1 clients as a line after the request
head, and both send later updates as raw lines on the same socket (ntrip.md). Any talker is accepted
(`$GPGGA`, `$GNGGA`, `$GBGGA`, ...). A sentence with a bad checksum, no fix or out-of-range values
yields nothing; it never raises.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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


def _coord(value: bytes, hemi: bytes, deg_digits: int, limit: float) -> float | None:
    if len(value) < deg_digits + 2 or hemi not in (b"N", b"S", b"E", b"W"):
        return None
    try:
        deg = int(value[:deg_digits])
        minutes = float(value[deg_digits:])
    except ValueError:
        return None
    if not 0.0 <= minutes < 60.0:
        return None
    out = deg + minutes / 60.0
    if out > limit or not math.isfinite(out):
        return None
    return -out if hemi in (b"S", b"W") else out


def parse_gga(line: bytes) -> GgaFix | None:
    """A `GgaFix` from one GGA sentence (line ends optional), or None if it is not a usable GGA.

    Requires a valid checksum when one is present (every real receiver sends one); a sentence
    without '*hh' is accepted, as RTKLIB and BKG's caster do.
    """
    line = line.strip()
    if len(line) > MAX_NMEA_LINE_BYTES or not line.startswith(b"$"):
        return None
    star = line.rfind(b"*")
    if star >= 0:
        body, check = line[1:star], line[star + 1:]
        try:
            if len(check) != 2 or int(check, 16) != nmea_checksum(body):
                return None
        except ValueError:
            return None
    else:
        body = line[1:]
    fields = body.split(b",")
    if len(fields) < 10 or len(fields[0]) != 5 or fields[0][2:] != b"GGA":
        return None
    try:
        quality = int(fields[6] or b"0")
        num_sats = int(fields[7] or b"0")
    except ValueError:
        return None
    lat = _coord(fields[2], fields[3], 2, 90.0)
    lon = _coord(fields[4], fields[5], 3, 180.0)
    if lat is None or lon is None:
        return None
    try:
        alt = float(fields[9]) if fields[9] else 0.0
        sep = float(fields[11]) if len(fields) > 11 and fields[11] else 0.0
    except ValueError:
        return None
    if not (math.isfinite(alt) and math.isfinite(sep)):
        return None
    return GgaFix(lat, lon, alt + sep, quality, num_sats, fields[0][:2].decode("ascii", "replace"),
                  line)


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

"""NMEA 0183 GGA and RMC sentences from a solution (for the caster's VRS and for train equipment).

Written here rather than with pynmeagps's builder because RTK needs more digits than its default
five decimals of minutes (1.8 cm); we write eight (2 mm resolution would need seven; eight is what
high-precision receivers emit).  pynmeagps parses them back in the tests.

Heights: without a geoid model onboard, GGA's altitude is the ellipsoidal height and the geoid
separation is 0, so altitude + separation is still the ellipsoidal height (NMEA 0183 4.1 defines the
sum); a VRS caster reading the GGA gets the right 3-D point.
"""

from __future__ import annotations

import math

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from augnet.onboard.rtk import RtkSolution, Status

# GGA quality indicator (NMEA 0183 4.1): 0 invalid, 1 GPS fix, 2 DGPS, 4 RTK fixed, 5 RTK float.
GGA_QUALITY = {Status.NONE: 0, Status.SINGLE: 1, Status.FLOAT: 5, Status.FIX: 4}
# RMC mode indicator: N not valid, A autonomous, D differential, F float RTK, R real-time kinematic.
RMC_MODE = {Status.NONE: "N", Status.SINGLE: "A", Status.FLOAT: "F", Status.FIX: "R"}
KNOTS_PER_M_S = 3600.0 / 1852.0


def checksum(body: str) -> str:
    c = 0
    for ch in body.encode("ascii"):
        c ^= ch
    return f"{c:02X}"


def _sentence(body: str) -> str:
    return f"${body}*{checksum(body)}\r\n"


def _lat(lat_deg: float) -> tuple[str, str]:
    a = abs(lat_deg)
    d = int(a)
    m = (a - d) * 60.0
    if round(m, 8) >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:02d}{m:011.8f}", "N" if lat_deg >= 0 else "S"


def _lon(lon_deg: float) -> tuple[str, str]:
    lon_deg = (lon_deg + 180.0) % 360.0 - 180.0
    a = abs(lon_deg)
    d = int(a)
    m = (a - d) * 60.0
    if round(m, 8) >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:03d}{m:011.8f}", "E" if lon_deg >= 0 else "W"


def _utc(t_gpst: float):
    return gtime.gpst_to_utc(t_gpst)


def gga(sol: RtkSolution, talker: str = "GN", hdop: float = 1.0, station_id: int = 0) -> str:
    """A GGA sentence; an invalid position gives quality 0 and empty position fields."""
    utc = _utc(sol.time)
    hhmmss = f"{utc.hour:02d}{utc.minute:02d}{utc.second + utc.microsecond * 1e-6:05.2f}"
    q = GGA_QUALITY[sol.status]
    p = np.asarray(sol.position_m, dtype=float)
    if q == 0 or not np.all(np.isfinite(p)):
        return _sentence(f"{talker}GGA,{hhmmss},,,,,0,00,,,M,,M,,")
    llh = ecef_to_geodetic(p)
    lat, ns = _lat(math.degrees(llh[0]))
    lon, ew = _lon(math.degrees(llh[1]))
    age = f"{sol.age_s:.1f}" if sol.status in (Status.FIX, Status.FLOAT) and math.isfinite(sol.age_s) else ""
    sid = f"{station_id:04d}" if age else ""
    return _sentence(f"{talker}GGA,{hhmmss},{lat},{ns},{lon},{ew},{q},{min(sol.n_sats, 99):02d},{hdop:.1f},"
                     f"{llh[2]:.4f},M,0.000,M,{age},{sid}")


def rmc(sol: RtkSolution, talker: str = "GN") -> str:
    """An RMC sentence; speed and course from the filter's velocity when it has one."""
    utc = _utc(sol.time)
    hhmmss = f"{utc.hour:02d}{utc.minute:02d}{utc.second + utc.microsecond * 1e-6:05.2f}"
    date = f"{utc.day:02d}{utc.month:02d}{utc.year % 100:02d}"
    mode = RMC_MODE[sol.status]
    p = np.asarray(sol.position_m, dtype=float)
    if mode == "N" or not np.all(np.isfinite(p)):
        return _sentence(f"{talker}RMC,{hhmmss},V,,,,,,,{date},,,N")
    llh = ecef_to_geodetic(p)
    lat, ns = _lat(math.degrees(llh[0]))
    lon, ew = _lon(math.degrees(llh[1]))
    spd = cog = ""
    v = np.asarray(sol.velocity_m_s, dtype=float)
    if np.all(np.isfinite(v)):
        enu = enu_rotation(llh[0], llh[1]) @ v
        speed = math.hypot(enu[0], enu[1])
        spd = f"{speed * KNOTS_PER_M_S:.3f}"
        cog = f"{math.degrees(math.atan2(enu[0], enu[1])) % 360.0:.2f}"
    return _sentence(f"{talker}RMC,{hhmmss},A,{lat},{ns},{lon},{ew},{spd},{cog},{date},,,{mode}")

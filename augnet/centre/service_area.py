"""Where the centre serves a VRS: a client position is checked before a session opens or moves.

A VRS is interpolated from the reference stations around it; far from all of them (the other hemisphere,
a pole, a typo in a GGA) the stations share no satellites with the point and the stream would carry 0-1
satellites, served as if it were fine. So every position is first checked for being a place on Earth
(`augwire.positions`: finite, latitude, longitude, height), then against the service area: within
`max_distance_m` of the nearest station (by default the network's largest nearest-neighbour spacing, at
least `MIN_SERVICE_RADIUS_M`) and, when one is configured, inside a polygon. Outside it the session is
refused (`outside="refuse"`, the default) or served at the nearest station (`outside="nearest"`: that
station's own observations, a single-base stream). The caller raises an alarm; the client is told why by
an RTCM 1029 text message (`refusal_message`), a format every RTCM 3 decoder reads (RTKLIB prints it).
What each class of GGA gets, end to end: docs/gga.md.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from typing import Literal

import numpy as np

from augnet.gnss.geometry import ecef_to_geodetic, geodetic_deg_to_ecef
from augwire.positions import position_problem
from augwire.rtcm_framing import frame

# A network of one station is a single base: RTK is routinely served out to ~50 km from one (network-rtk.md:
# VRS measured at 21-62 km from stations); a network's own spacing wins when larger.
MIN_SERVICE_RADIUS_M = 50_000.0
# Sphere of the WGS 84 equatorial radius: service distances need ~0.5 % (the ellipsoid's flattening).
EARTH_RADIUS_M = 6_378_137.0
TEXT_MESSAGE_TYPE = 1029  # RTCM 10403.3 "Unicode text string"
MAX_TEXT_UTF8_BYTES = 255  # DF139 is 8 bits
MAX_TEXT_CHARS = 127  # DF138 is 7 bits
GPS_EPOCH_MJD = 44244  # 1980-01-06


@dataclass(frozen=True)
class AreaConfig:
    """How the service area is drawn (plain values: it crosses to the centre's process)."""

    max_distance_m: float | None = None  # None: from the network geometry (`default_radius_m`)
    polygon: tuple[tuple[float, float], ...] = ()  # (lat, lon) [deg] vertices; empty: no polygon
    outside: Literal["refuse", "nearest"] = "refuse"


@dataclass(frozen=True)
class AreaAnswer:
    """The answer for one position: where to serve it (None: refused) and why."""

    kind: Literal["inside", "invalid", "outside"]
    point_ecef: np.ndarray | None  # the VRS point: the position, or the nearest station's under "nearest"
    reason: str = ""  # empty when inside
    nearest: str | None = None
    distance_m: float = float("nan")

    @property
    def refused(self) -> bool:
        return self.point_ecef is None


def great_circle_m(lat1_deg, lon1_deg, lat2_deg, lon2_deg):
    """Haversine distance [m] on the sphere; arrays broadcast."""
    p1, p2 = np.radians(lat1_deg), np.radians(lat2_deg)
    dp, dl = p2 - p1, np.radians(np.asarray(lon2_deg) - lon1_deg)
    a = np.sin(dp / 2) ** 2 + np.cos(p1) * np.cos(p2) * np.sin(dl / 2) ** 2
    return 2 * EARTH_RADIUS_M * np.arcsin(np.minimum(1.0, np.sqrt(a)))


def default_radius_m(station_lat_lon_deg: np.ndarray) -> float:
    """The network's largest nearest-neighbour spacing (every point between stations is in), at least
    `MIN_SERVICE_RADIUS_M`."""
    ll = np.asarray(station_lat_lon_deg, float).reshape(-1, 2)
    if len(ll) < 2:
        return MIN_SERVICE_RADIUS_M
    d = great_circle_m(ll[:, None, 0], ll[:, None, 1], ll[None, :, 0], ll[None, :, 1])
    np.fill_diagonal(d, np.inf)
    return max(MIN_SERVICE_RADIUS_M, float(d.min(axis=1).max()))


def inside_polygon(lat_deg: float, lon_deg: float, polygon) -> bool:
    """Ray casting in (lon, lat) degrees (a regional polygon that does not cross the antimeridian)."""
    poly = np.asarray(polygon, float)
    y, x = poly[:, 0], poly[:, 1]
    y2, x2 = np.roll(y, -1), np.roll(x, -1)
    crosses = (y > lat_deg) != (y2 > lat_deg)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = x + (lat_deg - y) * (x2 - x) / (y2 - y)
    return bool(np.count_nonzero(crosses & (lon_deg < x_at)) % 2)


class ServiceArea:
    """The network's service area: `check(lat, lon, h)` for every session opened or moved."""

    def __init__(self, stations_ecef: dict[str, np.ndarray], config: AreaConfig | None = None):
        self.config = config or AreaConfig()
        if self.config.outside not in ("refuse", "nearest"):
            raise ValueError(f"service area: outside must be 'refuse' or 'nearest', not {self.config.outside!r}")
        self.names = list(stations_ecef)
        self.ecef = np.array([np.asarray(stations_ecef[k], float) for k in self.names]).reshape(-1, 3)
        llh = ecef_to_geodetic(self.ecef)
        self.lat_lon_deg = np.degrees(llh[:, :2])
        self.radius_m = (float(self.config.max_distance_m) if self.config.max_distance_m is not None
                         else default_radius_m(self.lat_lon_deg))
        if len(self.config.polygon) and len(self.config.polygon) < 3:
            raise ValueError("service area: a polygon needs at least 3 vertices")

    def check(self, lat_deg: float, lon_deg: float, h_m: float) -> AreaAnswer:
        problem = position_problem(lat_deg, lon_deg, h_m)
        if problem is not None:
            return AreaAnswer("invalid", None, f"invalid position: {problem}")
        lat, lon, h = float(lat_deg), float(lon_deg), float(h_m)
        if not self.names:
            return AreaAnswer("outside", None, "no reference station in the network")
        d = great_circle_m(lat, lon, self.lat_lon_deg[:, 0], self.lat_lon_deg[:, 1])
        k = int(np.argmin(d))
        nearest, dist = self.names[k], float(d[k])
        why = ""
        if dist > self.radius_m:
            why = (f"outside the service area: {dist / 1000:.1f} km from the nearest station {nearest} "
                   f"(limit {self.radius_m / 1000:.1f} km)")
        elif len(self.config.polygon) and not inside_polygon(lat, lon, self.config.polygon):
            why = "outside the service area: outside its polygon"
        if not why:
            return AreaAnswer("inside", geodetic_deg_to_ecef(lat, lon, h), "", nearest, dist)
        if self.config.outside == "nearest":
            return AreaAnswer("outside", self.ecef[k].copy(), f"{why}; serving station {nearest}", nearest, dist)
        return AreaAnswer("outside", None, why, nearest, dist)


def refusal_message(text: str, station_id: int = 0, now: dt.datetime | None = None) -> bytes:
    """An RTCM 3 frame of message 1029 (Unicode text string, RTCM 10403.3 3.5.12) carrying `text`
    (truncated to 127 characters and 255 UTF-8 bytes), time-stamped with UTC `now`."""
    now = now or dt.datetime.now(dt.timezone.utc)
    chars = text.encode("utf-8")[:MAX_TEXT_UTF8_BYTES].decode("utf-8", "ignore")[:MAX_TEXT_CHARS]
    raw = chars.encode("utf-8")
    day = now.date() - dt.date(1980, 1, 6)
    mjd = GPS_EPOCH_MJD + day.days
    sod = now.hour * 3600 + now.minute * 60 + now.second
    bits = 0
    for value, width in ((TEXT_MESSAGE_TYPE, 12), (station_id & 0xFFF, 12), (mjd & 0xFFFF, 16), (sod, 17),
                         (len(chars), 7), (len(raw), 8)):
        bits = (bits << width) | value
    header = bits.to_bytes(9, "big")  # 72 bits
    return frame(header + raw)


AREA_ALARM_KIND = "vrs-outside-area"
# The alarm stays raised this long after the last refusal: one alarm per episode, not one per client (a
# client retrying, or a flood of bad positions, would otherwise write an alarm a second).
AREA_ALARM_HOLD_S = 300.0


class AreaAlarm:
    """One `vrs-outside-area` alarm per network, raised at a refusal, cleared `AREA_ALARM_HOLD_S` after the
    last one; `refusals` counts them all. Events are (kind, subject, severity, message, cleared)."""

    def __init__(self, subject: str, hold_s: float = AREA_ALARM_HOLD_S):
        self.subject = subject
        self.hold_s = hold_s
        self.refusals = 0
        self.raised = False
        self._last = -np.inf

    def refused(self, now: float, client_id: str, answer: AreaAnswer) -> tuple | None:
        self.refusals += 1
        self._last = now
        if self.raised:
            return None
        self.raised = True
        return (AREA_ALARM_KIND, self.subject, "warning", f"{client_id}: {answer.reason}", False)

    def poll(self, now: float) -> tuple | None:
        if not self.raised or now - self._last < self.hold_s:
            return None
        self.raised = False
        return (AREA_ALARM_KIND, self.subject, "warning", f"no position refused for {self.hold_s:.0f} s", True)

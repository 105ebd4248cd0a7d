"""Positions for the console: the store's ECEF station coordinates as latitude/longitude/height, and where a
point lies along the line's centre line (for the line diagram)."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from augnet.gnss.constants import WGS84_A_M
from augnet.gnss.geometry import ecef_to_geodetic, geodetic_deg_to_ecef

# Distinct station positions / (line, point) pairs remembered: conversions are pure, and /api/stations asks for
# the same few dozen on every poll.
CACHE_ENTRIES = 4096
# A point further than this from the centre line is not drawn on it (a station of a neighbouring line).
MAX_CROSS_TRACK_KM = 50.0


@lru_cache(maxsize=CACHE_ENTRIES)
def to_geodetic_deg(x_m: float, y_m: float, z_m: float) -> tuple[float, float, float]:
    lat, lon, h = ecef_to_geodetic(np.array([x_m, y_m, z_m]))
    return math.degrees(lat), math.degrees(lon), float(h)


def to_ecef_m(lat_deg: float, lon_deg: float, h_m: float) -> tuple[float, float, float]:
    x, y, z = geodetic_deg_to_ecef(lat_deg, lon_deg, h_m)
    return float(x), float(y), float(z)


def along_track_km(polyline: list[list[float]], lat_deg: float, lon_deg: float,
                   length_km: float | None = None) -> float | None:
    """Distance along the polyline ([[lat, lon], ...]) of the point nearest to (lat, lon), in km.

    Local equirectangular projection around the polyline's mean latitude: the error over a line a few
    hundred km long is well under the width of a station symbol on the diagram. When the line's surveyed
    length is given, the result is scaled to it so stations and trains (whose along-track distance comes
    from the track map) share one scale. None when the polyline is empty or the point is off the line."""
    if not polyline or len(polyline) < 2:
        return None
    return _along_track_km(tuple(tuple(p[:2]) for p in polyline), lat_deg, lon_deg, length_km)


@lru_cache(maxsize=CACHE_ENTRIES)
def _along_track_km(polyline: tuple[tuple[float, float], ...], lat_deg: float, lon_deg: float,
                    length_km: float | None) -> float | None:
    pts = np.asarray(polyline, dtype=float)
    lat0 = math.radians(float(pts[:, 0].mean()))
    km_per_rad = WGS84_A_M / 1000.0
    xy = np.column_stack([np.radians(pts[:, 1]) * math.cos(lat0), np.radians(pts[:, 0])]) * km_per_rad
    p = np.array([math.radians(lon_deg) * math.cos(lat0), math.radians(lat_deg)]) * km_per_rad
    a, b = xy[:-1], xy[1:]
    ab = b - a
    seg_len = np.hypot(ab[:, 0], ab[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(np.einsum("ij,ij->i", p - a, ab) / seg_len**2, 0.0, 1.0)
    t = np.nan_to_num(t)
    nearest = a + ab * t[:, None]
    dist = np.hypot(*(nearest - p).T)
    i = int(np.argmin(dist))
    if dist[i] > MAX_CROSS_TRACK_KM:
        return None
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    along = float(cum[i] + t[i] * seg_len[i])
    total = float(cum[-1])
    if length_km and total > 0:
        along *= length_km / total
    return along

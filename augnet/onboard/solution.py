"""The per-epoch solution record (what the console shows and `augnet rtk` writes) and its CSV form.

CSV columns (one header line, then one row per epoch; empty cells where a value does not exist):
  gpst_s        GPST seconds since 1980-01-06 (augnet's time representation)
  gps_week, tow_s
  utc           ISO 8601 UTC
  x_m, y_m, z_m ECEF WGS 84
  lat_deg, lon_deg, h_m   geodetic, ellipsoidal height
  status        fix / float / single / none   (status_q: RTKLIB's Q code 1/2/5/0)
  ratio         LAMBDA ratio of the fix (0 when not fixed)
  success_rate  bootstrapped success rate of the fixed subset
  n_sats, n_fixed
  sd_e_m, sd_n_m, sd_u_m  standard deviations, local east/north/up
  age_s         age of corrections (rover time minus base time)
  baseline_m
  vel_e_m_s, vel_n_m_s, vel_u_m_s   velocity (filter state with dynamics, else from Dopplers)
  message       why the status is what it is
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from typing import IO, Iterable

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from augnet.onboard.rtk import RtkSolution

CSV_COLUMNS = (
    "gpst_s", "gps_week", "tow_s", "utc", "x_m", "y_m", "z_m", "lat_deg", "lon_deg", "h_m",
    "status", "status_q", "ratio", "success_rate", "n_sats", "n_fixed", "sd_e_m", "sd_n_m", "sd_u_m",
    "age_s", "baseline_m", "vel_e_m_s", "vel_n_m_s", "vel_u_m_s", "message",
)


@dataclass(frozen=True)
class SolutionRecord:
    """A flat, serialisable view of an `RtkSolution` (geodetic position and ENU sigmas included)."""

    gpst_s: float
    x_m: float
    y_m: float
    z_m: float
    lat_deg: float
    lon_deg: float
    h_m: float
    status: str
    status_q: int
    ratio: float
    success_rate: float
    n_sats: int
    n_fixed: int
    sd_e_m: float
    sd_n_m: float
    sd_u_m: float
    age_s: float
    baseline_m: float
    message: str
    vel_e_m_s: float = math.nan
    vel_n_m_s: float = math.nan
    vel_u_m_s: float = math.nan

    @classmethod
    def from_solution(cls, sol: RtkSolution) -> "SolutionRecord":
        p = np.asarray(sol.position_m, dtype=float)
        if np.all(np.isfinite(p)):
            llh = ecef_to_geodetic(p)
            R = enu_rotation(llh[0], llh[1])
            C = R @ np.asarray(sol.covariance_m2, dtype=float) @ R.T
            sd = np.sqrt(np.clip(np.diag(C), 0.0, None))
            lat, lon, h = math.degrees(llh[0]), math.degrees(llh[1]), float(llh[2])
            venu = R @ np.asarray(sol.velocity_m_s, dtype=float)
        else:
            sd = np.full(3, math.nan)
            lat = lon = h = math.nan
            venu = np.full(3, math.nan)
        return cls(float(sol.time), float(p[0]), float(p[1]), float(p[2]), lat, lon, h, sol.status_name,
                   int(sol.status), float(sol.ratio), float(sol.success_rate), int(sol.n_sats), int(sol.n_fixed),
                   float(sd[0]), float(sd[1]), float(sd[2]), float(sol.age_s), float(sol.baseline_m), sol.message,
                   float(venu[0]), float(venu[1]), float(venu[2]))


def _fmt(v, digits: int) -> str:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else f"{v:.{digits}f}"
    return str(v)


def write_csv(records: Iterable[SolutionRecord | RtkSolution], out: IO[str]) -> int:
    """Write solutions as CSV; returns the number of rows written."""
    w = csv.writer(out, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    n = 0
    for r in records:
        if isinstance(r, RtkSolution):
            r = SolutionRecord.from_solution(r)
        week, tow = gtime.week_tow(r.gpst_s)
        try:
            utc = gtime.gpst_to_utc(r.gpst_s).isoformat(timespec="milliseconds")
        except (ValueError, OverflowError, gtime.TimeError):
            utc = ""
        w.writerow([
            _fmt(r.gpst_s, 3), int(week), _fmt(float(tow), 3), utc,
            _fmt(r.x_m, 4), _fmt(r.y_m, 4), _fmt(r.z_m, 4),
            _fmt(r.lat_deg, 9), _fmt(r.lon_deg, 9), _fmt(r.h_m, 4),
            r.status, r.status_q, _fmt(r.ratio, 1), _fmt(r.success_rate, 6), r.n_sats, r.n_fixed,
            _fmt(r.sd_e_m, 4), _fmt(r.sd_n_m, 4), _fmt(r.sd_u_m, 4),
            _fmt(r.age_s, 1), _fmt(r.baseline_m, 3),
            _fmt(r.vel_e_m_s, 3), _fmt(r.vel_n_m_s, 3), _fmt(r.vel_u_m_s, 3), r.message,
        ])
        n += 1
    return n


def read_csv(f: IO[str]) -> list[dict[str, str]]:
    """Rows of a solution CSV as dicts (for tests and tools)."""
    return list(csv.DictReader(f))

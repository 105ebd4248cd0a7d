"""GNSS time scales: GPST, GST, BDT, UTC; weeks and times of week; calendar conversions.

Representation (one choice, used everywhere in augnet):
    a time is a float64 (or an array of them) of **seconds since the GPS epoch,
    1980-01-06 00:00:00, in GPS Time (GPST)**.  Call it "GPST seconds".

Why: GPST is continuous (no leap seconds), Galileo System Time is steered to it (offset of a few ns,
broadcast, ignored here) and BeiDou Time is GPST - 14 s exactly, so every system's time is one
subtraction away and times vectorise as plain numpy arrays.  Precision: float64 resolves 2.4e-7 s
at 1.4e9 s (the 2020s), so a time is held to +-0.12 us; that moves a satellite by < 0.5 mm and a
range by < 0.1 mm.  Where small differences matter (transit time, finite differences) the
ephemeris code adds them after subtracting toe (`satellite_state(..., offset_s=)`), at full
precision.  RINEX epochs (0.1 us digits) are written rounded to 7 decimals; whole, 0.1 s and
0.5 ms epochs print exactly, and write -> read returns the same float.

UTC: GPST - UTC = number of leap seconds since 1980 (18 s from 2017-01-01 on; IERS Bulletin C).
"""

from __future__ import annotations

import datetime as _dt

import numpy as np

from augnet.gnss.constants import (
    BDS_WEEK_OFFSET_FROM_GPS,
    BDT_MINUS_GPST_S,
    GAL_WEEK_OFFSET_FROM_GPS,
    SECONDS_PER_DAY,
    SECONDS_PER_WEEK,
)

GPS_EPOCH = _dt.datetime(1980, 1, 6)  # naive datetime, in whatever time scale it labels
# BDS week 0 starts at 2006-01-01 00:00:00 BDT; in GPST that is 14 s later.
BDS_EPOCH_GPST_S = BDS_WEEK_OFFSET_FROM_GPS * SECONDS_PER_WEEK - BDT_MINUS_GPST_S
GAL_EPOCH_GPST_S = GAL_WEEK_OFFSET_FROM_GPS * SECONDS_PER_WEEK

# Leap second table: (first UTC day it applies, GPST - UTC [s]).  IERS Bulletin C; the last entry
# (2017-01-01, 18 s) is still current (no leap second announced through 2026).
LEAP_SECONDS: tuple[tuple[_dt.datetime, int], ...] = (
    (_dt.datetime(1981, 7, 1), 1),
    (_dt.datetime(1982, 7, 1), 2),
    (_dt.datetime(1983, 7, 1), 3),
    (_dt.datetime(1985, 7, 1), 4),
    (_dt.datetime(1988, 1, 1), 5),
    (_dt.datetime(1990, 1, 1), 6),
    (_dt.datetime(1991, 1, 1), 7),
    (_dt.datetime(1992, 7, 1), 8),
    (_dt.datetime(1993, 7, 1), 9),
    (_dt.datetime(1994, 7, 1), 10),
    (_dt.datetime(1996, 1, 1), 11),
    (_dt.datetime(1997, 7, 1), 12),
    (_dt.datetime(1999, 1, 1), 13),
    (_dt.datetime(2006, 1, 1), 14),
    (_dt.datetime(2009, 1, 1), 15),
    (_dt.datetime(2012, 7, 1), 16),
    (_dt.datetime(2015, 7, 1), 17),
    (_dt.datetime(2017, 1, 1), 18),
)

SYSTEM_TIME_SCALES = {"G": "GPS", "E": "GAL", "C": "BDT", "J": "QZS", "R": "GLO", "S": "SBAS", "I": "IRN"}


class TimeError(ValueError):
    """A time that cannot be represented (before the GPS epoch, bad calendar fields)."""


# ---------------------------------------------------------------------------------------------
# calendar <-> seconds (no leap seconds: the calendar is read in the scale it labels)


def from_datetime(t: _dt.datetime) -> float:
    """Seconds since 1980-01-06 of a calendar instant, read in the same time scale.

    A timezone-aware datetime is converted to its naive UTC calendar first; use `utc_to_gpst` to
    step from UTC to GPST.  Microsecond resolution (datetime's own).
    """
    if t.tzinfo is not None:
        t = t.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    d = t - GPS_EPOCH
    return d.days * SECONDS_PER_DAY + d.seconds + d.microseconds * 1e-6


def to_datetime(s: float) -> _dt.datetime:
    """Naive calendar datetime of seconds since 1980-01-06 (same scale), rounded to 1 us."""
    s = float(s)
    if not np.isfinite(s):
        raise TimeError(f"not a finite time: {s}")
    days, rem = divmod(s, SECONDS_PER_DAY)
    micro = round(rem * 1e6)
    return GPS_EPOCH + _dt.timedelta(days=int(days), microseconds=micro)


def from_calendar(year: int, month: int, day: int, hour: int = 0, minute: int = 0,
                  second: float = 0.0) -> float:
    """Seconds since 1980-01-06 of calendar fields (same scale); `second` keeps its full float."""
    try:
        base = _dt.datetime(int(year), int(month), int(day), int(hour), int(minute))
    except (ValueError, OverflowError) as exc:
        raise TimeError(f"bad calendar time {year}-{month}-{day} {hour}:{minute}:{second}: {exc}") from None
    d = base - GPS_EPOCH
    return d.days * SECONDS_PER_DAY + d.seconds + float(second)


def to_calendar(s: float, decimals: int = 7) -> tuple[int, int, int, int, int, float]:
    """(year, month, day, hour, minute, second) with the seconds rounded to `decimals` places.

    Rounding carries into the minute (59.99999999 s with 7 decimals becomes the next minute).
    """
    s = float(s)
    if not np.isfinite(s):
        raise TimeError(f"not a finite time: {s}")
    whole = np.floor(s)
    frac = round(s - whole, decimals)
    if frac >= 1.0:
        whole += 1.0
        frac = 0.0
    days, rem = divmod(int(whole), int(SECONDS_PER_DAY))
    t = GPS_EPOCH + _dt.timedelta(days=days, seconds=rem)
    return t.year, t.month, t.day, t.hour, t.minute, t.second + frac


# ---------------------------------------------------------------------------------------------
# week / time of week per system


def gpst_from_week_tow(week, tow):
    """GPST seconds from GPS week (continuous, no 1024 roll-over) and time of week [s]."""
    return np.asarray(week, dtype=float) * SECONDS_PER_WEEK + np.asarray(tow, dtype=float)


def week_tow(t_gpst):
    """(GPS week, GPS time of week [s]) of GPST seconds; arrays broadcast."""
    t = np.asarray(t_gpst, dtype=float)
    week = np.floor(t / SECONDS_PER_WEEK)
    return week.astype(np.int64), t - week * SECONDS_PER_WEEK


def gpst_to_bdt(t_gpst):
    """BDT seconds since the GPS epoch instant (BDT = GPST - 14 s)."""
    return np.asarray(t_gpst, dtype=float) + BDT_MINUS_GPST_S


def bdt_to_gpst(t_bdt):
    return np.asarray(t_bdt, dtype=float) - BDT_MINUS_GPST_S


def bds_week_tow(t_gpst):
    """(BDS week, BDT seconds of week) of GPST seconds.  BDS week 0 began 2006-01-01 00:00 BDT."""
    t = np.asarray(t_gpst, dtype=float) - BDS_EPOCH_GPST_S
    week = np.floor(t / SECONDS_PER_WEEK)
    return week.astype(np.int64), t - week * SECONDS_PER_WEEK


def gpst_from_bds_week_tow(week, sow):
    return BDS_EPOCH_GPST_S + np.asarray(week, dtype=float) * SECONDS_PER_WEEK + np.asarray(sow, dtype=float)


def gal_week_tow(t_gpst):
    """(Galileo week, GST seconds of week).  GST week 0 began 1999-08-22 = GPS week 1024."""
    t = np.asarray(t_gpst, dtype=float) - GAL_EPOCH_GPST_S
    week = np.floor(t / SECONDS_PER_WEEK)
    return week.astype(np.int64), t - week * SECONDS_PER_WEEK


def gpst_from_gal_week_tow(week, sow):
    return GAL_EPOCH_GPST_S + np.asarray(week, dtype=float) * SECONDS_PER_WEEK + np.asarray(sow, dtype=float)


def system_week_tow(system: str, t_gpst):
    """(week, seconds of week) in the system's own time scale and week numbering."""
    if system == "C":
        return bds_week_tow(t_gpst)
    if system == "E":
        return gal_week_tow(t_gpst)
    return week_tow(t_gpst)


def gpst_from_system_week_tow(system: str, week, sow):
    if system == "C":
        return gpst_from_bds_week_tow(week, sow)
    if system == "E":
        return gpst_from_gal_week_tow(week, sow)
    return gpst_from_week_tow(week, sow)


def system_to_gpst(system: str, t_sys):
    """GPST seconds of a time read in a system's scale (only BDS differs: +14 s)."""
    if system == "C":
        return bdt_to_gpst(t_sys)
    return np.asarray(t_sys, dtype=float)


def gpst_to_system(system: str, t_gpst):
    if system == "C":
        return gpst_to_bdt(t_gpst)
    return np.asarray(t_gpst, dtype=float)


def resolve_tow(tow, t_ref_tow):
    """Undo a time-of-week wrap: return `tow` shifted by whole weeks to lie within half a week of
    `t_ref_tow`.  Used for a broadcast toc/toe given as seconds of week near a week boundary."""
    tow = np.asarray(tow, dtype=float)
    d = tow - np.asarray(t_ref_tow, dtype=float)
    return tow - np.round(d / SECONDS_PER_WEEK) * SECONDS_PER_WEEK


def time_of_week_difference(a, b):
    """a - b for times of week, folded into [-302400, 302400) s (IS-GPS-200 20.3.3.4.3 tk rule)."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    return d - np.round(d / SECONDS_PER_WEEK) * SECONDS_PER_WEEK


# ---------------------------------------------------------------------------------------------
# UTC (leap seconds)


def leap_seconds_at_utc(t_utc: _dt.datetime) -> int:
    """GPST - UTC [s] in force at a UTC calendar instant."""
    if t_utc.tzinfo is not None:
        t_utc = t_utc.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    if t_utc < GPS_EPOCH:
        raise TimeError(f"{t_utc} is before the GPS epoch")
    n = 0
    for start, leap in LEAP_SECONDS:
        if t_utc >= start:
            n = leap
    return n


# The leap second starting at UTC `start` takes effect at GPST start + leap.
_LEAP_STARTS_GPST = np.array([from_datetime(start) + leap for start, leap in LEAP_SECONDS])
_LEAP_VALUES = np.array([0] + [leap for _, leap in LEAP_SECONDS])


def leap_seconds_at_gpst(t_gpst):
    """GPST - UTC [s] at GPST instant(s); an int for a scalar, an int array for an array."""
    t = np.asarray(t_gpst, dtype=float)
    n = _LEAP_VALUES[np.searchsorted(_LEAP_STARTS_GPST, t, side="right")]
    return int(n) if n.ndim == 0 else n


def gpst_to_utc_seconds(t_gpst):
    """UTC as seconds since 1980-01-06 00:00:00 UTC (no leap seconds counted), vectorised."""
    return np.asarray(t_gpst, dtype=float) - leap_seconds_at_gpst(t_gpst)


def utc_to_gpst(t_utc: _dt.datetime) -> float:
    """GPST seconds of a UTC calendar instant (naive = UTC, or timezone-aware)."""
    if t_utc.tzinfo is not None:
        t_utc = t_utc.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    return from_datetime(t_utc) + leap_seconds_at_utc(t_utc)


def gpst_to_utc(t_gpst: float) -> _dt.datetime:
    """UTC calendar instant (timezone-aware) of GPST seconds."""
    return to_datetime(float(t_gpst) - leap_seconds_at_gpst(t_gpst)).replace(tzinfo=_dt.timezone.utc)


def now_gpst() -> float:
    """The current instant in GPST seconds (from the host's UTC clock)."""
    return utc_to_gpst(_dt.datetime.now(_dt.timezone.utc))

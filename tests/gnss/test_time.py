"""Time scales: GPS/BDS/Galileo weeks, BDT offset, calendar conversions, leap seconds."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from augnet.gnss import time as gt


def test_gps_week_and_tow_of_known_dates():
    # 2023-07-11 (a Tuesday) is GPS week 2270, 2 days into the week: the toe of the day's
    # first GPS ephemerides in brdm-2023-07-11.nav (week 2270, toe 172800).
    assert gt.week_tow(gt.from_calendar(2023, 7, 11)) == (2270, 172800.0)
    assert gt.week_tow(0.0) == (0, 0.0)
    # The first GPS week roll-over: 1999-08-22 00:00 is week 1024.
    assert gt.week_tow(gt.from_calendar(1999, 8, 22))[0] == 1024
    weeks, tows = gt.week_tow(np.array([0.0, 604799.5, 604800.0]))
    assert weeks.tolist() == [0, 0, 1] and tows.tolist() == [0.0, 604799.5, 0.0]


def test_bds_time_is_gpst_minus_14_s_and_week_0_starts_2006():
    t = gt.from_calendar(2023, 7, 11)
    assert gt.gpst_to_bdt(t) == t - 14.0
    assert gt.bdt_to_gpst(gt.gpst_to_bdt(t)) == t
    # BDS week 0 starts 2006-01-01 00:00:00 BDT, i.e. 14 s after 2006-01-01 00:00:00 GPST.
    assert gt.gpst_from_bds_week_tow(0, 0.0) == gt.from_calendar(2006, 1, 1) + 14.0
    # The 2023 nav file's BDUT line gives BDS week 914 for this day; sow 172786 = 2 days - 14 s.
    assert gt.bds_week_tow(t) == (914, 172786.0)
    w, s = gt.bds_week_tow(t)
    assert gt.gpst_from_bds_week_tow(w, s) == t


def test_galileo_week():
    t = gt.from_calendar(2023, 7, 11)
    assert gt.gal_week_tow(t) == (2270 - 1024, 172800.0)
    assert gt.gpst_from_gal_week_tow(0, 0.0) == gt.from_calendar(1999, 8, 22)
    for sys in "GEC":
        w, s = gt.system_week_tow(sys, t)
        assert gt.gpst_from_system_week_tow(sys, w, s) == t


def test_leap_seconds():
    assert gt.leap_seconds_at_utc(dt.datetime(2023, 7, 11)) == 18
    assert gt.leap_seconds_at_utc(dt.datetime(2016, 12, 31, 23, 59, 59)) == 17
    assert gt.leap_seconds_at_utc(dt.datetime(2017, 1, 1)) == 18
    assert gt.leap_seconds_at_utc(dt.datetime(1980, 1, 6)) == 0
    t_utc = dt.datetime(2023, 7, 11, 12, 0, 0, tzinfo=dt.timezone.utc)
    t = gt.utc_to_gpst(t_utc)
    assert t == gt.from_calendar(2023, 7, 11, 12) + 18.0
    assert gt.gpst_to_utc(t) == t_utc
    # Around the 2017 leap second: GPST 2017-01-01 00:00:18 is UTC midnight.
    assert gt.gpst_to_utc(gt.from_calendar(2017, 1, 1) + 18.0) == dt.datetime(2017, 1, 1, tzinfo=dt.timezone.utc)
    assert gt.gpst_to_utc(gt.from_calendar(2017, 1, 1) + 16.5) == dt.datetime(
        2016, 12, 31, 23, 59, 59, 500000, tzinfo=dt.timezone.utc
    )
    with pytest.raises(gt.TimeError):
        gt.leap_seconds_at_utc(dt.datetime(1979, 1, 1))
    # Vectorised, for NMEA time stamps of many epochs.
    t17 = gt.from_calendar(2017, 1, 1)
    assert gt.leap_seconds_at_gpst(np.array([t17 + 16.9, t17 + 18.0, 0.0])).tolist() == [17, 18, 0]
    assert gt.gpst_to_utc_seconds(np.array([t17 + 18.0]))[0] == t17


def test_calendar_rounding_carries_and_bad_dates_raise():
    t = gt.from_calendar(2023, 12, 31, 23, 59, 59.99999999)
    assert gt.to_calendar(t, decimals=7) == (2024, 1, 1, 0, 0, 0.0)
    assert gt.to_calendar(gt.from_calendar(2021, 9, 22, 6, 30, 12.5)) == (2021, 9, 22, 6, 30, 12.5)
    with pytest.raises(gt.TimeError):
        gt.from_calendar(2023, 2, 30)
    with pytest.raises(gt.TimeError):
        gt.to_datetime(float("nan"))


def test_resolve_tow_across_week_boundary():
    # toc just before the week roll-over with toe just after it: toc belongs to the previous week.
    assert gt.resolve_tow(604790.0, 10.0) == -10.0
    assert gt.resolve_tow(10.0, 604790.0) == 604810.0
    assert gt.time_of_week_difference(5.0, 604795.0) == 10.0


@given(st.integers(min_value=0, max_value=3_000_000_000), st.integers(min_value=0, max_value=9_999_999))
def test_calendar_round_trip(whole, tenth_us):
    t = whole + tenth_us * 1e-7
    y, mo, d, h, mi, s = gt.to_calendar(t)
    assert abs(gt.from_calendar(y, mo, d, h, mi, s) - t) < 5e-7
    assert abs(gt.from_datetime(gt.to_datetime(t)) - t) < 1e-6

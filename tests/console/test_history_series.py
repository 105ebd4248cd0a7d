"""The quality history's series for the page's charts (GET /api/history/series, decision 0185): every series
of a window, downsampled in the store into equal buckets (mean, min, max), bounded in window and points."""

from __future__ import annotations

import datetime as dt

import pytest

from augnet.store import queries as q
from augnet.store import series

from tests.console.helpers import error_fields

UNTIL = dt.datetime(2026, 12, 3, 12, 0, tzinfo=dt.timezone.utc)
STEP_S = 10  # the system's cadence (persistence.QUALITY_INTERVAL_S)


def seed(sessions, n: int = 360) -> None:
    """An hour at 10 s: one baseline rising 0 -> ~1, the network's series, a station silent in its 2nd half."""
    with sessions.begin() as s:
        for i in range(n):
            at = UNTIL - dt.timedelta(seconds=STEP_S * (n - i))
            q.record_quality(s, at, "STA1-STA2", i / n, 0.01, 20)
            q.record_quality(s, at, "STA1", 0.5, None, 20)  # a station's own row: no series
            series.record_series(s, at, series.CORRECTION_AGE_P99, 0.5 + (i % 2))
            series.record_series(s, at, series.TRAINS_FIXED, 2.0)
            if i < n // 2:
                series.record_series(s, at, series.station_data_age("STA1"), 0.3)


def get(c, **params):
    r = c.client.get("/api/history/series", params=params, headers=c.as_("vera"))
    assert r.status_code == 200, r.text
    return r.json()


def test_a_window_of_every_series_downsampled_into_buckets(console):
    seed(console.sessions)
    h = get(console, window_s=3600, points=60, until=UNTIL.isoformat())
    assert dt.datetime.fromisoformat(h["until"]) == UNTIL and h["bucket_s"] == 60.0
    assert dt.datetime.fromisoformat(h["since"]) == UNTIL - dt.timedelta(hours=1)
    by = {s["subject"]: s for s in h["series"]}
    assert set(by) == {"STA1-STA2", series.CORRECTION_AGE_P99, series.TRAINS_FIXED, "station:STA1:data_age_s"}
    assert [(by[k]["kind"], by[k]["unit"], by[k]["label"]) for k in sorted(by)] == [
        ("fixed_fraction", "1", "STA1-STA2"), ("correction_age_p99", "s", "p99"),
        ("station_data_age", "s", "STA1"), ("trains", "count", "fixed")]
    ff = by["STA1-STA2"]["points"]
    assert len(ff) == 60  # 6 samples a bucket
    t, mean, low, high = ff[0]
    assert (low, high) == (0.0, pytest.approx(5 / 360)) and mean == pytest.approx(2.5 / 360)
    assert t == pytest.approx((UNTIL - dt.timedelta(seconds=3600 - 25)).timestamp())  # the samples' mean time
    assert all(b[0] - a[0] == pytest.approx(60.0) for a, b in zip(ff, ff[1:]))
    age = by[series.CORRECTION_AGE_P99]["points"]
    assert {(p[1], p[2], p[3]) for p in age} == {(1.0, 0.5, 1.5)}  # a bucket keeps its extremes
    assert len(by["station:STA1:data_age_s"]["points"]) == 30  # silent since: no points, a gap


def test_naive_until_is_utc_and_a_short_window_gets_raw_samples(console):
    seed(console.sessions)
    h = get(console, window_s=120, points=600, until=UNTIL.replace(tzinfo=None).isoformat())
    fixed = next(s for s in h["series"] if s["subject"] == series.TRAINS_FIXED)["points"]
    assert len(fixed) == 12 and all(p[1:] == [2.0, 2.0, 2.0] for p in fixed)
    assert get(console, window_s=3600, until=(UNTIL - dt.timedelta(days=1)).isoformat())["series"] == []


def test_the_default_window_ends_now(console):
    with console.sessions.begin() as s:
        series.record_series(s, dt.datetime.now(dt.timezone.utc) - dt.timedelta(minutes=5), series.TRAINS_FIXED, 4.0)
    (only,) = get(console)["series"]
    assert only["subject"] == series.TRAINS_FIXED and only["points"][0][1] == 4.0


@pytest.mark.parametrize("params, field", [({"window_s": 59}, "window_s"), ({"window_s": 7 * 86400 + 1}, "window_s"),
                                           ({"points": 1}, "points"), ({"points": 601}, "points"),
                                           ({"until": "tomorrow"}, "until")])
def test_window_and_points_are_bounded(sqlite_console, params, field):
    c = sqlite_console
    assert error_fields(c.client.get("/api/history/series", params=params, headers=c.as_("vera"))) == {field}


def test_the_series_need_a_login(sqlite_console):
    assert sqlite_console.client.get("/api/history/series").status_code == 401


def test_at_most_max_series_subjects_alphabetically_first(sqlite_console):
    seed(sqlite_console.sessions, n=30)
    with sqlite_console.sessions() as s:
        capped = series.series_buckets(s, UNTIL - dt.timedelta(hours=1), UNTIL, 10, max_series=2)
    assert list(capped) == ["STA1", "STA1-STA2"]  # the station's own row counts; the API then drops it
    with pytest.raises(ValueError):
        with sqlite_console.sessions() as s:
            series.series_buckets(s, UNTIL, UNTIL, 10, max_series=2)

"""History: network quality samples, the quality history's series downsampled for the page's charts
(decision 0185), and the audit log of operator actions."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, Query
from pydantic import BaseModel

from augnet.console.deps import DB, Viewer, utc
from augnet.console.schemas import AuditOut, QualityOut
from augnet.store import queries as q
from augnet.store import series

router = APIRouter(tags=["history"])
MAX_QUALITY_SAMPLES = 10_000  # one day of one baseline at 10 s, or a week of a dozen at 10 min
MAX_AUDIT_ENTRIES = 1_000
MIN_WINDOW_S, MAX_WINDOW_S = 60, 7 * 86_400  # the charts' windows: a minute to a week
DEFAULT_WINDOW_S = 3_600
# Points per series: a chart ~900 px wide gains nothing from more than one point per 1.5 px.
MAX_POINTS, DEFAULT_POINTS = 600, 240
MAX_SERIES = 256  # subjects per answer: every baseline and station of a large network, and the network's own


class SeriesOut(BaseModel):
    subject: str  # as stored: "STA1-STA2", "network:correction_age_p99_s", "station:STA1:data_age_s", ...
    kind: str  # the chart: "fixed_fraction" | "correction_age_p99" | "trains" | "station_data_age"
    unit: str  # "1" (a fraction), "s", "count"
    label: str  # the legend's name: the baseline, the station, "fixed" / "reporting", "p99"
    points: list[tuple[float, float, float, float]]  # [t_unix, mean, min, max] per bucket, oldest first


class HistoryOut(BaseModel):
    since: dt.datetime
    until: dt.datetime
    bucket_s: float  # each point stands for this much time (its mean, min and max)
    series: list[SeriesOut]


def series_label(subject: str, kind: str) -> str:
    if kind == "station_data_age":
        return subject.removeprefix(series.STATION_PREFIX).removesuffix(series.STATION_DATA_AGE_SUFFIX)
    if kind == "trains":
        return subject.split(":", 1)[1]
    if kind == "correction_age_p99":
        return "p99"
    return subject


@router.get("/quality", response_model=list[QualityOut])
def quality(who: Viewer, session: DB,
            subject: Annotated[str | None, Query(max_length=64, pattern=r"^[^\x00]*$", description='"STA1-STA2" or "STA1"')] = None,
            since: Annotated[dt.datetime | None, Query(description="ISO 8601; naive times are UTC")] = None,
            limit: Annotated[int, Query(ge=1, le=MAX_QUALITY_SAMPLES)] = 1000) -> list[QualityOut]:
    """Quality samples, oldest first: fixed fraction, residual RMS [m], satellites, per baseline or station."""
    if since is not None and since.tzinfo is None:
        since = since.replace(tzinfo=dt.timezone.utc)
    return [QualityOut(at=utc(at), subject=subj, fixed_fraction=ff, residual_rms_m=rms, satellites=n)
            for at, subj, ff, rms, n in q.quality_rows(session, subject=subject, since=since, limit=limit)]


@router.get("/history/series", response_model=HistoryOut)
def history_series(who: Viewer, session: DB,
                   window_s: Annotated[int, Query(ge=MIN_WINDOW_S, le=MAX_WINDOW_S, description="seconds")] = DEFAULT_WINDOW_S,
                   until: Annotated[dt.datetime | None, Query(description="ISO 8601 end of the window (default now); naive times are UTC")] = None,
                   points: Annotated[int, Query(ge=2, le=MAX_POINTS)] = DEFAULT_POINTS) -> HistoryOut:
    """Every series of the quality history over [until - window_s, until), downsampled in the store into
    `points` equal buckets (each point the bucket's mean time, mean, min and max; an empty bucket is a gap):
    per-baseline fixed fraction, correction age p99 [s], trains fixed and reporting, station data age [s]."""
    if until is None:
        until = dt.datetime.now(dt.timezone.utc)
    elif until.tzinfo is None:
        until = until.replace(tzinfo=dt.timezone.utc)
    until = until.astimezone(dt.timezone.utc)
    since = until - dt.timedelta(seconds=window_s)
    out = []
    for subject, buckets in series.series_buckets(session, since, until, points, MAX_SERIES).items():
        kind = series.kind_of(subject)
        if kind is None:
            continue
        out.append(SeriesOut(subject=subject, kind=kind, unit=series.KINDS[kind], label=series_label(subject, kind),
                             points=[(b.t_unix, b.mean, b.low, b.high) for b in buckets]))
    return HistoryOut(since=since, until=until, bucket_s=window_s / points, series=out)


@router.get("/audit", response_model=list[AuditOut])
def audit(who: Viewer, session: DB,
          limit: Annotated[int, Query(ge=1, le=MAX_AUDIT_ENTRIES)] = 200) -> list[AuditOut]:
    """Operator actions, newest first."""
    return [AuditOut(id=e.id, at=utc(e.at), actor=e.actor, action=e.action, target=e.target, detail=e.detail or {})
            for e in q.audit_log(session, limit=limit)]

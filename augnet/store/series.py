"""The quality history's series: what each subject of `quality_history` means, recording a series value, and
reading a window of every series downsampled in the database (decision 0185).

A baseline's row ("STA1-STA2") keeps its columns (fixed fraction, fixed residual RMS, satellites). The
network's other figures share the table as one value per row, in the `fixed_fraction` column, under a subject
"<group>:<name>" or "station:<code>:<name>" whose last part names the unit:
  network:correction_age_p99_s   the centre's correction age, 99th percentile over its last epochs [s]
  trains:fixed, trains:reporting  trains with an RTK fix / with any solution [count]
  station:<code>:data_age_s       a station's data age at the network epoch [s]
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass

from sqlalchemy import Integer, cast, func, select
from sqlalchemy.orm import Session

from augnet.store.models import QualitySample

CORRECTION_AGE_P99 = "network:correction_age_p99_s"
TRAINS_FIXED = "trains:fixed"
TRAINS_REPORTING = "trains:reporting"
STATION_PREFIX = "station:"
STATION_DATA_AGE_SUFFIX = ":data_age_s"
SUBJECT_MAX_CHARS = 64  # QualitySample.subject is String(64)
# Series kinds as the console groups them into charts, with the unit of their values.
KINDS = {"fixed_fraction": "1", "correction_age_p99": "s", "trains": "count", "station_data_age": "s"}
UNIX_EPOCH_JULIAN_DAY = 2440587.5  # SQLite's julianday() of 1970-01-01T00:00Z
SECONDS_PER_DAY = 86400.0
# julianday() in double precision is ~10 us off at today's dates: a sample on a bucket edge stays in its bucket
EDGE_TOLERANCE_S = 1e-3


def station_data_age(code: str) -> str:
    return STATION_PREFIX + code + STATION_DATA_AGE_SUFFIX


def kind_of(subject: str) -> str | None:
    """The chart a subject belongs to (a key of KINDS), None for a subject that is no series (a station's
    own quality row "STA1", or a name this version does not know)."""
    if subject == CORRECTION_AGE_P99:
        return "correction_age_p99"
    if subject in (TRAINS_FIXED, TRAINS_REPORTING):
        return "trains"
    if subject.startswith(STATION_PREFIX) and subject.endswith(STATION_DATA_AGE_SUFFIX):
        return "station_data_age"
    if ":" not in subject and subject.count("-") == 1:
        return "fixed_fraction"
    return None


def record_series(session: Session, at: dt.datetime, subject: str, value: float) -> QualitySample:
    """One value of a network series (a subject named as in the module's docstring)."""
    if kind_of(subject) in (None, "fixed_fraction") or len(subject) > SUBJECT_MAX_CHARS:
        raise ValueError(f"not a series subject: {subject!r}")
    if not math.isfinite(value):
        raise ValueError(f"{subject}: a series value must be finite, not {value!r}")
    sample = QualitySample(at=at, subject=subject, fixed_fraction=float(value), residual_rms_m=None, satellites=0)
    session.add(sample)
    return sample


@dataclass(frozen=True, slots=True)
class Bucket:
    t_unix: float  # mean time of the samples in the bucket
    mean: float
    low: float
    high: float
    samples: int


def _epoch_s(session: Session, column):
    """SQL for a timestamp column as Unix seconds, on either backend."""
    if session.get_bind().dialect.name == "sqlite":
        return (func.julianday(column) - UNIX_EPOCH_JULIAN_DAY) * SECONDS_PER_DAY
    return func.extract("epoch", column)


def series_buckets(session: Session, since: dt.datetime, until: dt.datetime, buckets: int,
                   max_series: int) -> dict[str, list[Bucket]]:
    """Every subject's samples in [since, until) averaged into `buckets` equal time buckets, in the database
    (a week of 10 s rows never leaves it as rows): {subject: [Bucket, ...] oldest first}. Empty buckets are
    absent (a gap). At most `max_series` subjects (alphabetically first)."""
    if buckets < 1 or until <= since:
        raise ValueError("need at least one bucket and until after since")
    width_s = (until - since).total_seconds() / buckets
    t = _epoch_s(session, QualitySample.at)
    since_s = since.timestamp()
    raw = (t - since_s + EDGE_TOLERANCE_S) / width_s  # >= 0 in the window: truncation is the floor on both backends
    index = cast(raw, Integer) if session.get_bind().dialect.name == "sqlite" else cast(func.floor(raw), Integer)
    v = QualitySample.fixed_fraction
    q = (select(QualitySample.subject, index.label("i"), func.avg(t), func.avg(v), func.min(v), func.max(v),
                func.count())
         .where(QualitySample.at >= since, QualitySample.at < until)
         .group_by(QualitySample.subject, "i").order_by(QualitySample.subject, "i"))
    out: dict[str, list[Bucket]] = {}
    for subject, _i, t_mean, mean, low, high, n in session.execute(q):
        if subject not in out and len(out) >= max_series:
            break  # ordered by subject: the rest are later subjects (one pass over the window, no subquery)
        out.setdefault(subject, []).append(Bucket(float(t_mean), float(mean), float(low), float(high), int(n)))
    return out

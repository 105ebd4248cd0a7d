"""The network's figures besides its baselines that go into the quality history at its cadence (decision
0185): the correction age p99, how many trains are fixed (of those reporting), each station's data age."""

from __future__ import annotations

import math

import numpy as np

from augnet.store import series
from augnet.system.live_state import CORRECTION_AGE_P99_EPOCHS  # the same p99 as the live summary shows

FIX_STATE = "fix"  # a train's RTK solution with its integers fixed (RtkSolution.status_name)


def series_values(correction_ages_s, train_states, station_ages_s: dict[str, float | None]) -> dict[str, float]:
    """{subject: value} for one history row each. `correction_ages_s`: the centre's per-epoch correction
    ages, oldest first [s]; `train_states`: each reporting train's fix state name; `station_ages_s`: each
    station's data age [s], None for one not delivering (no row: the chart shows a gap)."""
    out: dict[str, float] = {}
    ages = np.asarray(list(correction_ages_s)[-CORRECTION_AGE_P99_EPOCHS:], float)
    ages = ages[np.isfinite(ages)]
    if ages.size:
        out[series.CORRECTION_AGE_P99] = float(np.percentile(ages, 99))
    states = list(train_states)
    out[series.TRAINS_FIXED] = float(sum(1 for s in states if s == FIX_STATE))
    out[series.TRAINS_REPORTING] = float(len(states))
    for code, age in station_ages_s.items():
        subject = series.station_data_age(code)
        if age is not None and math.isfinite(age) and len(subject) <= series.SUBJECT_MAX_CHARS:
            out[subject] = float(age)
    return out

"""A network baseline's quality as `augnet up` shows and stores it: fixed or float, and how well its fixed
satellites agree (the console's baselines, the terminal view, the quality history)."""

from __future__ import annotations

import numpy as np

# A baseline counts as fixed when at least this fraction of its satellites have their DD integers fixed
# (the console's "fixed" state, the terminal view's green, the status line's count).
FIXED_BASELINE_FRACTION = 0.5


def fixed_residual_rms_m(b) -> float | None:
    """RMS of a baseline epoch's non-dispersive DD residuals over its fixed satellites [m] (None when none
    is fixed). `b` is an `augnet.centre.baseline.BaselineEpoch`."""
    return float(np.sqrt(np.nanmean(b.dd_trop_m[b.fixed] ** 2))) if b.fixed.any() else None


def quality_rows(network) -> list[tuple[str, float, float | None, int]]:
    """(baseline, fixed fraction, fixed residual RMS [m], satellites) per baseline that solved this epoch:
    one row each of the quality history. `network` is the epoch's `NetworkEpoch`."""
    return [(key, float(b.fixed_fraction), fixed_residual_rms_m(b), int(len(b.sats)))
            for key, b in network.baselines.items() if b is not None]

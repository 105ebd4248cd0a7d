"""What the age of corrections does to the RTK measurement model: an aged base observation misses the
satellite clock's (and the atmosphere's) change since it was made, so its single differences carry an
error growing with the age; its variance enters the DD covariance.

A rover at 1 Hz against a base at 30 s (a network station) uses corrections up to 30 s old.  The part
of the error the broadcast clock does not predict is per satellite and the same on every frequency and
on code and phase (a clock), so it enters the DD covariance as D diag(v) D^T over the rows of *every*
slot and kind: the filter cannot average it down with L2 or code.  RTKLIB adds (c * sclkstab * age)^2 to
each SD variance instead (rtkpos.c varerr, prcopt sclkstab = 5e-12 s/s, i.e. 1.5 mm/s), per frequency,
as if independent.
"""

from __future__ import annotations

import numpy as np

# Growth rate of a base observation's unmodelled SD range error with its age [m/s] (RMS over
# satellites): 0.9 mm/s measured on catnet-2010-077 (UPC1 1 Hz, 05:00-06:00, L1 phase residuals against
# the truth, 1-29 s apart, common mode removed; p95 1.9 mm/s); not predictable from the base's own
# previous 30 s (linear extrapolation 31.6 mm RMS at 29 s against 26.4 raw).  Rounded up; RTKLIB's
# default is c * 5e-12 s/s = 1.5 mm/s (docs/decisions/0162-correction-age-and-learned-ionosphere.md).
AGE_RANGE_DRIFT_M_S = 1.0e-3
# Below this age [s] the term is left out (time-tag rounding between receivers, simultaneous epochs).
MIN_AGE_S = 0.5


def sd_variance_m2(age_s: float, n_sats: int) -> np.ndarray:
    """Variance [m^2] of each satellite's SD error from corrections age_s old (the same on every slot)."""
    if not np.isfinite(age_s) or abs(age_s) < MIN_AGE_S:
        return np.zeros(n_sats)
    return np.full(n_sats, (AGE_RANGE_DRIFT_M_S * abs(age_s)) ** 2)


def dd_covariance(k: np.ndarray, ref: np.ndarray, var_sat: np.ndarray) -> np.ndarray:
    """D diag(var_sat) D^T for DD rows k - ref (epoch satellite indices): the covariance [m^2] of a
    per-satellite error common to the rows' slots."""
    same = lambda a, b: (a[:, None] == b[None, :])  # noqa: E731
    return (same(k, k) * var_sat[k][:, None] - same(k, ref) * var_sat[k][:, None]
            - same(ref, k) * var_sat[ref][:, None] + same(ref, ref) * var_sat[ref][:, None])

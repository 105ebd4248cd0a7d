"""Quantiles of the normal and chi-square distributions, for the estimators' consistency tests."""

from __future__ import annotations

import functools
import math


def normal_cdf(x: float) -> float:
    """Phi(x), the standard normal distribution function."""
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def normal_quantile(p: float) -> float:
    """The standard normal quantile: x with Phi(x) = p, by bisection on erf (80 halvings of [-10, 10])."""
    lo, hi = -10.0, 10.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if normal_cdf(mid) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@functools.lru_cache(maxsize=1024)
def chi2_quantile(dof: int, p_false_alarm: float) -> float:
    """Upper quantile of the chi-square distribution with `dof` degrees of freedom, exceeded with
    probability `p_false_alarm` (Wilson-Hilferty approximation, good to ~1%); inf for no dof."""
    if dof <= 0:
        return math.inf
    z = normal_quantile(1.0 - p_false_alarm)
    a = 2.0 / (9.0 * dof)
    return dof * (1.0 - a + z * math.sqrt(a)) ** 3

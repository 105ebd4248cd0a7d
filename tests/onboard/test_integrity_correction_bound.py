"""The onboard PL takes in the centre's correction-error bound (4001): it grows with the bound, equals the
plain PL when none is sent, becomes infinite for a used satellite without a bound, and the axis sigma from
the per-satellite sigmas is the correlation-free (Minkowski) sum."""

from __future__ import annotations

import math

import numpy as np
import pytest

from augnet.onboard.integrity_allocation import (
    IntegrityAllocation,
    axis_availability,
    correction_sigma_on_axis,
)

SIGMA_RX_M = 0.05  # receiver-side 1-sigma on an axis (a fixed RTK, cm level)


def test_pl_grows_with_the_correction_bound_and_is_unchanged_without_one():
    a = IntegrityAllocation()
    plain = a.protection_level(SIGMA_RX_M, "along")
    assert a.protection_level(SIGMA_RX_M, "along", 0.0) == plain
    pls = [a.protection_level(SIGMA_RX_M, "along", c) for c in (0.01, 0.03, 0.1)]
    assert plain < pls[0] < pls[1] < pls[2]
    # fault-free term inflated in quadrature: K * hypot(sigma, correction sigma) at least
    assert pls[2] >= a.k_fault_free * math.hypot(SIGMA_RX_M, 0.1) - 1e-12
    assert math.isinf(a.protection_level(SIGMA_RX_M, "cross", math.nan))
    with pytest.raises(ValueError):
        a.protection_level(SIGMA_RX_M, "along", -0.01)


def test_a_large_correction_bound_makes_the_axis_unavailable():
    ok = axis_availability(0.05, 0.05)
    assert ok.along_available and ok.cross_available
    bad = axis_availability(0.05, 0.05, correction_sigma_along_m=0.5)
    assert not bad.along_available and bad.cross_available and bad.along_pl_m > ok.along_pl_m


def test_axis_sigma_from_satellite_sigmas():
    gain = np.array([[0.5, -0.3, 0.0, 0.2], [0.1, 0.1, -0.4, 0.0]])  # along, cross rows
    sigma = np.array([0.01, 0.02, np.nan, 0.03])  # the third satellite has no bound
    out = correction_sigma_on_axis(gain, sigma)
    assert out[0] == pytest.approx(0.5 * 0.01 + 0.3 * 0.02 + 0.2 * 0.03)
    assert math.isinf(out[1])  # uses the unbounded satellite
    # never below the sigma of any correlation: perfectly correlated errors reach the sum exactly
    rng = np.random.default_rng(4)
    common = rng.standard_normal(200_000)
    errors = common[:, None] * np.array([0.01, 0.02, 0.0, 0.03]) * np.sign(gain[0])
    assert np.std(errors @ gain[0]) <= out[0] * 1.01
    with pytest.raises(ValueError):
        correction_sigma_on_axis(gain, np.array([0.01, -0.02, 0.0, 0.03]))

"""Integrity allocation: K from the hourly risk and the decision rate, fault terms, per-axis decisions."""

import math

import pytest

from augnet.onboard.integrity_allocation import (ALLOCATED_PER_DECISION_RISK, FaultMode, IntegrityAllocation,
                                                 axis_availability, gaussian_k, one_sided_k)


def test_k_matches_the_standard_normal_table():
    # two-sided quantiles from the normal table: 1e-7 -> 5.3267, 1e-9 -> 6.1094; one-sided 1e-6 -> 4.7534
    assert gaussian_k(1e-7) == pytest.approx(5.3267, abs=1e-4)
    assert gaussian_k(1e-9) == pytest.approx(6.1094, abs=1e-4)
    assert one_sided_k(1e-6) == pytest.approx(4.7534, abs=1e-4)


def test_per_decision_risk_and_k_from_the_hourly_budget():
    a = IntegrityAllocation(hourly_risk=1e-9, epoch_interval_s=1.0, correlation_time_s=1.0, fault_free_share=0.5)
    assert a.decisions_per_hour == pytest.approx(3600.0)
    p = 1e-9 * 0.5 / 3600.0  # hand: 1.3889e-13
    assert a.per_decision_risk == pytest.approx(p)
    assert math.erfc(a.k_fault_free / math.sqrt(2.0)) == pytest.approx(p, rel=1e-6)
    assert a.k_fault_free == pytest.approx(7.3974, abs=1e-3)
    assert ALLOCATED_PER_DECISION_RISK == pytest.approx(p)


def test_longer_correlation_time_means_fewer_decisions_and_smaller_k():
    short = IntegrityAllocation(correlation_time_s=1.0)
    long = IntegrityAllocation(correlation_time_s=10.0)
    assert long.decisions_per_hour == pytest.approx(360.0)
    assert long.per_decision_risk == pytest.approx(1e-9 * 0.5 / 360.0)
    assert long.k_fault_free < short.k_fault_free
    # the correlation time never counts more decisions than epochs
    assert IntegrityAllocation(epoch_interval_s=2.0, correlation_time_s=0.5).decisions_per_hour == pytest.approx(1800.0)


def test_fault_term_per_fault_bound_with_prior():
    mode = FaultMode("sat", prior_per_hour=1e-4, bias_along_m=0.5, bias_cross_m=0.2)
    a = IntegrityAllocation(faults=(mode,), fault_free_share=0.5)
    r = 0.5e-9  # hand: the whole fault share to the single mode
    assert a.risk_per_fault_mode == pytest.approx(r)
    k_md = a.k_missed_detection(mode)
    assert 0.5 * math.erfc(k_md / math.sqrt(2.0)) == pytest.approx(r / 1e-4, rel=1e-6)
    sigma = 0.05  # small sigma: the bias term dominates
    assert a.protection_level(sigma, "along") == pytest.approx(0.5 + k_md * sigma)
    assert a.protection_level(sigma, "cross") == pytest.approx(0.2 + k_md * sigma)
    # a mode whose prior is within its share needs no coverage: fault-free term only
    rare = FaultMode("rare", prior_per_hour=1e-10, bias_along_m=5.0, bias_cross_m=5.0)
    b = IntegrityAllocation(faults=(rare,))
    assert b.k_missed_detection(rare) is None
    assert b.protection_level(sigma, "along") == pytest.approx(b.k_fault_free * sigma)
    with pytest.raises(ValueError):
        a.protection_level(sigma, "vertical")


def test_each_axis_against_its_own_alert_limit():
    a = IntegrityAllocation(faults=())  # fault-free only, all of the budget to it
    k = a.k_fault_free
    # along-track poor, cross-track good: mileage unavailable, track discrimination available
    d = axis_availability(2.0 / k, 1.0 / k, a)
    assert d.along_pl_m == pytest.approx(2.0) and d.cross_pl_m == pytest.approx(1.0)
    assert not d.along_available and d.cross_available
    # the 2-D HPL of the same errors (K * sqrt of the larger eigenvalue = 2.0 m) would have failed both
    d = axis_availability(1.0 / k, 2.0 / k, a)
    assert d.along_available and not d.cross_available
    d = axis_availability(math.inf, 0.01, a)
    assert not d.along_available and d.cross_available
    # separate alert limits are honoured
    d = axis_availability(1.0 / k, 1.0 / k, a, along_alert_limit_m=0.9, cross_alert_limit_m=1.1)
    assert not d.along_available and d.cross_available

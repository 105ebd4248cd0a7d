"""Quantiles against tabulated values."""

import math

import pytest

from augnet.gnss.statistics import chi2_quantile, normal_quantile


def test_chi2_quantile_matches_tabulated_values():
    # chi-square 0.999 quantiles (Abramowitz & Stegun Table 26.8): dof 5: 20.52, 10: 29.59
    assert chi2_quantile(5, 1e-3) == pytest.approx(20.52, rel=0.02)
    assert chi2_quantile(10, 1e-3) == pytest.approx(29.59, rel=0.02)
    assert chi2_quantile(0, 1e-3) == math.inf


def test_normal_quantile():
    assert normal_quantile(0.5) == pytest.approx(0.0, abs=1e-12)
    assert normal_quantile(0.975) == pytest.approx(1.959964, abs=1e-6)

"""When the rover models the SD ionosphere, and with what prior."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.onboard import ionosphere_prior as ip


def test_sigma0_is_the_users_then_the_vrs_then_per_km():
    assert ip.iono_sigma0(10_000.0, True, 0.05, 0.02) == 0.05
    assert ip.iono_sigma0(10_000.0, True, None, 0.02) == 0.02
    assert ip.iono_sigma0(10_000.0, False, None, 0.02) == pytest.approx(0.02)  # 2 mm per km


def test_the_ionosphere_enters_the_model_beyond_7_5_km_in_auto():
    assert not ip.estimate_ionosphere("auto", ip.iono_sigma0(7_000.0, False, None, 0.02))
    assert ip.estimate_ionosphere("auto", ip.iono_sigma0(8_000.0, False, None, 0.02))
    assert ip.estimate_ionosphere("estimate", 0.0) and not ip.estimate_ionosphere("off", 1.0)


def test_prior_grows_with_the_slant_and_the_random_walk_with_time():
    m = ip.mapping(np.radians([90.0, 10.0]))
    assert m[0] == pytest.approx(1.0) and m[1] > 2.5
    assert ip.prior_variance(0.02, m[0]) == pytest.approx(0.02**2)
    assert ip.process_variance(0.02, 100.0) == pytest.approx((0.03 * 0.02) ** 2 * 100.0)

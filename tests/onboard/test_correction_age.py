"""The age of corrections in the DD covariance, a 30 s base's arcs, the learned ionosphere prior, and
`augnet rtk --start/--end` (docs/decisions/0162)."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.onboard import correction_age as ca
from augnet.onboard import ionosphere_prior as ip
from augnet.onboard.cycleslip import BASE_MAX_ARC_GAP_S, SlipDetector
from augnet.onboard.inputs import InputError, parse_gpst, time_window
from augnet.onboard.observations import EpochObs, ObsArrays


def test_age_variance_grows_with_the_age_and_is_nil_for_simultaneous_epochs():
    assert np.all(ca.sd_variance_m2(0.0, 3) == 0.0) and np.all(ca.sd_variance_m2(0.3, 3) == 0.0)
    v10, v30 = ca.sd_variance_m2(10.0, 2), ca.sd_variance_m2(30.0, 2)
    assert v10[0] == pytest.approx((ca.AGE_RANGE_DRIFT_M_S * 10.0) ** 2)
    assert v30[0] == pytest.approx(9.0 * v10[0])
    assert np.all(ca.sd_variance_m2(float("nan"), 2) == 0.0)


def test_dd_covariance_is_d_diag_d_transpose_across_slots_and_references():
    # rows: slot 0 sats 1, 2 against 0; slot 1 sats 1, 3 against 2 (another reference)
    k, ref = np.array([1, 2, 1, 3]), np.array([0, 0, 2, 2])
    v = np.array([1.0, 2.0, 3.0, 4.0])
    D = np.zeros((4, 4))
    D[np.arange(4), k] = 1.0
    D[np.arange(4), ref] = -1.0
    A = ca.dd_covariance(k, ref, v)
    np.testing.assert_allclose(A, D @ np.diag(v) @ D.T)
    assert A[0, 2] == pytest.approx(v[1])  # sat 1 in both (another slot, another reference)
    assert A[1, 2] == pytest.approx(-v[2])  # sat 2: row 1's satellite, row 2's reference


def _epoch(t, phase):
    n = len(phase)
    wl = np.tile([0.19029367, 0.24421021], (n, 1))
    return EpochObs(t, np.array([f"G{i:02d}" for i in range(1, n + 1)]), np.full((n, 2), 2.2e7),
                    np.asarray(phase, dtype=float), np.full((n, 2), np.nan), np.full((n, 2), 45.0),
                    np.zeros((n, 2), dtype=int), wl, np.full((n, 2), "1C"))


def test_a_30s_base_keeps_its_arcs_and_a_missed_epoch_breaks_them():
    ph = np.array([[1.0e6, 0.8e6], [2.0e6, 1.6e6]])
    det = SlipDetector(max_gap_s=BASE_MAX_ARC_GAP_S)
    det.detect(_epoch(0.0, ph))
    assert not det.detect(_epoch(30.0, ph)).any()
    assert det.detect(_epoch(90.0, ph)).all()
    # the rover's default (10 s) would have restarted every arc at the 30 s step
    rover = SlipDetector()
    rover.detect(_epoch(0.0, ph))
    assert rover.detect(_epoch(30.0, ph)).all()


def test_gpst_times_and_windows():
    t = parse_gpst("2010-03-18T05:00:00")
    assert parse_gpst("2010/03/18 05:00:30") == pytest.approx(t + 30.0)
    with pytest.raises(InputError):
        parse_gpst("05:00")
    times = t + np.arange(5.0)
    data = ObsArrays(times, ["G01"], {"C1C": np.arange(5.0)[:, None]}, {"L1C": np.zeros((5, 1), int)})
    w = time_window(data, t + 1.0, t + 3.0)
    assert list(w.times - t) == [1.0, 2.0] and list(w.obs["C1C"][:, 0]) == [1.0, 2.0]


def test_the_days_level_from_fixed_satellites():
    lp = ip.LearnedPrior()
    assert not lp.known and lp.sigma0_m(20_000.0) is None  # the per-km prior until satellites are fixed
    lp.learn_fixed(1200.0, np.array([0.004, -0.003, 0.005, 0.002]))  # 4 satellites within half a centimetre
    assert lp.known
    floor = ip.LEARNED_FLOOR_PPM * 1e-6 * 20_000.0
    assert lp.sigma0_m(20_000.0) == pytest.approx(floor)  # 1.2 x the upper bound of a 3.7 mm RMS: under the floor
    assert not ip.estimate_ionosphere("auto", lp.sigma0_m(20_000.0))  # a quiet night: out of the model at 20 km
    lp.learn_fixed(1500.0, np.array([0.03, -0.04, 0.035, 0.02]))  # a livelier day, a full time constant later
    assert lp.sigma0_m(20_000.0) == pytest.approx(1.2 * 0.03211 * ip.rms_upper_bound_factor(4), rel=1e-3)
    assert ip.estimate_ionosphere("auto", lp.sigma0_m(20_000.0))
    few = ip.LearnedPrior()
    few.learn_fixed(0.0, np.array([0.01, 0.01, 0.01]))  # too few satellites
    assert not few.known

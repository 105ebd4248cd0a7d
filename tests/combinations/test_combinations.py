"""Observable combinations cancel what they are meant to cancel; slip tests catch one-cycle slips."""

from __future__ import annotations

import numpy as np

from augnet.gnss import combinations as cb
from augnet.gnss.signals import FREQ_L1_HZ as F1, FREQ_L2_HZ as F2, FREQ_L5_HZ as F5

C = 299_792_458.0


def synth(rho, iono1, N1, N2, f1=F1, f2=F2, clk=0.0, trop=0.0):
    """Ideal dual-frequency observables for geometric range rho and f1 slant ionosphere iono1 [m]."""
    g = (f1 / f2) ** 2
    P1 = rho + clk + trop + iono1
    P2 = rho + clk + trop + g * iono1
    L1 = (rho + clk + trop - iono1) / (C / f1) + N1
    L2 = (rho + clk + trop - g * iono1) / (C / f2) + N2
    return P1, P2, L1, L2


def test_wavelengths():
    np.testing.assert_allclose(cb.widelane_wavelength(F1, F2), 0.8619, atol=1e-4)
    np.testing.assert_allclose(cb.narrowlane_wavelength(F1, F2), 0.1070, atol=1e-4)


def test_combinations_cancel_their_terms():
    rng = np.random.default_rng(0)
    rho = rng.uniform(2.0e7, 2.6e7, 50)
    iono = rng.uniform(1, 15, 50)
    N1 = rng.integers(-1e6, 1e6, 50).astype(float)
    N2 = rng.integers(-1e6, 1e6, 50).astype(float)
    for f2 in (F2, F5):
        P1, P2, L1, L2 = synth(rho, iono, N1, N2, f2=f2, clk=123.4, trop=2.3)
        # Melbourne-Wuebbena: exactly N1 - N2 without noise
        np.testing.assert_allclose(cb.melbourne_wubbena_cycles(L1, L2, P1, P2, F1, f2), N1 - N2, atol=1e-6)
        # ionosphere-free code: geometry + clock + troposphere only
        np.testing.assert_allclose(cb.ionosphere_free(P1, P2, F1, f2), rho + 123.4 + 2.3, atol=1e-6)
        # geometry-free phase gives back the ionosphere once the ambiguity term is known
        amb = N1 * C / F1 - N2 * C / f2
        np.testing.assert_allclose(cb.ionosphere_on_f1_m(L1, L2, F1, f2, amb), iono, atol=1e-6)
        np.testing.assert_allclose(cb.geometry_free_code_m(P1, P2), ((F1 / f2) ** 2 - 1) * iono, atol=1e-6)


def test_geometry_free_slip_test():
    _, _, L1, L2 = synth(2.2e7, 5.0, 100.0, 80.0)
    gf = cb.geometry_free_phase_m(L1, L2, F1, F2)
    _, _, L1s, L2s = synth(2.2e7 + 800.0, 5.005, 101.0, 80.0)  # one L1 cycle, 5 mm of iono change
    _, _, L1n, L2n = synth(2.2e7 + 800.0, 5.005, 100.0, 80.0)
    assert cb.slip_geometry_free(gf, cb.geometry_free_phase_m(L1s, L2s, F1, F2), 1.0)
    assert not cb.slip_geometry_free(gf, cb.geometry_free_phase_m(L1n, L2n, F1, F2), 1.0)


def test_melbourne_wubbena_tracker_detects_a_one_cycle_widelane_slip_in_noise():
    rng = np.random.default_rng(1)
    tr = cb.MelbourneWubbenaTracker(3)
    keys = np.arange(3)
    for _ in range(60):
        slip = tr.update(keys, np.array([5.0, -3.0, 12.0]) + rng.normal(scale=0.15, size=3))
        assert not slip.any()
    np.testing.assert_allclose(tr.mean, [5.0, -3.0, 12.0], atol=0.1)
    slip = tr.update(keys, np.array([5.0, -2.0, 12.0]) + rng.normal(scale=0.15, size=3))
    assert slip.tolist() == [False, True, False]
    assert tr.count[1] == 1 and abs(tr.mean[1] + 2.0) < 0.5  # new arc starts at the new value
    # a flagged loss of lock restarts the arc even without a jump; NaN is ignored
    slip = tr.update(keys, np.array([5.0, np.nan, 12.0]), lli_slip=np.array([True, False, False]))
    assert slip.tolist() == [True, False, False] and tr.count[1] == 1

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


# --- the quiet-ionosphere rate: the rover's 1 Hz GF minus the base's own 30 s arcs (decision 0221) ------------

BASE_GF_NOISE_M = 0.003  # a 30 s base's GF phase noise and multipath per epoch (catnet GARR, decision 0221)
ROVER_GF_NOISE_M = 0.0005  # a 1 Hz rover's GF phase noise per epoch


def _world(dd_rate_m_s: np.ndarray, seed: int = 7):
    """Six satellites: the base's GF a smooth slant trend (the whole ionosphere seen from one place), the rover's
    the same plus its SD ionosphere drifting at dd_rate_m_s [m/s of GF]; base epochs every 30 s from -600 s."""
    rng = np.random.default_rng(seed)
    sats = [f"G{k:02d}" for k in range(1, 7)]
    el = np.radians([80.0, 65.0, 50.0, 40.0, 30.0, 20.0])
    b = rng.uniform(-3e-4, 3e-4, 6)  # slant GF trends [m/s], the base's and the rover's alike
    c = rng.uniform(-2e-7, 2e-7, 6)  # and their curvature [m/s^2]
    truth = lambda t: 5.0 + b * t + c * t * t  # noqa: E731
    base_t = np.arange(-600.0, 61.0, 30.0)
    base_gf = {t: truth(t) + rng.normal(0.0, BASE_GF_NOISE_M, 6) for t in base_t}

    def base_at(t):  # the base interpolated linearly between its epochs (base_interpolation.py)
        t0 = base_t[base_t <= t].max()
        t1 = t0 + 30.0
        return base_gf[t0] + (t - t0) / 30.0 * (base_gf[t1] - base_gf[t0])

    def rover_at(t):
        return truth(t) + dd_rate_m_s * t + rng.normal(0.0, ROVER_GF_NOISE_M, 6)

    return sats, el, base_t, base_gf, base_at, rover_at


def _monitor_after(t_end: float, dd_rate_m_s: np.ndarray, with_base_history: bool = True) -> tuple:
    sats, el, base_t, base_gf, base_at, rover_at = _world(dd_rate_m_s)
    mon = ip.QuietMonitor()
    ok = np.zeros(6, dtype=bool)
    if with_base_history:
        for t in base_t[base_t < 0]:
            mon.base.update(t, sats, base_gf[t], ok)
    for t in np.arange(0.0, t_end + 0.5, 1.0):
        if with_base_history and t in base_gf:
            mon.base.update(t, sats, base_gf[t], ok)
        g_rov = rover_at(t)
        mon.update(t, sats, g_rov - base_at(t), ok, g_rov if with_base_history else None)
    return mon, sats, el


def test_the_base_rate_follows_its_own_30s_arc_and_a_slip_or_gap_restarts_it():
    h = ip.BaseRateHistory()
    sats, ok = ["G01"], np.zeros(1, dtype=bool)
    rng = np.random.default_rng(3)
    for t in np.arange(-600.0, 1.0, 30.0):  # GF 5 m + 1e-4 m/s + 1e-7 m/s^2, 3 mm noise
        h.update(t, sats, np.array([5.0 + 1e-4 * t + 1e-7 * t * t + rng.normal(0.0, BASE_GF_NOISE_M)]), ok)
    # a quadratic over 21 epochs of 3 mm: the derivative at the arc's end to ~5e-6 m/s (against 1.4e-4 m/s from
    # two epochs 30 s apart)
    assert abs(h.rate("G01", 15.0) - (1e-4 + 2e-7 * 15.0)) < 1.5e-5
    assert h.rate("G01", 15.0 + ip.BASE_RATE_MAX_GAP_S + 1.0) is None  # no extrapolation beyond one gap
    h.update(30.0, sats, np.array([5.003]), np.ones(1, dtype=bool))  # a slip: the arc starts again
    assert h.rate("G01", 30.0) is None
    for t in (60.0, 90.0, 120.0, 150.0, 180.0, 210.0, 240.0, 300.0):  # 60 s gap before the last: restarted
        h.update(t, sats, np.array([5.0 + 1e-4 * t]), ok)
    assert h.rate("G01", 300.0) is None


def test_a_quiet_dd_ionosphere_reads_quiet_after_30s_from_the_rover_minus_the_base_history():
    """The interpolated base's 3 mm GF noise makes a 30 s SD slope read ~1e-4 m/s; the base's own 600 s arc
    removes it (decision 0221)."""
    mon, sats, el = _monitor_after(35.0, np.zeros(6))
    rate = mon.rms_rate(35.0, sats, el)
    assert rate is not None and rate < 0.3 * ip.QUIET_SIGMA_M / ip.QUIET_HORIZON_S
    assert mon.quiet(35.0, sats, el)
    sd_only, _, _ = _monitor_after(35.0, np.zeros(6), with_base_history=False)
    assert sd_only.rms_rate(35.0, sats, el) > 3.0 * rate


def test_a_drifting_dd_ionosphere_is_not_quiet():
    """The satellites' SD vertical ionosphere moving 1 cm (L1) a minute, some up, some down: not quiet."""
    _, el, *_ = _world(np.zeros(6))
    signs = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    drift = signs * 0.01 / 60.0 * ip.mapping(el) * (ip.GPS_MU2 - 1.0)  # GF = (mu2 - 1) I1
    mon, sats, el = _monitor_after(35.0, drift)
    assert not mon.quiet(35.0, sats, el)
    assert mon.rms_rate(35.0, sats, el) > ip.QUIET_SIGMA_M / ip.QUIET_HORIZON_S

"""Base observations interpolated to the rover's epoch (post-processing; base_interpolation.py), on noise-free
synthetic observations whose truth at every second is known: what is linear in time is recovered, what is
common to the satellites cancels, a slipped phase is not interpolated across."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.geometry import enu_to_ecef, geodetic_deg_to_ecef
from augnet.onboard.base_interpolation import _geometry_minus_clock, flag_slips, interpolate
from augnet.onboard.observations import LLI_HALF_CYCLE, LLI_SLIP, ObsArrays, epochs
from augnet.onboard.postprocess import process
from augnet.onboard.rtk import RtkOptions, Status
from augnet.onboard.spp import first_code
from tests.onboard.synth import simulate, visible_sats

BASE = geodetic_deg_to_ecef(35.1347, 136.9776, 105.0)
T0 = 1403252400.0
SPAN = 31  # 1 Hz epochs 0..30: base epochs 0 and 30
AT = 12  # the epoch interpolated


@pytest.fixture(scope="module")
def nav(shared_data):
    from augnet.gnss.rinex import read_nav

    return NavigationData(read_nav(shared_data / "rinex/static-1m-2024/base.nav").ephemerides)


@pytest.fixture(scope="module")
def sats(nav):
    return visible_sats(nav, BASE, T0, systems=("G",))


def _base(nav, sats, clock_s, slips=None):
    t = T0 + np.arange(float(SPAN))
    obs, _ = simulate(nav, sats, t, BASE, clock_s=clock_s, code_sigma=0.0, phase_sigma=0.0, slips=slips)
    return epochs(obs, 2, ("G",))


def _dd(a: np.ndarray) -> np.ndarray:
    """Between-satellite differences against the first satellite, per slot (what every receiver clock leaves)."""
    return a[1:] - a[:1]


def test_linear_terms_are_recovered_to_the_millimetre(nav, sats):
    eps = _base(nav, sats, clock_s=1e-4 + 2e-8 * np.arange(SPAN))
    got = interpolate(eps[0], eps[30], eps[AT].time, nav, BASE)
    want = eps[AT]
    wl = want.wavelength_m
    assert np.nanmax(np.abs(got.phase_cyc - want.phase_cyc) * wl) < 2e-3
    assert np.nanmax(np.abs(got.code_m - want.code_m)) < 2e-3
    # without interpolation the base 12 s old is metres off (the range changes by ~100s of m/s)
    held = np.nanmax(np.abs(eps[0].code_m - want.code_m))
    assert held > 100.0
    assert got.info_age_s == pytest.approx(AT, abs=1e-3)


def _residuals(nav, ep):
    """Code and phase [m] minus geometry and satellite clock as the filter computes them (at the epoch's time tag
    and code): what the double differences are made of."""
    g, _ = _geometry_minus_clock(nav, ep.sats, ep.time, first_code(ep), BASE, ep.time)
    return ep.code_m - g[:, None], ep.phase_cyc * ep.wavelength_m - g[:, None]


def test_a_receiver_clock_step_cancels_between_satellites(nav, sats):
    clock = 1e-4 + np.where(np.arange(SPAN) >= 20, 1e-3, 0.0)  # a millisecond step between the base epochs
    eps = _base(nav, sats, clock_s=clock)
    smooth = _base(nav, sats, clock_s=np.full(SPAN, 1e-4))
    got = interpolate(eps[0], eps[30], T0 + AT + 1e-4, nav, BASE)
    (gc, gp), (wc, wp) = _residuals(nav, got), _residuals(nav, smooth[AT])
    assert np.nanmin(np.abs(gc - wc)) > 1e4  # the step's share is there, in every satellite alike
    assert np.nanmax(np.abs(_dd(gp - wp))) < 5e-3
    assert np.nanmax(np.abs(_dd(gc - wc))) < 5e-3


def test_a_phase_slipped_at_the_later_epoch_keeps_its_earlier_residual(nav, sats):
    slipped = sats[2]
    eps = _base(nav, sats, clock_s=np.full(SPAN, 1e-4), slips=[(25, slipped, 0, 7)])
    b0, b1 = eps[0], eps[30]  # the base at 30 s: the slip at 25 s has no flag in these two epochs
    assert not np.any(b1.lli & LLI_SLIP)
    flag_slips([b0, b1])
    k = list(b0.sats).index(slipped)
    # the geometry-free jump names the satellite, not the frequency: both its slots, no other satellite
    assert np.array_equal(np.flatnonzero(np.any(b1.lli & LLI_SLIP, axis=1)), [k])
    got = interpolate(b0, b1, eps[AT].time, nav, BASE)
    want = eps[AT]
    wl = want.wavelength_m
    err = (got.phase_cyc - want.phase_cyc) * wl
    # the slipped slot: not 7 cycles (1.3 m) wrong, only aged (the atmosphere's change over 12 s, mm)
    assert abs(err[k, 0]) < 0.02
    assert np.nanmax(np.abs(np.delete(err, k, axis=0))) < 2e-3


def test_loss_of_lock_flags_are_handed_on_once_the_half_cycle_flag_always(nav, sats):
    eps = _base(nav, sats, clock_s=np.full(SPAN, 1e-4))
    b0 = eps[0]
    b0.lli[:] = 0
    b0.lli[1, 0] = LLI_SLIP
    b0.lli[2, 1] = LLI_HALF_CYCLE
    first = interpolate(b0, eps[30], eps[1].time, nav, BASE, first_after_b0=True)
    later = interpolate(b0, eps[30], eps[2].time, nav, BASE, first_after_b0=False)
    assert first.lli[1, 0] == LLI_SLIP and first.lli[2, 1] == LLI_HALF_CYCLE
    assert later.lli[1, 0] == 0 and later.lli[2, 1] == LLI_HALF_CYCLE


def test_rtk_on_the_interpolated_30s_base_matches_rtk_on_the_1hz_base(nav, sats):
    t = T0 + np.arange(61.0)
    base_clock = 1e-4 + 1e-9 * np.arange(61)
    base, _ = simulate(nav, sats, t, BASE, clock_s=base_clock, seed=11, code_sigma=0.0, phase_sigma=0.0)
    rover_pos = BASE + enu_to_ecef(np.array([1500.0, -800.0, 5.0]), BASE)
    rover, _ = simulate(nav, sats, t, rover_pos, clock_s=-2e-4 + 3e-9 * np.arange(61), seed=12)
    every30 = np.arange(0, 61, 30)
    slow = ObsArrays(base.times[every30], base.sats, {k: v[every30] for k, v in base.obs.items()},
                     {k: v[every30] for k, v in base.lli.items()}, base.approx_position_m)
    opt = RtkOptions(systems=("G",), max_age_s=30.0)
    fast = list(process(rover, base, nav, BASE, opt))
    interp = list(process(rover, slow, nav, BASE, opt, interpolate_base=True))
    aged = list(process(rover, slow, nav, BASE, opt))
    fixed = [i for i, s in enumerate(fast) if s.status == Status.FIX]
    assert len(fixed) > 50
    assert all(interp[i].status == Status.FIX for i in fixed)
    d_interp = max(np.linalg.norm(interp[i].position_m - fast[i].position_m) for i in fixed)
    d_aged = max(np.linalg.norm(aged[i].position_m - fast[i].position_m) for i in fixed
                 if aged[i].status == Status.FIX)
    assert d_interp < 2e-3
    assert d_interp < d_aged
    assert max(s.age_s for s in interp) <= 15.0 + 1e-6

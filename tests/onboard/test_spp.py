"""Single point positioning on synthetic observations (truth known) and with bad input."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.geometry import geodetic_deg_to_ecef
from augnet.onboard.observations import epochs
from augnet.onboard.spp import SppOptions, solve_spp
from tests.onboard.synth import simulate, visible_sats

# A point near the static-1m-2024 site, at the time of its navigation file.
SITE = geodetic_deg_to_ecef(35.1347, 136.9776, 105.0)
T0 = 1403252400.0  # 2024-06-24 08:20 GPST


@pytest.fixture(scope="module")
def nav(shared_data):
    from augnet.gnss.rinex import read_nav

    return NavigationData(read_nav(shared_data / "rinex/static-1m-2024/base.nav").ephemerides)


def _epochs(nav, seed=1, **kw):
    sats = visible_sats(nav, SITE, T0)
    data, truth = simulate(nav, sats, T0 + np.arange(3.0), SITE, clock_s=np.full(3, 3.2e-4), seed=seed, **kw)
    return epochs(data), truth


def test_spp_recovers_position_and_clock_to_code_noise_level(nav):
    eps, truth = _epochs(nav)
    r = solve_spp(eps[0], nav)
    assert r.ok, r.message
    err = np.linalg.norm(r.position_m - SITE)
    assert err < 3.0  # 0.3 m code noise, PDOP ~ 2, Klobuchar and Saastamoinen modelled exactly
    assert set(r.clocks_m) == {"G", "E"}
    assert r.clocks_m["G"] == pytest.approx(3.2e-4 * 299792458.0, abs=5.0)
    assert not r.excluded


def test_raim_excludes_a_satellite_with_a_100_m_blunder(nav):
    eps, _ = _epochs(nav, seed=2)
    e = eps[0]
    bad = 3
    e.code_m[bad, 0] += 100.0
    r = solve_spp(e, nav)
    assert r.ok
    assert r.excluded == [str(e.sats[bad])]
    assert np.linalg.norm(r.position_m - SITE) < 3.0
    r_off = solve_spp(e, nav, SppOptions(raim=False))
    assert np.linalg.norm(r_off.position_m - SITE) > np.linalg.norm(r.position_m - SITE)


def test_too_few_satellites_and_garbage_give_a_status_not_an_exception(nav):
    eps, _ = _epochs(nav)
    few = eps[0].take(np.arange(3))
    r = solve_spp(few, nav)
    assert not r.ok and "too few" in r.message
    junk = eps[0]
    junk.code_m[:] = np.nan
    r = solve_spp(junk, nav)
    assert not r.ok
    eps2, _ = _epochs(nav)
    e = eps2[0]
    e.code_m[:, 0] = 1e12  # absurd ranges are not used: the second frequency's code takes over
    r = solve_spp(e, nav)
    assert r.ok and np.linalg.norm(r.position_m - SITE) < 3.0
    e.code_m[:] = -5.0
    assert not solve_spp(e, nav).ok
    empty = eps2[1].take(np.zeros(0, dtype=int))
    assert not solve_spp(empty, nav).ok

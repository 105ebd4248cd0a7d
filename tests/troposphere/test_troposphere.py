import numpy as np

from augnet.gnss import troposphere as tr


def test_zenith_delays_match_the_standard_atmosphere():
    zhd, zwd = tr.zenith_delays_m(np.radians(45.0), 0.0)
    # Saastamoinen with 1013.25 hPa at 45 deg: 2.2768e-3 * 1013.25 / (1 - 0.00266 cos 90deg) = 2.307 m
    np.testing.assert_allclose(zhd, 0.0022768 * 1013.25, rtol=1e-3)
    assert 0.05 < zwd < 0.2
    zhd_high, zwd_high = tr.zenith_delays_m(np.radians(45.0), 2000.0)
    assert zhd_high < 0.8 * zhd and zwd_high < zwd  # less air above a mountain station


def test_niell_mapping_is_one_at_zenith_and_about_csc_at_mid_elevation():
    el = np.radians([90.0, 30.0, 10.0, 5.0])
    mh, mw = tr.niell(el, np.radians(45.0), 0.0, 100)
    np.testing.assert_allclose(mh[0], 1.0, atol=1e-6)
    np.testing.assert_allclose(mw[0], 1.0, atol=1e-6)
    np.testing.assert_allclose(mh[1], 1.0 / np.sin(el[1]), rtol=0.01)
    assert 5.0 < mh[2] < 1.0 / np.sin(el[2]) and 9.0 < mh[3] < 11.5  # flattened near the horizon


def test_slant_delay_broadcasts_over_satellites_and_stations():
    el = np.radians(np.linspace(10, 90, 12))
    lat = np.radians([[30.0], [40.0]])
    d = tr.slant_delay_m(el, lat, np.array([[10.0], [500.0]]), 200)
    assert d.shape == (2, 12) and np.all(np.diff(d, axis=1) < 0)

"""The VRS geometry for many points (one orbit evaluation, carried by velocity) equals a full transit per
point."""

import numpy as np

from augnet.centre.vrs import geometry_many
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData, transit
from augnet.gnss.geometry import geodetic_deg_to_ecef
from augnet.gnss.rinex import read_nav


def test_carried_geometry_equals_full_transit_per_point(shared_data):
    nav = NavigationData(read_nav(shared_data / "nav" / "brdm-2023-07-11.nav"))
    t = float(nav.table.toe_gpst[0]) + 600.0
    sats = [s for s in nav.satellites if s[0] in "GEC"]
    # points up to ~250 km apart (a network's extent), with a receiver clock offset
    pts = geodetic_deg_to_ecef(np.array([35.0, 35.5, 36.8, 34.9]), np.array([139.0, 139.8, 138.5, 140.9]),
                               np.array([50.0, 80.0, 20.0, 400.0]))
    g, trop, el = geometry_many(sats, t, 1e-4, pts, nav)
    for i, p in enumerate(pts):
        tr = transit(nav, sats, p, t - 1e-4)
        ref = tr.range_m - SPEED_OF_LIGHT_M_S * tr.sat_clock_bias_s
        ok = np.isfinite(ref)
        assert ok.sum() > 20
        np.testing.assert_allclose(g[i][ok], ref[ok], atol=1e-4)  # 0.1 mm
    assert np.all((trop[np.isfinite(el) & (el > np.radians(5))] > 2.0))


def test_each_point_at_its_own_receiver_clock(shared_data):
    """VRS take their master's clock: points in one call may have receive times milliseconds apart."""
    nav = NavigationData(read_nav(shared_data / "nav" / "brdm-2023-07-11.nav"))
    t = float(nav.table.toe_gpst[0]) + 900.0
    sats = [s for s in nav.satellites if s[0] in "GEC"]
    pts = geodetic_deg_to_ecef(np.array([35.0, 35.5, 36.0]), np.array([139.0, 139.8, 138.5]),
                               np.array([50.0, 80.0, 20.0]))
    clocks = np.array([-4e-4, 2e-7, 6e-4])  # receiver clocks steered only to the millisecond
    g, _, _ = geometry_many(sats, t, clocks, pts, nav)
    for i, p in enumerate(pts):
        tr = transit(nav, sats, p, t - clocks[i])
        ref = tr.range_m - SPEED_OF_LIGHT_M_S * tr.sat_clock_bias_s
        ok = np.isfinite(ref)
        np.testing.assert_allclose(g[i][ok], ref[ok], atol=1e-4)

"""The network's geometry of all stations in one evaluation equals one `satellite_geometry` call per station, bit
for bit (issue 17: the centre's epoch shares the orbit evaluation; its results must not change)."""

import numpy as np

from augnet.centre.satellite_geometry import GeometryRequest, satellite_geometry, station_geometries
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData, transit
from augnet.gnss.geometry import geodetic_deg_to_ecef
from augnet.gnss.rinex import read_nav


def test_all_stations_at_once_equal_one_call_each(shared_data):
    nav = NavigationData(read_nav(shared_data / "nav" / "brdm-2023-07-11.nav"))
    t = float(nav.table.toe_gpst[0]) + 700.0
    sats = np.array([s for s in nav.satellites if s[0] in "GEC"])
    rng = np.random.default_rng(3)
    pts = geodetic_deg_to_ecef(np.array([35.0, 35.4, 36.1, 34.8, 35.2]), np.array([139.0, 139.6, 138.7, 140.2, 139.1]),
                               np.array([40.0, 90.0, 15.0, 300.0, 60.0]))
    requests = []
    for i, p in enumerate(pts):
        mine = sats[rng.random(len(sats)) < 0.7]  # each station its own subset of satellites
        clock = (i - 2) * 3e-4  # receiver clocks a fraction of a millisecond apart
        tr = transit(nav, list(mine), p, t - clock)
        code = tr.range_m - SPEED_OF_LIGHT_M_S * tr.sat_clock_bias_s + SPEED_OF_LIGHT_M_S * clock
        code = code + rng.normal(0.0, 2.0, len(mine))
        if i == 3:
            code[:] = np.nan  # no usable code: the clock stays as given
        requests.append(GeometryRequest(mine, t, p, None if i == 4 else code, 1e-5 * i))
    together = station_geometries(requests, nav)
    for r, g in zip(requests, together):
        alone = satellite_geometry(r.sats, r.t_tag_gpst, r.xyz_m, nav, r.code_m, r.clock_s)
        assert g.clock_s == alone.clock_s
        for f in ("sats", "g_m", "elevation_rad", "azimuth_rad", "trop_model_m", "wet_mapping", "valid"):
            np.testing.assert_array_equal(getattr(g, f), getattr(alone, f), err_msg=f)
    assert together[3].clock_s == requests[3].clock_s and together[4].clock_s == requests[4].clock_s
    assert abs(together[0].clock_s - (-6e-4)) < 1e-8  # estimated from the code (2 m noise: a few ns)

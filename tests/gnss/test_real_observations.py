"""Real receivers agree with our orbits and clocks: measured pseudoranges minus our modelled ones.

The receivers' code observations, less our geometric range (Earth rotation included), satellite
clock (relativity included) and group delay, leave the receiver clock (common to all satellites
of a system, removed by the median) plus what we do not model here: ionosphere (a few to ~15 m
on a summer afternoon in Japan) and troposphere (2.4 m at zenith, ~9 m at 15 degrees).  So every
residual must stay within 20 m; an orbit, a clock, a time scale or a BDS GEO frame that is wrong
gives kilometres (GEO), tens of metres (relativity, BDT offset) or more.
"""

from __future__ import annotations

import numpy as np
import pytest

from augnet.gnss.constants import BDS_GEO_PRNS, SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData, group_delay_s, transit
from augnet.gnss.geometry import azimuth_elevation
from augnet.gnss.rinex.nav import read_nav
from augnet.gnss.rinex.obs import read_obs

pytestmark = pytest.mark.shared_data

UNMODELLED_ATMOSPHERE_M = 20.0
ELEVATION_MASK_DEG = 15.0

CASES = [
    ("static-1m-2024/base.nav", "static-1m-2024/base.obs", {"G": "C1C", "E": "C1C", "C": "C2I"}),
    ("rtk-base-rover-yokohama-2021/nav-SEPT2650.21P", "rtk-base-rover-yokohama-2021/base-3034265G.21O",
     {"G": "C1C", "E": "C1X"}),
    # (nl-network-2021's merged nav file holds ephemerides for only 3 of the satellites DELF saw
    # in its first hour, too few to separate the receiver clock.)
]


@pytest.mark.parametrize("nav_name,obs_name,codes", CASES)
def test_pseudorange_residuals_are_atmosphere_sized(shared_data, nav_name, obs_name, codes):
    folder = shared_data / "rinex"
    nav = NavigationData(read_nav(folder / nav_name))
    obs = read_obs(folder / obs_name)
    rx = np.array(obs.header.approx_position_m)
    every = slice(None, None, 20)
    checked = 0
    for system, code in codes.items():
        cols = np.flatnonzero(np.char.startswith(obs.sats, system))
        pr = obs.obs[code][every][:, cols]
        tr = transit(nav, obs.sats[cols], rx, obs.times[every])
        rows = nav.table.take(np.maximum(tr.ephemeris_index, 0))
        gd = group_delay_s(rows, code[1:])
        res = pr - tr.range_m + SPEED_OF_LIGHT_M_S * (tr.sat_clock_bias_s - gd)
        _, el = azimuth_elevation(rx, tr.sat_position_m)
        res = np.where(np.degrees(np.nan_to_num(el, nan=-90.0)) > ELEVATION_MASK_DEG, res, np.nan)
        res -= np.nanmedian(res, axis=1, keepdims=True)  # the receiver clock
        n = np.isfinite(res).sum(axis=1)
        assert n.min() >= 3, f"{obs_name} {system}: too few satellites {n}"
        worst = np.nanmax(np.abs(res))
        assert worst < UNMODELLED_ATMOSPHERE_M, f"{obs_name} {system}: residual {worst:.1f} m"
        checked += int(n.sum())
        if system == "C":
            geo = [j for j, s in enumerate(obs.sats[cols]) if int(s[1:]) in BDS_GEO_PRNS]
            assert np.isfinite(res[:, geo]).any(), "no BDS GEO observed above the mask"
    assert checked > 30

"""Broadcast ephemeris: orbits, velocities, clocks, GEO rotation, selection, group delays, transit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from augnet.gnss import time as gt
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import (
    Ephemeris,
    EphemerisError,
    EphemerisTable,
    NavigationData,
    group_delay_s,
    satellite_state,
    solve_kepler,
    transit,
)
from augnet.gnss.geometry import ecef_to_geodetic, geodetic_deg_to_ecef, geometric_range_m
from augnet.gnss.rinex.nav import read_nav

# IS-GPS-200-style record of G01 on 2023-07-11 (from brdm-2023-07-11.nav), for tests that must
# run without the shared data.
G01 = Ephemeris(
    system="G", prn=1, week=2270, toe=172800.0, toc=172800.0, af0=1.7365859821e-04,
    af1=-1.9326762413e-12, af2=0.0, iode=84, crs=-48.15625, delta_n=3.6930109716e-09,
    m0=0.35633960165, cuc=-2.6542693377e-06, e=0.012934625032, cus=9.1120600700e-06,
    sqrt_a=5153.6449070, cic=-1.5459954739e-07, omega0=1.5185419068, cis=1.7136335373e-07,
    i0=0.98992047457, crc=222.71875, omega=0.98412632858, omega_dot=-7.9039006578e-09,
    idot=-1.7857886710e-10, tgd=4.6566128731e-09, iodc=84, accuracy_m=2.0,
)


@pytest.fixture(scope="module")
def nav2023(shared_data):
    return read_nav(shared_data / "nav" / "brdm-2023-07-11.nav").ephemerides


@pytest.fixture(scope="module")
def nav2024(shared_data):
    return read_nav(shared_data / "rinex" / "static-1m-2024" / "base.nav").ephemerides


@settings(max_examples=200, deadline=None)
@given(st.floats(-50.0, 50.0), st.floats(0.0, 0.95))
def test_kepler_solution_satisfies_the_equation(m, e):
    ecc = solve_kepler(np.array([m]), np.array([e]))
    assert abs(ecc[0] - e * np.sin(ecc[0]) - m) < 1e-11


def test_gps_orbit_radius_clock_and_relativity():
    tb = EphemerisTable.from_list([G01])
    t = G01.toe_gpst + np.linspace(-7200.0, 7200.0, 49)
    st_ = satellite_state(tb, t)
    r = np.linalg.norm(st_.position_m, axis=-1)
    a = G01.sqrt_a**2
    assert np.all(np.abs(r - a) <= a * G01.e + 1000.0)
    # Clock = polynomial + F e sqrt(A) sin E; relativistic term bounded by |F| e sqrt(A) (~30 ns).
    poly = G01.af0 + G01.af1 * (t - G01.toc_gpst)
    assert np.allclose(st_.clock_bias_s - poly, st_.relativistic_s, atol=1e-18)
    bound = 4.442807633e-10 * G01.e * G01.sqrt_a
    assert np.max(np.abs(st_.relativistic_s)) <= bound * (1 + 1e-9)
    assert np.max(np.abs(st_.relativistic_s)) > 0.5 * bound  # it really varies over 4 h


def test_velocity_and_drift_are_the_derivatives(nav2023, nav2024):
    recs = [nav2023[0]] + [e for e in nav2023 if e.system in "EC"][:40] + [e for e in nav2024 if e.system == "C"]
    tb = EphemerisTable.from_list(recs)
    assert tb.is_geo.any() and (~tb.is_geo).any()
    t = tb.toe_gpst + 1234.5
    h = 0.01
    ahead, behind, mid = satellite_state(tb, t, h), satellite_state(tb, t, -h), satellite_state(tb, t)
    fd_vel = (ahead.position_m - behind.position_m) / (2 * h)
    assert np.max(np.abs(fd_vel - mid.velocity_m_s)) < 1e-4
    fd_drift = (ahead.clock_bias_s - behind.clock_bias_s) / (2 * h)
    assert np.max(np.abs(fd_drift - mid.clock_drift_s_s)) < 1e-15


def test_bds_geo_is_geostationary(nav2024):
    """BDS GEOs (C01-C05, C59-C62) hang over the BDS arc (58-160 E) at 35,786 km above the
    equator: only with the D2 -5 degree frame rotation do they land there, stationary to a few
    kilometres over an hour."""
    geo = [e for e in nav2024 if e.is_bds_geo]
    assert len(geo) == 8
    tb = EphemerisTable.from_list(geo)
    t = tb.toe_gpst[:, None] + np.array([-1800.0, 0.0, 1800.0])[None, :]
    pos = satellite_state(tb.take(np.arange(len(geo))[:, None]), t).position_m  # (8, 3 epochs, 3)
    llh = ecef_to_geodetic(pos)
    lon = np.degrees(llh[..., 1])
    assert np.all((lon > 55.0) & (lon < 165.0))
    assert np.all(np.ptp(lon, axis=1) < 0.1)
    assert np.all(np.abs(np.degrees(llh[..., 0])) < 3.0)
    assert np.all(np.abs(llh[..., 2] - 35_786_000.0) < 50_000.0)
    # Treating a GEO as an IGSO/MEO (no rotation) puts it thousands of km away.
    as_meo = EphemerisTable.from_list([e.replace(prn=40) for e in geo])  # C40 is an IGSO/MEO id
    wrong = satellite_state(as_meo, tb.toe_gpst).position_m
    right = satellite_state(tb, tb.toe_gpst).position_m
    assert np.min(np.linalg.norm(wrong - right, axis=-1)) > 1000e3


def test_selection_rules(nav2023, nav2024):
    nav = NavigationData(nav2023)
    t0 = gt.from_calendar(2023, 7, 11, 0, 40)
    idx = nav.select(["G14", "E07", "C06", "G99", "G01"], t0)
    assert idx[3] == -1  # no such satellite
    assert idx[4] == -1  # G01 broadcast health 60 all day: unusable
    assert [nav.table.records[i].sat for i in idx[:3]] == ["G14", "E07", "C06"]
    g14 = nav.table.records[idx[0]]
    assert abs(g14.toe_gpst - t0) <= 7200.0
    # GPS: nearest toe; Galileo: nearest toe strictly before t (age of data > 0).
    g_toes = nav.table.toe_gpst[nav.table.sat == "G14"]
    assert abs(g14.toe_gpst - t0) == np.min(np.abs(g_toes - t0))
    e07 = nav.table.records[idx[1]]
    assert e07.toe_gpst < t0 and t0 - e07.toe_gpst <= 600.0
    # Far from any ephemeris: none.
    assert (nav.select(["G14"], t0 + 10 * 86400.0) == -1).all()
    # Unhealthy sets are skipped unless asked for.
    sick = [e for e in nav2023 if e.health != 0 and e.system == "G"]
    assert sick
    s = sick[0]
    only_sick = NavigationData([s])
    assert only_sick.select([s.sat], s.toe_gpst)[0] == -1
    assert NavigationData([s], allow_unhealthy=True).select([s.sat], s.toe_gpst)[0] == 0
    # Galileo I/NAV vs F/NAV (the 2024 file has both).
    t1 = gt.from_calendar(2024, 6, 24, 8, 22)
    inav = NavigationData(nav2024, galileo_source="inav")
    fnav = NavigationData(nav2024, galileo_source="fnav")
    gal = [s for s in inav.satellites if s[0] == "E"]
    i_idx, f_idx = inav.select(gal, t1), fnav.select(gal, t1)
    i_src = {inav.table.records[i].data_sources for i in i_idx if i >= 0}
    f_src = {fnav.table.records[i].data_sources for i in f_idx if i >= 0}
    assert i_src == {517} and f_src == {258}
    # A Galileo set whose data sources were not recorded (0) is used under either preference.
    unknown = [e.replace(data_sources=0) for e in nav2024 if e.system == "E" and e.data_sources == 258]
    assert NavigationData(unknown, galileo_source="inav").select([unknown[0].sat], t1)[0] >= 0
    # Midway between two GPS toes (2 h apart): the later set wins the tie.
    g14 = sorted((e for e in nav2023 if e.sat == "G14" and e.health == 0), key=lambda e: e.toe_gpst)
    pair = next((a, b) for a, b in zip(g14, g14[1:]) if b.toe_gpst - a.toe_gpst == 7200.0)
    mid = 0.5 * (pair[0].toe_gpst + pair[1].toe_gpst)
    assert nav.table.records[nav.select(["G14"], mid)[0]] == pair[1]
    assert nav.table.records[nav.select(["G14"], mid - 1.0)[0]] == pair[0]
    # Vectorised over epochs: T x N.
    times = t0 + np.arange(0.0, 3600.0, 600.0)
    assert nav.select(["G01", "E07", "C06"], times).shape == (6, 3)


def test_pinned_holds_each_satellite_to_the_set_selected_then(nav2023):
    """`NavigationData.pinned`: across a later toe the original set stays in use (vrs_densify.py), the original
    data are untouched, and a satellite without a set at that time has none."""
    nav = NavigationData(nav2023)
    g14 = sorted((e for e in nav2023 if e.sat == "G14" and e.health == 0), key=lambda e: e.toe_gpst)
    a, b = next((a, b) for a, b in zip(g14, g14[1:]) if b.toe_gpst - a.toe_gpst == 7200.0)
    mid = 0.5 * (a.toe_gpst + b.toe_gpst)
    held = nav.pinned(["G14", "G99"], mid - 1.0)
    assert held.table.records[held.select(["G14"], mid + 10.0)[0]] == a
    assert nav.table.records[nav.select(["G14"], mid + 10.0)[0]] == b
    assert held.select(["G99"], mid)[0] == -1
    ta = transit(held, ["G14"], geodetic_deg_to_ecef(52.0, 4.5, 0.0), mid + 10.0)
    tb = transit(nav, ["G14"], geodetic_deg_to_ecef(52.0, 4.5, 0.0), mid + 10.0)
    assert np.isfinite(ta.range_m).all() and not np.array_equal(ta.range_m, tb.range_m)


def test_group_delays():
    from augnet.gnss.signals import FREQ_E5B_HZ, FREQ_L1_HZ, FREQ_L2_HZ, FREQ_L5_HZ

    e_i = G01.replace(system="E", prn=11, bgd_e5a_e1=-1.0e-9, bgd_e5b_e1=-2.0e-9, data_sources=517, tgd=0.0)
    e_f = e_i.replace(data_sources=258)
    c = G01.replace(system="C", prn=30, tgd=0.0, tgd1=3e-9, tgd2=-4e-9)
    tb = EphemerisTable.from_list([G01, e_i, e_f, c])
    l1 = group_delay_s(tb, "1C")
    assert l1[0] == G01.tgd and l1[1] == -2.0e-9 and l1[2] == -1.0e-9 and np.isnan(l1[3])
    assert np.isclose(group_delay_s(tb, "2W")[0], (FREQ_L1_HZ / FREQ_L2_HZ) ** 2 * G01.tgd)
    g_a, g_b = (FREQ_L1_HZ / FREQ_L5_HZ) ** 2, (FREQ_L1_HZ / FREQ_E5B_HZ) ** 2
    e5a = group_delay_s(tb, "5Q")
    # The ICD cases: E5a with the F/NAV clock, E5b with the I/NAV clock.
    assert np.isnan(e5a[0]) and np.isclose(e5a[2], g_a * -1.0e-9)
    assert np.isclose(group_delay_s(tb, "7Q")[1], g_b * -2.0e-9)
    # The cross cases follow from the same three signal delays: the ionosphere-free combination
    # of each pair, formed with these group delays, must equal that pair's clock (delay 0).
    # The other pair's combination is off by the offset between the two clocks,
    # BGD(E1,E5b) - BGD(E1,E5a) = -1 ns (I/NAV clock) or +1 ns (F/NAV clock).
    bgd_a, bgd_b = -1.0e-9, -2.0e-9
    for row, own_offset in ((1, 0.0), (2, 0.0)):
        d1, d5, d7 = (group_delay_s(tb, code)[row] for code in ("1C", "5Q", "7Q"))
        if_a = (g_a * d1 - d5) / (g_a - 1.0)
        if_b = (g_b * d1 - d7) / (g_b - 1.0)
        if row == 1:  # I/NAV clock = the E1/E5b combination
            assert abs(if_b - own_offset) < 1e-20 and np.isclose(if_a, bgd_b - bgd_a, rtol=0, atol=1e-20)
        else:  # F/NAV clock = the E1/E5a combination
            assert abs(if_a - own_offset) < 1e-20 and np.isclose(if_b, bgd_a - bgd_b, rtol=0, atol=1e-20)
    assert group_delay_s(tb, "2I")[3] == 3e-9
    assert group_delay_s(tb, "7I")[3] == -4e-9
    assert group_delay_s(tb, "6I")[3] == 0.0


def test_unknown_system_and_bad_orbit_rejected():
    with pytest.raises(EphemerisError):
        EphemerisTable.from_list([G01.replace(system="R")])
    with pytest.raises(EphemerisError):
        satellite_state(EphemerisTable.from_list([G01.replace(sqrt_a=0.0)]), G01.toe_gpst)


def test_transit_geometry_many_epochs_and_receivers(nav2023):
    nav = NavigationData(nav2023)
    sats = [s for s in nav.satellites if s[0] in "GEC"]
    t = gt.from_calendar(2023, 7, 11, 6, 7) + np.arange(0.0, 300.0, 30.0)
    rx = geodetic_deg_to_ecef(35.0, 139.0, 10.0)
    tr = transit(nav, sats, rx, t)
    assert tr.range_m.shape == (10, len(sats))
    v = tr.valid
    assert v.sum() > 0.5 * v.size  # the file only holds satellites its receiver tracked
    # Light time is consistent: range = c (t_rx - t_tx).
    assert np.allclose(tr.range_m[v], SPEED_OF_LIGHT_M_S * (t[:, None] - tr.transmit_time_gpst)[v], atol=1e-3)
    # The rotated-frame range equals |sat - rx| + the linearised Sagnac term to a millimetre.
    lin = geometric_range_m(tr.sat_position_m, rx)
    assert np.max(np.abs(lin[v] - tr.range_m[v])) < 2e-3
    # Sagnac matters: tens of metres of difference for some satellites.
    plain = np.linalg.norm(tr.sat_position_m - rx, axis=-1)
    assert np.nanmax(np.abs(plain - tr.range_m)) > 10.0
    # One receiver per epoch (a moving train): same shapes, and a receiver 1 km east changes ranges.
    rxs = np.repeat(rx[None, :], 10, axis=0)
    rxs[:, 1] += 1000.0
    tr2 = transit(nav, sats, rxs, t)
    assert tr2.range_m.shape == (10, len(sats))
    assert np.nanmax(np.abs(tr2.range_m - tr.range_m)) > 100.0
    # Los vectors are unit vectors.
    assert np.allclose(np.linalg.norm(tr.line_of_sight[v], axis=-1), 1.0)


def test_no_ephemeris_gives_nan_not_an_error():
    empty = NavigationData([])
    st_, valid = empty.states(["G01", "E02"], np.array([1.3e9, 1.3e9 + 1.0]))
    assert st_.position_m.shape == (2, 2, 3) and not valid.any() and np.isnan(st_.clock_bias_s).all()
    tr = transit(empty, ["C01"], [6.4e6, 0.0, 0.0], 1.3e9)
    assert tr.range_m.shape == (1,) and np.isnan(tr.range_m).all()
    # A satellite without ephemeris among others: NaN in its column only.
    nav = NavigationData([G01])
    tr = transit(nav, ["G01", "G02"], [6.4e6, 0.0, 0.0], G01.toe_gpst)
    assert np.isfinite(tr.range_m[0]) and np.isnan(tr.range_m[1])

"""The project's own constellation: public slots, broadcast sets that agree with each other and
with what RTCM carries."""

from __future__ import annotations

import io
from collections import Counter

import numpy as np
import pytest
from pyrtcm import RTCMReader

from augnet.gnss import time as gtime
from augnet.gnss.ephemeris import NavigationData, satellite_state
from augnet.gnss.geometry import ecef_to_geodetic
from augnet.gnss.rtcm.codec import encode_frame
from stations.constellation import TOE_INTERVAL_S, broadcast_ephemerides, nominal_orbits
from augnet.gnss.rtcm.ephemeris import SEMICIRCLE_RAD, ephemeris_message, quantise

T0 = gtime.from_calendar(2026, 3, 10, 0)


@pytest.fixture(scope="module")
def nav():
    orbits = nominal_orbits("GEC", T0, seed=3)
    return orbits, NavigationData(broadcast_ephemerides(orbits, T0, T0 + 86400))


def test_slots(nav):
    orbits, _ = nav
    count = Counter(o.system for o in orbits)
    assert count == {"G": 27, "E": 24, "C": 24 + 3 + 5}
    radius = {o.sat: o.a_m for o in orbits}
    assert radius["G01"] == pytest.approx(26_559_700.0)
    assert radius["E01"] - 6_378_137.0 == pytest.approx(23_222_181.0, abs=1e3)
    assert radius["C19"] - 6_378_137.0 == pytest.approx(21_528_000.0)
    inc = {o.sat: np.degrees(o.inc_rad) for o in orbits}
    assert inc["G05"] == 55.0 and inc["E07"] == 56.0 and inc["C30"] == 55.0


def test_geo_and_igso_ground_tracks(nav):
    orbits, nd = nav
    t = T0 + np.arange(0, 86400, 900.0)
    sats = ["C01", "C02", "C03", "C04", "C05", "C38", "C39", "C40"]
    st, ok = nd.states(sats, t)
    assert ok.all()
    llh = ecef_to_geodetic(st.position_m)
    lat, lon = np.degrees(llh[..., 0]), np.degrees(llh[..., 1])
    for k, lon0 in enumerate((140.0, 80.0, 110.5, 160.0, 58.75)):
        assert np.all(np.abs(lat[:, k]) < 0.01) and np.all(np.abs(lon[:, k] - lon0) < 0.05)
    # IGSO: figure-of-eight between +-55 deg latitude centred on 118 E
    for k in range(5, 8):
        assert lat[:, k].max() > 50 and lat[:, k].min() < -50
        assert abs(0.5 * (lon[:, k].max() + lon[:, k].min()) - 118.0) < 2.0


def test_consecutive_sets_agree(nav):
    _, nd = nav
    tab = nd.table
    for sat in ("G07", "E12", "C25", "C03", "C39"):
        idx = np.flatnonzero(tab.sat == sat)[:2]
        t_switch = tab.toe_gpst[idx[1]]
        st = satellite_state(tab.take(idx), np.full(2, t_switch))
        # only the broadcast quantisation separates them: cm in position, < 0.5 ns in clock
        assert np.max(np.abs(st.position_m[0] - st.position_m[1])) < 0.1
        assert abs(st.clock_bias_s[0] - st.clock_bias_s[1]) < 0.5e-9
        step = tab.toe_gpst[idx[1]] - tab.toe_gpst[idx[0]]
        assert step == TOE_INTERVAL_S[sat[0]]


def test_rtcm_ephemeris_carries_the_nav_values(nav):
    _, nd = nav
    recs = nd.table.records
    frames = b"".join(encode_frame(ephemeris_message(e)) for e in recs[:200])
    msgs = [m for _, m in RTCMReader(io.BytesIO(frames))]
    assert len(msgs) == 200
    for e, m in zip(recs[:200], msgs):
        assert quantise(e) == e  # already on the broadcast grid
        if e.system == "G":
            assert m.DF009 == e.prn and m.DF071 == e.iode and m.DF093 == e.toe
            assert m.DF092 == pytest.approx(e.sqrt_a, abs=1e-12)
            assert m.DF088 * SEMICIRCLE_RAD == pytest.approx(e.m0, abs=1e-12)
            assert m.DF084 == pytest.approx(e.af0, abs=1e-15)
        elif e.system == "C":
            assert m.DF488 == e.prn and m.DF505 == e.toe
            assert m.DF507 * SEMICIRCLE_RAD == pytest.approx(e.omega0, abs=1e-12) or \
                abs(abs(e.omega0) - np.pi) < 1e-9
        else:
            assert m.DF252 == e.prn and m.DF290 == e.iode and m.DF304 == e.toe
            assert m.DF303 == pytest.approx(e.sqrt_a, abs=1e-12)

"""Broadcast ephemerides through RTCM 1019 / 1042 / 1046 and back: the same orbit to the broadcast resolution."""

from __future__ import annotations

import numpy as np

from augnet.gnss.ephemeris import NavigationData, satellite_state
from augnet.gnss.rinex import read_nav
from augnet.gnss.rtcm import decode, encode
from augnet.gnss.rtcm.ephemeris import ephemeris_message, message_ephemeris, quantise


def test_real_ephemerides_round_trip_through_rtcm(shared_data):
    ephs = [e for e in read_nav(shared_data / "nav" / "brdm-2023-07-11.nav") if e.system in "GEC"]
    picked = {}
    for e in ephs:  # one set per satellite, Galileo I/NAV (1046 carries I/NAV)
        if e.system == "E" and not (e.data_sources & 1):
            continue
        picked.setdefault(e.sat, e)
    assert {s[0] for s in picked} == {"G", "E", "C"}
    for e in picked.values():
        q = quantise(e)
        back = message_ephemeris(decode(encode(ephemeris_message(q))), q.toe_gpst)
        assert (back.system, back.prn, back.week, back.iode) == (q.system, q.prn, q.week, q.iode)
        t = q.toe_gpst + np.array([-3600.0, 0.0, 1800.0])
        a = satellite_state(NavigationData([q], galileo_source="any").table, t[:, None])
        b = satellite_state(NavigationData([back], galileo_source="any").table, t[:, None])
        np.testing.assert_allclose(a.position_m, b.position_m, atol=1e-4)
        np.testing.assert_allclose(a.clock_bias_s, b.clock_bias_s, atol=1e-15)


def test_truncated_weeks_resolve_against_the_reference_time(shared_data):
    e = next(x for x in read_nav(shared_data / "nav" / "brdm-2023-07-11.nav") if x.system == "G")
    msg = decode(encode(ephemeris_message(quantise(e))))
    assert msg.fields["DF076"] == e.week % 1024
    for offset_days in (-3.0, 0.0, 3.0):  # a reference a few days off still finds the right week
        assert message_ephemeris(msg, e.toe_gpst + offset_days * 86400).week == e.week

"""What `augnet up` shows and stores of a network epoch, a train's solution and an alarm, from fixed inputs:
the console's rows, the quality history's rows, an alarm raised once until cleared."""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest

from augnet.console.live import LiveState, StationLive
from augnet.gnss import time as gtime
from augnet.gnss.geometry import geodetic_deg_to_ecef
from augnet.system.baseline_quality import quality_rows
from augnet.system.live_state import LivePublisher
from augnet.system.persistence import AlarmRecorder


def _epoch(age_s: float = 1.0):
    xyz = np.array([geodetic_deg_to_ecef(39.0, 116.0 + 0.1 * k, 20.0) for k in range(3)])
    fixed = NS(fixed_fraction=0.75, fixed=np.array([True, True, False]), dd_trop_m=np.array([0.01, -0.01, np.nan]),
               sats=np.array(["G01", "G02", "G03"]))
    ne = NS(present=["A", "B"], stations=["A", "B", "C"], station_xyz_m=xyz, sats=np.array(["G01", "G02", "G03"]),
            baselines={"A-B": fixed, "B-C": None}, excluded=set(), master="A", misclosures=0)
    return NS(network=ne, t_gpst=gtime.now_gpst() - age_s, sessions=2, vrs_models={})


def _centre():
    return NS(excluded_stations={"C"}, solve_ms_p99=lambda: 40.0,
              latency_ms_p99=lambda: {"vrs_ready_ms_p99": 1.0, "vrs_sent_ms_p99": 2.0})


def _publisher() -> LivePublisher:
    pub = LivePublisher()
    pub.live = LiveState()
    for k, code in enumerate("ABC"):
        pub.live.update_station(StationLive(id=code, station_id=100 + k, lat_deg=39.0, lon_deg=116.0 + 0.1 * k,
                                            h_m=20.0))
    return pub


def test_a_network_epoch_becomes_the_consoles_stations_baselines_and_figures():
    pub = _publisher()
    r = _epoch()
    pub.record_epoch(r)
    pub.publish_network(r, _centre(), None)
    st = pub.live.stations
    assert st["A"].up and st["A"].satellites == 3 and st["A"].enabled and 0.9 < st["A"].last_data_age_s < 5
    assert not st["C"].up and not st["C"].enabled and st["C"].last_data_age_s is None
    ab, bc = pub.live.baselines
    assert (ab.a, ab.b, ab.state, ab.fixed_fraction, ab.residual_rms_cm) == ("A", "B", "fixed", 0.75, 1.0)
    assert ab.length_km == pytest.approx(8.66, abs=0.01)  # 0.1 deg of longitude at 39 deg N
    assert (bc.state, bc.fixed_fraction, bc.residual_rms_cm) == ("none", 0.0, None)
    net = pub.live.network
    assert (net["master"], net["stations_present"], net["stations"], net["satellites"], net["sessions"]) == ("A", 2, 3, 3, 2)
    assert net["solve_ms_p99"] == 40.0 and net["vrs_sent_ms_p99"] == 2.0 and net["rbc"] is None
    assert pub.last_report is r and 0.9 < net["correction_age_p99_s"] < 5
    assert quality_rows(r.network) == [("A-B", 0.75, pytest.approx(0.01), 3)]


def test_a_trains_solution_is_shown_at_most_twice_a_second():
    pub = _publisher()
    train = NS(id="G101", protection_levels=lambda: (1.5, 2.5), correction_age_s=lambda: 0.4)
    out = NS(solution=NS(position_m=geodetic_deg_to_ecef(39.0, 116.0, 20.0), velocity_m_s=[10.0, 0.0, 0.0],
                         status_name="fix"),
             match=NS(track="L1-1", km=12.345678, cross_m=0.12345))
    pub.publish_train(train, out)
    t = pub.live.trains["G101"]
    assert (t.track_id, t.along_km, t.cross_track_m, t.fix_state) == ("L1-1", 12.3457, 0.123, "fix")
    assert (t.hpl_m, t.vpl_m, t.correction_age_s) == (1.5, 2.5, 0.4) and t.speed_kmh == pytest.approx(36.0)
    assert t.lat_deg == pytest.approx(39.0) and t.lon_deg == pytest.approx(116.0)
    moved = NS(solution=out.solution, match=NS(track="L1-1", km=13.0, cross_m=0.0))
    pub.publish_train(train, moved)
    assert pub.live.trains["G101"].along_km == 12.3457  # within LIVE_PUBLISH_INTERVAL_S: not shown yet


def test_an_alarm_is_stored_once_until_cleared():
    submitted = []
    alarms = AlarmRecorder(NS(submit=submitted.append))
    assert alarms.record("station-down", "STA4", "warning", "silent", cleared=False)
    assert not alarms.record("station-down", "STA4", "warning", "silent", cleared=False)
    assert len(submitted) == 1 and [a["subject"] for a in alarms.log] == ["STA4"]
    assert not alarms.record("station-down", "STA4", "warning", "", cleared=True)
    assert not alarms.record("station-down", "STA4", "warning", "", cleared=True)  # not open: nothing to clear
    assert len(submitted) == 2
    assert alarms.record("station-down", "STA4", "critical", "silent again", cleared=False)
    assert len(submitted) == 3 and len(alarms.log) == 2

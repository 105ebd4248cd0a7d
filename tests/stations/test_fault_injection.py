"""The campaign's fault kinds act on the simulator's side as their schema says (issue 15, decision 0252)."""

import numpy as np
import pytest

from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from stations.odometer import simulate_odometers
from stations.orbit_errors import OrbitClockErrors
from stations.scenario import ScenarioError, parse_scenario
from stations.world import World

LINE = {"waypoints": [{"lat_deg": 39.0, "lon_deg": 116.0, "h_m": 10},
                      {"lat_deg": 39.0, "lon_deg": 116.5, "h_m": 10}]}


def scenario(**extra):
    base = {"name": "faults", "seed": 7, "duration_s": 20, "line": LINE,
            "stations": [{"id": "S1", "lat_deg": 39.01, "lon_deg": 116.1, "h_m": 10},
                         {"id": "S2", "lat_deg": 39.01, "lon_deg": 116.4, "h_m": 10}],
            "trains": [{"id": "T1", "start_km": 5.0, "start_speed_kmh": 200, "speed_kmh": 200}]}
    base.update(extra)
    return parse_scenario(base)


def test_slip_overcounts_and_slide_undercounts():
    n = 200
    t = np.arange(n, dtype=float)
    speed = np.full((1, n), 50.0)
    km = 5.0 + np.cumsum(speed, axis=1) / 1e3
    slip = scenario(faults=[{"kind": "odometer_slip", "train": "T1", "at_s": 50, "until_s": 54, "slip_fraction": 0.3}])
    slide = scenario(faults=[{"kind": "odometer_slide", "train": "T1", "at_s": 50, "until_s": 54,
                              "slide_fraction": 0.3}])
    assert simulate_odometers(slip, t, km, speed).truth.slip_m[0, -1] == pytest.approx(0.3 * 50 * 4, rel=1e-6)
    assert simulate_odometers(slide, t, km, speed).truth.slip_m[0, -1] == pytest.approx(-0.3 * 50 * 4, rel=1e-6)


def test_clock_ramp_grows_then_clears():
    e = OrbitClockErrors(["G01", "G02"], 0.0, 0.0, 1, np.array([43000.0, 43000.0]),
                         clock_ramps=[("G01", 100.0, 160.0, 2e-9)])
    t = np.array([99.0, 100.0, 130.0, 159.0, 160.0])
    assert e.clock_s(np.zeros(5, int), t) == pytest.approx([0, 0, 60e-9, 118e-9, 0], abs=1e-15)
    assert np.all(e.clock_s(np.ones(5, int), t) == 0.0)


def test_wrong_station_coordinates_are_published_not_true():
    off = (0.04, -0.03, 0.06)
    w = World(scenario(faults=[{"kind": "station_coordinates", "station": "S2", "at_s": 0, "offset_enu_m": off}]))
    true = w.receivers[w.receiver_ids.index("S2")].ecef[0]
    llh = ecef_to_geodetic(true)
    d = enu_rotation(llh[0], llh[1]) @ (w.published_position("S2") - true)
    assert d == pytest.approx(off, abs=1e-9)
    assert np.array_equal(w.published_position("S1"), w.receivers[0].ecef[0])


def test_multipath_burst_biases_only_its_receiver_and_window():
    burst = {"kind": "multipath_burst", "receiver": "T1", "at_s": 5, "until_s": 8, "code_m": 4.0, "phase_m": 0.02}
    plain = next(World(scenario(errors={"noise": {"enabled": False}})).epochs(block=20))
    hit = next(World(scenario(errors={"noise": {"enabled": False}}, faults=[burst])).epochs(block=20))
    d = hit.pseudorange_m - plain.pseudorange_m  # (E, R, N, K)
    seen = np.isfinite(d)
    per_epoch = np.nanmax(np.abs(np.where(seen, d, 0.0)), axis=(2, 3))
    assert per_epoch[5:8, 2] == pytest.approx(4.0) and np.all(per_epoch[:5] == 0) and np.all(per_epoch[8:] == 0)
    assert np.all(per_epoch[:, :2] == 0)  # the stations see nothing
    signs = np.sign(d[6, 2][seen[6, 2]])
    assert set(signs.tolist()) == {-1.0, 1.0}  # no common bias a receiver clock would absorb


def test_fault_fields_checked():
    with pytest.raises(ScenarioError, match="ramp_ns_per_s"):
        scenario(faults=[{"kind": "satellite_clock_ramp", "satellite": "G05", "at_s": 1}])
    with pytest.raises(ScenarioError, match="receiver"):
        scenario(faults=[{"kind": "multipath_burst", "receiver": "X9", "at_s": 1, "until_s": 2, "code_m": 1}])
    with pytest.raises(ScenarioError, match="offset_enu_m"):
        scenario(faults=[{"kind": "station_coordinates", "station": "S1", "at_s": 0}])
    with pytest.raises(ScenarioError, match="slip_fraction"):
        scenario(faults=[{"kind": "odometer_slip", "train": "T1", "at_s": 1, "until_s": 2}])

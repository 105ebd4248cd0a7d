"""The simulated odometer: counts follow the truth within its error model; faults and rail act as stated."""

import numpy as np
import pytest

from augnet.onboard.odometer import OdometerModel
from stations.odometer import simulate_odometers
from stations.scenario import ScenarioError, parse_scenario

LINE = {"waypoints": [{"lat_deg": 39.0, "lon_deg": 116.0, "h_m": 10},
                      {"lat_deg": 39.0, "lon_deg": 117.0, "h_m": 10}]}


def scenario(**extra):
    base = {"name": "odo", "seed": 7, "line": LINE,
            "stations": [{"id": "S1", "lat_deg": 39.0, "lon_deg": 116.5, "h_m": 10}],
            "trains": [{"id": "T1", "speed_kmh": 300}, {"id": "T2", "speed_kmh": 160, "wheel_radius_error_pct": 1.0}]}
    base.update(extra)
    return parse_scenario(base)


def motion(n=600, v1=83.0, v2=44.0):
    t = np.arange(n, dtype=float)
    speed = np.vstack([np.full(n, v1), np.full(n, v2)])
    km = 10.0 + np.cumsum(speed, axis=1) / 1e3 - speed[:, :1] / 1e3
    return t, km, speed


def test_counts_follow_truth_within_model():
    sc = scenario()
    t, km, v = motion()
    s = simulate_odometers(sc, t, km, v)
    m = OdometerModel()
    d = s.pulses[0] * m.metres_per_pulse
    err = d - s.truth.distance_m[0]
    # constant speed: no slip; white speed error + quantisation only
    sigma = np.sqrt([m.increment_variance_m2(x, tt) for x, tt in zip(s.truth.distance_m[0], t)])
    assert np.all(np.abs(err) < 5 * sigma)
    assert np.all(s.truth.slip_m[0] == 0.0)
    assert s.pulses.dtype == np.int64 and s.pulses[0, 0] == 0


def test_radius_error_shortens_distance():
    sc = scenario()
    t, km, v = motion()
    s = simulate_odometers(sc, t, km, v)
    m = OdometerModel()
    d = s.pulses[1, -1] * m.metres_per_pulse
    true = s.truth.distance_m[1, -1]
    assert d / true - 1 == pytest.approx(-1 / 101, abs=1e-3)  # wheel 1 % larger: 1 % fewer revolutions


def test_seeded_and_vectorised():
    t, km, v = motion()
    a = simulate_odometers(scenario(), t, km, v)
    b = simulate_odometers(scenario(), t, km, v)
    c = simulate_odometers(scenario(seed=8), t, km, v)
    assert np.array_equal(a.pulses, b.pulses)
    assert not np.array_equal(a.pulses, c.pulses)


def test_wet_rail_slips_more_under_traction():
    n = 400
    t = np.arange(n, dtype=float)
    speed = np.vstack([np.minimum(0.5 * t, 83.0)] * 2)  # accelerating for 166 s
    km = np.cumsum(speed, axis=1) / 1e3
    spread = {}
    for rail in ("dry", "wet"):
        slips = [simulate_odometers(scenario(rail=rail, seed=k), t, km, speed).truth.slip_m[:, -1] for k in range(40)]
        spread[rail] = float(np.std(slips))
    assert spread["wet"] > 1.5 * spread["dry"] > 0


def test_injected_slide_undercounts():
    sc = scenario(faults=[{"kind": "odometer_slide", "at_s": 100, "until_s": 110, "train": "T1",
                           "slide_fraction": 0.5}])
    t, km, v = motion()
    s = simulate_odometers(sc, t, km, v)
    assert s.truth.slip_m[0, -1] == pytest.approx(-0.5 * 83.0 * 10, rel=1e-6)
    assert s.truth.slip_m[1, -1] == 0.0


def test_bad_scenario_fields_refused():
    with pytest.raises(ScenarioError, match="rail"):
        scenario(rail="icy")
    with pytest.raises(ScenarioError, match="train"):
        scenario(faults=[{"kind": "odometer_slide", "at_s": 1, "until_s": 2, "train": "X", "slide_fraction": 1}])
    with pytest.raises(ScenarioError, match="until_s"):
        scenario(faults=[{"kind": "odometer_slide", "at_s": 1, "train": "T1", "slide_fraction": 1}])
    with pytest.raises(ValueError, match="trains, epochs"):
        simulate_odometers(scenario(), np.arange(3.0), np.zeros((1, 3)), np.zeros((1, 3)))

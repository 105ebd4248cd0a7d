"""The runner's pieces on their own: reading the ionosphere out of a VRS, the truth's DD ambiguities, balise
passages, outage runs and acquisitions, protection levels, the latency model, the warm-up world."""

from __future__ import annotations

import math

import numpy as np
import pytest

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.geometry import enu_rotation, geodetic_to_ecef
from augnet.scenario import metrics as M
from augnet.scenario.latency import LatencyModel
from augnet.scenario.runner import DEFAULT_WARM_UP_S, WarmUpWorld, load, vrs_ionosphere_m, warm_up_s_for
from augnet.scenario.truth import TruthIndex, passages


def test_vrs_ionosphere_comes_back_out_of_the_geometry_free_combination():
    """Phases built by the VRS equation (augnet.centre.vrs): master phase + (shift - mu_k dI) / lambda_k,
    with any geometric shift and integer ambiguities: the function returns dI exactly."""
    rng = np.random.default_rng(7)
    S = 12
    f = np.tile([1575.42e6, 1227.60e6], (S, 1))
    f[6:] = [1561.098e6, 1268.52e6]  # BeiDou B1I / B3I
    lam = SPEED_OF_LIGHT_M_S / f
    mu = (f[:, :1] / f) ** 2
    master = rng.normal(2e7, 1e6, (S, 2)) / lam + rng.integers(-1000, 1000, (S, 2))
    shift = rng.normal(0.0, 800.0, S)  # a VRS hundreds of metres from its master ... or 30 km
    d_iono = rng.normal(0.0, 0.2, S)
    vrs = master + (shift[:, None] - mu * d_iono[:, None]) / lam
    np.testing.assert_allclose(vrs_ionosphere_m(vrs, master, f), d_iono, atol=1e-6)


def test_truth_dd_ambiguities_match_the_centre_tests_helper():
    from stations.scenario import load_scenario
    from stations.world import World
    from tests.centre.simdata import truth_dd_ambiguity

    world = World(load_scenario("network-70km").model_copy(update={"duration_s": 2}))
    blk = next(world.epochs())
    idx = TruthIndex(world)
    amb = blk.ambiguity_cyc[1]
    ids = world.receiver_ids
    tracked = [s for j, s in enumerate(world.sats) if np.isfinite(amb[[ids.index("NORTH"), ids.index("EAST")], j, :2]).all()]
    refs = {}
    for s in tracked:
        refs.setdefault(s[0], s)
    sats = np.array(tracked)
    freq = world.freq_hz[[world.sats.index(s) for s in tracked]][:, :2]
    got = idx.dd_ambiguity(amb, "NORTH", "EAST", sats, refs, freq)
    want = np.array([truth_dd_ambiguity(world, blk, 1, ids.index("NORTH"), ids.index("EAST"), s, refs[s[0]])
                     for s in tracked])
    assert len(tracked) > 10
    np.testing.assert_array_equal(got, want)
    assert np.all(got[np.isin(sats, list(refs.values()))] == 0)
    # the same frequencies in the other column order give the columns swapped
    np.testing.assert_array_equal(idx.dd_ambiguity(amb, "NORTH", "EAST", sats, refs, freq[:, ::-1]), want[:, ::-1])


def test_passages_of_marks_forwards_backwards_and_never():
    t = np.arange(6, dtype=float)
    along = np.array([0.0, 10.0, 20.0, 30.0, 40.0, 50.0])
    got = passages(along, t, np.array([15.0, 10.0, 0.0, 55.0, 49.0]))
    np.testing.assert_allclose(got[:2], [1.5, 1.0])
    assert np.isnan(got[2]) and np.isnan(got[3])  # at the start (not passed since) and beyond the end
    assert got[4] == 4.9
    back = passages(along[::-1], t, np.array([15.0]))
    np.testing.assert_allclose(back, [3.5])


def test_runs_and_acquisitions_count_outages_and_refixes():
    assert M.runs(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]
    assert M.runs(np.zeros(3, bool)) == []
    t = np.arange(12, dtype=float)
    sky = np.array([1, 1, 1, 1, 1, 0, 0, 1, 1, 1, 1, 1], bool)
    fixed = np.array([0, 0, 0, 1, 1, 0, 0, 0, 0, 1, 1, 1], bool)
    acq = M.acquisitions(t, fixed, sky, usable_from=1)
    assert [(a["kind"], a["from_s"], a["time_s"]) for a in acq] == [("first", 1.0, 2.0), ("after_outage", 7.0, 2.0)]
    never = M.acquisitions(t, np.zeros(12, bool), sky, usable_from=0)
    assert [a["time_s"] for a in never] == [None, None]
    assert M.acquisitions(t, fixed, sky, usable_from=None) == []


def test_protection_levels_are_k_sigma_in_the_local_frame():
    lat, lon = math.radians(39.5), math.radians(116.7)
    R = enu_rotation(lat, lon)
    est = geodetic_to_ecef(np.array([[lat, lon, 30.0]]))
    cov_enu = np.diag([0.03**2, 0.01**2, 0.05**2])
    cov = (R.T @ cov_enu @ R)[None]
    hpl, vpl = M.protection_levels(est, cov, k=5.0)
    np.testing.assert_allclose([hpl[0], vpl[0]], [0.15, 0.25], rtol=1e-6)  # the larger horizontal axis
    hpl, vpl = M.protection_levels(np.full((1, 3), np.nan), np.full((1, 3, 3), np.nan), k=5.0)
    assert np.isinf(hpl[0]) and np.isinf(vpl[0])


def test_latency_model_is_seeded_and_mostly_under_one_epoch():
    a, b = LatencyModel(3), LatencyModel(3)
    da, db = a.downlink(20_000), b.downlink(20_000)
    np.testing.assert_array_equal(da, db)
    total = a.uplink_s + a.processing_s + da
    assert np.median(total) < 0.6
    assert 0.001 < np.mean(total > 1.0) < 0.05  # a few late epochs: the correction age is then 2 s
    assert not np.array_equal(LatencyModel(4).downlink(10), LatencyModel(3).downlink(10))


def test_a_base_epoch_reused_by_a_low_latency_rover_is_not_a_slip():
    """The runner's rover solves epoch t with the newest VRS epoch received; when one arrives late it reuses
    the previous one (age 2 s), and the base's slip detector sees the same epoch twice: nothing slipped."""
    from augnet.onboard.cycleslip import SlipDetector
    from augnet.scenario.observations import RoverObservations
    from stations.scenario import load_scenario
    from stations.world import World

    world = World(load_scenario("baseline-10km").model_copy(update={"duration_s": 3}))
    blk = next(world.epochs())
    obs = RoverObservations(world)
    det = SlipDetector()
    first, second = obs.epoch(blk, 0, 0), obs.epoch(blk, 1, 0)
    det.detect(first)
    assert not det.detect(second).any()
    assert not det.detect(second).any()  # the same epoch again
    np.testing.assert_array_equal(det.detect(first), np.isfinite(first.phase_cyc))  # back in time: all restart


def test_warm_up_defaults_to_300_s_with_trains_and_none_without():
    from stations.scenario import ScenarioError

    assert warm_up_s_for(load("demo"), None) == DEFAULT_WARM_UP_S == 300.0
    assert warm_up_s_for(load("baseline-10km"), None) == 0.0  # nothing connects: the centre's own cold start
    assert warm_up_s_for(load("demo"), 0) == 0.0
    assert warm_up_s_for(load("demo"), 12.4) == 12.0  # whole epochs
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ScenarioError, match="warm-up"):
            warm_up_s_for(load("demo"), bad)


def test_the_warm_up_world_keeps_the_scenarios_sky_and_trains_and_switches_the_trains_on_at_time_0():
    """The stations observe during the warm-up; from the scenario's start on, the sky (satellite ranges,
    elevations, clocks and orbit errors, atmosphere) and the trains' motion are those of the world begun at the
    start, and the trains' receivers acquire at time 0 (switched off before)."""
    from stations.world import World

    sc = load("demo", 10)
    # the receivers' unannounced gaps are draws of their own stream, which the warm-up starts 30 s earlier: off
    # here, the sky and the trains' acquisition are what is compared (decision 0272)
    sc = sc.model_copy(update={"errors": sc.errors.model_copy(update=dict(data_gaps_per_hour=0.0))})
    warm_s = 30
    cold, warm = World(sc), WarmUpWorld(sc, warm_s)
    assert warm.t0 == cold.t0 - warm_s and warm.start_gpst == cold.t0 and warm.n_epochs == 40
    np.testing.assert_array_equal(warm.t_tags[warm_s:], cold.t_tags)
    blocks = list(warm.epochs(block=10))
    b_cold = next(cold.epochs(block=10))
    b_warm = blocks[3]  # epochs 30-39: the scenario's 0-9
    assert b_warm.epoch_index[0] == warm_s
    for key in ("range_m", "elevation_rad", "rx_ecef", "stec_tecu", "tropo_m", "orbit_error_range_m",
                "sat_clock_error_s"):
        np.testing.assert_array_equal(getattr(b_warm, key), getattr(b_cold, key), err_msg=key)
    trains = [i for i, r in enumerate(warm.receivers) if r.kind == "train"]
    stations = [i for i, r in enumerate(warm.receivers) if r.kind == "station"]
    for i in trains:
        np.testing.assert_array_equal(warm.receivers[i].km[warm_s:], cold.receivers[i].km)
        assert np.all(warm.receivers[i].km[:warm_s] == cold.receivers[i].km[0])  # standing, switched off
    for blk in blocks[:3]:
        assert not blk.observed[:, trains].any() and blk.observed[:, stations].any()
    # the trains acquire at time 0 as in the cold world: new arcs, lock time 0
    np.testing.assert_array_equal(b_warm.observed[:, trains], b_cold.observed[:, trains])
    assert np.all(b_warm.lock_time_s[0, trains][b_warm.observed[0, trains]] == 0.0)
    assert np.all(b_warm.lock_time_s[0, stations][b_warm.observed[0, stations]] > 0.0)  # tracking for 30 s

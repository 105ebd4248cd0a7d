"""The network's single-layer ionosphere model on synthetic baselines: the DD ionosphere of each satellite is the
vertical TEC times the DD of the stations' mapping functions plus a gradient residual of a known level; the fit
must find the TEC within its stated uncertainty, and its predictions must miss by what their sigma says."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.baseline import BaselineEpoch
from augnet.centre.baseline_config import BaselineConfig
from augnet.centre.ionosphere_model import ionosphere_model
from augnet.gnss.ionosphere import IONO_K_M3_S2, thin_shell_mapping

F1_HZ = 1575.42e6
LENGTH_M = 50_000.0
SHELL_KM = 350.0
VTEC_TECU = 18.0
RESIDUAL_PPM = 0.4  # the quiet day's level after the model (network-70km, measured)


def _mapping(el_deg):
    return thin_shell_mapping(np.radians(el_deg), 1e3 * SHELL_KM)


def _baseline(rng, n_sats: int, fixed_share: float, vtec: float) -> tuple[BaselineEpoch, np.ndarray, np.ndarray]:
    """One baseline epoch (the DD ionosphere given where fixed), its true DD ionosphere and the gradient part of
    it: GPS satellites from 15 to 80 degrees, the first (highest) the reference; the stations' elevations differ
    by up to the 0.45 degree a 50 km baseline gives along the satellite's azimuth."""
    el_a = np.sort(rng.uniform(15.0, 80.0, n_sats))[::-1]
    el_b = el_a + rng.uniform(-0.45, 0.45, n_sats)
    ma, mb = _mapping(el_a), _mapping(el_b)
    d = (mb - ma) - (mb[0] - ma[0])
    low = np.maximum(ma, mb)
    tecu_m = IONO_K_M3_S2 / F1_HZ**2
    gradient = RESIDUAL_PPM * 1e-6 * LENGTH_M * np.hypot(low, low[0]) * rng.standard_normal(n_sats)
    dd = d * vtec * tecu_m + gradient
    dd[0] = 0.0
    fixed = rng.uniform(size=n_sats) < fixed_share
    fixed[0] = True
    sats = np.array([f"G{k + 1:02d}" for k in range(n_sats)])
    gradient[0] = 0.0
    epoch = BaselineEpoch(t_gpst=0.0, refs={"G": "G01"}, sats=sats, elevation_a_deg=el_a, elevation_b_deg=el_b,
                          fixed=fixed, dd_n=np.zeros((n_sats, 2)), dd_iono_m=np.where(fixed, dd, np.nan),
                          dd_trop_m=np.zeros(n_sats), freq_hz=np.full((n_sats, 2), F1_HZ),
                          eligible=np.ones(n_sats, bool))
    return epoch, dd, gradient


def _network(rng, fixed_share: float, vtec: float = VTEC_TECU):
    """Four baselines: (results, lengths, truth, gradient part) keyed by baseline."""
    runs = {(0, k): _baseline(rng, 12, fixed_share, vtec) for k in range(4)}
    return ({e: r[0] for e, r in runs.items()}, {e: LENGTH_M for e in runs}, {e: r[1] for e, r in runs.items()},
            {e: r[2] for e, r in runs.items()})


def test_the_fit_finds_the_vertical_tec_within_its_uncertainty():
    rng = np.random.default_rng(5)
    cfg = BaselineConfig()
    z = []
    for _ in range(200):
        results, lengths, _, _ = _network(rng, 0.8)
        model = ionosphere_model(results, lengths, cfg)
        z.append((model.vtec_tecu - VTEC_TECU) / np.sqrt(model.vtec_var_tecu2))
    z = np.abs(np.array(z))
    # the level is the 95 % bound of the residual RMS times 1.2: the uncertainty is stated on the safe side
    assert np.mean(z < 2.0) > 0.95
    assert np.sqrt(np.mean(z**2)) > 0.4  # ... but it is not vacuous


def test_predictions_miss_by_what_their_sigma_says():
    rng = np.random.default_rng(6)
    cfg = BaselineConfig(iono_model_floor_ppm=0.01)  # the data's level, not the floor
    z, miss, truth, gradient = [], [], [], []
    for _ in range(100):
        results, lengths, dd, grad = _network(rng, 0.6)
        model = ionosphere_model(results, lengths, cfg)
        for e, r in results.items():
            mean, var = model.predict(r, LENGTH_M)
            open_ = ~r.fixed
            z.append((dd[e][open_] - mean[open_]) / np.sqrt(var[open_]))
            miss.append(dd[e][open_] - mean[open_])
            truth.append(dd[e][open_])
            gradient.append(grad[e][open_])
    z, miss, truth, gradient = (np.concatenate(v) for v in (z, miss, truth, gradient))
    assert 0.6 < np.sqrt(np.mean(z**2)) <= 1.0
    # what is left is the gradient part, which no model of the vertical TEC can know
    assert np.sqrt(np.mean(miss**2)) < 0.9 * np.sqrt(np.mean(truth**2))
    assert np.sqrt(np.mean(miss**2)) < 1.1 * np.sqrt(np.mean(gradient**2))


def test_the_model_needs_enough_fixed_satellites_and_can_be_switched_off():
    rng = np.random.default_rng(7)
    few = {(0, 1): _baseline(rng, 6, 0.0, VTEC_TECU)[0]}  # only the reference fixed
    assert ionosphere_model(few, {(0, 1): LENGTH_M}, BaselineConfig()) is None
    many, lengths, _, _ = _network(rng, 1.0)
    assert ionosphere_model(many, lengths, BaselineConfig()) is not None
    assert ionosphere_model(many, lengths, BaselineConfig(iono_model_floor_ppm=0.0)) is None


@pytest.mark.parametrize("floor", [0.5, 2.0])
def test_the_level_is_never_below_the_floor(floor):
    rng = np.random.default_rng(8)
    results, lengths, _, _ = _network(rng, 1.0)
    model = ionosphere_model(results, lengths, BaselineConfig(iono_model_floor_ppm=floor))
    assert model.level_ppm >= floor


def test_the_models_prediction_becomes_the_prior_the_state_would_have_started_with():
    """The prior enters the integer decision as a pseudo-observation beside the state's own wide prior (zero mean):
    together they must give the model's mean and variance, and a network hint must then count as independent data."""
    from augnet.centre.baseline_integers import BaselineIntegers
    from augnet.centre.ionosphere_prior import IonospherePrior

    prior = IonospherePrior(BaselineConfig(), LENGTH_M)
    none_fixed = BaselineIntegers()
    sats, rows, ref_k, mapping = np.array(["G01", "G02"]), np.array([1]), np.array([0, 0]), np.array([1.0, 2.5])
    prior._state_prior = {"G01": 0.04, "G02": 0.25}  # the states' own priors [m^2]
    state_var = prior.state_prior_dd("G02", "G01")
    mean, var = 0.08, 0.004  # the model's DD ionosphere [m] and variance [m^2], far tighter than the day's
    out = prior.pseudo_observations(sats, rows, ref_k, mapping, none_fixed, None, {"G02": ("G01", mean, var)})
    ref, z, v = out["G02"]
    assert ref == "G01"
    post_var = 1.0 / (1.0 / state_var + 1.0 / v)
    assert post_var == pytest.approx(var)
    assert post_var * z / v == pytest.approx(mean)
    # a network hint beside it: the posterior is the model's prior updated with the hint
    hint = ("G01", 0.02, 0.002)
    ref, z2, v2 = prior.pseudo_observations(sats, rows, ref_k, mapping, none_fixed, {"G02": hint},
                                           {"G02": ("G01", mean, var)})["G02"]
    post_var = 1.0 / (1.0 / state_var + 1.0 / v2)
    assert post_var == pytest.approx(1.0 / (1.0 / var + 1.0 / hint[2]))
    assert post_var * z2 / v2 == pytest.approx(post_var * (mean / var + hint[1] / hint[2]))
    # a model no tighter than the day's prior is not used: the day's zero-mean prior stays
    loose = prior.pseudo_observations(sats, rows, ref_k, mapping, none_fixed, None, {"G02": ("G01", mean, 0.2)})
    assert loose["G02"][1] == 0.0

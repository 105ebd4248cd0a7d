"""The centre's 4001 bound at the train (decision 0281): the decoder keeps the received sigmas by epoch, a
missing or stale one is unbounded once bounds come, the DD gain carries a satellite's correction error to the
position as the least-squares solution does, and the map match's PLs grow by it (unchanged without one)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from augnet.gnss.rtcm.correction_bound import CorrectionBoundMessage, encode_correction_bound_frame
from augnet.onboard.correction_bound import CorrectionBounds, DDGeometry, dd_position_gain, epoch_key
from augnet.onboard.corrections import CorrectionDecoder
from augnet.onboard.trackmap import gaussian_k
from tests.onboard.test_trackmap_balise_nmea import make_db

T_GPST = 1_420_000_123.0


def _msg(t, sats, sigma):
    return CorrectionBoundMessage(4001, epoch_key(t), 7, list(sats), np.asarray(sigma, float), 1.2)


def test_the_decoder_keeps_4001_bounds_by_epoch_and_a_missing_one_is_unbounded():
    dec = CorrectionDecoder()
    assert dec.bounds.sigmas(T_GPST, ["G01"]) is None  # no 4001 on this stream: PLs as they were
    data = encode_correction_bound_frame(_msg(T_GPST, ["G01", "G02", "E11"], [0.0, 0.012, math.nan]))
    # a client with many satellites gets a second message for the same epoch: merged
    data += encode_correction_bound_frame(_msg(T_GPST, ["C30"], [0.03]))
    assert dec.feed(data, T_GPST) == [] and dec.stats.decode_errors == 0
    assert dec.bounds.receiving and dec.bounds.received == 2
    got = dec.bounds.sigmas(T_GPST, ["G02", "G01", "C30", "E11", "G05"])
    assert got[:3] == pytest.approx([0.0121, 0.0, 0.03], abs=1e-4)  # rounded up to 0.1 mm, never down
    assert got[1] == 0.0 and got[0] >= 0.012 and np.isnan(got[3]) and np.isnan(got[4])
    stale = dec.bounds.sigmas(T_GPST + 1.0, ["G01", "G02"])  # that epoch's 4001 never came
    assert np.all(np.isnan(stale))


def test_bounds_of_old_epochs_are_forgotten():
    b = CorrectionBounds(kept=3)
    for i in range(5):
        b.add(_msg(T_GPST + i, ["G01"], [0.01]))
    assert not b.has_epoch(T_GPST + 1) and b.has_epoch(T_GPST + 2) and b.has_epoch(T_GPST + 4)
    b.reset()
    assert b.sigmas(T_GPST + 4, ["G01"]) is None


def _geometry(rng, n=8):
    az = rng.uniform(0, 2 * np.pi, n)
    el = rng.uniform(np.radians(15), np.radians(85), n)
    los = np.column_stack((np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)))
    ref = int(np.argmax(el))
    k = np.array([i for i in range(n) if i != ref])
    var = (0.003 / np.sin(el)) ** 2
    return DDGeometry([f"G{i + 1:02d}" for i in range(n)], los, k, np.full(len(k), ref), np.zeros(len(k), int),
                      np.zeros(len(k), int), var[:, None], np.ones((n, 1))), ref


def test_the_gain_is_the_least_squares_response_to_each_satellites_correction_error():
    rng = np.random.default_rng(3)
    geo, ref = _geometry(rng)
    G = dd_position_gain(geo)
    assert G.shape == (3, 8)
    # a correction error e (per satellite, DD against the centre's reference) moves the position by G e:
    # compare with re-solving the DD least squares on the perturbed DDs
    e = rng.normal(0, 0.02, 8)
    H = -(geo.los[geo.k] - geo.los[geo.ref])
    R = np.diag(geo.var_sd[geo.k, 0]) + geo.var_sd[ref, 0]
    W = np.linalg.inv(R)
    dx = np.linalg.solve(H.T @ W @ H, H.T @ W @ (e[geo.k] - e[geo.ref]))
    assert G @ e == pytest.approx(dx, abs=1e-12)
    # the same error on every satellite is common to both ends of every DD: no position change
    assert np.abs(G.sum(axis=1)).max() < 1e-9
    # too few rows to place the rover: no gain, so no bound
    geo2 = DDGeometry(geo.sats, geo.los, geo.k[:2], geo.ref[:2], geo.f[:2], geo.group[:2], geo.var_sd, geo.mu)
    assert np.all(np.isnan(dd_position_gain(geo2)))


def test_the_map_match_pl_grows_by_the_bound_and_is_infinite_for_a_used_satellite_without_one():
    db = make_db()
    p = db.position_at("UP", 11.0)
    T, N, U = db.tangent_at("UP", 11.0)
    C = 0.02**2 * np.outer(T, T) + 0.01**2 * np.outer(N, N) + 0.05**2 * np.outer(U, U)
    plain = db.match(p, C, integrity_risk=1e-9, allocation=None)  # the fault-free term: the bound's effect on it
    assert db.match(p, C, integrity_risk=1e-9, correction_gain=None, correction_sigma_m=None, allocation=None) == plain
    geo, _ = _geometry(np.random.default_rng(4))
    G = dd_position_gain(geo)
    sigma = np.full(8, 0.01)
    m = db.match(p, C, integrity_risk=1e-9, correction_gain=G, correction_sigma_m=sigma, allocation=None)
    k = gaussian_k(1e-9)
    corr_a = float(np.sum(np.abs(T @ G) * sigma))
    assert m.correction_along_m == pytest.approx(corr_a, rel=1e-4) and corr_a > 0
    assert m.along_pl_m == pytest.approx(k * math.hypot(0.02, corr_a), rel=1e-4)
    assert m.cross_pl_m == pytest.approx(k * math.hypot(0.01, m.correction_cross_m)) and m.cross_pl_m > plain.cross_pl_m
    sigma[3] = math.nan  # a used satellite without a bound: that correction is unbounded
    bad = db.match(p, C, integrity_risk=1e-9, correction_gain=G, correction_sigma_m=sigma)
    assert math.isinf(bad.along_pl_m) and math.isinf(bad.cross_pl_m) and not bad.confirmed
    # bounds received but no gain to carry them (no RTK rows known): unbounded too
    assert math.isinf(db.match(p, C, 1e-9, correction_gain=None, correction_sigma_m=np.ones(1)).along_pl_m)

"""Interpolation of network residuals: exactness on fields each model represents, degeneracy detection,
missing data, leave-one-out."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.interpolation import (
    MAX_CROSS_LINE_DISTANCE_M,
    MODEL_CODES,
    InterpolationError,
    Model,
    distance_weights,
    interpolate,
    kriging_weights,
    leave_one_out,
    plane_weights,
    select_model,
    spread_ratio,
)

# A 210 km railway with stations every ~70 km, gently curving (a few km off a straight line), and two
# stations 25-30 km off the line.
LINE = np.array([[0.0, 0.0], [70e3, 3e3], [140e3, 4e3], [210e3, 1e3]])
OFF_LINE = np.array([[60e3, 28e3], [150e3, -25e3]])


def test_collinear_railway_is_detected_and_off_line_stations_restore_2d():
    assert spread_ratio(LINE) < 0.1
    assert select_model(LINE) is Model.ALONG_LINE
    assert select_model(np.vstack([LINE, OFF_LINE])) is Model.KRIGING
    assert select_model(LINE[:2]) is Model.ALONG_LINE
    assert select_model(LINE[:1]) is Model.DISTANCE


def test_plane_model_is_exact_for_a_planar_field():
    rng = np.random.default_rng(1)
    sta = np.vstack([LINE, OFF_LINE])
    grad = rng.normal(size=(2, 30)) * 1e-7  # 0.1 ppm-ish gradients per satellite, metres per metre
    V = (sta - sta[0]) @ grad
    rovers = rng.uniform([0, -20e3], [210e3, 20e3], size=(500, 2))
    corr, codes = interpolate(sta, rovers, V, Model.PLANE)
    np.testing.assert_allclose(corr, (rovers - sta[0]) @ grad, atol=1e-12)
    assert np.all(codes == 0)


def test_kriging_is_exact_for_a_planar_field_and_at_every_station():
    """Universal kriging with a linear drift: any plane is reproduced (with its offset), and a rover on a
    station gets that station's residual, whatever the field."""
    rng = np.random.default_rng(11)
    sta = np.vstack([LINE, OFF_LINE])
    grad = rng.normal(size=(2, 30)) * 1e-7
    V = (sta - sta[0]) @ grad
    rovers = rng.uniform([0, -20e3], [210e3, 20e3], size=(300, 2))
    corr, codes = interpolate(sta, rovers, V)
    np.testing.assert_allclose(corr, (rovers - sta[0]) @ grad, atol=1e-10)
    assert np.all(codes == MODEL_CODES[Model.KRIGING])
    W = kriging_weights(sta, sta)
    np.testing.assert_allclose(W, np.eye(len(sta)), atol=1e-8)
    rough = rng.normal(scale=0.05, size=(len(sta), 5))
    rough[0] = 0.0
    np.testing.assert_allclose(interpolate(sta, sta, rough)[0], rough, atol=1e-8)


def test_kriging_weighs_the_corners_of_a_square_equally_at_its_centre():
    """In the middle of a network the stations count alike (the plane through the master alone gives the
    master and its opposite station twice the weight of the other two)."""
    square = np.array([[0.0, 0.0], [35e3, -35e3], [0.0, -70e3], [-35e3, -35e3]])
    centre = np.array([[0.0, -35e3]])
    np.testing.assert_allclose(kriging_weights(square, centre), [[0.25] * 4], atol=1e-9)
    np.testing.assert_allclose(plane_weights(square, centre), [[0.0, 1 / 6, 1 / 3, 1 / 6]], atol=1e-9)


def test_along_line_gives_no_correction_far_across_the_line():
    """Two stations only (a satellite fixed on one baseline): the model knows nothing across their line."""
    sta = np.array([[0.0, 0.0], [50e3, 0.0]])
    V = np.array([[0.0], [0.03]])
    near = np.array([[25e3, 0.5 * MAX_CROSS_LINE_DISTANCE_M]])
    far = np.array([[25e3, 2.0 * MAX_CROSS_LINE_DISTANCE_M]])
    c_near, code = interpolate(sta, near, V)
    c_far, code_far = interpolate(sta, far, V)
    assert abs(c_near[0, 0] - 0.015) < 1e-12 and code[0] == MODEL_CODES[Model.ALONG_LINE]
    assert np.isnan(c_far[0, 0]) and code_far[0] == MODEL_CODES[Model.ALONG_LINE]


def test_plane_model_refuses_collinear_stations():
    with pytest.raises(InterpolationError):
        plane_weights(np.array([[0, 0], [1e3, 0], [2e3, 0]], float), np.zeros((1, 2)))


def test_along_line_model_is_exact_at_stations_and_linear_between():
    rng = np.random.default_rng(2)
    V = rng.normal(scale=0.05, size=(4, 12))
    V[0] = 0.0
    corr, codes = interpolate(LINE, LINE, V)
    assert np.all(codes == 1)
    np.testing.assert_allclose(corr, V, atol=1e-12)
    mid = 0.5 * (LINE[1] + LINE[2])
    corr_mid, _ = interpolate(LINE, mid, V)
    np.testing.assert_allclose(corr_mid[0], 0.5 * (V[1] + V[2]), atol=1e-9)


def _rms(errs):
    return float(np.sqrt(np.mean(np.square(errs))))


def test_along_line_follows_a_nonlinear_trend_that_a_single_plane_cannot():
    """Over 210 km the ionosphere is not one plane; the piecewise model follows it between stations."""
    rng = np.random.default_rng(3)
    truth_at = lambda p: 0.05 * np.sin(2 * np.pi * p[..., 0] / 300e3)  # noqa: E731  5 cm, 300 km wave
    rovers = np.column_stack([np.linspace(5e3, 205e3, 50), np.linspace(0, 3e3, 50)])
    errs = {Model.PLANE: [], Model.ALONG_LINE: []}
    for _ in range(20):
        V = (truth_at(LINE) - truth_at(LINE[0]) + rng.normal(scale=0.003, size=4))[:, None]
        V[0] = 0.0
        for model in errs:
            corr, _ = interpolate(LINE, rovers, V, model)
            errs[model].append(corr[:, 0] - (truth_at(rovers) - truth_at(LINE[0])))
    rms = {m: _rms(e) for m, e in errs.items()}
    assert rms[Model.ALONG_LINE] < 0.5 * rms[Model.PLANE], rms


def test_plane_on_nearly_collinear_stations_amplifies_noise_off_the_line():
    """200 m of cross-line spread: 3 mm of station noise becomes centimetres 3 km off the line."""
    rng = np.random.default_rng(5)
    sta = np.array([[0.0, 0.0], [70e3, 200.0], [140e3, -100.0], [210e3, 50.0]])
    assert select_model(sta) is Model.ALONG_LINE
    rover = np.array([[100e3, 3e3]])
    errs = {Model.PLANE: [], Model.ALONG_LINE: []}
    for _ in range(200):
        V = rng.normal(scale=0.003, size=(4, 1))
        V[0] = 0.0
        for model in errs:
            corr, _ = interpolate(sta, rover, V, model)
            errs[model].append(corr[0, 0])  # the truth is zero
    rms = {m: _rms(e) for m, e in errs.items()}
    assert rms[Model.PLANE] > 0.02 and rms[Model.ALONG_LINE] < 0.005, rms


def test_distance_weights_sum_to_one_and_honour_a_station():
    w = distance_weights(LINE, np.array([[35e3, 1e3], LINE[2]]))
    np.testing.assert_allclose(w.sum(axis=1), 1.0)
    np.testing.assert_array_equal(w[1], np.eye(4)[2])


def test_missing_residuals_use_the_stations_that_have_them():
    sta = np.vstack([LINE, OFF_LINE])
    grad = np.array([[1e-7], [-2e-7]])
    V = np.repeat((sta - sta[0]) @ grad, 3, axis=1)
    V[4, 1] = np.nan  # one off-line station lacks satellite 1: still 2-D with the other
    V[4:, 2] = np.nan  # both off-line stations lack satellite 2: falls back to the line
    V[0, 0] = np.nan  # the master's own residual is zero by definition, NaN or not
    rover = np.array([[100e3, 2e3]])
    corr, codes = interpolate(sta, rover, V)
    exact = float(((rover - sta[0]) @ grad)[0, 0])
    np.testing.assert_allclose(corr[0, :2], exact, atol=1e-12)
    assert list(codes) == [MODEL_CODES[Model.KRIGING]] * 2 + [MODEL_CODES[Model.ALONG_LINE]]
    assert abs(corr[0, 2] - exact) < 0.01


def test_leave_one_out_is_zero_on_a_planar_field_and_reports_curvature():
    sta = np.vstack([LINE, OFF_LINE])
    V = (sta - sta[0]) @ np.array([[1e-7], [3e-7]])
    err = leave_one_out(sta, V, Model.PLANE)
    assert np.isnan(err[0]).all()
    np.testing.assert_allclose(err[1:], 0.0, atol=1e-12)
    curved = V + 1e-12 * ((sta - sta[0]) ** 2).sum(axis=1, keepdims=True)
    assert np.nanmax(np.abs(leave_one_out(sta, curved, Model.PLANE))) > 1e-3


def test_many_rovers_and_satellites_in_one_product():
    rng = np.random.default_rng(4)
    sta = np.vstack([LINE, OFF_LINE])
    V = rng.normal(scale=0.02, size=(6, 40))
    V[0] = 0
    rovers = np.column_stack([rng.uniform(0, 210e3, 2000), rng.uniform(-2e3, 5e3, 2000)])
    corr, codes = interpolate(sta, rovers, V)
    assert corr.shape == (2000, 40) and np.isfinite(corr).all()

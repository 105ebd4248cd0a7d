"""The centre's correction error bound on a simulated railway network: it holds the true interpolation error
(known here because the field is ours, never given to the estimator) without being loose, follows the
ionosphere level, grows with the distance from the stations, and needs its station-noise term."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.correction_bound import (
    MIN_GEOMETRY_DISTANCE_M,
    CorrectionBound,
    CorrectionBoundError,
    nearest_station_distance,
)
from augnet.centre.interpolation import interpolate

# A 210 km railway, stations every ~70 km plus two off the line (as tests/centre/test_interpolation.py).
STATIONS = np.array([[0.0, 0.0], [70e3, 3e3], [140e3, 4e3], [210e3, 1e3], [60e3, 28e3], [150e3, -25e3]])
NSAT = 16
SATS = [f"G{i:02d}" for i in range(1, NSAT + 1)]
NOISE_M = 0.003  # white noise of a fixed DD residual [m]
WARM_UP_EPOCHS = 60  # one window before the bound is judged


def _field(rng):
    """A residual field per satellite: a gradient (2 ppm rms, the quiet day) and a travelling wave of ~200 km
    (a medium-scale disturbance) moving at 100 m/s; returns f(points, t) -> (points x satellites) [m]."""
    grad = rng.normal(size=(2, NSAT)) * 2e-6
    amp = 0.03 * rng.uniform(0.3, 1.0, NSAT)
    k = 2 * np.pi / 200e3 * rng.uniform(0.7, 1.3, NSAT)
    phase = rng.uniform(0, 2 * np.pi, NSAT)

    def f(p, t):
        x, y = p[:, :1], p[:, 1:]
        return x * grad[0] + y * grad[1] + amp * np.sin(k * (x - 100.0 * t) + phase)
    return f


def _run(estimator_factory=CorrectionBound, epochs=200, trains=40, seed=3, storm_from=None):
    """(true |error|, bound) per evaluated epoch, train and satellite of a simulated run."""
    rng = np.random.default_rng(seed)
    f = _field(rng)
    cb = estimator_factory()
    errs, bounds = [], []
    for t in range(epochs):
        scale = 3.0 if storm_from is not None and t >= storm_from else 1.0  # the ionosphere level triples
        truth = scale * (f(STATIONS, t) - f(STATIONS[:1], t))
        v = truth + rng.normal(size=truth.shape) * NOISE_M
        v[0] = 0.0
        level = 2.0 * scale  # what the network's own level estimate would say [ppm]
        cb.update(STATIONS, v, SATS, ionosphere_level_ppm=level)
        if t < WARM_UP_EPOCHS:
            continue
        pts = np.column_stack([rng.uniform(0, 210e3, trains), rng.uniform(-5e3, 8e3, trains)])
        corr, _ = interpolate(STATIONS, pts, v)
        errs.append(np.abs(corr - scale * (f(pts, t) - f(STATIONS[:1], t))))
        bounds.append(cb.bound(STATIONS, pts, SATS, ionosphere_level_ppm=level))
    return np.array(errs), np.array(bounds)


def _looseness(err, bound):
    """Per epoch: median bound over the error's 99.9th percentile (all trains and satellites of it)."""
    p999 = np.quantile(err.reshape(len(err), -1), 0.999, axis=1)
    return np.median(bound.reshape(len(bound), -1), axis=1) / p999


def test_bound_holds_the_true_interpolation_error_and_is_not_loose():
    err, bound = _run()
    assert np.all(np.isfinite(bound))
    assert np.mean(err <= bound) >= 0.999
    assert np.max(_looseness(err, bound)) < 10.0


def test_bound_follows_an_ionosphere_storm_through_the_level():
    err, bound = _run(storm_from=120)
    assert np.mean(err <= bound) >= 0.999
    assert np.median(bound[-40:]) > 2.0 * np.median(bound[:40])  # level x3: the field part follows at once


def test_without_the_noise_term_trains_near_stations_are_not_bounded():
    """The station noise does not shrink with distance: dropping its overbound must lose coverage."""
    class FieldOnly(CorrectionBound):
        def noise_sigma(self, sats):
            return np.zeros(len(sats))
    err, bound = _run(FieldOnly)
    assert np.mean(err <= bound) < 0.999


def test_bound_grows_with_the_distance_from_the_stations():
    rng = np.random.default_rng(5)
    f = _field(rng)
    cb = CorrectionBound()
    for t in range(WARM_UP_EPOCHS):
        v = f(STATIONS, t) - f(STATIONS[:1], t) + rng.normal(size=(len(STATIONS), NSAT)) * NOISE_M
        v[0] = 0.0
        cb.update(STATIONS, v, SATS)
    pts = np.array([[70e3, 3e3], [105e3, 3.5e3]])  # on a station, then mid-gap
    assert nearest_station_distance(STATIONS, pts)[0] < MIN_GEOMETRY_DISTANCE_M
    b = cb.bound(STATIONS, pts, SATS)
    assert np.all(b[1] > b[0]) and np.all(b[0] > 0)


def test_bad_input_is_refused():
    cb = CorrectionBound()
    with pytest.raises(CorrectionBoundError):
        cb.update(STATIONS, np.zeros((len(STATIONS), NSAT)), SATS, master=9)
    with pytest.raises(CorrectionBoundError):
        cb.update(STATIONS, np.zeros((len(STATIONS), NSAT)), SATS, ionosphere_level_ppm=float("nan"))


def test_satellites_sent_uncorrected_near_the_master_are_bounded_by_the_fields_gradient():
    """Decision 0281: within 5 km of its master a VRS sends the master's own observations for some satellites;
    their error is the whole field difference to the master, bounded from the stations' residual per metre."""
    from augnet.centre.correction_bound import K_CORRECTION_BOUND

    rng = np.random.default_rng(11)
    f = _field(rng)
    cb = CorrectionBound()
    errs, bounds = [], []
    for t in range(200):
        truth = f(STATIONS, t) - f(STATIONS[:1], t)
        v = truth + rng.normal(size=truth.shape) * NOISE_M
        v[0] = 0.0
        cb.update(STATIONS, v, SATS, ionosphere_level_ppm=2.0)
        if t < WARM_UP_EPOCHS:
            continue
        r = rng.uniform(0, MIN_GEOMETRY_DISTANCE_M, 40)
        a = rng.uniform(0, 2 * np.pi, 40)
        pts = STATIONS[0] + np.column_stack([r * np.cos(a), r * np.sin(a)])
        errs.append(np.abs(f(pts, t) - f(STATIONS[:1], t)))  # the master's own value used: error = the difference
        bounds.append(K_CORRECTION_BOUND * cb.uncorrected_sigma(r, SATS, 2.0))
    err, bound = np.array(errs), np.array(bounds)
    assert np.all(np.isfinite(bound))
    assert np.mean(err <= bound) >= 0.999
    assert np.max(_looseness(err, bound)) < 10.0
    assert np.all(np.isnan(CorrectionBound().uncorrected_sigma([1e3], SATS, 2.0)))  # no window yet: no bound

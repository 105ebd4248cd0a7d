"""Interpolating network corrections (DD residuals relative to a master station) to any point.

Every model here is linear in the station residuals: the correction at a rover is w @ v, where v holds the
residual of each station (the master's is zero by construction: residuals are double differences against
it) and w depends only on geometry. So the weights are computed once per rover and epoch and applied to all
satellites (and all rovers) as one matrix product: corrections = W (rovers x stations) @ V (stations x
satellites).

Models:
- ``kriging`` (the default where the stations span two dimensions): universal kriging with a linear drift,
  i.e. a least-squares plane with an offset over all the surrounding stations (the master included, with its
  zero) plus a smooth correlated part that makes the surface pass through every station. In the middle of a
  network it weighs the stations like Han and Rizos' linear combination model (the minimum-norm weights
  that reproduce any plane: 1/4 each at the centre of a square); next to a station it returns that
  station's own residual, which a single plane does not. On network RTK residuals, Ouassou et al. (Int. J.
  Navig. Obs. 2015, Norwegian CPOS network, 60-70 km spacing) found ordinary kriging the best of the
  interpolators they compared; Tang et al. (J. Navigation 69, 2016) compare kriging with the linear and
  distance models and their own grid method.
- ``plane``: the linear interpolation model (LIM) of the seed paper -- a plane through the master in the
  east/north coordinate differences, least-squares fitted over the surrounding stations (Wanninger 1995;
  Han and Rizos 1996). Kept for comparison: against the simulator's truth it is worse than ``kriging``
  between the stations and near any station but the master (docs/decisions/0002-kriging-over-plane.md).
- ``along-line``: railway networks are long and thin, so the stations are nearly collinear and the plane is
  ill-conditioned across the line. The along-line model projects stations and rovers onto the line's
  principal axis and interpolates piecewise linearly between the two stations bracketing the rover (the end
  segments are extended linearly beyond the outermost stations).
- ``distance``: inverse-distance weighting, the fallback when neither fits (e.g. a single station left).

``select_model`` detects the degenerate geometry from the singular values of the station coordinates,
rather than assuming it from the network's name.

Not done, and why:
- interpolating vertical (zenith) values at the ionospheric pierce points and mapping back: stations a few
  tens of km apart see a satellite along parallel rays, so the pierce points are the stations' pattern
  shifted and the mapping-function part is linear across the network
  (docs/decisions/0005-no-pierce-point-or-time-smoothing.md);
- smoothing the interpolated corrections in time: the DD ionosphere itself moves, and the station residuals
  are already smoothed on each baseline (same decision);
- a nugget in the kriging (a surface that no longer passes through the station residuals): the smooth field
  between stations ~70 km apart is what the exact surface follows
  (docs/decisions/0004-exact-kriging-no-nugget.md); the VRS takes each point's six nearest stations for it
  (`augnet.centre.vrs.SUBNET_STATIONS`).
"""

from __future__ import annotations

from enum import Enum

import numpy as np

# The plane model is used when the station spread across the principal axis is at least this fraction of
# the spread along it. Below it the normal matrix's condition number exceeds ~1/ratio^2 = 100 and a few mm
# of residual noise becomes cm across the line.
MIN_CROSS_TO_ALONG_SPREAD = 0.1
# Inverse-distance exponent (Shepard weighting, p = 2 is the usual choice).
DISTANCE_WEIGHT_POWER = 2.0
# Below this distance [m] a rover is taken to sit on a station.
COINCIDENT_DISTANCE_M = 1e-3
# Correlation length of the non-planar part of the residual field in the kriging model [m]: medium-scale
# travelling disturbances have wavelengths of 100-500 km (Hernandez-Pajares et al., J. Geophys. Res. 111,
# 2006; 300 +- 150 km for the terminator-generated ones over North America). The weights depend little on it:
# the drift carries the trend (docs/decisions/0003-kriging-correlation-length.md).
KRIGING_CORRELATION_LENGTH_M = 200e3
# The along-line model assumes no gradient across the line. A rover farther than this from the line of the
# stations it uses gets no correction from it: at 1-4 ppm of DD ionosphere (quiet day, network-rtk.md) the
# unmodelled cross-line part is already 1-4 cm at 10 km (docs/decisions/0006-along-line-cross-line-limit.md).
MAX_CROSS_LINE_DISTANCE_M = 10e3


class Model(str, Enum):
    PLANE = "plane"
    ALONG_LINE = "along-line"
    DISTANCE = "distance"
    KRIGING = "kriging"


# Model codes as `interpolate` returns them (and a VRS carries them per satellite); -1: no correction.
MODEL_CODES = {Model.PLANE: 0, Model.ALONG_LINE: 1, Model.DISTANCE: 2, Model.KRIGING: 3}
MODEL_NAMES = {-1: "none", **{code: m.value for m, code in MODEL_CODES.items()}}


class InterpolationError(ValueError):
    pass


def spread_ratio(station_en: np.ndarray) -> float:
    """Cross-line over along-line spread of the stations (ratio of singular values, 0 = collinear)."""
    en = np.asarray(station_en, dtype=float)
    if en.shape[0] < 3:
        return 0.0
    s = np.linalg.svd(en - en.mean(axis=0), compute_uv=False)
    return float(s[1] / s[0]) if s[0] > 0 else 0.0


def select_model(station_en: np.ndarray) -> Model:
    """The model the station geometry supports: kriging when 2-D, along-line when nearly collinear."""
    n = np.asarray(station_en).shape[0]
    if n < 2:
        return Model.DISTANCE
    if n >= 3 and spread_ratio(station_en) >= MIN_CROSS_TO_ALONG_SPREAD:
        return Model.KRIGING
    return Model.ALONG_LINE


def plane_weights(station_en: np.ndarray, rover_en: np.ndarray, master: int = 0) -> np.ndarray:
    """LIM weights (rovers x stations): correction = a*dE + b*dN fitted to the non-master stations."""
    en = np.asarray(station_en, dtype=float)
    rov = np.atleast_2d(np.asarray(rover_en, dtype=float))
    aux = np.array([i for i in range(en.shape[0]) if i != master])
    if aux.size < 2:
        raise InterpolationError("the plane model needs the master and at least two more stations")
    A = en[aux] - en[master]
    N = A.T @ A
    if np.linalg.cond(N) > 1e12:
        raise InterpolationError("stations are collinear: the plane model is undefined")
    W = np.zeros((rov.shape[0], en.shape[0]))
    W[:, aux] = (rov - en[master]) @ np.linalg.solve(N, A.T)
    return W


def kriging_weights(station_en: np.ndarray, rover_en: np.ndarray,
                    length_m: float = KRIGING_CORRELATION_LENGTH_M) -> np.ndarray:
    """Universal-kriging weights with a linear drift (rovers x stations).

    The weights reproduce any plane exactly (sum to one, first moments match the rover), pass through every
    station (a rover on a station gets that station's residual), and between stations follow a Gaussian
    covariance of the non-planar part with the given correlation length."""
    en = np.asarray(station_en, dtype=float)
    rov = np.atleast_2d(np.asarray(rover_en, dtype=float))
    n = en.shape[0]
    if n < 3:
        raise InterpolationError("the kriging model needs at least three stations")
    centre = en.mean(axis=0)
    x = (en - centre) / length_m  # scaled coordinates keep the system well conditioned
    xr = (rov - centre) / length_m
    F = np.column_stack([np.ones(n), x])
    if np.linalg.cond(F.T @ F) > 1e12:
        raise InterpolationError("stations are collinear: the kriging drift (a plane) is undefined")
    C = np.exp(-np.sum((x[:, None, :] - x[None, :, :]) ** 2, axis=2))
    K = np.block([[C, F], [F.T, np.zeros((3, 3))]])
    rhs = np.vstack([np.exp(-np.sum((x[:, None, :] - xr[None, :, :]) ** 2, axis=2)),
                     np.ones((1, len(rov))), xr.T])
    return np.linalg.solve(K, rhs)[:n].T


def _principal_axis(en: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    centre = en.mean(axis=0)
    _, _, vt = np.linalg.svd(en - centre)
    return centre, vt[0]


def along_line_weights(station_en: np.ndarray, rover_en: np.ndarray) -> np.ndarray:
    """Piecewise-linear weights along the stations' principal axis (rovers x stations)."""
    en = np.asarray(station_en, dtype=float)
    rov = np.atleast_2d(np.asarray(rover_en, dtype=float))
    n = en.shape[0]
    if n < 2:
        raise InterpolationError("the along-line model needs at least two stations")
    centre, axis = _principal_axis(en)
    s_sta = (en - centre) @ axis
    s_rov = (rov - centre) @ axis
    order = np.argsort(s_sta, kind="stable")
    s_sorted = s_sta[order]
    if np.any(np.diff(s_sorted) <= COINCIDENT_DISTANCE_M):
        raise InterpolationError("two stations project onto the same point of the line")
    # segment index k: the rover lies between s_sorted[k] and s_sorted[k+1] (end segments extended)
    k = np.clip(np.searchsorted(s_sorted, s_rov) - 1, 0, n - 2)
    s0 = s_sorted[k]
    s1 = s_sorted[k + 1]
    t = (s_rov - s0) / (s1 - s0)
    W = np.zeros((rov.shape[0], n))
    rows = np.arange(rov.shape[0])
    W[rows, order[k]] = 1.0 - t
    W[rows, order[k + 1]] += t
    return W


def distance_weights(station_en: np.ndarray, rover_en: np.ndarray,
                     power: float = DISTANCE_WEIGHT_POWER) -> np.ndarray:
    """Inverse-distance weights (rovers x stations), normalised to sum to one."""
    en = np.asarray(station_en, dtype=float)
    rov = np.atleast_2d(np.asarray(rover_en, dtype=float))
    d = np.linalg.norm(rov[:, None, :] - en[None, :, :], axis=2)
    on_station = d < COINCIDENT_DISTANCE_M
    w = 1.0 / np.maximum(d, COINCIDENT_DISTANCE_M) ** power
    w = np.where(on_station.any(axis=1, keepdims=True), on_station.astype(float), w)
    return w / w.sum(axis=1, keepdims=True)


def cross_line_distance(station_en: np.ndarray, rover_en: np.ndarray) -> np.ndarray:
    """Distance [m] of each rover from the principal axis (the line) of the stations."""
    en = np.asarray(station_en, dtype=float)
    rov = np.atleast_2d(np.asarray(rover_en, dtype=float))
    centre, axis = _principal_axis(en)
    d = rov - centre
    return np.abs(d[:, 0] * axis[1] - d[:, 1] * axis[0])


def weights(station_en: np.ndarray, rover_en: np.ndarray, model: Model | str | None = None,
            master: int = 0) -> tuple[np.ndarray, Model]:
    """Weights for the given model, or for the one the geometry supports when model is None."""
    model = select_model(station_en) if model is None else Model(model)
    if model is Model.KRIGING:
        return kriging_weights(station_en, rover_en), model
    if model is Model.PLANE:
        return plane_weights(station_en, rover_en, master), model
    if model is Model.ALONG_LINE:
        return along_line_weights(station_en, rover_en), model
    return distance_weights(station_en, rover_en), model


def interpolate(station_en: np.ndarray, rover_en: np.ndarray, residuals: np.ndarray,
                model: Model | str | None = None, master: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Corrections at the rovers (rovers x satellites) from station residuals (stations x satellites).

    NaN marks a residual a station does not have (satellite not tracked, ambiguity not fixed). Satellites
    are grouped by which stations have them, and each group gets the weights of its own station subset
    (always including the master, whose residual is zero by definition), with the model re-selected for
    that subset. Returns (corrections, model code per satellite: `MODEL_CODES`, -1 none). A satellite no
    station but the master has gets NaN: there is nothing to interpolate. Rovers farther than
    `MAX_CROSS_LINE_DISTANCE_M` from the line of an along-line subset get NaN for its satellites (model
    code still that of the subset): the model knows nothing across the line.
    """
    en = np.asarray(station_en, dtype=float)
    V = np.asarray(residuals, dtype=float)
    rov = np.atleast_2d(np.asarray(rover_en, dtype=float))
    nsat = V.shape[1]
    out = np.full((rov.shape[0], nsat), np.nan)
    codes = np.full(nsat, -1, dtype=np.int8)
    have = ~np.isnan(V)
    have[master] = True  # the master's own residual is zero
    V = np.where(np.isnan(V), 0.0, V)
    V[master] = 0.0
    patterns, inverse = np.unique(have.T, axis=0, return_inverse=True)
    for p, pattern in enumerate(patterns):
        cols = np.nonzero(inverse.ravel() == p)[0]
        idx = np.nonzero(pattern)[0]
        if idx.size == 1:
            continue  # only the master has it: nothing to interpolate from (NaN, model -1)
        else:
            sub_master = int(np.nonzero(idx == master)[0][0])
            try:
                W, used = weights(en[idx], rov, model if model is not None else None, sub_master)
            except InterpolationError:
                W, used = distance_weights(en[idx], rov), Model.DISTANCE
        corr = W @ V[np.ix_(idx, cols)]
        if used is Model.ALONG_LINE:
            far = cross_line_distance(en[idx], rov) > MAX_CROSS_LINE_DISTANCE_M
            corr[far] = np.nan
        out[:, cols] = corr
        codes[cols] = MODEL_CODES[used]
    return out, codes


def leave_one_out(station_en: np.ndarray, residuals: np.ndarray, model: Model | str | None = None,
                  master: int = 0) -> np.ndarray:
    """Prediction error at each non-master station from the others (stations x satellites; master row NaN).

    This is the network's own estimate of its interpolation error, available without a rover.
    """
    en = np.asarray(station_en, dtype=float)
    V = np.asarray(residuals, dtype=float)
    err = np.full(V.shape, np.nan)
    for k in range(en.shape[0]):
        if k == master:
            continue
        keep = np.array([i for i in range(en.shape[0]) if i != k])
        sub_master = int(np.nonzero(keep == master)[0][0])
        pred, _ = interpolate(en[keep], en[k], V[keep], model, sub_master)
        err[k] = pred[0] - V[k]
    return err

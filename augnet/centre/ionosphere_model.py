"""The network's single-layer ionosphere model of the DD ionosphere, fitted over every baseline's fixed satellites.

The DD ionosphere of a satellite low at both stations holds a term the zero-mean prior ignores: the vertical TEC
times the difference of the two stations' mapping functions. Fitted over the fixed satellites, the model centres
the prior of the satellites not yet fixed, whose spread is then the model's residual level instead of the day's
(decision 0105).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from augnet.centre.baseline import BaselineEpoch
from augnet.centre.baseline_config import BaselineConfig
from augnet.centre.ionosphere_prior import PPM, network_shell_height_km, rms_upper_bound_factor
from augnet.gnss.ionosphere import IONO_K_M3_S2, thin_shell_mapping


@dataclass(frozen=True)
class IonosphereModel:
    """A vertical TEC `vtec_tecu` on a shell at `shell_km`, which a satellite's DD ionosphere holds through the
    difference of the two stations' mapping functions (b minus a, satellite minus reference), plus a residual (the
    TEC's gradients between the pierce points) of `level_ppm` [ppm of the baseline length, vertical, mapped with
    hypot(M_s, M_ref) like the day's level]: the 95 % upper bound of the fit's residual RMS times
    `iono_prior_adapt`, never below `iono_model_floor_ppm`."""

    vtec_tecu: float
    vtec_var_tecu2: float
    level_ppm: float
    n: int  # fixed DD ionospheres it was fitted on
    shell_km: float

    def predict(self, r: BaselineEpoch, length_m: float) -> tuple[np.ndarray, np.ndarray]:
        """A baseline's DD ionosphere on f1 [m] and its variance [m^2] for each of its satellites against its
        reference (NaN where the system has no reference)."""
        d, m, mr = mapping_terms(r, self.shell_km)
        tecu_m = IONO_K_M3_S2 / r.freq_hz[:, 0] ** 2  # metres of f1 delay per TECU
        mean = d * self.vtec_tecu * tecu_m
        spread = self.level_ppm * PPM * length_m * np.hypot(m, mr)
        return mean, spread**2 + (d * tecu_m) ** 2 * self.vtec_var_tecu2


def mapping_terms(r: BaselineEpoch, shell_km: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per satellite of a baseline epoch: the DD of the stations' mapping functions (b - a, satellite - its
    reference; NaN without a reference), and the mapping function at the lower station of the satellite and of
    its reference (the scale of the day's level)."""
    ma = thin_shell_mapping(np.radians(r.elevation_a_deg), 1e3 * shell_km)
    mb = thin_shell_mapping(np.radians(r.elevation_b_deg), 1e3 * shell_km)
    low = np.maximum(ma, mb)
    pos = {str(s): k for k, s in enumerate(r.sats)}
    kr = np.array([pos.get(r.refs.get(str(s)[0]), -1) for s in r.sats])
    has = kr >= 0
    kr = np.where(has, kr, 0)
    sd = mb - ma
    return np.where(has, sd - sd[kr], np.nan), low, np.where(has, low[kr], np.nan)


def ionosphere_model(results: dict, lengths: dict, cfg: BaselineConfig) -> IonosphereModel | None:
    """Fit the vertical TEC of the single-layer model over every baseline's fixed satellites by weighted least
    squares (each DD ionosphere weighted by the day level's scale, L * hypot(M_s, M_ref)); the residual's level
    in ppm. None without `iono_model_min_dd` fixed DD ionospheres, or when the model is off."""
    if cfg.iono_model_floor_ppm <= 0:
        return None
    shell = network_shell_height_km(cfg.iono_shell_height_km)
    ys, ds, ss = [], [], []
    for e, r in results.items():
        if r is None:
            continue
        fixed = r.fixed & ~r.is_reference() & np.isfinite(r.dd_iono_m)
        if not fixed.any():
            continue
        d, m, mr = mapping_terms(r, shell)
        tecu_m = IONO_K_M3_S2 / r.freq_hz[:, 0] ** 2
        scale = PPM * lengths[e] * np.hypot(m, mr) / tecu_m  # TECU per ppm
        ok = fixed & np.isfinite(d)
        ys.append(r.dd_iono_m[ok] / tecu_m[ok])
        ds.append(d[ok])
        ss.append(scale[ok])
    if not ys:
        return None
    y, d, s = np.concatenate(ys), np.concatenate(ds), np.concatenate(ss)
    n = y.size
    if n < max(cfg.iono_model_min_dd, 2):
        return None
    a = d / s
    info = float(a @ a)
    if not info > 0:
        return None
    v = float(a @ (y / s)) / info
    rms = math.sqrt(float(np.sum((y / s - a * v) ** 2)) / (n - 1))
    level = max(cfg.iono_model_floor_ppm, cfg.iono_prior_adapt * rms * rms_upper_bound_factor(n - 1))
    return IonosphereModel(vtec_tecu=v, vtec_var_tecu2=level**2 / info, level_ppm=level, n=n, shell_km=shell)


def model_predictions(model: IonosphereModel | None, results: dict,
                      lengths: dict) -> dict[tuple[int, int], dict[str, tuple[str, float, float]]]:
    """Per baseline, the model's DD ionosphere [m] and its variance [m^2] for the satellites high enough to be
    fixed and not fixed yet (against the baseline's reference): the prior of their next integer decision."""
    if model is None:
        return {}
    out = {}
    for e, r in results.items():
        if r is None:
            continue
        need = ~r.fixed & (r.eligible if r.eligible is not None else True)
        if not need.any():
            continue
        mean, var = model.predict(r, lengths[e])
        pos = {str(s): k for k, s in enumerate(r.sats)}
        hints = {}
        for k in np.flatnonzero(need & np.isfinite(mean)):
            s = str(r.sats[k])
            ref = r.refs.get(s[0])
            if ref in pos and ref != s:
                hints[s] = (ref, float(mean[k]), float(var[k]))
        out[e] = hints
    return out

"""Ionosphere hints between baselines: a satellite fixed on some baselines predicts its DD ionosphere on the
others, which separates the wide-lane candidates (0.57-0.8 m of DD ionosphere apart) at once.

Per satellite pair, a linear model of the DD ionosphere over the network (DD ionosphere = gradient . baseline
vector), the gradient fitted by weighted least squares over the baselines near enough, each weighted by the model
error at its distance (`iono_hint_ppm_per_100km`, decision 0104). A satellite fixed on one baseline thus helps the
parallel ones at once, and two non-parallel ones help every baseline around them.
"""

from __future__ import annotations

import math

import numpy as np

from augnet.centre.baseline_config import BaselineConfig
from augnet.centre.ionosphere_prior import PPM, IonospherePrior, network_shell_height_km
from augnet.gnss.ionosphere import thin_shell_mapping

Edge = tuple[int, int]
# The gradient's weak prior: this many times the default prior [ppm], mapped
GRADIENT_PRIOR_FACTOR = 10.0
# A source baseline's distance counts as at least this share of the target's length
MIN_DISTANCE_SHARE_OF_LENGTH = 0.5
# A float source is used only where its posterior variance is below this share of its prior (it says something)
FLOAT_SOURCE_MAX_VARIANCE_SHARE = 0.8
M_PER_100_KM = 1e5


class IonosphereHints:
    """The baselines' geometry (east/north vectors, lengths, the ones near each other) and the hints of an epoch."""

    def __init__(self, edges: list[Edge], station_en_m: np.ndarray, cfg: BaselineConfig):
        self.cfg = cfg
        en = station_en_m
        self.vector = {e: en[e[1]] - en[e[0]] for e in edges}  # b minus a, east/north [m]
        self.length = {e: float(np.linalg.norm(v)) for e, v in self.vector.items()}
        mid = {e: 0.5 * (en[e[0]] + en[e[1]]) for e in edges}
        far = cfg.iono_hint_max_distance_km * 1e3
        # per baseline, the others near enough to lend it their ionosphere, with the distance between midpoints
        self.near = {t: [(e, float(np.linalg.norm(mid[e] - mid[t]))) for e in edges
                         if e != t and np.linalg.norm(mid[e] - mid[t]) <= far] for t in edges}

    def predict(self, results: dict, priors: dict[Edge, IonospherePrior]) -> dict[Edge, dict[str, tuple]]:
        """For each baseline and satellite not fixed there: sat -> (the baseline's reference, the DD ionosphere
        predicted from the other baselines [m], its variance [m^2]), where it says more than the baseline's own
        prior. Used for the next epoch."""
        cfg = self.cfg
        if not cfg.iono_hints:
            return {}
        shell_m = 1e3 * network_shell_height_km(cfg.iono_shell_height_km)
        info = {e: (r, {str(s): k for k, s in enumerate(r.sats)}) for e, r in results.items() if r is not None}
        hints: dict[Edge, dict[str, tuple]] = {}
        for t, (rt, post) in info.items():
            need = ~rt.fixed & (rt.eligible if rt.eligible is not None else True)
            if not need.any():
                continue
            prior = priors[t]
            # the hint's error model is the quiet day's: scaled up with the day's level where it is higher
            activity = max(1.0, prior.level_ppm / cfg.iono_prior_ppm)
            mapping = thin_shell_mapping(np.radians(np.minimum(rt.elevation_a_deg, rt.elevation_b_deg)), shell_m)
            out = {}
            for k in np.flatnonzero(need):
                s = str(rt.sats[k])
                ref = rt.refs.get(s[0])
                kr = post.get(ref)
                if kr is None or s == ref:
                    continue
                hint = self._hint(t, s, ref, math.hypot(mapping[k], mapping[kr]), activity, info, priors)
                if hint is not None:
                    out[s] = (ref, *hint)
            if out:
                hints[t] = out
        return hints

    def _hint(self, t: Edge, s: str, ref: str, meff: float, activity: float, info, priors):
        """(DD ionosphere [m], variance [m^2]) of (s - ref) on baseline t from the baselines near it, or None."""
        cfg = self.cfg
        lt = self.length[t]
        lam = np.eye(2) / (GRADIENT_PRIOR_FACTOR * cfg.iono_prior_ppm * PPM * meff) ** 2
        vec = np.zeros(2)
        used = 0
        for e, dist in self.near[t]:
            src = info.get(e)
            if src is None:
                continue
            re, pe = src
            ks, kq = pe.get(s), pe.get(ref)
            if ks is None or kq is None:
                continue
            dxe = self.vector[e]
            var = (cfg.iono_hint_ppm_per_100km * activity * PPM * max(dist, MIN_DISTANCE_SHARE_OF_LENGTH * lt)
                   / M_PER_100_KM * self.length[e] * meff) ** 2
            if re.fixed[ks] and re.fixed[kq]:
                y = re.dd_iono_m[ks] - re.dd_iono_m[kq]
            elif (cfg.iono_hints_float and re.iono_float_m is not None and re.refs.get(s[0]) == ref
                  and not set(e) & set(t)):
                # not fixed there either: the float estimate of a baseline with no station in common (independent
                # multipath and noise), less its prior (which this baseline has too): in information form,
                # data = posterior - prior
                vp = priors[e].state_prior_dd(s, ref)
                v = float(re.iono_float_var_m2[ks])
                if not v < FLOAT_SOURCE_MAX_VARIANCE_SHARE * vp:
                    continue
                y = float(re.iono_float_m[ks]) * vp / (vp - v)
                var += v * vp / (vp - v)
            else:
                continue
            if not np.isfinite(y):
                continue
            lam += np.outer(dxe, dxe) / var
            vec += dxe * y / var
            used += 1
        if not used:
            return None
        cov = np.linalg.inv(lam)
        dxt = self.vector[t]
        var = float(dxt @ cov @ dxt)
        prior_dd = priors[t].level_ppm * PPM * lt * meff
        if var < prior_dd**2:
            return float(dxt @ cov @ vec), var
        return None

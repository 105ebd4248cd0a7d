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
        sources = _Sources(results, priors)
        hints: dict[Edge, dict[str, tuple]] = {}
        for t, rt in sources.results.items():
            post = sources.local[t]
            need = ~rt.fixed & (rt.eligible if rt.eligible is not None else True)
            if not need.any():
                continue
            prior = priors[t]
            # the hint's error model is the quiet day's: scaled up with the day's level where it is higher
            activity = max(1.0, prior.level_ppm / cfg.iono_prior_ppm)
            mapping = thin_shell_mapping(np.radians(np.minimum(rt.elevation_a_deg, rt.elevation_b_deg)), shell_m)
            sats, refs, meff = [], [], []
            for k in np.flatnonzero(need):
                s = str(rt.sats[k])
                ref = rt.refs.get(s[0])
                kr = post.get(ref)
                if kr is None or s == ref:
                    continue
                sats.append(s)
                refs.append(ref)
                meff.append(math.hypot(mapping[k], mapping[kr]))
            if sats:
                out = self._hints(t, sats, refs, np.array(meff), activity, sources)
                if out:
                    hints[t] = out
        return hints

    def _hints(self, t: Edge, sats: list[str], refs: list[str], meff: np.ndarray, activity: float,
               sources: _Sources) -> dict[str, tuple]:
        """sat -> (ref, DD ionosphere [m], variance [m^2]) of each (sat - ref) on baseline t from the baselines near
        it, where it says more than t's prior. Vectorised over t's satellites, the sources taken in the same order
        for each, so the sums (the hints) are those of one satellite at a time, bit for bit (`float_power`: the C
        library's pow, as Python's ** on a float)."""
        cfg = self.cfg
        lt = self.length[t]
        n = len(sats)
        gs, gr = sources.ids(sats), sources.ids(refs)
        lam00 = 1.0 / np.float_power(GRADIENT_PRIOR_FACTOR * cfg.iono_prior_ppm * PPM * meff, 2.0)
        lam01 = np.zeros(n)
        lam11 = lam00.copy()
        vec0, vec1 = np.zeros(n), np.zeros(n)
        used = np.zeros(n, dtype=bool)
        for e, dist in self.near[t]:
            re = sources.results.get(e)
            if re is None:
                continue
            ks, kq = sources.index[e][gs], sources.index[e][gr]
            seen = (ks >= 0) & (kq >= 0)
            if not seen.any():
                continue
            ks, kq = np.where(seen, ks, 0), np.where(seen, kq, 0)
            dxe = self.vector[e]
            a = (cfg.iono_hint_ppm_per_100km * activity * PPM * max(dist, MIN_DISTANCE_SHARE_OF_LENGTH * lt)
                 / M_PER_100_KM * self.length[e])
            var = np.float_power(a * meff, 2.0)
            fixed = seen & re.fixed[ks] & re.fixed[kq]
            y = np.where(fixed, re.dd_iono_m[ks] - re.dd_iono_m[kq], np.nan)
            if cfg.iono_hints_float and re.iono_float_m is not None and not set(e) & set(t):
                # not fixed there either: the float estimate of a baseline with no station in common (independent
                # multipath and noise), less its prior (which this baseline has too): in information form,
                # data = posterior - prior
                fl = np.flatnonzero(seen & ~fixed & (sources.ref_of[e][gs] == gr))
                if fl.size:
                    sp = sources.state_priors(e)
                    vp = sp[gs[fl]] + sp[gr[fl]]
                    v = re.iono_float_var_m2[ks[fl]].astype(float)
                    ok = v < FLOAT_SOURCE_MAX_VARIANCE_SHARE * vp
                    fl, vp, v = fl[ok], vp[ok], v[ok]
                    y[fl] = re.iono_float_m[ks[fl]].astype(float) * vp / (vp - v)
                    var[fl] += v * vp / (vp - v)
            use = np.isfinite(y)
            if not use.any():
                continue
            w, yu = var[use], y[use]
            lam00[use] += dxe[0] * dxe[0] / w  # as np.outer(dxe, dxe) / var, entry by entry
            lam01[use] += dxe[0] * dxe[1] / w
            lam11[use] += dxe[1] * dxe[1] / w
            vec0[use] += dxe[0] * yu / w
            vec1[use] += dxe[1] * yu / w
            used |= use
        if not used.any():
            return {}
        k = np.flatnonzero(used)
        lam = np.stack([np.stack([lam00[k], lam01[k]], -1), np.stack([lam01[k], lam11[k]], -1)], -2)
        cov = np.linalg.inv(lam)
        vec = np.stack([vec0[k], vec1[k]], -1)
        dxt = self.vector[t]
        level = sources.priors[t].level_ppm
        out = {}
        for j, i in enumerate(k):
            var_t = float(dxt @ cov[j] @ dxt)
            prior_dd = level * PPM * lt * float(meff[i])
            if var_t < prior_dd**2:
                out[sats[i]] = (refs[i], float(dxt @ cov[j] @ vec[j]), var_t)
        return out


class _Sources:
    """An epoch's baseline results indexed by one numbering of all their satellites: per baseline, each
    satellite's row (-1: not there) and its system's reference (-1: none), and the state priors on demand."""

    def __init__(self, results: dict, priors: dict[Edge, IonospherePrior]):
        self.results = {e: r for e, r in results.items() if r is not None}
        self.priors = priors
        self.local = {e: {str(s): k for k, s in enumerate(r.sats)} for e, r in self.results.items()}
        self.number = {}
        for pos in self.local.values():
            for s in pos:
                self.number.setdefault(s, len(self.number))
        names = list(self.number)
        self.index, self.ref_of = {}, {}
        for e, r in self.results.items():
            idx = np.full(len(names), -1, dtype=int)
            for s, k in self.local[e].items():
                idx[self.number[s]] = k
            self.index[e] = idx
            refs = {sys_: self.number.get(ref, -1) for sys_, ref in r.refs.items()}
            self.ref_of[e] = np.array([refs.get(s[0], -1) for s in names], dtype=int)
        self._names = names
        self._state_priors: dict[Edge, np.ndarray] = {}

    def ids(self, sats: list[str]) -> np.ndarray:
        return np.array([self.number[s] for s in sats], dtype=int)

    def state_priors(self, e: Edge) -> np.ndarray:
        got = self._state_priors.get(e)
        if got is None:
            got = self._state_priors[e] = self.priors[e].state_priors(self._names)
        return got

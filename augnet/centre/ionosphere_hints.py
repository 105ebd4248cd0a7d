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
        pairs: list[tuple[Edge, str, str, float, float]] = []  # (target, sat, ref, m_eff, activity) to predict
        for t, rt in sources.results.items():
            post = sources.local[t]
            need = ~rt.fixed & (rt.eligible if rt.eligible is not None else True)
            if not need.any():
                continue
            prior = priors[t]
            # the hint's error model is the quiet day's: scaled up with the day's level where it is higher
            activity = max(1.0, prior.level_ppm / cfg.iono_prior_ppm)
            mapping = thin_shell_mapping(np.radians(np.minimum(rt.elevation_a_deg, rt.elevation_b_deg)), shell_m)
            for k in np.flatnonzero(need):
                s = str(rt.sats[k])
                ref = rt.refs.get(s[0])
                kr = post.get(ref)
                if kr is None or s == ref:
                    continue
                pairs.append((t, s, ref, math.hypot(mapping[k], mapping[kr]), activity))
        return self._hints(pairs, sources) if pairs else {}

    def _hints(self, pairs: list, sources: _Sources) -> dict[Edge, dict[str, tuple]]:
        """target -> sat -> (ref, DD ionosphere [m], variance [m^2]) of each (sat - ref) on its baseline from the
        baselines near it, where it says more than the target's prior. Vectorised over every (target, satellite)
        pair of the epoch: round j takes each target's j-th near baseline, so each pair's sums run in the order of
        one pair at a time and the hints are the same bit for bit (`float_power`: the C library's pow, as Python's
        ** on a float)."""
        cfg = self.cfg
        targets = [p[0] for p in pairs]
        gs, gr = sources.ids([p[1] for p in pairs]), sources.ids([p[2] for p in pairs])
        meff = np.array([p[3] for p in pairs])
        activity = np.array([p[4] for p in pairs], dtype=float)
        lt = np.array([self.length[t] for t in targets])
        n = len(pairs)
        lam00 = 1.0 / np.float_power(GRADIENT_PRIOR_FACTOR * cfg.iono_prior_ppm * PPM * meff, 2.0)
        lam01 = np.zeros(n)
        lam11 = lam00.copy()
        vec0, vec1 = np.zeros(n), np.zeros(n)
        used = np.zeros(n, dtype=bool)
        # each target's sources in order (those without a result this epoch are skipped, as before)
        near = {t: [(sources.row[e], e, d) for e, d in self.near[t] if e in sources.row] for t in dict.fromkeys(targets)}
        for j in range(max(len(v) for v in near.values())):
            at = np.array([i for i, t in enumerate(targets) if len(near[t]) > j], dtype=int)
            if not at.size:
                break
            src = [near[targets[i]][j] for i in at]
            row = np.array([r for r, _, _ in src], dtype=int)
            dist = np.array([d for _, _, d in src])
            length_e = np.array([self.length[e] for _, e, _ in src])
            dxe = np.array([self.vector[e] for _, e, _ in src], dtype=float).reshape(-1, 2)
            disjoint = np.array([not set(e) & set(targets[i]) for (_, e, _), i in zip(src, at)], dtype=bool)
            ks, kq = sources.index_all[row, gs[at]], sources.index_all[row, gr[at]]
            seen = (ks >= 0) & (kq >= 0)
            ks, kq = sources.offset[row] + np.where(seen, ks, 0), sources.offset[row] + np.where(seen, kq, 0)
            a = (cfg.iono_hint_ppm_per_100km * activity[at] * PPM * np.maximum(dist, MIN_DISTANCE_SHARE_OF_LENGTH * lt[at])
                 / M_PER_100_KM * length_e)
            var = np.float_power(a * meff[at], 2.0)
            fixed = seen & sources.fixed[ks] & sources.fixed[kq]
            y = np.where(fixed, sources.dd_iono[ks] - sources.dd_iono[kq], np.nan)
            if cfg.iono_hints_float:
                # not fixed there either: the float estimate of a baseline with no station in common (independent
                # multipath and noise), less its prior (which this baseline has too): in information form,
                # data = posterior - prior
                fl = np.flatnonzero(seen & ~fixed & disjoint & sources.has_float[row]
                                    & (sources.ref_of_all[row, gs[at]] == gr[at]))
                if fl.size:
                    sp = sources.state_priors_all()
                    vp = sp[row[fl], gs[at][fl]] + sp[row[fl], gr[at][fl]]
                    v = sources.float_var[ks[fl]]
                    ok = v < FLOAT_SOURCE_MAX_VARIANCE_SHARE * vp
                    fl, vp, v = fl[ok], vp[ok], v[ok]
                    y[fl] = sources.float_iono[ks[fl]] * vp / (vp - v)
                    var[fl] += v * vp / (vp - v)
            use = np.isfinite(y)
            if not use.any():
                continue
            u, w, yu, d0, d1 = at[use], var[use], y[use], dxe[use, 0], dxe[use, 1]
            lam00[u] += d0 * d0 / w  # as np.outer(dxe, dxe) / var, entry by entry
            lam01[u] += d0 * d1 / w
            lam11[u] += d1 * d1 / w
            vec0[u] += d0 * yu / w
            vec1[u] += d1 * yu / w
            used[u] = True
        if not used.any():
            return {}
        k = np.flatnonzero(used)
        lam = np.stack([np.stack([lam00[k], lam01[k]], -1), np.stack([lam01[k], lam11[k]], -1)], -2)
        cov = np.linalg.inv(lam)
        vec = np.stack([vec0[k], vec1[k]], -1)
        out: dict[Edge, dict[str, tuple]] = {}
        for j, i in enumerate(k):
            t, s, ref, m, _ = pairs[i]
            dxt = self.vector[t]
            var_t = float(dxt @ cov[j] @ dxt)
            prior_dd = sources.priors[t].level_ppm * PPM * self.length[t] * m
            if var_t < prior_dd**2:
                out.setdefault(t, {})[s] = (ref, float(dxt @ cov[j] @ vec[j]), var_t)
        return out


class _Sources:
    """An epoch's baseline results indexed by one numbering of all their satellites: per baseline (a row), each
    satellite's position in the baseline's arrays (-1: not there) and its system's reference (-1: none); the
    baselines' arrays end to end (`offset`), and their state priors on demand."""

    def __init__(self, results: dict, priors: dict[Edge, IonospherePrior]):
        self.results = {e: r for e, r in results.items() if r is not None}
        self.priors = priors
        self.local = {e: {str(s): k for k, s in enumerate(r.sats)} for e, r in self.results.items()}
        self.number: dict[str, int] = {}
        for pos in self.local.values():
            for s in pos:
                self.number.setdefault(s, len(self.number))
        names = list(self.number)
        edges = list(self.results)
        self.row = {e: i for i, e in enumerate(edges)}
        self.index_all = np.full((len(edges), len(names)), -1, dtype=int)
        self.ref_of_all = np.full((len(edges), len(names)), -1, dtype=int)
        for i, e in enumerate(edges):
            for s, k in self.local[e].items():
                self.index_all[i, self.number[s]] = k
            refs = {sys_: self.number.get(ref, -1) for sys_, ref in self.results[e].refs.items()}
            self.ref_of_all[i] = [refs.get(s[0], -1) for s in names]
        rs = [self.results[e] for e in edges]
        sizes = [len(r.sats) for r in rs]
        self.offset = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int) if rs else np.zeros(0, int)
        cat = (lambda arrays: np.concatenate(arrays) if arrays else np.zeros(0))
        self.fixed = cat([np.asarray(r.fixed, bool) for r in rs]).astype(bool)
        self.dd_iono = cat([np.asarray(r.dd_iono_m, float) for r in rs])
        self.has_float = np.array([r.iono_float_m is not None for r in rs], dtype=bool)
        self.float_iono = cat([np.asarray(r.iono_float_m if r.iono_float_m is not None else np.full(n, np.nan), float)
                               for r, n in zip(rs, sizes)])
        self.float_var = cat([np.asarray(r.iono_float_var_m2 if r.iono_float_var_m2 is not None
                                         else np.full(n, np.nan), float) for r, n in zip(rs, sizes)])
        self._names, self._edges = names, edges
        self._state_priors: np.ndarray | None = None

    def ids(self, sats: list[str]) -> np.ndarray:
        return np.array([self.number[s] for s in sats], dtype=int)

    def state_priors_all(self) -> np.ndarray:
        """(baselines, satellites) the prior variance of each SD ionosphere state [m^2], NaN if unknown."""
        if self._state_priors is None:
            self._state_priors = np.array([self.priors[e].state_priors(self._names) for e in self._edges],
                                          dtype=float).reshape(len(self._edges), len(self._names))
        return self._state_priors

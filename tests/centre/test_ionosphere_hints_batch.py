"""The network's ionosphere hints, vectorised over every (baseline, satellite) pair, equal the plain definition
(one satellite at a time, one near baseline after the other), bit for bit, on a simulated network (issue 17)."""

import math

import numpy as np

from augnet.bench.centre import _epochs, _world
from augnet.centre.ionosphere_hints import (FLOAT_SOURCE_MAX_VARIANCE_SHARE, GRADIENT_PRIOR_FACTOR, M_PER_100_KM,
                                            MIN_DISTANCE_SHARE_OF_LENGTH)
from augnet.centre.ionosphere_prior import PPM, network_shell_height_km
from augnet.centre.network import NetworkSolver
from augnet.gnss.ionosphere import thin_shell_mapping

EPOCHS = 40  # first fixes within the first half minute: both fixed and float sources occur


def _reference(h, results, priors):
    """IonosphereHints.predict as first written: per baseline, per satellite, per near baseline."""
    cfg = h.cfg
    shell_m = 1e3 * network_shell_height_km(cfg.iono_shell_height_km)
    info = {e: (r, {str(s): k for k, s in enumerate(r.sats)}) for e, r in results.items() if r is not None}
    hints = {}
    for t, (rt, post) in info.items():
        need = ~rt.fixed & (rt.eligible if rt.eligible is not None else True)
        activity = max(1.0, priors[t].level_ppm / cfg.iono_prior_ppm)
        mapping = thin_shell_mapping(np.radians(np.minimum(rt.elevation_a_deg, rt.elevation_b_deg)), shell_m)
        out = {}
        for k in np.flatnonzero(need):
            s = str(rt.sats[k])
            ref = rt.refs.get(s[0])
            kr = post.get(ref)
            if kr is None or s == ref:
                continue
            meff = math.hypot(mapping[k], mapping[kr])
            lt = h.length[t]
            lam = np.eye(2) / (GRADIENT_PRIOR_FACTOR * cfg.iono_prior_ppm * PPM * meff) ** 2
            vec = np.zeros(2)
            used = 0
            for e, dist in h.near[t]:
                if e not in info:
                    continue
                re, pe = info[e]
                ks, kq = pe.get(s), pe.get(ref)
                if ks is None or kq is None:
                    continue
                var = (cfg.iono_hint_ppm_per_100km * activity * PPM * max(dist, MIN_DISTANCE_SHARE_OF_LENGTH * lt)
                       / M_PER_100_KM * h.length[e] * meff) ** 2
                if re.fixed[ks] and re.fixed[kq]:
                    y = re.dd_iono_m[ks] - re.dd_iono_m[kq]
                elif (cfg.iono_hints_float and re.iono_float_m is not None and re.refs.get(s[0]) == ref
                      and not set(e) & set(t)):
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
                lam += np.outer(h.vector[e], h.vector[e]) / var
                vec += h.vector[e] * y / var
                used += 1
            if not used:
                continue
            cov = np.linalg.inv(lam)
            dxt = h.vector[t]
            v_t = float(dxt @ cov @ dxt)
            if v_t < (priors[t].level_ppm * PPM * lt * meff) ** 2:
                out[s] = (ref, float(dxt @ cov @ vec), v_t)
        if out:
            hints[t] = out
    return hints


def test_vectorised_hints_equal_the_definition():
    world = _world(6, EPOCHS)
    net = NetworkSolver({r.id: r.ecef[0] for r in world.receivers})
    seen = {"hints": 0, "epochs": 0}
    predict = net.ionosphere_hints.predict

    def checked(results, priors):
        got = predict(results, priors)
        assert got == _reference(net.ionosphere_hints, results, priors)  # exact floats, same keys and order
        assert [list(v) for v in got.values()] == [list(v) for v in _reference(net.ionosphere_hints, results,
                                                                               priors).values()]
        seen["hints"] += sum(len(v) for v in got.values())
        seen["epochs"] += 1
        return got

    net.ionosphere_hints.predict = checked
    for eps in _epochs(world):
        net.update(eps, world.nav)
    assert seen["epochs"] == EPOCHS and seen["hints"] > 50  # the comparison saw many hints

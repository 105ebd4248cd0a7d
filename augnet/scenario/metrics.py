"""Figures from a run's per-epoch record: every one is an estimate compared with the simulator's truth.

Definitions (the README's report section repeats them):

- An epoch *has sky* when the train receiver tracks at least one satellite; in a tunnel (and the epoch
  passing under a bridge) it tracks none. Such epochs can have no GNSS solution at all; railway practice
  bridges them with odometry, which is not this unit's job. They are left out of the fix-rate
  denominator and counted separately (`epochs_without_sky`); the time the unit takes to fix again after
  one is a re-acquisition and is reported on its own.
- *Corrections usable* from the first epoch at which the VRS epoch in use carries at least
  `min_fix_ambiguities + 1` satellites (the onboard filter's own minimum to fix).
- *Time to first fix* is counted from then (the network's own start-up, before it can correct the
  train's satellites, is the baselines' fix time, reported per baseline).
- *Acquisitions*: the first fix, and the first fix after each epoch run without sky; the target's median
  is over them.
- A *wrong fix* is a fixed epoch more than `WRONG_FIX_ERROR_M` from the truth (3-D).
- Protection levels: HPL = K sqrt(largest eigenvalue of the horizontal covariance), VPL = K sigma_up, K the
  two-sided Gaussian quantile of the integrity risk per epoch (the track map's allocation).
"""

from __future__ import annotations

import numpy as np

from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation

# A "fixed" epoch this far from the truth has wrong integers: a few cm is the RTK error budget, a wrong
# integer set moves the position by at least a decimetre on dual-frequency combinations. The same limit
# as the onboard and centre tests (tests/onboard/test_simulated.py, tests/centre/test_vrs_rtklib.py).
WRONG_FIX_ERROR_M = 0.10


def pct(values, qs=(50, 95, 99)) -> dict:
    """Percentiles, RMS, max and count of a sample (of absolute values when the caller passes them)."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    out = {"n": int(v.size)}
    if v.size == 0:
        out.update({f"p{q}": None for q in qs} | {"rms": None, "max": None})
        return out
    out.update({f"p{q}": float(np.percentile(v, q)) for q in qs})
    out["rms"] = float(np.sqrt(np.mean(v**2)))
    out["max"] = float(np.max(v))
    return out


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index ranges of the True runs of a boolean array."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def enu_errors(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(E, 3) estimate minus truth in east/north/up at the truth."""
    llh = ecef_to_geodetic(truth)
    R = enu_rotation(llh[:, 0], llh[:, 1])
    return np.einsum("eij,ej->ei", R, est - truth)


def protection_levels(est: np.ndarray, cov: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """(HPL, VPL) per epoch from ECEF covariances, in the local frame at the estimate (inf when none)."""
    ok = np.all(np.isfinite(est), axis=1) & np.all(np.isfinite(cov), axis=(1, 2))
    hpl = np.full(len(est), np.inf)
    vpl = np.full(len(est), np.inf)
    if ok.any():
        llh = ecef_to_geodetic(est[ok])
        R = enu_rotation(llh[:, 0], llh[:, 1])
        C = R @ cov[ok] @ np.transpose(R, (0, 2, 1))
        hpl[ok] = k * np.sqrt(np.maximum(np.linalg.eigvalsh(C[:, :2, :2])[:, -1], 0.0))
        vpl[ok] = k * np.sqrt(np.maximum(C[:, 2, 2], 0.0))
    return hpl, vpl


def acquisitions(t: np.ndarray, fixed: np.ndarray, sky: np.ndarray, usable_from: int | None) -> list[dict]:
    """The first fix after corrections became usable, then the first fix after each run without sky.

    Each: {"kind": "first" | "after_outage", "from_s", "fixed_s" (None if never), "time_s"}."""
    out = []
    if usable_from is None:
        return out
    starts = [("first", usable_from)]
    for a, b in runs(~sky):
        if b < len(t) and b > usable_from:
            starts.append(("after_outage", b))
    for kind, s in starts:
        later = np.flatnonzero(fixed[s:])
        fixed_at = s + int(later[0]) if later.size else None
        out.append({"kind": kind, "from_s": float(t[s]),
                    "fixed_s": float(t[fixed_at]) if fixed_at is not None else None,
                    "time_s": float(t[fixed_at] - t[s]) if fixed_at is not None else None})
    return out

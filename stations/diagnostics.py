"""Figures about a simulated world computed from its truth: what the scenario levels amount to.

Used by tests and reports (e.g. "DD ionosphere over the 70 km baseline is 2.2 ppm RMS"), never by
an estimator.
"""

from __future__ import annotations

import numpy as np

from stations.ionosphere import delay_m
from stations.world import EpochBlock, World

L1_HZ = 1575.42e6
DD_MIN_ELEVATION_DEG = 15.0


def dd_truth(world: World, blocks: list[EpochBlock], a: str, b: str, field: str) -> np.ndarray:
    """Double differences of a truth field per (receiver, satellite) between receivers a and b.

    Per epoch and system, the reference satellite is the highest one seen by a; satellites below
    `DD_MIN_ELEVATION_DEG` at either receiver are left out.  `field` is an (E, R, N) attribute of
    the EpochBlock, or "iono_l1_m" for the L1 ionospheric delay.  Returns all DDs, flattened.
    """
    ia, ib = world.receiver_ids.index(a), world.receiver_ids.index(b)
    out = []
    for blk in blocks:
        x = delay_m(blk.stec_tecu, L1_HZ) if field == "iono_l1_m" else getattr(blk, field)
        el = blk.elevation_rad
        ok = (el[:, ia] > np.radians(DD_MIN_ELEVATION_DEG)) & (el[:, ib] > np.radians(DD_MIN_ELEVATION_DEG))
        ok &= blk.observed[:, ia].any(-1) & blk.observed[:, ib].any(-1)
        sd = x[:, ia] - x[:, ib]
        for e in range(len(blk.t_gpst)):
            for sysl in np.unique(world.sat_system):
                m = ok[e] & (world.sat_system == sysl)
                if m.sum() < 2:
                    continue
                s = sd[e, m]
                ref = int(np.argmax(el[e, ia, m]))
                out.append(np.delete(s - s[ref], ref))
    return np.concatenate(out) if out else np.zeros(0)


def baseline_m(world: World, a: str, b: str) -> float:
    ia, ib = world.receiver_ids.index(a), world.receiver_ids.index(b)
    return float(np.linalg.norm(world.receivers[ia].ecef[0] - world.receivers[ib].ecef[0]))


def dd_ionosphere_ppm(world: World, blocks: list[EpochBlock], a: str, b: str) -> dict[str, float]:
    """RMS, median and 95th percentile of |DD L1 ionosphere| in ppm of the a-b baseline length."""
    dd = np.abs(dd_truth(world, blocks, a, b, "iono_l1_m"))
    scale = 1e6 / baseline_m(world, a, b)
    return {"rms": float(np.sqrt(np.mean(dd**2)) * scale), "median": float(np.median(dd) * scale),
            "p95": float(np.percentile(dd, 95) * scale), "n": int(dd.size)}

"""A simulated survey run: a survey train recording the track it runs on, every edge of a layout once.

What a railway's survey department collects to build its track database: GNSS positions of the track centre
line at rail level (the antenna's lever arm already reduced), at survey speed, with the errors of a
survey-grade kinematic GNSS solution.  Per edge one run, from one node to the other (the surveyor's log
names the edge and the direction it was run in).  Errors, per point:

* a time-correlated error (AR(1), `TAU_S`) of `SIGMA_H_M` per horizontal axis and `SIGMA_V_M` vertical;
* outliers: with probability `OUTLIER_RATE` a point is off by `OUTLIER_RANGE_M` in a random horizontal
  direction (a wrong fix or multipath burst the processing did not flag);
* gaps: chainage ranges given by the caller where no position was recorded (an overbridge, a tunnel).

The record (`augnet-survey/1`) holds only what a survey delivers; which points were outliers is truth,
returned apart.  The geometry the train ran on is the layout's as-built truth (stations/layout.py).
"""

from __future__ import annotations

import math

import numpy as np

from stations.layout import Layout

FORMAT = "augnet-survey/1"
SURVEY_SPEED_M_S = 5.0  # 18 km/h, a track-recording run (assumed)
SURVEY_RATE_HZ = 5.0  # positions per second: one per metre at survey speed
# Survey-grade kinematic GNSS (post-processed, fixed): 1 cm per horizontal axis, 2 cm vertical (assumed;
# the project's fixed RTK H95 is 1-2 cm, docs/measured.md), correlated over TAU_S (multipath, atmosphere).
SIGMA_H_M = 0.01
SIGMA_V_M = 0.02
TAU_S = 30.0
OUTLIER_RATE = 0.002  # per point (assumed)
OUTLIER_RANGE_M = (0.3, 3.0)


def survey_run(layout: Layout, seed: int, *, gaps: tuple[tuple[str, float, float], ...] = (),
               speed_m_s: float = SURVEY_SPEED_M_S, rate_hz: float = SURVEY_RATE_HZ,
               sigma_h_m: float = SIGMA_H_M, sigma_v_m: float = SIGMA_V_M,
               outlier_rate: float = OUTLIER_RATE) -> tuple[dict, dict]:
    """(survey record, truth): every edge of `layout` run once; `gaps` are (edge, from_m, to_m) arc-length
    ranges from the edge's begin node without positions."""
    if not (speed_m_s > 0 and rate_hz > 0):
        raise ValueError("survey speed and rate must be positive")
    rng = np.random.default_rng([seed, 0x5EB])
    runs, truth = [], {"outliers": {}, "layout": layout.name}
    t0 = 0.0
    step = speed_m_s / rate_hz
    rho = math.exp(-1.0 / (rate_hz * TAU_S))
    for k, e in enumerate(layout.edges.values()):
        direction = "up" if rng.random() < 0.5 else "down"
        s = np.arange(0.0, e.length_m, step)
        s = np.r_[s, e.length_m] if e.length_m - s[-1] > 1e-6 else s
        if direction == "down":
            s = s[::-1]
        keep = np.ones(len(s), bool)
        for g_edge, a, b in gaps:
            if g_edge == e.id:
                keep &= ~((s >= a) & (s <= b))
        xy = np.column_stack([np.interp(s, e.s_m, e.xy[:, 0]), np.interp(s, e.s_m, e.xy[:, 1])])
        z = np.interp(s, e.s_m, e.z)
        n = len(s)
        err = np.zeros((n, 3))
        sig = np.array([sigma_h_m, sigma_h_m, sigma_v_m])
        err[0] = rng.normal(0.0, 1.0, 3) * sig
        w = rng.normal(0.0, 1.0, (n, 3)) * sig * math.sqrt(1.0 - rho * rho)
        for i in range(1, n):
            err[i] = rho * err[i - 1] + w[i]
        out = rng.random(n) < outlier_rate
        ang = rng.uniform(0.0, 2 * math.pi, n)
        mag = rng.uniform(*OUTLIER_RANGE_M, n)
        err[out, 0] += mag[out] * np.cos(ang[out])
        err[out, 1] += mag[out] * np.sin(ang[out])
        llh = layout.plane_to_geodetic(xy + err[:, :2], z + err[:, 2])
        t = t0 + np.arange(n) / rate_hz
        t0 = float(t[-1]) + 60.0  # the next run starts a minute later
        rid = f"run{k + 1:02d}"
        runs.append({"id": rid, "edge": e.id, "direction": direction, "t_s": np.round(t[keep], 3).tolist(),
                     "points": np.round(llh[keep], 10).tolist(), "sigma_h_m": sigma_h_m, "sigma_v_m": sigma_v_m})
        truth["outliers"][rid] = np.flatnonzero(out[keep]).tolist()
    return {"format": FORMAT, "layout": layout.name, "seed": int(seed), "runs": runs}, truth

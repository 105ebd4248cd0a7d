"""A post-processed VRS at the rover's rate: epochs between the network's epochs, interpolated in time.

Reference stations often log at 30 s; a rover at 1 Hz then holds each VRS epoch up to 29 s, and everything that
changes per satellite in that time and no rover model follows reaches its double differences (the broadcast
satellite clock and orbit errors, the ionosphere and the wet troposphere as the satellite moves; not separated
here). That stale-base error is common to any
base at 30 s, physical or virtual (issue 14, decision 0222: on catnet UPC1 its vertical part is 3.1 cm rms, the
same to 0.4 cm on our VRS and on GARR, correlation 0.99), so a 30 s VRS can only be as good as its corrections
and the age allow. A post-processing service knows the epoch after as well as the one before, so it writes the VRS
at the rover's epochs: what RTKLIB's `misc-timeinterp` does to a 30 s base on the rover side, done once at the
centre for every rover.

Between two consecutive VRS epochs t_a < t < t_b (at most one output interval of the network apart, same master):

    obs(t) = g(t) + c clk(t) + T(t) + r_a + (r_b - r_a) (t - t_a) / (t_b - t_a),   r = obs - g - c clk - T

with g = rho - c dts and T the troposphere model computed at the point at t itself (`vrs.geometry_many`: transit
time, Earth rotation, broadcast clock), clk the master's receiver clock the VRS inherits (interpolated), and r the
residual the VRS carries (ambiguity, the master's atmosphere and the network's corrections, the satellite clock
error), which is smooth over 30 s. Only the geometry is recomputed; only the residual is interpolated, so the
observations stay consistent with the position a rover gives the VRS at every epoch. A satellite flagged
loss-of-lock at t_b (a slip, an admission moment, a new master) or missing at either end is left out between them:
its phase is not continuous there. The broadcast set of each satellite is held from t_a to t_b (an upload between
them would step the model, not the signal). Epochs more than `max_gap_s` apart are not bridged (a gap stays a gap).
"""

from __future__ import annotations

import numpy as np

from augnet.centre.observations import StationEpoch
from augnet.centre.vrs import geometry_many
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData

C = SPEED_OF_LIGHT_M_S
GRID_TOLERANCE_S = 1e-6  # an output time this close to a network epoch is that epoch


def _model(ep: StationEpoch, t: float, clock_s: float, point, nav: NavigationData) -> np.ndarray:
    """g + c clk + T at the point for the epoch's satellites at time tag t (S,)."""
    g, trop, _ = geometry_many(ep.sats, t, clock_s, point, nav)
    return (g + trop)[0] + C * clock_s


def densify(epochs: list[StationEpoch], clocks_s: list[float], masters: list[str], point_ecef_m,
            nav: NavigationData, interval_s: float, max_gap_s: float) -> tuple[list[StationEpoch], int]:
    """The VRS epochs with epochs on the grid of `interval_s` (multiples of it in GPS seconds) between each
    consecutive pair at most `max_gap_s` apart and with the same master; returns the epochs and how many were
    interpolated. `clocks_s`: per epoch, the master receiver clock its geometry was computed with."""
    point = np.asarray(point_ecef_m, float).reshape(1, 3)
    if not epochs or not interval_s > 0:
        return list(epochs), 0
    out: list[StationEpoch] = []
    added = 0
    for k, ep_a in enumerate(epochs):
        out.append(ep_a)
        if k + 1 == len(epochs):
            break
        ep_b = epochs[k + 1]
        span = ep_b.t_gpst - ep_a.t_gpst
        first = np.floor(ep_a.t_gpst / interval_s + 1.0 + GRID_TOLERANCE_S) * interval_s
        grid = np.arange(first, ep_b.t_gpst - GRID_TOLERANCE_S, interval_s)
        if span > max_gap_s + GRID_TOLERANCE_S or masters[k] != masters[k + 1] or not grid.size:
            continue
        # satellites continuous from a to b on each frequency: present at both, same signal, no loss of lock at b
        common, ia, ib = np.intersect1d(ep_a.sats, ep_b.sats, return_indices=True)
        ok = (np.isfinite(ep_a.code_m[ia]) & np.isfinite(ep_b.code_m[ib]) & np.isfinite(ep_a.phase_cyc[ia])
              & np.isfinite(ep_b.phase_cyc[ib]) & ((ep_b.lli[ib] & 1) == 0) & (ep_a.codes[ia] == ep_b.codes[ib]))
        keep = ok.all(axis=1)
        if not keep.any():
            continue
        ia, ib = ia[keep], ib[keep]
        lam_a = C / ep_a.freq_hz[ia]
        nav_ab = nav.pinned(ep_a.sats[ia], ep_a.t_gpst)  # one ephemeris set per satellite from a to b
        ma = _model(ep_a.subset(ia), ep_a.t_gpst, clocks_s[k], point, nav_ab)[:, None]
        mb = _model(ep_b.subset(ib), ep_b.t_gpst, clocks_s[k + 1], point, nav_ab)[:, None]
        rc_a, rc_b = ep_a.code_m[ia] - ma, ep_b.code_m[ib] - mb
        rl_a, rl_b = ep_a.phase_cyc[ia] * lam_a - ma, ep_b.phase_cyc[ib] * lam_a - mb
        sub = ep_a.subset(ia)
        for t in grid:
            w = (t - ep_a.t_gpst) / span
            clk = clocks_s[k] + (clocks_s[k + 1] - clocks_s[k]) * w
            m = _model(sub, float(t), clk, point, nav_ab)[:, None]
            code = m + rc_a + (rc_b - rc_a) * w
            phase = (m + rl_a + (rl_b - rl_a) * w) / lam_a
            out.append(StationEpoch(ep_a.station, float(t), sub.sats, code, phase, np.zeros_like(sub.lli),
                                    sub.cnr_dbhz, sub.freq_hz, sub.codes))
            added += 1
    return out, added

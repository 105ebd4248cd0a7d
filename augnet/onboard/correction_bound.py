"""The centre's bound on its correction error (RTCM 4001) at the train: kept per epoch, carried to the axes.

The centre sends, after each VRS epoch, an overbound sigma of the error of that epoch's corrections per
satellite (docs/correction-bound-message.md, decision 0280). `CorrectionBounds` keeps the received
messages by epoch; `sigmas(t, sats)` gives the bound of the corrections of the base epoch t the solution
used. While bounds are received, a used satellite without one - or a base epoch whose 4001 never came
(stale: the bound of *those* corrections is unknown) - is NaN, and `integrity_allocation.
correction_sigma_on_axis` turns a NaN of a used satellite into an infinite PL (decision 0280: unbounded,
never exact). Before any 4001 (a mountpoint that does not send it), `sigmas` is None: the PLs are what they
were (decision 0281).

`dd_position_gain` is the gain from each satellite's correction error to the position: the weighted
least-squares solution of the epoch's DD phase rows (the geometry and weights the RTK filter used). The
centre's sigma is of satellite j's DD correction error e_j against the centre's reference satellite; a
rover DD of j against its own reference r carries e_j - e_r, so row gains are summed per satellite with
that sign (exact for any reference choice, no correlation assumed). A slot on another frequency carries the
ionospheric part scaled by mu = (f1/f)^2 >= 1: its row counts mu times (an overbound of the troposphere's
1). The snapshot gain stands for the filter's: the correction errors are biases correlated over minutes
(decision 0280's 60-epoch window), which a Kalman filter averages no better than the snapshot solution.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

from augnet.gnss.rtcm.correction_bound import CorrectionBoundMessage

# Epochs of bounds kept: the base epoch a rover epoch uses is at most the filter's age limit old (rtk.py
# max_age_s, 30 s by default) and the runs are 1 Hz.
BOUND_EPOCHS_KEPT = 64
MS_PER_WEEK = 604_800_000


def epoch_key(t_gpst: float) -> int:
    """A GPST instant as the 4001's epoch field: GPS time of week [ms] (as the VRS's MSM, `msm_epoch_ms`)."""
    return int(round(float(t_gpst) * 1000.0)) % MS_PER_WEEK


class CorrectionBounds:
    """The 4001 bounds received on one correction stream, by epoch."""

    def __init__(self, kept: int = BOUND_EPOCHS_KEPT):
        self.kept = kept
        self.received = 0  # 4001 messages taken
        self._by_epoch: collections.OrderedDict[int, dict[str, float]] = collections.OrderedDict()

    def add(self, msg: CorrectionBoundMessage) -> None:
        """One message (a client with many satellites gets several per epoch: merged)."""
        got = self._by_epoch.setdefault(int(msg.epoch_ms), {})
        got.update({s: float(v) for s, v in zip(msg.sats, np.asarray(msg.sigma_m, float))})
        self._by_epoch.move_to_end(int(msg.epoch_ms))
        while len(self._by_epoch) > self.kept:
            self._by_epoch.popitem(last=False)
        self.received += 1

    @property
    def receiving(self) -> bool:
        """Bounds come on this stream: from now on a missing one means unbounded corrections."""
        return self.received > 0

    def has_epoch(self, t_gpst: float) -> bool:
        return epoch_key(t_gpst) in self._by_epoch

    def sigmas(self, t_gpst: float, sats) -> np.ndarray | None:
        """Overbound sigma [m] per satellite of the corrections of base epoch `t_gpst` (NaN: none, or the
        epoch's 4001 missing); None when this stream never carried a 4001."""
        if not self.receiving:
            return None
        got = self._by_epoch.get(epoch_key(t_gpst), {})
        return np.array([got.get(str(s), math.nan) for s in sats], dtype=float)

    def reset(self) -> None:
        """A new correction session (another base): its bounds, if any, start afresh."""
        self.received = 0
        self._by_epoch.clear()


@dataclass(frozen=True)
class DDGeometry:
    """The DD phase rows an RTK epoch used: satellites, rover line of sight, rows (satellite, reference,
    slot, group), SD phase variances [m^2] and the ionosphere's scale per satellite and slot."""

    sats: list[str]
    los: np.ndarray  # (n, 3) unit vectors rover -> satellite, ECEF
    k: np.ndarray  # (m,) row satellite (index into sats)
    ref: np.ndarray  # (m,) row reference satellite
    f: np.ndarray  # (m,) slot
    group: np.ndarray  # (m,) group (a reference's rows share it)
    var_sd: np.ndarray  # (n, nf)
    mu: np.ndarray  # (n, nf) (f1 / f)^2


def dd_position_gain(geo: DDGeometry) -> np.ndarray:
    """(3, n) ECEF position change per metre of each satellite's DD correction error (see the module)."""
    n, m = len(geo.sats), len(geo.k)
    out = np.zeros((3, n))
    if m < 3:
        return np.full((3, n), np.nan) if m else out
    k, ref, f = geo.k, geo.ref, geo.f
    H = -(geo.los[k] - geo.los[ref])
    same = geo.group[:, None] == geo.group[None, :]
    R = np.diag(geo.var_sd[k, f]) + same * geo.var_sd[ref, f][:, None]
    W = np.linalg.inv(R)
    N = H.T @ W @ H
    if np.linalg.cond(N) > 1e12:
        return np.full((3, n), np.nan)
    G = np.linalg.solve(N, H.T @ W)  # (3, m): position per metre of each row
    scale = np.maximum(geo.mu[k, f], 1.0)
    np.add.at(out.T, k, (G * scale).T)
    np.add.at(out.T, ref, -(G * scale).T)
    return out


__all__ = ["BOUND_EPOCHS_KEPT", "CorrectionBounds", "DDGeometry", "dd_position_gain", "epoch_key"]

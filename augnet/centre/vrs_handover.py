"""A VRS keeps its carrier phase continuous when its master station changes (decision 0223).

A VRS inherits its master's ambiguities (vrs.py): a point whose master changes from m1 to m2 would see every
satellite's phase jump by the single-difference ambiguity m2 - m1 plus the clock difference, and a rover would
have to fix again at every midpoint between two stations. Where the network has fixed the DD integers between
m1 and m2 (`NetworkEpoch.dd_n`, chained over its baselines, satellite minus the system's reference), the
handover subtracts, per satellite s and frequency k,

    offset_s,k = N_s,k(m2) - N_s,k(m1) + C_sys,k

from the VRS phase from then on (accumulated over later changes), where the DD integer keeps every double
difference continuous and C, one number per system and frequency, is the mean over the handed-over satellites
of the jump left in phase minus code (lambda_k L_k - P_1, free of geometry and clocks): a common term, it
cancels in the rover's double differences; it keeps the phase beside the code (MSM carries the phase within
+-1171 m of it) and, being the same mean of the same code on both frequencies, leaves the geometry-free
combination (a rover's slip test) continuous to millimetres. The code jumps by the masters' clock difference
and multipath: it has no ambiguity, and the clock cancels in the double differences.

Satellites whose m1 - m2 integers are not fixed, or that slip at m2 at the change, are flagged loss-of-lock
(a restart, as every satellite was before). Integers come from the change's network epoch when it still has
m1, else from the previous one (m1 deleted or without data).
"""

from __future__ import annotations

import numpy as np

from augnet.centre.network import NetworkEpoch
from augnet.centre.vrs import VrsEpoch
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S

# The previous VRS epoch of the point must be this recent: phase minus code drifts with the ionosphere (mm/s)
# and the last epoch's value stands for the change's; a longer gap is a restart anyway for most rovers.
MAX_GAP_S = 5.0
LLI_LOSS_OF_LOCK = 1  # RINEX LLI bit 0: what the stream encoder restarts a lock on


class MasterHandover:
    """Per session (key): its master, its phase offsets since its last restart, and last epoch's phase minus
    code; `apply` hands each changed session over, in place on the VRS epoch."""

    def __init__(self):
        self.masters: dict = {}  # key -> master station of the last epoch
        self._offsets: dict = {}  # key -> {satellite: (2,) cycles subtracted from the VRS phase}
        self._last: dict = {}  # key -> (t, {satellite: ((2,) phase minus code [m], (2,) codes)})
        self._ints: list = []  # the last two network epochs' (stations, sats, dd_n)
        self.kept = 0  # satellites handed over (for the log and the tests)
        self.restarted = 0  # satellites restarted at a handover

    def remove(self, key) -> None:
        self.masters.pop(key, None)
        self._offsets.pop(key, None)
        self._last.pop(key, None)

    def apply(self, keys: list, vrs: VrsEpoch, net: NetworkEpoch) -> np.ndarray:
        """Hand over the sessions `keys` (rows of `vrs`) whose master changed; apply every session's offsets.
        Sets and returns `vrs.handed_over`."""
        T = len(keys)
        self._ints = (self._ints + [_integers(net)])[-2:]
        handed = np.zeros(T, bool)
        lam = SPEED_OF_LIGHT_M_S / vrs.freq_hz
        sats = [str(s) for s in vrs.sats]
        for i, k in enumerate(keys):
            m = vrs.master[i]
            old = self.masters.get(k)
            if old is not None and old != m:
                handed[i] = self._hand_over(i, k, old, m, vrs, sats, lam)
                if not handed[i]:
                    self._offsets.pop(k, None)
            self.masters[k] = m
            off = self._offsets.get(k)
            if off:
                for j, s in enumerate(sats):
                    o = off.get(s)
                    if o is not None:
                        vrs.phase_cyc[i, j] -= o
        phi = lam[None] * vrs.phase_cyc - _code1(vrs.code_m)[..., None]
        for i, k in enumerate(keys):
            ok = np.flatnonzero(np.isfinite(phi[i]).all(axis=1))
            self._last[k] = (vrs.t_gpst, {sats[j]: (phi[i, j], vrs.codes[j]) for j in ok})
        vrs.handed_over = handed
        return handed

    def _hand_over(self, i: int, key, old: str, new: str, vrs: VrsEpoch, sats: list, lam: np.ndarray) -> bool:
        last = self._last.get(key)
        if last is None or vrs.t_gpst - last[0] > MAX_GAP_S:
            return False
        ints = next((x for x in reversed(self._ints) if old in x[0] and new in x[0]), None)
        if ints is None:
            return False
        stations, col, dd_n = ints
        n_old, n_new = dd_n[stations.index(old)], dd_n[stations.index(new)]
        phi_now = lam * vrs.phase_cyc[i] - _code1(vrs.code_m[i])[:, None]  # raw: before any offset
        before = self._offsets.get(key) or {}  # what the last epoch's phase had subtracted
        cand, x, delta = [], [], []
        for j, s in enumerate(sats):
            prev, c = last[1].get(s), col.get(s)
            if prev is None or c is None or not np.isfinite(phi_now[j]).all() or np.any(vrs.lli[i, j] & 1):
                continue
            if np.any(prev[1] != vrs.codes[j]):  # another signal: another phase
                continue
            dn = n_new[c] - n_old[c] + before.get(s, 0.0)
            if not np.isfinite(dn).all():
                continue
            cand.append(j)
            delta.append(dn)
            x.append((phi_now[j] - prev[0]) / lam[j] - dn)
        if not cand:
            return False
        cand, x, delta = np.array(cand), np.array(x), np.array(delta)
        system = np.array([sats[j][0] for j in cand])
        offsets = {}
        for sys_ in set(system.tolist()):
            w = system == sys_
            common = x[w].mean(axis=0)  # (2,) cycles: the one jump the double differences do not see
            for j, dn in zip(cand[w], delta[w]):
                offsets[sats[j]] = dn + common
        self._offsets[key] = offsets
        have = np.isfinite(vrs.phase_cyc[i]).any(axis=1)
        restart = have & ~np.isin(np.arange(len(sats)), cand)
        vrs.lli[i, restart] |= LLI_LOSS_OF_LOCK
        self.kept += len(cand)
        self.restarted += int(restart.sum())
        return True


def _code1(code_m: np.ndarray) -> np.ndarray:
    """The first frequency's code (the second's where the first is missing): one code for both frequencies'
    phase minus code, so that its error cancels in their geometry-free combination."""
    return np.where(np.isfinite(code_m[..., 0]), code_m[..., 0], code_m[..., 1])


def _integers(net: NetworkEpoch):
    if net is None or net.dd_n is None:
        return ([], {}, np.zeros((0, 0, 2)))
    return (list(net.stations), {str(s): k for k, s in enumerate(net.sats)}, net.dd_n)

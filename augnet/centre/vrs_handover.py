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

# The previous VRS epoch (the point must be in it) must be this recent: phase minus code drifts with the
# ionosphere (mm/s) and the last epoch's value stands for the change's; a longer gap restarts most rovers anyway.
MAX_GAP_S = 5.0
LLI_LOSS_OF_LOCK = 1  # RINEX LLI bit 0: what the stream encoder restarts a lock on


def _capacity(have: int, need: int, least: int) -> int:
    """An array axis's new length: unchanged while it holds `need`, else doubled (amortised growth)."""
    return have if need <= have else max(need, 2 * have, least)


class MasterHandover:
    """Per session (key): its master and its phase offsets since its last restart (dense, a row per session and a
    column per satellite ever seen); and the last epoch's phase minus code of every session. `apply` hands each
    changed session over, in place on the VRS epoch: a few array operations per epoch for thousands of
    sessions, only a handover walks its satellites."""

    def __init__(self):
        self.masters: dict = {}  # key -> master station of the last epoch
        self._rows: dict = {}  # key -> row of the offsets
        self._free_rows: list[int] = []
        self._cols: dict[str, int] = {}  # satellite -> column of the offsets
        self._off = np.zeros((0, 0, 2))  # cycles subtracted from the VRS phase
        self._has_off = np.zeros(0, bool)  # rows with any offset
        # the last epoch: (t, key -> row, satellite -> column, (T, S, 2) phase minus code [m], (S, 2) signals)
        self._last: tuple | None = None
        self._ints: list = []  # the last two network epochs' (stations, sats, dd_n)
        self.kept = 0  # satellites handed over (for the log and the tests)
        self.restarted = 0  # satellites restarted at a handover

    def _grow(self, rows: int, cols: int) -> None:
        r0, k0 = self._off.shape[:2]
        if rows <= r0 and cols <= k0:
            return
        r1, k1 = _capacity(r0, rows, 16), _capacity(k0, cols, 64)
        off, has = np.zeros((r1, k1, 2)), np.zeros(r1, bool)
        off[:r0, :k0], has[:r0] = self._off, self._has_off
        self._off, self._has_off = off, has

    def _row(self, key) -> int:
        r = self._rows.get(key)
        if r is None:
            r = self._rows[key] = self._free_rows.pop() if self._free_rows else len(self._rows)
            self._grow(r + 1, len(self._cols))
            self._off[r], self._has_off[r] = 0.0, False
        return r

    def remove(self, key) -> None:
        self.masters.pop(key, None)
        r = self._rows.pop(key, None)
        if r is not None:
            self._free_rows.append(r)

    def apply(self, keys: list, vrs: VrsEpoch, net: NetworkEpoch) -> np.ndarray:
        """Hand over the sessions `keys` (rows of `vrs`) whose master changed; apply every session's offsets.
        Sets and returns `vrs.handed_over`."""
        T = len(keys)
        self._ints = (self._ints + [_integers(net)])[-2:]
        sats = [str(s) for s in vrs.sats]
        for s in sats:
            if s not in self._cols:
                self._cols[s] = len(self._cols)
        rows = np.array([self._row(k) for k in keys], dtype=int)
        self._grow(len(self._rows), len(self._cols))
        cols = np.array([self._cols[s] for s in sats], dtype=int)
        handed = np.zeros(T, bool)
        lam = SPEED_OF_LIGHT_M_S / vrs.freq_hz
        masters = self.masters
        for i, k in enumerate(keys):
            m = vrs.master[i]
            old = masters.get(k)
            if old != m:
                if old is not None:
                    handed[i] = self._hand_over(i, k, rows[i], old, m, vrs, sats, cols, lam)
                    if not handed[i]:
                        self._off[rows[i]], self._has_off[rows[i]] = 0.0, False
                masters[k] = m
        has = self._has_off[rows]
        if has.any() and cols.size:
            vrs.phase_cyc[has] -= self._off[np.ix_(rows[has], cols)]
        phi = lam[None] * vrs.phase_cyc - _code1(vrs.code_m)[..., None]
        self._last = (vrs.t_gpst, dict(zip(keys, range(T))), dict(zip(sats, range(len(sats)))), phi, vrs.codes)
        vrs.handed_over = handed
        return handed

    def _hand_over(self, i: int, key, row: int, old: str, new: str, vrs: VrsEpoch, sats: list, cols: np.ndarray,
                   lam: np.ndarray) -> bool:
        last = self._last
        if last is None or not vrs.t_gpst - last[0] <= MAX_GAP_S or key not in last[1]:
            return False
        ints = next((x for x in reversed(self._ints) if old in x[0] and new in x[0]), None)
        if ints is None:
            return False
        stations, col, dd_n = ints
        n_old, n_new = dd_n[stations.index(old)], dd_n[stations.index(new)]
        phi_now = lam * vrs.phase_cyc[i] - _code1(vrs.code_m[i])[:, None]  # raw: before any offset
        prev_phi, last_col, prev_codes = last[3][last[1][key]], last[2], last[4]
        before = self._off[row, cols]  # what the last epoch's phase had subtracted
        cand, x, delta = [], [], []
        for j, s in enumerate(sats):
            c, p = col.get(s), last_col.get(s)
            if c is None or p is None or not np.isfinite(phi_now[j]).all() or not np.isfinite(prev_phi[p]).all() \
                    or np.any(vrs.lli[i, j] & 1) or np.any(prev_codes[p] != vrs.codes[j]):  # another signal
                continue
            dn = n_new[c] - n_old[c] + before[j]
            if not np.isfinite(dn).all():
                continue
            cand.append(j)
            delta.append(dn)
            x.append((phi_now[j] - prev_phi[p]) / lam[j] - dn)
        if not cand:
            return False
        cand, x, delta = np.array(cand), np.array(x), np.array(delta)
        system = np.array([sats[j][0] for j in cand])
        self._off[row] = 0.0
        for sys_ in set(system.tolist()):
            w = system == sys_
            common = x[w].mean(axis=0)  # (2,) cycles: the one jump the double differences do not see
            self._off[row, cols[cand[w]]] = delta[w] + common
        self._has_off[row] = True
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

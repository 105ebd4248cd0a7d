"""Integer decisions on a baseline's DD ambiguities: search, confirmation, hold and release.

Per epoch, over the DD ambiguities not yet fixed (both frequencies, satellites above `fix_min_elevation_deg`):

1. the float solution, conditioned on the DD ionosphere pseudo-observations of the prior in force and the
   network's hints (`ionosphere_prior.py`): this is what rejects the near-equivalent integer pairs (e.g. N1 + 7,
   Nw - 2 on GPS L1/L2; (3, 4) on Galileo E1/E5a) that the ionosphere-free phase alone cannot tell apart;
2. a wide-lane pre-transform, then LAMBDA with partial fixing (`augnet.gnss.ambiguity.partial_fix`: ratio test and
   bootstrapped success rate);
3. the float solution conditioned on the fixed subset: a DD ambiguity (or a wide lane on its own) it pins to an
   integer is a candidate, fixed once confirmed (`integer_streaks.py`);
4. fixed integers are held as tight pseudo-observations (fix and hold), a new satellite is fixed against the held
   ones, and fixed ones are released when their phase residuals stop supporting them.
"""

from __future__ import annotations

import math

import numpy as np

from augnet.centre.baseline_config import BaselineConfig, fix_policy
from augnet.centre.baseline_state import IONO, N1, ZWD_A, ZWD_B, dd_indices
from augnet.centre.integer_streaks import IntegerStreaks
from augnet.centre.baseline_integers import ALL_TABLES, FREQUENCY_TABLES, WIDE_LANE, BaselineIntegers
from augnet.centre.single_differences import SingleDifferences
from augnet.gnss.ambiguity import AmbiguityError, partial_fix
from augnet.gnss.state_layout import StateLayout

# A conditioned ambiguity is pinned when within this many of its sigmas of the integer
PINNED_SIGMAS = 3
# A hold is applied where the held combination's variance is above this many times the hold's own (new or reset)
HOLD_APPLIED_ABOVE = 2.0


def wide_lane_transform(cands: list[tuple[int, int]]) -> tuple[np.ndarray, dict[tuple[int, int], int]]:
    """Per satellite with both frequencies among the candidates (k, table), (N1, N2) -> (N1 - N2, N1): an
    integer unimodular map. The wide lane is far better determined than N1 and N2, which are ionosphere-limited;
    starting from it leaves LAMBDA's reduction a fraction of the permutations. Returns T and (k, table) -> row."""
    T = np.eye(len(cands))
    where = {kf: i for i, kf in enumerate(cands)}
    for i, (k, fq) in enumerate(cands):
        j = where.get((k, 1))
        if fq == 0 and j is not None:
            T[j, :] = 0.0
            T[j, i], T[j, j] = 1.0, -1.0  # row of N2 becomes N1 - N2
    return T, where


def conditioned_on_fix(a_hat: np.ndarray, Q: np.ndarray, Zs: np.ndarray,
                       z_fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The float ambiguities and covariance given the fixed integer combinations Zs^T a = z_fixed."""
    S = Zs.T @ Q @ Zs
    K = np.linalg.solve(S, Zs.T @ Q).T
    return a_hat - K @ (Zs.T @ a_hat - z_fixed), Q - K @ Zs.T @ Q


def pinned(value: float, sigma: float, max_sigma: float) -> int | None:
    """The integer a conditioned ambiguity is pinned to, or None."""
    n = int(round(value))
    return n if sigma <= max_sigma and abs(value - n) < PINNED_SIGMAS * max_sigma else None


def _pinned_mask(value: np.ndarray, sigma: np.ndarray, max_sigma: float) -> np.ndarray:
    """`pinned` element-wise: True where the value is pinned to its nearest integer."""
    return (sigma <= max_sigma) & (np.abs(value - np.round(value)) < PINNED_SIGMAS * max_sigma)


def conditioned_on_pseudo_observations(x, P, D, a_hat, Q, H, z, var):
    """The float ambiguities D x (a_hat, Q) given pseudo-observations z = H x + e, e ~ N(0, diag(var)).
    D and H: dense matrices, or (plus, minus) index pairs of rows x[plus] - x[minus] (the same numbers, without
    the products by zero: a sum of a, -b and zeros is a - b in any order)."""
    if isinstance(H, tuple):
        PHt = P[:, H[0]] - P[:, H[1]]
        S = (PHt[H[0]] - PHt[H[1]]) + np.diag(var)
        Hx = x[H[0]] - x[H[1]]
    else:
        PHt = P @ H.T
        S = H @ PHt + np.diag(var)
        Hx = H @ x
    DPHt = PHt[D[0]] - PHt[D[1]] if isinstance(D, tuple) else D @ PHt
    try:
        G = np.linalg.solve(S, DPHt.T).T  # D P H^T S^-1
    except np.linalg.LinAlgError:
        return a_hat, Q
    return a_hat + G @ (z - Hx), Q - G @ DPHt.T


def dd_ambiguity_rows(state: StateLayout, sats, ks, ref_k, table: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows picking DD ambiguities out of the state, as (columns, values), four per row: N1, N2 or the wide lane
    N1 - N2."""
    ps, pr = dd_indices(state, sats, ks, ref_k, 0)
    one = np.ones(len(ks))
    if table != WIDE_LANE:
        return (np.column_stack([ps + N1 + table, pr + N1 + table, ps, ps]),
                np.column_stack([one, -one, 0 * one, 0 * one]))
    return (np.column_stack([ps + N1, pr + N1, ps + N1 + 1, pr + N1 + 1]),
            np.column_stack([one, -one, -one, one]))


class BaselineAmbiguities:
    """A baseline's fixed DD integers and the decisions that make, hold and release them."""

    def __init__(self, cfg: BaselineConfig):
        self.cfg = cfg
        self.fixed = BaselineIntegers()
        self.confirmation = IntegerStreaks(cfg.fix_confirm_epochs, cfg.fix_confirm_epochs_sure)
        self._bad_streak: dict[str, int] = {}  # sat -> epochs its fixed DD's residual has been too large

    def forget(self, sat: str) -> None:
        """A new arc: nothing about the satellite is kept."""
        self.fixed.forget(sat)
        self.confirmation.forget(sat)
        self._bad_streak.pop(sat, None)

    def restart(self, sat: str) -> None:
        """The satellite's ambiguities restart (a slip or a release): its integers and candidates go."""
        self.fixed.forget(sat)
        self.confirmation.forget(sat)

    def rereference(self, system: str, old: str, new: str) -> None:
        self.fixed.rereference(system, old, new)
        self.confirmation.forget_system(system)

    # --- fix and hold ---------------------------------------------------------------------------------

    def hold_rows(self, state: StateLayout, sats, rows, ref_k):
        """The fixed DD integers as pseudo-observations (columns, values, integers), where their state is not
        already held (ambiguities have no process noise: a held one stays held after one update, so the hold
        is applied where it is new or the state was reset); None if there are none. A wide lane is held on its
        own where the satellite's narrow lane is still open."""
        cs, vs, zs = [], [], []
        for table in ALL_TABLES:
            fixed = self.fixed.table(table)
            held = [k for k in rows if str(sats[k]) in fixed]
            if table == WIDE_LANE:
                held = [k for k in held if not self.fixed.both(str(sats[k]))]
            if not held:
                continue
            c, v = dd_ambiguity_rows(state, sats, held, ref_k, table)
            cs.append(c)
            vs.append(v)
            zs.append(np.array([fixed[str(sats[k])] for k in held], float))
        if not cs:
            return None
        cols, vals, zh = np.vstack(cs), np.vstack(vs), np.concatenate(zs)
        Pc = state.P[cols[:, :, None], cols[:, None, :]]  # (rows, 4, 4) in one gather; summed in the same order
        var = np.zeros(len(zh))
        for i in range(cols.shape[1]):
            for j in range(cols.shape[1]):
                var += vals[:, i] * vals[:, j] * Pc[:, i, j]
        new = var > HOLD_APPLIED_ABOVE * self.cfg.hold_sigma_cyc**2
        if not new.any():
            return None
        return cols[new], vals[new], zh[new]

    def releases(self, state: StateLayout, sd: SingleDifferences, rows, ref_k) -> list[str]:
        """Post-fit DD phase residuals of fixed satellites: a wrong fix shows as a persistent residual. Returns the
        satellites to release (their ambiguities must start afresh: the hold has pinned their states to the
        integers let go)."""
        cfg = self.cfg
        x = state.x
        out = []
        for k in rows:
            s = str(sd.sats[k])
            if not self.fixed.any_frequency(s):
                continue
            r = ref_k[k]
            p, q = state.index(s), state.index(str(sd.sats[r]))
            trop = (-(sd.ga.wet_mapping[k] - sd.ga.wet_mapping[r]) * x[ZWD_A]
                    + (sd.gb.wet_mapping[k] - sd.gb.wet_mapping[r]) * x[ZWD_B])
            d_iono = x[p + IONO] - x[q + IONO]
            worst = 0.0
            for fq, icoef in ((0, 1.0), (1, sd.gamma[k])):
                fixed = self.fixed.table(fq)
                if s not in fixed:
                    continue
                pred = trop - icoef * d_iono + sd.wavelength_m[k, fq] * fixed[s]
                worst = max(worst, abs(sd.phase_m[k, fq] - sd.phase_m[r, fq] - pred))
            if worst > cfg.release_residual_m:
                self._bad_streak[s] = self._bad_streak.get(s, 0) + 1
                if self._bad_streak[s] >= cfg.release_epochs:
                    out.append(s)
                    self._bad_streak[s] = 0
            else:
                self._bad_streak[s] = 0
        return out

    # --- the integer decision ---------------------------------------------------------------------------

    def decide(self, state: StateLayout, sats, rows, ref_k, pseudo_obs: dict | None, commit: bool) -> float:
        """One epoch's decision over the DD ambiguities of `rows` not yet fixed; commits confirmed integers when
        `commit`. Returns the partial fix's ratio (0 without one)."""
        cfg = self.cfg
        cands, ia, ib = self._searchable(state, sats, rows, ref_k)
        held = self.fixed.frequency_count()
        min_count = cfg.fix_min_count if held < cfg.fix_min_count else min(cfg.fix_min_count, cfg.fix_min_count_held)
        if len(cands) < min_count:
            return 0.0
        P = state.P
        a_hat = state.x[ia] - state.x[ib]
        DP = P[ia] - P[ib]
        Q = DP[:, ia] - DP[:, ib]
        if pseudo_obs:
            a_hat, Q = self._with_pseudo_observations(state, sats, rows, ref_k, pseudo_obs, cands, ia, ib, a_hat, Q)
        T, where = wide_lane_transform(cands)
        try:
            fix = partial_fix(T @ a_hat, T @ Q @ T.T, fix_policy(cfg, min_count))
        except AmbiguityError:
            fix = None
        pins = self._pinned(sats, cands, where, a_hat, Q, T, fix) if fix is not None else {}
        wide_lanes = [(k, WIDE_LANE) for k, fq in cands
                      if fq == 0 and (k, 1) in where and str(sats[k]) not in self.fixed.wide_lane]
        sure = fix is not None and fix.success_rate >= cfg.fix_sure_success_rate
        self._confirm(sats, cands + wide_lanes, pins, sure, commit)
        for k, _ in wide_lanes:
            s = str(sats[k])
            if self.fixed.both(s):
                self.fixed.wide_lane[s] = self.fixed.n1[s] - self.fixed.n2[s]
        return fix.ratio if fix is not None else 0.0

    def _searchable(self, state: StateLayout, sats, rows, ref_k):
        """The open DD ambiguities (k, table), frequency by frequency, certain enough to enter the search, with
        the state indices of the satellite's and the reference's (DD ambiguity = x[ia] - x[ib]). The others'
        candidates are dropped."""
        cands = [(k, fq) for fq in FREQUENCY_TABLES for k in rows if str(sats[k]) not in self.fixed.table(fq)]
        ia = np.array([state.index(str(sats[k])) + N1 + fq for k, fq in cands], dtype=int)
        ib = np.array([state.index(str(sats[ref_k[k]])) + N1 + fq for k, fq in cands], dtype=int)
        P = state.P
        ready = P[ia, ia] + P[ib, ib] - 2.0 * P[ia, ib] <= self.cfg.search_max_sigma_cyc**2
        for i in np.flatnonzero(~ready):
            k, fq = cands[i]
            self.confirmation.clear(str(sats[k]), fq)
        return [c for c, r in zip(cands, ready) if r], ia[ready], ib[ready]

    def _with_pseudo_observations(self, state, sats, rows, ref_k, pseudo_obs, cands, ia, ib, a_hat, Q):
        """The float ambiguities conditioned on the DD ionosphere pseudo-observations of satellites not fixed."""
        hs = []
        for k in rows:
            s = str(sats[k])
            h = pseudo_obs.get(s)
            if h is None or h[0] != str(sats[ref_k[k]]) or self.fixed.both(s):
                continue
            hs.append((state.index(s) + IONO, state.index(h[0]) + IONO, h[1], h[2]))
        if not hs:
            return a_hat, Q
        H = (np.array([h[0] for h in hs], dtype=int), np.array([h[1] for h in hs], dtype=int))
        return conditioned_on_pseudo_observations(state.x, state.P, (ia, ib), a_hat, Q, H,
                                                  np.array([h[2] for h in hs]), [h[3] for h in hs])

    def _pinned(self, sats, cands, where, a_hat, Q, T, fix) -> dict[tuple[int, int], int]:
        """(k, table) -> integer for the DD ambiguities the conditioned solution pins, and the wide lanes it pins
        where the satellite's wide lane is open (N1 and N2 need not be pinned on their own)."""
        sigma = self.cfg.pinned_sigma_cyc
        a_cond, Qc = conditioned_on_fix(a_hat, Q, T.T @ fix.Zs, fix.z_fixed)  # Zs in terms of (N1, N2)
        sig = np.sqrt(np.clip(np.diag(Qc), 0.0, None))
        out = {}
        for i in np.flatnonzero(_pinned_mask(a_cond, sig, sigma)):  # `pinned`, on the whole vector
            out[cands[i]] = int(np.round(a_cond[i]))
        pairs = [(i, where[(k, 1)], k) for i, (k, fq) in enumerate(cands)
                 if fq == 0 and (k, 1) in where and str(sats[k]) not in self.fixed.wide_lane]
        if pairs:
            i, j = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
            w = a_cond[i] - a_cond[j]
            sig_w = np.sqrt(np.maximum(Qc[i, i] + Qc[j, j] - 2 * Qc[i, j], 0.0))
            for n in np.flatnonzero(_pinned_mask(w, sig_w, sigma)):
                out[(pairs[n][2], WIDE_LANE)] = int(np.round(w[n]))
        return out

    def _confirm(self, sats, decisions, pins, sure: bool, commit: bool) -> None:
        """Count each decision's streak; fix the confirmed ones when `commit`."""
        for k, table in decisions:
            s = str(sats[k])
            val = pins.get((k, table))
            if val is None:
                self.confirmation.clear(s, table)
            elif self.confirmation.observe(s, table, val, sure) and commit:
                self.fixed.table(table)[s] = val

"""Fix confirmation: an integer fix is declared only when consecutive epochs' validated decisions agree.

A float solution biased by unmodelled atmosphere can pass one epoch's ratio and success-rate tests by
chance; it rarely passes them with the same integers epoch after epoch.  An epoch's decision is kept
as integer functionals C a = z of identified ambiguity states a: each DD ambiguity the fix determines
(sigma below DETERMINED_SIGMA_CYC) and the fixed decorrelated combinations themselves (what a partial
fix determines).  The next epoch agrees when every functional it can evaluate and determines has the
same integer, and there are at least `min_count` of them.  A state re-initialised since (a slip: a new
arc under the same satellite and slot) is, like a satellite risen since, not comparable: its
functionals are left out.

States are named by an identity the caller chooses (e.g. (satellite, slot, arc serial)); `index_of`
maps an identity to its state index this epoch, or -1 when it is gone.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass

import numpy as np

from augnet.gnss.ambiguity import DETERMINED_SIGMA_CYC

# Two decisions agree on a functional when their values differ by less than half a cycle (same integer).
SAME_INTEGER_CYC = 0.5


@dataclass(frozen=True)
class IntegerDecision:
    """One epoch's integer decision: C a = z over the states named in `states` (one per column of C)."""

    states: tuple[Hashable, ...]
    C: np.ndarray  # (r, c) integer coefficients
    z: np.ndarray  # (r,) integers, as floats

    @classmethod
    def from_fix(cls, identity: Callable[[int], Hashable], i: np.ndarray, iref: np.ndarray, Hc: np.ndarray,
                 z_fixed: np.ndarray, x_fix: np.ndarray, P_fix: np.ndarray,
                 max_sigma_cyc: float = DETERMINED_SIGMA_CYC) -> "IntegerDecision":
        """The decision of a fix Hc x = z_fixed (rows over the full state) with fixed state x_fix, P_fix:
        the DD ambiguities x[i] - x[iref] it determines, then its fixed combinations.  `identity` names the
        state of a column of Hc."""
        var = P_fix[i, i] + P_fix[iref, iref] - 2.0 * P_fix[i, iref]
        det = np.flatnonzero(var < max_sigma_cyc**2)
        # a DD ambiguity determined without a coefficient in the fix (held from earlier epochs) is a column too
        cols = np.union1d(np.flatnonzero(np.any(Hc != 0.0, axis=0)), np.concatenate((i[det], iref[det])))
        pos = {int(c): j for j, c in enumerate(cols)}
        C_dd = np.zeros((len(det), len(cols)))
        C_dd[np.arange(len(det)), [pos[int(c)] for c in i[det]]] = 1.0
        C_dd[np.arange(len(det)), [pos[int(c)] for c in iref[det]]] = -1.0
        z_dd = np.round(x_fix[i[det]] - x_fix[iref[det]])
        return cls(tuple(identity(int(c)) for c in cols), np.vstack((C_dd, Hc[:, cols])),
                   np.concatenate((z_dd, np.asarray(z_fixed, dtype=float))))

    def agrees(self, index_of: Callable[[Hashable], int], x: np.ndarray, P: np.ndarray, min_count: int,
               max_sigma_cyc: float = DETERMINED_SIGMA_CYC) -> bool:
        """Whether a later state (x, P) determines at least `min_count` of this decision's comparable
        functionals, all to the same integers."""
        idx = np.array([index_of(s) for s in self.states], dtype=int)
        usable = ~np.any((self.C != 0.0) & (idx < 0)[None, :], axis=1)
        if np.count_nonzero(usable) < min_count:
            return False
        present = idx >= 0
        Cu = self.C[np.ix_(usable, present)]
        ip = idx[present]
        val = Cu @ x[ip]
        var = np.einsum("ij,jk,ik->i", Cu, P[np.ix_(ip, ip)], Cu)
        det = var < max_sigma_cyc**2
        return (np.count_nonzero(det) >= min_count
                and bool(np.all(np.abs(val[det] - self.z[usable][det]) < SAME_INTEGER_CYC)))


class FixConfirmation:
    """Counts consecutive epochs whose validated (complete or partial) integer decisions agree."""

    def __init__(self, min_count: int):
        self.min_count = int(min_count)  # fewest agreeing functionals for two decisions to agree
        self.decision: IntegerDecision | None = None
        self.count = 0

    def reset(self) -> None:
        self.decision = None
        self.count = 0

    def observe(self, decision: IntegerDecision, index_of: Callable[[Hashable], int], x: np.ndarray,
                P: np.ndarray) -> int:
        """Take this epoch's decision (its fixed state x, P) and return the length of the agreeing streak
        it ends, this epoch included."""
        prev = self.decision
        agree = prev is not None and prev.agrees(index_of, x, P, self.min_count)
        self.count = self.count + 1 if agree else 1
        self.decision = decision
        return self.count

"""Integer ambiguity resolution: LAMBDA decorrelation and MLAMBDA search, validation, partial fixing.

The method is Teunissen's LAMBDA (J. Geodesy 70, 1995) with the search of Chang, Yang and Zhou's
MLAMBDA (J. Geodesy 79, 2005): factor the float covariance as Q = L^T D L (L unit lower triangular),
reduce it with integer Gauss transformations and permutations to a nearly diagonal Z^T Q Z, then enumerate
the integer vectors inside a shrinking ellipsoid in the decorrelated space, and map the best candidates back
with Z^-T. Validation uses the ratio test (second best over best squared norm) and the bootstrapped success
rate (Teunissen 1998), which is also what partial ambiguity resolution uses to pick a subset that can be fixed
reliably.

Written for this project from the published algorithms; nothing here touches I/O.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from math import inf, sqrt

import numpy as np

from augnet.gnss.statistics import chi2_quantile, normal_cdf

# A permutation in the reduction is only worth doing when it lowers D[j+1] by more than this (relative
# tolerance against round-off looping; Chang et al. 2005 use the same kind of guard).
_PERMUTE_TOLERANCE = 1e-6

try:  # compiled kernels when numba is there (a dependency); the plain versions otherwise
    from augnet.gnss import lambda_kernels as _kernels
except ImportError:  # pragma: no cover
    _kernels = None

DEFAULT_RATIO_THRESHOLD = 3.0  # RTKLIB's default pos2-arthres; common in commercial engines (2-3)
DEFAULT_MIN_SUCCESS_RATE = 0.999  # bootstrapped success rate asked of a (partial) fix
DEFAULT_MIN_COUNT = 4  # fewest ambiguities fixed (RTKLIB's minimum of 4 for a position)
# A float vector is called biased when its bootstrapped solution's norm fails a chi-square test at this
# false-alarm probability AND the RMS of the conditional fractions exceeds BIASED_FLOAT_RMS_CYC: with a
# success rate >= 0.999 every conditional sigma is below ~0.15 cycle, so 0.2 is well outside noise; the
# RMS test as well because under fix-and-hold the covariance is far below the true (time-correlated) error.
BIASED_FLOAT_FALSE_ALARM = 1e-6
BIASED_FLOAT_RMS_CYC = 0.2
# A DD ambiguity counts as determined by a fix when its conditional sigma is below this [cycles]: 0.05
# cycle leaves a rounding error probability below 1e-20.
DETERMINED_SIGMA_CYC = 0.05


class AmbiguityError(ValueError):
    """The covariance is not positive definite, or the inputs do not fit together."""


def ldl(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Factor a symmetric positive-definite Q as L^T diag(D) L with L unit lower triangular.

    Factoring from the last index means D[n-1] is the unconditional variance of the last component and
    D[k] the variance of component k conditioned on components k+1..n-1.  Computed by LAPACK's Cholesky:
    with J the order reversal, J Q J = C C^T gives Q = U U^T for the upper triangular U = J C J, so
    D = diag(U)^2 and L = diag(U)^-1 U^T; equal to `ldl_reference` to rounding, and two orders of
    magnitude faster for the 30-80 ambiguities of a multi-GNSS epoch.
    """
    Q = np.asarray(Q, dtype=float)
    if Q.ndim != 2 or Q.shape[0] != Q.shape[1]:
        raise AmbiguityError(f"covariance must be square, got {Q.shape}")
    if not np.all(np.isfinite(Q)):
        raise AmbiguityError("covariance is not positive definite")
    try:
        C = np.linalg.cholesky(Q[::-1, ::-1])
    except np.linalg.LinAlgError:
        raise AmbiguityError("covariance is not positive definite") from None
    U = C[::-1, ::-1]
    u = np.diag(U).copy()
    return U.T / u[:, None], u * u


def ldl_reference(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`ldl` by rank-one downdates in plain numpy (the reference the LAPACK form is tested against)."""
    A = np.array(Q, dtype=float, copy=True)
    n = A.shape[0]
    if A.shape != (n, n):
        raise AmbiguityError(f"covariance must be square, got {A.shape}")
    L = np.zeros((n, n))
    D = np.zeros(n)
    for i in range(n - 1, -1, -1):
        D[i] = A[i, i]
        if not D[i] > 0.0:
            raise AmbiguityError("covariance is not positive definite")
        row = A[i, : i + 1] / sqrt(D[i])
        # rank-one downdate of the leading block
        A[:i, :i] -= np.outer(row[:i], row[:i])
        L[i, : i + 1] = row / row[i]
    return L, D


def reduce(L: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """LAMBDA reduction: returns (L', D', Z) with Z unimodular and Z^T Q Z = L'^T diag(D') L'."""
    if _kernels is not None:
        return _kernels.reduce_kernel(np.ascontiguousarray(L, dtype=float), np.ascontiguousarray(D, dtype=float))
    return reduce_reference(L, D)


def reduce_reference(L: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reduction in plain numpy (the reference the compiled kernel is tested against)."""
    L = L.copy()
    D = D.copy()
    n = len(D)
    Z = np.eye(n)
    j = n - 2
    k = n - 2
    while j >= 0:
        if j <= k:
            _gauss_column(L, Z, j)
        delta = D[j] + L[j + 1, j] ** 2 * D[j + 1]
        if delta + _PERMUTE_TOLERANCE < D[j + 1]:
            _permute(L, D, j, delta, Z)
            k = j
            j = n - 2
        else:
            j -= 1
    return L, D, Z


def _gauss_column(L: np.ndarray, Z: np.ndarray, j: int) -> None:
    """Integer Gauss transformations of column j against columns j+1..n-1, in that order.

    The same result as calling `_gauss(L, Z, i, j)` for i = j+1..n-1, computed as a forward
    substitution: L is unit lower triangular, so the i-th step's multiplier depends only on the
    earlier ones (mu_i = round(L[i, j] - sum_{i' < i} mu_i' L[i, i'])), and column j and Z[:, j]
    are updated once at the end.  About ten times faster for the 30-80 ambiguities of a
    multi-GNSS dual-frequency epoch (the per-element numpy calls dominated).
    """
    n = L.shape[0]
    if j + 1 >= n:
        return
    col = L[j + 1 :, j]
    sub = L[j + 1 :, j + 1 :]
    m = n - j - 1
    big = np.flatnonzero(np.abs(col) >= 0.5)
    if len(big) == 0:
        return  # every multiplier is zero: nothing to do (the common case)
    mu = np.zeros(m)
    any_nonzero = False
    for r in range(int(big[0]), m):  # rows before the first |L| >= 1/2 round to zero
        val = float(col[r]) - (float(sub[r, :r] @ mu[:r]) if any_nonzero and r else 0.0)
        mr = round(val)
        if mr != 0:
            mu[r] = mr
            any_nonzero = True
    if any_nonzero:
        L[j + 1 :, j] -= sub @ mu
        Z[:, j] -= Z[:, j + 1 :] @ mu


def _gauss(L: np.ndarray, Z: np.ndarray, i: int, j: int) -> None:
    mu = round(L[i, j])
    if mu != 0:
        L[i:, j] -= mu * L[i:, i]
        Z[:, j] -= mu * Z[:, i]


def _permute(L: np.ndarray, D: np.ndarray, j: int, delta: float, Z: np.ndarray) -> None:
    eta = D[j] / delta
    lam = D[j + 1] * L[j + 1, j] / delta
    D[j] = eta * D[j + 1]
    D[j + 1] = delta
    a0 = L[j, :j].copy()
    a1 = L[j + 1, :j].copy()
    L[j, :j] = -L[j + 1, j] * a0 + a1
    L[j + 1, :j] = eta * a0 + lam * a1
    L[j + 1, j] = lam
    L[j + 2 :, [j, j + 1]] = L[j + 2 :, [j + 1, j]]
    Z[:, [j, j + 1]] = Z[:, [j + 1, j]]


def search(L: np.ndarray, D: np.ndarray, zs: np.ndarray, m: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """MLAMBDA search: the m integer vectors z nearest to zs in the metric (L^T D L)^-1.

    Returns (candidates of shape (m, n), squared norms of shape (m,)), best first.
    """
    if _kernels is not None:
        cand, norms = _kernels.search_kernel(np.ascontiguousarray(L, dtype=float), np.ascontiguousarray(D, dtype=float),
                                             np.ascontiguousarray(zs, dtype=float), int(m))
        order = np.argsort(norms, kind="stable")
        return cand[order], norms[order]
    return search_reference(L, D, zs, m)


def search_reference(L: np.ndarray, D: np.ndarray, zs: np.ndarray, m: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """MLAMBDA search in plain Python (the reference the compiled kernel is tested against).

    Returns (candidates of shape (m, n), squared norms of shape (m,)), best first.
    """
    n = len(D)
    S = np.zeros((n, n))
    dist = np.zeros(n)
    zb = np.zeros(n)
    z = np.zeros(n)
    step = np.zeros(n)
    cand = np.zeros((m, n))
    norms = np.full(m, np.inf)
    count = 0
    imax = 0
    maxdist = np.inf

    k = n - 1
    zb[k] = zs[k]
    z[k] = round(zb[k])
    y = zb[k] - z[k]
    step[k] = 1.0 if y > 0 else -1.0
    # A hard bound on iterations guards against a pathological (near-singular) covariance.
    for _ in range(10_000_000):
        newdist = dist[k] + y * y / D[k]
        if newdist < maxdist:
            if k != 0:
                k -= 1
                dist[k] = newdist
                S[k, : k + 1] = S[k + 1, : k + 1] + (z[k + 1] - zb[k + 1]) * L[k + 1, : k + 1]
                zb[k] = zs[k] + S[k, k]
                z[k] = round(zb[k])
                y = zb[k] - z[k]
                step[k] = 1.0 if y > 0 else -1.0
            else:
                if count < m:
                    if count == 0 or newdist > norms[imax]:
                        imax = count
                    cand[count] = z
                    norms[count] = newdist
                    count += 1
                    if count == m:
                        maxdist = norms[imax]
                else:
                    if newdist < norms[imax]:
                        cand[imax] = z
                        norms[imax] = newdist
                        imax = int(np.argmax(norms))
                    maxdist = norms[imax]
                z[0] += step[0]
                y = zb[0] - z[0]
                step[0] = -step[0] - (1.0 if step[0] > 0 else -1.0)
        else:
            if k == n - 1:
                break
            k += 1
            z[k] += step[k]
            y = zb[k] - z[k]
            step[k] = -step[k] - (1.0 if step[k] > 0 else -1.0)
    else:  # pragma: no cover - only for a degenerate covariance
        raise AmbiguityError("integer search did not terminate")
    order = np.argsort(norms[:count], kind="stable")
    return cand[order], norms[order]


@dataclass(frozen=True)
class LambdaResult:
    candidates: np.ndarray  # (m, n) integer ambiguity vectors in the original space, best first
    norms: np.ndarray  # (m,) squared distances (a_hat - a)^T Q^-1 (a_hat - a)
    Z: np.ndarray  # (n, n) integer decorrelating transformation, z = Z^T a
    D: np.ndarray  # (n,) conditional variances of the decorrelated ambiguities

    @property
    def best(self) -> np.ndarray:
        return self.candidates[0]

    @property
    def ratio(self) -> float:
        """Second-best over best squared norm (inf when the best is exact)."""
        if len(self.norms) < 2:
            return np.inf
        return float(self.norms[1] / self.norms[0]) if self.norms[0] > 0 else np.inf

    @property
    def success_rate(self) -> float:
        return bootstrap_success_rate(self.D)


def lambda_search(a_hat: np.ndarray, Q: np.ndarray, m: int = 2) -> LambdaResult:
    """Integer least squares: the m best integer vectors for float ambiguities a_hat with covariance Q."""
    a_hat = np.asarray(a_hat, dtype=float)
    n = a_hat.shape[0]
    if n == 0:
        raise AmbiguityError("no ambiguities to fix")
    Q = 0.5 * (np.asarray(Q, dtype=float) + np.asarray(Q, dtype=float).T)
    if Q.shape != (n, n):
        raise AmbiguityError(f"covariance shape {Q.shape} does not fit {n} ambiguities")
    L, D = ldl(Q)
    L, D, Z = reduce(L, D)
    zs = Z.T @ a_hat
    zc, norms = search(L, D, zs, m)
    # a = Z^-T z; Z is unimodular so the result is integer up to round-off.
    cand = np.rint(np.linalg.solve(Z.T, zc.T).T)
    return LambdaResult(candidates=cand, norms=norms, Z=Z, D=D)


def bootstrap_success_rate(D: np.ndarray) -> float:
    """Teunissen's bootstrapped success rate from the decorrelated conditional variances (a lower bound
    of the integer least-squares success rate)."""
    p = 1.0
    for d in np.asarray(D, dtype=float):
        p *= 2.0 * normal_cdf(1.0 / (2.0 * sqrt(d))) - 1.0
    return p


@dataclass(frozen=True)
class PartialFix:
    """A fix of the best-determined decorrelated ambiguities z = Zs^T a (possibly all of them)."""

    Zs: np.ndarray  # (n, p) integer columns: the fixed combinations of the original ambiguities
    z_fixed: np.ndarray  # (p,) their integer values
    ratio: float
    success_rate: float

    @property
    def count(self) -> int:
        return self.z_fixed.shape[0]


class FixedIntegers(Mapping):
    """Integer double-difference ambiguities [cycles] by (satellite, reference satellite, frequency slot):
    what a fix determined, immutable.

    `dd(sat, ref, slot)` also answers for any pair whose two satellites are both fixed against one common
    reference (z(s, r) = z(s, R) - z(r, R)), so two sets fixed against different references compare
    (`agrees_with`).
    """

    __slots__ = ("_z",)

    def __init__(self, items=()):
        pairs = items.items() if isinstance(items, Mapping) else items
        self._z = {(str(s), str(r), int(f)): int(z) for (s, r, f), z in pairs}

    @classmethod
    def determined(cls, keys, x: np.ndarray, P: np.ndarray, i: np.ndarray, iref: np.ndarray,
                   max_sigma_cyc: float = DETERMINED_SIGMA_CYC) -> "FixedIntegers":
        """The DD ambiguities x[i] - x[iref] (state indices of single-difference ambiguities, one pair per
        key) whose sigma under covariance P is below `max_sigma_cyc`, rounded."""
        var = P[i, i] + P[iref, iref] - 2.0 * P[i, iref]
        val = x[i] - x[iref]
        return cls((key, int(round(a))) for key, a, v in zip(keys, val, var) if v < max_sigma_cyc**2)

    def __getitem__(self, key) -> int:
        return self._z[key]

    def __iter__(self) -> Iterator[tuple[str, str, int]]:
        return iter(self._z)

    def __len__(self) -> int:
        return len(self._z)

    def __repr__(self) -> str:
        return f"FixedIntegers({self._z!r})"

    __hash__ = None  # a mapping: compared by value, like a dict

    def dd(self, sat: str, ref: str, slot: int) -> int | None:
        """The integer DD ambiguity of sat against ref in a slot, directly or through a common reference;
        None when this set does not determine it."""
        if sat == ref:
            return 0
        if (sat, ref, slot) in self._z:
            return self._z[(sat, ref, slot)]
        if (ref, sat, slot) in self._z:
            return -self._z[(ref, sat, slot)]
        for common in {r for (_, r, f) in self._z if f == slot}:
            a = 0 if sat == common else self._z.get((sat, common, slot))
            b = 0 if ref == common else self._z.get((ref, common, slot))
            if a is not None and b is not None:
                return a - b
        return None

    def agrees_with(self, other: Mapping) -> bool:
        """Whether every DD ambiguity of `other` that this set also determines has the same integer."""
        return all(self.dd(s, r, f) in (None, z) for (s, r, f), z in other.items())


@dataclass(frozen=True)
class FixPolicy:
    """How partial ambiguity resolution picks and accepts a fix: the one policy of both estimators.

    The trailing blocks of the decorrelated ambiguities (largest first) whose bootstrapped success rate
    reaches `min_success_rate` and that hold at least `min_count` ambiguities are candidates; the first
    whose integer solution passes the ratio test is the fix.  `max_tries` bounds the searches per call
    (None: every candidate).  `biased_float_false_alarm` (None: no screening) skips a block whose float
    values are too far from every integer to pass anyway (see BIASED_FLOAT_FALSE_ALARM), before its
    search is spent.
    """

    min_success_rate: float = DEFAULT_MIN_SUCCESS_RATE
    ratio_threshold: float = DEFAULT_RATIO_THRESHOLD
    min_count: int = DEFAULT_MIN_COUNT
    max_tries: int | None = None
    biased_float_false_alarm: float | None = None
    biased_float_rms_cyc: float = BIASED_FLOAT_RMS_CYC


def partial_fix(a_hat: np.ndarray, Q: np.ndarray, policy: FixPolicy = FixPolicy()) -> PartialFix | None:
    """Partial ambiguity resolution (Teunissen et al. 1999) under `policy` (default: `FixPolicy()`): fix the largest trailing block of the decorrelated ambiguities whose bootstrapped success
    rate reaches the policy's minimum and whose integer solution passes the ratio test.  In the L^T D L
    ordering the trailing block is self-contained (its own factors are the trailing block of L and D), so
    it is searched on its own; a failing ratio on a block with a high success rate means the float
    solution disagrees with its covariance, so smaller blocks, without the worst-determined parts, are
    tried next.  None when nothing can be fixed.
    """
    a_hat = np.asarray(a_hat, dtype=float)
    n = a_hat.shape[0]
    if n < max(policy.min_count, 1):
        return None
    Q = 0.5 * (np.asarray(Q, dtype=float) + np.asarray(Q, dtype=float).T)
    L, D = ldl(Q)
    L, D, Z = reduce(L, D)
    zs = Z.T @ a_hat
    trailing = trailing_success_rates(D)
    starts = [k for k in range(0, n - policy.min_count + 1) if trailing[k] >= policy.min_success_rate]
    for start in starts[:policy.max_tries]:
        if _biased(L[start:, start:], D[start:], zs[start:], policy):
            continue
        cand, norms = search(L[start:, start:], D[start:], zs[start:], 2)
        ratio = float(norms[1] / norms[0]) if norms[0] > 0 else inf
        if ratio >= policy.ratio_threshold:
            return PartialFix(Zs=Z[:, start:], z_fixed=cand[0], ratio=ratio, success_rate=float(trailing[start]))
    return None


def trailing_success_rates(D: np.ndarray) -> np.ndarray:
    """The bootstrapped success rate of every trailing block D[k:] at once: products of the
    per-ambiguity factors 2 Phi(1 / (2 sqrt(d))) - 1 (`bootstrap_success_rate` of one ambiguity)."""
    factors = np.array([2.0 * normal_cdf(1.0 / (2.0 * sqrt(d))) - 1.0 for d in D])
    return np.cumprod(factors[::-1])[::-1]


def _biased(L: np.ndarray, D: np.ndarray, zs: np.ndarray, policy: FixPolicy) -> bool:
    """Whether a block's float values fail the policy's biased-float screening (never without one)."""
    if policy.biased_float_false_alarm is None:
        return False
    q_boot, rms_frac = bootstrapped_norm(L, D, zs)
    return q_boot > chi2_quantile(len(D), policy.biased_float_false_alarm) and rms_frac > policy.biased_float_rms_cyc


def bootstrapped_norm(L: np.ndarray, D: np.ndarray, zs: np.ndarray) -> tuple[float, float]:
    """(squared distance, RMS conditional fraction [cycles]) of the integer bootstrapping (sequential
    conditional rounding) solution from the float ambiguities zs, in the metric of their covariance
    L^T diag(D) L (last index first)."""
    if _kernels is not None:
        return _kernels.bootstrapped_norm_kernel(L, D, zs)
    return bootstrapped_norm_reference(L, D, zs)


def bootstrapped_norm_reference(L: np.ndarray, D: np.ndarray, zs: np.ndarray) -> tuple[float, float]:
    """`bootstrapped_norm` in plain Python (the reference the compiled kernel is tested against)."""
    n = len(D)
    z = np.zeros(n)
    zb = np.zeros(n)
    dist = 0.0
    for k in range(n - 1, -1, -1):
        acc = 0.0
        for j in range(k + 1, n):
            acc += (z[j] - zb[j]) * L[j, k]
        zb[k] = zs[k] + acc
        z[k] = np.round(zb[k])
        dist += (zb[k] - z[k]) ** 2 / D[k]
    return dist, float(np.sqrt(np.mean((zb - z) ** 2)))


def condition_on_fixed(
    x: np.ndarray, P: np.ndarray, amb_index: np.ndarray, fix: PartialFix
) -> tuple[np.ndarray, np.ndarray]:
    """Update a float state (x, P) with the constraint Zs^T a = z_fixed on its ambiguity part a = x[amb_index].

    Returns the fixed state and its covariance (the textbook conditional mean and covariance).
    """
    amb_index = np.asarray(amb_index)
    H = np.zeros((fix.count, x.shape[0]))
    H[:, amb_index] = fix.Zs.T
    S = H @ P @ H.T
    K = np.linalg.solve(S, H @ P).T
    x_fixed = x - K @ (H @ x - fix.z_fixed)
    P_fixed = P - K @ H @ P
    return x_fixed, 0.5 * (P_fixed + P_fixed.T)

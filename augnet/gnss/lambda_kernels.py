"""Compiled kernels of the LAMBDA reduction and MLAMBDA search (numba), the hot loops of both the network
engine and the onboard RTK: a 50-ambiguity reduction takes some hundreds of permutations, which cost ~60 us
each as numpy calls and ~0.1 us compiled. Same algorithm and rounding (half to even) as the reference
Python in `ambiguity.py`, which the tests compare them against. Compiled on first use and cached on disk.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_PERMUTE_TOLERANCE = 1e-6  # as ambiguity._PERMUTE_TOLERANCE


@njit(cache=True)
def _gauss_column(L, Z, j):
    n = L.shape[0]
    m = n - j - 1
    if m <= 0:
        return
    mu = np.zeros(m)
    anyz = False
    for r in range(m):
        val = L[j + 1 + r, j]
        if anyz:
            for c in range(r):
                if mu[c] != 0.0:
                    val -= L[j + 1 + r, j + 1 + c] * mu[c]
        mr = np.rint(val)
        if mr != 0.0:
            mu[r] = mr
            anyz = True
    if anyz:
        for r in range(m):
            if mu[r] != 0.0:
                i = j + 1 + r
                for q in range(i, n):
                    L[q, j] -= mu[r] * L[q, i]
                for q in range(n):
                    Z[q, j] -= mu[r] * Z[q, i]


@njit(cache=True)
def reduce_kernel(L0, D0):
    L = L0.copy()
    D = D0.copy()
    n = D.shape[0]
    Z = np.eye(n)
    j = n - 2
    k = n - 2
    while j >= 0:
        if j <= k:
            _gauss_column(L, Z, j)
        delta = D[j] + L[j + 1, j] ** 2 * D[j + 1]
        if delta + _PERMUTE_TOLERANCE < D[j + 1]:
            eta = D[j] / delta
            lam = D[j + 1] * L[j + 1, j] / delta
            D[j] = eta * D[j + 1]
            D[j + 1] = delta
            for c in range(j):
                a0 = L[j, c]
                a1 = L[j + 1, c]
                L[j, c] = -L[j + 1, j] * a0 + a1
                L[j + 1, c] = eta * a0 + lam * a1
            L[j + 1, j] = lam
            for q in range(j + 2, n):
                tmp = L[q, j]
                L[q, j] = L[q, j + 1]
                L[q, j + 1] = tmp
            for q in range(n):
                tmp = Z[q, j]
                Z[q, j] = Z[q, j + 1]
                Z[q, j + 1] = tmp
            k = j
            j = n - 2
        else:
            j -= 1
    return L, D, Z


@njit(cache=True)
def search_kernel(L, D, zs, m):
    n = D.shape[0]
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
    z[k] = np.rint(zb[k])
    y = zb[k] - z[k]
    step[k] = 1.0 if y > 0 else -1.0
    for _ in range(100_000_000):
        newdist = dist[k] + y * y / D[k]
        if newdist < maxdist:
            if k != 0:
                k -= 1
                dist[k] = newdist
                for i in range(k + 1):
                    S[k, i] = S[k + 1, i] + (z[k + 1] - zb[k + 1]) * L[k + 1, i]
                zb[k] = zs[k] + S[k, k]
                z[k] = np.rint(zb[k])
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
    return cand[:count], norms[:count]


@njit(cache=True)
def bootstrapped_norm_kernel(L, D, zs):
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
    return dist, np.sqrt(np.mean((zb - z) ** 2))

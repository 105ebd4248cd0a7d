"""LAMBDA / MLAMBDA against brute-force integer least squares, and validation properties."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from augnet.gnss.ambiguity import (
    AmbiguityError,
    FixPolicy,
    bootstrap_success_rate,
    condition_on_fixed,
    lambda_search,
    ldl,
    partial_fix,
    reduce,
)


def random_covariance(rng: np.random.Generator, n: int, max_cond: float = 1e4) -> np.ndarray:
    """Random SPD matrix with strong correlations, like GNSS float ambiguities (condition up to max_cond)."""
    A = rng.normal(size=(n, n))
    U, _ = np.linalg.qr(A)
    eig = np.exp(rng.uniform(0, np.log(max_cond), size=n)) * rng.uniform(1e-3, 1e-1)
    return (U * eig) @ U.T


def quad(a_hat, Qinv, a):
    d = a_hat - a
    return float(d @ Qinv @ d)


def brute_force(a_hat: np.ndarray, Q: np.ndarray, m: int = 2):
    Qinv = np.linalg.inv(Q)
    base = np.rint(a_hat)
    # two distinct integer vectors bound the m-th best norm from above
    probe = [base + np.eye(len(a_hat))[i] for i in range(m - 1)]
    chi = max(quad(a_hat, Qinv, v) for v in [base, *probe])
    radius = np.ceil(np.sqrt(chi * np.diag(Q))).astype(int)
    ranges = [range(int(np.floor(a_hat[i])) - radius[i], int(np.ceil(a_hat[i])) + radius[i] + 1)
              for i in range(len(a_hat))]
    best = sorted((quad(a_hat, Qinv, np.array(v, float)), v) for v in itertools.product(*ranges))
    return [np.array(v, float) for _, v in best[:m]], [n for n, _ in best[:m]]


@pytest.mark.parametrize("seed", range(40))
def test_lambda_equals_brute_force_on_small_problems(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 5))
    Q = random_covariance(rng, n, max_cond=1e3)
    a_hat = rng.normal(scale=20, size=n)
    res = lambda_search(a_hat, Q, m=2)
    expect, norms = brute_force(a_hat, Q, m=2)
    np.testing.assert_allclose(res.norms, norms[: len(res.norms)], rtol=1e-8, atol=1e-10)
    assert np.array_equal(res.candidates[0], expect[0])
    if len(norms) > 1 and not np.isclose(norms[0], norms[1]):
        assert np.array_equal(res.candidates[1], expect[1])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 12))
def test_reduction_is_unimodular_and_preserves_the_metric(seed, n):
    rng = np.random.default_rng(seed)
    Q = random_covariance(rng, n)
    L, D = ldl(Q)
    np.testing.assert_allclose(L.T @ np.diag(D) @ L, Q, rtol=1e-9, atol=1e-12 * np.abs(Q).max())
    L2, D2, Z = reduce(L, D)
    assert np.array_equal(Z, np.rint(Z))
    assert abs(round(np.linalg.det(Z))) == 1
    np.testing.assert_allclose(L2.T @ np.diag(D2) @ L2, Z.T @ Q @ Z, rtol=1e-7, atol=1e-9 * np.abs(Q).max())
    # decorrelation never makes the bootstrapped success rate worse
    assert bootstrap_success_rate(D2) >= bootstrap_success_rate(D) - 1e-12


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 15))
def test_search_result_is_at_least_as_good_as_rounding_and_bootstrapping(seed, n):
    rng = np.random.default_rng(seed)
    Q = random_covariance(rng, n)
    a_hat = rng.normal(scale=50, size=n)
    res = lambda_search(a_hat, Q, m=2)
    Qinv = np.linalg.inv(Q)
    assert res.norms[0] <= quad(a_hat, Qinv, np.rint(a_hat)) + 1e-9
    assert res.norms[0] <= res.norms[1] + 1e-12
    np.testing.assert_allclose(res.norms[0], quad(a_hat, Qinv, res.best), rtol=1e-6, atol=1e-9)
    assert not np.array_equal(res.candidates[0], res.candidates[1])


def test_recovers_true_integers_from_a_precise_float_solution():
    rng = np.random.default_rng(7)
    n = 16
    Q = random_covariance(rng, n, max_cond=1e5) * 1e-3
    truth = rng.integers(-1_000_000, 1_000_000, size=n).astype(float)
    a_hat = rng.multivariate_normal(truth, Q)
    res = lambda_search(a_hat, Q)
    assert np.array_equal(res.best, truth)
    assert res.ratio > 3.0
    assert res.success_rate > 0.999


def test_partial_fix_leaves_out_the_poorly_determined_part():
    rng = np.random.default_rng(3)
    n = 10
    sig = np.full(n, 0.05)
    sig[:3] = 3.0  # three ambiguities barely determined (e.g. newly risen satellites)
    Q = np.diag(sig**2)
    truth = rng.integers(-100, 100, size=n).astype(float)
    a_hat = truth + rng.normal(scale=sig)
    assert lambda_search(a_hat, Q).success_rate < 0.5
    fix = partial_fix(a_hat, Q, FixPolicy(min_success_rate=0.999, ratio_threshold=3.0))
    assert fix is not None and fix.count == 7
    np.testing.assert_array_equal(fix.z_fixed, fix.Zs.T @ truth)
    # conditioning the state on the fix pins the fixed ambiguities to their integers
    x = np.concatenate([[10.0, 20.0], a_hat])
    P = np.zeros((n + 2, n + 2))
    P[:2, :2] = np.eye(2)
    P[2:, 2:] = Q
    P[0, 2:] = P[2:, 0] = 0.5 * np.sqrt(Q[0, 0] * 1.0) * (np.arange(n) == 5)
    xf, Pf = condition_on_fixed(x, P, np.arange(2, n + 2), fix)
    np.testing.assert_allclose(fix.Zs.T @ xf[2:], fix.z_fixed, atol=1e-9)
    assert np.all(np.diag(Pf) <= np.diag(P) + 1e-12)


def test_nothing_fixable_gives_none():
    Q = np.eye(5) * 4.0
    assert partial_fix(np.zeros(5) + 0.5, Q) is None


def test_not_positive_definite_is_refused():
    with pytest.raises(AmbiguityError):
        lambda_search(np.zeros(2), np.array([[1.0, 2.0], [2.0, 1.0]]))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 25))
def test_compiled_kernels_agree_with_the_reference_python(seed, n):
    from augnet.gnss import ambiguity as am

    if am._kernels is None:
        pytest.skip("numba not installed: the reference Python is in use")
    rng = np.random.default_rng(seed)
    Q = random_covariance(rng, n, max_cond=1e4)
    L, D = ldl(Q)
    L1, D1, Z1 = am._kernels.reduce_kernel(L, D)
    L2, D2, Z2 = am.reduce_reference(L, D)
    np.testing.assert_array_equal(Z1, Z2)
    np.testing.assert_allclose(D1, D2, rtol=1e-9)
    zs = Z1.T @ rng.normal(scale=30, size=n)
    c1, s1 = am.search(L1, D1, zs, 3)
    c2, s2 = am.search_reference(L1, D1, zs, 3)
    np.testing.assert_array_equal(c1, c2)
    np.testing.assert_allclose(s1, s2, rtol=1e-12)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 30))
def test_lapack_ldl_equals_the_reference_factorisation(seed, n):
    from augnet.gnss.ambiguity import ldl_reference

    Q = random_covariance(np.random.default_rng(seed), n)
    L1, D1 = ldl(Q)
    L2, D2 = ldl_reference(Q)
    np.testing.assert_allclose(D1, D2, rtol=1e-9)
    np.testing.assert_allclose(L1, L2, rtol=1e-7, atol=1e-9)
    assert np.array_equal(np.diag(L1), np.ones(n))


def test_both_factorisations_refuse_what_is_not_positive_definite():
    from augnet.gnss.ambiguity import ldl_reference

    for bad in (np.array([[1.0, 2.0], [2.0, 1.0]]), np.array([[np.nan, 0.0], [0.0, 1.0]]), np.zeros((2, 3))):
        for factor in (ldl, ldl_reference):
            with pytest.raises(AmbiguityError):
                factor(bad)


def test_bounded_tries_and_biased_float_screening():
    from augnet.gnss.ambiguity import FixPolicy

    rng = np.random.default_rng(5)
    n = 8
    Q = np.diag(np.full(n, 0.02**2))
    truth = rng.integers(-100, 100, size=n).astype(float)
    # a float half a cycle from every integer: biased, and the ratio test cannot pass
    biased = truth + 0.5
    assert partial_fix(biased, Q, FixPolicy(biased_float_false_alarm=1e-6)) is None
    # a good float passes with or without screening, in the first try
    good = truth + rng.normal(scale=0.02, size=n)
    fix = partial_fix(good, Q, FixPolicy(max_tries=1, biased_float_false_alarm=1e-6))
    assert fix is not None and fix.count == n
    np.testing.assert_array_equal(fix.z_fixed, fix.Zs.T @ truth)
    # no try allowed: nothing is searched
    assert partial_fix(good, Q, FixPolicy(max_tries=0)) is None


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 20))
def test_compiled_bootstrapped_norm_agrees_with_the_reference(seed, n):
    from augnet.gnss import ambiguity as am

    if am._kernels is None:
        pytest.skip("numba not installed: the reference Python is in use")
    rng = np.random.default_rng(seed)
    L, D = ldl(random_covariance(rng, n))
    zs = rng.normal(scale=10, size=n)
    d1, r1 = am.bootstrapped_norm(L, D, zs)
    d2, r2 = am.bootstrapped_norm_reference(L, D, zs)
    assert d1 == pytest.approx(d2, rel=1e-12)
    assert r1 == pytest.approx(r2, rel=1e-12)


def test_fixed_integers_is_a_read_only_mapping_that_rereferences():
    from augnet.gnss.ambiguity import FixedIntegers

    z = FixedIntegers({("G05", "G10", 0): 7, ("G12", "G10", 0): -3, ("G05", "G10", 1): 2})
    assert z == {("G05", "G10", 0): 7, ("G12", "G10", 0): -3, ("G05", "G10", 1): 2}
    assert len(z) == 3 and z[("G12", "G10", 0)] == -3
    assert z.dd("G10", "G05", 0) == -7  # swapped
    assert z.dd("G05", "G12", 0) == 10  # through the common reference G10
    assert z.dd("G12", "G05", 1) is None  # slot 1 knows nothing of G12
    assert z.dd("G05", "G05", 0) == 0
    other = FixedIntegers({("G05", "G12", 0): 10, ("E01", "E02", 0): 4})
    assert z.agrees_with(other)
    assert not z.agrees_with({("G05", "G12", 0): 9})
    with pytest.raises(TypeError):
        z[("G05", "G10", 0)] = 8
    assert FixedIntegers() == {}


def test_fixed_integers_keeps_only_what_the_covariance_determines():
    from augnet.gnss.ambiguity import DETERMINED_SIGMA_CYC, FixedIntegers

    x = np.array([0.0, 12.02, 5.0, 3.49])
    P = np.diag([1.0, 1e-4, 1e-4, 1.0])
    keys = [("G01", "G02", 0), ("G03", "G02", 0)]
    z = FixedIntegers.determined(keys, x, P, np.array([1, 3]), np.array([2, 2]))
    assert dict(z) == {("G01", "G02", 0): 7}  # G03's sigma is a cycle: not determined
    assert DETERMINED_SIGMA_CYC == 0.05

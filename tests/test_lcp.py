"""Tests for models.lcp: Lemke and PGS LCP solvers, statuses, fc2d <-> LCP conversion."""

from __future__ import annotations

import dataclasses
import itertools
import warnings
from fractions import Fraction
from types import SimpleNamespace

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from models import lcp
from models.lcp import (
    DEFAULT_TOL,
    INACCURATE_TOL,
    LCPResult,
    LCPStatus,
    complementarity_residual,
    contact_lcp_from_fc2d,
    fc2d_coulomb_error,
    fc2d_reactions_from_lcp,
    lemke_kernel,
    lemke_warm_kernel,
    pgs_kernel,
    solve_lcp,
    warm_guess_dropping_into,
)

METHODS = ("lemke", "pgs")


# ------------------------------------------------------------------------------------------
# Independent references (plain numpy / exact rationals; they share no code with the solver)
# ------------------------------------------------------------------------------------------
def natural_residual(M, q, z):
    """||min(z, Mz+q)||_inf / (1 + ||q||_inf), computed independently of models.lcp."""
    M = np.asarray(M, float)
    q = np.asarray(q, float)
    z = np.asarray(z, float)
    if q.size == 0:
        return 0.0
    w = M @ z + q
    return float(np.max(np.abs(np.minimum(z, w))) / (1.0 + np.max(np.abs(q))))


def brute_force_solutions(M, q, tol=1e-9):
    """All complementary basic solutions of LCP(M, q) (exponential; small n only)."""
    M = np.asarray(M, float)
    q = np.asarray(q, float)
    n = q.size
    sols = []
    for k in range(n + 1):
        for J in itertools.combinations(range(n), k):
            J = list(J)
            z = np.zeros(n)
            if J:
                A = M[np.ix_(J, J)]
                if abs(np.linalg.det(A)) < 1e-12:
                    continue
                z[J] = np.linalg.solve(A, -q[J])
            if natural_residual(M, q, z) <= tol:
                sols.append(z)
    return sols


def lemke_exact(M, q, max_pivots=10_000):
    """Lemke's method with the lexicographic rule in exact rational arithmetic.

    Same conventions as the kernel (covering vector e, first pivot in the lexicographically
    smallest row of (q, I), z0 leaves as soon as it ties for the minimum ratio).
    Returns (status, pivots, z) with status in {"solved", "ray", "max"}.
    """
    n = len(q)
    Mf = [[Fraction(M[i][j]) for j in range(n)] for i in range(n)]
    qb = [Fraction(x) for x in q]
    B = [[Fraction(int(i == j)) for j in range(n)] for i in range(n)]
    basis = list(range(n))
    if n == 0 or min(qb) >= 0:
        return "solved", 0, [Fraction(0)] * n

    def column(v):
        if v < n:
            return [B[i][v] for i in range(n)]
        if v < 2 * n:
            j = v - n
            return [-sum(B[i][k] * Mf[k][j] for k in range(n)) for i in range(n)]
        return [-sum(B[i]) for i in range(n)]

    def pivot(d, r):
        p = d[r]
        B[r] = [x / p for x in B[r]]
        qb[r] = qb[r] / p
        for i in range(n):
            if i != r and d[i] != 0:
                f = d[i]
                B[i] = [a - f * b for a, b in zip(B[i], B[r])]
                qb[i] -= f * qb[r]

    def lexmin(rows, div):
        return min(rows, key=lambda i: [qb[i] / div[i]] + [B[i][k] / div[i] for k in range(n)])

    r = lexmin(range(n), [Fraction(1)] * n)
    leaving = basis[r]
    pivot([Fraction(-1)] * n, r)
    basis[r] = 2 * n
    entering = leaving + n
    pivots = 1
    while pivots < max_pivots:
        d = column(entering)
        cand = [i for i in range(n) if d[i] > 0]
        if not cand:
            return "ray", pivots, None
        zr = basis.index(2 * n)
        theta = min(qb[i] / d[i] for i in cand)
        r = zr if (zr in cand and qb[zr] / d[zr] == theta) else lexmin(cand, d)
        leaving = basis[r]
        pivot(d, r)
        basis[r] = entering
        pivots += 1
        if leaving == 2 * n:
            z = [Fraction(0)] * n
            for i in range(n):
                if n <= basis[i] < 2 * n:
                    z[basis[i] - n] = qb[i]
            return "solved", pivots, z
        entering = leaving + n if leaving < n else leaving - n
    return "max", pivots, None


def murty(n):
    """Murty's exponential example: upper triangular, 1 on the diagonal, 2 above."""
    M = np.eye(n) + 2.0 * np.triu(np.ones((n, n)), 1)
    q = -(2.0 ** (n + 1) - 2.0 ** np.arange(1, n + 1))
    return M, q


def random_fc2d(rng, nc, ndof, mu_scale=1.0):
    """A random 2D contact problem as a time-stepper builds it: W = J Minv J^T (PSD, singular
    when 2 nc > ndof), q = J v_free plus nonnegative gap terms on the normal rows, random mu.
    Such problems always have a solution (for an arbitrary q a rigid one may not).  All
    numbers are small integers or dyadic fractions, so W, q are exact in floating point: W is
    exactly PSD and the solvability guarantee holds for the data the solver sees."""
    J = rng.integers(-3, 4, size=(2 * nc, ndof)).astype(float)
    Minv = np.diag(rng.choice([0.5, 1.0, 2.0], ndof))
    W = J @ Minv @ J.T
    q = J @ (rng.integers(-8, 9, ndof) / 4.0)
    q[0::2] += rng.integers(0, 5, nc) / 4.0 * (rng.random(nc) < 0.5)
    mu = mu_scale * rng.integers(0, 9, nc) / 8.0
    return W, q, mu


# ------------------------------------------------------------------------------------------
# Statuses and the result type
# ------------------------------------------------------------------------------------------
def test_status_codes_match_module_constants_and_have_messages():
    assert LCPStatus.SOLVED == lcp.STATUS_SOLVED == 0
    assert LCPStatus.SOLVED_INACCURATE == lcp.STATUS_SOLVED_INACCURATE
    assert LCPStatus.RAY_TERMINATION == lcp.STATUS_RAY_TERMINATION
    assert LCPStatus.MAX_ITERATIONS == lcp.STATUS_MAX_ITERATIONS
    assert LCPStatus.ZERO_DIAGONAL == lcp.STATUS_ZERO_DIAGONAL
    assert LCPStatus.NON_FINITE_INPUT == lcp.STATUS_NON_FINITE_INPUT
    assert LCPStatus.NON_FINITE_OUTPUT == lcp.STATUS_NON_FINITE_OUTPUT
    assert LCPStatus.INVALID_INPUT == lcp.STATUS_INVALID_INPUT
    assert LCPStatus.NUMERICAL_FAILURE == lcp.STATUS_NUMERICAL_FAILURE
    assert len({int(s) for s in LCPStatus}) == len(LCPStatus)
    for s in LCPStatus:
        assert isinstance(s.message, str) and len(s.message) > 10
        assert s.is_success == (s is LCPStatus.SOLVED)
    assert "secondary ray" in LCPStatus.RAY_TERMINATION.message
    assert "copositive-plus" in LCPStatus.RAY_TERMINATION.message


def test_result_is_frozen_and_success_means_solved():
    res = solve_lcp([[2.0]], [-1.0])
    assert isinstance(res, LCPResult)
    assert res.success and res.status is LCPStatus.SOLVED
    assert res.message == LCPStatus.SOLVED.message
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.status = LCPStatus.RAY_TERMINATION  # type: ignore[misc]
    bad = solve_lcp([[-1.0]], [-1.0])
    assert not bad.success


# ------------------------------------------------------------------------------------------
# Known solutions
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_trivial_q_nonnegative_gives_zero(method):
    M = np.array([[1.0, -3.0, 0.0], [2.0, 1.0, 5.0], [0.0, 4.0, 2.0]])
    q = np.array([1.0, 0.0, 2.5])
    res = solve_lcp(M, q, method)
    assert res.status is LCPStatus.SOLVED
    np.testing.assert_array_equal(res.z, 0.0)
    np.testing.assert_array_equal(res.w, q)
    assert res.iterations == 0
    assert res.residual == 0.0


@pytest.mark.parametrize("method", METHODS)
def test_empty_problem_is_an_empty_success(method):
    res = solve_lcp(np.zeros((0, 0)), np.zeros(0), method)
    assert res.status is LCPStatus.SOLVED and res.success
    assert res.z.shape == (0,) and res.w.shape == (0,)
    assert res.residual == 0.0 and res.iterations == 0
    z, w, code, it = lemke_kernel(np.zeros((0, 0)), np.zeros(0), 10)
    assert code == lcp.STATUS_SOLVED and z.shape == (0,) and w.shape == (0,) and it == 0


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("method", METHODS)
def test_positive_definite_constructed_solution(seed, method):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 12))
    A = rng.normal(size=(n, n))
    M = A @ A.T + 0.5 * np.eye(n)  # SPD: the LCP has exactly one solution
    active = rng.random(n) < 0.5
    z_star = np.where(active, rng.uniform(0.1, 3.0, n), 0.0)
    w_star = np.where(active, 0.0, rng.uniform(0.1, 3.0, n))
    q = w_star - M @ z_star
    res = solve_lcp(M, q, method, max_iterations=200_000 if method == "pgs" else None)
    assert res.status is LCPStatus.SOLVED, res.status.message
    assert res.residual <= DEFAULT_TOL
    assert natural_residual(M, q, res.z) <= DEFAULT_TOL
    np.testing.assert_allclose(res.z, z_star, atol=1e-6)
    np.testing.assert_allclose(res.w, M @ res.z + q, rtol=0, atol=1e-12)


@pytest.mark.parametrize("n", range(1, 10))
def test_murty_exponential_family_takes_2_to_the_n_pivots(n):
    M, q = murty(n)
    res = solve_lcp(M, q, max_iterations=10_000)
    assert res.status is LCPStatus.SOLVED
    expected = np.zeros(n)
    expected[-1] = 2.0**n  # the unique solution (M is a P-matrix)
    np.testing.assert_array_equal(res.z, expected)
    assert res.iterations == 2**n  # Murty (1988): exponentially many pivots
    (only,) = brute_force_solutions(M, q)
    np.testing.assert_allclose(only, expected)
    # the q = -ones member of the family is easy
    easy = solve_lcp(M, -np.ones(n))
    assert easy.success and easy.iterations == 2
    np.testing.assert_array_equal(easy.z, np.eye(n)[-1])


def test_pivot_limit_is_reported_not_hidden():
    M, q = murty(10)  # needs 1024 pivots; the default limit is 50 * 11 = 550
    res = solve_lcp(M, q)
    assert res.status is LCPStatus.MAX_ITERATIONS and not res.success
    assert res.iterations == 550
    assert res.residual > DEFAULT_TOL
    capped = solve_lcp(*murty(4), max_iterations=15)
    assert capped.status is LCPStatus.MAX_ITERATIONS and capped.iterations == 15
    assert solve_lcp(*murty(4), max_iterations=16).success


@pytest.mark.parametrize("k", [2, 3, 5])
def test_degenerate_continuum_of_solutions(k):
    # lcp_CPS_1 for k = 2: every z >= 0 with sum(z) = 1 is a solution.
    M = np.ones((k, k))
    q = -np.ones(k)
    res = solve_lcp(M, q)
    assert res.status is LCPStatus.SOLVED
    assert res.residual <= 1e-12
    assert np.all(res.z >= -1e-12)
    assert abs(res.z.sum() - 1.0) <= 1e-12
    np.testing.assert_allclose(res.w, 0.0, atol=1e-12)


def test_negative_scalar_reports_ray_termination():
    # w = -z - 1 < 0 for every z >= 0: no solution; M = [[-1]] is not copositive.
    res = solve_lcp([[-1.0]], [-1.0])
    assert res.status is LCPStatus.RAY_TERMINATION
    assert not res.success
    assert res.residual > DEFAULT_TOL
    assert natural_residual([[-1.0]], [-1.0], res.z) > DEFAULT_TOL
    assert solve_lcp([[-1.0]], [-1.0], "pgs").status is LCPStatus.ZERO_DIAGONAL


def test_infeasible_psd_problem_ray_is_a_proof():
    # M PSD (copositive-plus): w_0 = z_0 - z_1 - 1, w_1 = -z_0 + z_1 - 1 sum to -2 < 0.
    M = np.array([[1.0, -1.0], [-1.0, 1.0]])
    q = np.array([-1.0, -1.0])
    assert brute_force_solutions(M, q) == []
    res = solve_lcp(M, q)
    assert res.status is LCPStatus.RAY_TERMINATION


def test_bimatrix_game_lemke_cannot_reach_existing_solution():
    # lcp_CPS_3 (Cottle-Pang-Stone example 4.4.23): M = [[0, A], [B, 0]] with positive
    # A, B, q = -e.  Solutions exist (Nash equilibria), but M is not copositive-plus and
    # Lemke with covering vector e ends on a secondary ray after its first pivot.
    M = np.array(
        [
            [0.0, 0.0, 10.0, 20.0],
            [0.0, 0.0, 30.0, 15.0],
            [10.0, 20.0, 0.0, 0.0],
            [30.0, 15.0, 0.0, 0.0],
        ]
    )
    q = -np.ones(4)
    assert len(brute_force_solutions(M, q)) > 0
    res = solve_lcp(M, q)
    assert res.status is LCPStatus.RAY_TERMINATION
    assert res.iterations == 1
    assert not res.success
    st_, piv, _ = lemke_exact(M.astype(int).tolist(), q.astype(int).tolist())
    assert (st_, piv) == ("ray", 1)


@pytest.mark.parametrize("seed", range(3))
def test_lemke_follows_the_exact_lexicographic_path(seed):
    """On small degenerate integer LCPs the float kernel takes exactly the pivots of the
    exact-arithmetic lexicographic method (same outcome, same count, same z)."""
    rng = np.random.default_rng(1000 + seed)
    checked = 0
    for t in range(40):
        n = int(rng.integers(2, 8))
        kind = t % 4
        if kind == 0:
            M = rng.integers(-3, 4, (n, n))
        elif kind == 1:
            A = rng.integers(-2, 3, (n, n))
            M = A @ A.T
        elif kind == 2:
            k = n // 2
            M = np.zeros((n, n), dtype=int)
            M[:k, k:] = rng.integers(1, 6, (k, n - k))
            M[k:, :k] = rng.integers(1, 6, (n - k, k))
        else:
            A = rng.integers(-2, 3, (n, n))
            M = A - A.T + np.diag(rng.integers(0, 2, n))
        q = rng.integers(-2, 3, n) * (rng.random(n) < 0.7)  # many zeros: degenerate
        ex_status, ex_pivots, ex_z = lemke_exact(M.tolist(), q.tolist(), 2000)
        z, w, code, pivots = lemke_kernel(M.astype(float), q.astype(float), 2000)
        name = {lcp.STATUS_SOLVED: "solved", lcp.STATUS_RAY_TERMINATION: "ray"}.get(code, code)
        assert (name, pivots) == (ex_status, ex_pivots), (t, M, q)
        if ex_status == "solved":
            np.testing.assert_allclose(z, [float(x) for x in ex_z], atol=1e-9)
            checked += 1
    assert checked >= 10


def test_lemke_kernel_direct_call_contract():
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    q = np.array([-5.0, -6.0])
    z, w, code, pivots = lemke_kernel(M, q, 100)
    assert code == lcp.STATUS_SOLVED
    np.testing.assert_allclose(z, [4.0 / 3.0, 7.0 / 3.0])
    np.testing.assert_allclose(w, M @ z + q, atol=1e-14)
    assert pivots == 3
    z, w, code, pivots = lemke_kernel(M, q, 2)
    assert code == lcp.STATUS_MAX_ITERATIONS and pivots == 2


def test_lemke_warm_start_on_the_right_basis_takes_no_pivot():
    """A guess of the solution's basis is verified, not trusted: the right one is accepted with
    0 pivots and the cold solution; a wrong one, a singular one and a neighbouring problem's
    fall back to pivoting and still solve exactly, returning the basis they ended on (from the
    wrong guess's basis, one pivot fewer than from scratch)."""
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    q = np.array([-5.0, -6.0])
    z_cold, _, _, pivots = lemke_kernel(M, q, 100)
    z, w, code, pivots, basic_z, warm, residual = lemke_warm_kernel(M, q, 100, np.array([True, True]), 1e-12)
    assert warm and pivots == 0 and code == lcp.STATUS_SOLVED
    assert residual == pytest.approx(natural_residual(M, q, z), abs=1e-15) and residual <= 1e-12
    np.testing.assert_allclose(z, z_cold, rtol=1e-15)
    np.testing.assert_allclose(w, M @ z + q, atol=1e-14)
    assert basic_z.tolist() == [True, True]
    for guess in ([False, False], [True, False], [False, True]):  # z = 0 or a negative z / w
        z, w, code, pivots, basic_z, warm, residual = lemke_warm_kernel(M, q, 100, np.array(guess), 1e-12)
        assert not warm and pivots == (2 if any(guess) else 3) and code == lcp.STATUS_SOLVED
        assert residual == pytest.approx(natural_residual(M, q, z), abs=1e-15)
        np.testing.assert_allclose(z, z_cold, rtol=1e-14)
        assert basic_z.tolist() == [True, True]
    # a singular guess: M[J, J] = 0
    S = np.array([[0.0, 1.0], [-1.0, 1.0]])
    z, w, code, pivots, basic_z, warm, residual = lemke_warm_kernel(S, np.array([-1.0, 1.0]), 100, np.array([True, False]), 1e-12)
    assert not warm and code == lcp.STATUS_SOLVED and natural_residual(S, [-1.0, 1.0], z) < 1e-14
    assert residual == pytest.approx(natural_residual(S, [-1.0, 1.0], z), abs=1e-15)
    # contact-like problems (as `random_fc2d`, whose solvability holds for any free velocity):
    # the basis of one solves its neighbour, a slightly different free velocity, without a pivot
    rng = np.random.default_rng(3)
    warm_count = 0
    for _ in range(20):
        nc, ndof = 4, 6
        J = rng.integers(-3, 4, size=(2 * nc, ndof)).astype(float)
        W = J @ np.diag(rng.choice([0.5, 1.0, 2.0], ndof)) @ J.T
        v, gap = rng.integers(-8, 9, ndof) / 4.0, np.zeros(2 * nc)
        gap[0::2] = rng.integers(0, 5, nc) / 4.0 * (rng.random(nc) < 0.5)
        mu = rng.integers(1, 9, nc) / 8.0
        base = contact_lcp_from_fc2d(W, J @ v + gap, mu)
        _, _, code, _, basic_z, _, _ = lemke_warm_kernel(base.M, base.q, 1000, np.zeros(base.q.size, np.bool_), 1e-12)
        assert code == lcp.STATUS_SOLVED
        near = contact_lcp_from_fc2d(W, J @ (v + 1e-7 * rng.standard_normal(ndof)) + gap, mu)
        z, w, code, pivots, _, warm, residual = lemke_warm_kernel(near.M, near.q, 1000, basic_z, 1e-12)
        assert code == lcp.STATUS_SOLVED and natural_residual(near.M, near.q, z) <= 1e-12
        assert residual == pytest.approx(natural_residual(near.M, near.q, z), rel=1e-9, abs=1e-15)
        warm_count += warm
        assert not warm or pivots == 0
    assert warm_count >= 15


def test_lemke_from_a_failed_guess_solves_exactly_in_fewer_pivots():
    """`lemke_from_guess_into` follows Lemke's path from a guessed basis that does not solve
    the LCP (on the principal pivot transform that makes it the standard basis, its columns
    made as they enter) and solves the final basis on M itself: on contact-like LCPs (as
    `random_fc2d`) from the basis of a neighbouring problem (another free velocity), of a
    random one and of none, every solve ends on a point of M whose natural-map residual is
    recomputed and at most the tolerance, and on the P-matrix problems (no friction: a unique
    solution) it is the solution from scratch. From the neighbour's basis the paths are shorter
    than from scratch."""
    rng = np.random.default_rng(11)
    warm_pivots, cold_pivots, neighbours = 0, 0, 0
    for trial in range(60):
        nc, ndof = 4, 6
        J = rng.integers(-3, 4, size=(2 * nc, ndof)).astype(float)
        W = J @ np.diag(rng.choice([0.5, 1.0, 2.0], ndof)) @ J.T + 1e-3 * np.eye(2 * nc)
        v, gap = rng.integers(-8, 9, ndof) / 4.0, np.zeros(2 * nc)
        gap[0::2] = rng.integers(0, 5, nc) / 4.0 * (rng.random(nc) < 0.5)
        frictionless = trial % 3 == 0
        if frictionless:  # the normals' LCP alone: W's normal block, positive definite
            Wn = W[0::2, 0::2]
            base = SimpleNamespace(M=Wn, q=(J @ v + gap)[0::2])
            near_q = (J @ (v + 0.3 * rng.standard_normal(ndof)) + gap)[0::2]
            near = SimpleNamespace(M=Wn, q=near_q)
        else:
            mu = rng.integers(1, 9, nc) / 8.0
            base = contact_lcp_from_fc2d(W, J @ v + gap, mu)
            near = contact_lcp_from_fc2d(W, J @ (v + 0.3 * rng.standard_normal(ndof)) + gap, mu)
        n = near.q.size
        _, _, code, _, basic = lcp.lemke_warm_kernel(base.M, base.q, 1000, np.zeros(n, np.bool_), 1e-12)[:5]
        assert code == lcp.STATUS_SOLVED
        z_cold, _, code, cold = lemke_kernel(near.M, near.q, 1000)
        assert code == lcp.STATUS_SOLVED
        for guess in (basic, rng.random(n) < 0.4, np.zeros(n, np.bool_)):
            z, w, basic_z = np.empty(n), np.empty(n), np.empty(n, np.bool_)
            J_, A = np.empty(n, np.int64), np.empty((n + 1, n))
            status, pivots, residual = lcp.lemke_from_guess_into(
                near.M, near.q, guess.copy(), 1000, lcp.lemke_work(n), z, w, basic_z, J_, A, 1e-12
            )
            assert status == lcp.STATUS_SOLVED
            assert residual == pytest.approx(natural_residual(near.M, near.q, z), abs=1e-15) and residual <= 1e-12
            np.testing.assert_allclose(w, near.M @ z + near.q, atol=1e-12)
            assert np.all(z[~basic_z] == 0.0)
            if frictionless:
                np.testing.assert_allclose(z, z_cold, rtol=1e-9, atol=1e-12)
            if guess is basic and lcp.warm_guess_into(near.M, near.q, guess, J_, A, np.empty(n), np.empty(n)) > 1e-12:
                neighbours += 1
                warm_pivots += pivots
                cold_pivots += cold
    assert neighbours >= 20
    assert warm_pivots < 0.7 * cold_pivots


def test_a_singular_guess_is_tried_again_without_a_redundant_row():
    """A rigid plate on four coplanar corners: their normals span three DOFs (height, roll,
    pitch), so the guess that all four push is singular. `warm_guess_dropping_into` tries it
    again without each of its first `droppable` basic rows in turn and keeps the first that
    solves the LCP: without corner 0, corners 1 and 2 (a diagonal) carry the plate's weight.
    Lemke's warm kernel does the same when told how many rows it may drop, and still pivots
    from scratch when none does."""
    a, b = 0.1, 0.05
    corners = np.array([[a, b], [a, -b], [-a, b], [-a, -b]])
    N = np.column_stack([np.ones(4), corners[:, 1], -corners[:, 0]])  # normal velocity = N v
    M = N @ np.diag([2.0, 50.0, 20.0]) @ N.T  # rank 3: N A^-1 N^T
    q = N @ np.array([-1.0, 0.0, 0.0])  # falling: every corner approaching at 1
    n = 4
    work = np.empty(n, np.int64), np.empty((n + 1, n)), np.empty(n), np.empty(n)
    assert lcp.warm_guess_into(M, q, np.ones(n, np.bool_), *work) == np.inf  # singular
    guess = np.ones(n, np.bool_)
    residual = warm_guess_dropping_into(M, q, guess, *work, n, 1e-12)
    z = work[2]
    assert guess.tolist() == [False, True, True, True]
    assert residual <= 1e-12 and natural_residual(M, q, z) <= 1e-12
    np.testing.assert_allclose(N.T @ z, [0.5, 0.0, 0.0], atol=1e-14)  # the plate's momentum stopped
    np.testing.assert_allclose(z, [0.0, 0.25, 0.25, 0.0], atol=1e-14)
    z, w, code, pivots, basic_z, warm, residual = lemke_warm_kernel(M, q, 100, np.ones(n, np.bool_), 1e-12, n)
    assert warm and pivots == 0 and code == lcp.STATUS_SOLVED and natural_residual(M, q, z) <= 1e-12
    z, w, code, pivots, basic_z, warm, residual = lemke_warm_kernel(M, q, 100, np.ones(n, np.bool_), 1e-12)
    assert not warm and pivots > 0 and code == lcp.STATUS_SOLVED and natural_residual(M, q, z) <= 1e-12
    # no drop solves it (the only basic row dropped leaves w = q < 0): +inf, the guess as given
    S = np.array([[0.0, 1.0], [-1.0, 1.0]])
    guess = np.array([True, False])
    assert warm_guess_dropping_into(S, np.array([-1.0, 1.0]), guess, *work, 2, 1e-12) == np.inf
    assert guess.tolist() == [True, False]


# ------------------------------------------------------------------------------------------
# PGS specifics
# ------------------------------------------------------------------------------------------
def test_pgs_zero_diagonal_on_friction_lcp():
    rng = np.random.default_rng(7)
    W, q, _ = random_fc2d(rng, nc=3, ndof=8)
    mu = np.array([0.5, 0.25, 1.0])
    prob = contact_lcp_from_fc2d(W, q, mu)
    assert np.all(prob.gamma_index >= 0)
    assert np.all(np.diag(prob.M)[prob.gamma_index] == 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no division-by-zero RuntimeWarning either
        res = solve_lcp(prob.M, prob.q, "pgs")
    assert res.status is LCPStatus.ZERO_DIAGONAL
    assert not res.success and res.iterations == 0
    assert np.all(np.isfinite(res.z))
    # Lemke solves the same LCP
    lem = solve_lcp(prob.M, prob.q)
    assert lem.success


@pytest.mark.parametrize("diag", [[0.0, 1.0], [1.0, -2.0], [1.0, 1e-20], [1e-30, 1e-30]], ids=str)
def test_pgs_zero_or_tiny_or_negative_diagonal(diag):
    M = np.diag(diag) + np.array([[0.0, 0.5], [0.5, 0.0]])
    q = np.array([-1.0, -1.0])
    res = solve_lcp(M, q, "pgs")
    if diag == [1e-30, 1e-30]:
        # tiny but uniformly scaled: relative test passes, PGS runs (and must stay honest)
        assert res.status is not LCPStatus.ZERO_DIAGONAL
        assert (not res.success) or natural_residual(M, q, res.z) <= DEFAULT_TOL
    else:
        assert res.status is LCPStatus.ZERO_DIAGONAL
    z, w, code, it = pgs_kernel(np.diag([1.0, 0.0]), q, np.zeros(2), 10, 1e-9, 1.0)
    assert code == lcp.STATUS_ZERO_DIAGONAL and it == 0


def test_pgs_warm_start_at_solution_needs_no_sweep():
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    q = np.array([-5.0, -6.0])
    z_star = np.array([4.0 / 3.0, 7.0 / 3.0])
    res = solve_lcp(M, q, "pgs", z0=z_star)
    assert res.success and res.iterations == 0
    cold = solve_lcp(M, q, "pgs")
    assert cold.success and cold.iterations > 0


def test_pgs_over_relaxation_and_iteration_limit():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(15, 15))
    M = A @ A.T + 0.1 * np.eye(15)
    q = rng.normal(size=15)
    ref = solve_lcp(M, q)
    assert ref.success
    for omega in (0.7, 1.0, 1.3):
        res = solve_lcp(M, q, "pgs", omega=omega, max_iterations=200_000)
        assert res.success, (omega, res.status)
        np.testing.assert_allclose(res.z, ref.z, atol=1e-6)
    short = solve_lcp(M, q, "pgs", max_iterations=3)
    assert short.status is LCPStatus.MAX_ITERATIONS and short.iterations == 3
    assert short.residual > DEFAULT_TOL


def test_pgs_divergence_is_non_finite_output():
    # w1 + w2 = -z1 - z2 - 2 < 0: no solution.  PGS iterates z <- 1 + 2 z (x4 per sweep)
    # until overflow, and must say so; Lemke proves infeasibility (M is not copositive, so
    # the ray alone would prove nothing, but here it is right).
    M = np.array([[1.0, -2.0], [-2.0, 1.0]])
    q = np.array([-1.0, -1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = solve_lcp(M, q, "pgs")
    assert res.status is LCPStatus.NON_FINITE_OUTPUT
    assert res.residual == np.inf and not res.success
    assert 0 < res.iterations < 1000
    assert solve_lcp(M, q).status is LCPStatus.RAY_TERMINATION


# ------------------------------------------------------------------------------------------
# Lemke vs PGS on random contact LCPs
# ------------------------------------------------------------------------------------------
def test_lemke_and_pgs_agree_on_random_contact_lcps():
    rng = np.random.default_rng(2024)
    compared = 0
    for t in range(300):
        ndof = int(rng.integers(3, 10))
        Minv = np.diag(rng.uniform(0.5, 2.0, ndof))
        if t % 2 == 0:  # frictionless, fewer contacts than DOFs: M = J Minv J^T is PD
            m = int(rng.integers(1, ndof))
            J = rng.normal(size=(m, ndof))
            M = J @ Minv @ J.T
        else:  # more contacts than DOFs: PSD, regularised to PD (compliant contacts)
            m = int(rng.integers(ndof, 2 * ndof + 1))
            J = rng.normal(size=(m, ndof))
            M = J @ Minv @ J.T + rng.uniform(0.05, 0.5) * np.eye(m)
        q = rng.normal(size=m)
        lem = solve_lcp(M, q)
        pgs = solve_lcp(M, q, "pgs", max_iterations=100_000)
        assert lem.status is LCPStatus.SOLVED, (t, lem.status)
        assert pgs.status is LCPStatus.SOLVED, (t, pgs.status)
        assert lem.residual <= DEFAULT_TOL and pgs.residual <= DEFAULT_TOL
        assert natural_residual(M, q, lem.z) <= DEFAULT_TOL
        assert natural_residual(M, q, pgs.z) <= DEFAULT_TOL
        np.testing.assert_allclose(lem.z, pgs.z, atol=1e-6, err_msg=f"problem {t}")
        compared += 1
    assert compared == 300


def test_lemke_solves_random_friction_lcps_and_coulomb_holds():
    rng = np.random.default_rng(99)
    for t in range(60):
        nc = int(rng.integers(1, 6))
        ndof = int(rng.integers(2, 10))
        W, q, mu = random_fc2d(rng, nc, ndof)
        if t % 3 == 0:
            mu[rng.random(nc) < 0.5] = 0.0  # some frictionless contacts
        prob = contact_lcp_from_fc2d(W, q, mu)
        res = solve_lcp(prob.M, prob.q)
        assert res.status is LCPStatus.SOLVED, (t, res.status)
        assert res.residual <= DEFAULT_TOL
        r = fc2d_reactions_from_lcp(prob, res.z)
        assert fc2d_coulomb_error(W, q, mu, r) <= 1e-8, t
        assert np.all(np.abs(r[1::2]) <= mu * r[0::2] + 1e-9)


# ------------------------------------------------------------------------------------------
# The wrapper never trusts the kernel and never raises
# ------------------------------------------------------------------------------------------
def test_wrapper_downgrades_a_lying_kernel(monkeypatch):
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    q = np.array([-5.0, -6.0])

    def liar(M, q, max_pivots):
        z = np.array([1.0, 1.0])  # not a solution
        return z, np.zeros(2), lcp.STATUS_SOLVED, 1

    monkeypatch.setattr(lcp, "lemke_kernel", liar)
    res = solve_lcp(M, q)
    assert res.status is LCPStatus.NUMERICAL_FAILURE
    np.testing.assert_allclose(res.w, M @ np.ones(2) + q)  # recomputed, not the kernel's
    assert res.residual == pytest.approx(natural_residual(M, q, np.ones(2)))

    def slightly_off(M, q, max_pivots):
        return np.array([4.0 / 3.0 + 1e-8, 7.0 / 3.0]), np.zeros(2), lcp.STATUS_SOLVED, 3

    monkeypatch.setattr(lcp, "lemke_kernel", slightly_off)
    assert solve_lcp(M, q).status is LCPStatus.SOLVED_INACCURATE

    def nan_kernel(M, q, max_pivots):
        return np.array([np.nan, 1.0]), np.zeros(2), lcp.STATUS_SOLVED, 3

    monkeypatch.setattr(lcp, "lemke_kernel", nan_kernel)
    res = solve_lcp(M, q)
    assert res.status is LCPStatus.NON_FINITE_OUTPUT and res.residual == np.inf


def test_tolerance_controls_solved_vs_inaccurate():
    M = np.array([[4.0, 1.0, 0.3], [1.0, 3.0, 0.2], [0.3, 0.2, 5.0]]) / 3.0
    q = np.array([-1.0, -2.0, -0.7]) / 7.0
    res = solve_lcp(M, q)
    assert res.success and 0.0 < res.residual <= DEFAULT_TOL
    tight = solve_lcp(M, q, tol=res.residual / 2)
    assert tight.status is LCPStatus.SOLVED_INACCURATE
    assert tight.residual <= INACCURATE_TOL


def test_invalid_inputs_are_statuses_not_exceptions():
    good_M = np.eye(2)
    cases = [
        (np.eye(3), np.ones(2)),  # size mismatch
        (np.ones((2, 3)), np.ones(2)),  # non-square
        (np.ones(4), np.ones(2)),  # 1-D M
        (good_M, np.ones((2, 1))),  # 2-D q
        (5.0, 1.0),  # scalars
        ([[1, 2], [3]], [1, 2]),  # ragged
        ([["a", "b"], ["c", "d"]], [1, 2]),  # not numbers
        (np.eye(2) * 1j, np.ones(2)),  # complex
        (None, None),
    ]
    for method in METHODS:
        for M, q in cases:
            res = solve_lcp(M, q, method)
            assert res.status is LCPStatus.INVALID_INPUT, (method, M, q)
            assert not res.success and res.residual == np.inf
        for kwargs in (
            {"tol": -1.0},
            {"tol": float("nan")},
            {"omega": 2.0},
            {"omega": 0.0},
            {"max_iterations": -1},
            {"max_iterations": 2.5},
            {"z0": np.ones(3)},
        ):
            res = solve_lcp(good_M, -np.ones(2), method, **kwargs)
            assert res.status is LCPStatus.INVALID_INPUT, (method, kwargs)
    with pytest.raises(ValueError, match="unknown LCP method"):
        solve_lcp(good_M, np.ones(2), method="dantzig")


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input(method, bad):
    M = np.eye(2)
    q = np.array([-1.0, -1.0])
    M_bad = M.copy()
    M_bad[0, 1] = bad
    q_bad = q.copy()
    q_bad[1] = bad
    for args in ((M_bad, q), (M, q_bad)):
        res = solve_lcp(*args, method)
        assert res.status is LCPStatus.NON_FINITE_INPUT and not res.success
    res = solve_lcp(M, q, method, z0=np.array([0.0, bad]))
    assert res.status is LCPStatus.NON_FINITE_INPUT


def test_accepts_lists_ints_and_non_contiguous_arrays():
    base = np.array([[2, 1, 0], [1, 2, 0], [0, 0, 1]])
    Mf = np.asfortranarray(base.astype(float))
    big = np.zeros((6, 6))
    big[::2, ::2] = base
    strided = big[::2, ::2]
    q = [-5, -6, 1]
    for M in (base.tolist(), base, Mf, strided):
        for method in METHODS:
            res = solve_lcp(M, q, method)
            assert res.success, (M, method)
            np.testing.assert_allclose(res.z, [4 / 3, 7 / 3, 0.0], atol=1e-8)


@pytest.mark.parametrize("method", METHODS)
def test_overflowing_values_do_not_raise(method):
    M = np.array([[1e308, -1e308], [-1e308, 1e308]])
    q = np.array([-1e308, 1e308])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = solve_lcp(M, q, method)
    assert isinstance(res.status, LCPStatus)
    assert (not res.success) or natural_residual(M, q, res.z) <= DEFAULT_TOL


def test_complementarity_residual_values():
    M = np.eye(2)
    q = np.array([-1.0, 3.0])
    assert complementarity_residual(M, q, np.array([1.0, 0.0])) == 0.0
    # z = 0: w = q, min(z, w) = (-1, 0) -> 1 / (1 + 3)
    assert complementarity_residual(M, q, np.zeros(2)) == pytest.approx(0.25)
    # both positive: min(2, 1) = 1 at index 0
    assert complementarity_residual(M, q, np.array([2.0, 0.0])) == pytest.approx(0.25)
    assert complementarity_residual(M, q, np.array([np.nan, 0.0])) == np.inf


# ------------------------------------------------------------------------------------------
# Property tests
# ------------------------------------------------------------------------------------------
_floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
_nice = st.floats(min_value=-10, max_value=10, allow_nan=False, allow_infinity=False)


@st.composite
def lcp_inputs(draw):
    n = draw(st.integers(0, 6))
    elems = draw(st.sampled_from([_nice, _floats, st.just(0.0), st.integers(-3, 3)]))
    M = draw(hnp.arrays(np.float64, (n, n), elements=elems))
    q = draw(hnp.arrays(np.float64, (n,), elements=st.one_of(_nice, _floats)))
    shape_bug = draw(st.integers(0, 5))
    if shape_bug == 1:
        q = np.append(q, 1.0)
    elif shape_bug == 2:
        M = M[:, : max(n - 1, 0)]
    elif shape_bug == 3:
        q = q.reshape(-1, 1)
    return M, q


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=lcp_inputs(), method=st.sampled_from(METHODS))
def test_property_never_raises_never_false_success(data, method):
    M, q = data
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = solve_lcp(M, q, method, max_iterations=500)
    assert isinstance(res.status, LCPStatus)
    finite_ok = M.ndim == 2 and q.ndim == 1 and M.shape == (q.size, q.size) and np.isfinite(M).all() and np.isfinite(q).all()
    if not finite_ok:
        assert res.status in (LCPStatus.INVALID_INPUT, LCPStatus.NON_FINITE_INPUT)
    if res.success:
        assert res.residual <= DEFAULT_TOL
        # recomputed independently (NumPy's M @ z): equal to the solver's up to the product's
        # round-off, n eps |M| |z| (found by this test: M entries of 2e8 and 4e7 whose terms
        # cancel to 1e-9, read 0 by one sum and 1.4e-9 by the other)
        terms = float(np.max(np.abs(M) @ np.abs(res.z), initial=0.0))
        roundoff = q.size * np.finfo(float).eps * terms / (1.0 + np.max(np.abs(q), initial=0.0))
        assert natural_residual(M, q, res.z) <= DEFAULT_TOL * (1 + 1e-9) + roundoff
        assert res.z.shape == q.shape
    if res.status is LCPStatus.SOLVED_INACCURATE:
        assert DEFAULT_TOL < res.residual <= INACCURATE_TOL


def exact_psd_problem(seed, n, scale):
    """A feasible LCP with M = scale * A A^T, A a small integer matrix and scale a power of
    two, and q = w* - M z* with dyadic z*, w*: every number is exact in floating point, so M
    is exactly PSD and the problem has the solution z* (Lemke must find a solution)."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, n + 1))
    A = rng.integers(-3, 4, size=(n, k)).astype(float)
    M = scale * (A @ A.T)
    z_star = np.where(rng.random(n) < 0.5, rng.integers(1, 9, n) / 4.0, 0.0)
    w_star = np.where(z_star > 0, 0.0, rng.integers(0, 9, n) / 4.0)
    return M, w_star - M @ z_star


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 7),
    scale=st.sampled_from([2.0**-20, 1.0, 2.0**20]),
)
def test_property_lemke_solves_psd_problems_with_a_solution(seed, n, scale):
    """PSD M is copositive-plus: when a solution exists Lemke must find one."""
    M, q = exact_psd_problem(seed, n, scale)
    res = solve_lcp(M, q)
    assert res.status is LCPStatus.SOLVED, (res.status, res.residual)
    assert natural_residual(M, q, res.z) <= DEFAULT_TOL


@pytest.mark.parametrize("seed", [2449629383, 3409553017, 3191630798, 1094990479])
def test_badly_scaled_degenerate_psd_regressions(seed):
    # Found by stress testing: rank-deficient PSD M scaled by 2^20, where a loose tie test
    # once let Lemke pick a wrong row (false "solution") or stop on a false ray.
    for n in range(4, 8):
        for scale in (2.0**-20, 1.0, 2.0**20):
            M, q = exact_psd_problem(seed, n, scale)
            res = solve_lcp(M, q)
            assert res.status is LCPStatus.SOLVED, (seed, n, scale, res.status)
            assert natural_residual(M, q, res.z) <= DEFAULT_TOL


@pytest.mark.slow
def test_stress_lemke_on_many_psd_and_friction_problems():
    rng = np.random.default_rng(31337)
    for t in range(20_000):
        M, q = exact_psd_problem(int(rng.integers(0, 2**32 - 1)), int(rng.integers(1, 9)), [2.0**-20, 1.0, 2.0**20][t % 3])
        res = solve_lcp(M, q)
        assert res.success and natural_residual(M, q, res.z) <= DEFAULT_TOL, t
    for t in range(3000):
        W, q, mu = random_fc2d(rng, int(rng.integers(1, 12)), int(rng.integers(2, 15)))
        if t % 5 == 0:  # badly scaled units (powers of two keep the data exact)
            W = W * 2.0 ** int(rng.integers(-14, 15))
            q = q * 2.0 ** int(rng.integers(-14, 15))
        prob = contact_lcp_from_fc2d(W, q, mu)
        res = solve_lcp(prob.M, prob.q)
        assert res.success, (t, res.status)
        r = fc2d_reactions_from_lcp(prob, res.z)
        assert fc2d_coulomb_error(W, q, mu, r) <= 1e-8, t


# ------------------------------------------------------------------------------------------
# fc2d <-> LCP
# ------------------------------------------------------------------------------------------
def test_fc2d_conversion_layout_and_frictionless_drop():
    rng = np.random.default_rng(5)
    W, q, _ = random_fc2d(rng, nc=3, ndof=7)
    mu = np.array([0.5, 0.0, 0.3])
    prob = contact_lcp_from_fc2d(W, q, mu)
    assert prob.M.shape == (9, 9) and prob.q.shape == (9,)
    np.testing.assert_array_equal(prob.normal_index, [0, 4, 5])
    np.testing.assert_array_equal(prob.plus_index, [1, -1, 6])
    np.testing.assert_array_equal(prob.gamma_index, [3, -1, 8])
    # the normal-normal block is W_nn, the sliding rows read mu r_n - b+ - b-
    normals = np.ix_([0, 4, 5], [0, 4, 5])
    np.testing.assert_allclose(prob.M[normals], W[np.ix_([0, 2, 4], [0, 2, 4])])
    s0 = prob.gamma_scale[0]
    assert s0 == 2.0 ** np.round(np.log2(max(W[0, 0], W[1, 1])))
    np.testing.assert_allclose(prob.M[3, [0, 1, 2, 3]], s0 * np.array([0.5, -1.0, -1.0, 0.0]))
    np.testing.assert_allclose(prob.M[[1, 2], 3], [s0, s0])
    np.testing.assert_allclose(prob.q[[1, 2, 3]], [q[1], -q[1], 0.0])
    all_zero = contact_lcp_from_fc2d(W, q, np.zeros(3))
    np.testing.assert_allclose(all_zero.M, W[::2, ::2])
    z = np.arange(9.0)
    r = fc2d_reactions_from_lcp(prob, z)
    np.testing.assert_allclose(r, [0.0, 1.0 - 2.0, 4.0, 0.0, 5.0, 6.0 - 7.0])
    with pytest.raises(ValueError):
        contact_lcp_from_fc2d(W, q, np.array([0.5, -0.1, 0.3]))
    with pytest.raises(ValueError):
        contact_lcp_from_fc2d(W[:4, :4], q, mu)


def test_fc2d_coulomb_error_detects_each_violation():
    W = np.eye(2)
    mu = np.array([0.5])
    # sticking contact: q_t = 0 -> r = (1, 0) with q = (-1, 0) is a solution
    assert fc2d_coulomb_error(W, np.array([-1.0, 0.0]), mu, np.array([1.0, 0.0])) == 0.0
    # sliding: u_t = r_t + q_t with q_t = 2 -> r_t = -0.5, u_t = 1.5 > 0: opposite, OK
    assert fc2d_coulomb_error(W, np.array([-1.0, 2.0]), mu, np.array([1.0, -0.5])) == 0.0
    # wrong sliding direction
    assert fc2d_coulomb_error(W, np.array([-1.0, 2.0]), mu, np.array([1.0, 0.5])) > 0.1
    # outside the cone
    assert fc2d_coulomb_error(W, np.array([-1.0, -0.8]), mu, np.array([1.0, 0.8])) > 0.1
    # normal complementarity: separating contact pushing
    assert fc2d_coulomb_error(W, np.array([1.0, 0.0]), mu, np.array([1.0, 0.0])) > 0.1
    # sticking force inside the cone but the contact slides
    assert fc2d_coulomb_error(W, np.array([-1.0, 0.3]), mu, np.array([1.0, 0.1])) > 0.1
    assert fc2d_coulomb_error(W, np.array([-1.0, 0.0]), mu, np.array([np.nan, 0.0])) == np.inf


def test_fc2d_lcp_solution_matches_hand_solution():
    # one contact, decoupled W = I: pushed in (q_n = -1) and sliding (q_t = 2), mu = 0.5:
    # r_n = 1, r_t = -0.5 (opposes u_t = 1.5).
    W = np.eye(2)
    q = np.array([-1.0, 2.0])
    mu = np.array([0.5])
    prob = contact_lcp_from_fc2d(W, q, mu)
    res = solve_lcp(prob.M, prob.q)
    assert res.success
    r = fc2d_reactions_from_lcp(prob, res.z)
    np.testing.assert_allclose(r, [1.0, -0.5], atol=1e-12)
    gamma = res.z[prob.gamma_index[0]] * prob.gamma_scale[0]
    assert gamma == pytest.approx(1.5)  # the sliding speed
    # sticking case: q_t = 0.2 -> r_t = -0.2 within the cone, u_t = 0
    q2 = np.array([-1.0, 0.2])
    prob2 = contact_lcp_from_fc2d(W, q2, mu)
    r2 = fc2d_reactions_from_lcp(prob2, solve_lcp(prob2.M, prob2.q).z)
    np.testing.assert_allclose(r2, [1.0, -0.2], atol=1e-12)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=lcp_inputs(), seed=st.integers(0, 2**32 - 1))
def test_property_lemke_from_any_guess_never_false_success(data, seed):
    """Lemke's method from any guessed basis (`lemke_warm_kernel`: the guess, then
    `lemke_from_guess_into`, then from scratch): on any finite square LCP and any guess it
    returns, never raises, and where it reports a solution, its residual is the point's own,
    recomputed independently (to the product's round-off), and a guess it accepts is exact to
    the tolerance asked. (Lemke's paths are checked against known solutions above.)"""
    M, q = data
    assume(M.ndim == 2 and q.ndim == 1 and M.shape == (q.size, q.size) and q.size > 0)
    assume(np.isfinite(M).all() and np.isfinite(q).all())
    guess = np.random.default_rng(seed).random(q.size) < 0.5
    M, q = np.ascontiguousarray(M, float), np.ascontiguousarray(q, float)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        z, w, code, pivots, basic_z, warm, residual = lcp.lemke_warm_kernel(M, q, 500, guess.copy(), 1e-12)
    assert code in (
        lcp.STATUS_SOLVED,
        lcp.STATUS_SOLVED_INACCURATE,
        lcp.STATUS_RAY_TERMINATION,
        lcp.STATUS_MAX_ITERATIONS,
        lcp.STATUS_NON_FINITE_OUTPUT,
    )
    if code == lcp.STATUS_SOLVED and np.isfinite(residual):
        terms = float(np.max(np.abs(M) @ np.abs(z), initial=0.0))
        roundoff = q.size * np.finfo(float).eps * terms / (1.0 + np.max(np.abs(q), initial=0.0))
        assert abs(natural_residual(M, q, z) - residual) <= roundoff + 1e-15
        if warm:
            assert residual <= 1e-12


# ------------------------------------------------------------------------------------------
# matrix_view: the warm steps' and Lemke's C-contiguous views of their flat buffers
# ------------------------------------------------------------------------------------------
@numba.njit(cache=False)
def _views_of(buf, offset, rows, cols):
    """matrix_view and reshape of buf[offset:]'s first rows * cols entries, and the view's
    (0, 0) and last entry written through (to 1 and 2)."""
    v = lcp.matrix_view(buf[offset:], rows, cols)
    r = buf[offset : offset + rows * cols].reshape((rows, cols))
    same = v.shape == r.shape and (rows * cols == 0 or v.strides == r.strides)  # (an empty array's strides are moot)
    for i in range(rows):
        for j in range(cols):
            if v[i, j] != r[i, j]:
                same = False
    if rows > 0 and cols > 0:
        v[0, 0] = 1
        v[rows - 1, cols - 1] = 2
    return same


@numba.njit(cache=False)
def _view_too_big(buf, rows, cols):
    return lcp.matrix_view(buf, rows, cols).shape[0]


@pytest.mark.parametrize("dtype", [np.float64, np.int64])
@pytest.mark.parametrize(("offset", "rows", "cols"), [(0, 3, 4), (5, 2, 7), (0, 0, 5), (3, 6, 1), (1, 4, 0)])
def test_matrix_view_is_reshape_without_its_call(dtype, offset, rows, cols):
    """matrix_view(buf, r, c) is buf[: r * c].reshape((r, c)): the same shape, strides (of a
    non-empty view) and entries, and a write through it lands in buf at row-major offsets."""
    buf = np.arange(40, dtype=dtype) + 10
    assert _views_of(buf, offset, rows, cols)
    if rows > 0 and cols > 0:
        assert buf[offset] == 1 and buf[offset + rows * cols - 1] == 2
        untouched = np.delete(np.arange(40), [offset, offset + rows * cols - 1])
        assert np.array_equal(buf[untouched], untouched + 10)


def test_matrix_view_that_does_not_fit_raises():
    """A view larger than its buffer (or of a negative size) raises, as reshape does on a size
    that does not match, instead of reading past the buffer."""
    buf = np.zeros(12)
    assert _view_too_big(buf, 3, 4) == 3
    for rows, cols in [(3, 5), (13, 1), (-1, 4)]:
        with pytest.raises(ValueError, match="does not fit"):
            _view_too_big(buf, rows, cols)


def test_matrix_view_takes_integer_sizes_only():
    """A float size is refused when the kernel is typed, not truncated to an integer."""
    with pytest.raises(numba.core.errors.TypingError):
        _view_too_big(np.zeros(12), 3.0, 4)


def test_refinement_on_a_singular_basis_solves_its_rows():
    """Two identical contacts (a statically indeterminate pair) make M[J, J] singular, and there
    a z off by 1e-6 on one of them leaves its rows 3 short. `refined_on_basis` corrects the
    basic unknowns by least squares: the rows solved to round-off, the pair's total kept, the
    non-basic unknown untouched. A correction that would take an unknown below 0 stops it at 0,
    and the residual says what is left."""
    from models.stepper import LCP_TOLERANCE

    a, b = 3.0e6, 9.8e3
    M = np.array([[a, a, 0.0], [a, a, 0.0], [0.0, 0.0, 1.0]])
    q = np.array([-b, -b, 1.0])
    basic = np.array([True, True, False])
    z = np.array([b / a / 2 + 1e-6, b / a / 2, 0.0])
    assert np.allclose(M @ z + q, [3.0, 3.0, 1.0])
    out, w, residual = lcp.refined_on_basis(M, q, z, basic)
    np.testing.assert_allclose(w, M @ out + q, rtol=0, atol=0)
    assert np.abs(w[:2]).max() < 1e-9 and w[2] == 1.0
    assert out[0] + out[1] == pytest.approx(b / a, rel=1e-14) and out[2] == 0.0
    assert residual < 1e-15 and residual == lcp.complementarity_residual(M, q, out)
    # a correction past 0: the least-squares step splits the excess (3000 a row) over both, and the
    # second would go to -5e-4; stopped at 0, the rows are 1500 long and the residual says so
    past, w, residual = lcp.refined_on_basis(M, q, np.array([b / a + 1e-3, 0.0, 0.0]), basic)
    assert past[1] == 0.0 and past[0] == pytest.approx(b / a + 5e-4, rel=1e-12)
    assert w[:2] == pytest.approx([1500.0, 1500.0], rel=1e-9) and residual > LCP_TOLERANCE

"""The OSQP wrapper: known solutions, honest statuses, recomputed residuals."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from models.qp import QPStatus, solve_qp


def test_projection_onto_a_halfspace_matches_the_closed_form():
    # min 1/2 |x - z|^2  s.t.  a.x >= b   ->   x = z + max(0, b - a.z) a / |a|^2
    rng = np.random.default_rng(3)
    for _ in range(50):
        z, a, b = rng.normal(size=3), rng.normal(size=3), rng.normal()
        r = solve_qp(np.eye(3), -z, a[None, :], [b], [np.inf])
        expected = z + max(0.0, b - a @ z) * a / (a @ a)
        assert r.status == QPStatus.SOLVED
        np.testing.assert_allclose(r.x, expected, atol=1e-7)
        assert r.primal_residual <= 1e-9 and r.dual_residual <= 1e-6


def test_min_norm_passive_speed_of_the_kinematic_rung():
    # eq. (8) for one pushed body: min |v|^2 s.t. psi + h (w_a u + w_p . v) >= 0
    psi, h, u = 0.0, 0.01, -1.0
    w_a, w_p = np.array([0.7]), np.array([0.5, -0.5])
    rhs = -(psi + h * w_a @ [u]) / h
    r = solve_qp(2 * np.eye(2), np.zeros(2), w_p[None, :], [rhs], [np.inf])
    assert r.success
    np.testing.assert_allclose(r.x, rhs * w_p / (w_p @ w_p), atol=1e-8)


def test_box_constraints_clip():
    r = solve_qp(np.eye(2), [-3.0, 3.0], np.eye(2), [-1.0, -1.0], [1.0, 1.0])
    assert r.success
    np.testing.assert_allclose(r.x, [1.0, -1.0], atol=1e-8)


def test_infeasible_is_a_status():
    r = solve_qp(np.eye(2), [1, 1], [[1, 1], [1, 1]], [1, -np.inf], [np.inf, 0])
    assert r.status == QPStatus.PRIMAL_INFEASIBLE and not r.success
    assert np.all(np.isnan(r.x))


def test_unbounded_is_a_status():
    r = solve_qp(np.zeros((2, 2)), [1, 1], [[1, 0]], [0], [1])
    assert r.status == QPStatus.DUAL_INFEASIBLE


def test_nonconvex_is_a_status():
    assert solve_qp(-np.eye(2), [1, 1], [[1, 0]], [0], [1]).status == QPStatus.SOLVER_ERROR


def test_bad_input_is_a_status():
    assert solve_qp(np.eye(2), [np.nan, 1], [[1, 0]], [0], [1]).status == QPStatus.NON_FINITE_INPUT
    assert solve_qp(np.eye(3), [1, 1], [[1, 0]], [0], [1]).status == QPStatus.INVALID_INPUT
    assert solve_qp(np.eye(2), [1, 1], [[1, 0]], [2], [1]).status == QPStatus.PRIMAL_INFEASIBLE
    assert solve_qp(np.eye(2), [1, 1], [[1, 0]], [np.inf], [np.inf]).status == QPStatus.NON_FINITE_INPUT


def test_empty_problem():
    r = solve_qp(np.zeros((0, 0)), np.zeros(0), np.zeros((0, 0)), np.zeros(0), np.zeros(0))
    assert r.success and r.x.shape == (0,)


@settings(max_examples=60, deadline=None)
@given(
    st.integers(1, 4),
    st.integers(0, 4),
    st.integers(0, 2**31 - 1),
    st.sampled_from([0.0, 1.0, 1e-8, 1e8, np.nan, np.inf]),
)
def test_never_raises_never_lies(n, m, seed, special):
    rng = np.random.default_rng(seed)
    L = rng.normal(size=(n, n))
    P = L @ L.T
    c = rng.normal(size=n)
    A = rng.normal(size=(m, n))
    lower, upper = -rng.uniform(0, 2, m), rng.uniform(0, 2, m)
    if m:
        A[0, 0] = special
    r = solve_qp(P, c, A, lower, upper)
    if r.success:
        assert r.primal_residual <= 1e-6 and r.dual_residual <= 1e-6

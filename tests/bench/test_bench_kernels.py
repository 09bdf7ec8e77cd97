"""Kernel benchmarks (pytest-benchmark; run with `pytest -m slow tests/bench --benchmark-enable`).

Per-call times are measured over compiled loops of many calls, so they exclude Python's
dispatch cost, which the rollout never pays.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

from models.contact import capacity, contact_jacobian, detect_contacts, tangents
from models.kinematics import compile_scene
from models.lcp import solve_lcp
from models.scenario import load_scenario
from tests.conftest import SCENARIOS

pytestmark = pytest.mark.slow
CALLS = 10_000


@numba.njit(cache=True)
def _contacts_loop(S, q, calls):
    cap = 0
    for p in range(S.pair_max_contacts.shape[0]):
        cap += S.pair_max_contacts[p]
    c_pair = np.zeros(cap, np.int64)
    c_psi = np.zeros(cap)
    c_n, c_t, c_o = np.zeros((cap, 3)), np.zeros((cap, 3)), np.zeros((cap, 3))
    c_pa, c_pb = np.zeros((cap, 3)), np.zeros((cap, 3))
    unsupported = np.zeros(S.pair_a.shape[0], np.int64)
    W_n, W_t = np.zeros((S.nv, cap)), np.zeros((S.nv, cap))
    nu = np.zeros(S.nv)
    total = 0
    for k in range(calls):
        q[1] -= 1e-9  # keep the compiler from hoisting the work
        nc, _ = detect_contacts(S, q, nu, 1e-4, 1e-3, c_pair, c_psi, c_n, c_pa, c_pb, unsupported)
        tangents(S, nc, c_n, c_t, c_o)
        contact_jacobian(S, q, nc, c_pair, c_n, c_pa, c_pb, W_n)
        contact_jacobian(S, q, nc, c_pair, c_t, c_pa, c_pb, W_t)
        total += nc
    return total


def test_paper_scene_distance_and_jacobians(benchmark):
    S = compile_scene(load_scenario(SCENARIOS / "two_finger_triangle.toml"))
    y = 0.5 + 0.05 * np.sqrt(2)
    q = np.array([0.0, y, y])
    _contacts_loop(S, q.copy(), 10)
    total = benchmark(_contacts_loop, S, q.copy(), CALLS)
    assert total >= 2 * CALLS  # both finger contacts found every call
    benchmark.extra_info["per_call_us"] = benchmark.stats.stats.median / CALLS * 1e6


def _contact_lcp(n, rng):
    J = rng.normal(size=(n, n + 2))
    M = J @ J.T + 1e-3 * np.eye(n)
    return M, rng.normal(size=n)


@pytest.mark.parametrize("n", [2, 4, 8, 16, 32, 64])
@pytest.mark.parametrize("method", ["lemke", "pgs"])
def test_lcp(benchmark, method, n):
    M, q = _contact_lcp(n, np.random.default_rng(n))
    result = benchmark(solve_lcp, M, q, method=method, max_iterations=100_000)
    assert result.residual < 1e-6

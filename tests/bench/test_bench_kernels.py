"""Kernel benchmarks (pytest-benchmark): `pytest -m slow tests/bench --benchmark-enable`.

Per-call times are measured over compiled loops of many calls, so they exclude Python's
dispatch cost, which the rollout never pays. `extra_info["per_call_us"]` holds the median
per call.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

from models.contact import ContactSet, contact_frames, detect_planar, jacobian_packed, tangents_packed
from models.contact3d import collide_pair_3d
from models.contact_pgs import body_blocks
from models.lcp import lemke_kernel, pgs_kernel
from models.rungs import RUNGS, compiled
from models.scenario import load_scenario
from models.stepper import contact_lcp, system_matrix
from tests.bench import timed_median
from tests.conftest import SCENARIOS

pytestmark = pytest.mark.slow
CALLS = 10_000


@numba.njit(cache=True)
def _contacts_loop(bi, bf, verts, pi, nv, q, calls):
    cap = 1
    for p in range(pi.shape[0]):
        cap += pi[p, 2]
    c_pair = np.zeros(cap, np.int64)
    c_psi = np.zeros(cap)
    c_n, c_t, c_o = np.zeros((cap, 3)), np.zeros((cap, 3)), np.zeros((cap, 3))
    c_pa, c_pb = np.zeros((cap, 3)), np.zeros((cap, 3))
    W_n, W_t = np.zeros((nv, cap)), np.zeros((nv, cap))
    nu = np.zeros(nv)
    total = 0
    for _ in range(calls):
        q[0] += 1e-12  # keep the compiler from hoisting the work
        nc = detect_planar(bi, bf, verts, pi, q, nu, 1e-4, 1e-3, c_pair, c_psi, c_n, c_pa, c_pb)
        tangents_packed(2, nc, c_n, c_t, c_o)
        jacobian_packed(bi, bf, pi, q, nc, c_pair, c_n, c_pa, c_pb, W_n)
        jacobian_packed(bi, bf, pi, q, nc, c_pair, c_t, c_pa, c_pb, W_t)
        total += nc
    return total


def _paper_scene():
    scenario = load_scenario(SCENARIOS / "two_finger_triangle.toml")
    y = 0.5 + 0.05 * np.sqrt(2)  # both fingers on the faces
    return scenario, compiled(scenario), np.array([0.0, y, y])


def test_paper_scene_distance_and_jacobians(benchmark):
    _, c, q = _paper_scene()
    S = c.scene
    args = (S.bi, S.bf, S.verts, S.pi, S.nv)
    _contacts_loop(*args, q.copy(), 10)
    total = benchmark(_contacts_loop, *args, q.copy(), CALLS)
    assert total >= 2 * CALLS  # both finger contacts found every call
    if (median := timed_median(benchmark)) is not None:
        benchmark.extra_info["per_call_us"] = median / CALLS * 1e6


def paper_scene_lcp():
    """The dynamic-compliant step's LCP with both fingers on the faces (h = 1e-4)."""
    scenario, c, q = _paper_scene()
    S, D = c.scene, c.drives
    h = 1e-4
    frames = contact_frames(S, q)
    fingers = np.flatnonzero(np.abs(frames.W_n[1:, :]).sum(axis=0) > 0)  # the two finger contacts
    A = system_matrix(S.bi, S.bf, q, S.nv, 1.0, h, D.v_index, D.kp, D.kd, D.max_force)
    nu_free = np.linalg.solve(A, np.array([0.0, -0.05, -0.05]))
    slots = np.arange(len(frames.psi))
    contacts = ContactSet(
        frames.pair,
        frames.psi,
        slots,
        np.ascontiguousarray(frames.W_n),
        np.ascontiguousarray(frames.W_t),
        np.zeros_like(frames.W_n),
        np.zeros((len(slots), 3)),
    )
    dofs, count, inv, ok = body_blocks(S.bi, A, np.linalg.inv(A))
    assert ok
    M, qv, *_ = contact_lcp(
        RUNGS["dynamic-compliant"].model,
        False,
        h,
        dofs,
        count,
        inv,
        nu_free,
        fingers.astype(np.int64),
        S.pi,
        S.pf,
        contacts,
        np.zeros(len(slots)),
        np.zeros((len(slots), 2)),
        D,
        np.zeros(len(D.v_index)),
    )
    return M, qv


@numba.njit(cache=True)
def _lemke_loop(M, q, calls):
    total = 0
    for _ in range(calls):
        q[0] += 1e-15
        z, w, status, pivots = lemke_kernel(M, q, 500)
        total += pivots
    return total


@numba.njit(cache=True)
def _pgs_loop(M, q, calls):
    total = 0
    z0 = np.zeros(q.shape[0])
    for _ in range(calls):
        q[0] += 1e-15
        z, w, status, iterations = pgs_kernel(M, q, z0, 100_000, 1e-9, 1.0)
        total += iterations
    return total


def test_lemke_on_the_paper_scene_lcp(benchmark):
    M, q = paper_scene_lcp()
    assert M.shape == (8, 8)  # 2 normals, 2 x 2 friction directions, 2 sliding speeds
    _lemke_loop(M, q.copy(), 10)
    pivots = benchmark(_lemke_loop, M, q.copy(), CALLS)
    assert pivots > 0
    if (median := timed_median(benchmark)) is not None:
        benchmark.extra_info["per_call_us"] = median / CALLS * 1e6
    benchmark.extra_info["pivots"] = pivots / CALLS


def _contact_lcp(n, rng):
    J = rng.normal(size=(n, n + 2))
    M = J @ J.T + 1e-3 * np.eye(n)
    return M, rng.normal(size=n)


@pytest.mark.parametrize("n", [4, 8, 16, 32, 64])
@pytest.mark.parametrize("method", ["lemke", "pgs"])
def test_lcp(benchmark, method, n):
    M, q = _contact_lcp(n, np.random.default_rng(n))
    loop = _lemke_loop if method == "lemke" else _pgs_loop
    calls = max(10, 20_000 // n**2)
    loop(M, q.copy(), 2)
    benchmark(loop, M, q.copy(), calls)
    if (median := timed_median(benchmark)) is not None:
        benchmark.extra_info["per_call_us"] = median / calls * 1e6


@numba.njit(cache=True)
def _collide_loop(S, q, p, margin, calls):
    cap = 8
    c_psi = np.zeros(cap)
    c_n, c_pa, c_pb = np.zeros((cap, 3)), np.zeros((cap, 3)), np.zeros((cap, 3))
    total = 0
    for _ in range(calls):
        q[0] += 1e-15  # keep the compiler from hoisting the work
        total += collide_pair_3d(S, q, p, margin, c_psi, c_n, c_pa, c_pb, 0)
    return total


def box_wedge_poses():
    """box_push_3d with the box against the wedge: (name, q) for a face contact (the box's +x
    face 0.1 mm into the wedge's back face, 4 contacts), the tilted box's face 0.1 mm into the
    slope, a vertical box edge 0.2 mm into the back face, and apart edge to edge (closest
    features)."""
    scenario = load_scenario(SCENARIOS / "box_push_3d.toml")
    q0 = np.array(scenario.start, float)
    out = []

    def pose(x, y, z, quat):
        q = q0.copy()
        q[0:3] = [x, y, z]
        q[3:7] = np.asarray(quat) / np.linalg.norm(quat)
        return q

    def yaw(a):
        return [np.cos(a / 2), 0.0, 0.0, np.sin(a / 2)]

    out.append(("face", pose(0.35 - 0.1 + 1e-4, -0.3, 0.05, [1.0, 0, 0, 0])))
    # tilted above the slope (normal (0.6, 0, 0.8)), 0.1 mm into it
    out.append(("tilted on slope", pose(0.47 - 0.6 * (0.0362105 + 1e-4), -0.35, 0.25 - 0.8 * (0.0362105 + 1e-4), [0.9, 0.2, -0.3, 0.1])))
    out.append(("edge", pose(0.35 - 0.1 * np.sqrt(2) + 2e-4, -0.35, 0.06, yaw(np.pi / 4))))
    # the box's corner edge 0.3 mm off the wedge's vertical edge at (0.35, -0.2) in x and y
    out.append(("apart", pose(0.25 - 3e-4, -0.1 + 3e-4, 0.05, [1.0, 0, 0, 0])))
    return scenario, out


def test_mesh_box_collide(benchmark):
    import time

    from models.kinematics import compile_scene

    scenario, poses = box_wedge_poses()
    S = compile_scene(scenario)
    names = [b.name for b in scenario.spec.bodies]
    p = next(i for i, (a, b) in enumerate(zip(S.pair_a, S.pair_b)) if {names[a], names[b]} == {"box", "wedge"})
    per_call = {}
    for name, q in poses:
        _collide_loop(S, q.copy(), p, 1e-2, 10)
        t0 = time.perf_counter()
        _collide_loop(S, q.copy(), p, 1e-2, CALLS)
        per_call[name] = (time.perf_counter() - t0) / CALLS * 1e6
    q = poses[0][1]
    benchmark(lambda: _collide_loop(S, q.copy(), p, 1e-2, CALLS))
    benchmark.extra_info["per_call_us"] = per_call

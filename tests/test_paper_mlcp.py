"""The paper's own MLCP (Section 4) against our stepper's contact problem.

Section 4 writes the dynamic model (3) of its scene, for the configuration where finger 1
is directly above the left edge of the triangle and finger 2 above the right one, as an MLCP
with q = (x3), M = 1, h = 1e-4, mu = 0.5, K = 1e6 (diagonal, normal and tangential) and
C = 1e4 (plastic) or 0 (elastic), and

    W_n = [[ s, -s],      W_t = [[ s,  s],      s = sqrt(2) / 2.
           [ s,  s]]             [ s,  s]]

Conventions (what "same problem" means here):

- The first row of each matrix is d/dx3 (q = (x3)); the second row is the derivative in the
  height y of the finger of that contact (the fingers' motion is prescribed, so it enters as
  a known velocity term). We model the prescribed fingers as scripted obstacles: our q is
  (x3) alone, as the paper's.
- W_n is the paper's exactly (x3 row: the Jacobian; y row: the scripted-motion term). A
  tangent's sign is a convention: the paper's x3 row of W_t is that of t1 = (-1, -1)/sqrt 2
  (down the left face) and t2 = (-1, 1)/sqrt 2 (up the right face); ours may point the other
  way (its +t and -t friction columns then swap). The paper's printed y row of W_t does not
  follow from any tangent of the left face: with x3 entry +s, a tangent of the left face has
  y entry -s (the printed +s is the left face's *normal*); we use the geometric one, -s.
- Units: the paper's unknowns are forces lambda; ours are impulses p = h lambda, its normal
  rows are divided by h, and our sliding-speed column gamma is scaled (`_scale_gamma`); we
  undo that scaling to compare.

The paper's MLCP is solved here independently of Lemke: by enumerating each contact's mode
(separate, stick, slide either way) with the exact 2-D Coulomb law, in the paper's force
variables. Our solution is one real step of the rung (`Rung.rollout`).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from models.contact import ContactSet, contact_buffers, contact_frames, place_scripted, scripted_bias
from models.contact_pgs import body_blocks
from models.rollout import _start_system
from models.rungs import compiled, own_poses, rung_for
from models.scenario import load_scenario
from models.stepper import SceneTables, _free_velocity, contact_lcp

S2 = math.sqrt(2.0) / 2.0
PAPER_W_N = np.array([[S2, -S2], [S2, S2]])
PAPER_W_T = np.array([[S2, S2], [S2, S2]])  # as printed (see the module docstring for its y row)
H, MU, K, MASS, R = 1e-4, 0.5, 1e6, 1.0, 0.05

SCENE = """
version = 1
[scenario]
name = "paper_mlcp"
[scene]
dimension = 2
gravity = [0.0, -9.81]
[contact]
mu = {mu}
K = {K}
C = {C}
[[bodies]]
name = "triangle"
role = "object"
mass = {mass}
inertia = 0.1667
shape = {{ type = "polygon", vertices = [[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0]] }}
pose = {{ x = {x3}, y = 0.0 }}
dofs = ["x"]
[[bodies]]
name = "finger1"
role = "obstacle"
shape = {{ type = "disc", radius = {r} }}
pose = {{ x = -0.5, y = {y1} }}
velocity = {{ y = {v1} }}
[[bodies]]
name = "finger2"
role = "obstacle"
shape = {{ type = "disc", radius = {r} }}
pose = {{ x = 0.5, y = {y2} }}
velocity = {{ y = {v2} }}
[task]
horizon = 1.0
goal = {{ box = {{ "triangle.x" = [100.0, 200.0] }} }}
[ladder]
time_limit = 1.0
[[ladder.rungs]]
model = "dynamic-compliant"
h = {h}
"""


def psi(x3, y1, y2):
    """Signed distances of the finger discs from the left and right faces (the faces' lines)."""
    return np.array([(x3 + y1 - 0.5) * S2 - R, (y2 - x3 - 0.5) * S2 - R])


def scene(tmp_path, C, x3, gaps, v1, v2):
    """The paper's scene with the fingers at signed distances `gaps` from their faces."""
    y1 = (gaps[0] + R) / S2 + 0.5 - x3
    y2 = (gaps[1] + R) / S2 + 0.5 + x3
    path = tmp_path / "paper_mlcp.toml"
    path.write_text(SCENE.format(mu=MU, K=K, C=C, mass=MASS, x3=x3, r=R, y1=y1, y2=y2, v1=v1, v2=v2, h=H))
    return load_scenario(path), (y1, y2)


def paper_solution(C, nu, psi_n, b_n, b_t, delta_n, delta_t):
    """The paper's MLCP solved by mode enumeration, in its force variables and its tangents.

    M (nu+ - nu) = h (W_n lambda_n + W_t lambda_t) (x3 rows; no force on x3 but contacts),
    0 <= lambda_n _|_ delta_n+ + psi + h (W_n^T nu+ + b_n) >= 0,
    lambda_t in [-mu lambda_n, mu lambda_n] maximising dissipation against
    s = W_t^T nu+ + b_t + (delta_t+ - delta_t) / h, with lambda = K delta+ + C / h (delta+ - delta).
    Returns every solution found: [(nu+, lambda_n, lambda_t)]."""
    wn, wt = PAPER_W_N[0], PAPER_W_T[0]
    c = 1.0 / (H * K + C)
    found = []
    for modes in itertools.product(("separate", "stick", "slide+", "slide-"), repeat=2):
        A, b = np.zeros((5, 5)), np.zeros(5)  # x = (nu+, lambda_n1, lambda_n2, lambda_t1, lambda_t2)
        A[0] = [MASS, -H * wn[0], -H * wn[1], -H * wt[0], -H * wt[1]]
        b[0] = MASS * nu
        for i, mode in enumerate(modes):
            rn, rt = 1 + 2 * i, 2 + 2 * i
            if mode == "separate":
                A[rn, 1 + i], A[rt, 3 + i] = 1.0, 1.0
                continue
            # w_n = 0: psi + h (wn nu + b_n) + (h lambda_n + C delta_n) c
            A[rn, 0], A[rn, 1 + i], b[rn] = H * wn[i], H * c, -(psi_n[i] + H * b_n[i] + C * delta_n[i] * c)
            if mode == "stick":  # s = 0
                A[rt, 0], A[rt, 3 + i], b[rt] = wt[i], c, -(b_t[i] - K * delta_t[i] * c)
            else:
                A[rt, 3 + i], A[rt, 1 + i] = 1.0, (MU if mode == "slide+" else -MU)
        try:
            x = np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            continue
        nu_new, lam_n, lam_t = x[0], x[1:3], x[3:5]
        s = wt * nu_new + b_t + lam_t * c - K * delta_t * c
        w = psi_n + H * (wn * nu_new + b_n) + (H * lam_n + C * delta_n) * c
        tol = 1e-9 * max(1.0, np.abs(x).max())
        ok = True
        for i, mode in enumerate(modes):
            if mode == "separate":
                ok &= w[i] >= -1e-12
            else:
                ok &= lam_n[i] >= -tol
                if mode == "stick":
                    ok &= abs(lam_t[i]) <= MU * lam_n[i] + tol
                elif mode == "slide+":
                    ok &= s[i] >= -1e-12
                else:
                    ok &= s[i] <= 1e-12
        if ok:
            found.append((nu_new, lam_n, lam_t, modes))
    return found


CASES = {
    # (C, x3, the fingers' signed distances at the start (a scene may not start in penetration),
    # finger speeds, steps taken before the step compared)
    "plastic, symmetric, first touch": (1e4, 0.0, (0.0, 0.0), -1.0, -1.0, 0),
    "plastic, unequal, deformed": (1e4, 0.05, (0.0, 5e-5), -0.8, -1.0, 30),
    "elastic, unequal, deformed": (0.0, -0.1, (1e-5, 0.0), -1.0, -0.5, 30),
    "plastic, one finger slow": (1e4, 0.2, (0.0, 0.0), -0.1, -1.0, 60),
}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_our_contact_problem_is_the_papers_mlcp(tmp_path, case):
    C, x3, gaps, v1, v2, before = CASES[case]
    sc, (y1, y2) = scene(tmp_path, C, x3, gaps, v1, v2)
    rung = rung_for(sc, "dynamic-compliant")
    state = rung.initial_state(sc)
    if before:  # some steps first: the step compared then starts with velocity and deformations
        warm = rung.rollout(sc, state, np.zeros((1, 0)), [before * H], H, stop_at_outcome=False)
        assert warm.ok
        state = warm.state
    t0 = before * H
    q, nu = state.q.copy(), state.nu.copy()
    c = compiled(sc)
    S = own_poses(c.scene)
    place_scripted(S.bf, S.base_pos, S.base_quat, t0)
    frames = contact_frames(S, q, nu, H)
    finger = [1 if "finger1" in (sc.pairs[p].body_a, sc.pairs[p].body_b) else 2 for p in frames.pair]
    assert sorted(finger) == [1, 2]  # one contact per finger, nothing else (the triangle has no palm here)
    order = [finger.index(1), finger.index(2)]  # our contact index of the paper's contact 1, 2
    _, first_slot = contact_buffers(S.pi, S.nv)
    slots = first_slot[frames.pair]

    # the matrices: M = 1, W_n's x3 row exactly, W_t's x3 row up to each tangent's sign
    assert S.nv == 1 and list(sc.coordinates) == ["triangle.x"]
    W_n, W_t = frames.W_n[0, order], frames.W_t[0, order]
    np.testing.assert_allclose(W_n, PAPER_W_N[0], rtol=0, atol=1e-12)
    sign = np.sign(W_t / PAPER_W_T[0])
    np.testing.assert_allclose(sign * W_t, PAPER_W_T[0], rtol=0, atol=1e-12)
    # the prescribed fingers' terms: the paper's y row of W_n times the finger speeds; for W_t
    # the geometric y row (-s, s) (see the docstring)
    bias = np.zeros((len(frames.pair), 3))
    scripted_bias(S.bf, S.pi, len(frames.pair), frames.pair, frames.n, frames.t, frames.o, frames.pa, frames.pb, bias)
    ydot = np.array([v1, v2])
    b_n, b_t = PAPER_W_N[1] * ydot, np.array([-S2, S2]) * ydot
    np.testing.assert_allclose(bias[order, 0], b_n, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sign * bias[order, 1], b_t, rtol=0, atol=1e-12)
    y = (y1 + v1 * t0, y2 + v2 * t0)
    psi_n = psi(q[0], *y)
    np.testing.assert_allclose(frames.psi[order], psi_n, rtol=0, atol=1e-12)

    # the LCP our step assembles, against the paper's in impulse units (z = h lambda)
    delta_n = state.delta_n[slots][order]
    delta_t = sign * state.delta_t[slots, 0][order]  # along the paper's tangents
    model, D = rung.model, c.drives
    system = _start_system(S, D, model, H, q)
    dofs, count, inv, ok = body_blocks(S.bi, system.A, system.Ainv)
    assert ok
    tables = SceneTables(S.bi, S.bf, S.pi, S.pf, False)
    nu_free, _, drive_a = _free_velocity(model, D, tables, system, H, q, nu, state.q_ref, np.zeros(0), dofs, count, inv)
    contacts = ContactSet(frames.pair, frames.psi, slots, frames.W_n, frames.W_t, np.zeros_like(frames.W_n), bias)
    active = np.arange(len(frames.pair), dtype=np.int64)
    Mo, qo, *_ = contact_lcp(
        model, False, H, dofs, count, inv, nu_free, active, S.pi, S.pf, contacts, state.delta_n, state.delta_t, D, drive_a
    )
    Mo, qo = Mo.copy(), qo.copy()
    for g in (6, 7):  # undo _scale_gamma: the friction rows' gamma entry was 1
        scale = Mo[2 + 2 * (g - 6), g]
        Mo[:, g] /= scale
        Mo[g, :] /= scale
    Mp, qp = paper_lcp(C, nu[0], psi_n, b_n, b_t, delta_n, delta_t)
    # our variables in the paper's order: contacts by `order`, +t/-t swapped where our t is -paper's
    perm = []
    for i in range(2):
        perm.append(order[i])
    for i in range(2):
        plus, minus = 2 + 2 * order[i], 3 + 2 * order[i]
        perm += [plus, minus] if sign[i] > 0 else [minus, plus]
    perm += [6 + order[0], 6 + order[1]]
    np.testing.assert_allclose(Mo[np.ix_(perm, perm)], Mp, rtol=1e-10, atol=1e-10 * np.abs(Mp).max())
    np.testing.assert_allclose(qo[perm], qp, rtol=1e-10, atol=1e-10 * np.abs(qp).max())

    # the solution: one real step against the paper's MLCP solved by enumeration
    solutions = paper_solution(C, nu[0], psi_n, b_n, b_t, delta_n, delta_t)
    assert solutions, "the paper's MLCP has no solution here"
    nu_p, lam_n, lam_t, modes = solutions[0]
    for other in solutions[1:]:  # a unique solution (several modes may describe it at a boundary)
        np.testing.assert_allclose(other[0], nu_p, rtol=1e-9, atol=1e-12)
    out = rung.rollout(sc, state, np.zeros((1, 0)), [H], H, stop_at_outcome=False, t0=t0)
    assert out.ok and out.steps == 1
    np.testing.assert_allclose(out.state.nu[0], nu_p, rtol=1e-9, atol=1e-12)
    for i in range(2):
        k = order[i]
        pair = frames.pair[k]
        n, t = frames.n[k, :2], sign[i] * frames.t[k, :2]
        on_b = lam_n[i] * n + lam_t[i] * t  # our n, t act on the pair's second body with these signs
        np.testing.assert_allclose(out.pair_force[pair], lam_n[i], rtol=1e-9, atol=1e-9 * max(1.0, abs(lam_n).max()))
        np.testing.assert_allclose(out.pair_wrench[pair][:2], on_b, rtol=1e-9, atol=1e-9 * max(1.0, abs(lam_n).max()))
        np.testing.assert_allclose(out.state.delta_n[slots[k]], (H * lam_n[i] + C * delta_n[i]) / (H * K + C), rtol=1e-9, atol=1e-15)
    assert all(m != "separate" for m in modes)  # the case exercises both contacts


def paper_lcp(C, nu, psi_n, b_n, b_t, delta_n, delta_t):
    """The paper's MLCP with nu+ eliminated, in impulses z = (p_n1, p_n2, beta_1+, beta_1-,
    beta_2+, beta_2-, gamma_1, gamma_2), p = h lambda, lambda_t = (beta+ - beta-) / h: normal
    rows over h, friction rows gamma +- s, gamma rows mu p_n - beta+ - beta-."""
    wn, wt = PAPER_W_N[0], PAPER_W_T[0]
    c = 1.0 / (H * (H * K + C))
    Mp, qp = np.zeros((8, 8)), np.zeros(8)
    cols = np.zeros(8)
    cols[0:2] = wn
    cols[2], cols[3], cols[4], cols[5] = wt[0], -wt[0], wt[1], -wt[1]
    rows = np.array([wn[0], wn[1], wt[0], -wt[0], wt[1], -wt[1]])
    Mp[:6, :6] = np.outer(rows, cols[:6]) / MASS
    qp[:6] = rows * nu
    for i in range(2):
        Mp[i, i] += c
        qp[i] += psi_n[i] / H + b_n[i] + c * C * delta_n[i]
        for j, sgn in ((2 + 2 * i, 1.0), (3 + 2 * i, -1.0)):
            qp[j] += sgn * (b_t[i] - K * delta_t[i] / (H * K + C))
            Mp[j, 2 + 2 * i] += sgn * c
            Mp[j, 3 + 2 * i] -= sgn * c
            Mp[j, 6 + i] = 1.0
            Mp[6 + i, j] = -1.0
        Mp[6 + i, i] = MU
    return Mp, qp

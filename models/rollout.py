"""Rollouts: many steps per call inside numba, with goal/unsafe checks and early stops.

`rollout_kernel` runs a piecewise-constant control sequence (controls[k] for durations[k]
seconds) with a fixed step h. Each step: detect contacts at q, classify q (unsafe first,
then goal; touch predicates use the contacts just found, so they cost nothing extra), then
step the model (`models.stepper`). It stops at the first of: unsafe entered, goal reached, a
step failure (status), the end of the controls (the final state is classified once more).
Every `record_every`-th state, and the last, is recorded for plots and plans.

Skipping what a scene does not need: with no contact the step is a free update with a
precomputed inverse system matrix; mu = 0 pairs get no friction variables; rigid models
carry no deformation; quasistatic models never touch the inertia terms.
"""

from __future__ import annotations

import numba
import numpy as np

from models.contact import (
    detect_planar,
    detect_planar_into,
    detect_spatial,
    has_script,
    jacobian_packed,
    place_scripted,
    scripted_bias,
    tangents_packed,
)
from models.predicates import evaluate, evaluate_with
from models.stepper import (
    CONTACT_MARGIN,
    QUASISTATIC_INERTIA,
    SOLVER_LEMKE,
    STEP_OK,
    STEP_SINGULAR,
    STEP_UNSUPPORTED_PAIR,
    any_limited,
    dynamics_step,
    free_step,
    gravity_force,
    has_rotations,
    kinematic_step,
    mass_matrix,
    system_matrix,
)

OUTCOME_NONE = 0
OUTCOME_GOAL = 1
OUTCOME_UNSAFE = 2
OUTCOME_NAMES = {OUTCOME_NONE: "none", OUTCOME_GOAL: "goal", OUTCOME_UNSAFE: "unsafe"}


@numba.njit(cache=True)
def _classify(goal, unsafe, q, pair_psi):
    outcome = OUTCOME_NONE
    if evaluate(unsafe, q, pair_psi):
        outcome = OUTCOME_UNSAFE
    elif evaluate(goal, q, pair_psi):
        outcome = OUTCOME_GOAL
    return outcome


@numba.njit(cache=True)
def _classify_with(g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, q, pair_psi, stack):
    outcome = OUTCOME_NONE
    if evaluate_with(u_op, u_index, u_lo, u_hi, q, pair_psi, stack):
        outcome = OUTCOME_UNSAFE
    elif evaluate_with(g_op, g_index, g_lo, g_hi, q, pair_psi, stack):
        outcome = OUTCOME_GOAL
    return outcome


@numba.njit(cache=True)
def _inverse_or_empty(A):
    """A^-1 when A is safely invertible, else an empty matrix (the step reports singularity)."""
    out = np.zeros((0, 0))
    ok = True
    for r in range(A.shape[0]):
        if not (A[r, r] > 0.0):
            ok = False
    if ok:
        out = np.linalg.inv(A).copy()
    return out


@numba.njit(cache=True)
def rollout_kernel(S, D, model, solver, goal, unsafe, q, nu, q_ref, delta_n, delta_t, controls, durations, h, record_every, max_records, stop_at_outcome, t0):
    """Run the controls from the given state (stopping at goal/unsafe if stop_at_outcome;
    otherwise the returned outcome is the first one met, and the run goes on).

    model: `models.stepper.Model` (what is solved); solver: `models.stepper.Solver` (how the
    contact problems are solved). t0: the time of the start state, where scripted obstacles
    are (their poses are written into S's pose tables as time goes on: pass a scene copy of
    the caller's own when the scene has one). PGS warm starts travel from step to step within the call
    (by contact slot) and start cold in every call, so a rollout depends only on its inputs.

    Returns (q, nu, q_ref, delta_n, delta_t, t, outcome, status, steps, lcp_solves, pivots,
    max_residual, max_lcp_size, rec_t (n,), rec_q (n, nq), rec_nu (n, nv), pair_force (n_pairs,):
    the normal contact force of each pair over the last step taken, min_psi: the smallest
    contact signed distance met at the start of any step (inf if none), force_steps: how many
    steps had a positive normal contact impulse, sweeps: PGS sweeps over all steps, pair_wrench
    (n_pairs, 3): the world-frame contact force on each pair's second body over the last step
    taken, normal plus friction, N; zero in the kinematic rung, which has no forces).
    """
    dimension = S.dimension
    spatial = dimension == 3
    bi, bf, pi, pf, verts = S.bi, S.bf, S.pi, S.pf, S.verts
    nv = S.nv
    q_index, v_index, kp, kd, lower, upper, max_force = D.q_index, D.v_index, D.kp, D.kd, D.lower, D.upper, D.max_force
    limited = any_limited(max_force)
    scripted = has_script(bf)
    if scripted:
        place_scripted(bf, S.base_pos, S.base_quat, t0)
    kinematic = model.kinematic
    compliant = model.compliant
    theta = model.theta
    directions = model.friction_directions
    eps = model.eps
    eps_eff = QUASISTATIC_INERTIA if eps == 0.0 else eps
    # buffers, allocated once
    cap = 1
    first_slot = np.zeros(pi.shape[0], np.int64)
    for p in range(pi.shape[0]):
        first_slot[p] = cap - 1
        cap += pi[p, 2]
    c_pair = np.zeros(cap, np.int64)
    c_slot = np.zeros(cap, np.int64)
    c_psi = np.zeros(cap)
    c_n, c_t, c_o = np.zeros((cap, 3)), np.zeros((cap, 3)), np.zeros((cap, 3))
    c_pa, c_pb = np.zeros((cap, 3)), np.zeros((cap, 3))
    W_n, W_t, W_o = np.zeros((nv, cap)), np.zeros((nv, cap)), np.zeros((nv, cap))
    c_bias = np.zeros((cap, 3))  # contact velocity from scripted obstacles along (n, t, o)
    warm_n, warm_t = np.zeros(cap), np.zeros((cap, 2))  # PGS: last step's impulses by slot
    warm_slots = np.zeros(cap, np.int64)  # the slots written last step (reset them, not all cap)
    n_warm = 0
    keep_warm = solver.method != SOLVER_LEMKE
    unsupported = np.zeros(max(pi.shape[0], 1), np.int64)
    pair_psi = np.full(max(pi.shape[0], 1), np.inf)
    pair_force = np.zeros(max(pi.shape[0], 1))  # normal force per pair in the last step
    pair_wrench = np.zeros((max(pi.shape[0], 1), 3))  # world-frame force on each pair's body B
    scratch = np.empty((bi.shape[0], 8))
    g_op, g_index, g_lo, g_hi = goal.op, goal.index, goal.lo, goal.hi
    u_op, u_index, u_lo, u_hi = unsafe.op, unsafe.index, unsafe.lo, unsafe.hi
    stack = np.zeros(max(g_op.shape[0], u_op.shape[0]) + 1, np.bool_)
    # what never changes during the rollout
    rhs_const = h * gravity_force(bi, bf, D.gravity, nv)
    constant_A = not has_rotations(bi)
    A = system_matrix(bi, bf, q, nv, eps_eff, h, v_index, kp, kd, max_force)
    Ainv = np.zeros((0, 0))
    M_const = np.zeros((0, 0))
    if constant_A:
        Ainv = _inverse_or_empty(A)
        M_const = mass_matrix(bi, bf, q, nv)
    max_records = max(max_records, 2)
    rec_t = np.zeros(max_records)
    rec_q = np.zeros((max_records, q.shape[0]))
    rec_nu = np.zeros((max_records, nv))
    rec_q[0] = q
    rec_nu[0] = nu
    n_rec = 1
    t = 0.0
    steps = 0
    lcp_solves = 0
    pivots = 0
    max_residual = 0.0
    max_size = 0
    min_psi = np.inf
    force_steps = 0
    sweeps = 0
    outcome = OUTCOME_NONE
    status = STEP_OK
    if not kinematic and constant_A and Ainv.shape[0] != nv:
        status = STEP_SINGULAR
    for k in range(controls.shape[0]):
        if status != STEP_OK or (outcome != OUTCOME_NONE and stop_at_outcome):
            break
        n_steps = int(np.round(durations[k] / h))
        u = controls[k]
        for _ in range(n_steps):
            # contacts at q (scripted obstacles where they are at this time)
            if scripted:
                place_scripted(bf, S.base_pos, S.base_quat, t0 + t)
            n_unsupported = 0
            if spatial:
                nc, n_unsupported = detect_spatial(S, q, nu, h, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, unsupported)
            else:
                nc = detect_planar_into(bi, bf, verts, pi, q, nu, h, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, scratch)
            pair_psi[:] = np.inf
            for i in range(nc):
                p = c_pair[i]
                if c_psi[i] < min_psi:
                    min_psi = c_psi[i]
                if c_psi[i] < pair_psi[p]:
                    pair_psi[p] = c_psi[i]
                c_slot[i] = first_slot[p] if (i == 0 or c_pair[i - 1] != p) else c_slot[i - 1] + 1
            if outcome == OUTCOME_NONE or stop_at_outcome:
                outcome = _classify_with(g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, q, pair_psi, stack)
                if outcome != OUTCOME_NONE and stop_at_outcome:
                    break
            if n_unsupported > 0:
                status = STEP_UNSUPPORTED_PAIR
                break
            if nc > 0:
                jacobian_packed(bi, bf, pi, q, nc, c_pair, c_n, c_pa, c_pb, W_n)
                if scripted:
                    tangents_packed(dimension, nc, c_n, c_t, c_o)
                    scripted_bias(bf, pi, nc, c_pair, c_n, c_t, c_o, c_pa, c_pb, c_bias)
            p_t = np.zeros((0, 2))
            if kinematic:
                q2, nu2, q_ref2, st, piv, res = kinematic_step(bi, h, q, q_ref, u, q_index, v_index, lower, upper, nc, c_psi, c_bias, W_n, nv)
                dn2, dt2 = delta_n, delta_t
                size = nc
                p_n = np.zeros(nc)
            elif nc == 0 and constant_A and not limited:
                # the cheap path: no contact, constant system matrix
                q2, nu2, q_ref2, st = free_step(eps, theta, h, bi, Ainv, M_const, rhs_const, q, nu, q_ref, u, q_index, v_index, kp, kd, lower, upper)
                dn2, dt2 = delta_n, delta_t
                if compliant and (delta_n.any() or delta_t.any()):
                    dn2, dt2 = np.zeros_like(delta_n), np.zeros_like(delta_t)
                piv, res, size = 0, 0.0, 0
                p_n = np.zeros(0)
            else:
                if nc > 0:
                    tangents_packed(dimension, nc, c_n, c_t, c_o)
                    jacobian_packed(bi, bf, pi, q, nc, c_pair, c_t, c_pa, c_pb, W_t)
                    if spatial:
                        jacobian_packed(bi, bf, pi, q, nc, c_pair, c_o, c_pa, c_pb, W_o)
                if not constant_A:
                    A = system_matrix(bi, bf, q, nv, eps_eff, h, v_index, kp, kd, max_force)
                q2, nu2, q_ref2, dn2, dt2, st, piv, res, size, p_n, p_t, sw = dynamics_step(
                    eps, compliant, theta, directions, h, bi, bf, pf, A, Ainv, M_const, rhs_const,
                    q, nu, q_ref, delta_n, delta_t, u, q_index, v_index, kp, kd, lower, upper, max_force,
                    nc, c_pair, c_psi, c_slot, W_n, W_t, W_o, c_bias, spatial, pi, solver, warm_n, warm_t,
                )
                sweeps += sw
                if keep_warm and st == STEP_OK:
                    for i in range(n_warm):
                        warm_n[warm_slots[i]] = 0.0
                        warm_t[warm_slots[i], 0] = 0.0
                        warm_t[warm_slots[i], 1] = 0.0
                    for i in range(nc):
                        warm_slots[i] = c_slot[i]
                        warm_n[c_slot[i]] = p_n[i]
                        warm_t[c_slot[i], 0] = p_t[i, 0]
                        warm_t[c_slot[i], 1] = p_t[i, 1]
                    n_warm = nc
            if size > 0:
                lcp_solves += 1
                if size > max_size:
                    max_size = size
            pivots += piv
            if res > max_residual:
                max_residual = res
            if st != STEP_OK:
                status = st
                break
            q, nu, q_ref, delta_n, delta_t = q2, nu2, q_ref2, dn2, dt2
            pair_force[:] = 0.0
            pair_wrench[:] = 0.0
            pushed = False
            for i in range(p_n.shape[0]):
                pair_force[c_pair[i]] += p_n[i] / h
                if p_n[i] > 0.0:
                    pushed = True
                for k in range(3):
                    f = p_n[i] * c_n[i, k]
                    if p_t.shape[0] > i:
                        f += p_t[i, 0] * c_t[i, k] + p_t[i, 1] * c_o[i, k]
                    pair_wrench[c_pair[i], k] += f / h
            if pushed:
                force_steps += 1
            t += h
            steps += 1
            if record_every > 0 and steps % record_every == 0 and n_rec < max_records - 1:
                rec_t[n_rec] = t
                rec_q[n_rec] = q
                rec_nu[n_rec] = nu
                n_rec += 1
    if status == STEP_OK and outcome == OUTCOME_NONE:
        if scripted:
            place_scripted(bf, S.base_pos, S.base_quat, t0 + t)
        zero = np.zeros(nv)
        if spatial:
            nc, _ = detect_spatial(S, q, zero, 0.0, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, unsupported)
        else:
            nc = detect_planar(bi, bf, verts, pi, q, zero, 0.0, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb)
        pair_psi[:] = np.inf
        for i in range(nc):
            if c_psi[i] < pair_psi[c_pair[i]]:
                pair_psi[c_pair[i]] = c_psi[i]
        outcome = _classify(goal, unsafe, q, pair_psi)
    if rec_t[n_rec - 1] != t:
        rec_t[n_rec] = t
        rec_q[n_rec] = q
        rec_nu[n_rec] = nu
        n_rec += 1
    return (q, nu, q_ref, delta_n, delta_t, t, outcome, status, steps, lcp_solves, pivots, max_residual, max_size,
            rec_t[:n_rec], rec_q[:n_rec], rec_nu[:n_rec], pair_force, min_psi, force_steps, sweeps, pair_wrench)

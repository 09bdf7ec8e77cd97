"""Rollouts: many steps per call inside numba, with goal/unsafe checks and early stops.

`rollout_kernel` runs a piecewise-constant control sequence (controls[k] for durations[k]
seconds) with a fixed step h. Each step: detect contacts at q, classify q (unsafe first,
then goal; touch predicates use the contacts just found, so they cost nothing extra), then
step the model (`models.stepper`). It stops at the first of: unsafe entered, goal reached, a
step failure (status), the end of the controls (the final state is classified once more).
Every `record_every`-th state, and the last, is recorded for plots and plans.

A step of the rollout reads as its stages, each a function named after it:
detect (`models.contact`) / `_distances` (contacts at q) -> `_classify_with` (goal / unsafe) -> `_assemble`
(Jacobians, frames) -> solve and integrate (the rung's step kernel, `models.stepper`:
`kinematic_step`, `free_step` or `dynamics_step`) -> `_record_forces` / `_record_state`.
Runs of steps of one kind go to a kernel of their own, which takes them in one call, the same
stages in the same order, without the reference counts the kernel's loop pays on the arrays it
rebinds at every step: `_free_run` (no contact detected) and `_contact_run` (contacts in space,
each step taken by a warm step).

Skipping what a scene does not need: with no contact the step is a free update with a
precomputed inverse system matrix; mu = 0 pairs get no friction variables; rigid models
carry no deformation; quasistatic models never touch the inertia terms.
"""

from __future__ import annotations

from types import FunctionType
from typing import NamedTuple

import numba
import numpy as np

from models.contact import (
    CONTACT_MARGIN,
    contact_buffers,
    detect_contacts_into,
    detect_planar,
    detect_planar_into,
    detect_spatial,
    detect_spatial_into,
    has_script,
    jacobian_at,
    place_scripted,
    planar_scratch,
    scripted_bias,
    step_outran,
    tangents_packed,
    widened_velocity,
)
from models.contact_pgs import BODY_DOFS, _pgs_directions, pgs_work
from models.kinematics import body_pose_3d, positions
from models.predicates import evaluate, evaluate_with
from models.stepper import (
    LAW_ACTIVE,
    LAW_AXIS,
    LAW_BODY,
    LAW_MAX_SPEED,
    LAW_RATE,
    LAW_TARGET,
    PART_ASSEMBLY,
    PART_CONTACT_SOLVE,
    PART_STEP,
    SOLVER_AUTO,
    SOLVER_LEMKE,
    SPATIAL_WARM_CONTACTS,
    WARM_DONE,
    WARM_NOT_TAKEN,
    SceneTables,
    Solver,
    StepStatus,
    _may_take_pgs_warm,
    _may_take_planar_warm,
    _may_take_spatial_warm,
    actuated_dofs,
    any_limited,
    basis_table,
    contact_stage,
    drive_step,
    dynamics_step,
    free_step,
    free_step_into,
    gravity_force,
    has_rotations,
    kinematic_free_step_into,
    kinematic_step,
    make_system,
    mass_matrix,
    passive_metric_inverse,
    pgs_warm_fixed,
    pgs_warm_step,
    pgs_warm_step_on,
    planar_warm_buffers,
    planar_warm_fixed,
    planar_warm_step,
    planar_warm_step_on,
    rotating_blocks_into,
    spatial_warm_buffers,
    spatial_warm_fixed,
    spatial_warm_step,
    spatial_warm_step_on,
    system_matrix,
    warm_results,
)
from models.task import Outcome


class RolloutOutput(NamedTuple):
    """What `rollout_kernel` returns (`rollout_bound` as a plain tuple in this order, which
    `Rung.rollout` unpacks by position: tests/test_made.py checks the two against each other)."""

    q: np.ndarray  # the final state: (nq,)
    nu: np.ndarray  # (nv,)
    q_ref: np.ndarray  # (n_actuated,)
    delta_n: np.ndarray  # (slots,)
    delta_t: np.ndarray  # (slots, 2)
    t: float  # time run, s (from the start of this call)
    outcome: int  # a models.task.Outcome value: the first class other than NONE met
    status: int  # a models.stepper.StepStatus value: OK, or the failure that stopped the run
    steps: int
    lcp_solves: int  # steps that solved a contact problem
    pivots: int  # Lemke pivots over all steps
    max_residual: float  # the largest solver residual of any step
    max_lcp_size: int  # the most unknowns of any step's contact problem
    times: np.ndarray  # (n,) recorded times
    trajectory: np.ndarray  # (n, nq) recorded q
    velocities: np.ndarray  # (n, nv) recorded nu
    pair_force: np.ndarray  # (n_pairs,) normal contact force of each pair over the last step taken, N
    min_psi: float  # smallest contact signed distance met at the start of any step (inf if none), m
    force_steps: int  # steps with a positive normal contact impulse
    sweeps: int  # PGS sweeps over all steps
    pair_wrench: np.ndarray  # (n_pairs, 3) world-frame force on each pair's second body over the last step, N
    basis: np.ndarray  # int8: Lemke's warm start for the next call (`models.stepper.basis_table`)


# ----------------------------------------------------------------------------- the stages
#
# Hot-path note (`models.stepper`): a stage called every step takes the arrays it reads, not
# the named tuples holding them: numba increfs and decrefs every array of a tuple argument on
# each call, which measurably slowed the cheap rungs (about a microsecond a step); the small
# ones are inlined (numba IR inlining: no call, no reference counting of their arguments).
#
# Every kernel here and in `models.stepper` (the step kernels, the general step's and the
# warm steps') uses numpy's error model, as `models.lcp` does: a float division by zero gives
# inf or NaN, which the steps' finiteness checks return as a status, where Python's model
# raises ZeroDivisionError out of the kernel. The speed is the same (docs/measurements.md).
# Every integer // and % they reach divides by a count that is positive where it is reached
# (friction directions and friction contacts, whose rows exist only then, the friction
# polygon's sides, 2 or 3, record_every and warm_every behind their > 0 tests). The collision
# kernels (`models.contact2d`, `models.contact3d`) are called, not inlined, and keep Python's.


@numba.njit(cache=True, _nrt=False, error_model="numpy")  # a call without numba's runtime: no array argument reference-counted
def _distances(nc, c_pair, c_psi, c_slot, first_slot, pair_psi):
    """Stage detect (after `models.contact`'s detection into the buffers): each contact's
    slot, each pair's smallest psi. Returns the
    smallest psi of any contact (inf without contacts)."""
    smallest = np.inf
    for p in range(pair_psi.shape[0]):  # (indexed: a slice is an array object, counted each step)
        pair_psi[p] = np.inf
    for i in range(nc):
        p = c_pair[i]
        if c_psi[i] < smallest:
            smallest = c_psi[i]
        if c_psi[i] < pair_psi[p]:
            pair_psi[p] = c_psi[i]
        c_slot[i] = first_slot[p] if (i == 0 or c_pair[i - 1] != p) else c_slot[i - 1] + 1
    return smallest


@numba.njit(cache=True, error_model="numpy")
def _classify(goal, unsafe, q, pair_psi):
    """Stage classify (allocating its own stack): the Outcome value of q."""
    outcome = Outcome.NONE.value
    if evaluate(unsafe, q, pair_psi):
        outcome = Outcome.UNSAFE.value
    elif evaluate(goal, q, pair_psi):
        outcome = Outcome.GOAL.value
    return outcome


@numba.njit(cache=True, _nrt=False, error_model="numpy")  # a call without numba's runtime: no array argument reference-counted
def _classify_with(g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, q, pair_psi, stack):
    """Stage classify on the rollout's stack: unsafe first, then goal."""
    outcome = Outcome.NONE.value
    if evaluate_with(u_op, u_index, u_lo, u_hi, q, pair_psi, stack):
        outcome = Outcome.UNSAFE.value
    elif evaluate_with(g_op, g_index, g_lo, g_hi, q, pair_psi, stack):
        outcome = Outcome.GOAL.value
    return outcome


@numba.njit(cache=True, _nrt=False, error_model="numpy")  # a call without numba's runtime: no array argument reference-counted
def _observe(
    nc, c_pair, c_psi, c_slot, first_slot, pair_psi, min_psi, outcome, stop_at_outcome, g_op, g_index, g_lo, g_hi, u_op, u_index,
    u_lo, u_hi, q, stack,
):  # fmt: skip
    """Stages distances and classify at a step's detection (`rollout_kernel`'s and
    `_contact_run`'s): `_distances`, min_psi lowered to the smallest psi, and q classified
    (`_classify_with`) while no outcome is met yet, or at every step where the run stops at one.
    Returns (min_psi, outcome); the caller stops where stop_at_outcome and an outcome is met."""
    smallest = _distances(nc, c_pair, c_psi, c_slot, first_slot, pair_psi)
    if smallest < min_psi:
        min_psi = smallest
    if outcome == Outcome.NONE or stop_at_outcome:
        outcome = _classify_with(g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, q, pair_psi, stack)
    return min_psi, outcome


@numba.njit(cache=True, _nrt=False, error_model="numpy")  # a call without numba's runtime: no array argument reference-counted
def _assemble(bi, bf, pi, dimension, q, nc, c_pair, c_n, c_t, c_o, c_pa, c_pb, W_n, W_t, W_o, c_bias, scripted, with_friction, pos):
    """Stage assemble: W_n of the first nc (> 0) contacts at q; with scripted obstacles the frames
    and their velocity bias; with friction (every rung with forces) t, o and W_t, W_o. pos: the
    rollout's scratch for the bodies' origins (nb, 3), filled here at q."""
    positions(bi, bf, q, pos)
    jacobian_at(bi, pi, pos, nc, c_pair, c_n, c_pa, c_pb, W_n)
    if scripted:
        tangents_packed(dimension, nc, c_n, c_t, c_o)
        scripted_bias(bf, pi, nc, c_pair, c_n, c_t, c_o, c_pa, c_pb, c_bias)
    if with_friction:
        tangents_packed(dimension, nc, c_n, c_t, c_o)
        jacobian_at(bi, pi, pos, nc, c_pair, c_t, c_pa, c_pb, W_t)
        if dimension == 3:
            jacobian_at(bi, pi, pos, nc, c_pair, c_o, c_pa, c_pb, W_o)


@numba.njit(cache=True, _nrt=False, error_model="numpy")  # a call without numba's runtime: no array argument reference-counted
def _rotating_blocks_at(bi, bf, q, eps, h, v_index, kp, kd, max_force, system, block, work, R, I):
    """The System's blocks of A^-1 of the rotating bodies at q, in place
    (`models.stepper.rotating_blocks_into`); block, work, R, I: scratch. Returns ok (False: a
    block is singular, or the System holds none, where A's are singular from the start)."""
    if system.count.shape[0] != bi.shape[0]:
        return False
    return rotating_blocks_into(bi, bf, q, eps, h, v_index, kp, kd, max_force, system.dofs, system.count, system.inv, block, work, R, I)


@numba.njit(cache=True)
def warm_period_steps(warm_period, h):
    """The steps of a warm period (`models.stepper.Model.warm_period`) at step h: a rollout drops
    its warm starts at every step whose index from t = 0 is a multiple of it; 0: never (no
    period, or one shorter than half a step)."""
    return int(np.round(warm_period / h)) if warm_period > 0.0 else 0


@numba.njit(cache=True, _nrt=False, error_model="numpy")  # a call without numba's runtime: no array argument reference-counted
def _keep_warm(spatial, nc, c_slot, p_n, p_t, c_t, c_o, warm_n, warm_t, warm_w, warm_slots, n_warm):
    """PGS warm start for the next step: this step's impulses by slot (the previous step's
    slots reset, not all of them); in space the friction also in world coordinates (warm_w,
    (slots, 3), from the step's frames c_t, c_o), which `_warm_in_frames` puts in the next
    step's frames. Returns the number of slots written."""
    _drop_warm(n_warm, warm_slots, warm_n, warm_t, warm_w)
    for i in range(nc):
        s = c_slot[i]
        warm_slots[i] = s
        warm_n[s] = p_n[i]
        warm_t[s, 0] = p_t[i, 0]
        warm_t[s, 1] = p_t[i, 1]
        if spatial:
            for a in range(3):
                warm_w[s, a] = p_t[i, 0] * c_t[i, a] + p_t[i, 1] * c_o[i, a]
    return nc


@numba.njit(cache=True, inline="always")
def _drop_warm(n_warm, warm_slots, warm_n, warm_t, warm_w):
    """The PGS warm start's n_warm slots kept (`_keep_warm`) reset to zero: no warm start.
    Returns 0, the slots now kept."""
    for i in range(n_warm):
        s = warm_slots[i]
        warm_n[s] = 0.0
        warm_t[s, 0] = warm_t[s, 1] = 0.0
        warm_w[s, 0] = warm_w[s, 1] = warm_w[s, 2] = 0.0
    return 0


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def _warm_in_frames(nc, c_slot, c_t, c_o, warm_w, warm_t):
    """In space, the PGS warm start's friction impulses in this step's contact frames: the kept
    world impulses (`_keep_warm`) on each contact's t and o. The tangent basis follows the
    normal discontinuously (box_push_3d's pusher normal along -x: t flips between +z and -z with
    the sign of the normal's round-off), so impulses kept as (t, o) components would start a
    step with its friction reversed (docs/measurements.md)."""
    for i in range(nc):
        s = c_slot[i]
        warm_t[s, 0] = warm_w[s, 0] * c_t[i, 0] + warm_w[s, 1] * c_t[i, 1] + warm_w[s, 2] * c_t[i, 2]
        warm_t[s, 1] = warm_w[s, 0] * c_o[i, 0] + warm_w[s, 1] * c_o[i, 1] + warm_w[s, 2] * c_o[i, 2]


@numba.njit(cache=True, _nrt=False, error_model="numpy")  # a call without numba's runtime: no array argument reference-counted
def _record_forces(c_pair, c_n, c_t, c_o, p_n, p_t, h, pair_force, pair_wrench):
    """Stage record: each pair's normal force and world-frame force on its body B over the
    step. Returns whether some contact carried a positive normal impulse."""
    for p in range(pair_force.shape[0]):  # (indexed, as in `_distances`)
        pair_force[p] = 0.0
        pair_wrench[p, 0], pair_wrench[p, 1], pair_wrench[p, 2] = 0.0, 0.0, 0.0
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
    return pushed


@numba.njit(cache=True, inline="always")
def _record_state(rec_t, rec_q, rec_nu, n_rec, t, q, nu):
    """Stage record: keep (t, q, nu) as record n_rec; returns the next record's index. (Copied
    entry by entry: a row assignment may allocate, where source and row overlap, which a kernel
    compiled without numba's runtime, `_contact_run`, cannot.)"""
    rec_t[n_rec] = t
    for j in range(q.shape[0]):
        rec_q[n_rec, j] = q[j]
    for j in range(nu.shape[0]):
        rec_nu[n_rec, j] = nu[j]
    return n_rec + 1


@numba.njit(cache=True, error_model="numpy")
def _final_outcome(S, goal, unsafe, q, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pair_psi):
    """Classify the state a run ended in (contacts at rest: no broadphase widening)."""
    zero = np.zeros(S.nv)
    if S.dimension == 3:
        nc, _ = detect_spatial(S, q, zero, 0.0, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, unsupported)
    else:
        nc = detect_planar(S.bi, S.bf, S.verts, S.pi, q, zero, 0.0, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb)
    pair_psi[:] = np.inf
    for i in range(nc):
        if c_psi[i] < pair_psi[c_pair[i]]:
            pair_psi[c_pair[i]] = c_psi[i]
    return _classify(goal, unsafe, q, pair_psi)


@numba.njit(cache=True, error_model="numpy")
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


@numba.njit(cache=True, error_model="numpy")
def _start_system(S, D, model, h, q):
    """The System at the start of a rollout: A, and A^-1 and M when they never change."""
    bi, bf, nv = S.bi, S.bf, S.nv
    eps = model.eps
    eps_eff = model.quasistatic_inertia if eps == 0.0 else eps
    A = system_matrix(bi, bf, q, nv, eps_eff, drive_step(model, h), D.v_index, D.kp, D.kd, D.max_force)
    Ainv = np.zeros((0, 0))
    M_const = np.zeros((0, 0))
    if not has_rotations(bi):
        Ainv = _inverse_or_empty(A)
        M_const = mass_matrix(bi, bf, q, nv)
    return make_system(bi, A, Ainv, M_const, h * gravity_force(bi, bf, D.gravity, nv))


@numba.njit(cache=True, error_model="numpy")
def _contact_frames(cap):
    """Per-contact buffers of a rollout, allocated once: frames n, t, o and points pa, pb
    (cap, 3), and the PGS warm start by slot (warm_n, warm_t, in space warm_w: `_keep_warm`;
    the slots last written)."""
    c_n, c_t, c_o, c_pa, c_pb = np.zeros((cap, 3)), np.zeros((cap, 3)), np.zeros((cap, 3)), np.zeros((cap, 3)), np.zeros((cap, 3))
    warm_n, warm_t, warm_w, warm_slots = np.zeros(cap), np.zeros((cap, 2)), np.zeros((cap, 3)), np.zeros(cap, np.int64)
    return c_n, c_t, c_o, c_pa, c_pb, warm_n, warm_t, warm_w, warm_slots


@numba.njit(cache=True, error_model="numpy")
def _pair_buffers(n_pairs, bi):
    """Per-pair buffers of a rollout, allocated once (at least one pair): unsupported flags,
    smallest psi, normal force, world force; and the planar detection's scratch (`planar_scratch`)."""
    n_pairs = max(n_pairs, 1)
    unsupported = np.zeros(n_pairs, np.int64)
    pair_psi, pair_force, pair_wrench = np.full(n_pairs, np.inf), np.zeros(n_pairs), np.zeros((n_pairs, 3))
    return unsupported, pair_psi, pair_force, pair_wrench, planar_scratch(bi, n_pairs)


@numba.njit(cache=True, inline="always")
def _tally(sweeps, lcp_solves, max_size, pivots, max_residual, sw, size, piv, res):
    """A step's solver statistics into the rollout's: PGS sweeps, contact problems solved and
    their largest size, Lemke pivots, largest residual. Returns the updated five."""
    sweeps += sw
    if size > 0:
        lcp_solves += 1
        if size > max_size:
            max_size = size
    pivots += piv
    if res > max_residual:
        max_residual = res
    return sweeps, lcp_solves, max_size, pivots, max_residual


@numba.njit(cache=True, error_model="numpy")
def _start_records(max_records, q, nu, record_every, steps):
    """The record buffers (at least two records: start and end) with the start state at t = 0
    as record 0, for a run of at most `steps` steps recording every record_every-th (none where
    record_every <= 0): no more than it can record (the start, steps // record_every, the end),
    so that a short call does not allocate the default 2,000 (about 1% of box_push_3d's 100-step
    `Rung.rollout` call). Returns (max_records, rec_t, rec_q, rec_nu, next record's index). Not
    zeroed: a record is written before it is read, and the run returns those written (views, or
    copies where they are under half: `rollout_kernel`'s end; zeroing the default 2,000 records
    cost about 3 us a call, docs/measurements.md)."""
    max_records = max(min(max_records, (steps // record_every if record_every > 0 else 0) + 2), 2)
    rec_t, rec_q, rec_nu = np.empty(max_records), np.empty((max_records, q.shape[0])), np.empty((max_records, nu.shape[0]))
    n_rec = _record_state(rec_t, rec_q, rec_nu, 0, 0.0, q, nu)
    return max_records, rec_t, rec_q, rec_nu, n_rec


@numba.njit(cache=True, error_model="numpy")
def _finish(
    S,
    goal,
    unsafe,
    scripted,
    t0,
    t,
    q,
    nu,
    status,
    outcome,
    c_pair,
    c_psi,
    c_n,
    c_pa,
    c_pb,
    unsupported,
    pair_psi,
    rec_t,
    rec_q,
    rec_nu,
    n_rec,
):
    """End of a run: a run that ended with no step failure and no outcome is classified in
    its final state (scripted obstacles placed at the end time); the final state is recorded
    unless it already is. Returns (outcome, number of records)."""
    if status == StepStatus.OK and outcome == Outcome.NONE:
        if scripted:
            place_scripted(S.bf, S.base_pos, S.base_quat, t0 + t)
        outcome = _final_outcome(S, goal, unsafe, q, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pair_psi)
    if rec_t[n_rec - 1] != t:
        n_rec = _record_state(rec_t, rec_q, rec_nu, n_rec, t, q, nu)
    return outcome, n_rec


@numba.njit(cache=True, error_model="numpy")
def law_speeds(S, law, q, q_index, u, out):
    """The commanded speeds of a step under feedback laws (`models.stepper.Drives.law`): out[j]
    = u[j] for a drive without a law, else the law's desired speed (kp / kd) (target - q_j),
    limited to its max speed, where the target is a coordinate value or the world coordinate,
    along the drive's axis, of a point fixed in a body at q. Its drive (kp = 0) then applies
    kd (out[j] - v): the force of the law's quadratic well, with damping (`models.rungs.policy_drives`)."""
    for j in range(law.shape[0]):
        out[j] = u[j]
        if law[j, LAW_ACTIVE] == 0.0:
            continue
        b, target = int(law[j, LAW_BODY]), law[j, LAW_TARGET]
        if b >= 0:
            p, R = body_pose_3d(S, q, b)  # planar bodies too: their yaw is the angle, z = 0
            axis = int(law[j, LAW_AXIS])
            target = p[axis]
            for k in range(3):
                target += R[axis, k] * law[j, LAW_TARGET + k]
        v, top = law[j, LAW_RATE] * (target - q[q_index[j]]), law[j, LAW_MAX_SPEED]
        out[j] = min(max(v, -top), top)


# ----------------------------------------------------------------------------- the rollout


#: Why `_free_run` returned: the control's steps are done; a contact or an unsupported pair
#: detected at its next step, or its free step failed (the caller takes that step, whole);
#: the outcome met with stop_at_outcome (the caller stops, that step not taken).
FREE_DONE, FREE_HANDED_BACK, FREE_OUTCOME = 0, 1, 2

#: How many times `rollout_kernel` takes a step again over the contacts its motion could reach
#: (`models.contact.step_outran`) before it keeps the step as it is.
WIDEN_TRIES = 3


@numba.njit(cache=True, _nrt=False, error_model="numpy")  # no reference counts: none of its rebindings is counted
def _free_run(
    S, g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, stack, eps, theta, h, Ainv, M_const, rhs_const, q, nu,
    q_ref, u, q_index, v_index, kp, kd, lower, upper, rhs, blend, free_q, free_nu, free_q_ref, free_side, c_pair, c_psi, c_n,
    c_pa, c_pb, c_t, c_o, c_slot, first_slot, unsupported, pos, poses, speed, reach, axis, cores, pair_psi, no_impulse,
    no_friction, pair_force, pair_wrench, rec_t, rec_q, rec_nu, n_rec, record_every, max_records, steps, t, t0, outcome, stop_at_outcome,
    warm_every, n_left, kinematic, moved,
):  # fmt: skip
    """Up to n_left of `rollout_kernel`'s steps while no contact is detected, in one call: the
    same stages in the same order as the kernel's loop (detection, distances, classification,
    `free_step_into`, the forces' record, the state's record; compiled into it, `_inlined`), the same bits, without most of
    the reference counts that the kernel's loop pays on its arrays at every step (a third of a
    free step, profiled), and without numba's runtime: none of the rest. For a
    scene with no scripted obstacle and no speed law, in the kinematic rung (its free step,
    `kinematic_free_step_into`: kinematic True) or with A constant, no force-limited drive and
    no compliant deformation left (`rollout_kernel` checks). Each step writes its state on side
    free_side of free_q, free_nu, free_q_ref and flips it, as the kernel's free step does.
    Returns (why it returned: FREE_DONE, FREE_HANDED_BACK, FREE_OUTCOME; the steps taken,
    whose last state is on side 1 - free_side; t, steps, the records kept, the outcome,
    free_side, whether a step of a new warm period (`Model.warm_period`) was taken or met the
    outcome, whose warm starts the caller drops: a free step reads and writes none of them; and
    the contacts and unsupported pairs detected at the step handed back, whose detection the
    buffers hold: the caller does not detect them again). A step that moved a body further than
    its detection allowed for (`models.contact.step_outran`; moved: its scratch) is handed back
    untaken, for the caller to take and detect again."""
    bi = S.bi
    cq, cnu, cq_ref = q, nu, q_ref
    taken, crossed = 0, False
    while taken < n_left:
        period = warm_every > 0 and int(np.round((t0 + t) / h)) % warm_every == 0
        nc, n_unsupported = _detect_in_free_run(
            S, cq, cnu, h, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, poses, speed, reach, axis, cores
        )
        if nc > 0 or n_unsupported > 0:
            return FREE_HANDED_BACK, taken, t, steps, n_rec, outcome, free_side, crossed, nc, n_unsupported
        _distances_in_run(nc, c_pair, c_psi, c_slot, first_slot, pair_psi)
        if outcome == Outcome.NONE or stop_at_outcome:
            outcome = _classify_in_run(g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, cq, pair_psi, stack)
            if outcome != Outcome.NONE and stop_at_outcome:  # (the kernel drops at a period's step before it stops)
                return FREE_OUTCOME, taken, t, steps, n_rec, outcome, free_side, crossed or period, nc, n_unsupported
        f_q, f_nu, f_q_ref = free_q[free_side], free_nu[free_side], free_q_ref[free_side]
        if kinematic:
            ok = _kinematic_free_step_in_run(bi, h, cq, u, q_index, v_index, lower, upper, f_q, f_nu, f_q_ref)
        else:
            ok = _free_step_in_run(
                eps, theta, h, bi, Ainv, M_const, rhs_const, cq, cnu, cq_ref, u, q_index, v_index, kp, kd, lower, upper, rhs, blend, f_q,
                f_nu, f_q_ref,
            )  # fmt: skip
        if not ok:
            return FREE_HANDED_BACK, taken, t, steps, n_rec, outcome, free_side, crossed, nc, n_unsupported
        if _step_outran_in_run(bi, S.bf, h, CONTACT_MARGIN, f_nu, speed, moved):  # the caller's: it detects again
            return FREE_HANDED_BACK, taken, t, steps, n_rec, outcome, free_side, crossed, nc, n_unsupported
        free_side = 1 - free_side
        cq, cnu, cq_ref = f_q, f_nu, f_q_ref
        crossed = crossed or period
        _record_forces_in_run(c_pair, c_n, c_t, c_o, no_impulse, no_friction, h, pair_force, pair_wrench)
        t += h
        steps += 1
        taken += 1
        if record_every > 0 and steps % record_every == 0 and n_rec < max_records - 1:
            n_rec = _record_state(rec_t, rec_q, rec_nu, n_rec, t, cq, cnu)
    return FREE_DONE, taken, t, steps, n_rec, outcome, free_side, crossed, 0, 0


#: Why `_contact_run` returned: the control's steps are done; or at a step it does not take
#: (no contact, an unsupported pair, the outcome met with stop_at_outcome, a step the warm steps
#: do not take), handed back to the caller with that step's detection, which takes it whole.
CONTACT_DONE, CONTACT_HANDED_BACK = 0, 1


def _inlined(kernel, **callees):
    """A second dispatcher of `kernel`'s Python function, compiled into each function that calls
    it (numba's inline="always"; no cache entry of its own). For `_free_run` and `_contact_run`,
    compiled without numba's runtime: there an inlined helper's array arguments are not
    reference-counted, and its call no longer copies them onto the stack (about 630 words a
    step at box_push_3d's push, 330 of them detection's, the scene's 40 arrays); a free step
    in the plane, whose stages are each a few dozen operations, ran 1.6-2x faster so
    (docs/measurements.md, thirty-ninth session). `rollout_kernel`, with the runtime, calls the
    kernels themselves. callees: global names of the function resolved to other kernels
    (their inlined copies). The copies compile with their caller's flags (numpy's error model:
    a division by zero is inf, not an exception)."""
    function = kernel.py_func
    if callees:
        names = dict(function.__globals__)
        names.update(callees)
        function = FunctionType(function.__code__, names, function.__name__, function.__defaults__, function.__closure__)
    return numba.njit(_nrt=False, error_model="numpy", inline="always")(function)


# `_free_run`'s and `_contact_run`'s stages, compiled into them (`_inlined`)
# (`_free_run` calls the spatial detection: a copy of it there lengthened a cold compile, for
# the free runs of scenes in space without rotating bodies only; docs/measurements.md)
_detect_planar_in_run = _inlined(detect_planar_into)
_detect_in_run = _inlined(detect_contacts_into, detect_planar_into=_detect_planar_in_run, detect_spatial_into=_inlined(detect_spatial_into))
_detect_in_free_run = _inlined(detect_contacts_into, detect_planar_into=_detect_planar_in_run)
_distances_in_run, _classify_in_run = _inlined(_distances), _inlined(_classify_with)
_observe_in_run = _inlined(_observe, _distances=_distances_in_run, _classify_with=_classify_in_run)
_assemble_in_run = _inlined(_assemble)
_record_forces_in_run = _inlined(_record_forces)
_free_step_in_run, _kinematic_free_step_in_run = _inlined(free_step_into), _inlined(kinematic_free_step_into)
_step_outran_in_run = _inlined(step_outran)


#: Which basis table a `_contact_run` left its caller with: the one passed in, the cold table,
#: or (0, 1) that side of the warm steps' results.
BASIS_PASSED, BASIS_COLD = -2, -1


@numba.njit(cache=True, _nrt=False, error_model="numpy")  # no reference counts: none of its rebindings is counted
def _contact_run(
    S, g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, stack, model, solver, lemke, step_solver, D, tables, system, rotating,
    limited, scripted, h, q, nu, q_ref, u, contacts, delta_n, delta_t, basis, cold, B, W, P, side, whole, keep_warm, c_n, c_t, c_o, c_pa,
    c_pb, warm_n, warm_t, warm_w, warm_slots, n_warm, first_slot, unsupported, pos, poses, speed, reach, axis, cores, pair_psi, pair_force,
    pair_wrench,
    rec_t, rec_q, rec_nu, n_rec, record_every, max_records, steps, t, t0, outcome, stop_at_outcome, warm_every, n_left, min_psi,
    force_steps, sweeps, lcp_solves, max_size, pivots, max_residual, moved,
):  # fmt: skip
    """Up to n_left of `rollout_kernel`'s contact steps while a warm step takes them (PGS's
    `models.stepper.pgs_warm_step`; Lemke's `models.stepper.spatial_warm_step` in space,
    `models.stepper.planar_warm_step` in the plane), in one call compiled without numba's runtime: the same
    stages in the same order as the kernel's loop (the warm period's drop, detection,
    distances, classification, assembly, the warm start in the frames, the warm step, auto's
    switch, the warm start kept, the tally, the forces' and the state's records), the same
    bits, without the reference counts the kernel's loop pays on the arrays it rebinds at every
    step (57 a step at box_push_3d's push: the push about 5% faster, docs/measurements.md). For
    a scene with no scripted obstacle (scripted: False), no speed law, no force-limited drive,
    not kinematic, and in the plane A constant and Lemke's steps (`rollout_kernel` checks).
    Each step writes its state on side `side` of the warm steps' results (W's and B's, the
    same) and flips it, as the kernel's warm steps do. It hands a step back, with its detection, where it has no contact or an unsupported
    pair, where the outcome is met with stop_at_outcome, or where neither warm step takes it
    (tried: the warm step was tried there and did not take it, so the caller goes to the
    general step without trying it again; the stages before it are repeated, the same), or
    where the warm step moved a body further than its detection allowed for
    (`models.contact.step_outran`; moved: its scratch; tried too: the caller takes the step and
    detects again).
    Returns (why: CONTACT_DONE or CONTACT_HANDED_BACK; the steps taken, whose last state is
    on side 1 - side; t, steps, the records kept, the outcome, side, the basis table now
    (BASIS_PASSED, BASIS_COLD, or the side of W's results), whether auto switched to Lemke,
    the PGS warm start's slots kept, min_psi, force_steps and the tally's five; the
    contacts and unsupported pairs detected at the step handed back, and tried)."""
    R = W.out
    c_pair, c_psi, c_slot, W_n, W_t, W_o, c_bias = contacts
    bi, bf, pi, dimension = S.bi, S.bf, S.pi, S.dimension
    # the helpers' flags as values, not literals (a literal argument compiles a signature of its own)
    spatial, with_friction = dimension == 3, not model.kinematic
    basis_from, taken, nc, n_unsupported = BASIS_PASSED, 0, np.int64(0), 0
    # the steps' fixed arguments by reference, made once (`models.reference`, `spatial_warm_fixed`)
    warm_fixed = spatial_warm_fixed(D, tables, system, contacts, W)
    pgs_fixed = pgs_warm_fixed(D, tables, system, contacts, warm_n, warm_t, W, P)
    planar_fixed = planar_warm_fixed(D, tables, system, contacts, B)
    while taken < n_left:
        if warm_every > 0 and int(np.round((t0 + t) / h)) % warm_every == 0:
            basis, step_solver, basis_from = cold, solver, BASIS_COLD
            n_warm = _drop_warm(n_warm, warm_slots, warm_n, warm_t, warm_w)
        nc, n_unsupported = _detect_in_run(
            S, q, nu, h, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, poses, speed, reach, axis, cores
        )
        if nc == 0 or n_unsupported > 0:
            break
        min_psi, outcome = _observe_in_run(
            nc, c_pair, c_psi, c_slot, first_slot, pair_psi, min_psi, outcome, stop_at_outcome, g_op, g_index, g_lo, g_hi, u_op,
            u_index, u_lo, u_hi, q, stack,
        )  # fmt: skip
        if outcome != Outcome.NONE and stop_at_outcome:
            break
        _assemble_in_run(
            bi, bf, pi, dimension, q, nc, c_pair, c_n, c_t, c_o, c_pa, c_pb, W_n, W_t, W_o, c_bias, scripted, with_friction, pos
        )
        if keep_warm and spatial:
            _warm_in_frames(nc, c_slot, c_t, c_o, warm_w, warm_t)
        warm, pgs, sw, warm_pivots, size, res = WARM_NOT_TAKEN, False, 0, 0, 0, 0.0
        if _may_take_pgs_warm(limited, model, step_solver, nc):
            pgs = True
            warm, size, res, sw = pgs_warm_step_on(
                model, step_solver, pgs_fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, side, whole
            )
        elif _may_take_spatial_warm(spatial, limited, model, step_solver, nc):
            warm, size, res, warm_pivots = spatial_warm_step_on(
                model, warm_fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, whole
            )
        elif _may_take_planar_warm(not spatial, not rotating, limited, model, step_solver, nc):
            warm, size, res, warm_pivots = planar_warm_step_on(
                model, planar_fixed, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, whole
            )
        if warm != WARM_DONE or _step_outran_in_run(bi, bf, h, CONTACT_MARGIN, R.nu[side], speed, moved):
            return (
                CONTACT_HANDED_BACK, taken, t, steps, n_rec, outcome, side, basis_from, step_solver.method == SOLVER_LEMKE, n_warm,
                min_psi, force_steps, sweeps, lcp_solves, max_size, pivots, max_residual, nc, n_unsupported, True,
            )  # fmt: skip
        q, nu, q_ref = R.q[side], R.nu[side], R.q_ref[side]
        if not pgs:  # (PGS keeps the basis table as it is)
            basis, basis_from = R.basis[side], side
        if model.compliant:
            delta_n, delta_t = R.delta_n[side], R.delta_t[side]
        side = 1 - side
        p_n, p_t = R.impulses[:nc], R.frictions[:nc]
        if step_solver.method == SOLVER_AUTO and sw >= solver.max_sweeps:
            step_solver = lemke
        if keep_warm:
            n_warm = _keep_warm(spatial, nc, c_slot, p_n, p_t, c_t, c_o, warm_n, warm_t, warm_w, warm_slots, n_warm)
        sweeps, lcp_solves, max_size, pivots, max_residual = _tally(
            sweeps, lcp_solves, max_size, pivots, max_residual, sw, size, warm_pivots, res
        )
        force_steps += _record_forces_in_run(c_pair, c_n, c_t, c_o, p_n, p_t, h, pair_force, pair_wrench)
        t += h
        steps += 1
        taken += 1
        if record_every > 0 and steps % record_every == 0 and n_rec < max_records - 1:
            n_rec = _record_state(rec_t, rec_q, rec_nu, n_rec, t, q, nu)
    why = CONTACT_DONE if taken >= n_left else CONTACT_HANDED_BACK  # (the loop breaks before a step it hands back)
    return (
        why, taken, t, steps, n_rec, outcome, side, basis_from, step_solver.method == SOLVER_LEMKE, n_warm, min_psi,
        force_steps, sweeps, lcp_solves, max_size, pivots, max_residual, nc, n_unsupported, False,
    )  # fmt: skip


@numba.njit(cache=True, error_model="numpy")
def rollout_kernel(
    S,
    D,
    model,
    solver,
    goal,
    unsafe,
    q,
    nu,
    q_ref,
    delta_n,
    delta_t,
    basis,
    controls,
    durations,
    h,
    record_every,
    max_records,
    stop_at_outcome,
    t0,
):
    """Run the controls from the given state (stopping at goal/unsafe if stop_at_outcome;
    otherwise the returned outcome is the first one met, and the run goes on).

    model: `models.stepper.Model` (what is solved); solver: `models.stepper.Solver` (how the
    contact problems are solved). t0: the time of the start state, where scripted obstacles
    are (their poses are written into S's pose tables as time goes on: pass a scene copy of
    the caller's own when the scene has one). PGS warm starts travel from step to step within the call
    (by contact slot; in space their friction in world coordinates, `_keep_warm`) and start
    cold in every call, so a rollout depends only on its inputs; like Lemke's basis they are
    dropped at every period of `Model.warm_period`.
    Returns a `RolloutOutput`.
    """
    bi, bf, pi, verts, nv, dimension = S.bi, S.bf, S.pi, S.verts, S.nv, S.dimension
    tables = SceneTables(bi, bf, pi, S.pf, dimension == 3)
    scripted = has_script(bf)
    if scripted:
        place_scripted(bf, S.base_pos, S.base_quat, t0)
    contacts, first_slot = contact_buffers(pi, nv)  # buffers, allocated once
    c_pair, c_psi, c_slot, W_n, W_t, W_o, c_bias = contacts
    c_n, c_t, c_o, c_pa, c_pb, warm_n, warm_t, warm_w, warm_slots = _contact_frames(c_psi.shape[0])
    # counters that helpers take start as np.int64, not a literal 0: numba compiles a helper first
    # for a literal argument's type (its type inference's first guess), a second signature, and a
    # first run's compile paid it (`_free_run` twice, about 30 s; docs/measurements.md)
    n_warm, keep_warm = np.int64(0), solver.method != SOLVER_LEMKE  # PGS warm start: by slot
    # auto: once PGS does not converge on a step (a stack: coupled contacts) the rest of the
    # call solves with Lemke, instead of paying PGS's sweeps before Lemke every step
    lemke = Solver(SOLVER_LEMKE, solver.tolerance, solver.max_sweeps, solver.auto_contacts)
    step_solver = solver
    unsupported, pair_psi, pair_force, pair_wrench, (pos, poses, speed, reach, axis, cores) = _pair_buffers(pi.shape[0], bi)
    g_op, g_index, g_lo, g_hi = goal  # hoisted: reading a tuple's array in the loop costs a reference count
    u_op, u_index, u_lo, u_hi = unsafe
    q_index, v_index, kp, kd, lower, upper, _, max_force, law = D
    has_law = False
    for j in range(law.shape[0]):
        has_law = has_law or law[j, LAW_ACTIVE] != 0.0
    stack = np.zeros(max(g_op.shape[0], u_op.shape[0]) + 1, np.bool_)
    slots, directions = c_psi.shape[0], model.friction_directions if dimension == 3 else 2
    # at the steps that start a warm period the basis is this cold table, never written into
    # (nor is the caller's table: the steps write their next tables into new arrays or their buffers)
    cold = basis_table(slots, v_index.shape[0], directions)
    if basis.shape[0] != slots + v_index.shape[0] or basis.shape[1] != 3 + directions:
        basis = cold
    # the warm starts are dropped at the steps that start a period of model.warm_period (Model)
    warm_every = warm_period_steps(model.warm_period, h)
    system = _start_system(S, D, model, h, q)
    Ainv, M_const, rhs_const = system.Ainv, system.M_const, system.rhs_const
    # scratch of the rotating bodies' blocks where A changes with q (`_rotating_blocks_at`)
    R3, I3, block3, work3 = np.empty((3, 3)), np.empty((3, 3)), np.empty((BODY_DOFS, BODY_DOFS)), np.empty((BODY_DOFS, 2 * BODY_DOFS))
    constant_A, limited = not has_rotations(bi), any_limited(max_force)
    kinematic, eps, compliant, theta = model.kinematic, model.eps, model.compliant, model.theta
    # the kinematic step's metric where M is constant (no rotating body): computed at the first
    # contact step and kept (empty until then, in the inverse's layout: its transpose)
    metric = np.empty((0, 0)).T
    hd = drive_step(model, h)  # (A's drive term's step: the rotating blocks' refresh below)
    # the warm steps' arrays (planar, spatial; their results R, which the free step's scratch is
    # also) and the free step's results: each writes its results on its side, not the one its last
    # results (which the state may be) are on; buffers for contacts only where that warm step can
    # run (`_may_take_planar_warm`, `_may_take_spatial_warm`, `_may_take_pgs_warm`)
    planar_cap = slots if dimension == 2 and constant_A and not limited and not kinematic else 0
    spatial_cap = min(slots, SPATIAL_WARM_CONTACTS) if dimension == 3 and not limited and not kinematic else 0
    pgs_cap = slots if _may_take_pgs_warm(limited, model, solver, slots) else 0
    R = warm_results(max(planar_cap, spatial_cap, pgs_cap), nv, q.shape[0], v_index.shape[0], basis, delta_n.shape[0])
    B, W = planar_warm_buffers(planar_cap, R), spatial_warm_buffers(spatial_cap, directions, bi.shape[0], R)
    # the side and the whole step (PART_STEP) as int64s, not literals: the warm steps compile once
    # for this kernel, stage_loop and Python's calls (a literal argument is a specialization of its
    # own, compiled even where it is only the type inference's first guess at a loop's variable)
    side, whole = np.int64(0), np.int64(PART_STEP)
    P = pgs_work(pgs_cap, _pgs_directions(model, dimension == 3))
    free_q, free_nu, free_q_ref, free_side = np.empty((2, q.shape[0])), np.empty((2, nv)), np.empty((2, q_ref.shape[0])), np.int64(0)
    eps_eff = model.quasistatic_inertia if eps == 0.0 else eps
    total_steps = 0
    for k in range(controls.shape[0]):
        total_steps += int(np.round(durations[k] / h))  # (as each control's steps are counted below)
    max_records, rec_t, rec_q, rec_nu, n_rec = _start_records(max_records, q, nu, record_every, total_steps)
    # runs of free steps in one call (`_free_run`), where they take the free step: tried from the
    # start and after each free step the loop takes, not while contacts persist
    free_runs = (kinematic or (constant_A and not limited)) and not scripted and not has_law
    try_free, detected, nc_back, unsupported_back = free_runs, False, 0, 0
    # a step that moved a body further than its detection allowed for (`step_outran`) is taken
    # again over the contacts detected at a velocity that covers its motion (probe), up to
    # WIDEN_TRIES times, where that detection finds more (a memoryless or kinematic step's
    # velocity is not the last one's: a pusher started at 0.5 m/s moves 5 cm in a 0.1 s step)
    widen, moved, probe = 0, np.empty(bi.shape[0]), np.empty(nv)
    # runs of contact steps in one call (`_contact_run`), where a warm step takes them (PGS's,
    # or Lemke's where its buffers are made)
    planar_run = planar_cap > 0 and solver.method == SOLVER_LEMKE
    try_contact = not kinematic and not limited and not scripted and not has_law and (pgs_cap > 0 or spatial_cap > 0 or planar_run)
    t, steps, lcp_solves, pivots, max_residual, max_size, min_psi, force_steps, sweeps = (
        0.0, np.int64(0), np.int64(0), np.int64(0), 0.0, np.int64(0), np.inf, np.int64(0), np.int64(0)
    )  # fmt: skip
    no_impulse, no_friction = np.zeros(0), np.zeros((0, 2))  # a step without contact problem (no allocation a step)
    outcome = Outcome.NONE.value
    status = StepStatus.SINGULAR.value if (not kinematic and constant_A and Ainv.shape[0] != nv) else StepStatus.OK.value
    for k in range(controls.shape[0]):
        if status != StepStatus.OK or (outcome != Outcome.NONE and stop_at_outcome):
            break
        u = controls[k]
        if has_law:
            u = u.copy()  # the laws' speeds, step by step
        n_steps, i = int(np.round(durations[k] / h)), 0
        while i < n_steps:
            detected, tried = widen > 0, False  # (taken again: its detection is in the buffers)
            if try_free and not detected and not (compliant and (delta_n.any() or delta_t.any())):
                why, taken, t, steps, n_rec, outcome, free_side, crossed, nc_back, unsupported_back = _free_run(
                    S, g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, stack, eps, theta, h, Ainv, M_const, rhs_const,
                    q, nu, q_ref, u, q_index, v_index, kp, kd, lower, upper, R.rhs, R.blend, free_q, free_nu, free_q_ref, free_side,
                    c_pair, c_psi, c_n, c_pa, c_pb, c_t, c_o, c_slot, first_slot, unsupported, pos, poses, speed, reach, axis, cores,
                    pair_psi, no_impulse, no_friction, pair_force, pair_wrench, rec_t, rec_q, rec_nu, n_rec, record_every, max_records,
                    steps, t, t0, outcome, stop_at_outcome, warm_every, n_steps - i, kinematic, moved,
                )  # fmt: skip
                if taken > 0:
                    last = 1 - free_side
                    q, nu, q_ref = free_q[last], free_nu[last], free_q_ref[last]
                    i += taken
                if crossed:
                    basis, step_solver = cold, solver
                    n_warm = _drop_warm(n_warm, warm_slots, warm_n, warm_t, warm_w)
                if why != FREE_HANDED_BACK:
                    break
                detected, try_free = True, False
            if try_contact and not detected:
                run = _contact_run(
                    S, g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, stack, model, solver, lemke, step_solver, D, tables, system,
                    not constant_A, limited, scripted, h, q, nu, q_ref, u, contacts, delta_n, delta_t, basis, cold, B, W, P, side, whole,
                    keep_warm, c_n, c_t, c_o, c_pa, c_pb, warm_n, warm_t, warm_w, warm_slots, n_warm, first_slot, unsupported, pos, poses,
                    speed, reach, axis, cores, pair_psi, pair_force, pair_wrench, rec_t, rec_q, rec_nu, n_rec, record_every, max_records,
                    steps, t, t0,
                    outcome, stop_at_outcome, warm_every, n_steps - i, min_psi, force_steps, sweeps, lcp_solves, max_size, pivots,
                    max_residual, moved,
                )  # fmt: skip
                why, taken, t, steps, n_rec, outcome, side, basis_from, to_lemke, n_warm, min_psi, force_steps = run[:12]
                sweeps, lcp_solves, max_size, pivots, max_residual, nc_back, unsupported_back, tried = run[12:]
                if taken > 0:  # its last state, on the side its last step wrote
                    last = 1 - side
                    q, nu, q_ref = R.q[last], R.nu[last], R.q_ref[last]
                    if compliant:
                        delta_n, delta_t = R.delta_n[last], R.delta_t[last]
                    i += taken
                if basis_from == BASIS_COLD:
                    basis = cold
                elif basis_from != BASIS_PASSED:
                    basis = R.basis[basis_from]
                step_solver = lemke if to_lemke else solver
                if why == CONTACT_DONE:
                    continue
                detected = True  # the step handed back, whose detection the buffers hold
            if warm_every > 0 and int(np.round((t0 + t) / h)) % warm_every == 0:
                # every warm start the call carries, as a call starts: Lemke's basis, PGS's
                # impulses by slot, auto's switch to Lemke
                basis, step_solver = cold, solver
                n_warm = _drop_warm(n_warm, warm_slots, warm_n, warm_t, warm_w)
            if scripted:  # obstacles where they are at this time
                place_scripted(bf, S.base_pos, S.base_quat, t0 + t)
            side0, basis0, free_side0 = side, basis, free_side  # (a step taken again starts from these)
            # stage detect (SceneData crosses a call only in space, where detection needs it)
            n_unsupported = 0
            if detected:  # by `_free_run`, at this state: its buffers hold it
                nc, n_unsupported = nc_back, unsupported_back
            elif dimension == 3:
                nc, n_unsupported = detect_spatial_into(
                    S, q, nu, h, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, speed, reach
                )
            else:
                nc = detect_planar_into(
                    bi, bf, verts, pi, q, nu, h, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, pos, poses, speed, reach, axis, cores
                )
            min_psi, outcome = _observe(
                nc, c_pair, c_psi, c_slot, first_slot, pair_psi, min_psi, outcome, stop_at_outcome, g_op, g_index, g_lo, g_hi, u_op,
                u_index, u_lo, u_hi, q, stack,
            )  # fmt: skip
            if outcome != Outcome.NONE and stop_at_outcome:
                break
            if n_unsupported > 0:
                status = StepStatus.UNSUPPORTED_PAIR.value
                break
            if nc > 0:
                _assemble(
                    bi, bf, pi, dimension, q, nc, c_pair, c_n, c_t, c_o, c_pa, c_pb, W_n, W_t, W_o, c_bias, scripted, not kinematic, pos
                )
            if has_law:
                law_speeds(S, law, q, q_index, controls[k], u)
            # stages solve and integrate: the rung's step kernel (in line: arguments of an inlined
            # stage are reference-counted each step, which slowed the cheap rungs by about 10%);
            # the general contact step is a call of `dynamics_step` (not inlined: compiled once)
            p_t, dn2, dt2, sw = no_friction, delta_n, delta_t, 0
            if kinematic:
                if nc > 0 and constant_A and metric.shape[0] != nv:
                    metric = passive_metric_inverse(bi, bf, q, nv, actuated_dofs(v_index, nv))
                q2, nu2, q_ref2, st, piv, res = kinematic_step(
                    bi, bf, h, q, q_ref, u, q_index, v_index, lower, upper, nc, c_psi, c_bias, W_n, nv, metric
                )
                size, p_n = nc, np.zeros(nc)
                if nc == 0:  # a free step: runs of them tried again from here
                    try_free = free_runs
            elif nc == 0 and constant_A and not limited:  # the cheap path: no contact problem
                try_free = free_runs
                f_q, f_nu, f_q_ref = free_q[free_side], free_nu[free_side], free_q_ref[free_side]
                if free_step_into(
                    eps, theta, h, bi, Ainv, M_const, rhs_const, q, nu, q_ref, u, q_index, v_index, kp, kd, lower, upper, R.rhs, R.blend,
                    f_q, f_nu, f_q_ref,
                ):  # fmt: skip
                    q2, nu2, q_ref2, st = f_q, f_nu, f_q_ref, StepStatus.OK.value
                    free_side = 1 - free_side  # the next free step writes the other side, not this state
                else:  # the status
                    q2, nu2, q_ref2, st = free_step(
                        eps, theta, h, bi, Ainv, M_const, rhs_const, q, nu, q_ref, u, q_index, v_index, kp, kd, lower, upper
                    )
                if compliant and (delta_n.any() or delta_t.any()):
                    dn2, dt2 = np.zeros_like(delta_n), np.zeros_like(delta_t)
                piv, res, size, p_n = 0, 0.0, 0, no_impulse
            else:
                # the usual step, without numba's runtime: PGS's (`pgs_warm_step`) or, while
                # contacts persist, Lemke's warm step (`spatial_warm_step`, `planar_warm_step`);
                # else the general one
                warm, pgs, warm_pivots = WARM_NOT_TAKEN, False, 0
                if keep_warm and dimension == 3:
                    _warm_in_frames(nc, c_slot, c_t, c_o, warm_w, warm_t)
                # (not where `_contact_run` tried the warm step at this state: it did not take it)
                if not tried and _may_take_pgs_warm(limited, model, step_solver, nc):
                    pgs = True
                    warm, size, res, sw = pgs_warm_step(
                        model, step_solver, D, tables, system, not constant_A, h, q, nu, q_ref, u, contacts, nc, delta_n, delta_t,
                        warm_n, warm_t, W, P, side, whole,
                    )  # fmt: skip
                elif not tried and _may_take_spatial_warm(dimension == 3, limited, model, step_solver, nc):
                    warm, size, res, warm_pivots = spatial_warm_step(
                        model, D, tables, system, not constant_A, h, q, nu, q_ref, u, contacts, nc, delta_n, delta_t, basis, W, side,
                        whole,
                    )  # fmt: skip
                blocks_ok = True
                if not constant_A and warm != WARM_DONE:  # the rotating bodies' blocks at q, in place: the System's own
                    blocks_ok = _rotating_blocks_at(bi, bf, q, eps_eff, hd, v_index, kp, kd, max_force, system, block3, work3, R3, I3)
                if warm != WARM_DONE and not tried and _may_take_planar_warm(dimension == 2, constant_A, limited, model, step_solver, nc):
                    warm, size, res, warm_pivots = planar_warm_step(
                        model, D, tables, system, h, q, nu, q_ref, u, contacts, nc, delta_n, delta_t, basis, B, side, whole
                    )
                if warm == WARM_DONE:  # its results, on its side of R
                    q2, nu2, q_ref2 = R.q[side], R.nu[side], R.q_ref[side]
                    if not pgs:  # (PGS keeps the basis table as it is)
                        basis = R.basis[side]
                    if compliant:
                        dn2, dt2 = R.delta_n[side], R.delta_t[side]
                    side = 1 - side  # the next warm step writes the other side, not this state
                    st, piv, p_n, p_t = StepStatus.OK.value, warm_pivots, R.impulses[:nc], R.frictions[:nc]
                elif not blocks_ok:  # (as `dynamics_step` reports A's singular blocks)
                    q2, nu2, q_ref2, st, piv, res, size, p_n = q, nu, q_ref, StepStatus.SINGULAR.value, 0, 0.0, 0, no_impulse
                else:
                    r = dynamics_step(
                        model, step_solver, D, tables, system, h, q, nu, q_ref, delta_n, delta_t, u, contacts, nc, warm_n, warm_t, basis
                    )
                    q2, nu2, q_ref2, dn2, dt2, st, piv, res, size, p_n, p_t, sw, basis = r
                if step_solver.method == SOLVER_AUTO and sw >= solver.max_sweeps:
                    step_solver = lemke
                if keep_warm and st == StepStatus.OK:
                    n_warm = _keep_warm(dimension == 3, nc, c_slot, p_n, p_t, c_t, c_o, warm_n, warm_t, warm_w, warm_slots, n_warm)
            sweeps, lcp_solves, max_size, pivots, max_residual = _tally(
                sweeps, lcp_solves, max_size, pivots, max_residual, sw, size, piv, res
            )
            if st != StepStatus.OK:
                status = st
                break
            if widen < WIDEN_TRIES and step_outran(bi, bf, h, CONTACT_MARGIN, nu2, speed, moved):
                widened_velocity(probe if widen > 0 else nu, nu2, probe)
                nc_back, unsupported_back = detect_contacts_into(
                    S, q, probe, h, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, poses, speed, reach, axis, cores
                )
                if nc_back != nc or unsupported_back > 0:  # more contacts within its reach: the step taken again over them
                    widen += 1
                    side, basis, free_side = side0, basis0, free_side0
                    continue
            widen = 0
            q, nu, q_ref, delta_n, delta_t = q2, nu2, q_ref2, dn2, dt2
            force_steps += _record_forces(c_pair, c_n, c_t, c_o, p_n, p_t, h, pair_force, pair_wrench)
            t += h
            steps += 1
            if record_every > 0 and steps % record_every == 0 and n_rec < max_records - 1:
                n_rec = _record_state(rec_t, rec_q, rec_nu, n_rec, t, q, nu)
            i += 1
    outcome, n_rec = _finish(
        S,
        goal,
        unsafe,
        scripted,
        t0,
        t,
        q,
        nu,
        status,
        outcome,
        c_pair,
        c_psi,
        c_n,
        c_pa,
        c_pb,
        unsupported,
        pair_psi,
        rec_t,
        rec_q,
        rec_nu,
        n_rec,
    )
    # the records as views of their buffers, which are sized to the run (`_start_records`); copies
    # where the run stopped before it had written half of them (an outcome met early), so that a
    # result does not hold a buffer mostly unwritten
    times, trajectory, velocities = rec_t[:n_rec], rec_q[:n_rec], rec_nu[:n_rec]
    if 2 * n_rec < max_records:
        times, trajectory, velocities = times.copy(), trajectory.copy(), velocities.copy()
    return RolloutOutput(
        q,
        nu,
        q_ref,
        delta_n,
        delta_t,
        t,
        outcome,
        status,
        steps,
        lcp_solves,
        pivots,
        max_residual,
        max_size,
        times,
        trajectory,
        velocities,
        pair_force,
        min_psi,
        force_steps,
        sweeps,
        pair_wrench,
        basis,
    )


@numba.njit(cache=True, error_model="numpy")
def bind(items):
    """A typed List holding the one tuple `items`, what `rollout_bound` and `propagate_kernel`
    take as `bound`. Made here, in a cached kernel, not by numba.typed.List in Python: there
    numba compiles the List's own methods for each new tuple type, in every process (about 1 s
    a type, measured: the first `ladder simulate` call paid it, `ladder plan` twice), and each
    binding took about 1.4 ms; from here, 0.1 ms and nothing compiled after the cache's first
    run."""
    bound = numba.typed.List()
    bound.append(items)
    return bound


def general_step_types(S, D, model, solver, q, nu, q_ref, delta_n, delta_t, h) -> tuple:
    """numba's types of the arguments `rollout_kernel` passes `models.stepper.dynamics_step`
    (its general contact step), made from values built as the kernel builds them, so that
    `models.kernel_cache.compile_ahead` can compile that step beside the kernel's own compile
    (tests/test_kernel_cache.py checks them against the cache's entry)."""
    tables = SceneTables(S.bi, S.bf, S.pi, S.pf, S.dimension == 3)
    system = _start_system(S, D, model, h, q)
    contacts, _ = contact_buffers(S.pi, S.nv)
    frames = _contact_frames(contacts.psi.shape[0])
    directions = model.friction_directions if S.dimension == 3 else 2
    basis = basis_table(contacts.psi.shape[0], D.v_index.shape[0], directions)
    u = np.zeros((1, D.v_index.shape[0]))[0]
    args = (model, solver, D, tables, system, float(h), q, nu, q_ref, delta_n, delta_t, u, contacts, 0, frames[5], frames[6], basis)
    return tuple(numba.typeof(a) for a in args)


@numba.njit(cache=True, error_model="numpy")
def rollout_bound(bound, q, nu, q_ref, delta_n, delta_t, basis, controls, durations, h, record_every, max_records, stop_at_outcome, t0):
    """`rollout_kernel` on a scene bound once: bound, a typed List holding one tuple (S, D,
    model, solver, goal, unsafe), crosses into the kernel as one pointer, where the scene's
    30-odd arrays would be unboxed one by one on every call (about 12 us of a call, measured;
    `propagate_kernel` binds its scene the same way). Not for scenes with scripted obstacles,
    whose pose tables the kernel writes (`Rung.rollout` passes those a copy per call). Returns
    the `RolloutOutput`'s fields as a plain tuple, in its order: numba boxes a tuple of 22 values
    about 0.5 us faster than the named tuple (a 100-step push of box_push_3d is about 300 us)."""
    S, D, model, solver, goal, unsafe = bound[0]
    return rollout_kernel(
        S, D, model, solver, goal, unsafe, q, nu, q_ref, delta_n, delta_t, basis, controls, durations, h, record_every, max_records,
        stop_at_outcome, t0,
    )[:]  # fmt: skip


@numba.njit(cache=True, error_model="numpy")
def rollout_each(bound, q, nu, q_ref, delta_n, delta_t, basis, controls, durations, h):
    """`rollout_bound` once per control, in one compiled call: control k runs from the state
    and basis table control k - 1 ended on, each in a `rollout_kernel` call of its own (stopping
    at an outcome, from t0 = 0, its warm starts dropped at its start), as separate calls of
    `Rung.rollout` would run them, with the same bits, until one ends in an outcome or a step
    failure. Only the Python round trip of each call is saved (about 20 of its 35 us before
    its steps, docs/measurements.md): the ladder replays plans this way. A scene with scripted
    obstacles is bound with pose tables of this call's own (`models.rungs.own_poses`): each
    control's call places them at its start. The caller's state arrays are copied, not
    written. Returns (n: the controls run; per control, n rows
    of: its end state's q, nu, q_ref, delta_n, delta_t, basis table; its `StepStatus` value,
    outcome, smallest signed distance and steps with a contact force)."""
    S, D, model, solver, goal, unsafe = bound[0]
    K = controls.shape[0]
    Q, NU, Q_REF = np.empty((K, q.shape[0])), np.empty((K, nu.shape[0])), np.empty((K, q_ref.shape[0]))
    DN, DT = np.empty((K, delta_n.shape[0])), np.empty((K, delta_t.shape[0], 2))
    BASIS = np.empty((K, 0, 0), np.int8)  # shaped by the first call's table
    status, outcome = np.zeros(K, np.int64), np.zeros(K, np.int64)
    min_psi, force_steps = np.empty(K), np.zeros(K, np.int64)
    u, d = np.empty((1, controls.shape[1])), np.empty(1)
    # np.int64 / np.bool_, as `propagate_kernel`: the types Python's calls compiled rollout_kernel for
    every, records, stop = np.int64(1 << 30), np.int64(2), np.bool_(True)
    n = 0
    for k in range(K):
        u[0] = controls[k]
        d[0] = durations[k]
        out = rollout_kernel(
            S, D, model, solver, goal, unsafe, q.copy(), nu.copy(), q_ref.copy(), delta_n.copy(), delta_t.copy(), basis, u, d, h,
            every, records, stop, 0.0,
        )  # fmt: skip
        if k == 0:
            BASIS = np.empty((K, out.basis.shape[0], out.basis.shape[1]), np.int8)
        Q[k], NU[k], Q_REF[k], DN[k], DT[k], BASIS[k] = out.q, out.nu, out.q_ref, out.delta_n, out.delta_t, out.basis
        status[k], outcome[k], min_psi[k], force_steps[k] = out.status, out.outcome, out.min_psi, out.force_steps
        q, nu, q_ref, delta_n, delta_t, basis = out.q, out.nu, out.q_ref, out.delta_n, out.delta_t, out.basis
        n = k + 1
        if out.status != StepStatus.OK or out.outcome != Outcome.NONE:
            break
    return n, Q, NU, Q_REF, DN, DT, BASIS, status, outcome, min_psi, force_steps


# ----------------------------------------------------------------------------- the planners' propagation

#: How the rollout that made a planner's state ended, held as its last entry (see
#: `planner.ompl_adapter`): running, the goal reached, unsafe, a numerical failure, outside
#: the configuration limits or a drive wound up (`propagate_kernel`).
FLAG_RUNNING, FLAG_GOAL, FLAG_UNSAFE, FLAG_FAILED, FLAG_INVALID = 0.0, 1.0, 2.0, 3.0, 4.0


@numba.njit(cache=True, error_model="numpy")
def propagate_kernel(bound, x, u, duration, h, y):
    """One propagation of a sampling planner, with nothing crossing into Python but two flat
    vectors: the state x = [q, nu, q_ref, delta_n, delta_t, flag] runs control u for
    `duration` (`rollout_kernel`, stopping at an outcome) into y, whose flag says how it ended:
    FLAG_FAILED (a step failure), FLAG_GOAL, FLAG_UNSAFE, else FLAG_RUNNING; a running or goal
    state outside [low, high] or with a drive wound up (its reference ahead of its position
    q[drive_q[j]] by more than windup[j]) is FLAG_INVALID. Returns the run's step status.

    bound: a typed List holding one tuple (S, D, model, solver, goal, unsafe, sizes, low, high,
    drive_q, windup, basis), what stays the same from call to call (sizes: nq, nv, na, nd of
    the flattening; basis: the kernel's warm start, an empty table for none). One typed List
    crosses into the kernel as one pointer, where the scene's 30-odd arrays would be unboxed
    one by one on every call (about 10 us of a 35 us propagation, measured)."""
    S, D, model, solver, goal, unsafe, sizes, low, high, drive_q, windup, basis = bound[0]
    nq, nv, na, nd = sizes[0], sizes[1], sizes[2], sizes[3]
    q = x[:nq].copy()
    nu = x[nq : nq + nv].copy()
    q_ref = x[nq + nv : nq + nv + na].copy()
    delta_n = x[nq + nv + na : nq + nv + na + nd].copy()
    delta_t = x[nq + nv + na + nd : nq + nv + na + 3 * nd].copy().reshape(nd, 2)
    durations = np.empty(1)
    durations[0] = duration
    # np.int64 / np.bool_: literal constants would type as Literal[...] and compile a second
    # rollout_kernel (minutes of a fresh clone's first run) beside the one Python calls
    every, records, stop = np.int64(1 << 30), np.int64(2), np.bool_(True)
    out = rollout_kernel(
        S, D, model, solver, goal, unsafe, q, nu, q_ref, delta_n, delta_t, basis, u.reshape(1, -1), durations, h, every, records, stop, 0.0
    )
    flag = FLAG_RUNNING
    if out.status != StepStatus.OK:
        flag = FLAG_FAILED
    elif out.outcome == Outcome.GOAL:
        flag = FLAG_GOAL
    elif out.outcome == Outcome.UNSAFE:
        flag = FLAG_UNSAFE
    if flag == FLAG_RUNNING or flag == FLAG_GOAL:
        for i in range(nq):
            if not low[i] <= out.q[i] <= high[i]:  # NaN is outside
                flag = FLAG_INVALID
        for j in range(drive_q.shape[0]):
            if abs(out.q_ref[j] - out.q[drive_q[j]]) > windup[j]:
                flag = FLAG_INVALID
    y[:nq] = out.q
    y[nq : nq + nv] = out.nu
    y[nq + nv : nq + nv + na] = out.q_ref
    y[nq + nv + na : nq + nv + na + nd] = out.delta_n
    y[nq + nv + na + nd : nq + nv + na + 3 * nd] = out.delta_t.ravel()
    y[nq + nv + na + 3 * nd] = flag
    return out.status


# ----------------------------------------------------------------------------- the cost split

#: Stages `stage_loop` repeats (`ladder bench`'s cost split of a contact step); SETUP repeats none.
#: ASSEMBLY and CONTACT_SOLVE are the first parts of SOLVE (`models.stepper.contact_stage`).
STAGE_SETUP, STAGE_DETECT, STAGE_CLASSIFY, STAGE_JACOBIANS, STAGE_SOLVE, STAGE_ASSEMBLY, STAGE_CONTACT_SOLVE = -1, 0, 1, 2, 3, 4, 5


@numba.njit(cache=True, error_model="numpy")
def stage_loop(stage, S, D, model, solver, goal, unsafe, q, nu, q_ref, delta_n, delta_t, u, h, repeats):
    """One stage of a dynamics step of `rollout_kernel`, `repeats` times at the state (q, nu,
    q_ref, delta_n, delta_t) under command u: STAGE_DETECT the contacts (broadphase, narrowphase),
    STAGE_CLASSIFY the pair distances and the task's goal and unsafe predicates, STAGE_JACOBIANS
    the contact frames' Jacobian columns, STAGE_SOLVE the rung's dynamics step (A^-1's rotating
    bodies' blocks where A depends on q, the contact problem's assembly, its solve warm-started from the state's own
    first solve as in a steady push (Lemke's basis, PGS's impulses), the integration), and its
    first parts: STAGE_ASSEMBLY (those blocks, the free velocity and the LCP's assembly) and
    STAGE_CONTACT_SOLVE (that and the contact solve); where the rollout would take the planar
    or spatial warm step at the state (`models.stepper.planar_warm_step`,
    `models.stepper.spatial_warm_step`), these time it and its parts. Every
    stage runs once first (STAGE_SETUP: only that), so a
    stage's cost per call is (time(stage) - time(STAGE_SETUP)) / repeats. For `ladder bench`
    (planar scenes without scripted obstacles, or spatial ones). Returns (the contacts found,
    and the warm-started solve's work at the state: the Lemke pivots and PGS sweeps of a
    STAGE_SOLVE step, zeros for the other stages)."""
    bi, bf, pi, verts, nv, dimension = S.bi, S.bf, S.pi, S.verts, S.nv, S.dimension
    tables = SceneTables(bi, bf, pi, S.pf, dimension == 3)
    contacts, first_slot = contact_buffers(pi, nv)
    c_pair, c_psi, c_slot, W_n, W_t, W_o, c_bias = contacts
    c_n, c_t, c_o, c_pa, c_pb, warm_n, warm_t, warm_w, warm_slots = _contact_frames(c_psi.shape[0])
    unsupported, pair_psi, _, _, (pos, poses, speed, reach, axis, cores) = _pair_buffers(pi.shape[0], bi)
    g_op, g_index, g_lo, g_hi = goal
    u_op, u_index, u_lo, u_hi = unsafe
    stack = np.zeros(max(g_op.shape[0], u_op.shape[0]) + 1, np.bool_)
    directions = model.friction_directions if dimension == 3 else 2
    basis = basis_table(c_psi.shape[0], D.v_index.shape[0], directions)
    system = _start_system(S, D, model, h, q)
    rotating = has_rotations(bi)
    eps_eff = model.quasistatic_inertia if model.eps == 0.0 else model.eps
    hd = drive_step(model, h)  # (A's drive term's step, as rollout_kernel's)
    nc, pivots, sweeps = 0, 0, 0
    R3, I3, block3, work3 = np.empty((3, 3)), np.empty((3, 3)), np.empty((BODY_DOFS, BODY_DOFS)), np.empty((BODY_DOFS, 2 * BODY_DOFS))
    limited = any_limited(D.max_force)
    planar_cap = c_psi.shape[0] if dimension == 2 else 0
    spatial_cap = min(c_psi.shape[0], SPATIAL_WARM_CONTACTS) if dimension == 3 else 0
    R = warm_results(c_psi.shape[0], nv, q.shape[0], D.v_index.shape[0], basis, delta_n.shape[0])
    B, W = planar_warm_buffers(planar_cap, R), spatial_warm_buffers(spatial_cap, directions, bi.shape[0], R)
    P = pgs_work(c_psi.shape[0], _pgs_directions(model, dimension == 3))
    # side 0 of R, the whole step and _assemble's flags as runtime values, not literals: the warm
    # steps and _assemble compile once, for this loop, rollout_kernel and Python's calls alike
    side, whole, scripted, with_friction = np.int64(0), np.int64(PART_STEP), np.bool_(False), np.bool_(True)
    warm = False  # whether the rollout takes the planar warm step at the state (as rollout_kernel)
    warm3 = False  # the spatial warm step
    warm_pgs = False  # the PGS step
    # the spatial steps' fixed arguments by reference, as `_contact_run` passes them
    warm_fixed = spatial_warm_fixed(D, tables, system, contacts, W)
    pgs_fixed = pgs_warm_fixed(D, tables, system, contacts, warm_n, warm_t, W, P)
    planar_fixed = planar_warm_fixed(D, tables, system, contacts, B)
    for k in range(repeats + 1):
        if k == 0 or stage == STAGE_DETECT:
            if dimension == 3:
                nc, _ = detect_spatial_into(S, q, nu, h, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, speed, reach)
            else:
                nc = detect_planar_into(
                    bi, bf, verts, pi, q, nu, h, CONTACT_MARGIN, c_pair, c_psi, c_n, c_pa, c_pb, pos, poses, speed, reach, axis, cores
                )
        if k == 0 or stage == STAGE_CLASSIFY:
            _distances(nc, c_pair, c_psi, c_slot, first_slot, pair_psi)
            _classify_with(g_op, g_index, g_lo, g_hi, u_op, u_index, u_lo, u_hi, q, pair_psi, stack)
        if k == 0 or stage == STAGE_JACOBIANS:
            _assemble(bi, bf, pi, dimension, q, nc, c_pair, c_n, c_t, c_o, c_pa, c_pb, W_n, W_t, W_o, c_bias, scripted, with_friction, pos)
        if k == 0 or stage >= STAGE_SOLVE:
            if rotating and not (warm3 or warm_pgs):  # as rollout_kernel: A^-1's rotating blocks at q (the spatial steps refresh them)
                _rotating_blocks_at(bi, bf, q, eps_eff, hd, D.v_index, D.kp, D.kd, D.max_force, system, block3, work3, R3, I3)
        if k > 0 and stage > STAGE_SOLVE:
            part = PART_ASSEMBLY if stage == STAGE_ASSEMBLY else PART_CONTACT_SOLVE
            if warm:
                planar_warm_step_on(model, planar_fixed, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, part)
            elif warm3:
                spatial_warm_step_on(model, warm_fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, part)
            elif warm_pgs:
                pgs_warm_step_on(model, solver, pgs_fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, side, part)
            else:
                contact_stage(
                    part, model, solver, D, tables, system, h, q, nu, q_ref, delta_n, delta_t, u, contacts, nc, warm_n, warm_t, basis
                )
        # the whole step called as its parts are above and as the rollout calls it (its fixed
        # arguments by reference, so no array in them is counted at the call)
        if k > 0 and stage == STAGE_SOLVE and warm:
            pivots = planar_warm_step_on(model, planar_fixed, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, whole)[3]
            sweeps = 0
        elif k > 0 and stage == STAGE_SOLVE and warm3:
            pivots = spatial_warm_step_on(model, warm_fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, whole)[3]
            sweeps = 0
        elif k > 0 and stage == STAGE_SOLVE and warm_pgs:
            sweeps = pgs_warm_step_on(model, solver, pgs_fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, side, whole)[3]
            pivots = 0
        elif k == 0 or stage == STAGE_SOLVE:
            r = dynamics_step(model, solver, D, tables, system, h, q, nu, q_ref, delta_n, delta_t, u, contacts, nc, warm_n, warm_t, basis)
            if k == 0:  # the warm starts (Lemke's basis, PGS's impulses) of a steady push
                basis = r.basis
                _keep_warm(dimension == 3, nc, c_slot, r.p_n, r.p_t, c_t, c_o, warm_n, warm_t, warm_w, warm_slots, 0)
                if _may_take_planar_warm(dimension == 2, not rotating, limited, model, solver, nc):
                    args = (model, D, tables, system, h, q, nu, q_ref, u, contacts, nc, delta_n, delta_t, basis, B, side, whole)
                    warm = planar_warm_step(*args)[0] == WARM_DONE
                if _may_take_spatial_warm(dimension == 3, limited, model, solver, nc):
                    args3 = (model, D, tables, system, rotating, h, q, nu, q_ref, u, contacts, nc, delta_n, delta_t, basis, W, side, whole)
                    warm3 = spatial_warm_step(*args3)[0] == WARM_DONE
                if _may_take_pgs_warm(limited, model, solver, nc):
                    argsp = (model, solver, D, tables, system, rotating, h, q, nu, q_ref, u, contacts, nc, delta_n, delta_t)
                    warm_pgs = pgs_warm_step(*argsp, warm_n, warm_t, W, P, side, whole)[0] == WARM_DONE
            else:
                pivots, sweeps = r.pivots, r.sweeps
        if stage == STAGE_SETUP:
            break
    return nc, pivots, sweeps

"""One time-stepper for the paper's eq. (3), compiled; every rung is a setting of it.

A step from (q, nu, q_ref, delta) with commanded actuator speeds u over h reads as
contacts -> assemble -> solve -> integrate:

1. contacts (done by the caller, `models.rollout`): detected at q with a broadphase margin
   from nu and h; frames n, t (o); Jacobians W_n, W_t (W_o). Friction directions D are +-t in
   the plane (exact) and d directions of a polyhedral cone in space.
2. assemble: the drives are implicit PD laws tracking q_ref (advanced by h u, clamped to the
   position limits), so with inertia scale eps

       A nu+ = eps M nu + h (f_gravity + kp (q_ref+ - q) + kd u) + W_n p_n + D beta,
       A = eps M + h (h kp + kd) on the driven DOFs,

   at theta = 1; with the paper's theta-rule (theta < 1) the drives' force is evaluated at
   l+theta (`_drive_impulse`; A's drive term theta h (theta h kp + kd)),

   where p = h lambda are contact impulses.
3. solve the LCP in (p_n, beta, gamma) (Stewart-Trinkle form) with Lemke. Compliant contact
   (eq. 3, damping read as C/h (delta+ - delta)) adds 1 / (h (h K + C)) to the diagonal of the
   normal and friction blocks and shifts q by the previous deformation; rigid contact (eq. 5)
   has neither. Or (`Solver`: how, not what) solve the same problem by projected Gauss-Seidel
   on the contact impulses, body by body (`models.contact_pgs`): no dense matrix, O(bodies +
   contacts) per step beyond contact detection, to a tolerance, warm-started by the caller.
4. integrate: q+ = q + h G(q) (theta nu+ + (1 - theta) nu) (theta = 1: the paper's semi-implicit
   scheme), delta+ = (p + C delta) / (h K + C).

Quasistatic rungs (eps = 0) as the limit eps -> 0 of the dynamic model: at eps = 0 a passive
body with nothing resisting it (the triangle on its frictionless palm, pushed by one finger
with mu < 1) has no unique velocity. We take the limit of the *memoryless* dynamic step
eps M nu+ = h F + W p as eps -> 0: it selects, among all velocities that satisfy equilibrium
and the contact conditions, the one of least kinetic norm nu^T M nu (the LCP is the
optimality condition of that QP). Numerically eps = QUASISTATIC_INERTIA and the previous
velocity is not remembered.

Failures never raise: the step returns a `StepStatus` (OK or a failure whose `.message` says
why; PGS that does not converge: CONTACT_NOT_CONVERGED) and the solver's recomputed residual,
in a `StepResult`; the rollout stops
on a failure.

Contracts are named tuples: `Model` (what is solved), `Solver` (how), `Drives`, `SceneTables`
(the packed scene tables), `System` (A and what never changes), `models.contact.ContactSet`
(the contacts at q) in; `StepResult` out (`dynamics_step`). Hot-path note: numba increfs and
decrefs every array of a tuple argument on each call, so the tuples a step takes are built
once per rollout (the contact set is refilled in place, its count nc travels beside it),
kernels take the packed scene tables, not `SceneData`, and the two cheap steps (`free_step`,
`kinematic_step`, about a microsecond each) take plain arrays.
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numba
import numpy as np

from models.contact_pgs import (
    BODY_DOFS,
    PgsStatus,
    _apply_block,
    _by_contact_into,
    _invert_small_into,
    _split,
    block_solve_into,
    body_blocks,
    cone_directions_into,
    contact_pgs,
    contact_pgs_into,
)
from models.kinematics import (
    BF_AXES,
    BF_INERTIA,
    BF_MASS,
    BF_TILTED,
    BI_QMAP,
    BI_VMAP,
    PF_C,
    PF_K,
    PF_MU,
    Q_QW,
    V_ANGLE,
    V_WX,
    quat_matrix_into,
    quat_mul_scalars,
)
from models.lcp import (
    DEFAULT_LEMKE_PIVOTS_PER_VARIABLE,
    LCP_REGULARIZATION,
    LCP_REGULARIZATION_STEPS,
    STATUS_SOLVED,
    STATUS_SOLVED_INACCURATE,
    LemkeWork,
    _gauss_solve,
    _natural_map_residual,
    complementarity_residual,
    lemke_from_guess_into,
    lemke_kernel,
    lemke_warm_kernel,
    lemke_work,
    matrix_view,
    refined_on_basis,
    warm_guess_dropping_into,
)
from models.nonnegative import nonnegative_indices
from models.reference import reference, referent

#: Quasistatic rungs: inertia scale standing in for eps -> 0 (times the mass matrix).
QUASISTATIC_INERTIA = 1e-6
#: A contact whose Jacobian column is below this does not couple to any free DOF.
ZERO_COLUMN = 1e-12
#: An LCP solution is accepted while its recomputed residual is below this.
LCP_TOLERANCE = 1e-7
#: A contact step's solution is accepted while no active contact's normal row is short by more
#: than this over the step (m): rigid, psi + h (W_n^T nu+ + bias) >= -CLOSING_TOL (`_closes`),
#: the LCP's own row in lengths. Its residual is relative to its q, which a quasistatic
#: rung's free velocity (h F over an inertia of 1e-6) makes large: a residual of 6.5e-10 had
#: left a prism's support on an incline closing at 0.08 m/s, and the prism went 8 km through
#: it in 0.3 s, with status ok. Healthy steps of the shipped scenes close by at most 2.5e-8 m.
CLOSING_TOL = 1e-6
#: A step's LCP is first tried on the previous step's complementary basis (`basis_table`); that
#: point is accepted when its recomputed natural-map residual (on the LCP scaled to max |M| = 1)
#: is at most this (1e3 below LCP_TOLERANCE, what the step accepts of a cold solve); else Lemke
#: pivots from scratch. Not tighter: degenerate solutions carry round-off above 1e-14 whichever
#: way they are found. A contact whose friction sits exactly on the cone's edge (gamma = 0 and
#: mu p_n - sum beta = 0, round-off in its scaled gamma row) left 1e-13 in a jammed grasp and
#: 1.07e-12 in the paper scene's compliant squeeze, where at 1e-12 every step fell back to
#: Lemke, which pivoted to the guessed basis and the same residual (89,160 pivots in 25,224
#: LCPs; docs/measurements.md).
WARM_TOLERANCE = 1e-10
#: A state entry above this in magnitude counts as diverged.
DIVERGENCE_LIMIT = 1e10


class StepStatus(IntEnum):
    """How a step ended. Only OK is a success; `.label` is the name files and the CLI print,
    `.message` says why (and what to try). Compiled code compares and stores the values."""

    OK = 0
    LCP_FAILED = 1
    NON_FINITE = 2
    DIVERGED = 3
    UNSUPPORTED_PAIR = 4
    SINGULAR = 5
    BLOCKED = 6
    CONTACT_NOT_CONVERGED = 7

    @property
    def label(self) -> str:
        return self.name.lower()

    @property
    def message(self) -> str:
        return _STEP_MESSAGES[self]


_STEP_MESSAGES = {
    StepStatus.OK: "ok",
    StepStatus.LCP_FAILED: (
        "the contact LCP could not be solved (Lemke failed, its residual is too large, or its solution leaves a contact"
        " closing); try a smaller step or, on a quasistatic rung, a larger inertia"
    ),
    StepStatus.NON_FINITE: "the state became non-finite",
    StepStatus.DIVERGED: "the state diverged (an entry exceeded 1e10); try a smaller step",
    StepStatus.UNSUPPORTED_PAIR: "a contact pair needs python-fcl (a mesh against a non-plane), which compiled rollouts cannot call",
    StepStatus.SINGULAR: "the velocity system is singular (a free DOF with neither inertia nor a drive)",
    StepStatus.BLOCKED: "kinematic model: the commanded motion would penetrate something nothing can push away",
    StepStatus.CONTACT_NOT_CONVERGED: (
        "PGS reached its sweep limit before the contact impulses met its tolerance; use the lemke (or auto) contact solver "
        "(the rung's contact_solver), on the polygonal cone (the exact cone is PGS's only, and Lemke on polygons aligned with its "
        "friction did not solve it either); from Python, a models.stepper.Solver with more max_sweeps or a looser tolerance"
    ),
}


class Model(NamedTuple):
    """Physics settings of a rung (what is solved); see the module docstring."""

    kinematic: bool  # eq. (8): actuated speeds exact, passive speeds min-norm; no forces
    eps: float  # inertia scale: 1 dynamic, 0 quasistatic
    compliant: bool  # finite K, C with deformation state; else rigid
    theta: float  # theta-rule weight for the position update
    friction_directions: int  # polyhedral cone directions in space (2 in the plane)
    # eps = 0 (quasistatic): the inertia scale the memoryless step keeps; QUASISTATIC_INERTIA
    # stands in for the limit eps -> 0, 1 is a quasi-dynamic step with full inertia
    quasistatic_inertia: float = QUASISTATIC_INERTIA
    # s: the contact solver's warm starts (Lemke's basis table, `basis_table`; PGS's impulses
    # by slot; auto's switch to Lemke) are dropped at every multiple of this time (0: never).
    # A planner's control period: a planner propagates a plan one control period per call, each
    # starting cold from a state vector, and its one-call replay must solve the same contact
    # problems (at a degenerate LCP another basis is another exact solution; PGS stops within
    # its tolerance of the solution its start leads it to). Lemke's first step of a period
    # guesses its basis from its own LCP's q (`_basis_guess`), not from the steps before
    warm_period: float = 0.0
    # in space, friction in the exact circular Coulomb cone (eq. 4: mu p_n in every direction of
    # sliding) instead of the polygon of friction_directions sides: PGS solves it
    # (`models.contact_pgs.disk_minimiser`); Lemke's LCP is the polygon's
    exact_cone: bool = False
    # rigid contact's normal impulses are statically indeterminate where more contacts support a
    # body than its DOFs pin (a box on a plane that turns about the vertical only: four corners,
    # one equation), and Lemke's vertex solution may load them unevenly, whose friction turns a
    # box pushed through its centre. This fraction of the largest normal Delassus diagonal added
    # to every normal diagonal makes the normal block positive definite: the load is shared as
    # equally stiff contacts share it (the rigid limit of compliance, least squares of the
    # impulses), at the cost of a penetration speed of that much times the diagonal times the
    # impulse. 0: the LCP as it is (exact rigid contact)
    regularization: float = 0.0


class Drives(NamedTuple):
    """Actuated DOFs: nu/q indices, PD gains, limits (arrays of length n_actuated)."""

    q_index: np.ndarray
    v_index: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    gravity: np.ndarray  # (3,)
    max_force: np.ndarray  # force limit per drive, N (inf: unlimited)
    law: np.ndarray  # (n_actuated, LAW_COLUMNS): each drive's feedback law (`models.rollout.law_speeds`; LAW_ACTIVE 0: none)


#: Columns of Drives.law: active (1: the drive follows its law, its commanded speed is the
#: law's desired speed each step), the target's body (-1: a fixed coordinate value), the world
#: axis the drive moves along (0, 1, 2), the gain kp / kd (1/s), the desired speed's limit
#: (inf: none), then the target: a coordinate value, or a point (3) in the body's frame.
LAW_ACTIVE, LAW_BODY, LAW_AXIS, LAW_RATE, LAW_MAX_SPEED, LAW_TARGET = 0, 1, 2, 3, 4, 5
LAW_COLUMNS = 8


SOLVER_LEMKE = 0
SOLVER_PGS = 1
SOLVER_AUTO = 2
#: Contact solvers by name (the scenario format's `contact_solver` values).
SOLVER_METHODS = {"lemke": SOLVER_LEMKE, "pgs": SOLVER_PGS, "auto": SOLVER_AUTO}
#: PGS: accepted residual, relative to the step's impulse scale (models.contact_pgs).
PGS_TOLERANCE = 1e-6
#: PGS: sweeps before the step reports StepStatus.CONTACT_NOT_CONVERGED.
PGS_MAX_SWEEPS = 1000
#: auto: PGS from this many detected contacts on. A count does not see what decides, the
#: contacts' coupling (`ladder bench`, scaling; dynamic-rigid, us/step, Lemke against PGS): on
#: boxes apart PGS is the cheaper from the first contact in either dimension (in the plane 2
#: contacts 1.1 against 0.8, 4: 1.5 against 1.1, 32: 33.9 against 5.5; in space 4: 1.9
#: against 1.5), on a stack Lemke is (in the plane 4 contacts 2.3 against 2.5, 8: 5.2 against
#: 17.2; in space 8: 4.0 against 6.3). Below 4 contacts PGS saves under 0.5 us a step and
#: Lemke is exact. Where PGS does not converge, auto pays its sweeps and Lemke's step once, and
#: the rest of the rollout solves with Lemke.
AUTO_PGS_CONTACTS = 4


class Solver(NamedTuple):
    """How the contact problem of a step is solved (numerics; `Model` says what is solved).

    lemke: Lemke's method on the dense Stewart-Trinkle LCP (exact up to round-off; the
    default). pgs: projected Gauss-Seidel on the contact impulses (`models.contact_pgs`),
    O(contacts) per sweep; a step that does not converge within max_sweeps ends with
    StepStatus.CONTACT_NOT_CONVERGED. auto: pgs on steps with at least auto_contacts detected
    contacts, lemke on the others and on any step where PGS does not converge (and, in a
    rollout, on every step after one where PGS did not converge: `models.rollout`).
    The kinematic rung's projection LCP always uses Lemke. Build with `contact_solver`.
    """

    method: int  # SOLVER_LEMKE, SOLVER_PGS or SOLVER_AUTO
    tolerance: float  # PGS: accepted residual, relative to the impulse scale (times eps if eps < 1)
    max_sweeps: int  # PGS: sweep limit per step
    auto_contacts: int  # auto: PGS from this many detected contacts on


def contact_solver(
    name: str = "lemke",
    *,
    tolerance: float = PGS_TOLERANCE,
    max_sweeps: int = PGS_MAX_SWEEPS,
    auto_contacts: int = AUTO_PGS_CONTACTS,
) -> Solver:
    """A validated `Solver`; raises ValueError on an unknown name or an out-of-range setting."""
    if name not in SOLVER_METHODS:
        raise ValueError(f"unknown contact solver {name!r}; expected one of {', '.join(SOLVER_METHODS)}")
    if not (0.0 < tolerance < 1.0):
        raise ValueError(f"PGS tolerance must be in (0, 1), got {tolerance!r}")
    if isinstance(max_sweeps, bool) or int(max_sweeps) != max_sweeps or max_sweeps < 1:
        raise ValueError(f"PGS max_sweeps must be a positive integer, got {max_sweeps!r}")
    if isinstance(auto_contacts, bool) or int(auto_contacts) != auto_contacts or auto_contacts < 1:
        raise ValueError(f"auto_contacts must be a positive integer, got {auto_contacts!r}")
    return Solver(SOLVER_METHODS[name], float(tolerance), int(max_sweeps), int(auto_contacts))


#: The default: every rung solves its contacts with Lemke unless told otherwise.
LEMKE = contact_solver("lemke")


class SceneTables(NamedTuple):
    """The packed scene tables a step reads (`models.kinematics.SceneData`'s bi, bf, pi, pf)."""

    bi: np.ndarray  # int64[nb, BI_COLUMNS]
    bf: np.ndarray  # float64[nb, BF_COLUMNS]
    pi: np.ndarray  # int64[n_pairs, 4]: bodies a, b of each pair
    pf: np.ndarray  # float64[n_pairs, 3]: mu, K, C
    spatial: bool  # a 3-D scene (friction cones, W_o, gyroscopic terms)


class System(NamedTuple):
    """The step's linear system: A nu+ = rhs (+ contact impulses), see the module docstring."""

    A: np.ndarray  # (nv, nv) eps M + h (h kp + kd) on the unlimited drives' DOFs
    Ainv: np.ndarray  # A^-1, or (0, 0) when A changes with q (then A is solved each step)
    M_const: np.ndarray  # the mass matrix when it does not depend on q, else (0, 0)
    rhs_const: np.ndarray  # (nv,) h * gravity force: the part of rhs that never changes
    # A^-1's body blocks (`models.contact_pgs.body_blocks`), read from Ainv where it is given,
    # else A's inverted; empty where a block is singular (then `_blocks` says so): built by
    # `make_system`. Where A changes with q (a free rotation), the rotating bodies' blocks are
    # A(q)'s at the q they were last refreshed at (`rotating_blocks_into`, at every step of a
    # rollout: the other bodies' blocks do not change), and A is A at the start
    dofs: np.ndarray
    count: np.ndarray
    inv: np.ndarray


@numba.njit(cache=True, error_model="numpy")
def make_system(bi, A, Ainv, M_const, rhs_const):
    """The `System` of A (Ainv: A^-1 when A never changes, else (0, 0)), with A^-1's body
    blocks made once (read from Ainv where it is given, else A's inverted): building them
    costs four allocations a step, and where A changes with q only the rotating bodies' change
    (`rotating_blocks_into` refreshes them in place)."""
    dofs, count, inv, ok = body_blocks(bi, A, Ainv)
    if ok:
        return System(A, Ainv, M_const, rhs_const, dofs, count, inv)
    none = np.zeros((0, BODY_DOFS), np.int64)
    return System(A, Ainv, M_const, rhs_const, none, np.zeros(0, np.int64), np.zeros((0, BODY_DOFS, BODY_DOFS)))


@numba.njit(cache=True, inline="always")
def _blocks(bi, system):
    """(dofs, count, inv, ok): A^-1's body blocks, from the System when it holds them (else A's
    are singular: ok False)."""
    if system.count.shape[0] == bi.shape[0]:
        return system.dofs, system.count, system.inv, True
    return body_blocks(bi, system.A, system.Ainv)


class StepResult(NamedTuple):
    """What `dynamics_step` returns. On a failure (status != StepStatus.OK) the state fields
    are the step's input state."""

    q: np.ndarray  # (nq,) q+
    nu: np.ndarray  # (nv,) nu+
    q_ref: np.ndarray  # (n_actuated,) the drives' references, advanced
    delta_n: np.ndarray  # (slots,) normal deformations (compliant contact; zeros when rigid)
    delta_t: np.ndarray  # (slots, 2) tangential deformations in the (t, o) basis
    status: int  # a StepStatus value
    pivots: int  # Lemke pivots taken
    residual: float  # the solver's recomputed residual (Lemke: LCP; PGS: `models.contact_pgs`)
    lcp_size: int  # unknowns of the contact problem (0: none solved)
    p_n: np.ndarray  # (nc,) normal impulse of each contact, N s
    p_t: np.ndarray  # (nc, 2) friction impulse in the (t, o) basis, zero where inactive ((0, 2): none)
    sweeps: int  # PGS sweeps taken
    basis: np.ndarray  # int8 (slots + drives, 3 + d): the complementary basis of this step's LCP (`basis_table`)


#: Columns of a basis table (`basis_table`): whether the row's contact / drive took part, then
#: one flag per LCP variable (1: z basic, 0: w basic).
BASIS_PRESENT = 0
BASIS_NORMAL = 1  # a contact's p_n; a force-limited drive's x
BASIS_GAMMA = 2  # a contact's gamma; a drive's slack s
BASIS_DIRECTIONS = 3  # a contact's friction directions beta_j


@numba.njit(cache=True, error_model="numpy")
def basis_table(slots, drives, directions):
    """An empty basis table (no row present): the warm start of a step that has none.

    The Lemke solver's warm start travels between steps in this table, one row per contact slot
    (`models.contact.ContactSet.slot`), then one per drive: the LCP variables of a contact or
    drive that were basic (z, not w) at the last step that solved an LCP. Rows by slot, not by
    LCP position, so the guess survives contacts that come and go."""
    return np.zeros((slots + drives, BASIS_DIRECTIONS + directions), np.int8)


# ----------------------------------------------------------------------------- mass and forces


@numba.njit(cache=True, error_model="numpy")
def mass_matrix(bi, bf, q, nv):
    """M(q) in velocity coordinates: m on translations, I_zz on planar/yaw angles, R I R^T on rotations."""
    M = np.empty((nv, nv))
    _mass_matrix_into(bi, bf, q, M, np.empty((3, 3)), np.empty((3, 3)))
    return M


@numba.njit(cache=True, inline="always")
def _mass_matrix_into(bi, bf, q, M, R, I):
    """`mass_matrix` into the caller's M (nv, nv), zeroed here; R and I (3, 3) scratch."""
    for r in range(M.shape[0]):
        for c in range(M.shape[1]):
            M[r, c] = 0.0
    for b in range(bi.shape[0]):
        for k in range(3):
            if bi[b, BI_VMAP + k] >= 0:
                M[bi[b, BI_VMAP + k], bi[b, BI_VMAP + k]] = bf[b, BF_MASS]
        if bi[b, BI_VMAP + V_ANGLE] >= 0:
            M[bi[b, BI_VMAP + V_ANGLE], bi[b, BI_VMAP + V_ANGLE]] = bf[b, BF_INERTIA + 2]
        if bi[b, BI_VMAP + V_WX] >= 0:
            _world_inertia_into(bi, bf, q, b, R, I)
            for r in range(3):
                for c in range(3):
                    M[bi[b, BI_VMAP + V_WX + r], bi[b, BI_VMAP + V_WX + c]] = I[r, c]


@numba.njit(cache=True, error_model="numpy")
def body_rotation(bi, q, b):
    """Body b's rotation matrix from its (normalised) quaternion coordinates in q."""
    R = np.empty((3, 3))
    _rotation_into(bi, q, b, R)
    return R


@numba.njit(cache=True, inline="always")
def _principal_axes_into(bi, bf, q, b, R):
    """Body b's principal axes in world axes into the caller's R (3, 3): its rotation
    (`_rotation_into`), times the rotation to its principal axes where they are not its own
    (`inertia_products`: BF_TILTED, BF_AXES), so that its inertia in world axes is
    R diag(BF_INERTIA's moments) R^T. (A body without products of inertia takes its rotation
    alone: the same operations as before the axes were kept.)"""
    _rotation_into(bi, q, b, R)
    if bf[b, BF_TILTED] != 0.0:
        for r in range(3):
            a0, a1, a2 = R[r, 0], R[r, 1], R[r, 2]
            for c in range(3):
                R[r, c] = a0 * bf[b, BF_AXES + c] + a1 * bf[b, BF_AXES + 3 + c] + a2 * bf[b, BF_AXES + 6 + c]


@numba.njit(cache=True, inline="always")
def _rotation_into(bi, q, b, R):
    """`body_rotation` into the caller's R (3, 3)."""
    w, x, y, z = q[bi[b, BI_QMAP + Q_QW]], q[bi[b, BI_QMAP + Q_QW + 1]], q[bi[b, BI_QMAP + Q_QW + 2]], q[bi[b, BI_QMAP + Q_QW + 3]]
    norm = np.sqrt(0.0 + w * w + x * x + y * y + z * z)  # (np.sum's order, from 0)
    quat_matrix_into(w / norm, x / norm, y / norm, z / norm, R)


@numba.njit(cache=True, error_model="numpy")
def world_inertia(bi, bf, q, b):
    """Body b's inertia about its centre in world axes: R diag(I) R^T (R: its principal axes in
    world axes, `_principal_axes_into`)."""
    I = np.empty((3, 3))
    _world_inertia_into(bi, bf, q, b, np.empty((3, 3)), I)
    return I


@numba.njit(cache=True, inline="always")
def _world_inertia_into(bi, bf, q, b, R, I):
    """`world_inertia` into the caller's I (3, 3), with R (3, 3) scratch."""
    _principal_axes_into(bi, bf, q, b, R)
    for r in range(3):
        for c in range(3):
            s = 0.0
            for k in range(3):
                s += R[r, k] * bf[b, BF_INERTIA + k] * R[c, k]
            I[r, c] = s


@numba.njit(cache=True, error_model="numpy")
def rotating_blocks(bi, bf, q, eps, h, v_index, kp, kd, max_force, dofs, count, inv):
    """`rotating_blocks_into` with its scratch made here (for tests and Python callers)."""
    block, work, R, I = np.empty((BODY_DOFS, BODY_DOFS)), np.empty((BODY_DOFS, 2 * BODY_DOFS)), np.empty((3, 3)), np.empty((3, 3))
    return rotating_blocks_into(bi, bf, q, eps, h, v_index, kp, kd, max_force, dofs, count, inv, block, work, R, I)


@numba.njit(cache=True, inline="always")
def rotating_blocks_into(bi, bf, q, eps, h, v_index, kp, kd, max_force, dofs, count, inv, block, work, R, I):
    """The body blocks of A(q)^-1 (`models.contact_pgs.body_blocks_into` of `system_matrix` at
    q) of the bodies with a free rotation, in place in inv; dofs and count are the System's
    (they never change), and the other bodies' blocks do not depend on q. Each block is built
    alone, its entries as A(q) holds them (eps M(q), then the unlimited drives' h (h kp + kd)
    on their DOFs, in the drives' order), and inverted as `body_blocks_into` inverts it: the
    same bits, without A's nv x nv rebuild and the other bodies' inversions (0.85 -> 0.19 us
    a step at box_push_3d, with `_invert_3x3_into`: docs/measurements.md). block (BODY_DOFS,
    BODY_DOFS), work (BODY_DOFS, 2 BODY_DOFS), R, I (3, 3): scratch. Returns ok (False: a
    block is singular, or q not finite)."""
    for b in range(bi.shape[0]):
        if bi[b, BI_VMAP + V_WX] < 0:
            continue
        m = count[b]
        for r in range(m):
            for c in range(m):
                block[r, c] = 0.0
        a = 0  # the block's rows in slot order (x, y, z, the angle: diagonal), the rotation's last
        for k in range(V_WX):
            if bi[b, BI_VMAP + k] >= 0:
                block[a, a] = eps * (bf[b, BF_MASS] if k < V_ANGLE else bf[b, BF_INERTIA + 2])
                a += 1
        _world_inertia_into(bi, bf, q, b, R, I)
        for r in range(3):
            for c in range(3):
                block[a + r, a + c] = eps * I[r, c]
        for j in range(v_index.shape[0]):
            if not np.isfinite(max_force[j]):
                for r in range(m):
                    if dofs[b, r] == v_index[j]:
                        block[r, r] += h * (h * kp[j] + kd[j])
        if not _invert_small_into(block, m, inv[b], work):
            return False
    return True


@numba.njit(cache=True, inline="always")
def _diagonal_momentum_into(bi, bf, nu, b, out):
    """Body b's entries of M nu on its translations (m v) and its planar angle (I_z w), where M
    is diagonal, into the caller's out."""
    for k in range(3):
        if bi[b, BI_VMAP + k] >= 0:
            out[bi[b, BI_VMAP + k]] = bf[b, BF_MASS] * nu[bi[b, BI_VMAP + k]]
    if bi[b, BI_VMAP + V_ANGLE] >= 0:
        out[bi[b, BI_VMAP + V_ANGLE]] = bf[b, BF_INERTIA + 2] * nu[bi[b, BI_VMAP + V_ANGLE]]


@numba.njit(cache=True, inline="always")
def _mass_times_into(bi, bf, q, nu, out, R, I):
    """M(q) nu body by body (the products of `mass_matrix` without forming it), O(bodies), into
    the caller's out (nv), zeroed here; R and I (3, 3) scratch."""
    for v in range(out.shape[0]):
        out[v] = 0.0
    for b in range(bi.shape[0]):
        _diagonal_momentum_into(bi, bf, nu, b, out)
        if bi[b, BI_VMAP + V_WX] >= 0:
            _world_inertia_into(bi, bf, q, b, R, I)
            for r in range(3):
                s = 0.0
                for c in range(3):
                    s += I[r, c] * nu[bi[b, BI_VMAP + V_WX + c]]
                out[bi[b, BI_VMAP + V_WX + r]] = s


@numba.njit(cache=True, inline="always")
def _mass_times_gyro_into(bi, bf, q, nu, mass_nu, gyro, R):
    """M(q) nu (`_mass_times_into`) and the gyroscopic force (`_gyroscopic_into`) in one pass,
    into the caller's mass_nu and gyro (nv each, zeroed here); R (3, 3) scratch. A rotating
    body's M nu there is its angular momentum L = R diag(I) R^T w, which the gyroscopic force
    -w x L needs too: its rotation and L are made once, not three times (L by the gyroscopic
    term's products, not by the world inertia's 3 x 3)."""
    for v in range(nu.shape[0]):
        mass_nu[v] = 0.0
        gyro[v] = 0.0
    for b in range(bi.shape[0]):
        _diagonal_momentum_into(bi, bf, nu, b, mass_nu)
        if bi[b, BI_VMAP + V_WX] < 0:
            continue
        _principal_axes_into(bi, bf, q, b, R)
        i0, i1, i2 = bi[b, BI_VMAP + V_WX], bi[b, BI_VMAP + V_WX + 1], bi[b, BI_VMAP + V_WX + 2]
        w0, w1, w2 = nu[i0], nu[i1], nu[i2]
        L0, L1, L2 = _angular_momentum(bf, b, R, w0, w1, w2)
        mass_nu[i0], mass_nu[i1], mass_nu[i2] = L0, L1, L2
        gyro[i0] -= w1 * L2 - w2 * L1
        gyro[i1] -= w2 * L0 - w0 * L2
        gyro[i2] -= w0 * L1 - w1 * L0


@numba.njit(cache=True, error_model="numpy")
def has_rotations(bi):
    """True when M depends on q (a free spatial rotation)."""
    for b in range(bi.shape[0]):
        if bi[b, BI_VMAP + V_WX] >= 0:
            return True
    return False


@numba.njit(cache=True, error_model="numpy")
def gravity_force(bi, bf, gravity, nv):
    f = np.zeros(nv)
    for b in range(bi.shape[0]):
        for k in range(3):
            if bi[b, BI_VMAP + k] >= 0:
                f[bi[b, BI_VMAP + k]] += bf[b, BF_MASS] * gravity[k]
    return f


@numba.njit(cache=True, inline="always")
def _angular_momentum(bf, b, R, w0, w1, w2):
    """Body b's angular momentum L = R diag(I) R^T w in world axes (R: its principal axes,
    `_principal_axes_into`; w its
    angular velocity), written out: numba's @ calls BLAS, whose overhead dwarfs a 3 x 3."""
    l0 = bf[b, BF_INERTIA] * (R[0, 0] * w0 + R[1, 0] * w1 + R[2, 0] * w2)
    l1 = bf[b, BF_INERTIA + 1] * (R[0, 1] * w0 + R[1, 1] * w1 + R[2, 1] * w2)
    l2 = bf[b, BF_INERTIA + 2] * (R[0, 2] * w0 + R[1, 2] * w1 + R[2, 2] * w2)
    L0 = R[0, 0] * l0 + R[0, 1] * l1 + R[0, 2] * l2
    L1 = R[1, 0] * l0 + R[1, 1] * l1 + R[1, 2] * l2
    L2 = R[2, 0] * l0 + R[2, 1] * l1 + R[2, 2] * l2
    return L0, L1, L2


@numba.njit(cache=True, inline="always")
def _gyroscopic_into(bi, bf, q, nu, f, R):
    """-w x (I_world w) for free spatial rotations (the paper's k(t, q, nu)) into the caller's f
    (nv), zeroed here; R (3, 3) scratch."""
    for v in range(f.shape[0]):
        f[v] = 0.0
    for b in range(bi.shape[0]):
        if bi[b, BI_VMAP + V_WX] < 0:
            continue
        _principal_axes_into(bi, bf, q, b, R)
        w0, w1, w2 = nu[bi[b, BI_VMAP + V_WX]], nu[bi[b, BI_VMAP + V_WX + 1]], nu[bi[b, BI_VMAP + V_WX + 2]]
        L0, L1, L2 = _angular_momentum(bf, b, R, w0, w1, w2)
        f[bi[b, BI_VMAP + V_WX]] -= w1 * L2 - w2 * L1
        f[bi[b, BI_VMAP + V_WX + 1]] -= w2 * L0 - w0 * L2
        f[bi[b, BI_VMAP + V_WX + 2]] -= w0 * L1 - w1 * L0


@numba.njit(cache=True, error_model="numpy")
def system_matrix(bi, bf, q, nv, eps, h, v_index, kp, kd, max_force):
    """A = eps M + h (h kp + kd) on the DOFs of unlimited drives (a force-limited drive's
    impulse is an unknown of the contact problem instead; see `contact_lcp`)."""
    A = np.empty((nv, nv))
    _system_matrix_into(bi, bf, q, eps, h, v_index, kp, kd, max_force, A, np.empty((3, 3)), np.empty((3, 3)))
    return A


@numba.njit(cache=True, inline="always")
def _system_matrix_into(bi, bf, q, eps, h, v_index, kp, kd, max_force, A, R, I):
    """`system_matrix` into the caller's A (nv, nv); R and I (3, 3) scratch."""
    _mass_matrix_into(bi, bf, q, A, R, I)
    for r in range(A.shape[0]):
        for c in range(A.shape[1]):
            A[r, c] = eps * A[r, c]
    for j in range(v_index.shape[0]):
        if not np.isfinite(max_force[j]):
            A[v_index[j], v_index[j]] += h * (h * kp[j] + kd[j])


@numba.njit(cache=True, inline="always")
def drive_step(model, h):
    """The step A's drive term is built at, h' (h' kp + kd) on the driven DOFs (`system_matrix`,
    `rotating_blocks_into`, the force-limited drives' rows): theta h, the implicit part of the
    drives' force under the paper's theta-rule (`_drive_impulse`); h at theta = 1."""
    return model.theta * h


@numba.njit(cache=True, inline="always")
def _drive_impulse(h, theta, kp, kd, q_ref, q_ref_new, q, nu, ff):
    """A drive's PD impulse over a step but its implicit part (in A: theta h (theta h kp + kd) nu+,
    `system_matrix` at step theta h): with the paper's theta-rule, the force evaluated at l+theta,
    h (kp (q_ref(theta) - q(theta)) + kd (ff - nu(theta))), q_ref(theta) = theta q_ref+ +
    (1 - theta) q_ref, q(theta) = q + theta h nu(theta), nu(theta) = theta nu+ + (1 - theta) nu;
    at theta = 1, h (kp (q_ref+ - q) + kd ff) (eq. 3's semi-implicit step: the same bits)."""
    pd = h * (kp * (q_ref_new - q) + kd * ff)
    if theta != 1.0:
        pd -= h * (1.0 - theta) * (kp * (q_ref_new - q_ref) + (theta * h * kp + kd) * nu)
    return pd


@numba.njit(cache=True, error_model="numpy")
def any_limited(max_force):
    """True when some drive has a finite force limit."""
    for j in range(max_force.shape[0]):
        if np.isfinite(max_force[j]):
            return True
    return False


@numba.njit(cache=True, inline="always")
def drive_reference(h, q_ref, u, lower, upper):
    """(q_ref+, feed-forward speed) of a drive at reference q_ref, commanded speed u and
    position limits [lower, upper]: the reference advances by h u, stopped at the limits; its
    speed is u, or the reference's own speed where a limit stopped it (so a drive held at its
    limit rests at the limit, not kd u / kp past it). Scalars: the callers loop over the
    drives, and an inlined helper's array arguments are reference-counted on every pass."""
    target = q_ref + h * u
    new = min(max(target, lower), upper)
    if new == target:
        return new, u
    return new, (new - q_ref) / h


@numba.njit(cache=True, error_model="numpy")
def integrate_positions(bi, q, nu, h):
    """q + h G(q) nu, renormalising quaternions (the paper's q^{l+1} = q^l + h G nu^{l+1})."""
    out = np.empty(q.shape[0])
    _integrate_positions_into(bi, q, nu, h, out)
    return out


@numba.njit(cache=True, inline="always")
def _integrate_positions_into(bi, q, nu, h, out):
    """`integrate_positions` into the caller's out (nq)."""
    for i in range(q.shape[0]):
        out[i] = q[i]
    _integrate_translations_into(bi, q, nu, h, out)
    for b in range(bi.shape[0]):
        if bi[b, BI_QMAP + Q_QW] >= 0:
            i0, i1, i2, i3 = bi[b, BI_QMAP + Q_QW], bi[b, BI_QMAP + Q_QW + 1], bi[b, BI_QMAP + Q_QW + 2], bi[b, BI_QMAP + Q_QW + 3]
            b0, b1, b2, b3 = q[i0], q[i1], q[i2], q[i3]
            a0, a1, a2, a3 = 0.0, nu[bi[b, BI_VMAP + V_WX]], nu[bi[b, BI_VMAP + V_WX + 1]], nu[bi[b, BI_VMAP + V_WX + 2]]
            d0, d1, d2, d3 = quat_mul_scalars(a0, a1, a2, a3, b0, b1, b2, b3)  # quat_mul(omega, quat)
            b0 += 0.5 * h * d0
            b1 += 0.5 * h * d1
            b2 += 0.5 * h * d2
            b3 += 0.5 * h * d3
            norm = np.sqrt(0.0 + b0 * b0 + b1 * b1 + b2 * b2 + b3 * b3)
            out[i0], out[i1], out[i2], out[i3] = b0 / norm, b1 / norm, b2 / norm, b3 / norm


@numba.njit(cache=True, inline="always")
def _integrate_translations_into(bi, q, nu, h, out):
    """out = q + h nu on the translations and the planar/yaw angle (G = identity there), in the
    caller's out; its other entries (quaternions) untouched."""
    for b in range(bi.shape[0]):
        for k in range(4):
            if bi[b, BI_QMAP + k] >= 0:
                out[bi[b, BI_QMAP + k]] = q[bi[b, BI_QMAP + k]] + h * nu[bi[b, BI_VMAP + k]]


# ----------------------------------------------------------------------------- the step


@numba.njit(cache=True, inline="always")
def _column_norm(W, i):
    s = 0.0
    for r in range(W.shape[0]):
        s += W[r, i] * W[r, i]
    return np.sqrt(s)


@numba.njit(cache=True, inline="always")
def _finite_and_bounded(x):
    """Every entry of the 1-D x finite and within DIVERGENCE_LIMIT (indexed: x.ravel() made a
    new array each step)."""
    ok = True
    for i in range(x.shape[0]):
        if not (abs(x[i]) <= DIVERGENCE_LIMIT):
            ok = False
    return ok


@numba.njit(cache=True, inline="always")
def _blended(theta, nu_new, nu, blend):
    """The position update's velocity theta nu+ + (1 - theta) nu: nu_new itself at theta = 1,
    else written into blend (nv)."""
    if theta == 1.0:
        return nu_new
    for v in range(nu_new.shape[0]):
        blend[v] = theta * nu_new[v] + (1.0 - theta) * nu[v]
    return blend


@numba.njit(cache=True, inline="always")
def add_product(out, A, x, scale):
    """out += scale A x, in place, with plain loops: the per-step products are a few entries,
    where a BLAS call costs more than the arithmetic."""
    for i in range(A.shape[0]):
        acc = 0.0
        for j in range(A.shape[1]):
            acc += A[i, j] * x[j]
        out[i] += scale * acc


@numba.njit(cache=True, error_model="numpy")
def free_step(eps, theta, h, bi, Ainv, M_const, rhs_const, q, nu, q_ref, u, q_index, v_index, kp, kd, lower, upper):
    """dynamics_step without contacts and with a constant system matrix: the cheap path.

    Returns (q+, nu+, q_ref+, status: a StepStatus value); equals dynamics_step with nc = 0
    (tests check it). Not for scenes with force-limited drives (their impulses need the
    contact problem). Plain arrays, not `Drives` / `System`: this step takes about a
    microsecond, and numba reference-counts every array of a tuple argument on each call
    (measured: whole tuples on the per-step calls made the paper scene's rungs up to 45% slower).
    The rollout takes it in `free_step_into`, on its own arrays.
    """
    nv = rhs_const.shape[0]
    rhs, blend, q_new, nu_new, q_ref_new = np.empty(nv), np.empty(nv), np.empty_like(q), np.empty(nv), q_ref.copy()
    args = (q_index, v_index, kp, kd, lower, upper, rhs, blend, q_new, nu_new, q_ref_new)
    if free_step_into(eps, theta, h, bi, Ainv, M_const, rhs_const, q, nu, q_ref, u, *args):
        return q_new, nu_new, q_ref_new, StepStatus.OK.value
    status = StepStatus.DIVERGED.value
    if not (np.all(np.isfinite(q_new)) and np.all(np.isfinite(nu_new))):
        status = StepStatus.NON_FINITE.value
    return q, nu, q_ref, status


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def free_step_into(
    eps, theta, h, bi, Ainv, M_const, rhs_const, q, nu, q_ref, u, q_index, v_index, kp, kd, lower, upper, rhs, blend, q_new, nu_new, q_ref_new  # noqa: E501
):  # fmt: skip
    """`free_step` into the caller's arrays (rhs, blend: scratch of nv; q_new, nu_new,
    q_ref_new: q+, nu+, q_ref+), compiled without numba's runtime (as `planar_warm_step`: no
    reference counts, no allocation). Returns whether q+ and nu+ are finite and bounded (else
    the caller takes `free_step` for the status). A constant A has no spatial rotation (its
    quaternions come with angular velocities), so the position update is
    `_integrate_translations_into`."""
    for i in range(rhs.shape[0]):
        rhs[i] = rhs_const[i]
    if eps != 0.0:  # dynamic: the momentum term
        add_product(rhs, M_const, nu, eps)
    for j in range(q_ref.shape[0]):
        q_ref_new[j] = q_ref[j]
    for j in range(v_index.shape[0]):
        q_ref_new[j], ff = drive_reference(h, q_ref[j], u[j], lower[j], upper[j])
        rhs[v_index[j]] += _drive_impulse(h, theta, kp[j], kd[j], q_ref[j], q_ref_new[j], q[q_index[j]], nu[v_index[j]], ff)
    for v in range(nu_new.shape[0]):
        nu_new[v] = 0.0
    add_product(nu_new, Ainv, rhs, 1.0)
    velocity = _blended(theta, nu_new, nu, blend)
    for i in range(q.shape[0]):
        q_new[i] = q[i]
    _integrate_translations_into(bi, q, velocity, h, q_new)
    return _finite_and_bounded(q_new) and _finite_and_bounded(nu_new)


@numba.njit(cache=True, error_model="numpy")
def dynamics_step(model, solver, drives, tables, system, h, q, nu, q_ref, delta_n, delta_t, u, contacts, nc, warm_n, warm_t, basis):
    """One step of eq. (3) given the contacts at q. Pure: returns a new StepResult.

    model, solver, drives: `Model`, `Solver`, `Drives`; tables: `SceneTables`; system: the
    `System` at q; contacts: a `models.contact.ContactSet` whose first nc entries are the
    contacts at q (bias: zeros without scripted obstacles); warm_n (slots,), warm_t (slots,
    2): PGS warm start by contact slot (the previous step's p_n, p_t; zeros for a cold start;
    Lemke ignores them); basis: Lemke's warm start, the previous step's `StepResult.basis`
    (a `basis_table` of the contact buffers' slots, the drives and the friction directions;
    all zeros, as `basis_table` makes it: Lemke starts cold; required, since a default of None
    would compile this whole step a second time). The result's basis is this step's (the
    input's where no LCP was solved). A force-limited drive's impulse is solved with the contacts, by
    Lemke. On the PGS path residual is `models.contact_pgs`'s and lcp_size the number of
    scalar impulses; where auto falls back to Lemke, sweeps still counts PGS's.

    The step's once-a-step links (`_lemke_step`, `_pgs_step`, `_free_velocity`, `_contact_solve`)
    are inlined: a call reference-counts each of the ~30 arrays it is passed, a fifth to a third
    of a contact step when profiled (docs/measurements.md). This step, by the rollout too (its
    general path: a contact episode's first step, a changed basis), and the LCP's builds
    (`contact_lcp`, `_planar_lcp`) are called: inlined, they were compiled anew at each site,
    minutes of a first run's compile, where their calls cost no time the rollouts show.
    """
    sweeps = 0
    if _uses_pgs(model, solver, nc, any_limited(drives.max_force)):
        out = _pgs_step(model, solver, drives, tables, system, h, q, nu, q_ref, delta_n, delta_t, u, contacts, nc, warm_n, warm_t, basis)
        if out.status == StepStatus.OK or solver.method == SOLVER_PGS or model.exact_cone:
            return out  # (no LCP of the exact cone to fall back on)
        sweeps = out.sweeps  # auto falls back on Lemke; the result counts PGS's sweeps
    # one call site: numba compiles an inlined function anew at each (two doubled the step's
    # compile time)
    return _lemke_step(model, drives, tables, system, h, q, nu, q_ref, delta_n, delta_t, u, contacts, nc, basis, sweeps)


@numba.njit(cache=True, inline="always")
def _pgs_tolerance(model, solver):
    """PGS's relative tolerance in a step: a passive body's velocity error is its impulse error
    over eps m, so the solver's tolerance is tightened by eps, and quasistatic rungs (eps -> 0)
    get velocities as accurate as dynamic ones."""
    eps = model.quasistatic_inertia if model.eps == 0.0 else model.eps
    return solver.tolerance * min(eps, 1.0)


@numba.njit(cache=True, inline="always")
def _may_take_planar_warm(planar, constant_A, limited, model, solver, nc):
    """Whether a step with nc contacts may go to `planar_warm_step` (planar: the scene's
    dimension is 2): A constant, no force-limited drive, not kinematic, a Lemke step."""
    return planar and constant_A and not limited and not model.kinematic and not _uses_pgs(model, solver, nc, limited)


@numba.njit(cache=True, inline="always")
def _may_take_spatial_warm(spatial, limited, model, solver, nc):
    """Whether a step with nc contacts may go to `spatial_warm_step` (spatial: the scene's
    dimension is 3): no force-limited drive, not kinematic, a Lemke step with contacts."""
    return spatial and nc > 0 and not limited and not model.kinematic and not _uses_pgs(model, solver, nc, limited)


@numba.njit(cache=True, inline="always")
def _may_take_pgs_warm(limited, model, solver, nc):
    """Whether a step with nc contacts may go to `pgs_warm_step` (in the plane or in space): not
    kinematic, a PGS step (`_uses_pgs`)."""
    return not model.kinematic and _uses_pgs(model, solver, nc, limited)


@numba.njit(cache=True, inline="always")
def _uses_pgs(model, solver, nc, limited):
    """Whether a step with nc contacts (limited: force-limited drives, whose box rows only the
    LCP has) solves them by PGS (`contact_pgs`), not the LCP by Lemke."""
    use_pgs = model.exact_cone or solver.method == SOLVER_PGS or (solver.method == SOLVER_AUTO and nc >= solver.auto_contacts)
    return nc > 0 and use_pgs and not limited


#: Parts of a dynamics step `contact_stage` and `planar_warm_step` run (`ladder bench`'s cost
#: split); PART_STEP: all of it.
PART_ASSEMBLY, PART_CONTACT_SOLVE, PART_STEP = 0, 1, 2


@numba.njit(cache=True, error_model="numpy")
def contact_stage(part, model, solver, drives, tables, system, h, q, nu, q_ref, delta_n, delta_t, u, contacts, nc, warm_n, warm_t, basis):
    """The first part of `dynamics_step`, for the cost split: PART_ASSEMBLY the free velocity
    (A's blocks, nu_free) and, on the Lemke path, the contact LCP built, scaled and its warm
    start guessed (PGS assembles its blocks in its solve); PART_CONTACT_SOLVE that and the
    contact problem solved (Lemke from the guess, or PGS from warm_n, warm_t). What is left of
    the step is the impulses' velocity update, the deformations and the integration. Returns
    the contact problem's size (0 where PART_CONTACT_SOLVE failed)."""
    dofs, count, inv, ok = _blocks(tables.bi, system)
    if not ok:
        return 0
    nu_free, q_ref_new, drive_a = _free_velocity(model, drives, tables, system, h, q, nu, q_ref, u, dofs, count, inv)
    if _uses_pgs(model, solver, nc, any_limited(drives.max_force)):
        if part == PART_ASSEMBLY:
            return nc
        tolerance = _pgs_tolerance(model, solver)
        r = contact_pgs(
            model,
            tables.spatial,
            h,
            tables.pi,
            tables.pf,
            contacts,
            nc,
            delta_n,
            delta_t,
            dofs,
            count,
            inv,
            nu_free,
            warm_n,
            warm_t,
            ZERO_COLUMN,
            tolerance,
            solver.max_sweeps,
        )
        return r.unknowns if r.status == PgsStatus.CONVERGED else 0
    active = _active_contacts(contacts.W_n, nc)
    spatial = tables.spatial
    if _planar_case(spatial, drives.max_force, active, contacts.pair, tables.pf, contacts.W_t):  # (as _contact_solve)
        Mlcp, qlcp, Y, gen, cf, fric, nf, lim, G, B = _planar_lcp(
            model, h, dofs, count, inv, nu_free, active, tables.pi, tables.pf, contacts, delta_n, delta_t
        )
    else:
        Mlcp, qlcp, Y, gen, cf, fric, nf, lim, G, B = contact_lcp(
            model, spatial, h, dofs, count, inv, nu_free, active, tables.pi, tables.pf, contacts, delta_n, delta_t, drives, drive_a
        )
    d = model.friction_directions if spatial else 2
    nc = active.shape[0]
    m = nc + nf * d + lim.shape[0]
    n = qlcp.shape[0]
    on_generators = _on_generators(spatial, lim.shape[0])  # (as _contact_solve)
    comp, gs, gmu = np.empty(nc), np.empty(nf), np.empty(nf)
    reg, scale = _scale_contact_lcp(
        model, on_generators, h, Mlcp, qlcp, Y, B, gen, cf, active, fric, nf, tables.pf, contacts.pair, m, comp, gs, gmu
    )
    guess = _basis_guess(basis, active, contacts.slot, fric, nf, d, lim, m, n, qlcp)
    if part == PART_ASSEMBLY:
        return n
    if on_generators:
        status = _guess_or_lemke(Y, B, gen, cf, model.compliant, nc, d, m, fric, nf, reg, comp, gs, gmu, Mlcp, qlcp, scale, guess)[2]
    else:
        status = lemke_warm_kernel(Mlcp, qlcp, DEFAULT_LEMKE_PIVOTS_PER_VARIABLE * (n + 1), guess, WARM_TOLERANCE, nc)[2]
    return n if status == STATUS_SOLVED or status == STATUS_SOLVED_INACCURATE else 0


@numba.njit(cache=True, inline="always")
def _drives_into(h, theta, q, nu, q_ref, u, drives, rhs, q_ref_new, a):
    """Advance the drive references (stopped at their limits) into q_ref_new and add the PD terms
    of the unlimited drives to rhs. A force-limited drive j instead gets -h max_force[j] (its
    impulse enters the contact problem shifted to be >= 0) and its PD impulse at nu = 0 in a[j]
    (a: one entry per drive, as q_ref_new)."""
    q_index, v_index, kp, kd, max_force = drives.q_index, drives.v_index, drives.kp, drives.kd, drives.max_force
    lower, upper = drives.lower, drives.upper  # hoisted: a tuple's array read in the loop is counted per pass
    for j in range(v_index.shape[0]):
        q_ref_new[j], ff = drive_reference(h, q_ref[j], u[j], lower[j], upper[j])
        pd = _drive_impulse(h, theta, kp[j], kd[j], q_ref[j], q_ref_new[j], q[q_index[j]], nu[v_index[j]], ff)
        a[j] = 0.0
        if np.isfinite(max_force[j]):
            a[j] = pd
            rhs[v_index[j]] -= h * max_force[j]
        else:
            rhs[v_index[j]] += pd


@numba.njit(cache=True, inline="always")
def _deformations(h, pf, c_pair, c_slot, active, p_n, p_t, delta_n, delta_t):
    """Compliant contact: delta+ = (p + C delta) / (h K + C) per active contact k (p_n[k], p_t[k])."""
    delta_n_new = np.empty_like(delta_n)
    delta_t_new = np.empty_like(delta_t)
    _deformations_into(h, pf, c_pair, c_slot, active, p_n, p_t, delta_n, delta_t, delta_n_new, delta_t_new)
    return delta_n_new, delta_t_new


@numba.njit(cache=True, inline="always")
def _deformations_into(h, pf, c_pair, c_slot, active, p_n, p_t, delta_n, delta_t, delta_n_new, delta_t_new):
    """`_deformations` into the caller's arrays (shaped as delta_n, delta_t; zeros where no
    contact is active)."""
    for s in range(delta_n_new.shape[0]):
        delta_n_new[s] = 0.0
    for s in range(delta_t_new.shape[0]):
        for c in range(delta_t_new.shape[1]):
            delta_t_new[s, c] = 0.0
    for k in range(active.shape[0]):
        i = active[k]
        K, C = pf[c_pair[i], PF_K], pf[c_pair[i], PF_C]
        slot = c_slot[i]
        delta_n_new[slot] = (p_n[k] + C * delta_n[slot]) / (h * K + C)
        for c in range(2):
            delta_t_new[slot, c] = (p_t[k, c] + C * delta_t[slot, c]) / (h * K + C)


@numba.njit(cache=True, inline="always")
def _integrate_checked(bi, theta, h, q, nu, nu_new):
    """(q+, status): the position update, DIVERGED / NON_FINITE if it left the finite range."""
    if theta == 1.0:
        q_new = integrate_positions(bi, q, nu_new, h)
    else:
        q_new = integrate_positions(bi, q, theta * nu_new + (1.0 - theta) * nu, h)
    if not (_finite_and_bounded(q_new) and _finite_and_bounded(nu_new)):
        if not (np.all(np.isfinite(q_new)) and np.all(np.isfinite(nu_new))):
            return q_new, StepStatus.NON_FINITE.value
        return q_new, StepStatus.DIVERGED.value
    return q_new, StepStatus.OK.value


@numba.njit(cache=True, inline="always")
def _free_velocity(model, drives, tables, system, h, q, nu, q_ref, u, dofs, count, inv):
    """Stage assemble, without contacts: (nu_free = A^-1 rhs, q_ref+, a: the force-limited
    drives' PD impulses at nu = 0, see `_drives_into`); A^-1 from system.Ainv when A is constant,
    else from its body blocks (dofs, count, inv: `models.contact_pgs.body_blocks`)."""
    nv = nu.shape[0]
    if _constant_plane(model, tables.spatial, system, nv):
        nu_free, q_ref_new, drive_a = np.empty(nv), np.empty(q_ref.shape[0]), np.empty(q_ref.shape[0])
        _free_velocity_into(model, drives, system, h, q, nu, q_ref, u, np.empty(nv), nu_free, q_ref_new, drive_a)
        return nu_free, q_ref_new, drive_a
    return _free_velocity_by_body(model, drives, tables, system, True, h, q, nu, q_ref, u, dofs, count, inv)


@numba.njit(cache=True, inline="always")
def _free_velocity_by_body(model, drives, tables, system, held, h, q, nu, q_ref, u, dofs, count, inv):
    """`_free_velocity_by_body_into` on new arrays: returns (nu_free, q_ref+, a)."""
    nv, nd = nu.shape[0], q_ref.shape[0]
    nu_free, q_ref_new, drive_a = np.empty(nv), np.empty(nd), np.empty(nd)
    _free_velocity_by_body_into(
        model, drives, tables.bi, tables.bf, tables.spatial, system, held, h, q, nu, q_ref, u, dofs, count, inv, np.empty(nv), nu_free,
        q_ref_new, drive_a, np.empty(nv), np.empty(nv), np.empty((3, 3)), np.empty((3, 3)),
    )  # fmt: skip
    return nu_free, q_ref_new, drive_a


@numba.njit(cache=True, inline="always")
def _constant_plane(model, spatial, system, nv):
    """Whether `_free_velocity_into` serves the step: a planar scene whose A and (for a dynamic
    rung) M are constant and held by the System."""
    return not spatial and system.Ainv.shape[0] == nv and (model.eps == 0.0 or system.M_const.shape[0] == nv)


@numba.njit(cache=True, inline="always")
def _free_velocity_into(model, drives, system, h, q, nu, q_ref, u, rhs, nu_free, q_ref_new, a):
    """`_free_velocity` where `_constant_plane` holds, on the caller's arrays: rhs (scratch) and
    nu_free (nv each), q_ref_new and a (one entry per drive)."""
    nv = nu.shape[0]
    rhs_const = system.rhs_const
    for v in range(nv):
        rhs[v] = rhs_const[v]
    if model.eps != 0.0:
        add_product(rhs, system.M_const, nu, model.eps)
    _drives_into(h, model.theta, q, nu, q_ref, u, drives, rhs, q_ref_new, a)
    for v in range(nv):
        nu_free[v] = 0.0
    add_product(nu_free, system.Ainv, rhs, 1.0)


@numba.njit(cache=True, inline="always")
def _active_contacts(W_n, nc):
    """The contacts that couple to a free DOF (W_n column above ZERO_COLUMN)."""
    active = np.empty(nc, np.int64)
    return active[: _active_into(W_n, nc, active)]


@numba.njit(cache=True, inline="always")
def _active_into(W_n, nc, active):
    """`_active_contacts` into the caller's active (at least nc entries): returns their count."""
    n_act = 0
    for i in range(nc):
        if _column_norm(W_n, i) > ZERO_COLUMN:
            active[n_act] = i
            n_act += 1
    return n_act


@numba.njit(cache=True, inline="always")
def _lemke_step(model, drives, tables, system, h, q, nu, q_ref, delta_n, delta_t, u, contacts, nc, basis, sweeps):
    """dynamics_step with the dense LCP solved by Lemke (see `_contact_solve`); sweeps: PGS's,
    where auto fell back on Lemke (else 0), as the result's."""
    # A is block diagonal by body: its blocks' inverses serve the free velocity (when A changes
    # with q) and the Delassus matrix (`_delassus_into`)
    dofs, count, inv, ok = _blocks(tables.bi, system)
    if not ok:
        return StepResult(
            q, nu, q_ref, delta_n, delta_t, StepStatus.SINGULAR.value, 0, 0.0, 0, np.zeros(nc), np.zeros((nc, 2)), sweeps, basis
        )
    nu_free, q_ref_new, drive_a = _free_velocity(model, drives, tables, system, h, q, nu, q_ref, u, dofs, count, inv)
    nu_new = nu_free
    delta_n_new = delta_n  # rigid models keep them zero; compliant ones get new arrays below
    delta_t_new = delta_t
    status = StepStatus.OK.value
    pivots = 0
    residual = 0.0
    size = 0
    impulses = np.zeros(nc)
    frictions = np.zeros((nc, 2))
    basis_new = basis
    # contacts that couple to a free DOF; friction only where mu > 0 and the tangent couples
    active = _active_contacts(contacts.W_n, nc)
    n_act = active.shape[0]
    if n_act > 0 or any_limited(drives.max_force):
        nu_new, p_n, p_t, status, pivots, residual, size, basis_new = _contact_solve(
            model,
            tables.spatial,
            h,
            dofs,
            count,
            inv,
            nu_free,
            active,
            tables.pi,
            tables.pf,
            contacts,
            delta_n,
            delta_t,
            drives,
            drive_a,
            basis,
        )
        _by_contact_into(nc, active, p_n, p_t, impulses, frictions)
        if status == StepStatus.OK and model.compliant:
            delta_n_new, delta_t_new = _deformations(h, tables.pf, contacts.pair, contacts.slot, active, p_n, p_t, delta_n, delta_t)
    elif model.compliant:  # no contact problem: every deformation relaxes to zero
        delta_n_new = np.zeros_like(delta_n)
        delta_t_new = np.zeros_like(delta_t)
    if status != StepStatus.OK:
        return StepResult(q, nu, q_ref, delta_n, delta_t, status, pivots, residual, size, impulses, frictions, sweeps, basis)
    q_new, bad = _integrate_checked(tables.bi, model.theta, h, q, nu, nu_new)
    if bad != StepStatus.OK:
        return StepResult(q, nu, q_ref, delta_n, delta_t, bad, pivots, residual, size, impulses, frictions, sweeps, basis)
    return StepResult(
        q_new, nu_new, q_ref_new, delta_n_new, delta_t_new, status, pivots, residual, size, impulses, frictions, sweeps, basis_new
    )


@numba.njit(cache=True, inline="always")
def _pgs_step(model, solver, drives, tables, system, h, q, nu, q_ref, delta_n, delta_t, u, contacts, nc, warm_n, warm_t, basis):
    """dynamics_step with PGS on the contact impulses; every product body by body, so the
    step costs O(bodies + contacts) beyond what the caller built (`models.contact_pgs`)."""
    bi = tables.bi
    dofs, count, inv, ok = _blocks(bi, system)
    if not ok:
        return StepResult(q, nu, q_ref, delta_n, delta_t, StepStatus.SINGULAR.value, 0, 0.0, 0, np.zeros(nc), np.zeros((nc, 2)), 0, basis)
    nu_free, q_ref_new, _ = _free_velocity_by_body(model, drives, tables, system, False, h, q, nu, q_ref, u, dofs, count, inv)
    tolerance = _pgs_tolerance(model, solver)
    r = contact_pgs(
        model,
        tables.spatial,
        h,
        tables.pi,
        tables.pf,
        contacts,
        nc,
        delta_n,
        delta_t,
        dofs,
        count,
        inv,
        nu_free,
        warm_n,
        warm_t,
        ZERO_COLUMN,
        tolerance,
        solver.max_sweeps,
    )
    if r.status != PgsStatus.CONVERGED:
        bad = StepStatus.CONTACT_NOT_CONVERGED.value if r.status == PgsStatus.NOT_CONVERGED else StepStatus.NON_FINITE.value
        return StepResult(q, nu, q_ref, delta_n, delta_t, bad, r.pivots, r.residual, r.unknowns, r.p_n, r.p_t, r.sweeps, basis)
    delta_n_new, delta_t_new = delta_n, delta_t
    if model.compliant:
        active = r.active
        n_act = active.shape[0]
        pa = np.empty(n_act)
        ta = np.empty((n_act, 2))
        for k in range(n_act):
            pa[k] = r.p_n[active[k]]
            ta[k, 0], ta[k, 1] = r.p_t[active[k], 0], r.p_t[active[k], 1]
        delta_n_new, delta_t_new = _deformations(h, tables.pf, contacts.pair, contacts.slot, active, pa, ta, delta_n, delta_t)
    q_new, bad = _integrate_checked(bi, model.theta, h, q, nu, r.nu)
    if bad != StepStatus.OK:
        return StepResult(q, nu, q_ref, delta_n, delta_t, bad, r.pivots, r.residual, r.unknowns, r.p_n, r.p_t, r.sweeps, basis)
    return StepResult(
        q_new,
        r.nu,
        q_ref_new,
        delta_n_new,
        delta_t_new,
        StepStatus.OK.value,
        r.pivots,
        r.residual,
        r.unknowns,
        r.p_n,
        r.p_t,
        r.sweeps,
        basis,
    )


# called, not inlined (as `_planar_lcp`): numba compiles an inlined function anew at each call
# site, and the step's compile grows about as its size squared; once a general step, its call's
# reference counts are not seen beside the build
@numba.njit(cache=True, error_model="numpy")
def contact_lcp(model, spatial, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, drives, drive_a):
    """Assemble the contact LCP of the active contacts and the force-limited drives.

    Unknowns z = (p_n (nc), beta (nf * d), x (nl), gamma (nf), s (nl)); with J = [W_n | D | E]
    the top-left block of M is J^T A^-1 J. It is assembled over the DOFs contacts touch: J = B C,
    B the generators (the Jacobian columns of each contact's n, t, o and the drives' unit DOFs,
    `_generators_into`), C how each LCP column combines them (a friction direction is cos t + sin o),
    and the Delassus matrix G = B^T A^-1 B from A's body blocks (dofs, count, inv:
    `models.contact_pgs.body_blocks`), so M = C^T G C costs O(contacts^2), not O(nv contacts^2).

    Returns (M, q, Y = A^-1 B, gen, cf: LCP column r < m is cf[0, r] B[:, gen[0, r]] +
    cf[1, r] B[:, gen[1, r]] (`_combinations_into`), fric, nf, lim: the indices of the nl
    force-limited drives, G, B = (ldof, nloc, Bl): the generators on the DOFs they touch,
    `_generators_into`).

    A force-limited drive j (limit F, P = h F) is a bounded impulse p = x - P, x in [0, 2P]:
    unbounded it would be a - b v (a: its PD impulse at v = 0, `_drives_into`; b = h (h kp + kd); v
    its DOF's new speed), so its row says r = v + (p - a) / b, with r >= 0 at p = -P, r <= 0 at
    p = P and r = 0 between: the box split 0 <= x _|_ r + s >= 0, 0 <= s _|_ 2P - x >= 0.
    nu_free has the -P shift in it already (`_drives_into`); E's columns are the drives' unit DOFs.
    """
    nc = active.shape[0]
    lim = np.empty(drives.max_force.shape[0], np.int64)
    nl = _limited_into(drives.max_force, lim)
    fric = np.empty(nc, np.int64)
    nf = _friction_into(spatial, active, contacts.pair, pf, contacts.W_t, contacts.W_o, fric)
    d = model.friction_directions if spatial else 2
    ng = nc + (2 if spatial else 1) * nf + nl
    m = nc + nf * d + nl
    n = m + nf + nl
    Mlcp, qlcp, Y, gen, cf = np.empty((n, n)), np.empty(n), np.empty((nu_free.shape[0], ng)), np.empty((2, m), np.int64), np.empty((2, m))
    body, ldof, nloc = np.empty((ng, 2), np.int64), np.empty((ng, LOCAL_DOFS), np.int64), np.empty(ng, np.int64)
    Bl = np.empty((ng, LOCAL_DOFS))
    G, p, Bt_nu, Jt_nu = np.empty((ng, ng)), np.empty(ng), np.empty(ng), np.empty(m)
    scratch = (body, ldof, nloc, Bl, G, p, Bt_nu, Jt_nu, np.empty((ng, BODY_DOFS)), np.empty((ng, BODY_DOFS)), np.empty(ng, np.int64))
    dirs = np.empty((2, d if spatial else 0))
    cone_directions_into(dirs[0], dirs[1])
    contact_lcp_into(
        model, spatial, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, drives, drive_a, lim, nl, fric, nf,
        scratch, Mlcp, qlcp, Y, gen, cf, dirs,
    )  # fmt: skip
    return Mlcp, qlcp, Y, gen, cf, fric, nf, lim[:nl], G, (ldof, nloc, Bl)


@numba.njit(cache=True, inline="always")
def contact_lcp_into(
    model, spatial, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, drives, drive_a, lim, nl, fric, nf,
    scratch, Mlcp, qlcp, Y, gen, cf, dirs,
):  # fmt: skip
    """`contact_lcp` on the caller's arrays, given the force-limited drives (lim, nl:
    `_limited_into`) and the friction contacts (fric, nf: `_friction_into`), each array shaped
    exactly (ng = nc + nf (2 in space, else 1) + nl generators, m = nc + d nf + nl, n = m + nf +
    nl): the scratch (body (ng, 2), ldof (ng, LOCAL_DOFS), nloc (ng,), Bl (ng, LOCAL_DOFS), G
    (ng, ng), p, Bt_nu (ng each), Jt_nu (m), `_delassus_into`'s Bb, Yb (ng, BODY_DOFS) and gl
    (ng,); a tuple: an inlined function takes at most 30 arguments), and the LCP's M (n, n), q
    (n), Y (nv, ng), gen and cf (2, m), all set here; dirs: the cone's directions in space
    (`_combinations_into`)."""
    lcp_generators_into(
        model, spatial, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, drives, lim, nl, fric, nf, scratch, qlcp,
        Y, gen, cf, dirs, True,
    )  # fmt: skip
    reg = _regularization(Y, scratch[1], scratch[2], scratch[3], gen, cf, active.shape[0], model.compliant, model.regularization)
    lcp_matrix_into(model, spatial, h, active, pf, contacts.pair, drives, drive_a, lim, nl, fric, nf, reg, scratch, Mlcp, qlcp, gen, cf)


@numba.njit(cache=True, inline="always")
def lcp_generators_into(
    model, spatial, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, drives, lim, nl, fric, nf, scratch, qlcp, Y,
    gen, cf, dirs, gram,
):  # fmt: skip
    """The first part of `contact_lcp_into`, all the LCP but M: the generators (`_generators_into`),
    Y and, where gram, G (`_delassus_into`, G in scratch[4]), C (gen, cf) and q (the normal and
    friction rows'; the drives' rows are M's part, `lcp_matrix_into`), unscaled. On these alone
    (Y, not G) the previous basis's guess is tried (`_generator_guess_into`): G and M are built
    only where it fails. dirs: the cone's directions in space (`_combinations_into`)."""
    body, ldof, nloc, Bl, G, p, Bt_nu, Jt_nu, Bb, Yb, gl = scratch
    compliant = model.compliant
    c_pair, c_psi, c_slot, c_bias = contacts.pair, contacts.psi, contacts.slot, contacts.bias
    W_n, W_t, W_o = contacts.W_n, contacts.W_t, contacts.W_o
    nc = active.shape[0]
    d = model.friction_directions if spatial else 2
    nd = nf * d
    m = nc + nd + nl
    _generators_into(spatial, active, fric, nf, lim, nl, drives.v_index, pi, c_pair, W_n, W_t, W_o, dofs, count, body, ldof, nloc, Bl)
    _delassus_into(body, ldof, nloc, Bl, dofs, count, inv, Y, G, Bb, Yb, gl, gram)
    _combinations_into(spatial, d, nc, fric, nf, nl, gen, cf, dirs)
    n = m + nf + nl
    for r in range(n):
        qlcp[r] = 0.0
    for g in range(nloc.shape[0]):  # B^T nu_free, over each generator's local DOFs
        s0 = 0.0
        for a in range(nloc[g]):
            s0 += Bl[g, a] * nu_free[ldof[g, a]]
        Bt_nu[g] = s0
    for r in range(m):  # J^T nu_free = C^T (B^T nu_free)
        Jt_nu[r] = cf[0, r] * Bt_nu[gen[0, r]] + cf[1, r] * Bt_nu[gen[1, r]]
    _normal_q(qlcp, compliant, h, active, pf, c_pair, c_psi, c_slot, c_bias, Jt_nu, delta_n)
    _friction_q(qlcp, compliant, h, d, active, fric, nf, cf, pf, c_pair, c_slot, c_bias, Jt_nu, delta_t)


@numba.njit(cache=True, inline="always")
def lcp_matrix_into(model, spatial, h, active, pf, c_pair, drives, drive_a, lim, nl, fric, nf, reg, scratch, Mlcp, qlcp, gen, cf):
    """The second part of `contact_lcp_into`, after `lcp_generators_into`: M (unscaled), and the
    force-limited drives' rows of M and q. reg: `_regularization`."""
    G, p, Jt_nu = scratch[4], scratch[5], scratch[7]
    nc = active.shape[0]
    d = model.friction_directions if spatial else 2
    nd = nf * d
    m = nc + nd + nl
    n = m + nf + nl
    for r in range(n):
        for c in range(n):
            Mlcp[r, c] = 0.0
    _fill_jacobian_block(Mlcp, G, gen, cf, spatial, d, nc, nf, nl, p)
    _normal_diagonal(Mlcp, model.compliant, h, active, pf, c_pair, reg)
    _friction_matrix(Mlcp, model.compliant, h, d, m, active, fric, nf, cf, pf, c_pair)
    _scale_gamma(Mlcp, d, m, nc, nf)
    _drive_rows(Mlcp, qlcp, h, drive_step(model, h), nc + nd, m + nf, lim, nl, drives.kp, drives.kd, drives.max_force, drive_a, Jt_nu)


@numba.njit(cache=True, inline="always")
def _limited_into(max_force, lim):
    """The force-limited drives (finite max_force) into the caller's lim (one entry per drive):
    their indices, first. Returns their count."""
    nl = 0
    for j in range(max_force.shape[0]):
        if np.isfinite(max_force[j]):
            lim[nl] = j
            nl += 1
    return nl


@numba.njit(cache=True, inline="always")
def _friction_into(spatial, active, c_pair, pf, W_t, W_o, fric):
    """The active contacts (positions k in active) with friction rows: mu > 0 and a tangent
    Jacobian column that couples to a free DOF, into the caller's fric (at least nc entries).
    Returns their count nf."""
    nc = active.shape[0]
    nf = 0
    for k in range(nc):
        i = active[k]
        couples = _column_norm(W_t, i) > ZERO_COLUMN
        if spatial and _column_norm(W_o, i) > ZERO_COLUMN:
            couples = True
        if pf[c_pair[i], PF_MU] > 0.0 and couples:
            fric[nf] = k
            nf += 1
    return nf


#: Local DOFs of a generator (`_generators_into`): the DOFs of the (at most two) bodies it touches.
LOCAL_DOFS = 2 * BODY_DOFS


@numba.njit(cache=True, inline="always")
def _generators_into(spatial, active, fric, nf, lim, nl, v_index, pi, c_pair, W_n, W_t, W_o, dofs, count, body, ldof, nloc, Bl):
    """The columns B that the LCP's J = B C combines, gathered on the DOFs they touch: each
    active contact's normal (generator k), each friction contact's t (nc + f) and, in space, o
    (nc + nf + f), each force-limited drive's unit DOF (last). Into the caller's arrays, shaped
    for the ng generators and set here: body (ng, 2): the bodies with DOFs each touches, -1
    padded; ldof (ng, LOCAL_DOFS): those bodies' DOFs, body by body; nloc (ng,): how many; Bl
    (ng, LOCAL_DOFS): the column's entries there (ldof and Bl set only on each row's first
    nloc entries, all that is read)."""
    nc = active.shape[0]
    nt = 2 if spatial else 1
    # each contact's normal (g < nc), then its friction generators t and o (the gather written
    # out here: a helper's array arguments would be reference-counted per generator)
    for g in range(nc + nt * nf):
        if g < nc:
            k, src = g, W_n
            body[k, 0], body[k, 1] = -1, -1
            s = 0
            for side in range(2):
                b = pi[c_pair[active[k]], side]
                if count[b] > 0:
                    body[k, s] = b
                    s += 1
        else:  # (g - nc) % nf without a division a generator
            f = g - nc if g < nc + nf else g - nc - nf
            k, src = fric[f], W_t if g < nc + nf else W_o
            body[g, 0], body[g, 1] = body[k, 0], body[k, 1]
        i = active[k]
        a = 0
        for s in range(2):
            b = body[g, s]
            if b < 0:
                continue
            for r in range(count[b]):
                v = dofs[b, r]
                ldof[g, a] = v
                Bl[g, a] = src[v, i]
                a += 1
        nloc[g] = a
    for e in range(nl):
        g = nc + nt * nf + e
        body[g, 0], body[g, 1], nloc[g] = -1, -1, 0
        v = v_index[lim[e]]
        for b in range(count.shape[0]):
            for r in range(count[b]):
                if dofs[b, r] == v:
                    body[g, 0] = b
        b = body[g, 0]
        if b >= 0:
            nloc[g] = count[b]
            for r in range(count[b]):
                ldof[g, r] = dofs[b, r]
                Bl[g, r] = 1.0 if dofs[b, r] == v else 0.0


@numba.njit(cache=True, inline="always")
def _delassus_into(body, ldof, nloc, Bl, dofs, count, inv, Y, G, Bb, Yb, gl, gram):
    """(Y = A^-1 B (nv, ng), G = B^T A^-1 B (ng, ng)) into the caller's Y and G, set here (G
    only where gram: the guess on the generators needs Y alone, `_generator_guess_into`), over
    the DOFs of the bodies each generator touches: A is block diagonal by body (inv: its blocks'
    inverses), so Y[:, g] lives on g's bodies and G[g1, g2] is zero unless g1 and g2 share one.
    G is symmetric: its upper triangle is mirrored.

    Body by body: the generators touching it (gl) and their entries on its DOFs (Bb), their
    Y there (Yb = inv_b Bb, also into Y), and each G[g1, g2 >= g1] of generators touching it
    summed on (Bb[g1] . Yb[g2], contiguous; a body of 6 DOFs, a rigid body in space, by loops
    of fixed length). A generator on two bodies (a contact between two moving bodies) whose
    local DOFs list the later body first sums over them against Y after all bodies. The same
    sums in the same order as one gather loop over each g1's local DOFs (the zero terms of a
    body g2 does not touch aside): the same bits, 1.45 -> 1.1-1.25 us at box_push_3d's push
    (15 generators on a box). On a 6-DOF body, Yb leaves out the zero entries of a `_split`
    block and G's sums go two at a time (two independent chains of adds, each in its order):
    the same bits again, a further 2.5 -> 2.0 us there (the probe's medians in one process, a
    noisier spell than the figure before). Bb, Yb (ng, BODY_DOFS), gl (ng,): scratch."""
    ng = nloc.shape[0]
    for v in range(Y.shape[0]):
        for g in range(ng):
            Y[v, g] = 0.0
    if gram:
        for g1 in range(ng):
            for g2 in range(ng):
                G[g1, g2] = 0.0
    for b in range(count.shape[0]):
        m = count[b]
        if m == 0:
            continue
        split = m == 6 and _split(inv[b])
        k = 0
        for g in range(ng):  # the generators touching b, and their entries on b's DOFs
            if body[g, 0] == b:
                a0 = 0
            elif body[g, 1] == b:
                a0 = count[body[g, 0]]
            else:
                continue
            gl[k] = g
            for r in range(m):
                Bb[k, r] = Bl[g, a0 + r]
            _apply_block(inv, b, m, Bb, Yb, k, 0, split)  # (a split block's zero entries' terms left out)
            for r in range(m):
                Y[dofs[b, r], g] = Yb[k, r]
            k += 1
        if not gram:
            continue
        for k1 in range(k):
            g1 = gl[k1]
            if body[g1, 1] >= 0 and body[g1, 1] < body[g1, 0]:  # its sum starts on the later body: below
                continue
            k2 = k1
            if m == 6:  # two entries a pass: two independent sums, each in its own order
                while k2 + 1 < k:
                    ga, gb = gl[k2], gl[k2 + 1]
                    acc = G[g1, ga]  # (what g1's first body gave, if any)
                    acc2 = G[g1, gb]
                    for r in range(6):
                        x = Bb[k1, r]
                        acc += x * Yb[k2, r]
                        acc2 += x * Yb[k2 + 1, r]
                    G[g1, ga] = acc
                    G[g1, gb] = acc2
                    G[ga, g1] = acc
                    G[gb, g1] = acc2
                    k2 += 2
            for k3 in range(k2, k):
                acc = G[g1, gl[k3]]
                for r in range(m):
                    acc += Bb[k1, r] * Yb[k3, r]
                G[g1, gl[k3]] = acc
                G[gl[k3], g1] = acc
    if not gram:
        return
    for g1 in range(ng):
        p, r = body[g1, 0], body[g1, 1]
        if r < 0 or r > p:
            continue
        for g2 in range(g1, ng):
            if p != body[g2, 0] and p != body[g2, 1] and r != body[g2, 0] and r != body[g2, 1]:
                continue
            acc = 0.0
            for a in range(nloc[g1]):
                acc += Bl[g1, a] * Y[ldof[g1, a], g2]
            G[g1, g2] = acc
            G[g2, g1] = acc


@numba.njit(cache=True, inline="always")
def _ctg_row_into(G, gen, cf, r, p):
    """Row r (< m) of C^T G into the caller's p (ng): cf[0, r] G[gen[0, r]] + cf[1, r]
    G[gen[1, r]]."""
    a0, a1, x0, x1 = gen[0, r], gen[1, r], cf[0, r], cf[1, r]
    for g in range(G.shape[0]):
        p[g] = x0 * G[a0, g] + x1 * G[a1, g]


@numba.njit(cache=True, inline="always")
def _fill_jacobian_block(Mlcp, G, gen, cf, spatial, d, nc, nf, nl, p):
    """M[:m, :m] = C^T G C, row by row: the row p = (C^T G)[r] (ng), then each column group
    from it (a normal's generator, a friction contact's d directions from its t and o
    generators, a drive's DOF), so the inner loops are contiguous. p: scratch (ng)."""
    nt = 2 if spatial else 1
    nd = nf * d
    m = nc + nd + nl
    for r in range(m):
        _ctg_row_into(G, gen, cf, r, p)
        for k in range(nc):
            Mlcp[r, k] = p[k]
        for f in range(nf):
            pt = p[nc + f]
            po = p[nc + nf + f] if spatial else 0.0
            first = nc + f * d
            for j in range(d):
                Mlcp[r, first + j] = pt * cf[0, first + j] + po * cf[1, first + j]
        for e in range(nl):
            Mlcp[r, nc + nd + e] = p[nc + nt * nf + e]


@numba.njit(cache=True, inline="always")
def _combinations_into(spatial, d, nc, fric, nf, nl, gen, cf, dirs):
    """C of J = B C, as (gen (2, m), cf (2, m)): LCP column r < m is cf[0, r] B[:, gen[0, r]] +
    cf[1, r] B[:, gen[1, r]] (cf[1, r] = 0 for a single generator). A friction row's
    (cf[0, r], cf[1, r]) is its direction in the (t, o) basis: in space the d directions around
    the cone, dirs (2, d: `cone_directions_into`'s cosines and sines, made once by the caller),
    +t and -t in the plane (dirs unused), the same for every friction contact, into the
    caller's gen and cf (2, m each)."""
    nt = 2 if spatial else 1
    nd = nf * d
    for k in range(nc):
        gen[0, k] = gen[1, k] = k
        cf[0, k], cf[1, k] = 1.0, 0.0
    for f in range(nf):
        for j in range(d):
            r = nc + f * d + j
            if spatial:
                cf[0, r], cf[1, r] = dirs[0, j], dirs[1, j]
            else:
                cf[0, r], cf[1, r] = (1.0 if j == 0 else -1.0), 0.0
            gen[0, r] = nc + f
            gen[1, r] = nc + nf + f if spatial else nc + f
    for e in range(nl):
        r = nc + nd + e
        gen[0, r] = gen[1, r] = nc + nt * nf + e
        cf[0, r], cf[1, r] = 1.0, 0.0


@numba.njit(cache=True, inline="always")
def _compliance(h, K, C):
    """A compliant contact's term on its rows' diagonal, 1 / (h (h K + C)) (stiffness K,
    damping C, step h)."""
    return 1.0 / (h * (h * K + C))


@numba.njit(cache=True, inline="always")
def _gram_entry(Y, ldof, nloc, Bl, a, b):
    """G[a, b] (G = B^T A^-1 B, `_delassus_into`'s) from Y = A^-1 B and the generators (ldof,
    nloc, Bl: `_generators_into`) alone: B[:, lo]^T Y[:, hi] (lo, hi: a, b in order) over lo's
    local DOFs in their order, G's upper triangle's sum with the same terms in the same order
    (its other entries' products are zeros): G's entry bit for bit, where G is not built
    (`spatial_warm_step` builds it only where the guess fails)."""
    if a > b:
        a, b = b, a
    s = 0.0
    for i in range(nloc[a]):
        s += Bl[a, i] * Y[ldof[a, i], b]
    return s


@numba.njit(cache=True, inline="always")
def _normal_diagonal_entry(Y, ldof, nloc, Bl, gen, cf, k):
    """(C^T G C)[k, k] of active contact k's normal row (`_fill_jacobian_block`'s operations, on
    `_gram_entry`: M's bits)."""
    a0, a1 = gen[0, k], gen[1, k]
    g0 = _gram_entry(Y, ldof, nloc, Bl, a0, k)
    g1 = g0 if a1 == a0 else _gram_entry(Y, ldof, nloc, Bl, a1, k)
    return cf[0, k] * g0 + cf[1, k] * g1


@numba.njit(cache=True, inline="always")
def _regularization(Y, ldof, nloc, Bl, gen, cf, nc, compliant, regularization):
    """The rigid contact rows' regularization: `Model.regularization` of the largest normal
    diagonal of C^T G C (`_normal_diagonal_entry`; 0 with compliance, which regularizes them
    already)."""
    reg = 0.0
    if not compliant and regularization > 0.0:
        for k in range(nc):
            reg = max(reg, regularization * _normal_diagonal_entry(Y, ldof, nloc, Bl, gen, cf, k))
    return reg


@numba.njit(cache=True, inline="always")
def _ctg_row_on_y_into(Y, ldof, nloc, Bl, gen, cf, r, p):
    """Row r (< m) of C^T G into the caller's p (ng), from Y without G (`_ctg_row_into`'s
    values, not its bits): (cf[0, r] B[:, gen[0, r]] + cf[1, r] B[:, gen[1, r]])^T Y, each
    local DOF's entry times Y's row there, added to p (contiguous rows of ng)."""
    a0, a1, x0, x1 = gen[0, r], gen[1, r], cf[0, r], cf[1, r]
    ng = p.shape[0]
    for g in range(ng):
        p[g] = 0.0
    for i in range(nloc[a0]):
        e, v = x0 * Bl[a0, i], ldof[a0, i]
        for g in range(ng):
            p[g] += e * Y[v, g]
    if x1 != 0.0:
        for i in range(nloc[a1]):
            e, v = x1 * Bl[a1, i], ldof[a1, i]
            for g in range(ng):
                p[g] += e * Y[v, g]


@numba.njit(cache=True, inline="always")
def _normal_q(qlcp, compliant, h, active, pf, c_pair, c_psi, c_slot, c_bias, Jt_nu, delta_n):
    """Normal rows' q, in place: psi / h + W_n^T nu_free + bias and, for compliant contact, the
    previous deformation's term (`_compliance` C delta_n)."""
    for k in range(active.shape[0]):
        i = active[k]
        qlcp[k] = c_psi[i] / h + Jt_nu[k] + c_bias[i, 0]
        if compliant:
            K, C = pf[c_pair[i], PF_K], pf[c_pair[i], PF_C]
            qlcp[k] += _compliance(h, K, C) * C * delta_n[c_slot[i]]


@numba.njit(cache=True, inline="always")
def _normal_diagonal(Mlcp, compliant, h, active, pf, c_pair, reg):
    """Normal rows' diagonal, in place: reg (`_regularization`) and, for compliant contact,
    `_compliance`."""
    for k in range(active.shape[0]):
        i = active[k]
        Mlcp[k, k] += reg
        if compliant:
            Mlcp[k, k] += _compliance(h, pf[c_pair[i], PF_K], pf[c_pair[i], PF_C])


@numba.njit(cache=True, inline="always")
def _friction_q(qlcp, compliant, h, d, active, fric, nf, cf, pf, c_pair, c_slot, c_bias, Jt_nu, delta_t):
    """Friction rows' q, in place: each friction contact's d direction rows from nu_free and the
    bias and, compliant, the previous tangential deformation's term (gamma rows' q is 0)."""
    nc = active.shape[0]
    for f in range(nf):
        i = active[fric[f]]
        p = c_pair[i]
        K, C = pf[p, PF_K], pf[p, PF_C]
        slot = c_slot[i]
        for j in range(d):
            r = nc + f * d + j
            qlcp[r] = Jt_nu[r] + cf[0, r] * c_bias[i, 1] + cf[1, r] * c_bias[i, 2]
            if compliant:
                qlcp[r] -= K / (h * K + C) * (cf[0, r] * delta_t[slot, 0] + cf[1, r] * delta_t[slot, 1])


@numba.njit(cache=True, inline="always")
def _friction_matrix(Mlcp, compliant, h, d, m, active, fric, nf, cf, pf, c_pair):
    """Friction rows' part of M, in place: each friction contact's gamma row and column (mu,
    +-1), unscaled, and with compliance its friction block's `_compliance`."""
    nc = active.shape[0]
    for f in range(nf):
        k = fric[f]
        p = c_pair[active[k]]
        g = m + f
        Mlcp[g, k] = pf[p, PF_MU]
        for j in range(d):
            r = nc + f * d + j
            Mlcp[r, g] = 1.0
            Mlcp[g, r] = -1.0
            if compliant:
                comp = _compliance(h, pf[p, PF_K], pf[p, PF_C])
                for j2 in range(d):
                    r2 = nc + f * d + j2
                    Mlcp[r, r2] += comp * (cf[0, r] * cf[0, r2] + cf[1, r] * cf[1, r2])


@numba.njit(cache=True, inline="always")
def _scale_gamma(Mlcp, d, m, nc, nf):
    """Scale each friction contact's gamma row and column, in place, to the largest diagonal
    entry of its friction block.

    The sliding-speed variable gamma sits beside W-sized entries with entries mu and +-1;
    the scaling keeps complementarity (gamma is not used afterwards), as Siconos-style LCPs
    need.
    """
    n = Mlcp.shape[0]
    for f in range(nf):
        g = m + f
        scale = 0.0
        for j in range(d):
            r = nc + f * d + j
            scale = max(scale, abs(Mlcp[r, r]))
        if scale > 0.0:
            for r in range(n):
                Mlcp[r, g] *= scale
                Mlcp[g, r] *= scale


@numba.njit(cache=True, inline="always")
def _drive_rows(Mlcp, qlcp, h, hd, first_row, first_slack, lim, nl, kp, kd, max_force, drive_a, Jt_nu):
    """Box rows of the force-limited drives, in place (see `contact_lcp`): row first_row + e
    of drive lim[e] gets 1 / b on the diagonal and q = J^T nu_free - (P + a) / b; its slack s
    (row and column first_slack + e) is scaled to that diagonal, with q = 2 P times it."""
    for e in range(nl):
        j = lim[e]
        r = first_row + e
        sx = first_slack + e
        P = h * max_force[j]
        b = hd * (hd * kp[j] + kd[j])  # (hd: `drive_step`)
        Mlcp[r, r] += 1.0 / b
        qlcp[r] = Jt_nu[r] - (P + drive_a[j]) / b
        scale = abs(Mlcp[r, r])
        Mlcp[r, sx] = scale
        Mlcp[sx, r] = -scale
        qlcp[sx] = 2.0 * P * scale


@numba.njit(cache=True, error_model="numpy")  # called, not inlined (see `contact_lcp`)
def _planar_lcp(model, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t):
    """`contact_lcp` for the planar case (`_planar_case`): every active contact with friction
    rows (its normal generator k, its tangent nc + k, the directions +t and -t), no force-limited
    drive. The same LCP bit for bit (tests/test_planar_lcp.py): `_generators_into`, `_delassus_into`,
    `_fill_jacobian_block`, the rows, `_scale_gamma` and `_combinations_into` written out with their
    operations in their order, a zero coefficient's products included (they decide a zero's sign
    as there), on two flat buffers (I: ints, F: floats) instead of contact_lcp's 15 arrays (the squeeze's
    contact steps 7% faster, docs/measurements.md). Returns what contact_lcp returns; M, q, Y,
    gen, cf and G are views of F and I."""
    nc = active.shape[0]
    nv = nu_free.shape[0]
    n, m, ng = 4 * nc, 3 * nc, 2 * nc
    n_int, n_float = _planar_scratch(nc)
    I = np.empty(n_int + 2 * m + nc, np.int64)
    F = np.empty(n_float + n * n + n + nv * ng + 2 * m)
    # after the scratch: F holds M, q, Y and cf; I holds gen and fric
    fM = n_float
    fq = fM + n * n
    fY = fq + n
    fC = fY + nv * ng
    Mlcp = matrix_view(F[fM:], n, n)
    qlcp = F[fq:fY]
    Y = matrix_view(F[fY:], nv, ng)
    cf = matrix_view(F[fC:], 2, m)
    gen = matrix_view(I[n_int:], 2, m)
    fric = I[n_int + 2 * m : n_int + 2 * m + nc]
    _planar_lcp_into(model, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, I, F, Mlcp, qlcp, Y, gen, cf, fric)
    fG = ng * LOCAL_DOFS  # (`_planar_lcp_into`'s layout of F)
    return Mlcp, qlcp, Y, gen, cf, fric, nc, fric[:0], matrix_view(F[fG:], ng, ng), _planar_generators(I, F, ng)


@numba.njit(cache=True, inline="always")
def _planar_generators(I, F, ng):
    """B = (ldof, nloc, Bl) of `contact_lcp`: the ng generators on the DOFs they touch, as
    `_planar_lcp_into` leaves them in its scratch I and F (views)."""
    oL = 2 * ng
    oN = oL + ng * LOCAL_DOFS
    return matrix_view(I[oL:], ng, LOCAL_DOFS), I[oN : oN + ng], matrix_view(F, ng, LOCAL_DOFS)


@numba.njit(cache=True, inline="always")
def _planar_scratch(nc):
    """(ints, floats): the scratch `_planar_lcp_into` needs for nc active contacts."""
    ng = 2 * nc
    return ng * (2 + LOCAL_DOFS + 1), ng * (LOCAL_DOFS + ng + 2)


@numba.njit(cache=True, inline="always")
def _planar_lcp_into(model, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, I, F, M, qv, Y, gen, cf, fric):
    """`_planar_lcp` on the caller's arrays: the scratch I and F (`_planar_scratch`, or larger)
    and the LCP's M (n, n), q (n), Y (nv, ng), gen and cf (2, m), fric (nc), n = 4 nc."""
    c_pair, c_psi, c_slot, c_bias, W_n, W_t = contacts.pair, contacts.psi, contacts.slot, contacts.bias, contacts.W_n, contacts.W_t
    compliant = model.compliant
    nc = active.shape[0]
    nv = nu_free.shape[0]
    d = 2
    nf = nc
    ng = 2 * nc
    m = 3 * nc
    n = 4 * nc
    LD = LOCAL_DOFS
    # I: each generator's bodies (oB, 2 each), its local DOFs (oL, LD each) and their count
    # (oN); F: the generators' entries (fB), G (fG), a row of C^T G (fp), B^T nu_free (fS)
    oB = 0
    oL = oB + 2 * ng
    oN = oL + ng * LD
    fB = 0
    fG = fB + ng * LD
    fp = fG + ng * ng
    fS = fp + ng
    # generators (_generators_into): normal k, then its tangent nc + k
    for g in range(ng):
        k = g if g < nc else g - nc
        i = active[k]
        if g < nc:
            I[oB + 2 * g] = -1
            I[oB + 2 * g + 1] = -1
            s = 0
            for side in range(2):
                b = pi[c_pair[i], side]
                if count[b] > 0:
                    I[oB + 2 * g + s] = b
                    s += 1
        else:
            I[oB + 2 * g] = I[oB + 2 * k]
            I[oB + 2 * g + 1] = I[oB + 2 * k + 1]
        a = 0
        for s in range(2):
            b = I[oB + 2 * g + s]
            if b < 0:
                continue
            for r in range(count[b]):
                v = dofs[b, r]
                I[oL + g * LD + a] = v
                F[fB + g * LD + a] = W_n[v, i] if g < nc else W_t[v, i]
                a += 1
        I[oN + g] = a
    # Delassus matrix (_delassus_into)
    for v in range(nv):
        for g in range(ng):
            Y[v, g] = 0.0
    for g in range(ng):
        a0 = 0
        for s in range(2):
            b = I[oB + 2 * g + s]
            if b < 0:
                continue
            mm = count[b]
            for r in range(mm):
                acc = 0.0
                for c in range(mm):
                    acc += inv[b, r, c] * F[fB + g * LD + a0 + c]
                Y[dofs[b, r], g] = acc
            a0 += mm
    for x in range(ng * ng):
        F[fG + x] = 0.0
    for g1 in range(ng):
        p_, r_ = I[oB + 2 * g1], I[oB + 2 * g1 + 1]
        for g2 in range(g1, ng):
            b0, b1 = I[oB + 2 * g2], I[oB + 2 * g2 + 1]
            if p_ != b0 and p_ != b1 and (r_ < 0 or (r_ != b0 and r_ != b1)):
                continue
            acc = 0.0
            for a in range(I[oN + g1]):
                acc += F[fB + g1 * LD + a] * Y[I[oL + g1 * LD + a], g2]
            F[fG + g1 * ng + g2] = acc
            F[fG + g2 * ng + g1] = acc
    # M = C^T G C (_fill_jacobian_block; row r's generator a0 and sign x0: c1 = 0 in the plane)
    for r in range(n):
        for c in range(n):
            M[r, c] = 0.0
        qv[r] = 0.0
    for r in range(m):
        a0 = r if r < nc else nc + (r - nc) // d
        x0 = 1.0 if (r < nc or (r - nc) % d == 0) else -1.0
        for g in range(ng):
            F[fp + g] = x0 * F[fG + a0 * ng + g] + 0.0 * F[fG + a0 * ng + g]
        for k in range(nc):
            M[r, k] = F[fp + k]
        for f in range(nf):
            pt = F[fp + nc + f]
            M[r, nc + f * d] = pt * 1.0 + 0.0 * 0.0
            M[r, nc + f * d + 1] = pt * -1.0 + 0.0 * 0.0
    # B^T nu_free, the rows (_normal_q, _normal_diagonal, _friction_q, _friction_matrix), gamma (_scale_gamma)
    for g in range(ng):
        s0 = 0.0
        for a in range(I[oN + g]):
            s0 += F[fB + g * LD + a] * nu_free[I[oL + g * LD + a]]
        F[fS + g] = s0
    reg = 0.0
    if not compliant and model.regularization > 0.0:
        for k in range(nc):
            reg = max(reg, model.regularization * M[k, k])
    for k in range(nc):
        i = active[k]
        qv[k] = c_psi[i] / h + (1.0 * F[fS + k] + 0.0 * F[fS + k]) + c_bias[i, 0]
        M[k, k] += reg
        if compliant:
            K, C = pf[c_pair[i], PF_K], pf[c_pair[i], PF_C]
            comp = 1.0 / (h * (h * K + C))
            M[k, k] += comp
            qv[k] += comp * C * delta_n[c_slot[i]]
    for f in range(nf):
        k = f
        i = active[k]
        pr = c_pair[i]
        g = m + f
        M[g, k] = pf[pr, PF_MU]
        K, C = pf[pr, PF_K], pf[pr, PF_C]
        slot = c_slot[i]
        for j in range(d):
            r = nc + f * d + j
            x0 = 1.0 if j == 0 else -1.0
            jt = x0 * F[fS + nc + f] + 0.0 * F[fS + nc + f]
            qv[r] = jt + x0 * c_bias[i, 1] + 0.0 * c_bias[i, 2]
            M[r, g] = 1.0
            M[g, r] = -1.0
            if compliant:
                comp = 1.0 / (h * (h * K + C))
                for j2 in range(d):
                    r2 = nc + f * d + j2
                    y0 = 1.0 if j2 == 0 else -1.0
                    M[r, r2] += comp * (x0 * y0 + 0.0 * 0.0)
                qv[r] -= K / (h * K + C) * (x0 * delta_t[slot, 0] + 0.0 * delta_t[slot, 1])
    for f in range(nf):
        g = m + f
        sc = 0.0
        for j in range(d):
            r = nc + f * d + j
            sc = max(sc, abs(M[r, r]))
        if sc > 0.0:
            for r in range(n):
                M[r, g] *= sc
                M[g, r] *= sc
    # C (_combinations_into) and fric: every active contact
    for r in range(m):
        a0 = r if r < nc else nc + (r - nc) // d
        gen[0, r] = a0
        gen[1, r] = a0
        cf[0, r] = 1.0 if (r < nc or (r - nc) % d == 0) else -1.0
        cf[1, r] = 0.0
    for k in range(nc):
        fric[k] = k


class WarmResults(NamedTuple):
    """The arrays a warm step (`planar_warm_step`, `spatial_warm_step`) writes outside its
    contact problem, made once per rollout (`warm_results`) and held by both steps' buffers:
    the free velocity's and the position update's scratch, the impulses by contact, and the
    step's results (q+, nu+, q_ref+, the next basis table, the deformations) on two sides: a
    step writes one side while the state it starts from may be the other's, so that the
    rollout takes them as its next state without copying."""

    rhs: np.ndarray  # (nv,) scratch
    nu_free: np.ndarray  # (nv,)
    drive_a: np.ndarray  # (drives,)
    blend: np.ndarray  # (nv,) theta nu+ + (1 - theta) nu (`_blended`)
    impulses: np.ndarray  # (cap,) p_n by contact
    frictions: np.ndarray  # (cap, 2) p_t by contact
    q_ref: np.ndarray  # (2, drives) q_ref+ on either side
    nu: np.ndarray  # (2, nv) nu+
    q: np.ndarray  # (2, nq) q+
    basis: np.ndarray  # (2, rows, columns) the next basis table, each shaped as the rollout's
    delta_n: np.ndarray  # (2, slots) compliant deformations delta_n+ (rungs with compliance)
    delta_t: np.ndarray  # (2, slots, 2) delta_t+


@numba.njit(cache=True, error_model="numpy")
def warm_results(cap, nv, nq, drives, basis, slots):
    """`WarmResults` for up to cap contacts, basis tables shaped as basis and deformations of
    `slots` contact slots."""
    return WarmResults(
        np.empty(nv),
        np.empty(nv),
        np.empty(drives),
        np.empty(nv),
        np.empty(cap),
        np.empty((cap, 2)),
        np.empty((2, drives)),
        np.empty((2, nv)),
        np.empty((2, nq)),
        np.empty((2, basis.shape[0], basis.shape[1]), basis.dtype),
        np.empty((2, slots)),
        np.empty((2, slots, 2)),
    )


class WarmLCP(NamedTuple):
    """A warm step's contact problem (`warm_lcp`) for up to cap contacts: an LCP of n unknowns
    whose first m rows are the generators' (J^T's columns: normals and friction directions),
    ng contact directions (2 a contact in the plane, 3 in space). The matrices are flat: a step
    views its own sizes' part as a C-contiguous array (`matrix_view(buf, n, n)`; a view
    such as M[:n, :n] has a row stride numba does not know, and indexing it made the build 35%
    slower)."""

    active: np.ndarray  # (cap,) int
    fric: np.ndarray  # (cap,) int
    M: np.ndarray  # (n * n,) flat
    q_lcp: np.ndarray  # (n,)
    Y: np.ndarray  # (nv * ng,) flat
    gen: np.ndarray  # (2 * m,) int, flat
    cf: np.ndarray  # (2 * m,) flat
    guess: np.ndarray  # (n,) bool
    J: np.ndarray  # (n,) int
    lu: np.ndarray  # (n + 1, n) the warm start's elimination
    z: np.ndarray  # (n,)
    w: np.ndarray  # (n,)
    t: np.ndarray  # (ng,)
    p_t: np.ndarray  # (cap, 2) friction impulses of the active contacts
    lemke: LemkeWork  # Lemke's arrays, where the guess does not solve the LCP
    u: np.ndarray  # (ng,) G t (`_generator_guess_into`)
    comp: np.ndarray  # (cap,) each active contact's compliance (`_generator_scales_into`)
    gs: np.ndarray  # (cap,) each friction contact's gamma scale
    gmu: np.ndarray  # (cap,) and mu times it
    slide: np.ndarray  # (2 cap,) int: the sliding contacts the guess eliminates (`_generator_guess_into`)


@numba.njit(cache=True, error_model="numpy")
def warm_lcp(cap, n, m, ng, nv):
    """`WarmLCP` for up to cap contacts, n unknowns, m generators, ng directions, nv DOFs."""
    return WarmLCP(
        np.empty(cap, np.int64),
        np.empty(cap, np.int64),
        np.empty(n * n),
        np.empty(n),
        np.empty(nv * ng),
        np.empty(2 * m, np.int64),
        np.empty(2 * m),
        np.empty(n, np.bool_),
        np.empty(n, np.int64),
        np.empty((n + 1, n)),
        np.empty(n),
        np.empty(n),
        np.empty(ng),
        np.empty((cap, 2)),
        lemke_work(n),
        np.empty(ng),
        np.empty(cap),
        np.empty(cap),
        np.empty(cap),
        np.empty(2 * cap, np.int64),
    )


class PlanarWarm(NamedTuple):
    """The arrays of `planar_warm_step`, made once per rollout (`planar_warm_buffers`) for a
    contact capacity: every array the step writes, so that it runs without numba's runtime."""

    I: np.ndarray  # int scratch of `_planar_lcp_into`
    F: np.ndarray  # float scratch of `_planar_lcp_into`
    lcp: WarmLCP  # n = 4 cap, m = 3 cap, ng = 2 cap
    out: WarmResults


@numba.njit(cache=True, error_model="numpy")
def planar_warm_buffers(cap, out):
    """`PlanarWarm` for up to cap contacts (a `models.contact.ContactSet`'s capacity; 0: none,
    the step then is never taken), writing into out (`warm_results`)."""
    n_int, n_float = _planar_scratch(cap)
    nv = out.rhs.shape[0]
    return PlanarWarm(np.empty(n_int, np.int64), np.empty(n_float), warm_lcp(cap, 4 * cap, 3 * cap, 2 * cap, nv), out)


#: `planar_warm_step`'s outcomes: the step is done, or the caller takes the general path.
WARM_DONE, WARM_NOT_TAKEN = 0, 1


@numba.njit(cache=True, inline="always")
def _warm_solve(M, q_lcp, guess, L, n, nc):
    """The planar warm step's solve of its LCP (n unknowns, nc contacts, on `WarmLCP` L's arrays):
    the guessed basis (`warm_guess_dropping_into`, as `lemke_warm_kernel` tries it), and where
    that does not solve it, Lemke from the guess's basis (`_lemke_after_guess`), as
    `lemke_warm_kernel` goes on after a failed guess (a contact made or broken that q does not
    predict). Returns (solved,
    pivots, the final basis's flags, the natural-map residual: the guess's own, computed there,
    else Lemke's solution's); z and w in L.z[:n], L.w[:n]. Where Lemke fails, the general path
    regularizes the LCP."""
    z, w = L.z[:n], L.w[:n]
    residual = warm_guess_dropping_into(M, q_lcp, guess, L.J, L.lu, z, w, nc, WARM_TOLERANCE)
    if residual <= WARM_TOLERANCE:
        return True, 0, guess, residual
    # the final basis's flags replace the guess
    status, pivots, residual = _lemke_after_guess(M, q_lcp, guess, L.lemke, z, w, L.J, L.lu)
    return status == STATUS_SOLVED or status == STATUS_SOLVED_INACCURATE, pivots, guess, residual


@numba.njit(cache=True, inline="always")
def _lemke_after_guess(M, q_lcp, guess, work, z, w, J, A):
    """Where a step's guessed basis does not solve its LCP: Lemke's method from that basis
    (`lemke_from_guess_into`: its point kept at WARM_TOLERANCE, as a guess's is), else from
    scratch, with the step's pivot limit; guess becomes the final basis's flags. Every step
    (warm or general) that fails its guess goes on here: the same bits either way. Returns
    (status, pivots, the natural-map residual: +inf where not solved)."""
    n = q_lcp.shape[0]
    return lemke_from_guess_into(M, q_lcp, guess, DEFAULT_LEMKE_PIVOTS_PER_VARIABLE * (n + 1), work, z, w, guess, J, A, WARM_TOLERANCE)


@numba.njit(cache=True, inline="always")
def planar_warm_fixed(drives, tables, system, contacts, B):
    """The reference `planar_warm_step_on` takes (`models.reference`), as `spatial_warm_fixed`
    makes its own."""
    return reference((drives, tables, system, contacts, B))


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def planar_warm_step(model, drives, tables, system, h, q, nu, q_ref, u, contacts, nc, delta_n, delta_t, basis, B, side, part):
    """`planar_warm_step_on` with its arguments by value: its fixed ones (drives, tables, system,
    contacts, B) passed on by reference (`models.reference`), as `spatial_warm_step`."""
    fixed = planar_warm_fixed(drives, tables, system, contacts, B)
    return planar_warm_step_on(model, fixed, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, part)


@numba.njit(cache=True, _nrt=False, error_model="numpy")
@nonnegative_indices
def planar_warm_step_on(model, fixed, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, part):
    """A contact step of `_lemke_step` in the plane with A constant and no force-limited drive,
    compiled without numba's runtime: no reference counts, no allocation; every array is B's
    (`PlanarWarm`); and without numba's wraparound of negative indices (`nonnegative_indices`,
    as `spatial_warm_step_on`). The LCP is solved on the previous step's basis (the usual step while
    contacts persist; a contact not in it guessed from q, `_basis_guess`) or, where that guess
    does not solve it, by Lemke from that basis (`_warm_solve`). Where the LCP is not `_planar_case`, Lemke does not solve it to
    LCP_TOLERANCE (the general path then regularizes it), its solution leaves a contact
    closing (`_closes`) or the state leaves the finite range,
    it returns WARM_NOT_TAKEN and the caller takes the general path, which solves the step again
    from the start. Else (WARM_DONE): q+, nu+, q_ref+, the next basis table and, with
    compliance, the deformations on side `side` of B.out (`WarmResults`; 0 or 1: not the side
    the state q, nu, q_ref, basis, delta_n, delta_t is on), and the impulses by contact. The
    same operations in the same order as `_lemke_step`: the same bits
    (tests/test_warm_steps.py). part: PART_STEP, or the first parts only, for the cost split (as
    `contact_stage`). Returns (outcome, the LCP's size, residual, Lemke's pivots). fixed: a
    reference (`models.reference`) to (drives, tables, system, contacts, B), read once here
    (`planar_warm_fixed`)."""
    drives, tables, system, contacts, B = referent(fixed)
    nv = nu.shape[0]
    # A^-1's body blocks held (`_blocks`), A (and M) constant in the plane, no force limit
    if system.count.shape[0] != tables.bi.shape[0] or not _constant_plane(model, tables.spatial, system, nv):
        return WARM_NOT_TAKEN, 0, 0.0, 0
    if any_limited(drives.max_force):
        return WARM_NOT_TAKEN, 0, 0.0, 0
    L, R = B.lcp, B.out
    _free_velocity_into(model, drives, system, h, q, nu, q_ref, u, R.rhs, R.nu_free, R.q_ref[side], R.drive_a)
    n_act = _active_into(contacts.W_n, nc, L.active)
    active = L.active[:n_act]
    if not _planar_case(False, drives.max_force, active, contacts.pair, tables.pf, contacts.W_t):
        return WARM_NOT_TAKEN, 0, 0.0, 0
    n, m, ng = 4 * n_act, 3 * n_act, 2 * n_act
    M, q_lcp, Y, gen, cf = _lcp_views(L, nv, n, m, ng)
    fric = L.fric[:n_act]
    dofs, count, inv, pi, pf = system.dofs, system.count, system.inv, tables.pi, tables.pf
    _planar_lcp_into(
        model, h, dofs, count, inv, R.nu_free, active, pi, pf, contacts, delta_n, delta_t, B.I, B.F, M, q_lcp, Y, gen, cf, fric
    )
    _scale_lcp(M, q_lcp, m)
    lim = fric[:0]
    _fill_basis_guess(L.guess, basis, active, contacts.slot, fric, n_act, 2, lim, m, n, q_lcp)
    guess = L.guess[:n]
    if part == PART_ASSEMBLY:
        return WARM_DONE, n, 0.0, 0
    solved, pivots, guess, residual = _warm_solve(M, q_lcp, guess, L, n, n_act)
    if not solved:
        return WARM_NOT_TAKEN, n, 0.0, pivots
    if part == PART_CONTACT_SOLVE:
        return WARM_DONE, n, 0.0, pivots
    z = L.z[:n]
    if not (residual <= LCP_TOLERANCE):
        return WARM_NOT_TAKEN, n, residual, pivots
    nu_new, p_t = R.nu[side], L.p_t[:n_act]
    _impulses_into(False, n_act, m, n_act, fric, gen, cf, z, Y, R.nu_free, L.t[:ng], p_t, nu_new)
    ldof, nloc, Bl = _planar_generators(B.I, B.F, ng)
    reg = _regularization(Y, ldof, nloc, Bl, gen, cf, n_act, model.compliant, model.regularization)
    c_psi, c_bias = contacts.psi, contacts.bias
    if _closes(h, model.compliant, reg, active, pf, contacts.pair, contacts.slot, c_psi, c_bias, contacts.W_n, nu_new, z, delta_n):
        return WARM_NOT_TAKEN, n, residual, pivots
    _fill_basis_kept(R.basis[side], basis, guess, active, contacts.slot, fric, n_act, 2, lim, m)
    if model.compliant:
        _deformations_into(h, pf, contacts.pair, contacts.slot, active, z, p_t, delta_n, delta_t, R.delta_n[side], R.delta_t[side])
    _by_contact_into(nc, active, z, p_t, R.impulses, R.frictions)
    # the position update (`_integrate_checked`; in the plane integrate_positions has only its
    # translations and angles)
    velocity = _blended(model.theta, nu_new, nu, R.blend)
    q_new = R.q[side]
    for i in range(q.shape[0]):
        q_new[i] = q[i]
    _integrate_translations_into(tables.bi, q, velocity, h, q_new)
    if not (_finite_and_bounded(q_new) and _finite_and_bounded(nu_new)):
        return WARM_NOT_TAKEN, n, residual, pivots
    return WARM_DONE, n, residual, pivots


@numba.njit(cache=True, inline="always")
def _lcp_views(L, nv, n, m, ng):
    """A `WarmLCP`'s arrays for a step's sizes (n unknowns, m generators, ng directions): M
    (n, n), q_lcp (n,), Y (nv, ng), gen and cf (2, m), the matrices C-contiguous views of the
    flat buffers."""
    M, q_lcp = matrix_view(L.M, n, n), L.q_lcp[:n]
    Y, gen, cf = matrix_view(L.Y, nv, ng), matrix_view(L.gen, 2, m), matrix_view(L.cf, 2, m)
    return M, q_lcp, Y, gen, cf


#: Active contacts the spatial warm step's buffers hold (`spatial_warm_buffers`): a step with more
#: takes the general path. Its LCP has (2 + d) of them unknowns, so at d = 8 M is 120 x 120
#: (115 kB, under malloc's threshold for a mapping of its own, made once per rollout).
SPATIAL_WARM_CONTACTS = 12


class SpatialWarm(NamedTuple):
    """The arrays of `spatial_warm_step`, made once per rollout (`spatial_warm_buffers`) for up
    to cap contacts, d friction directions, nb bodies: every array the step writes, so that it
    runs without numba's runtime (as `PlanarWarm`, with A's blocks, the free velocity's
    rotational terms and the general LCP build's scratch). ng = 3 cap, m = (1 + d) cap, n = (2
    + d) cap."""

    lim: np.ndarray  # (0,) int: no force-limited drive takes this step
    R: np.ndarray  # (3, 3) scratch
    I: np.ndarray  # (3, 3) scratch
    mass_nu: np.ndarray  # (nv,) M(q) nu
    gyro: np.ndarray  # (nv,) the gyroscopic force
    block: np.ndarray  # (BODY_DOFS, BODY_DOFS) scratch of the rotating blocks (`rotating_blocks_into`)
    work: np.ndarray  # (BODY_DOFS, 2 BODY_DOFS) scratch
    body: np.ndarray  # (ng, 2) int: the generators (`_generators_into`)
    ldof: np.ndarray  # (ng, LOCAL_DOFS) int
    nloc: np.ndarray  # (ng,) int
    Bl: np.ndarray  # (ng, LOCAL_DOFS)
    G: np.ndarray  # (ng * ng,) the Delassus matrix, flat (as `WarmLCP`'s M)
    p: np.ndarray  # (ng,) scratch
    Bt_nu: np.ndarray  # (ng,)
    Jt_nu: np.ndarray  # (m,)
    Bb: np.ndarray  # (ng, BODY_DOFS) scratch of `_delassus_into`
    Yb: np.ndarray  # (ng, BODY_DOFS)
    gl: np.ndarray  # (ng,) int
    dirs: np.ndarray  # (2, d) the cone's directions (`cone_directions_into`)
    lcp: WarmLCP
    out: WarmResults


@numba.njit(cache=True, error_model="numpy")
def spatial_warm_buffers(cap, d, nb, out):
    """`SpatialWarm` for up to cap contacts (0: none; the step then is never taken), d friction
    directions and nb bodies, writing into out (`warm_results`)."""
    ng, m, n = 3 * cap, (1 + d) * cap, (2 + d) * cap
    nv = out.rhs.shape[0]
    dirs = np.empty((2, d))
    cone_directions_into(dirs[0], dirs[1])
    return SpatialWarm(
        np.empty(0, np.int64),
        np.empty((3, 3)),
        np.empty((3, 3)),
        np.empty(nv),
        np.empty(nv),
        np.empty((BODY_DOFS, BODY_DOFS)),
        np.empty((BODY_DOFS, 2 * BODY_DOFS)),
        np.empty((ng, 2), np.int64),
        np.empty((ng, LOCAL_DOFS), np.int64),
        np.empty(ng, np.int64),
        np.empty((ng, LOCAL_DOFS)),
        np.empty(ng * ng),
        np.empty(ng),
        np.empty(ng),
        np.empty(m),
        np.empty((ng, BODY_DOFS)),
        np.empty((ng, BODY_DOFS)),
        np.empty(ng, np.int64),
        dirs,
        warm_lcp(cap, n, m, ng, nv),
        out,
    )


@numba.njit(cache=True, inline="always")
def spatial_warm_fixed(drives, tables, system, contacts, W):
    """The reference `spatial_warm_step_on` takes (`models.reference`), its one layout. Inlined,
    so the value is copied into the caller's frame, where the reference stays valid."""
    return reference((drives, tables, system, contacts, W))


@numba.njit(cache=True, inline="always")
def pgs_warm_fixed(drives, tables, system, contacts, warm_n, warm_t, W, P):
    """The reference `pgs_warm_step_on` takes, as `spatial_warm_fixed` makes its own."""
    return reference((drives, tables, system, contacts, warm_n, warm_t, W, P))


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def spatial_warm_step(model, drives, tables, system, rotating, h, q, nu, q_ref, u, contacts, nc, delta_n, delta_t, basis, W, side, part):
    """`spatial_warm_step_on` with its arguments by value: its fixed ones (drives, tables, system,
    contacts, W) passed on by reference (`models.reference`). For a caller taking one step; a
    run of steps makes the reference once (`models.rollout._contact_run`)."""
    fixed = spatial_warm_fixed(drives, tables, system, contacts, W)
    return spatial_warm_step_on(model, fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, part)


@numba.njit(cache=True, _nrt=False, error_model="numpy")
@nonnegative_indices
def spatial_warm_step_on(model, fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, basis, side, part):
    """A contact step of `_lemke_step` in space with no force-limited drive, compiled without
    numba's runtime: no reference counts, no allocation; every array is W's (`SpatialWarm`); and
    without numba's wraparound of negative indices (`nonnegative_indices`: every index in it,
    its inlined helpers' included, is at least 0).
    The LCP is solved on the previous step's basis (a contact not in it guessed from q,
    `_basis_guess`), tried on G and C without building M (`_generator_guess_dropping_into`), and
    where that guess does not solve it, M is built and Lemke
    runs from the guess's basis (`_lemke_after_guess`, as the general step in space without
    force-limited drives, `_on_generators`).
    rotating: A depends on q (`has_rotations`), so the rotating bodies' blocks of A^-1 are
    refreshed here (`rotating_blocks_into`), where the general step has the rollout refresh them. Where
    there are no active contacts or more than W holds, a block of A is singular, Lemke does not
    solve the LCP to LCP_TOLERANCE (the general path then regularizes it), its solution leaves a
    contact closing (`_closes`) or the state leaves the finite range, it returns
    WARM_NOT_TAKEN and the caller takes the general path, which solves the step again from the
    start. Else (WARM_DONE): q+, nu+, q_ref+, the next basis
    table and, with compliance, the deformations on side `side` of W.out (`WarmResults`; not
    the side the state is on), and the impulses by contact. The same operations in the same
    order as `_lemke_step`: the same bits (tests/test_warm_steps.py). part: PART_STEP, or the
    first parts only, for the cost split (as `contact_stage`). Returns (outcome, the LCP's
    size, residual, Lemke's pivots). fixed: a reference (`models.reference`) to (drives, tables,
    system, contacts, W), read once here (`spatial_warm_fixed`)."""
    drives, tables, system, contacts, W = referent(fixed)
    bi, pi, pf = tables.bi, tables.pi, tables.pf
    nv = nu.shape[0]
    L, R = W.lcp, W.out
    if not tables.spatial or nc > L.active.shape[0] or any_limited(drives.max_force):
        return WARM_NOT_TAKEN, 0, 0.0, 0
    ok, dofs, count, inv = _warm_free_velocity_into(model, drives, tables, system, True, rotating, h, q, nu, q_ref, u, W, side, True)
    if not ok:
        return WARM_NOT_TAKEN, 0, 0.0, 0
    nu_free = R.nu_free
    # the LCP (`contact_lcp`), scaled, and the previous basis's guess
    n_act = _active_into(contacts.W_n, nc, L.active)
    if n_act == 0:
        return WARM_NOT_TAKEN, 0, 0.0, 0
    active = L.active[:n_act]
    fric = L.fric[:n_act]
    nf = _friction_into(True, active, contacts.pair, pf, contacts.W_t, contacts.W_o, fric)
    d = model.friction_directions
    ng, m = n_act + 2 * nf, n_act + nf * d
    n = m + nf
    lim = W.lim[:0]
    M, q_lcp, Y, gen, cf = _lcp_views(L, nv, n, m, ng)
    G = matrix_view(W.G, ng, ng)
    scratch = (W.body[:ng], W.ldof[:ng], W.nloc[:ng], W.Bl[:ng], G, W.p[:ng], W.Bt_nu[:ng], W.Jt_nu[:m], W.Bb[:ng], W.Yb[:ng], W.gl[:ng])
    # all of the LCP but G and M (`lcp_generators_into`), scaled as the general step scales it
    # (`_scale_contact_lcp` on the generators), and the previous basis's guess on Y and C (from q
    # where a contact is not in it): G and M are built only where that fails (a contact made or
    # broken that q does not predict)
    lcp_generators_into(
        model, True, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, drives, lim, 0, fric, nf, scratch, q_lcp, Y,
        gen, cf, W.dirs, False,
    )  # fmt: skip
    compliant = model.compliant
    comp, gs, gmu = L.comp[:n_act], L.gs[:nf], L.gmu[:nf]
    ldof, nloc, Bl, dv = W.ldof[:ng], W.nloc[:ng], W.Bl[:ng], W.gyro  # (gyro: the free velocity's scratch, nv)
    B = (ldof, nloc, Bl)
    reg, scale = _scale_contact_lcp(model, True, h, M[:0], q_lcp, Y, B, gen, cf, active, fric, nf, pf, contacts.pair, m, comp, gs, gmu)
    _fill_basis_guess(L.guess, basis, active, contacts.slot, fric, nf, d, lim, m, n, q_lcp)
    guess = L.guess[:n]
    if part == PART_ASSEMBLY:
        return WARM_DONE, n, 0.0, 0
    z, w = L.z[:n], L.w[:n]
    pivots = 0
    residual = _generator_guess_dropping_into(
        Y, ldof, nloc, Bl, dv, gen, cf, compliant, n_act, d, m, fric, nf, reg, comp, gs, gmu, q_lcp, scale, guess, L.J, L.lu, z, w,
        L.t[:ng], L.u[:ng], L.slide[: 2 * nf],
    )  # fmt: skip
    guessed = residual <= WARM_TOLERANCE  # (the guess solved it: z, t = C z and dv = Y t are its)
    if not guessed:
        # G (Y again with it, the same bits), M, scaled as q is, and Lemke from the failed
        # guess's basis (`_warm_solve`'s); the final basis's flags replace the guess, and the
        # residual is its solution's (the guess's is its own point's, computed there)
        _delassus_into(W.body[:ng], ldof, nloc, Bl, dofs, count, inv, Y, G, W.Bb[:ng], W.Yb[:ng], W.gl[:ng], True)
        lcp_matrix_into(model, True, h, active, pf, contacts.pair, drives, R.drive_a, lim, 0, fric, nf, reg, scratch, M, q_lcp, gen, cf)
        _scale_lcp_by(M, q_lcp[:0], scale)
        status, pivots, residual = _lemke_after_guess(M, q_lcp, guess, L.lemke, z, w, L.J, L.lu)
        if status != STATUS_SOLVED and status != STATUS_SOLVED_INACCURATE:
            return WARM_NOT_TAKEN, n, 0.0, pivots
    if part == PART_CONTACT_SOLVE:
        return WARM_DONE, n, 0.0, pivots
    if not (residual <= LCP_TOLERANCE):
        return WARM_NOT_TAKEN, n, residual, pivots
    nu_new, p_t = R.nu[side], L.p_t[:n_act]
    # (where the guess solved it, t = C z and dv = Y t are the guess's: the same bits,
    # `_generator_impulses_in_space_into` and `add_product`'s sums)
    if not guessed:
        _generator_impulses_into(m, gen, cf, z, L.t[:ng])
    _impulses_of_t_into(True, n_act, nf, fric, Y, nu_free, L.t[:ng], p_t, nu_new, dv, guessed)
    if _closes(h, compliant, reg, active, pf, contacts.pair, contacts.slot, contacts.psi, contacts.bias, contacts.W_n, nu_new, z, delta_n):
        return WARM_NOT_TAKEN, n, residual, pivots
    _fill_basis_kept(R.basis[side], basis, guess, active, contacts.slot, fric, nf, d, lim, m)
    if model.compliant:
        _deformations_into(h, pf, contacts.pair, contacts.slot, active, z, p_t, delta_n, delta_t, R.delta_n[side], R.delta_t[side])
    _by_contact_into(nc, active, z, p_t, R.impulses, R.frictions)
    # the position update (`_integrate_checked`)
    velocity = _blended(model.theta, nu_new, nu, R.blend)
    q_new = R.q[side]
    _integrate_positions_into(bi, q, velocity, h, q_new)
    if not (_finite_and_bounded(q_new) and _finite_and_bounded(nu_new)):
        return WARM_NOT_TAKEN, n, residual, pivots
    return WARM_DONE, n, residual, pivots


@numba.njit(cache=True, inline="always")
def _warm_free_velocity_into(model, drives, tables, system, spatial, rotating, h, q, nu, q_ref, u, W, side, held):
    """The free velocity of a warm step (in space, or PGS's in the plane: spatial False) on W's
    arrays (`SpatialWarm`): A^-1's body blocks (the System's, the rotating bodies' refreshed at q
    where rotating: `rotating_blocks_into`), and into W.out nu_free, q_ref+ on side `side` and
    the drives' a (`_free_velocity_by_body_into`; held and spatial as there). spatial is
    tables.spatial, passed as a value so that Lemke's spatial warm step gives it as the literal
    True and its planar branches fold away. Returns (ok: A's blocks are not singular, dofs,
    count, inv)."""
    bi, bf, R = tables.bi, tables.bf, W.out
    eps = model.quasistatic_inertia if model.eps == 0.0 else model.eps
    dofs, count, inv = system.dofs, system.count, system.inv
    if count.shape[0] != bi.shape[0]:  # (the System holds none: A's blocks are singular)
        return False, dofs, count, inv
    if rotating and not rotating_blocks_into(
        bi, bf, q, eps, drive_step(model, h), drives.v_index, drives.kp, drives.kd, drives.max_force, dofs, count, inv,
        W.block, W.work, W.R, W.I,
    ):  # fmt: skip
        return False, dofs, count, inv
    _free_velocity_by_body_into(
        model, drives, bi, bf, spatial, system, held, h, q, nu, q_ref, u, dofs, count, inv, R.rhs, R.nu_free, R.q_ref[side], R.drive_a,
        W.mass_nu, W.gyro, W.R, W.I,
    )  # fmt: skip
    return True, dofs, count, inv


@numba.njit(cache=True, inline="always")
def _free_velocity_by_body_into(
    model, drives, bi, bf, spatial, system, held, h, q, nu, q_ref, u, dofs, count, inv, rhs, nu_free, q_ref_new, a, mass_nu, gyro, R, I
):  # fmt: skip
    """Stage assemble, without contacts, on the caller's arrays: nu_free = A^-1 rhs, q_ref+ in
    q_ref_new and the force-limited drives' a (`_drives_into`); rhs, mass_nu, gyro (nv each), R, I
    (3 x 3) are scratch. held: M nu and A^-1 rhs by the System's constant M and A^-1 where it
    holds them (`_free_velocity`), else body by body (`_pgs_step`: M(q) nu, and A^-1 from its
    body blocks dofs, count, inv: `models.contact_pgs.body_blocks`); spatial: with the
    gyroscopic term."""
    nv = nu.shape[0]
    quasistatic = model.eps == 0.0
    eps = model.quasistatic_inertia if quasistatic else model.eps
    for v in range(nv):
        rhs[v] = system.rhs_const[v]
    if not quasistatic:
        if held and system.M_const.shape[0] == nv:
            add_product(rhs, system.M_const, nu, eps)
            if spatial:
                _gyroscopic_into(bi, bf, q, nu, gyro, R)
        else:
            if spatial:  # (with the gyroscopic force: one rotation per body for both)
                _mass_times_gyro_into(bi, bf, q, nu, mass_nu, gyro, R)
            else:
                _mass_times_into(bi, bf, q, nu, mass_nu, R, I)
            for v in range(nv):
                rhs[v] += eps * mass_nu[v]
        if spatial:
            he = h * eps
            for v in range(nv):
                rhs[v] += he * gyro[v]
    _drives_into(h, model.theta, q, nu, q_ref, u, drives, rhs, q_ref_new, a)
    if held and system.Ainv.shape[0] == nv:
        for v in range(nv):
            nu_free[v] = 0.0
        add_product(nu_free, system.Ainv, rhs, 1.0)
    else:
        block_solve_into(dofs, count, inv, rhs, nu_free)


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def pgs_warm_step(
    model, solver, drives, tables, system, rotating, h, q, nu, q_ref, u, contacts, nc, delta_n, delta_t, warm_n, warm_t, W, P, side,
    part,
):  # fmt: skip
    """`pgs_warm_step_on` with its arguments by value: its fixed ones (drives, tables, system,
    contacts, the warm starts warm_n and warm_t, W, P) passed on by reference
    (`models.reference`), as `spatial_warm_step` passes its own."""
    fixed = pgs_warm_fixed(drives, tables, system, contacts, warm_n, warm_t, W, P)
    return pgs_warm_step_on(model, solver, fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, side, part)


@numba.njit(cache=True, _nrt=False, error_model="numpy")
@nonnegative_indices
def pgs_warm_step_on(model, solver, fixed, rotating, h, q, nu, q_ref, u, nc, delta_n, delta_t, side, part):
    """`_pgs_step` (in space on the polygon or the exact cone, in the plane on its two
    directions), compiled without numba's
    runtime and without its wraparound of negative indices (`nonnegative_indices`): no reference
    counts, no allocation; the free velocity's arrays and the results
    are W's (`SpatialWarm`, as `spatial_warm_step`'s; in the plane W holds no contact), the contacts' rows P's
    (`models.contact_pgs.PgsWork`). Where nc exceeds P, a block of A is singular, PGS does not
    converge or the state leaves the finite range, it returns WARM_NOT_TAKEN and the caller
    takes the general path, which solves the step again from the start (and returns its
    status). Else (WARM_DONE): q+, nu+, q_ref+ and, with compliance, the deformations on side
    `side` of W.out (not the side the state is on), and the impulses by contact. The same
    operations in the same order as `_pgs_step`: the same bits (tests/test_warm_steps.py).
    part: PART_STEP, or the first parts only, for the cost split (as `contact_stage`). Returns
    (outcome, unknowns, residual, sweeps). fixed: a reference (`models.reference`) to (drives,
    tables, system, contacts, warm_n, warm_t, W, P), read once here (`pgs_warm_fixed`)."""
    drives, tables, system, contacts, warm_n, warm_t, W, P = referent(fixed)
    R = W.out
    spatial = tables.spatial
    if nc > P.active.shape[0] or any_limited(drives.max_force):
        return WARM_NOT_TAKEN, 0, 0.0, 0
    ok, dofs, count, inv = _warm_free_velocity_into(model, drives, tables, system, spatial, rotating, h, q, nu, q_ref, u, W, side, False)
    if not ok:
        return WARM_NOT_TAKEN, 0, 0.0, 0
    if part == PART_ASSEMBLY:
        return WARM_DONE, 0, 0.0, 0
    nu_new = R.nu[side]
    tolerance = _pgs_tolerance(model, solver)
    status, sweeps, residual, unknowns, n = contact_pgs_into(
        model, spatial, h, tables.pi, tables.pf, contacts, nc, delta_n, delta_t, dofs, count, inv, R.nu_free, warm_n, warm_t,
        ZERO_COLUMN, tolerance, solver.max_sweeps, P, nu_new,
    )  # fmt: skip
    if status != PgsStatus.CONVERGED:
        return WARM_NOT_TAKEN, unknowns, residual, sweeps
    if part == PART_CONTACT_SOLVE:
        return WARM_DONE, unknowns, residual, sweeps
    active, p_n, f = P.active[:n], P.p_n[:n], P.f[:n]
    if model.compliant:
        _deformations_into(h, tables.pf, contacts.pair, contacts.slot, active, p_n, f, delta_n, delta_t, R.delta_n[side], R.delta_t[side])
    _by_contact_into(nc, active, p_n, f, R.impulses, R.frictions)
    velocity = _blended(model.theta, nu_new, nu, R.blend)  # the position update (`_integrate_checked`)
    q_new = R.q[side]
    _integrate_positions_into(tables.bi, q, velocity, h, q_new)
    if not (_finite_and_bounded(q_new) and _finite_and_bounded(nu_new)):
        return WARM_NOT_TAKEN, unknowns, residual, sweeps
    return WARM_DONE, unknowns, residual, sweeps


@numba.njit(cache=True, inline="always")
def _planar_case(spatial, max_force, active, c_pair, pf, W_t):
    """Whether `_planar_lcp` builds this step's LCP: a planar scene without force-limited
    drives whose active contacts (at least one) all have friction rows (`_friction_into`).
    (It takes arrays, not the contact set and the drives: an inlined helper reference-counts
    every array of the tuples it is passed.)"""
    if spatial or active.shape[0] == 0 or any_limited(max_force):
        return False
    for k in range(active.shape[0]):
        i = active[k]
        if not (pf[c_pair[i], PF_MU] > 0.0 and _column_norm(W_t, i) > ZERO_COLUMN):
            return False
    return True


@numba.njit(cache=True, inline="always")
def _contact_solve(model, spatial, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, drives, drive_a, basis):
    """Build and solve the contact LCP, first on the previous step's basis (`basis_table`).
    Returns (nu+, p_n, p_t, status, pivots, residual, size, basis+)."""
    # the builder chosen here, not in a helper: one that took the build's arguments would count
    # their references each step, 2-3% of the squeeze's (docs/measurements.md)
    if _planar_case(spatial, drives.max_force, active, contacts.pair, pf, contacts.W_t):
        Mlcp, qlcp, Y, gen, cf, fric, nf, lim, G, B = _planar_lcp(
            model, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t
        )
    else:
        Mlcp, qlcp, Y, gen, cf, fric, nf, lim, G, B = contact_lcp(
            model, spatial, h, dofs, count, inv, nu_free, active, pi, pf, contacts, delta_n, delta_t, drives, drive_a
        )
    nc = active.shape[0]
    d = model.friction_directions if spatial else 2
    nd = nf * d
    m = nc + nd + lim.shape[0]
    n = qlcp.shape[0]
    on_generators = _on_generators(spatial, lim.shape[0])
    comp, gs, gmu = np.empty(nc), np.empty(nf), np.empty(nf)
    reg, scale = _scale_contact_lcp(
        model, on_generators, h, Mlcp, qlcp, Y, B, gen, cf, active, fric, nf, pf, contacts.pair, m, comp, gs, gmu
    )
    slot = contacts.slot
    guess = _basis_guess(basis, active, slot, fric, nf, d, lim, m, n, qlcp)
    limit = DEFAULT_LEMKE_PIVOTS_PER_VARIABLE * (n + 1)
    if on_generators:  # (the residual, as from lemke_warm_kernel: the guess's own, computed there, or Lemke's solution's)
        z, w, status, pivots, basic_z, residual = _guess_or_lemke(
            Y, B, gen, cf, model.compliant, nc, d, m, fric, nf, reg, comp, gs, gmu, Mlcp, qlcp, scale, guess
        )
    else:
        z, w, status, pivots, basic_z, _, residual = lemke_warm_kernel(Mlcp, qlcp, limit, guess, WARM_TOLERANCE, nc)
    added = 0.0
    p_t = np.zeros((nc, 2))
    nu_new = np.empty(nu_free.shape[0])
    solved = False
    for k in range(LCP_REGULARIZATION_STEPS + 1):
        solved = (status == STATUS_SOLVED or status == STATUS_SOLVED_INACCURATE) and residual <= LCP_TOLERANCE
        if solved:
            _impulses_into(spatial, nc, m, nf, fric, gen, cf, z, Y, nu_free, np.empty(Y.shape[1]), p_t, nu_new)
            if not _closes(
                h, model.compliant, reg, active, pf, contacts.pair, slot, contacts.psi, contacts.bias, contacts.W_n, nu_new, z, delta_n
            ):
                break
            # a contact left closing: the LCP's round-off (a statically indeterminate contact set:
            # z refined on its basis, `refined_on_basis`), or the retries' compliance (below) on
            # a row that carries a large impulse
            z2, w2, residual2 = refined_on_basis(Mlcp, qlcp, z, basic_z)
            if residual2 <= LCP_TOLERANCE:
                _impulses_into(spatial, nc, m, nf, fric, gen, cf, z2, Y, nu_free, np.empty(Y.shape[1]), p_t, nu_new)
                if not _closes(
                    h, model.compliant, reg, active, pf, contacts.pair, slot, contacts.psi, contacts.bias, contacts.W_n, nu_new, z2,
                    delta_n,
                ):  # fmt: skip
                    z, w, residual = z2, w2, residual2
                    break
            solved = False
        if k == LCP_REGULARIZATION_STEPS:
            break
        # redundant rigid contacts make M singular; a tiny compliance on the contact rows
        # restores a unique solution: relative to each row's own diagonal (LCP_REGULARIZATION,
        # then 100 times more per retry), as the exact cone's pivoting has it; one relative to
        # the largest diagonal gave a light row many times its own
        target = LCP_REGULARIZATION * 100.0**k
        grow = (1.0 + target) / (1.0 + added)
        for r in range(nc + nd):
            Mlcp[r, r] *= grow
        added = target
        z, w, status, more, basic_z, _, residual = lemke_warm_kernel(
            Mlcp, qlcp, limit, guess, WARM_TOLERANCE, np.int64(0)
        )  # (none dropped, passed: the call above's signature, not a second one with it omitted)
        pivots += more
    p_n = z[:nc]  # (a view: z is not written again)
    if not solved:
        return nu_free, p_n, p_t, StepStatus.LCP_FAILED.value, pivots, residual, n, basis
    basis_new = _basis_kept(basis, basic_z, active, slot, fric, nf, d, lim, m)
    return nu_new, p_n, p_t, StepStatus.OK.value, pivots, residual, n, basis_new


@numba.njit(cache=True, inline="always")
def _closes(h, compliant, reg, active, pf, c_pair, c_slot, c_psi, c_bias, W_n, nu_new, p_n, delta_n):
    """Whether a step's nu+ and normal impulses p_n (by active contact) leave a contact's normal
    row short by more than CLOSING_TOL over the step: h w < -CLOSING_TOL, where the LCP asks
    w = psi / h + W_n^T nu+ + bias + reg p_n (+ `_compliance` (p_n + C delta_n) with compliance)
    >= 0; reg: the rung's own regularization of rigid rows (`_regularization`, a compliance the
    rung asks for: box_rotate_3d's quasistatic rows give by 3e-6 m a step under it), not the
    retries' (`LCP_REGULARIZATION`), which only make Lemke's problem solvable."""
    for k in range(active.shape[0]):
        i = active[k]
        w = c_psi[i] / h + c_bias[i, 0] + reg * p_n[k]
        for v in range(nu_new.shape[0]):
            w += W_n[v, i] * nu_new[v]
        if compliant:
            K, C = pf[c_pair[i], PF_K], pf[c_pair[i], PF_C]
            w += _compliance(h, K, C) * (p_n[k] + C * delta_n[c_slot[i]])
        if h * w < -CLOSING_TOL:
            return True
    return False


@numba.njit(cache=True, inline="always")
def _on_generators(spatial, nl):
    """Whether a contact LCP's guess is tried on G and C (`_generator_guess_into`), M used only
    where it fails: in space without force-limited drives (`spatial_warm_step`'s case; the
    general step does the same there, for the same bits)."""
    return spatial and nl == 0


@numba.njit(cache=True, inline="always")
def _scale_contact_lcp(model, on_generators, h, Mlcp, qlcp, Y, B, gen, cf, active, fric, nf, pf, c_pair, m, comp, gs, gmu):
    """Scale a built contact LCP (`_scale_lcp`): on the generators (`_on_generators`) by
    `_generator_scales_into`'s max |M|, which fills comp, gs and gmu for the guess, else by M's
    own. Y, B = (ldof, nloc, Bl): the generators' (`contact_lcp`). Returns (reg:
    `_regularization`, the rigid rows' regularization the builder put in M; the scale)."""
    ldof, nloc, Bl = B
    reg = _regularization(Y, ldof, nloc, Bl, gen, cf, active.shape[0], model.compliant, model.regularization)
    if not on_generators:
        return reg, _scale_lcp(Mlcp, qlcp, m)
    d = model.friction_directions
    scale = _generator_scales_into(Y, ldof, nloc, Bl, gen, cf, model.compliant, h, reg, active, fric, nf, d, pf, c_pair, comp, gs, gmu)
    _scale_lcp_by(Mlcp, qlcp, scale)
    return reg, scale


@numba.njit(cache=True, inline="always")
def _guess_or_lemke(Y, B, gen, cf, compliant, nc, d, m, fric, nf, reg, comp, gs, gmu, Mlcp, qlcp, scale, guess):
    """`lemke_warm_kernel` with its guess on the generators (`_generator_guess_dropping_into`)
    and, where that fails, Lemke from the guess's basis on the scaled M, q (`_lemke_after_guess`).
    Returns (z, w, status, pivots, basic_z,
    the natural-map residual: the guess's own, computed there, else Lemke's solution's)."""
    n = qlcp.shape[0]
    nv, ng = Y.shape
    ldof, nloc, Bl = B
    z, w, dv = np.empty(n), np.empty(n), np.empty(nv)
    J, A, t, u, slide = np.empty(n, np.int64), np.empty((n + 1, n)), np.empty(ng), np.empty(ng), np.empty(2 * nf, np.int64)
    residual = _generator_guess_dropping_into(
        Y, ldof, nloc, Bl, dv, gen, cf, compliant, nc, d, m, fric, nf, reg, comp, gs, gmu, qlcp, scale, guess, J, A, z, w, t, u, slide
    )
    if residual <= WARM_TOLERANCE:
        return z, w, STATUS_SOLVED, 0, guess, residual
    status, pivots, residual = _lemke_after_guess(Mlcp, qlcp, guess, lemke_work(n), z, w, J, A)
    return z, w, status, pivots, guess, residual


@numba.njit(cache=True, inline="always")
def _generator_impulses_into(m, gen, cf, z, t):
    """The generators' impulses t = C z (t: ng entries, set here) of the LCP's first m unknowns."""
    for g in range(t.shape[0]):
        t[g] = 0.0
    for r in range(m):
        t[gen[0, r]] += cf[0, r] * z[r]
        t[gen[1, r]] += cf[1, r] * z[r]


@numba.njit(cache=True, inline="always")
def _generator_impulses_in_space_into(nc, nf, d, cf, z, t):
    """`_generator_impulses_into` for a contact LCP in space without force-limited drives
    (`_combinations_into`'s C: each normal its own generator, each friction contact's d
    directions its t and o): each sum in a register, in the same order, so the same bits,
    where `_generator_impulses_into` adds each term to t in memory, a chain of stores and
    loads (with the rows' loop of `_generator_guess_into` without a division a row: its guess
    1.12-1.2x faster at box_push_3d's push, in one process)."""
    for k in range(nc):
        s = 0.0
        s += cf[0, k] * z[k]
        s += cf[1, k] * z[k]
        t[k] = s
    for f in range(nf):
        s0, s1 = 0.0, 0.0
        for j in range(d):
            r = nc + f * d + j
            s0 += cf[0, r] * z[r]
            s1 += cf[1, r] * z[r]
        t[nc + f], t[nc + nf + f] = s0, s1


@numba.njit(cache=True, inline="always")
def _impulses_into(spatial, nc, m, nf, fric, gen, cf, z, Y, nu_free, t, p_t, nu_new):
    """The contact LCP's solution z as impulses and velocity, on the caller's arrays: the
    generators' impulses t = C z (ng = Y.shape[1] entries), each friction contact's impulse
    along t and o in p_t (nc, 2; zeroed first), and nu+ = nu_free + Y t in nu_new, by
    add_product's loops, not numba's BLAS call: the same bits on every CPU (OpenBLAS picks its
    kernel by CPU), and 0.15-0.3 us less a contact step."""
    _generator_impulses_into(m, gen, cf, z, t)
    _impulses_of_t_into(spatial, nc, nf, fric, Y, nu_free, t, p_t, nu_new, nu_new[:0], False)


@numba.njit(cache=True, inline="always")
def _impulses_of_t_into(spatial, nc, nf, fric, Y, nu_free, t, p_t, nu_new, dv, made):
    """`_impulses_into` from the generators' impulses t = C z already made (where
    `_generator_guess_into` solved the step, it leaves them in t) and, where made, Y t too (in
    dv: the guess's, by `add_product`'s sums, so nu_free + dv is add_product's nu+ bit for
    bit)."""
    for k in range(nc):
        p_t[k, 0] = 0.0
        p_t[k, 1] = 0.0
    for f in range(nf):
        p_t[fric[f], 0] = t[nc + f]
        if spatial:
            p_t[fric[f], 1] = t[nc + nf + f]
    if made:
        for v in range(nu_free.shape[0]):
            nu_new[v] = nu_free[v] + dv[v]
        return
    for v in range(nu_free.shape[0]):
        nu_new[v] = nu_free[v]
    add_product(nu_new, Y, t, 1.0)


@numba.njit(cache=True, inline="always")
def _scale_lcp(Mlcp, qlcp, m):
    """LCP(s M, s q) has the solutions of LCP(M, q): scale both, in place, to max |M| = 1 for
    Lemke's pivot tolerances (quasistatic rungs make M ~ 1 / QUASISTATIC_INERTIA). Returns the
    scale, max |M| before."""
    scale = _largest_entry(Mlcp, m)
    _scale_lcp_by(Mlcp, qlcp, scale)
    return scale


@numba.njit(cache=True, inline="always")
def _scale_lcp_by(Mlcp, qlcp, scale):
    """`_scale_lcp` by a given max |M| (`_largest_entry`, `_generator_scales_into`): M and q
    times 1 / scale, in place (not at all where scale is 0). Either may be empty (M built only
    where the guess fails, `spatial_warm_step`)."""
    if scale > 0.0:
        inverse = 1.0 / scale  # a product per entry: divisions cost 0.5 us of box_push's 9.5 us solve
        for r in range(Mlcp.shape[0]):  # (loops: the array expressions cost more instructions)
            for c in range(Mlcp.shape[1]):
                Mlcp[r, c] *= inverse
        for r in range(qlcp.shape[0]):
            qlcp[r] *= inverse


@numba.njit(cache=True, inline="always")
def _largest_entry(Mlcp, m):
    """max |M| of a contact LCP without scanning it all: its top-left m x m block J^T A^-1 J
    (plus compliance and drive terms) is positive semidefinite, so no entry there exceeds the
    largest diagonal one; the rest (gamma and slack rows and columns, each row's magnitudes
    mirrored in its column) is read in its rows."""
    n = Mlcp.shape[0]
    scale = 0.0
    for r in range(m):
        scale = max(scale, abs(Mlcp[r, r]))
    for r in range(m, n):
        for c in range(n):
            scale = max(scale, abs(Mlcp[r, c]))
    return scale


@numba.njit(cache=True, inline="always")
def _lcp_entry(jac, cf, compliant, nc, d, m, fric, reg, comp, gs, gmu, r, c):
    """M[r, c] of a contact LCP in space without force-limited drives (`contact_lcp`,
    unscaled), from jac = (C^T G C)[r, c] (read where r, c < m: `_normal_diagonal_entry`, a row of
    C^T G's `_fill_jacobian_block` way) by the build's operations (`lcp_matrix_into`: the same
    bits): the normal diagonal's reg and compliance, the friction blocks' compliance, gamma's
    entries. comp (nc): each active contact's `_compliance` (with compliance); gs, gmu (nf):
    each friction contact's gamma scale (`_scale_gamma`; 1 where it does not scale) and mu
    times it (`_generator_scales_into`)."""
    if r < m and c < m:
        v = jac
        if r < nc:
            if r == c:
                v += reg
                if compliant:
                    v += comp[r]
        elif c >= nc and compliant:
            f = (r - nc) // d
            if (c - nc) // d == f:
                v += comp[fric[f]] * (cf[0, r] * cf[0, c] + cf[1, r] * cf[1, c])
        return v
    if r < m:  # gamma's column
        f = c - m
        return gs[f] if r >= nc and (r - nc) // d == f else 0.0
    f = r - m  # gamma's row
    if c == fric[f]:
        return gmu[f]
    if nc <= c < m and (c - nc) // d == f:
        return -gs[f]
    return 0.0


@numba.njit(cache=True, inline="always")
def _generator_scales_into(Y, ldof, nloc, Bl, gen, cf, compliant, h, reg, active, fric, nf, d, pf, c_pair, comp, gs, gmu):
    """What `_lcp_entry` needs besides C^T G C, into the caller's comp (nc), gs and gmu (nf):
    each active contact's `_compliance` (0 without), each friction contact's gamma scale
    (`_scale_gamma`'s: its block's largest diagonal entry, 1 where that is 0) and mu times it.
    Returns max |M| (`_largest_entry`'s: the diagonal's largest, or gamma rows'), without M or
    G: C^T G C's diagonal from Y (`_gram_entry`; a friction contact's three entries of G once,
    its d directions' diagonal by `_fill_jacobian_block`'s operations: M's bits)."""
    nc = active.shape[0]
    m = nc + nf * d
    for k in range(nc):
        p = c_pair[active[k]]
        comp[k] = _compliance(h, pf[p, PF_K], pf[p, PF_C]) if compliant else 0.0
    scale = 0.0
    for k in range(nc):
        jac = _normal_diagonal_entry(Y, ldof, nloc, Bl, gen, cf, k)
        scale = max(scale, abs(_lcp_entry(jac, cf, compliant, nc, d, m, fric, reg, comp, gs, gmu, k, k)))
    for f in range(nf):
        s = 0.0
        a0, a1 = nc + f, nc + nf + f  # (each direction's gen[:, r]: its t and o)
        gtt = _gram_entry(Y, ldof, nloc, Bl, a0, a0)
        gto = _gram_entry(Y, ldof, nloc, Bl, a0, a1)
        goo = _gram_entry(Y, ldof, nloc, Bl, a1, a1)
        for j in range(d):
            r = nc + f * d + j
            x0, x1 = cf[0, r], cf[1, r]
            jac = (x0 * gtt + x1 * gto) * x0 + (x0 * gto + x1 * goo) * x1
            s = max(s, abs(_lcp_entry(jac, cf, compliant, nc, d, m, fric, reg, comp, gs, gmu, r, r)))
        scale = max(scale, s)
        mu = pf[c_pair[active[fric[f]]], PF_MU]
        gs[f] = s if s > 0.0 else 1.0
        gmu[f] = mu * gs[f]  # (mu itself where gs is 1)
        scale = max(scale, abs(gmu[f]))
        scale = max(scale, gs[f])
    return scale


@numba.njit(cache=True, inline="always")
def _combined(gen, cf, x, r):
    """Entry r (< m) of C^T x for x on the generators (ng entries; C: `_combinations_into`'s gen
    and cf): cf[0, r] x[gen[0, r]] + cf[1, r] x[gen[1, r]]. `lcp_generators_into` writes the
    same sum out: the general step, compiled with numba's runtime, shares it, and there a
    helper's array arguments would be reference-counted on every row."""
    return cf[0, r] * x[gen[0, r]] + cf[1, r] * x[gen[1, r]]


@numba.njit(cache=True, inline="always")
def _guess_entry(u, gen, cf, compliant, nc, d, m, fric, reg, comp, gs, gmu, r, c):
    """M[r, c] (unscaled) by `_lcp_entry`, with u row r of C^T G where r < m (`_ctg_row_into`)."""
    jac = 0.0
    if r < m and c < m:
        jac = u[c] if c < nc else _combined(gen, cf, u, c)
    return _lcp_entry(jac, cf, compliant, nc, d, m, fric, reg, comp, gs, gmu, r, c)


@numba.njit(cache=True, inline="always")
def _sliding_impulse(gmu, gs, q, m, f, inverse):
    """Friction contact f's basic direction impulse where it slides (`_generator_guess_into`),
    beta = per_normal p_n + constant, from its gamma row (gmu p_n - gs beta) / scale + q_gamma =
    0 (inverse = 1 / scale): (per_normal, constant)."""
    return gmu[f] / gs[f], q[m + f] / (gs[f] * inverse)


@numba.njit(cache=True, inline="always")
def _friction_row(compliant, nc, nf, fric, comp, gen, cf, t, u, f, r):
    """(M z)[r] of friction contact f's direction row r (unscaled, gamma's term aside) from t = C
    z and u = G t (`_generator_guess_into`): (C^T G C z)[r] and, with compliance, its friction
    block's term."""
    v = _combined(gen, cf, u, r)
    if compliant:  # (gen[:, r] = nc + f, nc + nf + f: its t and o generators)
        v += comp[fric[f]] * _combined(gen, cf, t, r)
    return v


@numba.njit(cache=True, inline="always")
def _generator_guess_into(
    Y, ldof, nloc, Bl, dv, gen, cf, compliant, nc, d, m, fric, nf, reg, comp, gs, gmu, q, scale, guess, J, A, z, w, t, u, slide
):  # fmt: skip
    """The previous basis's guess (`warm_guess_into`) on an LCP without force-limited drives,
    without M: z_J = -M[J, J]^-1 q_J with M[J, J]'s entries made by `_lcp_entry` (M's own
    bits) and scaled by 1 / scale as `_scale_lcp_by` scales M (q: scaled already), z = 0
    elsewhere, and w = M z + q through the generators: t = C z, G t, C^T (G t), and the
    diagonal's, friction blocks' and gamma's terms (O(ng^2 + n), not O(n nj)). G itself is
    not needed: its rows from Y = A^-1 B and the generators (ldof, nloc, Bl:
    `_ctg_row_on_y_into`), G t as B^T (Y t) (Y t in dv, nv entries), so a warm step builds G
    only where the guess fails (at box_push_3d's push, G's 15 x 15 entries cost more than the
    guess's few rows).

    A sliding contact of the guess (its gamma and exactly one of its directions basic) is
    eliminated from M[J, J] before the solve: gamma's row gives that direction's impulse, beta
    = (gmu p_n + scale q_gamma) / gs (mu p_n), substituted into the other rows; gamma appears
    in no basic row but that direction's, which gives gamma once the rest of z is known (from
    G t, which w takes too, not row by row from M's entries: 15% of the guess at the push). At
    box_push_3d's push that takes the solve from 14 unknowns to 4. The same z as the dense
    solve's to round-off (not its bits: another elimination).

    On the caller's J (n), A ((n + 1, n) at least), z, w (n), t, u (ng), slide (2 nf: each
    friction contact's sliding direction row, -1 if not sliding, then its normal's position in
    the solve, -1 if not basic). Returns that point's natural-map residual (+inf where the
    eliminated M[J, J] is numerically singular): the callers accept it at their tolerance and
    keep it as the step's residual, not computing it again."""
    n = q.shape[0]
    inverse = 1.0 / scale if scale > 0.0 else 1.0
    for f in range(nf):
        slide[f] = -1
        if guess[m + f]:
            basic = 0
            for j in range(d):
                if guess[nc + f * d + j]:
                    slide[f] = nc + f * d + j
                    basic += 1
            if basic != 1:
                slide[f] = -1
    nj = np.int64(0)
    for i in range(n):
        if guess[i] and not (i >= m and slide[i - m] >= 0) and not (nc <= i < m and slide[(i - nc) // d] == i):
            J[nj] = i
            nj += 1
    for f in range(nf):
        slide[nf + f] = -1
        for a in range(nj):
            if J[a] == fric[f]:
                slide[nf + f] = a
    for f in range(nf):  # each sliding direction's impulse (`_sliding_impulse`) in t, until t is C z
        if slide[f] >= 0:
            t[f], t[nf + f] = _sliding_impulse(gmu, gs, q, m, f, inverse)
    for a in range(nj):
        r = J[a]
        if r < m:  # row r of C^T G, in u (`_fill_jacobian_block`'s p)
            _ctg_row_on_y_into(Y, ldof, nloc, Bl, gen, cf, r, u)
        for b in range(nj):
            A[a, b] = _guess_entry(u, gen, cf, compliant, nc, d, m, fric, reg, comp, gs, gmu, r, J[b]) * inverse
        rhs = -q[r]
        for f in range(nf):  # the sliding directions' impulses, substituted
            if slide[f] >= 0:
                e = _guess_entry(u, gen, cf, compliant, nc, d, m, fric, reg, comp, gs, gmu, r, slide[f]) * inverse
                if e != 0.0:
                    if slide[nf + f] >= 0:
                        A[a, slide[nf + f]] += e * t[f]
                    rhs -= e * t[nf + f]
        A[nj, a] = rhs
    ok = _gauss_solve(A, nj)
    for i in range(n):
        z[i] = 0.0
    if not ok:
        return np.inf
    for a in range(nj):
        z[J[a]] = A[nj, a]
    for f in range(nf):
        if slide[f] >= 0:
            z[slide[f]] = t[f] * z[fric[f]] + t[nf + f]
    # z[:m] is whole (gamma is no column of C): t = C z, u = G t, and each row's (M z)[r] but
    # gamma's term (`_friction_row`), which gives a sliding contact's gamma (its direction's w
    # is 0) and then every w
    nv, ng = Y.shape
    _generator_impulses_in_space_into(nc, nf, d, cf, z, t)
    for v in range(nv):  # Y t (`add_product`'s sums: the velocity change `_impulses_of_t_into` makes)
        s = 0.0
        for g in range(ng):
            s += Y[v, g] * t[g]
        dv[v] = s
    for g in range(ng):  # G t = B^T (Y t), over each generator's local DOFs
        s = 0.0
        for a in range(nloc[g]):
            s += Bl[g, a] * dv[ldof[g, a]]
        u[g] = s
    for f in range(nf):
        s = slide[f]
        if s >= 0:
            v = _friction_row(compliant, nc, nf, fric, comp, gen, cf, t, u, f, s)
            z[m + f] = -(v * inverse + q[s]) / (gs[f] * inverse)
    for r in range(nc):
        v = _combined(gen, cf, u, r)
        v += reg * z[r]
        if compliant:
            v += comp[r] * z[r]
        w[r] = v * inverse + q[r]
    for f in range(nf):  # (each friction contact's rows in a loop of their own: no division r // d a row)
        for j in range(d):
            r = nc + f * d + j
            v = _friction_row(compliant, nc, nf, fric, comp, gen, cf, t, u, f, r)
            v += gs[f] * z[m + f]
            w[r] = v * inverse + q[r]
    for f in range(nf):
        s = 0.0
        for j in range(d):
            s += z[nc + f * d + j]
        w[m + f] = (gmu[f] * z[fric[f]] - gs[f] * s) * inverse + q[m + f]
    return _natural_map_residual(z, w, q)


@numba.njit(cache=True, inline="always")
def _generator_guess_dropping_into(
    Y, ldof, nloc, Bl, dv, gen, cf, compliant, nc, d, m, fric, nf, reg, comp, gs, gmu, q, scale, guess, J, A, z, w, t, u, slide
):  # fmt: skip
    """`_generator_guess_into`, and where its system is singular, the guess again without one of
    its basic normals, in order, as `warm_guess_dropping_into` drops them on M: the first whose
    point's residual is at most WARM_TOLERANCE is kept, and guess is changed to it. Returns the
    residual of the point left in z and w (+inf where none solves, guess then as given)."""
    # one call site (the guess is inlined): k = -1 the guess as given, then each basic normal k dropped
    k = -1
    while True:
        residual = _generator_guess_into(
            Y, ldof, nloc, Bl, dv, gen, cf, compliant, nc, d, m, fric, nf, reg, comp, gs, gmu, q, scale, guess, J, A, z, w, t, u, slide
        )
        if k < 0 and residual != np.inf:
            return residual
        if k >= 0:
            if residual <= WARM_TOLERANCE:
                return residual
            guess[k] = True
        k += 1
        while k < nc and not guess[k]:
            k += 1
        if k >= nc:
            return np.inf
        guess[k] = False


@numba.njit(cache=True, inline="always")
def _basis_guess(basis, active, slot, fric, nf, d, lim, m, n, q):
    """The LCP's first guess of a complementary basis (True: z_i basic) from the previous
    step's table (`basis_table`; rows: the contact slots, slot.shape[0] of them, then the
    drives): each contact's and force-limited drive's flags. A contact that was not in the
    previous LCP (all of them at a period's first step, or with a table of another shape) is
    guessed from q, the LCP's (scaled) q, what its rows would be with no impulse: it pushes
    where its normal's q < 0, and where it pushes and some friction direction's q < 0, it slides
    against the most negative (that direction and gamma basic); else w is basic on its rows. A
    force-limited drive not in the table guesses w basic. Exact either way: a guess is kept only
    where it solves the LCP to WARM_TOLERANCE (then, where its rigid normals are redundant,
    without one of them: `_generator_guess_dropping_into`), else Lemke runs from its basis
    (`_lemke_after_guess`)."""
    guess = np.empty(n, np.bool_)
    _fill_basis_guess(guess, basis, active, slot, fric, nf, d, lim, m, n, q)
    return guess


@numba.njit(cache=True, inline="always")
def _fill_basis_guess(guess, basis, active, slot, fric, nf, d, lim, m, n, q):
    """`_basis_guess` into the caller's guess (at least n entries)."""
    for r in range(n):
        guess[r] = False
    nc = active.shape[0]
    nl = lim.shape[0]
    slots = slot.shape[0]
    fits = basis.shape[1] == BASIS_DIRECTIONS + d and basis.shape[0] >= slots
    nd = nf * d
    for k in range(nc):
        s = slot[active[k]]
        if fits and basis[s, BASIS_PRESENT] != 0:
            guess[k] = basis[s, BASIS_NORMAL] != 0
        else:
            guess[k] = q[k] < 0.0
    for f in range(nf):
        s = slot[active[fric[f]]]
        if fits and basis[s, BASIS_PRESENT] != 0:
            guess[m + f] = basis[s, BASIS_GAMMA] != 0
            for j in range(d):
                guess[nc + f * d + j] = basis[s, BASIS_DIRECTIONS + j] != 0
        elif guess[fric[f]]:
            first, least = nc + f * d, 0.0
            for j in range(d):
                if q[nc + f * d + j] < least:
                    first, least = nc + f * d + j, q[nc + f * d + j]
            if least < 0.0:
                guess[first] = True
                guess[m + f] = True
    if not fits:
        return
    for e in range(nl):
        r = slots + lim[e]
        if r < basis.shape[0] and basis[r, BASIS_PRESENT] != 0:
            guess[nc + nd + e] = basis[r, BASIS_NORMAL] != 0
            guess[m + nf + e] = basis[r, BASIS_GAMMA] != 0


@numba.njit(cache=True, inline="always")
def _basis_kept(basis, basic_z, active, slot, fric, nf, d, lim, m):
    """The table (`basis_table`, shaped as the given one) of this step's final basis basic_z:
    the rows of its contacts and force-limited drives present, all others absent. A table of
    another shape than the LCP needs is replaced by one that fits nothing (no warm start)."""
    out = np.empty_like(basis)
    _fill_basis_kept(out, basis, basic_z, active, slot, fric, nf, d, lim, m)
    return out


@numba.njit(cache=True, inline="always")
def _fill_basis_kept(out, basis, basic_z, active, slot, fric, nf, d, lim, m):
    """`_basis_kept` into the caller's out (shaped as basis)."""
    for r in range(out.shape[0]):
        for c in range(out.shape[1]):
            out[r, c] = 0
    slots = slot.shape[0]
    if basis.shape[1] != BASIS_DIRECTIONS + d or basis.shape[0] < slots:
        return
    nc = active.shape[0]
    nl = lim.shape[0]
    nd = nf * d
    for k in range(nc):
        s = slot[active[k]]
        out[s, BASIS_PRESENT] = 1
        out[s, BASIS_NORMAL] = basic_z[k]
    for f in range(nf):
        s = slot[active[fric[f]]]
        out[s, BASIS_GAMMA] = basic_z[m + f]
        for j in range(d):
            out[s, BASIS_DIRECTIONS + j] = basic_z[nc + f * d + j]
    for e in range(nl):
        r = slots + lim[e]
        if r < basis.shape[0]:
            out[r, BASIS_PRESENT] = 1
            out[r, BASIS_NORMAL] = basic_z[nc + nd + e]
            out[r, BASIS_GAMMA] = basic_z[m + nf + e]


@numba.njit(cache=True, error_model="numpy")
def _min_norm_passive(Wp, MWp, psi_h, Wa_u, alpha, nc):
    """Passive speeds of eq. (8) with the actuated motion scaled by alpha (see kinematic_step);
    MWp = M_p^-1 W_p (the metric's inverse times the passive Jacobian)."""
    qlcp = np.empty(nc)
    for i in range(nc):
        qlcp[i] = psi_h[i] + alpha * Wa_u[i]
    Mlcp = np.ascontiguousarray(Wp.T) @ MWp
    lam, w, st, pivots = lemke_kernel(Mlcp, qlcp, DEFAULT_LEMKE_PIVOTS_PER_VARIABLE * (nc + 1))
    residual = complementarity_residual(Mlcp, qlcp, lam)
    ok = (st == STATUS_SOLVED or st == STATUS_SOLVED_INACCURATE) and residual <= LCP_TOLERANCE
    return MWp @ lam, ok, pivots, residual


@numba.njit(cache=True, error_model="numpy")
def actuated_dofs(v_index, nv):
    """Whether each of the nv DOFs is a drive's (v_index: the drives' DOFs)."""
    actuated = np.zeros(nv, np.bool_)
    for j in range(v_index.shape[0]):
        actuated[v_index[j]] = True
    return actuated


@numba.njit(cache=True, error_model="numpy")
def passive_metric_inverse(bi, bf, q, nv, actuated):
    """The kinematic rung's metric on the passive DOFs, inverted: M(q)^-1 restricted to them
    (the identity on actuated DOFs, which W_p does not reach). M is block diagonal by body."""
    M = mass_matrix(bi, bf, q, nv)
    for v in range(nv):
        if actuated[v] or M[v, v] <= 0.0:
            for k in range(nv):
                M[v, k] = 0.0
                M[k, v] = 0.0
            M[v, v] = 1.0
    return np.linalg.inv(M)


#: Bisection steps for the largest feasible fraction of a blocked kinematic step.
BLOCKED_BISECTIONS = 30


@numba.njit(cache=True, error_model="numpy")
def _passive_problem(nc, h, c_psi, c_bias, W_n, u_eff, actuated, nv):
    """Eq. (8)'s data: (W_p: W_n on the passive DOFs, psi / h + bias, W_a^T u)."""
    Wp = np.zeros((nv, nc))
    psi_h = np.zeros(nc)
    Wa_u = np.zeros(nc)
    for i in range(nc):
        psi_h[i] = c_psi[i] / h + c_bias[i, 0]
        for v in range(nv):
            if actuated[v]:
                Wa_u[i] += W_n[v, i] * u_eff[v]
            else:
                Wp[v, i] = W_n[v, i]
    return Wp, psi_h, Wa_u


@numba.njit(cache=True, error_model="numpy")
def _largest_feasible(Wp, MWp, psi_h, Wa_u, nc, residual):
    """A blocked kinematic command: the largest feasible fraction alpha of it, by bisection.
    Returns (alpha, passive speeds, feasible: standing still is, pivots, residual: the accepted
    (largest feasible) solve's, else, when not even standing still is feasible, the one passed in).
    A command jammed outright keeps alpha = 0, and reports the standing-still solve's residual,
    not the infeasible full command's."""
    lo, hi = 0.0, 1.0
    v_lo, ok_lo, pivots, res = _min_norm_passive(Wp, MWp, psi_h, Wa_u, 0.0, nc)
    if not ok_lo:
        return 0.0, v_lo, False, pivots, residual
    residual = res
    for _ in range(BLOCKED_BISECTIONS):
        mid = 0.5 * (lo + hi)
        v_mid, ok_mid, piv, res = _min_norm_passive(Wp, MWp, psi_h, Wa_u, mid, nc)
        pivots += piv
        if ok_mid:
            lo, v_lo, residual = mid, v_mid, res
        else:
            hi = mid
    return lo, v_lo, True, pivots, residual


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def kinematic_free_step_into(bi, h, q, u, q_index, v_index, lower, upper, q_new, nu_new, q_ref_new):
    """`kinematic_step` without contacts (nc = 0: nothing to solve, the passive DOFs rest) into
    the caller's q_new, nu_new, q_ref_new, compiled without numba's runtime (the rollout's runs
    of free steps, `models.rollout._free_run`): the same operations in the same order, the same
    bits (tests/test_model_family.py). Returns whether q+ and nu+ are finite and bounded (else
    the caller takes `kinematic_step` for the status)."""
    for v in range(nu_new.shape[0]):
        nu_new[v] = 0.0
    for j in range(v_index.shape[0]):  # (q_ref_new: one reference a drive, each written here)
        target = min(max(q[q_index[j]] + h * u[j], lower[j]), upper[j])
        nu_new[v_index[j]] = 1.0 * ((target - q[q_index[j]]) / h)  # alpha u_eff, alpha = 1
        q_ref_new[j] = q[q_index[j]] + h * 1.0 * nu_new[v_index[j]]
    _integrate_positions_into(bi, q, nu_new, h, q_new)
    return _finite_and_bounded(q_new) and _finite_and_bounded(nu_new)


@numba.njit(cache=True, error_model="numpy")
def kinematic_step(bi, bf, h, q, q_ref, u, q_index, v_index, lower, upper, nc, c_psi, c_bias, W_n, nv, metric):
    """The paper's eq. (8) given the contacts at q. Returns (q+, nu+, q_ref+, status: a
    StepStatus value, pivots, residual). Plain arrays, as `free_step` (a cheap step). metric:
    `passive_metric_inverse` at q where the rollout holds it (M constant: no rotating body;
    the same array, in its layout, as computed here: the same bits), else empty (0 x 0), and it
    is computed here where contacts need it.

    Actuated DOFs move at the commanded speed (stopping at their position limits; a kinematic
    model has no forces, so a drive's force limit does not apply); c_bias[i, 0] is contact i's
    normal speed from scripted obstacles (a scripted obstacle pushes like an actuator); the
    passive speeds v are the least-norm ones keeping every contact's psi + h W_n^T nu >= 0, in
    the kinetic-energy metric: min v^T M_p v s.t. W_p^T v >= -(psi / h + W_a^T u). The paper
    prints eq. (8) with |nu|^2, which mixes metres and radians (a push off a box's centre line
    then barely turns it); M_p makes the norm unit-free and is the selection the quasistatic
    rung's limit makes (the least kinetic energy motion), without friction and gravity, so a
    push turns a body as it turns a body free of friction (tests/test_kinematic_metric.py).
    Its dual is the LCP 0 <= lam _|_ W_p^T M_p^-1 W_p lam + (psi / h + W_a^T u) >= 0 with
    v = M_p^-1 W_p lam, solved by Lemke (tests check it against the OSQP wrapper).

    A command that pushes into something nothing can move (the two fingers closing on the
    triangle: form closure) has no solution. The kinematic model then moves the actuators by
    the largest feasible fraction of the step (bisection), so the world jams: a state, not an
    error. StepStatus.BLOCKED only when not even standing still is feasible.
    """
    na = v_index.shape[0]
    nu = np.zeros(nv)
    u_eff = np.zeros(nv)
    actuated = actuated_dofs(v_index, nv)
    for j in range(na):
        target = min(max(q[q_index[j]] + h * u[j], lower[j]), upper[j])
        u_eff[v_index[j]] = (target - q[q_index[j]]) / h
    pivots = 0
    residual = 0.0
    alpha = 1.0
    status = StepStatus.OK.value
    v_passive = np.zeros(nv)
    if nc > 0:
        Wp, psi_h, Wa_u = _passive_problem(nc, h, c_psi, c_bias, W_n, u_eff, actuated, nv)
        if metric.shape[0] == nv:
            MWp = metric @ Wp
        else:
            MWp = passive_metric_inverse(bi, bf, q, nv, actuated) @ Wp
        v_passive, ok, pivots, residual = _min_norm_passive(Wp, MWp, psi_h, Wa_u, 1.0, nc)
        if not ok:
            alpha, v_passive, feasible, more, residual = _largest_feasible(Wp, MWp, psi_h, Wa_u, nc, residual)
            pivots += more
            if not feasible:
                status = StepStatus.BLOCKED.value
    if status != StepStatus.OK:
        return q, nu, q_ref, status, pivots, residual
    q_ref_new = q_ref.copy()
    for j in range(na):
        q_ref_new[j] = q[q_index[j]] + h * alpha * u_eff[v_index[j]]
    for v in range(nv):
        nu[v] = alpha * u_eff[v] if actuated[v] else v_passive[v]
    q_new = integrate_positions(bi, q, nu, h)
    if not (_finite_and_bounded(q_new) and _finite_and_bounded(nu)):
        return q, nu, q_ref, StepStatus.NON_FINITE.value, pivots, residual
    return q_new, nu, q_ref_new, status, pivots, residual

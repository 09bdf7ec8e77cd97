"""Projected Gauss-Seidel (PGS) on the contact impulses of one step, sparse by body.

The problem is the one `models.stepper.contact_lcp` hands to Lemke (Stewart-Trinkle, the same
polyhedral friction cone), written in the impulses of each active contact k instead of LCP
variables. With the free velocity nu_free and A from `models.stepper`,

    nu+ = nu_free + A^-1 sum_k (W_n,k p_n,k + W_t,k f_k[0] + W_o,k f_k[1])

    0 <= p_n,k  _|_  w_k = psi_k / h + W_n,k^T nu+ + c_k (p_n,k + C_k delta_n,k) >= 0
    f_k in P_k = P(mu_k p_n,k) with u_k^T (f' - f_k) >= 0 for every f' in P_k,
    u_k = (W_t,k, W_o,k)^T nu+ + c_k f_k - K_k / (h K_k + C_k) delta_t,k

where c_k = 1 / (h (h K + C)) for compliant contact (0 for rigid) and P(r) is the polygon with
vertices r (cos 2 pi j / d, sin 2 pi j / d), j < d, in the contact's (t, o) basis (planar: the
segment [-r, r] along t). The variational inequality on f is maximal dissipation over the
polygon: it is exactly the complementarity of Lemke's (beta, gamma) rows, since the polygon is
the image of {beta >= 0, sum beta <= mu p_n} under the direction matrix (tests compare them).

A sweep first sets each contact's p_n to the exact minimiser of its scalar problem (clamped at
0), then each friction impulse f to the exact minimiser of its tangential block over its
polygon (the unconstrained point if it lies inside, else the best point on an edge), with
everything else held. Warm start: impulses from the previous step (by contact slot), clipped
into their cones.

Known limits (tests and `ladder bench` show them): rigid contacts with more impulses than the
bodies have DOFs (a box flat on a plane: two corners, two frictions, three DOFs) leave a
workless part of the friction undetermined, and PGS may return any admissible one where
regularised Lemke returns the smallest; tall rigid stacks and squeezes converge slowly (a
stack of 8 boxes does not converge in 1000 sweeps from a cold start), which comes back as a
status.

Sparsity: A is block diagonal by body (the mass matrix is, and each drive acts on one DOF) and a
contact's Jacobian columns are nonzero only on the DOFs of its two bodies. Each contact keeps
its Jacobian rows and the matching entries of A^-1 W (at most CONTACT_DOFS numbers), nu+ is kept
up to date as impulses change, and a sweep costs O(contacts): the Delassus matrix W^T A^-1 W is
never formed.

Convergence and residual: sweeps stop once the recomputed residual is at most tolerance. The
residual is the natural-map residual in impulse units, max over contacts of |min(p_n, w / G_nn)|
and |f - f*| (f* the tangential block minimiser at the current point), divided by the impulse
scale (the largest impulse, or the largest impulse that would stop a contact's free approach).
It costs most of a sweep, so it is recomputed after the first sweep and then only once the
largest impulse change of a sweep (relative to the same scale) predicts it passes
(`RESIDUAL_CHECK`), and at least every `RESIDUAL_EVERY` sweeps. Failing that within
max_sweeps (the residual after the last sweep is recomputed and decides) comes back as
PgsStatus.NOT_CONVERGED, never raised, unless the cone is the exact one in space: there
`contact_pgs` first hands PGS's iterate to `aligned_lemke_into` (Lemke on polygons turned to put
a vertex on each contact's friction), whose solution is kept only where this residual passes.
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numba
import numpy as np

from models.kinematics import BI_VMAP, PF_C, PF_K, PF_MU, PI_A, PI_B
from models.lcp import (
    DEFAULT_LEMKE_PIVOTS_PER_VARIABLE,
    LCP_REGULARIZATION,
    LCP_REGULARIZATION_STEPS,
    STATUS_SOLVED,
    STATUS_SOLVED_INACCURATE,
    lemke_kernel,
)

#: Velocity slots of a body (x, y, z, angle rate, wx, wy, wz: `models.kinematics` vmap).
BODY_DOFS = 7
#: A contact touches the DOFs of at most two bodies.
CONTACT_DOFS = 2 * BODY_DOFS
#: A body block of A with a pivot below this times its largest entry counts as singular.
SINGULAR_PIVOT = 1e-14
#: A 2x2 tangential block with det <= this times trace^2 counts as singular (rank 1 or 0).
SINGULAR_BLOCK = 1e-12
#: A point is inside a friction polygon when no edge has it outside by more than this
#: (relative to the polygon's radius).
INSIDE_TOL = 1e-12
#: The exact cone's pivoting (`aligned_lemke_into`): the friction directions of the polygons it
#: aligns with each contact's friction, and how many alignments it tries. On box_push_3d's push,
#: from PGS's iterate after one sweep and after three (4,000 steps), every step passed 1e-6
#: with 54 pivots; at PGS's creeping state after 1000 sweeps, with 59. An unscaled first
#: version allowed 3 rounds, where a copy in numpy needed 3 to 5 (docs/measurements.md).
ALIGNED_DIRECTIONS = 4
ALIGNED_ROUNDS = 8
#: There, a friction impulse within this of its disk's edge (relative to the radius) slides.
EDGE_TOL = 1e-9


class PgsStatus(IntEnum):
    """How a PGS solve ended; only CONVERGED is a success. Users meet it as the step's
    `models.stepper.StepStatus` (CONTACT_NOT_CONVERGED or NON_FINITE), whose message says why."""

    CONVERGED = 0  # the recomputed residual is within the tolerance
    NOT_CONVERGED = 1  # the sweep limit was reached first
    NON_FINITE = 2  # the impulses or the residual became non-finite


class PgsResult(NamedTuple):
    """What `contact_pgs` returns."""

    nu: np.ndarray  # (nv,) nu+
    p_n: np.ndarray  # (nc,) normal impulses, zero where inactive
    p_t: np.ndarray  # (nc, 2) friction impulses in the (t, o) basis, zero where inactive
    active: np.ndarray  # int64: indices of the active contacts
    status: int  # a PgsStatus value
    sweeps: int
    residual: float  # natural-map residual over the impulse scale (see the module docstring)
    unknowns: int  # scalar impulses solved for
    pivots: int  # Lemke pivots of the exact cone's pivoting (`aligned_lemke_into`; 0 where PGS converged)


# ----------------------------------------------------------------------------- A by body


@numba.njit(cache=True)
def _invert_small(B, m, out):
    """out[:m, :m] = B[:m, :m]^-1 by Gauss-Jordan with partial pivoting; False if singular."""
    return _invert_small_into(B, m, out, np.zeros((m, 2 * m)))


@numba.njit(cache=True, inline="always")
def _invert_small_into(B, m, out, work):
    """`_invert_small` on the caller's work (at least (m, 2 m)), zeroed here. A 6 x 6 block of
    a free rigid body in space (`_split`) is inverted by its parts (`_invert_split_into`: the
    translations' reciprocals, the rotations' adjugate)."""
    if m == 6 and _split(B):
        return _invert_split_into(B, out)
    for r in range(m):
        for c in range(2 * m):
            work[r, c] = 0.0
    big = 0.0
    for r in range(m):
        for c in range(m):
            work[r, c] = B[r, c]
            big = max(big, abs(B[r, c]))
        work[r, m + r] = 1.0
    if not (big > 0.0):
        return False
    if not _gauss_jordan(work, m, big):
        return False
    for r in range(m):
        for c in range(m):
            out[r, c] = work[r, m + c]
    return True


@numba.njit(cache=True, inline="always")
def _gauss_jordan(work, m, big):
    """Gauss-Jordan with partial pivoting on work[:m, :2 m] = [B | I], in place (B^-1 ends in
    work[:m, m:]); a pivot at most SINGULAR_PIVOT times big (B's largest entry) is singular:
    returns False."""
    for k in range(m):
        p = k
        for r in range(k + 1, m):
            if abs(work[r, k]) > abs(work[p, k]):
                p = r
        if not (abs(work[p, k]) > SINGULAR_PIVOT * big):
            return False
        if p != k:
            for c in range(2 * m):
                work[k, c], work[p, c] = work[p, c], work[k, c]
        inv = 1.0 / work[k, k]
        for c in range(2 * m):
            work[k, c] *= inv
        for r in range(m):
            if r != k and work[r, k] != 0.0:
                f = work[r, k]
                for c in range(2 * m):
                    work[r, c] -= f * work[k, c]
    return True


@numba.njit(cache=True, inline="always")
def _split(B):
    """Whether a 6 x 6 block (a rigid body in space: translations, then rotations) is zero but
    on the translations' diagonal and the rotations' 3 x 3 block: a free body's (m on the
    translations, R I R^T on the rotations, no drive coupling them). `_invert_small_into`
    inverts such a block by its parts, and `models.stepper._delassus_into` and PGS's
    `_apply_inverse` leave out the zero entries' products of its inverse (also split): their
    terms are +-0 added to sums that start at +0, so the bits are the same (for finite
    Jacobians, the only ones a step keeps)."""
    for r in range(6):
        for c in range(6):
            if r != c and (r < 3 or c < 3) and B[r, c] != 0.0:
                return False
    return True


@numba.njit(cache=True, inline="always")
def _invert_split_into(B, out):
    """B^-1 of a `_split` 6 x 6 block into out: 1 / B[k, k] on the translations, the rotations'
    3 x 3 block by its adjugate over its determinant (`_invert_3x3_into`), zero elsewhere.
    Singular as `_gauss_jordan` judges a pivot: a translation's diagonal at most SINGULAR_PIVOT
    times the whole block's largest entry, or the rotations' determinant as
    `_invert_3x3_into` judges it."""
    big = 0.0
    for r in range(6):
        for c in range(6):
            big = max(big, abs(B[r, c]))
    if not (big > 0.0):
        return False
    for k in range(3):
        if not (abs(B[k, k]) > SINGULAR_PIVOT * big):
            return False
    for r in range(6):
        for c in range(6):
            out[r, c] = 0.0
    for k in range(3):
        out[k, k] = 1.0 / B[k, k]
    return _invert_3x3_into(B, 3, big, out)


@numba.njit(cache=True, inline="always")
def _invert_3x3_into(B, o, big, out):
    """out[o:o + 3, o:o + 3] = B[o:o + 3, o:o + 3]^-1 by the adjugate over the determinant (a
    rigid body's world inertia, R I R^T, times eps: symmetric positive definite, whose inverse
    the rotations' rows of A^-1 are); False, out untouched, where the determinant is at most
    SINGULAR_PIVOT big r^2 (big: the whole block's largest entry, r: this 3 x 3's; as
    `_gauss_jordan` holds its smallest pivot to SINGULAR_PIVOT big, the other two at most about
    r) or not finite. A fifth of Gauss-Jordan's cost on the 3 x 6 [B | I] with pivoting, which
    it replaced (box_push_3d's step, docs/measurements.md), and as accurate on such a block
    (tests/test_rotating_blocks.py)."""
    a, b, c = B[o, o], B[o, o + 1], B[o, o + 2]
    d, e, f = B[o + 1, o], B[o + 1, o + 1], B[o + 1, o + 2]
    g, h, i = B[o + 2, o], B[o + 2, o + 1], B[o + 2, o + 2]
    r = 0.0
    for x in (a, b, c, d, e, f, g, h, i):
        r = max(r, abs(x))
    c00, c10, c20 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * c00 + b * c10 + c * c20
    if not (abs(det) > SINGULAR_PIVOT * big * r * r and np.isfinite(det)):
        return False
    s = 1.0 / det
    out[o, o], out[o, o + 1], out[o, o + 2] = c00 * s, (c * h - b * i) * s, (b * f - c * e) * s
    out[o + 1, o], out[o + 1, o + 1], out[o + 1, o + 2] = c10 * s, (a * i - c * g) * s, (c * d - a * f) * s
    out[o + 2, o], out[o + 2, o + 1], out[o + 2, o + 2] = c20 * s, (b * g - a * h) * s, (a * e - b * d) * s
    return True


@numba.njit(cache=True)
def body_blocks(bi, A, Ainv):
    """The blocks of A^-1 per body (A is block diagonal by body).

    Returns (dofs (nb, BODY_DOFS) nu indices, -1 padded; count (nb,); inv (nb, BODY_DOFS,
    BODY_DOFS) with inv[b, :count, :count] = (A restricted to body b's DOFs)^-1; ok). Read from
    Ainv when it is given (shape (nv, nv)), else each block of A is inverted; ok is False when
    a block is singular.
    """
    nb = bi.shape[0]
    dofs = np.full((nb, BODY_DOFS), -1, np.int64)
    count = np.zeros(nb, np.int64)
    inv = np.zeros((nb, BODY_DOFS, BODY_DOFS))
    ok = body_blocks_into(bi, A, Ainv, dofs, count, inv, np.zeros((BODY_DOFS, BODY_DOFS)), np.zeros((BODY_DOFS, 2 * BODY_DOFS)))
    return dofs, count, inv, ok


@numba.njit(cache=True, inline="always")
def body_blocks_into(bi, A, Ainv, dofs, count, inv, block, work):
    """`body_blocks` into the caller's dofs (nb, BODY_DOFS), count (nb,) and inv (nb,
    BODY_DOFS, BODY_DOFS), with the scratch block (BODY_DOFS, BODY_DOFS) and work (BODY_DOFS,
    2 BODY_DOFS). Sets dofs, count and each body's inv[b, :count, :count], the only entries
    its readers take (loops to count[b]; `_split` on a block of 6): the rest of inv is left as
    it was (zeroing it was 216 stores a step at box_push_3d's five bodies). Returns ok."""
    nb = bi.shape[0]
    for b in range(nb):
        for r in range(BODY_DOFS):
            dofs[b, r] = -1
    have_inverse = Ainv.shape[0] == A.shape[0]
    for b in range(nb):
        m = np.int64(0)
        for s in range(BODY_DOFS):
            v = bi[b, BI_VMAP + s]
            if v >= 0:
                dofs[b, m] = v
                m += 1
        count[b] = m
        for r in range(m):
            for c in range(m):
                if have_inverse:
                    inv[b, r, c] = Ainv[dofs[b, r], dofs[b, c]]
                else:
                    block[r, c] = A[dofs[b, r], dofs[b, c]]
        if m > 0 and not have_inverse:
            if not _invert_small_into(block, m, inv[b], work):
                return False
    return True


@numba.njit(cache=True, inline="always")
def block_solve_into(dofs, count, inv, rhs, out):
    """A^-1 rhs from the body blocks of `body_blocks`, O(bodies), into the caller's out
    (rhs.shape[0] entries), zeroed here."""
    for v in range(rhs.shape[0]):
        out[v] = 0.0
    for b in range(count.shape[0]):
        for r in range(count[b]):
            s = 0.0
            for c in range(count[b]):
                s += inv[b, r, c] * rhs[dofs[b, c]]
            out[dofs[b, r]] = s


# ----------------------------------------------------------------------------- one contact's blocks


# Rows are passed as (2-D array, row index), not as row views: a view is a new array object
# whose reference counting costs more than the few products of a contact.


@numba.njit(cache=True, inline="always")
def _dot(J, k, cdof, m, v):
    """J[k] . v on contact k's DOFs."""
    s = 0.0
    for j in range(m):
        s += J[k, j] * v[cdof[k, j]]
    return s


@numba.njit(cache=True, inline="always")
def _add(Y, k, cdof, m, scale, v):
    """v += scale Y[k] on contact k's DOFs."""
    for j in range(m):
        v[cdof[k, j]] += scale * Y[k, j]


@numba.njit(cache=True, inline="always")
def _apply_inverse(inv, a, b, ca, cb, J, Y, k, split_a, split_b):
    """Y[k] = A^-1 J[k] on contact k's DOFs (body a's first ca entries, then body b's cb).
    split_a, split_b: whether body a's, b's block is `_split` (6 DOFs), whose zero entries'
    products are left out (the same bits: `_split`)."""
    _apply_block(inv, a, ca, J, Y, k, 0, split_a)
    _apply_block(inv, b, cb, J, Y, k, ca, split_b)


@numba.njit(cache=True, inline="always")
def _apply_block(inv, b, m, J, Y, k, offset, split):
    """Y[k, offset:offset + m] = inv[b, :m, :m] J[k, offset:offset + m] (`_apply_inverse`,
    `models.stepper._delassus_into`'s Yb): each sum from +0 in the order of its columns, a
    `_split` block's zero entries' terms left out."""
    if split:
        for r in range(3):
            s = 0.0
            s += inv[b, r, r] * J[k, offset + r]
            Y[k, offset + r] = s
        for r in range(3, 6):
            s = 0.0
            for c in range(3, 6):
                s += inv[b, r, c] * J[k, offset + c]
            Y[k, offset + r] = s
        return
    if m == 6:  # (a trip count the compiler knows: a body in space)
        for r in range(6):
            s = 0.0
            for c in range(6):
                s += inv[b, r, c] * J[k, offset + c]
            Y[k, offset + r] = s
        return
    for r in range(m):
        s = 0.0
        for c in range(m):
            s += inv[b, r, c] * J[k, offset + c]
        Y[k, offset + r] = s


@numba.njit(cache=True, inline="always")
def _inside(f0, f1, radius, cosines, sines):
    """Whether (f0, f1) lies in the polygon of `polygon_minimiser` (no vertices: the disk of
    the exact cone)."""
    if not (radius > 0.0):
        return f0 == 0.0 and f1 == 0.0
    d = cosines.shape[0]
    if d == 0:
        return f0 * f0 + f1 * f1 <= (1.0 + INSIDE_TOL) * radius * radius
    for j in range(d):
        j2 = (j + 1) % d
        ax, ay = radius * cosines[j], radius * sines[j]
        ex, ey = radius * cosines[j2] - ax, radius * sines[j2] - ay
        if ex * (f1 - ay) - ey * (f0 - ax) < -INSIDE_TOL * radius * radius:
            return False
    return True


@numba.njit(cache=True, inline="always")
def polygon_minimiser(f0, f1, u0, u1, g00, g01, g11, radius, cosines, sines):
    """argmin over f in P(radius) of u.(f - f_old) + 1/2 (f - f_old)^T G (f - f_old).

    f_old = (f0, f1), u the tangential velocity at f_old, G = [[g00, g01], [g01, g11]] positive
    semidefinite, P(radius) the convex polygon with vertices radius (cosines[j], sines[j]) in
    counter-clockwise order. The unconstrained minimiser when G is regular and it lies inside;
    else the best point on the boundary, which also attains the minimum when G is singular and
    its line of minimisers meets P.
    """
    if not (radius > 0.0):
        return 0.0, 0.0
    if cosines.shape[0] == 0:  # no vertices: the exact cone's disk
        return disk_minimiser(f0, f1, u0, u1, g00, g01, g11, radius)
    det = g00 * g11 - g01 * g01
    trace = g00 + g11
    if det > SINGULAR_BLOCK * trace * trace:
        n0 = f0 - (g11 * u0 - g01 * u1) / det
        n1 = f1 - (g00 * u1 - g01 * u0) / det
        if _inside(n0, n1, radius, cosines, sines):
            return n0, n1
    best, b0, b1 = np.inf, 0.0, 0.0
    d = cosines.shape[0]
    for j in range(d):
        j2 = (j + 1) % d
        a0, a1 = radius * cosines[j], radius * sines[j]
        e0, e1 = radius * cosines[j2] - a0, radius * sines[j2] - a1
        x0, x1 = a0 - f0, a1 - f1  # start of the edge relative to f_old
        g0 = u0 + g00 * x0 + g01 * x1  # gradient at the start of the edge
        g1 = u1 + g01 * x0 + g11 * x1
        slope = g0 * e0 + g1 * e1
        curve = e0 * (g00 * e0 + g01 * e1) + e1 * (g01 * e0 + g11 * e1)
        if curve > 0.0:
            s = min(max(-slope / curve, 0.0), 1.0)
        else:
            s = 1.0 if slope < 0.0 else 0.0
        p0, p1 = x0 + s * e0, x1 + s * e1
        value = u0 * p0 + u1 * p1 + 0.5 * (p0 * (g00 * p0 + g01 * p1) + p1 * (g01 * p0 + g11 * p1))
        if value < best:
            best, b0, b1 = value, f0 + p0, f1 + p1
    return b0, b1


#: PGS recomputes its residual once a sweep's change (relative to the largest impulse) is at
#: most this times the tolerance, and after the first sweep (`_sweeps`). On box_push_3d's push the
#: residual after a sweep is 0.15-0.2 of that sweep's change: 10 checks one sweep early, and
#: after a failed check the next one waits for the change that check predicts.
RESIDUAL_CHECK = 10.0

#: ... and at least once in this many sweeps: a sweep's change does not always follow the
#: residual (on box_push_3d's turning push the friction disks creep along the four corners'
#: undetermined share of the load, the change stays up while the residual falls: a step whose
#: residual passed after 4 sweeps waited 49,631 for the change its last check predicted).
RESIDUAL_EVERY = 8

#: Newton iterations of the disk minimiser's multiplier (it converges in a handful).
DISK_ITERATIONS = 60


@numba.njit(cache=True)
def disk_minimiser(f0, f1, u0, u1, g00, g01, g11, radius):
    """argmin over |f| <= radius of u.(f - f_old) + 1/2 (f - f_old)^T G (f - f_old): the
    friction block of the exact Coulomb cone (eq. 4: every direction of sliding meets exactly
    mu p_n), as `polygon_minimiser` is of the polygon. In x = f it is the trust-region problem
    min 1/2 x^T G x + c^T x, |x| <= radius, c = u - G f_old: the unconstrained minimiser when it
    lies inside, else x(lam) = -(G + lam I)^-1 c on the circle, lam >= 0 the root of
    1/|x(lam)| - 1/radius (safeguarded Newton in G's eigenbasis; that function is increasing
    and nearly linear in lam). G singular with c in its range: of the minimisers, the one
    nearest f_old."""
    if not (radius > 0.0):
        return 0.0, 0.0
    c0 = u0 - (g00 * f0 + g01 * f1)
    c1 = u1 - (g01 * f0 + g11 * f1)
    det = g00 * g11 - g01 * g01
    trace = g00 + g11
    if det > SINGULAR_BLOCK * trace * trace:
        x0 = -(g11 * c0 - g01 * c1) / det
        x1 = -(g00 * c1 - g01 * c0) / det
        if x0 * x0 + x1 * x1 <= radius * radius:
            return x0, x1
    # G = a e_a e_a^T + b e_b e_b^T, a >= b >= 0
    half = 0.5 * (g00 - g11)
    root = np.sqrt(half * half + g01 * g01)
    a, b = max(0.5 * trace + root, 0.0), max(0.5 * trace - root, 0.0)
    # e_a at half the angle of (g00 - g11, 2 g01), without trigonometry: (root + half, g01) has
    # that angle, and (g01, root - half) the same up to sign where the first one cancels
    ea0, ea1 = (root + half, g01) if half >= 0.0 else (g01, root - half)
    size_e = np.sqrt(ea0 * ea0 + ea1 * ea1)
    ea0, ea1 = (ea0 / size_e, ea1 / size_e) if size_e > 0.0 else (1.0, 0.0)
    eb0, eb1 = -ea1, ea0
    ca, cb = c0 * ea0 + c1 * ea1, c0 * eb0 + c1 * eb1
    size_c = np.sqrt(c0 * c0 + c1 * c1)
    if size_c == 0.0:
        return 0.0, 0.0
    tiny = SINGULAR_BLOCK * max(trace, 1e-300)
    if b <= tiny and abs(cb) <= SINGULAR_BLOCK * size_c:
        # singular, c in the range: minimisers -ca/a e_a + t e_b; the one nearest f_old, in the disk
        xa = -ca / a if a > tiny else 0.0
        if xa * xa <= radius * radius:
            reach = np.sqrt(radius * radius - xa * xa)
            t = min(max(f0 * eb0 + f1 * eb1, -reach), reach)
            return xa * ea0 + t * eb0, xa * ea1 + t * eb1
    # |c| / (a + lam) <= |x(lam)| <= |c| / (b + lam): the root lies in [|c| / radius - a,
    # |c| / radius - b] (an interval no wider than a - b: a point where G is isotropic), and
    # Newton starts at its lower end
    lo, hi = max(size_c / radius - a, 0.0), max(size_c / radius - b, 0.0)
    lam = lo
    for _ in range(DISK_ITERATIONS):
        da, db = a + lam, b + lam
        if not (da > 0.0 and db > 0.0):
            lam = 0.5 * (lo + hi) if lam <= lo else lam
            da, db = a + lam, b + lam
        xa, xb = -ca / da, -cb / db
        size = np.sqrt(xa * xa + xb * xb)
        value = 1.0 / size - 1.0 / radius
        if value < 0.0:
            lo = lam
        else:
            hi = lam
        if abs(value) * radius <= 1e-15 or hi - lo <= 1e-15 * hi:
            break
        slope = (ca * ca / (da * da * da) + cb * cb / (db * db * db)) / (size * size * size)
        step = lam - value / slope if slope > 0.0 else 0.5 * (lo + hi)
        lam = step if lo < step < hi else 0.5 * (lo + hi)
    da, db = a + lam, b + lam
    xa, xb = -ca / da, -cb / db
    size = np.sqrt(xa * xa + xb * xb)
    if size > radius:  # round-off: onto the circle
        xa, xb = xa * radius / size, xb * radius / size
    return xa * ea0 + xb * eb0, xa * ea1 + xb * eb1


@numba.njit(cache=True, inline="always")
def _tangential_update(spatial, f0, f1, u0, u1, g00, g01, g11, bound, cosines, sines):
    """The minimiser of a contact's tangential block with the rest held: f_old = (f0, f1), u
    its tangential velocity, G its block, bound = mu p_n (in space over the cone's polygon, or
    the exact cone's disk; in the plane the clamp to [-bound, bound])."""
    if not spatial:
        return min(max(f0 - u0 / g00, -bound), bound), 0.0
    if cosines.shape[0] == 0:
        return disk_minimiser(f0, f1, u0, u1, g00, g01, g11, bound)
    return polygon_minimiser(f0, f1, u0, u1, g00, g01, g11, bound, cosines, sines)


# ----------------------------------------------------------------------------- the solver


class PgsWork(NamedTuple):
    """The arrays of a PGS solve (`pgs_work`) for up to cap contacts and d friction directions:
    each active contact's rows, which `_gather_contacts_into` sets (its DOFs cdof, cm of them;
    Jacobian rows jn, jt, jo; y = A^-1 J^T rows yn, yt, yo; the Delassus blocks gnn, g00, g01,
    g11, compliance comp; the constant terms bn, bt; mu; whether it has friction), its
    impulses p_n, f and the directions' cosines and sines. Made per call by `contact_pgs`,
    once per rollout for `models.stepper.pgs_warm_step`."""

    cosines: np.ndarray  # (d,)
    sines: np.ndarray  # (d,)
    cdof: np.ndarray  # (cap, CONTACT_DOFS) int
    cm: np.ndarray  # (cap,) int
    jn: np.ndarray  # (cap, CONTACT_DOFS)
    jt: np.ndarray
    jo: np.ndarray
    yn: np.ndarray
    yt: np.ndarray
    yo: np.ndarray
    active: np.ndarray  # (cap,) int: the active contacts' indices
    fric: np.ndarray  # (cap,) bool
    gnn: np.ndarray  # (cap,)
    g00: np.ndarray
    g01: np.ndarray
    g11: np.ndarray
    comp: np.ndarray
    bn: np.ndarray
    bt: np.ndarray  # (cap, 2)
    mu: np.ndarray  # (cap,)
    p_n: np.ndarray  # (cap,) normal impulses of the active contacts
    f: np.ndarray  # (cap, 2) their friction impulses in the (t, o) basis


@numba.njit(cache=True)
def pgs_work(cap, d):
    """`PgsWork` for up to cap contacts and d friction directions."""
    rows = (cap, CONTACT_DOFS)
    return PgsWork(
        np.empty(d),
        np.empty(d),
        np.empty(rows, np.int64),
        np.empty(cap, np.int64),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(cap, np.int64),
        np.empty(cap, np.bool_),
        np.empty(cap),
        np.empty(cap),
        np.empty(cap),
        np.empty(cap),
        np.empty(cap),
        np.empty(cap),
        np.empty((cap, 2)),
        np.empty(cap),
        np.empty(cap),
        np.empty((cap, 2)),
    )


@numba.njit(cache=True, inline="always")
def _pgs_directions(model, spatial):
    """The friction directions PGS's polygon has: 0 for the exact cone's disk in space."""
    return (0 if model.exact_cone else model.friction_directions) if spatial else 2


@numba.njit(cache=True, inline="always")
def cone_directions_into(cosines, sines):
    """The polygonal friction cone's d = cosines.shape[0] directions in a contact's (t, o)
    plane, evenly around it from t: cos and sin of 2 pi j / d, into the caller's arrays."""
    d = cosines.shape[0]
    for j in range(d):
        cosines[j] = np.cos(2.0 * np.pi * j / d)
        sines[j] = np.sin(2.0 * np.pi * j / d)


@numba.njit(cache=True)
def contact_pgs(
    model,
    spatial,
    h,
    pi,
    pf,
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
    zero_column,
    tolerance,
    max_sweeps,
):
    """Solve the contact problem of the module docstring by PGS.

    model: `models.stepper.Model` (compliant, friction_directions); contacts: a
    `models.contact.ContactSet`, contacts 0..nc-1 with Jacobian columns W_n, W_t (W_o in
    space) of shape (nv, >= nc); a contact is active when its W_n column's norm exceeds
    zero_column, and has friction when mu > 0 and W_t (or W_o) exceeds it. bias (>= nc, 3):
    relative velocity along (n, t, o) from scripted obstacles, added to the contact's
    velocity. (dofs, count, inv): `body_blocks` of A. warm_n (slots,), warm_t (slots, 2): the
    previous step's impulses by contact slot (zeros: a cold start).

    Returns a `PgsResult`.
    """
    P = pgs_work(nc, _pgs_directions(model, spatial))
    v = np.empty(nu_free.shape[0])
    status, sweeps, residual, unknowns, n = contact_pgs_into(
        model, spatial, h, pi, pf, contacts, nc, delta_n, delta_t, dofs, count, inv, nu_free, warm_n, warm_t, zero_column, tolerance,
        max_sweeps, P, v,
    )  # fmt: skip
    pivots = 0
    if status == PgsStatus.NOT_CONVERGED.value and spatial and model.exact_cone:
        scale = _impulse_scale(n, P.cdof, P.cm, P.jn, P.gnn, P.bn, nu_free)
        solved, pivots, aligned_residual = aligned_lemke_into(  # n as int64: not also compiled for a literal 0
            np.int64(n), P.cdof, P.cm, P.jn, P.jt, P.jo, P.yn, P.yt, P.yo, P.gnn, P.g00, P.g01, P.g11, P.comp, P.bn, P.bt, P.mu, P.fric,
            P.p_n, P.f, nu_free, v, scale, tolerance,
        )  # fmt: skip
        if solved:
            status, residual = PgsStatus.CONVERGED.value, aligned_residual
    p_out, t_out = np.empty(nc), np.empty((nc, 2))
    _by_contact_into(nc, P.active[:n], P.p_n[:n], P.f[:n], p_out, t_out)
    return PgsResult(v, p_out, t_out, P.active[:n], status, sweeps, residual, unknowns, pivots)


@numba.njit(cache=True, inline="always")
def _by_contact_into(nc, active, p_n, p_t, impulses, frictions):
    """The active contacts' impulses p_n (n_act), p_t (n_act, 2) by contact: impulses (nc),
    frictions (nc, 2), zeros for the contacts not active."""
    for i in range(nc):
        impulses[i] = 0.0
        frictions[i, 0] = 0.0
        frictions[i, 1] = 0.0
    for k in range(active.shape[0]):
        impulses[active[k]] = p_n[k]
        frictions[active[k], 0] = p_t[k, 0]
        frictions[active[k], 1] = p_t[k, 1]


@numba.njit(cache=True, inline="always")
def contact_pgs_into(
    model, spatial, h, pi, pf, contacts, nc, delta_n, delta_t, dofs, count, inv, nu_free, warm_n, warm_t, zero_column, tolerance,
    max_sweeps, P, v,
):  # fmt: skip
    """`contact_pgs` on the caller's arrays: P (`PgsWork` for at least nc contacts and the
    directions `_pgs_directions` gives) and v (nv), nu+. Returns (status: a PgsStatus value,
    sweeps, residual, unknowns, n): the n active contacts are P.active[:n], their impulses
    P.p_n[:n] and P.f[:n]."""
    d = _pgs_directions(model, spatial)
    cosines, sines = P.cosines[:d], P.sines[:d]
    cone_directions_into(cosines, sines)
    for i in range(nu_free.shape[0]):
        v[i] = nu_free[i]
    # each active contact's DOFs, Jacobian rows, A^-1 times them, Delassus blocks and terms
    n, nf = _gather_contacts_into(model.compliant, spatial, h, pi, pf, contacts, nc, delta_n, delta_t, dofs, count, inv, zero_column, P)
    if n == 0:
        return PgsStatus.CONVERGED.value, 0, 0.0, 0, 0
    unknowns = n + nf * (2 if spatial else 1)
    cdof, cm, jn, jt, jo, yn, yt, yo = P.cdof, P.cm, P.jn, P.jt, P.jo, P.yn, P.yt, P.yo
    active, fric, gnn, g00, g01, g11, comp, bn, bt, mu, p_n, f = (
        P.active,
        P.fric,
        P.gnn,
        P.g00,
        P.g01,
        P.g11,
        P.comp,
        P.bn,
        P.bt,
        P.mu,
        P.p_n,
        P.f,
    )
    scale = _impulse_scale(n, cdof, cm, jn, gnn, bn, nu_free)
    for k in range(n):
        p_n[k] = 0.0
        f[k, 0] = 0.0
        f[k, 1] = 0.0
    _warm_start(n, spatial, d, active, contacts.slot, warm_n, warm_t, cdof, cm, yn, yt, yo, fric, mu, p_n, f, v, cosines, sines)
    status, sweeps, residual = _sweeps(
        n,
        spatial,
        cdof,
        cm,
        jn,
        jt,
        jo,
        yn,
        yt,
        yo,
        gnn,
        g00,
        g01,
        g11,
        comp,
        bn,
        bt,
        mu,
        fric,
        p_n,
        f,
        v,
        cosines,
        sines,
        scale,
        tolerance,
        max_sweeps,
    )
    return status, sweeps, residual, unknowns, n


@numba.njit(cache=True, inline="always")
def _gather_contacts_into(compliant, spatial, h, pi, pf, contacts, nc, delta_n, delta_t, dofs, count, inv, zero_column, P):
    """Gather the active contacts into rows 0..n-1 of P's per-contact arrays (`PgsWork`):
    their DOFs, Jacobian rows, y = A^-1 J^T rows, Delassus blocks (compliance comp on the
    diagonal), the constant terms bn, bt (approach, scripted bias, previous deformation), mu
    and whether each has friction. Returns (n, nf): n active contacts, nf with friction.
    Only what the solve reads is set: a row's first cm entries (the y rows of t and o where it
    has friction, the o rows in space), its scalars, and no row past n. (Zeroing the rows
    first, with the split check once a contact and the runs' own dispatch of the detection,
    was about 5% of box_push_3d's push, measured together in one process: docs/measurements.md.)"""
    c_pair, c_psi, c_slot, c_bias = contacts.pair, contacts.psi, contacts.slot, contacts.bias
    W_n, W_t, W_o = contacts.W_n, contacts.W_t, contacts.W_o
    cdof, cm, jn, jt, jo, yn, yt, yo = P.cdof, P.cm, P.jn, P.jt, P.jo, P.yn, P.yt, P.yo
    active, fric, gnn, g00, g01, g11, comp, bn, bt, mu = P.active, P.fric, P.gnn, P.g00, P.g01, P.g11, P.comp, P.bn, P.bt, P.mu
    n = 0
    nf = 0
    # whether a body's block of A^-1 is `_split`: checked once per body a call, not per contact
    # (the bodies a contact meets repeat: box_push_3d's box in all five)
    split_body, split_last = np.int64(-1), False
    for i in range(nc):
        p = c_pair[i]
        a, b = pi[p, PI_A], pi[p, PI_B]
        ca, cb = count[a], count[b]
        m = ca + cb
        sn = 0.0
        st = 0.0
        so = 0.0
        for j in range(m):
            v = dofs[a, j] if j < ca else dofs[b, j - ca]
            cdof[n, j] = v
            jn[n, j] = W_n[v, i]
            jt[n, j] = W_t[v, i]
            sn += jn[n, j] * jn[n, j]
            st += jt[n, j] * jt[n, j]
            if spatial:
                jo[n, j] = W_o[v, i]
                so += jo[n, j] * jo[n, j]
        if not (np.sqrt(sn) > zero_column):
            continue
        active[n] = i
        cm[n] = m
        gnn[n] = g00[n] = g01[n] = g11[n] = comp[n] = bn[n] = 0.0
        bt[n, 0] = bt[n, 1] = 0.0
        K, C = pf[p, PF_K], pf[p, PF_C]
        if compliant:
            comp[n] = 1.0 / (h * (h * K + C))
            bn[n] = comp[n] * C * delta_n[c_slot[i]]
            for c in range(2):
                bt[n, c] = -K / (h * K + C) * delta_t[c_slot[i], c]
        bn[n] += c_psi[i] / h + c_bias[i, 0]
        bt[n, 0] += c_bias[i, 1]
        bt[n, 1] += c_bias[i, 2]
        mu[n] = pf[p, PF_MU]
        fric[n] = mu[n] > 0.0 and (np.sqrt(st) > zero_column or np.sqrt(so) > zero_column)
        split_a, split_b = False, False
        if ca == 6:
            if a != split_body:
                split_body, split_last = a, _split(inv[a])
            split_a = split_last
        if cb == 6:
            if b != split_body:
                split_body, split_last = b, _split(inv[b])
            split_b = split_last
        _delassus(inv, a, b, ca, cb, n, spatial, fric[n], split_a, split_b, jn, jt, jo, yn, yt, yo, gnn, g00, g01, g11, comp)
        if fric[n]:
            nf += 1
        n += 1
    return n, nf


@numba.njit(cache=True, inline="always")
def _delassus(inv, a, b, ca, cb, n, spatial, has_friction, split_a, split_b, jn, jt, jo, yn, yt, yo, gnn, g00, g01, g11, comp):
    """Contact n's rows y = A^-1 J^T and Delassus blocks, in place on the zeros its caller set:
    gnn = jn . yn + comp and, with friction, g00 = jt . yt + comp (in space also g01 = jt . yo,
    g11 = jo . yo + comp). split_a, split_b: `_apply_inverse`'s."""
    m = ca + cb
    _apply_inverse(inv, a, b, ca, cb, jn, yn, n, split_a, split_b)
    for j in range(m):
        gnn[n] += jn[n, j] * yn[n, j]
    gnn[n] += comp[n]
    if has_friction:
        _apply_inverse(inv, a, b, ca, cb, jt, yt, n, split_a, split_b)
        for j in range(m):
            g00[n] += jt[n, j] * yt[n, j]
        g00[n] += comp[n]
        if spatial:
            _apply_inverse(inv, a, b, ca, cb, jo, yo, n, split_a, split_b)
            for j in range(m):
                g01[n] += jt[n, j] * yo[n, j]
                g11[n] += jo[n, j] * yo[n, j]
            g11[n] += comp[n]


@numba.njit(cache=True, inline="always")
def _impulse_scale(n, cdof, cm, jn, gnn, bn, nu_free):
    """The impulse scale: the largest normal impulse that would stop a contact's free approach."""
    scale = 0.0
    for k in range(n):
        w = bn[k] + _dot(jn, k, cdof, cm[k], nu_free)
        scale = max(scale, -w / gnn[k])
    return scale


@numba.njit(cache=True, inline="always")
def _warm_start(n, spatial, d, active, c_slot, warm_n, warm_t, cdof, cm, yn, yt, yo, fric, mu, p_n, f, v, cosines, sines):
    """Warm start, in place: p_n, f from the previous step's impulses by contact slot, clipped
    into their cones (in space, onto the polygon's inscribed circle), and v = nu_free plus
    A^-1 times their impulse."""
    for k in range(n):
        slot = c_slot[active[k]]
        p_n[k] = max(warm_n[slot], 0.0)
        if fric[k]:
            f0 = warm_t[slot, 0]
            f1 = warm_t[slot, 1] if spatial else 0.0
            radius = mu[k] * p_n[k]
            if spatial and not _inside(f0, f1, radius, cosines, sines):
                # shrink onto the polygon's inscribed circle (radius mu p_n cos(pi / d); the
                # exact cone's, d = 0: its disk)
                size = np.sqrt(f0 * f0 + f1 * f1)
                shrink = radius * (np.cos(np.pi / d) if d > 0 else 1.0) / size
                f0, f1 = shrink * f0, shrink * f1
            elif not spatial:
                f0 = min(max(f0, -radius), radius)
            f[k, 0], f[k, 1] = f0, f1
        _add(yn, k, cdof, cm[k], p_n[k], v)
        if fric[k]:
            _add(yt, k, cdof, cm[k], f[k, 0], v)
            if spatial:
                _add(yo, k, cdof, cm[k], f[k, 1], v)


@numba.njit(cache=True, inline="always")
def _largest_impulse(n, scale, p_n, f):
    """max(scale, every p_n, every |f|): the size the convergence tests are relative to."""
    big = scale
    for k in range(n):
        big = max(big, p_n[k], np.sqrt(f[k, 0] * f[k, 0] + f[k, 1] * f[k, 1]))
    return big


@numba.njit(cache=True, inline="always")
def _sweeps(
    n,
    spatial,
    cdof,
    cm,
    jn,
    jt,
    jo,
    yn,
    yt,
    yo,
    gnn,
    g00,
    g01,
    g11,
    comp,
    bn,
    bt,
    mu,
    fric,
    p_n,
    f,
    v,
    cosines,
    sines,
    scale,
    tolerance,
    max_sweeps,
):
    """PGS sweeps, in place on (p_n, f, v), until the recomputed residual (relative to the
    largest impulse; recomputed when the sweep's change predicts it passes, `RESIDUAL_CHECK`,
    and at least every `RESIDUAL_EVERY` sweeps) is below tolerance, or max_sweeps. Returns
    (status, sweeps, residual), the residual recomputed at the end when not converged, which
    then decides the status as a check would (NON_FINITE when it, or a sweep's change, is not
    finite)."""
    status = PgsStatus.NOT_CONVERGED.value
    sweeps = 0
    residual = np.inf
    check = RESIDUAL_CHECK * tolerance  # the change (relative) at which the residual is recomputed
    checked = 0  # the sweep of the last check
    for sweep in range(max_sweeps):
        sweeps = sweep + 1
        change = 0.0
        # all normal impulses, then all friction impulses: interleaving them per contact lets
        # the two corners of a box on a plane creep along their (workless) squeeze for
        # thousands of sweeps after an impact. The updates index the arrays here, in the
        # loop: an inlined helper's array arguments are reference-counted on every call
        # (docs/measurements.md), which was a third of an exact-cone step
        for k in range(n):  # the normal impulse to its exact minimiser, clamped at 0
            m = cm[k]
            s = 0.0
            for j in range(m):
                s += jn[k, j] * v[cdof[k, j]]
            w = bn[k] + comp[k] * p_n[k] + s
            new = max(p_n[k] - w / gnn[k], 0.0)
            dp = new - p_n[k]
            if dp != 0.0:
                for j in range(m):
                    v[cdof[k, j]] += dp * yn[k, j]
                p_n[k] = new
            change = max(change, abs(dp))
        for k in range(n):  # the friction impulse to its block minimiser over the cone
            if not fric[k]:
                continue
            m = cm[k]
            f0, f1 = f[k, 0], f[k, 1]
            s0 = 0.0
            s1 = 0.0
            for j in range(m):
                x = v[cdof[k, j]]
                s0 += jt[k, j] * x
                if spatial:
                    s1 += jo[k, j] * x
            u0 = bt[k, 0] + comp[k] * f0 + s0
            u1 = bt[k, 1] + comp[k] * f1 + s1 if spatial else 0.0
            n0, n1 = _tangential_update(spatial, f0, f1, u0, u1, g00[k], g01[k], g11[k], mu[k] * p_n[k], cosines, sines)
            d0, d1 = n0 - f0, n1 - f1
            if d0 != 0.0 or d1 != 0.0:
                for j in range(m):
                    v[cdof[k, j]] += d0 * yt[k, j]
                if spatial:
                    for j in range(m):
                        v[cdof[k, j]] += d1 * yo[k, j]
                f[k, 0], f[k, 1] = n0, n1
            change = max(change, np.sqrt(d0 * d0 + d1 * d1))
        if not np.isfinite(change):
            status = PgsStatus.NON_FINITE.value
            break
        big = _largest_impulse(n, scale, p_n, f)
        # the residual decides; it costs most of a sweep, so it is recomputed after the first
        # sweep (a warm start that was nearly the solution stops there) and then once the
        # change predicts it passes: at first RESIDUAL_CHECK times the tolerance; after a check
        # that failed, at the change that check's ratio of residual to change predicts; and
        # RESIDUAL_EVERY sweeps after the last check at the latest
        if sweeps == 1 or change <= check * big or sweeps - checked >= RESIDUAL_EVERY:
            checked = sweeps
            residual = _residual(n, spatial, cdof, cm, jn, jt, jo, gnn, g00, g01, g11, comp, bn, bt, mu, fric, p_n, f, v, cosines, sines)
            residual = residual / big if big > 0.0 else residual
            if residual <= tolerance:
                status = PgsStatus.CONVERGED.value
                break
            if sweeps > 1 and big > 0.0 and residual > 0.0:
                check = min(check, change / big * tolerance / residual)
    if status != PgsStatus.CONVERGED:
        big = _largest_impulse(n, scale, p_n, f)
        residual = _residual(n, spatial, cdof, cm, jn, jt, jo, gnn, g00, g01, g11, comp, bn, bt, mu, fric, p_n, f, v, cosines, sines)
        residual = residual / big if big > 0.0 else residual
        if not np.isfinite(residual):
            status = PgsStatus.NON_FINITE.value
        elif status == PgsStatus.NOT_CONVERGED.value and residual <= tolerance:  # the last sweep's, as a check would
            status = PgsStatus.CONVERGED.value
    return status, sweeps, residual


@numba.njit(cache=True, inline="always")
def _residual(n, spatial, cdof, cm, jn, jt, jo, gnn, g00, g01, g11, comp, bn, bt, mu, fric, p_n, f, v, cosines, sines):
    """Natural-map residual in impulse units (see the module docstring), not yet scaled."""
    r = 0.0
    for k in range(n):  # (arrays indexed here, as in `_sweeps`)
        m = cm[k]
        s = 0.0
        s0 = 0.0
        s1 = 0.0
        for j in range(m):
            x = v[cdof[k, j]]
            s += jn[k, j] * x
            s0 += jt[k, j] * x
            if spatial:
                s1 += jo[k, j] * x
        w = bn[k] + comp[k] * p_n[k] + s
        u0 = bt[k, 0] + comp[k] * f[k, 0] + s0
        u1 = bt[k, 1] + comp[k] * f[k, 1] + s1 if spatial else 0.0
        r = max(r, abs(min(p_n[k], w / gnn[k])))
        if fric[k]:
            f0, f1 = f[k, 0], f[k, 1]
            n0, n1 = _tangential_update(spatial, f0, f1, u0, u1, g00[k], g01[k], g11[k], mu[k] * p_n[k], cosines, sines)
            r = max(r, np.sqrt((n0 - f0) ** 2 + (n1 - f1) ** 2))
    return r


# ------------------------------------------------------------------- the exact cone's pivoting


@numba.njit(cache=True, inline="always")
def _aligned_direction(f0, f1, u0, u1, radius):
    """The direction (cos, sin) in the (t, o) plane a contact's aligned polygon puts a vertex on:
    its friction impulse's where that sticks (inside the disk: the polygon then holds it), else
    against its slip (a sliding contact's friction lies there: the vertex gives it exactly)."""
    fn = np.sqrt(f0 * f0 + f1 * f1)
    un = np.sqrt(u0 * u0 + u1 * u1)
    if fn > 0.0 and (fn < (1.0 - EDGE_TOL) * radius or un == 0.0):
        return f0 / fn, f1 / fn
    if un > 0.0:
        return -u0 / un, -u1 / un
    return 1.0, 0.0


@numba.njit(cache=True)
def aligned_lemke_into(
    n, cdof, cm, jn, jt, jo, yn, yt, yo, gnn, g00, g01, g11, comp, bn, bt, mu, fric, p_n, f, nu_free, v, scale, tolerance
):
    """The exact cone's pivoting, for a step whose PGS did not converge (in space).

    PGS creeps where the exact solution is far from its iterate along a nearly workless
    direction: on box_push_3d's push the four coplanar corners' loads, where the exact solution
    lifts one corner (docs/measurements.md). Here the contact problem is solved by Lemke on
    the Stewart-Trinkle LCP of polygons with ALIGNED_DIRECTIONS directions, each contact's
    rotated to put a vertex on its friction as PGS left it (`_aligned_direction`). A polygon
    inscribed in the disk holds every sticking impulse along that vertex, and gives a sliding
    contact exactly mu p_n against its slip when the slip points at the vertex: where the
    LCP's solution does that on every contact it solves the exact cone. Whether it does is
    decided by the exact cone's own residual, recomputed (`_residual`, relative as `_sweeps`
    makes it); a solution above the tolerance is aligned again from its own friction and slip,
    up to ALIGNED_ROUNDS times. The LCP is scaled to a unit diagonal on its contact rows, and
    Lemke retries a singular one with the stepper's regularization
    (`models.lcp.LCP_REGULARIZATION`), which only ever yields a candidate that the residual
    then judges.

    The contacts are `_sweeps`'s (n, their rows, blocks and terms); p_n (n), f (n, 2) and v (nv)
    are PGS's iterate and nu+, replaced only by a solution within the tolerance. Returns
    (solved, pivots, residual): residual the accepted solution's (inf where none was).
    """
    nv = nu_free.shape[0]
    # the Delassus matrix in the contacts' (n, t, o) frames, dense (3 rows a contact), and
    # their free velocities: r(x) = r0 + D x for the impulses x = (p_n, f) by contact
    Y = np.zeros((3 * n, nv))
    for k in range(n):
        for j in range(cm[k]):
            Y[3 * k, cdof[k, j]] += yn[k, j]
            if fric[k]:
                Y[3 * k + 1, cdof[k, j]] += yt[k, j]
                Y[3 * k + 2, cdof[k, j]] += yo[k, j]
    D = np.zeros((3 * n, 3 * n))
    r0 = np.zeros(3 * n)
    for k in range(n):
        rows = 3 if fric[k] else 1
        for a in range(rows):
            jr = jn if a == 0 else (jt if a == 1 else jo)
            i = 3 * k + a
            for j in range(cm[k]):
                c = cdof[k, j]
                r0[i] += jr[k, j] * nu_free[c]
                for e in range(3 * n):
                    D[i, e] += jr[k, j] * Y[e, c]
            D[i, i] += comp[k]
        r0[3 * k] += bn[k]
        if fric[k]:
            r0[3 * k + 1] += bt[k, 0]
            r0[3 * k + 2] += bt[k, 1]
    d = ALIGNED_DIRECTIONS
    base_c, base_s = np.empty(d), np.empty(d)
    cone_directions_into(base_c, base_s)
    nf = 0
    for k in range(n):
        if fric[k]:
            nf += 1
    m = n + nf * (d + 1)
    rows = n + nf * d  # the contact rows (normal and direction), regularized on a retry
    first = np.zeros(n, np.int64)  # a friction contact's first direction row
    fi = 0
    for k in range(n):
        if fric[k]:
            first[k] = n + fi * d
            fi += 1
    # the impulses by contact, PGS's iterate to align the first round with
    x = np.zeros(3 * n)
    for k in range(n):
        x[3 * k] = p_n[k]
        x[3 * k + 1] = f[k, 0]
        x[3 * k + 2] = f[k, 1]
    vel = np.empty(3 * n)
    dc, ds = np.empty((n, d)), np.empty((n, d))
    M, q, scaling = np.empty((m, m)), np.empty(m), np.empty(m)
    pn_try, f_try, v_try = np.empty(n), np.empty((n, 2)), np.empty(nv)
    pivots = 0
    for _ in range(ALIGNED_ROUNDS):
        for i in range(3 * n):  # the frame velocities at x (PGS's iterate, then the last candidate)
            vel[i] = r0[i]
            for e in range(3 * n):
                vel[i] += D[i, e] * x[e]
        for k in range(n):
            if fric[k]:
                c, s = _aligned_direction(x[3 * k + 1], x[3 * k + 2], vel[3 * k + 1], vel[3 * k + 2], mu[k] * x[3 * k])
                for j in range(d):
                    dc[k, j] = c * base_c[j] - s * base_s[j]
                    ds[k, j] = s * base_c[j] + c * base_s[j]
        # the LCP: rows k (normal), first[k] + j (direction j), n + nf d + (friction index) (gamma)
        for i in range(m):
            q[i] = 0.0
            for e in range(m):
                M[i, e] = 0.0
        gi = n + nf * d
        for k in range(n):
            q[k] = r0[3 * k]
            for l in range(n):
                M[k, l] = D[3 * k, 3 * l]
                if fric[l]:
                    for j in range(d):
                        M[k, first[l] + j] = D[3 * k, 3 * l + 1] * dc[l, j] + D[3 * k, 3 * l + 2] * ds[l, j]
            if not fric[k]:
                continue
            for j in range(d):
                i = first[k] + j
                q[i] = dc[k, j] * r0[3 * k + 1] + ds[k, j] * r0[3 * k + 2]
                for l in range(n):
                    M[i, l] = dc[k, j] * D[3 * k + 1, 3 * l] + ds[k, j] * D[3 * k + 2, 3 * l]
                    if fric[l]:
                        t0 = dc[k, j] * D[3 * k + 1, 3 * l + 1] + ds[k, j] * D[3 * k + 2, 3 * l + 1]
                        t1 = dc[k, j] * D[3 * k + 1, 3 * l + 2] + ds[k, j] * D[3 * k + 2, 3 * l + 2]
                        for jj in range(d):
                            M[i, first[l] + jj] = t0 * dc[l, jj] + t1 * ds[l, jj]
                M[i, gi] = 1.0
                M[gi, i] = -1.0
            M[gi, k] = mu[k]
            gi += 1
        # scaled to a unit diagonal on the contact rows (gamma's rows, of zero diagonal, as they
        # are): unscaled, Lemke's solutions on the four corners' nearly singular rows kept w
        # at -2e-8 and the residual above 1e-6 round after round
        for i in range(m):
            scaling[i] = 1.0 / np.sqrt(M[i, i]) if i < rows and M[i, i] > 0.0 else 1.0
        for i in range(m):
            q[i] *= scaling[i]
            for e in range(m):
                M[i, e] *= scaling[i] * scaling[e]
        added = 0.0
        for retry in range(LCP_REGULARIZATION_STEPS + 1):
            if retry > 0:  # a singular LCP: regularized (relative: the diagonal is 1)
                target = LCP_REGULARIZATION * 100.0 ** (retry - 1)
                for i in range(rows):
                    M[i, i] += target - added
                added = target
            z, w, status, piv = lemke_kernel(M, q, DEFAULT_LEMKE_PIVOTS_PER_VARIABLE * (m + 1))
            pivots += piv
            if status == STATUS_SOLVED or status == STATUS_SOLVED_INACCURATE:
                break
        if status != STATUS_SOLVED and status != STATUS_SOLVED_INACCURATE:
            break
        for i in range(m):
            z[i] *= scaling[i]
        # the candidate's impulses and nu+
        for k in range(n):
            pn_try[k] = z[k]
            f0 = 0.0
            f1 = 0.0
            if fric[k]:
                for j in range(d):
                    f0 += z[first[k] + j] * dc[k, j]
                    f1 += z[first[k] + j] * ds[k, j]
            f_try[k, 0], f_try[k, 1] = f0, f1
            x[3 * k], x[3 * k + 1], x[3 * k + 2] = pn_try[k], f0, f1
        for c in range(nv):
            v_try[c] = nu_free[c]
            for e in range(3 * n):
                v_try[c] += Y[e, c] * x[e]
        big_impulse = _largest_impulse(n, scale, pn_try, f_try)
        disk = base_c[:0]  # (no polygon: the exact cone's disk)
        residual = _residual(n, True, cdof, cm, jn, jt, jo, gnn, g00, g01, g11, comp, bn, bt, mu, fric, pn_try, f_try, v_try, disk, disk)
        residual = residual / big_impulse if big_impulse > 0.0 else residual
        if residual <= tolerance:
            for k in range(n):
                p_n[k], f[k, 0], f[k, 1] = pn_try[k], f_try[k, 0], f_try[k, 1]
            for c in range(nv):
                v[c] = v_try[c]
            return True, pivots, residual
    return False, pivots, np.inf

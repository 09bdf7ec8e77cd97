"""Compiled solvers for the linear complementarity problem (LCP), with honest statuses.

The LCP(M, q): given a square ``M`` (n x n) and ``q`` (n,), find ``z`` with

    z >= 0,    w = M z + q >= 0,    z^T w = 0.

Two solvers, both compiled with numba:

* `lemke_kernel` -- Lemke's complementary pivoting method (covering vector e = ones, dense
  revised tableau, lexicographic minimum-ratio rule).  Finite and exact up to round-off; it
  solves every LCP with a P-matrix or a positive semidefinite M that has a solution, and more
  generally every feasible LCP with a copositive-plus M.  On other matrices it may stop on a
  secondary ray although a solution exists (e.g. bimatrix games).
* `pgs_kernel` -- projected Gauss-Seidel / projected SOR.  Cheap, converges for symmetric
  positive definite M (and some other classes), needs M[i, i] > 0.

Use `solve_lcp`, the Python-facing entry point: it validates the input, runs a kernel, then
*recomputes* ``w`` and the residual from ``M``, ``q`` and ``z`` (it never trusts a kernel's own
success flag) and classifies the result with an `LCPStatus`.  It never raises on numerical
trouble: bad shapes, non-finite numbers, divergence, cycling and ray termination all come
back as statuses.

Residual (`complementarity_residual`): the natural-map residual

    r(z) = || min(z, M z + q) ||_inf / (1 + ||q||_inf),

which is zero exactly when z solves the LCP (it measures infeasibility of z, infeasibility of
w and complementarity at once; it is the inf-norm version of Siconos's
``||z - max(0, z - w)|| / (1 + ||q||)``).  It is absolute for small q and relative to q for
large q; it is +inf if z or w has a non-finite entry.

Also here: the conversion of a 2D frictional contact problem ("fc2d", local form) to an LCP
(`contact_lcp_from_fc2d`), its inverse map (`fc2d_reactions_from_lcp`) and a direct check of
the Coulomb conditions (`fc2d_coulomb_error`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np
from numba.core import types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

__all__ = [
    "DEFAULT_LEMKE_PIVOTS_PER_VARIABLE",
    "DEFAULT_PGS_MAX_ITERATIONS",
    "DEFAULT_TOL",
    "INACCURATE_TOL",
    "LCP_REGULARIZATION",
    "LCP_REGULARIZATION_STEPS",
    "LCPResult",
    "LCPStatus",
    "Fc2dLCP",
    "complementarity_residual",
    "contact_lcp_from_fc2d",
    "default_max_iterations",
    "fc2d_coulomb_error",
    "fc2d_reactions_from_lcp",
    "lemke_kernel",
    "lemke_warm_kernel",
    "natural_map_residual",
    "pgs_kernel",
    "solve_lcp",
]

# --------------------------------------------------------------------------------------------
# Status codes.  Plain module-level ints so that the numba kernels can return them; the
# `LCPStatus` enum below has the same values.
# --------------------------------------------------------------------------------------------
STATUS_SOLVED = 0
STATUS_SOLVED_INACCURATE = 1
STATUS_RAY_TERMINATION = 2
STATUS_MAX_ITERATIONS = 3
STATUS_ZERO_DIAGONAL = 4
STATUS_NON_FINITE_INPUT = 5
STATUS_NON_FINITE_OUTPUT = 6
STATUS_INVALID_INPUT = 7
STATUS_NUMERICAL_FAILURE = 8

# --------------------------------------------------------------------------------------------
# Algorithm constants.
# --------------------------------------------------------------------------------------------
#: Default acceptance tolerance on the recomputed residual (`complementarity_residual`).
DEFAULT_TOL = 1e-9
#: A finished solve whose residual is above ``tol`` but at most this is SOLVED_INACCURATE;
#: above this it is NUMERICAL_FAILURE.
INACCURATE_TOL = 1e-6
#: Default Lemke pivot limit is this times (n + 1).
DEFAULT_LEMKE_PIVOTS_PER_VARIABLE = 50
#: Diagonal added to a contact LCP's contact rows when Lemke fails on a singular (redundant)
#: one, relative to each row's own diagonal; each further retry adds 100 times more, up to
#: LCP_REGULARIZATION * 100**(steps - 1) = 1e-5 (`models.stepper`, and the exact cone's
#: pivoting in `models.contact_pgs`).
LCP_REGULARIZATION = 1e-9
LCP_REGULARIZATION_STEPS = 3
#: Default number of PGS sweeps.
DEFAULT_PGS_MAX_ITERATIONS = 10_000
#: Lemke: an entry d_i = sum_k Binv[i, k] a_k of the entering column is a pivot candidate
#: only if d_i > LEMKE_PIVOT_TOL * max(sum_k |Binv[i, k] a_k|, h_i max_k |a_k|), where h_i is
#: the magnitude of the numbers that went into row i of Binv (below that d_i is round-off).
#: Row-wise, so it does not depend on how M, q and the covering vector compare in scale.
LEMKE_PIVOT_TOL = 1e-10
#: Lemke: in a stage of the lexicographic ratio test (values a_i, divisors d_i, minimum ratio
#: r_min), row i ties with the minimum when (a_i / d_i - r_min) * max_c d_c is at most
#: LEMKE_TIE_TOL times the magnitudes involved (|a_i|, |r_min| d_c, the stage's largest |a|
#: or the LEMKE_NOISE floor): choosing it then moves no other basic value by more than
#: round-off.
LEMKE_TIE_TOL = 1e-11
#: Lemke: round-off floor of the tableau entries (a few hundred ulps) relative to the size of
#: the numbers that went into them; differences below it are ties in the lexicographic test.
LEMKE_NOISE = 1e-13
#: Lemke: when the path ends on a ray at a point whose natural-map residual is at most this
#: (z0 ~ 0: a round-off-broken tie with z0), that point is returned as a solution.
LEMKE_RESCUE_TOL = DEFAULT_TOL
#: PGS: M[i, i] <= PGS_ZERO_DIAGONAL_TOL * max_j |M[j, j]| (or <= 0) counts as a zero diagonal.
PGS_ZERO_DIAGONAL_TOL = 1e-14


class LCPStatus(enum.IntEnum):
    """Outcome of an LCP solve.  Only `SOLVED` is a success; see `.message`."""

    SOLVED = STATUS_SOLVED
    SOLVED_INACCURATE = STATUS_SOLVED_INACCURATE
    RAY_TERMINATION = STATUS_RAY_TERMINATION
    MAX_ITERATIONS = STATUS_MAX_ITERATIONS
    ZERO_DIAGONAL = STATUS_ZERO_DIAGONAL
    NON_FINITE_INPUT = STATUS_NON_FINITE_INPUT
    NON_FINITE_OUTPUT = STATUS_NON_FINITE_OUTPUT
    INVALID_INPUT = STATUS_INVALID_INPUT
    NUMERICAL_FAILURE = STATUS_NUMERICAL_FAILURE

    @property
    def message(self) -> str:
        """A human-readable explanation of the status."""
        return _STATUS_MESSAGES[self]

    @property
    def is_success(self) -> bool:
        return self is LCPStatus.SOLVED


_STATUS_MESSAGES = {
    LCPStatus.SOLVED: "solved: the recomputed residual is within the tolerance",
    LCPStatus.SOLVED_INACCURATE: (
        "the solver finished, but the recomputed residual is above the tolerance "
        f"(though at most {INACCURATE_TOL:g}); z is an approximate solution"
    ),
    LCPStatus.RAY_TERMINATION: (
        "Lemke ended on a secondary ray: for copositive-plus M (e.g. positive semidefinite) "
        "this proves the LCP has no solution; for other M it proves nothing (a solution may "
        "exist that Lemke cannot reach)"
    ),
    LCPStatus.MAX_ITERATIONS: ("the pivot / iteration limit was reached before a solution was found"),
    LCPStatus.ZERO_DIAGONAL: (
        "PGS needs every diagonal entry M[i, i] > 0; a diagonal entry is zero, negative or negligible (use Lemke, or regularise M)"
    ),
    LCPStatus.NON_FINITE_INPUT: "M or q (or z0) contains NaN or infinity",
    LCPStatus.NON_FINITE_OUTPUT: ("the iterates became non-finite (overflow / divergence); z is not a solution"),
    LCPStatus.INVALID_INPUT: (
        "invalid input: M must be a square 2-D array, q a 1-D array of matching length, "
        "z0 (if given) like q, tol > 0, 0 < omega < 2, max_iterations >= 0"
    ),
    LCPStatus.NUMERICAL_FAILURE: (
        "the solver finished, but the recomputed residual is above the loose tolerance "
        f"{INACCURATE_TOL:g} (round-off or a singular pivot); z is not a solution"
    ),
}


# --------------------------------------------------------------------------------------------
# Residual.
# --------------------------------------------------------------------------------------------
@numba.njit(cache=True, error_model="numpy")
def _matvec_plus(M, z, q):
    """w = M z + q with explicit loops (works for any array layout)."""
    w = np.empty(q.shape[0])
    _matvec_plus_into(M, z, q, w)
    return w


@numba.njit(cache=True, error_model="numpy")
def _matvec_plus_into(M, z, q, w):
    """`_matvec_plus` into the caller's w (at least n entries). Four rows at a time, as
    `_entering_column`: each row's sum adds the same terms in the same order (the same bits)."""
    n = q.shape[0]
    i = 0
    while i + 4 <= n:
        s0, s1, s2, s3 = q[i], q[i + 1], q[i + 2], q[i + 3]
        for j in range(n):
            x = z[j]
            s0 += M[i, j] * x
            s1 += M[i + 1, j] * x
            s2 += M[i + 2, j] * x
            s3 += M[i + 3, j] * x
        w[i], w[i + 1], w[i + 2], w[i + 3] = s0, s1, s2, s3
        i += 4
    for r in range(i, n):
        s = q[r]
        for j in range(n):
            s += M[r, j] * z[j]
        w[r] = s


@numba.njit(cache=True, error_model="numpy")
def _matvec_on_into(M, z, q, J, nj, w):
    """w = M z + q for a z that is zero outside the nj indices J[:nj]: O(n nj), into the
    caller's w (at least n entries). Column by column: each w_i sums the same terms in the same
    order as a row's dot product would (the same bits), but the rows' sums are independent chains
    the CPU overlaps, not one chain of dependent adds per row (0.3 against 0.7 us at n = 50, nj =
    15, box_push_3d's sizes at the push, in one compiled loop)."""
    n = q.shape[0]
    for i in range(n):
        w[i] = q[i]
    for a in range(nj):
        c = J[a]
        x = z[c]
        for i in range(n):
            w[i] += M[i, c] * x


# in line: every contact step's guess calls it (a call with the runtime counted its three
# arguments' references each time, also from the warm steps, which have none of their own)
@numba.njit(cache=True, error_model="numpy", inline="always")
def _natural_map_residual(z, w, q):
    """||min(z, w)||_inf / (1 + ||q||_inf); +inf if anything is non-finite."""
    n = q.shape[0]
    qmax = 0.0
    for i in range(n):
        a = abs(q[i])
        if not np.isfinite(a):
            return np.inf
        if a > qmax:
            qmax = a
    r = 0.0
    for i in range(n):
        if not (np.isfinite(z[i]) and np.isfinite(w[i])):
            return np.inf
        m = abs(min(z[i], w[i]))
        if m > r:
            r = m
    return r / (1.0 + qmax)


@numba.njit(cache=True, error_model="numpy")
def natural_map_residual(z, w, q):
    """`complementarity_residual` of z given w = M z + q already recomputed from M, q and z
    (as the Lemke kernels return it): O(n)."""
    return _natural_map_residual(z, w, q)


@numba.njit(cache=True, error_model="numpy")
def refined_on_basis(M, q, z, basic_z):
    """One step of iterative refinement of an LCP solution z on its basis: the basic unknowns
    (basic_z) corrected by the least-squares solution dz of M[J, J] dz = -(M z + q)[J] (numpy's
    lstsq: a statically indeterminate contact set makes M[J, J] singular, and there Lemke's z
    solves its rows only to round-off times M's conditioning), a corrected unknown below 0 set
    to 0. Returns (the corrected z, its w = M z + q, its natural-map residual), which the
    caller judges as any solution's."""
    n = q.shape[0]
    J = np.flatnonzero(basic_z[:n])
    k = J.shape[0]
    short = _matvec_plus(M, z, q)
    A, r = np.empty((k, k)), np.empty(k)
    for a in range(k):
        r[a] = -short[J[a]]
        for b in range(k):
            A[a, b] = M[J[a], J[b]]
    dz = np.linalg.lstsq(A, r)[0]
    out = z.copy()
    for a in range(k):
        out[J[a]] = max(out[J[a]] + dz[a], 0.0)
    w = _matvec_plus(M, out, q)
    return out, w, _natural_map_residual(out, w, q)


@numba.njit(cache=True, error_model="numpy")
def complementarity_residual(M, q, z):
    """Natural-map residual ``||min(z, M z + q)||_inf / (1 + ||q||_inf)``.

    Recomputed from M, q and z (never from a solver's w).  Zero iff z solves LCP(M, q);
    ``+inf`` if any of q, z or w = M z + q is non-finite.  M: (n, n), q and z: (n,).
    """
    w = _matvec_plus(M, z, q)
    return _natural_map_residual(z, w, q)


# --------------------------------------------------------------------------------------------
# Lemke.
# --------------------------------------------------------------------------------------------
@numba.njit(cache=True, error_model="numpy")
def _lex_select(qbar, Binv, div, cand, ncand, tie_tol, zrow, qscale, hist, marked):
    """Lexicographic minimum-ratio selection among rows ``cand[:ncand]``.

    Stage 0 compares qbar[i] / div[i]; stage k+1 compares Binv[i, k] / div[i] among the rows
    still tied, until one row is left (the rows of Binv are linearly independent, so in exact
    arithmetic the choice is unique).  ``div`` must be positive on the candidate rows.  If
    ``zrow >= 0`` (the row where the artificial z0 is basic) is tied in stage 0, it is chosen:
    letting z0 leave ends Lemke's method with a solution.  Ties are decided with the relative
    tolerance ``tie_tol`` against the magnitudes involved, with an absolute round-off floor
    LEMKE_NOISE * hist_i (times ``qscale`` = ||q||_inf in stage 0).  marked: 0 at the columns
    of Binv still the identity's (`_entering_column`): such a column's stage is all zeros, and
    skipped at once, unless one of the candidates is its row.
    """
    n = Binv.shape[0]
    for stage in range(-1, n):
        if ncand == 1:
            break
        if stage >= 0 and marked[stage] == 0:
            own = False
            for c in range(ncand):
                if cand[c] == stage:
                    own = True
            if not own:
                continue
        rmin = np.inf
        allzero = True
        dcmax = 0.0
        scale = 0.0
        hmax = 0.0
        for c in range(ncand):
            i = cand[c]
            a = qbar[i] if stage < 0 else Binv[i, stage]
            if a != 0.0:
                allzero = False
            r = a / div[i]
            if r < rmin:
                rmin = r
            if div[i] > dcmax:
                dcmax = div[i]
            if abs(a) > scale:
                scale = abs(a)
            if hist[i] > hmax:
                hmax = hist[i]
        if allzero:  # every candidate ties in this stage (common on sparse problems)
            if stage < 0 and zrow >= 0:
                for c in range(ncand):
                    if cand[c] == zrow:
                        return zrow
            continue
        # Absolute noise floor: an exact zero shows up as round-off of the size of the
        # numbers that went into the row (hist), times ||q||_inf for qbar = Binv q.
        floor = LEMKE_NOISE * hmax * (qscale if stage < 0 else 1.0)
        if floor > tie_tol * scale:
            scale = floor / tie_tol
        kept = 0
        zrow_tied = False
        for c in range(ncand):
            i = cand[c]
            a = qbar[i] if stage < 0 else Binv[i, stage]
            # Choosing row i instead of the minimising row m moves row m's basic value by
            # -(r_i - r_min) d_m; row i ties only if that is round-off sized for every
            # candidate m, i.e. (r_i - r_min) * max_c d_c is below the noise level.
            excess = (a / div[i] - rmin) * dcmax
            if excess <= tie_tol * (abs(a) * dcmax / div[i] + abs(rmin) * dcmax + scale):
                cand[kept] = i
                kept += 1
                if i == zrow:
                    zrow_tied = True
        if kept == 0:  # cannot happen except through NaN; keep the first candidate
            kept = 1
        ncand = kept
        if stage < 0 and zrow_tied:
            return zrow
    return cand[0]


@numba.njit(cache=True, error_model="numpy")
def _pivot(Binv, qbar, d, r, idx, hist):
    """Gauss-Jordan pivot of the revised tableau (Binv, qbar) on row r with column d.

    Only rows with d_i != 0 and only the nonzero columns of the pivot row are touched (``idx``
    is an int work array of length n), which keeps pivots cheap on sparse contact problems.
    ``hist[i]`` tracks the magnitude of the numbers that went into row i of Binv (its
    round-off scale, which cancellation does not reduce): hist_r /= |p| for the pivot row,
    and hist_i = max(hist_i, |d_i| max_k |Binv[r, k]|) for the updated rows.
    """
    n = Binv.shape[0]
    p = d[r]
    inv = 1.0 / p
    hist[r] *= abs(inv)
    nnz = 0
    hr = 0.0
    for k in range(n):
        v = Binv[r, k]
        if v != 0.0:
            v *= inv
            Binv[r, k] = v
            idx[nnz] = k
            nnz += 1
            if abs(v) > hr:
                hr = abs(v)
    qbar[r] *= inv
    if qbar[r] < 0.0:
        qbar[r] = 0.0
    dense = 2 * nnz > n
    for i in range(n):
        if i == r:
            continue
        f = d[i]
        if f == 0.0:
            continue
        if abs(f) * hr > hist[i]:
            hist[i] = abs(f) * hr
        if dense:
            for k in range(n):
                Binv[i, k] -= f * Binv[r, k]
        else:
            for t in range(nnz):
                k = idx[t]
                Binv[i, k] -= f * Binv[r, k]
        v = qbar[i] - f * qbar[r]
        # In exact arithmetic every basic value stays >= 0 after the first pivot; negative
        # values are round-off (or tie-tolerance) drift.  Clamping them to 0 is a tiny
        # perturbation of q that keeps the path feasible; the final polish uses the true q.
        qbar[i] = v if v > 0.0 else 0.0


@numba.njit(cache=True, error_model="numpy", inline="always")
def _touch(touched, marked, nt, r):
    """Row r pivoted on (`_entering_column`'s touched rows): into touched[:nt], kept
    ascending, and marked, unless it is there. Returns the count."""
    if marked[r] != 0:
        return nt
    marked[r] = 1
    k = nt
    while k > 0 and touched[k - 1] > r:
        touched[k] = touched[k - 1]
        k -= 1
    touched[k] = r
    return nt + 1


@numba.njit(cache=True, error_model="numpy")
def _entering_column(M, Binv, var, n, d, mag, col, idx, touched, marked, nt):
    """d = Binv @ a_var for the system  I w - M z - e z0 = q  (var: w_i=i, z_j=n+j, z0=2n).

    Also mag = |Binv| @ |a_var|, the size of the terms summed into each d_i (its round-off
    scale); returns max_k |a_k|.  Binv's columns outside the nt rows pivoted on so far
    (touched, ascending; marked: 1 at each) are still the identity's, exactly (a pivot on row
    r changes only the columns where row r is nonzero), so while they are fewer than the
    column's nonzeros each d_i sums only over them and its own column; else sparse columns of
    M (fewer than n/2 nonzeros) are multiplied through their nonzeros only.  Each way adds
    the same nonzero terms in the same order (ascending columns) and leaves out exact zeros
    only: the same bits as the dense sum.
    """
    amax = 1.0
    if var < n:
        for i in range(n):
            d[i] = Binv[i, var]
            mag[i] = abs(d[i])
    elif var < 2 * n:
        j = var - n
        nnz = 0
        amax = 0.0
        for k in range(n):
            v = M[k, j]
            col[k] = v
            if v != 0.0:
                idx[nnz] = k
                nnz += 1
                if abs(v) > amax:
                    amax = abs(v)
        if nt < nnz:
            for i in range(n):
                s = 0.0
                m = 0.0
                own = marked[i] == 0  # Binv[i, i] = 1, its only nonzero outside touched
                for t in range(nt):
                    k = touched[t]
                    if own and i < k:
                        s += col[i]
                        m += abs(col[i])
                        own = False
                    u = Binv[i, k] * col[k]
                    s += u
                    m += abs(u)
                if own:
                    s += col[i]
                    m += abs(col[i])
                d[i] = -s
                mag[i] = m
        elif 2 * nnz > n:
            # four rows at a time: each row's sums add the same terms in the same order (the
            # same bits), as four independent chains the CPU overlaps
            i = 0
            while i + 4 <= n:
                s0 = s1 = s2 = s3 = 0.0
                m0 = m1 = m2 = m3 = 0.0
                for k in range(n):
                    c = col[k]
                    t0, t1, t2, t3 = Binv[i, k] * c, Binv[i + 1, k] * c, Binv[i + 2, k] * c, Binv[i + 3, k] * c
                    s0 += t0
                    s1 += t1
                    s2 += t2
                    s3 += t3
                    m0 += abs(t0)
                    m1 += abs(t1)
                    m2 += abs(t2)
                    m3 += abs(t3)
                d[i], d[i + 1], d[i + 2], d[i + 3] = -s0, -s1, -s2, -s3
                mag[i], mag[i + 1], mag[i + 2], mag[i + 3] = m0, m1, m2, m3
                i += 4
            for r in range(i, n):
                s = 0.0
                m = 0.0
                for k in range(n):
                    t = Binv[r, k] * col[k]
                    s += t
                    m += abs(t)
                d[r] = -s
                mag[r] = m
        else:
            for i in range(n):
                s = 0.0
                m = 0.0
                for t in range(nnz):
                    k = idx[t]
                    u = Binv[i, k] * col[k]
                    s += u
                    m += abs(u)
                d[i] = -s
                mag[i] = m
    else:
        for i in range(n):
            s = 0.0
            m = 0.0
            for k in range(n):
                s += Binv[i, k]
                m += abs(Binv[i, k])
            d[i] = -s
            mag[i] = m
    return amax


@numba.njit(cache=True, error_model="numpy", inline="always")
def _largest_in_block(A, m):
    """max |A[i, j]| over A[:m, :m] (0 for m = 0; NaN entries ignored)."""
    amax = 0.0
    for i in range(m):
        for j in range(m):
            if abs(A[i, j]) > amax:
                amax = abs(A[i, j])
    return amax


@numba.njit(cache=True, error_model="numpy", inline="always")
def _pivot_row(A, k, m, amax):
    """Partial pivoting's row at step k of an elimination on A[:m, :m]: the first row i >= k of
    largest |A[i, k]|, or -1 where that is at most 1e-14 amax (numerically singular)."""
    p = k
    best = abs(A[k, k])
    for i in range(k + 1, m):
        if abs(A[i, k]) > best:
            best = abs(A[i, k])
            p = i
    if best <= 1e-14 * amax:
        return -1
    return p


@numba.njit(cache=True, error_model="numpy")
def _gauss_solve(A, m):
    """Solve A[:m] x = A[m] (the right-hand side in row m) by Gaussian elimination with
    partial pivoting, in place: x ends in row m (one array, no allocation: this runs every
    step on the warm-started basis). Returns ok: False if A[:m] is numerically singular or x
    is non-finite."""
    if m == 0:
        return True
    amax = _largest_in_block(A, m)
    if not (amax > 0.0) or not np.isfinite(amax):
        return False
    for k in range(m):
        p = _pivot_row(A, k, m, amax)
        if p < 0:
            return False
        if p != k:
            for j in range(m):
                t = A[k, j]
                A[k, j] = A[p, j]
                A[p, j] = t
            t = A[m, k]
            A[m, k] = A[m, p]
            A[m, p] = t
        for i in range(k + 1, m):
            f = A[i, k] / A[k, k]
            if f != 0.0:
                for j in range(k, m):
                    A[i, j] -= f * A[k, j]
                A[m, i] -= f * A[m, k]
    for k in range(m - 1, -1, -1):
        s = A[m, k]
        for j in range(k + 1, m):
            s -= A[k, j] * A[m, j]  # (A[m, j > k] already hold x)
        A[m, k] = s / A[k, k]
        if not np.isfinite(A[m, k]):
            return False
    return True


@numba.njit(cache=True, error_model="numpy")
def _z_from_basis(basis, qbar, n):
    z = np.zeros(n)
    for i in range(n):
        v = basis[i]
        if n <= v < 2 * n:
            z[v - n] = qbar[i]
    return z


@numba.njit(cache=True, error_model="numpy")
def lemke_kernel(M, q, max_pivots):
    """Lemke's method with covering vector e = ones and the lexicographic ratio test.

    Works on the system ``I w - M z - e z0 = q`` with an explicit basis inverse ``Binv``
    (n x n) and ``qbar = Binv q`` (a revised dense tableau, O(n^2) per pivot).  The ratio
    test is the lexicographic minimum-ratio rule of Cottle-Pang-Stone (sec. 4.9): among rows
    with d_i > 0 take the lexicographic minimum of ``(qbar_i, Binv[i, :]) / d_i``, which is
    Lemke's method applied to q perturbed by (eps, eps^2, ...) and cannot cycle on degenerate
    problems.  When the artificial variable z0 is among the rows tied for the minimum ratio
    it leaves at once (this ends the method with a solution).  When z0 leaves, the
    complementary solution is polished by solving ``M[J, J] z_J = -q_J`` on the final basis
    J (kept if it lowers the residual).  If the path ends on a secondary ray at a point that
    nevertheless solves the LCP to LEMKE_RESCUE_TOL (this happens when z0 reaches 0 in a
    tie that round-off broke the wrong way), that point is returned with STATUS_SOLVED.

    Round-off handling (see the LEMKE_* constants): an entry of the entering column counts as
    positive only above LEMKE_PIVOT_TOL times its own round-off scale; lexicographic ties are
    decided relative to the magnitudes involved with a LEMKE_NOISE floor; basic values that
    drift below 0 are clamped to 0.  Exact-arithmetic checks on small degenerate problems
    (tests/test_lcp.py) show the same pivot sequence as rational-arithmetic Lemke.

    Parameters: M (n, n) float64, q (n,) float64, max_pivots (int, counts every pivot
    including the first one that brings z0 in).

    Returns ``(z, w, status_code, pivots)`` with w = M z + q recomputed from z and status one
    of STATUS_SOLVED (z solves the LCP up to round-off), STATUS_RAY_TERMINATION (no pivot
    row for the entering column: secondary ray; z is the last basic point, which still has
    z0 > 0 and is not a solution), STATUS_MAX_ITERATIONS (z as for the ray) or
    STATUS_NON_FINITE_OUTPUT.  q >= 0 returns z = 0 with 0 pivots; n = 0 returns empty
    arrays and STATUS_SOLVED.  The kernel does not check its input (see `solve_lcp`).
    """
    z, w, status, pivots, _ = _lemke(M, q, max_pivots)
    return z, w, status, pivots


@intrinsic
def _c_matrix(typingctx, flat, rows, cols):
    """flat's data (a C-contiguous 1D array) as a C-contiguous (rows, cols) array of integer
    sizes: the same memory, the sizes not checked against flat (`matrix_view` checks)."""
    if not (isinstance(flat, types.Array) and flat.ndim == 1 and flat.layout == "C"):
        return None
    if not (isinstance(rows, types.Integer) and isinstance(cols, types.Integer)):
        return None
    sig = types.Array(flat.dtype, 2, "C")(flat, rows, cols)

    def codegen(context, builder, sig, args):
        ary = make_array(sig.args[0])(context, builder, args[0])
        r = context.cast(builder, args[1], sig.args[1], types.intp)
        c = context.cast(builder, args[2], sig.args[2], types.intp)
        out = make_array(sig.return_type)(context, builder)
        strides = [builder.mul(c, ary.itemsize), ary.itemsize]
        populate_array(out, data=ary.data, shape=[r, c], strides=strides, itemsize=ary.itemsize, meminfo=ary.meminfo, parent=ary.parent)
        return impl_ret_borrowed(context, builder, sig.return_type, out._getvalue())

    return sig, codegen


@numba.njit(cache=True, inline="always")
def matrix_view(flat, rows, cols):
    """The first rows * cols entries of flat (C-contiguous, 1D) as a C-contiguous (rows, cols)
    view: `flat[: rows * cols].reshape((rows, cols))` without reshape's call into numba's
    helpers (normalize_reshape_value, _attempt_nocopy_reshape: about 14 ns a view, five views a
    spatial warm step). A view that does not fit in flat raises ValueError (as reshape raises
    on a size that does not match)."""
    if rows < 0 or cols < 0 or rows * cols > flat.shape[0]:
        raise ValueError("matrix_view: the view does not fit in its buffer")
    return _c_matrix(flat, rows, cols)


class LemkeWork(NamedTuple):
    """Lemke's arrays for LCPs of up to N unknowns (`lemke_work`), so that a caller that solves
    many (a rollout's warm steps) allocates them once; two flat buffers (each array a caller
    passes on is reference-counted at each call), viewed per solve as C-contiguous arrays of
    its own size n (`lemke_views`)."""

    f: np.ndarray  # (2 N * N + 9 N + (N + 1) N,) floats
    i: np.ndarray  # (8 N,) ints


@numba.njit(cache=True)
def lemke_work(n):
    """`LemkeWork` for LCPs of up to n unknowns."""
    return LemkeWork(np.empty(2 * n * n + 9 * n + (n + 1) * n), np.empty(8 * n, np.int64))


@numba.njit(cache=True, error_model="numpy", inline="always")
def lemke_views(work, n):
    """work's arrays for an LCP of n unknowns: Binv (n, n), the tableau's inverse basis; qbar,
    the basic variables' values; d, the entering column, and mag, its round-off scale; hist,
    each row's round-off scale; col (scratch); z2, w2, the polish's point; A (n + 1, n), its
    elimination; basis (ints), the basic variable of each row; cand, the ratio test's rows and
    the polish's basic set; idx, a pivot row's nonzeros; touched, the rows pivoted on so far,
    ascending (`_touch`), and marked, 1 at each of them."""
    f, i = work.f, work.i
    Binv = matrix_view(f, n, n)
    o = n * n
    qbar, d, mag, hist = f[o : o + n], f[o + n : o + 2 * n], f[o + 2 * n : o + 3 * n], f[o + 3 * n : o + 4 * n]
    col, z2, w2 = f[o + 4 * n : o + 5 * n], f[o + 5 * n : o + 6 * n], f[o + 6 * n : o + 7 * n]
    A = matrix_view(f[o + 7 * n :], n + 1, n)
    basis, cand, idx, touched, marked = i[:n], i[n : 2 * n], i[2 * n : 3 * n], i[3 * n : 4 * n], i[4 * n : 5 * n]
    return Binv, qbar, d, mag, hist, col, z2, w2, A, basis, cand, idx, touched, marked


@numba.njit(cache=True, error_model="numpy", inline="always")
def _transform_views(work, n):
    """work's arrays for `lemke_from_guess_into`, after `lemke_views`' (which its path uses):
    Mp (n, n), the columns of the LCP principally pivoted on the guess's basic set that the
    path has asked for; qp (n), its q; x (n), scratch; pos (n ints), each index's place in the
    basic set (-1: not in it); perm (n ints), the LU's row order; filled (n ints), 1 at each
    column of Mp made."""
    f, i = work.f, work.i
    o = n * n + 7 * n + (n + 1) * n
    Mp = matrix_view(f[o:], n, n)
    qp, x = f[o + n * n : o + n * n + n], f[o + n * n + n : o + n * n + 2 * n]
    return Mp, qp, x, i[5 * n : 6 * n], i[6 * n : 7 * n], i[7 * n : 8 * n]


@numba.njit(cache=True, error_model="numpy")
def _lu_into(A, perm, m):
    """A[:m, :m] = P L U in place (Gaussian elimination with partial pivoting, `_gauss_solve`'s
    rule and singularity test: `_pivot_row`): the multipliers below the diagonal, U on and above it, perm[k]
    the row swapped into row k at step k. Returns ok: False if A[:m, :m] is numerically
    singular."""
    amax = _largest_in_block(A, m)
    if not (amax > 0.0) or not np.isfinite(amax):
        return False
    for k in range(m):
        p = _pivot_row(A, k, m, amax)
        if p < 0:
            return False
        perm[k] = p
        if p != k:
            for j in range(m):
                t = A[k, j]
                A[k, j] = A[p, j]
                A[p, j] = t
        for i in range(k + 1, m):
            f = A[i, k] / A[k, k]
            A[i, k] = f
            if f != 0.0:
                for j in range(k + 1, m):
                    A[i, j] -= f * A[k, j]
    return True


@numba.njit(cache=True, error_model="numpy")
def _lu_solve_into(A, perm, m, x):
    """x[:m] = A^-1 x[:m] in place, A factored by `_lu_into` (its row swaps first, as LAPACK's
    getrs: the factorization swapped whole rows, multipliers included)."""
    for k in range(m):
        p = perm[k]
        if p != k:
            t = x[k]
            x[k] = x[p]
            x[p] = t
    for k in range(m):
        for i in range(k + 1, m):
            x[i] -= A[i, k] * x[k]
    for k in range(m - 1, -1, -1):
        s = x[k]
        for j in range(k + 1, m):
            s -= A[k, j] * x[j]
        x[k] = s / A[k, k]


@numba.njit(cache=True, error_model="numpy")
def _transformed_column(M, J, nj, A, perm, pos, x, Mp, j):
    """Column j of M principally pivoted on J[:nj] (Cottle-Pang-Stone, sec. 2.3: z_J and w_J
    trade places), into Mp[:, j], from the LU of M[J, J] in A (`_lu_into`): with X = M[J, J]^-1,
    for j in J, X e_j on J and M[N, J] X e_j on N; else -X M[J, j] on J and M[N, j] - M[N, J] X
    M[J, j] on N."""
    n = M.shape[0]
    inside = pos[j] >= 0
    for a in range(nj):
        x[a] = 0.0 if inside else M[J[a], j]
    if inside:
        x[pos[j]] = 1.0
    _lu_solve_into(A, perm, nj, x)
    sign = 1.0 if inside else -1.0
    for i in range(n):
        if pos[i] >= 0:
            Mp[i, j] = sign * x[pos[i]]
        else:
            s = 0.0
            for a in range(nj):
                s += M[i, J[a]] * x[a]
            Mp[i, j] = s if inside else M[i, j] - s


@numba.njit(cache=True, error_model="numpy")
def lemke_from_guess_into(M, q, guess, max_pivots, work, z, w, basic_z, J, A, tol):
    """Lemke's method started from a guessed complementary basis that does not solve the LCP
    (a warm start's guess after a contact was made, broken or changed from sticking to
    sliding), on the caller's arrays. The LCP principally pivoted on the guess's basic set J
    (z_J and w_J trade places: M' = the principal pivot transform, q' = the guess's point, (z_J,
    w_N)) has the guess as its standard basis; Lemke's method with its covering vector e and
    its lexicographic rule (`_lemke_path`) follows the path from there, building only the
    columns of M' that enter (`_transformed_column`, from the LU of M[J, J]). Its final basis,
    mapped back, is solved on M itself (`warm_guess_into`, as a guess is): the point returned
    is M's and its residual recomputed. Kept where that residual is at most tol; else (M[J, J]
    singular, the path not ending within n + 1 pivots, or the point not that accurate) Lemke
    from scratch on M (`lemke_into`).

    work: `LemkeWork` for at least n unknowns; z, w, basic_z: n each, set here (basic_z the
    final basis's flags; it may be guess itself, which is read first); J: n ints and A: (n +
    1, n), scratch. Returns (status, pivots: both paths', the residual of z and w: +inf where
    not solved)."""
    n = q.shape[0]
    Mp, qp, x, pos, perm, filled = _transform_views(work, n)
    nj = np.int64(0)
    for i in range(n):
        pos[i] = -1
        filled[i] = 0
        if guess[i]:
            J[nj] = i
            pos[i] = nj
            nj += 1
    pivots = 0
    for a in range(nj):
        for c in range(nj):
            A[a, c] = M[J[a], J[c]]
    lu = nj > 0 and n > 0 and _lu_into(A, perm, nj)
    if lu:
        for a in range(nj):  # q' = (z_J, w_N) of the guess: -X q_J on J, q_N + M[N, J] (-X q_J) on N
            x[a] = -q[J[a]]
        _lu_solve_into(A, perm, nj, x)
        for i in range(n):
            if pos[i] >= 0:
                qp[i] = x[pos[i]]
            else:
                s = q[i]
                for a in range(nj):
                    s += M[i, J[a]] * x[a]
                qp[i] = s
    if lu and not _nonnegative(qp):
        status, pivots = _lemke_start_and_path(Mp, qp, n + 1, work, (lu, M, J, nj, A, perm, pos, x, filled))
        if status == STATUS_SOLVED:
            for i in range(n):
                basic_z[i] = False
            _mark_basic_z(lemke_views(work, n)[9], n, basic_z)
            for i in range(n):  # back to M's variables: z_i basic where w'_i is, for i in J
                if pos[i] >= 0:
                    basic_z[i] = not basic_z[i]
            residual = warm_guess_into(M, q, basic_z, J, A, z, w)
            if residual <= tol:
                return STATUS_SOLVED, pivots, residual
    status, more = lemke_into(M, q, max_pivots, work, z, w, basic_z)
    solved = status == STATUS_SOLVED or status == STATUS_SOLVED_INACCURATE
    return status, pivots + more, natural_map_residual(z, w, q) if solved else np.inf


@numba.njit(cache=True, error_model="numpy")
def _lemke(M, q, max_pivots):
    """`lemke_kernel`, also returning the final basis as flags: basic_z[i] is True where z_i
    (not w_i) is basic in the complementary basis the path ended on (all False for q >= 0;
    meaningless unless the status is STATUS_SOLVED)."""
    n = q.shape[0]
    z = np.zeros(n)
    w = np.empty(n)
    basic_z = np.zeros(n, np.bool_)
    # q >= 0 (z = 0 solves it; n = 0 too): no pivot, so no tableau to make
    work = lemke_work(0 if n == 0 or _nonnegative(q) else n)
    status, pivots = lemke_into(M, q, max_pivots, work, z, w, basic_z)
    return z, w, status, pivots, basic_z


@numba.njit(cache=True, error_model="numpy")
def lemke_into(M, q, max_pivots, work, z, w, basic_z):
    """`_lemke` on the caller's arrays: work (`LemkeWork` for at least n = q.shape[0] unknowns),
    z, w and basic_z (n entries each, set here). Returns (status, pivots). The same operations
    in the same order as a solve on arrays of its own: the same bits."""
    n = q.shape[0]
    for i in range(n):
        z[i] = 0.0
        basic_z[i] = False
    if n == 0 or _nonnegative(q):
        _matvec_plus_into(M, z, q, w)
        return STATUS_SOLVED, 0
    Binv, qbar, d, mag, hist, col, z2, w2, A, basis, cand, idx, touched, marked = lemke_views(work, n)
    # (no column made on demand: the path reads M's own)
    status, pivots = _lemke_start_and_path(M, q, max_pivots, work, (n < 0, M, idx, np.int64(0), A, cand, touched, col, marked))
    for i in range(n):
        v = basis[i]
        if n <= v < 2 * n:
            z[v - n] = qbar[i]
    _matvec_plus_into(M, z, q, w)
    status = _lemke_polish(M, q, basis, cand, z2, w2, A, z, w, status)
    _mark_basic_z(basis, n, basic_z)
    return status, pivots


@numba.njit(cache=True, error_model="numpy", inline="always")
def _mark_basic_z(basis, n, basic_z):
    """basic_z[j] = True for each z_j basic in a Lemke tableau's basis (w_i = i, z_j = n + j, z0
    = 2n); the other flags are left as they are."""
    for i in range(n):
        if n <= basis[i] < 2 * n:
            basic_z[basis[i] - n] = True


@numba.njit(cache=True, error_model="numpy", inline="always")
def _lemke_start_and_path(M, q, max_pivots, work, lazy):
    """Lemke's tableau on work (`lemke_views`: Binv = I, qbar = q, the w's basic), its first
    pivot and its path (`_lemke_path`; lazy: as there). Some q_i < 0. Returns (status,
    pivots); the final basis and its values are work's basis and qbar."""
    n = q.shape[0]
    qscale = _max_abs(q)
    Binv, qbar, d, mag, hist, col, z2, w2, A, basis, cand, idx, touched, marked = lemke_views(work, n)
    for i in range(n):
        for j in range(n):
            Binv[i, j] = 0.0
        Binv[i, i] = 1.0
        qbar[i] = q[i]
        basis[i] = i  # basic variable of each row: w_i = i, z_j = n + j, z0 = 2n
        hist[i] = 1.0
        marked[i] = 0
    entering, zrow = _lemke_first_pivot(Binv, qbar, basis, d, cand, idx, hist, qscale, mag, marked)
    nt = _touch(touched, marked, 0, zrow)
    return _lemke_path(M, Binv, qbar, basis, d, mag, hist, col, cand, idx, touched, marked, nt, entering, zrow, qscale, max_pivots, lazy)


@numba.njit(cache=True, error_model="numpy")
def lemke_warm_kernel(M, q, max_pivots, guess, tol, droppable=0):
    """Lemke's method started from a guessed complementary basis: exact, and free when the
    guess is right (e.g. the previous time step's basis while the contacts persist).

    guess: bool (n,), True where z_i is to be basic (w_i otherwise). The guess is tried
    first: z_J = -M[J, J]^-1 q_J on J = {i : guess[i]}, z = 0 elsewhere, and w = M z + q
    recomputed; it is accepted when that point's natural-map residual
    (`complementarity_residual`: z >= 0, w >= 0 and z^T w = 0 at once) is at most tol. Else
    Lemke's method runs from the guessed basis (`lemke_from_guess_into`), and from scratch
    where that does not end on a point solving the LCP to tol (or M[J, J] is singular). droppable: where
    M[J, J] is singular, the guess is tried again without one of its basic rows among the first
    droppable (`warm_guess_dropping_into`; the contact step passes its normals' count).

    Returns (z, w, status, pivots, basic_z, warm, residual): as `lemke_kernel`, plus the final
    basis as flags (basic_z, the next guess; the guess itself when it was accepted), whether
    the guess was accepted (then pivots = 0 and status = STATUS_SOLVED) and the returned
    point's natural-map residual (`natural_map_residual` of z and w: the guess's, computed
    once, or Lemke's solution's).
    """
    n = q.shape[0]
    if n > 0:
        z = np.empty(n)
        w = np.empty(n)
        J, A = np.empty(n, np.int64), np.empty((n + 1, n))
        residual = warm_guess_dropping_into(M, q, guess, J, A, z, w, droppable, tol)
        if residual <= tol:
            return z, w, STATUS_SOLVED, 0, guess, True, residual
        basic_z = np.empty(n, np.bool_)
        status, pivots, residual = lemke_from_guess_into(M, q, guess, max_pivots, lemke_work(n), z, w, basic_z, J, A, tol)
        return z, w, status, pivots, basic_z, False, residual
    z, w, status, pivots, basic_z = _lemke(M, q, max_pivots)
    return z, w, status, pivots, basic_z, False, _natural_map_residual(z, w, q)


# without numba's runtime, named: a warm step compiled without it (`models.stepper.planar_warm_step`)
# called the copy the general step had compiled first, with it, and paid its reference counts (32 a
# step at the paper's squeeze, these three)
@numba.njit(cache=True, _nrt=False, error_model="numpy")
def warm_guess_into(M, q, guess, J, A, z, w):
    """`lemke_warm_kernel`'s guess, on the caller's arrays (J: n ints, A: (n + 1, n), z and w:
    n each, or larger): z_J = -M[J, J]^-1 q_J on the guessed basic set, z = 0 elsewhere, w = M z
    + q. Returns that point's natural-map residual (+inf where M[J, J] is numerically
    singular): the callers accept the guess at their tolerance and keep it as the solve's
    residual, not computing it again."""
    n = q.shape[0]
    nj = np.int64(0)
    for i in range(n):
        if guess[i]:
            J[nj] = i
            nj += 1
    if not _solve_on_into(M, q, J, nj, A, z):
        return np.inf
    _matvec_on_into(M, z, q, J, nj, w)
    return _natural_map_residual(z, w, q)


# without numba's runtime, named (as `warm_guess_into`)
@numba.njit(cache=True, _nrt=False, error_model="numpy")
def warm_guess_dropping_into(M, q, guess, J, A, z, w, droppable, tol):
    """`warm_guess_into`, and where M[J, J] is numerically singular, the guess again without one
    of its basic rows among the first droppable, in order; the first whose point's residual is
    at most tol is kept, and guess is changed to it. Redundant rows guessed basic are what makes
    M[J, J] singular: a rigid box's four coplanar corners on a table, whose normals span three
    of its DOFs, all guessed to push (a cold guess, `models.stepper._fill_basis_guess`), where
    the LCP's solutions load three of them. Returns the residual of the point left in z and w:
    the guess's, or the kept drop's; +inf where M[J, J] is singular and no drop solves the LCP
    (guess then as given)."""
    residual = warm_guess_into(M, q, guess, J, A, z, w)
    if residual != np.inf:
        return residual
    for k in range(min(droppable, q.shape[0])):
        if guess[k]:
            guess[k] = False
            residual = warm_guess_into(M, q, guess, J, A, z, w)
            if residual <= tol:
                return residual
            guess[k] = True
    return np.inf


@numba.njit(cache=True, error_model="numpy", inline="always")
def _nonnegative(q):
    """True iff every q_i >= 0 (False on NaN): the LCP is solved by z = 0."""
    for i in range(q.shape[0]):
        if not (q[i] >= 0.0):
            return False
    return True


@numba.njit(cache=True, error_model="numpy", inline="always")
def _max_abs(q):
    """||q||_inf (NaN entries ignored)."""
    qscale = 0.0
    for i in range(q.shape[0]):
        if abs(q[i]) > qscale:
            qscale = abs(q[i])
    return qscale


@numba.njit(cache=True, error_model="numpy")
def _lemke_first_pivot(Binv, qbar, basis, d, cand, idx, hist, qscale, ones, marked):
    """Lemke's first pivot, in place: z0 enters (column -e) in the lexicographically smallest
    row of (q, I), i.e. (one of) the most negative q_i, which makes the basis feasible. ones:
    scratch (n), the ratio test's divisors; marked: all 0 (Binv = I).

    Returns (entering, zrow): the next entering variable (the complement of the w that left)
    and the row where z0 is basic.
    """
    n = qbar.shape[0]
    for i in range(n):
        d[i] = -1.0
        cand[i] = i
        ones[i] = 1.0
    r = _lex_select(qbar, Binv, ones, cand, n, LEMKE_TIE_TOL, np.int64(-1), qscale, hist, marked)
    leaving = basis[r]
    _pivot(Binv, qbar, d, r, idx, hist)
    basis[r] = 2 * n
    return leaving + n, r  # the complement of w_r is z_r


@numba.njit(cache=True, error_model="numpy")
def _lemke_path(M, Binv, qbar, basis, d, mag, hist, col, cand, idx, touched, marked, nt, entering, zrow, qscale, max_pivots, lazy):
    """Follow Lemke's complementary path from the first pivot, in place on the tableau
    (Binv, qbar, basis): entering column, lexicographic ratio test, pivot, until z0 leaves.
    touched, marked, nt: the rows pivoted on so far (`_touch`: the first pivot's row). lazy:
    (on, M0, J, nj, A, perm, pos, x, filled); where on, M is a principal pivot transform of M0
    whose columns are made as they enter (`_transformed_column`; filled: 1 at each made).

    Returns (status, pivots): STATUS_SOLVED (z0 left), STATUS_RAY_TERMINATION (no pivot row),
    STATUS_NON_FINITE_OUTPUT or STATUS_MAX_ITERATIONS; pivots counts the first one too.
    """
    n = qbar.shape[0]
    z0 = 2 * n
    pivots = 1
    status = STATUS_MAX_ITERATIONS
    on, M0, J, nj, A, perm, pos, x, filled = lazy
    while pivots < max_pivots:
        if on and n <= entering < 2 * n and filled[entering - n] == 0:
            _transformed_column(M0, J, nj, A, perm, pos, x, M, entering - n)
            filled[entering - n] = 1
        amax = _entering_column(M, Binv, entering, n, d, mag, col, idx, touched, marked, nt)
        dmax = 0.0
        for i in range(n):
            if abs(d[i]) > dmax:
                dmax = abs(d[i])
        if not np.isfinite(dmax):
            status = STATUS_NON_FINITE_OUTPUT
            break
        ncand = np.int64(0)
        for i in range(n):
            if d[i] > LEMKE_PIVOT_TOL * max(mag[i], hist[i] * amax):
                cand[ncand] = i
                ncand += 1
        if ncand == 0:
            status = STATUS_RAY_TERMINATION
            break
        r = _lex_select(qbar, Binv, d, cand, ncand, LEMKE_TIE_TOL, zrow, qscale, hist, marked)
        leaving = basis[r]
        _pivot(Binv, qbar, d, r, idx, hist)
        nt = _touch(touched, marked, nt, r)
        basis[r] = entering
        pivots += 1
        if leaving == z0:  # complementary basis reached: a solution
            status = STATUS_SOLVED
            break
        entering = leaving + n if leaving < n else leaving - n
        finite = True
        for i in range(n):
            if not np.isfinite(qbar[i]):
                finite = False
                break
        if not finite:
            status = STATUS_NON_FINITE_OUTPUT
            break
    return status, pivots


@numba.njit(cache=True, error_model="numpy")
def _lemke_polish(M, q, basis, J, z2, w2, A, z, w, status):
    """Polish the end point (z, w) of a path that stopped SOLVED or on a ray, in place: the
    complementary point of the final basis (w_J = 0 on the basic z_J, z = 0 elsewhere)
    recomputed from the true q replaces it if its residual is lower; a ray end point that
    solves the LCP to LEMKE_RESCUE_TOL becomes STATUS_SOLVED. J (ints), z2, w2 (n each), A
    ((n + 1, n)): scratch. Returns the status."""
    n = q.shape[0]
    if status == STATUS_SOLVED or status == STATUS_RAY_TERMINATION:
        nj = np.int64(0)
        for i in range(n):
            if n <= basis[i] < 2 * n:
                J[nj] = basis[i] - n
                nj += 1
        if _solve_on_into(M, q, J, nj, A, z2):
            _matvec_plus_into(M, z2, q, w2)
            if _natural_map_residual(z2, w2, q) < _natural_map_residual(z, w, q):
                for i in range(n):
                    z[i] = z2[i]
                    w[i] = w2[i]
        if status == STATUS_RAY_TERMINATION and _natural_map_residual(z, w, q) <= LEMKE_RESCUE_TOL:
            # The ray starts where z0 is (numerically) zero: the current point already
            # solves the LCP (z0 tied for leaving but round-off broke the tie the other way).
            status = STATUS_SOLVED
    return status


# without numba's runtime, named (as `warm_guess_into`)
@numba.njit(cache=True, _nrt=False, error_model="numpy")
def _solve_on_into(M, q, J, nj, A, z):
    """z_J = -M[J, J]^-1 q_J on the nj indices J[:nj], z = 0 elsewhere, on the caller's A (at
    least (nj + 1, nj): M[J, J] and, in row nj, -q_J, for `_gauss_solve`) and z (at least n
    entries). Returns ok: False where M[J, J] is numerically singular (then z = 0)."""
    n = q.shape[0]
    for a in range(nj):
        A[nj, a] = -q[J[a]]
        for c in range(nj):
            A[a, c] = M[J[a], J[c]]
    ok = _gauss_solve(A, nj)
    for i in range(n):
        z[i] = 0.0
    if ok:
        for a in range(nj):
            z[J[a]] = A[nj, a]
    return ok


# --------------------------------------------------------------------------------------------
# Projected Gauss-Seidel.
# --------------------------------------------------------------------------------------------
@numba.njit(cache=True, error_model="numpy")
def pgs_kernel(M, q, z0, max_iters, tol, omega):
    """Projected Gauss-Seidel with over-relaxation (projected SOR).

    One sweep: for i = 0..n-1, ``z_i <- max(0, z_i - omega * (M[i, :] z + q_i) / M[i, i])``.
    Starts from ``max(z0, 0)``; after every sweep recomputes w = M z + q and stops when the
    natural-map residual (see `complementarity_residual`) is <= tol.  Converges for
    symmetric positive definite M when 0 < omega < 2.

    Returns ``(z, w, status_code, iterations)``: STATUS_SOLVED (residual <= tol after
    ``iterations`` sweeps), STATUS_MAX_ITERATIONS (last iterate returned),
    STATUS_ZERO_DIAGONAL (some M[i, i] <= PGS_ZERO_DIAGONAL_TOL * max|diag| or <= 0; nothing
    is iterated, z = max(z0, 0)) or STATUS_NON_FINITE_OUTPUT (the iterates overflowed).
    n = 0 returns empty arrays and STATUS_SOLVED.  The kernel does not check its input.
    """
    n = q.shape[0]
    z = np.empty(n)
    for i in range(n):
        z[i] = max(z0[i], 0.0)
    if n == 0:
        return z, np.zeros(0), STATUS_SOLVED, 0
    dmax = 0.0
    for i in range(n):
        if abs(M[i, i]) > dmax:
            dmax = abs(M[i, i])
    for i in range(n):
        if not (M[i, i] > 0.0 and M[i, i] > PGS_ZERO_DIAGONAL_TOL * dmax):
            return z, _matvec_plus(M, z, q), STATUS_ZERO_DIAGONAL, 0
    w = _matvec_plus(M, z, q)
    if _natural_map_residual(z, w, q) <= tol:
        return z, w, STATUS_SOLVED, 0
    for it in range(max_iters):
        for i in range(n):
            s = q[i]
            for j in range(n):
                s += M[i, j] * z[j]
            v = z[i] - omega * s / M[i, i]
            z[i] = v if v > 0.0 else 0.0
        w = _matvec_plus(M, z, q)
        res = _natural_map_residual(z, w, q)
        if res <= tol:
            return z, w, STATUS_SOLVED, it + 1
        if not np.isfinite(res):
            return z, w, STATUS_NON_FINITE_OUTPUT, it + 1
    return z, w, STATUS_MAX_ITERATIONS, max_iters


# --------------------------------------------------------------------------------------------
# Python-facing API.
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LCPResult:
    """Result of `solve_lcp`.

    z, w: float64 arrays of shape (n,) with w = M z + q recomputed from M, q and z (empty
    arrays for INVALID_INPUT; z = 0 and w = NaN for NON_FINITE_INPUT).  On failure z is the
    solver's last iterate and is *not* a solution.  residual: `complementarity_residual`
    of z (+inf when it cannot be computed).  iterations: Lemke pivots or PGS sweeps.
    method: "lemke" or "pgs".
    """

    z: np.ndarray
    w: np.ndarray
    status: LCPStatus
    residual: float
    iterations: int
    method: str

    @property
    def success(self) -> bool:
        """True iff status is SOLVED (residual <= the tolerance that was asked for)."""
        return self.status is LCPStatus.SOLVED

    @property
    def message(self) -> str:
        return self.status.message


_METHODS = ("lemke", "pgs")


def default_max_iterations(method: str, n: int) -> int:
    """Default limit: Lemke DEFAULT_LEMKE_PIVOTS_PER_VARIABLE * (n + 1) pivots, PGS
    DEFAULT_PGS_MAX_ITERATIONS sweeps.  Raises ValueError for an unknown method."""
    if method == "lemke":
        return DEFAULT_LEMKE_PIVOTS_PER_VARIABLE * (n + 1)
    if method == "pgs":
        return DEFAULT_PGS_MAX_ITERATIONS
    raise ValueError(f"unknown LCP method {method!r}; expected one of {_METHODS}")


def _fail(status: LCPStatus, method: str, n: int | None) -> LCPResult:
    if n is None:
        z = np.zeros(0)
        w = np.zeros(0)
    else:
        z = np.zeros(n)
        w = np.full(n, np.nan)
    return LCPResult(z=z, w=w, status=status, residual=float("inf"), iterations=0, method=method)


def solve_lcp(
    M,
    q,
    method: str = "lemke",
    *,
    z0=None,
    max_iterations: int | None = None,
    tol: float = DEFAULT_TOL,
    omega: float = 1.0,
) -> LCPResult:
    """Solve LCP(M, q): z >= 0, w = M z + q >= 0, z^T w = 0.

    Parameters
    ----------
    M : array_like (n, n)   -- converted to a C-contiguous float64 array.
    q : array_like (n,)
    method : "lemke" (default) or "pgs".  Any other value raises ValueError (the only
        exception this function raises).
    z0 : array_like (n,), optional -- PGS warm start (default zeros); ignored by Lemke.
    max_iterations : Lemke pivot limit (default 50 (n + 1)) or PGS sweep limit (default
        10 000).
    tol : acceptance tolerance on the recomputed residual (default 1e-9).
    omega : PGS relaxation factor in (0, 2); 1 is plain PGS.

    Returns
    -------
    LCPResult.  ``w`` and ``residual`` are always recomputed here from M, q and z.  A kernel
    success is downgraded to SOLVED_INACCURATE (tol < residual <= 1e-6), NUMERICAL_FAILURE
    (residual above that) or NON_FINITE_OUTPUT.  Kernel failures are kept as they are
    (RAY_TERMINATION, MAX_ITERATIONS, ZERO_DIAGONAL, ...).  Shape or parameter errors give
    INVALID_INPUT and NaN/inf in M, q or z0 give NON_FINITE_INPUT, with no exception.
    """
    if method not in _METHODS:
        raise ValueError(f"unknown LCP method {method!r}; expected one of {_METHODS}")
    with np.errstate(all="ignore"):
        checked = _lcp_input(M, q, method, z0, max_iterations, tol, omega)
        if isinstance(checked, LCPResult):
            return checked
        M, q, z0a, max_iterations, tol, omega = checked
        if method == "lemke":
            z, _, code, iters = lemke_kernel(M, q, max_iterations)
        else:
            z, _, code, iters = pgs_kernel(M, q, z0a, max_iterations, tol, omega)
        z = np.asarray(z, dtype=np.float64)
        w = M @ z + q
        residual = float(complementarity_residual(M, q, z))
        status = _recomputed_status(LCPStatus(int(code)), z, w, residual, tol)
        return LCPResult(z=z, w=w, status=status, residual=residual, iterations=int(iters), method=method)


def _lcp_input(M, q, method, z0, max_iterations, tol, omega):
    """Validate and convert `solve_lcp`'s input (call under np.errstate(all="ignore")).

    Returns (M, q, z0, max_iterations, tol, omega) as C-contiguous float64 arrays, int and
    floats (z0 zeros when not given, max_iterations defaulted), or the failure LCPResult:
    INVALID_INPUT for bad shapes or parameters, NON_FINITE_INPUT for NaN/inf in M, q or z0.
    """
    try:
        if np.iscomplexobj(M) or np.iscomplexobj(q):
            raise TypeError("complex input")
        M = np.ascontiguousarray(M, dtype=np.float64)
        q = np.ascontiguousarray(q, dtype=np.float64)
    except Exception:  # noqa: BLE001 - anything not convertible to floats is invalid input
        return _fail(LCPStatus.INVALID_INPUT, method, None)
    if q.ndim != 1 or M.ndim != 2 or M.shape != (q.shape[0], q.shape[0]):
        return _fail(LCPStatus.INVALID_INPUT, method, None)
    n = q.shape[0]
    try:
        tol = float(tol)
        omega = float(omega)
        if max_iterations is None:
            max_iterations = default_max_iterations(method, n)
        if isinstance(max_iterations, bool) or int(max_iterations) != max_iterations:
            raise ValueError
        max_iterations = int(max_iterations)
        if z0 is not None and np.iscomplexobj(z0):
            raise TypeError("complex z0")
        z0a = np.zeros(n) if z0 is None else np.ascontiguousarray(z0, dtype=np.float64)
    except Exception:  # noqa: BLE001
        return _fail(LCPStatus.INVALID_INPUT, method, n)
    if not (tol > 0.0 and np.isfinite(tol)) or not (0.0 < omega < 2.0) or max_iterations < 0 or z0a.shape != (n,):
        return _fail(LCPStatus.INVALID_INPUT, method, n)
    if not (np.isfinite(M).all() and np.isfinite(q).all() and np.isfinite(z0a).all()):
        return _fail(LCPStatus.NON_FINITE_INPUT, method, n)
    return M, q, z0a, max_iterations, tol, omega


def _recomputed_status(status: LCPStatus, z, w, residual: float, tol: float) -> LCPStatus:
    """The status of a kernel's result judged on the recomputed w and residual: a kernel
    SOLVED becomes NON_FINITE_OUTPUT, SOLVED (residual <= tol), SOLVED_INACCURATE (up to
    INACCURATE_TOL) or NUMERICAL_FAILURE; any other kernel status is kept."""
    if status is LCPStatus.SOLVED:
        if not (np.isfinite(z).all() and np.isfinite(w).all()):
            status = LCPStatus.NON_FINITE_OUTPUT
        elif residual <= tol:
            status = LCPStatus.SOLVED
        elif residual <= max(INACCURATE_TOL, tol):
            status = LCPStatus.SOLVED_INACCURATE
        else:
            status = LCPStatus.NUMERICAL_FAILURE
    return status


# --------------------------------------------------------------------------------------------
# 2D frictional contact (fc2d) <-> LCP.
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Fc2dLCP:
    """An fc2d problem rewritten as LCP(M, q) (see `contact_lcp_from_fc2d`).

    normal_index[c], plus_index[c], minus_index[c], gamma_index[c] are the positions of
    contact c's r_n, b+, b-, gamma in the LCP vector (-1 for the last three when mu_c = 0).
    gamma_scale[c]: the LCP variable at gamma_index[c] is gamma_c / gamma_scale[c] (gamma is
    rescaled to force units so that all blocks of M have the scale of W).
    """

    M: np.ndarray
    q: np.ndarray
    mu: np.ndarray
    n_contacts: int
    normal_index: np.ndarray
    plus_index: np.ndarray
    minus_index: np.ndarray
    gamma_index: np.ndarray
    gamma_scale: np.ndarray


def _check_fc2d(W, q, mu):
    W = np.ascontiguousarray(W, dtype=np.float64)
    q = np.ascontiguousarray(q, dtype=np.float64)
    mu = np.ascontiguousarray(mu, dtype=np.float64).reshape(-1)
    nc = mu.shape[0]
    if q.shape != (2 * nc,) or W.shape != (2 * nc, 2 * nc):
        raise ValueError(f"fc2d shapes: need W (2nc, 2nc), q (2nc,), mu (nc,); got W {W.shape}, q {q.shape}, mu {mu.shape}")
    if not (np.isfinite(mu).all() and (mu >= 0).all()):
        raise ValueError("fc2d friction coefficients must be finite and >= 0")
    return W, q, mu, nc


def contact_lcp_from_fc2d(W, q, mu) -> Fc2dLCP:
    """Rewrite a 2D frictional contact problem (local form) as an LCP.

    fc2d problem: nc contacts, reaction r = (r_n^1, r_t^1, ..., r_n^nc, r_t^nc) (normal then
    tangential per contact), local velocity u = W r + q, and for each contact

        0 <= u_n  _|_  r_n >= 0,     |r_t| <= mu r_n,
        u_t != 0  =>  r_t = -mu r_n sign(u_t)      (Coulomb, maximal dissipation).

    Construction (the two-direction polyhedral cone; exact in 2D): split r_t = b+ - b- with
    b+, b- >= 0 and add gamma >= 0, the sliding speed.  The per-contact LCP variables are
    (r_n, b+, b-, gamma) and the complementarity pairs are

        u_n              >= 0  _|_  r_n   >= 0
        u_t  + gamma     >= 0  _|_  b+    >= 0
        -u_t + gamma     >= 0  _|_  b-    >= 0
        mu r_n - b+ - b- >= 0  _|_  gamma >= 0

    With u = W r + q and r_t = b+ - b- this is LCP(M, q_lcp); for contact blocks a, c
    (n = normal, t = tangential entries of W):

        rows of a \\ cols of c:  r_n        b+         b-         gamma
        u_n                    W_nn       W_nt       -W_nt      0
        u_t + gamma            W_tn       W_tt       -W_tt      [a == c]
        -u_t + gamma           -W_tn      -W_tt      W_tt       [a == c]
        mu r_n - b+ - b-       mu_a[a==c] -[a==c]    -[a==c]    0

    and q_lcp = (q_n, q_t, -q_t, 0) per contact.  Scaling: the gamma column and row of each
    contact are multiplied by s_c = max(W_nn, W_tt) of that contact, rounded to a power of
    two (a symmetric diagonal scaling, so the LCP solution is unchanged except that the
    variable becomes gamma / s_c); this keeps the unit entries of the friction rows at the
    scale of W, which Lemke's pivoting needs when W is far from 1 (e.g. 1e3 or 1e-4 in SI
    units).  If gamma > 0 then b+ + b- = mu r_n and
    gamma = |u_t|, and the complementarity forces the force component opposite to the
    sliding direction to vanish: exactly Coulomb's law.

    Properties: for z >= 0, z^T M z = r^T W r + sum_c mu_c gamma_c r_n,c, so M is copositive
    when W is positive semidefinite (but not copositive-plus in general; Lemke's method is
    known to process this LCP class, Anitescu & Potra 1997).  Every gamma row has a zero
    diagonal, so PGS cannot be applied to this LCP (it reports ZERO_DIAGONAL).

    Contacts with mu = 0 keep only r_n (their b+, b-, gamma are dropped; r_t = 0).

    Raises ValueError on inconsistent shapes or negative / non-finite mu.  Variables are
    ordered contact by contact.
    """
    W, q, mu, nc = _check_fc2d(W, q, mu)
    normal, plus, minus, gamma, m = _fc2d_layout(mu)
    fr = np.flatnonzero(mu > 0.0)
    nI = 2 * np.arange(nc)  # rows/cols of W for normals
    tI = nI + 1  # tangentials
    M = np.zeros((m, m))
    ql = np.zeros(m)
    gscale = _fc2d_gamma_scale(W, nI, tI, nc)
    _fc2d_normal_rows(M, ql, W, q, normal, plus, minus, fr, nI, tI)
    if fr.size:
        _fc2d_friction_rows(M, ql, W, q, mu, normal, plus, minus, gamma, fr, tI, nI, gscale)
    return Fc2dLCP(
        M=M,
        q=ql,
        mu=mu,
        n_contacts=nc,
        normal_index=normal,
        plus_index=plus,
        minus_index=minus,
        gamma_index=gamma,
        gamma_scale=gscale,
    )


def _fc2d_layout(mu):
    """LCP variable layout of `contact_lcp_from_fc2d`, contact by contact: the positions of
    each contact's r_n, b+, b-, gamma (-1 for the last three when mu = 0) and the size m."""
    nc = mu.shape[0]
    normal = np.full(nc, -1, dtype=np.int64)
    plus = np.full(nc, -1, dtype=np.int64)
    minus = np.full(nc, -1, dtype=np.int64)
    gamma = np.full(nc, -1, dtype=np.int64)
    k = 0
    for c in range(nc):
        normal[c] = k
        k += 1
        if mu[c] > 0.0:
            plus[c], minus[c], gamma[c] = k, k + 1, k + 2
            k += 3
    return normal, plus, minus, gamma, k


def _fc2d_gamma_scale(W, nI, tI, nc):
    """Per-contact scale s_c of the gamma row and column: max(|W_nn|, |W_tt|) rounded to a
    power of two (1 where both are zero)."""
    diag_scale = np.maximum(np.abs(W[nI, nI]), np.abs(W[tI, tI]))
    gscale = np.ones(nc)
    pos = diag_scale > 0.0
    gscale[pos] = np.exp2(np.round(np.log2(diag_scale[pos])))
    return gscale


def _fc2d_normal_rows(M, ql, W, q, normal, plus, minus, fr, nI, tI):
    """Fill the u_n rows of the fc2d LCP in place: W_nn, W_nt, -W_nt and q_n."""
    M[np.ix_(normal, normal)] = W[np.ix_(nI, nI)]
    M[np.ix_(normal, plus[fr])] = W[np.ix_(nI, tI[fr])]
    M[np.ix_(normal, minus[fr])] = -W[np.ix_(nI, tI[fr])]
    ql[normal] = q[nI]


def _fc2d_friction_rows(M, ql, W, q, mu, normal, plus, minus, gamma, fr, tI, nI, gscale):
    """Fill the rows of the frictional contacts fr in place: u_t + gamma, -u_t + gamma and
    the scaled cone row mu r_n - b+ - b- (gamma column and row scaled by gscale)."""
    P, Mi, G = plus[fr], minus[fr], gamma[fr]
    Wtn = W[np.ix_(tI[fr], nI)]
    Wtt = W[np.ix_(tI[fr], tI[fr])]
    M[np.ix_(P, normal)] = Wtn
    M[np.ix_(P, P)] = Wtt
    M[np.ix_(P, Mi)] = -Wtt
    sc = gscale[fr]
    M[P, G] = sc
    M[np.ix_(Mi, normal)] = -Wtn
    M[np.ix_(Mi, P)] = -Wtt
    M[np.ix_(Mi, Mi)] = Wtt
    M[Mi, G] = sc
    M[G, normal[fr]] = sc * mu[fr]
    M[G, P] = -sc
    M[G, Mi] = -sc
    ql[P] = q[tI[fr]]
    ql[Mi] = -q[tI[fr]]


def fc2d_reactions_from_lcp(problem: Fc2dLCP, z) -> np.ndarray:
    """Map an LCP solution of `contact_lcp_from_fc2d` back to r = (r_n, r_t) per contact.

    Returns a (2 nc,) array, normal then tangential per contact: r_n = z[normal], r_t =
    z[b+] - z[b-] (0 for frictionless contacts).
    """
    z = np.asarray(z, dtype=np.float64)
    if z.shape != problem.q.shape:
        raise ValueError(f"z has shape {z.shape}, expected {problem.q.shape}")
    nc = problem.n_contacts
    r = np.zeros(2 * nc)
    r[0::2] = z[problem.normal_index]
    fr = problem.plus_index >= 0
    rt = np.zeros(nc)
    rt[fr] = z[problem.plus_index[fr]] - z[problem.minus_index[fr]]
    r[1::2] = rt
    return r


def fc2d_coulomb_error(W, q, mu, r) -> float:
    """Coulomb-law error of reactions r for the fc2d problem (W, q, mu); u = W r + q.

    Per contact (r_n, r_t, u_n, u_t), with the non-associated Coulomb law of
    `contact_lcp_from_fc2d`, the max of

        |min(r_n, u_n)|                                  normal complementarity,
        max(0, |r_t| - mu r_n)                           cone feasibility,
        |r_t - clip(r_t - u_t, -mu r_n+, mu r_n+)|       sliding opposite to u_t
                                                         (r_n+ = max(r_n, 0)),

    each zero exactly when the contact satisfies Coulomb's law; the maximum over contacts is
    divided by (1 + ||q||_inf).  Returns +inf if anything is non-finite.  Raises ValueError
    on inconsistent shapes.
    """
    W, q, mu, nc = _check_fc2d(W, q, mu)
    r = np.asarray(r, dtype=np.float64)
    if r.shape != (2 * nc,):
        raise ValueError(f"r has shape {r.shape}, expected {(2 * nc,)}")
    with np.errstate(all="ignore"):
        u = W @ r + q
        if not (np.isfinite(u).all() and np.isfinite(r).all()):
            return float("inf")
        if nc == 0:
            return 0.0
        rn, rt, un, ut = r[0::2], r[1::2], u[0::2], u[1::2]
        e_n = np.abs(np.minimum(rn, un))
        e_cone = np.maximum(0.0, np.abs(rt) - mu * rn)
        bound = mu * np.maximum(rn, 0.0)
        e_t = np.abs(rt - np.clip(rt - ut, -bound, bound))
        err = max(e_n.max(), e_cone.max(), e_t.max())
        return float(err / (1.0 + np.abs(q).max()))

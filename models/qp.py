"""Convex QPs through OSQP (the one module that imports osqp), with honest statuses.

    minimise 1/2 x^T P x + c^T x   subject to   lower <= A x <= upper

`solve_qp` never raises on numerical trouble: the result carries a `QPStatus` whose message
explains itself, and residuals recomputed here from the problem data (never OSQP's own
flag alone): the primal residual max(lower - A x, A x - upper, 0) and the dual (stationarity)
residual ||P x + c + A^T y||_inf, both scaled by 1 + the largest data entry involved.
Invalid shapes and non-finite data come back as statuses too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import scipy.sparse as sp

#: OSQP tolerances (absolute and relative); tight, since the problems are small.
EPS_ABS = 1e-9
EPS_REL = 1e-9
MAX_ITERATIONS = 20_000
#: A recomputed (scaled) residual above this downgrades "solved" to "solved inaccurately".
RESIDUAL_TOLERANCE = 1e-6


class QPStatus(IntEnum):
    SOLVED = 0
    SOLVED_INACCURATE = 1
    PRIMAL_INFEASIBLE = 2
    DUAL_INFEASIBLE = 3
    MAX_ITERATIONS = 4
    NON_FINITE_INPUT = 5
    INVALID_INPUT = 6
    SOLVER_ERROR = 7

    @property
    def message(self) -> str:
        return _MESSAGES[self]


_MESSAGES = {
    QPStatus.SOLVED: "solved",
    QPStatus.SOLVED_INACCURATE: "solved, but the recomputed residuals exceed the tolerance",
    QPStatus.PRIMAL_INFEASIBLE: "the constraints cannot all hold (primal infeasible)",
    QPStatus.DUAL_INFEASIBLE: "the objective is unbounded below (dual infeasible)",
    QPStatus.MAX_ITERATIONS: "OSQP reached its iteration limit; try a looser tolerance or rescale",
    QPStatus.NON_FINITE_INPUT: "the problem data hold NaN or infinity (bounds may be infinite)",
    QPStatus.INVALID_INPUT: "the matrices and vectors have inconsistent shapes or P is not square",
    QPStatus.SOLVER_ERROR: "OSQP failed during setup or solve (e.g. P not positive semidefinite)",
}


@dataclass(frozen=True)
class QPResult:
    x: np.ndarray
    y: np.ndarray
    status: QPStatus
    primal_residual: float
    dual_residual: float
    iterations: int
    osqp_status: str

    @property
    def success(self) -> bool:
        return self.status == QPStatus.SOLVED

    @property
    def message(self) -> str:
        return self.status.message


def _failure(status: QPStatus, n: int, m: int, note: str = "") -> QPResult:
    return QPResult(np.full(n, np.nan), np.full(m, np.nan), status, math.inf, math.inf, 0, note)


def solve_qp(
    P, c, A, lower, upper, *, eps_abs: float = EPS_ABS, eps_rel: float = EPS_REL, max_iterations: int = MAX_ITERATIONS
) -> QPResult:
    """Solve the QP above. P (n, n) symmetric PSD (upper triangle used), A (m, n); bounds may be +-inf."""
    try:
        P = sp.csc_matrix(P, dtype=float)
        A = sp.csc_matrix(A, dtype=float)
        c = np.asarray(c, dtype=float).ravel()
        lower = np.asarray(lower, dtype=float).ravel()
        upper = np.asarray(upper, dtype=float).ravel()
    except (TypeError, ValueError):
        return _failure(QPStatus.INVALID_INPUT, 0, 0, "could not read the data as arrays")
    n, m = c.shape[0], lower.shape[0]
    if P.shape != (n, n) or A.shape != (m, n) or upper.shape[0] != m:
        return _failure(QPStatus.INVALID_INPUT, n, m)
    if not (np.all(np.isfinite(P.data)) and np.all(np.isfinite(A.data)) and np.all(np.isfinite(c))):
        return _failure(QPStatus.NON_FINITE_INPUT, n, m)
    if np.any(np.isnan(lower)) or np.any(np.isnan(upper)) or np.any(lower == np.inf) or np.any(upper == -np.inf):
        return _failure(QPStatus.NON_FINITE_INPUT, n, m)
    if np.any(lower > upper):
        return _failure(QPStatus.PRIMAL_INFEASIBLE, n, m, "lower > upper")
    if n == 0:
        return QPResult(np.zeros(0), np.zeros(m), QPStatus.SOLVED, 0.0, 0.0, 0, "empty")

    import osqp

    solver = osqp.OSQP()
    try:
        solver.setup(
            sp.triu(P, format="csc"),
            c,
            A,
            lower,
            upper,
            verbose=False,
            eps_abs=eps_abs,
            eps_rel=eps_rel,
            max_iter=max_iterations,
            polishing=True,
            eps_prim_inf=1e-10,
            eps_dual_inf=1e-10,
        )
        result = solver.solve(raise_error=False)
    except Exception as exc:  # OSQP raises its own errors for non-convex P and the like
        return _failure(QPStatus.SOLVER_ERROR, n, m, str(exc))
    name = str(result.info.status)
    x = np.asarray(result.x, dtype=float)
    y = np.asarray(result.y, dtype=float)
    status = _STATUS_FROM_OSQP.get(result.info.status_val, QPStatus.SOLVER_ERROR)
    if status not in (QPStatus.SOLVED, QPStatus.SOLVED_INACCURATE, QPStatus.MAX_ITERATIONS):
        return QPResult(np.full(n, np.nan), np.full(m, np.nan), status, math.inf, math.inf, int(result.info.iter), name)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        return QPResult(x, y, QPStatus.SOLVER_ERROR, math.inf, math.inf, int(result.info.iter), name)
    primal, dual = residuals(P, c, A, lower, upper, x, y)
    if status == QPStatus.SOLVED and max(primal, dual) > RESIDUAL_TOLERANCE:
        status = QPStatus.SOLVED_INACCURATE
    return QPResult(x, y, status, primal, dual, int(result.info.iter), name)


def residuals(P, c, A, lower, upper, x, y) -> tuple[float, float]:
    """Scaled primal and dual residuals of (x, y), recomputed from the data."""
    Ax = A @ x
    violation = np.concatenate([np.maximum(lower - Ax, 0.0), np.maximum(Ax - upper, 0.0), [0.0]])
    finite_bounds = np.concatenate([lower[np.isfinite(lower)], upper[np.isfinite(upper)], [0.0]])
    primal = float(np.max(violation)) / (1.0 + float(np.max(np.abs(finite_bounds))))
    stationarity = P @ x + c + A.T @ y
    scale = 1.0 + max(float(np.max(np.abs(c), initial=0.0)), float(np.max(np.abs(P.data), initial=0.0)))
    dual = float(np.max(np.abs(stationarity), initial=0.0)) / scale
    return primal, dual


def _status_table() -> dict[int, QPStatus]:
    import osqp

    members = osqp.SolverStatus.__members__
    table = {
        "OSQP_SOLVED": QPStatus.SOLVED,
        "OSQP_SOLVED_INACCURATE": QPStatus.SOLVED_INACCURATE,
        "OSQP_PRIMAL_INFEASIBLE": QPStatus.PRIMAL_INFEASIBLE,
        "OSQP_PRIMAL_INFEASIBLE_INACCURATE": QPStatus.PRIMAL_INFEASIBLE,
        "OSQP_DUAL_INFEASIBLE": QPStatus.DUAL_INFEASIBLE,
        "OSQP_DUAL_INFEASIBLE_INACCURATE": QPStatus.DUAL_INFEASIBLE,
        "OSQP_MAX_ITER_REACHED": QPStatus.MAX_ITERATIONS,
        "OSQP_TIME_LIMIT_REACHED": QPStatus.MAX_ITERATIONS,
        "OSQP_NON_CVX": QPStatus.SOLVER_ERROR,
    }
    return {int(members[name]): status for name, status in table.items() if name in members}


_STATUS_FROM_OSQP = _status_table()

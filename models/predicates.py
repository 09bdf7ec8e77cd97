"""Task predicates (goal and unsafe sets) compiled to a small postfix program for numba.

A predicate tree from the scenario (`box`, `touch`, `all`, `any`, `not`) becomes arrays of
instructions evaluated with a stack of booleans, so a rollout checks the goal and unsafe
sets every step without returning to Python:

    OP_BOX    coordinate index, [lo, hi]        -> q[index] in [lo, hi]
    OP_TOUCH  pair index, tol                    -> min psi of the pair's contacts <= tol
    OP_AND n / OP_OR n                           -> pops n values
    OP_NOT                                       -> pops one value

`touch` needs the pair's signed distance; the rollout passes the per-pair minimum psi of
the contacts it detected (pairs beyond the detection margin count as apart), so the margin
must be at least the largest touch tolerance: the loader (`models.scenario`) refuses a
larger one.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from models.scenario import Scenario

OP_BOX, OP_TOUCH, OP_AND, OP_OR, OP_NOT, OP_TRUE = 0, 1, 2, 3, 4, 5


class Program(NamedTuple):
    op: np.ndarray  # int64[k]
    index: np.ndarray  # int64[k]: coordinate (box), pair (touch) or operand count (and/or)
    lo: np.ndarray  # float64[k]: interval low, or touch tolerance
    hi: np.ndarray  # float64[k]


def _pair_index(scenario: Scenario, a: str, b: str) -> int:
    for i, pair in enumerate(scenario.pairs):
        if {pair.body_a, pair.body_b} == {a, b}:
            return i
    raise ValueError(
        f"touch predicate on {a!r} and {b!r}: these bodies are not a contact pair (both fixed, or the pair is disabled in [contact.pairs])"
    )


def compile_predicate(scenario: Scenario, predicate) -> Program:
    """Compile a predicate of `scenario` (None: never true)."""
    ops: list[tuple[int, int, float, float]] = []
    default_tol = scenario.spec.contact.touch_tolerance

    def emit(node) -> None:
        kind = type(node).__name__
        if kind == "BoxPredicate":
            for name, (lo, hi) in node.box.items():
                ops.append((OP_BOX, scenario.coordinates.index(name), lo, hi))
            if len(node.box) > 1:
                ops.append((OP_AND, len(node.box), 0.0, 0.0))
        elif kind == "TouchPredicate":
            tol = node.tol if node.tol is not None else default_tol
            ops.append((OP_TOUCH, _pair_index(scenario, *node.touch), tol, 0.0))
        elif kind in ("AllPredicate", "AnyPredicate"):
            children = node.all if kind == "AllPredicate" else node.any
            for child in children:
                emit(child)
            ops.append((OP_AND if kind == "AllPredicate" else OP_OR, len(children), 0.0, 0.0))
        else:
            emit(node.not_)
            ops.append((OP_NOT, 0, 0.0, 0.0))

    if predicate is None:
        ops.append((OP_NOT, 0, 0.0, 0.0))
        ops.insert(0, (OP_TRUE, 0, 0.0, 0.0))
    else:
        emit(predicate)
    return Program(
        op=np.array([o[0] for o in ops], np.int64),
        index=np.array([o[1] for o in ops], np.int64),
        lo=np.array([o[2] for o in ops], float),
        hi=np.array([o[3] for o in ops], float),
    )


@numba.njit(cache=True)
def evaluate(P, q, pair_psi):
    """Evaluate program P at configuration q with per-pair minimum distances pair_psi."""
    return evaluate_with(P.op, P.index, P.lo, P.hi, q, pair_psi, np.zeros(P.op.shape[0] + 1, np.bool_))


@numba.njit(cache=True, inline="always")
def evaluate_with(op_codes, index, lo, hi, q, pair_psi, stack):
    """evaluate() on the program's arrays with a caller-owned stack (len(op_codes) + 1)."""
    top = 0
    for k in range(op_codes.shape[0]):
        op = op_codes[k]
        if op == OP_BOX:
            v = q[index[k]]
            stack[top] = lo[k] <= v <= hi[k]
            top += 1
        elif op == OP_TOUCH:
            stack[top] = pair_psi[index[k]] <= lo[k]
            top += 1
        elif op == OP_TRUE:
            stack[top] = True
            top += 1
        elif op == OP_NOT:
            stack[top - 1] = not stack[top - 1]
        else:
            n = index[k]
            result = op == OP_AND
            for j in range(top - n, top):
                if op == OP_AND:
                    result = result and stack[j]
                else:
                    result = result or stack[j]
            top -= n
            stack[top] = result
            top += 1
    return stack[0]


def predicate_distance(scenario: Scenario, node, q: np.ndarray, pair_psi: np.ndarray) -> float:
    """How far q is from satisfying the predicate (0 inside): interval and touch violations,
    summed over `all`, the least over `any`; `not` is 0 or 1."""
    kind = type(node).__name__
    if kind == "BoxPredicate":
        total = 0.0
        for name, (lo, hi) in node.box.items():
            v = q[scenario.coordinates.index(name)]
            total += max(lo - v, 0.0, v - hi)
        return total
    if kind == "TouchPredicate":
        tol = node.tol if node.tol is not None else scenario.spec.contact.touch_tolerance
        index = _pair_index(scenario, *node.touch)
        return max(float(pair_psi[index]) - tol, 0.0)
    if kind == "AllPredicate":
        return sum(predicate_distance(scenario, c, q, pair_psi) for c in node.all)
    if kind == "AnyPredicate":
        return min(predicate_distance(scenario, c, q, pair_psi) for c in node.any)
    return 0.0 if predicate_distance(scenario, node.not_, q, pair_psi) > 0.0 else 1.0

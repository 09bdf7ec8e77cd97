"""Arithmetic on design parameters: the one place scenario strings become numbers.

Any numeric field of a scenario file may hold a string instead of a number: the name of a
design parameter (``"mu"``), or a small arithmetic expression over parameters
(``"-v1"``, ``"2 * r + 0.5"``, ``"0.05 * sin(radians(slope_deg))"``). Allowed: numbers,
parameter names, the constant ``pi``, ``+ - * / **``, unary minus, parentheses and the
functions in `FUNCTIONS`. Nothing else is evaluated: no attributes, no other calls.
"""

from __future__ import annotations

import ast
import math
import operator
import threading
from collections.abc import Mapping

_BINARY = {  # (the operation, its symbol)
    ast.Add: (operator.add, "+"),
    ast.Sub: (operator.sub, "-"),
    ast.Mult: (operator.mul, "*"),
    ast.Div: (operator.truediv, "/"),
    ast.Pow: (operator.pow, "**"),
}
_UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos}
#: Functions an expression may call (one argument each).
FUNCTIONS = {
    "sin": math.sin,
    "cos": math.cos,
    "tan": math.tan,
    "sqrt": math.sqrt,
    "exp": math.exp,
    "log": math.log,
    "radians": math.radians,
    "degrees": math.degrees,
    "abs": abs,
}
CONSTANTS = {"pi": math.pi}


class ExpressionError(ValueError):
    """An expression that cannot be evaluated; the message says why."""


#: CPython 3.11's ast construction is not safe across threads: parses at once in two threads
#: may fail with "SystemError: AST constructor recursion depth mismatch" (python/cpython
#: gh-106905; the service validates scenarios in a thread pool: a 500 under 100 concurrent
#: submissions). One parse at a time.
_PARSING = threading.Lock()


def _parse(text: str) -> ast.Expression:
    with _PARSING:
        return ast.parse(text.strip(), mode="eval")


def evaluate(text: str, parameters: Mapping[str, float]) -> float:
    """Evaluate ``text`` with ``parameters`` bound; raise ExpressionError on any problem."""
    try:
        tree = _parse(text)
    except SyntaxError:
        raise ExpressionError(f"{text!r} is neither a number nor a parameter expression") from None
    value = _eval(tree.body, text, parameters)
    if not math.isfinite(value):
        raise ExpressionError(f"{text!r} evaluates to {value}, not a finite number")
    return value


def names_in(text: str, parameters: Mapping[str, float] | None = None) -> set[str]:
    """Parameter names an expression refers to (empty if it does not parse). A name in
    `parameters` is the parameter's even where a constant has it (``pi``), as `evaluate` reads it."""
    try:
        tree = _parse(text)
    except SyntaxError:
        return set()
    called = {n.func.id for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
    constants = set(CONSTANTS) - set(parameters or ())
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)} - called - constants


def _eval(node: ast.AST, text: str, parameters: Mapping[str, float]) -> float:
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return float(node.value)
    if isinstance(node, ast.Name):
        if node.id in CONSTANTS and node.id not in parameters:
            return CONSTANTS[node.id]
        if node.id not in parameters:
            known = ", ".join(sorted(parameters)) or "none defined"
            raise ExpressionError(f"unknown parameter {node.id!r} (parameters: {known})")
        return float(parameters[node.id])
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        left = _eval(node.left, text, parameters)
        right = _eval(node.right, text, parameters)
        try:
            operation, symbol = _BINARY[type(node.op)]
            value = operation(left, right)
        except ZeroDivisionError as exc:
            raise ExpressionError(f"{text!r}: {exc}") from None
        except OverflowError:  # (its text for a power is an errno tuple: (34, 'Numerical result out of range'))
            raise ExpressionError(f"{text!r}: {left:g} {symbol} {right:g} is too large to compute with") from None
        if isinstance(value, complex):  # (-1) ** 0.5: Python's power of a negative base
            raise ExpressionError(f"{text!r}: ({left:g}) ** {right:g} is not a real number (a negative base to a fractional power)")
        return float(value)
    if isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
        return float(_UNARY[type(node.op)](_eval(node.operand, text, parameters)))
    if (
        isinstance(node, ast.Call)
        and isinstance(node.func, ast.Name)
        and node.func.id in FUNCTIONS
        and len(node.args) == 1
        and not node.keywords
    ):
        argument = _eval(node.args[0], text, parameters)
        try:
            return float(FUNCTIONS[node.func.id](argument))
        except OverflowError:
            raise ExpressionError(f"{text!r}: {node.func.id}({argument:g}) is too large to compute with") from None
        except ValueError as exc:
            raise ExpressionError(f"{text!r}: {node.func.id}({argument:g}): {exc}") from None
    raise ExpressionError(
        f"{text!r}: only numbers, parameter names, pi, + - * / **, parentheses and "
        f"the functions {', '.join(FUNCTIONS)} (one argument each) are allowed"
    )

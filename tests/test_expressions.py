import math
import re

import pytest

from models.expressions import ExpressionError, evaluate, names_in


@pytest.mark.parametrize(
    "text, value",
    [
        ("1.5", 1.5),
        ("-v1", -2.0),
        ("2 * v1 + 1", 5.0),
        ("v1 ** 2 / 4", 1.0),
        ("sin(radians(30))", 0.5),
        ("pi", math.pi),
        ("(1 - v1) * 3", -3.0),
    ],
)
def test_evaluates(text, value):
    assert evaluate(text, {"v1": 2.0}) == pytest.approx(value)


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("v2", "unknown parameter 'v2'"),
        ("v1 +", "neither a number"),
        ("__import__('os')", "only numbers"),
        ("v1.real", "only numbers"),
        ("[1]", "only numbers"),
        ("1 / 0", "division by zero"),
        ("sqrt(-1)", "domain"),
        ("exp(1000)", "'exp(1000)': exp(1000) is too large to compute with"),
        ("v1 ** 9999", "'v1 ** 9999': 2 ** 9999 is too large to compute with"),  # (had been an errno tuple)
        ("1e308 * 10", "not a finite number"),
        ("True", "only numbers"),
    ],
)
def test_rejects(text, fragment):
    with pytest.raises(ExpressionError, match=re.escape(fragment)):
        evaluate(text, {"v1": 2.0})


def test_names_in():
    assert names_in("2 * sin(alpha) + beta - pi") == {"alpha", "beta"}


def test_a_parameter_named_like_a_constant_is_the_parameter_in_names_in_as_in_evaluate():
    """A parameter `pi` shadows the constant where an expression is evaluated; `names_in` had
    still dropped it, so an override of it that put a key out of range went unnamed."""
    parameters = {"pi": 3.0, "r": 0.5}
    assert evaluate("2 * pi * r", parameters) == 3.0
    assert names_in("2 * pi * r", parameters) == {"pi", "r"}
    assert names_in("2 * pi * r", {"r": 0.5}) == names_in("2 * pi * r") == {"r"}

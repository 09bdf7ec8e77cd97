"""Values passed to a kernel by reference (`models.reference`): the value a kernel reads back is
the one referenced (a bool field included: a byte in memory, a bit in a value), and its arrays
are the caller's own (written through, not copied). The warm steps' bodies take their fixed
arguments this way; tests/test_warm_steps.py holds them, through their by-value wrappers, to
the general step bit for bit."""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from models import stepper
from models.reference import reference, referent


class Fixed(NamedTuple):
    """A value like the warm steps' fixed arguments: arrays of several kinds, a flag, a number."""

    table: np.ndarray  # int64 (n, 2)
    values: np.ndarray  # float64 (n,)
    spatial: bool
    scale: float


@numba.njit(_nrt=False)
def _read(fixed_ref, i):
    """Reads the referenced value's fields, writes into its array: returns (table row sum,
    values[i] * scale, spatial)."""
    f = referent(fixed_ref)
    f.values[i] = f.values[i] * f.scale
    return f.table[i, 0] + f.table[i, 1], f.values[i], f.spatial


@numba.njit
def _through(fixed, i, n):
    """n calls of `_read` on one reference made before them, as `_contact_run` makes its own."""
    ref = reference(fixed)
    total, last, flag = 0, 0.0, False
    for _ in range(n):
        s, last, flag = _read(ref, i)
        total += s
    return total, last, flag


def _fixed() -> Fixed:
    return Fixed(np.arange(8, dtype=np.int64).reshape(4, 2), np.array([1.0, 2.0, 3.0, 4.0]), True, 0.5)


def test_a_kernel_reads_the_referenced_value_and_writes_into_its_arrays():
    fixed = _fixed()
    total, last, flag = _through(fixed, 2, 3)
    assert total == 3 * (4 + 5)
    assert flag is True
    # the array is the caller's: three calls halved its entry three times, in place
    assert last == 3.0 / 8 and fixed.values[2] == 3.0 / 8
    assert list(fixed.values[[0, 1, 3]]) == [1.0, 2.0, 4.0]


def test_the_flag_reads_back_as_it_was_written():
    # (a bool is a byte in memory and a bit in a value: the reference stores and reads it as memory)
    fixed = _fixed()._replace(spatial=False)
    assert _through(fixed, 0, 1)[2] is False


def test_the_warm_steps_take_their_fixed_arguments_by_reference():
    # the bodies the runs call take one reference where their wrappers take the arrays
    assert "fixed" in stepper.spatial_warm_step_on.py_func.__code__.co_varnames[:3]
    assert "fixed" in stepper.pgs_warm_step_on.py_func.__code__.co_varnames[:3]
    assert "fixed" in stepper.planar_warm_step_on.py_func.__code__.co_varnames[:3]
    assert stepper.spatial_warm_step_on.py_func.__code__.co_argcount < stepper.spatial_warm_step.py_func.__code__.co_argcount
    assert stepper.planar_warm_step_on.py_func.__code__.co_argcount < stepper.planar_warm_step.py_func.__code__.co_argcount

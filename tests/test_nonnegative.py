"""Kernels marked `nonnegative_indices` compile without numba's wraparound of negative indices
(`models.nonnegative`); the marked steps (the spatial warm step and PGS's step in space) are
checked bit for bit against the general step in tests/test_warm_steps.py."""

import numba
import numpy as np
import pytest

import models  # noqa: F401  (installs the lowering)
from models import nonnegative, stepper
from models.nonnegative import _marked, _prefix, nonnegative_indices


# the same function twice, one marked, one not; bounds checked, so that an index outside the
# array raises instead of reading past it
@numba.njit(boundscheck=True)
@nonnegative_indices
def read_marked(a, i):
    return a[i]


@numba.njit(boundscheck=True)
def read_plain(a, i):
    return a[i]


def test_the_lowering_is_installed():
    assert nonnegative.installed()
    nonnegative.install()  # (idempotent)
    assert nonnegative.installed()


def test_a_marked_kernel_reads_a_non_negative_index_as_numba_does():
    a = np.arange(5.0) * 1.5
    for i in range(5):
        assert read_marked(a, i) == read_plain(a, i) == a[i]


def test_a_marked_kernel_takes_a_negative_index_as_it_is():
    a = np.arange(5.0)
    assert read_plain(a, -1) == 4.0  # numba's (Python's) meaning, unmarked
    with pytest.raises(IndexError):
        read_marked(a, -1)  # marked: -1 is below the array, caught by the bounds check


@numba.njit(boundscheck=True)
@nonnegative_indices
def _tail_sum(a, k):
    return a[-k:].sum() + a[k]


def test_a_marked_kernel_keeps_numba_s_slices():
    a = np.arange(6.0)
    assert _tail_sum(a, 2) == 4.0 + 5.0 + 2.0


def test_the_warm_steps_are_marked():
    # the steps' bodies (their arguments by reference); their by-value wrappers index nothing
    for name in ("spatial_warm_step_on", "pgs_warm_step_on", "planar_warm_step_on"):
        assert _prefix(f"models.stepper.{name}") in nonnegative._MARKED
        assert callable(getattr(stepper, name))
    for name in ("spatial_warm_step", "pgs_warm_step", "planar_warm_step"):
        assert _prefix(f"models.stepper.{name}") not in nonnegative._MARKED


def test_a_marked_name_is_matched_whole():
    p = _prefix("models.stepper.spatial_warm_step_on")
    assert p == "_ZN6models7stepper20spatial_warm_step_on"
    assert _marked(p + "B2v1B42xyzE5ArrayIdLi1E1C7mutable7alignedE")
    assert _marked(p + "E5Array")
    assert not _marked("_ZN6models7stepper17spatial_warm_stepB2v1")  # (the name it starts with: the wrapper)
    assert not _marked("_ZN6models7stepper21spatial_warm_step_onsB2v1")  # (another name it starts)
    assert not _marked("_ZN6models7stepper20spatial_warm_buffersB2v1")

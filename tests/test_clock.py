"""The planners' clock (planner/clock.py): rung caps do not count time in numba's compiler."""

import time

import numba
from numba.core.compiler_lock import global_compiler_lock

from planner.clock import compiler_seconds, planning_clock
from planner.ompl_adapter import _termination
from planner.plan_status import PlanStatus


def test_a_compile_counts_as_compiler_time_and_a_call_does_not():
    @numba.njit  # a kernel of its own, not cached: its first call compiles it
    def poly(x):
        s = 0.0
        for k in range(10):
            s += x**k / (k + 1)
        return s

    spent, t0 = compiler_seconds(), time.perf_counter()
    assert poly(0.5) > 0.0
    compiled = compiler_seconds() - spent
    assert 0.0 < compiled <= time.perf_counter() - t0
    spent = compiler_seconds()
    assert poly(0.25) > 0.0  # compiled already: no time in the compiler
    assert compiler_seconds() == spent


class _NoSolution:
    def haveExactSolutionPath(self) -> bool:
        return False


def test_a_search_cap_does_not_count_time_in_the_compiler():
    # OMPL's termination condition with a 1 s cap: 1.5 s spent holding numba's compiler lock (as a
    # first propagation compiling the kernels would) does not end the search; 1.5 s outside it does
    finished, done = _termination(_NoSolution(), iterations=100, time_limit=1.0)
    clock = planning_clock()
    with global_compiler_lock:
        time.sleep(1.5)
    assert planning_clock() - clock < 1.0
    assert not finished() and done["ended"] is None
    time.sleep(1.5)
    assert finished() and done["ended"] is PlanStatus.TIMEOUT

"""The planners' clock: wall time less the time spent in numba's compiler.

A rung's time cap (`time_limit`) is a safety net on top of its iteration budget: a plan is
reproducible unless a cap ends its search. A fresh clone's first plan compiles the physics
kernels inside whichever rung first calls them, minutes on two cores, and on wall time that
compile spent the rung's cap: the search ended as TIMEOUT, and the same seed planned something
other than it plans on every later run. The caps are measured on `planning_clock` instead:
`time.perf_counter()` less the time this thread has spent in numba's compiler (waiting for or
holding its lock, `numba:compiler_lock`: compiling a kernel, or loading one from the cache).
Reported wall times stay wall times.
"""

from __future__ import annotations

import threading
import time

from numba.core import event

_thread = threading.local()


class _CompilerTime(event.Listener):
    """Sums, per thread, the time between the outermost start and end of numba's compiler
    lock events (the lock is reentrant: a kernel's compile compiles its callees inside it)."""

    def on_start(self, ev) -> None:
        depth = getattr(_thread, "depth", 0)
        if depth == 0:
            _thread.since = time.perf_counter()
        _thread.depth = depth + 1

    def on_end(self, ev) -> None:
        depth = getattr(_thread, "depth", 0) - 1
        if depth < 0:  # the lock was taken before this listener was registered
            return
        _thread.depth = depth
        if depth == 0:
            _thread.spent = compiler_seconds() + time.perf_counter() - _thread.since


event.register("numba:compiler_lock", _CompilerTime())


def compiler_seconds() -> float:
    """Seconds this thread has spent in numba's compiler (finished spells) since this module
    was imported."""
    return getattr(_thread, "spent", 0.0)


def planning_clock() -> float:
    """`time.perf_counter()` less `compiler_seconds()`: a clock that stands still while this
    thread compiles (or loads) kernels. Only differences of its readings mean anything."""
    return time.perf_counter() - compiler_seconds()

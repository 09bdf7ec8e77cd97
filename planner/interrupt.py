"""Ctrl-C that never lands inside a compiled kernel.

Python raises KeyboardInterrupt from its SIGINT handler at the next bytecode; when that
happens while a numba kernel is running, the dispatcher returns "a result with an exception
set" (a SystemError with a long traceback) instead of a clean interrupt. So the command line
installs `handler`: inside a `deferred()` block a first Ctrl-C only sets a flag, which the
long loops (rollout chunks, OMPL's termination condition, the sweep's runs) read between
compiled calls (`asked`, `check`) and act on: they stop, keep what is done and the command
exits 130. A second Ctrl-C inside such a block stops the process at once (exit 130, nothing
more written). Outside a deferred block Ctrl-C raises KeyboardInterrupt as usual.
"""

from __future__ import annotations

import os
import signal
import sys
from contextlib import contextmanager

_state = {"asked": False, "deferring": 0}


def asked() -> bool:
    """Whether Ctrl-C was pressed."""
    return _state["asked"]


def check() -> None:
    """Raise KeyboardInterrupt if Ctrl-C was pressed (call between compiled calls)."""
    if _state["asked"]:
        raise KeyboardInterrupt


def handler(signum, frame) -> None:
    if _state["deferring"]:
        if _state["asked"]:  # the second Ctrl-C: the user does not want to wait for a clean stop
            print("interrupted", file=sys.stderr, flush=True)
            os._exit(130)
        _state["asked"] = True
        return
    _state["asked"] = True
    raise KeyboardInterrupt


def install() -> None:
    """Use `handler` for SIGINT (main thread only; a no-op elsewhere), with no Ctrl-C seen yet."""
    reset()
    try:
        signal.signal(signal.SIGINT, handler)
    except ValueError:  # not the main thread
        pass


@contextmanager
def deferred():
    """A block whose loops check `asked()` between compiled calls: Ctrl-C only sets the flag."""
    _state["deferring"] += 1
    try:
        yield
    finally:
        _state["deferring"] -= 1


def ask() -> None:
    """Ask the loops under way to stop, as a first Ctrl-C inside a deferred block does (the
    service's cancel and wall-time limit of a simulate job, from a thread of the worker)."""
    _state["asked"] = True


def reset() -> None:
    _state["asked"] = False

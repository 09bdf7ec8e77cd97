"""Ctrl-C that never lands inside a compiled kernel.

Python raises KeyboardInterrupt from its SIGINT handler at the next bytecode; when that
happens while a numba kernel is running, the dispatcher returns "a result with an exception
set" (a SystemError with a long traceback) instead of a clean interrupt. So the command line
installs `handler`: inside a `deferred()` block a first Ctrl-C only sets a flag, which the
long loops (rollout chunks, OMPL's termination condition, the sweep's runs) read between
compiled calls (`asked`, `check`) and act on: they stop, keep what is done and the command
exits 130. A second Ctrl-C inside such a block stops the process at once (exit 130, nothing
more written). So does a first Ctrl-C while a kernel compiles inside such a block, or one
before a compile starts there, while the block has nothing to keep yet (`keep`: a plan's rungs
done, a sweep's runs): a compile has no check in it and takes minutes on a first run, which had
held a first simulate's Ctrl-C for 10 minutes. Outside a deferred block Ctrl-C raises
KeyboardInterrupt as usual.

A command's results, once computed, are written inside a `shielded()` block: a first Ctrl-C
there is only remembered (`held`), so every output is written whole and the command reports
it; a second (or the first there after one that stopped the work) stops the process at once. A Ctrl-C had left a simulate's plot and
half its table, or a plan's plan.json (complete) with some of its plots, and exit 130.

Stopping at once skips every `finally`: what the process started that would outlive it (a
sweep's pool of worker processes) is registered with `stopped_at_once` and ended first.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from contextlib import contextmanager

_state = {
    "asked": False,
    "deferring": 0,
    "shielding": 0,
    "held": False,
    "signalled": False,
    "compiling": 0,
    "kept": False,
    "installed": False,
}
#: What a stop at once ends before the process exits (`stopped_at_once`).
_at_stop: list = []


def asked() -> bool:
    """Whether Ctrl-C was pressed."""
    return _state["asked"]


def check() -> None:
    """Raise KeyboardInterrupt if Ctrl-C was pressed (call between compiled calls)."""
    if _state["asked"]:
        raise KeyboardInterrupt


def held() -> bool:
    """Whether Ctrl-C was pressed inside a `shielded()` block (the outputs were still written)."""
    return _state["held"]


def _stop_now() -> None:
    """End the process at once (exit 130), first ending what `stopped_at_once` registered."""
    for end in reversed(_at_stop):
        try:
            end()
        except Exception:  # (ending the rest matters more than what this one said)
            pass
    print("interrupted", file=sys.stderr, flush=True)
    os._exit(130)


def handler(signum, frame) -> None:
    if _state["shielding"]:
        if _state["held"] or _state["asked"]:  # the second Ctrl-C (the first may have stopped the work): stop now
            _stop_now()
        _state["held"] = True
        return
    if _state["deferring"]:
        if _state["asked"] or (_state["compiling"] and not _state["kept"]):  # the second Ctrl-C, or one a compile would hold
            _stop_now()
        _state["asked"] = _state["signalled"] = True
        return
    _state["asked"] = True
    raise KeyboardInterrupt


def install() -> None:
    """Use `handler` for SIGINT (main thread only; a no-op elsewhere), with no Ctrl-C seen yet."""
    reset()
    try:
        signal.signal(signal.SIGINT, handler)
        _state["installed"] = True
    except ValueError:  # not the main thread
        pass


def keep() -> None:
    """The deferred block under way has work to keep at a stop (a rung or a run done): a Ctrl-C
    during a compile there waits for the compile, as for any check, rather than stop at once."""
    _state["kept"] = True


@contextmanager
def _inside(counter: str):
    """A block counted in _state[counter] (blocks nest)."""
    _state[counter] += 1
    try:
        yield
    finally:
        _state[counter] -= 1


@contextmanager
def stopped_at_once(end):
    """A block during which a stop at once (a second Ctrl-C) calls `end()` before the process
    exits: a sweep's worker processes, which ignore Ctrl-C, had been left running as orphans."""
    _at_stop.append(end)
    try:
        yield
    finally:
        _at_stop.remove(end)


def at_stop(end) -> None:
    """`end()` before the process exits at a stop at once, from now on (an output folder made
    empty: `end` must do no harm once the work is done); only in a process whose Ctrl-C is
    `handler`'s (a service worker's jobs, each with a folder, never stop so)."""
    if _state["installed"]:
        _at_stop.append(end)


def deferred():
    """A block whose loops check `asked()` between compiled calls: Ctrl-C only sets the flag
    (but stops at once while a kernel compiles there)."""
    watch_compiles()
    return _deferring()


@contextmanager
def _deferring():
    try:
        with _inside("deferring"):
            yield
    finally:
        if not _state["deferring"]:  # (the outermost: what it saw is not the next one's)
            _state["signalled"] = _state["kept"] = False


_watching: list = []
#: The seconds this process has spent compiling kernels: those of the compiles ended, and when
#: the outermost under way started (`compile_seconds`).
_compile_clock = {"ended": 0.0, "since": 0.0}


def compile_seconds() -> float:
    """Seconds spent compiling kernels since `watch_compiles` (the one under way counted so far):
    what a wall-time limit leaves out (a service job's `--max-job-seconds`), as the CLI's
    caps do, since a first run's compile takes minutes."""
    ended, since = _compile_clock["ended"], _compile_clock["since"]
    return ended + (time.monotonic() - since if _state["compiling"] else 0.0)


def watch_compiles() -> None:
    """Count the kernels compiling (numba's `numba:compile` event, which a load from the cache
    does not fire) and time them (`compile_seconds`), once per process; a compile that starts
    after a Ctrl-C in a deferred block (not one the service's `ask` made, nor while results
    are written) stops the process."""
    if _watching:
        return
    try:
        from numba.core import event
    except ImportError:  # (no kernels to compile)
        return

    class Compiles(event.Listener):
        def on_start(self, ev) -> None:
            if not _state["compiling"]:
                _compile_clock["since"] = time.monotonic()
            _state["compiling"] += 1
            if _state["signalled"] and _state["deferring"] and not _state["shielding"] and not _state["kept"]:
                _stop_now()

        def on_end(self, ev) -> None:
            _state["compiling"] -= 1
            if not _state["compiling"]:
                _compile_clock["ended"] += time.monotonic() - _compile_clock["since"]

    listener = Compiles()
    event.register("numba:compile", listener)
    _watching.append(listener)


def shielded():
    """A block that writes a command's results: Ctrl-C only sets `held` (see the module)."""
    return _inside("shielding")


def ask() -> None:
    """Ask the loops under way to stop, as a first Ctrl-C inside a deferred block does (the
    service's cancel and wall-time limit of a simulate job, from a thread of the worker)."""
    _state["asked"] = True


def reset() -> None:
    _state["asked"] = _state["held"] = _state["signalled"] = False

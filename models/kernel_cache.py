"""numba's on-disk cache of the compiled kernels, invalidated by any change to the package.

numba checks a cached kernel against the source file its Python function is in, and nothing
else. A kernel here inlines or links helpers from other modules (`models.rollout`'s kernel
compiles most of `models.stepper`, `models.contact_pgs` and `models.lcp` into itself), so after
an edit to a helper's module, or a `git pull` that changed one, numba loaded the kernel as it
was compiled before: the old physics, silently (docs/measurements.md). Here each kernel's
cache entry is stamped with a digest of every module of its package instead, so that any
change to one of them recompiles the kernels on their next use, where they are cached as
before (beside the sources, or in `NUMBA_CACHE_DIR` where it is set).

`install()` (called by `models/__init__`, before any kernel is defined) puts the locator first
in numba's `CACHE_LOCATOR_CLASSES`; kernels outside the stamped packages keep numba's own
locators and stamps. A kernel takes its locator when it is defined, at its module's import:
numba re-reads its whole configuration from the environment when a NUMBA_ variable changes in
the process, which would drop the setting for modules imported after such a change (none of
ladder's sets one).
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import os
import pickle
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from numba.core import caching, config

#: The package directories whose kernels are stamped with the whole package's digest.
PACKAGES: set[Path] = {Path(__file__).resolve().parent}

#: numba's own locators, in its order, after this package's.
NUMBA_LOCATORS = ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator", "IPythonCacheLocator", "ZipCacheLocator")


@functools.cache
def _package_of(py_file: str) -> Path:
    """The directory of a kernel's module (resolved once per module, not once per kernel)."""
    return Path(py_file).resolve().parent


@functools.cache
def package_stamp(package: Path) -> bytes:
    """A digest of the package's modules (the name and bytes of every .py file in it), read
    once per process."""
    digest = hashlib.sha256()
    for path in sorted(package.glob("*.py")):
        digest.update(path.name.encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.digest()


def _stamped(base: type) -> type:
    """numba's locator `base` with the package's digest as every function's source stamp."""

    class Stamped(base):
        def get_source_stamp(self):
            return package_stamp(_package_of(self._py_file))

    Stamped.__name__ = Stamped.__qualname__ = f"Package{base.__name__}"
    return Stamped


#: Where numba would cache a function (its own locators' order: NUMBA_CACHE_DIR, beside the
#: source, the user's cache directory), each stamped by the package.
_LOCATORS = tuple(_stamped(getattr(caching, name)) for name in NUMBA_LOCATORS[:3])


class PackageCacheLocator:
    """A numba cache locator for the functions of `PACKAGES`' modules: numba's own choice of
    place, stamped by the whole package (`package_stamp`); None for any other function, which
    numba's next locators then take."""

    @classmethod
    def from_function(cls, py_func, py_file):
        if _package_of(py_file) not in PACKAGES:
            return None
        for locator in _LOCATORS:
            found = locator.from_function(py_func, py_file)
            if found is not None:
                return found
        return None


def install() -> None:
    """Put `PackageCacheLocator` first in numba's locators (after any the user named in
    NUMBA_CACHE_LOCATOR_CLASSES, else before numba's own). Affects the kernels defined from
    here on."""
    name = f"{__name__}.{PackageCacheLocator.__name__}"
    given = [c.strip() for c in config.CACHE_LOCATOR_CLASSES.split(",") if c.strip()]
    if name not in given:
        config.CACHE_LOCATOR_CLASSES = ",".join([*given, name, *([] if given else NUMBA_LOCATORS)])


def kernels_cached(name: str = "rollout_kernel") -> bool:
    """Whether numba's on-disk cache holds the kernel `name` of models.rollout for this
    package's sources (its index file, stamped by `package_stamp`): False on a first run or
    after an edit. The rollout kernel is every command's; the planners' `propagate_kernel` is
    compiled by a first plan even where a simulation has run."""
    try:
        from models import rollout

        return bool(getattr(rollout, name)._cache._cache_file._load_index())  # numba internals: {} when cold or stale
    except Exception:  # numba changed its internals: look in the default place
        return any(Path(__file__).resolve().parent.joinpath("__pycache__").glob(f"rollout.{name}-*.nbi"))


#: The helper process's program (`_compile_from`).
HELPER = "import sys; from models.kernel_cache import _compile_from; _compile_from(sys.argv[1], int(sys.argv[2]))"

#: The kernels this process has already started (or declined to start) a compile ahead for.
_AHEAD: set = set()


def compile_ahead(kernel, types) -> object:
    """Compile `kernel` (a cached numba dispatcher of this package) for the argument types that
    `types()` returns (called only where the helper starts), in a helper process, while this
    one compiles the rest. The rollout kernel calls `models.stepper.dynamics_step`, the largest
    single compile of a first run (about 40% of it), and loads it from the cache when it meets
    the call after the helper has written it (else it compiles it too, as it would alone).
    Once per process, and only where it pays: the cache cold (`kernels_cached`) and a second
    core free. The helper is quiet, in a session of its own (a terminal's Ctrl-C is this
    process's to handle), and ends with this process (Linux: the parent-death signal; else it
    polls). Returns the helper's Popen, or None."""
    if kernel in _AHEAD:  # (Rung's every call asks: one set lookup after the first)
        return None
    _AHEAD.add(kernel)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if cores < 2 or kernels_cached():
        return None
    try:
        job = pickle.dumps((kernel.py_func.__module__, kernel.py_func.__name__, types()))
    except Exception:  # an optimisation only: this process compiles it as it would alone
        return None
    fd, path = tempfile.mkstemp(prefix="ladder-ahead-", suffix=".pkl")
    with os.fdopen(fd, "wb") as f:
        f.write(job)
    root = str(Path(__file__).resolve().parent.parent)  # the same package, whatever the cwd
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, *filter(None, [os.environ.get("PYTHONPATH")])]))
    try:
        helper = subprocess.Popen(
            [sys.executable, "-c", HELPER, path, str(os.getpid())],
            cwd=root,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
    except OSError:
        os.unlink(path)
        return None
    threading.Thread(target=helper.wait, daemon=True).start()  # reaped when it ends, not left a zombie
    return helper


def _end_with_parent(parent: int) -> None:
    """End this helper process when `parent` does."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # the parent was gone before the signal was asked for
        os._exit(0)

    def watch():
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(0)

    threading.Thread(target=watch, daemon=True).start()


def _compile_from(path: str, parent: int) -> None:
    """The helper of `compile_ahead`: compile the pickled (module, function, types)."""
    _end_with_parent(parent)
    try:
        with open(path, "rb") as f:
            module, name, types = pickle.load(f)
    finally:
        os.unlink(path)
    getattr(importlib.import_module(module), name).compile(types)

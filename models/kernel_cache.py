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

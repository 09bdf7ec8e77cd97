"""Kernels whose array indices are never negative, compiled without numba's wraparound.

numba lowers every signed integer index `a[i]` as `a[i + n if i < 0 else i]`, Python's meaning
of a negative index, a compare and a select at each access. Inside a kernel that indexes
through other arrays (`nu[ldof[g, a]]`, `pf[c_pair[i], ...]`) the compiler cannot prove the
index non-negative, so it keeps them all, and they hold back the loops' other optimizations.
On box_push_3d's push the two spatial steps marked here run faster compiled without them, with
the same bits: the spatial warm step (Lemke, 8 directions) 1.08-1.10x, PGS's step in space on
the exact cone 1.07-1.12x; left out of the rest of the compiled code, they cost 3-6%
(docs/measurements.md, thirty-seventh session). The planar warm step, marked too, made the
paper's squeeze 1.06-1.15x faster (thirty-ninth session).

`nonnegative_indices` marks a kernel whose integer indices are all at least 0: in its compiled
body (with every helper inlined into it; not in the functions it calls) a signed index is taken
as it is. A negative one then reads outside the array, as an index past the end already does
(numba's bounds checks are off by default); with `boundscheck=True` both raise IndexError.
Slices keep numba's meaning. `install()` (called by `models/__init__`, before any kernel is
defined) puts the lowering in place; where numba's internals are not as this module expects,
it leaves numba's as they are, and the marked kernels compile with the wraparound (the same
results, slower: `installed()` says which).

The kernels' cache entries are stamped with the package's digest (`models.kernel_cache`), so
marking or unmarking a kernel recompiles it.
"""

from __future__ import annotations

import inspect

from numba.core import types
from numba.core.itanium_mangler import mangle_identifier

#: The mangled-name prefixes of the marked kernels (`_prefix`).
_MARKED: set[str] = set()

#: numba's own `fix_integer_index`, where `install` replaced it.
_NUMBA_FIX = None


def _prefix(qualified: str) -> str:
    """The start of the LLVM name numba gives a function `module.qualname` (itanium mangling:
    _ZN, then each dotted part as its length and its text; the abi tags and arguments follow,
    after a B or an E)."""
    return "_ZN" + "".join(mangle_identifier(part) for part in qualified.split("."))


def nonnegative_indices(func):
    """Mark func (a plain Python function, under numba's `njit`) as a kernel whose signed integer
    indices are never negative: it compiles without the wraparound. Returns func."""
    _MARKED.add(_prefix(f"{func.__module__}.{func.__qualname__}"))
    return func


def _marked(llvm_name: str) -> bool:
    """Whether the function being lowered is a marked kernel (its own body, inlined helpers
    included)."""
    for prefix in _MARKED:
        if llvm_name.startswith(prefix) and llvm_name[len(prefix) : len(prefix) + 1] in ("B", "E"):
            return True
    return False


def _fix_integer_index(context, builder, idxty, idx, size):
    """numba's `fix_integer_index`, without the wraparound in a marked kernel."""
    if idxty.signed and _marked(builder.function.name):
        return context.cast(builder, idx, idxty, types.intp)
    return _NUMBA_FIX(context, builder, idxty, idx, size)


def install() -> None:
    """Lower the marked kernels' integer indices without the wraparound (idempotent). Leaves
    numba as it is where its `numba.np.arrayobj.fix_integer_index` is not there or takes other
    arguments."""
    global _NUMBA_FIX
    try:
        from numba.np import arrayobj
    except ImportError:  # (numba moved it)
        return
    current = getattr(arrayobj, "fix_integer_index", None)
    if current is None or current is _fix_integer_index:
        return
    if list(inspect.signature(current).parameters) != ["context", "builder", "idxty", "idx", "size"]:
        return
    _NUMBA_FIX = current
    arrayobj.fix_integer_index = _fix_integer_index


def installed() -> bool:
    """Whether the marked kernels compile without the wraparound in this process."""
    from numba.np import arrayobj

    return getattr(arrayobj, "fix_integer_index", None) is _fix_integer_index

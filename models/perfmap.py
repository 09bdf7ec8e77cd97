"""Name the compiled kernels in `perf` profiles: a perf map of the process's numba code.

`perf report` shows JIT code as bare addresses. A map file, /tmp/perf-<pid>.map (lines of
"start size name", hexadecimal), names it: `write_perf_map` lists every function defined in
the libraries of the numba kernels loaded so far (`models.*`, `planner.*`), compiled or loaded
from the cache, with the address where it is loaded. Functions inlined into their caller have
no code of their own: their time is the caller's (a step's helpers are `rollout_kernel`'s).

    LADDER_PERF_MAP=1 perf record -g ladder bench --quick   # `ladder` writes the map as it exits
    perf report --no-children --sort sym

A function's size is the distance to the next function loaded after it (numba's objects carry
no sizes through llvmlite), so the last function of each library is given at most MAX_SIZE.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: The size given to the last function of a library, whose end the map cannot see (bytes).
MAX_SIZE = 1 << 20

#: The environment variable that makes `ladder` write the map as it exits (`planner.cli.main`).
ENV = "LADDER_PERF_MAP"


def demangle(name: str) -> str:
    """A numba symbol's dotted name: _ZN6models7rollout14rollout_kernelB2v2... ->
    models.rollout.rollout_kernel (the C wrappers keep their prefix: cpython.models..., and a
    name that is not numba's mangling comes back as it is)."""
    prefix, _, mangled = name.rpartition(".")
    if not mangled.startswith("_ZN"):
        return name
    parts, i = [], 3
    while i < len(mangled) and mangled[i].isdigit():
        j = i
        while j < len(mangled) and mangled[j].isdigit():
            j += 1
        length = int(mangled[i:j])
        parts.append(mangled[j : j + length])
        i = j + length
    dotted = ".".join(parts) or name
    return f"{prefix}.{dotted}" if prefix else dotted


def loaded_functions(packages: tuple[str, ...] = ("models", "planner")) -> list[tuple[int, str]]:
    """(address, symbol) of every function defined in the libraries of the numba kernels of
    `packages` loaded in this process, one entry per address, sorted."""
    from numba.core.registry import CPUDispatcher

    libraries = {}
    for module_name, module in list(sys.modules.items()):
        if module is None or module_name.split(".")[0] not in packages:
            continue
        for value in list(vars(module).values()):
            if isinstance(value, CPUDispatcher):
                for result in value.overloads.values():
                    libraries[id(result.library)] = result.library
    found = {}
    for library in libraries.values():
        # the module a library links into its callers: the functions its object code defines
        module = getattr(library, "_shared_module", None) or getattr(library, "_final_module", None)
        if module is None:
            continue
        for function in module.functions:
            if function.is_declaration:
                continue
            address = library.get_pointer_to_function(function.name)
            if address:
                found.setdefault(address, function.name)
    return sorted(found.items())


def write_perf_map(path: str | os.PathLike | None = None) -> Path:
    """Write the perf map of the loaded kernels (default /tmp/perf-<pid>.map, where perf looks
    for it). Returns the path."""
    entries = loaded_functions()
    out = Path(path) if path is not None else Path(f"/tmp/perf-{os.getpid()}.map")
    lines = []
    for k, (address, symbol) in enumerate(entries):
        following = entries[k + 1][0] if k + 1 < len(entries) else address + MAX_SIZE
        lines.append(f"{address:x} {min(following - address, MAX_SIZE):x} {demangle(symbol)}")
    out.write_text("\n".join(lines) + "\n")
    return out

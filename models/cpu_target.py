"""The CPU the kernels are compiled for.

numba compiles for the host CPU under LLVM's name for it, and the name picks LLVM's tuning. On
an AMD EPYC of family 26 (Zen 5, LLVM's `znver5`) the kernels tuned for the generic `x86-64-v3`
ran faster than tuned for `znver5`: box_push_3d's push 5-7% a step, the exact cone's 12%, the
paper's squeeze 8-10%, each against MuJoCo timed in turns (docs/measurements.md, fifty-eighth
session); tuned for the generic `x86-64-v2` faster again, in 13 alternated runs of
`planner.bench.contact_steps`: the squeeze 3.6-4.5% (12 or 13 of 13 runs), the 8-sided push 4.8% as
the planners call it (11 of 13) and 1.4% through `Rung.rollout` (9 of 13), the exact cone 1.0%
(7 of 13); `x86-64`, `znver2`, `znver4` and `x86-64-v4` no faster than `x86-64-v2` on the
squeeze and the 8-sided push, in 3-4 runs each (`znver3` was compiled but not timed in turns;
sixty-first session). AVX-512 is not the cause: tuned for `znver5` without it they ran as with
it. The results are the same bits (numba compiles without fast-math: no reassociation, no fused
multiply-add), and the planning runs are the same seed for seed.

NUMBA_CPU_NAME names the CPU LLVM tunes for (its scheduling and its choice of instructions);
the features compiled for stay the host's (numba's default where NUMBA_CPU_FEATURES is unset),
so the code runs on the host whatever the name. `install()` (models/__init__, before any kernel
is defined) sets NUMBA_CPU_NAME to the target TUNED names for the host, unless the user has set
NUMBA_CPU_NAME or NUMBA_CPU_FEATURES; nothing where the host is not in TUNED (only hosts where
the difference was measured). Child processes (the kernel-compile helper, sweep and service
workers) inherit the setting.
"""

from __future__ import annotations

import os
import sys

#: LLVM's name for a host CPU -> the target its kernels compile for, where measured faster.
TUNED = {"znver5": "x86-64-v2"}


def target_for(host: str, environ) -> str | None:
    """The CPU name to compile for on a host LLVM calls `host`, or None to leave numba's default
    (the host's own): the user's NUMBA_CPU_NAME or NUMBA_CPU_FEATURES in environ, or a host not
    in TUNED."""
    if environ.get("NUMBA_CPU_NAME") or environ.get("NUMBA_CPU_FEATURES"):
        return None
    return TUNED.get(host)


def install() -> str | None:
    """Set NUMBA_CPU_NAME to `target_for` the host, if any: the CPU this process's kernels and
    its children's (which inherit the variable) compile for. Where numba has already made its
    CPU code generator (a kernel compiled before models was imported), that compiles for the
    host, and the variable names the host, so that a child process (`kernel_cache`'s compile
    helper) builds what this one loads. numba re-reads its configuration here, at once, where it
    is imported already: later, it would drop settings made after this (`kernel_cache.install`).
    Returns the name set, or None."""
    try:
        import llvmlite.binding as ll

        host = ll.get_host_cpu_name()
    except Exception:  # llvmlite cannot tell: numba's default
        return None
    target = target_for(host, os.environ)
    if target is None:
        return None
    if _generating_code():
        target = host
    os.environ["NUMBA_CPU_NAME"] = target
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.reload_config()
    return target


def _generating_code() -> bool:
    """Whether numba's CPU target context, and with it the code generator tuned for a CPU name,
    exists in this process."""
    registry = sys.modules.get("numba.core.registry")
    return registry is not None and "_toplevel_target_context" in vars(registry.cpu_target)


def tuned_for() -> str:
    """The CPU name numba compiles for in this process: its NUMBA_CPU_NAME setting (this
    module's, or the user's), else LLVM's name for the host."""
    import llvmlite.binding as ll
    from numba.core import config

    return config.CPU_NAME or ll.get_host_cpu_name()

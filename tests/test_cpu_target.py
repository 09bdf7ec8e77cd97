"""The CPU the kernels are tuned for (`models.cpu_target`)."""

import os
import subprocess
import sys

import llvmlite.binding as ll

from models.cpu_target import TUNED, target_for

HOST = ll.get_host_cpu_name()

# numba's name for the CPU its code generator compiles for, after compiling a kernel
COMPILED_FOR = (
    "{first}import numba; "
    "f = numba.njit(lambda x: x + 1); f(1); "
    "from numba.core.registry import cpu_target; "
    "print(cpu_target.target_context.codegen().magic_tuple()[1]); print(numba.config.CPU_NAME)"
)


def compiled_for(first: str, **env) -> list[str]:
    """(the CPU name a fresh process compiles for, numba's CPU_NAME setting) with `first` run
    before the kernel, in an environment without the NUMBA_CPU_ variables but `env`'s."""
    clean = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    out = subprocess.run(
        [sys.executable, "-c", COMPILED_FOR.format(first=first)], env=clean | env, capture_output=True, text=True, timeout=120, check=True
    )
    return out.stdout.split()


def test_a_tuned_host_compiles_for_its_target_unless_the_user_names_one():
    assert target_for("znver5", {}) == "x86-64-v2"
    for host in ("znver4", "znver1", "skylake-avx512", "generic", ""):
        assert target_for(host, {}) is None, host
    assert target_for("znver5", {"NUMBA_CPU_NAME": "znver5"}) is None
    assert target_for("znver5", {"NUMBA_CPU_FEATURES": "+avx2"}) is None
    assert all(target_for(host, {}) == target for host, target in TUNED.items())


def test_importing_models_first_tunes_the_kernels_for_the_host():
    expected = target_for(HOST, {}) or HOST
    assert compiled_for("import models; ") == [expected, expected if target_for(HOST, {}) else "None"]


def test_the_users_setting_is_left_alone():
    assert compiled_for("import models; ", NUMBA_CPU_NAME="generic") == ["generic", "generic"]


def test_numba_imported_first_is_tuned_unless_it_has_compiled_already():
    tuned = target_for(HOST, {})
    # numba imported, nothing compiled: its configuration re-read, the target taken
    assert compiled_for("import numba.core.config; import numba; import models; ") == [tuned or HOST, tuned or "None"]
    # a kernel compiled first: the code generator is the host's; the variable says so, for the
    # child processes (kernel_cache's helper compiles what this process then loads)
    first = "import numba; numba.njit(lambda x: x)(1); import models, os; print(os.environ.get('NUMBA_CPU_NAME')); "
    assert compiled_for(first) == [HOST if tuned else "None", HOST, HOST if tuned else "None"]

"""numba's cache of the kernels (models/kernel_cache.py): a kernel whose callee's module changed
is compiled again, not loaded as it was."""

import subprocess
import sys
import textwrap

from tests.conftest import ROOT

CALLEE = """\
import numba


@numba.njit(cache=True)
def callee():
    return {value}
"""

CALLER = """\
import numba

from pkg.callee import callee


@numba.njit(cache=True)
def caller():
    return callee() * 10
"""


def _run(tmp_path, stamped: bool) -> tuple[int, bool]:
    """caller() in a fresh process, the package stamped as a whole (or not: numba's own
    stamps), and whether its kernel came from the cache."""
    script = textwrap.dedent(f"""
        import sys
        from pathlib import Path
        sys.path.insert(0, {str(ROOT)!r})
        sys.path.insert(0, {str(tmp_path)!r})
        import models.kernel_cache as kc
        if {stamped!r}:
            kc.PACKAGES.add(Path({str(tmp_path / "pkg")!r}).resolve())
        from pkg.caller import caller
        print(caller(), caller.stats.cache_hits.total() > 0)
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    value, hit = out.stdout.split()
    return int(value), hit == "True"


def _package(tmp_path, value: int) -> None:
    pkg = tmp_path / "pkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "callee.py").write_text(CALLEE.format(value=value))
    (pkg / "caller.py").write_text(CALLER)


def test_a_kernel_is_compiled_again_when_its_callees_module_changes(tmp_path):
    _package(tmp_path, 1)
    assert _run(tmp_path, stamped=True) == (10, False)  # compiled, and cached
    assert _run(tmp_path, stamped=True) == (10, True)  # loaded from the cache
    _package(tmp_path, 2)  # only the callee's module changes
    assert _run(tmp_path, stamped=True) == (20, False)
    assert _run(tmp_path, stamped=True) == (20, True)


def test_numba_alone_loads_the_caller_as_it_was(tmp_path):
    """What the stamp is for: with numba's own stamps (each function's module only), the
    caller's cache entry outlives its callee's edit."""
    _package(tmp_path, 1)
    assert _run(tmp_path, stamped=False) == (10, False)
    _package(tmp_path, 2)
    assert _run(tmp_path, stamped=False) == (10, True)


def test_the_models_kernels_are_stamped_by_the_package():
    import models  # noqa: F401  (installs the locator)
    from models import kernel_cache
    from models.rollout import rollout_kernel

    locator = rollout_kernel._cache._impl.locator
    assert locator.get_source_stamp() == kernel_cache.package_stamp(ROOT / "models")

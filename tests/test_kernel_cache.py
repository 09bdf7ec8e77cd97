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


WORK = """\
import numba


@numba.njit(cache=True)
def work(x, n):
    return x * n
"""


def test_compile_ahead_compiles_in_a_helper_what_this_process_then_loads(tmp_path, monkeypatch):
    """`compile_ahead` on a cold cache: a helper process compiles the kernel for the types
    given, into the cache, where this process then finds it; once per process, and not at
    all where the cache is warm."""
    import numba

    from models import kernel_cache

    (tmp_path / "ahead").mkdir()
    (tmp_path / "ahead" / "__init__.py").write_text("")
    (tmp_path / "ahead" / "work.py").write_text(WORK)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))  # the helper imports the kernel's module too
    monkeypatch.setattr(kernel_cache, "_AHEAD", set())
    from ahead.work import work

    types = (numba.float64, numba.int64)
    monkeypatch.setattr(kernel_cache, "kernels_cached", lambda: True)
    assert kernel_cache.compile_ahead(work, lambda: types) is None  # a warm cache: no helper
    monkeypatch.setattr(kernel_cache, "_AHEAD", set())
    monkeypatch.setattr(kernel_cache, "kernels_cached", lambda: False)
    monkeypatch.setattr(kernel_cache.os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)  # a second core
    helper = kernel_cache.compile_ahead(work, lambda: types)
    assert helper is not None and helper.wait(timeout=300) == 0
    assert kernel_cache.compile_ahead(work, lambda: types) is None  # once per process
    assert [key[0] for key in work._cache._cache_file._load_index()] == [types]
    assert work(2.0, 3) == 6.0 and work.stats.cache_hits.total() == 1  # loaded, not compiled here


def test_the_general_step_compiled_ahead_is_the_one_the_rollouts_call():
    """The types `compile_ahead` compiles `dynamics_step` for are those of the rollout kernel's
    call, planar and spatial, on every dynamic rung: the cache's entry, which a rollout wrote
    (or found), is the helper's."""
    import numpy as np

    from models.rollout import general_step_types
    from models.rungs import compiled, rung_for
    from models.scenario import load_scenario
    from models.stepper import dynamics_step

    for name in ("two_finger_triangle", "box_push_3d"):
        scenario = load_scenario(ROOT / "scenarios" / f"{name}.toml")
        c = compiled(scenario)
        for rung_name in ("quasistatic-rigid", "dynamic-rigid", "dynamic-compliant"):
            rung = rung_for(scenario, rung_name)
            s = rung.initial_state(scenario)
            rung.rollout(scenario, s, np.zeros((1, len(scenario.actuated))), [1e-3], 1e-3)
            arrays = (np.array(a, dtype=float) for a in (s.q, s.nu, s.q_ref, s.delta_n, s.delta_t))
            types = general_step_types(c.scene, c.drives, rung.model, rung.solver, *arrays, 1e-3)
            assert types in {key[0] for key in dynamics_step._cache._cache_file._load_index()}, (name, rung_name)

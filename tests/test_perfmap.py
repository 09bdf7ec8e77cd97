"""The perf map of the compiled kernels (`models.perfmap`): names and ranges (`ladder`'s switch: tests/test_cli.py)."""

from __future__ import annotations

import numpy as np

from models import perfmap
from models.rungs import rung_for
from models.scenario import load_scenario
from tests.conftest import SCENARIOS, perf_map_entries


def test_demangle_numba_names():
    name = "_ZN6models7rollout14rollout_kernelB2v2B56c8tJTC_2fWwGaMLSgd6CjA4xXKR0tsqKIYSQtVGpi44MFbBJHTBAA_3dE1186SceneData"
    assert perfmap.demangle(name) == "models.rollout.rollout_kernel"
    assert perfmap.demangle("cpython." + name) == "cpython.models.rollout.rollout_kernel"
    assert perfmap.demangle("_ZN5numba2np8arrayobj11ol_np_zerosB3v81") == "numba.np.arrayobj.ol_np_zeros"
    assert perfmap.demangle("NRT_incref") == "NRT_incref"


def test_the_map_names_the_kernels_a_rollout_ran(tmp_path):
    scenario = load_scenario(SCENARIOS / "two_finger_triangle.toml")
    rung = rung_for(scenario, "dynamic-rigid")
    out = rung.rollout(scenario, rung.initial_state(scenario), np.array([[-1.0, -1.0]]), [0.01], 1e-4)
    assert out.steps == 100
    rows = perf_map_entries(perfmap.write_perf_map(tmp_path / "kernels.map"))
    names = {name for _, _, name in rows}
    # the rollout and the stages it calls (the step's helpers are inlined into it: no code of their own)
    assert {"models.rollout.rollout_kernel", "models.contact.detect_planar_into", "NRT_incref"} <= names
    starts = [start for start, _, _ in rows]
    assert starts == sorted(set(starts))
    # each function ends where the next one loaded after it starts, or within MAX_SIZE
    for (start, size, _), (following, _, _) in zip(rows, rows[1:]):
        assert 0 < size <= perfmap.MAX_SIZE and start + size <= following

"""A rollout allocates per call, never per step: its buffers are made when the call starts, and
the steps that follow run on them (detection, the warm contact steps, the free steps, the
records), so a call of 1,000 steps allocates no more than one of 10 from the same state (fewer
where the longer run met its outcome: the end's classification, which allocates, is then not
run; incline_block's block reaches its goal within the second).

Counted with numba's runtime statistics (allocations through the runtime: every NumPy array a
compiled kernel makes) on the runs the benchmarks time: the paper's scene in free flight and
squeezing after the grasp (the planar detection, the free and planar contact runs), and
box_push_3d's push with the 8-sided cone (Lemke) and the exact cone (PGS); and a block sliding
on an incline, the planar detection's half-plane test at every step. That test allocated the
block's world core every step until the twenty-seventh session (docs/measurements.md): 1,171
allocations for 1,000 steps against 190 for 10, counted here.
"""

from __future__ import annotations

import numpy as np
import pytest
from numba.core.runtime import _nrt_python, rtsys

from models.rungs import pgs_rung, policy_controls, rung_for
from models.scenario import load_scenario
from tests.conftest import SCENARIOS


@pytest.fixture
def allocations():
    """A function: the runtime's allocations made while running its argument (the statistics
    switched on for the test, and back off after it if they were off)."""
    was_on = _nrt_python.memsys_stats_enabled()
    _nrt_python.memsys_enable_stats()

    def count(run) -> int:
        before = rtsys.get_allocation_stats().alloc
        run()
        return rtsys.get_allocation_stats().alloc - before

    yield count
    if not was_on:
        _nrt_python.memsys_disable_stats()


def _per_call(allocations, rung, scenario, state, u, h, steps):
    """The allocations of one rollout call of each length in steps (each run once first, so that
    a first call's compile and cache loading is not counted), and the calls' (steps, steps with
    contact force)."""
    counts, taken = [], []
    for n in steps:
        outs = []

        def run(n=n, outs=outs):
            outs.append(rung.rollout(scenario, state, u, [n * h], h, stop_at_outcome=False, max_records=2))

        run()
        counts.append(allocations(run))
        taken.append((outs[-1].steps, outs[-1].force_steps))
    return counts, taken


@pytest.mark.parametrize("rung_name", ["quasistatic-rigid", "dynamic-rigid", "dynamic-compliant"])
def test_the_paper_scene_allocates_per_call_not_per_step(allocations, rung_name):
    scenario = load_scenario(SCENARIOS / "two_finger_triangle.toml")
    rung = rung_for(scenario, rung_name)
    u, h = np.array([[-1.0, -1.0]]), 1e-4
    start = rung.initial_state(scenario)
    counts, steps = _per_call(allocations, rung, scenario, start, u, h, [10, 1000])  # free flight
    assert steps == [(10, 0), (1000, 0)]
    assert 0 < counts[1] <= counts[0]
    grasp = rung.rollout(scenario, start, u, [1.5], h, stop_at_outcome=False).state
    counts, steps = _per_call(allocations, rung, scenario, grasp, u, h, [10, 1000])  # squeezing
    assert steps == [(10, 10), (1000, 1000)]
    assert 0 < counts[1] <= counts[0]


@pytest.mark.parametrize("exact", [False, True], ids=["lemke", "exact-cone"])
def test_box_push_3d_s_push_allocates_per_call_not_per_step(allocations, exact):
    scenario = load_scenario(SCENARIOS / "box_push_3d.toml")
    rung = rung_for(scenario, "dynamic-rigid")
    rung = pgs_rung(rung, exact_cone=True) if exact else rung
    h = scenario.rung_settings("dynamic-rigid").h
    u, _ = policy_controls(scenario)
    pushing = rung.rollout(scenario, rung.initial_state(scenario), u, [0.4], h, stop_at_outcome=False).state
    counts, steps = _per_call(allocations, rung, scenario, pushing, u, h, [10, 100])  # one control period: 100 steps
    assert steps == [(10, 10), (100, 100)]
    assert 0 < counts[1] <= counts[0]


@pytest.mark.parametrize("rung_name", ["dynamic-rigid", "dynamic-compliant"])
def test_a_block_sliding_on_an_incline_allocates_per_call_not_per_step(allocations, rung_name):
    """A box on a half-plane: the planar detection's half-plane test at every step."""
    scenario = load_scenario(SCENARIOS / "incline_block.toml")
    rung = rung_for(scenario, rung_name)
    h = scenario.rung_settings(rung_name).h
    sliding = rung.rollout(scenario, rung.initial_state(scenario), np.zeros((1, 0)), [0.1], h, stop_at_outcome=False).state
    counts, steps = _per_call(allocations, rung, scenario, sliding, np.zeros((1, 0)), h, [10, 1000])
    assert steps == [(10, 10), (1000, 1000)]
    assert 0 < counts[1] <= counts[0]

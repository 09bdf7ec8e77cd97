"""Model-family benchmarks: steps per second per rung on the paper's scene, and a small
work-precision table (error against a fine-step reference). Run on demand:

    pytest -m slow tests/bench/test_bench_models.py -s
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from models.rungs import rung_for
from models.scenario import load_scenario
from tests.bench import timed_median
from tests.conftest import SCENARIOS

pytestmark = pytest.mark.slow
TRIANGLE = SCENARIOS / "two_finger_triangle.toml"
RUNG_NAMES = ["kinematic", "quasistatic-rigid", "quasistatic-compliant", "dynamic-rigid", "dynamic-compliant"]


def _run(name, h, *, v1=1.0, duration=3.0, stop=True):
    scenario = load_scenario(TRIANGLE, {"v1": v1})
    rung = rung_for(scenario, name)
    state = rung.initial_state(scenario)
    controls = np.array([[-v1, -1.0]])
    rung.rollout(scenario, state, controls, [h], h)  # compiled code loaded
    return rung.rollout(scenario, state, controls, [duration], h, stop_at_outcome=stop)


@pytest.mark.parametrize("name", RUNG_NAMES)
def test_steps_per_second_on_the_paper_scene(benchmark, name):
    """The scenario's policy (v1 = v2 = 1) until the grasp, at h = 1e-4."""
    result = benchmark.pedantic(_run, args=(name, 1e-4), rounds=5, iterations=1)
    assert result.outcome == "goal"
    benchmark.extra_info["steps"] = result.steps
    if (median := timed_median(benchmark)) is not None:
        benchmark.extra_info["steps_per_s"] = result.steps / median


def work_precision(name, steps=(1e-2, 1e-3, 1e-4), reference=1e-5, v1=0.8, t_end=1.6):
    """Max error of the trajectory over [1.45, t_end] (the pushing phase) against the same rung at `reference`."""
    times = np.linspace(1.45, t_end, 31)

    def sample(result):
        return np.array([np.interp(times, result.times, result.trajectory[:, j]) for j in range(result.trajectory.shape[1])]).T

    ref = sample(_run(name, reference, v1=v1, duration=t_end, stop=False))
    rows = []
    for h in steps:
        start = time.perf_counter()
        result = _run(name, h, v1=v1, duration=t_end, stop=False)
        wall = time.perf_counter() - start
        rows.append({"rung": name, "h": h, "error": float(np.max(np.abs(sample(result) - ref))), "wall_s": wall, "status": result.status})
    return rows


@pytest.mark.parametrize("name", RUNG_NAMES)
def test_work_precision(name):
    rows = work_precision(name)
    for row in rows:
        print(f"{row['rung']:22s} h={row['h']:.0e}  error={row['error']:.2e}  wall={row['wall_s']:.3f}s  {row['status']}")
        assert row["status"] == "ok"
    assert rows[-1]["error"] <= rows[0]["error"] + 1e-12  # finer steps are no worse

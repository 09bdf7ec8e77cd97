"""Planner benchmarks: the ladder against planning flat at the top rung (issue: "aim for
5x"), and the Fig. 5 sweep's wall time. Run on demand:

    pytest -m slow tests/bench/test_bench_planner.py -s

Results go to out/bench/*.json and are printed; no timed asserts.
"""

from __future__ import annotations

import json
import time

import pytest

from models.scenario import load_scenario
from planner.benchmark import ladder_vs_flat
from tests.conftest import ROOT, SCENARIOS

pytestmark = pytest.mark.slow
OUT = ROOT / "out" / "bench"


@pytest.mark.parametrize("name, params", [("two_finger_triangle", {"v1": 0.8}), ("four_finger_grasp", {}), ("box_push_3d", {})])
def test_ladder_against_flat(name, params):
    scenario = load_scenario(SCENARIOS / f"{name}.toml", params)
    result = ladder_vs_flat(scenario, range(1, 11), progress=lambda run: print(run, flush=True))
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"ladder_vs_flat.{name}.json").write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result["summary"], indent=1))
    assert len(result["runs"]) == 20


def test_fig5_sweep_wall_time():
    """41 log ratios x mu in {0.3, 0.5, 0.8, 1.2}, dynamic rung with plastic and elastic
    impacts at h = 1e-4 (328 runs) on all cores; and the same map at the quasistatic rung."""
    from planner import sweep as sw

    axes = [sw.parse_axis("v1=0.25:4:41:log"), sw.parse_axis("mu=0.3,0.5,0.8,1.2")]
    rigid = "finger_mass=1e3;finger_kp=1e9;finger_kd=2e6"
    timings = {}
    with sw.Executor() as executor:
        sw.sweep(
            str(SCENARIOS / "two_finger_triangle.toml"),
            axes[:1],
            sw.parse_models("quasistatic-rigid"),
            fixed={"v2": 1.0},
            duration=0.01,
            executor=executor,
        )  # workers started and kernels loaded
        for label, models, h in [
            ("dynamic plastic + elastic", f"dynamic-compliant[C=1e4;{rigid}],dynamic-compliant[C=0;{rigid}]", 1e-4),
            ("quasistatic", "quasistatic-rigid", None),
        ]:
            t0 = time.perf_counter()
            result = sw.sweep(
                str(SCENARIOS / "two_finger_triangle.toml"),
                axes,
                sw.parse_models(models),
                fixed={"v2": 1.0},
                h=h,
                duration=8.0,
                executor=executor,
            )
            timings[label] = {"runs": len(result.points), "wall_s": time.perf_counter() - t0}
            assert result.complete and all(p is not None for p in result.points)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "fig5_sweep.json").write_text(json.dumps(timings, indent=1) + "\n")
    print(timings)

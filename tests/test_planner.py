"""The planner over the ladder: plans that hold, determinism, replay, bad starts."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from models.rungs import rung_for
from models.scenario import ScenarioError, load_scenario
from planner.ladder import run_ladder
from tests.conftest import ROOT, SCENARIOS

TRIANGLE = SCENARIOS / "two_finger_triangle.toml"


def test_paper_scene_plan_holds_at_the_top_rung_when_replayed_independently():
    scenario = load_scenario(TRIANGLE, {"v1": 0.8})
    result = run_ladder(scenario, seed=1, iterations=2000)
    assert result.top_holds
    top = result.rungs[-1]
    assert top.rung == "dynamic-compliant"
    rung = rung_for(scenario, "dynamic-compliant")
    replay = rung.rollout(scenario, rung.initial_state(scenario), np.array(top.controls), np.array(top.durations), 1e-4)
    assert replay.outcome == "goal" and replay.ok


def test_same_seed_gives_the_same_plan_different_seed_may_differ():
    scenario = load_scenario(SCENARIOS / "free_transfer.toml")
    a = run_ladder(scenario, seed=3, iterations=3000).to_json(timings=False)
    b = run_ladder(scenario, seed=3, iterations=3000).to_json(timings=False)
    c = run_ladder(scenario, seed=4, iterations=3000).to_json(timings=False)
    assert json.dumps(a) == json.dumps(b)
    assert a["top_holds"] and c["top_holds"]
    assert json.dumps(a) != json.dumps(c)


def test_free_transfer_higher_rungs_are_accepted_by_replay_without_search():
    scenario = load_scenario(SCENARIOS / "free_transfer.toml")
    result = run_ladder(scenario, rungs=["kinematic", "quasistatic-rigid", "dynamic-rigid", "dynamic-compliant"], seed=3, iterations=3000)
    assert result.rungs[0].ended == "planned"
    for report in result.rungs[1:]:
        assert report.ended == "replayed" and report.propagations == 0
    assert result.top_holds


def test_a_start_inside_the_unsafe_set_is_bad_input(tmp_path):
    text = TRIANGLE.read_text().replace("[task]\nhorizon = 4.0", '[task]\nhorizon = 4.0\nstart = { "triangle.x" = 0.6 }')
    path = tmp_path / "unsafe_start.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match="inside the unsafe set"):
        run_ladder(load_scenario(path), seed=1, iterations=100)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = tmp_path / "plan"
    done = subprocess.run([sys.executable, "-m", "planner", "plan", str(path), "--out", str(out)], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 2 and "task.start" in done.stderr and not out.exists()


def test_plan_command_writes_a_reproducible_plan(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    outputs = []
    for run in range(2):
        out = tmp_path / f"run{run}"
        done = subprocess.run(
            [sys.executable, "-m", "planner", "plan", str(TRIANGLE), "--param", "v1=0.8", "--seed", "2", "--out", str(out)],
            capture_output=True, text=True, env=env, timeout=600,
        )
        assert done.returncode == 0, done.stderr
        outputs.append((out / "plan.json").read_bytes())
        assert (out / "plan.dynamic-compliant.png").exists()
    assert outputs[0] == outputs[1]

"""Plans carry up the ladder by tracking (`planner.tracking`): the previous plan as a reference,
followed in closed loop under the upgraded rung, repaired locally where it is lost."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from models.rungs import rung_for
from models.scenario import load_scenario
from planner.ladder import run_ladder
from planner.plan_status import PlanStatus
from planner.tracking import TRACK_TOLERANCE, PoseError, Reference, track

ROOT = Path(__file__).resolve().parents[1]
PUSH = ROOT / "scenarios" / "box_push_3d.toml"


def test_the_reference_is_the_previous_plan_per_control_period():
    """Controls lasting several periods are recorded period by period, under the plan's own
    rung, and the reference's configuration at a period's end is that rollout's state."""
    scenario = load_scenario(PUSH)
    rung = rung_for(scenario, "quasistatic-rigid")
    start = rung.initial_state(scenario)
    controls, durations = [[0.2, 0.0], [0.1, 0.05]], [0.5, 0.3]
    reference = Reference.of(scenario, rung, start, controls, durations, 0.1, 0.1)
    assert reference.duration == pytest.approx(0.8)
    assert len(reference.times) == 9 and len(reference.controls) == 8
    np.testing.assert_array_equal(reference.control(0.45), [0.2, 0.0])
    np.testing.assert_array_equal(reference.control(0.5), [0.1, 0.05])
    whole = rung.rollout(scenario, start, np.array(controls), np.array(durations), 0.1)
    np.testing.assert_allclose(reference.configuration(0.8), whole.state.q, atol=1e-12)
    mid = 0.5 * (reference.configurations[2] + reference.configurations[3])
    np.testing.assert_allclose(reference.configuration(0.25), mid)


def test_pose_error_weighs_a_turn_by_the_body_radius():
    scenario = load_scenario(PUSH)
    error = PoseError(scenario)
    q = rung_for(scenario, "dynamic-rigid").initial_state(scenario).q
    names = scenario.coordinates
    turned = q.copy()
    theta = 0.1
    turned[names.index("box.qw")], turned[names.index("box.qz")] = np.cos(theta / 2), np.sin(theta / 2)
    radius = np.sqrt(0.1**2 + 0.1**2 + 0.05**2)  # the box's bounding radius (half its diagonal)
    assert error(turned, q) == pytest.approx(theta * radius, rel=1e-9)
    moved = q.copy()
    moved[names.index("box.y")] += 0.03
    moved[names.index("pusher.x")] += 1.0  # the robot is not what the task is about
    assert error(moved, q) == pytest.approx(0.03)


def test_a_plan_tracked_under_its_own_rung_is_replayed_without_correction():
    scenario = load_scenario(PUSH)
    rung = rung_for(scenario, "quasistatic-rigid")
    start = rung.initial_state(scenario)
    reference = Reference.of(scenario, rung, start, [[0.2, 0.0]], [3.0], 0.1, 0.1)
    run = track(scenario, rung, start, reference, 0.1, 0.1, seed=1)
    assert run.corrected == 0 and run.repairs == 0 and not run.lost
    assert run.fraction == pytest.approx(1.0)
    # the same states as the reference's (then it holds still for TRACK_SETTLE periods: no goal)
    for k in range(len(reference.controls)):
        np.testing.assert_allclose(run.states[k].q, reference.configurations[k + 1], atol=1e-12)


def test_tracking_ends_when_the_rungs_time_is_up_or_it_is_stopped(monkeypatch):
    """Tracking checks the rung's time limit and Ctrl-C every control period (it had checked
    them only between its repairs, so a rung whose tracking was slow ran past `--time-limit`):
    a clock that moves on 1 s at each look, against a limit of 2.5 s, lets it track 2 periods."""
    from planner import tracking

    scenario = load_scenario(PUSH)
    rung = rung_for(scenario, "quasistatic-rigid")
    start = rung.initial_state(scenario)
    reference = Reference.of(scenario, rung, start, [[0.2, 0.0]], [3.0], 0.1, 0.1)
    clock = iter(range(1000))
    monkeypatch.setattr(tracking, "planning_clock", lambda: float(next(clock)))
    run = track(scenario, rung, start, reference, 0.1, 0.1, seed=1, time_limit=2.5)
    assert run.lost == "time" and len(run.controls) == 2 and run.diverged_at == pytest.approx(0.2)
    monkeypatch.undo()
    calls = iter(range(1000))
    run = track(scenario, rung, start, reference, 0.1, 0.1, seed=1, stop=lambda: next(calls) >= 4)
    assert run.lost == "stopped" and len(run.controls) == 4 and run.repairs == 0


def test_tracking_carries_a_quasistatic_plan_that_open_loop_replay_loses():
    """box_push_3d, seed 2: the quasistatic rung's plan replayed open-loop under dynamic-rigid
    runs the box into the wedge; tracked, it reaches the goal, and its controls replay to the
    same end under the rung (the tracked plan is an ordinary plan). (Seed 6 did until the
    contact LCP's warm start: a push is statically indeterminate, round-off picks which of its
    exact contact-force vertices a step returns, and seed 6's tracking then ends short of the
    goal; seeds 1 and 2 track to the goal either way.)"""
    scenario = load_scenario(PUSH)
    lower = run_ladder(scenario, rungs=["geometric", "kinematic", "quasistatic-rigid"], seed=2).rungs[-1]
    assert lower.ended.holds
    top = rung_for(scenario, "dynamic-rigid")
    h, period = scenario.rung_settings("dynamic-rigid").h, scenario.rung_settings("dynamic-rigid").control_period
    start = top.initial_state(scenario)
    open_loop = top.rollout(scenario, start, np.array(lower.controls), np.array(lower.durations), h)
    assert open_loop.outcome == "unsafe"
    below = rung_for(scenario, lower.rung)
    reference = Reference.of(scenario, below, below.initial_state(scenario), lower.controls, lower.durations, 0.1, period)
    run = track(scenario, top, start, reference, h, period, seed=2)
    assert run.outcome == "goal" and run.status == "ok"
    assert run.fraction > 0.5 and run.corrected > 0
    replay = top.rollout(scenario, start, np.array(run.controls), np.array(run.durations), h)
    assert replay.outcome == "goal" and replay.ok
    # every tracked state stayed near the reference (that is what tracking means)
    error = PoseError(scenario)
    t = np.cumsum(run.durations[: len(run.states)])
    if run.repairs == 0:
        assert max(error(s.q, reference.configuration(tk)) for s, tk in zip(run.states, t)) <= TRACK_TOLERANCE


def test_the_ladder_reports_how_the_previous_plan_carried_up():
    scenario = load_scenario(PUSH)
    result = run_ladder(scenario, seed=2)
    assert result.top_holds
    top = result.rungs[-1]
    assert top.ended in (PlanStatus.REPLAYED, PlanStatus.TRACKED, PlanStatus.REPAIRED)
    assert top.tracked is not None and top.tracked > 0.5 and top.rollouts > 0
    assert "of the previous plan's duration" in top.reason
    data = result.to_json()["rungs"][-1]
    assert {"tracked", "diverged_at", "repairs", "rollouts"} <= set(data)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["box_push_3d", "box_rotate_3d"])
def test_the_spatial_ladders_hold_in_nearly_every_seed(name):
    """The issue's bar: at least 95 % of 20 seeds hold at the top rung (`pytest -m slow`; the
    bench, `ladder bench --planning`, times them against flat planning)."""
    scenario = load_scenario(ROOT / "scenarios" / f"{name}.toml")
    held = sum(run_ladder(scenario, seed=seed).top_holds for seed in range(1, 21))
    assert held >= 19


def test_pose_error_weighs_a_yaw_coordinate_as_a_turn():
    scenario = load_scenario(ROOT / "scenarios" / "box_rotate_3d.toml")
    error = PoseError(scenario)
    q = rung_for(scenario, "dynamic-rigid").initial_state(scenario).q
    turned = q.copy()
    turned[scenario.coordinates.index("box.yaw")] += 0.1
    assert error(turned, q) == pytest.approx(0.1 * np.sqrt(0.1**2 + 0.1**2 + 0.05**2), rel=1e-9)

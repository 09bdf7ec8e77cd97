"""`Rung.rollout_each` (the ladder's replays: controls one after the other in one compiled call)
against separate `Rung.rollout` calls of each control, bit for bit: each control's end state
(q, nu, q_ref, deformations, Lemke's basis table), its outcome, status, smallest signed
distance and steps with contact force, and where the run stops (the first control that ends
in an outcome or a failure). In the plane and in space, with Lemke and with PGS (whose warm
starts each separate call drops at its start), and on a scene with a scripted obstacle (its
pose tables the call's own, each control placing the obstacle at its start)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from models.rungs import pgs_rung, rung_for
from models.scenario import load_scenario
from tests.test_scene_features import RAM, load, scene

ROOT = Path(__file__).resolve().parent.parent


def separate(scenario, rung, state, controls, durations, h):
    """What `_replay_controls` did before: one `Rung.rollout` a control, to the first that ends
    in an outcome or a failure."""
    outs = []
    for u, d in zip(controls, durations):
        out = rung.rollout(scenario, state, np.asarray(u, float).reshape(1, -1), [float(d)], h)
        outs.append(out)
        state = out.state
        if not out.ok or out.outcome != "none":
            break
    return outs


def assert_same(ends, outs):
    assert len(ends) == len(outs)
    for end, out in zip(ends, outs):
        for name in ("q", "nu", "q_ref", "delta_n", "delta_t", "lcp_basis"):
            a, b = getattr(end.state, name), getattr(out.state, name)
            assert a.shape == b.shape and np.array_equal(a, b), name
        assert (end.outcome, end.status, end.message) == (out.outcome, out.status, out.message)
        assert end.min_psi == out.min_psi and end.force_steps == out.force_steps
        assert end.ok == out.ok


@pytest.mark.parametrize(("rung_name", "h"), [("quasistatic-rigid", 1e-2), ("dynamic-rigid", 1e-3), ("dynamic-compliant", 1e-3)])
def test_the_paper_s_scene_replayed_in_one_call_is_each_control_s_rollout(rung_name, h):
    """The fingers descend at different speeds (v1 = 1.2, v2 = 0.8), so the first to arrive
    pushes the triangle aside before the grasp (steps with contact force); the grasp (the
    goal) ends the replay before its last controls, on the control that reaches it."""
    scenario = load_scenario(ROOT / "scenarios" / "two_finger_triangle.toml")
    rung = rung_for(scenario, rung_name)
    controls = [[-1.2, -0.8]] * 40 + [[0.0, 0.0]] * 5
    durations = [0.05] * len(controls)
    start = rung.initial_state(scenario)
    ends = rung.rollout_each(scenario, start, controls, durations, h)
    outs = separate(scenario, rung, start, controls, durations, h)
    assert_same(ends, outs)
    assert ends[-1].outcome == "goal" and len(ends) < len(controls)
    assert sum(e.force_steps for e in ends) > 0
    assert ends[-1].state.named(scenario)["triangle.x"] > 0.2  # pushed aside


@pytest.mark.parametrize("solver", ["lemke", "pgs", "exact"])
def test_box_push_replayed_in_one_call_is_each_control_s_rollout(solver):
    """box_push_3d's push, every step in contact (the box rests on the table): Lemke's basis
    crosses from control to control in the state; PGS's warm starts (the polygon's and the
    exact cone's) are dropped at each control's start, as a separate call drops them. With
    PGS alone on the exact cone the run stops on a step it does not converge on, as separate
    calls stop."""
    scenario = load_scenario(ROOT / "scenarios" / "box_push_3d.toml")
    rung = rung_for(scenario, "dynamic-rigid")
    if solver != "lemke":
        rung = pgs_rung(rung, exact_cone=solver == "exact")
    controls = [[0.3, 0.0]] * 6 + [[0.3, 0.1]] * 4 + [[0.0, -0.2]] * 3
    durations = [0.1] * len(controls)
    start = rung.initial_state(scenario)
    ends = rung.rollout_each(scenario, start, controls, durations, 1e-3)
    outs = separate(scenario, rung, start, controls, durations, 1e-3)
    assert_same(ends, outs)
    assert all(e.force_steps == 100 for e in ends if e.ok)
    assert ends[-1].state.q[0] > start.q[0] + 0.05  # the box was pushed
    if solver == "exact":  # PGS alone (not auto) does not converge on the turn: the run stops there
        assert len(ends) < len(controls) and ends[-1].status == "contact_not_converged"
    else:
        assert len(ends) == len(controls) and all(e.ok for e in ends)


def test_a_scripted_scene_is_replayed_as_separate_rollouts(tmp_path):
    """A ram moving at 0.5 m/s reaches the puck at 0.1 s: each control's call places it at the
    call's start (t0 = 0), as separate calls do (the goal, puck.x >= 0.5, is not reached)."""
    text = scene(RAM, smooth=[("ram", "puck")]).replace('"floor_dummy" = [0.0, 1.0]', '"floor_dummy" = [0.5, 1.0]')
    scenario = load(tmp_path, text, "puck.x")
    rung = rung_for(scenario, "dynamic-rigid")
    controls, durations = np.zeros((4, 0)), [0.15] * 4
    start = rung.initial_state(scenario)
    ends = rung.rollout_each(scenario, start, controls, durations, 1e-3)
    outs = separate(scenario, rung, start, controls, durations, 1e-3)
    assert_same(ends, outs)
    assert len(ends) == 4 and all(e.outcome == "none" for e in ends)
    assert ends[0].force_steps > 0 and ends[-1].state.named(scenario)["puck.x"] > 0.02  # pushed


def test_no_controls_no_ends():
    scenario = load_scenario(ROOT / "scenarios" / "two_finger_triangle.toml")
    rung = rung_for(scenario, "quasistatic-rigid")
    assert rung.rollout_each(scenario, rung.initial_state(scenario), np.zeros((0, 2)), [], 1e-2) == []


def test_the_geometric_rung_has_nothing_to_replay():
    scenario = load_scenario(ROOT / "scenarios" / "two_finger_triangle.toml")
    rung = rung_for(scenario, "geometric")
    with pytest.raises(ValueError, match="geometric"):
        rung.rollout_each(scenario, rung.initial_state(scenario), [[0.0, 0.0]], [0.05], 1e-2)


@pytest.mark.parametrize("steps", [1999, 3000, 14779])
def test_a_long_runs_records_reach_its_end_evenly(steps):
    """A run of more steps than DEFAULT_RECORDS records every ceil(steps / 1998)-th step, to its
    end (rounded down, a run of 3,000 steps had recorded its first 1,998 and jumped to its last),
    in one call and in chunks alike."""
    from models.rungs import DEFAULT_RECORDS

    scenario = load_scenario(ROOT / "scenarios" / "free_transfer.toml")
    rung = rung_for(scenario, "dynamic-rigid")
    start = rung.initial_state(scenario)
    h = 1e-3
    every = -(-steps // (DEFAULT_RECORDS - 2))
    controls = np.zeros((1, len(scenario.actuated)))
    for out in (
        rung.rollout(scenario, start, controls, [steps * h], h, stop_at_outcome=False),
        rung.rollout_chunked(scenario, start, controls, [steps * h], h, chunk_s=0.5, first_chunk=500),
    ):
        gaps = np.diff(out.times)
        assert len(out.times) <= DEFAULT_RECORDS and out.times[-1] == pytest.approx(steps * h)
        assert gaps.max() <= every * h * (1 + 1e-9), (steps, gaps.max())

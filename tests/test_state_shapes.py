"""A state or configuration of another scene, or a step or duration no rollout can take, is refused
before the compiled kernels read it.

The kernels index their arrays unchecked: a state of free_transfer (2 coordinates) rolled out in
box_push_3d (9) had crashed the Python process with a segmentation fault. `Rung.rollout` (and
`step`, `rollout_chunked`, which call it), `Rung.rollout_each` and the pair distances now raise
ValueError naming what is wrong; a state of the scene itself runs as before. So do controls not
shaped one per duration (`models.rungs.run_arrays`), which numpy's reshape had refused in its own
words, or reshaped into other controls.
"""

from __future__ import annotations

import numpy as np
import pytest

from models.rungs import pair_signed_distances, pair_signed_distances_many, rung_for
from models.scenario import load_scenario
from tests.conftest import DATA, SCENARIOS


@pytest.fixture(scope="module")
def scenes():
    return load_scenario(SCENARIOS / "free_transfer.toml"), load_scenario(SCENARIOS / "box_push_3d.toml")


def test_a_state_of_another_scene_is_refused_by_every_rollout(scenes):
    small, box = scenes
    rung = rung_for(box, "dynamic-rigid")
    other = rung_for(small, "dynamic-rigid").initial_state(small)
    u, h = np.zeros((1, len(box.actuated))), box.rung_settings("dynamic-rigid").h
    expected = "the state is not one of box_push_3d.toml's (a state of another scenario?): q (2,) (expected (9,)); nu (2,) (expected (8,))"
    calls = [
        lambda: rung.rollout(box, other, u, [0.1], h),
        lambda: rung.step(box, other, u[0], h),
        lambda: rung.rollout_each(box, other, u, [0.1], h),
        lambda: rung.rollout_chunked(box, other, u, [0.1], h),
    ]
    for call in calls:
        with pytest.raises(ValueError) as refused:
            call()
        assert str(refused.value).startswith(expected)
    own = rung.rollout(box, rung.initial_state(box), u, [0.1], h)  # its own state runs
    assert own.ok and own.steps == 100


def test_a_configuration_of_another_scene_is_refused_by_the_pair_distances(scenes):
    small, box = scenes
    with pytest.raises(ValueError, match=r"expected a configuration of 9 coordinates of box_push_3d.toml, got an array of shape \(2,\)"):
        pair_signed_distances(box, small.start)
    with pytest.raises(ValueError, match=r"one per row, of 9 coordinates of box_push_3d.toml, got an array of shape \(3, 2\)"):
        pair_signed_distances_many(box, np.zeros((3, 2)))
    d = pair_signed_distances(box, box.start)
    np.testing.assert_array_equal(pair_signed_distances_many(box, np.array([box.start]))[0], d)


@pytest.mark.parametrize(
    ("h", "durations", "message"),
    [
        (0.0, [0.1], "the step h must be a positive number of seconds, got 0.0"),  # (a ZeroDivisionError)
        (-1e-3, [0.1], "the step h must be a positive number of seconds, got -0.001"),  # (had run no step, status ok)
        (float("nan"), [0.1], "the step h must be a positive number of seconds, got nan"),
        (1e-3, [0.1, float("nan")], "a control's duration must be a finite number of seconds, no less than 0, got nan"),
        (1e-3, [0.1, -0.2], "a control's duration must be a finite number of seconds, no less than 0, got -0.2"),
        (1e-300, [0.1], "a control of 0.1 s at h = 1e-300 is 1e+299 steps, more than a rollout counts"),  # (had run on for ever)
    ],
)
def test_a_step_or_duration_no_rollout_can_take_is_refused(scenes, h, durations, message):
    small, _ = scenes
    rung = rung_for(small, "dynamic-rigid")
    start, u = rung.initial_state(small), np.zeros((len(durations), len(small.actuated)))
    for call in (rung.rollout, rung.rollout_each, rung.rollout_chunked):
        with pytest.raises(ValueError) as refused:
            call(small, start, u, durations, h)
        assert str(refused.value).startswith(message)


@pytest.mark.parametrize(
    ("controls", "durations", "message"),
    [
        # (numpy's reshape had said "cannot reshape array of size 6 into shape (2,2)")
        (np.ones((3, 2)), [0.1, 0.1], "controls of shape (3, 2) for 2 duration(s): a run takes one control per duration, "),
        # (had been reshaped into two other controls of three drives, silently)
        (np.ones((2, 3)), [0.1, 0.1, 0.1], "each of 2 commanded speed(s) (pusher.x, pusher.y), shape (3, 2)"),
        (np.ones(6), [0.1, 0.1, 0.1], "controls of shape (6,) for 3 duration(s)"),  # (flat, with more than one drive)
        (np.ones((1, 2)), [[0.1]], "durations must be a list of seconds, one per control, got an array of shape (1, 1)"),
    ],
)
def test_controls_not_shaped_one_per_duration_are_refused_in_the_runs_words(scenes, controls, durations, message):
    _, box = scenes
    assert box.actuated == ("pusher.x", "pusher.y")
    rung = rung_for(box, "dynamic-rigid")
    start, h = rung.initial_state(box), box.rung_settings("dynamic-rigid").h
    for call in (rung.rollout, rung.rollout_each, rung.rollout_chunked):
        with pytest.raises(ValueError) as refused:
            call(box, start, controls, durations, h)
        assert message in str(refused.value)


def test_flat_controls_run_where_they_read_one_way_only(scenes):
    _, box = scenes
    rung = rung_for(box, "dynamic-rigid")
    start, h = rung.initial_state(box), box.rung_settings("dynamic-rigid").h
    u = np.array([0.1, 0.0])
    flat = rung.rollout(box, start, u, [0.05], h)  # one control given flat
    shaped = rung.rollout(box, start, u.reshape(1, 2), [0.05], h)
    np.testing.assert_array_equal(flat.state.q, shaped.state.q)
    assert flat.ok and flat.steps == 50
    strike = load_scenario(DATA / "strike.toml")
    assert strike.actuated == ("pusher.x",)
    one = rung_for(strike, "dynamic-rigid")  # one drive: a control per duration, given flat
    s0 = one.initial_state(strike)
    a = one.rollout(strike, s0, np.array([0.2, -0.1]), [0.05, 0.05], 1e-3)
    b = one.rollout(strike, s0, np.array([[0.2], [-0.1]]), [0.05, 0.05], 1e-3)
    np.testing.assert_array_equal(a.state.q, b.state.q)
    assert a.ok and a.steps == b.steps > 0

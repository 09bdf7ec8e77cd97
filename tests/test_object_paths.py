"""Object paths carry upward (`planner.pushing`): the geometric rung's path of a pushed object
becomes a pushing reference that the first physics rung tracks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from models.rungs import rung_for
from models.scenario import load_scenario
from planner.ladder import run_ladder
from planner.plan_status import PlanStatus
from planner.pushing import APPROACH_CLEARANCE, APPROACH_SPEED, PUSH_SPEED, push_reference, pushing_pair

ROOT = Path(__file__).resolve().parents[1]
ROTATE = ROOT / "scenarios" / "box_rotate_3d.toml"
HALF, RADIUS = 0.1, 0.03  # box_rotate_3d's box half-width and pusher radius
#: The limit-surface radius of its 0.2 m square footprint: 2/3 of the radius of the disc of equal area.
C = 2.0 / 3.0 * np.sqrt(0.2 * 0.2 / np.pi)


def _start(scenario):
    return rung_for(scenario, "quasistatic-rigid").initial_state(scenario).q


def _moved(scenario, q, **delta):
    out = q.copy()
    for name, d in delta.items():
        out[scenario.coordinates.index(f"box.{name}")] += d
    return out


def test_only_scenes_of_one_pusher_and_one_object_get_a_pushing_reference():
    assert pushing_pair(load_scenario(ROTATE)) == ("box", "pusher")
    assert pushing_pair(load_scenario(ROOT / "scenarios" / "box_push_3d.toml")) == ("box", "pusher")
    for other in (ROOT / "scenarios" / "two_finger_triangle.toml", ROOT / "tests" / "data" / "strike.toml"):
        scenario = load_scenario(other)  # two fingers; a striker driven along x only
        assert pushing_pair(scenario) is None
        assert push_reference(scenario, [_start(scenario)] * 2, _start(scenario), 0.1) is None


def test_a_straight_path_is_pushed_from_behind_on_the_centre_line_at_the_push_speed():
    scenario = load_scenario(ROTATE)
    q0 = _start(scenario)
    reference = push_reference(scenario, [q0, _moved(scenario, q0, x=0.3)], q0, 0.1)
    names = scenario.coordinates
    box, pusher = (
        reference.configurations[:, names.index("box.x")],
        reference.configurations[:, [names.index("pusher.x"), names.index("pusher.y")]],
    )
    pushing = box > 0.0
    np.testing.assert_allclose(pusher[pushing, 0], box[pushing] - (HALF + RADIUS), atol=1e-12)
    np.testing.assert_allclose(pusher[pushing, 1], 0.0, atol=1e-12)
    speed = PUSH_SPEED * 0.5  # of the pusher's 0.5 m/s
    assert np.diff(box[pushing]).max() <= speed * 0.1 + 1e-12
    assert reference.configurations[-1, names.index("box.x")] == pytest.approx(0.3)
    assert np.abs(reference.controls).max() <= APPROACH_SPEED * 0.5 + 1e-12


@pytest.mark.parametrize("turn", [-0.6, 0.3, 0.6])
def test_a_turning_path_is_pushed_off_centre_at_the_offset_that_turns_it_at_its_rate(turn):
    """Lynch and Mason's sticking push: an offset o from the centre line turns the object at
    o / (c^2 + o^2) rad per metre; a turn to the left (counter-clockwise) takes a push to the
    right of the centre line."""
    scenario = load_scenario(ROTATE)
    q0 = _start(scenario)
    length = 0.3
    reference = push_reference(scenario, [q0, _moved(scenario, q0, x=length, yaw=turn)], q0, 0.1)
    names = scenario.coordinates
    q = reference.configurations
    pushing = q[:, names.index("box.x")] > 1e-9
    offset = q[pushing, names.index("pusher.y")] - q[pushing, names.index("box.y")]
    rate = turn / length
    assert np.all(np.sign(offset) == -np.sign(rate))
    np.testing.assert_allclose(np.abs(offset) / (C**2 + offset**2), abs(rate), rtol=1e-9)
    # the pusher touches the turned box's face behind it
    yaw = q[pushing, names.index("box.yaw")]
    behind = q[pushing, names.index("box.x")] - q[pushing, names.index("pusher.x")]
    np.testing.assert_allclose(behind, HALF * (np.abs(np.cos(yaw)) + np.abs(np.sin(yaw))) + RADIUS, atol=1e-12)


def test_the_approach_goes_around_the_object_clear_of_it():
    """A path that pushes the box toward the pusher's start: the pusher goes around the box,
    clear of its bounding circle, to the push point on the far side."""
    scenario = load_scenario(ROTATE)
    q0 = _start(scenario)
    reference = push_reference(scenario, [q0, _moved(scenario, q0, x=-0.2)], q0, 0.1)
    names = scenario.coordinates
    q = reference.configurations
    approach = q[:, names.index("box.x")] == 0.0
    pusher = q[approach][:, [names.index("pusher.x"), names.index("pusher.y")]]
    assert pusher[-1] == pytest.approx([HALF + RADIUS, 0.0])
    clear = np.sqrt(2 * HALF**2 + 0.05**2) + RADIUS + APPROACH_CLEARANCE  # the box's bounding sphere
    distance = np.hypot(*pusher.T)
    assert distance[1:-2].min() >= clear - 1e-9
    steps = np.hypot(*np.diff(pusher, axis=0).T)
    assert steps.max() <= APPROACH_SPEED * 0.5 * 0.1 + 1e-12


def test_the_first_physics_rung_pushes_the_object_along_the_geometric_path():
    """box_rotate_3d, seed 7: the quasistatic rung reaches the goal by tracking the pushing
    reference alone (no search), and the ladder's plan holds at the top rung."""
    result = run_ladder(load_scenario(ROTATE), seed=7)
    assert result.top_holds
    quasi = next(r for r in result.rungs if r.rung == "quasistatic-rigid")
    assert quasi.ended in (PlanStatus.TRACKED, PlanStatus.REPAIRED)
    assert "a push along the geometric plan's object path" in quasi.reason
    assert quasi.tracked > 0.5 and quasi.rollouts > 0

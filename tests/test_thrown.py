"""A kinematic run that throws a body says so (`models.rungs.thrown_motion`).

The kinematic step (the paper's eq. 8) has no forces or friction: a pushed body moves the least
that keeps the contacts apart. A finger pressing down at speed v on a wedge's face, which rises at
alpha from the horizontal, drives the wedge (free along x only) at v / tan(alpha): the closed form,
without bound as the face flattens. A real wedge at half a degree would jam under any friction.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from models.rungs import DRIVEN_RATIO, policy_controls, run_warnings, rung_for, thrown_motion
from models.scenario import load_scenario

SPEED = 0.01  # the finger's descent, m/s
RADIUS = 0.02
LENGTH = 1.0
GAP = 1e-4  # the finger starts this far above the face


def wedge_scene(tmp_path, degrees: float, scripted: bool = False):
    """A right-triangle wedge whose face rises at `degrees` to the right, free along x, under a
    disc finger that descends at SPEED over the face's middle (scripted: an obstacle on a script,
    the scene's only driver)."""
    rise = LENGTH * math.tan(math.radians(degrees))
    path = tmp_path / f"wedge_{degrees}{'_scripted' if scripted else ''}.toml"
    finger = (
        f'role = "obstacle"\nvelocity = {{ y = {-SPEED} }}'
        if scripted
        else 'role = "robot"\nmass = 0.1\ndofs = ["y"]\nactuators.y = { kp = 1e4, kd = 2e2, max_speed = 1.0, lower = -1.0, upper = 1.0 }'
    )
    policy = "" if scripted else f'[task.policy]\ntype = "constant_speed"\nspeeds = {{ "finger.y" = {-SPEED} }}\nduration = 0.05\n'
    path.write_text(
        f"""version = 1
[scenario]
name = "wedge"
[scene]
dimension = 2
gravity = [0.0, -9.81]
[contact]
mu = 0.5
K = 1e6
C = 1e3
[[bodies]]
name = "wedge"
role = "object"
mass = 1.0
inertia = 0.1
shape = {{ type = "polygon", vertices = [[0.0, 0.0], [{LENGTH}, 0.0], [{LENGTH}, {rise!r}]] }}
dofs = ["x"]
[[bodies]]
name = "finger"
{finger}
shape = {{ type = "disc", radius = {RADIUS} }}
pose = {{ x = {LENGTH / 2}, y = {rise / 2 + RADIUS / math.cos(math.radians(degrees)) + GAP!r} }}
[task]
horizon = 1.0
goal = {{ box = {{ "wedge.x" = [5.0, 6.0] }} }}
{policy}[ladder]
control_period = 0.05
time_limit = 5.0
[[ladder.rungs]]
model = "kinematic"
h = 1e-3
"""
    )
    return path


def run(path, name: str = "kinematic"):
    scenario = load_scenario(path)
    rung = rung_for(scenario, name)
    controls, durations = policy_controls(scenario)
    out = rung.rollout(scenario, rung.initial_state(scenario), controls, durations, 1e-3, stop_at_outcome=False)
    return scenario, rung, out


@pytest.mark.parametrize("degrees", [0.3, 0.5])
def test_a_grazing_wedge_is_thrown_at_the_closed_form_speed(tmp_path, degrees):
    scenario, rung, out = run(wedge_scene(tmp_path, degrees))
    speed = SPEED / math.tan(math.radians(degrees))  # 1.91 and 1.15 m/s: 191 and 115 times the finger's
    assert out.status == "ok" and out.steps == 50
    assert out.velocities[-1][0] == pytest.approx(speed, rel=1e-9)  # the kinematic step's own answer
    found = thrown_motion(scenario, rung, 1e-3, out)
    assert found is not None and found.body == "wedge"
    assert found.speed == pytest.approx(speed, rel=1e-9) and found.driven == pytest.approx(SPEED, rel=1e-12)
    (warning,) = run_warnings(scenario, rung, 1e-3, out)
    assert warning.startswith(f"wedge was thrown: kinematic steps moved it at up to {speed:.3g} m/s, {speed / SPEED:,.0f} times")


@pytest.mark.parametrize("degrees", [0.7, 5.0, 30.0])
def test_a_wedge_driven_a_few_times_faster_than_its_pusher_is_not_thrown(tmp_path, degrees):
    """At 0.7 degrees the wedge moves 82 times the finger's speed: under DRIVEN_RATIO."""
    scenario, rung, out = run(wedge_scene(tmp_path, degrees))
    speed = SPEED / math.tan(math.radians(degrees))
    assert out.status == "ok" and out.velocities[-1][0] == pytest.approx(speed, rel=1e-9)
    assert speed < DRIVEN_RATIO * SPEED and thrown_motion(scenario, rung, 1e-3, out) is None
    assert run_warnings(scenario, rung, 1e-3, out) == []


def test_a_scripted_obstacle_drives_like_an_actuator(tmp_path):
    """The finger on a script at the same speed (the scene's only driver) throws the wedge as
    fast, and its speed is the one the ratio counts (`_driven_speed`); at 30 degrees it does not."""
    for degrees, thrown in ((0.3, True), (30.0, False)):
        scenario = load_scenario(wedge_scene(tmp_path, degrees, scripted=True))
        assert not scenario.actuated
        rung = rung_for(scenario, "kinematic")
        out = rung.rollout(scenario, rung.initial_state(scenario), np.zeros((1, 0)), [0.05], 1e-3, stop_at_outcome=False)
        speed = SPEED / math.tan(math.radians(degrees))
        assert out.status == "ok" and out.velocities[-1][0] == pytest.approx(speed, rel=1e-9)
        found = thrown_motion(scenario, rung, 1e-3, out)
        assert (found is not None) is thrown
        if thrown:
            assert found.speed == pytest.approx(speed, rel=1e-9) and found.driven == SPEED


def test_the_other_rungs_and_a_still_finger_say_nothing(tmp_path):
    """The rule is the kinematic model's: a dynamic rung's wedge is pushed by forces (and here
    friction holds it); with the finger still nothing moves."""
    path = wedge_scene(tmp_path, 0.3)
    for name in ("quasistatic-rigid", "dynamic-rigid"):
        scenario, rung, out = run(path, name)
        assert out.status == "ok" and thrown_motion(scenario, rung, 1e-3, out) is None
        assert abs(out.velocities[-1][0]) < 1.0  # not thrown: the kinematic answer is 1.91 m/s
    scenario = load_scenario(path)
    rung = rung_for(scenario, "kinematic")
    out = rung.rollout(scenario, rung.initial_state(scenario), np.zeros((1, 1)), [0.05], 1e-3)
    assert np.all(out.velocities == 0.0) and thrown_motion(scenario, rung, 1e-3, out) is None


def test_simulate_reports_it(tmp_path, capsys):
    from planner.cli import main

    assert main(["simulate", str(wedge_scene(tmp_path, 0.3)), "--model", "kinematic", "--step", "1e-3", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["status"] == "ok" and len(summary["warnings"]) == 1
    assert summary["warnings"][0].startswith("wedge was thrown: kinematic steps moved it at up to 1.91 m/s, 191 times")

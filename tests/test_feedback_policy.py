"""Feedback policies (`[task.policy] type = "feedback"`, `models.schema.Law`): a drive under a
law applies kd (v_des - v), v_des = (kp / kd) (target - q) limited to max_speed, with the
target a coordinate value or a point fixed in a body. Checked against closed forms: the
damped oscillator the law makes of a falling finger, its terminal speed where the limit acts,
and the kinematic rung's exact geometric approach to a body's point; and the paper's scene
under its Fig. 4 (d) controller."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from models.rollout import rollout_kernel
from models.rungs import RUNGS, _basis_of, compiled, policy_controls
from models.scenario import ScenarioError, load_scenario
from tests.test_cli import ladder

G = 9.81
MASS = 0.1


def finger_scene(tmp_path, law: str, *, start: float = 1.0, policy_type: str = "feedback", extra: str = ""):
    """A 0.1 kg disc moving along y (a drive with kp = 1e4 the law replaces) far above a floor,
    beside a post (an obstacle at (0.3, 0.4) turned by 90 degrees), never touching either."""
    text = textwrap.dedent(
        f"""
        version = 1
        [scenario]
        name = "finger"
        [scene]
        dimension = 2
        gravity = [0.0, -{G}]
        [contact]
        mu = 0.5
        K = 1e6
        C = 1e3
        [[bodies]]
        name = "floor"
        role = "obstacle"
        shape = {{ type = "halfplane", normal = [0.0, 1.0], offset = -5.0 }}
        [[bodies]]
        name = "post"
        role = "obstacle"
        shape = {{ type = "disc", radius = 0.05 }}
        pose = {{ x = 0.3, y = 0.4, theta = {math.pi / 2} }}
        [[bodies]]
        name = "finger"
        role = "robot"
        mass = {MASS}
        shape = {{ type = "disc", radius = 0.05 }}
        pose = {{ x = -1.0, y = {start} }}
        dofs = ["y"]
        actuators.y = {{ kp = 1e4, kd = 2e2, max_speed = 2.0 }}
        [task]
        horizon = 5.0
        goal = {{ box = {{ "finger.y" = [10.0, 11.0] }} }}
        [task.policy]
        type = "{policy_type}"
        duration = 3.0
        laws."finger.y" = {law}
        {extra}
        [ladder]
        time_limit = 5.0
        [[ladder.rungs]]
        model = "dynamic-compliant"
        h = 1e-4
        """
    )
    path = tmp_path / "finger.toml"
    path.write_text(text)
    return load_scenario(path)


def run_policy(scenario, rung: str, h: float, duration: float | None = None):
    r = RUNGS[rung]
    controls, durations = policy_controls(scenario, duration)
    out = r.rollout(scenario, r.initial_state(scenario), controls, durations, h, stop_at_outcome=False, max_records=3001, laws=True)
    assert out.status == "ok", out.message
    return out


def _oscillator(t, y0, target, kp, kd, m=MASS, g=G):
    """y(t) of m y'' + kd y' + kp y = kp target - m g from rest at y0 (overdamped)."""
    y_eq = target - m * g / kp
    disc = math.sqrt(kd * kd - 4 * m * kp)
    r1, r2 = (-kd + disc) / (2 * m), (-kd - disc) / (2 * m)
    a = y0 - y_eq  # y - y_eq = c1 e^(r1 t) + c2 e^(r2 t), c1 + c2 = a, r1 c1 + r2 c2 = 0
    c1 = -r2 * a / (r1 - r2)
    c2 = r1 * a / (r1 - r2)
    return y_eq + c1 * np.exp(r1 * t) + c2 * np.exp(r2 * t)


def test_a_law_to_a_fixed_target_is_the_damped_oscillator_it_defines(tmp_path):
    """kp = 200, kd = 20 on 0.1 kg under gravity: m y'' = kp (T - y) - kd y' - m g from rest at
    y = 1 toward T = 0.5 (overdamped, zeta = 2.24). The dynamic rung's semi-implicit step
    follows the closed form to O(h), and the finger settles at the gravity offset T - m g / kp."""
    scenario = finger_scene(tmp_path, "{ target = 0.5, kp = 200.0, kd = 20.0 }")
    errors = []
    for h in (1e-3, 1e-4):
        out = run_policy(scenario, "dynamic-compliant", h)
        y = out.trajectory[:, scenario.coordinates.index("finger.y")]
        errors.append(np.max(np.abs(y - _oscillator(out.times, 1.0, 0.5, 200.0, 20.0))))
    assert errors[1] < 2e-4
    assert errors[0] / errors[1] == pytest.approx(10.0, rel=0.2)  # first order in h
    assert out.state.named(scenario)["finger.y"] == pytest.approx(0.5 - MASS * G / 200.0, abs=1e-9)


def test_the_speed_limit_makes_a_terminal_speed(tmp_path):
    """Far from the target the desired speed is the limit, -0.2 m/s: kd (-0.2 - v) = m g at the
    terminal speed v = -0.2 - m g / kd = -0.249 m/s, reached with the time constant m / kd = 5 ms."""
    scenario = finger_scene(tmp_path, "{ target = -3.0, kp = 200.0, kd = 20.0, max_speed = 0.2 }")
    out = run_policy(scenario, "dynamic-compliant", 1e-4, duration=1.0)
    assert out.state.nu[scenario.velocities.index("finger.y")] == pytest.approx(-0.2 - MASS * G / 20.0, rel=1e-9)


def test_a_body_point_target_in_the_kinematic_rung_is_a_geometric_approach(tmp_path):
    """The post's point (0.1, 0) in its frame, turned by 90 degrees about (0.3, 0.4), is at
    world y = 0.5. The kinematic rung moves the finger at the law's speed: y+ = y + h r (0.5 - y),
    r = kp / kd = 10, so y_n = 0.5 + (1 - 0.5) (1 - h r)^n exactly."""
    scenario = finger_scene(tmp_path, '{ target = { body = "post", point = [0.1, 0.0] }, kp = 200.0, kd = 20.0 }')
    h = 1e-2
    out = run_policy(scenario, "kinematic", h, duration=1.0)
    n = round(1.0 / h)
    assert out.state.named(scenario)["finger.y"] == pytest.approx(0.5 + 0.5 * (1 - h * 10.0) ** n, abs=1e-12)


def test_the_paper_scene_grasps_under_its_fig_4d_controller():
    """The paper's scene with its named `potential` policy (scenarios/two_finger_triangle.toml):
    both fingers under the well centred on their face points grasp at v1 = 0.8, v2 = 1."""
    scenario = load_scenario("scenarios/two_finger_triangle.toml", {"v1": 0.8}).with_policy("potential")
    out = run_policy(scenario, "dynamic-compliant", 1e-4)
    assert out.outcome == "goal"


@pytest.mark.parametrize(
    "law, policy_type, extra, key",
    [
        ("{ target = 0.5, kp = 200.0, kd = 20.0 }", "constant_speed", "", "task.policy.laws"),
        (
            '{ target = { body = "nobody", point = [0.0, 0.0] }, kp = 1.0, kd = 1.0 }',
            "feedback",
            "",
            'task.policy.laws."finger.y".target.body',
        ),
        (
            '{ target = { body = "post", point = [0.0, 0.0, 0.0] }, kp = 1.0, kd = 1.0 }',
            "feedback",
            "",
            'task.policy.laws."finger.y".target.point',
        ),
        ("{ target = 0.5, kp = 200.0, kd = 20.0 }", "feedback", 'speeds = { "finger.y" = 0.1 }', "task.policy.speeds"),
        ("{ target = 0.5, kp = -1.0, kd = 20.0 }", "feedback", "", 'task.policy.laws."finger.y".kp'),
    ],
)
def test_bad_laws_name_their_key(tmp_path, law, policy_type, extra, key):
    with pytest.raises(ScenarioError) as err:
        finger_scene(tmp_path, law, policy_type=policy_type, extra=extra)
    assert any(p.key == key for p in err.value.problems), err.value.problems


def test_an_unknown_policy_name_is_bad_input():
    """`--policy NAME` that the file does not have: exit 2, the key and the names it has."""
    run = ladder("simulate", "scenarios/two_finger_triangle.toml", "--model", "kinematic", "--policy", "nope")
    assert run.returncode == 2
    assert "task.policies" in run.stderr and "potential" in run.stderr and "Traceback" not in run.stderr


def test_a_rollout_runs_on_the_drives_asked_for_with_the_scene_bound_once():
    """`Rung.rollout` binds the scene once per (model, solver, laws) (`models.rollout.rollout_bound`):
    with and without the laws, asked in turns, each run is the kernel's own on those drives,
    bit for bit, and the two differ."""
    scenario = load_scenario("scenarios/two_finger_triangle.toml", {"v1": 0.8}).with_policy("potential")
    r, h = RUNGS["dynamic-compliant"], 1e-4
    controls, durations = policy_controls(scenario, 0.05)
    start, c = r.initial_state(scenario), compiled(scenario)
    finals = {}
    for laws in (True, False, True):
        out = r.rollout(scenario, start, controls, durations, h, stop_at_outcome=False, laws=laws)
        raw = rollout_kernel(
            c.scene, c.policy_drives if laws else c.drives, r.model, r.solver, c.goal, c.unsafe, start.q.copy(), start.nu.copy(),
            start.q_ref.copy(), start.delta_n.copy(), start.delta_t.copy(), _basis_of(start),
            np.array(controls, dtype=float).reshape(len(durations), -1), np.array(durations, dtype=float), h, out.steps, 2, False, 0.0,
        )  # fmt: skip
        assert out.steps == raw.steps == 500
        assert np.array_equal(out.state.q, raw.q) and np.array_equal(out.state.nu, raw.nu)
        finals.setdefault(laws, out.state.q)
        assert np.array_equal(finals[laws], out.state.q)
    assert not np.array_equal(finals[True], finals[False])
    assert len(c.bound) == 2

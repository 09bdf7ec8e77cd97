"""Generalized coordinates, G(q) and the position update."""

from __future__ import annotations

import numpy as np
import pytest

from models.kinematics import G_matrix, compile_scene, quat_mul
from models.scenario import load_scenario
from models.stepper import integrate_positions
from tests.conftest import SCENARIOS


@pytest.fixture(scope="module")
def box_scene():
    scenario = load_scenario(SCENARIOS / "box_push_3d.toml")
    return scenario, compile_scene(scenario)


def test_planar_G_is_the_identity():
    S = compile_scene(load_scenario(SCENARIOS / "four_finger_grasp.toml"))
    q = np.array([0.1, 0.2, 0.3, 1.0, 1.0])
    np.testing.assert_array_equal(G_matrix(S, q), np.eye(5))
    nu = np.array([1.0, -2.0, 0.5, 0.1, 0.2])
    np.testing.assert_allclose(integrate_positions(S.bi, q, nu, 0.01), q + 0.01 * nu)


def test_quaternion_rate_map_matches_the_exact_rotation(box_scene):
    """G(q) nu is the derivative of q along the motion with world angular velocity w."""
    scenario, S = box_scene
    rng = np.random.default_rng(2)
    for _ in range(20):
        q = np.array(scenario.start, dtype=float)
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
        nu = rng.normal(size=S.nv)
        w = nu[3:6]
        dt = 1e-6
        # exact rotation by angle |w| dt about w, applied in the world frame
        angle = np.linalg.norm(w) * dt
        axis = w / np.linalg.norm(w)
        dq = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])
        exact = quat_mul(dq, q[3:7])
        rate = G_matrix(S, q) @ nu
        np.testing.assert_allclose(rate[3:7], (exact - q[3:7]) / dt, atol=1e-5)
        np.testing.assert_allclose(rate[:3], nu[:3])


def test_position_update_keeps_quaternions_unit(box_scene):
    scenario, S = box_scene
    q = np.array(scenario.start, dtype=float)
    nu = np.zeros(S.nv)
    nu[3:6] = [3.0, -2.0, 5.0]
    for _ in range(1000):
        q = integrate_positions(S.bi, q, nu, 1e-2)
    assert np.linalg.norm(q[3:7]) == pytest.approx(1.0, abs=1e-12)


def test_obstacles_contribute_no_dofs(box_scene):
    scenario, S = box_scene
    assert S.nq == 9 and S.nv == 8  # box: 3 + 4 (quaternion), pusher: 2; velocities 3 + 3 + 2
    assert scenario.coordinates[-2:] == ("pusher.x", "pusher.y")
    table = [b.name for b in scenario.spec.bodies].index("table")
    assert np.all(S.qmap[table] < 0) and np.all(S.vmap[table] < 0)

"""The paper's theta-rule on the drives (`models.stepper._drive_impulse`): a driven finger in free
flight against the exact solution of its linear ODE (the matrix exponential), first order at
theta = 1 (eq. 3's semi-implicit step) and second order at theta = 1/2."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.linalg import expm

from models.rungs import rung_for
from models.scenario import load_scenario
from planner.bench import SCENARIOS

T = 0.004  # s: the fingers descend from rest, far from the triangle (first contact after 1.4 s)


def _finger(theta: float, h: float) -> float:
    """finger2.y after T under the command -1 m/s, dynamic-compliant with the rung's theta."""
    tri = load_scenario(SCENARIOS / "two_finger_triangle.toml")
    rung = rung_for(tri, "dynamic-compliant")
    rung = replace(rung, model=rung.model._replace(theta=theta))
    out = rung.rollout(tri, rung.initial_state(tri), np.array([[-1.0, -1.0]]), [T], h, stop_at_outcome=False)
    assert out.status == "ok" and out.steps == round(T / h)
    return float(out.state.q[tri.coordinates.index("finger2.y")])


def _exact() -> float:
    """m y'' = kp (r - y) + kd (u - y') - m g with r = y0 + u t, from rest: the state (y, y', r, 1)
    is linear with a constant matrix, so its flow over T is expm(T A)."""
    m, kp, kd, g, u, y0 = 0.1, 1e5, 2e2, 9.81, -1.0, 2.05
    A = np.zeros((4, 4))
    A[0, 1] = 1.0
    A[1, :] = [-kp / m, -kd / m, kp / m, kd * u / m - g]
    A[2, 3] = u
    return float((expm(T * A) @ np.array([y0, 0.0, y0, 1.0]))[0])


@pytest.mark.parametrize(("theta", "order"), [(1.0, 1), (0.5, 2)])
def test_drive_theta_rule_converges_at_its_order(theta, order):
    exact = _exact()
    errors = [abs(_finger(theta, h) - exact) for h in (1e-4, 5e-5, 2.5e-5)]
    for coarse, fine in zip(errors, errors[1:]):
        assert 2**order * 0.8 < coarse / fine < 2**order * 1.25, errors


def test_drive_theta_rule_is_more_accurate_at_one_half():
    exact = _exact()
    assert abs(_finger(0.5, 1e-4) - exact) < 0.1 * abs(_finger(1.0, 1e-4) - exact)

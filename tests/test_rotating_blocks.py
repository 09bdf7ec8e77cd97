"""A^-1's body blocks where A changes with q (a free rotation in space).

A = eps M(q) + h (h kp + kd) on the unlimited drives' DOFs is block diagonal by body. Only the
blocks of the bodies with a free rotation change with q: the System holds every block, and a
rollout refreshes the rotating ones at each step (`rotating_blocks_into`) instead of rebuilding A
and inverting every block. That refresh is held here to the blocks `body_blocks` reads from
`system_matrix` at the same q, bit for bit; the rotations' 3 x 3 inverse by its adjugate
(`_invert_3x3_into`) to the inverse; M(q) nu with the gyroscopic force in one pass
(`_mass_times_gyro_into`) to the two products apart; and the free rotation they serve to its
closed forms (a spin about a principal axis is steady; a torque-free tumble keeps its angular
momentum in world axes and its kinetic energy).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from models.contact_pgs import BODY_DOFS, _invert_small_into, _invert_split_into, body_blocks
from models.rungs import compiled, rung_for
from models.scenario import load_scenario
from models.stepper import (
    _gyroscopic_into,
    _mass_times_gyro_into,
    _mass_times_into,
    rotating_blocks,
    system_matrix,
    world_inertia,
)

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"

#: Three rotating bodies: a free box, a box whose x and y are driven (its block's translations
#: carry the drives' terms), and a plate that only rises and turns (a block of 4, which
#: `_invert_small_into` inverts by Gauss-Jordan, not by parts).
SCENE = """
version = 1
[scenario]
name = "rotating_blocks"
[scene]
dimension = 3
gravity = [0.0, 0.0, 0.0]
[contact]
mu = 0.5
K = 1e6
C = 1e3
[[bodies]]
name = "tumbler"
role = "object"
mass = 2.0
inertia = [0.05, 0.11, 0.14]
shape = { type = "box", size = [0.4, 0.3, 0.2] }
pose = { x = 0.0, y = 0.0, z = 1.0 }
dofs = ["x", "y", "z", "rotation"]
[[bodies]]
name = "carried"
role = "robot"
mass = 0.7
inertia = [0.01, 0.02, 0.025]
shape = { type = "box", size = [0.2, 0.15, 0.1] }
pose = { x = 2.0, y = 0.0, z = 1.0 }
dofs = ["x", "y", "z", "rotation"]
actuators.x = { kp = 1e4, kd = 1e2, max_speed = 0.5 }
actuators.y = { kp = 3e3, kd = 50.0, max_speed = 0.5 }
[[bodies]]
name = "plate"
role = "object"
mass = 0.3
inertia = [0.002, 0.004, 0.005]
shape = { type = "box", size = [0.2, 0.1, 0.02] }
pose = { x = -2.0, y = 0.0, z = 1.0 }
dofs = ["z", "rotation"]
[task]
horizon = 1.0
goal = { box = { "tumbler.x" = [-1.0, 1.0] } }
velocity = { %s }
[ladder]
time_limit = 1.0
[[ladder.rungs]]
model = "dynamic-rigid"
h = 1e-3
"""


@pytest.fixture(scope="module")
def rotating(tmp_path_factory):
    path = tmp_path_factory.mktemp("rotating") / "rotating.toml"
    path.write_text(SCENE % "")
    return load_scenario(path)


def _random_quaternions(q, scenario, rng):
    """q with every free rotation's quaternion drawn at random (normalised, as a state holds it)."""
    q = q.copy()
    for i, name in enumerate(scenario.coordinates):
        if name.endswith(".qw"):
            quat = rng.normal(size=4)
            q[i : i + 4] = quat / np.linalg.norm(quat)
    return q


@pytest.mark.parametrize("name", ["rotating", "box_push_3d"])
@pytest.mark.parametrize("eps", [1.0, 1e-3])
def test_the_refreshed_blocks_are_the_blocks_of_A_at_q_bit_for_bit(rotating, name, eps):
    scenario = rotating if name == "rotating" else load_scenario(SCENARIOS / "box_push_3d.toml")
    c = compiled(scenario)
    S, D = c.scene, c.drives
    h, rng = 1e-3, np.random.default_rng(7)
    args = (D.v_index, D.kp, D.kd, D.max_force)
    q0 = _random_quaternions(scenario.start, scenario, rng)
    dofs, count, inv, ok = body_blocks(S.bi, system_matrix(S.bi, S.bf, q0, S.nv, eps, h, *args), np.zeros((0, 0)))
    assert ok
    for _ in range(50):
        q = _random_quaternions(scenario.start, scenario, rng)
        assert rotating_blocks(S.bi, S.bf, q, eps, h, *args, dofs, count, inv)
        want_dofs, want_count, want, ok = body_blocks(S.bi, system_matrix(S.bi, S.bf, q, S.nv, eps, h, *args), np.zeros((0, 0)))
        assert ok
        assert np.array_equal(count, want_count) and np.array_equal(dofs, want_dofs)
        for b, m in enumerate(count):
            assert np.array_equal(inv[b, :m, :m], want[b, :m, :m]), f"body {b} at q = {q}"


def _split_block(rng, inertia, eps, masses):
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    B = np.zeros((6, 6))
    B[:3, :3] = np.diag(masses)
    B[3:, 3:] = eps * R @ np.diag(inertia) @ R.T
    return B


@pytest.mark.parametrize("ratio", [1.0, 30.0, 1e4])
def test_the_rotations_adjugate_is_their_inverse(ratio):
    rng = np.random.default_rng(int(ratio))
    worst = 0.0
    for _ in range(200):
        inertia = np.array([1.0, rng.uniform(1.0, ratio), ratio]) * 10.0 ** rng.uniform(-4, 1)
        B = _split_block(rng, inertia, 10.0 ** rng.uniform(-3, 0), rng.uniform(0.1, 5.0, size=3))
        out, work = np.full((6, 6), np.nan), np.zeros((BODY_DOFS, 2 * BODY_DOFS))
        assert _invert_split_into(B, out)
        assert np.all(out[:3, 3:] == 0.0) and np.all(out[3:, :3] == 0.0)  # the parts stay apart
        residual = np.abs(out @ B - np.eye(6)).max()
        worst = max(worst, residual / (np.finfo(float).eps * ratio))
        # and the general elimination on the same block agrees to the block's conditioning
        gj = np.zeros((6, 6))
        assert _invert_small_into(B + 0.0, 6, gj, work)
        np.testing.assert_allclose(out, gj, rtol=0, atol=50 * ratio * np.finfo(float).eps * np.abs(gj).max())
    assert worst < 50.0, f"|B^-1 B - I| reached {worst:.1f} times eps times the conditioning"


@pytest.mark.parametrize("bad", ["flat", "nan", "zero"])
def test_a_singular_rotation_block_is_reported(bad):
    rng = np.random.default_rng(3)
    inertia = {"flat": [1.0, 1.0, 1e-17], "nan": [1.0, np.nan, 1.0], "zero": [0.0, 0.0, 0.0]}[bad]
    B = _split_block(rng, np.array(inertia), 1.0, np.ones(3))
    out = np.zeros((6, 6))
    assert not _invert_split_into(B, out)


def test_mass_times_nu_and_the_gyroscopic_force_in_one_pass_match_them_apart(rotating):
    c = compiled(rotating)
    S = c.scene
    rng = np.random.default_rng(11)
    R, I = np.empty((3, 3)), np.empty((3, 3))
    for _ in range(100):
        q = _random_quaternions(rotating.start, rotating, rng)
        nu = rng.normal(size=S.nv) * 3.0
        mass_nu, gyro, want_m, want_g = (np.full(S.nv, np.nan) for _ in range(4))
        _mass_times_gyro_into(S.bi, S.bf, q, nu, mass_nu, gyro, R)
        _mass_times_into(S.bi, S.bf, q, nu, want_m, R, I)
        _gyroscopic_into(S.bi, S.bf, q, nu, want_g, R)
        np.testing.assert_allclose(mass_nu, want_m, rtol=1e-14, atol=1e-15 * np.abs(want_m).max())
        np.testing.assert_allclose(gyro, want_g, rtol=1e-13, atol=1e-14 * np.abs(want_g).max())


def _tumble(directory, w0, seconds, h):
    """The tumbler spun at w0 (world axes), rolled out dynamic-rigid with no gravity and no
    contact: (start state, end state, its world inertia at each)."""
    path = directory / f"tumble_{h:g}.toml"
    path.write_text(SCENE % ", ".join(f'"tumbler.w{axis}" = {w}' for axis, w in zip("xyz", w0)))
    scenario = load_scenario(path)
    rung = rung_for(scenario, "dynamic-rigid")
    start = rung.initial_state(scenario)
    end = rung.rollout(scenario, start, np.zeros((1, len(scenario.actuated))), [seconds], h, stop_at_outcome=False).state
    S = compiled(scenario).scene
    return start, end, [world_inertia(S.bi, S.bf, s.q, 0) for s in (start, end)]


def test_a_spin_about_a_principal_axis_is_steady(tmp_path):
    h, steps, w = 1e-3, 500, 4.0
    start, end, _ = _tumble(tmp_path, (0.0, 0.0, w), steps * h, h)
    np.testing.assert_allclose(end.nu[3:6], [0.0, 0.0, w], rtol=0, atol=1e-12)
    # each step turns the quaternion q <- (q + h/2 (0, w) q) / |.|: by 2 atan(h w / 2) about z
    angle = steps * 2.0 * np.arctan(h * w / 2.0)
    np.testing.assert_allclose(end.q[3:7], [np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)], rtol=0, atol=1e-11)


def test_a_torque_free_tumble_keeps_its_angular_momentum_and_energy_to_first_order(tmp_path):
    w0 = np.array([1.0, 3.0, 0.5])  # near the intermediate axis: the tumble turns its spin over
    drift = []
    for h in (2e-4, 1e-4):
        start, end, (I0, I1) = _tumble(tmp_path, w0, 1.0, h)
        L0, L1 = I0 @ start.nu[3:6], I1 @ end.nu[3:6]
        E0, E1 = start.nu[3:6] @ L0 / 2, end.nu[3:6] @ L1 / 2
        assert end.nu[3] < 0.0 < w0[0]  # it did tumble: the spin about x turned over
        drift.append(np.array([np.linalg.norm(L1 - L0) / np.linalg.norm(L0), abs(E1 - E0) / E0]))
        # the step is first order (the gyroscopic force explicit): 0.59 h and 0.20 h measured
        assert drift[-1][0] < 1.0 * h and drift[-1][1] < 0.5 * h, f"h = {h}: drift {drift[-1]}"
    ratio = drift[0] / drift[1]
    assert np.all((1.8 < ratio) & (ratio < 2.2)), f"halving h divided the drift by {ratio}, not 2"

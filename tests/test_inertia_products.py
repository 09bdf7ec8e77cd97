"""Products of inertia: a spatial body whose principal axes are not its own axes.

`inertia_products` (Ixy, Ixz, Iyz) with `inertia` as the tensor's diagonal give the full tensor
about the centre of mass in the body's axes (as URDF and MuJoCo's fullinertia give it). The
scene keeps its principal moments and axes (`models.scenario.principal_inertia`), and the
dynamics turn the body's rotation to its principal axes where it needs its inertia
(`models.stepper._principal_axes_into`). Held here: the world inertia to the tensor (a closed
form); a tumble with products to the same body given by its principal moments and turned onto
its principal axes (the same motion, the same ODE); angular momentum kept in a torque-free
tumble; a scene without products to the same bits as its tensor's principal form; bad tensors
refused with the key and the reason; MuJoCo's peer given the same tensor.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from models.kinematics import BF_TILTED
from models.rungs import compiled, rung_for
from models.scenario import ScenarioError, inertia_tensor, load_scenario, principal_inertia
from models.stepper import world_inertia
from planner.peers import build_spatial
from tests.conftest import DATA

SCENE = """
version = 1
[scenario]
name = "inertia_products"
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
inertia = {inertia}
{products}
shape = {{ type = "box", size = [0.4, 0.3, 0.2] }}
pose = {{ x = 0.0, y = 0.0, z = 1.0{pose} }}
dofs = ["x", "y", "z", "rotation"]
[task]
horizon = 1.0
goal = {{ box = {{ "tumbler.x" = [-1.0, 1.0] }} }}
velocity = {{ "tumbler.wx" = 1.0, "tumbler.wy" = 3.0, "tumbler.wz" = 0.5 }}
[ladder]
time_limit = 1.0
[[ladder.rungs]]
model = "dynamic-rigid"
h = 1e-3
"""

#: principal moments, and the rotation from the body's axes to its principal ones (its columns)
MOMENTS = np.array([0.05, 0.11, 0.14])


def _rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


AXES = _rotation(0.3, -0.5, 0.8)
TENSOR = AXES @ np.diag(MOMENTS) @ AXES.T


def _quaternion(R: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix (its trace is positive here)."""
    w = np.sqrt(1.0 + np.trace(R)) / 2.0
    return np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)])


def _scene(directory, name, inertia, products=None, quaternion=None):
    path = directory / f"{name}.toml"
    text = SCENE.format(
        inertia="[" + ", ".join(repr(float(v)) for v in inertia) + "]",
        products="" if products is None else "inertia_products = [" + ", ".join(repr(float(v)) for v in products) + "]",
        pose="" if quaternion is None else ", quaternion = [" + ", ".join(repr(float(v)) for v in quaternion) + "]",
    )
    path.write_text(text)
    return path


def _with_products(directory):
    return load_scenario(_scene(directory, "products", TENSOR.diagonal(), (TENSOR[0, 1], TENSOR[0, 2], TENSOR[1, 2])))


def _body_rotation(q):
    w, x, y, z = q[3:7] / np.linalg.norm(q[3:7])
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_the_tensor_and_its_principal_form(tmp_path):
    scenario = _with_products(tmp_path)
    body = scenario.spec.bodies[0]
    np.testing.assert_allclose(inertia_tensor(body), TENSOR, rtol=0, atol=1e-15)
    moments, axes = principal_inertia(body)
    np.testing.assert_allclose(moments, MOMENTS, rtol=1e-13)
    np.testing.assert_allclose(axes @ np.diag(moments) @ axes.T, TENSOR, rtol=0, atol=1e-15)
    assert np.linalg.det(axes) == pytest.approx(1.0, abs=1e-13)
    # no products: the moments as given, in their order, and no axes
    plain = load_scenario(_scene(tmp_path, "plain", [0.11, 0.05, 0.14]))
    moments, axes = principal_inertia(plain.spec.bodies[0])
    assert axes is None and list(moments) == [0.11, 0.05, 0.14]


def test_the_world_inertia_is_the_tensor_turned_with_the_body(tmp_path):
    scenario = _with_products(tmp_path)
    S = compiled(scenario).scene
    np.testing.assert_allclose(world_inertia(S.bi, S.bf, scenario.start, 0), TENSOR, rtol=0, atol=1e-15)
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = scenario.start.copy()
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
        R = _body_rotation(q)
        np.testing.assert_allclose(world_inertia(S.bi, S.bf, q, 0), R @ TENSOR @ R.T, rtol=0, atol=2e-15)


def _tumble(scenario, seconds, h):
    rung = rung_for(scenario, "dynamic-rigid")
    start = rung.initial_state(scenario)
    out = rung.rollout(scenario, start, np.zeros((1, 0)), [seconds], h, stop_at_outcome=False)
    assert out.status == "ok"
    return start, out


def test_a_tumble_with_products_is_the_principal_bodys_turned_onto_its_axes(tmp_path):
    """The body with products at rest orientation, and the body with its principal moments
    turned onto the same principal axes (pose: AXES), spun at the same world angular velocity
    near the intermediate axis: the same motion, world angular velocity and principal axes."""
    products = _with_products(tmp_path)
    principal = load_scenario(_scene(tmp_path, "principal", MOMENTS, quaternion=_quaternion(AXES)))
    h = 1e-3
    _, a = _tumble(products, 1.0, h)
    _, b = _tumble(principal, 1.0, h)
    assert a.steps == b.steps == 1000
    # it tumbled: the spin's world direction moved by more than half a radian (0.77 rad)
    w0 = np.array([1.0, 3.0, 0.5])
    assert np.arccos(a.state.nu[3:6] @ w0 / np.linalg.norm(a.state.nu[3:6]) / np.linalg.norm(w0)) > 0.5
    np.testing.assert_allclose(a.velocities[:, 3:6], b.velocities[:, 3:6], rtol=0, atol=1e-10)
    np.testing.assert_allclose(_body_rotation(a.state.q) @ AXES, _body_rotation(b.state.q), rtol=0, atol=1e-10)


def test_a_torque_free_tumble_with_products_keeps_its_angular_momentum_to_first_order(tmp_path):
    scenario = _with_products(tmp_path)
    S = compiled(scenario).scene
    drift = []
    for h in (2e-4, 1e-4):
        start, out = _tumble(scenario, 1.0, h)
        end = out.state
        L0 = world_inertia(S.bi, S.bf, start.q, 0) @ start.nu[3:6]
        L1 = world_inertia(S.bi, S.bf, end.q, 0) @ end.nu[3:6]
        drift.append(np.linalg.norm(L1 - L0) / np.linalg.norm(L0))
        # the step is first order (the gyroscopic force explicit): 1.25 h measured at h = 2e-4
        assert drift[-1] < 2.0 * h, f"h = {h}: angular momentum drift {drift[-1]}"
    assert 1.8 < drift[0] / drift[1] < 2.2, f"halving h divided the drift by {drift[0] / drift[1]}, not 2"


def test_zero_products_move_the_body_as_none(tmp_path):
    """A body without products is not tilted (BF_TILTED 0: the kernels take its rotation alone,
    as before products existed); zero products (axes found by eigh: the identity up to order and
    sign) move it the same way."""
    plain = load_scenario(_scene(tmp_path, "plain", MOMENTS))
    zero = load_scenario(_scene(tmp_path, "zero", MOMENTS, (0.0, 0.0, 0.0)))
    S = compiled(plain).scene
    assert S.bf[0, BF_TILTED] == 0.0
    _, a = _tumble(plain, 0.2, 1e-3)
    _, b = _tumble(zero, 0.2, 1e-3)
    # the zero tensor's eigenvectors are the axes up to order and sign: the same motion, to rounding
    np.testing.assert_allclose(a.state.nu, b.state.nu, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("inertia", "products", "key", "words"),
    [
        ([0.1, 0.1, 0.1], (0.2, 0.0, 0.0), "bodies[0].inertia_products", "not positive definite"),
        ([0.02, 0.1, 0.1], (0.0, 0.0, 0.09), "bodies[0].inertia_products", "more than the sum of the other two"),
        ([0.1, 0.1, 0.1], (1e7, 0.0, 0.0), "bodies[0].inertia_products", "at most 1e+06"),
    ],
)
def test_a_tensor_no_rigid_body_has_is_refused_naming_the_key(tmp_path, inertia, products, key, words):
    with pytest.raises(ScenarioError) as info:
        load_scenario(_scene(tmp_path, "bad", inertia, products))
    text = str(info.value)
    assert key in text and words in text, text


def test_products_in_the_plane_are_refused(tmp_path):
    path = tmp_path / "planar.toml"
    good = (DATA / "good" / "minimal_triangle.toml").read_text()
    path.write_text(good.replace('dofs = ["x"]', 'dofs = ["x"]\ninertia_products = [0.0, 0.0, 0.0]', 1))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert "bodies[1].inertia_products" in str(info.value), str(info.value)
    assert "a planar body has no products of inertia" in str(info.value)


def test_mujocos_peer_gets_the_same_tensor(tmp_path):

    scenario = _with_products(tmp_path)
    peer = build_spatial(scenario, 1e-3)
    body = mujoco.mj_name2id(peer.model, mujoco.mjtObj.mjOBJ_BODY, "tumbler")
    moments = np.array(peer.model.body_inertia[body])
    w, x, y, z = peer.model.body_iquat[body]
    frame = _body_rotation(np.array([0.0, 0.0, 0.0, w, x, y, z]))
    np.testing.assert_allclose(frame @ np.diag(moments) @ frame.T, TENSOR, rtol=0, atol=1e-9)

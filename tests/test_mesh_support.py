"""A fine mesh against a plane: its contacts are its deepest vertex and the corners of its
support polygon in `PLANE_SUPPORT_DIRECTIONS` directions (models.contact3d._plane_support),
not one per vertex within the margin.

Checked against closed forms: a 64-sided prism stands on an incline while its centre of mass
is over its support polygon and tips once it is not, at tan(slope) = R / (H / 2) (the corner
downhill is kept), carrying m g cos(slope) on every force rung; the kept corners reach at least
cos(pi / 8) of the polygon's in every direction; a 200-vertex pebble pushed under the
quasistatic rung solves LCPs of a bounded size (it had made LCPs of 1,560 rows and failed).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from models.kinematics import PLANE_SUPPORT_BAND, PLANE_SUPPORT_DIRECTIONS, compile_scene
from models.rungs import rung_for
from models.scenario import load_scenario
from tests.test_contact3d import contacts

KEPT = PLANE_SUPPORT_DIRECTIONS + 1
SIDES, RADIUS, HEIGHT, MASS = 64, 0.05, 0.2, 0.5
#: the slope at which the prism's centre of mass is over its downhill corner
TIP = math.degrees(math.atan(RADIUS / (HEIGHT / 2)))


def write_obj(path: Path, vertices, faces) -> None:
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices] + ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def prism_obj(path: Path) -> None:
    """A regular SIDES-gon prism about z, centred on its centre of mass, a corner along +x."""
    angles = 2 * math.pi * np.arange(SIDES) / SIDES
    ring = [(RADIUS * math.cos(a), RADIUS * math.sin(a)) for a in angles]
    vertices = [(x, y, -HEIGHT / 2) for x, y in ring] + [(x, y, HEIGHT / 2) for x, y in ring]
    sides = [[k, (k + 1) % SIDES, SIDES + (k + 1) % SIDES, SIDES + k] for k in range(SIDES)]
    write_obj(path, vertices, [list(range(SIDES))[::-1], list(range(SIDES, 2 * SIDES))] + sides)


def pebble_obj(path: Path, n: int = 200) -> None:
    """n points spread over an ellipsoid of semi-axes 0.06, 0.05, 0.03 (a Fibonacci lattice),
    their hull's triangles wound outward."""
    i = np.arange(n) + 0.5
    phi, theta = np.arccos(1 - 2 * i / n), math.pi * (1 + 5**0.5) * i
    P = np.c_[np.cos(theta) * np.sin(phi) * 0.06, np.sin(theta) * np.sin(phi) * 0.05, np.cos(phi) * 0.03]
    hull = ConvexHull(P)
    faces = []
    for s, eq in zip(hull.simplices, hull.equations):
        a, b, c = P[s]
        faces.append(list(s) if np.dot(np.cross(b - a, c - a), eq[:3]) > 0 else list(s[::-1]))
    write_obj(path, P, faces)


def incline_scene(directory: Path, slope_deg: float, yaw: float = 0.0) -> Path:
    """The prism standing on an incline rising along +x (mu = 2: it cannot slide)."""
    prism_obj(directory / "prism.obj")
    a = math.radians(slope_deg)
    text = f"""version = 1
[scenario]
name = "prism_incline"
[scene]
dimension = 3
gravity = [0.0, 0.0, -9.81]
[contact]
mu = 2.0
K = 1e6
C = 1e3
[[bodies]]
name = "incline"
role = "obstacle"
shape = {{ type = "plane", normal = [{-math.sin(a)!r}, 0.0, {math.cos(a)!r}], offset = 0.0 }}
[[bodies]]
name = "prism"
role = "object"
mass = {MASS}
inertia = [{MASS * (3 * RADIUS**2 + HEIGHT**2) / 12!r}, {MASS * (3 * RADIUS**2 + HEIGHT**2) / 12!r}, {MASS * RADIUS**2 / 2!r}]
shape = {{ type = "mesh", file = "prism.obj" }}
pose = {{ x = {-math.sin(a) * HEIGHT / 2!r}, y = 0.0, z = {math.cos(a) * HEIGHT / 2!r}, rpy = [0.0, {-a!r}, {yaw!r}] }}
dofs = ["x", "y", "z", "rotation"]
[task]
horizon = 1.0
goal = {{ box = {{ "prism.z" = [10.0, 11.0] }} }}
[ladder]
time_limit = 1.0
[[ladder.rungs]]
model = "dynamic-rigid"
h = 1e-3
"""
    path = directory / f"incline_{slope_deg:.3f}_{yaw:.3f}.toml"
    path.write_text(text)
    return path


def settle(path: Path, rung_name: str, duration: float, h: float):
    scenario = load_scenario(path)
    rung = rung_for(scenario, rung_name)
    result = rung.rollout(scenario, rung.initial_state(scenario), np.zeros((1, 0)), [duration], h)
    return scenario, result


def tilt(scenario, q) -> float:
    """The angle (rad) between the prism's axis and the incline's normal."""
    X = scenario.placements(q)["prism"]
    n = np.asarray(scenario.geometries["incline"].normal, float)
    return math.acos(min(1.0, float(X.rotation[:, 2] @ n)))


# ----------------------------------------------------------------------------- the contact set


@pytest.mark.parametrize("yaw", [0.0, 0.3, 1.1])
def test_a_flat_face_keeps_its_support_polygon(tmp_path, yaw):
    """Standing flat: at most KEPT contacts, each a bottom corner exactly on the plane, whose
    polygon reaches at least cos(pi / directions) of the 64-gon's in every direction."""
    path = incline_scene(tmp_path, 0.0, yaw)
    scenario = load_scenario(path)
    S = compile_scene(scenario)
    assert S.pair_max_contacts[0] == KEPT
    k, psi, n, pa, pb = contacts(_Scene(scenario, S), scenario.start, 0, margin=1e-3)
    assert 3 <= k <= KEPT
    np.testing.assert_allclose(psi, 0.0, atol=1e-15)
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, 1.0], (k, 1)))
    r = np.hypot(pb[:, 0], pb[:, 1])
    np.testing.assert_allclose(r, RADIUS, rtol=1e-12)  # corners of the face
    corner = np.round((np.arctan2(pb[:, 1], pb[:, 0]) - yaw) / (2 * math.pi / SIDES), 9)
    np.testing.assert_allclose(corner, np.round(corner), atol=1e-9)
    assert len(set(np.round(corner) % SIDES)) == k  # distinct
    for a in np.linspace(0, 2 * math.pi, 721):
        d = np.array([math.cos(a), math.sin(a)])
        assert np.max(pb[:, :2] @ d) >= RADIUS * math.cos(math.pi / PLANE_SUPPORT_DIRECTIONS) - 1e-12


def test_a_tilted_face_keeps_its_deepest_corner_and_no_corner_beyond_the_band(tmp_path):
    """Tilted by 0.01 rad about y: the face's corners span 1 mm of height; the deepest is kept
    and every kept corner is within PLANE_SUPPORT_BAND of it; a wide margin takes in every
    bottom corner but still yields at most KEPT contacts."""
    path = incline_scene(tmp_path, 0.0)
    scenario = load_scenario(path)
    S = compile_scene(scenario)
    q = scenario.start.copy()
    names = list(scenario.coordinates)
    w = 0.005  # quaternion of 0.01 rad about y
    q[names.index("prism.qw")], q[names.index("prism.qy")] = math.cos(w), math.sin(w)
    q[names.index("prism.z")] += 0.01
    k, psi, n, pa, pb = contacts(_Scene(scenario, S), q, 0, margin=1.0)
    assert k <= KEPT
    corners = 2 * math.pi * np.arange(SIDES) / SIDES
    heights = q[names.index("prism.z")] - HEIGHT / 2 * math.cos(2 * w) - RADIUS * math.sin(2 * w) * np.cos(corners)
    assert psi.min() == pytest.approx(heights.min(), abs=1e-12)
    assert psi.max() <= heights.min() + PLANE_SUPPORT_BAND + 1e-12


class _Scene:
    """What tests.test_contact3d.contacts reads of a scene."""

    def __init__(self, scenario, S):
        self.sc, self.S = scenario, S


# ----------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize("rung_name", ["quasistatic-rigid", "quasistatic-compliant", "dynamic-rigid", "dynamic-compliant"])
def test_the_prism_stands_below_the_tipping_slope(tmp_path, rung_name):
    """At 0.95 of the tipping slope the prism stands: no tilt, and the incline carries
    m g cos(slope)."""
    slope = math.degrees(math.atan(0.95 * math.tan(math.radians(TIP))))
    scenario, result = settle(incline_scene(tmp_path, slope), rung_name, 0.3, 1e-3)
    assert result.status == "ok", result.message
    assert tilt(scenario, result.state.q) < 1e-3
    assert result.pair_force.sum() == pytest.approx(MASS * 9.81 * math.cos(math.radians(slope)), rel=1e-3)
    assert result.max_lcp_size <= KEPT * (2 + 4)  # four friction directions by default


@pytest.mark.parametrize("rung_name", ["quasistatic-rigid", "quasistatic-compliant"])
def test_a_step_that_leaves_a_contact_closing_fails(tmp_path, rung_name):
    """At h = 1e-2 and the quasistatic inertia of 1e-6, the LCP's velocities are its round-off
    times h F / 1e-6: a relative residual of 6.5e-10 left the prism's support closing at
    0.08 m/s, and it went 8 km through the incline in 0.3 s with status ok. Such a step now
    fails (models.stepper.CLOSING_TOL) with the prism where it stood; at an inertia of 1e-2
    the same steps stand."""
    slope = math.degrees(math.atan(0.95 * math.tan(math.radians(TIP))))
    path = incline_scene(tmp_path, slope)
    scenario, result = settle(path, rung_name, 0.3, 1e-2)
    assert result.status == "lcp_failed"
    assert "leaves a contact closing" in result.message and "larger inertia" in result.message
    np.testing.assert_allclose(result.state.q, scenario.start, atol=1e-5)
    rung = f'[[ladder.rungs]]\nmodel = "{rung_name}"\nh = 1e-2\ninertia = 1e-2\n'
    path.write_text(path.read_text().replace("[[ladder.rungs]]\n", rung + "[[ladder.rungs]]\n", 1))
    scenario, result = settle(path, rung_name, 0.3, 1e-2)
    assert result.status == "ok", result.message
    assert tilt(scenario, result.state.q) < 1e-3


def test_a_rungs_own_regularization_is_a_compliance_the_closing_check_allows(tmp_path):
    """A rung's `regularization` r adds r of the largest normal diagonal to each rigid normal
    row: a compliance it asks for. A sphere resting under quasistatic-rigid (inertia eps, step
    h) then settles where psi / h + reg m g h = 0, reg = r / (eps m): psi = -r g h^2 / eps,
    0.98 mm at the largest r, 1e-3, with h = 0.1 and eps = 1e-2: a row short of
    psi + h W_n^T nu+ = 0 by that much each step. The closing check reads the row with reg p_n in it (box_rotate_3d's pushes had failed
    at 3e-6 m short, its search's plans changed)."""
    r, h, eps, mass, radius, g = 1e-3, 0.1, 1e-2, 0.5, 0.05, 9.81
    (tmp_path / "rest.toml").write_text(
        f"""version = 1
[scenario]
name = "regularized_rest"
[scene]
dimension = 3
gravity = [0.0, 0.0, -{g}]
[contact]
mu = 0.5
K = 1e6
C = 1e3
[[bodies]]
name = "table"
role = "obstacle"
shape = {{ type = "plane", normal = [0.0, 0.0, 1.0], offset = 0.0 }}
[[bodies]]
name = "ball"
role = "object"
mass = {mass}
shape = {{ type = "sphere", radius = {radius} }}
pose = {{ x = 0.0, y = 0.0, z = {radius} }}
dofs = ["z"]
[task]
horizon = 2.0
goal = {{ box = {{ "ball.z" = [1.0, 2.0] }} }}
[ladder]
time_limit = 1.0
control_period = 0.1
[[ladder.rungs]]
model = "quasistatic-rigid"
h = {h}
inertia = {eps}
regularization = {r}
"""
    )
    scenario = load_scenario(tmp_path / "rest.toml")
    rung = rung_for(scenario, "quasistatic-rigid")
    result = rung.rollout(scenario, rung.initial_state(scenario), np.zeros((1, 0)), [2.0], h)
    assert result.status == "ok", result.message
    z = scenario.coordinates.index("ball.z")
    assert result.state.q[z] - radius == pytest.approx(-r * g * h**2 / eps, rel=1e-9)
    assert result.pair_force.sum() == pytest.approx(mass * g, rel=1e-9)


def test_the_prism_tips_past_the_tipping_slope(tmp_path):
    """At 1.05 of the tipping slope the prism's centre of mass is past its downhill corner: it
    tips over (dynamic-rigid); at 0.95 it does not move at all."""
    steep = math.degrees(math.atan(1.05 * math.tan(math.radians(TIP))))
    scenario, result = settle(incline_scene(tmp_path, steep), "dynamic-rigid", 0.5, 1e-3)
    assert result.status == "ok", result.message
    assert tilt(scenario, result.state.q) > 0.2
    shallow = math.degrees(math.atan(0.95 * math.tan(math.radians(TIP))))
    scenario, result = settle(incline_scene(tmp_path, shallow), "dynamic-rigid", 0.5, 1e-3)
    np.testing.assert_allclose(result.state.q, scenario.start, atol=1e-9)


def test_a_pebble_pushed_under_the_quasistatic_rung(tmp_path):
    """A 200-vertex pebble pushed along a table by a sphere under quasistatic-rigid at
    h = 0.1: the margin (1 mm plus what a step can close, 4 cm here) takes in half its
    vertices, which had made LCPs of 1,560 rows and failed; it is now pushed along."""
    pebble_obj(tmp_path / "pebble.obj")
    (tmp_path / "push.toml").write_text(
        """version = 1
[scenario]
name = "pebble_push"
[scene]
dimension = 3
gravity = [0.0, 0.0, -9.81]
[contact]
mu = 0.4
K = 1e6
C = 1e3
[[contact.pairs]]
bodies = ["pusher", "table"]
enabled = false
[[bodies]]
name = "table"
role = "obstacle"
shape = { type = "plane", normal = [0.0, 0.0, 1.0], offset = 0.0 }
[[bodies]]
name = "pebble"
role = "object"
mass = 0.4
inertia = [3.4e-4, 4.6e-4, 5.0e-4]
shape = { type = "mesh", file = "pebble.obj" }
pose = { x = 0.0, y = 0.0, z = 0.03 }
dofs = ["x", "y", "z", "rotation"]
[[bodies]]
name = "pusher"
role = "robot"
mass = 0.2
shape = { type = "sphere", radius = 0.02 }
pose = { x = -0.085, y = 0.0, z = 0.02 }
dofs = ["x", "y"]
actuators.x = { kp = 1e4, kd = 1e2, max_speed = 0.5 }
actuators.y = { kp = 1e4, kd = 1e2, max_speed = 0.5 }
[task]
horizon = 3.0
goal = { box = { "pebble.x" = [5.0, 6.0] } }
[ladder]
time_limit = 1.0
control_period = 0.1
[[ladder.rungs]]
model = "quasistatic-rigid"
h = 0.1
inertia = 1.0
friction_directions = 8
"""
    )
    scenario = load_scenario(tmp_path / "push.toml")
    rung = rung_for(scenario, "quasistatic-rigid")
    x = scenario.coordinates.index("pebble.x")
    result = rung.rollout(scenario, rung.initial_state(scenario), np.array([[0.2, 0.0]]), [1.6], 0.1)
    assert result.status == "ok", result.message
    assert result.max_lcp_size <= (KEPT + 1) * (2 + 8) + 4  # the pebble on the table and the pusher
    # the pusher travels 0.315 m past first touch; the pebble, not symmetric about the push,
    # turns as it goes (53 degrees of yaw), so the pusher slides along it and it lags a little
    assert 0.25 < result.state.q[x] < 0.2 * 1.6 - 0.005 + 1e-3
    assert result.min_psi > -1e-3  # on the table, not through it

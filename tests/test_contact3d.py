"""Compiled spatial contacts (models.contact3d) against the python-fcl reference, exact
certificates and closed forms.

Every contact must satisfy the convention exactly: |n| = 1, pb - pa = psi n, pa on A's
surface, pb on B's surface. For a pair's smallest psi two bounds pin it to the signed
distance: psi is at most the reference (fcl's distance is an upper bound when apart; its
penetration depth is good to ~1e-6), and the separation of the two shapes' support functions
along the contact's normal, a lower bound of the signed distance for any direction, equals
psi. Near-touching poses are checked against the distance they were built at, never handed
to fcl (python-fcl 0.7 aborts the process on some of them).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from models import geometry as geo
from models.contact3d import (
    _pose,
    collide_all_3d,
    collide_pair_3d,
    fcl_pair_contacts,
    tangent_basis,
)
from models.kinematics import SHAPE_HALFSPACE, SHAPE_MESH, body_pose_3d, compile_scene
from models.scenario import load_scenario
from tests.conftest import DATA

# ----------------------------------------------------------------------------- scenes

WEDGE = """\
v -0.1 -0.15 0.0
v  0.1 -0.15 0.0
v -0.1 -0.15 0.15
v -0.1  0.15 0.0
v  0.1  0.15 0.0
v -0.1  0.15 0.15
f 1 3 2
f 4 5 6
f 1 2 5 4
f 2 3 6 5
f 1 4 6 3
"""

FREE = 'role = "object"\nmass = 1.0\ninertia = [0.01, 0.01, 0.01]\ndofs = ["x", "y", "z", "rotation"]'
YAW = 'role = "object"\nmass = 1.0\ninertia = [0.01, 0.01, 0.01]\ndofs = ["x", "y", "z", "yaw"]'
FIXED = 'role = "obstacle"'

#: (name, shape, kind of body) in file order; free bodies start far apart, above plane1.
BODIES = [
    ("plane1", '{ type = "plane", normal = [0.1, -0.2, 1.0], offset = -0.3 }', FIXED),
    ("sph", '{ type = "sphere", radius = 0.15 }', FREE),
    ("cap", '{ type = "capsule", radius = 0.1, length = 0.5 }', FREE),
    ("box", '{ type = "box", size = [0.4, 0.3, 0.2] }', FREE),
    ("mesh", '{ type = "mesh", file = "wedge.obj", scale = 1.5 }', FREE),
    ("sph2", '{ type = "sphere", radius = 0.07 }', FREE),
    ("cap2", '{ type = "capsule", radius = 0.05, length = 0.3 }', FREE),
    ("box2", '{ type = "box", size = [0.25, 0.5, 0.15] }', FREE),
    ("ycap", '{ type = "capsule", radius = 0.04, length = 0.6 }', YAW),
    ("wall", '{ type = "box", size = [0.3, 0.1, 0.4] }', FIXED),
    ("plane2", '{ type = "plane", normal = [0.0, 0.3, -1.0], offset = -30.0 }', FIXED),
]


def write_scene(directory: Path, bodies, name="contacts") -> Path:
    """A scenario with the given (name, shape, kind) bodies, free ones apart at z = 5."""
    (directory / "wedge.obj").write_text(WEDGE)
    lines = [
        "version = 1",
        "[scenario]",
        f'name = "{name}"',
        "[scene]",
        "dimension = 3",
        "gravity = [0.0, 0.0, -9.81]",
        "[contact]",
        "mu = 0.5",
        "K = 1e6",
        "C = 1e3",
    ]
    for i, (body, shape, kind) in enumerate(bodies):
        lines += ["[[bodies]]", f'name = "{body}"', kind, f"shape = {shape}"]
        if body == "wall":
            lines.append("pose = { x = 40.0, y = 0.0, z = 5.0, rpy = [0.3, -0.2, 0.5] }")
        elif kind != FIXED:
            lines.append(f"pose = {{ x = {2.0 * i}, y = 0.0, z = 5.0 }}")
    lines += [
        "[task]",
        "horizon = 1.0",
        f'goal = {{ box = {{ "{next(b for b, _, k in bodies if k != FIXED)}.x" = [0.0, 1.0] }} }}',
        "[ladder]",
        "time_limit = 1.0",
        "[[ladder.rungs]]",
        'model = "kinematic"',
        "h = 1e-2",
    ]
    path = directory / f"{name}.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


class Scene:
    """A loaded scenario, its arrays, and helpers to pose bodies in q."""

    def __init__(self, path: Path):
        self.sc = load_scenario(path)
        self.S = compile_scene(self.sc)
        self.names = [b.name for b in self.sc.spec.bodies]
        self.index = {n: i for i, n in enumerate(self.sc.coordinates)}

    def pair(self, a: str, b: str) -> int:
        for p, (i, j) in enumerate(zip(self.S.pair_a, self.S.pair_b)):
            if (self.names[i], self.names[j]) == (a, b):
                return p
        raise KeyError((a, b))

    def pairs(self):
        """(p, name A, name B) of every pair."""
        return [(p, self.names[i], self.names[j]) for p, (i, j) in enumerate(zip(self.S.pair_a, self.S.pair_b))]

    def movable(self, name: str) -> bool:
        return f"{name}.x" in self.index

    def place(self, q, name, pos, quat=None):
        """Put body `name` at pos with orientation quat (yaw bodies take the yaw of quat)."""
        for k, c in enumerate("xyz"):
            q[self.index[f"{name}.{c}"]] = pos[k]
        if quat is None:
            return
        if f"{name}.qw" in self.index:
            for k, c in enumerate("wxyz"):
                q[self.index[f"{name}.q{c}"]] = quat[k]
        elif f"{name}.yaw" in self.index:
            R = geo.quaternion_matrix(quat)
            q[self.index[f"{name}.yaw"]] = math.atan2(R[1, 0], R[0, 0])

    def position(self, q, name):
        return self.sc.placements(q)[name].translation.copy()

    def geometry(self, name):
        return self.sc.geometries[name]


def contacts(scene: Scene, q, p, margin=np.inf, cap=16):
    psi = np.full(cap, np.nan)
    n, pa, pb = (np.full((cap, 3), np.nan) for _ in range(3))
    k = collide_pair_3d(scene.S, q, p, margin, psi, n, pa, pb, 0)
    return k, psi[: max(k, 0)], n[: max(k, 0)], pa[: max(k, 0)], pb[: max(k, 0)]


# ----------------------------------------------------------------------------- independent checks


def surface_distance(g: geo.Geometry, X: geo.Placement, x: np.ndarray) -> float:
    """Signed distance of world point x to the shape's surface (mesh: largest face-plane value,
    zero exactly on the surface)."""
    if g.kind == "halfspace":
        n, off = geo._halfspace_world(g, X)
        return float(n @ x - off)
    y = X.rotation.T @ (x - X.translation)
    kind = g.fcl_args[0]
    if kind == "sphere":
        return float(np.linalg.norm(y - g.core[0]) - g.radius)
    if kind == "capsule":
        return geo._point_segment_distance(y, g.core[0], g.core[1]) - g.radius
    if kind == "box":
        h = np.array(g.fcl_args[1:]) / 2
        c = np.clip(y, -h, h)
        if np.any(c != y):
            return float(np.linalg.norm(y - c))
        return -float(np.min(h - np.abs(y)))
    v, faces = g.fcl_args[1], g.fcl_args[2]
    centre = v.mean(axis=0)
    best = -np.inf
    for f in faces:
        a, b, c = v[f[0]], v[f[1]], v[f[2]]
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        if n @ (centre - a) > 0:
            n = -n
        best = max(best, float(n @ (y - a)))
    return best


def support_separation(scene: Scene, q, p, n) -> float:
    """min over B of n.x minus max over A of n.x: a lower bound of the signed distance."""
    X = scene.sc.placements(q)
    value = 0.0
    for body, sign in ((scene.S.pair_a[p], 1.0), (scene.S.pair_b[p], -1.0)):
        name = scene.names[body]
        g = scene.geometry(name)
        u = sign * np.asarray(n)
        if g.kind == "halfspace":
            nh, off = geo._halfspace_world(g, X[name])
            assert np.allclose(u, nh, atol=1e-12), "a plane's contact normal is the plane's"
            support = off
        else:
            support = float(np.max((g.core @ X[name].rotation.T + X[name].translation) @ u)) + g.radius
        value -= support
    return value


def reference(scene: Scene, q, p) -> float:
    a, b = scene.names[scene.S.pair_a[p]], scene.names[scene.S.pair_b[p]]
    X = scene.sc.placements(q)
    return geo.signed_distance(scene.geometry(a), X[a], scene.geometry(b), X[b])


def check_contacts(scene: Scene, q, p, tol=1e-9):
    """Every contact follows the convention; returns (k, psi, n, pa, pb)."""
    k, psi, n, pa, pb = contacts(scene, q, p)
    a, b = scene.names[scene.S.pair_a[p]], scene.names[scene.S.pair_b[p]]
    assert 1 <= k <= scene.S.pair_max_contacts[p], (a, b, k)
    X = scene.sc.placements(q)
    for i in range(k):
        assert abs(np.linalg.norm(n[i]) - 1.0) < 1e-12
        assert np.abs(pb[i] - pa[i] - psi[i] * n[i]).max() < tol, (a, b, i)
        assert abs(surface_distance(scene.geometry(a), X[a], pa[i])) < tol, (a, b, i, "pa off A's surface")
        assert abs(surface_distance(scene.geometry(b), X[b], pb[i])) < tol, (a, b, i, "pb off B's surface")
    # a contact as deep as the deepest whose normal certifies it: the support functions
    # along n are separated by exactly psi (to rounding, which the normal of a corner a
    # nanometre from an edge amplifies)
    low = psi.min()
    cert_tol = 1e-9 if abs(low) > 1e-6 else 1e-7
    gaps = [abs(support_separation(scene, q, p, n[i]) - psi[i]) for i in range(k) if psi[i] <= low + 1e-9]
    assert min(gaps) < cert_tol, (a, b, "no contact certifies the smallest psi", min(gaps))
    return k, psi, n, pa, pb


# ----------------------------------------------------------------------------- random poses


def random_quat(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def small_rotation(rng, max_angle):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(0.0, max_angle) if rng.uniform() < 0.8 else 0.0
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])


def _matrix_quat(R):
    from models.kinematics import _rotation_to_quat

    return _rotation_to_quat(R)


def random_pose(scene: Scene, p, rng, aligned=False):
    """q with the pair's bodies near each other: random, or aligned (faces and axes nearly
    parallel: a random one of the 24 axis permutations of A's frame, a small tilt, offset
    along one of A's axes so the faces meet)."""
    S = scene.S
    a, b = scene.names[S.pair_a[p]], scene.names[S.pair_b[p]]
    q = np.array(scene.sc.start, float)
    if S.kind[S.pair_a[p]] == SHAPE_HALFSPACE or S.kind[S.pair_b[p]] == SHAPE_HALFSPACE:
        plane, body = (a, b) if S.kind[S.pair_a[p]] == SHAPE_HALFSPACE else (b, a)
        X = scene.sc.placements(q)[plane]
        nh, off = geo._halfspace_world(scene.geometry(plane), X)
        quat = random_quat(rng)
        if aligned:
            # a body axis along the plane normal, then a small tilt
            R = geo.quaternion_matrix(quat)
            k = rng.integers(3)
            axis = np.cross(R[:, k], nh)
            angle = math.atan2(np.linalg.norm(axis), R[:, k] @ nh)
            if np.linalg.norm(axis) > 1e-12:
                axis /= np.linalg.norm(axis)
                turn = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])
                quat = quat_mul(small_rotation(rng, 2e-2), quat_mul(turn, quat))
        scene.place(q, body, np.zeros(3), quat)
        R = scene.sc.placements(q)[body].rotation
        g = scene.geometry(body)
        lowest = -np.min(g.core @ (R.T @ nh)) + g.radius  # centre height when touching
        spread = 0.03 if aligned else 1.2 * S.bound_radius[scene.names.index(body)]
        height = off + lowest + rng.uniform(-spread, 0.7 * spread)
        tangent = rng.uniform(-1, 1, 3)
        scene.place(q, body, nh * height + tangent - nh * (tangent @ nh))
        return q
    # the moving body goes next to the other (a fixed obstacle stays where it is)
    first, second = (a, b) if scene.movable(b) else (b, a)
    if scene.movable(first):
        scene.place(q, first, rng.uniform(-1, 1, 3), random_quat(rng))
    Xf = scene.sc.placements(q)[first]
    if aligned:
        turn = [
            np.array([1.0, 0, 0, 0]),
            np.array([math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)]),
            np.array([math.cos(math.pi / 8), math.sin(math.pi / 8), 0, 0]),
        ][rng.integers(3)]
        quat_f = _matrix_quat(Xf.rotation)
        quat = quat_mul(small_rotation(rng, 2e-2), quat_mul(quat_f, quat_mul(turn, small_rotation(rng, 2e-2))))
    else:
        quat = random_quat(rng)
    scene.place(q, second, Xf.translation, quat)
    Xs = scene.sc.placements(q)[second]
    gf, gs = scene.geometry(first), scene.geometry(second)
    if aligned:
        ext_f = np.max(np.abs(gf.core), axis=0) + gf.radius
        ext_s = np.max(np.abs(gs.core @ Xs.rotation.T @ Xf.rotation), axis=0) + gs.radius
        offset = rng.uniform(-0.8, 0.8, 3) * (ext_f + ext_s)
        k = rng.integers(3)
        offset[k] = rng.choice([-1.0, 1.0]) * (ext_f[k] + ext_s[k] + rng.uniform(-0.03, 0.01))
        pos = Xf.translation + Xf.rotation @ offset
    else:
        d = rng.normal(size=3)
        reach = S.bound_radius[scene.names.index(first)] + S.bound_radius[scene.names.index(second)]
        pos = Xf.translation + d / np.linalg.norm(d) * rng.uniform(0.0, 1.1) * reach
    scene.place(q, second, pos)
    return q


def moved_to(scene: Scene, q, p, eps):
    """q with the pair's mover translated along the deepest contact's normal so that the
    signed distance becomes eps (exact when the pair is apart and eps >= 0, or penetrating)."""
    k, psi, n, pa, pb = contacts(scene, q, p)
    i = int(np.argmin(psi))
    a, b = scene.names[scene.S.pair_a[p]], scene.names[scene.S.pair_b[p]]
    q = q.copy()
    if scene.movable(b):
        scene.place(q, b, scene.position(q, b) + (eps - psi[i]) * n[i])
    else:
        scene.place(q, a, scene.position(q, a) - (eps - psi[i]) * n[i])
    return q


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    directory = tmp_path_factory.mktemp("contact3d")
    forward = Scene(write_scene(directory, BODIES, "forward"))
    backward = Scene(write_scene(directory, BODIES[::-1], "backward"))
    return forward, backward


def compiled_pairs(scene: Scene):
    """Pairs held to python-fcl here: all but meshes against non-planes (fcl is not tight enough
    for those; tests/test_contact3d_mesh.py checks them against a plain-numpy reference)."""
    S = scene.S
    return [
        (p, a, b)
        for p, a, b in scene.pairs()
        if not (
            SHAPE_MESH in (S.kind[S.pair_a[p]], S.kind[S.pair_b[p]]) and SHAPE_HALFSPACE not in (S.kind[S.pair_a[p]], S.kind[S.pair_b[p]])
        )
    ]


CURVED = ("sph", "cap", "sph2", "cap2", "ycap")
#: fcl's penetration depth (EPA) is good to about 1e-6; seen up to 2.2e-6 on capsule-box.
PENETRATION_TOL = 5e-6


# ----------------------------------------------------------------------------- against the reference


@pytest.mark.parametrize("order", [0, 1], ids=["forward", "backward"])
def test_every_compiled_pair_matches_the_reference(scenes, order):
    """Random, aligned (parallel faces and axes) and near-touching poses of every pair kind."""
    scene = scenes[order]
    rng = np.random.default_rng(1234 + order)
    tested = set()
    for p, a, b in compiled_pairs(scene):
        for trial in range(60):
            q = random_pose(scene, p, rng, aligned=trial % 2 == 1)
            k, psi, n, pa, pb = check_contacts(scene, q, p)
            ref = reference(scene, q, p)
            low = psi.min()
            if ref <= 0.0 or (a not in CURVED and b not in CURVED):
                assert abs(low - ref) < PENETRATION_TOL, (a, b, low, ref)
            else:
                # fcl's GJK distance between curved shapes is an upper bound, seen up to 3e-4
                # high (the certificate in check_contacts bounds psi from below exactly)
                assert ref - 1e-3 <= low <= ref + 1e-9, (a, b, low, ref)
            if trial % 3 == 0:
                # touching and slightly penetrating or apart, along the contact normal
                eps = rng.choice([0.0, 1e-9, -1e-9, -1e-5]) if low <= 0 else rng.choice([0.0, 1e-9, 1e-5])
                qt = moved_to(scene, q, p, eps)
                k, psi, n, pa, pb = check_contacts(scene, qt, p)
                assert abs(psi.min() - eps) < 1e-11, (a, b, psi.min(), eps)
        tested.add(tuple(sorted((kind_name(scene.geometry(a)), kind_name(scene.geometry(b))))))
    assert len(tested) == 10  # plane x 4 shapes, and the 6 pairs of sphere, capsule, box


def kind_name(g: geo.Geometry) -> str:
    return "plane" if g.kind == "halfspace" else g.fcl_args[0]


def test_pair_order_only_flips_the_contacts(scenes):
    forward, backward = scenes
    rng = np.random.default_rng(7)
    for p, a, b in compiled_pairs(forward):
        r = backward.pair(b, a)
        for trial in range(10):
            q = random_pose(forward, p, rng, aligned=trial % 2 == 1)
            qb = np.array(backward.sc.start, float)
            for i, name in enumerate(backward.sc.coordinates):
                qb[i] = q[forward.index[name]]
            k1, psi1, n1, pa1, pb1 = contacts(forward, q, p)
            k2, psi2, n2, pa2, pb2 = contacts(backward, qb, r)
            assert abs(psi1.min() - psi2.min()) < 1e-12, (a, b)
            if k1 == 1 and k2 == 1:
                np.testing.assert_allclose(n2, -n1, atol=1e-12)
                np.testing.assert_allclose(pa2, pb1, atol=1e-12)
                np.testing.assert_allclose(pb2, pa1, atol=1e-12)


# ----------------------------------------------------------------------------- closed forms


def at(scene: Scene, **bodies):
    """q with the given bodies at (position, quaternion) and the others where they start."""
    q = np.array(scene.sc.start, float)
    for name, (pos, quat) in bodies.items():
        scene.place(q, name, np.asarray(pos, float), None if quat is None else np.asarray(quat, float))
    return q


def yaw_quat(angle):
    return [math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)]


@pytest.fixture(scope="module")
def flat(tmp_path_factory):
    """A horizontal floor (first and last in the file) and free shapes."""
    directory = tmp_path_factory.mktemp("flat")
    floor = '{ type = "plane", normal = [0.0, 0.0, 1.0], offset = 0.0 }'
    ceiling = '{ type = "plane", normal = [0.0, 0.0, -1.0], offset = -50.0 }'
    bodies = [("floor", floor, FIXED)] + [b for b in BODIES if b[2] == FREE] + [("ceiling", ceiling, FIXED)]
    return Scene(write_scene(directory, bodies, "flat"))


@pytest.mark.parametrize("yaw", [0.0, 0.7])
def test_box_resting_on_a_plane_touches_at_its_four_bottom_corners(flat, yaw):
    q = at(flat, box=([0.3, -0.2, 0.1], yaw_quat(yaw)))
    p = flat.pair("floor", "box")
    k, psi, n, pa, pb = contacts(flat, q, p, margin=1e-3)
    assert k == 4
    np.testing.assert_allclose(psi, 0.0, atol=1e-15)
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, 1.0], (4, 1)))
    c, s = math.cos(yaw), math.sin(yaw)
    corners = {(round(0.3 + c * x - s * y, 12), round(-0.2 + s * x + c * y, 12), 0.0) for x in (-0.2, 0.2) for y in (-0.15, 0.15)}
    assert {tuple(np.round(v, 12) + 0.0) for v in pb} == corners
    np.testing.assert_allclose(pa, pb, atol=1e-15)
    # a plane as B, with a margin that takes in every corner
    k, psi, n, pa, pb = contacts(flat, q, flat.pair("box", "ceiling"), margin=100.0)
    assert k == 8
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, 1.0], (8, 1)))
    np.testing.assert_allclose(np.sort(psi), [49.8] * 4 + [50.0] * 4, atol=1e-12)


def test_capsule_lying_on_a_plane_touches_at_both_ends(flat):
    q = at(flat, cap=([0.0, 0.0, 0.1], yaw_quat(0.3)))
    k, psi, n, pa, pb = contacts(flat, q, flat.pair("floor", "cap"), margin=1e-6)
    assert k == 2
    np.testing.assert_allclose(psi, 0.0, atol=1e-15)
    ends = np.array([[math.cos(0.3), math.sin(0.3), 0.0], [-math.cos(0.3), -math.sin(0.3), 0.0]]) * 0.25
    np.testing.assert_allclose(np.sort(pb, axis=0), np.sort(ends, axis=0), atol=1e-15)


def test_tilted_capsule_far_end_is_on_its_surface(flat):
    tilt = 0.01
    q = at(flat, cap=([0.0, 0.0, 0.1 + 0.25 * math.sin(tilt)], [math.cos(tilt / 2), 0.0, -math.sin(tilt / 2), 0.0]))
    k, psi, n, pa, pb = check_contacts(flat, q, flat.pair("floor", "cap"))
    assert k == 2
    assert min(psi) == pytest.approx(0.0, abs=1e-12)
    # the raised end: its axis point is 0.5 sin(tilt) higher; the surface below it a bit lower than r
    assert max(psi) == pytest.approx(0.5 * math.sin(tilt) + 0.1 - 0.1 / math.cos(tilt), abs=1e-12)


@pytest.mark.parametrize("gap", [0.0, 0.01, -0.005])
def test_box_on_a_box_face_to_face_touches_at_the_overlap_corners(flat, gap):
    # box: half extents (0.2, 0.15, 0.1); box2: (0.125, 0.25, 0.075) shifted by (0.1, 0.05)
    q = at(flat, box=([0.0, 0.0, 1.0], [1.0, 0, 0, 0]), box2=([0.1, 0.05, 1.0 + 0.175 + gap], [1.0, 0, 0, 0]))
    p = flat.pair("box", "box2")
    k, psi, n, pa, pb = check_contacts(flat, q, p)
    assert k == 4
    np.testing.assert_allclose(psi, gap, atol=1e-14)
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-14)
    overlap = {(x, y) for x in (-0.025, 0.2) for y in (-0.15, 0.15)}
    assert {(round(v[0], 12), round(v[1], 12)) for v in pa} == overlap
    np.testing.assert_allclose(pa[:, 2], 1.1, atol=1e-14)


def test_box_on_a_turned_box_keeps_four_spread_contacts(flat):
    q = at(flat, box=([0.0, 0.0, 1.0], [1.0, 0, 0, 0]), box2=([0.02, 0.0, 1.0 + 0.175 - 1e-3], yaw_quat(math.pi / 4)))
    p = flat.pair("box", "box2")
    k, psi, n, pa, pb = check_contacts(flat, q, p)
    # the clipped polygon has 8 corners: 4 are kept, the deepest among them, and they span
    # most of the overlap's area
    assert k == 4
    np.testing.assert_allclose(psi, -1e-3, atol=1e-14)
    hull = pa[:, :2] - pa[:, :2].mean(axis=0)
    order = np.argsort(np.arctan2(hull[:, 1], hull[:, 0]))
    x, y = hull[order, 0], hull[order, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert area > 0.5 * 0.4 * 0.3  # the overlap is nearly all of box's 0.4 x 0.3 top


def test_sphere_inside_a_box_reports_the_depth_to_the_nearest_face(flat):
    centre = np.array([0.15, 0.02, 1.0 - 0.03])
    q = at(flat, box=([0.0, 0.0, 1.0], [1.0, 0, 0, 0]), sph2=(centre, None))
    p = flat.pair("box", "sph2")
    k, psi, n, pa, pb = check_contacts(flat, q, p)
    assert k == 1
    assert psi[0] == pytest.approx(-(0.2 - 0.15) - 0.07, abs=1e-15)
    np.testing.assert_allclose(n[0], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(pa[0], [0.2, 0.02, 0.97], atol=1e-15)
    np.testing.assert_allclose(pb[0], centre - [0.07, 0, 0], atol=1e-15)


def test_sphere_outside_a_box_edge(flat):
    q = at(flat, box=([0.0, 0.0, 1.0], [1.0, 0, 0, 0]), sph2=([0.2 + 0.06, 0.0, 1.1 + 0.08], None))
    k, psi, n, pa, pb = check_contacts(flat, q, flat.pair("box", "sph2"))
    assert psi[0] == pytest.approx(0.1 - 0.07, abs=1e-15)
    np.testing.assert_allclose(n[0], [0.6, 0.0, 0.8], atol=1e-15)


def test_parallel_capsules_touch_at_the_ends_of_their_overlap(flat):
    # cap: axis 0.5 long (x in [-0.25, 0.25]) radius 0.1; cap2: 0.3 long, radius 0.05, above it
    # shifted so that the overlap is x in [0.05, 0.25]
    q = at(flat, cap=([0.0, 0.0, 1.0], [1.0, 0, 0, 0]), cap2=([0.2, 0.0, 1.15], [1.0, 0, 0, 0]))
    k, psi, n, pa, pb = check_contacts(flat, q, flat.pair("cap", "cap2"))
    assert k == 2
    np.testing.assert_allclose(psi, 0.0, atol=1e-15)
    np.testing.assert_allclose(np.sort(pa[:, 0]), [0.05, 0.25], atol=1e-15)
    # slightly crossed: still two contacts, the closest one exact
    q = at(flat, cap=([0.0, 0.0, 1.0], [1.0, 0, 0, 0]), cap2=([0.2, 0.0, 1.15], yaw_quat(5e-3)))
    k, psi, n, pa, pb = check_contacts(flat, q, flat.pair("cap", "cap2"))
    assert k == 2 and psi.min() == pytest.approx(0.0, abs=1e-15)
    # crossing at right angles: one contact
    q = at(flat, cap=([0.0, 0.0, 1.0], [1.0, 0, 0, 0]), cap2=([0.0, 0.0, 1.14], yaw_quat(math.pi / 2)))
    k, psi, n, pa, pb = check_contacts(flat, q, flat.pair("cap", "cap2"))
    assert k == 1 and psi[0] == pytest.approx(-0.01, abs=1e-15)


def test_capsule_lying_on_a_box_touches_at_the_ends_over_the_face(flat):
    # cap (x in [-0.25, 0.25], r 0.1) on box's top face (x in [-0.2, 0.2]): it overhangs both sides
    q = at(flat, box=([0.0, 0.0, 1.0], [1.0, 0, 0, 0]), cap=([0.0, 0.05, 1.2 - 1e-4], [1.0, 0, 0, 0]))
    k, psi, n, pa, pb = check_contacts(flat, q, flat.pair("cap", "box"))
    assert k == 2
    np.testing.assert_allclose(psi, -1e-4, atol=1e-14)
    np.testing.assert_allclose(np.sort(pb[:, 0]), [-0.2, 0.2], atol=1e-14)
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, -1.0], (2, 1)), atol=1e-14)
    # shorter than the face: contacts at its own ends
    q = at(flat, box=([0.0, 0.0, 1.0], [1.0, 0, 0, 0]), cap2=([0.05, 0.0, 1.15], [1.0, 0, 0, 0]))
    k, psi, n, pa, pb = check_contacts(flat, q, flat.pair("box", "cap2"))
    assert k == 2
    np.testing.assert_allclose(np.sort(pa[:, 0]), [-0.1, 0.2], atol=1e-14)


def test_mesh_on_a_plane_touches_at_its_base_corners(flat):
    q = at(flat, mesh=([0.0, 0.0, 0.0], [1.0, 0, 0, 0]))
    k, psi, n, pa, pb = contacts(flat, q, flat.pair("floor", "mesh"), margin=1e-6)
    assert k == 4
    np.testing.assert_allclose(psi, 0.0, atol=1e-15)


# ----------------------------------------------------------------------------- buffers and dispatch


def test_never_writes_more_than_the_pair_allows(scenes):
    scene = scenes[0]
    rng = np.random.default_rng(3)
    start = 3
    for p, a, b in scene.pairs():
        most = int(scene.S.pair_max_contacts[p])
        for trial in range(20):
            q = random_pose(scene, p, rng, aligned=trial % 2 == 1)
            for size in (start + most + 4, start + most, start + max(most - 1, 0)):
                psi = np.full(size + 2, np.nan)
                vec = [np.full((size + 2, 3), np.nan) for _ in range(3)]
                # the buffers end at `size`; the two entries beyond are views' neighbours
                k = collide_pair_3d(scene.S, q, p, 1e3, psi[:size], vec[0][:size], vec[1][:size], vec[2][:size], start)
                assert k >= 0, (a, b)  # every spatial pair is compiled
                assert k <= min(most, size - start), (a, b, k)
                written = np.zeros(size + 2, bool)
                written[start : start + k] = True
                assert np.all(np.isnan(psi[~written])), (a, b)
                assert np.all(~np.isnan(psi[written]))
                for v in vec:
                    assert np.all(np.isnan(v[~written]))


def test_planar_scenes_are_left_to_the_caller_and_meshes_are_compiled(scenes):
    scene = scenes[0]
    q = np.array(scene.sc.start, float)
    buffers = (np.empty(8), np.empty((8, 3)), np.empty((8, 3)), np.empty((8, 3)))
    for other in ("sph", "cap", "box", "sph2", "cap2", "box2", "ycap", "wall"):
        names = ("mesh", other) if scene.names.index("mesh") < scene.names.index(other) else (other, "mesh")
        assert collide_pair_3d(scene.S, q, scene.pair(*names), 0.0, *buffers, 0) == 0  # apart (see test_contact3d_mesh)
    planar = load_scenario(DATA / "good" / "minimal_triangle.toml")
    S2 = compile_scene(planar)
    assert collide_pair_3d(S2, np.array(planar.start, float), 0, 0.0, *buffers, 0) == -1


def test_collide_all_matches_pair_by_pair(scenes):
    scene = scenes[0]
    S = scene.S
    rng = np.random.default_rng(11)
    for _trial in range(20):
        q = np.array(scene.sc.start, float)
        for name in ("sph", "cap", "box", "mesh", "sph2", "cap2", "box2", "ycap"):
            scene.place(q, name, rng.uniform(-0.4, 0.4, 3) + [0.0, 0.0, 0.5], random_quat(rng))
        cap = 200
        psi, n, pa, pb = np.empty(cap), np.empty((cap, 3)), np.empty((cap, 3)), np.empty((cap, 3))
        pair = np.empty(cap, np.int64)
        fallback = np.empty(len(S.pair_a), np.bool_)
        total = collide_all_3d(S, q, 0.01, psi, n, pa, pb, pair, fallback)
        expected = []
        for p in range(len(S.pair_a)):
            k, ps, ns, pas, pbs = contacts(scene, q, p, margin=0.01)
            assert fallback[p] == (k < 0)
            expected += [(p, ps[i], *ns[i], *pas[i], *pbs[i]) for i in range(max(k, 0))]
        got = [(pair[i], psi[i], *n[i], *pa[i], *pb[i]) for i in range(total)]
        assert got == expected


# ----------------------------------------------------------------------------- python-fcl fallback


def test_fcl_fallback_for_meshes(scenes):
    scene = scenes[0]
    rng = np.random.default_rng(5)
    for other in ("sph", "cap", "box", "sph2", "cap2", "box2", "wall"):
        names = ("mesh", other) if scene.names.index("mesh") < scene.names.index(other) else (other, "mesh")
        p = scene.pair(*names)
        for _trial in range(15):
            q = random_pose(scene, p, rng)
            ref = reference(scene, q, p)
            found = fcl_pair_contacts(scene.sc, scene.S, q, p, np.inf)
            assert len(found) == 1
            psi, n, pa, pb = found[0]
            assert psi == pytest.approx(ref, abs=1e-6)
            assert abs(np.linalg.norm(n) - 1.0) < 1e-12
            np.testing.assert_allclose(pb - pa, psi * n, atol=1e-6)
            assert fcl_pair_contacts(scene.sc, scene.S, q, p, psi - 1e-3) == []


def test_fcl_fallback_agrees_with_compiled_pairs(scenes):
    scene = scenes[0]
    rng = np.random.default_rng(6)
    for names in (("box", "box2"), ("cap", "box"), ("plane1", "box"), ("box", "plane2"), ("plane1", "mesh")):
        p = scene.pair(*names)
        for _trial in range(10):
            q = random_pose(scene, p, rng)
            k, psi, n, pa, pb = contacts(scene, q, p)
            found = fcl_pair_contacts(scene.sc, scene.S, q, p, np.inf)
            assert min(c[0] for c in found) == pytest.approx(psi.min(), abs=PENETRATION_TOL)
            if "plane1" in names or "plane2" in names:  # planes never reach fcl: the same contacts
                assert len(found) == k
                np.testing.assert_array_equal(np.array([c[1] for c in found]), n)


# ----------------------------------------------------------------------------- helpers


def test_tangent_basis_is_orthonormal_right_handed_and_continuous():
    rng = np.random.default_rng(2)
    normals = rng.normal(size=(500, 3))
    normals = np.vstack([normals, [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1, 0], [1, 0, -0.0]]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    for n in normals:
        t, o = tangent_basis(n)
        assert abs(t @ n) < 1e-14 and abs(o @ n) < 1e-14 and abs(t @ o) < 1e-14
        assert abs(np.linalg.norm(t) - 1) < 1e-14 and abs(np.linalg.norm(o) - 1) < 1e-14
        np.testing.assert_allclose(np.cross(t, o), n, atol=1e-14)
        t2, o2 = tangent_basis(n.copy())
        assert np.array_equal(t, t2) and np.array_equal(o, o2)  # deterministic
        if abs(n[2]) > 0.05:  # continuous away from the n_z = 0 seam
            m = n + 1e-7 * rng.normal(size=3)
            m /= np.linalg.norm(m)
            t3, o3 = tangent_basis(m)
            assert np.abs(t3 - t).max() < 1e-4 and np.abs(o3 - o).max() < 1e-4


def test_poses_match_the_kinematics(scenes):
    scene = scenes[0]
    rng = np.random.default_rng(4)
    for _trial in range(20):
        q = np.array(scene.sc.start, float) + rng.normal(size=len(scene.sc.start))
        X = scene.sc.placements(q)
        for b, name in enumerate(scene.names):
            p, R = _pose(scene.S, q, b)
            p_ref, R_ref = body_pose_3d(scene.S, q, b)
            np.testing.assert_allclose(p, p_ref, atol=1e-15)
            np.testing.assert_allclose(np.array(R), R_ref, atol=1e-15)
            np.testing.assert_allclose(np.array(R), X[name].rotation, atol=1e-14)
            np.testing.assert_allclose(p, X[name].translation, atol=1e-15)


def test_spatial_jacobians_are_rates_of_psi_along_the_motion():
    """W^T nu equals d psi / dt along q(t) = q + t G(q) nu (world angular velocity), by central
    differences, for the box on the table and the sphere pusher against the box."""
    from models.contact import contact_frames
    from models.kinematics import G_matrix, compile_scene
    from models.scenario import load_scenario
    from tests.conftest import SCENARIOS

    scenario = load_scenario(SCENARIOS / "box_push_3d.toml")
    S = compile_scene(scenario)
    rng = np.random.default_rng(4)
    checked = 0
    for _ in range(30):
        q = np.array(scenario.start, dtype=float)
        quat = np.array([1.0, *rng.normal(scale=0.15, size=3)])
        q[3:7] = quat / np.linalg.norm(quat)
        q[2] = 0.05 + rng.uniform(0.0, 0.02)  # near the table
        q[7:9] = [-0.1 - 0.03 - rng.uniform(0, 0.01), rng.uniform(-0.05, 0.05)]  # pusher near the -x face
        nu = rng.normal(size=S.nv)
        frames = contact_frames(S, q, margin=0.2)
        eps = 1e-7
        G = G_matrix(S, q)
        plus = contact_frames(S, q + eps * G @ nu, margin=0.2)
        minus = contact_frames(S, q - eps * G @ nu, margin=0.2)
        for p in np.unique(frames.pair):
            rows = np.flatnonzero(frames.pair == p)
            i = rows[np.argmin(frames.psi[rows])]
            others = frames.psi[rows]
            if len(rows) > 1 and np.sort(others)[1] - np.sort(others)[0] < 1e-3:
                continue  # the min of near-equal contacts is not differentiable
            psi_plus = plus.psi[plus.pair == p].min()
            psi_minus = minus.psi[minus.pair == p].min()
            rate = (psi_plus - psi_minus) / (2 * eps)
            assert frames.W_n[:, i] @ nu == pytest.approx(rate, abs=1e-5 * (1 + abs(rate)))
            checked += 1
    assert checked >= 30

"""Signed distances against closed forms; polygon and mesh checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import geometry as geo
from models.schema import Box, Capsule, Disc, HalfPlane, Plane, Polygon, Sphere

I2 = np.eye(2)
I3 = np.eye(3)


def at(x, y, theta=0.0):
    return geo.Placement(geo.rotation_2d(theta), np.array([x, y], float))


def at3(x, y, z, quat=(1.0, 0.0, 0.0, 0.0)):
    return geo.Placement(geo.quaternion_matrix(np.array(quat)), np.array([x, y, z], float))


def g2(shape):
    return geo.make_geometry(shape, 2)


def g3(shape):
    return geo.make_geometry(shape, 3)


DISC = g2(Disc(type="disc", radius=0.5))
TRIANGLE = g2(Polygon(type="polygon", vertices=((-1, 0), (1, 0), (0, 1))))
FLOOR = g2(HalfPlane(type="halfplane", normal=(0, 1)))


@pytest.mark.parametrize("d", [2.0, 1.0, 0.5, 0.2])
def test_disc_disc(d):
    assert geo.signed_distance(DISC, at(0, 0), DISC, at(d, 0)) == pytest.approx(d - 1.0)


@pytest.mark.parametrize("y", [1.0, 0.5, 0.3])
def test_disc_on_halfplane(y):
    assert geo.signed_distance(FLOOR, at(0, 0), DISC, at(3, y)) == pytest.approx(y - 0.5)
    assert geo.signed_distance(DISC, at(3, y), FLOOR, at(0, 0)) == pytest.approx(y - 0.5)


def test_tilted_halfplane():
    tilted = at(0, 0, math.radians(30))
    # the origin-centred disc's centre is on the boundary line: depth = radius
    assert geo.signed_distance(FLOOR, tilted, DISC, at(0, 0)) == pytest.approx(-0.5)
    n = np.array([-math.sin(math.radians(30)), math.cos(math.radians(30))])
    p = 2.0 * n
    assert geo.signed_distance(FLOOR, tilted, DISC, at(*p)) == pytest.approx(1.5)


def test_disc_and_triangle_face_outside_and_inside():
    small = g2(Disc(type="disc", radius=0.05))
    # above the left face, nearest point on the face interior: distance (y - x - 1)/sqrt(2) - r
    for x, y in [(-0.5, 1.0), (-0.6, 0.9), (-0.5, 0.45)]:
        expected = (y - x - 1) / math.sqrt(2) - 0.05
        assert geo.signed_distance(TRIANGLE, at(0, 0), small, at(x, y)) == pytest.approx(expected, abs=1e-12)
    # above the apex: distance to the apex
    assert geo.signed_distance(TRIANGLE, at(0, 0), small, at(0, 2)) == pytest.approx(0.95)


def test_overlapping_boxes_depth_is_the_smaller_overlap():
    box = g2(Box(type="box", size=(2.0, 1.0)))
    assert geo.signed_distance(box, at(0, 0), box, at(1.9, 0.3)) == pytest.approx(-0.1)
    assert geo.signed_distance(box, at(0, 0), box, at(0.5, 0.9)) == pytest.approx(-0.1)
    assert geo.signed_distance(box, at(0, 0), box, at(3.0, 0.0)) == pytest.approx(1.0)


def test_rotated_box_corner_on_floor():
    box = g2(Box(type="box", size=(1.0, 1.0)))
    # a unit square rotated 45 degrees: its lowest corner is sqrt(2)/2 below its centre
    assert geo.signed_distance(FLOOR, at(0, 0), box, at(0, 1.0, math.pi / 4)) == pytest.approx(1 - math.sqrt(0.5))


def test_capsule_distances():
    cap = g2(Capsule(type="capsule", radius=0.1, length=1.0))
    assert geo.signed_distance(cap, at(0, 0), DISC, at(0, 1.0)) == pytest.approx(0.4)  # over the side
    assert geo.signed_distance(cap, at(0, 0), DISC, at(1.5, 0)) == pytest.approx(0.4)  # beyond the end cap
    assert geo.signed_distance(cap, at(0, 0), cap, at(0, 0.15)) == pytest.approx(-0.05)  # parallel overlap
    assert geo.signed_distance(cap, at(0, 0), cap, at(2.0, 0)) == pytest.approx(0.8)  # collinear, apart


def test_distance_is_symmetric_and_moves_with_poses():
    rng = np.random.default_rng(0)
    shapes = [DISC, TRIANGLE, g2(Box(type="box", size=(0.6, 0.3))), g2(Capsule(type="capsule", radius=0.1, length=0.5))]
    for _ in range(300):
        a, b = rng.choice(len(shapes), 2)
        pa, pb = at(*rng.uniform(-1, 1, 2), rng.uniform(-3, 3)), at(*rng.uniform(-1, 1, 2), rng.uniform(-3, 3))
        d1 = geo.signed_distance(shapes[a], pa, shapes[b], pb)
        d2 = geo.signed_distance(shapes[b], pb, shapes[a], pa)
        assert d1 == pytest.approx(d2, abs=1e-12)
        # translating both bodies together changes nothing
        shift = rng.uniform(-5, 5, 2)
        moved = geo.signed_distance(
            shapes[a], geo.Placement(pa.rotation, pa.translation + shift), shapes[b], geo.Placement(pb.rotation, pb.translation + shift)
        )
        assert moved == pytest.approx(d1, abs=1e-9)


def test_polygon_winding_is_normalised():
    cw = g2(Polygon(type="polygon", vertices=((0, 1), (1, 0), (-1, 0))))
    np.testing.assert_allclose(cw.core, [[-1, 0], [1, 0], [0, 1]])


@pytest.mark.parametrize(
    "vertices, message",
    [
        (((0, 0), (1, 0), (2, 0)), "degenerate"),
        (((0, 0), (1, 0), (1, 0), (0, 1)), "repeated"),
        (((0, 0), (1, 0), (2, 0), (1, 1)), "collinear"),
        (((0, 0), (2, 0), (1, 0.3), (1, 2)), "not convex"),
        (((0, 0), (2, 0), (0.5, 1.5), (1, -1), (1.5, 1.5)), "not convex"),
    ],
)
def test_bad_polygons(vertices, message):
    with pytest.raises(geo.GeometryError, match=message):
        geo.convex_polygon(np.array(vertices, float))


def test_spatial_closed_forms():
    sphere = g3(Sphere(type="sphere", radius=0.5))
    box = g3(Box(type="box", size=(2.0, 2.0, 2.0)))
    table = g3(Plane(type="plane", normal=(0, 0, 1)))
    assert geo.signed_distance(sphere, at3(0, 0, 0), sphere, at3(0, 0, 2)) == pytest.approx(1.0, abs=1e-6)
    assert geo.signed_distance(box, at3(0, 0, 0), sphere, at3(2.0, 0, 0)) == pytest.approx(0.5, abs=1e-6)
    assert geo.signed_distance(box, at3(0, 0, 0), sphere, at3(1.2, 0, 0)) == pytest.approx(-0.3, abs=1e-6)
    assert geo.signed_distance(table, at3(0, 0, 0), box, at3(0, 0, 1.5)) == pytest.approx(0.5)
    # a box rolled 45 degrees about x stands on an edge sqrt(2) below its centre
    q = geo.rpy_quaternion(math.pi / 4, 0.0, 0.0)
    assert geo.signed_distance(table, at3(0, 0, 0), box, at3(0, 0, 3.0, q)) == pytest.approx(3.0 - math.sqrt(2))
    # and rolled into the table by 0.1 it penetrates by 0.1, through python-fcl too
    assert geo.signed_distance(box, at3(0, 0, 0), box, at3(0, 0, 1.9 + math.sqrt(2) - 1, q)) == pytest.approx(-0.1, abs=1e-6)


def test_capsule_3d_runs_along_x():
    cap = g3(Capsule(type="capsule", radius=0.1, length=1.0))
    sphere = g3(Sphere(type="sphere", radius=0.1))
    assert geo.signed_distance(cap, at3(0, 0, 0), sphere, at3(1.0, 0, 0)) == pytest.approx(0.3, abs=1e-6)
    assert geo.signed_distance(cap, at3(0, 0, 0), sphere, at3(0, 0, 1.0)) == pytest.approx(0.8, abs=1e-6)


def test_rpy_quaternion_is_unit_and_matches_rotation():
    q = geo.rpy_quaternion(0.3, -0.2, 1.1)
    assert np.linalg.norm(q) == pytest.approx(1.0)
    R = geo.quaternion_matrix(q)
    cz, sz, cy, sy, cx, sx = math.cos(1.1), math.sin(1.1), math.cos(-0.2), math.sin(-0.2), math.cos(0.3), math.sin(0.3)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    np.testing.assert_allclose(R, Rz @ Ry @ Rx, atol=1e-12)


def test_sphere_resting_on_a_box_near_touching_does_not_reach_fcl():
    """python-fcl 0.7 aborts the process on this pose (libccd); the analytic path answers."""
    sphere = g3(Sphere(type="sphere", radius=0.07))
    box = g3(Box(type="box", size=(0.4, 0.3, 0.2)))
    d = geo.signed_distance(box, at3(0, 0, 0), sphere, at3(0.05, 0.02, 0.1 + 0.07 - 1e-9))
    assert d == pytest.approx(-1e-9, abs=1e-15)
    # inside: depth to the nearest face
    assert geo.signed_distance(box, at3(0, 0, 0), sphere, at3(0.15, 0.0, 0.0)) == pytest.approx(-0.05 - 0.07)
    # off an edge
    assert geo.signed_distance(box, at3(0, 0, 0), sphere, at3(0.3, 0.25, 0.0)) == pytest.approx(np.hypot(0.1, 0.1) - 0.07)


def test_capsule_pairs_are_analytic():
    cap = g3(Capsule(type="capsule", radius=0.1, length=1.0))
    # crossed capsules, one above the other
    q = geo.rpy_quaternion(0.0, 0.0, math.pi / 2)
    assert geo.signed_distance(cap, at3(0, 0, 0), cap, at3(0.2, 0.1, 0.5, q)) == pytest.approx(0.3)
    # parallel, overlapping sideways
    assert geo.signed_distance(cap, at3(0, 0, 0), cap, at3(0.3, 0.15, 0.0)) == pytest.approx(-0.05)

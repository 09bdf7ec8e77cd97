"""Shapes and signed distances between posed bodies (the paper's psi, Section 3.1).

Every planar shape is a *rounded convex polygon*: a convex core (one point for a disc, a
segment for a capsule, a polygon for boxes and polygons) swept by a disc of ``radius``.
Signed distance between two of them is the distance between their cores minus both radii,
or, when the cores overlap, minus the cores' penetration depth (found by the separating-axis
test over the cores' edge normals, exact for convex polygons). Half-planes and planes are
handled by support points.

Spatial pairs of bounded shapes go through python-fcl (the only module that imports fcl);
planes use the same support-point formula as half-planes.

This module is the reference implementation in plain numpy, used for validating scenario
files; the compiled kernels of the rollout are tested against it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: Cross products below this (relative to the polygon's size squared) count as collinear.
COLLINEAR_TOLERANCE = 1e-12


class GeometryError(ValueError):
    """A shape that cannot be used: degenerate, non-convex, unreadable mesh. Message says why."""


@dataclass(frozen=True)
class Geometry:
    """A shape ready for distance queries.

    kind: ``"halfspace"`` (planar half-plane or spatial plane: ``normal``, ``offset`` in the
    body frame, solid where normal . p <= offset), ``"rounded"`` (planar: ``core`` (k, 2) convex
    points, counter-clockwise, plus ``radius``) or ``"solid3d"`` (spatial bounded shape:
    ``support`` (k, 3) points plus ``radius`` whose hull is the shape, and ``fcl_geometry``).
    """

    kind: str
    dimension: int
    core: np.ndarray
    radius: float = 0.0
    normal: np.ndarray | None = None
    offset: float = 0.0
    fcl_args: tuple = ()


# ----------------------------------------------------------------------------- construction


def convex_polygon(vertices: np.ndarray) -> np.ndarray:
    """Return ``vertices`` (k, 2) counter-clockwise; raise GeometryError if degenerate or not convex."""
    v = np.asarray(vertices, dtype=float)
    if len(v) < 3:
        raise GeometryError(f"a polygon needs at least 3 vertices, got {len(v)}")
    edges = np.roll(v, -1, axis=0) - v
    scale = max(float(np.max(np.abs(v - v.mean(axis=0)))), 1e-300)
    if np.any(np.linalg.norm(edges, axis=1) <= 1e-12 * scale):
        raise GeometryError("polygon has repeated vertices (a zero-length edge)")
    cross = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    area = 0.5 * float(np.sum(v[:, 0] * np.roll(v, -1, axis=0)[:, 1] - np.roll(v, -1, axis=0)[:, 0] * v[:, 1]))
    if abs(area) <= COLLINEAR_TOLERANCE * scale**2:
        raise GeometryError("polygon is degenerate (zero area)")
    if np.any(np.abs(cross) <= COLLINEAR_TOLERANCE * scale**2):
        raise GeometryError("polygon has three collinear consecutive vertices; drop the middle one")
    if not (np.all(cross > 0) or np.all(cross < 0)):
        raise GeometryError("polygon is not convex (its edges turn both ways)")
    # A star polygon turns one way yet winds twice: the turning must total one revolution.
    turning = np.sum(np.arctan2(cross, np.einsum("ij,ij->i", edges, np.roll(edges, -1, axis=0))))
    if abs(abs(turning) - 2 * math.pi) > 1e-6:
        raise GeometryError("polygon is not convex (its boundary winds more than once)")
    return v if area > 0 else v[::-1].copy()


def read_obj(path: Path) -> tuple[np.ndarray, list[list[int]]]:
    """Vertices (k, 3) and faces (0-based index lists) of a Wavefront OBJ file. A vertex line
    gives x y z (anything after them, a w or a colour, is left); a face's indices count from 1,
    or back from the vertices read so far where negative (OBJ's relative indices)."""
    vertices: list[list[float]] = []
    faces: list[list[int]] = []
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise GeometryError(f"cannot read mesh file {str(path)!r}: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise GeometryError(f"{path.name}: not a Wavefront OBJ file (a text file; byte {exc.start} is not UTF-8)") from None
    for number, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        where = f"{path.name} line {number}"
        try:
            if parts[0] == "v":
                if len(parts) < 4:
                    raise GeometryError(f"{where}: a vertex needs three coordinates, x y z: {line.strip()!r}")
                vertices.append([float(x) for x in parts[1:4]])
            elif parts[0] == "f":
                if len(parts) < 4:
                    raise GeometryError(f"{where}: a face needs at least three vertices: {line.strip()!r}")
                indices = [int(p.split("/")[0]) for p in parts[1:]]
                if any(i == 0 or i < -len(vertices) for i in indices):
                    raise GeometryError(f"{where}: a face refers to a vertex that does not exist: {line.strip()!r}")
                faces.append([i - 1 if i > 0 else len(vertices) + i for i in indices])
        except GeometryError:
            raise
        except ValueError:  # (a number that is none)
            raise GeometryError(f"{where}: cannot read {line.strip()!r}") from None
    if not vertices and not faces:
        raise GeometryError(
            f"{path.name}: no vertex ('v') or face ('f') lines: not a Wavefront OBJ file (meshes are read from OBJ only; "
            "convert an STL or PLY file to OBJ first)"
        )
    v = np.array(vertices, dtype=float).reshape(-1, 3)
    if len(v) < 4 or not faces:
        raise GeometryError(f"{path.name}: a solid mesh needs at least 4 vertices and some faces")
    if not np.all(np.isfinite(v)):
        raise GeometryError(f"{path.name}: non-finite vertex coordinates")
    if any(max(f) >= len(v) for f in faces):
        raise GeometryError(f"{path.name}: a face refers to a vertex that does not exist")
    return v, faces


def check_convex_mesh(v: np.ndarray, faces: list[list[int]], name: str) -> None:
    """Raise GeometryError unless the vertices span a volume (a flat mesh bounds no solid: its
    hull has no inside) and every vertex lies on the inner side of every face plane."""
    centre = v.mean(axis=0)
    scale = float(np.max(np.linalg.norm(v - centre, axis=1)))
    if not _least_extent(v) > 1e-9 * scale:
        raise GeometryError(f"{name}: mesh is flat (its vertices lie in one plane): a solid needs volume")
    for face in faces:
        a, b, c = v[face[0]], v[face[1]], v[face[2]]
        n = np.cross(b - a, c - a)
        if np.linalg.norm(n) <= 1e-12 * scale**2:
            raise GeometryError(f"{name}: a face is degenerate (zero area)")
        n /= np.linalg.norm(n)
        if np.dot(n, centre - a) > 0:
            n = -n
        if np.max((v - a) @ n) > 1e-9 * scale:
            raise GeometryError(f"{name}: mesh is not convex")
    unpaired = _unpaired_edges(v, faces, scale)
    if unpaired:
        raise GeometryError(
            f"{name}: mesh is not closed: {unpaired} edge(s) border one face only, or more than two (a solid's surface "
            "has every edge on two faces; a mesh with a hole would be taken for its convex hull)"
        )


def _unpaired_edges(v: np.ndarray, faces: list[list[int]], scale: float) -> int:
    """How many edges of the mesh's faces do not border exactly two faces, its coincident
    vertices welded first (a file that repeats a vertex for each face it is on is closed)."""
    _, weld = np.unique(np.round(v / max(1e-9 * scale, 1e-300)), axis=0, return_inverse=True)
    weld = weld.ravel()
    counts: dict[tuple[int, int], int] = {}
    for face in faces:
        for a, b in zip(face, face[1:] + face[:1]):
            edge = (min(weld[a], weld[b]), max(weld[a], weld[b]))
            counts[edge] = counts.get(edge, 0) + 1
    return sum(1 for c in counts.values() if c != 2)


def make_geometry(shape, dimension: int, base_dir: Path | None = None, max_coordinate: float = math.inf) -> Geometry:
    """Build the query geometry of a validated shape spec (see models.schema); a mesh whose
    scaled vertices reach beyond ``max_coordinate`` is rejected (the spec bounds the rest)."""
    t = shape.type
    if t in ("halfplane", "plane"):
        n = np.asarray(shape.normal, dtype=float)
        norm = float(np.linalg.norm(n))
        if norm == 0.0:
            raise GeometryError("normal is the zero vector")
        return Geometry("halfspace", dimension, np.zeros((0, dimension)), normal=n / norm, offset=shape.offset / norm)
    if dimension == 2:
        if t == "disc":
            return Geometry("rounded", 2, np.zeros((1, 2)), radius=shape.radius)
        if t == "capsule":
            half = 0.5 * shape.length
            return Geometry("rounded", 2, np.array([[-half, 0.0], [half, 0.0]]), radius=shape.radius)
        if t == "box":
            w, h = 0.5 * shape.size[0], 0.5 * shape.size[1]
            return Geometry("rounded", 2, np.array([[-w, -h], [w, -h], [w, h], [-w, h]]))
        if t == "polygon":
            return Geometry("rounded", 2, convex_polygon(np.array(shape.vertices)))
        raise GeometryError(f"shape {t!r} is not planar")
    if t == "sphere":
        return Geometry("solid3d", 3, np.zeros((1, 3)), radius=shape.radius, fcl_args=("sphere", shape.radius))
    if t == "capsule":
        half = 0.5 * shape.length
        core = np.array([[-half, 0.0, 0.0], [half, 0.0, 0.0]])
        return Geometry("solid3d", 3, core, radius=shape.radius, fcl_args=("capsule", shape.radius, shape.length))
    if t == "box":
        half = 0.5 * np.asarray(shape.size, dtype=float)
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
        return Geometry("solid3d", 3, corners, fcl_args=("box", *shape.size))
    if t == "mesh":
        path = (base_dir or Path(".")) / shape.file
        v, faces = read_obj(path)
        v = v * shape.scale
        if np.max(np.abs(v)) > max_coordinate:
            raise GeometryError(
                f"{path.name}: vertex coordinates times scale reach {np.max(np.abs(v)):g}, "
                f"beyond the bound on coordinates ({max_coordinate:g} m)"
            )
        check_convex_mesh(v, faces, path.name)
        return Geometry("solid3d", 3, v, fcl_args=("mesh", v, tuple(tuple(f) for f in faces)))
    raise GeometryError(f"shape {t!r} is not spatial")


def thickness(g: Geometry) -> float:
    """How thick the shape is across its thinnest principal direction, m (inf for a half-plane
    or plane): the core's extent along the last of its principal axes, plus twice the radius (a
    disc's or sphere's diameter, a capsule's, a box's least side). A penetration past half of it
    has pushed a body's middle through the other's surface: no contact model's result."""
    if g.kind == "halfspace":
        return math.inf
    return _least_extent(g.core) + 2.0 * g.radius


def _least_extent(points: np.ndarray) -> float:
    """The points' extent along their direction of least spread (their last principal axis): 0
    for one point, or for points on a line (in the plane) or in a plane (in space)."""
    if len(points) < 2:
        return 0.0
    centred = points - points.mean(axis=0)
    least = np.linalg.svd(centred, full_matrices=True)[2][-1]
    return float(np.ptp(centred @ least))


# ----------------------------------------------------------------------------- poses


def rotation_2d(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rpy_quaternion(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


@dataclass(frozen=True)
class Placement:
    """A rigid transform: world point = rotation @ body point + translation."""

    rotation: np.ndarray
    translation: np.ndarray


# ----------------------------------------------------------------------------- distances


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    denom = float(ab @ ab)
    s = 0.0 if denom == 0.0 else min(1.0, max(0.0, float((p - a) @ ab) / denom))
    return float(np.linalg.norm(p - (a + s * ab)))


def _edges(points: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    k = len(points)
    if k == 1:
        return []
    if k == 2:
        return [(points[0], points[1])]
    return [(points[i], points[(i + 1) % k]) for i in range(k)]


def _segments_cross(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> bool:
    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    o1, o2, o3, o4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
    return (o1 * o2 <= 0) and (o3 * o4 <= 0) and not (o1 == o2 == o3 == o4 == 0)


def _inside(p: np.ndarray, poly: np.ndarray) -> bool:
    """p inside or on a counter-clockwise convex polygon (k >= 3)."""
    if len(poly) < 3:
        return False
    e = np.roll(poly, -1, axis=0) - poly
    r = p - poly
    return bool(np.all(e[:, 0] * r[:, 1] - e[:, 1] * r[:, 0] >= 0))


def _axes(points: np.ndarray) -> list[np.ndarray]:
    axes = []
    for a, b in _edges(points):
        d = b - a
        n = np.array([d[1], -d[0]])
        axes.append(n / np.linalg.norm(n))
        if len(points) == 2:
            axes.append(d / np.linalg.norm(d))
    return axes


def core_signed_distance_2d(P: np.ndarray, Q: np.ndarray) -> float:
    """Signed distance between two convex point sets (point, segment or CCW polygon), world frame."""
    dist = math.inf
    for p in P:
        for a, b in _edges(Q) or [(Q[0], Q[0])]:
            dist = min(dist, _point_segment_distance(p, a, b))
    for q in Q:
        for a, b in _edges(P) or [(P[0], P[0])]:
            dist = min(dist, _point_segment_distance(q, a, b))
    overlap = dist == 0.0 or any(_inside(p, Q) for p in P) or any(_inside(q, P) for q in Q)
    if not overlap:
        overlap = any(_segments_cross(a, b, c, d) for a, b in _edges(P) for c, d in _edges(Q))
    if not overlap:
        return dist
    depth = math.inf
    for axis in _axes(P) + _axes(Q):
        pa, qa = P @ axis, Q @ axis
        depth = min(depth, min(pa.max() - qa.min(), qa.max() - pa.min()))
    return -max(depth, 0.0) if math.isfinite(depth) else 0.0


def _halfspace_world(g: Geometry, X: Placement) -> tuple[np.ndarray, float]:
    n = X.rotation @ g.normal
    return n, g.offset + float(n @ X.translation)


def signed_distance(ga: Geometry, Xa: Placement, gb: Geometry, Xb: Placement) -> float:
    """psi between two posed shapes: > 0 apart, 0 touching, < 0 the penetration depth.

    Two half-spaces have no meaningful distance: returns +inf (they are never paired).
    """
    if ga.kind == "halfspace" and gb.kind == "halfspace":
        return math.inf
    if gb.kind == "halfspace":
        ga, Xa, gb, Xb = gb, Xb, ga, Xa
    if ga.kind == "halfspace":
        n, off = _halfspace_world(ga, Xa)
        points = gb.core @ Xb.rotation.T + Xb.translation
        return float(np.min(points @ n) - off - gb.radius)
    if ga.dimension == 2:
        P = ga.core @ Xa.rotation.T + Xa.translation
        Q = gb.core @ Xb.rotation.T + Xb.translation
        return core_signed_distance_2d(P, Q) - ga.radius - gb.radius
    return _spatial_signed_distance(ga, Xa, gb, Xb)


def _segment_closest(p1, q1, p2, q2) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of segments [p1, q1] and [p2, q2] (Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = float(d1 @ d1), float(d2 @ d2), float(d2 @ r)
    if a <= 1e-300 and e <= 1e-300:
        return p1, p2
    if a <= 1e-300:
        return p1, p2 + min(max(f / e, 0.0), 1.0) * d2
    c = float(d1 @ r)
    if e <= 1e-300:
        return p1 + min(max(-c / a, 0.0), 1.0) * d1, p2
    b = float(d1 @ d2)
    denom = a * e - b * b
    s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > 1e-14 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    return p1 + s * d1, p2 + t * d2


def _point_box_signed_distance(p: np.ndarray, half: np.ndarray) -> float:
    """Signed distance of a point (box frame) to a box of half extents `half`."""
    d = np.abs(p) - half
    outside = np.linalg.norm(np.maximum(d, 0.0))
    return float(outside) if outside > 0.0 else float(np.max(d))


def _spatial_signed_distance(ga: Geometry, Xa: Placement, gb: Geometry, Xb: Placement) -> float:
    """Analytic for pairs of spheres and capsules and for sphere-box (python-fcl's GJK/EPA can
    abort the process on such pairs near touching); python-fcl for box-box, capsule-box, meshes."""
    kinds = {ga.fcl_args[0], gb.fcl_args[0]}
    if kinds <= {"sphere", "capsule"}:
        A = ga.core @ Xa.rotation.T + Xa.translation
        B = gb.core @ Xb.rotation.T + Xb.translation
        pa, pb = _segment_closest(A[0], A[-1], B[0], B[-1])
        return float(np.linalg.norm(pb - pa)) - ga.radius - gb.radius
    if kinds == {"sphere", "box"}:
        sphere, Xs, box, Xbox = (ga, Xa, gb, Xb) if ga.fcl_args[0] == "sphere" else (gb, Xb, ga, Xa)
        centre = Xbox.rotation.T @ (Xs.translation - Xbox.translation)
        half = 0.5 * np.asarray(box.fcl_args[1:], dtype=float)
        return _point_box_signed_distance(centre, half) - sphere.radius
    return _fcl_signed_distance(ga, Xa, gb, Xb)


# ----------------------------------------------------------------------------- python-fcl


def _fcl_object(g: Geometry, X: Placement):
    import fcl

    kind, *args = g.fcl_args
    rotation = X.rotation
    if kind == "sphere":
        geom = fcl.Sphere(args[0])
    elif kind == "box":
        geom = fcl.Box(*args)
    elif kind == "capsule":
        geom = fcl.Capsule(args[0], args[1])
        # fcl's capsule runs along its z axis; ours along x: rotate z onto x.
        rotation = rotation @ np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    elif kind == "mesh":
        v, faces = args
        flat = []
        for f in faces:
            flat += [len(f), *f]
        geom = fcl.Convex(np.ascontiguousarray(v), len(faces), np.array(flat, dtype=np.int32))
    else:  # pragma: no cover - make_geometry only builds the kinds above
        raise GeometryError(f"no fcl geometry for {kind!r}")
    return fcl.CollisionObject(geom, fcl.Transform(np.ascontiguousarray(rotation), np.ascontiguousarray(X.translation)))


def _fcl_signed_distance(ga: Geometry, Xa: Placement, gb: Geometry, Xb: Placement) -> float:
    import fcl

    request = fcl.DistanceRequest(enable_signed_distance=True)
    result = fcl.DistanceResult()
    return float(fcl.distance(_fcl_object(ga, Xa), _fcl_object(gb, Xb), request, result))


def fcl_nearest_points(ga: Geometry, Xa: Placement, gb: Geometry, Xb: Placement) -> tuple[float, np.ndarray, np.ndarray]:
    """python-fcl's signed distance of two posed bounded spatial shapes and its nearest points
    (world frame, on A and on B): (psi, pa, pb). Not for planes (fcl's Halfspace distance
    crashes python-fcl 0.7)."""
    import fcl

    request = fcl.DistanceRequest(enable_nearest_points=True, enable_signed_distance=True)
    result = fcl.DistanceResult()
    psi = float(fcl.distance(_fcl_object(ga, Xa), _fcl_object(gb, Xb), request, result))
    return psi, np.array(result.nearest_points[0], float), np.array(result.nearest_points[1], float)

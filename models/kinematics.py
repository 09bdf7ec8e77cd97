"""Body kinematics in arrays: generalized coordinates q, velocities nu, G(q), body poses.

`compile_scene(scenario)` packs a validated `Scenario` into `SceneData`, a namedtuple of
numpy arrays that compiled (numba) kernels take as one argument. Conventions:

- q stacks each body's free DOFs in the scenario's coordinate order; nu likewise
  (`Scenario.coordinates`, `Scenario.velocities`).
- Planar bodies: q = nu components (x, y, theta); G = I.
- Spatial bodies: translations x, y, z; ``yaw`` (rotation about world z) is one coordinate
  with rate = its velocity; ``rotation`` is a unit quaternion (w, x, y, z) in q and a
  **world-frame** angular velocity (wx, wy, wz) in nu, with q_dot = 1/2 [0, w] (x) quat,
  so G(q) is 4x3 for that block and the identity elsewhere.
- Contact convention (shared by the 2D and 3D kernels): a contact of pair (A, B) has a
  world normal n pointing from A to B, points pa on A's surface and pb on B's surface, and
  psi = (pb - pa) . n, the signed distance (negative: penetration depth).

Index maps: ``qmap[b]`` = q indices of (x, y, z, angle, qw, qx, qy, qz) and
``vmap[b]`` = nu indices of (vx, vy, vz, angle rate, wx, wy, wz), -1 where not free.
``angle`` is theta in the plane, yaw in space.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from models.scenario import Scenario, principal_inertia

SHAPE_HALFSPACE = 0  # half-plane / plane: hs_normal, hs_offset (body frame)
SHAPE_POINTS = 1  # planar rounded convex core: point, segment or CCW polygon, plus radius
SHAPE_SPHERE = 2  # spatial: one core point + radius
SHAPE_CAPSULE = 3  # spatial: segment along body x + radius
SHAPE_BOX = 4  # spatial: half_extents; verts hold its 8 corners
SHAPE_MESH = 5  # spatial convex mesh: verts, and hull tables (faces, edges) like boxes

Q_X, Q_Y, Q_Z, Q_ANGLE, Q_QW = 0, 1, 2, 3, 4
V_X, V_Y, V_Z, V_ANGLE, V_WX = 0, 1, 2, 3, 4

# columns of the packed tables (see SceneData.bi, .bf, .pi, .pf)
BI_KIND, BI_VSTART, BI_VCOUNT, BI_QMAP, BI_VMAP, BI_COLUMNS = 0, 1, 2, 3, 11, 18
BF_RADIUS, BF_HALF, BF_HSN, BF_HSO, BF_POS, BF_QUAT, BF_MASS, BF_INERTIA, BF_BOUND = 0, 1, 4, 7, 8, 11, 15, 16, 19
# scripted obstacles: pose at t = 0 (x, y, z, angle about z) and constant velocity (vx, vy, vz,
# angular rate about z); zeros for every other body. BF_SPEED bounds the speed of any of the
# body's points (a scripted body's broadphase reach grows with it).
BF_SCRIPT, BF_SCRIPT_V, BF_SPEED = 20, 24, 28
# a spatial body whose principal axes are not its own (`inertia_products`): the rotation from its
# axes to its principal ones (3 x 3, by rows; its columns the principal axes), and 1.0 in
# BF_TILTED (0.0 and zeros for every other body, whose inertia is about its own axes); the
# moments in BF_INERTIA are then the principal ones
BF_AXES, BF_TILTED, BF_COLUMNS = 29, 38, 39
PI_A, PI_B, PI_MAX, PI_INERT = 0, 1, 2, 3
PF_MU, PF_K, PF_C = 0, 1, 2


class SceneData(NamedTuple):
    """Arrays describing a scene for compiled kernels (see module docstring)."""

    dimension: int
    nq: int
    nv: int
    kind: np.ndarray  # int64[nb]
    vstart: np.ndarray  # int64[nb]
    vcount: np.ndarray  # int64[nb]
    verts: np.ndarray  # float64[total, dim] core points in body frames
    radius: np.ndarray  # float64[nb]
    half_extents: np.ndarray  # float64[nb, 3] (spatial boxes)
    hs_normal: np.ndarray  # float64[nb, dim] unit normals (half-spaces)
    hs_offset: np.ndarray  # float64[nb]
    base_pos: np.ndarray  # float64[nb, 3] (planar: z = 0)
    base_quat: np.ndarray  # float64[nb, 4] (planar: rotation about z by theta)
    qmap: np.ndarray  # int64[nb, 8]
    vmap: np.ndarray  # int64[nb, 7]
    mass: np.ndarray  # float64[nb] (0 for obstacles)
    inertia: np.ndarray  # float64[nb, 3] principal moments (planar: [0, 0, Izz])
    bound_radius: np.ndarray  # float64[nb] radius of a ball around the body origin holding the shape (inf: unbounded)
    pair_a: np.ndarray  # int64[np]
    pair_b: np.ndarray  # int64[np]
    pair_mu: np.ndarray  # float64[np]
    pair_K: np.ndarray  # float64[np]
    pair_C: np.ndarray  # float64[np]
    pair_max_contacts: np.ndarray  # int64[np] most contacts the pair can produce at once
    # Convex hulls of boxes and meshes (body frame, from `hull_tables`), for the compiled
    # polytope tests of meshes. hull[b] = (first face, faces, first edge, edges, first edge
    # direction, edge directions) into the next four tables; zero counts for other shapes.
    hull: np.ndarray  # int64[nb, 6]
    planes: np.ndarray  # float64[nf, 4] outward unit face normal n and offset d: the body is n.x <= d
    face_verts: np.ndarray  # int64[nf, 1 + w]: vertex count k, then k indices into verts, counterclockwise about n
    edges: np.ndarray  # int64[ne, 2] end points of each hull edge, indices into verts
    edge_dirs: np.ndarray  # float64[nd, 3] distinct unit edge directions (up to sign)
    # The same data packed into four tables for the hot paths: numba increfs every array of
    # a tuple that crosses a function boundary, so hot code passes these few instead of S.
    bi: np.ndarray  # int64[nb, BI_COLUMNS]: kind, vstart, vcount, qmap (8), vmap (7)
    bf: np.ndarray  # float64[nb, BF_COLUMNS]: radius, half extents, hs normal, hs offset, base pos, base quat, mass, inertia, bound,
    #                 scripted pose at t = 0 and velocity, speed bound of a scripted body, principal axes and their flag
    pi: np.ndarray  # int64[np, 4]: a, b, max contacts, inert (1: the pair can never matter; see inert_pairs)
    pf: np.ndarray  # float64[np, 3]: mu, K, C


def _quat_z(theta: float) -> np.ndarray:
    return np.array([np.cos(theta / 2), 0.0, 0.0, np.sin(theta / 2)])


#: A polytope against a plane keeps at most its deepest vertex and, of its vertices within
#: `PLANE_SUPPORT_BAND` of that depth, the farthest in each of this many directions along the
#: plane (`models.contact3d._plane_shape`): a 200-vertex pebble had made 100 contacts a step.
PLANE_SUPPORT_DIRECTIONS = 8
#: How far above the deepest vertex (m) a polytope's vertex still counts as bearing on a plane.
PLANE_SUPPORT_BAND = 1e-3


def _max_contacts(kind_a: int, count_a: int, kind_b: int, count_b: int, dimension: int) -> int:
    if kind_a == SHAPE_HALFSPACE or kind_b == SHAPE_HALFSPACE:
        count = count_b if kind_a == SHAPE_HALFSPACE else count_a
        return min(count, PLANE_SUPPORT_DIRECTIONS + 1) if dimension == 3 else count
    if dimension == 2:
        return 1 if min(count_a, count_b) == 1 else 2
    if SHAPE_SPHERE in (kind_a, kind_b):
        return 1
    if kind_a == SHAPE_CAPSULE and kind_b == SHAPE_CAPSULE:
        return 2
    return 4


#: Hull triangles whose unit normals differ by less than this (and offsets relative to the
#: size) are one face; edge directions closer than this are one direction.
COPLANAR_TOL = 1e-9


def hull_tables(core: np.ndarray):
    """Faces, edges and distinct edge directions of the convex hull of core points (k, 3).

    Returns (planes (nf, 4): outward unit normal, offset; loops: list of vertex index lists,
    counterclockwise about the normal; edges (ne, 2); dirs (nd, 3)), with indices into core.
    Coplanar hull triangles are merged, so a quad face gives one plane and four edges.
    """
    from scipy.spatial import ConvexHull

    core = np.asarray(core, float)
    hull = ConvexHull(core)
    scale = float(np.max(np.linalg.norm(core - core.mean(axis=0), axis=1)))
    eq = hull.equations  # n.x + c <= 0 inside
    nt = len(hull.simplices)
    parent = list(range(nt))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(nt):
        for j in hull.neighbors[i]:
            if np.dot(eq[i, :3], eq[j, :3]) > 1.0 - COPLANAR_TOL and abs(eq[i, 3] - eq[j, 3]) <= COPLANAR_TOL * scale:
                parent[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for i in range(nt):
        groups.setdefault(find(i), []).append(i)
    planes, loops = [], []
    for tris in groups.values():
        n = eq[tris, :3].mean(axis=0)
        n /= np.linalg.norm(n)
        idx = sorted({int(v) for t in tris for v in hull.simplices[t]})
        pts = core[idx]
        d = float(np.max(pts @ n))
        # counterclockwise about n: angles in a basis (t, o) with t x o = n
        t = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        t /= np.linalg.norm(t)
        o = np.cross(n, t)
        rel = pts - pts.mean(axis=0)
        order = np.argsort(np.arctan2(rel @ o, rel @ t))
        planes.append([*n, d])
        loops.append([idx[k] for k in order])
    edges = sorted({tuple(sorted((lp[k], lp[(k + 1) % len(lp)]))) for lp in loops for k in range(len(lp))})
    # distinct directions, the first of each kept: compared with numpy against those kept so far
    # (a loop over them in Python took 41 s for a 2,000-vertex mesh)
    pairs = np.array(edges, np.int64).reshape(-1, 2)
    units = core[pairs[:, 1]] - core[pairs[:, 0]]
    units /= np.linalg.norm(units, axis=1)[:, None]
    dirs = np.empty_like(units)
    nd = 0
    for u in units:
        if nd == 0 or np.max(np.abs(dirs[:nd] @ u)) <= 1.0 - COPLANAR_TOL:
            dirs[nd] = u
            nd += 1
    return (np.array(planes, float).reshape(-1, 4), loops, pairs, dirs[:nd].copy())


def _shape_tables(scenario: Scenario):
    """Per-body shape tables: kind, core-point ranges (vstart, vcount), core points, radius,
    box half extents, half-space normal and offset, and bounding radius (inf for half-spaces).
    """
    dim = scenario.dimension
    bodies = scenario.spec.bodies
    nb = len(bodies)
    kind = np.zeros(nb, np.int64)
    vstart = np.zeros(nb, np.int64)
    vcount = np.zeros(nb, np.int64)
    verts_list: list[np.ndarray] = []
    radius = np.zeros(nb)
    half_extents = np.zeros((nb, 3))
    hs_normal = np.zeros((nb, dim))
    hs_offset = np.zeros(nb)
    bound = np.zeros(nb)
    offset = 0
    for b, body in enumerate(bodies):
        g = scenario.geometries[body.name]
        core = np.asarray(g.core, float).reshape(-1, dim)
        if g.kind == "halfspace":
            kind[b] = SHAPE_HALFSPACE
            hs_normal[b] = g.normal
            hs_offset[b] = g.offset
            bound[b] = np.inf
        elif dim == 2:
            kind[b] = SHAPE_POINTS
        else:
            kind[b] = {"sphere": SHAPE_SPHERE, "capsule": SHAPE_CAPSULE, "box": SHAPE_BOX, "mesh": SHAPE_MESH}[body.shape.type]
            if body.shape.type == "box":
                half_extents[b] = 0.5 * np.asarray(body.shape.size)
        radius[b] = g.radius
        vstart[b], vcount[b] = offset, len(core)
        verts_list.append(core)
        offset += len(core)
        if g.kind != "halfspace":
            bound[b] = (np.max(np.linalg.norm(core, axis=1)) if len(core) else 0.0) + g.radius
    verts = np.concatenate(verts_list) if verts_list else np.zeros((0, dim))
    return kind, vstart, vcount, verts, radius, half_extents, hs_normal, hs_offset, bound


def _scene_hulls(scenario: Scenario, kind, vstart):
    """Hull tables of the boxes and meshes (spatial scenes): per-body ranges hull (nb, 6) and
    the stacked planes, face vertex loops (face_verts), edges and edge directions, with vertex
    indices into the scene's stacked core points.
    """
    dim = scenario.dimension
    nb = len(kind)
    hull = np.zeros((nb, 6), np.int64)
    planes_list: list[np.ndarray] = []
    loops_list: list[list[int]] = []
    edges_list: list[np.ndarray] = []
    dirs_list: list[np.ndarray] = []
    for b, body in enumerate(scenario.spec.bodies):
        if not (dim == 3 and kind[b] in (SHAPE_BOX, SHAPE_MESH)):
            continue
        core = np.asarray(scenario.geometries[body.name].core, float).reshape(-1, dim)
        offset = vstart[b]
        planes, loops, edges, dirs = hull_tables(core)
        hull[b] = [sum(map(len, planes_list)), len(planes), sum(map(len, edges_list)), len(edges), sum(map(len, dirs_list)), len(dirs)]
        planes_list.append(planes)
        loops_list += [[offset + k for k in lp] for lp in loops]
        edges_list.append(edges + offset)
        dirs_list.append(dirs)
    width = max((len(lp) for lp in loops_list), default=0)
    face_verts = np.zeros((len(loops_list), 1 + width), np.int64)
    for f, lp in enumerate(loops_list):
        face_verts[f, 0] = len(lp)
        face_verts[f, 1 : 1 + len(lp)] = lp
    planes = np.ascontiguousarray(np.concatenate(planes_list) if planes_list else np.zeros((0, 4)))
    edges = np.ascontiguousarray(np.concatenate(edges_list) if edges_list else np.zeros((0, 2), np.int64))
    edge_dirs = np.ascontiguousarray(np.concatenate(dirs_list) if dirs_list else np.zeros((0, 3)))
    return hull, planes, face_verts, edges, edge_dirs


def _index_maps(scenario: Scenario):
    """Per-body index maps: qmap (nb, 8) and vmap (nb, 7), the q and nu indices of each
    body's free coordinates (-1 where not free; see the module docstring)."""
    dim = scenario.dimension
    bodies = scenario.spec.bodies
    nb = len(bodies)
    qmap = -np.ones((nb, 8), np.int64)
    vmap = -np.ones((nb, 7), np.int64)
    q_index = {name: i for i, name in enumerate(scenario.coordinates)}
    v_index = {name: i for i, name in enumerate(scenario.velocities)}
    for b, body in enumerate(bodies):
        for col, name in enumerate(("x", "y", "z")):
            key = f"{body.name}.{name}"
            if key in q_index:
                qmap[b, col] = q_index[key]
                vmap[b, col] = v_index[key]
        angle = f"{body.name}.{'theta' if dim == 2 else 'yaw'}"
        if angle in q_index:
            qmap[b, Q_ANGLE] = q_index[angle]
            vmap[b, V_ANGLE] = v_index[angle]
        if f"{body.name}.qw" in q_index:
            for k, c in enumerate("wxyz"):
                qmap[b, Q_QW + k] = q_index[f"{body.name}.q{c}"]
            for k, c in enumerate("xyz"):
                vmap[b, V_WX + k] = v_index[f"{body.name}.w{c}"]
    return qmap, vmap


def _poses_and_inertia(scenario: Scenario, bound):
    """Per-body poses and mass properties: base pose (position, quaternion), the scripted
    motion of moving obstacles (pose at t = 0, velocity, speed bound from the bounding radius),
    mass and principal moments of inertia (zero for bodies without DOFs) and, for a body whose
    principal axes are not its own, those axes (`principal_inertia`; BF_AXES, BF_TILTED)."""
    dim = scenario.dimension
    bodies = scenario.spec.bodies
    nb = len(bodies)
    base_pos = np.zeros((nb, 3))
    base_quat = np.zeros((nb, 4))
    mass = np.zeros(nb)
    inertia = np.zeros((nb, 3))
    axes = np.zeros((nb, BF_COLUMNS - BF_AXES))
    script = np.zeros((nb, 9))
    for b, body in enumerate(bodies):
        placement = scenario.base_placements[body.name]
        base_pos[b, :dim] = placement.translation
        if dim == 2:
            base_quat[b] = _quat_z(float(body.pose.theta or 0.0))
        else:
            base_quat[b] = _rotation_to_quat(placement.rotation)
        if body.velocity:
            script[b, :3] = base_pos[b]
            script[b, 3] = float(body.pose.theta or 0.0) if dim == 2 else 0.0
            for col, name in enumerate(("x", "y", "z", "theta")):
                script[b, 4 + col] = float(body.velocity.get(name, 0.0))
            omega = abs(script[b, 7])
            script[b, 8] = float(np.linalg.norm(script[b, 4:7])) + (omega * bound[b] if omega > 0.0 else 0.0)
        if body.dofs:
            mass[b] = body.mass
            if body.inertia is not None and dim == 2:
                inertia[b] = [0.0, 0.0, body.inertia[0]]
            elif body.inertia is not None:
                inertia[b], principal = principal_inertia(body)
                if principal is not None:
                    axes[b, :9], axes[b, 9] = principal.ravel(), 1.0
    return base_pos, base_quat, mass, inertia, script, axes


def _pair_tables(scenario: Scenario, kind, vcount):
    """Per-pair tables: body indices a and b, the most contacts the pair can produce at once,
    and the contact parameters pf (np, 3): mu, K, C."""
    names = [b.name for b in scenario.spec.bodies]
    pairs = scenario.pairs
    pair_a = np.array([names.index(p.body_a) for p in pairs], np.int64)
    pair_b = np.array([names.index(p.body_b) for p in pairs], np.int64)
    max_contacts = np.array(
        [_max_contacts(kind[a], vcount[a], kind[b], vcount[b], scenario.dimension) for a, b in zip(pair_a, pair_b)], np.int64
    )
    pf = np.array([[p.mu, p.K, p.C] for p in pairs], float).reshape(-1, 3)
    return pair_a, pair_b, max_contacts, pf


def kernel_array(a) -> np.ndarray:
    """a as the compiled kernels take an array from Python: float64, C-contiguous and writeable
    (copied only when it is not). A scenario's start is read-only, and numba compiles a kernel
    once more for every read-only argument type it meets."""
    return np.require(a, np.float64, "CW")


def compile_scene(scenario: Scenario) -> SceneData:
    """Pack a validated scenario into arrays for the compiled kernels."""
    dim = scenario.dimension
    nb = len(scenario.spec.bodies)
    kind, vstart, vcount, verts, radius, half_extents, hs_normal, hs_offset, bound = _shape_tables(scenario)
    hull, planes, face_verts, edges, edge_dirs = _scene_hulls(scenario, kind, vstart)
    qmap, vmap = _index_maps(scenario)
    base_pos, base_quat, mass, inertia, script, axes = _poses_and_inertia(scenario, bound)
    pairs = scenario.pairs
    pair_a, pair_b, max_contacts, pf = _pair_tables(scenario, kind, vcount)
    bi = np.concatenate([kind[:, None], vstart[:, None], vcount[:, None], qmap, vmap], axis=1).astype(np.int64)
    normals3 = np.zeros((nb, 3))
    normals3[:, :dim] = hs_normal
    bf = np.concatenate(
        [radius[:, None], half_extents, normals3, hs_offset[:, None], base_pos, base_quat, mass[:, None], inertia, bound[:, None]]
        + [script, axes],
        axis=1,
    )
    assert bi.shape[1] == BI_COLUMNS and bf.shape[1] == BF_COLUMNS
    return SceneData(
        dimension=dim,
        nq=len(scenario.coordinates),
        nv=len(scenario.velocities),
        kind=kind,
        vstart=vstart,
        vcount=vcount,
        verts=np.ascontiguousarray(verts, dtype=np.float64),
        radius=radius,
        half_extents=half_extents,
        hs_normal=hs_normal,
        hs_offset=hs_offset,
        base_pos=base_pos,
        base_quat=base_quat,
        qmap=qmap,
        vmap=vmap,
        mass=mass,
        inertia=inertia,
        bound_radius=bound,
        pair_a=pair_a,
        pair_b=pair_b,
        pair_mu=np.array([p.mu for p in pairs], float),
        pair_K=np.array([p.K for p in pairs], float),
        pair_C=np.array([p.C for p in pairs], float),
        pair_max_contacts=max_contacts,
        hull=hull,
        planes=planes,
        face_verts=face_verts,
        edges=edges,
        edge_dirs=edge_dirs,
        bi=np.ascontiguousarray(bi),
        bf=np.ascontiguousarray(bf),
        pi=np.ascontiguousarray(
            np.stack([pair_a, pair_b, max_contacts, inert_pairs(scenario, pair_a, pair_b, bound)], axis=1).reshape(-1, 4).astype(np.int64)
        ),
        pf=np.ascontiguousarray(pf),
    )


#: Bodies whose fixed separation exceeds their bounding radii by this much never meet (m).
NEVER_MEET_MARGIN = 1e-2


def inert_pairs(scenario: Scenario, pair_a, pair_b, bound) -> np.ndarray:
    """1 for contact pairs that can never change the motion, which detection then skips:

    - a fixed half-space against a body that only translates, along axes parallel to the
      boundary (the triangle sliding on the palm): psi never changes, W_n is zero;
    - two bodies that only translate, whose separation across all their free axes exceeds
      their bounding radii (two fingers moving vertically side by side).

    Touch predicates can still ask for such a pair: `models.rungs` clears the flag for them.
    """
    dim = scenario.dimension
    bodies = scenario.spec.bodies
    flags = np.zeros(len(pair_a), np.int64)
    for p, (a, b) in enumerate(zip(pair_a, pair_b)):
        A, B = bodies[a], bodies[b]
        if A.velocity or B.velocity:
            continue  # scripted obstacles move in ways the DOFs do not say
        if any(d in ("theta", "yaw", "rotation") for d in A.dofs + B.dofs):
            continue
        free = {"xyz".index(d) for d in A.dofs + B.dofs}
        ga, gb = scenario.geometries[A.name], scenario.geometries[B.name]
        if ga.kind == "halfspace" or gb.kind == "halfspace":
            h = A if ga.kind == "halfspace" else B
            g = ga if ga.kind == "halfspace" else gb
            normal = scenario.base_placements[h.name].rotation @ g.normal
            flags[p] = int(all(abs(normal[k]) < 1e-12 for k in free))
            continue
        pa = scenario.base_placements[A.name].translation
        pb = scenario.base_placements[B.name].translation
        fixed = [k for k in range(dim) if k not in free]
        separation = float(np.linalg.norm([pa[k] - pb[k] for k in fixed])) if fixed else 0.0
        flags[p] = int(separation > bound[a] + bound[b] + NEVER_MEET_MARGIN)
    return flags


def _rotation_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method)."""
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    return q / np.linalg.norm(q)


# ----------------------------------------------------------------------------- compiled helpers


@numba.njit(cache=True)
def quat_mul(a, b):
    """Hamilton product of (w, x, y, z) quaternions."""
    d0, d1, d2, d3 = quat_mul_scalars(a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3])
    return np.array([d0, d1, d2, d3])


@numba.njit(cache=True, inline="always")
def quat_mul_scalars(a0, a1, a2, a3, b0, b1, b2, b3):
    """`quat_mul` of quaternions given and returned as four scalars each."""
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


@numba.njit(cache=True)
def quat_to_matrix(q):
    R = np.empty((3, 3))
    quat_matrix_into(q[0], q[1], q[2], q[3], R)
    return R


@numba.njit(cache=True, inline="always")
def quat_matrix_into(w, x, y, z, R):
    """`quat_to_matrix` of (w, x, y, z) into the caller's R (3, 3)."""
    R[0, 0] = 1 - 2 * (y * y + z * z)
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = 1 - 2 * (x * x + z * z)
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = 1 - 2 * (x * x + y * y)


@numba.njit(cache=True)
def body_pose_3d(S, q, b):
    """(position (3,), rotation matrix (3, 3)) of spatial body b at configuration q."""
    p = S.base_pos[b].copy()
    for k in range(3):
        if S.qmap[b, k] >= 0:
            p[k] = q[S.qmap[b, k]]
    if S.qmap[b, Q_QW] >= 0:
        quat = np.empty(4)
        for k in range(4):
            quat[k] = q[S.qmap[b, Q_QW + k]]
        quat /= np.sqrt(np.sum(quat * quat))
    elif S.qmap[b, Q_ANGLE] >= 0:
        yaw = q[S.qmap[b, Q_ANGLE]]
        quat = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
    else:
        quat = S.base_quat[b].copy()
    return p, quat_to_matrix(quat)


def G_matrix(S: SceneData, q: np.ndarray) -> np.ndarray:
    """G(q), (nq, nv): q_dot = G(q) nu. Identity except 1/2 [0, w] (x) quat blocks."""
    G = np.zeros((S.nq, S.nv))
    for b in range(len(S.kind)):
        for k in range(4):
            if S.qmap[b, k] >= 0:
                G[S.qmap[b, k], S.vmap[b, k]] = 1.0
        if S.qmap[b, Q_QW] >= 0:
            w, x, y, z = (q[S.qmap[b, Q_QW + k]] for k in range(4))
            # d quat / dt = 1/2 [0, omega] (x) quat, omega in the world frame
            block = 0.5 * np.array([[-x, -y, -z], [w, z, -y], [-z, w, x], [y, -x, w]])
            for r in range(4):
                for c in range(3):
                    G[S.qmap[b, Q_QW + r], S.vmap[b, V_WX + c]] = block[r, c]
    return G


@numba.njit(cache=True, inline="always")
def _planar_position(bi, bf, q, b):
    """Body b's (x, y) at q: its coordinates where free, else its base position's."""
    x = bf[b, BF_POS]
    y = bf[b, BF_POS + 1]
    if bi[b, BI_QMAP + Q_X] >= 0:
        x = q[bi[b, BI_QMAP + Q_X]]
    if bi[b, BI_QMAP + Q_Y] >= 0:
        y = q[bi[b, BI_QMAP + Q_Y]]
    return x, y


@numba.njit(cache=True, inline="always")
def _quaternion_angle(z, w):
    """The angle about z of a base quaternion (w, 0, 0, z): a planar body's theta where it has
    no angle coordinate."""
    return 2.0 * np.arctan2(z, w)


# without numba's runtime: a per-step call whose array arguments are not reference-counted
@numba.njit(cache=True, _nrt=False)
def planar_poses(bi, bf, q, poses):
    """Fill poses (nb, 4) with (x, y, cos theta, sin theta) of every planar body at q."""
    for b in range(bi.shape[0]):
        theta = _quaternion_angle(bf[b, BF_QUAT + 3], bf[b, BF_QUAT])
        if bi[b, BI_QMAP + Q_ANGLE] >= 0:
            theta = q[bi[b, BI_QMAP + Q_ANGLE]]
        poses[b, 0], poses[b, 1] = _planar_position(bi, bf, q, b)
        poses[b, 2] = np.cos(theta)
        poses[b, 3] = np.sin(theta)


#: Columns of the planar detection's poses (`models.contact.planar_scratch`): (x, y, cos theta,
#: sin theta) as `planar_poses` writes them, then the two numbers the cos and sin were computed
#: from (`planar_poses_kept`).
KEPT_POSE_COLUMNS = 6


@numba.njit(cache=True, inline="always")
def _same_number(a, b):
    """a and b the same number, the sign of a zero included (sin(-0.0) is -0.0); never for NaN."""
    return a == b and np.copysign(1.0, a) == np.copysign(1.0, b)


# without numba's runtime: a per-step call whose array arguments are not reference-counted
@numba.njit(cache=True, _nrt=False)
def planar_poses_kept(bi, bf, q, poses):
    """`planar_poses` into poses (nb, KEPT_POSE_COLUMNS) that carry over from step to step (the
    detection's scratch): a body's cos theta and sin theta are computed again only where what
    theta comes from changed since (its angle coordinate; for a body without one, the two
    entries of its base quaternion, which a scripted obstacle's script moves), kept in columns
    4 and 5 (NaN at first: computed on the first call). A body that does not turn pays no
    trigonometry, where the paper's scene spent about 70 ns a step on four bodies that never
    turn; the same values as `planar_poses`, bit for bit."""
    for b in range(bi.shape[0]):
        poses[b, 0], poses[b, 1] = _planar_position(bi, bf, q, b)
        turning = bi[b, BI_QMAP + Q_ANGLE] >= 0
        k0, k1 = 0.0, 0.0
        if turning:
            k0 = q[bi[b, BI_QMAP + Q_ANGLE]]
        else:
            k0, k1 = bf[b, BF_QUAT + 3], bf[b, BF_QUAT]
        if not (_same_number(poses[b, 4], k0) and _same_number(poses[b, 5], k1)):
            theta = k0 if turning else _quaternion_angle(k0, k1)
            poses[b, 2] = np.cos(theta)
            poses[b, 3] = np.sin(theta)
            poses[b, 4], poses[b, 5] = k0, k1


# without numba's runtime: a per-step call whose array arguments are not reference-counted
@numba.njit(cache=True, _nrt=False)
def positions(bi, bf, q, out):
    """Fill out (nb, 3) with every body's origin at q (planar: z = 0)."""
    for b in range(bi.shape[0]):
        for k in range(3):
            out[b, k] = bf[b, BF_POS + k]
            if bi[b, BI_QMAP + k] >= 0:
                out[b, k] = q[bi[b, BI_QMAP + k]]

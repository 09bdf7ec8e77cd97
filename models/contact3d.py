"""Compiled spatial (3D) contact detection: the contacts of one pair at configuration q.

Convention (``models.kinematics``): a contact of pair p = (A, B) = (S.pair_a[p], S.pair_b[p])
has a unit world normal n pointing from A to B, a point pa on A's surface and pb on B's
surface (world frame) with pb - pa = psi n, where psi is the signed distance along n
(negative: penetration depth). Every contact written satisfies these exactly (to rounding),
and the smallest psi of a pair is the pair's signed distance.

`collide_pair_3d` (compiled) supports:

- plane vs sphere / capsule / box / mesh: one contact per core point (sphere centre, capsule
  end, box corner, mesh vertex) within the margin: exact for polyhedra (a box resting flat
  gives 4 contacts, a capsule lying flat 2); a mesh with more than 9 vertices within the
  margin keeps 9 at most, its deepest and the corners of its support polygon in 8 directions
  (`_plane_support`);
- sphere-sphere, sphere-capsule, capsule-capsule (closest points of the axes; nearly
  parallel overlapping axes give two contacts, at the ends of the overlap), sphere-box (the
  deepest-face rule inside);
- capsule-box (segment vs box: closest features when apart, separating axes over the three
  faces and three edge crossings when the axis cuts the box; an axis nearly parallel to the
  face in contact gives two contacts, at the ends of the part of the axis over that face);
- box-box (separating axes over the 15 axes; a face axis gives the incident face clipped
  against the reference face's side planes, at most 4 points: the deepest, the farthest
  from it, then the two spanning the most area; an edge-edge axis gives one contact; boxes
  apart get their exact distance from their closest features when the faces do not show it);
- convex mesh vs box and mesh vs mesh (`_hull_hull`, both as polytopes from the hull tables
  `SceneData.hull/planes/face_verts/edges/edge_dirs`, built by `models.kinematics.hull_tables`
  at scene compile time: coplanar triangles merged into one face, distinct edge directions):
  separating axes over the face normals of both and the crossings of their edge directions.
  A face axis clips the other body's most opposed face against the reference face's side
  planes (plus that body's deepest vertex when it lies over the face and the clipped face
  missed it), reduced to at most 4 points like box-box; an edge-edge axis gives one contact
  at the support edges; apart, the exact distance comes from the closest features (a vertex
  against a face it projects into, or two edges, brute force) when the axes do not show it;
- convex mesh vs sphere (the core point vs the polytope: closest point when outside, the
  deepest-face rule inside) and mesh vs capsule (the axis vs the polytope: closest features
  when apart; separating axes over the faces and the crossings of the edge directions with
  the axis when it meets the polytope): one contact.

Where two contacts stand for a segment over a face (capsules), the point on the curved
surface is where the line along n leaves the capsule, so it is exactly on the surface even
when n is not the surface normal there, and the exact closest contact always replaces an
end contact that is shallower or deeper than it.

A pair returns -1 only when it has no compiled test (planar scenes, or a mesh or box without
hull tables): the caller may then use `fcl_pair_contacts` (python-fcl, one contact).
`collide_all_3d` does every pair of a scene in one call.

Performance notes: vectors are tuples of three floats and rotations tuples of rows, so the
compiled path allocates nothing but two small scratch arrays for face clipping (box-box, and
mesh-box / mesh-mesh face contacts). Calling a compiled function increments and decrements
the reference count of every array in its arguments (SceneData holds 30), a cost per
`collide_pair_3d` call comparable to the test itself (docs/measurements.md), which
`collide_all_3d` pays once per scene. Only mesh pairs get the hull tables (`_collide_hull`). Helper calls
never pass literal constants (numba would compile a specialised copy for each).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from models.kinematics import (
    PLANE_SUPPORT_BAND,
    PLANE_SUPPORT_DIRECTIONS,
    Q_ANGLE,
    Q_QW,
    Q_X,
    Q_Y,
    Q_Z,
    SHAPE_BOX,
    SHAPE_CAPSULE,
    SHAPE_HALFSPACE,
    SHAPE_MESH,
    SHAPE_SPHERE,
)

#: Two segments (capsule axes, or a capsule axis and a box face) whose directions make an
#: angle with sine below this count as parallel: they get two contacts, at the overlap ends.
PARALLEL_SIN = 1e-2
#: Overlaps of parallel segments shorter than this (relative to the segment) give one contact.
MIN_OVERLAP = 1e-6
#: Core points (sphere centres, capsule axes) closer than this (m) count as coincident: the
#: normal then comes from a fallback direction instead of their difference.
CORE_TOL = 1e-10
#: An edge-edge separating axis replaces the best face axis only if it is better by more
#: than this, relative to the size of the pair (ties go to faces: they give whole faces).
EDGE_AXIS_TOL = 1e-9
#: Cross products of unit edge directions shorter than this are parallel edges: skipped.
EDGE_PARALLEL = 1e-6
#: A contact found exactly replaces an overlap-end contact if it is deeper by more than this (m).
EXACT_TOL = 1e-12

_INF = np.inf


# ----------------------------------------------------------------------------- 3-vectors as tuples


@numba.njit(cache=True)
def _add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@numba.njit(cache=True)
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@numba.njit(cache=True)
def _scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@numba.njit(cache=True)
def _axpy(a, s, b):
    """a + s b."""
    return (a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2])


@numba.njit(cache=True)
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@numba.njit(cache=True)
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@numba.njit(cache=True)
def _norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@numba.njit(cache=True)
def _rot(R, v):
    """R v for a 3x3 matrix R given as a tuple of rows."""
    return (
        R[0][0] * v[0] + R[0][1] * v[1] + R[0][2] * v[2],
        R[1][0] * v[0] + R[1][1] * v[1] + R[1][2] * v[2],
        R[2][0] * v[0] + R[2][1] * v[1] + R[2][2] * v[2],
    )


@numba.njit(cache=True)
def _rot_t(R, v):
    """R^T v."""
    return (
        R[0][0] * v[0] + R[1][0] * v[1] + R[2][0] * v[2],
        R[0][1] * v[0] + R[1][1] * v[1] + R[2][1] * v[2],
        R[0][2] * v[0] + R[1][2] * v[1] + R[2][2] * v[2],
    )


@numba.njit(cache=True)
def _col(R, j):
    return (R[0][j], R[1][j], R[2][j])


@numba.njit(cache=True)
def _transpose(M):
    return ((M[0][0], M[1][0], M[2][0]), (M[0][1], M[1][1], M[2][1]), (M[0][2], M[1][2], M[2][2]))


@numba.njit(cache=True)
def _mat_t_mul(A, B):
    """A^T B."""
    c0 = _rot_t(A, (B[0][0], B[1][0], B[2][0]))
    c1 = _rot_t(A, (B[0][1], B[1][1], B[2][1]))
    c2 = _rot_t(A, (B[0][2], B[1][2], B[2][2]))
    return ((c0[0], c1[0], c2[0]), (c0[1], c1[1], c2[1]), (c0[2], c1[2], c2[2]))


@numba.njit(cache=True)
def _pose(S, q, b):
    """(position, rotation as a tuple of rows) of spatial body b at q, without allocating:
    the same pose as models.kinematics.body_pose_3d."""
    return pose_of(S.qmap, S.base_pos, S.base_quat, q, b)


@numba.njit(cache=True, inline="always")
def pose_of(qm, base_pos, base_quat, q, b):
    """`_pose` on the three arrays it reads (qmap, base_pos, base_quat of `SceneData`): for
    callers in a per-pair loop, where passing the whole scene would reference-count its ~30
    arrays on every pass."""
    px = base_pos[b, 0] if qm[b, Q_X] < 0 else q[qm[b, Q_X]]
    py = base_pos[b, 1] if qm[b, Q_Y] < 0 else q[qm[b, Q_Y]]
    pz = base_pos[b, 2] if qm[b, Q_Z] < 0 else q[qm[b, Q_Z]]
    if qm[b, Q_QW] >= 0:
        w, x, y, z = q[qm[b, Q_QW]], q[qm[b, Q_QW + 1]], q[qm[b, Q_QW + 2]], q[qm[b, Q_QW + 3]]
        inv = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w * inv, x * inv, y * inv, z * inv
    elif qm[b, Q_ANGLE] >= 0:
        yaw = q[qm[b, Q_ANGLE]]
        w, x, y, z = math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)
    else:
        w, x, y, z = base_quat[b, 0], base_quat[b, 1], base_quat[b, 2], base_quat[b, 3]
    R = (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )
    return (px, py, pz), R


@numba.njit(cache=True)
def _unit(k):
    if k == 0:
        return (1.0, 0.0, 0.0)
    if k == 1:
        return (0.0, 1.0, 0.0)
    return (0.0, 0.0, 1.0)


@numba.njit(cache=True)
def _with(a, k, value):
    """a with component k replaced by value."""
    if k == 0:
        return (value, a[1], a[2])
    if k == 1:
        return (a[0], value, a[2])
    return (a[0], a[1], value)


@numba.njit(cache=True)
def _clamp01(x):
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


@numba.njit(cache=True)
def _sign(x):
    return -1.0 if x < 0.0 else 1.0


@numba.njit(cache=True)
def _basis(n):
    """Orthonormal t, o with (t, o, n) right-handed (Duff et al. 2017, branchless Frisvad)."""
    s = 1.0 if n[2] >= 0.0 else -1.0
    a = -1.0 / (s + n[2])
    b = n[0] * n[1] * a
    t = (1.0 + s * n[0] * n[0] * a, s * b, -s * n[0])
    o = (b, s + n[1] * n[1] * a, -n[1])
    return t, o


@numba.njit(cache=True)
def tangent_basis(n):
    """(t, o): unit vectors, perpendicular to the unit vector n and to each other, t x o = n.

    Duff, Burgess, Christensen, Hery, Kensler, Liani, Villemin, "Building an orthonormal basis,
    revisited" (JCGT 2017): continuous in n except across n_z = 0 with n_z < 0 on one side.
    """
    t, o = _basis((n[0], n[1], n[2]))
    return np.array([t[0], t[1], t[2]]), np.array([o[0], o[1], o[2]])


# ----------------------------------------------------------------------------- closest points


@numba.njit(cache=True)
def _seg_seg(p1, q1, p2, q2):
    """Parameters (s, t) of closest points p1 + s (q1 - p1), p2 + t (q2 - p2) (Ericson 5.1.9)."""
    d1 = _sub(q1, p1)
    d2 = _sub(q2, p2)
    r = _sub(p1, p2)
    a = _dot(d1, d1)
    e = _dot(d2, d2)
    f = _dot(d2, r)
    if a <= 1e-30 and e <= 1e-30:
        return 0.0, 0.0
    if a <= 1e-30:
        return 0.0, _clamp01(f / e)
    c = _dot(d1, r)
    if e <= 1e-30:
        return _clamp01(-c / a), 0.0
    b = _dot(d1, d2)
    denom = a * e - b * b
    s = _clamp01((b * f - c * e) / denom) if denom > 1e-14 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t = 0.0
        s = _clamp01(-c / a)
    elif t > 1.0:
        t = 1.0
        s = _clamp01((b - c) / a)
    return s, t


@numba.njit(cache=True)
def _point_seg(x, a, b):
    """Parameter of the point of segment ab closest to x."""
    d = _sub(b, a)
    dd = _dot(d, d)
    if dd <= 1e-30:
        return 0.0
    return _clamp01(_dot(_sub(x, a), d) / dd)


@numba.njit(cache=True)
def _point_box(y, h):
    """Point y vs box [-h, h] (box frame): (signed distance, surface point, outward unit normal).

    Outside: the clamped point and the direction to y. Inside or on the surface: the nearest
    face (the deepest-face rule), distance minus the depth.
    """
    c0 = min(max(y[0], -h[0]), h[0])
    c1 = min(max(y[1], -h[1]), h[1])
    c2 = min(max(y[2], -h[2]), h[2])
    d = (y[0] - c0, y[1] - c1, y[2] - c2)
    dist = _norm(d)
    if dist > 0.0:
        return dist, (c0, c1, c2), _scale(d, 1.0 / dist)
    best = _INF
    k = np.int64(0)
    sg = 1.0
    for i in range(3):
        up = h[i] - y[i]
        down = h[i] + y[i]
        if up < best:
            best, k, sg = up, i, 1.0
        if down < best:
            best, k, sg = down, i, -1.0
    return -best, _with(y, k, sg * h[k]), _scale(_unit(k), sg)


@numba.njit(cache=True)
def _capsule_exit(x, m, a0, a1, r):
    """Largest T >= 0 with x + T m in the capsule (segment a0 a1, radius r); x on the segment, |m| = 1.

    The capsule is convex, so the ray from x leaves it where the last of its pieces (two balls,
    the finite cylinder) does.
    """
    best = 0.0
    for end in range(2):
        c = a0 if end == 0 else a1
        w = _sub(x, c)
        wm = _dot(w, m)
        disc = wm * wm - (_dot(w, w) - r * r)
        if disc >= 0.0:
            best = max(best, -wm + math.sqrt(disc))
    d = _sub(a1, a0)
    L2 = _dot(d, d)
    if L2 > 1e-30:
        L = math.sqrt(L2)
        u = _scale(d, 1.0 / L)
        w = _sub(x, a0)
        wu = _dot(w, u)
        mu = _dot(m, u)
        wp = _axpy(w, -wu, u)
        mp = _axpy(m, -mu, u)
        A = _dot(mp, mp)
        B = _dot(wp, mp)
        C = _dot(wp, wp) - r * r
        if A > 1e-300:
            disc = B * B - A * C
            tc = (-B + math.sqrt(disc)) / A if disc >= 0.0 else -1.0
        else:
            tc = _INF if C <= 0.0 else -1.0
        if mu > 0.0:
            ts = (L - wu) / mu
        elif mu < 0.0:
            ts = wu / (-mu)
        else:
            ts = _INF
        best = max(best, min(tc, ts))
    return best


@numba.njit(cache=True)
def _rounded(c1, c2, r1, r2, nf):
    """Contact of two rounded cores from their closest core points c1, c2 (nf: normal if they coincide)."""
    d = _sub(c2, c1)
    L = _norm(d)
    if L > CORE_TOL:
        n = _scale(d, 1.0 / L)
        return L - r1 - r2, n, _axpy(c1, r1, n), _axpy(c2, -r2, n)
    return -r1 - r2, nf, _axpy(c1, r1, nf), _axpy(c1, -r2, nf)


@numba.njit(cache=True)
def _perpendicular(u):
    """A unit vector perpendicular to the (non-zero) vector u."""
    L = _norm(u)
    t, _ = _basis(_scale(u, 1.0 / L))
    return t


# ----------------------------------------------------------------------------- output


@numba.njit(cache=True)
def _emit(c_psi, c_n, c_pa, c_pb, k, psi, n, p1, p2, flip):
    """Write a contact found from body 1 (point p1) to body 2 (p2); flip: body 1 is the pair's B."""
    c_psi[k] = psi
    if flip:
        for i in range(3):
            c_n[k, i] = -n[i]
            c_pa[k, i] = p2[i]
            c_pb[k, i] = p1[i]
    else:
        for i in range(3):
            c_n[k, i] = n[i]
            c_pa[k, i] = p1[i]
            c_pb[k, i] = p2[i]


@numba.njit(cache=True)
def _store(buf, k, psi, n, p1, p2):
    buf[k, 0] = psi
    for i in range(3):
        buf[k, 1 + i] = n[i]
        buf[k, 4 + i] = p1[i]
        buf[k, 7 + i] = p2[i]


@numba.njit(cache=True)
def _row_point(buf, k):
    return (buf[k, 7], buf[k, 8], buf[k, 9])


@numba.njit(cache=True)
def _reduce_emit(buf, m, limit, c_psi, c_n, c_pa, c_pb, start, flip):
    """Write at most `limit` of the m contacts in buf: all if they fit, else the deepest, the
    farthest from it, the one spanning the largest triangle with them, and the one adding the
    most area to that triangle."""
    if m <= limit:
        for k in range(m):
            _emit(
                c_psi,
                c_n,
                c_pa,
                c_pb,
                start + k,
                buf[k, 0],
                (buf[k, 1], buf[k, 2], buf[k, 3]),
                (buf[k, 4], buf[k, 5], buf[k, 6]),
                (buf[k, 7], buf[k, 8], buf[k, 9]),
                flip,
            )
        return m
    i0 = np.int64(0)
    for k in range(1, m):
        if buf[k, 0] < buf[i0, 0]:
            i0 = k
    P0 = _row_point(buf, i0)
    i1 = np.int64(-1)
    best = -1.0
    for k in range(m):
        if k != i0:
            d = _sub(_row_point(buf, k), P0)
            v = _dot(d, d)
            if v > best:
                best, i1 = v, k
    P1 = _row_point(buf, i1)
    e01 = _sub(P1, P0)
    i2 = np.int64(-1)
    best = -1.0
    for k in range(m):
        if k != i0 and k != i1:
            c = _cross(e01, _sub(_row_point(buf, k), P0))
            v = _dot(c, c)
            if v > best:
                best, i2 = v, k
    i3 = np.int64(-1)
    if i2 < 0:
        m = np.int64(0)  # fewer than three points: no fourth to look for
    P2 = _row_point(buf, max(i2, 0))
    N = _cross(e01, _sub(P2, P0))
    best = 0.0
    for k in range(m):
        if k != i0 and k != i1 and k != i2:
            P = _row_point(buf, k)
            added = 0.0
            for e in range(3):
                A = P0 if e == 0 else (P1 if e == 1 else P2)
                B = P1 if e == 0 else (P2 if e == 1 else P0)
                side = -_dot(_cross(_sub(B, A), _sub(P, A)), N)
                if side > 0.0:
                    added += side
            if added > best:
                best, i3 = added, k
    count = np.int64(0)
    for j in range(min(limit, 4)):
        k = i0 if j == 0 else (i1 if j == 1 else (i2 if j == 2 else i3))
        if k < 0:
            continue
        _emit(
            c_psi,
            c_n,
            c_pa,
            c_pb,
            start + count,
            buf[k, 0],
            (buf[k, 1], buf[k, 2], buf[k, 3]),
            (buf[k, 4], buf[k, 5], buf[k, 6]),
            (buf[k, 7], buf[k, 8], buf[k, 9]),
            flip,
        )
        count += 1
    return count


# ----------------------------------------------------------------------------- plane vs shape


@numba.njit(cache=True)
def _core_point(verts, i, p, R):
    """World position of core point verts[i] of a body at (p, R)."""
    v = _rot(R, (verts[i, 0], verts[i, 1], verts[i, 2]))
    return (v[0] + p[0], v[1] + p[1], v[2] + p[2])


@numba.njit(cache=True)
def _plane_shape(nh, off, kind, po, Ro, r, verts, v0, nv, flip, margin, c_psi, c_n, c_pa, c_pb, start, limit):
    """World plane n.x <= off vs the core points verts[v0:v0 + nv] of a body at (po, Ro) with
    radius r; contacts from the plane to the body (flip: the plane is the pair's B).

    A polytope with more than `PLANE_SUPPORT_DIRECTIONS` + 1 vertices within the margin keeps
    its deepest and, of those within `PLANE_SUPPORT_BAND` of its depth, the farthest along
    each of the directions spaced evenly in the plane (`_plane_support`)."""
    # the plane normal in the body's frame: the height of a core point is one dot product
    nl = _rot_t(Ro, nh)
    base = nh[0] * po[0] + nh[1] * po[1] + nh[2] * po[2] - off
    capsule = kind == SHAPE_CAPSULE
    count = np.int64(0)
    if kind == SHAPE_MESH and nv > PLANE_SUPPORT_DIRECTIONS + 1:
        deepest = v0
        lowest = np.inf
        for i in range(v0, v0 + nv):
            height = nl[0] * verts[i, 0] + nl[1] * verts[i, 1] + nl[2] * verts[i, 2] + base
            if height - r <= margin:
                count += 1
                if height < lowest:
                    deepest, lowest = i, height
        if count > PLANE_SUPPORT_DIRECTIONS + 1:
            count = _plane_support(nh, nl, base, Ro, verts, v0, nv, deepest, lowest, c_psi, start, limit)
            for k in range(start, start + count):
                _plane_vertex(nh, nl, base, po, Ro, r, verts, np.int64(c_psi[k]), flip, c_psi, c_n, c_pa, c_pb, k)
            return count
        count = 0
    if capsule:
        e0 = _core_point(verts, v0, po, Ro)
        e1 = _core_point(verts, v0 + 1, po, Ro)
    else:
        e0 = e1 = nh
    down = _scale(nh, -1.0)
    for i in range(v0, v0 + nv):
        height = nl[0] * verts[i, 0] + nl[1] * verts[i, 1] + nl[2] * verts[i, 2] + base
        if capsule:
            # the surface point below a capsule end: where the line down from it leaves the
            # capsule (further than r at the end tilted away from the plane)
            v = e0 if i == v0 else e1
            T = _capsule_exit(v, down, e0, e1, r)
        else:
            T = r
        psi = height - T
        if psi <= margin and count < limit:
            if capsule:
                _emit(c_psi, c_n, c_pa, c_pb, start + count, psi, nh, _axpy(v, -height, nh), _axpy(v, -T, nh), flip)
            else:
                _plane_vertex(nh, nl, base, po, Ro, r, verts, i, flip, c_psi, c_n, c_pa, c_pb, start + count)
            count += 1
    return count


@numba.njit(cache=True)
def _plane_vertex(nh, nl, base, po, Ro, r, verts, i, flip, c_psi, c_n, c_pa, c_pb, k):
    """Write the contact of core point verts[i] (not a capsule's) with the plane at slot k: its
    depth height - r, from the point on the plane below it to the point r below it."""
    height = nl[0] * verts[i, 0] + nl[1] * verts[i, 1] + nl[2] * verts[i, 2] + base
    v = _rot(Ro, (verts[i, 0], verts[i, 1], verts[i, 2]))
    v = (v[0] + po[0], v[1] + po[1], v[2] + po[2])
    _emit(c_psi, c_n, c_pa, c_pb, k, height - r, nh, _axpy(v, -height, nh), _axpy(v, -r, nh), flip)


@numba.njit(cache=True)
def _plane_support(nh, nl, base, Ro, verts, v0, nv, deepest, lowest, c_psi, start, limit):
    """The vertices a polytope bears on a plane with: the deepest (height `lowest`) and, of the
    vertices within `PLANE_SUPPORT_BAND` of it, the farthest along each of
    `PLANE_SUPPORT_DIRECTIONS` directions in the plane (a world basis of it, first found on
    ties). Their indices, ascending and distinct, are left in c_psi[start:start + count] (the
    output buffer as scratch); returns count.

    A face within the band keeps the corners its support polygon has in those directions: exact
    for a face whose interior angles are all under 135 degrees (a corner is then the farthest
    along an open range of more than 45 degrees of directions, which holds one of them: a
    rectangle, a regular polygon of up to 7 sides); otherwise the polygon loses at most a
    factor cos(pi / directions) of its reach in any direction. Vertices beyond the band, which
    the margin had kept for what a step could close, are left: one the body tilts onto is the
    deepest of its neighbourhood at the next step."""
    slots = min(PLANE_SUPPORT_DIRECTIONS + 1, limit)
    t, o = _basis(nh)
    c_psi[start] = deepest
    for j in range(1, slots):
        angle = 2.0 * math.pi * (j - 1) / PLANE_SUPPORT_DIRECTIONS
        d = _rot_t(Ro, _axpy(_scale(t, math.cos(angle)), math.sin(angle), o))
        best, score = deepest, d[0] * verts[deepest, 0] + d[1] * verts[deepest, 1] + d[2] * verts[deepest, 2]
        for i in range(v0, v0 + nv):
            height = nl[0] * verts[i, 0] + nl[1] * verts[i, 1] + nl[2] * verts[i, 2] + base
            if height <= lowest + PLANE_SUPPORT_BAND:
                s = d[0] * verts[i, 0] + d[1] * verts[i, 1] + d[2] * verts[i, 2]
                if s > score:
                    best, score = i, s
        c_psi[start + j] = best
    # ascending (insertion sort), then distinct
    for j in range(start + 1, start + slots):
        x = c_psi[j]
        k = j - 1
        while k >= start and c_psi[k] > x:
            c_psi[k + 1] = c_psi[k]
            k -= 1
        c_psi[k + 1] = x
    count = np.int64(1)
    for j in range(start + 1, start + slots):
        if c_psi[j] != c_psi[start + count - 1]:
            c_psi[start + count] = c_psi[j]
            count += 1
    return count


# ----------------------------------------------------------------------------- rounded pairs


@numba.njit(cache=True)
def _capsule_end_contact(e, on_second, a0, a1, ra, b0, b1, rb):
    """Contact through an axis end point e of one capsule and its closest point on the other.

    on_second: e is an end of the second capsule (b0 b1). Returns (ok, psi, n, pa, pb) with
    n from the first capsule to the second; pa, pb exactly on the surfaces (the point on e's
    own capsule is where the line from the other axis through e leaves it).
    """
    if on_second:
        c = _axpy(a0, _point_seg(e, a0, a1), _sub(a1, a0))
        d = _sub(e, c)
        L = _norm(d)
        if L <= CORE_TOL:
            return False, 0.0, d, d, d
        n = _scale(d, 1.0 / L)
        T = _capsule_exit(e, _scale(n, -1.0), b0, b1, rb)
        return True, L - ra - T, n, _axpy(c, ra, n), _axpy(e, -T, n)
    c = _axpy(b0, _point_seg(e, b0, b1), _sub(b1, b0))
    d = _sub(c, e)
    L = _norm(d)
    if L <= CORE_TOL:
        return False, 0.0, d, d, d
    n = _scale(d, 1.0 / L)
    T = _capsule_exit(e, n, a0, a1, ra)
    return True, L - rb - T, n, _axpy(e, T, n), _axpy(c, -rb, n)


@numba.njit(cache=True)
def _merge_ends(psi_e, t_e, psi0, t0, psi1, t1):
    """What to write in the two slots of an overlap-end pair, given the exact contact E (at
    parameter t_e): 0 the end contact, 1 E, 2 nothing. An end deeper than E is dropped (its
    line overlap along the face normal can exceed the penetration depth when that normal is
    not the exact one); E takes the slot nearer to it when it is at least as deep as the ends
    (on a tie E's normal is the exact one) or when an end was dropped."""
    deep0 = psi0 < psi_e - EXACT_TOL
    deep1 = psi1 < psi_e - EXACT_TOL
    use0 = 2 if deep0 else 0
    use1 = 2 if deep1 else 0
    if deep0 or deep1 or psi_e <= min(psi0, psi1) + EXACT_TOL:
        if abs(t_e - t0) <= abs(t_e - t1):
            use0 = 1
        else:
            use1 = 1
    return use0, use1


@numba.njit(cache=True)
def _capsule_capsule(a0, a1, ra, b0, b1, rb, margin, flip, c_psi, c_n, c_pa, c_pb, start, limit):
    d1 = _sub(a1, a0)
    d2 = _sub(b1, b0)
    s, t = _seg_seg(a0, a1, b0, b1)
    c1 = _axpy(a0, s, d1)
    c2 = _axpy(b0, t, d2)
    cr = _cross(d1, d2)
    aa = _dot(d1, d1)
    ee = _dot(d2, d2)
    crn = _norm(cr)
    if crn > 1e-12 * math.sqrt(aa * ee) and crn > 0.0:
        nf = _scale(cr, 1.0 / crn)
    elif aa > 1e-30:
        nf = _perpendicular(d1)
    elif ee > 1e-30:
        nf = _perpendicular(d2)
    else:
        nf = (0.0, 0.0, 1.0)
    centre = _sub(_scale(_add(b0, b1), 0.5), _scale(_add(a0, a1), 0.5))
    if _dot(nf, centre) < 0.0:
        nf = _scale(nf, -1.0)
    psi_e, n_e, pa_e, pb_e = _rounded(c1, c2, ra, rb, nf)

    if limit >= 2 and aa > 1e-30 and ee > 1e-30 and crn * crn <= PARALLEL_SIN * PARALLEL_SIN * aa * ee:
        tb0 = _dot(_sub(b0, a0), d1) / aa
        tb1 = _dot(_sub(b1, a0), d1) / aa
        lo_b, hi_b = min(tb0, tb1), max(tb0, tb1)
        lo, hi = max(0.0, lo_b), min(1.0, hi_b)
        if hi - lo > MIN_OVERLAP:
            # the end of the overlap is an end of the second axis if it lies inside the first
            second = lo_b > 0.0
            e = (b0 if tb0 < tb1 else b1) if second else a0
            ok0, psi0, n0, pa0, pb0 = _capsule_end_contact(e, second, a0, a1, ra, b0, b1, rb)
            second = hi_b < 1.0
            e = (b0 if tb0 >= tb1 else b1) if second else a1
            ok1, psi1, n1, pa1, pb1 = _capsule_end_contact(e, second, a0, a1, ra, b0, b1, rb)
            if ok0 and ok1:
                use0, use1 = _merge_ends(psi_e, s, psi0, lo, psi1, hi)
                if use0 == 1:
                    psi0, n0, pa0, pb0 = psi_e, n_e, pa_e, pb_e
                if use1 == 1:
                    psi1, n1, pa1, pb1 = psi_e, n_e, pa_e, pb_e
                count = np.int64(0)
                if use0 != 2 and psi0 <= margin:
                    _emit(c_psi, c_n, c_pa, c_pb, start, psi0, n0, pa0, pb0, flip)
                    count += 1
                if use1 != 2 and psi1 <= margin:
                    _emit(c_psi, c_n, c_pa, c_pb, start + count, psi1, n1, pa1, pb1, flip)
                    count += 1
                return count
    if psi_e <= margin and limit >= 1:
        _emit(c_psi, c_n, c_pa, c_pb, start, psi_e, n_e, pa_e, pb_e, flip)
        return 1
    return 0


# ----------------------------------------------------------------------------- boxes


@numba.njit(cache=True)
def _sphere_box(c, r, pb, Rb, h, margin, flip, c_psi, c_n, c_pa, c_pb, start, limit):
    """Box (body 1) vs sphere (body 2, centre c)."""
    y = _rot_t(Rb, _sub(c, pb))
    dist, cp, nl = _point_box(y, h)
    psi = dist - r
    if psi > margin or limit < 1:
        return 0
    n = _rot(Rb, nl)
    _emit(c_psi, c_n, c_pa, c_pb, start, psi, n, _add(_rot(Rb, cp), pb), _axpy(c, -r, n), flip)
    return 1


@numba.njit(cache=True)
def _clip_interval(a, d, h, skip):
    """[t0, t1] of t in [0, 1] with a + t d inside the slabs |y_k| <= h_k for k != skip (-1: all)."""
    t0 = 0.0
    t1 = 1.0
    for k in range(3):
        if k == skip:
            continue
        if d[k] == 0.0:
            if abs(a[k]) > h[k]:
                return 1.0, 0.0
            continue
        ta = (-h[k] - a[k]) / d[k]
        tb = (h[k] - a[k]) / d[k]
        if ta > tb:
            ta, tb = tb, ta
        t0 = max(t0, ta)
        t1 = min(t1, tb)
    return t0, t1


@numba.njit(cache=True)
def _box_edge(h, k, s1, s2):
    """End points of the box edge along axis k at signs s1, s2 of the two other axes."""
    u = (k + 1) % 3
    v = (k + 2) % 3
    P = _with(_with(_with((0.0, 0.0, 0.0), k, -h[k]), u, s1 * h[u]), v, s2 * h[v])
    return P, _with(P, k, h[k])


@numba.njit(cache=True)
def _capsule_box(a0w, a1w, r, cb, Rb, h, margin, flip, c_psi, c_n, c_pa, c_pb, start, limit):
    """Box (body 1) vs capsule (body 2, axis a0w a1w): computed in the box frame."""
    a = _rot_t(Rb, _sub(a0w, cb))
    b = _rot_t(Rb, _sub(a1w, cb))
    d = _sub(b, a)
    dd = _dot(d, d)
    dlen = math.sqrt(dd)
    t0, t1 = _clip_interval(a, d, h, np.int64(-1))
    hit = t0 <= t1
    face = np.int64(-1)  # box face of the contact (for the two-contact case)
    sg = 1.0
    n = (0.0, 0.0, 1.0)
    psi_e = _INF
    t_e = 0.0
    pbox_e = a
    pcap_e = a
    if not hit:
        # apart: closest features (an end point vs the box, or the axis vs a box edge)
        best = _INF
        t_e = 0.0
        core = a
        boxp = a
        for end in range(2):
            y = a if end == 0 else b
            dist, cp, nl = _point_box(y, h)
            if dist < best:
                best, t_e, core, boxp, n = dist, float(end), y, cp, nl
        for k in range(3):
            for s1 in (-1.0, 1.0):
                for s2 in (-1.0, 1.0):
                    P, Q = _box_edge(h, k, s1, s2)
                    s, t = _seg_seg(P, Q, a, b)
                    y = _axpy(a, t, d)
                    cp = _axpy(P, s, _sub(Q, P))
                    dist = _norm(_sub(y, cp))
                    if dist < best:
                        best, t_e, core, boxp = dist, t, y, cp
                        n = _edge_edge_normal(P, Q, a, b, s, t, cp, y, dist)
        if best - r > margin:
            return 0
        hit = best <= CORE_TOL
        if not hit:
            psi_e, pbox_e, pcap_e = best - r, boxp, _axpy(core, -r, n)
            face = np.int64(0)
            for k in range(1, 3):
                if abs(n[k]) > abs(n[face]):
                    face = k
            sg = _sign(n[face])
            if abs(n[face]) < 0.9:
                face = np.int64(-1)
    if hit:
        # the axis meets the box: separating axes (3 faces, 3 edge crossings)
        best = _INF
        kind = 0
        n = (0.0, 0.0, 1.0)
        for k in range(3):
            up = h[k] - min(a[k], b[k])
            down = max(a[k], b[k]) + h[k]
            dep, s = (up, 1.0) if up <= down else (down, -1.0)
            if dep < best:
                best, kind, face, sg = dep, 0, k, s
                n = _scale(_unit(k), s)
        tol = EDGE_AXIS_TOL * (h[0] + h[1] + h[2] + dlen)
        for k in range(3):
            L = _cross(_unit(k), d)
            ln = _norm(L)
            if ln <= EDGE_PARALLEL * dlen or ln == 0.0:
                continue
            L = _scale(L, 1.0 / ln)
            sa = _dot(a, L)
            rho = h[0] * abs(L[0]) + h[1] * abs(L[1]) + h[2] * abs(L[2])
            up = rho - sa
            down = sa + rho
            dep, s = (up, 1.0) if up <= down else (down, -1.0)
            if dep < best - tol:
                best, kind, face = dep, 1 + k, -1
                n = _scale(L, s)
        if -best - r > margin:
            return 0
        if kind == 0:
            # deepest point of the axis over the face
            u0, u1 = _clip_interval(a, d, h, face)
            if u0 > u1:
                u0 = u1 = 0.0 if sg * a[face] <= sg * b[face] else 1.0
            t_e = u0 if sg * (a[face] + u0 * d[face]) <= sg * (a[face] + u1 * d[face]) else u1
            core = _axpy(a, t_e, d)
            pbox_e = _with(core, face, sg * h[face])
            for j in range(3):
                if j != face:
                    pbox_e = _with(pbox_e, j, min(max(pbox_e[j], -h[j]), h[j]))
            T = _capsule_exit(core, _scale(n, -1.0), a, b, r)
            pcap_e = _axpy(core, -T, n)
            psi_e = _dot(_sub(pcap_e, pbox_e), n)
        else:
            k = kind - 1
            P, Q = _box_edge(h, k, _sign(n[(k + 1) % 3]), _sign(n[(k + 2) % 3]))
            s, t_e = _seg_seg(P, Q, a, b)
            pbox_e = _axpy(P, s, _sub(Q, P))
            core = _axpy(a, t_e, d)
            pcap_e = _axpy(core, -r, n)
            psi_e = _dot(_sub(pcap_e, pbox_e), n)

    count = np.int64(0)
    if face >= 0 and limit >= 2 and dlen > 0.0 and abs(d[face]) <= PARALLEL_SIN * dlen:
        # axis nearly parallel to the face: contacts at the ends of its part over the face
        u0, u1 = _clip_interval(a, d, h, face)
        if u1 - u0 > MIN_OVERLAP:
            nf = _scale(_unit(face), sg)
            core = _axpy(a, u0, d)
            psi0 = sg * core[face] - h[face] - _capsule_exit(core, _scale(nf, -1.0), a, b, r)
            core = _axpy(a, u1, d)
            psi1 = sg * core[face] - h[face] - _capsule_exit(core, _scale(nf, -1.0), a, b, r)
            use0, use1 = _merge_ends(psi_e, t_e, psi0, u0, psi1, u1)
            for j in range(2):
                use = use0 if j == 0 else use1
                if use == 2:
                    continue
                if use == 1:
                    psi, nn, p1, p2 = psi_e, n, pbox_e, pcap_e
                else:
                    u = u0 if j == 0 else u1
                    core = _axpy(a, u, d)
                    T = _capsule_exit(core, _scale(nf, -1.0), a, b, r)
                    psi, nn, p1, p2 = (psi0 if j == 0 else psi1), nf, _with(core, face, sg * h[face]), _axpy(core, -T, nf)
                if psi <= margin:
                    _emit(c_psi, c_n, c_pa, c_pb, start + count, psi, _rot(Rb, nn), _add(_rot(Rb, p1), cb), _add(_rot(Rb, p2), cb), flip)
                    count += 1
            return count
    if psi_e <= margin and limit >= 1:
        _emit(c_psi, c_n, c_pa, c_pb, start, psi_e, _rot(Rb, n), _add(_rot(Rb, pbox_e), cb), _add(_rot(Rb, pcap_e), cb), flip)
        return 1
    return 0


@numba.njit(cache=True)
def _box_vertex(h, k):
    return (h[0] if k & 1 else -h[0], h[1] if k & 2 else -h[1], h[2] if k & 4 else -h[2])


@numba.njit(cache=True)
def _edge_edge_normal(P, Q, U, V, s, t, x, y, dist):
    """Unit normal from x on edge PQ to y on edge UV: the edges' common perpendicular when both
    points are inside their edges (accurate even when dist is tiny), else the direction x to y."""
    if 0.0 < s < 1.0 and 0.0 < t < 1.0:
        e1 = _sub(Q, P)
        e2 = _sub(V, U)
        c = _cross(e1, e2)
        cn = _norm(c)
        if cn > EDGE_PARALLEL * _norm(e1) * _norm(e2):
            return _scale(c, _sign(_dot(c, _sub(y, x))) / cn)
    if dist > 0.0:
        return _scale(_sub(y, x), 1.0 / dist)
    return (0.0, 0.0, 1.0)


@numba.njit(cache=True)
def _box_box_closest(hA, hB, C, D):
    """Distance, closest points and unit normal (A's frame, from A to B) of two disjoint boxes:
    B's centre D and axes C[:][j] in A's frame. Closest features: a corner against the other
    box, or two edges."""
    best = _INF
    pa = D
    pb = D
    n = (0.0, 0.0, 1.0)
    for k in range(8):  # corners of B vs A
        y = _add(D, _rot(C, _box_vertex(hB, k)))
        dist, cp, nl = _point_box(y, hA)
        if dist < best:
            best, pa, pb, n = dist, cp, y, nl
    for k in range(8):  # corners of A vs B
        x = _box_vertex(hA, k)
        y = _rot_t(C, _sub(x, D))
        dist, cp, nl = _point_box(y, hB)
        if dist < best:
            best, pa, pb, n = dist, x, _add(D, _rot(C, cp)), _scale(_rot(C, nl), -1.0)
    for j in range(3):
        for sb1 in (-1.0, 1.0):
            for sb2 in (-1.0, 1.0):
                U, V = _box_edge(hB, j, sb1, sb2)
                U = _add(D, _rot(C, U))
                V = _add(D, _rot(C, V))
                for i in range(3):
                    for sa1 in (-1.0, 1.0):
                        for sa2 in (-1.0, 1.0):
                            P, Q = _box_edge(hA, i, sa1, sa2)
                            s, t = _seg_seg(P, Q, U, V)
                            x = _axpy(P, s, _sub(Q, P))
                            y = _axpy(U, t, _sub(V, U))
                            dist = _norm(_sub(y, x))
                            if dist < best:
                                best, pa, pb = dist, x, y
                                n = _edge_edge_normal(P, Q, U, V, s, t, x, y, dist)
    return best, pa, pb, n


@numba.njit(cache=True)
def _face_clip(hR, i, sg, cI, M, hI, clip):
    """Incident face of box I (centre cI, axes M[:][j], reference frame) clipped to the side
    planes of reference face i (outward normal sg e_i) of box [-hR, hR]. Returns the number
    of points and which half of `clip` (2 x 8 x 3) holds them."""
    j = np.int64(0)
    for k in range(1, 3):
        if abs(M[i][k]) > abs(M[i][j]):
            j = k
    s_inc = -_sign(sg * M[i][j])
    fc = _axpy(cI, s_inc * hI[j], _col(M, j))
    u = (j + 1) % 3
    v = (j + 2) % 3
    eu = _scale(_col(M, u), hI[u])
    ev = _scale(_col(M, v), hI[v])
    for c in range(4):
        su = 1.0 if c == 0 or c == 3 else -1.0
        sv = 1.0 if c < 2 else -1.0
        p = _axpy(_axpy(fc, su, eu), sv, ev)
        for k in range(3):
            clip[0, c, k] = p[k]
    count = np.int64(4)
    cur = np.int64(0)
    for plane in range(4):
        k = (i + 1 + plane // 2) % 3
        side = 1.0 if plane % 2 == 0 else -1.0
        nxt = 1 - cur
        out = np.int64(0)
        for c in range(count):
            c2 = c + 1 if c + 1 < count else 0
            d0 = side * clip[cur, c, k] - hR[k]
            d1 = side * clip[cur, c2, k] - hR[k]
            if d0 <= 0.0:
                for m in range(3):
                    clip[nxt, out, m] = clip[cur, c, m]
                out += 1
            if (d0 < 0.0 and d1 > 0.0) or (d0 > 0.0 and d1 < 0.0):
                f = d0 / (d0 - d1)
                for m in range(3):
                    clip[nxt, out, m] = clip[cur, c, m] + f * (clip[cur, c2, m] - clip[cur, c, m])
                out += 1
        count = out
        cur = nxt
        if count == 0:
            break
    return count, cur


# allocates its clipping buffers: compiled with numba's runtime even where its caller is not
# (`models.contact.detect_spatial_into`; a callee left unset inherits the caller's flag)
@numba.njit(cache=True, _nrt=True)
def _box_box(pA, RA, hA, pB, RB, hB, margin, flip, c_psi, c_n, c_pa, c_pb, start, limit):
    """Box A (body 1) vs box B (body 2). Separating axes in A's frame, then contacts."""
    C = _mat_t_mul(RA, RB)  # C[i][j] = a_i . b_j: B's axes in A's frame are the columns
    D = _rot_t(RA, _sub(pB, pA))
    best = -_INF
    kind = 0  # 0: face of A, 1: face of B, 2: edge-edge
    idx = np.int64(0)
    sg = 1.0
    axis = (0.0, 0.0, 1.0)  # unit axis in A's frame, from A to B
    for i in range(3):
        rb = hB[0] * abs(C[i][0]) + hB[1] * abs(C[i][1]) + hB[2] * abs(C[i][2])
        sep = abs(D[i]) - hA[i] - rb
        if sep > best:
            best, kind, idx, sg = sep, 0, i, _sign(D[i])
            axis = _scale(_unit(i), sg)
    for j in range(3):
        dist = D[0] * C[0][j] + D[1] * C[1][j] + D[2] * C[2][j]
        ra = hA[0] * abs(C[0][j]) + hA[1] * abs(C[1][j]) + hA[2] * abs(C[2][j])
        sep = abs(dist) - ra - hB[j]
        if sep > best:
            best, kind, idx, sg = sep, 1, j, _sign(dist)
            axis = _scale(_col(C, j), sg)
    tol = EDGE_AXIS_TOL * (hA[0] + hA[1] + hA[2] + hB[0] + hB[1] + hB[2])
    ei = np.int64(0)
    ej = np.int64(0)
    for i in range(3):
        for j in range(3):
            L = _cross(_unit(i), _col(C, j))
            ln = _norm(L)
            if ln <= EDGE_PARALLEL:
                continue
            L = _scale(L, 1.0 / ln)
            ra = hA[0] * abs(L[0]) + hA[1] * abs(L[1]) + hA[2] * abs(L[2])
            Lb = _rot_t(C, L)
            rb = hB[0] * abs(Lb[0]) + hB[1] * abs(Lb[1]) + hB[2] * abs(Lb[2])
            dist = _dot(D, L)
            sep = abs(dist) - ra - rb
            if sep > best + tol:
                best, kind, ei, ej = sep, 2, i, j
                axis = _scale(L, _sign(dist))
    if best > margin:
        return 0

    if kind == 2:
        # edge-edge axis: closest points of A's and B's support edges along it
        P, Q = _box_edge(hA, ei, _sign(axis[(ei + 1) % 3]), _sign(axis[(ei + 2) % 3]))
        Lb = _rot_t(C, axis)
        U, V = _box_edge(hB, ej, -_sign(Lb[(ej + 1) % 3]), -_sign(Lb[(ej + 2) % 3]))
        U = _add(D, _rot(C, U))
        V = _add(D, _rot(C, V))
        s, t = _seg_seg(P, Q, U, V)
        pa = _axpy(P, s, _sub(Q, P))
        pb = _axpy(U, t, _sub(V, U))
        n = axis
        psi = _dot(_sub(pb, pa), axis)
        if best > 0.0 and not (0.0 < s < 1.0 and 0.0 < t < 1.0):
            # apart, and the support edges do not realise the axis' separation: exact distance
            psi, pa, pb, n = _box_box_closest(hA, hB, C, D)
            if psi <= CORE_TOL:
                n = axis  # touching: the closest points give no direction, the axis does
        if psi <= margin and limit >= 1:
            _emit(c_psi, c_n, c_pa, c_pb, start, psi, _rot(RA, n), _add(_rot(RA, pa), pA), _add(_rot(RA, pb), pA), flip)
            return 1
        return 0

    # a face axis: clip the incident face against the reference face
    buf = np.empty((9, 10))
    clip = np.empty((2, 8, 3))
    m = np.int64(0)
    if kind == 0:  # reference A: frame A
        M = C
        cI = D
        hR, hI, RR, pR = hA, hB, RA, pA
    else:  # reference B: frame B; A's axes in B's frame are the rows of C
        M = _transpose(C)
        cI = _scale(_rot_t(C, D), -1.0)
        hR, hI, RR, pR = hB, hA, RB, pB
        sg = -sg  # B's face normal points towards A
    count, half = _face_clip(hR, idx, sg, cI, M, hI, clip)
    nref = _rot(RR, _scale(_unit(idx), sg))
    n_ab = nref if kind == 0 else _scale(nref, -1.0)
    min_sep = _INF
    for c in range(count):
        y = (clip[half, c, 0], clip[half, c, 1], clip[half, c, 2])
        sep = sg * y[idx] - hR[idx]
        min_sep = min(min_sep, sep)
        if sep <= margin:
            inc = _add(_rot(RR, y), pR)
            ref = _add(_rot(RR, _with(y, idx, sg * hR[idx])), pR)
            if kind == 0:
                _store(buf, m, sep, n_ab, ref, inc)
            else:
                _store(buf, m, sep, n_ab, inc, ref)
            m += 1
    if best > 0.0:
        # apart: the face points are at least the distance away and the axis' separation at
        # most; unless they meet, the closest features lie elsewhere (edges, corners)
        if min_sep > best + EXACT_TOL:
            dist, pa, pb, n = _box_box_closest(hA, hB, C, D)
            if dist <= CORE_TOL:
                n = axis
            if dist <= margin and dist < min_sep - EXACT_TOL:
                _store(buf, m, dist, _rot(RA, n), _add(_rot(RA, pa), pA), _add(_rot(RA, pb), pA))
                m += 1
    elif m == 0:
        # clipping lost the deepest point to rounding: the deepest incident corner instead
        yb = (0.0, 0.0, 0.0)
        lowest = _INF
        for k in range(8):
            y = _add(cI, _rot(M, _box_vertex(hI, k)))
            if sg * y[idx] < lowest:
                lowest, yb = sg * y[idx], y
        ref = yb
        for k in range(3):
            ref = _with(ref, k, min(max(ref[k], -hR[k]), hR[k]))
        ref = _with(ref, idx, sg * hR[idx])
        inc = _add(_rot(RR, yb), pR)
        ref = _add(_rot(RR, ref), pR)
        psi = _dot(_sub(inc, ref), nref)
        if psi <= margin:
            if kind == 0:
                _store(buf, m, psi, n_ab, ref, inc)
            else:
                _store(buf, m, psi, n_ab, inc, ref)
            m += 1
    return _reduce_emit(buf, m, limit, c_psi, c_n, c_pa, c_pb, start, flip)


# ----------------------------------------------------------------------------- convex polytopes (meshes)
#
# A polytope body b (box or mesh) is its vertices verts[v0:v0 + nv] and the hull tables of
# S.hull[b] = (f0, nf, e0, ne, d0, nd): face planes (outward unit n, offset d: n.x <= d),
# face loops (counterclockwise about n), edges (vertex index pairs), distinct edge directions,
# all in the body frame. `hb` below is that tuple followed by (v0, nv).

_IDENT = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
_ORIGIN = (0.0, 0.0, 0.0)


@numba.njit(cache=True)
def _vert(verts, i):
    return (verts[i, 0], verts[i, 1], verts[i, 2])


@numba.njit(cache=True)
def _face_plane(planes, f):
    return (planes[f, 0], planes[f, 1], planes[f, 2]), planes[f, 3]


@numba.njit(cache=True)
def _dot_range(verts, v0, nv, u):
    """(min, max) of u.v over vertices v0 .. v0 + nv - 1."""
    lo = _INF
    hi = -_INF
    for i in range(v0, v0 + nv):
        x = u[0] * verts[i, 0] + u[1] * verts[i, 1] + u[2] * verts[i, 2]
        lo = min(lo, x)
        hi = max(hi, x)
    return lo, hi


@numba.njit(cache=True)
def _in_face(y, n, verts, face_verts, f, slack):
    """Whether y (body frame) projects into face f (normal n): inside every side plane (e x n
    points out of the face for a counterclockwise loop) up to slack."""
    k = face_verts[f, 0]
    for j in range(k):
        a = _vert(verts, face_verts[f, 1 + j])
        b = _vert(verts, face_verts[f, 1 + (j + 1 if j + 1 < k else 0)])
        if _dot(_cross(_sub(b, a), n), _sub(y, a)) > slack:
            return False
    return True


@numba.njit(cache=True)
def _point_hull(y, verts, planes, face_verts, edges, hb):
    """Point y vs polytope hb (body frame): (signed distance, surface point, outward unit normal).

    Inside or on the surface: the face with the largest plane value (the deepest-face rule).
    Outside: the closest point, on a face (y projects into it) or on an edge.
    """
    f0, nf, e0, ne = hb[0], hb[1], hb[2], hb[3]
    top = -_INF
    fb = f0
    for f in range(f0, f0 + nf):
        n, d = _face_plane(planes, f)
        s = _dot(n, y) - d
        if s > top:
            top, fb = s, f
    nb, _ = _face_plane(planes, fb)
    if top <= 0.0:
        return top, _axpy(y, -top, nb), nb
    best = _INF
    cp = y
    nl = nb
    for f in range(f0, f0 + nf):
        n, d = _face_plane(planes, f)
        s = _dot(n, y) - d
        if s > 0.0 and s < best and _in_face(y, n, verts, face_verts, f, 0.0):
            best, cp, nl = s, _axpy(y, -s, n), n
    for e in range(e0, e0 + ne):
        P = _vert(verts, edges[e, 0])
        Q = _vert(verts, edges[e, 1])
        c = _axpy(P, _point_seg(y, P, Q), _sub(Q, P))
        g = _sub(y, c)
        dist = _norm(g)
        if dist < best:
            best, cp = dist, c
            nl = _scale(g, 1.0 / dist) if dist > 0.0 else nb
    return best, cp, nl


@numba.njit(cache=True)
def _sphere_hull(c, r, p1, R1, hb, verts, planes, face_verts, edges, margin, flip, c_psi, c_n, c_pa, c_pb, start, limit):
    """Polytope (body 1) vs sphere (body 2, centre c)."""
    y = _rot_t(R1, _sub(c, p1))
    dist, cp, nl = _point_hull(y, verts, planes, face_verts, edges, hb)
    psi = dist - r
    if psi > margin or limit < 1:
        return 0
    n = _rot(R1, nl)
    _emit(c_psi, c_n, c_pa, c_pb, start, psi, n, _add(_rot(R1, cp), p1), _axpy(c, -r, n), flip)
    return 1


@numba.njit(cache=True)
def _support_edge(verts, edges, e0, ne, u, axis, M, c):
    """End points (mapped by x -> c + M x) of the edge along direction u (mapped frame) that is
    highest along axis."""
    best = -_INF
    P = c
    Q = c
    for e in range(e0, e0 + ne):
        A = _add(c, _rot(M, _vert(verts, edges[e, 0])))
        B = _add(c, _rot(M, _vert(verts, edges[e, 1])))
        d = _sub(B, A)
        L = _norm(d)
        if L <= 0.0 or abs(_dot(d, u)) < (1.0 - 1e-6) * L:
            continue
        h = _dot(_add(A, B), axis)
        if h > best:
            best, P, Q = h, A, B
    return P, Q


@numba.njit(cache=True)
def _capsule_hull(a0w, a1w, r, p1, R1, hb, verts, planes, face_verts, edges, dirs, margin, flip, c_psi, c_n, c_pa, c_pb, start, limit):
    """Polytope (body 1) vs capsule (body 2, axis a0w a1w), in the polytope's frame: one contact
    (closest features when apart; separating axes over the faces and the crossings of the edge
    directions with the axis when the axis meets the polytope)."""
    f0, nf, e0, ne, d0, nd, v0, nv = hb
    a = _rot_t(R1, _sub(a0w, p1))
    b = _rot_t(R1, _sub(a1w, p1))
    d = _sub(b, a)
    dlen = _norm(d)
    # does the axis meet the polytope? (the segment clipped by every face's half-space)
    t0 = 0.0
    t1 = 1.0
    for f in range(f0, f0 + nf):
        n, off = _face_plane(planes, f)
        sa = _dot(n, a) - off
        sb = _dot(n, b) - off
        if sa > 0.0 and sb > 0.0:
            t0, t1 = 1.0, 0.0
            break
        if sa > 0.0:
            t0 = max(t0, sa / (sa - sb))
        elif sb > 0.0:
            t1 = min(t1, sa / (sa - sb))
    hit = t0 <= t1
    n = (0.0, 0.0, 1.0)
    core = a
    php = a
    pcap = a
    if not hit:
        best = _INF
        for end in range(2):
            y = a if end == 0 else b
            dist, cp, nl = _point_hull(y, verts, planes, face_verts, edges, hb)
            if dist < best:
                best, core, php, n = dist, y, cp, nl
        for e in range(e0, e0 + ne):
            P = _vert(verts, edges[e, 0])
            Q = _vert(verts, edges[e, 1])
            s, t = _seg_seg(P, Q, a, b)
            x = _axpy(P, s, _sub(Q, P))
            y = _axpy(a, t, d)
            dist = _norm(_sub(y, x))
            if dist < best:
                best, core, php = dist, y, x
                n = _edge_edge_normal(P, Q, a, b, s, t, x, y, dist)
        if best - r > margin:
            return 0
        hit = best <= CORE_TOL
        if not hit:
            pcap = _axpy(core, -r, n)
    if hit:
        best = -_INF
        face = f0
        kind = 0
        for f in range(f0, f0 + nf):
            nn, off = _face_plane(planes, f)
            sep = min(_dot(nn, a), _dot(nn, b)) - off
            if sep > best:
                best, face, n = sep, f, nn
        lo_a, hi_a = _dot_range(verts, v0, nv, n)
        tol = EDGE_AXIS_TOL * (hi_a - lo_a + dlen)
        for k in range(d0, d0 + nd):
            u = _vert(dirs, k)
            L = _cross(u, d)
            ln = _norm(L)
            if ln <= EDGE_PARALLEL * dlen or ln == 0.0:
                continue
            L = _scale(L, 1.0 / ln)
            lo, hi = _dot_range(verts, v0, nv, L)
            sa = _dot(L, a)
            sb = _dot(L, b)
            up = min(sa, sb) - hi
            down = lo - max(sa, sb)
            sep, sg = (up, 1.0) if up >= down else (down, -1.0)
            if sep > best + tol:
                best, kind, face = sep, 1, k
                n = _scale(L, sg)
        if best - r > margin:
            return 0
        if kind == 0:
            nn, off = _face_plane(planes, face)
            # the deepest point of the part of the axis over the face
            u0 = 0.0
            u1 = 1.0
            k = face_verts[face, 0]
            for j in range(k):
                A = _vert(verts, face_verts[face, 1 + j])
                B = _vert(verts, face_verts[face, 1 + (j + 1 if j + 1 < k else 0)])
                side = _cross(_sub(B, A), nn)
                sa = _dot(side, _sub(a, A))
                sb = _dot(side, _sub(b, A))
                if sa > 0.0 and sb > 0.0:
                    u0, u1 = 1.0, 0.0
                    break
                if sa > 0.0:
                    u0 = max(u0, sa / (sa - sb))
                elif sb > 0.0:
                    u1 = min(u1, sa / (sa - sb))
            if u0 > u1:
                u0 = u1 = 0.0 if _dot(nn, a) <= _dot(nn, b) else 1.0
            te = u0 if _dot(nn, _axpy(a, u0, d)) <= _dot(nn, _axpy(a, u1, d)) else u1
            core = _axpy(a, te, d)
            php = _axpy(core, -(_dot(nn, core) - off), nn)
            T = _capsule_exit(core, _scale(nn, -1.0), a, b, r)
            pcap = _axpy(core, -T, nn)
        else:
            P, Q = _support_edge(verts, edges, e0, ne, _vert(dirs, face), n, _IDENT, _ORIGIN)
            s, t = _seg_seg(P, Q, a, b)
            php = _axpy(P, s, _sub(Q, P))
            core = _axpy(a, t, d)
            pcap = _axpy(core, -r, n)
    psi = _dot(_sub(pcap, php), n)
    if psi > margin or limit < 1:
        return 0
    _emit(c_psi, c_n, c_pa, c_pb, start, psi, _rot(R1, n), _add(_rot(R1, php), p1), _add(_rot(R1, pcap), p1), flip)
    return 1


@numba.njit(cache=True)
def _hull_closest(h1, h2, C, D, verts, planes, face_verts, edges):
    """Distance, closest points and unit normal (frame 1, from 1 to 2) of two disjoint polytopes;
    body 2's frame maps into body 1's by y = D + C x. Closest features: a vertex against a face
    it projects into, or two edges."""
    best = _INF
    pa = D
    pb = D
    n = (0.0, 0.0, 1.0)
    for i in range(h2[6], h2[6] + h2[7]):  # vertices of 2 vs faces of 1
        y = _add(D, _rot(C, _vert(verts, i)))
        for f in range(h1[0], h1[0] + h1[1]):
            nn, off = _face_plane(planes, f)
            s = _dot(nn, y) - off
            if 0.0 <= s < best and _in_face(y, nn, verts, face_verts, f, 0.0):
                best, pa, pb, n = s, _axpy(y, -s, nn), y, nn
    for i in range(h1[6], h1[6] + h1[7]):  # vertices of 1 vs faces of 2 (in frame 2)
        x = _vert(verts, i)
        y = _rot_t(C, _sub(x, D))
        for f in range(h2[0], h2[0] + h2[1]):
            nn, off = _face_plane(planes, f)
            s = _dot(nn, y) - off
            if 0.0 <= s < best and _in_face(y, nn, verts, face_verts, f, 0.0):
                best, pa, n = s, x, _scale(_rot(C, nn), -1.0)
                pb = _add(D, _rot(C, _axpy(y, -s, nn)))
    for j in range(h2[2], h2[2] + h2[3]):
        U = _add(D, _rot(C, _vert(verts, edges[j, 0])))
        V = _add(D, _rot(C, _vert(verts, edges[j, 1])))
        for i in range(h1[2], h1[2] + h1[3]):
            P = _vert(verts, edges[i, 0])
            Q = _vert(verts, edges[i, 1])
            s, t = _seg_seg(P, Q, U, V)
            x = _axpy(P, s, _sub(Q, P))
            y = _axpy(U, t, _sub(V, U))
            dist = _norm(_sub(y, x))
            if dist < best:
                best, pa, pb = dist, x, y
                n = _edge_edge_normal(P, Q, U, V, s, t, x, y, dist)
    return best, pa, pb, n


# allocates its clipping buffers: compiled with numba's runtime even where its caller is not
# (`models.contact.detect_spatial_into`; a callee left unset inherits the caller's flag)
@numba.njit(cache=True, _nrt=True)
def _hull_hull(p1, R1, h1, s1, p2, R2, h2, s2, verts, planes, face_verts, edges, dirs, margin, flip, c_psi, c_n, c_pa, c_pb, start, limit):
    """Polytope 1 vs polytope 2 (s1, s2: their sizes, for tolerances). Separating axes in frame 1
    over the faces of both and the crossings of their edge directions, then contacts: a face
    axis clips the most opposed face of the other body against the face's side planes (points
    reduced to 4 like box-box), an edge axis gives one contact at the support edges."""
    C = _mat_t_mul(R1, R2)  # frame 2 -> frame 1: y = D + C x
    D = _rot_t(R1, _sub(p2, p1))
    best = -_INF
    kind = 0  # 0: face of 1, 1: face of 2, 2: edge-edge
    idx = np.int64(0)
    axis = (0.0, 0.0, 1.0)  # frame 1, from 1 to 2
    for f in range(h1[0], h1[0] + h1[1]):
        n, off = _face_plane(planes, f)
        lo, _ = _dot_range(verts, h2[6], h2[7], _rot_t(C, n))
        sep = lo + _dot(n, D) - off
        if sep > best:
            best, kind, idx, axis = sep, 0, f, n
    for f in range(h2[0], h2[0] + h2[1]):
        m, off = _face_plane(planes, f)
        mw = _rot(C, m)
        lo, _ = _dot_range(verts, h1[6], h1[7], mw)
        sep = lo - (off + _dot(mw, D))
        if sep > best:
            best, kind, idx, axis = sep, 1, f, _scale(mw, -1.0)
    tol = EDGE_AXIS_TOL * (s1 + s2)
    ei = np.int64(0)
    ej = np.int64(0)
    for i in range(h1[4], h1[4] + h1[5]):
        u = _vert(dirs, i)
        for j in range(h2[4], h2[4] + h2[5]):
            L = _cross(u, _rot(C, _vert(dirs, j)))
            ln = _norm(L)
            if ln <= EDGE_PARALLEL:
                continue
            L = _scale(L, 1.0 / ln)
            lo1, hi1 = _dot_range(verts, h1[6], h1[7], L)
            lo2, hi2 = _dot_range(verts, h2[6], h2[7], _rot_t(C, L))
            c = _dot(L, D)
            up = lo2 + c - hi1
            down = lo1 - (hi2 + c)
            sep, sg = (up, 1.0) if up >= down else (down, -1.0)
            if sep > best + tol:
                best, kind, ei, ej = sep, 2, i, j
                axis = _scale(L, sg)
    if best > margin or limit < 1:
        return 0

    if kind == 2:
        P, Q = _support_edge(verts, edges, h1[2], h1[3], _vert(dirs, ei), axis, _IDENT, _ORIGIN)
        U, V = _support_edge(verts, edges, h2[2], h2[3], _rot(C, _vert(dirs, ej)), _scale(axis, -1.0), C, D)
        s, t = _seg_seg(P, Q, U, V)
        pa = _axpy(P, s, _sub(Q, P))
        pb = _axpy(U, t, _sub(V, U))
        n = axis
        psi = _dot(_sub(pb, pa), axis)
        # apart, the axis' separation is the distance only if these edges are the supports
        # along it (else the supports are vertices) and their closest points are inside both
        _, hi1 = _dot_range(verts, h1[6], h1[7], axis)
        lo2, _ = _dot_range(verts, h2[6], h2[7], _rot_t(C, axis))
        lo2 += _dot(axis, D)
        slack = EDGE_AXIS_TOL * (s1 + s2)
        supported = min(_dot(P, axis), _dot(Q, axis)) >= hi1 - slack and max(_dot(U, axis), _dot(V, axis)) <= lo2 + slack
        if best > 0.0 and not (supported and 0.0 < s < 1.0 and 0.0 < t < 1.0):
            psi, pa, pb, n = _hull_closest(h1, h2, C, D, verts, planes, face_verts, edges)
            if psi <= CORE_TOL:
                n = axis
        if psi <= margin:
            _emit(c_psi, c_n, c_pa, c_pb, start, psi, _rot(R1, n), _add(_rot(R1, pa), p1), _add(_rot(R1, pb), p1), flip)
            return 1
        return 0

    # a face axis: work in the reference body's frame r; the incident body i maps in by c + M x
    if kind == 0:
        hI, M, cI, RR, pR = h2, C, D, R1, p1
    else:
        hI, M, cI, RR, pR = h1, _transpose(C), _scale(_rot_t(C, D), -1.0), R2, p2
    nref, dref = _face_plane(planes, idx)
    nloc = _rot_t(M, nref)  # the reference normal in the incident frame
    inc = hI[0]
    lowest = _INF
    for f in range(hI[0], hI[0] + hI[1]):
        m, _ = _face_plane(planes, f)
        if _dot(m, nloc) < lowest:
            lowest, inc = _dot(m, nloc), f
    width = face_verts.shape[1] - 1
    clip = np.empty((2, 2 * width + 1, 3))
    buf = np.empty((2 * width + 3, 10))
    count = face_verts[inc, 0]
    for c in range(count):
        y = _add(cI, _rot(M, _vert(verts, face_verts[inc, 1 + c])))
        for k in range(3):
            clip[0, c, k] = y[k]
    cur = np.int64(0)
    kr = face_verts[idx, 0]
    for j in range(kr):
        if count == 0:
            break
        A = _vert(verts, face_verts[idx, 1 + j])
        B = _vert(verts, face_verts[idx, 1 + (j + 1 if j + 1 < kr else 0)])
        side = _cross(_sub(B, A), nref)
        so = _dot(side, A)
        nxt = 1 - cur
        out = np.int64(0)
        for c in range(count):
            c2 = c + 1 if c + 1 < count else 0
            d0 = side[0] * clip[cur, c, 0] + side[1] * clip[cur, c, 1] + side[2] * clip[cur, c, 2] - so
            d1 = side[0] * clip[cur, c2, 0] + side[1] * clip[cur, c2, 1] + side[2] * clip[cur, c2, 2] - so
            if d0 <= 0.0:
                for k in range(3):
                    clip[nxt, out, k] = clip[cur, c, k]
                out += 1
            if (d0 < 0.0 and d1 > 0.0) or (d0 > 0.0 and d1 < 0.0):
                f = d0 / (d0 - d1)
                for k in range(3):
                    clip[nxt, out, k] = clip[cur, c, k] + f * (clip[cur, c2, k] - clip[cur, c, k])
                out += 1
        count = out
        cur = nxt
    n_ab = _rot(RR, nref) if kind == 0 else _rot(RR, _scale(nref, -1.0))
    m = np.int64(0)
    min_sep = _INF
    for c in range(count):
        y = (clip[cur, c, 0], clip[cur, c, 1], clip[cur, c, 2])
        sep = _dot(nref, y) - dref
        min_sep = min(min_sep, sep)
        if sep <= margin:
            yi = _add(_rot(RR, y), pR)
            yr = _add(_rot(RR, _axpy(y, -sep, nref)), pR)
            if kind == 0:
                _store(buf, m, sep, n_ab, yr, yi)
            else:
                _store(buf, m, sep, n_ab, yi, yr)
            m += 1
    # the incident body's deepest vertex, when it is over the reference face and the clipped
    # face missed it (the most opposed face need not hold it)
    yb = cI
    low = _INF
    for i in range(hI[6], hI[6] + hI[7]):
        y = _add(cI, _rot(M, _vert(verts, i)))
        if _dot(nref, y) < low:
            low, yb = _dot(nref, y), y
    sep = low - dref
    if sep < min_sep - EXACT_TOL and sep <= margin and _in_face(yb, nref, verts, face_verts, idx, EXACT_TOL * (s1 + s2)):
        min_sep = sep
        yi = _add(_rot(RR, yb), pR)
        yr = _add(_rot(RR, _axpy(yb, -sep, nref)), pR)
        if kind == 0:
            _store(buf, m, sep, n_ab, yr, yi)
        else:
            _store(buf, m, sep, n_ab, yi, yr)
        m += 1
    if best > 0.0 and min_sep > best + EXACT_TOL:
        # apart, and the face points do not realise the axis' separation: the closest features
        dist, pa, pb, n = _hull_closest(h1, h2, C, D, verts, planes, face_verts, edges)
        if dist <= CORE_TOL:
            n = axis
        if dist <= margin and dist < min_sep - EXACT_TOL:
            _store(buf, m, dist, _rot(R1, n), _add(_rot(R1, pa), p1), _add(_rot(R1, pb), p1))
            m += 1
    return _reduce_emit(buf, m, limit, c_psi, c_n, c_pa, c_pb, start, flip)


@numba.njit(cache=True)
def _collide_hull(
    ka, pA, RA, ra, hA, sA, kb, pB, RB, rb, hB, sB, verts, planes, face_verts, edges, dirs, margin, limit, c_psi, c_n, c_pa, c_pb, start
):
    """A pair with a mesh and no plane: hA, hB are (f0, nf, e0, ne, d0, nd, v0, nv); sA, sB the
    bodies' sizes. The polytope (the mesh, or the box vs a mesh) is body 1."""
    swapped = kb == SHAPE_MESH and ka != SHAPE_MESH  # body 1 is B
    if swapped:
        k2, p1, R1, h1, s1, p2, R2, r2, h2, s2 = ka, pB, RB, hB, sB, pA, RA, ra, hA, sA
    else:
        k2, p1, R1, h1, s1, p2, R2, r2, h2, s2 = kb, pA, RA, hA, sA, pB, RB, rb, hB, sB
    if k2 == SHAPE_SPHERE:
        return _sphere_hull(
            _core_point(verts, h2[6], p2, R2),
            r2,
            p1,
            R1,
            h1,
            verts,
            planes,
            face_verts,
            edges,
            margin,
            swapped,
            c_psi,
            c_n,
            c_pa,
            c_pb,
            start,
            limit,
        )
    if k2 == SHAPE_CAPSULE:
        return _capsule_hull(
            _core_point(verts, h2[6], p2, R2),
            _core_point(verts, h2[6] + 1, p2, R2),
            r2,
            p1,
            R1,
            h1,
            verts,
            planes,
            face_verts,
            edges,
            dirs,
            margin,
            swapped,
            c_psi,
            c_n,
            c_pa,
            c_pb,
            start,
            limit,
        )
    return _hull_hull(
        p1, R1, h1, s1, p2, R2, h2, s2, verts, planes, face_verts, edges, dirs, margin, swapped, c_psi, c_n, c_pa, c_pb, start, limit
    )


# ----------------------------------------------------------------------------- entry point


@numba.njit(cache=True)
def collide_pair_3d(S, q, p, margin, c_psi, c_n, c_pa, c_pb, start):
    """Contacts of pair p with psi <= margin, written from index `start` of the output buffers.

    Returns how many were written (never more than S.pair_max_contacts[p], nor past the end
    of the buffers), or -1 if the pair has no compiled test (planar scenes, a mesh or box
    without hull tables: use `fcl_pair_contacts`). n points from S.pair_a[p] to S.pair_b[p].

    A thin entry: it reads the pair's data from S and hands scalars, tuples and only the
    arrays the test needs to `_collide` (a compiled call increments and decrements the
    reference count of every array in its arguments: passing the whole scene on costs more
    than most tests; docs/measurements.md). `collide_all_3d` pays that once for all pairs;
    a compiled caller's per-pair loop calls `collide_pair_3d_inline`.
    """
    return collide_pair_3d_inline(S, q, p, margin, c_psi, c_n, c_pa, c_pb, start)


@numba.njit(cache=True, inline="always")
def collide_pair_3d_inline(S, q, p, margin, c_psi, c_n, c_pa, c_pb, start):
    """`collide_pair_3d`, inlined into its compiled caller (`models.contact.detect_spatial`'s
    loop over the pairs): a call would reference-count the scene's ~30 arrays twice per pair
    (about 50 counts a pair, 147 of a box_push_3d step's 1,170; docs/measurements.md)."""
    if S.dimension != 3:
        return -1
    A = S.pair_a[p]
    B = S.pair_b[p]
    ka = S.kind[A]
    kb = S.kind[B]
    if not _compiled(ka, kb, S.hull[A, 1], S.hull[B, 1]):
        return -1
    limit = min(S.pair_max_contacts[p], c_psi.shape[0] - start)
    if limit <= 0:
        return 0
    pA, RA = _pose(S, q, A)
    pB, RB = _pose(S, q, B)
    if (ka == SHAPE_MESH or kb == SHAPE_MESH) and ka != SHAPE_HALFSPACE and kb != SHAPE_HALFSPACE:
        return _collide_hull(
            ka,
            pA,
            RA,
            S.radius[A],
            (S.hull[A, 0], S.hull[A, 1], S.hull[A, 2], S.hull[A, 3], S.hull[A, 4], S.hull[A, 5], S.vstart[A], S.vcount[A]),
            S.bound_radius[A],
            kb,
            pB,
            RB,
            S.radius[B],
            (S.hull[B, 0], S.hull[B, 1], S.hull[B, 2], S.hull[B, 3], S.hull[B, 4], S.hull[B, 5], S.vstart[B], S.vcount[B]),
            S.bound_radius[B],
            S.verts,
            S.planes,
            S.face_verts,
            S.edges,
            S.edge_dirs,
            margin,
            limit,
            c_psi,
            c_n,
            c_pa,
            c_pb,
            start,
        )
    return _collide(
        S.kind[A],
        pA,
        RA,
        S.radius[A],
        (S.half_extents[A, 0], S.half_extents[A, 1], S.half_extents[A, 2]),
        (S.hs_normal[A, 0], S.hs_normal[A, 1], S.hs_normal[A, 2]),
        S.hs_offset[A],
        S.vstart[A],
        S.vcount[A],
        S.kind[B],
        pB,
        RB,
        S.radius[B],
        (S.half_extents[B, 0], S.half_extents[B, 1], S.half_extents[B, 2]),
        (S.hs_normal[B, 0], S.hs_normal[B, 1], S.hs_normal[B, 2]),
        S.hs_offset[B],
        S.vstart[B],
        S.vcount[B],
        S.verts,
        margin,
        limit,
        c_psi,
        c_n,
        c_pa,
        c_pb,
        start,
    )


@numba.njit(cache=True)
def _compiled(ka, kb, fa, fb):
    """Whether a pair of shape kinds has a compiled test (fa, fb: the bodies' hull face counts;
    a mesh or box without hull tables has none, except against a plane)."""
    if ka == SHAPE_HALFSPACE or kb == SHAPE_HALFSPACE:
        return True
    if ka < SHAPE_SPHERE or kb < SHAPE_SPHERE:
        return False
    if ka == SHAPE_MESH or kb == SHAPE_MESH:
        return (ka < SHAPE_BOX or fa > 0) and (kb < SHAPE_BOX or fb > 0)
    return True


@numba.njit(cache=True)
def _collide(
    ka, pA, RA, ra, hA, nA, offA, vA, cA, kb, pB, RB, rb, hB, nB, offB, vB, cB, verts, margin, limit, c_psi, c_n, c_pa, c_pb, start
):
    """`collide_pair_3d` on one pair's data: kind, pose, radius, half extents, plane normal
    and offset (body frame), first core point and count, for A then B."""
    if ka == SHAPE_HALFSPACE and kb == SHAPE_HALFSPACE:
        return 0
    if ka == SHAPE_HALFSPACE or kb == SHAPE_HALFSPACE:
        flip = kb == SHAPE_HALFSPACE  # the plane is B: contacts found from it are flipped
        if flip:
            nh = _rot(RB, nB)
            return _plane_shape(nh, offB + _dot(nh, pB), ka, pA, RA, ra, verts, vA, cA, flip, margin, c_psi, c_n, c_pa, c_pb, start, limit)
        nh = _rot(RA, nA)
        return _plane_shape(nh, offA + _dot(nh, pA), kb, pB, RB, rb, verts, vB, cB, flip, margin, c_psi, c_n, c_pa, c_pb, start, limit)
    if ka == SHAPE_MESH or kb == SHAPE_MESH or ka < SHAPE_SPHERE or kb < SHAPE_SPHERE:
        return -1
    # canonical order: x has the lower kind (sphere < capsule < box); swapped: x is B
    swapped = ka > kb
    if swapped:
        kx, px, Rx, rx, hx, vx, ky, py, Ry, ry, hy, vy = kb, pB, RB, rb, hB, vB, ka, pA, RA, ra, hA, vA
    else:
        kx, px, Rx, rx, hx, vx, ky, py, Ry, ry, hy, vy = ka, pA, RA, ra, hA, vA, kb, pB, RB, rb, hB, vB
    if kx == SHAPE_SPHERE:
        cx = _core_point(verts, vx, px, Rx)
        if ky == SHAPE_SPHERE:
            psi, n, pa, pb = _rounded(cx, _core_point(verts, vy, py, Ry), rx, ry, (0.0, 0.0, 1.0))
        elif ky == SHAPE_CAPSULE:
            b0 = _core_point(verts, vy, py, Ry)
            b1 = _core_point(verts, vy + 1, py, Ry)
            c = _axpy(b0, _point_seg(cx, b0, b1), _sub(b1, b0))
            ax = _sub(b1, b0)
            nf = _perpendicular(ax) if _dot(ax, ax) > 1e-30 else (0.0, 0.0, 1.0)
            psi, n, pa, pb = _rounded(cx, c, rx, ry, nf)
        else:  # box: computed from the box to the sphere
            return _sphere_box(cx, rx, py, Ry, hy, margin, not swapped, c_psi, c_n, c_pa, c_pb, start, limit)
        if psi > margin:
            return 0
        _emit(c_psi, c_n, c_pa, c_pb, start, psi, n, pa, pb, swapped)
        return 1
    if kx == SHAPE_CAPSULE:
        a0 = _core_point(verts, vx, px, Rx)
        a1 = _core_point(verts, vx + 1, px, Rx)
        if ky == SHAPE_CAPSULE:
            return _capsule_capsule(
                a0,
                a1,
                rx,
                _core_point(verts, vy, py, Ry),
                _core_point(verts, vy + 1, py, Ry),
                ry,
                margin,
                swapped,
                c_psi,
                c_n,
                c_pa,
                c_pb,
                start,
                limit,
            )
        return _capsule_box(a0, a1, rx, py, Ry, hy, margin, not swapped, c_psi, c_n, c_pa, c_pb, start, limit)
    return _box_box(px, Rx, hx, py, Ry, hy, margin, swapped, c_psi, c_n, c_pa, c_pb, start, limit)


@numba.njit(cache=True)
def collide_all_3d(S, q, margin, c_psi, c_n, c_pa, c_pb, c_pair, fallback):
    """Contacts of every pair of the scene, as `collide_pair_3d` writes them, from index 0.

    c_pair[k] receives the pair of contact k; fallback[p] is set True for the pairs with no
    compiled test (they get no contacts here: use `fcl_pair_contacts`), False for the others.
    Returns the number of contacts written (stops adding pairs when the buffers are full).
    Faster than calling `collide_pair_3d` per pair: the scene's arrays are passed once (the
    pair test is `collide_pair_3d_inline`, inlined here).
    """
    count = np.int64(0)
    if S.dimension != 3:
        for p in range(S.pair_a.shape[0]):
            fallback[p] = True
        return 0
    for p in range(S.pair_a.shape[0]):
        k = collide_pair_3d_inline(S, q, p, margin, c_psi, c_n, c_pa, c_pb, count)
        fallback[p] = k < 0
        if k <= 0:
            continue
        for i in range(count, count + k):
            c_pair[i] = p
        count += k
    return count


# ----------------------------------------------------------------------------- python-fcl fallback


def fcl_pair_contacts(scenario, S, q, p, margin):
    """One contact of pair p from python-fcl's signed distance: [(psi, n, pa, pb)] or [] if psi > margin.

    For pairs without a compiled test (none in a spatial scene whose meshes have hull tables,
    which `compile_scene` always builds: convex meshes are compiled against every shape; this
    stays as an independent check). Its distance is a GJK upper bound, not exact (how far off:
    docs/measurements.md). Planes never reach fcl (its distance to a Halfspace crashes
    python-fcl 0.7): pairs with a plane use the compiled test.
    """
    a, b = int(S.pair_a[p]), int(S.pair_b[p])
    bodies = scenario.spec.bodies
    ga, gb = scenario.geometries[bodies[a].name], scenario.geometries[bodies[b].name]
    if ga.kind == "halfspace" or gb.kind == "halfspace":
        cap = int(S.pair_max_contacts[p])
        psi = np.empty(cap)
        n, pa, pb = np.empty((cap, 3)), np.empty((cap, 3)), np.empty((cap, 3))
        k = collide_pair_3d(S, np.asarray(q, float), p, float(margin), psi, n, pa, pb, 0)
        return [(float(psi[i]), n[i].copy(), pa[i].copy(), pb[i].copy()) for i in range(k)]

    from models.geometry import fcl_nearest_points  # python-fcl, through the one module that imports it

    placements = scenario.placements(np.asarray(q, float))
    Xa, Xb = placements[bodies[a].name], placements[bodies[b].name]
    psi, pa, pb = fcl_nearest_points(ga, Xa, gb, Xb)
    if psi > margin:
        return []
    gap = pb - pa
    length = float(np.linalg.norm(gap))
    if length > 1e-9 and abs(psi) > 1e-9:
        n = gap / length * (1.0 if psi > 0 else -1.0)  # penetrating: pb lies behind pa along n
    else:
        # touching: no direction between the points; use the centres of the shapes
        ca = Xa.rotation @ ga.core.mean(axis=0) + Xa.translation
        cb = Xb.rotation @ gb.core.mean(axis=0) + Xb.translation
        n = cb - ca
        norm = float(np.linalg.norm(n))
        n = n / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
    return [(psi, n, pa, pb)]

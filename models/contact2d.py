"""Planar narrowphase, compiled: contacts between rounded convex shapes and half-planes.

Every planar shape is a rounded convex core (point, segment or counter-clockwise polygon,
see `models.geometry`), so one kernel covers disc, capsule, box and polygon pairs:

1. the cores' signed distance and direction n (A to B): closest features when apart, the
   separating-axis test (edge normals of both cores, plus segment directions) when they
   overlap;
2. a *contact manifold*: a disc makes one contact; two cores with edges make up to two, by
   clipping the incident edge against the reference edge (the face whose normal is n), as
   in Box2D. Where the closest features are two vertices (n is no face normal), one contact.
3. a half-plane makes one contact per core vertex, which is exact for polygons.

Outputs follow `models.kinematics`: normal from A to B, pa on A, pb on B, psi = (pb - pa).n,
written into caller-owned buffers with 3 columns (z = 0). Only contacts with psi <= margin.
"""

from __future__ import annotations

import numba
import numpy as np

from models.kinematics import (
    BF_HSN,
    BF_HSO,
    BF_RADIUS,
    BI_KIND,
    BI_VCOUNT,
    BI_VSTART,
    PI_A,
    PI_B,
    SHAPE_HALFSPACE,
    planar_poses,
)

#: Below this core distance two cores count as touching (and overlapping: `_overlap`).
TINY = 1e-14
#: Below this core distance (m) the witness points' direction is dominated by their round-off
#: (about 1e-16 m here, so a direction error of 1e-6 at 1e-10 m): the normal is then the
#: separating axis of the cores' faces (`_penetration`), as for touching ones.
NEAR_TOUCH = 1e-10
#: A face is the reference face when its normal is this aligned with the witness direction.
FACE_ALIGNMENT = 1.0 - 1e-9
#: Relative preference for A's face over B's when both are aligned (keeps manifolds stable).
REFERENCE_BIAS = 1e-9
#: How far (m) a pair's gap along its last separating axis must exceed its reach before the
#: narrowphase is skipped (`apart_along`): far above the round-off of the exact distance and of
#: the axis's unit length (about 1e-16 m), so a skipped pair is one the narrowphase would also
#: have found apart.
APART_SLACK = 1e-12


@numba.njit(cache=True)
def core_scratch(bi):
    """The scratch of the general narrowphase (`_core_vs_core`): room for two bodies' world
    cores, (2, the most core vertices of a body, 2), so the narrowphase allocates nothing and
    the planar detection runs without numba's runtime (`models.contact.detect_planar_into`)."""
    most = 1
    for b in range(bi.shape[0]):
        most = max(most, bi[b, BI_VCOUNT])
    return np.empty((2, most, 2))


@numba.njit(cache=True)
def _world_core(bi, verts, poses, b, out):
    """Body b's core vertices in the world at its pose, written into out's first rows (out:
    one side of `core_scratch`; a call without numba's runtime returns no view of it)."""
    px, py, c, s = poses[b, 0], poses[b, 1], poses[b, 2], poses[b, 3]
    k = bi[b, BI_VCOUNT]
    v0 = bi[b, BI_VSTART]
    for i in range(k):
        vx = verts[v0 + i, 0]
        vy = verts[v0 + i, 1]
        out[i, 0] = px + c * vx - s * vy
        out[i, 1] = py + s * vx + c * vy


@numba.njit(cache=True, inline="always")
def _closest_on_segment(px, py, ax, ay, bx, by):
    dx, dy = bx - ax, by - ay
    den = dx * dx + dy * dy
    t = 0.0
    if den > 0.0:
        t = ((px - ax) * dx + (py - ay) * dy) / den
        t = min(1.0, max(0.0, t))
    return ax + t * dx, ay + t * dy


@numba.njit(cache=True)
def _n_edges(k):
    if k == 1:
        return 0
    if k == 2:
        return 1
    return k


@numba.njit(cache=True)
def _inside(px, py, P):
    k = P.shape[0]
    if k < 3:
        return False
    for i in range(k):
        j = i + 1 if i + 1 < k else 0
        ex, ey = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1]
        if ex * (py - P[i, 1]) - ey * (px - P[i, 0]) < 0.0:
            return False
    return True


@numba.njit(cache=True)
def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@numba.njit(cache=True)
def _segments_cross(P, i0, i1, Q, j0, j1):
    o1 = _orient(P[i0, 0], P[i0, 1], P[i1, 0], P[i1, 1], Q[j0, 0], Q[j0, 1])
    o2 = _orient(P[i0, 0], P[i0, 1], P[i1, 0], P[i1, 1], Q[j1, 0], Q[j1, 1])
    o3 = _orient(Q[j0, 0], Q[j0, 1], Q[j1, 0], Q[j1, 1], P[i0, 0], P[i0, 1])
    o4 = _orient(Q[j0, 0], Q[j0, 1], Q[j1, 0], Q[j1, 1], P[i1, 0], P[i1, 1])
    if o1 == 0.0 and o2 == 0.0 and o3 == 0.0 and o4 == 0.0:
        return False
    return o1 * o2 <= 0.0 and o3 * o4 <= 0.0


#: `_closer`'s slack on squared distances: far above their round-off (a few units of 1e-16).
DIST_FILTER = 1.0 + 1e-9


@numba.njit(cache=True, inline="always")
def _closer(dx, dy, best, best2):
    """(best, best2, closer) after a candidate at (dx, dy) in a distance search whose best so far
    is best, with best2 = best * best * DIST_FILTER (both inf at first): closer when
    hypot(dx, dy) is below best, which it then replaces. hypot is a libm call (about 6 ns here,
    against 1 for the sum of squares) and most candidates are farther than the best by far more
    than the squares' round-off, so it runs only where the squares do not rule the candidate
    out: the same results as hypot on every candidate, bit for bit."""
    d2 = dx * dx + dy * dy
    if d2 > best2:
        return best, best2, False
    d = np.hypot(dx, dy)
    if d < best:
        return d, d * d * DIST_FILTER, True
    return best, best2, False


@numba.njit(cache=True)
def _closest_features(P, Q):
    """Distance between two convex cores and witness points (cp on P, cq on Q)."""
    best = best2 = np.inf
    cpx = cpy = cqx = cqy = 0.0
    for swap in range(2):
        A = P if swap == 0 else Q
        B = Q if swap == 0 else P
        ka, kb = A.shape[0], B.shape[0]
        ne = _n_edges(kb)
        for i in range(ka):
            ax, ay = A[i, 0], A[i, 1]
            for e in range(max(ne, 1)):  # a single point is a zero-length segment
                j = e + 1 if e + 1 < kb else 0
                cx, cy = _closest_on_segment(ax, ay, B[e, 0], B[e, 1], B[j, 0], B[j, 1])
                best, best2, closer = _closer(ax - cx, ay - cy, best, best2)
                if closer:
                    if swap == 0:
                        cpx, cpy, cqx, cqy = ax, ay, cx, cy
                    else:
                        cpx, cpy, cqx, cqy = cx, cy, ax, ay
    return best, cpx, cpy, cqx, cqy


@numba.njit(cache=True)
def _overlap(P, Q, dist):
    if dist <= TINY:
        return True
    for i in range(P.shape[0]):
        if _inside(P[i, 0], P[i, 1], Q):
            return True
    for i in range(Q.shape[0]):
        if _inside(Q[i, 0], Q[i, 1], P):
            return True
    nep, neq = _n_edges(P.shape[0]), _n_edges(Q.shape[0])
    for e in range(nep):
        for f in range(neq):
            if _segments_cross(P, e, e + 1 if e + 1 < P.shape[0] else 0, Q, f, f + 1 if f + 1 < Q.shape[0] else 0):
                return True
    return False


@numba.njit(cache=True)
def _project_range(P, ax, ay):
    lo, hi = np.inf, -np.inf
    for i in range(P.shape[0]):
        v = P[i, 0] * ax + P[i, 1] * ay
        lo = min(lo, v)
        hi = max(hi, v)
    return lo, hi


@numba.njit(cache=True)
def _sat_axis(P, Q, best_depth, bnx, bny, ax, ay):
    """Update the minimum-penetration axis (oriented from P to Q) with candidate axis a."""
    plo, phi = _project_range(P, ax, ay)
    qlo, qhi = _project_range(Q, ax, ay)
    d1 = phi - qlo  # Q on the +a side of P
    d2 = qhi - plo  # Q on the -a side of P
    if d1 < best_depth:
        best_depth, bnx, bny = d1, ax, ay
    if d2 < best_depth:
        best_depth, bnx, bny = d2, -ax, -ay
    return best_depth, bnx, bny


@numba.njit(cache=True)
def _penetration(P, Q):
    """Penetration depth of overlapping cores and its direction from P to Q (unit)."""
    depth, nx, ny = np.inf, 0.0, 1.0
    for which in range(2):
        A = P if which == 0 else Q
        k = A.shape[0]
        for e in range(_n_edges(k)):
            j = e + 1 if e + 1 < k else 0
            dx, dy = A[j, 0] - A[e, 0], A[j, 1] - A[e, 1]
            L = np.hypot(dx, dy)
            depth, nx, ny = _sat_axis(P, Q, depth, nx, ny, dy / L, -dx / L)
            if k == 2:
                depth, nx, ny = _sat_axis(P, Q, depth, nx, ny, dx / L, dy / L)
    if depth == np.inf:  # two points at the same place
        depth = 0.0
    return max(depth, 0.0), nx, ny


@numba.njit(cache=True)
def core_distance(P, Q):
    """Signed distance of two cores, unit direction n (P to Q) and witness points.

    Returns (psi_core, nx, ny, cpx, cpy, cqx, cqy) with cq - cp = psi_core * n (to round-off
    below NEAR_TOUCH, where n is the separating face axis).
    """
    dist, cpx, cpy, cqx, cqy = _closest_features(P, Q)
    if not _overlap(P, Q, dist):
        if dist > NEAR_TOUCH:
            return dist, (cqx - cpx) / dist, (cqy - cpy) / dist, cpx, cpy, cqx, cqy
        _, nx, ny = _penetration(P, Q)  # all but touching: the faces' separating axis
        return dist, nx, ny, cpx, cpy, cqx, cqy
    depth, nx, ny = _penetration(P, Q)
    # witness points: the deepest point of the core that is a single point, else the
    # support points along n (refined by the manifold for polygon pairs)
    if Q.shape[0] == 1:
        cqx, cqy = Q[0, 0], Q[0, 1]
        return -depth, nx, ny, cqx + depth * nx, cqy + depth * ny, cqx, cqy
    if P.shape[0] == 1:
        cpx, cpy = P[0, 0], P[0, 1]
        return -depth, nx, ny, cpx, cpy, cpx - depth * nx, cpy - depth * ny
    best = np.inf
    for i in range(Q.shape[0]):
        v = Q[i, 0] * nx + Q[i, 1] * ny
        if v < best:
            best = v
            cqx, cqy = Q[i, 0], Q[i, 1]
    return -depth, nx, ny, cqx + depth * nx, cqy + depth * ny, cqx, cqy


# without numba's runtime: a per-step call whose array arguments are not reference-counted
@numba.njit(cache=True, _nrt=False)
def _write(c_psi, c_n, c_pa, c_pb, idx, psi, nx, ny, pax, pay, pbx, pby):
    c_psi[idx] = psi
    c_n[idx, 0], c_n[idx, 1], c_n[idx, 2] = nx, ny, 0.0
    c_pa[idx, 0], c_pa[idx, 1], c_pa[idx, 2] = pax, pay, 0.0
    c_pb[idx, 0], c_pb[idx, 1], c_pb[idx, 2] = pbx, pby, 0.0


@numba.njit(cache=True)
def _best_face(A, nx, ny):
    """Index and alignment of A's face whose outward normal best matches (nx, ny)."""
    k = A.shape[0]
    best, index, sign = -np.inf, -1, 1.0
    for e in range(_n_edges(k)):
        j = e + 1 if e + 1 < k else 0
        dx, dy = A[j, 0] - A[e, 0], A[j, 1] - A[e, 1]
        L = np.hypot(dx, dy)
        mx, my = dy / L, -dx / L
        a = mx * nx + my * ny
        if a > best:
            best, index, sign = a, e, 1.0
        if k == 2 and -a > best:  # a segment has two sides
            best, index, sign = -a, e, -1.0
    return index, sign, best


@numba.njit(cache=True)
def _halfspace_vs_core(bi, bf, verts, poses, h, b, h_is_a, margin, c_psi, c_n, c_pa, c_pb, start):
    px, py, c, s = poses[h, 0], poses[h, 1], poses[h, 2], poses[h, 3]
    lnx, lny = bf[h, BF_HSN], bf[h, BF_HSN + 1]
    mx, my = c * lnx - s * lny, s * lnx + c * lny
    off = bf[h, BF_HSO] + mx * px + my * py
    r = bf[b, BF_RADIUS]
    gx, gy, gc, gs = poses[b, 0], poses[b, 1], poses[b, 2], poses[b, 3]
    count = np.int64(0)
    for i in range(bi[b, BI_VSTART], bi[b, BI_VSTART] + bi[b, BI_VCOUNT]):  # the core's vertices in the world, one by one
        vx, vy = _world_vertex(verts, gx, gy, gc, gs, i)
        sep = vx * mx + vy * my - off - r
        if sep > margin:
            continue
        bx, by = vx - r * mx, vy - r * my  # on the shape's surface
        hx, hy = bx - sep * mx, by - sep * my  # on the boundary line
        if h_is_a:
            _write(c_psi, c_n, c_pa, c_pb, start + count, sep, mx, my, hx, hy, bx, by)
        else:
            _write(c_psi, c_n, c_pa, c_pb, start + count, sep, -mx, -my, bx, by, hx, hy)
        count += 1
    return count


# without numba's runtime: a per-step call whose array arguments are not reference-counted
@numba.njit(cache=True, _nrt=False)
def apart_along(bi, bf, verts, poses, a, b, nx, ny):
    """A lower bound of the signed distance of bodies a and b (two cores with their radii): their
    gap along the unit axis (nx, ny), from a to b, with both at their poses (separating-axis
    theorem: two convex sets are at least their projections' gap apart along any unit axis).
    The axis is the pair's last exact direction (`collide_2d`), so while the pair stays apart
    this bound follows its distance closely, at a few flops a vertex and no allocation; a zero
    axis gives 0 minus the radii."""
    hi_a, lo_b = -np.inf, np.inf
    for body in (a, b):
        px, py, c, s = poses[body, 0], poses[body, 1], poses[body, 2], poses[body, 3]
        v0 = bi[body, BI_VSTART]
        for i in range(v0, v0 + bi[body, BI_VCOUNT]):
            vx, vy = verts[i, 0], verts[i, 1]
            d = (px + c * vx - s * vy) * nx + (py + s * vx + c * vy) * ny
            if body == a:
                hi_a = max(hi_a, d)
            else:
                lo_b = min(lo_b, d)
    return lo_b - hi_a - bf[a, BF_RADIUS] - bf[b, BF_RADIUS]


@numba.njit(cache=True, inline="always")
def _world_vertex(verts, px, py, c, s, i):
    """Vertex i at the pose (px, py, cos, sin): as `_world_core` computes it."""
    vx = verts[i, 0]
    vy = verts[i, 1]
    return px + c * vx - s * vy, py + s * vx + c * vy


# without numba's runtime: a per-step call whose array arguments are not reference-counted
@numba.njit(cache=True, _nrt=False)
def _point_vs_polygon(bi, bf, verts, poses, a, b, margin, c_psi, c_n, c_pa, c_pb, start, axis):
    """`_core_vs_core` for a single-point core (a disc's) against a polygon's (three or more
    vertices) while the point lies outside the polygon by more than NEAR_TOUCH: the operations of
    the general path (`_closest_features`, `_overlap`, `core_distance` and the single contact) in
    the same order, so the same contact bit for bit, without building the world cores (two
    allocations) and at one call. Returns -1 where the general path must decide (the point
    inside the polygon or all but touching it)."""
    point_is_a = bi[a, BI_VCOUNT] == 1
    pt, pg = (a, b) if point_is_a else (b, a)
    X, Y = _world_vertex(verts, poses[pt, 0], poses[pt, 1], poses[pt, 2], poses[pt, 3], bi[pt, BI_VSTART])
    gx, gy, gc, gs = poses[pg, 0], poses[pg, 1], poses[pg, 2], poses[pg, 3]
    g0, k = bi[pg, BI_VSTART], bi[pg, BI_VCOUNT]
    best = best2 = np.inf
    cpx = cpy = cqx = cqy = 0.0
    for swap in range(2):  # _closest_features(P, Q): first P's vertices against Q, then Q's against P
        if (swap == 0) != point_is_a:  # the polygon's vertices against the point (a zero-length segment)
            for i in range(k):
                ax, ay = _world_vertex(verts, gx, gy, gc, gs, g0 + i)
                cx, cy = _closest_on_segment(ax, ay, X, Y, X, Y)
                best, best2, closer = _closer(ax - cx, ay - cy, best, best2)
                if closer:
                    if point_is_a:  # swap 1: A = the polygon (Q), B = the point (P)
                        cpx, cpy, cqx, cqy = cx, cy, ax, ay
                    else:
                        cpx, cpy, cqx, cqy = ax, ay, cx, cy
        else:  # the point against the polygon's edges (each vertex transformed once, the
            # first kept for the last edge: the values of `_world_core`'s, without a modulo)
            fx, fy = _world_vertex(verts, gx, gy, gc, gs, g0)
            e1x, e1y = fx, fy
            for e in range(k):
                e0x, e0y = e1x, e1y
                e1x, e1y = (fx, fy) if e + 1 == k else _world_vertex(verts, gx, gy, gc, gs, g0 + e + 1)
                cx, cy = _closest_on_segment(X, Y, e0x, e0y, e1x, e1y)
                best, best2, closer = _closer(X - cx, Y - cy, best, best2)
                if closer:
                    if point_is_a:
                        cpx, cpy, cqx, cqy = X, Y, cx, cy
                    else:
                        cpx, cpy, cqx, cqy = cx, cy, X, Y
    if best <= NEAR_TOUCH:  # (also _overlap's dist <= TINY)
        return -1
    inside = True  # _inside(point, polygon), its vertices as the edges' loop takes them
    fx, fy = _world_vertex(verts, gx, gy, gc, gs, g0)
    jx, jy = fx, fy
    for i in range(k):
        ix, iy = jx, jy
        jx, jy = (fx, fy) if i + 1 == k else _world_vertex(verts, gx, gy, gc, gs, g0 + i + 1)
        ex, ey = jx - ix, jy - iy
        if ex * (Y - iy) - ey * (X - ix) < 0.0:
            inside = False
            break
    if inside:
        return -1
    psi_core, nx, ny = best, (cqx - cpx) / best, (cqy - cpy) / best
    ra, rb = bf[a, BF_RADIUS], bf[b, BF_RADIUS]
    axis[0], axis[1] = nx, ny  # as `_core_vs_core` keeps it
    if psi_core - ra - rb > margin:
        return 0
    _write(c_psi, c_n, c_pa, c_pb, start, psi_core - ra - rb, nx, ny, cpx + ra * nx, cpy + ra * ny, cqx - rb * nx, cqy - rb * ny)
    return 1


@numba.njit(cache=True)
def _core_vs_core(bi, bf, verts, poses, a, b, margin, c_psi, c_n, c_pa, c_pb, start, axis, cores):
    _world_core(bi, verts, poses, a, cores[0])
    _world_core(bi, verts, poses, b, cores[1])
    P, Q = cores[0, : bi[a, BI_VCOUNT]], cores[1, : bi[b, BI_VCOUNT]]
    ra, rb = bf[a, BF_RADIUS], bf[b, BF_RADIUS]
    psi_core, nx, ny, cpx, cpy, cqx, cqy = core_distance(P, Q)
    axis[0], axis[1] = nx, ny  # the direction from a to b, kept for `apart_along`
    if psi_core - ra - rb > margin:
        return 0
    single = P.shape[0] == 1 or Q.shape[0] == 1
    if not single:
        fa, sa, al_a = _best_face(P, nx, ny)
        fb, sb, al_b = _best_face(Q, -nx, -ny)
        if max(al_a, al_b) < FACE_ALIGNMENT:
            single = True
    if single:
        _write(c_psi, c_n, c_pa, c_pb, start, psi_core - ra - rb, nx, ny, cpx + ra * nx, cpy + ra * ny, cqx - rb * nx, cqy - rb * ny)
        return 1
    # reference face on A (normal m = its outward normal) or on B
    ref_is_a = al_a + REFERENCE_BIAS >= al_b
    R = P if ref_is_a else Q
    I = Q if ref_is_a else P
    f = fa if ref_is_a else fb
    sgn = sa if ref_is_a else sb
    r_ref = ra if ref_is_a else rb
    r_inc = rb if ref_is_a else ra
    kr = R.shape[0]
    r0x, r0y = R[f, 0], R[f, 1]
    f1 = f + 1 if f + 1 < kr else 0
    r1x, r1y = R[f1, 0], R[f1, 1]
    ux, uy = r1x - r0x, r1y - r0y
    L = np.hypot(ux, uy)
    ux, uy = ux / L, uy / L
    mx, my = sgn * uy, -sgn * ux
    # incident face: the face of I most anti-parallel to m
    g, _, _ = _best_face(I, -mx, -my)
    ki = I.shape[0]
    i0x, i0y = I[g, 0], I[g, 1]
    g1 = g + 1 if g + 1 < ki else 0
    i1x, i1y = I[g1, 0], I[g1, 1]
    # clip the incident segment to the reference face's extent [0, L] along u
    t0 = (i0x - r0x) * ux + (i0y - r0y) * uy
    t1 = (i1x - r0x) * ux + (i1y - r0y) * uy
    count = np.int64(0)
    for end in range(2):
        bound = 0.0 if end == 0 else L
        # point of the incident segment at u-coordinate clamp
        if t0 == t1:
            if end == 1:
                break
            cx, cy = i0x, i0y
            tc = t0
            if tc < 0.0 or tc > L:
                continue
        else:
            lo, hi = min(t0, t1), max(t0, t1)
            tc = min(max(bound, lo), hi)
            if tc < 0.0 or tc > L:
                continue
            w = (tc - t0) / (t1 - t0)
            cx, cy = i0x + w * (i1x - i0x), i0y + w * (i1y - i0y)
        sep_core = (cx - r0x) * mx + (cy - r0y) * my
        sep = sep_core - r_ref - r_inc
        if sep > margin:
            continue
        incx, incy = cx - r_inc * mx, cy - r_inc * my
        refx, refy = cx - sep_core * mx + r_ref * mx, cy - sep_core * my + r_ref * my
        if count == 1:
            prev = start
            dx = incx - (c_pb[prev, 0] if ref_is_a else c_pa[prev, 0])
            dy = incy - (c_pb[prev, 1] if ref_is_a else c_pa[prev, 1])
            if dx * dx + dy * dy <= TINY * TINY:
                continue  # both clip bounds landed on one point
        if ref_is_a:
            _write(c_psi, c_n, c_pa, c_pb, start + count, sep, mx, my, refx, refy, incx, incy)
        else:
            _write(c_psi, c_n, c_pa, c_pb, start + count, sep, -mx, -my, incx, incy, refx, refy)
        count += 1
    if count == 0:
        _write(c_psi, c_n, c_pa, c_pb, start, psi_core - ra - rb, nx, ny, cpx + ra * nx, cpy + ra * ny, cqx - rb * nx, cqy - rb * ny)
        count = 1
    elif psi_core > TINY:
        # apart, every clipped point lies at least the exact distance from the reference face;
        # its closest one may lie farther when the closest features are not the clipped ones
        # (a vertex beside the face): that point takes the exact distance, its incident point
        # moved along the normal, so that the manifold's smallest psi is the signed distance
        k = start
        for j in range(start + 1, start + count):
            if c_psi[j] < c_psi[k]:
                k = j
        exact = psi_core - ra - rb
        if exact < c_psi[k]:
            c_psi[k] = exact
            if ref_is_a:
                c_pb[k, 0], c_pb[k, 1] = c_pa[k, 0] + exact * c_n[k, 0], c_pa[k, 1] + exact * c_n[k, 1]
            else:
                c_pa[k, 0], c_pa[k, 1] = c_pb[k, 0] - exact * c_n[k, 0], c_pb[k, 1] - exact * c_n[k, 1]
    return count


@numba.njit(cache=True, inline="always")
def collide_2d(bi, bf, verts, poses, a, b, margin, c_psi, c_n, c_pa, c_pb, start, axis, cores):
    """Contacts between bodies a and b with psi <= margin, written from index start; returns how many.

    poses: (nb, 4) rows (x, y, cos theta, sin theta) from `models.kinematics.planar_poses`.
    axis (2,): for two cores, set to the unit direction from a's core to b's (`apart_along`).
    cores: the general narrowphase's scratch (`core_scratch`).
    """
    count = np.int64(0)
    ka, kb = bi[a, BI_KIND], bi[b, BI_KIND]
    if ka == SHAPE_HALFSPACE and kb != SHAPE_HALFSPACE:
        count = _halfspace_vs_core(bi, bf, verts, poses, a, b, np.bool_(True), margin, c_psi, c_n, c_pa, c_pb, start)
    elif kb == SHAPE_HALFSPACE and ka != SHAPE_HALFSPACE:
        count = _halfspace_vs_core(bi, bf, verts, poses, b, a, np.bool_(False), margin, c_psi, c_n, c_pa, c_pb, start)
    elif ka != SHAPE_HALFSPACE:
        count = -1
        na, nb = bi[a, BI_VCOUNT], bi[b, BI_VCOUNT]
        if (na == 1 and nb >= 3) or (nb == 1 and na >= 3):  # a disc and a polygon: one call
            count = _point_vs_polygon(bi, bf, verts, poses, a, b, margin, c_psi, c_n, c_pa, c_pb, start, axis)
        if count < 0:
            count = _core_vs_core(bi, bf, verts, poses, a, b, margin, c_psi, c_n, c_pa, c_pb, start, axis, cores)
    return count


@numba.njit(cache=True)
def collide_pair_2d(S, q, p, margin, c_psi, c_n, c_pa, c_pb, start):
    """Contacts of pair p at configuration q (convenience entry; the rollout uses collide_2d)."""
    poses = np.zeros((S.bi.shape[0], 4))
    planar_poses(S.bi, S.bf, q, poses)
    axis = np.zeros(2)
    return collide_2d(
        S.bi, S.bf, S.verts, poses, S.pi[p, PI_A], S.pi[p, PI_B], margin, c_psi, c_n, c_pa, c_pb, start, axis, core_scratch(S.bi)
    )

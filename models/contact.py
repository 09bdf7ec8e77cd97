"""Contact detection and contact Jacobians, compiled: broadphase -> narrowphase -> W_n, W_t, W_o.

The paper's Section 3.1: for every candidate pair, the signed distance psi_i(q), the contact
frame (normal n, tangents t and, in space, o), and the Jacobians
W_{n,t,o} = G(q)^T (d psi_{n,t,o} / d q)^T, here assembled directly in velocity space: the
column of contact i holds, for each free DOF, the rate at which that DOF moves B's contact
point relative to A's along the direction (translation: the direction itself; rotation:
r x direction, r from the body's origin to its contact point). Only free DOFs have rows.

Broadphase: a pair is skipped when its bounding spheres stay apart by more than one step
can close: ``margin + h * (speed bound of A + speed bound of B)``, with a body's speed bound
|v| + |w| * (its bounding radius). Two bodies that never move are never pairs. A rollout's
step that moves a body further than its detection allowed for (a memoryless or kinematic
step: its velocity is not the last one's) is taken again over the contacts its motion reaches
(`step_outran`, `models.rollout.rollout_kernel`).

Everything here runs in numba; `contact_frames` is the Python-facing convenience.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from models.contact2d import APART_SLACK, apart_along, collide_2d, core_scratch
from models.contact3d import _basis, collide_pair_3d_inline, pose_of
from models.kinematics import (
    BF_BOUND,
    BF_HSN,
    BF_HSO,
    BF_POS,
    BF_QUAT,
    BF_SCRIPT,
    BF_SCRIPT_V,
    BF_SPEED,
    BI_KIND,
    BI_QMAP,
    BI_VMAP,
    KEPT_POSE_COLUMNS,
    PI_A,
    PI_B,
    PI_INERT,
    Q_ANGLE,
    SHAPE_HALFSPACE,
    V_ANGLE,
    V_WX,
    SceneData,
    kernel_array,
    planar_poses_kept,
    positions,
)

#: The one contact margin: contacts are kept while psi <= this plus what one step can close (m).
#: Rollouts detect with it, and so does `contact_frames` by default.
CONTACT_MARGIN = 1e-3
#: The step-closing margin is multiplied by this for safety against curved motion.
MARGIN_SAFETY = 2.0


class ContactSet(NamedTuple):
    """The contacts of one step as the compiled step reads them: buffers of a capacity (the
    most contacts the scene's pairs can produce at once, `contact_buffers`), of which the first
    nc are the step's (nc travels beside the set: the rollout refills the buffers in place, so
    the hot loop builds no new tuple). Symbols as in the paper: psi the signed distances, W_n,
    W_t, W_o the contact Jacobians in velocity coordinates (one column per contact). The
    frames (n, t, o, contact points) stay with the rollout: the step does not read them."""

    pair: np.ndarray  # int64[cap]: contact i's pair (row of SceneData.pi / .pf)
    psi: np.ndarray  # float64[cap]: signed distance, m (negative: penetration)
    slot: np.ndarray  # int64[cap]: its deformation / warm-start slot (the pair's first slot + rank in the pair)
    W_n: np.ndarray  # float64[nv, cap]
    W_t: np.ndarray  # float64[nv, cap]
    W_o: np.ndarray  # float64[nv, cap] (space only)
    bias: np.ndarray  # float64[cap, 3]: velocity along (n, t, o) from scripted obstacles (`scripted_bias`)


@numba.njit(cache=True)
def contact_buffers(pi, nv):
    """(ContactSet of zeros sized for the scene's pair table pi, first_slot (n_pairs,): each
    pair's first slot). Capacity: 1 + the pairs' contact counts."""
    cap = 1
    first_slot = np.zeros(pi.shape[0], np.int64)
    for p in range(pi.shape[0]):
        first_slot[p] = cap - 1
        cap += pi[p, 2]
    contacts = ContactSet(
        np.zeros(cap, np.int64),
        np.zeros(cap),
        np.zeros(cap, np.int64),
        np.zeros((nv, cap)),
        np.zeros((nv, cap)),
        np.zeros((nv, cap)),
        np.zeros((cap, 3)),
    )
    return contacts, first_slot


@numba.njit(cache=True, inline="always")
def _speed_margins(bi, bf, nu, scale, out):
    """out[b] = scale times an upper bound of the speed of any point of body b (0 for fixed
    bodies; a scripted obstacle's from its script), for every body: one loop here, since a
    per-body helper's array arguments are reference-counted on every pass of the caller's loop."""
    for b in range(bi.shape[0]):
        v2 = 0.0
        w2 = 0.0
        for k in range(3):
            if bi[b, BI_VMAP + k] >= 0:
                v2 += nu[bi[b, BI_VMAP + k]] ** 2
            if bi[b, BI_VMAP + V_WX + k] >= 0:
                w2 += nu[bi[b, BI_VMAP + V_WX + k]] ** 2
        if bi[b, BI_VMAP + V_ANGLE] >= 0:
            w2 += nu[bi[b, BI_VMAP + V_ANGLE]] ** 2
        bound = np.sqrt(v2) + bf[b, BF_SPEED]
        if w2 > 0.0:
            bound += np.sqrt(w2) * bf[b, BF_BOUND]
        out[b] = scale * bound


@numba.njit(cache=True, inline="always")
def step_outran(bi, bf, h, margin, nu_step, speed, moved):
    """Whether a step whose positions moved at nu_step (the new velocity; with theta < 1 the blend
    moves no faster than the larger of the two, and the old one is within its margin) carried
    some body further than the detection before it allowed for: each pair is detected out to
    margin plus both bodies' speed margins (speed, `_speed_margins` at the velocity detected
    with), so a body that moved at most its own plus half the margin cannot have closed a
    pair's gap unseen. A memoryless (quasistatic) or kinematic step's velocity is not the last
    one's, so its detection can fall short. moved: (nb,) scratch, each body's bound over h."""
    _speed_margins(bi, bf, nu_step, h, moved)
    for b in range(bi.shape[0]):
        if moved[b] > speed[b] + 0.5 * margin:
            return True
    return False


@numba.njit(cache=True, inline="always")
def widened_velocity(nu, nu_step, probe):
    """probe = max(|nu|, |nu_step|) entrywise: a velocity whose speed bounds cover both (the
    bound is monotone in each entry's magnitude), to detect a step's contacts again with
    (`step_outran`)."""
    for j in range(nu.shape[0]):
        probe[j] = max(abs(nu[j]), abs(nu_step[j]))


@numba.njit(cache=True, inline="always")
def _halfspace_normal(bi, bf, q, h, pos):
    """World normal (nx, ny, nz) and offset of half-space body h."""
    lx, ly, lz = bf[h, BF_HSN], bf[h, BF_HSN + 1], bf[h, BF_HSN + 2]
    nx, ny, nz = lx, ly, lz
    if bi[h, BI_QMAP + Q_ANGLE] >= 0 or bf[h, BF_QUAT + 1] != 0.0 or bf[h, BF_QUAT + 2] != 0.0 or bf[h, BF_QUAT + 3] != 0.0:
        w, x, y, z = bf[h, BF_QUAT], bf[h, BF_QUAT + 1], bf[h, BF_QUAT + 2], bf[h, BF_QUAT + 3]
        if bi[h, BI_QMAP + Q_ANGLE] >= 0:
            half = 0.5 * q[bi[h, BI_QMAP + Q_ANGLE]]
            w, x, y, z = np.cos(half), 0.0, 0.0, np.sin(half)
        nx = (1 - 2 * (y * y + z * z)) * lx + 2 * (x * y - w * z) * ly + 2 * (x * z + w * y) * lz
        ny = 2 * (x * y + w * z) * lx + (1 - 2 * (x * x + z * z)) * ly + 2 * (y * z - w * x) * lz
        nz = 2 * (x * z - w * y) * lx + 2 * (y * z + w * x) * ly + (1 - 2 * (x * x + y * y)) * lz
    off = bf[h, BF_HSO] + nx * pos[h, 0] + ny * pos[h, 1] + nz * pos[h, 2]
    return nx, ny, nz, off


@numba.njit(cache=True, inline="always")
def _broadphase(bi, bf, q, pi, pos, speed, margin, reach):
    """First broadphase stage, for every pair: reach[p] = margin + both bodies' speed margins
    (speed, `_speed_margins`) where the pair's bounding spheres (against a half-space: the
    sphere against the plane) are within it, -inf where they are not or the pair is inert.
    One loop here, as `_speed_margins`."""
    for p in range(pi.shape[0]):
        reach[p] = -np.inf
        if pi[p, PI_INERT]:
            continue
        a, b = pi[p, PI_A], pi[p, PI_B]
        r = margin + speed[a] + speed[b]
        keep = False
        ka, kb = bi[a, BI_KIND], bi[b, BI_KIND]
        if ka == SHAPE_HALFSPACE or kb == SHAPE_HALFSPACE:
            h, o = a, b
            if ka != SHAPE_HALFSPACE:
                h, o = b, a
            if bi[o, BI_KIND] != SHAPE_HALFSPACE:
                nx, ny, nz, off = _halfspace_normal(bi, bf, q, h, pos)
                keep = nx * pos[o, 0] + ny * pos[o, 1] + nz * pos[o, 2] - off - bf[o, BF_BOUND] <= r
        else:
            d = np.sqrt((pos[a, 0] - pos[b, 0]) ** 2 + (pos[a, 1] - pos[b, 1]) ** 2 + (pos[a, 2] - pos[b, 2]) ** 2)
            keep = d - bf[a, BF_BOUND] - bf[b, BF_BOUND] <= r
        if keep:
            reach[p] = r


@numba.njit(cache=True)
def detect_contacts(S, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, unsupported):
    """All contacts with psi <= their pair's margin. Returns (count, number of unsupported pairs).

    A pair's margin is ``margin + MARGIN_SAFETY * h * (speed bounds of both bodies)``.
    Buffers hold at least sum(S.pair_max_contacts) rows. Pairs the compiled kernels cannot
    handle are listed in ``unsupported``: since convex meshes are compiled (against every
    spatial shape), only a mesh or box without hull tables in `SceneData` would be.
    """
    pos, poses, speed, reach, axis, cores = planar_scratch(S.bi, S.pi.shape[0])
    return detect_contacts_into(S, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, poses, speed, reach, axis, cores)


@numba.njit(cache=True, inline="always")
def detect_contacts_into(S, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, poses, speed, reach, axis, cores):
    """`detect_contacts` on the caller's scratch (`planar_scratch`; in space poses, axis and cores are
    unused). The rollout's runs, compiled without numba's runtime (`models.rollout._free_run`,
    `_contact_run`), call it; the loops compiled with it (`rollout_kernel`'s, `stage_loop`'s)
    dispatch on the dimension themselves, on the scene's arrays unpacked: there an inlined
    helper taking the scene would count its 30-odd arrays' references every step (`rollout_kernel`
    calls it only to detect again for a step it takes again, `step_outran`)."""
    if S.dimension == 2:
        bi, bf, verts, pi = S.bi, S.bf, S.verts, S.pi
        nc = detect_planar_into(bi, bf, verts, pi, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, pos, poses, speed, reach, axis, cores)
        return nc, 0
    return detect_spatial_into(S, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, speed, reach)


@numba.njit(cache=True)
def detect_planar(bi, bf, verts, pi, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb):
    """detect_contacts for planar scenes on the packed tables."""
    pos, poses, speed, reach, axis, cores = planar_scratch(bi, pi.shape[0])
    return detect_planar_into(bi, bf, verts, pi, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, pos, poses, speed, reach, axis, cores)


@numba.njit(cache=True, inline="always")
def planar_scratch(bi, n_pairs):
    """The planar detection's scratch (`detect_planar_into`) for the bodies bi: per body its
    position (nb, 3), pose (nb, KEPT_POSE_COLUMNS: `planar_poses_kept`, which carries over from
    step to step) and speed margin (nb,), per pair its reach (n_pairs,) and last separating
    axis (n_pairs, 2; zero: none yet), which carries over too, and the general narrowphase's
    world cores (`models.contact2d.core_scratch`). C-contiguous arrays, not views of one table:
    a strided view compiled the narrowphase kernels a second time, beside the C-contiguous
    arrays Python passes them."""
    nb = bi.shape[0]
    poses = np.full((nb, KEPT_POSE_COLUMNS), np.nan)
    return np.empty((nb, 3)), poses, np.empty(nb), np.empty(n_pairs), np.zeros((n_pairs, 2)), core_scratch(bi)


# without numba's runtime, as `detect_spatial_into`: the rollout's per-step call, on its scratch
# (`core_scratch` holds the general narrowphase's world cores, which it allocated before)
@numba.njit(cache=True, _nrt=False)
def detect_planar_into(bi, bf, verts, pi, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, pos, poses, speed, reach, axis, cores):
    """detect_planar with the caller's scratch (`planar_scratch`): the rollout's hot path.

    Between the broadphase and the narrowphase, a pair of two cores is skipped when its gap
    along its last separating axis (`apart_along`, the axis kept in the scratch from the step
    that last ran its narrowphase) exceeds its reach by APART_SLACK: the narrowphase would find
    it apart too, so the contacts are the same, without its allocations and distance search."""
    positions(bi, bf, q, pos)
    planar_poses_kept(bi, bf, q, poses)
    _speed_margins(bi, bf, nu, MARGIN_SAFETY * h, speed)
    _broadphase(bi, bf, q, pi, pos, speed, margin, reach)
    # np.int64: a counter started at a literal 0 and passed to a compiled function compiles
    # that function twice, for Literal[int](0) (numba's first typing pass) and for int64
    nc = np.int64(0)
    for p in range(pi.shape[0]):
        r = reach[p]
        if r > -np.inf:
            a, b = pi[p, PI_A], pi[p, PI_B]
            if (
                bi[a, BI_KIND] != SHAPE_HALFSPACE
                and bi[b, BI_KIND] != SHAPE_HALFSPACE
                and apart_along(bi, bf, verts, poses, a, b, axis[p, 0], axis[p, 1]) > r + APART_SLACK
            ):
                continue
            k = collide_2d(bi, bf, verts, poses, a, b, r, c_psi, c_n, c_pa, c_pb, nc, axis[p], cores)
            for i in range(nc, nc + k):
                c_pair[i] = p
            nc += k
    return nc


@numba.njit(cache=True, inline="always")
def _world_aabb(qmap, base_pos, base_quat, vstart, vcount, verts, radius, q, b):
    """Body b's world bounding box at q, (lo x, y, z, hi x, y, z): without allocating, and on
    the arrays of `SceneData` it reads, not the scene (the broadphase runs per pair each step,
    and the scene's ~30 arrays would be reference-counted on every pass)."""
    (px, py, pz), R = pose_of(qmap, base_pos, base_quat, q, b)
    lx, ly, lz, hx, hy, hz = np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf
    for i in range(vstart[b], vstart[b] + vcount[b]):
        vx, vy, vz = verts[i, 0], verts[i, 1], verts[i, 2]
        x = px + R[0][0] * vx + R[0][1] * vy + R[0][2] * vz
        y = py + R[1][0] * vx + R[1][1] * vy + R[1][2] * vz
        z = pz + R[2][0] * vx + R[2][1] * vy + R[2][2] * vz
        lx, ly, lz = min(lx, x), min(ly, y), min(lz, z)
        hx, hy, hz = max(hx, x), max(hy, y), max(hz, z)
    r = radius[b]
    return lx - r, ly - r, lz - r, hx + r, hy + r, hz + r


@numba.njit(cache=True, inline="always")
def _aabbs_apart(qmap, base_pos, base_quat, vstart, vcount, verts, radius, q, a, b, reach):
    """Second broadphase stage in space: world bounding boxes farther apart than reach."""
    a0, a1, a2, a3, a4, a5 = _world_aabb(qmap, base_pos, base_quat, vstart, vcount, verts, radius, q, a)
    b0, b1, b2, b3, b4, b5 = _world_aabb(qmap, base_pos, base_quat, vstart, vcount, verts, radius, q, b)
    return b0 - a3 > reach or a0 - b3 > reach or b1 - a4 > reach or a1 - b4 > reach or b2 - a5 > reach or a2 - b5 > reach


@numba.njit(cache=True)
def detect_spatial(S, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, unsupported):
    """detect_contacts for spatial scenes (`detect_spatial_into` on scratch of its own)."""
    pos, _, speed, reach, _, _ = planar_scratch(S.bi, S.pi.shape[0])
    return detect_spatial_into(S, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, speed, reach)


# without numba's runtime: the rollout's per-step call, on its scratch (allocating its three
# arrays and counting the references of the scene's arrays took 1.6 us a step at box_push_3d's
# push against 0.8-0.9)
@numba.njit(cache=True, _nrt=False)
def detect_spatial_into(S, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, speed, reach):
    """detect_spatial with the caller's scratch (`planar_scratch`'s pos (nb, 3), speed (nb) and
    reach (n_pairs)): the rollout's hot path."""
    bi, bf, pi = S.bi, S.bf, S.pi
    positions(bi, bf, q, pos)
    _speed_margins(bi, bf, nu, MARGIN_SAFETY * h, speed)
    _broadphase(bi, bf, q, pi, pos, speed, margin, reach)
    qmap, base_pos, base_quat, vstart, vcount, verts, radius = S.qmap, S.base_pos, S.base_quat, S.vstart, S.vcount, S.verts, S.radius
    nc = np.int64(0)
    n_unsupported = 0
    for p in range(pi.shape[0]):
        r = reach[p]
        if r == -np.inf:
            continue
        a, b = pi[p, PI_A], pi[p, PI_B]
        if bi[a, BI_KIND] != SHAPE_HALFSPACE and bi[b, BI_KIND] != SHAPE_HALFSPACE:
            if _aabbs_apart(qmap, base_pos, base_quat, vstart, vcount, verts, radius, q, a, b, r):
                continue
        k = collide_pair_3d_inline(S, q, p, r, c_psi, c_n, c_pa, c_pb, nc)
        if k < 0:
            unsupported[n_unsupported] = p
            n_unsupported += 1
        else:
            for i in range(nc, nc + k):
                c_pair[i] = p
            nc += k
    return nc, n_unsupported


@numba.njit(cache=True)
def tangents(S, nc, c_n, c_t, c_o):
    """Tangent directions: planar t = z x n; spatial (t, o) an orthonormal basis with n."""
    tangents_packed(S.dimension, nc, c_n, c_t, c_o)


@numba.njit(cache=True)
def tangents_packed(dimension, nc, c_n, c_t, c_o):
    for i in range(nc):
        if dimension == 2:
            c_t[i, 0], c_t[i, 1], c_t[i, 2] = -c_n[i, 1], c_n[i, 0], 0.0
        else:
            t, o = _basis((c_n[i, 0], c_n[i, 1], c_n[i, 2]))  # (`tangent_basis` without its arrays)
            c_t[i, 0], c_t[i, 1], c_t[i, 2] = t[0], t[1], t[2]
            c_o[i, 0], c_o[i, 1], c_o[i, 2] = o[0], o[1], o[2]


@numba.njit(cache=True)
def contact_jacobian(S, q, nc, c_pair, dirs, c_pa, c_pb, W):
    """Fill W (nv, >= nc) with the Jacobian columns of directions dirs[i] at each contact."""
    jacobian_packed(S.bi, S.bf, S.pi, q, nc, c_pair, dirs, c_pa, c_pb, W)


@numba.njit(cache=True)
def jacobian_packed(bi, bf, pi, q, nc, c_pair, dirs, c_pa, c_pb, W):
    """`jacobian_at` with the bodies' origins at q."""
    pos = np.empty((bi.shape[0], 3))
    positions(bi, bf, q, pos)
    jacobian_at(bi, pi, pos, nc, c_pair, dirs, c_pa, c_pb, W)


# without numba's runtime: a per-step call whose array arguments are not reference-counted
@numba.njit(cache=True, _nrt=False)
def jacobian_at(bi, pi, pos, nc, c_pair, dirs, c_pa, c_pb, W):
    """Fill W[:, :nc] with the Jacobian columns of directions dirs[i] at each contact, the
    bodies' origins at pos (`models.kinematics.positions`): the rollout computes them once a
    step for all its Jacobians, into its scratch."""
    # rows and columns indexed, not sliced: a view (c_pb[i], W[:, :nc]) is an array object of
    # its own, reference-counted as it is made and dropped, per contact
    for v in range(W.shape[0]):
        for i in range(nc):
            W[v, i] = 0.0
    for i in range(nc):
        p = c_pair[i]
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        for side in range(2):
            b = pi[p, PI_B] if side == 0 else pi[p, PI_A]
            sign = 1.0 if side == 0 else -1.0
            if side == 0:
                px, py, pz = c_pb[i, 0], c_pb[i, 1], c_pb[i, 2]
            else:
                px, py, pz = c_pa[i, 0], c_pa[i, 1], c_pa[i, 2]
            for k in range(3):
                if bi[b, BI_VMAP + k] >= 0:
                    W[bi[b, BI_VMAP + k], i] += sign * dirs[i, k]
            rx, ry, rz = px - pos[b, 0], py - pos[b, 1], pz - pos[b, 2]
            cx = ry * dz - rz * dy
            cy = rz * dx - rx * dz
            cz = rx * dy - ry * dx
            if bi[b, BI_VMAP + V_ANGLE] >= 0:
                W[bi[b, BI_VMAP + V_ANGLE], i] += sign * cz
            if bi[b, BI_VMAP + V_WX] >= 0:
                W[bi[b, BI_VMAP + V_WX], i] += sign * cx
                W[bi[b, BI_VMAP + V_WX + 1], i] += sign * cy
                W[bi[b, BI_VMAP + V_WX + 2], i] += sign * cz


# ----------------------------------------------------------------------------- scripted obstacles


@numba.njit(cache=True)
def has_script(bf):
    """True when some obstacle of the scene moves on a script (a constant velocity)."""
    for b in range(bf.shape[0]):
        for k in range(4):
            if bf[b, BF_SCRIPT_V + k] != 0.0:
                return True
    return False


@numba.njit(cache=True)
def place_scripted(bf, base_pos, base_quat, t):
    """Move every scripted obstacle to its pose at time t (pose at 0 plus t times its velocity):
    the packed table bf and the scene's base_pos / base_quat (both are read by the contact
    kernels). Writes only scripted bodies; callers pass a scene copy of their own."""
    for b in range(bf.shape[0]):
        moving = False
        for k in range(4):
            if bf[b, BF_SCRIPT_V + k] != 0.0:
                moving = True
        if not moving:
            continue
        for k in range(3):
            x = bf[b, BF_SCRIPT + k] + t * bf[b, BF_SCRIPT_V + k]
            bf[b, BF_POS + k] = x
            base_pos[b, k] = x
        if bf[b, BF_SCRIPT_V + 3] != 0.0:
            half = 0.5 * (bf[b, BF_SCRIPT + 3] + t * bf[b, BF_SCRIPT_V + 3])
            bf[b, BF_QUAT], bf[b, BF_QUAT + 1], bf[b, BF_QUAT + 2], bf[b, BF_QUAT + 3] = np.cos(half), 0.0, 0.0, np.sin(half)
            base_quat[b, 0], base_quat[b, 1], base_quat[b, 2], base_quat[b, 3] = np.cos(half), 0.0, 0.0, np.sin(half)


@numba.njit(cache=True)
def scripted_bias(bf, pi, nc, c_pair, c_n, c_t, c_o, c_pa, c_pb, bias):
    """bias[i] = (n, t, o) . (v_B(pb) - v_A(pa)) of contact i from the scripted motion of its
    bodies (zero for bodies that are not scripted): the part of the contact's relative velocity
    that no free DOF carries. It enters the contact problem beside W^T nu."""
    for i in range(nc):
        p = c_pair[i]
        r0, r1, r2 = 0.0, 0.0, 0.0  # the relative velocity (scalars: no allocation in the rollout's step)
        for side in range(2):
            b = pi[p, 1] if side == 0 else pi[p, 0]
            sign = 1.0 if side == 0 else -1.0
            pt = c_pb[i] if side == 0 else c_pa[i]
            w = bf[b, BF_SCRIPT_V + 3]
            r0 += sign * (bf[b, BF_SCRIPT_V] - w * (pt[1] - bf[b, BF_POS + 1]))
            r1 += sign * (bf[b, BF_SCRIPT_V + 1] + w * (pt[0] - bf[b, BF_POS]))
            r2 += sign * bf[b, BF_SCRIPT_V + 2]
        bias[i, 0] = c_n[i, 0] * r0 + c_n[i, 1] * r1 + c_n[i, 2] * r2
        bias[i, 1] = c_t[i, 0] * r0 + c_t[i, 1] * r1 + c_t[i, 2] * r2
        bias[i, 2] = c_o[i, 0] * r0 + c_o[i, 1] * r1 + c_o[i, 2] * r2


# ----------------------------------------------------------------------------- Python facing


@dataclass(frozen=True)
class Contacts:
    """Contacts at one configuration. Arrays have one row (or column, for W) per contact."""

    pair: np.ndarray  # int (nc,)
    psi: np.ndarray  # (nc,)
    n: np.ndarray  # (nc, 3)
    t: np.ndarray  # (nc, 3)
    o: np.ndarray  # (nc, 3) zeros in the plane
    pa: np.ndarray  # (nc, 3)
    pb: np.ndarray  # (nc, 3)
    W_n: np.ndarray  # (nv, nc)
    W_t: np.ndarray  # (nv, nc)
    W_o: np.ndarray  # (nv, nc) empty columns in the plane
    unsupported: np.ndarray  # pair indices left to python-fcl


def capacity(S: SceneData) -> int:
    return int(np.sum(S.pair_max_contacts))


def contact_frames(S: SceneData, q: np.ndarray, nu: np.ndarray | None = None, h: float = 0.0, margin: float = CONTACT_MARGIN) -> Contacts:
    """Detect contacts at q (velocities nu over a step h widen the margin) and assemble W."""
    q = kernel_array(q)
    nu = np.zeros(S.nv) if nu is None else kernel_array(nu)
    cap = max(capacity(S), 1)
    c_pair = np.zeros(cap, np.int64)
    c_psi = np.zeros(cap)
    c_n, c_pa, c_pb = np.zeros((cap, 3)), np.zeros((cap, 3)), np.zeros((cap, 3))
    unsupported = np.zeros(max(len(S.pair_a), 1), np.int64)
    nc, nu_count = detect_contacts(S, q, nu, h, margin, c_pair, c_psi, c_n, c_pa, c_pb, unsupported)
    c_t, c_o = np.zeros((cap, 3)), np.zeros((cap, 3))
    tangents(S, nc, c_n, c_t, c_o)
    W_n, W_t, W_o = np.zeros((S.nv, cap)), np.zeros((S.nv, cap)), np.zeros((S.nv, cap))
    contact_jacobian(S, q, nc, c_pair, c_n, c_pa, c_pb, W_n)
    contact_jacobian(S, q, nc, c_pair, c_t, c_pa, c_pb, W_t)
    if S.dimension == 3:
        contact_jacobian(S, q, nc, c_pair, c_o, c_pa, c_pb, W_o)
    return Contacts(
        pair=c_pair[:nc].copy(),
        psi=c_psi[:nc].copy(),
        n=c_n[:nc].copy(),
        t=c_t[:nc].copy(),
        o=c_o[:nc].copy(),
        pa=c_pa[:nc].copy(),
        pb=c_pb[:nc].copy(),
        W_n=W_n[:, :nc].copy(),
        W_t=W_t[:, :nc].copy(),
        W_o=W_o[:, :nc].copy() if S.dimension == 3 else np.zeros((S.nv, 0)),
        unsupported=unsupported[:nu_count].copy(),
    )


@numba.njit(cache=True)
def pair_min_distances(S, q, margin, out):
    """Fill out (n_pairs,) with each pair's signed distance at q (inf beyond margin or inert;
    nan for pairs only python-fcl can measure)."""
    pair_min_distances_into(S, q, margin, out, pair_distance_buffers(S))


@numba.njit(cache=True)
def pair_distance_buffers(S):
    """`pair_min_distances_into`'s buffers for scene S: the contacts' (every pair's most), the
    unsupported pairs', the detection's scratch (`planar_scratch`) and a zero velocity."""
    cap = 1
    for p in range(S.pi.shape[0]):
        cap += S.pi[p, 2]
    pos, poses, speed, reach, axis, cores = planar_scratch(S.bi, S.pi.shape[0])
    return (
        np.zeros(cap, np.int64),
        np.zeros(cap),
        np.zeros((cap, 3)),
        np.zeros((cap, 3)),
        np.zeros((cap, 3)),
        np.zeros(max(S.pi.shape[0], 1), np.int64),
        pos,
        poses,
        speed,
        reach,
        axis,
        cores,
        np.zeros(S.nv),
    )


@numba.njit(cache=True, inline="always")
def pair_min_distances_into(S, q, margin, out, buffers):
    """`pair_min_distances` on the caller's buffers (`pair_distance_buffers`), allocating
    nothing: the geometric rung's validity check, thousands a plan (the allocations were
    0.7-1 us of the distances' 2.3-6.5 us, measured). The planar separating axes start at zero on
    every call, so a pair's distance does not depend on the calls before it."""
    c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, poses, speed, reach, axis, cores, nu = buffers
    axis[:] = 0.0
    nc, n_unsupported = detect_contacts_into(
        S, q, nu, 0.0, margin, c_pair, c_psi, c_n, c_pa, c_pb, unsupported, pos, poses, speed, reach, axis, cores
    )
    out[:] = np.inf
    for i in range(nc):
        if c_psi[i] < out[c_pair[i]]:
            out[c_pair[i]] = c_psi[i]
    for k in range(n_unsupported):
        out[unsupported[k]] = np.nan

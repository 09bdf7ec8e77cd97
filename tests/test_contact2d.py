"""Planar contact kernels against the reference signed distance, Jacobians against finite
differences and rigid-body point velocities, manifolds against closed forms."""

from __future__ import annotations

import itertools
import zlib

import numpy as np
import pytest

from models import geometry as geo
from models.contact import contact_frames
from models.contact2d import collide_pair_2d
from tests.contact_scenes import SHAPES_2D, pair_scene

PAIRS = list(itertools.combinations_with_replacement(sorted(SHAPES_2D), 2))


def reference_psi(scenario, q, p, S):
    A = scenario.spec.bodies[S.pair_a[p]].name
    B = scenario.spec.bodies[S.pair_b[p]].name
    P = scenario.placements(q)
    return geo.signed_distance(scenario.geometries[A], P[A], scenario.geometries[B], P[B])


def kernel(S, q, p, margin=1e9):
    cap = int(S.pair_max_contacts[p])
    psi, n, pa, pb = np.zeros(cap), np.zeros((cap, 3)), np.zeros((cap, 3)), np.zeros((cap, 3))
    k = collide_pair_2d(S, q, p, margin, psi, n, pa, pb, 0)
    return psi[:k], n[:k], pa[:k], pb[:k]


def random_q(rng):
    return np.concatenate([rng.uniform(-1, 1, 2), rng.uniform(-3, 3, 1), rng.uniform(-1, 1, 2), rng.uniform(-3, 3, 1)])


@pytest.mark.parametrize("a, b", PAIRS, ids=lambda x: x)
def test_min_psi_matches_reference_on_random_touching_and_penetrating_poses(tmp_path, a, b):
    scenario, S = pair_scene(tmp_path, a, b)
    rng = np.random.default_rng(zlib.crc32(f"{a}-{b}".encode()))  # not hash(): salted per process
    checked = 0
    for _ in range(120):
        q = random_q(rng)
        psi, n, _, _ = kernel(S, q, 2)  # pair 2 = (a, b)
        # slide b along the witness normal to touching, just apart, just inside, and 1 mm inside
        i = int(np.argmin(psi))
        for target in (None, 0.0, 1e-9, -1e-9, -1e-3):
            qq = q.copy()
            if target is not None:
                qq[3:5] += (target - psi[i]) * n[i, :2]
            for p in range(3):
                got, nn, pa, pb = kernel(S, qq, p)
                assert 1 <= len(got) <= S.pair_max_contacts[p]
                assert got.min() == pytest.approx(reference_psi(scenario, qq, p, S), abs=1e-9)
                np.testing.assert_allclose(np.linalg.norm(nn, axis=1), 1.0, atol=1e-12)
                np.testing.assert_allclose(pb - pa, got[:, None] * nn, atol=1e-9)
                checked += 1
    assert checked == 120 * 5 * 3


@pytest.mark.parametrize("a, b", PAIRS, ids=lambda x: x)
def test_normal_jacobian_is_the_gradient_of_the_reference_distance(tmp_path, a, b):
    scenario, S = pair_scene(tmp_path, a, b)
    rng = np.random.default_rng(7)
    eps = 1e-6
    for _ in range(40):
        q = random_q(rng)
        c = contact_frames(S, q, margin=1e9)
        for p in range(3):
            rows = np.flatnonzero(c.pair == p)
            psi = c.psi[rows]
            order = np.argsort(psi)
            if len(psi) > 1 and psi[order[1]] - psi[order[0]] < 1e-4:
                continue  # the min of two nearly equal contacts is not differentiable there
            col = c.W_n[:, rows[order[0]]]
            for j in range(S.nv):
                dq = np.zeros(S.nq)
                dq[j] = eps
                fd = (reference_psi(scenario, q + dq, p, S) - reference_psi(scenario, q - dq, p, S)) / (2 * eps)
                assert col[j] == pytest.approx(fd, abs=1e-5)


def point_velocity(q, nu, body, point):
    """Velocity of a material point of planar body 1 (a) or 2 (b): v + w x r."""
    base = 0 if body == "a" else 3
    r = point[:2] - q[base : base + 2]
    w = nu[base + 2]
    return np.array([nu[base] - w * r[1], nu[base + 1] + w * r[0]])


@pytest.mark.parametrize("a, b", PAIRS[:6], ids=lambda x: x)
def test_tangent_jacobian_is_the_relative_sliding_velocity(tmp_path, a, b):
    _, S = pair_scene(tmp_path, a, b)
    rng = np.random.default_rng(11)
    for _ in range(30):
        q = random_q(rng)
        nu = rng.normal(size=6)
        c = contact_frames(S, q, margin=1e9)
        for i in np.flatnonzero(c.pair == 2):
            rel = point_velocity(q, nu, "b", c.pb[i]) - point_velocity(q, nu, "a", c.pa[i])
            assert c.W_t[:, i] @ nu == pytest.approx(rel @ c.t[i, :2], abs=1e-12)
            assert c.W_n[:, i] @ nu == pytest.approx(rel @ c.n[i, :2], abs=1e-12)
            assert c.t[i, :2] @ c.n[i, :2] == pytest.approx(0.0, abs=1e-15)


def test_box_flat_on_the_floor_makes_two_contacts_at_its_corners(tmp_path):
    scenario, S = pair_scene(tmp_path, "box", "disc")
    # rotate the box to the floor's slope and put its lower face 1e-4 above the floor line
    n = np.array([0.3, 1.0]) / np.hypot(0.3, 1.0)
    theta = np.arctan2(-n[0], n[1])
    offset = -20.0 / np.hypot(0.3, 1.0)
    centre = (offset + 0.2 + 1e-4) * n
    q = np.array([centre[0], centre[1], theta, 5.0, 5.0, 0.0])
    psi, nn, pa, pb = kernel(S, q, 0)
    assert len(psi) == 4 and np.sum(np.abs(psi - 1e-4) < 1e-12) == 2
    lower = np.flatnonzero(np.abs(psi - 1e-4) < 1e-12)
    R = geo.rotation_2d(theta)
    corners = {tuple(np.round(R @ v + centre, 9)) for v in ([-0.4, -0.2], [0.4, -0.2])}
    assert {tuple(np.round(pb[i, :2], 9)) for i in lower} == corners


def test_face_to_face_boxes_give_the_overlap_interval(tmp_path):
    _, S = pair_scene(tmp_path, "box", "box")
    # b directly above a, shifted right by 0.3, gap 0.01: contacts at x = -0.1 and 0.4
    q = np.array([0.0, 0.0, 0.0, 0.3, 0.41, 0.0])
    psi, nn, pa, pb = kernel(S, q, 2)
    assert len(psi) == 2
    np.testing.assert_allclose(psi, 0.01, atol=1e-12)
    np.testing.assert_allclose(nn[:, :2], [[0, 1], [0, 1]], atol=1e-12)
    assert sorted(np.round(pb[:, 0], 12)) == [-0.1, 0.4]


def test_boxes_all_but_touching_keep_their_face_normal_and_two_contacts(tmp_path):
    # a box resting on a box, apart by round-off with round-off rotations (a rigid stack's
    # state): the witness points' direction is noise there (it once tipped a 1e4 kg box onto
    # one corner); the face normal and both corners must come back
    _, S = pair_scene(tmp_path, "box", "box")
    rng = np.random.default_rng(51)
    for gap in (1e-15, 1e-14, 1e-13, 1e-12, 1e-11):
        for _ in range(20):
            x, theta = rng.uniform(-1e-14, 1e-14, 2), rng.uniform(-2e-13, 2e-13, 2)
            q = np.array([x[0], 0.0, theta[0], x[1], 0.4 + gap, theta[1]])
            psi, nn, pa, pb = kernel(S, q, 2)
            assert len(psi) == 2, (gap, q)
            np.testing.assert_allclose(nn[:, :2], [[0, 1], [0, 1]], atol=1e-9)
            np.testing.assert_allclose(psi, gap, atol=1e-12)  # the rotations tilt the faces by 2e-13


def test_paper_scene_contacts(triangle_file):
    from models.kinematics import compile_scene
    from models.scenario import load_scenario

    scenario = load_scenario(triangle_file)
    S = compile_scene(scenario)
    # fingers lowered onto the faces: finger1 at depth where it touches the left face
    y_touch = 0.5 + 0.05 * np.sqrt(2)  # centre above the face point x = -0.5, y = 0.5
    q = np.array([0.0, y_touch, y_touch])
    c = contact_frames(S, q)
    pairs = {(scenario.spec.bodies[S.pair_a[p]].name, scenario.spec.bodies[S.pair_b[p]].name) for p in c.pair}
    assert ("triangle", "finger1") in pairs and ("triangle", "finger2") in pairs
    i = next(i for i, p in enumerate(c.pair) if scenario.spec.bodies[S.pair_b[p]].name == "finger1")
    assert c.psi[i] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(c.n[i, :2], [-np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    # W_n column over (triangle.x, finger1.y, finger2.y): the paper's sqrt(2)/2 entries
    np.testing.assert_allclose(c.W_n[:, i], [np.sqrt(0.5), np.sqrt(0.5), 0.0], atol=1e-12)


def test_broadphase_keeps_far_pairs_out_and_widens_with_speed(tmp_path):
    _, S = pair_scene(tmp_path, "disc", "disc")
    q = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])  # 0.4 apart
    assert not np.any(contact_frames(S, q).pair == 2)
    nu = np.array([0.0, 0.0, 0.0, -50.0, 0.0, 0.0])  # closing at 50 m/s: 0.5 m in one 10 ms step
    assert np.any(contact_frames(S, q, nu=nu, h=1e-2).pair == 2)


@pytest.mark.parametrize("a, b", PAIRS, ids=lambda x: x)
def test_gap_along_any_axis_bounds_the_distance_and_the_last_axis_meets_it(tmp_path, a, b):
    from models.contact2d import apart_along, collide_2d, core_scratch
    from models.kinematics import planar_poses

    scenario, S = pair_scene(tmp_path, a, b)
    ia, ib = int(S.pi[2, 0]), int(S.pi[2, 1])  # pair 2 = (a, b)
    rng = np.random.default_rng(zlib.crc32(f"axis-{a}-{b}".encode()))
    poses = np.zeros((S.bi.shape[0], 4))
    tight = 0
    for _ in range(100):
        q = random_q(rng) * np.array([2.0, 2.0, 1.0, 2.0, 2.0, 1.0])  # apart as often as not
        planar_poses(S.bi, S.bf, q, poses)
        exact = reference_psi(scenario, q, 2, S)
        for angle in rng.uniform(-np.pi, np.pi, 5):  # any unit axis: a lower bound
            assert apart_along(S.bi, S.bf, S.verts, poses, ia, ib, np.cos(angle), np.sin(angle)) <= exact + 1e-12
        cap = int(S.pair_max_contacts[2])
        axis = np.zeros(2)  # set by the narrowphase: its direction from a to b
        collide_2d(
            S.bi, S.bf, S.verts, poses, ia, ib, 1e9, np.zeros(cap), *(np.zeros((cap, 3)) for _ in range(3)), 0, axis, core_scratch(S.bi)
        )
        bound = apart_along(S.bi, S.bf, S.verts, poses, ia, ib, axis[0], axis[1])
        assert bound <= exact + 1e-12
        if exact > 1e-6:  # apart: the narrowphase's own direction gives the distance itself
            assert bound == pytest.approx(exact, abs=1e-9)
            tight += 1
    assert tight >= 20


def test_detection_skips_pairs_apart_along_their_last_axis_and_finds_the_same_contacts(triangle_file):
    """The rollout's detection carries each pair's last separating axis from step to step and
    skips the narrowphase of a pair whose gap along it exceeds its reach: along the fingers'
    descent onto the triangle (apart, then touching, then pressed in) the contacts are bitwise
    those of a detection that starts afresh every step, and the skip happens."""
    from models.contact import detect_planar, detect_planar_into, planar_scratch
    from models.contact2d import APART_SLACK, apart_along
    from models.kinematics import BI_KIND, SHAPE_HALFSPACE, compile_scene, planar_poses
    from models.scenario import load_scenario

    S = compile_scene(load_scenario(triangle_file))
    bi, bf, verts, pi = S.bi, S.bf, S.verts, S.pi
    cap = int(S.pair_max_contacts.sum())
    carried, fresh = ([np.zeros(cap, np.int64), np.zeros(cap), *(np.zeros((cap, 3)) for _ in range(3))] for _ in range(2))
    pos, poses, speed, reach, axis, world_cores = planar_scratch(bi, pi.shape[0])
    cores = [p for p in range(pi.shape[0]) if SHAPE_HALFSPACE not in (bi[pi[p, 0], BI_KIND], bi[pi[p, 1], BI_KIND])]
    h, nu, here = 1e-3, np.array([0.3, -1.0, -1.2]), np.zeros_like(poses)
    skipped, narrowphase, touching = 0, 0, 0
    for k in range(1700):  # the fingers from y = 2.05 to 0.5 and below, the triangle sliding
        q = np.array([0.3 * k * h - 0.2, 2.05 - 1.0 * k * h, 2.05 - 1.2 * k * h])
        before = axis.copy()
        n_c = detect_planar_into(bi, bf, verts, pi, q, nu, h, 1e-3, *carried, pos, poses, speed, reach, axis, world_cores)
        n_f = detect_planar(bi, bf, verts, pi, q, nu, h, 1e-3, *fresh)
        assert n_c == n_f
        for x, y in zip(carried, fresh):
            np.testing.assert_array_equal(x[:n_c], y[:n_f])
        touching += n_c > 0
        planar_poses(bi, bf, q, here)
        for p in cores:
            if reach[p] > -np.inf:
                gap = apart_along(bi, bf, verts, here, pi[p, 0], pi[p, 1], before[p, 0], before[p, 1])
                skip = gap > reach[p] + APART_SLACK
                skipped += skip
                narrowphase += not skip
                if skip:  # the narrowphase did not run: the pair keeps its axis
                    assert np.array_equal(axis[p], before[p])
    assert skipped > 200 and narrowphase > 200 and touching > 100


def test_kept_poses_are_planar_poses_bit_for_bit_and_skip_what_did_not_turn(tmp_path):
    """The detection's poses carry over from step to step (`planar_poses_kept`): a body's cos
    and sin are computed again only where its angle coordinate (or, for a body without one, its
    base quaternion, which a script moves) changed. Along states that keep, change and flip
    the sign of a zero angle, and a fixed body's quaternion moved as a script would, they are
    `planar_poses`' bit for bit (zeros' signs included); a value planted in a kept cos survives
    exactly where nothing turned (no trigonometry ran there) and is replaced elsewhere."""
    from models.contact import planar_scratch
    from models.kinematics import BF_QUAT, BI_QMAP, Q_ANGLE, planar_poses, planar_poses_kept

    def bits(x):
        return np.ascontiguousarray(x).view(np.int64)

    _, S = pair_scene(tmp_path, "box", "triangle")
    bi, bf = S.bi, S.bf.copy()
    nb = bi.shape[0]
    angle = [int(bi[b, BI_QMAP + Q_ANGLE]) for b in range(nb)]
    assert sorted(angle) == [-1, 2, 5]  # the floor (its quaternion), a and b (theta in q)
    kept = planar_scratch(bi, S.pi.shape[0])[1]
    fresh = np.zeros((nb, 4))
    rng = np.random.default_rng(7)
    a_angles = [0.0, 0.0, -0.0, -0.0, 0.3, 0.3, -1.2, np.pi, np.pi]
    b_angles = [1.0, 1.0, 1.0, -0.0, 0.0, 0.0, 2.5, 2.5, -2.5]
    quats = {5: (np.cos(0.2), 0.0, 0.0, np.sin(0.2)), 6: (1.0, 0.0, 0.0, -0.0), 7: (1.0, 0.0, 0.0, 0.0)}
    kept_somewhere, replaced, previous = 0, 0, []
    for k, (ta, tb) in enumerate(zip(a_angles, b_angles)):
        q = random_q(rng)
        q[2], q[5] = ta, tb
        if k in quats:  # the floor turned by a script
            bf[angle.index(-1), BF_QUAT : BF_QUAT + 4] = quats[k]
        source = [bits(q[a : a + 1]) if a >= 0 else bits(bf[b, [BF_QUAT + 3, BF_QUAT]]) for b, a in enumerate(angle)]
        probe = kept.copy()
        probe[:, 2] = 7.0
        planar_poses(bi, bf, q, fresh)
        planar_poses_kept(bi, bf, q, kept)
        planar_poses_kept(bi, bf, q, probe)
        assert np.array_equal(bits(kept[:, :4]), bits(fresh)), k
        for b in range(nb):
            if previous and np.array_equal(source[b], previous[b]):
                assert probe[b, 2] == 7.0, (k, b)
                kept_somewhere += 1
            else:
                assert np.array_equal(bits(probe[b, :4]), bits(fresh[b])), (k, b)
                replaced += 1
        previous = source
    assert kept_somewhere >= 8 and replaced >= 10


@pytest.mark.parametrize("polygon", ["triangle", "box", "hexagon"])
@pytest.mark.parametrize("disc_first", [True, False], ids=["disc-polygon", "polygon-disc"])
def test_the_disc_polygon_path_gives_the_general_paths_contact_bit_for_bit(tmp_path, polygon, disc_first):
    """`_point_vs_polygon` (a disc against a polygon in one call, no world cores built) against
    `_core_vs_core` (the general path) on random poses: apart, touching and pressed in, and
    with the disc's centre inside the polygon (where it hands over to the general path)."""
    from models.contact2d import _core_vs_core, _point_vs_polygon, collide_2d, core_scratch
    from models.kinematics import planar_poses

    scenario, S = pair_scene(tmp_path, "disc", polygon) if disc_first else pair_scene(tmp_path, polygon, "disc")
    ia, ib = int(S.pi[2, 0]), int(S.pi[2, 1])
    rng = np.random.default_rng(zlib.crc32(f"fast-{polygon}-{disc_first}".encode()))
    poses = np.zeros((S.bi.shape[0], 4))
    handed_over, fast = 0, 0
    for _ in range(300):
        q = random_q(rng) * np.array([1.5, 1.5, 1.0, 1.5, 1.5, 1.0])
        planar_poses(S.bi, S.bf, q, poses)
        out = []
        for kernel_ in (collide_2d, _core_vs_core):
            buffers, axis = [np.zeros(4), *(np.zeros((4, 3)) for _ in range(3))], np.zeros(2)
            k = kernel_(S.bi, S.bf, S.verts, poses, ia, ib, 0.2, *buffers, 0, axis, core_scratch(S.bi))
            out.append((k, [b[:k] for b in buffers], axis))
        (k1, b1, a1), (k2, b2, a2) = out
        assert k1 == k2
        for x, y in zip(b1, b2):
            np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(a1, a2)
        direct = _point_vs_polygon(
            S.bi, S.bf, S.verts, poses, ia, ib, 0.2, np.zeros(4), *(np.zeros((4, 3)) for _ in range(3)), 0, np.zeros(2)
        )
        handed_over += direct < 0
        fast += direct >= 0
    assert handed_over >= 5 and fast >= 200


def test_the_distance_filter_decides_as_hypot_does():
    """`_closer` skips hypot where the sums of squares rule a candidate out: on candidates at
    random scales and on ones within a few ulps of the best (where the squares' round-off
    could mislead a filter without slack), it decides and returns what hypot would."""
    from models.contact2d import DIST_FILTER, _closer

    rng = np.random.default_rng(7)
    skipped = 0
    for _ in range(20_000):
        scale = 10.0 ** rng.uniform(-8, 3)
        dx, dy = rng.normal(size=2) * scale
        best = np.hypot(*(rng.normal(size=2) * scale))
        if rng.random() < 0.5:  # at the best, give or take a few ulps
            best = np.hypot(dx, dy) + rng.integers(-3, 4) * np.spacing(best)
        best2 = best * best * DIST_FILTER
        got = _closer(dx, dy, best, best2)
        d = np.hypot(dx, dy)
        assert got == ((d, d * d * DIST_FILTER, True) if d < best else (best, best2, False))
        skipped += bool(dx * dx + dy * dy > best * best * DIST_FILTER)
    assert _closer(3.0, 4.0, np.inf, np.inf) == (5.0, 25.0 * DIST_FILTER, True)  # a search's first candidate
    assert 5_000 < skipped < 15_000

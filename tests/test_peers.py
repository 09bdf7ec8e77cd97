"""The MuJoCo peer (`planner.peers`) on the paper's scene: the model builds with the
scenario's coordinates, drives and pairs; its geometry and its contact law are the
scenario's; its fingers follow the drives' closed form before contact and then touch the
triangle. No timing asserts: `ladder bench` times it."""

from __future__ import annotations

import math

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from models.rungs import pair_signed_distances  # noqa: E402
from models.scenario import load_scenario  # noqa: E402
from planner import peers  # noqa: E402
from tests.conftest import SCENARIOS  # noqa: E402

G = 9.81


@pytest.fixture(scope="module")
def scene():
    return load_scenario(SCENARIOS / "two_finger_triangle.toml")


@pytest.mark.parametrize("contact", peers.CONTACT_MAPPINGS)
def test_the_model_has_the_scenarios_coordinates_drives_and_pairs(scene, contact):
    peer = peers.build(scene, 1e-4, contact)
    m = peer.model
    joints = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)]
    assert joints == list(scene.coordinates) and m.nq == m.nv == len(scene.coordinates)
    assert m.nu == 2 * len(scene.actuated) and m.na == len(scene.actuated)  # PD + feed-forward per drive
    assert m.npair == len(scene.pairs)
    assert m.opt.timestep == 1e-4 and np.allclose(m.opt.gravity, [0.0, -G, 0.0])
    data = mujoco.MjData(m)
    peer.reset(data, [-1.0, -1.0])
    assert np.array_equal(data.qpos, scene.start) and np.array_equal(data.act, scene.start[1:])


def test_bad_input_raises(scene):
    with pytest.raises(ValueError, match="planar"):
        peers.build(load_scenario(SCENARIOS / "box_push_3d.toml"), 1e-4)
    with pytest.raises(ValueError, match="contact mapping"):
        peers.build(scene, 1e-4, "stiff")
    with pytest.raises(ValueError, match="positive"):
        peers.build(scene, 0.0)


def test_signed_distances_match_the_scenarios_geometry(scene):
    """MuJoCo's distance between every pair's geoms (sphere, extruded triangle, plane) is our
    planar signed distance, apart and in shallow penetration."""
    peer = peers.build(scene, 1e-4)
    data = mujoco.MjData(peer.model)
    rng = np.random.default_rng(7)
    for _ in range(25):
        q = np.array([rng.uniform(-0.4, 0.4), rng.uniform(0.4, 2.05), rng.uniform(0.4, 2.05)])
        data.qpos[:] = q
        mujoco.mj_kinematics(peer.model, data)
        ours = pair_signed_distances(scene, q)
        for i, pair in enumerate(scene.pairs):
            if not np.isfinite(ours[i]):  # palm-triangle: no free DOF couples to it, ours is inert
                continue
            theirs = peers.geom_distance(peer, data, pair.body_a, pair.body_b)
            assert theirs == pytest.approx(ours[i], abs=1e-5), (pair, q)


def test_force_mapping_gives_the_scenes_contact_law(scene):
    """Finger 1 pressed into the triangle's left face by r at normal speed w: the normal force
    is K r + C w (the `force` mapping; MuJoCo's soft constraint at impedance d leaves O(d))."""
    peer = peers.build(scene, 1e-4, "force")
    data = mujoco.MjData(peer.model)
    K, C = scene.parameters["K"], scene.parameters["C"]
    touch = 0.5 + 0.05 * math.sqrt(2)  # disc centre height when touching the face x + y = 1 at x = -0.5
    for r, w in ((1e-4, 0.0), (1e-3, 0.0), (1e-2, 0.0), (1e-3, 0.01), (1e-3, -0.01)):
        peer.reset(data, [0.0, 0.0])
        data.qpos[1] = data.act[0] = touch - r * math.sqrt(2)  # the face normal is (-1, 1)/sqrt(2)
        data.qvel[1] = -w * math.sqrt(2)
        mujoco.mj_forward(peer.model, data)
        force = peers.contact_forces(peer, data)[("triangle", "finger1")]
        assert force == pytest.approx(K * r + C * w, rel=2e-3), (r, w)


def test_fingers_descend_at_the_commanded_speed_before_contact(scene):
    """Before contact each finger tracks its ramp: y = y0 - v t, low by its weight over the
    drive's stiffness (m g / kp), once the critically damped start (1 ms) has died out."""
    peer = peers.build(scene, 1e-4)
    u = np.array([-0.8, -1.0])
    run = peers.run(peer, u, 1.0, period=0.05)
    sag = scene.parameters["finger_mass"] * G / scene.parameters["finger_kp"]
    for t, q in zip(run.times[1:], run.q[1:]):
        for j, name in enumerate(scene.actuated):
            k = scene.coordinates.index(name)
            assert q[k] == pytest.approx(scene.start[k] + u[j] * t - sag, abs=1e-7), (name, t)
        assert q[0] == 0.0  # nothing has touched the triangle
    assert run.finite and not run.diverged


def test_a_short_run_is_finite(scene):
    for contact in peers.CONTACT_MAPPINGS:
        run = peers.run(peers.build(scene, 1e-4, contact), [-1.0, -1.0], 0.2)
        assert run.finite and not run.diverged and run.steps == 2000
        assert np.all(np.isfinite(run.q)) and len(run.times) == len(run.q) == 201


@pytest.mark.parametrize("contact, h", [("force", 2e-5), ("direct", 1e-4)])
def test_both_fingers_touch_the_triangle(scene, contact, h):
    """At v1 = v2 = 1 both fingers meet the triangle's faces at t = 2.05 - (0.5 + 0.05 sqrt 2)
    (about 1.479 s) and then press on it: positive normal force on both pairs, the triangle
    held between them. (At h = 1e-4 the force mapping throws the fingers off again: MuJoCo's
    contact damping is explicit and h C / m_eff > 2 there; `ladder bench` reports it.)"""
    peer = peers.build(scene, h, contact)
    data = mujoco.MjData(peer.model)
    peer.reset(data, [-1.0, -1.0])
    contact_time = 2.05 - (0.5 + 0.05 * math.sqrt(2))
    mujoco.mj_step(peer.model, data, nstep=int(round((contact_time - 0.01) / h)))
    assert peers.geom_distance(peer, data, "finger1", "triangle") > 0
    mujoco.mj_step(peer.model, data, nstep=int(round(0.03 / h)))
    forces = peers.contact_forces(peer, data)
    assert forces.get(("triangle", "finger1"), 0.0) > 0 and forces.get(("triangle", "finger2"), 0.0) > 0
    psi = pair_signed_distances(scene, data.qpos)
    touching = [i for i, p in enumerate(scene.pairs) if "triangle" in (p.body_a, p.body_b) and p.body_a != "palm"]
    assert len(touching) == 2 and all(psi[touching] < 0)  # both pressed in
    assert abs(data.qpos[0]) < 1e-9  # symmetric: the triangle does not move


@pytest.mark.parametrize("contact", peers.CONTACT_MAPPINGS)
def test_leaving_out_the_inert_palm_triangle_pair_changes_nothing(scene, contact):
    """The triangle (free in x only) on the frictionless palm: no free DOF feels that pair,
    so MuJoCo without it runs the same trajectory, through the grasp and the pressing."""
    assert [(p.body_a, p.body_b) for p in peers.inert_pairs(scene)] == [("palm", "triangle")]
    kept, dropped = peers.build(scene, 1e-4, contact), peers.build(scene, 1e-4, contact, drop_inert=True)
    assert dropped.dropped == ("palm-triangle",) and dropped.model.npair == kept.model.npair - 1
    u = [-0.8, -1.0]  # finger 2 pushes the triangle first
    a, b = peers.run(kept, u, 1.7, period=0.01), peers.run(dropped, u, 1.7, period=0.01)
    assert abs(a.q[-1, 0]) > 1e-3  # the triangle has moved
    assert np.allclose(a.q, b.q, rtol=0.0, atol=1e-9)


def test_a_spatial_scene_builds_with_qpos_as_its_coordinates_and_the_box_is_pushed():
    """box_push_3d in MuJoCo (`peers.build_spatial`: free joint for the box, slides for the
    pusher, MuJoCo's own contact model): the keyframe is the scenario's start, and a second of
    the straight push moves the box forward on the table. A planar scene is refused."""
    scenario = load_scenario(SCENARIOS / "box_push_3d.toml")
    peer = peers.build_spatial(scenario, 1e-3)
    assert peer.model.nq == len(scenario.coordinates) and peer.model.nu == 2 * len(scenario.actuated)
    data = mujoco.MjData(peer.model)
    peer.reset(data, np.array([0.2, 0.0]))
    np.testing.assert_allclose(peer.q(data), scenario.start, atol=1e-12)
    mujoco.mj_step(peer.model, data, nstep=1000)
    q = dict(zip(scenario.coordinates, peer.q(data)))
    assert q["pusher.x"] == pytest.approx(0.0, abs=2e-3)  # -0.2 + 0.2 m/s for 1 s
    assert 0.05 < q["box.x"] < 0.2 and q["box.z"] == pytest.approx(0.05, abs=2e-3)
    with pytest.raises(ValueError, match="spatial"):
        peers.build_spatial(load_scenario(SCENARIOS / "two_finger_triangle.toml"), 1e-3)

"""The PGS contact solver (issue 7) against closed forms and against Lemke on the same steps.

Closed forms: boxes resting on a plane (each box's normal impulse over a step is m g h), a box
sliding on a plane (friction impulse mu times the normal one; deceleration mu g per step,
exactly, in the semi-implicit scheme), in the plane and in space. Random small scenes: PGS's
impulses satisfy Signorini, the friction cone and maximal dissipation within its tolerance,
and on frictionless scenes with a unique solution they equal Lemke's. Failures: a sweep limit
that is too small, and a rigid stack PGS cannot converge on, come back as a status.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from models.contact import CONTACT_MARGIN, ContactSet, contact_frames
from models.contact_pgs import disk_minimiser, polygon_minimiser
from models.rollout import _keep_warm, _warm_in_frames
from models.rungs import RUNGS, compiled, pgs_rung, policy_controls, rung_for
from models.scenario import ScenarioError, load_scenario
from models.schema import CONTACT_SOLVERS
from models.stepper import (
    LEMKE,
    PGS_TOLERANCE,
    QUASISTATIC_INERTIA,
    SOLVER_METHODS,
    SceneTables,
    StepStatus,
    basis_table,
    contact_solver,
    dynamics_step,
    gravity_force,
    make_system,
    mass_matrix,
    system_matrix,
)
from tests.conftest import SCENARIOS
from tests.stress.scenes import body, box_inertia, box_shape, check_invariants, disc_shape, scene

H = 1e-3
G = 9.81
SOLVERS = ("lemke", "pgs")


def step(scenario, rung_name: str, solver: str, q, nu, h: float = H, **settings):
    """One dynamics_step at (q, nu) with the rung's model and the named solver, cold-started.

    Returns (contacts, Ainv, out) with out = dynamics_step's StepResult.
    """
    c = compiled(scenario)
    S, D = c.scene, c.drives
    model = rung_for(scenario, rung_name).model
    q = np.array(q, float)  # writable: StepResult unifies only with writable state arrays
    nu = np.array(nu, float)
    A = system_matrix(S.bi, S.bf, q, S.nv, model.eps or QUASISTATIC_INERTIA, h, D.v_index, D.kp, D.kd, D.max_force)
    Ainv = np.linalg.inv(A)
    M = mass_matrix(S.bi, S.bf, q, S.nv)
    rhs = h * gravity_force(S.bi, S.bf, D.gravity, S.nv)
    frames = contact_frames(S, q, nu, h, CONTACT_MARGIN)
    nc = len(frames.psi)
    spatial = S.dimension == 3
    W_o = frames.W_o if spatial else np.zeros_like(frames.W_n)
    u = np.zeros(len(D.v_index))
    contacts = ContactSet(
        frames.pair,
        frames.psi,
        np.arange(nc, dtype=np.int64),
        frames.W_n,
        frames.W_t,
        W_o,
        np.zeros((max(nc, 1), 3)),
    )
    out = dynamics_step(
        model,
        contact_solver(solver, **settings),
        D,
        SceneTables(S.bi, S.bf, S.pi, S.pf, spatial),
        make_system(S.bi, A, Ainv, M, rhs),
        h,
        q,
        nu,
        q[D.q_index].copy(),
        np.zeros(nc),
        np.zeros((nc, 2)),
        u,
        contacts,
        nc,
        np.zeros(nc),
        np.zeros((nc, 2)),
        basis_table(nc, len(D.v_index), model.friction_directions if spatial else 2),
    )
    return frames, Ainv, out


def with_solver(scenario, rung_name: str, solver: str, **settings):
    return replace(rung_for(scenario, rung_name), solver=contact_solver(solver, **settings))


def resting_boxes(tmp_path, mu=0.5):
    """Three boxes of different sizes and masses resting apart on the plane."""
    sizes = [(0.2, 0.1, 1.0), (0.1, 0.3, 2.5), (0.4, 0.05, 0.4)]
    bodies, x = [], 0.0
    for k, (w, hh, m) in enumerate(sizes):
        bodies.append(body(f"b{k}", box_shape(w, hh), x, hh / 2, mass=m, inertia=box_inertia(m, w, hh)))
        x += 1.0
    return scene(tmp_path, bodies, mu=mu), [m for _, _, m in sizes]


def per_body_normal(scenario, frames, p_n):
    """Sum of a per-contact quantity (normal impulses) over each body's pair with the floor, in body order."""
    names = [f"b{k}" for k in range(3)]
    pair_of = {frozenset((p.body_a, p.body_b)): i for i, p in enumerate(scenario.pairs)}
    return np.array([p_n[frames.pair == pair_of[frozenset(("floor", name))]].sum() for name in names])


# ----------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize("rung", ["dynamic-rigid", "quasistatic-rigid"])
@pytest.mark.parametrize("solver", SOLVERS)
def test_resting_boxes_normal_impulse_is_m_g_h(tmp_path, rung, solver):
    sc, masses = resting_boxes(tmp_path)
    frames, _, out = step(sc, rung, solver, sc.start, np.zeros(len(sc.velocities)))
    assert out.status == StepStatus.OK
    p_n, p_t, nu_new = out.p_n, out.p_t, out.nu
    assert len(frames.psi) == 6  # two corners per box
    np.testing.assert_allclose(per_body_normal(sc, frames, p_n), np.array(masses) * G * H, rtol=10 * PGS_TOLERANCE)
    assert np.all(p_n > 0.0)
    # nothing pushes sideways: each box's net friction impulse vanishes (a rigid box's two
    # corners may squeeze it with equal and opposite friction: that pair does no work, and PGS,
    # unlike regularised Lemke, need not pick zero; it stays inside the cone)
    sideways = per_body_normal(sc, frames, p_t[:, 0] * frames.t[:, 0])
    assert np.max(np.abs(sideways)) <= 10 * PGS_TOLERANCE * np.max(p_n)
    assert np.all(np.abs(p_t[:, 0]) <= 0.5 * p_n * (1 + 1e-12))
    assert np.max(np.abs(nu_new)) < 1e-6  # the fall is stopped within the step


@pytest.mark.parametrize("solver", SOLVERS)
def test_resting_boxes_compliant_settle_to_their_weight(tmp_path, solver):
    sc, masses = resting_boxes(tmp_path)
    rung = with_solver(sc, "dynamic-compliant", solver)
    result = rung.rollout(sc, rung.initial_state(sc), np.zeros((1, 0)), [0.5], H, stop_at_outcome=False)
    assert result.status == "ok"
    np.testing.assert_allclose(result.pair_force[: len(masses)], np.array(masses) * G, rtol=1e-5)
    assert (result.sweeps > 0) == (solver == "pgs")


def test_pgs_and_lemke_rest_the_same_way(tmp_path):
    sc, _ = resting_boxes(tmp_path)
    states = {}
    for solver in SOLVERS:
        rung = with_solver(sc, "dynamic-compliant", solver)
        states[solver] = rung.rollout(sc, rung.initial_state(sc), np.zeros((1, 0)), [0.5], H, stop_at_outcome=False).state.q
    np.testing.assert_allclose(states["pgs"], states["lemke"], rtol=0, atol=1e-8)


def sliding_box(tmp_path, mu):
    return scene(tmp_path, [body("box", box_shape(0.2, 0.1), 0.0, 0.05, inertia=box_inertia(1.0, 0.2, 0.1))], mu=mu)


@pytest.mark.parametrize("mu", [0.2, 0.6])
@pytest.mark.parametrize("solver", SOLVERS)
def test_sliding_box_friction_is_mu_times_normal(tmp_path, mu, solver):
    sc = sliding_box(tmp_path, mu)
    frames, _, out = step(sc, "dynamic-rigid", solver, sc.start, np.array([1.0, 0.0, 0.0]))
    assert out.status == StepStatus.OK
    p_n, p_t = out.p_n, out.p_t[:, 0]
    tangent_x = frames.t[:, 0]  # the contacts' tangent directions along x
    friction_x = float(np.sum(p_t * tangent_x))
    assert p_n.sum() == pytest.approx(G * H, rel=10 * PGS_TOLERANCE)
    assert friction_x == pytest.approx(-mu * p_n.sum(), rel=10 * PGS_TOLERANCE)  # opposes the sliding
    assert out.nu[0] == pytest.approx(1.0 - mu * G * H, rel=1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_sliding_box_decelerates_at_mu_g(tmp_path, solver):
    mu, steps = 0.6, 100
    sc = sliding_box(tmp_path, mu)
    rung = with_solver(sc, "dynamic-rigid", solver)
    start = replace(rung.initial_state(sc), nu=np.array([1.0, 0.0, 0.0]))
    result = rung.rollout(sc, start, np.zeros((1, 0)), [steps * H], H, stop_at_outcome=False)
    assert result.status == "ok" and result.steps == steps
    assert result.state.nu[0] == pytest.approx(1.0 - steps * mu * G * H, abs=1e-6)  # v_k = v_0 - k mu g h
    expected_x = sum(1.0 - k * mu * G * H for k in range(1, steps + 1)) * H
    assert result.state.q[0] == pytest.approx(expected_x, abs=1e-8)
    assert abs(result.state.q[1] - 0.05) < 1e-9 and abs(result.state.q[2]) < 1e-9  # flat on the plane


@pytest.mark.parametrize("speed", [0.0, 1.0])
def test_one_contact_is_solved_by_the_first_sweep_and_pgs_stops_there(tmp_path, speed):
    """A disc on the plane, at rest or sliding: its one contact's normal passes through the
    centre, so friction does not move the normal velocity, and the first sweep's two exact
    minimisers solve the step. PGS stops after that sweep: its residual, recomputed after the
    first sweep, decides (a rule that waited for a sweep without change took two)."""
    mu, m = 0.5, 2.0
    sc = scene(tmp_path, [body("disc", disc_shape(0.1), 0.0, 0.1, mass=m, inertia=0.5 * m * 0.01)], mu=mu)
    frames, _, out = step(sc, "dynamic-rigid", "pgs", sc.start, np.array([speed, 0.0, 0.0]))
    assert out.status == StepStatus.OK and out.sweeps == 1
    assert out.p_n.sum() == pytest.approx(m * G * H, rel=1e-12)
    friction_x = float(np.sum(out.p_t[:, 0] * frames.t[:, 0]))
    assert friction_x == pytest.approx(-mu * m * G * H if speed else 0.0, rel=1e-12, abs=1e-15)


# ----------------------------------------------------------------------------- in space


def test_box_on_the_table_rests_with_pgs():
    sc = load_scenario(SCENARIOS / "box_push_3d.toml")
    rung = with_solver(sc, "dynamic-rigid", "pgs")
    result = rung.rollout(sc, rung.initial_state(sc), np.zeros((1, 2)), [1.0], H)
    assert result.status == "ok" and result.steps == 1000
    assert np.max(np.abs(result.state.q[:7] - sc.start[:7])) < 1e-6
    assert result.pair_force[0] == pytest.approx(0.5 * G, rel=1e-5)  # the table carries the weight


@pytest.mark.parametrize("solver", SOLVERS)
def test_box_sliding_on_the_table_decelerates_at_mu_g(solver):
    sc = load_scenario(SCENARIOS / "box_push_3d.toml")
    mu, steps = 0.4, 50
    rung = with_solver(sc, "dynamic-rigid", solver)
    start = rung.initial_state(sc)
    nu = start.nu.copy()
    nu[sc.velocities.index("box.x")] = 0.5
    result = rung.rollout(sc, replace(start, nu=nu), np.zeros((1, 2)), [steps * H], H, stop_at_outcome=False)
    assert result.status == "ok"
    assert result.state.nu[sc.velocities.index("box.x")] == pytest.approx(0.5 - steps * mu * G * H, abs=1e-6)
    assert abs(result.state.nu[sc.velocities.index("box.y")]) < 1e-9  # the cone's vertex lies along -x


def test_the_warm_friction_is_kept_in_world_coordinates_across_a_flipped_tangent_basis():
    p_t = np.array([[0.2, -0.1]])  # (t, o) components of slot 3's friction impulse
    t, o = np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 1.0, 0.0]])
    warm_n, warm_t, warm_w, c_slot, warm_slots = np.zeros(5), np.zeros((5, 2)), np.zeros((5, 3)), np.array([3]), np.zeros(5, np.int64)
    n_warm = _keep_warm(True, 1, c_slot, np.array([1.0]), p_t, t, o, warm_n, warm_t, warm_w, warm_slots, 0)
    np.testing.assert_allclose(warm_w[3], 0.2 * t[0] - 0.1 * o[0])
    _warm_in_frames(1, c_slot, -t, -o, warm_w, warm_t)  # the next step's basis flipped
    np.testing.assert_array_equal(warm_t[3], [-0.2, 0.1])  # the same world impulse
    _keep_warm(True, 0, c_slot, np.array([1.0]), p_t, t, o, warm_n, warm_t, warm_w, warm_slots, n_warm)  # the slot not met again: reset
    assert not warm_w.any()


@pytest.mark.parametrize("exact", [True, False])
def test_the_push_warm_starts_pgs_although_the_pushers_tangent_basis_flips(exact):
    """box_push_3d's push from the Lemke rung's state (as `ladder bench` times it), with PGS: the
    pusher's normal lies along -x, where the tangent basis flips between t = +z and -z with the
    sign of the normal's round-off, and the pusher's friction on the box is vertical, at its
    cone's edge. The warm start keeps friction in world coordinates, so every step after the
    call's cold first one starts from the last step's impulses and takes about one sweep; kept
    as (t, o) components, the friction started reversed at every flip, and the steps took 7, 8,
    2 sweeps over and over (4.67 a step over the push, the box's speed swinging with them)."""
    sc = load_scenario(SCENARIOS / "box_push_3d.toml")
    base = rung_for(sc, "dynamic-rigid")
    rung = pgs_rung(base, exact_cone=exact)
    u, _ = policy_controls(sc)
    start = base.rollout(sc, base.initial_state(sc), u, [0.4], H, stop_at_outcome=False).state
    out = rung.rollout(sc, start, u, [0.5], H, stop_at_outcome=False)
    assert out.status == "ok" and out.steps == out.force_steps == 500
    assert out.sweeps <= 10 + 1.2 * 499  # the cold first step, then the warm ones


#: box_push_3d's straight push with the exact cone from t0 = 0.05 (the policy's speeds, one call,
#: default PGS), the state its 563rd step starts from: q, nu and the drives' references. There
#: the box's four corners slide on the table, coplanar, and their approach terms do not fit a
#: plane exactly (by 1e-9 of w / G_nn), so the exact solution lifts a corner and moves load
#: along the corners' nearly workless squeeze, where PGS creeps: its residual stays at 1.0025e-6
#: for thousands of sweeps and passes 1e-6 after 8,370 (docs/measurements.md).
CREEP_STATE = (
    [0.04221830203735205, 1.9302772390866238e-11, 0.049999999993724606, 1.0, -4.839046169054608e-13, -7.271546884596125e-11,
     9.108733238349016e-11, -0.08778169796236882, -4.980849106048231e-13],
    [0.20000375906524992, 8.824795353622277e-11, -5.247362397711149e-09, 1.6917119840187866e-09, -1.4731508421390428e-07,
     1.2251314713543447e-09, 0.20000375604606652, -3.426480042453543e-11],
    [-0.08759999999999679, 0.0],
)  # fmt: skip


#: The table's friction on the box against mu times its normal force, relatively: each corner
#: within PGS_TOLERANCE of the largest impulse (the residual's scale), four corners.
COULOMB_REL = 4 * PGS_TOLERANCE


def _table_box(sc):
    """The index of box_push_3d's table-box contact pair."""
    return next(k for k, pair in enumerate(sc.pairs) if {pair.body_a, pair.body_b} == {"table", "box"})


def _push_table_friction(sc, out):
    """The table's force on the box in a rollout's last step: (friction along the table, the
    normal force), the friction's x component signed against the box's velocity (> 0: opposing)."""
    table = _table_box(sc)
    on_box = 1.0 if sc.pairs[table].body_b == "box" else -1.0  # (the wrench is on the pair's second body)
    force = on_box * out.pair_wrench[table]
    return np.hypot(force[0], force[1]), abs(force[2]), -force[0] * np.sign(out.state.nu[sc.velocities.index("box.x")])


def test_where_pgs_creeps_the_exact_cone_pivots_on_polygons_aligned_with_its_friction():
    """At `CREEP_STATE` PGS does not converge within its 1000 sweeps. The step is then solved
    by Lemke on polygons turned to put a vertex on each contact's friction as PGS left it
    (`aligned_lemke_into`, its pivots counted), kept because the exact cone's own residual
    passes: the step is ok, and the table's friction on the sliding box is exactly mu times its
    normal force, against its motion (eq. 4; the 8-sided polygon gives that only along a
    vertex). Before, the step ended the push with contact_not_converged."""
    sc = load_scenario(SCENARIOS / "box_push_3d.toml")
    rung = pgs_rung(rung_for(sc, "dynamic-rigid"), exact_cone=True)
    q, nu, q_ref = (np.array(a) for a in CREEP_STATE)
    start = replace(rung.initial_state(sc), q=q, nu=nu, q_ref=q_ref)
    u, _ = policy_controls(sc)
    out = rung.rollout(sc, start, u, [H], H, stop_at_outcome=False)
    assert out.status == "ok" and out.steps == 1
    assert out.sweeps == 1000 and out.pivots > 0  # PGS ran out, the pivoting solved it
    assert out.max_residual <= PGS_TOLERANCE
    friction, normal, opposing = _push_table_friction(sc, out)
    mu = sc.pairs[_table_box(sc)].mu
    assert friction == pytest.approx(mu * normal, rel=COULOMB_REL) and opposing > 0


def test_the_exact_cones_pivoting_solves_the_push_wherever_pgs_stops_short():
    """The same pivoting from PGS's iterate after a single sweep (max_sweeps = 1), at every step
    of 0.2 s of box_push_3d's push, one call a step (so PGS starts cold each time): every step
    ends within the tolerance, and at every step that pivoted the table's friction on the
    sliding box is exactly mu times its normal force, against its motion."""
    sc = load_scenario(SCENARIOS / "box_push_3d.toml")
    base = rung_for(sc, "dynamic-rigid")
    rung = replace(pgs_rung(base, exact_cone=True), solver=contact_solver("pgs", max_sweeps=1))
    mu = sc.pairs[_table_box(sc)].mu
    u, _ = policy_controls(sc)
    state = base.rollout(sc, base.initial_state(sc), u, [0.4], H, stop_at_outcome=False).state
    pivoted = 0
    for _ in range(200):
        out = rung.rollout(sc, state, u, [H], H, stop_at_outcome=False)
        assert out.status == "ok" and out.steps == 1 and out.max_residual <= PGS_TOLERANCE, (out.status, out.max_residual)
        if out.pivots > 0:
            pivoted += 1
            friction, normal, opposing = _push_table_friction(sc, out)
            assert friction == pytest.approx(mu * normal, rel=COULOMB_REL) and opposing > 0
        state = out.state
    assert pivoted > 100


@pytest.mark.parametrize("d", [3, 4, 8])
def test_polygon_minimiser_satisfies_its_variational_inequality(d):
    rng = np.random.default_rng(d)
    cosines = np.cos(2 * np.pi * np.arange(d) / d)
    sines = np.sin(2 * np.pi * np.arange(d) / d)
    vertices = np.stack([cosines, sines], axis=1)
    for trial in range(200):
        B = rng.normal(size=(2, 2 if trial % 4 else 1))  # every fourth block singular
        Gt = B @ B.T
        f_old, u, radius = rng.normal(size=2), rng.normal(size=2) * 3, rng.uniform(0.1, 2.0)
        f = np.array(polygon_minimiser(f_old[0], f_old[1], u[0], u[1], Gt[0, 0], Gt[0, 1], Gt[1, 1], radius, cosines, sines))
        gradient = u + Gt @ (f - f_old)
        scale = 1e-9 * (1 + np.abs(u).max() + np.abs(Gt).max()) * radius
        # inside: no edge has f outside; optimal: no vertex (hence no point) lowers the objective to first order
        edges = np.roll(vertices, -1, axis=0) - vertices
        outside = edges[:, 0] * (f[1] - radius * vertices[:, 1]) - edges[:, 1] * (f[0] - radius * vertices[:, 0])
        assert np.all(outside >= -1e-9 * radius * radius), (trial, f)
        assert np.all((radius * vertices - f) @ gradient >= -scale), (trial, f, gradient)


def test_disk_minimiser_satisfies_its_variational_inequality():
    """The exact cone's friction block: f in the disk of the radius, and no point of the disk
    lowers the objective to first order (gradient . (y - f) >= 0 for every |y| <= radius, i.e.
    gradient . f + radius |gradient| = 0), singular blocks included."""
    rng = np.random.default_rng(7)
    for trial in range(2000):
        B = rng.normal(size=(2, 2 if trial % 4 else 1))  # every fourth block singular
        Gt = B @ B.T
        f_old, u, radius = rng.normal(size=2), rng.normal(size=2) * 3, rng.uniform(0.1, 2.0)
        f = np.array(disk_minimiser(f_old[0], f_old[1], u[0], u[1], Gt[0, 0], Gt[0, 1], Gt[1, 1], radius))
        gradient = u + Gt @ (f - f_old)
        scale = 1e-9 * (1 + np.abs(u).max() + np.abs(Gt).max()) * radius
        assert np.linalg.norm(f) <= radius * (1 + 1e-12), (trial, f)
        assert gradient @ f + radius * np.linalg.norm(gradient) <= scale, (trial, f, gradient)


@pytest.mark.parametrize("angle_deg", [0.0, 22.5, 30.0, 100.0])
def test_exact_cone_box_slides_at_any_angle_decelerating_at_mu_g_along_its_velocity(angle_deg):
    """Eq. (4)'s cone: a box sliding on the table in any direction meets exactly mu of friction
    against its velocity, so it decelerates at mu g on a straight line (the semi-implicit
    step: by mu g h a step, exactly). The 8-sided polygon meets mu cos(22.5 deg) between its
    vertices and pulls the velocity toward one: it fails the same closed form off its vertices."""
    sc = load_scenario(SCENARIOS / "box_push_3d.toml")
    mu, steps, speed = 0.4, 50, 0.5
    angle = math.radians(angle_deg)
    ix, iy = sc.velocities.index("box.x"), sc.velocities.index("box.y")
    exact = pgs_rung(rung_for(sc, "dynamic-rigid"), exact_cone=True)
    polygon = rung_for(sc, "dynamic-rigid")
    errors = {}
    for name, rung in (("exact", exact), ("polygon", polygon)):
        start = rung.initial_state(sc)
        nu = start.nu.copy()
        nu[ix], nu[iy] = speed * math.cos(angle), speed * math.sin(angle)
        result = rung.rollout(sc, replace(start, nu=nu), np.zeros((1, 2)), [steps * H], H, stop_at_outcome=False)
        assert result.status == "ok"
        expected = (speed - steps * mu * G * H) * np.array([math.cos(angle), math.sin(angle)])
        errors[name] = np.max(np.abs(result.state.nu[[ix, iy]] - expected))
    assert errors["exact"] < 1e-6
    if angle_deg % 45.0 != 0.0:  # off the polygon's vertices
        assert errors["polygon"] > 1e-3


def test_the_exact_cone_is_a_rung_setting_solved_by_pgs(tmp_path):
    text = (SCENARIOS / "box_push_3d.toml").read_text()
    path = tmp_path / "cone.toml"
    exact = 'model = "dynamic-rigid"\nfriction_cone = "exact"\n'
    path.write_text(text.replace('model = "dynamic-rigid"\n', exact).replace("meshes/", str(SCENARIOS / "meshes") + "/"))
    assert rung_for(load_scenario(path), "dynamic-rigid").model.exact_cone
    path.write_text(
        text.replace('model = "dynamic-rigid"\n', exact + 'contact_solver = "lemke"\n').replace("meshes/", str(SCENARIOS / "meshes") + "/")
    )
    with pytest.raises(ScenarioError, match="friction_cone"):
        load_scenario(path)


# ----------------------------------------------------------------------------- random scenes


def coulomb_residual(frames, Ainv, out, mu):
    """Natural-map residuals of a planar step's impulses in impulse units, relative to the
    largest impulse: Signorini and Coulomb with maximal dissipation per contact."""
    nu_new, p_n, p_t = out.nu, out.p_n, out.p_t[:, 0]
    w_n = frames.psi / H + frames.W_n.T @ nu_new
    v_t = frames.W_t.T @ nu_new
    g_nn = np.einsum("vi,vw,wi->i", frames.W_n, Ainv, frames.W_n)
    g_tt = np.einsum("vi,vw,wi->i", frames.W_t, Ainv, frames.W_t)
    bound = mu * np.maximum(p_n, 0.0)
    normal = np.abs(np.minimum(p_n, w_n / g_nn))
    cone = np.maximum(np.abs(p_t) - bound, 0.0)
    dissipation = np.abs(p_t - np.clip(p_t - v_t / g_tt, -bound, bound)) if mu > 0 else np.abs(p_t)
    return max(normal.max(), cone.max(), dissipation.max()) / np.abs(p_n).max()


def random_loose_scene(tmp_path, rng):
    """Up to three discs and tilted boxes apart on the plane, just above or on it."""
    bodies, x = [], 0.0
    for k in range(rng.integers(1, 4)):
        m = float(rng.uniform(0.3, 3.0))
        lift = float(rng.uniform(0.0, 3e-4))
        if rng.random() < 0.4:
            r = float(rng.uniform(0.03, 0.2))
            bodies.append(body(f"b{k}", disc_shape(r), x, r + lift, mass=m, inertia=0.5 * m * r * r))
        else:
            w, hh = float(rng.uniform(0.05, 0.4)), float(rng.uniform(0.05, 0.4))
            theta = float(rng.choice([0.0, rng.uniform(-0.6, 0.6)]))
            low = 0.5 * (abs(w * math.sin(theta)) + abs(hh * math.cos(theta)))
            bodies.append(body(f"b{k}", box_shape(w, hh), x, low + lift, theta=theta, mass=m, inertia=box_inertia(m, w, hh)))
        x += 1.0
    return scene(tmp_path, bodies, mu=float(rng.uniform(0.0, 1.5)))


@pytest.mark.parametrize("seed", range(8))
def test_random_scene_pgs_satisfies_coulomb_within_its_tolerance(tmp_path, seed):
    rng = np.random.default_rng(seed)
    sc = random_loose_scene(tmp_path, rng)
    nu = rng.uniform(-1.0, 1.0, len(sc.velocities))
    nu[1::3] = -rng.uniform(0.4, 1.0, len(nu[1::3]))  # every body hits the plane within the step
    mu = sc.spec.contact.mu
    for solver, tolerance in (("lemke", 1e-9), ("pgs", 10 * PGS_TOLERANCE)):
        frames, Ainv, out = step(sc, "dynamic-rigid", solver, sc.start, nu)
        assert out.status == StepStatus.OK
        assert np.abs(out.p_n).max() > 0.0  # something is hit
        assert coulomb_residual(frames, Ainv, out, mu) <= tolerance, solver


def disc_row(tmp_path, rng):
    """Three to five frictionless discs in a row on the plane, each a hair from its neighbours:
    as many contacts as the discs' translations can tell apart, so one solution."""
    bodies, x, previous = [], 0.0, None
    for k in range(rng.integers(3, 6)):
        r = float(rng.uniform(0.05, 0.15))
        y = r + float(rng.uniform(0.0, 2e-4))
        if previous is not None:  # a gap of at most 2e-4 m to the neighbour
            distance = previous[0] + r + rng.uniform(0.0, 2e-4)
            x += math.sqrt(distance**2 - (y - previous[1]) ** 2)
        m = float(rng.uniform(0.5, 2.0))
        bodies.append(body(f"d{k}", disc_shape(r), x, y, mass=m, inertia=0.5 * m * r * r))
        previous = (r, y)
    return scene(tmp_path, bodies, mu=0.0)


@pytest.mark.parametrize("seed", range(6))
def test_random_frictionless_discs_pgs_normal_impulses_equal_lemkes(tmp_path, seed):
    rng = np.random.default_rng(100 + seed)
    sc = disc_row(tmp_path, rng)
    nu = rng.uniform(-1.0, 1.0, len(sc.velocities))
    nu[1::3] = -rng.uniform(0.4, 1.0, len(nu[1::3]))
    frames, _, lemke = step(sc, "dynamic-rigid", "lemke", sc.start, nu)
    _, _, pgs = step(sc, "dynamic-rigid", "pgs", sc.start, nu)
    assert lemke.status == StepStatus.OK and pgs.status == StepStatus.OK
    assert np.linalg.matrix_rank(frames.W_n) == len(frames.psi)  # non-degenerate: independent contacts
    assert np.count_nonzero(lemke.p_n) >= 2
    np.testing.assert_allclose(pgs.p_n, lemke.p_n, rtol=0, atol=1e-4 * np.abs(lemke.p_n).max())
    np.testing.assert_allclose(pgs.nu, lemke.nu, rtol=0, atol=1e-4 * np.abs(nu).max())


@pytest.mark.parametrize("solver", ["pgs", "auto"])
def test_random_scenes_keep_the_stress_invariants(tmp_path, solver):
    rng = np.random.default_rng(7)
    for _trial in range(4):
        sc = random_loose_scene(tmp_path, rng)
        for rung_name in ("dynamic-rigid", "dynamic-compliant"):
            rung = with_solver(sc, rung_name, solver, auto_contacts=2)
            result = rung.rollout(sc, rung.initial_state(sc), np.zeros((1, 0)), [0.5], H, stop_at_outcome=False)
            check_invariants(result, h=H, rigid=rung_name == "dynamic-rigid", passive=True, scenario=sc)
            assert result.status == "ok"


# ----------------------------------------------------------------------------- statuses and settings


def test_a_sweep_limit_too_small_is_a_status_not_an_exception(tmp_path):
    sc, _ = resting_boxes(tmp_path)
    _, _, out = step(sc, "dynamic-rigid", "pgs", sc.start, np.zeros(len(sc.velocities)), max_sweeps=2)
    assert out.status != StepStatus.OK and out.sweeps == 2
    rung = with_solver(sc, "dynamic-rigid", "pgs", max_sweeps=2)
    result = rung.rollout(sc, rung.initial_state(sc), np.zeros((1, 0)), [0.1], H)
    assert result.status == "contact_not_converged" and result.steps == 0
    assert "lemke" in result.message
    np.testing.assert_array_equal(result.state.q, sc.start)


def stack(tmp_path, n):
    bodies = [body(f"b{k}", box_shape(0.1, 0.1), 0.0, 0.05 + 0.1 * k, inertia=box_inertia(1.0, 0.1, 0.1)) for k in range(n)]
    return scene(tmp_path, bodies, mu=0.5)


def test_rigid_stack_pgs_reports_non_convergence_and_auto_falls_back_to_lemke(tmp_path):
    sc = stack(tmp_path, 8)
    pgs = with_solver(sc, "dynamic-rigid", "pgs")
    result = pgs.rollout(sc, pgs.initial_state(sc), np.zeros((1, 0)), [0.05], H)
    assert result.status == "contact_not_converged" and result.sweeps == 1000
    auto = with_solver(sc, "dynamic-rigid", "auto", auto_contacts=1, max_sweeps=50)
    lemke = rung_for(sc, "dynamic-rigid")
    a = auto.rollout(sc, auto.initial_state(sc), np.zeros((1, 0)), [0.05], H)
    b = lemke.rollout(sc, lemke.initial_state(sc), np.zeros((1, 0)), [0.05], H)
    assert a.status == "ok" and a.steps == 50
    assert a.sweeps > 0 and a.pivots > 0  # PGS tried, Lemke finished what it could not
    np.testing.assert_allclose(a.state.q, b.state.q, rtol=0, atol=1e-5)  # the stack stands either way


def test_auto_uses_lemke_below_its_contact_count_and_pgs_from_it(tmp_path):
    sc, _ = resting_boxes(tmp_path)
    runs = {}
    for name, rung in (
        ("lemke", rung_for(sc, "dynamic-compliant")),
        ("pgs", with_solver(sc, "dynamic-compliant", "pgs")),
        ("auto-high", with_solver(sc, "dynamic-compliant", "auto", auto_contacts=7)),  # 6 contacts: Lemke
        ("auto-low", with_solver(sc, "dynamic-compliant", "auto", auto_contacts=6)),  # PGS
    ):
        runs[name] = rung.rollout(sc, rung.initial_state(sc), np.zeros((1, 0)), [0.2], H, stop_at_outcome=False)
    np.testing.assert_array_equal(runs["auto-high"].state.q, runs["lemke"].state.q)
    np.testing.assert_array_equal(runs["auto-low"].state.q, runs["pgs"].state.q)
    assert runs["auto-high"].sweeps == 0 and runs["auto-low"].sweeps == runs["pgs"].sweeps > 0


def test_lemke_is_every_rungs_default():
    sc = load_scenario(SCENARIOS / "two_finger_triangle.toml")
    for name, rung in RUNGS.items():
        assert rung.solver == LEMKE
        assert rung_for(sc, name).solver == LEMKE


def test_scenario_rung_chooses_its_contact_solver(tmp_path):
    sliding_box(tmp_path, 0.5)  # writes stress.toml
    text = (tmp_path / "stress.toml").read_text()
    path = tmp_path / "choice.toml"
    path.write_text(text.replace('model = "dynamic-rigid"\n', 'model = "dynamic-rigid"\ncontact_solver = "pgs"\n'))
    assert rung_for(load_scenario(path), "dynamic-rigid").solver == contact_solver("pgs")
    path.write_text(text.replace('model = "dynamic-rigid"\n', 'model = "dynamic-rigid"\ncontact_solver = "jacobi"\n'))
    with pytest.raises(ScenarioError, match="contact_solver"):
        load_scenario(path)


def test_solver_names_and_settings_are_validated():
    assert tuple(SOLVER_METHODS) == CONTACT_SOLVERS
    for bad in (
        {"name": "jacobi"},
        {"name": "pgs", "tolerance": 0.0},
        {"name": "pgs", "max_sweeps": 0},
        {"name": "auto", "auto_contacts": 1.5},
    ):
        with pytest.raises(ValueError):
            contact_solver(**bad)


def test_auto_solves_the_rest_of_a_rollout_with_lemke_once_pgs_does_not_converge(tmp_path):
    """On the rigid stack PGS fails on the first step: auto pays its sweeps once, and every
    later step of the rollout is Lemke's, so the run is Lemke's own step for step (before, each
    of the 50 steps paid the sweeps first: 920 us/step against Lemke's 27 on 8 boxes)."""
    sc = stack(tmp_path, 8)
    auto = with_solver(sc, "dynamic-rigid", "auto", auto_contacts=1, max_sweeps=50)
    lemke = rung_for(sc, "dynamic-rigid")
    a = auto.rollout(sc, auto.initial_state(sc), np.zeros((1, 0)), [0.05], H)
    b = lemke.rollout(sc, lemke.initial_state(sc), np.zeros((1, 0)), [0.05], H)
    assert a.status == "ok" and a.steps == b.steps == 50
    assert a.sweeps == 50  # one step's worth
    assert a.pivots == b.pivots
    np.testing.assert_array_equal(a.state.q, b.state.q)


def test_auto_holds_on_a_statically_indeterminate_grasp_where_lemke_does():
    """four_finger_grasp under quasistatic-compliant: PGS solves auto's steps of 4 contacts until it
    meets its sweep limit, then Lemke, and auto's run stays within 1e-9 of Lemke's own. At 2.95 s
    Lemke's solution of that state's LCP (its basic block singular: the grasp's two symmetric
    pairs) had left a contact closing by 8e-5 m in the step, and the run ended lcp_failed;
    refined on its basis (`models.lcp.refined_on_basis`) it closes by under 1e-10 m. Both runs
    reach the policy's end."""
    sc = load_scenario(SCENARIOS / "four_finger_grasp.toml")
    controls, durations = policy_controls(sc)
    h = sc.rung_settings("quasistatic-compliant").h
    runs = {}
    for solver in ("lemke", "auto"):
        rung = with_solver(sc, "quasistatic-compliant", solver)
        runs[solver] = rung.rollout(sc, rung.initial_state(sc), controls, durations, h, stop_at_outcome=False)
    lemke, auto = runs["lemke"], runs["auto"]
    assert lemke.status == auto.status == "ok" and lemke.steps == auto.steps == round(durations.sum() / h)
    assert auto.sweeps > 0  # PGS solved steps of the run
    np.testing.assert_allclose(auto.state.q, lemke.state.q, rtol=0, atol=1e-9)

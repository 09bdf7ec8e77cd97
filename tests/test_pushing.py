"""Pushing a box on a table, in every rung: the closed forms a lower rung must keep so that
its plans mean something above it, and the turn an off-centre push gives.

box_push_3d's box (0.2 x 0.2 x 0.1 m, 0.5 kg, mu 0.4 on the table, 8 friction directions).
A box on four support points is statically indeterminate: the quasistatic rung's limit
eps -> 0 (inertia 1e-6) picks a turning solution for a straight central push, with a sign
that flips with the step. The quasistatic rungs here keep the bodies' full inertia in their
memoryless step (`[[ladder.rungs]] inertia = 1`, a quasi-dynamic step) at h = 0.1 s, one
step per control period, as box_push_3d's ladder does. The kinematic rung's passive motion
is least-norm in the kinetic-energy metric (`models.stepper.kinematic_step`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from models.rungs import pgs_rung, rung_for
from models.scenario import load_scenario
from models.stepper import contact_solver

ROOT = Path(__file__).resolve().parents[1]
PUSH = ROOT / "scenarios" / "box_push_3d.toml"
SQUEEZE = ROOT / "tests" / "data" / "squeeze_3d.toml"

#: (rung, step): each rung at the step a ladder runs it at.
RUNG_STEPS = [
    ("kinematic", 1e-2),
    ("quasistatic-rigid", 0.1),
    # at 0.1 s this rung's Lemke ends 2e-7 off complementarity on first contact (LCP_FAILED,
    # a status): a degenerate friction basis; at 0.05 s it is solved exactly
    ("quasistatic-compliant", 0.05),
    ("dynamic-rigid", 1e-3),
    ("dynamic-compliant", 1e-3),
]
#: The pusher starts 7 cm from the box's face and moves at 0.2 m/s: 0.3 m of push after contact.
PUSH_TIME = (0.07 + 0.3) / 0.2


def rung(scenario, name):
    """The scenario's rung, quasistatic ones with the quasi-dynamic step (full inertia)."""
    r = rung_for(scenario, name)
    if r.model.eps == 0.0:
        r = replace(r, model=r.model._replace(quasistatic_inertia=1.0, friction_directions=8))
    return replace(r, model=r.model._replace(friction_directions=8))


def run(r, scenario, speeds, duration, h, offset=0.0):
    state = r.initial_state(scenario)
    q = state.q.copy()
    if offset:
        q[scenario.coordinates.index("pusher.y")] = offset
    q_ref = q[[scenario.coordinates.index(a) for a in scenario.actuated]].copy()
    state = replace(state, q=q, q_ref=q_ref)
    return r.rollout(scenario, state, np.array([speeds]), [duration], h, stop_at_outcome=False)


def yaw_tilt(scenario, q):
    n = dict(zip(scenario.coordinates, q))
    w, x, y, z = (n[f"box.q{c}"] for c in "wxyz")
    yaw = np.degrees(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    tilt = np.degrees(np.arccos(min(1.0, 1 - 2 * (x * x + y * y))))
    return yaw, tilt


def assert_straight_flat_and_out(scenario, out):
    yaw, tilt = yaw_tilt(scenario, out.state.q)
    assert out.status == "ok"
    assert abs(yaw) < 0.5 and tilt < 0.1, (yaw, tilt)
    assert out.max_penetration < 1e-4
    assert abs(out.state.named(scenario)["box.z"] - 0.05) < 1e-4


@pytest.mark.parametrize(("name", "h"), RUNG_STEPS)
def test_a_central_push_stays_straight_flat_and_out_of_the_table(name, h):
    scenario = load_scenario(PUSH)
    out = run(rung(scenario, name), scenario, [0.2, 0.0], 3.0, h)
    assert_straight_flat_and_out(scenario, out)
    # the pusher's 0.6 m less the 7 cm gap to the face: box.x = -0.2 + 0.6 + 0.03 + 0.1
    assert out.state.named(scenario)["box.x"] == pytest.approx(0.53, abs=1e-3)


@pytest.mark.parametrize(("name", "h"), RUNG_STEPS)
def test_a_symmetric_squeeze_leaves_the_box_where_it_is(name, h):
    scenario = load_scenario(SQUEEZE)
    out = run(rung(scenario, name), scenario, [0.2, -0.2], 3.0, h)
    assert_straight_flat_and_out(scenario, out)
    named = out.state.named(scenario)
    assert abs(named["box.x"]) < 1e-6 and abs(named["box.y"]) < 1e-6
    # both fingers reached the box (centre 0.13 m from the box's centre) and stay symmetric
    assert named["left.y"] == pytest.approx(-named["right.y"], abs=1e-6)
    assert -0.1301 < named["left.y"] < -0.125


@pytest.mark.parametrize(("name", "h"), RUNG_STEPS[:3])
def test_a_pusher_started_from_rest_meets_the_box_within_its_first_step_not_inside_it(name, h):
    """The memoryless and kinematic steps move at the commanded speed from the first step, which
    the velocity the contacts were detected with (the last step's: zero at rest) does not
    foresee: a pusher at rest half its first step's travel short of the face (0.5 m/s) moved
    through it untouched, the box left where it was (models.contact.step_outran). Now the step
    is taken again over the contacts its motion reaches: the sphere ends on the face
    (box.x - pusher.x = 0.13 m, the half width plus the radius; less the compliant rung's
    deformation, its impulse over h K + C) and the box moved by the rest."""
    scenario = load_scenario(PUSH)
    r = rung(scenario, name)
    names = list(scenario.coordinates)
    free = run(r, scenario, [0.5, 0.0], h, h, offset=0.5)  # beside the box: one free step's travel
    travel = free.state.named(scenario)["pusher.x"] + 0.2
    assert travel > 4 * 1e-3  # more than the contact margin (1 mm) can see from rest
    state = r.initial_state(scenario)
    q = state.q.copy()
    q[names.index("pusher.x")] = -0.13 - travel / 2
    state = replace(state, q=q, q_ref=q[[names.index(a) for a in scenario.actuated]].copy())
    out = r.rollout(scenario, state, np.array([[0.5, 0.0]]), [h], h, stop_at_outcome=False)
    named = out.state.named(scenario)
    assert out.status == "ok" and out.steps == 1
    k, pair = next((k, p) for k, p in enumerate(scenario.pairs) if {p.body_a, p.body_b} == {"box", "pusher"})
    deformation = out.pair_force[k] * h / (h * pair.K + pair.C) if r.model.compliant else 0.0
    assert named["box.x"] - named["pusher.x"] == pytest.approx(0.13 - deformation, abs=1e-9)
    assert named["box.x"] > travel / 4  # pushed, not passed through


#: Pusher offsets off the box's centre line (m) for the turn tests.
OFFSETS = [0.02, 0.04, 0.06, 0.08]


@pytest.fixture(scope="module")
def dynamic_yaws():
    """The reference: dynamic-rigid at h = 1e-4, 0.3 m of push at each offset (degrees)."""
    scenario = load_scenario(PUSH)
    reference = rung(scenario, "dynamic-rigid")
    return {e: yaw_tilt(scenario, run(reference, scenario, [0.2, 0.0], PUSH_TIME, 1e-4, e).state.q)[0] for e in OFFSETS}


def test_off_centre_pushes_turn_the_box_in_the_quasistatic_rung_as_in_dynamics(dynamic_yaws):
    """The quasi-dynamic step at h = 0.1 s: final yaw within 20 % of dynamic-rigid's at 1e-4.
    Measured (degrees, offsets 2/4/6/8 cm): dynamic -30.7/-31.2/-37.2/-49.0, quasistatic
    -29.8/-31.3/-43.7/-55.3 (at most 17.5 % off). The step is part of this model: at h = 0.05 s
    it turns 25-30 % more at 4-8 cm."""
    scenario = load_scenario(PUSH)
    quasi = rung(scenario, "quasistatic-rigid")
    for e, reference in dynamic_yaws.items():
        out = run(quasi, scenario, [0.2, 0.0], PUSH_TIME, 0.1, e)
        yaw, tilt = yaw_tilt(scenario, out.state.q)
        assert out.status == "ok" and tilt < 0.1
        assert reference < -20.0  # the offset does turn the box (clockwise: pushed left of centre)
        assert yaw == pytest.approx(reference, rel=0.2), e


def test_off_centre_pushes_turn_the_box_in_the_kinematic_rung(dynamic_yaws):
    """Least kinetic energy passive motion: the same sign as dynamics, within a factor 2.
    Measured (degrees, 2/4/6/8 cm): -30.0/-51.1/-62.6/-68.2 (factor 1.0-1.7); with the
    paper's |nu|^2 metric -0.3/-0.7/-1.0/-1.4 (metres and radians weighed alike)."""
    scenario = load_scenario(PUSH)
    kinematic = rung(scenario, "kinematic")
    for e, reference in dynamic_yaws.items():
        out = run(kinematic, scenario, [0.2, 0.0], PUSH_TIME, 1e-2, e)
        yaw, tilt = yaw_tilt(scenario, out.state.q)
        assert out.status == "ok" and tilt < 0.1
        assert np.sign(yaw) == np.sign(reference)
        assert abs(reference) / 2 < abs(yaw) < 2 * abs(reference), e


def test_the_kinematic_step_is_the_least_kinetic_energy_motion():
    """One kinematic step of a push 5 cm off centre against the QP min v^T M v s.t. the
    contacts open, solved by OSQP: the box translates and turns (the |v|^2 metric would
    barely turn it)."""
    from models.contact import contact_frames
    from models.qp import solve_qp
    from models.rungs import compiled
    from models.stepper import mass_matrix

    scenario = load_scenario(PUSH)
    S = compiled(scenario).scene
    kinematic = rung(scenario, "kinematic")
    state = kinematic.initial_state(scenario)
    q = state.q.copy()
    names = list(scenario.coordinates)
    q[names.index("pusher.x")] = -0.13 - 1e-4  # the sphere just short of the box's face
    q[names.index("pusher.y")] = 0.05
    state = replace(state, q=q, q_ref=q[[names.index(a) for a in scenario.actuated]].copy())
    h, u = 1e-2, np.array([0.2, 0.0])
    result = kinematic.step(scenario, state, u, h)
    assert result.status == "ok"
    frames = contact_frames(S, q, nu=np.r_[np.zeros(S.nv - 2), u], h=h)
    v_act = [scenario.velocities.index(a) for a in scenario.actuated]
    passive = [v for v in range(S.nv) if v not in v_act]
    M = mass_matrix(S.bi, S.bf, q, S.nv)[np.ix_(passive, passive)]
    Wp, Wa = frames.W_n[passive, :], frames.W_n[v_act, :]
    qp = solve_qp(2 * M, np.zeros(len(passive)), Wp.T, -(frames.psi / h + Wa.T @ u), np.full(len(frames.psi), np.inf))
    assert qp.success
    np.testing.assert_allclose(result.state.nu[passive], qp.x, atol=1e-6)
    wz = result.state.nu[scenario.velocities.index("box.wz")]
    vx = result.state.nu[scenario.velocities.index("box.x")]
    assert vx > 0.05 and wz < -1.0  # pushed forward and turned clockwise


@pytest.mark.parametrize("offset", [0.0, 0.04])
def test_the_warm_started_contact_solve_is_the_cold_one_and_nearly_free(offset):
    """Lemke starts each step from the previous step's basis (`models.stepper.basis_table`,
    carried in `State.lcp_basis`): a push, central and turning the box, as one call against
    the same steps solved from scratch each (one-step calls from states without a basis).

    The warm run pivots on few steps only: it starts cold, and pivots where the contacts change
    (the pusher arriving) or, as the box turns, where its sliding friction moves to another side
    of the polyhedral cone; where the previous basis fails, Lemke follows its path from that
    basis (`models.lcp.lemke_from_guess_into`). Measured: 10 pivots over the 1850 steps central,
    41 turning (28 and 292 when a failed basis sent Lemke back to scratch). The one-step calls
    guess each step's basis from its LCP's q (`models.stepper._basis_guess`): central, that
    guess solves the steps (13 pivots in all, where Lemke from scratch took 15 a step); turning,
    it does not (the corners' friction on two sides of the cone at once, the pusher sticking),
    and Lemke pivots about 13 times a step from it (15 from scratch). The
    states agree up to the push's indeterminacy: a rigid box on four corners, pushed by a rigid
    sphere with friction, has a continuum of contact forces (the pusher's
    vertical friction anywhere in +-mu N: the table's normal force, so its friction, and the
    pushing force move by up to 0.3 N, the pusher's velocity in a step by up to 3e-4 m/s; the
    four corners' share of the box's weight, so the friction torque that turns it); Lemke
    returns a vertex, and which one is decided by where its path starts (from scratch, from
    the last basis or from the guess) and by round-off. Measured: 1.5e-5 m apart central; turning
    1.5e-4 in the box's orientation (2.5e-4 rad of yaw) and 3.1e-3 rad/s in its yaw rate at the
    end, 3e-4 m/s in the pusher's velocity (before paths started from failed guesses: 3.2e-5 m
    and 9.5e-6 m, 1e-5 rad/s); every solve exact (residual <= 1e-12). The warm start here runs
    through the whole call (no `Model.warm_period`)."""
    scenario = load_scenario(PUSH)
    r = rung(scenario, "dynamic-rigid")
    r = replace(r, model=r.model._replace(warm_period=0.0))
    h = 1e-3
    start = r.initial_state(scenario)
    q = start.q.copy()
    q[scenario.coordinates.index("pusher.y")] = offset
    start = replace(start, q=q, q_ref=q[[scenario.coordinates.index(a) for a in scenario.actuated]].copy())
    warm = r.rollout(scenario, start, np.array([[0.2, 0.0]]), [PUSH_TIME], h, stop_at_outcome=False)
    state, pivots, residual = start, 0, 0.0
    for _ in range(warm.steps):
        out = r.rollout(scenario, replace(state, lcp_basis=np.zeros((0, 0), np.int8)), np.array([[0.2, 0.0]]), [h], h)
        state, pivots, residual = out.state, pivots + out.pivots, max(residual, out.max_residual)
        assert out.status == "ok"
    assert warm.status == "ok" and warm.force_steps > 1000
    np.testing.assert_allclose(warm.state.q, state.q, rtol=0, atol=5e-4)
    np.testing.assert_allclose(warm.state.nu, state.nu, rtol=0, atol=1e-2)
    assert residual <= 1e-12 and warm.max_residual <= 1e-12
    if offset == 0.0:  # cold: the guess from q solves nearly every step
        assert pivots < 0.05 * warm.force_steps
    else:  # cold: the guess from q fails, and Lemke pivots about 15 times a step
        assert pivots > 10 * warm.force_steps
    assert warm.pivots < (0.05 if offset == 0.0 else 0.2) * warm.force_steps
    assert warm.max_residual <= 1e-12 and residual <= 1e-12


#: A push with turns (Lemke: degenerate LCPs on the turns); PGS on the polygonal cone turns only
#: at its end: at 1.745 s into the other its step takes about 40,000 sweeps to reach the
#: tolerance (a status after the default 1,000; auto then takes Lemke; docs/measurements.md).
PUSH_WITH_TURNS = ([[0.2, 0.0], [0.2, 0.08], [0.15, -0.1], [0.2, 0.0]], [0.6, 0.4, 0.5, 0.5])
PUSH_TURNING_AT_ITS_END = ([[0.2, 0.0], [0.2, 0.08]], [0.6, 0.1])


@pytest.mark.parametrize("solver", ["lemke", "pgs", "auto", "exact cone"])
def test_a_plan_replayed_in_one_call_is_the_plan_propagated_one_period_a_call(solver):
    """A planner propagates one control period per call, each from a state vector that holds
    no warm start; the plan's replay is one call. With the warm starts dropped at every control
    period (`Model.warm_period`, from the rung's settings) both solve the same contact problems:
    the same states to the last bit. Lemke: over a push with turns, where degenerate contact
    LCPs have more than one exact solution and a warm basis would pick another. PGS (polygon,
    auto, exact cone): it stops within its tolerance of the solution its warm start leads to,
    so its impulses kept across periods ended these pushes 2.5e-5 to 0.08 m elsewhere."""
    scenario = load_scenario(PUSH)
    r = rung(scenario, "dynamic-rigid")
    if solver == "exact cone":
        r = pgs_rung(r, exact_cone=True)
    elif solver != "lemke":
        r = replace(r, solver=contact_solver(solver))
    period = scenario.rung_settings("dynamic-rigid").control_period
    assert r.model.warm_period == period
    h = 1e-3
    controls, durations = (np.array(a) for a in (PUSH_TURNING_AT_ITS_END if solver == "pgs" else PUSH_WITH_TURNS))
    one = r.rollout(scenario, r.initial_state(scenario), controls, durations, h, stop_at_outcome=False)
    state, force_steps = r.initial_state(scenario), 0
    for u, d in zip(controls, durations):
        for _ in range(round(d / period)):
            out = r.rollout(scenario, replace(state, lcp_basis=np.zeros((0, 0), np.int8)), u, [period], h, stop_at_outcome=False)
            state, force_steps = out.state, force_steps + out.force_steps
            assert out.status == "ok"
    assert one.status == "ok" and one.force_steps == force_steps > 500
    assert np.array_equal(one.state.q, state.q) and np.array_equal(one.state.nu, state.nu)


def test_a_period_s_first_step_is_solved_by_its_guess_from_q():
    """A planner propagates one control period a call from a state with no basis, so each
    call's first step has no warm start (`Model.warm_period`). Its basis is guessed from the
    LCP's own q (`models.stepper._basis_guess`: a contact pushes where its normal's q < 0 and
    slides against its most negative friction direction), and on the straight push the box's
    four coplanar corners, all guessed to push, make that guess singular: tried again without
    the first of them (`_generator_guess_dropping_into`) it solves the LCP. So no step of these
    calls pivots, where Lemke from scratch took 15 pivots at each call's first step; each
    step's impulses are still exact (every guess is kept only within its tolerance, and the
    rollout checks each step's residual: status ok)."""
    scenario = load_scenario(PUSH)
    r = rung(scenario, "dynamic-rigid")
    period, h = scenario.rung_settings("dynamic-rigid").control_period, 1e-3
    state = run(r, scenario, [0.2, 0.0], 0.4, h).state  # the pusher reaches the box at 0.35 s
    for _ in range(10):
        out = r.rollout(scenario, replace(state, lcp_basis=np.zeros((0, 0), np.int8)), np.array([[0.2, 0.0]]), [period], h)
        assert out.status == "ok" and out.force_steps == round(period / h)
        assert out.pivots == 0
        state = out.state

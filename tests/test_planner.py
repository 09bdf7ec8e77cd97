"""The planner over the ladder: plans that hold, determinism, replay, bad starts."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from models.rungs import RUNGS, rung_for
from models.scenario import ScenarioError, load_scenario
from planner.ladder import run_ladder
from planner.plan_status import PlanStatus
from tests.conftest import ROOT, SCENARIOS

TRIANGLE = SCENARIOS / "two_finger_triangle.toml"


def test_paper_scene_plan_holds_at_the_top_rung_when_replayed_independently():
    scenario = load_scenario(TRIANGLE, {"v1": 0.8})
    result = run_ladder(scenario, seed=1, iterations=2000)
    assert result.top_holds
    top = result.rungs[-1]
    assert top.rung == "dynamic-compliant"
    rung = rung_for(scenario, "dynamic-compliant")
    replay = rung.rollout(scenario, rung.initial_state(scenario), np.array(top.controls), np.array(top.durations), 1e-4)
    assert replay.outcome == "goal" and replay.ok


def test_same_seed_gives_the_same_plan_different_seed_may_differ():
    scenario = load_scenario(SCENARIOS / "free_transfer.toml")
    a = run_ladder(scenario, seed=3, iterations=3000).to_json(timings=False)
    b = run_ladder(scenario, seed=3, iterations=3000).to_json(timings=False)
    c = run_ladder(scenario, seed=4, iterations=3000).to_json(timings=False)
    assert json.dumps(a) == json.dumps(b)
    assert a["top_holds"] and c["top_holds"]
    assert json.dumps(a) != json.dumps(c)


def test_free_transfer_higher_rungs_are_accepted_by_replay_without_search():
    scenario = load_scenario(SCENARIOS / "free_transfer.toml")
    # the iterations are the budget; the scenario's 10 s cap per rung could end a search whose
    # kernels compile in this test (a subset run), so it is lifted
    rungs = ["kinematic", "quasistatic-rigid", "dynamic-rigid", "dynamic-compliant"]
    result = run_ladder(scenario, rungs=rungs, seed=3, iterations=3000, time_limit=600.0)
    assert result.rungs[0].ended is PlanStatus.EXACT
    for report in result.rungs[1:]:
        assert report.ended in (PlanStatus.REPLAYED, PlanStatus.SKIPPED) and report.propagations == 0
    # nothing is touched on the way, so dynamic-compliant (same step as dynamic-rigid) is the same physics
    assert [r.ended for r in result.rungs[1:]] == [PlanStatus.REPLAYED, PlanStatus.REPLAYED, PlanStatus.SKIPPED]
    assert result.rungs[2].contact_steps == 0 and "no contact carries force" in result.rungs[3].reason
    assert result.top_holds
    rung = rung_for(scenario, "dynamic-compliant")  # the skip was right: the plan does hold there
    top = result.rungs[-1]
    assert rung.rollout(scenario, rung.initial_state(scenario), np.array(top.controls), np.array(top.durations), 1e-4).outcome == "goal"


def test_a_plan_that_pushes_is_not_skipped_between_rigid_and_compliant_contact():
    scenario = load_scenario(TRIANGLE, {"v1": 0.8})
    result = run_ladder(scenario, rungs=["kinematic", "dynamic-rigid", "dynamic-compliant"], seed=1, iterations=2000)
    assert result.rungs[1].contact_steps > 0
    assert result.rungs[2].ended is not PlanStatus.SKIPPED


def test_a_start_inside_the_unsafe_set_is_bad_input(tmp_path):
    text = TRIANGLE.read_text().replace("[task]\nhorizon = 4.0", '[task]\nhorizon = 4.0\nstart = { "triangle.x" = 0.6 }')
    path = tmp_path / "unsafe_start.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match="inside the unsafe set"):
        run_ladder(load_scenario(path), seed=1, iterations=100)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = tmp_path / "plan"
    done = subprocess.run(
        [sys.executable, "-m", "planner", "plan", str(path), "--out", str(out)], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 2 and "task.start" in done.stderr and not out.exists()


def test_plan_command_writes_a_reproducible_plan(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    outputs = []
    for run in range(2):
        out = tmp_path / f"run{run}"
        done = subprocess.run(
            [sys.executable, "-m", "planner", "plan", str(TRIANGLE), "--param", "v1=0.8", "--seed", "2", "--out", str(out)],
            capture_output=True,
            text=True,
            env=env,
            timeout=600,
        )
        assert done.returncode == 0, done.stderr
        outputs.append((out / "plan.json").read_bytes())
        assert (out / "plan.dynamic-compliant.png").exists()
    assert outputs[0] == outputs[1]


def test_seeding_from_the_previous_plan_saves_propagations():
    """Replan free_transfer's dynamic-rigid rung given the kinematic plan cut short (so its
    replay stops before the goal): roots along the replayed prefix need fewer propagations
    than planning from scratch, in the median over seeds."""
    from planner.ladder import RungReport, _replay
    from planner.ompl_adapter import plan_control

    scenario = load_scenario(SCENARIOS / "free_transfer.toml")
    first = run_ladder(scenario, rungs=["kinematic"], seed=3, iterations=3000).rungs[0]
    cut = max(1, int(0.8 * len(first.durations)))
    previous = RungReport("kinematic", "planned", controls=first.controls[:cut], durations=first.durations[:cut])
    rung = rung_for(scenario, "dynamic-rigid")
    start = rung.initial_state(scenario)
    seeds = _replay(scenario, rung, start, previous, 1e-3).states
    assert len(seeds) >= cut // 2
    scratch, seeded = [], []
    for seed in range(1, 8):
        a = plan_control(scenario, rung, start, h=1e-3, control_period=0.1, seed=seed, iterations=4000)
        b = plan_control(scenario, rung, start, h=1e-3, control_period=0.1, seed=seed, iterations=4000, extra_starts=seeds)
        assert b.exact
        scratch.append(a.propagations if a.exact else 10**9)
        seeded.append(b.propagations)
    assert np.median(seeded) < np.median(scratch)


def test_a_rung_may_spend_what_the_rungs_below_left_and_the_ladder_never_more_than_flat(monkeypatch):
    """box_push_3d's geometric path takes ~20 of its 200 iterations; the kinematic rung (which
    must replan: the geometric path moves the box on its own, and here no push along it is
    tracked first) may spend the rest on top of its own 200, and the ladder as a whole never
    more than the 400 that --flat would get."""
    import planner.ladder

    monkeypatch.setattr(planner.ladder, "push_reference", lambda *args: None)  # (it tracks a push in 0 iterations)
    scenario = load_scenario(SCENARIOS / "box_push_3d.toml")
    spent_beyond_own = False
    for seed in (1, 2, 3):
        geometric, kinematic = run_ladder(scenario, rungs=["geometric", "kinematic"], seed=seed, iterations=200).rungs
        assert geometric.iterations < 200
        assert geometric.iterations + kinematic.iterations <= 400
        # (with 400 iterations the kinematic rung, whose pushes turn the box, does not reach the goal)
        spent_beyond_own |= kinematic.iterations > 200
    assert spent_beyond_own


def test_the_scenarios_time_limit_caps_a_search_and_the_report_says_so(tmp_path):
    """[ladder] time_limit is a wall-clock safety net on top of the iteration budget."""
    path = tmp_path / "hurried.toml"
    path.write_text((SCENARIOS / "free_transfer.toml").read_text().replace("time_limit = 10.0", "time_limit = 1e-4"))
    result = run_ladder(load_scenario(path), seed=3, iterations=100_000)
    assert not result.top_holds
    failed = result.rungs[-1]
    assert failed.ended is PlanStatus.TIMEOUT and failed.reason.startswith(PlanStatus.TIMEOUT.message)
    assert "time limit ran out" in failed.reason and failed.iterations < 100_000


def test_simulate_replays_a_plan_file_under_any_rung(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = tmp_path / "plan"
    done = subprocess.run(
        [sys.executable, "-m", "planner", "plan", str(TRIANGLE), "--param", "v1=0.8", "--out", str(out)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    for model in ("quasistatic-rigid", "dynamic-compliant"):
        sim = subprocess.run(
            [
                sys.executable,
                "-m",
                "planner",
                "simulate",
                str(TRIANGLE),
                "--param",
                "v1=0.8",
                "--plan",
                str(out / "plan.json"),
                "--model",
                model,
                "--json",
            ],
            capture_output=True,
            text=True,
            env=env,
            timeout=600,
        )
        assert sim.returncode == 0, sim.stderr
        assert json.loads(sim.stdout)["outcome"] == "goal"
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    sim = subprocess.run(
        [sys.executable, "-m", "planner", "simulate", str(TRIANGLE), "--plan", str(bad), "--model", "kinematic"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert sim.returncode == 2 and f"{bad}: rungs: no rung with controls" in sim.stderr


def test_scenario_expectations_run_as_pytest_items_and_can_fail(tmp_path):
    text = (SCENARIOS / "incline_block.toml").read_text()
    good = tmp_path / "good.toml"
    good.write_text(text)
    wrong = tmp_path / "wrong.toml"
    wrong.write_text(
        text.replace('policy = { dynamic-rigid = "goal", dynamic-compliant = "goal" }', 'policy = { dynamic-rigid = "unsafe" }')
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(tmp_path), str(tmp_path)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        cwd=tmp_path,
    )
    assert done.returncode == 1, done.stdout + done.stderr
    # good: its two policy items and its `sticks` case's two; wrong: its case's two
    assert "6 passed" in done.stdout and "1 failed" in done.stdout
    assert "expected 'unsafe'" in done.stdout


def test_geometric_rung_plans_free_transfer_and_the_kinematic_rung_replays_it():
    """No contact is needed: the geometric path, turned into speeds, holds under kinematics."""
    scenario = load_scenario(SCENARIOS / "free_transfer.toml")
    result = run_ladder(scenario, seed=3, iterations=3000)
    geometric, kinematic = result.rungs
    assert geometric.ended is PlanStatus.EXACT and geometric.outcome == "goal"
    assert kinematic.ended is PlanStatus.REPLAYED and kinematic.propagations == 0
    from planner.ompl_adapter import plan_geometric

    path = plan_geometric(scenario, seed=3, iterations=3000)
    assert all(RUNGS["geometric"].valid(scenario, q) for q in path.states)


@pytest.mark.parametrize("name", ["four_finger_grasp", pytest.param("box_push_3d", marks=pytest.mark.slow)])
def test_plans_that_hold_at_the_top_rung_in_most_seeds(name):
    """The issue's bar: a plan within the default budget in at least 8 of 10 seeds, each one
    checked by replaying it under the top rung. box_push_3d replans its quasistatic and
    dynamic rungs (a few minutes in all): `pytest -m slow`."""
    scenario = load_scenario(SCENARIOS / f"{name}.toml")
    held = 0
    for seed in range(1, 11):
        result = run_ladder(scenario, seed=seed)
        top = result.rungs[-1]
        rung = rung_for(scenario, top.rung)
        replay = (
            rung.rollout(
                scenario,
                rung.initial_state(scenario),
                np.array(top.controls).reshape(len(top.durations), -1),
                np.array(top.durations),
                scenario.rung_settings(top.rung).h,
            )
            if top.durations
            else None
        )
        held += bool(result.top_holds and replay is not None and replay.outcome == "goal" and replay.ok)
    assert held >= 8


def _holds_at_a_tenth_of_the_step(scenario, report) -> bool:
    """The rung's accepted plan, replayed under the rung at a tenth of its step, still ends in
    the goal: it does not rely on the discretisation error (a planner exploits it if it can)."""
    rung = rung_for(scenario, report.rung)
    out = rung.rollout(
        scenario,
        rung.initial_state(scenario),
        np.array(report.controls).reshape(len(report.durations), -1),
        np.array(report.durations),
        scenario.rung_settings(report.rung).h / 10,
    )
    return out.ok and out.outcome == "goal"


@pytest.mark.parametrize("name", ["two_finger_triangle", "four_finger_grasp"])
def test_every_rungs_plan_holds_at_a_tenth_of_its_step(name):
    scenario = load_scenario(SCENARIOS / f"{name}.toml", {"v1": 0.8} if name == "two_finger_triangle" else {})
    for seed in (1, 2, 3):
        result = run_ladder(scenario, seed=seed)
        assert result.top_holds
        for report in result.rungs:
            if rung_for(scenario, report.rung).propagates:
                assert _holds_at_a_tenth_of_the_step(scenario, report), (seed, report.rung)


@pytest.mark.slow
def test_box_push_plans_mostly_hold_at_a_tenth_of_their_step():
    """Pushing is unstable and the goal is reached past a wall within a 1e-6 m touch tolerance,
    so a plan found at one step need not hold at a finer one. The dynamic plans (h = 1e-3)
    hold at 1e-4 in most seeds: 23 of seeds 1-30 (26 before Lemke started from failed guesses'
    bases, which changed the pushes' contact forces where they are not unique; 8 and 6 of seeds
    1-10, so 10 seeds were too few for a 7-of-10 bound), asserted at 70% of 30. The quasistatic
    rung's step is part of its model (a memoryless quasi-dynamic step of 0.1 s, one per control
    period; at 0.01 s it is a different model that turns a pushed box more: 2 of 10 of its plans
    hold there), so it is not checked here: its plans carry upward by tracking
    (`planner.tracking`)."""
    scenario = load_scenario(SCENARIOS / "box_push_3d.toml")
    fine = 0
    for seed in range(1, 31):
        result = run_ladder(scenario, seed=seed)
        assert result.top_holds
        top = result.rungs[-1]
        assert top.rung == "dynamic-rigid"
        fine += _holds_at_a_tenth_of_the_step(scenario, top)
    assert fine >= 21


def test_reports_carry_goal_distance_penetration_and_failures():
    scenario = load_scenario(TRIANGLE, {"v1": 0.8})
    result = run_ladder(scenario, seed=2)
    for report in result.rungs:
        assert report.goal_distance == 0.0  # every rung's accepted plan ends in the goal
        assert report.solver_failures >= 0 and report.status == "ok"
    top = result.rungs[-1]
    assert top.contact_steps > 0  # the grasp is made by contact
    assert 0.0 < top.max_penetration < 1e-3  # compliant contact: small, positive penetration (K = 1e6)
    data = json.loads(json.dumps(result.to_json()))
    assert {"goal_distance", "max_penetration", "solver_failures", "contact_steps"} <= set(data["rungs"][-1])


def test_goal_states_made_by_projection_are_in_the_goal_and_valid():
    from models.predicates import predicate_distance
    from models.rungs import GeometricChecker, pair_signed_distances
    from planner.ompl_adapter import GoalSampler, configuration_limits, plan_geometric

    scenario = load_scenario(TRIANGLE)
    low, high = configuration_limits(scenario, scenario.start)
    valid = GeometricChecker(scenario, low, high)
    sampler = GoalSampler(scenario, np.random.default_rng(0), low, high, valid)
    samples = [sampler.draw() for _ in range(10)]
    assert all(q is not None for q in samples)
    for q in samples:
        assert predicate_distance(scenario, scenario.spec.task.goal, q, pair_signed_distances(scenario, q)) == 0.0
        assert valid(q) and RUNGS["geometric"].valid(scenario, q)  # the reference (python-fcl / numpy) geometry agrees
    assert len({tuple(np.round(q, 6)) for q in samples}) == 10  # spread over the goal set, not one point
    path = plan_geometric(scenario, seed=1, iterations=2000)
    assert path.exact and path.goal_samples >= 1
    assert all(valid(q) for q in path.states)


@pytest.mark.parametrize("name", ["two_finger_triangle", "four_finger_grasp", "box_push_3d"])
def test_the_geometric_check_and_the_distances_on_bound_buffers_answer_as_fresh_ones(name):
    """`GeometricChecker` binds its scene and the distances' buffers once and reuses them
    check after check: every answer is the one a checker made for that q alone gives, and
    the distances on shared buffers, and `pair_signed_distances`' on the bound scene, are
    `pair_min_distances`' own, bit for bit, as are `pair_signed_distances_many`'s rows. The
    check measures pairs within CONTACT_MARGIN only: its answer is the one every pair's exact
    distance gives (bounds, no penetration beyond the tolerance, not unsafe), and the pairs
    within the margin read the same bits as at any margin, the others more than it."""
    from models.contact import CONTACT_MARGIN, pair_distance_buffers, pair_min_distances, pair_min_distances_into
    from models.rungs import GEOMETRIC_TOLERANCE, GeometricChecker, compiled, pair_signed_distances, pair_signed_distances_many
    from models.task import Outcome, classify
    from planner.ompl_adapter import sampling_limits

    def exact(q):  # every pair measured, whatever its distance
        d = pair_signed_distances(scenario, q)
        inside = bool(np.all(q >= low) and np.all(q <= high))
        return inside and not np.any(d < -GEOMETRIC_TOLERANCE) and classify(scenario, q, d) is not Outcome.UNSAFE

    scenario = load_scenario(SCENARIOS / f"{name}.toml")
    low, high = sampling_limits(scenario, scenario.start)
    valid = GeometricChecker(scenario, low, high)
    S = compiled(scenario).scene
    buffers = pair_distance_buffers(S)
    rng = np.random.default_rng(3)
    answers = set()
    sampled = high > low
    drawn = []
    close = 0
    for k in range(60):
        if k % 2:  # anywhere in the sampling limits
            q = np.where(sampled, low + rng.random(len(low)) * (high - low), scenario.start)
        else:  # near the start
            q = np.clip(scenario.start + 0.02 * rng.standard_normal(len(low)) * sampled, low, high)
        drawn.append(q)
        answers.add(valid(q))
        assert valid(q) == GeometricChecker(scenario, low, high)(q) == exact(q)
        fresh, shared, near = np.empty(len(S.pi)), np.empty(len(S.pi)), np.empty(len(S.pi))
        pair_min_distances(S, q, 1e9, fresh)
        pair_min_distances_into(S, q, 1e9, shared, buffers)
        assert np.array_equal(fresh, shared, equal_nan=True)
        pair_min_distances_into(S, q, CONTACT_MARGIN, near, buffers)
        within = fresh <= CONTACT_MARGIN
        close += int(within.sum())
        assert np.array_equal(near[within], fresh[within]) and np.all(near[fresh > CONTACT_MARGIN] > CONTACT_MARGIN)
        measured = ~np.isnan(fresh[: len(scenario.pairs)])  # (python-fcl measures the others)
        assert np.array_equal(pair_signed_distances(scenario, q)[measured], fresh[: len(scenario.pairs)][measured])
    assert answers == {True, False}  # the states drawn reach both answers
    assert close > 0  # and pairs within the margin
    assert np.array_equal(pair_signed_distances_many(scenario, drawn), [pair_signed_distances(scenario, q) for q in drawn])


@pytest.mark.parametrize("name", ["two_finger_triangle", "four_finger_grasp"])  # (the scenes whose goals have touch pairs)
def test_the_goal_projections_terms_in_one_compiled_call_are_the_numpy_terms(name):
    """The goal sampler's Gauss-Newton terms (residuals and finite-difference Jacobian of the
    touch pairs' distances) come from one compiled call (`models.rungs.projection_terms`); its
    NumPy version (`GoalSampler._terms`, on distances python-fcl completes) stays for pairs the
    kernels cannot measure. At 40 states a scene, from the projection's own start states to the
    goal states it makes, both give the same answer and the same bits."""
    from models.rungs import GeometricChecker, projection_terms
    from planner.ompl_adapter import PROJECTION_STEP, GoalSampler, sampling_limits

    scenario = load_scenario(SCENARIOS / f"{name}.toml")
    low, high = sampling_limits(scenario, scenario.start)
    sampler = GoalSampler(scenario, np.random.default_rng(4), low, high, GeometricChecker(scenario, low, high))
    boxes, touches = [], []
    sampler._constraints(scenario.spec.task.goal, boxes, touches)
    pairs = np.array([p for p, _ in touches], np.int64)
    targets = np.array([t for _, t in touches])
    movable = sampler.movable
    rng = np.random.default_rng(6)
    goal_states = [q for q in (sampler.draw() for _ in range(4)) if q is not None]
    states = goal_states + [np.where(high > low, low + rng.random(len(low)) * (high - low), scenario.start) for _ in range(36)]
    answers = set()
    for q in states:
        r, J = np.full(len(pairs), np.nan), np.full((len(pairs), len(movable)), np.nan)
        got = projection_terms(scenario, q, movable, pairs, targets, PROJECTION_STEP, r, J)
        expected, r_numpy, J_numpy = sampler._terms(q, pairs, targets)
        assert got == expected
        answers.add(got)
        assert np.array_equal(r, r_numpy)
        if got == 0:
            assert np.array_equal(J, J_numpy) and np.all(np.isfinite(J))
    assert answers == {0, 1}


@pytest.mark.parametrize("name", ["two_finger_triangle", "four_finger_grasp", "box_push_3d"])
def test_a_compiled_motion_check_asks_ompls_states_in_ompls_order(name):
    """`GeometricChecker.motion` checks a straight motion in one compiled call where OMPL's
    default motion validator asks Python for each state: over 120 motions between random
    states (many blocked), the answer, the number of states checked and the states themselves,
    in order and bit for bit, are the ones OMPL's validator asks of a recording checker; and
    `plan_geometric` with it (its default) plans the same paths with the same checks as with
    OMPL's validator alone (seeds 1-4: on box_push_3d seed 4 a validator set again after the
    search changed the path), also where every motion goes to OMPL's validator (as one
    through a pair only python-fcl measures does)."""
    from ompl import base as ob

    import planner.ompl_adapter as oa
    from models.rungs import GeometricChecker

    scenario = load_scenario(SCENARIOS / f"{name}.toml")
    steered = oa.steered_coordinates(scenario)
    space, low, high = oa._geometric_space(scenario, steered)
    checker = GeometricChecker(scenario, low, high)
    x, asked = np.array(scenario.start, float), []

    def recording(s):
        q = oa._q_of(scenario, steered, s)
        asked.append(q)
        return checker(q)

    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(recording)
    si.setStateValidityCheckingResolution(oa.GEOMETRIC_RESOLUTION)
    si.setup()
    rng = np.random.default_rng(5)
    index = np.array(steered, np.int64)
    s1, s2 = space.allocState(), space.allocState()
    answers, longest = set(), 0
    for k in range(120):
        a = low[index] + rng.random(len(index)) * (high[index] - low[index])
        b = a + (0.05 if k % 2 else 0.5) * rng.standard_normal(len(index)) * (high[index] - low[index])
        b = np.clip(b, low[index], high[index])
        for i in range(len(index)):
            s1[i], s2[i] = float(a[i]), float(b[i])
        asked.clear()
        expected = si.checkMotion(s1, s2)
        nd = space.validSegmentCount(s1, s2)
        trace = np.full((nd + 1, len(x)), np.nan)
        ok, checks = checker.motion(x, index, a, b, nd, trace)
        assert ok >= 0  # (no pair of these scenes needs python-fcl)
        assert (ok == 1) == expected and checks == len(asked)
        assert np.array_equal(trace[:checks], np.array(asked))
        answers.add(expected)
        longest = max(longest, checks)
    assert answers == {True, False} and longest > 20

    compiled_for = oa._SIMPLE_MOTION_PLANNERS
    paths = []
    try:
        for planners in (compiled_for, ()):  # the compiled motions, then OMPL's validator alone
            oa._SIMPLE_MOTION_PLANNERS = planners
            plans = [oa.plan_geometric(scenario, seed=seed, iterations=2000) for seed in (1, 2, 3, 4)]
            paths.append([(p.states, p.checks, p.status) for p in plans])
    finally:
        oa._SIMPLE_MOTION_PLANNERS = compiled_for
    for (states, checks, status), (states_o, checks_o, status_o) in zip(*paths):
        assert np.array_equal(states, states_o) and checks == checks_o and status == status_o
    assert any(status.name == "EXACT" for _, _, status in paths[0])

    # a motion through a pair only python-fcl measures (-1) goes to OMPL's own validator: the same plans
    motion = GeometricChecker.motion
    try:
        GeometricChecker.motion = lambda self, *args, **kwargs: (-1, 1)
        plans = [oa.plan_geometric(scenario, seed=seed, iterations=2000) for seed in (1, 2)]
    finally:
        GeometricChecker.motion = motion
    for p, (states_o, checks_o, status_o) in zip(plans, paths[1]):
        assert np.array_equal(p.states, states_o) and p.checks == checks_o and p.status == status_o


def test_every_planner_a_scenario_may_name_exists_and_the_geometric_ones_reach_the_goal_set():
    """The planners the format offers are in OMPL's bindings (geometric ones in ompl.geometric,
    control ones in ompl.control), and each geometric planner, growing toward the projected goal
    states, finds an exact path on the paper's scene (seeds 1-3, 2000 iterations): RRT,
    RRTstar and KPIECE1 exhausted their budgets on every seed while only RRTConnect had goal
    states to grow toward."""
    from ompl import control as oc
    from ompl import geometric as og

    from models.schema import CONTROL_PLANNERS, GEOMETRIC_PLANNERS
    from planner.ompl_adapter import plan_geometric

    assert all(hasattr(og, name) for name in GEOMETRIC_PLANNERS)
    assert all(hasattr(oc, name) for name in CONTROL_PLANNERS)
    scenario = load_scenario(TRIANGLE)
    for name in GEOMETRIC_PLANNERS:
        plans = [plan_geometric(scenario, seed=seed, iterations=2000, planner=name) for seed in (1, 2, 3)]
        assert all(p.exact and p.goal_samples >= 1 for p in plans), name


@pytest.mark.parametrize("planner", ["RRT", "KPIECE1", "EST"])
@pytest.mark.parametrize("rung_name", ["kinematic", "quasistatic-rigid"])
def test_every_control_planner_plans_the_paper_scene(planner, rung_name):
    """Each control planner the format offers finds an exact plan on the paper's scene (seeds
    1-3, 2000 iterations) that ends in the goal when replayed under the rung. EST grows toward
    states from OMPL's valid-state sampler, which never drew a valid one (a drawn state's flag
    is a uniform number): it propagated nothing and failed every search, on every scene."""
    from planner.ompl_adapter import plan_control

    scenario = load_scenario(TRIANGLE, {"v1": 0.8})
    rung = rung_for(scenario, rung_name)
    settings = scenario.rung_settings(rung_name)
    start = rung.initial_state(scenario)
    for seed in (1, 2, 3):
        plan = plan_control(
            scenario, rung, start, h=settings.h, control_period=settings.control_period, seed=seed, iterations=2000, planner=planner
        )
        assert plan.exact and plan.propagations > 0, (seed, plan.status, plan.propagations)
        replay = rung.rollout(scenario, start, plan.controls, plan.durations, settings.h)
        assert replay.ok and replay.outcome == "goal", (seed, replay.outcome)


def test_every_rung_above_the_first_says_why_it_ended():
    """A rung that planned again after the geometric path says so, and that the path did not
    guide it (its reason was empty, and the status's words say "guided by it")."""
    scenario = load_scenario(SCENARIOS / "four_finger_grasp.toml")
    result = run_ladder(scenario, seed=1)
    assert all(r.reason for r in result.rungs[1:]), [(r.rung, r.ended) for r in result.rungs]
    kinematic = next(r for r in result.rungs if r.rung == "kinematic")
    assert kinematic.ended is PlanStatus.REPLANNED
    assert kinematic.reason.endswith("found a plan into the goal set (a geometric path is no guide for physics)")


def test_a_rung_whose_coarse_stage_spent_its_iterations_says_so():
    """A coarse stage that finds no plan may spend all of its rung's iterations; the rung's own
    search then runs none, and its reason says why (it read as an ordinary search that failed)."""
    scenario = load_scenario(SCENARIOS / "four_finger_grasp.toml")
    result = run_ladder(scenario, seed=31, iterations=30, planner="KPIECE1")  # (seed 7 holds: a closer replay goes up)
    stage, top = result.rungs[-2], result.rungs[-1]
    assert stage.stage == "coarse" and not stage.ended.holds
    assert top.rung == stage.rung and top.iterations == 0 and not top.ended.holds
    assert top.reason.endswith(f"(the coarse stage spent the rung's {stage.iterations} iterations)"), top.reason


def test_a_rung_that_cannot_express_the_task_does_not_end_the_ladder():
    """tests/data/strike.toml: the pusher may not pass x = 0, the puck must reach x >= 0.5, so
    only momentum gets it there. The kinematic rung cannot (no inertia: the puck stops with
    the pusher) and fails; the ladder goes on, guided by its best partial plan, and the top
    rung (dynamic-rigid) plans. Seeds 1-5, equal budgets."""
    from pathlib import Path

    from models.scenario import load_scenario
    from planner.ladder import run_ladder

    scenario = load_scenario(Path(__file__).parent / "data" / "strike.toml")
    held = 0
    for seed in range(1, 6):
        result = run_ladder(scenario, seed=seed, time_limit=20.0)
        kinematic = next(r for r in result.rungs if r.rung == "kinematic")
        assert not kinematic.ended.holds and kinematic.outcome != "goal"
        assert "the ladder goes on" in kinematic.reason
        # the top rung may plan at a coarser step first (a coarse stage, `planner.ladder.COARSE_FACTORS`)
        assert [r.rung for r in result.rungs if not r.stage] == ["geometric", "kinematic", "dynamic-rigid"]
        assert all(r.rung == "dynamic-rigid" and r.h > result.rungs[-1].h for r in result.rungs if r.stage)
        held += result.top_holds
    assert held == 5


def test_ompl_states_read_back_what_was_written_by_either_path():
    """The control layout writes a flattened rung state through the space in one call and
    reads it back through the components' wrappers, or by address where a wrapper comes back
    as another type: both give every entry back exactly (steered coordinates first)."""
    from ompl import base as ob

    from planner.ompl_adapter import _control_state_space, _ControlLayout

    scenario = load_scenario(SCENARIOS / "box_rotate_3d.toml")
    rung = rung_for(scenario, "quasistatic-rigid")
    start = rung.initial_state(scenario)
    layout = _ControlLayout(scenario, start)
    space, _ = _control_state_space(ob, layout, scenario, start)
    state = space.allocState()
    x = np.random.default_rng(3).normal(size=layout.n_flat)
    layout.write(state, x)
    assert np.array_equal(layout.read(state), x)
    assert np.array_equal(layout.read_by_address(state), x)
    assert layout.flag(state) == x[-1]
    assert [state[0][k] for k in range(layout.ns)] == x[layout.steered].tolist()


def test_a_rungs_report_says_how_much_of_its_wall_time_went_to_compiling():
    """`compile_s`: the part of a rung's wall_s spent in numba's compiler (a fresh clone's first
    plan compiles the kernels inside whichever rung calls them first); plan.json has neither."""
    import time

    import numba

    from planner.ladder import RungReport, _Step, rung_json

    step = _Step(*[None] * 9, t0=time.perf_counter())
    increment = numba.njit(lambda x: x + 1)  # a function nothing has compiled
    assert increment(1) == 2
    spent = step.spent()
    assert 0.0 < spent["compile_s"] <= spent["wall_s"]
    warm = _Step(*[None] * 9, t0=time.perf_counter())
    assert increment(2) == 3
    assert warm.spent()["compile_s"] == 0.0
    report = RungReport("kinematic", PlanStatus.EXACT, **spent)
    assert rung_json(report)["compile_s"] == spent["compile_s"]
    assert "compile_s" not in rung_json(report, timings=False)


def test_the_geometric_rungs_iterations_count_against_the_ladders_budget():
    """The geometric search spends iterations (no propagations), and the whole ladder never
    spends more than --flat gets (the rungs' budgets summed). A report built by position once
    put the geometric iterations under propagations, and the next rung spent them again."""
    scenario = load_scenario(SCENARIOS / "free_transfer.toml")
    result = run_ladder(scenario, seed=1, iterations=200)
    geometric = result.rungs[0]
    assert geometric.rung == "geometric" and geometric.propagations == 0 and geometric.iterations > 0
    assert isinstance(geometric.compile_s, float)
    assert sum(r.iterations for r in result.rungs) <= 200 * len(result.rungs)


def test_a_search_keeps_its_plans_within_the_tasks_horizon():
    """`[task] horizon` is the longest plan: a control that would end past it makes an invalid
    state (`planner.ompl_adapter._Propagator`). The times are kept outside OMPL's state, so a
    horizon that never binds plans exactly what no horizon plans (the same random stream)."""
    from planner.ompl_adapter import plan_control

    scenario = load_scenario(TRIANGLE, {"v1": 0.8})
    rung = rung_for(scenario, "kinematic")
    settings = scenario.rung_settings("kinematic")
    start = rung.initial_state(scenario)

    def plan(seed, **kwargs):
        return plan_control(
            scenario, rung, start, h=settings.h, control_period=settings.control_period, seed=seed, iterations=2000, **kwargs
        )

    for seed in (1, 2):
        free, loose = plan(seed), plan(seed, horizon=1e6)
        assert free.exact and loose.exact and loose.past_horizon == 0
        assert np.array_equal(free.controls, loose.controls) and np.array_equal(free.durations, loose.durations)
        # the fingers need 0.74 s at full speed (2 m/s) to close on the triangle: 1.2 s binds some branches
        tight = plan(seed, horizon=1.2)
        assert tight.exact and tight.past_horizon > 0
        # it reaches the goal within the horizon (its last control runs on past the goal, where a rollout stops)
        run = rung.rollout(scenario, start, tight.controls, tight.durations, settings.h)
        assert run.outcome == "goal" and run.t <= 1.2 + 1e-9 and sum(tight.durations[:-1]) < 1.2, (seed, run.t)
    # too short for any plan: every propagation ends past it
    short = plan(1, horizon=0.3)
    assert not short.exact and short.past_horizon > 0 and sum(short.durations) <= 0.3 + 1e-9  # (its closest path)
    # a root already at the horizon (a state along an earlier plan) makes nothing valid
    late = plan(1, horizon=4.0, start_times=[4.0])
    assert not late.exact and 0 < late.past_horizon <= late.propagations


def test_a_plan_longer_than_the_horizon_does_not_hold(tmp_path):
    """A plan that reaches the goal but lasts longer than `[task] horizon` is not accepted: the
    rung ends PAST_HORIZON (a geometric path, a replayed or tracked plan) or its search finds none
    within it, the reason says so, and the top rung does not hold. It had been ignored: plans
    of 16.6 s were accepted for a horizon of 10 s. free_transfer's seed 1 path detours round the
    obstacle: 2.6 s, where its goal state is 2.2 s away (in reach: `GoalSampler.in_reach`)."""
    text = (SCENARIOS / "free_transfer.toml").read_text()
    assert "horizon = 10.0" in text
    path = tmp_path / "short.toml"
    path.write_text(text.replace("horizon = 10.0", "horizon = 2.2"))
    result = run_ladder(load_scenario(path), seed=1, iterations=400, time_limit=600.0)
    geometric, kinematic = result.rungs
    assert geometric.ended is PlanStatus.PAST_HORIZON and geometric.ended.label == "failed" and geometric.outcome == "goal"
    assert sum(geometric.durations) == pytest.approx(2.6) and geometric.reason == (
        f"{PlanStatus.PAST_HORIZON.message}: it reaches the goal at t = 2.6 s (the task's horizon, 2.2 s)"
    )
    assert not kinematic.ended.holds and "would have ended past the task's horizon (the task's horizon, 2.2 s)" in kinematic.reason
    assert not result.top_holds and result.to_json()["top_holds"] is False
    # both read `failed`; plan.json's `cause` tells them apart without the reason's words
    assert [(r["ended"], r["cause"]) for r in result.to_json()["rungs"]] == [("failed", "past_horizon"), ("failed", "budget_exhausted")]
    # the paper's scene at its own horizon: the ladder holds, and its plan reaches the goal within it
    scenario = load_scenario(TRIANGLE, {"v1": 0.8})
    held = run_ladder(scenario, rungs=["geometric", "kinematic"], seed=1, iterations=400, time_limit=600.0)
    assert held.top_holds and sum(held.rungs[0].durations) <= 4.0  # a geometric path ends at the goal
    top = held.rungs[-1]  # (a search's last control may run on past the goal: its rollout stops there)
    kinematic = rung_for(scenario, "kinematic")
    run = kinematic.rollout(
        scenario, kinematic.initial_state(scenario), np.array(top.controls), np.array(top.durations), scenario.rung_settings("kinematic").h
    )
    assert run.outcome == "goal" and run.t <= 4.0


def triangle_with_horizon(tmp_path, horizon: float):
    text = TRIANGLE.read_text()
    assert "horizon = 4.0" in text
    path = tmp_path / f"horizon_{horizon}.toml"
    path.write_text(text.replace("horizon = 4.0", f"horizon = {horizon}"))
    return load_scenario(path)


def geometric_time(scenario, states) -> float:
    """How long the geometric rung's controls take along a path (`planner.ladder._geometric`)."""
    from planner.ompl_adapter import segment_periods

    index = [scenario.coordinates.index(n) for n in scenario.actuated]
    period = scenario.rung_settings("geometric").control_period
    return period * sum(segment_periods(b[index] - a[index], scenario.max_speeds, period) for a, b in zip(states[:-1], states[1:]))


def test_the_geometric_rung_roots_its_goal_tree_only_at_goal_states_in_reach_by_the_horizon(tmp_path):
    """The fingers close on the triangle in 0.74 s at full speed (2 m/s). At a horizon of 0.8 s
    the geometric rung's goal states had been drawn anywhere in the goal set: seed 1's path went
    straight to a grasp low on the triangle's side, 0.95 s away, and the scene failed at every
    seed. A goal state the actuators cannot reach by the horizon, straight at their max speeds as
    the rung times a path, is dropped (`GoalSampler.in_reach`). Where the horizon binds nothing
    the geometric plans are the ones it made without the check (the same random stream)."""
    from planner.ompl_adapter import plan_geometric

    own, loose, tight = load_scenario(TRIANGLE), triangle_with_horizon(tmp_path, 1e6), triangle_with_horizon(tmp_path, 0.8)
    assert geometric_time(own, plan_geometric(own, seed=1, iterations=2000).states) == pytest.approx(0.95)
    late = 0
    for seed in (1, 2, 3, 4):
        path, unbound = plan_geometric(own, seed=seed, iterations=2000), plan_geometric(loose, seed=seed, iterations=2000)
        assert path.exact and path.late_goals == 0 and np.array_equal(path.states, unbound.states)
        short = plan_geometric(tight, seed=seed, iterations=2000)
        assert short.exact and geometric_time(tight, short.states) <= 0.8 + 1e-9, seed
        late += short.late_goals
    assert late > 0  # (goal states were drawn out of reach, and dropped)
    result = run_ladder(tight, seed=1)
    assert result.top_holds and result.rungs[0].ended is PlanStatus.EXACT


def test_a_failed_search_passes_up_the_previous_plans_replay_where_it_ends_closer_to_the_goal(tmp_path):
    """At a horizon of 0.76 s (full speed grasps at 0.74 s) seed 1's kinematic search finds no
    plan in time; the geometric plan's replay under the rung ends on the goal set's edge
    (3e-11 m out), where the search's closest path ends 0.85 m away. The replay had been dropped
    for it, and every rung above failed; passed up, it holds above, within the horizon."""
    from planner.ladder import _closer_partial, _Replay

    scenario = triangle_with_horizon(tmp_path, 0.76)
    result = run_ladder(scenario, seed=1)
    kinematic, top = result.rungs[1], result.rungs[-1]
    assert kinematic.rung == "kinematic" and not kinematic.ended.holds and kinematic.goal_distance < 1e-9
    assert (
        "the previous plan's replay, " in kinematic.reason
        and "is the partial plan passed up (the search's closest path ends 0.8" in kinematic.reason
    )
    assert result.top_holds and top.ended.holds
    rung = rung_for(scenario, top.rung)
    run = rung.rollout(scenario, rung.initial_state(scenario), np.array(top.controls), np.array(top.durations), top.h)
    assert run.outcome == "goal" and run.t <= 0.76 + 1e-9
    # at 0.5 s (no grasp in reach) only the replay's controls within the horizon go up: the
    # geometric path's 25 controls (1.25 s) had; a tracked run is named as one
    short = run_ladder(triangle_with_horizon(tmp_path, 0.5), seed=1)
    for report in short.rungs[1:]:
        assert not report.ended.holds and len(report.controls) == 10 and sum(report.durations) == pytest.approx(0.5), report.label
        assert "(its first 10 controls, those within the task's horizon, 0.5 s)" in report.reason
    assert "the previous plan's tracked run (its first 10" in short.rungs[-1].reason
    # the table's `tracked` column of a failed rung is the tracking before its search: its reason says so
    top = short.rungs[-1]
    assert top.tracked is not None
    assert f"before the search, tracked {top.tracked:.0%} of the previous plan's duration (a partial plan" in top.reason
    # a replay that reached the goal (late), ended unsafe or failed is not passed up
    for outcome, status in (("goal", "ok"), ("unsafe", "ok"), ("none", "lcp_failed")):
        replay = _Replay(None, controls=[[0.0, 0.0]], durations=[0.05], outcome=outcome, status=status)
        assert _closer_partial(None, replay, {"goal_distance": 1.0}) is None


def test_a_lost_push_passes_up_its_tracked_run_where_it_ends_closer_to_the_goal():
    """tests/data/push_past_post.toml, seed 9: the quasistatic rung loses the push along the
    geometric plan's object path at 6.9 s, and with 50 iterations a rung its search finds no plan
    (with the scenario's budget a local repair finds one in 721 propagations). The partial plan
    passed up had been the geometric plan's replay under the rung, whose robot pushes nothing
    along (0.48 m from the goal); it is now the push's tracked run, which took the box further."""
    from pathlib import Path

    from models.task import goal_distance

    scenario = load_scenario(Path(__file__).parent / "data" / "push_past_post.toml")
    result = run_ladder(scenario, seed=9, rungs=["geometric", "quasistatic-rigid"], iterations=50)
    geometric, quasi = result.rungs[0], result.rungs[-1]
    assert not quasi.ended.holds and quasi.tracked == pytest.approx(0.64, abs=0.01)
    said = f"the push along the geometric plan's object path, its tracked run, {quasi.goal_distance:.3g} m from the goal"
    assert f"{said}, is the partial plan passed up" in quasi.reason and "lost at 6.9 s" in quasi.reason, quasi.reason
    rung = rung_for(scenario, quasi.rung)
    start = rung.initial_state(scenario)
    run = rung.rollout(scenario, start, np.array(quasi.controls), np.array(quasi.durations), quasi.h)  # the controls passed up
    assert run.outcome == "none" and run.status == "ok"
    assert goal_distance(scenario, run.state.q) == pytest.approx(quasi.goal_distance, abs=1e-9)
    assert quasi.states[-1] == pytest.approx(run.state.q.tolist(), abs=1e-12) and sum(quasi.durations) <= 12.0
    replay = rung.rollout(scenario, start, np.array(geometric.controls), np.array(geometric.durations), quasi.h)
    assert goal_distance(scenario, replay.state.q) > quasi.goal_distance + 0.1  # what had been passed up


def test_the_partial_plan_passed_up_is_the_run_that_ends_closest_to_the_goal(tmp_path):
    """`_closer_partial` with a lost push beside the previous plan's replay: the closer of the two,
    if closer than the search's; a push's run is named as one."""
    from types import SimpleNamespace

    from models.task import goal_distance
    from planner.ladder import _closer_partial, _Replay, _replay_controls
    from planner.tracking import Tracked

    scenario = triangle_with_horizon(tmp_path, 3.0)
    rung = rung_for(scenario, "kinematic")
    start = rung.initial_state(scenario)
    step = SimpleNamespace(scenario=scenario)

    def run_of(speed: float, n: int) -> _Replay:  # the fingers moving at `speed` for n periods of 0.1 s (down: < 0)
        controls = np.full((n, len(scenario.actuated)), speed)
        return _replay_controls(scenario, rung, start, controls, [0.1] * n, 1e-3, _Replay.empty(start))

    def tracked(r: _Replay) -> Tracked:
        return Tracked(start, r.state, list(r.states), list(r.controls), list(r.durations), steps_min_psi=list(r.steps_min_psi))

    short, longer = run_of(-1.0, 2), run_of(-1.0, 4)
    near, far = (goal_distance(scenario, r.state.q) for r in (longer, short))
    assert longer.outcome == short.outcome == "none" and near < far
    words, run = _closer_partial(step, short, {"goal_distance": 10.0}, pushed=tracked(longer))
    assert words.startswith(f"; the push along the geometric plan's object path, its tracked run, {near:.3g} m from the goal")
    assert run.controls == longer.controls
    words, run = _closer_partial(step, longer, {"goal_distance": 10.0}, pushed=tracked(short))
    assert words.startswith(f"; the previous plan's replay, {near:.3g} m from the goal") and run.controls == longer.controls
    assert _closer_partial(step, short, {"goal_distance": near / 2}, pushed=tracked(longer)) is None  # the search's ends closer


def test_a_failed_search_from_a_root_along_the_previous_plan_reports_the_states_of_its_controls(tmp_path):
    """At 0.8 s seed 2's top rung finds no plan in time; its closest path starts at a root part
    way along the previous plan, and the report's controls begin with that plan's prefix. Its
    states had been the tree's path from the root (2 states for 10 controls), which the plot and
    a rung above read against the controls; they are the controls' replay from the start."""
    scenario = triangle_with_horizon(tmp_path, 0.8)
    top = run_ladder(scenario, seed=2).rungs[-1]
    assert not top.ended.holds and len(top.controls) == 10
    assert len(top.states) == len(top.controls) + 1 and top.states[0] == list(scenario.start)  # the start, after each control
    rung = rung_for(scenario, top.rung)
    run = rung.rollout(scenario, rung.initial_state(scenario), np.array(top.controls), np.array(top.durations), top.h)
    assert np.allclose(run.state.q, top.states[-1], atol=1e-12)


def test_a_replays_configurations_are_one_per_control_boundary():
    """The start, after each control that ran on, and the end when a control ended the replay;
    a replay whose every control ran on had listed its last state twice."""
    from types import SimpleNamespace

    from planner.ladder import _Replay

    start, a, b, end = (SimpleNamespace(q=np.array([float(i)])) for i in range(4))
    ran_on = _Replay(b, states=[a, b], controls=[[1.0], [1.0]], durations=[0.1, 0.1], steps_min_psi=[(1.0, 0), (1.0, 0)])
    assert ran_on.configurations(start) == [[0.0], [1.0], [2.0]]
    assert ran_on.head(1).configurations(start) == [[0.0], [1.0]]
    for outcome, status in (("goal", "ok"), ("unsafe", "ok"), ("none", "lcp_failed")):  # the third control ended it
        stopped = _Replay(end, states=[a, b], controls=[[1.0], [1.0]], durations=[0.1, 0.1], outcome=outcome, status=status)
        assert stopped.configurations(start) == [[0.0], [1.0], [2.0], [3.0]]
    assert _Replay.empty(start).configurations(start) == [[0.0]]
    assert _Replay(end, outcome="goal").configurations(start) == [[0.0], [3.0]]  # the first control reached the goal


def test_a_geometric_rung_whose_every_goal_state_is_out_of_reach_says_so(tmp_path):
    """At 0.5 s no grasp is in reach (the fingers need 0.74 s): the rung searches for the goal
    region instead, and its reason says why it had no goal state."""
    from planner.ladder import _geometric

    scenario = triangle_with_horizon(tmp_path, 0.5)
    report = _geometric(scenario, 1, 2000)
    assert report.ended is PlanStatus.APPROXIMATE and report.outcome == "none"  # (the region search does not land in the thin goal set)
    assert re.fullmatch(
        re.escape(f"{PlanStatus.APPROXIMATE.message}; no goal state could be made by projection (")
        + "[1-9][0-9]*"
        + re.escape(
            " made were out of reach: the actuators at their max speeds, in whole control periods, do not get there by "
            "the task's horizon, 0.5 s), so RRT searched for the goal region"
        ),
        report.reason,
    )
    assert not run_ladder(scenario, rungs=["geometric", "kinematic"], seed=1, iterations=400).top_holds


def test_check_says_when_no_goal_state_is_in_reach_of_the_horizon(tmp_path, capsys):
    """`ladder check` draws goal states as the geometric rung does: at 0.5 s every one is out of
    reach (the fingers need 0.74 s, 0.75 s in whole 0.05 s periods) and it says so; at 0.8 s and
    at the file's 4 s it does not (it had been silent at 0.5 s)."""
    from planner.cli import main

    short = triangle_with_horizon(tmp_path, 0.5).path
    assert main(["check", str(short), "--json"]) == 0
    reach = json.loads(capsys.readouterr().out)["task"]["goal_reach"]
    assert reach["in_reach"] is False and reach["late"] > 0 and reach["earliest"] == pytest.approx(0.75)
    assert main(["check", str(short)]) == 0
    said = " ".join(capsys.readouterr().out.split())
    assert f"task.horizon: 0.5 s looks too short for the goal: the {reach['late']} goal states the geometric rung made" in said
    assert "the soonest 0.75 s away (the actuators straight at their max speeds, in whole control periods)" in said
    for path in (triangle_with_horizon(tmp_path, 0.8).path, TRIANGLE):
        assert main(["check", str(path), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["task"]["goal_reach"] == {"in_reach": True, "late": 0, "earliest": None}
        assert main(["check", str(path)]) == 0 and "looks too short" not in capsys.readouterr().out
    from planner import ompl_adapter

    with pytest.MonkeyPatch.context() as patch:  # no goal state made at all: nothing to time, not "out of reach"
        patch.setattr(ompl_adapter.GoalSampler, "draw", lambda self: None)
        assert ompl_adapter.goal_reach(load_scenario(TRIANGLE)) == {"in_reach": None, "late": 0, "earliest": None}
    assert main(["check", str(SCENARIOS / "bouncing_disc.toml"), "--json"]) == 0  # nothing to actuate: no plan, no draw
    assert json.loads(capsys.readouterr().out)["task"]["goal_reach"] is None  # (the key is always there: a trial missed it)


def test_a_horizon_shorter_than_a_control_period_cannot_be_planned(tmp_path, capsys):
    """The planners' controls last whole control periods (0.05 s here), a geometric path's too:
    `ladder plan` refuses a shorter horizon as bad input, and `ladder check` says so.
    It had passed `check`, and every rung spent its budget."""
    from planner.cli import main

    text = TRIANGLE.read_text()
    start = text.index("[expect]")
    path = tmp_path / "short.toml"
    path.write_text(text[:start].replace("horizon = 4.0", "horizon = 0.03"))
    reason = (
        "task.horizon: the task's horizon, 0.03 s, is shorter than one control period (0.05 s, the shortest of the ladder's): "
        "the planners' controls last whole periods, so their plans cannot meet it; lengthen the horizon or shorten ladder.control_period"
    )
    assert main(["check", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["task"]["unplannable"] == [reason]
    assert main(["check", str(path)]) == 0
    assert f"`ladder plan` refuses this scene: {reason}" in " ".join(capsys.readouterr().out.split())
    assert main(["plan", str(path), "--out", str(tmp_path / "p")]) == 2
    assert capsys.readouterr().err == f"error: {path}: {reason}\n" and not (tmp_path / "p").exists()
    path.write_text(text[:start].replace("horizon = 4.0", "horizon = 0.05"))  # one period: a plan may reach the goal by it
    assert main(["check", str(path), "--json"]) == 0 and json.loads(capsys.readouterr().out)["task"]["unplannable"] == []
    with pytest.raises(ScenarioError, match=r"expect.plan: .* leave plan out \(task.horizon: the task's horizon, 0.03 s, is shorter"):
        _load_text(tmp_path, text.replace("horizon = 4.0", "horizon = 0.03"))  # ([expect] plan = true: the file's own problem)


def _load_text(tmp_path, text):
    path = tmp_path / "with_expect.toml"
    path.write_text(text)
    return load_scenario(path)


def test_a_control_that_moves_nothing_does_not_make_its_state_later():
    """A control that presses the fingers into their upper limits (the start) makes a state with
    the start's exact values; the propagator keys times by those values, so that state kept the
    later time and held the start, still in the tree, to it (a 9-period control moved the start
    from 0 to 0.45 s, and every expansion from it was judged later). The earliest time is kept."""
    from ompl import base as ob

    from planner.ompl_adapter import _control_state_space, _ControlLayout, _Limits, _Propagator, flatten

    scenario = load_scenario(TRIANGLE, {"v1": 0.8})
    rung = rung_for(scenario, "kinematic")
    settings = scenario.rung_settings("kinematic")
    start = rung.initial_state(scenario)
    layout = _ControlLayout(scenario, start)
    limits = _Limits(scenario, start, settings.control_period)
    space, _projection = _control_state_space(ob, layout, scenario, start)
    propagate = _Propagator(scenario, rung, layout, limits, settings.h, horizon=1.0)
    root, result = space.allocState(), space.allocState()
    layout.write(root, flatten(start))
    x0 = layout.read(root)
    propagate.at(x0, 0.0)
    for _ in range(9):  # up, into the limits: nothing moves
        propagate(root, [0.4, 0.4], settings.control_period, result)
        assert layout.read(result).tobytes() == x0.tobytes()
    assert propagate.times[x0.tobytes()] == 0.0
    propagate(root, [-1.0, -1.0], settings.control_period, result)  # down: a new state, one period on
    y = layout.read(result)
    assert y.tobytes() != x0.tobytes() and propagate.times[y.tobytes()] == settings.control_period and y[-1] == 0.0
    assert propagate.past_horizon == 0 and propagate.untimed == 0


def test_a_plans_goal_time_is_infinite_where_its_rollout_does_not_reach_the_goal():
    """`_goal_time` replays a plan whose durations pass the horizon to find when it reaches the
    goal; a rollout that ends elsewhere (unsafe, a solver failure, or nowhere) is no time within it."""
    from planner.ladder import _Budget, _goal_time, _in_time, _Step

    scenario = load_scenario(TRIANGLE, {"v1": 0.8})
    rung = rung_for(scenario, "kinematic")
    step = _Step(scenario, "kinematic", rung, scenario.rung_settings("kinematic"), 1, 0, 0, _Budget(), None, 0.0)

    class Plan:
        controls, durations = [[0.0, 0.0]] * 100, [0.05] * 100  # 5 s of nothing: past the 4 s horizon, never the goal

    assert _goal_time(step, Plan) == float("inf") and not _in_time(step, Plan)

    class Short:
        controls, durations = [[0.0, 0.0]] * 10, [0.05] * 10

    assert _goal_time(step, Short) == 0.5 and _in_time(step, Short)  # within the horizon: its durations' sum, no replay


def test_a_previous_plan_refused_for_reaching_the_goal_late_says_so(tmp_path):
    """At a horizon of 0.9 s (seed 2) the rungs below plan a grasp at 0.9 s that the dynamic rung,
    tracking it, reaches at 0.909 s: refused, and a search from the tracked states plans within
    it. The reason had said tracking was lost (it tracked 100%), and nothing of the horizon."""
    path = tmp_path / "short.toml"
    path.write_text(TRIANGLE.read_text().replace("horizon = 4.0", "horizon = 0.9"))
    scenario = load_scenario(path, {"v1": 0.8})
    result = run_ladder(scenario, seed=2, time_limit=600.0)
    top = result.rungs[-1]
    assert result.top_holds and top.ended is PlanStatus.REPAIRED, (top.ended, top.reason)
    assert top.reason.startswith("the previous plan reaches the goal later than the task's horizon allows (0.9 s; tracked 100%")
    assert "a search from tracked state" in top.reason and "lost" not in top.reason
    rung = rung_for(scenario, top.rung)
    run = rung.rollout(scenario, rung.initial_state(scenario), np.array(top.controls), np.array(top.durations), top.h)
    assert run.outcome == "goal" and run.t <= 0.9 + 1e-9


def test_a_coarse_replan_starts_where_the_horizon_leaves_it_time(monkeypatch):
    """tests/data/push_past_post.toml, seed 7: the coarse stage's plan reaches the goal at 11.0 s
    (horizon 12 s). Tracked at the rung's own step it ran on to 12.0 s and ended 2.6 mm outside
    the goal set; the coarse re-plan from there had no time left, spent the rung's 7,994
    iterations in vain, and the search at the rung's own step had none left: the top rung
    failed. The re-plan now starts SEARCH_TIME before the horizon, and the top rung holds."""
    from pathlib import Path

    import planner.pushing
    from planner.ladder import SEARCH_TIME

    scenario = load_scenario(Path(__file__).parent / "data" / "push_past_post.toml")
    # the push along the geometric path as it was (a diagonal push: `pushable_path` now makes
    # it legs along the box's faces, and seed 7 then holds with no coarse re-plan)
    monkeypatch.setattr(planner.pushing, "pushable_path", lambda *args: None)
    result = run_ladder(scenario, seed=7)
    stage, top = result.rungs[-2], result.rungs[-1]
    assert stage.stage == "coarse" and stage.ended is PlanStatus.TRACKED and sum(stage.durations) > 12.0 - SEARCH_TIME
    assert result.top_holds and top.ended is PlanStatus.REPAIRED, top.reason
    assert top.iterations < 2000 and sum(top.durations) <= 12.0 + 1e-9
    rung = rung_for(scenario, top.rung)
    run = rung.rollout(scenario, rung.initial_state(scenario), np.array(top.controls), np.array(top.durations), top.h)
    assert run.outcome == "goal" and run.status == "ok"


def test_coarse_rounds_leave_the_rungs_own_search_half_its_budget():
    """box_push_3d, seed 5: the top rung lost its coarse stage's plan at 2.6 s; a coarse re-plan
    from there was lost again in its first period, yet the rounds went on re-planning at the
    coarse step and spent all 7,584 iterations, and the search at the rung's own step had none:
    the top rung failed. The rounds now stop at a plan lost in its first period and spend at most
    COARSE_SHARE of the budget, and the rung's own search finds the plan."""
    from planner.ladder import COARSE_SHARE

    scenario = load_scenario(SCENARIOS / "box_push_3d.toml")
    result = run_ladder(scenario, seed=5)
    stage, top = result.rungs[-2], result.rungs[-1]
    assert stage.stage == "coarse" and stage.ended.holds
    assert result.top_holds and top.ended is PlanStatus.REPAIRED, top.reason
    assert COARSE_SHARE == 0.5 and "then a search from tracked state" in top.reason
    rung = rung_for(scenario, top.rung)
    run = rung.rollout(scenario, rung.initial_state(scenario), np.array(top.controls), np.array(top.durations), top.h)
    assert run.outcome == "goal" and run.status == "ok"


def test_time_left_for_search_keeps_the_controls_that_end_before_the_horizon_less_search_time(tmp_path):
    from types import SimpleNamespace

    from planner.ladder import SEARCH_SHARE, SEARCH_TIME, _time_left_for_search
    from planner.tracking import Tracked

    run = Tracked(SimpleNamespace(), durations=[0.5] * 25, controls=[[0.0]] * 25)  # 12.5 s
    scenario = triangle_with_horizon(tmp_path, 12.0)
    assert SEARCH_TIME == 2.0 and _time_left_for_search(scenario, run, 0) == 20  # ends at 10 s, 2 s before
    assert _time_left_for_search(scenario, run, 22) == 22  # not into the rounds before
    assert _time_left_for_search(triangle_with_horizon(tmp_path, 30.0), run, 0) == 25  # time left: all kept
    # a short horizon: a share of it (the paper's scene at 0.8 s: 0.2 s before)
    short = Tracked(SimpleNamespace(), durations=[0.1] * 8, controls=[[0.0]] * 8)
    assert SEARCH_SHARE == 0.25 and _time_left_for_search(triangle_with_horizon(tmp_path, 0.8), short, 0) == 6


def test_a_search_with_no_iteration_left_names_the_start_beside_the_partial_plan(tmp_path):
    """A search that ran no iteration (its budget spent before it) has no closest path of its own:
    the partial plan's words had called the start "the search's closest path"."""
    from types import SimpleNamespace

    from planner.ladder import _closer_partial, _Replay, _replay_controls

    scenario = triangle_with_horizon(tmp_path, 3.0)
    rung = rung_for(scenario, "kinematic")
    start = rung.initial_state(scenario)
    controls = np.zeros((2, len(scenario.actuated)))
    replay = _replay_controls(scenario, rung, start, controls, [0.1, 0.1], 1e-3, _Replay.empty(start))
    step = SimpleNamespace(scenario=scenario)
    far = {"goal_distance": 10.0}
    words, _ = _closer_partial(step, replay, far, searched=False)
    assert "(the search had no iteration left to run; the start is 10 m from it)" in words
    words, _ = _closer_partial(step, replay, far)
    assert "(the search's closest path ends 10 m from it)" in words


def test_a_local_repair_searches_within_the_tasks_horizon(tmp_path, monkeypatch):
    """Tracking's local repair searched with no horizon: a repair ending past it only made a
    plan the rung then refused as late. Its search now has the task's horizon and its roots' times."""
    from types import SimpleNamespace

    import planner.tracking as tracking

    scenario = triangle_with_horizon(tmp_path, 3.0)
    rung = rung_for(scenario, "kinematic")
    start = rung.initial_state(scenario)
    seen = {}

    def plan_control(*args, **kwargs):
        seen.update(kwargs, root=args[2])
        return SimpleNamespace(exact=False, propagations=0, iterations=0)

    monkeypatch.setattr(tracking, "plan_control", plan_control)
    na = len(scenario.actuated)
    reference = tracking.Reference(np.array([0.0, 1.0]), np.array([start.q, start.q]), np.zeros((1, na)))
    follower = SimpleNamespace(reference=reference, period=0.1, h=1e-3, error=lambda q, target: 0.0)
    run = tracking.Tracked(start, states=[start] * 4, controls=[[0.0] * na] * 4, durations=[0.1, 0.2, 0.3, 0.4])
    run.diverged_at = 0.5
    assert tracking._repair(scenario, rung, follower, run, start, 1, 1.0, 300, None, None) is None
    assert seen["horizon"] == 3.0
    assert seen["start_times"] == pytest.approx([0.3, 0.6, 1.0])  # the last 3 tracked states: after 2, 3 and 4 controls
    assert len(seen["extra_starts"]) == 2

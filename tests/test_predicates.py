"""Compiled goal/unsafe predicates agree with a direct reading of the scenario's tree."""

from __future__ import annotations

import numpy as np
import pytest

from models import geometry as geo
from models.contact import CONTACT_MARGIN
from models.predicates import compile_predicate, evaluate
from models.scenario import ScenarioError, load_scenario
from models.task import Outcome, classify, goal_distance
from tests.conftest import SCENARIOS


def reference(scenario, node, q):
    kind = type(node).__name__
    if node is None:
        return False
    if kind == "BoxPredicate":
        return all(lo <= q[scenario.coordinates.index(n)] <= hi for n, (lo, hi) in node.box.items())
    if kind == "TouchPredicate":
        a, b = node.touch
        P = scenario.placements(q)
        tol = node.tol if node.tol is not None else scenario.spec.contact.touch_tolerance
        return geo.signed_distance(scenario.geometries[a], P[a], scenario.geometries[b], P[b]) <= tol
    if kind == "AllPredicate":
        return all(reference(scenario, c, q) for c in node.all)
    if kind == "AnyPredicate":
        return any(reference(scenario, c, q) for c in node.any)
    return not reference(scenario, node.not_, q)


def pair_distances(scenario, q):
    P = scenario.placements(q)
    return np.array(
        [
            geo.signed_distance(scenario.geometries[p.body_a], P[p.body_a], scenario.geometries[p.body_b], P[p.body_b])
            for p in scenario.pairs
        ]
    )


@pytest.mark.parametrize("name", ["two_finger_triangle", "four_finger_grasp", "free_transfer"])
def test_compiled_predicates_match_the_tree(name):
    scenario = load_scenario(SCENARIOS / f"{name}.toml")
    task = scenario.spec.task
    goal, unsafe = compile_predicate(scenario, task.goal), compile_predicate(scenario, task.unsafe)
    rng = np.random.default_rng(5)
    hits = {"goal": 0, "unsafe": 0}
    for _ in range(400):
        q = scenario.start + rng.normal(scale=0.6, size=len(scenario.start))
        if name == "two_finger_triangle" and rng.random() < 0.5:
            # fingers resting on the faces: the goal region is reachable
            x = rng.uniform(-0.6, 0.6)
            q = np.array([x, 0.5 - x + 0.05 * np.sqrt(2), 0.5 + x + 0.05 * np.sqrt(2)])
        psi = pair_distances(scenario, q)
        g, u = evaluate(goal, q, psi), evaluate(unsafe, q, psi)
        assert g == reference(scenario, task.goal, q)
        assert u == reference(scenario, task.unsafe, q)
        hits["goal"] += g
        hits["unsafe"] += u
    if name == "two_finger_triangle":
        assert 0 < hits["goal"] < 400 and 0 < hits["unsafe"] < 400  # both branches exercised
    else:
        assert 0 < hits["unsafe"] < 400


def test_missing_unsafe_set_is_never_true():
    scenario = load_scenario(SCENARIOS / "incline_block.toml")
    program = compile_predicate(scenario, None)
    assert not evaluate(program, scenario.start, np.zeros(len(scenario.pairs)))


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("touch_tolerance = 1e-3", f"touch_tolerance = {2 * CONTACT_MARGIN}", "contact.touch_tolerance"),
        (
            '{ touch = ["finger2", "triangle"] }',
            f'{{ touch = ["finger2", "triangle"], tol = {2 * CONTACT_MARGIN} }}',
            "task.goal.all[1].tol",
        ),
    ],
)
def test_a_touch_tolerance_above_the_detection_margin_is_bad_input(tmp_path, old, new, key):
    """Rollouts see a pair only within the contact-detection margin: a wider touch would make
    the compiled goal check disagree with predicate_distance, so the loader refuses it."""
    text = (SCENARIOS / "two_finger_triangle.toml").read_text()
    assert old in text
    path = tmp_path / "wide.toml"
    path.write_text(text.replace(old, new))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert f"{path}: {key}: touch tolerance" in str(err.value) and "margin" in str(err.value)


def test_classify_and_goal_distance_agree():
    """A configuration is classified GOAL exactly where its goal distance is 0 (and it is not unsafe)."""
    scenario = load_scenario(SCENARIOS / "two_finger_triangle.toml")
    rng = np.random.default_rng(3)
    seen = set()
    for _ in range(200):
        x = rng.uniform(-0.7, 0.7)
        q = np.array([x, 0.5 - x + 0.05 * np.sqrt(2), 0.5 + x + 0.05 * np.sqrt(2)]) + rng.normal(scale=2e-3, size=3)
        outcome = classify(scenario, q)
        seen.add(outcome)
        if outcome is not Outcome.UNSAFE:
            assert (outcome is Outcome.GOAL) == (goal_distance(scenario, q) == 0.0)
    assert seen == set(Outcome)

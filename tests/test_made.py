"""`models.rungs.made`: a frozen dataclass made without its `__init__` (`Rung.rollout`'s result,
per call) is the instance `__init__` makes, and a missing or unknown field is refused."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, fields

import numpy as np
import pytest

from models.rollout import RolloutOutput, rollout_bound, rollout_kernel
from models.rungs import RolloutResult, State, _basis_of, compiled, made, policy_controls, rung_for
from models.scenario import load_scenario
from tests.conftest import SCENARIOS


def test_a_rollouts_result_has_every_field_as_its_init_would_set_them():
    box = load_scenario(SCENARIOS / "box_push_3d.toml")
    rung = rung_for(box, "dynamic-rigid")
    h = box.rung_settings("dynamic-rigid").h
    out = rung.rollout(box, rung.initial_state(box), np.zeros((1, len(box.actuated))), [0.05], h)
    assert type(out) is RolloutResult and type(out.state) is State
    for obj in (out, out.state):
        again = type(obj)(**{f.name: getattr(obj, f.name) for f in fields(obj)})
        assert vars(again).keys() == vars(obj).keys()
        for name, value in vars(again).items():
            assert np.array_equal(value, vars(obj)[name]), name
    with pytest.raises(FrozenInstanceError):
        out.steps = 0  # (still frozen)
    assert out.ok and out.steps == 50


def test_a_missing_or_unknown_field_is_refused():
    arrays = {"q": np.zeros(2), "nu": np.zeros(2), "q_ref": np.zeros(0), "delta_n": np.zeros(1), "delta_t": np.zeros((1, 2))}
    assert made(State, arrays | {"lcp_basis": np.zeros((0, 0), np.int8)}).q.shape == (2,)
    with pytest.raises(TypeError, match=r"made\(State\): missing fields \['lcp_basis'\], unknown fields \[\]"):
        made(State, dict(arrays))
    with pytest.raises(TypeError, match=r"unknown fields \['speed'\]"):
        made(State, arrays | {"lcp_basis": None, "speed": 1.0})


def test_a_state_whose_arrays_are_lists_is_refused_by_its_shapes():
    box = load_scenario(SCENARIOS / "box_push_3d.toml")
    rung = rung_for(box, "dynamic-rigid")
    start = rung.initial_state(box)
    listed = State(list(start.q), start.nu, start.q_ref, start.delta_n, start.delta_t)
    with pytest.raises(ValueError, match=r"q None \(expected \(9,\)\)"):
        rung.rollout(box, listed, np.zeros((1, len(box.actuated))), [0.01], 1e-3)


def test_the_kernels_plain_tuple_is_its_named_tuple_in_order():
    """`models.rollout.rollout_bound` returns `RolloutOutput`'s fields as a plain tuple, which
    `Rung.rollout` unpacks by position: the same values, in the named tuple's order, as
    `rollout_kernel`'s own result for the same run; and the records as `Rung.rollout` gives them."""
    box = load_scenario(SCENARIOS / "box_push_3d.toml")
    rung = rung_for(box, "dynamic-rigid")
    h = box.rung_settings("dynamic-rigid").h
    c, state = compiled(box), rung.initial_state(box)
    assert not c.scripted
    u, _ = policy_controls(box)

    def arguments():
        arrays = (state.q, state.nu, state.q_ref, state.delta_n, state.delta_t)
        return (*(a.copy() for a in arrays), _basis_of(state), np.array(u[:1], dtype=float), np.array([0.3]), h, 1, 2000, True, 0.0)

    plain = rollout_bound(rung._bound(c, False), *arguments())
    named = rollout_kernel(c.scene, c.drives, rung.model, rung.solver, c.goal, c.unsafe, *arguments())
    assert type(plain) is tuple and len(plain) == len(RolloutOutput._fields) == len(named)
    for name, a, b in zip(RolloutOutput._fields, plain, named):
        assert np.array_equal(a, b), name
    out = rung.rollout(box, state, u[:1], [0.3], h)
    assert out.steps == named.steps == 300 and len(out.trajectory) == 301
    assert np.array_equal(out.trajectory, named.trajectory) and np.array_equal(out.state.q, named.q)

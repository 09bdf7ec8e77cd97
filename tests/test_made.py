"""`models.rungs.made`: a frozen dataclass made without its `__init__` (`Rung.rollout`'s result,
per call) is the instance `__init__` makes, and a missing or unknown field is refused."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, fields

import numpy as np
import pytest

from models.rungs import RolloutResult, State, made, rung_for
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
    assert made(State, **arrays, lcp_basis=np.zeros((0, 0), np.int8)).q.shape == (2,)
    with pytest.raises(TypeError, match=r"made\(State\): missing fields \['lcp_basis'\], unknown fields \[\]"):
        made(State, **arrays)
    with pytest.raises(TypeError, match=r"unknown fields \['speed'\]"):
        made(State, **arrays, lcp_basis=None, speed=1.0)


def test_a_state_whose_arrays_are_lists_is_refused_by_its_shapes():
    box = load_scenario(SCENARIOS / "box_push_3d.toml")
    rung = rung_for(box, "dynamic-rigid")
    start = rung.initial_state(box)
    listed = State(list(start.q), start.nu, start.q_ref, start.delta_n, start.delta_t)
    with pytest.raises(ValueError, match=r"q None \(expected \(9,\)\)"):
        rung.rollout(box, listed, np.zeros((1, len(box.actuated))), [0.01], 1e-3)

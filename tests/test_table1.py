"""Table 1 in numbers (planner.table1): each reduction's distance shrinks toward its limit.

Short cheap sequences (three scales); every assertion is about a measured distance or rate.
"""

from __future__ import annotations

import math

import pytest

from models.scenario import load_scenario
from planner import table1

SHORT = (1.0, 1e-1, 1e-2)


@pytest.mark.parametrize("row", table1.ROWS, ids=lambda r: f"{r.source}->{r.limit}")
def test_definition2_distance_shrinks_monotonically_with_a_positive_rate(row):
    c = table1.definition2_row(row, SHORT)
    assert c.statuses == ("ok",) * len(SHORT)
    assert c.monotone, c.distances
    assert c.rate > 0.3, c.rate
    assert c.distances[-1] < 1e-2  # within 1 cm of the limit model at s = 0.01


def test_stiffening_is_first_order_in_the_compliance():
    """K, C -> infinity together: the compliance 1 / (h (h K + C)) is O(s), so is the distance."""
    c = table1.definition2_row(table1.ROWS[0], SHORT)
    assert c.rate == pytest.approx(1.0, abs=0.1)


def test_definition1_same_input_stays_within_the_drives_sag_until_the_outcome():
    check = table1.definition1_input(1.0)
    assert check.outcome == "goal"
    scene = load_scenario(table1.SCENE)
    sag = scene.parameters["finger_mass"] * abs(scene.spec.scene.gravity[1]) / scene.parameters["finger_kp"]
    assert check.until_outcome == pytest.approx(sag, rel=0.01)
    assert check.best_other is None  # the same input sufficed


def test_definition1_residual_vanishes_as_the_drives_stiffen():
    c = table1.drive_row((1.0, 1e-1, 1e-2))
    assert c.monotone, c.distances
    assert c.rate == pytest.approx(1.0, abs=0.05)


def test_fitted_rate_of_a_power_law_and_of_too_few_points():
    assert table1.fitted_rate([1.0, 0.1, 0.01], [3.0, 0.03, 3e-4]) == pytest.approx(2.0)
    assert math.isnan(table1.fitted_rate([1.0, 0.1], [1.0, math.nan]))


def test_trajectory_distance_refuses_runs_recorded_at_different_times():
    a = table1._rollout("quasistatic-rigid", {}, [[-1.0, -1.0]], 0.1, 1e-3)
    b = table1._rollout("quasistatic-rigid", {}, [[-1.0, -1.0]], 0.1, 1e-4)
    with pytest.raises(ValueError, match="same times"):
        table1.trajectory_distance(a, b)
    assert table1.trajectory_distance(a, a) == 0.0

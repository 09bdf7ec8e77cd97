"""A quasistatic run that moves a body nothing holds says so (`models.rungs.unbalanced_motion`).

The quasistatic step is memoryless, eps M nu = h (forces): a body left unbalanced moves at
h F / (eps m), as fast as the inertia scale eps is small. A block on an incline it slides down
is the closed form: the unbalanced share of its weight is sin(alpha) - mu cos(alpha).
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from models.rungs import UNBALANCED_SHARE, policy_controls, run_warnings, rung_for, unbalanced_motion
from models.scenario import load_scenario
from tests.conftest import SCENARIOS

INCLINE = SCENARIOS / "incline_block.toml"
SLOPE = math.radians(30.0)


def incline_run(mu: float, name: str = "quasistatic-rigid", *, inertia: float | None = None, records: int = 2000):
    scenario = load_scenario(INCLINE, {"mu": mu})
    rung = rung_for(scenario, name)
    if inertia is not None:
        rung = replace(rung, model=rung.model._replace(quasistatic_inertia=inertia))
    controls, durations = policy_controls(scenario, 1.0)
    out = rung.rollout(scenario, rung.initial_state(scenario), controls, durations, 1e-3, stop_at_outcome=False, max_records=records)
    return scenario, rung, out


@pytest.mark.parametrize("mu", [0.0, 0.2, 0.5, 0.57])
@pytest.mark.parametrize("records", [2000, 2])
def test_a_sliding_block_leaves_the_closed_form_share_of_its_weight_unbalanced(mu, records):
    """Measured at every step, or (two records, as a sweep keeps) as the run's average speed."""
    scenario, rung, out = incline_run(mu, records=records)
    found = unbalanced_motion(scenario, rung, 1e-3, out)
    share = math.sin(SLOPE) - mu * math.cos(SLOPE)
    assert out.status == "ok" and found is not None and found.body == "block"
    assert found.share == pytest.approx(share, rel=1e-9)
    assert found.speed == pytest.approx(share * 9.81 * 1e-3 / 1e-6, rel=1e-9)  # h F / (eps m)
    assert found.driven == 0.0 and out.steps == 1000  # (nothing actuated)


def test_a_held_block_and_the_other_rungs_say_nothing():
    """mu = 0.7 > tan 30 holds the block; dynamic and kinematic rungs model no equilibrium; a
    quasi-dynamic rung (the bodies' full inertia, eps * steps >= 1) moves an unbalanced body no
    faster than the real inertia would."""
    scenario, rung, out = incline_run(0.7)
    assert np.abs(out.trajectory[-1] - out.trajectory[0]).max() < 1e-9
    assert unbalanced_motion(scenario, rung, 1e-3, out) is None
    for name in ("dynamic-rigid", "kinematic"):
        scenario, rung, out = incline_run(0.0, name)
        assert unbalanced_motion(scenario, rung, 1e-3, out) is None
    scenario, rung, out = incline_run(0.0, inertia=1.0)
    assert out.trajectory[-1][0] - out.trajectory[0][0] < -4e-3  # it slides, at h g sin(alpha) per step: slower than the real block
    assert unbalanced_motion(scenario, rung, 1e-3, out) is None


def test_a_disc_that_falls_onto_the_floor_within_a_step_was_unbalanced():
    """From 0.15 m the quasistatic step drops the disc 5 cm onto the floor in 1 ms: the floor
    cut the step, so the share is a lower bound, but nothing held the disc on the way."""
    scenario = load_scenario(SCENARIOS / "bouncing_disc.toml", {"drop": 0.15})
    rung = rung_for(scenario, "quasistatic-rigid")
    controls, durations = policy_controls(scenario, 0.1)
    out = rung.rollout(scenario, rung.initial_state(scenario), controls, durations, 1e-3)
    found = unbalanced_motion(scenario, rung, 1e-3, out)
    assert out.steps == 1 and found is not None and found.body == "disc"
    assert found.speed == pytest.approx(50.0, rel=1e-6) and 0.0 < found.share < 1.0


def test_a_pushed_body_at_a_small_step_is_driven_not_unbalanced():
    """The paper's scene at h = 1e-5: the fingers push the triangle at their own speed, and the
    step's inertia term is 1% of its weight (eps v / (h g)): the triangle is driven."""
    scenario = load_scenario(SCENARIOS / "two_finger_triangle.toml", {"v1": 0.8})
    rung = rung_for(scenario, "quasistatic-rigid")
    controls, durations = policy_controls(scenario, 1.6)
    out = rung.rollout(scenario, rung.initial_state(scenario), controls, durations, 1e-5, laws=True)
    moved = np.abs(np.diff(out.trajectory[:, 0])).sum()
    assert out.status == "ok" and moved > 0.05  # the triangle was pushed
    assert eps_share(out) > 1e-3 and unbalanced_motion(scenario, rung, 1e-5, out) is None


def eps_share(out) -> float:
    """The triangle's largest eps v / (h g) at the recorded steps, at h = 1e-5."""
    return 1e-6 * float(np.max(np.abs(out.velocities[:, 0]))) / (1e-5 * 9.81)


def test_a_pushed_box_is_far_below_the_share():
    """box_push_3d's straight push at the default inertia scale: the pusher balances the box's
    friction; the step's own inertia term is 2e-6 of its weight, and the box moves as the pusher."""
    scenario = load_scenario(SCENARIOS / "box_push_3d.toml")
    rung = rung_for(scenario, "quasistatic-rigid")
    rung = replace(rung, model=rung.model._replace(quasistatic_inertia=1e-6))
    controls, durations = policy_controls(scenario, 3.0)
    out = rung.rollout(scenario, rung.initial_state(scenario), controls, durations, 1e-2, laws=True)
    assert out.status == "ok" and out.trajectory[-1][0] - out.trajectory[0][0] > 0.1  # the box moved
    assert unbalanced_motion(scenario, rung, 1e-2, out) is None
    assert UNBALANCED_SHARE == 1e-4


def test_simulate_sweep_and_plan_report_it(tmp_path, capsys):
    from planner.cli import _write_plan_outputs, main
    from planner.ladder import LadderResult, RungReport
    from planner.plan_status import PlanStatus

    incline = str(INCLINE)
    assert main(["simulate", incline, "--model", "quasistatic-rigid", "--param", "mu=0", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["status"] == "ok" and len(summary["warnings"]) == 1
    assert summary["warnings"][0].startswith(
        "block was not held in equilibrium: quasistatic steps moved it at up to 4.9e+03 m/s (with nothing actuated or scripted moving)"
    )
    assert "leaves at least 50% of its weight unbalanced" in summary["warnings"][0]
    assert main(["simulate", incline, "--model", "quasistatic-rigid", "--param", "mu=0.7", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["warnings"] == []

    args = ["sweep", incline, "--grid", "mu=0,0.7", "--model", "quasistatic-rigid", "--workers", "1", "--out", str(tmp_path / "s")]
    assert main(args) == 0
    assert "1 run is not physical, whatever the outcome" in " ".join(capsys.readouterr().out.split())
    points = {p["parameters"]["mu"]: p for p in json.loads((tmp_path / "s" / "sweep.json").read_text())["points"]}
    assert points[0.0]["warnings"][0].startswith("block was not held") and points[0.7]["warnings"] == []
    rows = [line.split(",") for line in (tmp_path / "s" / "sweep.csv").read_text().splitlines()]
    column = rows[0].index("warnings")
    assert {float(r[1]): r[column] for r in rows[1:]} == {0.0: "1", 0.7: "0"}  # (sweep.csv counts them)

    # a plan's rung is replayed for its plot, and report.json gives what the replay says
    scenario = load_scenario(INCLINE, {"mu": 0.0})
    rung_report = RungReport("quasistatic-rigid", PlanStatus.EXACT, outcome="goal", h=1e-3, controls=[[]], durations=[0.5])
    _write_plan_outputs(SimpleNamespace(out=tmp_path, json=False), scenario, LadderResult(str(INCLINE), 0, [rung_report]))
    (warnings,) = [r["warnings"] for r in json.loads((tmp_path / "report.json").read_text())["rungs"]]
    assert len(warnings) == 1 and warnings[0].startswith("block was not held in equilibrium")
    assert warnings == run_warnings(scenario, rung_for(scenario, "quasistatic-rigid"), 1e-3, incline_run_with(scenario))
    assert "warnings" not in (tmp_path / "plan.json").read_text()


def incline_run_with(scenario):
    rung = rung_for(scenario, "quasistatic-rigid")
    return rung.rollout(scenario, rung.initial_state(scenario), np.zeros((1, 0)), [0.5], 1e-3)

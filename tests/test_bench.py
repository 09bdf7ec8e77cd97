"""`ladder bench --quick`: every section runs and says something checkable; the OMPL logs
load into OMPL's benchmark database."""

from __future__ import annotations

import json
import math
import sqlite3
import subprocess
import sys

import pytest

from planner.bench import SPLIT_STEP_PARTS, run_all


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    return out, run_all(out, out / "benchmarks.md", quick=True, progress=lambda text: None)


def test_work_precision_is_first_order_against_the_closed_forms(quick):
    _, r = quick
    for scene, rung in (("incline_block", "dynamic-rigid"), ("bouncing_disc", "dynamic-rigid")):
        rows = sorted((row for row in r["work_precision"]["rows"] if row["scene"] == scene and row["rung"] == rung), key=lambda x: -x["h"])
        errors = [row["error"] for row in rows]
        assert all(row["status"] == "ok" for row in rows)
        for coarse, fine in zip(errors, errors[1:]):
            assert 5 < coarse / fine < 20, errors  # ten times smaller h, about ten times smaller error


def test_large_steps_stay_bounded_and_keep_the_outcome(quick):
    """The issue's stability claim: dynamic-compliant, K = 1e6, plastic and elastic contact,
    h up to 1e-3 reaches the grasp like h = 1e-5, with the triangle within a few mm of it."""
    _, r = quick
    rows = r["stability"]["rows"]
    assert {row["C"] for row in rows} == {1e4, 0.0} and max(row["h"] for row in rows) == pytest.approx(1e-3)
    for row in rows:
        assert row["bounded"] and row["status"] == "ok" and row["outcome"] == row["reference_outcome"] == "goal"
        assert row["x_error"] < 5e-3
        # along the way the gap is larger than at the end (the grasp brings the runs together) and bounded
        assert row["x_error"] <= row["largest_x_gap"] < 5e-2 and 1.4 < row["largest_x_gap_t"] <= row["t"]
    # the gap along the way is first order in h: where the push before the grasp is resolved in fewer steps
    plastic = {row["h"]: row["largest_x_gap"] for row in rows if row["C"] == 1e4}
    assert 1.5 < plastic[1e-3] / plastic[5e-4] < 2.5 and 1.5 < plastic[2e-4] / plastic[1e-4] < 2.5, plastic
    assert "## Stability" in (r_text := (quick[0] / "benchmarks.md").read_text()) and "x at the end" in r_text
    assert "largest gap (at t)" in r_text


def test_largest_gap_interpolates_the_reference_at_the_runs_times():
    """`_largest_gap` against a reference x = t (every 0.1 s to 1 s) and a run x = t + 0.05 sin(pi t)
    recorded every 0.25 s past the reference's end: the gap is largest at t = 0.5, and the
    record after the reference's end is not compared."""
    from types import SimpleNamespace

    import numpy as np

    from planner.bench import _largest_gap

    rt = np.linspace(0.0, 1.0, 11)
    ref = SimpleNamespace(times=rt, trajectory=np.stack([-rt, rt], axis=1))
    t = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 1.25])
    run = SimpleNamespace(times=t, trajectory=np.stack([-t, t + 0.05 * np.sin(np.pi * t) + 9.0 * (t > 1.0)], axis=1))
    gap, when = _largest_gap(run, ref, 1)
    assert gap == pytest.approx(0.05) and when == 0.5


def test_throughput_and_scaling_report_every_rung(quick):
    _, r = quick
    assert {row["rung"] for row in r["throughput"]["rows"]} >= {"kinematic", "quasistatic-rigid", "dynamic-compliant"}
    assert all(row["outcome"] == "goal" and row["steps_per_s"] > 0 for row in r["throughput"]["rows"])
    # the runs until the grasp are free flight; the contact rows are steps that push
    assert all(row["contact_steps"] == 0 for row in r["throughput"]["rows"] if row["rung"].startswith("dynamic"))
    contact = r["throughput"]["contact"]["rows"]
    assert len(contact) == 7 and all(row["contact_steps"] > 0.5 * row["steps"] and row["us_per_step"] > 0 for row in contact)
    # each row's contact-solve work: Lemke's rows pivot less than once a step (the warm start holds on most
    # steps) and do not sweep; the push, in calls of one period, not at all (each call's first step guessed
    # from its LCP's q, `models.stepper._basis_guess`); the exact cone's PGS sweeps at least once on every
    # step with contact, and has no pivots
    *squeeze, push, push_rollout, exact, exact_rollout = contact
    assert all(row["sweeps_per_step"] == 0 and row["pivots_per_step"] < 1 for row in squeeze)
    assert push["sweeps_per_step"] == 0 and push["pivots_per_step"] == 0
    assert exact["rung"].endswith("(exact cone, pgs)") and exact["pivots_per_step"] == 0 and exact["sweeps_per_step"] >= 1
    # each push timed two ways, as a planner calls it and through Rung.rollout: the same steps (the same end)
    for planners, rollout in ((push, push_rollout), (exact, exact_rollout)):
        assert "the planners' propagation" in planners["scene"] and "`Rung.rollout`" in rollout["scene"]
        assert planners["same_end"] and rollout["same_end"] and planners["rung"] == rollout["rung"]
    # the cones timed in the same rounds: their ratio is reported each way, and said in the document
    cones = r["throughput"]["contact"]["exact_vs_polygon"]
    assert set(cones) == {"planners", "rollout"} and all(math.isfinite(v) and v > 0 for v in cones.values())
    doc = (quick[0] / "benchmarks.md").read_text()
    assert f"{cones['planners']:.2f}x as a planner calls it" in doc
    # the cost split of a contact step, at a squeezing and two pushing states: every stage timed, the dynamics
    # step in its three parts (medians over the rounds of differences of runs in the same round, floored at 0), which
    # together cost the most; each state with the rounds' spread
    split = r["throughput"]["contact"]["split"]
    assert [s["contacts"] for s in split] == [2, 5, 5]
    # the solve's work at the state, warm-started from its own solution: Lemke needs no pivot, PGS sweeps
    assert [(s["pivots"], s["sweeps"] > 0) for s in split] == [(0, False), (0, False), (0, True)]
    for s in split:
        assert list(s["us"]) == ["detection", "distances and predicates", "Jacobians", *SPLIT_STEP_PARTS]
        step = sum(s["us"][name] for name in SPLIT_STEP_PARTS)
        assert step > max(s["us"]["detection"], s["us"]["distances and predicates"], s["us"]["Jacobians"]) and min(s["us"].values()) >= 0
        assert s["rounds"] >= 3 and math.isfinite(s["spread_us"]) and s["spread_us"] >= 0
    assert "| rounds' spread |" in doc
    peer = r["throughput"]["peer"]
    assert "skipped" in peer or "steps_per_s" in peer
    if "skipped" not in peer:  # the contact rows are timed against MuJoCo too
        assert all(row["mujoco_us_per_step"] > 0 and row["speed_vs_mujoco"] > 0 for row in contact)
        assert {row["contact"] for row in peer["rows"]} == {"force", "direct"} and peer["ratio"] > 0
        assert peer["inert_pairs"] == ["palm-triangle"] and len(peer["rows"]) == 4  # each mapping with and without it
        assert all(row["steps"] == peer["steps"] and row["end"]["outcome"] == "goal" for row in peer["rows"])  # MuJoCo at the grasp too
        stability = peer["stability"]["rows"]
        ours = [row for row in stability if row["simulator"].startswith("ours")]
        assert len(ours) == 8 and all(row["end"] == "goal" and row["unsafe_at"] is None and row["status"] == "ok" for row in ours)
        # at h = 1e-4 the direct mapping (MuJoCo's own contact model) reaches the grasp when ours does
        for row in (row for row in stability if row["h"] == 1e-4 and row["simulator"] == "MuJoCo (direct)"):
            mine = next(o for o in ours if o["scene"] == row["scene"] and o["h"] == 1e-4)
            assert row["goal_at"] == pytest.approx(mine["goal_at"], abs=5e-3), row
    s = r["scaling"]
    rows = s["rows"]
    assert all(row["status"] == "ok" and row["max_drift"] < 1e-3 for row in rows)  # boxes stay at rest
    for rung in ("dynamic-rigid", "dynamic-compliant"):
        for solver in ("lemke", "pgs"):
            mine = [row for row in rows if row["rung"] == rung and row["solver"] == solver]
            assert [row["contacts"] for row in mine] == [2, 4, 8, 16, 32]
            assert all(math.isfinite(row["us_per_step"]) and row["us_per_step"] > 0 for row in mine)
            assert all((row["sweeps_per_step"] >= 1) == (solver == "pgs") for row in mine)
            assert 0.0 < s["growth_exponent"][rung][solver] < 3.0
        assert s["crossover_contacts"][rung] in (None, 2, 4, 8, 16, 32)
        assert s["stack_lemke_cheaper_from"][rung] in (None, 2, 4, 8)
    for row in s["stack_rows"]:  # a stack PGS cannot converge on is a status, and then has no cost per step
        assert row["status"] in ("ok", "contact_not_converged")
        assert (row["us_per_step"] is None) == (row["steps"] == 0)
    assert {(row["solver"], row["status"]) for row in s["stack_rows"] if row["solver"] == "lemke"} == {("lemke", "ok")}
    spatial = s["spatial_rows"]  # boxes apart in space: 4 contacts each, at rest under both solvers
    assert all(row["status"] == "ok" and row["max_drift"] < 1e-3 for row in spatial)
    for rung in ("dynamic-rigid", "dynamic-compliant"):
        for solver in ("lemke", "pgs"):
            mine = [row for row in spatial if row["rung"] == rung and row["solver"] == solver]
            assert [row["contacts"] for row in mine] == [4, 8, 16]
            assert all((row["sweeps_per_step"] >= 1) == (solver == "pgs") for row in mine)
        assert s["spatial_crossover_contacts"][rung] in (None, 4, 8, 16)


def test_planning_section_and_ompl_logs(quick):
    out, r = quick
    for scene, res in r["planning"].items():
        assert res["summary"]["ladder"]["success_rate"] >= 2 / 3
        log = out / f"ladder_vs_flat.{scene}.log"
        db = out / f"{scene}.db"
        done = subprocess.run(
            [sys.executable, "-m", "ompl.ompl_benchmark_statistics", str(log), "-d", str(db)], capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 0, done.stderr
        rows = (
            sqlite3.connect(db)
            .execute(
                "SELECT plannerConfigs.name, COUNT(*), AVG(runs.solved) "
                "FROM runs JOIN plannerConfigs ON runs.plannerid = plannerConfigs.id GROUP BY 1"
            )
            .fetchall()
        )
        assert {name for name, _, _ in rows} == {"control_ladder", "control_flat"}
        assert all(count == 3 for _, count, _ in rows)
        # the budgets the runs had: flat has the sum of the ladder's rungs' iterations, at the top rung
        ladder, flat = res["budget"]["ladder"], res["budget"]["flat"]
        assert list(flat) == [list(ladder)[-1]] and sum(ladder.values()) == sum(flat.values()) > 0
        assert f"flat: {list(flat)[0]} {sum(flat.values())}, the whole ladder's" in log.read_text()
        # the warm-up loaded every kernel the timed runs use: none of them compiles or loads one
        assert all(run["compile_s"] == 0.0 for run in res["runs"]), res["runs"]
    text = (out / "benchmarks.md").read_text()
    assert "| two_finger_triangle | ladder | " in text and "median rollouts" in text and "parameters v1 = 0.8" in text
    assert "## Throughput" in text and "## Work-precision" in text and "ladder against flat" in text
    assert "## Scaling" in text and "PGS us/step" in text and "Fitted growth exponent" in text and "PGS is cheaper" in text
    assert ("Peer (MuJoCo): skipped" in text) != ("### Peer: MuJoCo" in text and "### Stability over h" in text)
    assert json.loads((out / "bench.json").read_text())["quick"] is True


def test_peer_says_it_skipped_without_mujoco(monkeypatch):
    import planner
    from planner import bench

    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco raises ImportError
    monkeypatch.delitem(sys.modules, "planner.peers", raising=False)
    monkeypatch.delattr(planner, "peers", raising=False)
    peer = bench.mujoco_peer(None, None, 0, 1e-4, None)
    assert set(peer) == {"skipped"} and "not installed" in peer["skipped"]
    assert bench.peer_markdown(peer) == [f"Peer (MuJoCo): skipped: {peer['skipped']}."]


def test_cpu_name_tells_machines_of_one_model_name_apart():
    """`cpu_name` on /proc/cpuinfo texts: the first processor's model name, family, model and
    widest vector extension; the second processor's fields are not read; no model name, no name."""
    from planner.bench import cpu_name

    zen4 = "processor\t: 0\ncpu family\t: 25\nmodel\t\t: 17\nmodel name\t: AMD EPYC\nflags\t\t: fpu avx2 avx512f\n"
    other = "\nprocessor\t: 1\ncpu family\t: 23\nmodel\t\t: 49\nmodel name\t: AMD EPYC\nflags\t\t: fpu avx2\n"
    assert cpu_name(zen4 + other) == "AMD EPYC (family 25, model 17, AVX-512)"
    assert cpu_name(other) == "AMD EPYC (family 23, model 49, AVX2)"
    assert cpu_name("model name\t: Some CPU\n") == "Some CPU"
    assert cpu_name("processor\t: 0\nflags\t\t: avx2\n") == ""


def test_planning_takes_a_scene_file_and_quick_keeps_the_seeds_given(tmp_path):
    """`ladder bench --planning FILE`: a scenario file by its path, its own parameters; --quick
    shrinks the seeds only where none are given (it had run 3 seeds whatever --seeds said)."""
    from planner.bench import SCENARIOS, planning

    path = str(SCENARIOS / "two_finger_triangle.toml")
    r = planning(quick=True, out=tmp_path, scenes=[path], seeds=1)
    assert list(r) == [path] and r[path]["parameters"] == {}
    assert [(run["mode"], run["seed"]) for run in r[path]["runs"]] == [("ladder", 1), ("flat", 1)]
    assert "ladder vs flat planning on " + path in (tmp_path / "ladder_vs_flat.two_finger_triangle.log").read_text()

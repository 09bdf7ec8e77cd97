"""Parameter sweeps: classification, refinement against the hand derivation, executors,
interruption, bad input."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from models.scenario import ScenarioError
from planner import sweep as sw
from tests.conftest import ROOT, SCENARIOS
from tests.test_model_family import RHO_LOW

TRIANGLE = str(SCENARIOS / "two_finger_triangle.toml")
RIGID_FINGERS = "finger_mass=1e3;finger_kp=1e9;finger_kd=2e6"


def ratio_sweep(models: str, mus: str, count: int = 9, tolerance: float = 1e-3, executor=None):
    axes = [sw.parse_axis(f"v1=0.25:4:{count}:log"), sw.parse_axis(f"mu={mus}")]
    result = sw.sweep(TRIANGLE, axes, sw.parse_models(models), fixed={"v2": 1.0}, duration=8.0, executor=executor)
    return sw.refine(result, tolerance=tolerance, executor=executor)


def only_band(result, model, mu):
    edges = sw.bands(result, "v1")[model][f"mu={mu:g}"]
    assert len(edges) == 1, edges
    return edges[0]


def test_quasistatic_band_equals_the_hand_derivation_within_the_refinement_tolerance():
    tolerance = 1e-3
    result = ratio_sweep("quasistatic-rigid", "0.3,0.8", tolerance=tolerance)
    assert result.complete and all(p.status == "ok" for p in result.points)
    for mu in (0.3, 0.8):
        band = only_band(result, "quasistatic-rigid", mu)
        assert not band["from_is_grid_end"] and not band["to_is_grid_end"]
        # the refined edge lies within one bracket (log-relative tolerance) of the derived ratio
        assert abs(math.log(band["from"] / RHO_LOW)) <= tolerance
        assert abs(math.log(band["to"] * RHO_LOW)) <= tolerance


def test_with_mu_at_least_one_every_ratio_in_the_quadrant_grasps():
    axes = [sw.parse_axis("v1=0.25:4:13:log"), sw.parse_axis("mu=1.0,1.2")]
    result = sw.sweep(TRIANGLE, axes, sw.parse_models("quasistatic-rigid"), fixed={"v2": 1.0}, duration=8.0)
    assert len(result.points) == 26
    assert all(p.outcome == "goal" for p in result.points), [(p.parameters, p.outcome) for p in result.points if p.outcome != "goal"]


def test_elastic_band_lies_inside_the_plastic_band():
    models = f"plastic=dynamic-compliant[C=1e4;{RIGID_FINGERS}],elastic=dynamic-compliant[C=0;{RIGID_FINGERS}]"
    result = ratio_sweep(models, "0.5", count=9, tolerance=1e-2)
    plastic, elastic = only_band(result, "plastic", 0.5), only_band(result, "elastic", 0.5)
    assert plastic["from"] < elastic["from"] < elastic["to"] < plastic["to"]
    assert elastic["to"] / elastic["from"] < 0.9 * plastic["to"] / plastic["from"]  # clearly narrower


def test_local_pool_and_dask_local_cluster_give_identical_results():
    distributed = pytest.importorskip("distributed", reason="the test extra installs distributed")
    with sw.Executor(2) as pool:
        local = ratio_sweep("quasistatic-rigid", "0.5,1.2", count=7, tolerance=1e-2, executor=pool)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with sw.Executor(address=f"dask://{cluster.scheduler_address}") as dask:
            remote = ratio_sweep("quasistatic-rigid", "0.5,1.2", count=7, tolerance=1e-2, executor=dask)
    assert [(p.parameters, p.outcome, p.status, p.t) for p in local.points] == [
        (p.parameters, p.outcome, p.status, p.t) for p in remote.points
    ]
    assert local.boundaries == remote.boundaries
    serial = ratio_sweep("quasistatic-rigid", "0.5,1.2", count=7, tolerance=1e-2)
    assert [p.outcome for p in serial.points] == [p.outcome for p in local.points]


def test_an_interrupted_sweep_keeps_what_it_computed():
    seen = []

    def progress(done, total):
        seen.append(done)
        if done == 5:
            raise KeyboardInterrupt

    axes = [sw.parse_axis("v1=0.25:4:20:log")]
    result = sw.sweep(TRIANGLE, axes, sw.parse_models("quasistatic-rigid"), fixed={"v2": 1.0}, duration=8.0, progress=progress)
    assert not result.complete
    assert sum(p is not None for p in result.points) == 5
    data = result.to_json()
    assert data["complete"] is False and data["missing"] == 15 and len(data["points"]) == 5


def test_ctrl_c_on_the_command_writes_partial_results_marked_incomplete(tmp_path):
    # 4,000 runs: far more than 3 s of work (400 once were; the faster free and contact steps
    # of the thirty-ninth session finished them within it)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = tmp_path / "sweep"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "planner",
            "sweep",
            TRIANGLE,
            "--grid",
            "v1=0.25:4:4000:log",
            "--param",
            "v2=1",
            "--model",
            "dynamic-compliant",
            "--workers",
            "1",
            "--duration",
            "8",
            "--out",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    line = proc.stderr.readline()  # "sweeping N runs ..." once the sweep starts
    assert line.startswith("sweeping 4000 runs"), line
    time.sleep(3.0)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 130, stderr
    data = json.loads((out / "sweep.json").read_text())
    assert data["complete"] is False
    assert 0 < len(data["points"]) < 4000 and data["missing"] == 4000 - len(data["points"])
    assert "INCOMPLETE" in stdout
    assert (out / "sweep.csv").read_text().count("\n") == len(data["points"]) + 1


@pytest.mark.parametrize(
    "axes, x, y, title",
    [
        ((("mu", (0.5,)), ("v1", (0.5, 1.0, 2.0))), "v1", "", "quasistatic-rigid (mu = 0.5)"),  # the README's Fig. 5 row
        ((("v1", (0.5, 1.0, 2.0)), ("mu", (0.5, 1.2))), "v1", "mu", "quasistatic-rigid"),
        ((("v1", (1.0,)),), "v1", "", "quasistatic-rigid"),
    ],
)
def test_the_sweep_plot_takes_an_axis_of_one_value_as_a_fixed_parameter(tmp_path, monkeypatch, axes, x, y, title):
    """`--grid mu=0.5` fixes mu: the map is a strip over the axis that varies, with mu = 0.5 in
    the panel's title, not a y axis of one value."""
    from planner import plots

    drawn = []
    monkeypatch.setattr(plots, "_save", lambda fig, path, svg=False: drawn.append(fig) or path)
    grid = [sw.Axis(name, values, log=name == "v1") for name, values in axes]
    model = sw.ModelSpec("quasistatic-rigid")
    points = [
        sw.Point(model.label, dict(p), "goal" if dict(p)["v1"] == 1.0 else "unsafe", 1.0, "ok", {}, 10, 0.0) for p in sw.grid_points(grid)
    ]
    result = sw.SweepResult(str(TRIANGLE), grid, [model], {}, None, None, points)
    plots.plot_feasible_sets(tmp_path / "sweep.png", result)
    (panel,) = drawn[0].axes
    assert (panel.get_xlabel(), panel.get_ylabel(), panel.get_title()) == (x, y, title)
    if not y:
        assert len(panel.get_yticks()) == 0  # a strip's height means nothing


def test_sweep_command_writes_json_csv_and_plot(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = tmp_path / "s"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "planner",
            "sweep",
            TRIANGLE,
            "--grid",
            "v1=0.4:2.5:5:log",
            "--grid",
            "mu=0.5,1.2",
            "--param",
            "v2=1",
            "--model",
            "quasistatic-rigid",
            "--workers",
            "1",
            "--duration",
            "8",
            "--refine",
            "--tolerance",
            "1e-2",
            "--out",
            str(out),
            "--json",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)
    assert data["complete"] and len(data["points"]) == 10 and data["boundaries"]
    assert json.loads((out / "sweep.json").read_text())["points"] == data["points"]
    assert (out / "sweep.csv").read_text().splitlines()[0].startswith("model,v1,mu,outcome,t,status,steps,max_penetration,")
    assert all(0.0 <= p["max_penetration"] < 1e-6 for p in data["points"])  # quasistatic-rigid: contacts met to round-off
    from models.scenario import load_scenario

    h = load_scenario(TRIANGLE).rung_settings("quasistatic-rigid").h
    assert data["h"] is None and {p["h"] for p in data["points"] + data["refine_points"]} == {h}  # each run's own step
    assert (out / "sweep.png").stat().st_size > 0 and (out / "sweep.svg").exists()


@pytest.mark.parametrize(
    "args, key",
    [
        (["--grid", "nope=0:1:3"], "--grid nope"),
        (["--grid", "v1=1:0.5"], "--grid v1=1:0.5"),
        (["--grid", "v1=0:1:3:log"], "--grid v1=0:1:3:log"),
        (["--grid", "v1=0.5:1:3", "--model", "warp-drive"], "--model warp-drive"),
        (["--grid", "v1=0.5:1:3", "--model", "dynamic-rigid[Q=1]"], "--model dynamic-rigid"),
        (["--grid", "v1=0.5:1:3", "--workers", "0"], "--workers"),
        (["--grid", "v1=0.5:1:3", "--executor", "tcp://x:1"], "--executor"),
        (["--grid", "v1=0.5:1:3", "--step", "10"], "--step: quasistatic-rigid at v1=0.5 and 2 more grid points: a run of 3 s at h = 10"),
        (["--grid", "v1=0.5:1:3", "--duration", "1e-6"], "--duration: quasistatic-rigid at v1=0.5 and 2 more grid points: a run of 1e-06"),
    ],
)
def test_bad_sweep_input_is_exit_2_naming_the_key_and_writes_nothing(tmp_path, args, key):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = tmp_path / "s"
    if "--model" not in args:
        args = args + ["--model", "quasistatic-rigid"]
    assert "Traceback" not in args
    done = subprocess.run(
        [sys.executable, "-m", "planner", "sweep", TRIANGLE, *args, "--out", str(out)], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 2, done.stderr
    assert key in done.stderr and "Traceback" not in done.stderr
    assert not out.exists()


def test_parse_axis_values():
    axis = sw.parse_axis("v1=0.25:4:5:log")
    assert axis.log and axis.values == pytest.approx((0.25, 0.5, 1.0, 2.0, 4.0))
    assert sw.parse_axis("mu=0.3,0.5").values == (0.3, 0.5)
    # the decimals meant: the middle of 0.2:0.4:3 had been 0.30000000000000004, 0.1:1:10's 0.30000000000000004 too
    assert sw.parse_axis("mu=0.2:0.4:3").values == (0.2, 0.3, 0.4)
    assert sw.parse_axis("mu=0.1:1:10").values == (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
    assert sw.parse_axis("v1=0.25:4:5:log").values == (0.25, 0.5, 1.0, 2.0, 4.0)
    assert sw.parse_axis("x=-0.7:0.3:11").values[7] == 0.0  # (crossing 0: it had been 1.1e-16)
    with pytest.raises(ScenarioError):
        sw.parse_axis("mu=")


def sweep_command(tmp_path, *args, timeout=120):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-m", "planner", "sweep", TRIANGLE, *args, "--out", str(tmp_path / "s")],
        capture_output=True,
        text=True,
        env=env,
        timeout=timeout,
    )


def test_sweep_names_the_defaults_of_a_rung_the_ladder_does_not_list(tmp_path):
    # the paper's scene lists kinematic, quasistatic-rigid and dynamic-compliant, not dynamic-rigid
    done = sweep_command(tmp_path, "--grid", "v1=0.8,1", "--model", "kinematic,dynamic-rigid[mu=0.3]", "--duration", "0.01")
    assert done.returncode == 0, done.stderr
    notes = [line for line in done.stderr.splitlines() if "is not in the scenario's ladder" in line]
    assert notes == [
        "dynamic-rigid is not in the scenario's ladder, so it runs at its family's defaults: h = 0.0001 (unless --step), lemke; "
        "a [[ladder.rungs]] entry would set them (and add the rung to the ladder)"
    ]


@pytest.mark.parametrize(
    "args, message",
    [
        # 1e8 runs would not fit in memory: refused before any value is made
        (
            ["--grid", "v1=1:2:100000000", "--model", "kinematic"],
            "--grid v1=1:2:100000000: COUNT 100,000,000 is more than a sweep may run (1,000,000 runs)",
        ),
        (
            ["--grid", "v1=1:2:1000", "--grid", "mu=0:1:1001", "--model", "kinematic"],
            "--grid: 1000 x 1001 grid points x 1 model(s) = 1,001,000 runs, more than a sweep may run (1,000,000)",
        ),
        # values are checked before the pool starts (it used to die with BrokenProcessPool)
        (
            ["--grid", "mu=-1:1:3", "--model", "kinematic", "--workers", "2"],
            "--grid mu=-1:1:3: kinematic at mu=-1: the scenario is invalid: "
            "contact.pairs[0].mu: must be greater than or equal to 0, got -1 from 'mu' (--grid mu)",
        ),
        (
            ["--grid", "v1=0.5,1", "--model", "kinematic[mu=-2]", "--workers", "2"],
            "--model kinematic[mu=-2]: kinematic[mu=-2] at v1=0.5 and 1 more grid point: the scenario is invalid: contact.pairs[0].mu",
        ),
        (
            ["--grid", "v1=1:2:3", "--model", "dynamic-compliant[C=0"],
            "--model dynamic-compliant[C=0: a '[' is not closed; expected [LABEL=]RUNG[NAME=VALUE,...]",
        ),
        (["--grid", "v1=1:2:3", "--model", "dynamic-compliant]C=0["], "--model dynamic-compliant]C=0[: unbalanced ']'"),
        (  # an unknown rung: the syntax as the other messages and --help give it (commas; it had said semicolons)
            ["--grid", "v1=1:2:3", "--model", "kinematic,nope"],
            "--model nope: expected [LABEL=]RUNG[NAME=VALUE,...], e.g. elastic=dynamic-compliant[C=0,finger_mass=1e3]; RUNG one of "
            "kinematic, quasistatic-rigid",
        ),
        (
            ["--grid", "v1=1:2:3", "--model", "a=kinematic,a=dynamic-compliant"],
            "--model a=kinematic,a=dynamic-compliant: the label 'a' names two models",
        ),
        (["--grid", "v1=1:2:3", "--model", "quasistatic-rigid,quasistatic-rigid"], "the label 'quasistatic-rigid' names two models"),
        (["--grid", "v1=1:2:3", "--model", "dynamic-rigid[mu=1,mu=2]"], "--model dynamic-rigid[mu=1,mu=2]: mu overridden twice"),
        (
            ["--grid", "v1=1:2:3", "--model", "kinematic", "--step", "1e-12"],
            "--step: kinematic at v1=1 and 2 more grid points: a run of 3 s at h = 1e-12 is 3e+12 steps",
        ),
        (["--grid", "v1=1:2:3", "--model", "kinematic", "--tolerance", "0"], "--tolerance: must be a positive number, got 0.0"),
        (["--grid", "v1=1:2:3", "--model", "kinematic", "--duration", "-1"], "--duration: must be a positive number, got -1.0"),
    ],
)
def test_every_sweep_problem_is_exit_2_before_any_run(tmp_path, args, message):
    t0 = time.perf_counter()
    done = sweep_command(tmp_path, *args)
    assert done.returncode == 2, done.stderr
    assert message in done.stderr and done.stderr.startswith("error: ") and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.splitlines()) == 1, done.stderr
    assert not (tmp_path / "s").exists()
    assert time.perf_counter() - t0 < 60  # refused up front, not after 1e8 values or runs


def test_sweep_out_onto_a_file_is_bad_input(tmp_path):
    (tmp_path / "s").write_text("x")
    done = sweep_command(tmp_path, "--grid", "v1=1:2:3", "--model", "kinematic")
    assert done.returncode == 2
    assert done.stderr == f"error: {TRIANGLE}: --out: {tmp_path / 's'} is a file, not a folder\n"


def test_dask_executor_without_the_extra_says_how_to_install_it(tmp_path):
    code = (
        "import sys; sys.modules['distributed'] = None; from planner.cli import main; "
        f"sys.exit(main(['sweep', {TRIANGLE!r}, '--grid', 'v1=1:2:3', '--model', 'kinematic', "
        f"'--executor', 'dask://127.0.0.1:8786', '--out', {str(tmp_path / 's')!r}]))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120
    )
    assert done.returncode == 2
    assert done.stderr == (
        f'error: {TRIANGLE}: --executor: a Dask executor needs the dask extra: install the dask extra: pip install "contact-ladder[dask]"\n'
    )
    assert not (tmp_path / "s").exists()


def test_sweep_help_shows_the_model_syntax():
    done = subprocess.run(
        [sys.executable, "-m", "planner", "sweep", "--help"],
        capture_output=True,
        text=True,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        timeout=60,
    )
    text = " ".join(done.stdout.split())
    assert "[LABEL=]RUNG[NAME=VALUE,...]" in text
    # the example's plastic and elastic models are the paper's, as `make paper` sweeps them
    from planner.paper import MODELS, RIGID_FINGERS

    assert f"F='{RIGID_FINGERS}'" in text
    example = text.split('--model "', 1)[1].split('"', 1)[0].replace("$F", RIGID_FINGERS)
    assert set(example.split(",")) <= set(MODELS.split(",")) and len(example.split(",")) == 2


def test_grid_points_stream_and_the_pool_is_fed_a_bounded_window():
    axes = [sw.parse_axis("v1=0.25:4:1000"), sw.parse_axis("mu=0:1:1000")]
    points = sw.grid_points(axes)
    assert next(points) == {"v1": 0.25, "mu": 0.0} and next(points) == {"v1": 0.25, "mu": pytest.approx(1 / 999)}
    assert sw.grid_size(axes) == 1_000_000
    pulled = []

    def tasks():
        for p in sw.grid_points([sw.parse_axis("v1=0.5:2:40")]):
            pulled.append(p)
            yield sw.Task(TRIANGLE, tuple({**p, "v2": 1.0}.items()), sw.ModelSpec("kinematic"), None, 1.0)

    with sw.Executor(2) as pool:
        results = pool.map(tasks())
        first = next(results)
        assert len(pulled) <= sw.WINDOW_PER_WORKER * 2 + 1  # not the whole stream
        rest = list(results)
    assert len(pulled) == 40 and sorted(i for i, _ in [first, *rest]) == list(range(40))


@pytest.mark.parametrize(
    "text, phrase",
    [
        ("v1=0:1:abc", "COUNT must be an integer, got 'abc'"),
        ("v1=a:1:3", "START must be a number, got 'a'"),
        ("mu=0.3,x", "must be a number, got 'x'"),
    ],
)
def test_parse_axis_says_what_it_expected(text, phrase):
    with pytest.raises(ScenarioError) as info:
        sw.parse_axis(text)
    assert phrase in info.value.problems[0].reason
    assert "invalid literal" not in str(info.value) and "could not convert" not in str(info.value)


class _ScriptedRuns:
    """An executor whose runs end as a script of the parameter x says: goal below 0.3, a solver
    failure (outcome none) in [0.3, 0.35), none after: refine's bookkeeping without physics."""

    def map(self, tasks, stop=None):
        for i, task in enumerate(tasks):
            x = dict(task.parameters)["x"]
            outcome, status = ("goal", "ok") if x < 0.3 else ("none", "lcp_failed" if x < 0.35 else "ok")
            yield i, sw.Point(task.model.label, dict(task.parameters), outcome, 1.0, status, {}, 10, 0.0)


def test_refinement_keeps_its_runs_and_names_a_boundary_a_solver_failure_bounds(capsys):
    from types import SimpleNamespace

    from planner import cli

    axes, models = [sw.parse_axis("x=0:1:3")], sw.parse_models("kinematic")
    runs = _ScriptedRuns()
    result = sw.sweep(TRIANGLE, axes, models, executor=runs)
    assert [(p.outcome, p.status) for p in result.points] == [("goal", "ok"), ("none", "ok"), ("none", "ok")]
    sw.refine(result, tolerance=1e-3, executor=runs)
    (boundary,) = result.boundaries
    assert boundary["low"] < 0.3 <= boundary["high"] and boundary["high"] - boundary["low"] <= 1e-3
    assert (boundary["low_status"], boundary["high_status"]) == ("ok", "lcp_failed")  # the none side is a failure, not physics
    data = result.to_json()
    assert len(data["refine_points"]) == len(result.refine_points) == 9  # 0.5 / 2**9 < 1e-3 <= 0.5 / 2**8
    assert sum(p["status"] == "lcp_failed" for p in data["refine_points"]) >= 1
    data["bands"] = {"x": sw.bands(result, "x")}  # (as the command adds them with --refine)
    cli._print_sweep(SimpleNamespace(json=False, out=Path("out")), result, data, None, False)
    said = capsys.readouterr().out
    (band,) = [line for line in said.splitlines() if line.startswith("goal band in ")]
    assert band == f"goal band in x, kinematic: 0 (grid end) .. {boundary['boundary']:.4g}"  # (no other axis: it had said "kinematic, -:")
    failed = sum(p.status != "ok" for p in result.refine_points)
    assert f"{failed} of the 9 refinement runs stopped on a solver failure" in said
    assert "1 refined boundary lies against a run a solver failure stopped" in said


class _ThreeClasses:
    """Runs that end in goal below x = 0.3, none in [0.3, 0.35) and unsafe after: a class narrower
    than the grid's spacing, between grid points of the other two."""

    def map(self, tasks, stop=None):
        for i, task in enumerate(tasks):
            x = dict(task.parameters)["x"]
            outcome = "goal" if x < 0.3 else "none" if x < 0.35 else "unsafe"
            yield i, sw.Point(task.model.label, dict(task.parameters), outcome, 1.0, "ok", {}, 10, 0.0)


def test_an_outcome_only_refining_found_is_printed_and_drawn(capsys, tmp_path, monkeypatch):
    """A trial's sweep printed "2 goal, 3 unsafe, 0 none" and a goal band, and its plot's legend
    said "none (0)" between two boundary ticks, where refining had found none between an unsafe
    and a goal grid point: a reader concluded unsafe met goal. A band's grid end was unmarked."""
    from types import SimpleNamespace

    import matplotlib.pyplot as plt

    from planner import cli, plots

    axes, models = [sw.parse_axis("x=0:1:3")], sw.parse_models("kinematic")
    result = sw.sweep(TRIANGLE, axes, models, executor=_ThreeClasses())
    sw.refine(result, tolerance=1e-3, executor=_ThreeClasses())
    low, high = sorted(result.boundaries, key=lambda b: b["boundary"])
    assert (low["low_outcome"], low["high_outcome"], high["high_outcome"]) == ("goal", "none", "unsafe")
    data = result.to_json()
    data["bands"] = {"x": sw.bands(result, "x")}
    cli._print_sweep(SimpleNamespace(json=False, out=tmp_path), result, data, None, False)
    said = capsys.readouterr().out.splitlines()
    ran = {o: sum(p.outcome == o for p in result.refine_points) for o in ("none", "goal", "unsafe")}
    assert ran["none"] > 0 and sum(ran.values()) == len(result.refine_points)
    assert said[0].startswith(f"kinematic: 1 goal, 2 unsafe, 0 none on the grid; refining's {len(result.refine_points)} runs: ")
    assert f"{ran['none']} none" in said[0]
    assert said[1] == (
        "kinematic: refining found none between x = 0 and 0.5: "
        f"goal | none at {low['boundary']:.4g}, none | unsafe at {high['boundary']:.4g}"
    )
    assert said[2] == f"goal band in x, kinematic: 0 (grid end) .. {low['boundary']:.4g}"
    drawn = []
    monkeypatch.setattr(plots, "_save", lambda fig, path, svg=False: drawn.append(fig) or path)
    plots.plot_feasible_sets(tmp_path / "sweep.png", result)
    try:
        labels = [t.get_text() for t in drawn[0].axes[0].get_legend().get_texts()]
        assert f"none (0; {ran['none']} refining, small dots)" in labels
    finally:
        plt.close(drawn[0])

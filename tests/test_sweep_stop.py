"""A sweep that is stopped (Ctrl-C, a lost Dask cluster) keeps the runs under way and leaves no
process behind; a plot of it draws the models it never reached. Found by a user's trial: a
second Ctrl-C left `--workers 2`'s pool running as orphans, the first threw away the runs that
finished after it, a Dask cluster that lost its workers hung the sweep unheard, a Dask worker read
a relative scenario path in its own folder, and the plot of a model with no run raised."""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from models.scenario import load_scenario
from planner import sweep as sw
from tests.conftest import ROOT
from tests.test_sweep import TRIANGLE


def _tasks(count: int):
    """Runs of the paper's scene under dynamic-compliant at h = 1e-5 (about 180,000 steps each
    to the grasp: under way when the sweep stops)."""
    values = [0.5 + 1.5 * k / (count - 1) for k in range(count)]
    return [sw.Task(TRIANGLE, (("v1", v), ("v2", 1.0)), sw.ModelSpec("dynamic-compliant"), 1e-5, 8.0) for v in values]


def _paper_sweep(axes, executor, progress, stop=None) -> sw.SweepResult:
    """The paper's scene swept under dynamic-compliant at h = 1e-5 (runs of seconds), v2 = 1."""
    models = sw.parse_models("dynamic-compliant")
    return sw.sweep(TRIANGLE, axes, models, fixed={"v2": 1.0}, h=1e-5, duration=8.0, executor=executor, progress=progress, stop=stop)


def test_a_stopped_pool_finishes_and_keeps_the_runs_under_way_and_starts_no_other():
    tasks = _tasks(40)
    got = []
    with sw.Executor(2) as pool:
        for i, point in pool.map(tasks, stop=lambda: bool(got)):
            got.append((i, point))
    # the first run, then those under way or done but not yet read: at most the window submitted
    # ahead and the first run's refill (runs of 0.06 s finish while the first is read); none after
    assert 2 <= len(got) <= sw.WINDOW_PER_WORKER * 2 + 1 < len(tasks), [i for i, _ in got]
    i, point = got[-1]
    again = sw.run_task(tasks[i])  # a kept run is the whole run, as run alone
    assert (point.outcome, point.t, point.steps, point.final) == (again.outcome, again.t, again.steps, again.final)


def test_a_stopped_sweep_is_incomplete_with_every_run_it_kept(monkeypatch):
    axes = [sw.parse_axis("v1=0.5:2:40")]
    seen = []

    def progress(done, total):
        seen.append(done)

    with sw.Executor(2) as pool:
        result = _paper_sweep(axes, pool, progress, stop=lambda: bool(seen))
    kept = [p for p in result.points if p is not None]
    assert not result.complete and 2 <= len(kept) <= sw.WINDOW_PER_WORKER * 2 + 1 and seen[-1] == len(kept)
    assert result.to_json()["missing"] == 40 - len(kept)


def test_the_runs_read_the_scenario_at_its_absolute_path(monkeypatch):
    """A Dask worker's working folder is its own: a relative path had been read there."""
    monkeypatch.chdir(ROOT)
    relative = os.path.relpath(TRIANGLE, ROOT)
    files = []

    class Recording:
        def map(self, tasks, stop=None):
            for i, task in enumerate(tasks):
                files.append(task.file)
                yield i, sw.Point(task.model.label, dict(task.parameters), "goal" if i == 0 else "none", 1.0, "ok", {}, 1, 0.0)

    result = sw.sweep(relative, [sw.parse_axis("v1=1,2")], sw.parse_models("kinematic"), executor=Recording())
    sw.refine(result, tolerance=0.3, executor=Recording())
    assert result.file == relative  # (sweep.json names the file as given)
    assert len(files) > 2 and set(files) == {TRIANGLE} and os.path.isabs(TRIANGLE)


def test_a_dask_sweep_stops_and_keeps_the_run_under_way():
    distributed = pytest.importorskip("distributed", reason="the test extra installs distributed")
    tasks = _tasks(12)
    got = []
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with sw.Executor(address=f"dask://{cluster.scheduler_address}") as dask:
            for i, point in dask.map(tasks, stop=lambda: bool(got)):
                got.append((i, point))
    # the first, the one the worker had begun then, and any done but not yet read: at most the
    # window submitted ahead and the first run's refill (CI kept 4 of runs of 0.06 s); none after
    assert 2 <= len(got) <= sw.WINDOW_PER_WORKER + 1 < len(tasks), [i for i, _ in got]
    i, point = got[-1]
    assert point.steps == sw.run_task(tasks[i]).steps


def test_a_dask_cluster_with_no_workers_is_said_and_ctrl_c_still_stops_the_sweep(monkeypatch):
    distributed = pytest.importorskip("distributed", reason="the test extra installs distributed")
    monkeypatch.setattr(sw, "NO_WORKERS_S", 0.3)
    said = []
    with distributed.LocalCluster(n_workers=0, processes=True, dashboard_address=None) as cluster:
        address = f"dask://{cluster.scheduler_address}"
        with sw.Executor(address=address, notice=said.append) as dask:
            start = time.monotonic()  # (the notice, then the stop a Ctrl-C makes; a limit should it never come)
            got = list(dask.map(_tasks(4), stop=lambda: bool(said) or time.monotonic() > start + 60))
    assert got == []
    assert said == [f"the Dask cluster at {address} has no workers: the sweep waits for one (Ctrl-C stops it and keeps what is done)"]


def _children(pid: int) -> set[int]:
    found = set()
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/children") as f:
            found |= {int(c) for c in f.read().split()}
    return found


def _gone(pids, within: float) -> set[int]:
    """Which of `pids` still run after `within` s."""
    end = time.monotonic() + within
    alive = set(pids)
    while alive and time.monotonic() < end:
        alive = {p for p in alive if os.path.exists(f"/proc/{p}") and "zombie" not in open(f"/proc/{p}/status").read()}
        time.sleep(0.2)
    return alive


#: Steps of each run of `_long_sweep`: fingers too slow to reach the triangle run them all.
LONG_RUN_STEPS = 16_000_000


def _long_sweep(out) -> subprocess.Popen:
    """`ladder sweep` with two workers, each run LONG_RUN_STEPS free steps (1.7 s each, 35 s in
    all, where it was written). Its runs had been the grasp at h = 1e-5, 800,000 steps at most,
    which on a faster machine reach the goal after about 110,000 (the whole sweep in 1.8 s, over
    before the tests' Ctrl-C)."""
    command = [sys.executable, "-m", "planner", "sweep", TRIANGLE, "--grid", "v1=0.01:0.02:40", "--param", "v2=0.01"]
    command += ["--model", "dynamic-compliant", "--step", "5e-7", "--duration", "8", "--workers", "2", "--out", str(out)]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.stderr.readline().startswith("sweeping 40 runs"), "the sweep did not start"
    deadline = time.monotonic() + 60
    while len(_children(proc.pid)) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(1.0)
    return proc


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads a process's children in /proc (Linux)")
def test_a_second_ctrl_c_ends_the_pools_workers_with_the_sweep(tmp_path):
    proc = _long_sweep(tmp_path / "sweep")
    workers = _children(proc.pid)
    assert len(workers) >= 2
    proc.send_signal(signal.SIGINT)
    stopping = "stopping: the runs under way finish and are kept (Ctrl-C again stops at once)\n"
    lines = [proc.stderr.readline()]
    while lines[-1] not in (stopping, "") and len(lines) < 5:  # (a note on compiling may come first)
        lines.append(proc.stderr.readline())
    assert lines[-1] == stopping, lines
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert stderr.rstrip().endswith("interrupted") and "Traceback" not in stderr
    assert _gone(workers, within=5.0) == set()  # they had run on as orphans, then blocked for good


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads a process's children in /proc (Linux)")
def test_the_pools_workers_end_when_the_sweep_is_killed(tmp_path):
    proc = _long_sweep(tmp_path / "sweep")
    workers = _children(proc.pid)
    proc.kill()
    proc.communicate(timeout=60)
    assert _gone(workers, within=60.0) == set()  # each ends once its run is done


def test_a_first_ctrl_c_keeps_the_runs_that_finish_after_it(tmp_path):
    proc = _long_sweep(tmp_path / "sweep")
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    data = json.loads((tmp_path / "sweep" / "sweep.json").read_text())
    # the two workers' runs under way were finishing: kept (a run ended by the interrupt would be short)
    assert data["complete"] is False and len(data["points"]) >= 2
    assert all(p["steps"] == LONG_RUN_STEPS and p["outcome"] == "none" for p in data["points"])


def test_the_plot_of_an_interrupted_sweep_draws_a_model_it_never_reached(tmp_path):
    """A log axis and a second model with no run: matplotlib had raised 'Data cannot be
    log-scaled', a traceback and exit 1 after Ctrl-C."""
    from planner.plots import plot_feasible_sets

    axes, models = [sw.parse_axis("x=0.25:4:5:log")], sw.parse_models("a=kinematic,b=dynamic-rigid")
    result = sw.SweepResult("scene.toml", axes, models, {}, None, None, [None] * 10, complete=False)
    for k, x in enumerate(axes[0].values[:3]):
        result.points[k] = sw.Point("a", {"x": x}, "goal", 1.0, "ok", {}, 10, 0.0)
    path = plot_feasible_sets(tmp_path / "sweep.png", result)
    assert path.stat().st_size > 0 and (tmp_path / "sweep.svg").read_text().count("no run done") == 1


def test_a_sweep_without_refine_prints_its_goal_bands_at_grid_points_and_names_a_model_with_no_run(capsys, tmp_path):
    """The README promised the goal bands in the summary; they were printed (and in sweep.json)
    only with --refine. An interrupted sweep's model with no run had no line at all, and its
    bands would end at runs not done: it has none."""
    from types import SimpleNamespace

    from models.scenario import load_scenario
    from planner import cli
    from tests.test_sweep import _ThreeClasses

    axes, models = [sw.parse_axis("x=0:1:5")], sw.parse_models("kinematic,late=dynamic-rigid")
    args = SimpleNamespace(json=False, out=tmp_path, step=None)
    result = sw.sweep(TRIANGLE, axes, models[:1], executor=_ThreeClasses())
    data, _ = cli._write_sweep_outputs(args, load_scenario(TRIANGLE), result, axes)
    assert data["bands"]["x"]["kinematic"]["-"] == [{"from": 0.0, "to": 0.25, "from_is_grid_end": True, "to_is_grid_end": False}]
    assert json.loads((tmp_path / "sweep.json").read_text())["bands"] == data["bands"]
    cli._print_sweep(args, result, data, None, False)
    assert capsys.readouterr().out.splitlines()[:3] == [
        "kinematic: 2 goal, 3 unsafe, 0 none",
        "goal band in x, kinematic: 0 (grid end) .. 0.25",
        "(the bands' edges are grid points: --refine finds the edges between them)",
    ]
    result.models, result.points, result.complete = models, result.points[:3] + [None] * 7, False
    data, _ = cli._write_sweep_outputs(args, load_scenario(TRIANGLE), result, axes)
    assert "bands" not in data
    cli._print_sweep(args, result, data, None, True)
    said = capsys.readouterr().out.splitlines()
    assert said[:2] == ["kinematic: 2 goal, 1 unsafe, 0 none", "late: no run done"]
    assert said[2].startswith("INCOMPLETE (interrupted), results written to ")


def test_a_scheduler_out_of_reach_is_named_and_leaves_no_output_folder(capsys, tmp_path):
    pytest.importorskip("distributed", reason="the test extra installs distributed")
    from planner import cli

    out = tmp_path / "sweep"
    argv = ["sweep", TRIANGLE, "--grid", "v1=1,2", "--model", "kinematic", "--executor", "dask://127.0.0.1:9", "--out", str(out)]
    assert cli.main(argv) == 2
    said = capsys.readouterr().err.splitlines()[-1]
    assert said.startswith("error: command line: --executor: cannot reach the Dask scheduler at dask://127.0.0.1:9: "), said
    assert not out.exists()  # (an empty folder had been left)


_run_task = sw.run_task


def _run_killing_its_worker_at_v1_1_5(task: sw.Task) -> sw.Point:
    """A run that kills its own pool worker (as the kernel's OOM killer would) at v1 = 1.5."""
    if abs(dict(task.parameters)["v1"] - 1.5) < 1e-9:
        os.kill(os.getpid(), signal.SIGKILL)
    return _run_task(task)


def _quick_run_killing_its_worker_at_30(task: int) -> int:
    if task == 30:
        os.kill(os.getpid(), signal.SIGKILL)
    time.sleep(0.005)
    return task


def test_a_pool_that_breaks_while_a_run_is_read_ends_in_executor_lost(monkeypatch):
    """The worker dies while the sweep reads a run (30 ms each, as a progress bar takes): the
    next run's submission to the broken pool had raised BrokenProcessPool, a traceback."""
    monkeypatch.setattr(sw, "run_task", _quick_run_killing_its_worker_at_30)
    got = []
    with pytest.raises(sw.ExecutorLost, match="a worker process of the local pool ended abruptly"):
        with sw.Executor(2) as pool:
            for i, value in pool.map(range(200)):
                assert value == i
                got.append(i)
                time.sleep(0.03)
    assert 30 not in got and 20 <= len(got) < 200


def test_a_pool_worker_killed_ends_the_sweep_as_a_failure_that_keeps_the_runs_done(capsys, tmp_path, monkeypatch):
    """A worker ended abruptly had raised BrokenProcessPool's traceback, and lost every run done.
    More runs than the pool is fed ahead (8): a run read, then the next submitted to the broken pool."""
    from planner import cli

    monkeypatch.setattr(sw, "run_task", _run_killing_its_worker_at_v1_1_5)
    out = tmp_path / "sweep"
    argv = ["sweep", TRIANGLE, "--grid", "v1=1:2:21", "--param", "v2=1", "--model", "kinematic", "--workers", "2", "--out", str(out)]
    assert cli.main(argv) == 1
    said = capsys.readouterr()
    assert "Traceback" not in said.err
    assert "error: the sweep ended after " in said.err
    assert ": a worker process of the local pool ended abruptly (killed, or out of memory), and the pool can run no more" in said.err
    assert "INCOMPLETE (the executor was lost), results written to" in said.out
    data = json.loads((out / "sweep.json").read_text())
    assert data["complete"] is False and data["error"].startswith("a worker process of the local pool ended abruptly")
    kept = [p["parameters"]["v1"] for p in data["points"]]
    assert 1.5 not in kept and len(kept) + data["missing"] == 21 and len(kept) >= 1
    for p in data["points"]:  # each kept run is whole
        again = _run_task(sw.Task(TRIANGLE, (("v1", p["parameters"]["v1"]), ("v2", 1.0)), sw.ModelSpec("kinematic"), None, None))
        assert (p["outcome"], p["steps"]) == (again.outcome, again.steps)


def test_a_dask_scheduler_that_dies_ends_the_sweep_as_a_failure_that_keeps_the_runs_done(tmp_path):
    """A scheduler gone mid-sweep had raised a traceback (FutureCancelledError or OSError), losing the runs done."""
    pytest.importorskip("distributed", reason="the test extra installs distributed")
    from planner import cli
    from tests import dask_processes as dp

    port = dp.free_port()
    got = []
    with dp.ended([dp.scheduler(port)]) as processes:
        processes.append(dp.worker(port))
        scheduler = processes[0]

        def progress(done, total):
            got.append(done)
            if done == 1:
                scheduler.kill()

        with sw.Executor(address=f"dask://127.0.0.1:{port}") as dask:
            result = _paper_sweep([sw.parse_axis("v1=0.5:2:12")], dask, progress)
    assert not result.complete
    assert result.error.startswith(f"lost the Dask scheduler at dask://127.0.0.1:{port}: its connection closed ("), result.error
    kept = [p for p in result.points if p is not None]
    assert len(kept) == got[-1] >= 1  # the runs read before it went are kept
    out = tmp_path / "sweep"
    out.mkdir()
    args = argparse.Namespace(json=False, out=out, step=1e-5)
    data, _ = cli._write_sweep_outputs(args, load_scenario(TRIANGLE), result, result.axes)
    assert data["error"] == result.error and data["complete"] is False and len(data["points"]) == len(kept)

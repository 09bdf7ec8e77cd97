"""A job's inputs made into a scenario, checked, and run: shared by the server (which checks
a request before accepting it) and the worker processes (which run it).

A request carries the scenario's TOML text and the files it names (meshes) as contents; they
are written into a fresh temporary folder and loaded from there, so a scenario reads no file
outside what its request carried. The job runs with that folder as the working directory and
the scenario at its request's `filename` (default scenario.toml), so its plan.json names the
scenario as `ladder plan FILENAME` run from the folder of the file would.

The checks and the runs are the CLI's own (planner.cli): the same problems, the same plan.json.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import tempfile
import threading
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path, PurePosixPath
from types import SimpleNamespace
from typing import Any

from models.scenario import Problem, ScenarioError

KINDS = ("plan", "simulate", "sweep")
#: Options per kind and their types (the CLI's options of the same names).
PLAN_OPTIONS = {
    "seed": int,
    "iterations": int,
    "time_limit": float,
    "flat": bool,
    "rungs": str,
    "top": str,
    "planner": str,
    "seed_roots": bool,
    "guide": bool,
}
SIMULATE_OPTIONS = {"model": str, "duration": float, "step": float, "policy": str}
#: A sweep's grid is a list of `ladder sweep --grid` texts; its model the `--model` text.
SWEEP_OPTIONS = {"grid": list, "model": str, "refine": bool, "tolerance": float, "duration": float, "step": float, "policy": str}
OPTIONS = {"plan": PLAN_OPTIONS, "simulate": SIMULATE_OPTIONS, "sweep": SWEEP_OPTIONS}
REQUIRED = {"plan": (), "simulate": ("model",), "sweep": ("grid", "model")}
#: The most runs (grid points x models) one sweep job may do: the service checks every run's
#: scenario before it accepts the job (as `ladder sweep` does), in the request.
MAX_SWEEP_RUNS = 10_000
#: The folder, in the job's folder, where a job's CLI outputs are written (a sweep's sweep.json).
OUT = ".ladder-out"


def path_problem(key: str, name: Any) -> Problem | None:
    """A problem when `name` is not a relative path that stays inside the request's folder."""
    if not isinstance(name, str) or not name.strip():
        return Problem(key, "expected a relative file name")
    if "\\" in name or "\0" in name:
        return Problem(key, f"{name!r}: use '/' between folders; no backslashes or NUL characters")
    path = PurePosixPath(name)
    if path.is_absolute():
        return Problem(key, f"{name!r} is an absolute path; a request may only name files it carries (relative paths)")
    if ".." in path.parts:
        return Problem(key, f"{name!r} leaves the request's folder ('..'); a request may only name files it carries")
    if path.parts in ((), (".",)):
        return Problem(key, f"{name!r} is not a file name")
    return None


def _inside(root: Path, path: Path) -> bool:
    root = Path(os.path.realpath(root))
    return Path(os.path.realpath(path)).is_relative_to(root)


def file_references(raw: Any, where: str = "") -> Iterator[tuple[str, Any]]:
    """Every `file = ...` in the scenario (mesh shapes), with its key path."""
    if isinstance(raw, dict):
        for key, value in raw.items():
            here = f"{where}.{key}" if where else str(key)
            if key == "file":
                yield here, value
            else:
                yield from file_references(value, here)
    elif isinstance(raw, list):
        for i, value in enumerate(raw):
            yield from file_references(value, f"{where}[{i}]")


def write_inputs(root: Path, inputs: dict) -> Path:
    """Write the scenario and its files under `root`; the scenario's path relative to `root`.
    A name that is absolute or leaves `root`, or a file reference in the scenario that points
    outside what the request carried, is a ScenarioError."""
    filename = inputs.get("filename") or "scenario.toml"
    problems = [p for p in [path_problem("filename", filename)] if p]
    files = inputs.get("files") or {}
    for name in files:
        problem = path_problem(f"files[{name!r}]", name)
        if problem:
            problems.append(problem)
    if problems:
        raise ScenarioError("request", problems)
    scenario = PurePosixPath(filename)
    folder = scenario.parent
    for name, text in [(str(scenario), inputs["scenario"])] + [(str(folder / n), t) for n, t in files.items()]:
        target = root / name
        if not _inside(root, target):
            raise ScenarioError("request", [Problem("files", f"{name!r} leaves the request's folder")])
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text, encoding="utf-8")
    try:  # a file the scenario names must be one the request carried: nothing else on the server
        raw = tomllib.loads(inputs["scenario"])
    except (tomllib.TOMLDecodeError, RecursionError):
        raw = {}  # the loader says what is wrong with the text
    for key, value in file_references(raw):
        if not isinstance(value, str):
            continue
        problem = path_problem(key, value)
        if problem is None and not _inside(root, root / folder / value):
            problem = Problem(key, f"{value!r} leaves the request's folder")
        if problem is None and not (root / folder / value).is_file():
            carried = ", ".join(sorted(files)) or "none"
            problem = Problem(key, f"{value!r} is not among the files the request carried ({carried}); send its contents in 'files'")
        if problem:
            raise ScenarioError(filename, [problem])
    return Path(filename)


@contextlib.contextmanager
def job_folder(inputs: dict) -> Iterator[Path]:
    """A temporary folder holding the request's files, made the working directory (a worker
    process runs one job at a time); yields the scenario's relative path."""
    with tempfile.TemporaryDirectory(prefix="ladder-job-") as tmp:
        old = os.getcwd()
        path = write_inputs(Path(tmp), inputs)
        os.chdir(tmp)
        try:
            yield path
        finally:
            os.chdir(old)


def _in_request(problems: list[Problem]) -> ScenarioError:
    """Problems of the request's options (keys options.seed, options.grid v1) as the service
    labels every problem of the request itself: under `request`, keyed where they are in its body
    as FastAPI's checks of the body key theirs (`request: body.options.seed: ...`, as
    `request: body.parameters.mu: ...`), not under the scenario's file name."""
    return ScenarioError("request", [Problem(f"body.{p.key}", p.reason) for p in problems])


def _option_problems(kind: str, options: dict) -> list[Problem]:
    problems = []
    allowed = OPTIONS[kind]
    for name, value in options.items():
        if name not in allowed:
            problems.append(Problem(f"options.{name}", f"unknown option for a {kind} job; options: {', '.join(allowed)}"))
            continue
        want = allowed[name]
        ok = (
            isinstance(value, bool)
            if want is bool
            else (isinstance(value, int) and not isinstance(value, bool))
            if want is int
            else (isinstance(value, int | float) and not isinstance(value, bool))
            if want is float
            else (isinstance(value, list) and all(isinstance(v, str) for v in value))
            if want is list
            else isinstance(value, str) or (name == "rungs" and isinstance(value, list) and all(isinstance(v, str) for v in value))
        )
        if not ok and value is not None:
            expected = "a list of strings" if want is list else want.__name__
            problems.append(Problem(f"options.{name}", f"expected {expected}, got {json.dumps(value)}"))
    for name in REQUIRED[kind]:
        if options.get(name) is None:
            what = {"model": "a model (a rung)" if kind == "simulate" else "models (as ladder sweep --model)", "grid": "a grid"}[name]
            problems.append(Problem(f"options.{name}", f"a {kind} job needs {what}"))
    if kind == "sweep" and not problems:
        problems += _sweep_size_problems(options)
    return problems


def _sweep_size_problems(options: dict) -> list[Problem]:
    """A sweep of more than MAX_SWEEP_RUNS runs (grid texts the CLI cannot read are its to report)."""
    from planner import sweep as sw

    try:
        runs = sw.grid_size([sw.parse_axis(text) for text in options["grid"]]) * len(sw.parse_models(options["model"]))
    except ScenarioError:
        return []
    if runs > MAX_SWEEP_RUNS:
        return [
            Problem("options.grid", f"{runs:,} runs, more than a sweep job may run ({MAX_SWEEP_RUNS:,}); use a coarser grid (and refine)")
        ]
    return []


#: The CLI's negative flags, as the request's options they set (--no-guide -> options.guide).
_NEGATED = {"no_seed_roots": "seed_roots", "no_guide": "guide"}


def _cli_key(key: str) -> str:
    """The CLI's option names in problems, as the request's keys: --time-limit -> options.time_limit,
    --grid v1 -> options.grid v1."""
    if key.startswith("--param "):
        return "parameters." + key.removeprefix("--param ").partition("=")[0]
    if key.startswith("--"):  # --grid v1 (an axis), --model plastic (a model's label): the rest is kept
        name, space, rest = key[2:].partition(" ")
        name = name.replace("-", "_")
        return "options." + _NEGATED.get(name, name) + space + rest
    return key


def cli_flag(key: str) -> str | None:
    """`_cli_key` the other way (`ladder submit`'s words for the service's refusals): a request's
    key, with or without its `body.`, as the CLI's flag (parameters.v1 -> --param v1,
    options.seed -> --seed); None for a key that is no flag's, or an option a negative flag sets."""
    key = key.removeprefix("body.")
    if key.startswith("parameters."):
        return "--param " + key.removeprefix("parameters.")
    name, space, rest = key.removeprefix("options.").partition(" ")
    if key.startswith("options.") and name not in _NEGATED.values():
        return "--" + name.replace("_", "-") + space + rest
    return None


def _cli_reason(kind: str, reason: str) -> str:
    """A CLI problem's advice in the request's words: "use a smaller --step" -> "use a smaller
    options.step", for the options this kind of job takes, and "--param mu" -> "parameters.mu"
    (other text is left as it is)."""

    def key(match: re.Match) -> str:
        name = _cli_key(match[0])
        return name if name.removeprefix("options.") in OPTIONS[kind] else match[0]

    reason = re.sub(r"(?<![\w-])--param (\w+)", lambda m: _cli_key(m[0]), reason)  # a value set by the request
    return re.sub(r"(?<![\w-])--[a-z][a-z-]*", key, reason)


def cli_args(kind: str, path: Path, parameters: dict, options: dict, out: Path) -> SimpleNamespace:
    """The namespace `ladder plan` / `ladder simulate` / `ladder sweep` would parse for this job."""
    param = [f"{k}={float(v)!r}" for k, v in parameters.items()]
    if kind == "plan":
        rungs = options.get("rungs")
        return SimpleNamespace(
            file=path,
            param=param,
            rungs=",".join(rungs) if isinstance(rungs, list) else rungs,
            top=options.get("top"),
            seed=options.get("seed"),
            iterations=options.get("iterations"),
            planner=options.get("planner"),
            time_limit=options.get("time_limit"),
            flat=bool(options.get("flat", False)),
            no_seed_roots=not options.get("seed_roots", True),
            no_guide=not options.get("guide", True),
            out=out,
            json=True,
        )
    if kind == "sweep":
        return SimpleNamespace(
            file=path,
            param=param,
            grid=list(options.get("grid") or []),
            model=options.get("model"),
            workers=1,  # the job's own worker process runs the sweep's runs (the service's --workers is the parallelism)
            executor=None,
            refine=bool(options.get("refine", False)),
            tolerance=options.get("tolerance"),
            duration=options.get("duration"),
            step=options.get("step"),
            policy=options.get("policy"),
            out=out,
            json=True,
        )
    return SimpleNamespace(
        file=path,
        param=param,
        model=options.get("model"),
        duration=options.get("duration"),
        step=options.get("step"),
        policy=options.get("policy"),
        plot=None,
        plan=None,
        json=True,
        quiet=True,  # no "simulating N steps (Ctrl-C stops)" in the server's log
    )


def check(kind: str, path: Path, parameters: dict, options: dict, out: Path) -> tuple[SimpleNamespace, tuple]:
    """The CLI's checks of a plan / simulate command on this job (run with the job's folder as
    the working directory): (the CLI namespace, what the check returns); else ScenarioError,
    its keys the request's (options.seed, parameters.v1): the problems of the request's options
    and parameters, if any, alone and under `request` (`_in_request`; a parameter the scenario
    does not have), else the scenario's under its file name (a parameter's value that breaks a
    rule of the scenario's is the scenario's: `contact.pairs[0].mu: ... from 'mu'`)."""
    from planner import cli

    problems = _option_problems(kind, options)
    if problems:
        raise _in_request(problems)
    args = cli_args(kind, path, parameters, options, out)
    if getattr(args, "planner", None) is not None and args.planner not in cli.CONTROL_PLANNERS:
        raise _in_request([Problem("options.planner", f"unknown planner; planners: {', '.join(cli.CONTROL_PLANNERS)}")])
    try:
        if kind == "plan":
            from planner.ladder import check_start

            checked = cli._check_plan_args(args)
            check_start(checked[0])
        elif kind == "sweep":
            checked = cli._check_sweep_args(args)
        else:
            checked = cli._check_simulate_args(args)
    except ScenarioError as exc:
        # the CLI gives its flags' problems (--seed, --param v1: the request's options and
        # parameters) under the scenario's file, with the file's own; the request's are the
        # request's, and its problems come first (as its others do)
        problems = [Problem(_cli_key(p.key), _cli_reason(kind, p.reason)) for p in exc.problems]
        flags = [mapped for p, mapped in zip(exc.problems, problems) if p.key.startswith("--")]
        raise (_in_request(flags) if flags else ScenarioError(exc.file, problems)) from None
    return args, checked


def validate(kind: str, inputs: dict, options: dict) -> None:
    """Check a request as the worker will run it; ScenarioError (the CLI's problems) if bad.
    Thread-safe: loads from an absolute path and names the file as the request does."""
    with tempfile.TemporaryDirectory(prefix="ladder-check-") as tmp:
        root = Path(tmp)
        path = write_inputs(root, inputs)
        try:
            # the CLI's checks, on the absolute path (no chdir: the server has many threads)
            check(kind, root / path, inputs.get("parameters") or {}, options, root)
        except ScenarioError as exc:
            prefix = os.path.realpath(tmp) + os.sep
            clean = lambda text: text.replace(prefix, "").replace(tmp + os.sep, "")  # noqa: E731
            raise ScenarioError(clean(exc.file), [Problem(p.key, clean(p.reason)) for p in exc.problems]) from None


def rung_view(report) -> dict:
    """A rung's report for the job's progress (the plan.json entry without its controls, durations and states)."""
    from planner.ladder import rung_json

    data = rung_json(report)
    data["controls"] = len(report.durations)
    del data["durations"], data["states"]
    return data


#: Seconds between a simulate job's looks at whether it should stop.
STOP_POLL_S = 0.25


@contextlib.contextmanager
def _interrupt_when(stop: Callable[[], bool] | None) -> Iterator[None]:
    """While the block runs, a thread asks `stop()` every STOP_POLL_S and, when it says so,
    stops the deferred loops as Ctrl-C would (planner.interrupt.ask): a simulation's rollout
    reads that flag between its chunks. The flag is cleared after (a worker runs many jobs)."""
    from planner import interrupt

    if stop is None:
        yield
        return
    done = threading.Event()

    def watch() -> None:
        while not done.wait(STOP_POLL_S):
            if stop():
                interrupt.ask()
                return

    watcher = threading.Thread(target=watch, name="ladder-job-stop", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        done.set()
        watcher.join()
        interrupt.reset()


def run(
    kind: str,
    inputs: dict,
    options: dict,
    *,
    progress=None,
    rung_done=None,
    job_progress: Callable[[dict], None] | None = None,
    stop: Callable[[], bool] | None = None,
):
    """Run a job from its inputs: (the result file's text, complete). A plan's text is plan.json
    (planner.ladder.plan_json_text, as `ladder plan` writes it); a simulation's is the JSON
    `ladder simulate --json` prints; a sweep's is the sweep.json `ladder sweep` writes.
    `progress(rung, iterations, propagations)` and `rung_done(report)` follow a plan,
    `job_progress(data)` a sweep ({runs_done, runs}, {refine_step, brackets}) and a simulation
    ({steps_done, steps}); `stop()` True ends the job, keeping what is done."""
    from planner import cli

    with job_folder(inputs) as path:
        try:  # a sweep's check loads the scenario at every grid point (seconds for 10,000): a stop ends it too
            with _interrupt_when(stop):
                args, checked = check(kind, path, inputs.get("parameters") or {}, options, Path(OUT))
        except KeyboardInterrupt:
            return None, False
        if kind == "plan":
            from planner.ladder import plan_json_text

            scenario, names = checked
            result = cli.ladder_for(scenario, names, args, progress=progress, stop=stop, rung_done=rung_done)
            return plan_json_text(result), result.complete
        if kind == "sweep":

            def on_progress(data: dict) -> None:
                if job_progress is not None:
                    job_progress(data)
                if stop is not None and stop():
                    raise KeyboardInterrupt  # the sweep stops between runs, keeping them

            result, interrupted = cli._run_sweep(args, *checked, on_progress=on_progress)
            cli._write_sweep_outputs(args, checked[0], result, checked[2], reword=lambda text: _cli_reason(kind, text))
            return (args.out / "sweep.json").read_text(), not interrupted
        scenario, plan_controls, h, duration, total = checked
        with _interrupt_when(stop):
            steps = None if job_progress is None else (lambda done, total: job_progress({"steps_done": done, "steps": total}))
            result = cli._run_simulation(args, scenario, plan_controls, h, duration, total, on_progress=steps)
        if result is None:
            return None, False
        summary = cli._simulation_summary(args, scenario, result, h, duration)
        if summary["not_in_ladder"]:  # ("unless --step": the request's options.step)
            summary["not_in_ladder"] = _cli_reason(kind, summary["not_in_ladder"])
        return json.dumps(summary, indent=2) + "\n", True

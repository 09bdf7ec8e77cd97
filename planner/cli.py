"""The ``ladder`` command line.

Exit codes: 0 ok, 1 the task failed (no plan), 2 bad input (message names file, key, reason),
130 interrupted. Human-readable output by default; ``--json`` prints one JSON object.
"""

from __future__ import annotations

import argparse
import atexit
import errno
import functools
import importlib.util
import json
import math
import os
import socket
import stat
import sys
import tempfile
from contextlib import contextmanager, suppress
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from models import perfmap
from models.family import PROPAGATING_RUNGS, RUNG_NAMES, control_steps
from models.kernel_cache import kernels_cached
from models.scenario import TRANSLATIONAL_DOFS, Problem, Scenario, ScenarioError, load_scenario, parse_overrides, penetration_warning
from models.schema import CONTROL_PLANNERS, MAX_ITERATIONS, MAX_SEED
from models.task import OUTCOME_LABELS
from planner import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK

#: The most runs one sweep may do (planner.sweep.MAX_RUNS, without importing it for --help).
MAX_RUNS = 1_000_000

#: Subcommands the design reserves whose machinery is not built yet, with what they will do.
RESERVED: dict[str, str] = {}


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose usage errors are bad input as every other: its usage, then
    `error: command line: --flag: reason` (and with --json the problem as JSON on stdout, `main`),
    not `ladder plan: error: argument --flag: ...` that a grep for ^error: misses. An option
    that takes one value takes it once (`_Once`)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.register("action", None, _Once)  # (argument groups share the parser's registry)
        self.register("action", "store", _Once)

    def parse_known_args(self, args=None, namespace=None):
        self._given = list(sys.argv[1:] if args is None else args)  # (what `error` looks through)
        self._once = {}  # (what `_Once` saw in this parse)
        return super().parse_known_args(args, namespace)

    def parse_args(self, args=None, namespace=None):
        """argparse's, but an unknown argument is the command's usage error, with its usage line
        (`ladder plan x --bogus` had printed `usage: ladder [-h] COMMAND ...`)."""
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            commands = [a for a in self._actions if isinstance(a, argparse._SubParsersAction)]  # noqa: SLF001
            chosen = commands[0].choices.get(getattr(parsed, commands[0].dest, None)) if commands else None
            (chosen or self).error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed

    def error(self, message: str):
        self.print_usage(sys.stderr)
        flag, colon, reason = message.removeprefix("argument ").partition(": ")
        problems = [Problem(flag, reason) if message.startswith("argument ") and colon else Problem("", message)]
        if message.startswith("the following arguments are required"):  # argparse stops there: an unknown flag too
            known, given = list(self._option_string_actions), getattr(self, "_given", [])
            given = given[: given.index("--")] if "--" in given else given  # (after it: positionals)
            names = [text.partition("=")[0] for text in given]
            unknown = [n for n in names if n.startswith("--") and len(n) > 2 and not any(option.startswith(n) for option in known)]
            problems[:0] = [Problem(name, "no such option") for name in unknown]
        raise ScenarioError("command line", problems)


class _Once(argparse.Action):
    """A value given at most once, every `_Parser` option's that takes one value (argparse's
    `store`): a second is refused, not silently the one that counts (`simulate --model A
    --model B` had run B alone, `plan --seed 1 --seed 2` planned seed 2)."""

    def __call__(self, parser, namespace, values, option_string=None):
        seen = parser._once  # (`_Parser.parse_known_args` starts it empty for each parse)
        if self.dest in seen and option_string is not None:
            parser.error(f"argument {option_string}: given twice ({seen[self.dest]} and {values}); it takes one")
        seen[self.dest] = values
        setattr(namespace, self.dest, values)


def build_parser() -> argparse.ArgumentParser:
    """The `ladder` argument parser, one subparser per command."""
    parser = _Parser(
        prog="ladder",
        description="Hierarchical manipulation planning: plan with the cheapest contact model, "
        "then upgrade the model and replan until the plan holds under the highest-fidelity one.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    _add_check_parser(sub)
    _add_schema_parser(sub)
    _add_simulate_parser(sub)
    _add_plan_parser(sub)
    _add_sweep_parser(sub)
    _add_bench_parser(sub)
    _add_serve_parser(sub)
    _add_submit_parser(sub)
    _add_reserved_parsers(sub)
    return parser


def _add_check_parser(sub: argparse._SubParsersAction) -> None:
    """Add the `check` subcommand: validate and summarise a scenario file."""
    check = sub.add_parser(
        "check",
        help="validate a scenario file and summarise it",
        description="Validate a scenario file (structure, parameters, geometry, initial penetration) "
        "and print its bodies, coordinates, contact pairs, parameters and ladder.",
    )
    check.add_argument("file", type=Path, help="scenario file (TOML)")
    _add_param_option(check)
    check.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    check.add_argument("--out", type=Path, help="also write the JSON summary to this file (its folder must exist)")
    check.set_defaults(handler=cmd_check)


def _add_schema_parser(sub: argparse._SubParsersAction) -> None:
    """Add the `schema` subcommand: print or write the scenario JSON Schema."""
    schema = sub.add_parser(
        "schema",
        help="print the JSON Schema of scenario files",
        description="Print (or write) the JSON Schema of the scenario format, for editors such as "
        "Taplo / Even Better TOML (put '#:schema ./scenario.schema.json' on a file's first line).",
    )
    schema.add_argument("--out", type=Path, help="write the schema to this file instead of printing it (its folder must exist)")
    schema.set_defaults(handler=cmd_schema)


def _add_simulate_parser(sub: argparse._SubParsersAction) -> None:
    """Add the `simulate` subcommand: run the policy (or a plan) under one rung."""
    simulate = sub.add_parser(
        "simulate",
        help="run the scenario's policy under one rung",
        description="Run the scenario's [task.policy] (constant commanded speeds, or feedback laws) under one rung of "
        "the model family and report the outcome (goal, unsafe or none), the final state and the "
        "solver counters. Exit 0 when the run completed, 1 when a numerical failure stopped it.",
    )
    simulate.add_argument("file", type=Path, help="scenario file (TOML)")
    rungs = ", ".join(PROPAGATING_RUNGS)
    simulate.add_argument("--model", required=True, metavar="RUNG", help=f"rung: {rungs} (one; `sweep` runs several)")
    _add_param_option(simulate)
    simulate.add_argument("--duration", type=float, help="seconds to run (default: the policy's duration)")
    _add_policy_option(simulate)
    simulate.add_argument("--step", type=float, help="time step h (default: the rung's h in the ladder, else the rung's default)")
    simulate.add_argument("--json", action="store_true", help="print one JSON object")
    simulate.add_argument("--plot", type=Path, help="write a trajectory plot (.png or .svg) here; its folder must exist")
    simulate.add_argument(
        "--plan",
        type=Path,
        help="replay this plan.json's top-rung controls instead of the policy "
        "(the plan must be of this scene: same scenario, contents after parameters, and driven coordinates)",
    )
    simulate.set_defaults(handler=cmd_simulate)


def _add_policy_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--policy", metavar="NAME", help="run [task.policies] NAME instead of [task.policy]")


def _add_plan_parser(sub: argparse._SubParsersAction) -> None:
    """Add the `plan` subcommand: plan up the model ladder."""
    plan = sub.add_parser(
        "plan",
        help="plan up the model ladder",
        description="Plan with the cheapest rung, then replay the plan under each higher rung and "
        "replan where it no longer holds. Writes plan.json (per rung: controls, durations, states, "
        "report) and a plot per rung. Exit 0 when the top rung holds, 1 when no plan was found.",
    )
    plan.add_argument("file", type=Path, help="scenario file (TOML)")
    _add_param_option(plan)
    plan.add_argument("--rungs", help="comma-separated rungs (default: the scenario's ladder)")
    plan.add_argument("--top", metavar="RUNG", help="stop at this rung")
    plan.add_argument("--seed", type=int, help="seed for OMPL's and our RNG (default: the scenario's)")
    plan.add_argument(
        "--iterations",
        type=int,
        help="planner iterations per rung (the budget; default: the scenario's, [ladder] iterations = 2000 unless set)",
    )
    plan.add_argument("--planner", choices=CONTROL_PLANNERS, help="control planner (default: the scenario's)")
    plan.add_argument(
        "--time-limit",
        type=float,
        help="wall-clock cap per rung in seconds, time spent compiling kernels not counted (default: the "
        "scenario's time_limit); a safety net on top of the iteration budget: a plan is reproducible unless a "
        "cap ends a search",
    )
    plan.add_argument("--flat", action="store_true", help="plan directly at the top rung with the same budget (the baseline)")
    plan.add_argument("--no-seed-roots", action="store_true", help="replan without rooting trees at the previous plan's states")
    plan.add_argument("--no-guide", action="store_true", help="replan without sampling near the previous plan")
    plan.add_argument("--out", type=Path, default=Path("out/plan"), help="output folder, created if missing (default out/plan)")
    plan.add_argument("--json", action="store_true", help="print the plan report as one JSON object")
    plan.set_defaults(handler=cmd_plan)


def _add_sweep_parser(sub: argparse._SubParsersAction) -> None:
    """Add the `sweep` subcommand: map feasible sets over design parameters."""
    sweep = sub.add_parser(
        "sweep",
        help="map feasible sets over design parameters (the paper's Fig. 5)",
        description="Run the scenario's [task.policy] at every point of a grid of design parameters under\n"
        "each model and classify the runs by outcome: goal (Z_F), unsafe (Z_U) or none. Writes sweep.json,\n"
        "sweep.csv and a map plot (sweep.png). Ctrl-C keeps what was computed, marked incomplete.\n"
        f"At most {MAX_RUNS:,} runs (grid points x models). Exit 0 when the sweep completed (runs a solver\n"
        "failure stopped are outcome none, with their status), 2 bad input, 130 interrupted.",
        epilog="models (--model): comma-separated [LABEL=]RUNG[NAME=VALUE,...], a rung with optional\n"
        "design-parameter overrides in brackets (',' or ';' between them) and a label, each label once.\n"
        "Example, the paper's plastic and elastic impacts at mu = 0.5 (Fig. 4 (b), (c): heavy, stiffly held fingers):\n\n"
        "  F='finger_mass=1e3;finger_kp=1e9;finger_kd=2e6'\n"
        "  ladder sweep scenarios/two_finger_triangle.toml --grid v1=0.25:4:41:log --grid mu=0.5 --param v2=1 --refine \\\n"
        '      --model "plastic=dynamic-compliant[C=1e4;$F],elastic=dynamic-compliant[C=0;$F]"',
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sweep.add_argument("file", type=Path, help="scenario file (TOML)")
    sweep.add_argument(
        "--grid",
        action="append",
        default=[],
        required=True,
        metavar="NAME=START:STOP:COUNT[:log]",
        help="a grid axis over a design parameter (repeatable); NAME=V1,V2,... lists values",
    )
    _add_param_option(sweep)
    sweep.add_argument(
        "--model",
        required=True,
        action="append",
        metavar="[LABEL=]RUNG[NAME=VALUE,...][,...]",
        help="models to run (see below; repeatable), e.g. quasistatic-rigid,elastic=dynamic-compliant[C=0]",
    )
    where = sweep.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    where.add_argument("--executor", metavar="dask://HOST:PORT", help="run on a Dask distributed scheduler")
    sweep.add_argument("--refine", action="store_true", help="bisect class boundaries along grid lines")
    sweep.add_argument("--tolerance", type=float, help="refinement bracket, with --refine (relative on log axes; default 1e-3)")
    sweep.add_argument("--duration", type=float, help="seconds per run (default: the policy's duration)")
    _add_policy_option(sweep)
    sweep.add_argument("--step", type=float, help="time step h (default: each rung's h in the ladder, else the rung's default)")
    sweep.add_argument("--out", type=Path, default=Path("out/sweep"), help="output folder, created if missing (default out/sweep)")
    sweep.add_argument("--json", action="store_true", help="print the result as one JSON object")
    sweep.set_defaults(handler=cmd_sweep)


def _add_bench_parser(sub: argparse._SubParsersAction) -> None:
    """Add the `bench` subcommand: the benchmarks."""
    bench = sub.add_parser(
        "bench",
        help="benchmarks: work-precision, throughput, scaling, ladder vs flat",
        description="Measure work-precision (error against closed forms or fine-step references vs wall "
        "time), throughput (steps/s per rung on the paper's scene, and MuJoCo's on the same scene with the "
        "peers extra), scaling with the number of contacts, "
        "and the ladder against flat planning (also as OMPL benchmark logs). Writes bench.json, plots, "
        "docs/benchmarks.md (--doc) and the README's figures (--readme). --quick is a smoke run of every section.",
    )
    bench.add_argument(
        "--quick",
        action="store_true",
        help="a small version of every section (under a minute once the kernels are compiled); it plans 3 seeds "
        "unless --seeds says otherwise, and the scenes --planning gives",
    )
    bench.add_argument("--out", type=Path, default=Path("out/bench"), help="output folder, created if missing (default out/bench)")
    bench.add_argument("--doc", type=Path, help="also write the markdown report here (make bench-doc: docs/benchmarks.md)")
    bench.add_argument(
        "--readme",
        type=Path,
        help="also write the figures into this README, between its '<!-- ladder bench: headline -->' and "
        "'<!-- ladder bench: figures -->' markers and their closing '<!-- /ladder bench: ... -->' lines (make bench-doc: "
        "README.md); full runs only",
    )
    bench.add_argument(
        "--from",
        dest="saved",
        type=Path,
        metavar="BENCH_JSON",
        help="write --doc and --readme from this saved result (a run's bench.json) instead of running the benchmarks",
    )
    bench.add_argument("--json", action="store_true", help="print the results as one JSON object")
    bench.add_argument(
        "--planning",
        metavar="SCENE,...",
        help="scenes of the ladder-vs-flat section, shipped scenes by name or scenario files by path (default: "
        "two_finger_triangle,four_finger_grasp, the planar scenes; make bench-doc plans all four shipped ones: "
        "box_push_3d's and box_rotate_3d's flat runs take minutes, each scene's time is in docs/benchmarks.md)",
    )
    bench.add_argument("--seeds", type=int, default=None, metavar="N", help="seeds 1..N per planning scene (default 20; --quick: 3)")
    bench.set_defaults(handler=cmd_bench)


def _add_serve_parser(sub: argparse._SubParsersAction) -> None:
    """Add the `serve` subcommand: the planning service over HTTP."""
    serve = sub.add_parser(
        "serve",
        help="serve planning jobs over HTTP (FastAPI on uvicorn)",
        description="Run the planning service: POST /jobs with a scenario's TOML text, follow GET /jobs/{id} or its "
        "server-sent events at /jobs/{id}/events, fetch GET /jobs/{id}/result (a plan's plan.json, as `ladder plan` "
        "writes it). Jobs live in SQLite (--db) and survive a restart. API description at /docs and /openapi.json. "
        'Needs the serve extra: pip install "contact-ladder[serve]".',
    )
    serve.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1; any other needs --token)")
    serve.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    serve.add_argument("--db", type=Path, default=Path("ladder-jobs.sqlite"), help="the jobs' SQLite database (default ladder-jobs.sqlite)")
    where = serve.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=1, help="worker processes running jobs (default 1; planning is CPU-bound)")
    where.add_argument(
        "--executor",
        metavar="dask://HOST:PORT",
        help="run the jobs on a Dask distributed scheduler instead (its workers need the planner installed; one job per "
        "worker process at a time)",
    )
    serve.add_argument("--token", help="require 'Authorization: Bearer TOKEN' on every request but /, /docs and /openapi.json")
    serve.add_argument("--max-queued", type=int, default=100, help="jobs that may wait; more get 429 (default 100)")
    serve.add_argument("--max-job-seconds", type=float, help="stop a job after this many seconds of running (default: no limit)")
    serve.set_defaults(handler=cmd_serve)


def _add_submit_parser(sub: argparse._SubParsersAction) -> None:
    """Add the `submit` subcommand: a plan job sent to a planning service (planner.service.client)."""
    submit = sub.add_parser(
        "submit",
        help="submit a plan job to a planning service (ladder serve)",
        description="Send a scenario file (and the meshes it names) to a planning service as a plan job and print "
        "the job (its id and state, as GET /jobs/{id} answers). --wait follows it to its end, showing progress on "
        "stderr; the exit code is then that of `ladder plan` (0 the top rung holds, 1 it does not or the job failed "
        "or was cancelled). 2: bad input, the service refused the job or cannot be reached. "
        'Needs httpx2 (the serve extra: pip install "contact-ladder[serve]").',
    )
    submit.add_argument("file", type=Path, help="scenario file (TOML)")
    submit.add_argument(
        "--server",
        default=os.environ.get("LADDER_SERVER", "http://127.0.0.1:8000"),
        help="the service's address (default $LADDER_SERVER, else http://127.0.0.1:8000)",
    )
    submit.add_argument("--token", default=os.environ.get("LADDER_TOKEN"), help="the service's bearer token (default $LADDER_TOKEN)")
    _add_param_option(submit)
    submit.add_argument("--seed", type=int, help="seed (default: the scenario's)")
    submit.add_argument("--flat", action="store_true", help="plan directly at the top rung (the baseline)")
    submit.add_argument("--wait", action="store_true", help="follow the job until it ends (its events), showing progress on stderr")
    submit.add_argument("--json", action="store_true", help="print the job as one JSON object")
    submit.set_defaults(handler=cmd_submit)


def _add_reserved_parsers(sub: argparse._SubParsersAction) -> None:
    """Add the reserved subcommands (RESERVED), which say they are not built yet."""
    for name, what in RESERVED.items():
        reserved = sub.add_parser(name, help=f"(not built yet) {what}", description=f"Not built yet: {what}.")
        reserved.add_argument("args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
        reserved.set_defaults(handler=cmd_reserved)


def _add_param_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override a design parameter of the file (repeatable)",
    )


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except ScenarioError as exc:  # (`_Parser.error`: no namespace to read --json from, or its abbreviation)
        return _bad_input(exc, any(a.startswith("--j") and "--json".startswith(a) for a in (sys.argv[1:] if argv is None else argv)))
    from planner import interrupt

    interrupt.install()
    if os.environ.get(perfmap.ENV):  # name the compiled kernels for `perf report` (models.perfmap)
        atexit.register(_write_perf_map)
    try:
        return args.handler(args)
    except ScenarioError as exc:
        return _bad_input(exc, getattr(args, "json", False))
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except SystemError:
        # Ctrl-C landed inside a compiled kernel outside a deferred block: numba reports "a
        # result with an exception set"; it is still only an interrupt
        if not interrupt.asked():
            raise
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # the reader went away (e.g. `| head`): nothing more to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK


def _bad_input(exc: ScenarioError, as_json: bool) -> int:
    """Report bad input: with --json also as one object on stdout (a script reading it gets the
    problems too), always as `error:` lines on stderr; EXIT_BAD_INPUT."""
    if as_json:
        print(json.dumps(exc.to_json(), indent=2))
    _print_error(exc)
    return EXIT_BAD_INPUT


def _print_error(exc: Exception) -> None:
    """Bad input on stderr: `error:` before each of its lines (a problem each; a grep for ^error: finds every one)."""
    print("\n".join(f"error: {line}" for line in str(exc).splitlines()), file=sys.stderr)


def _write_perf_map() -> None:
    print(f"perf map: {perfmap.write_perf_map()}", file=sys.stderr)


# ----------------------------------------------------------------------------- commands


def load_from_args(args: argparse.Namespace, problems: list[Problem] | None = None) -> Scenario:
    """The scenario of the command line; when it does not load, its problems and `problems`
    (the other arguments' checked so far) are reported together."""
    if problems is not None:
        problems += _repeated_params(args.param)
    try:  # --policy (simulate, sweep): run one of [task.policies] instead of [task.policy]
        scenario = load_scenario(args.file, parse_overrides(args.param), override_key="--param {}")
        return scenario.with_policy(getattr(args, "policy", None))
    except ScenarioError as exc:
        if not problems:
            raise
        raise ScenarioError(exc.file, exc.problems + problems) from None


def _repeated_params(items: list[str] | None) -> list[Problem]:
    """A --param name given more than once (the last had been taken, silently)."""
    values: dict[str, list[str]] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if sep:
            values.setdefault(name.strip(), []).append(value.strip())
    counts = {2: "twice", 3: "three times"}
    return [
        Problem(f"--param {name}", f"given {counts.get(len(given), f'{len(given)} times')} ({' and '.join(given)}); give it once")
        for name, given in values.items()
        if len(given) > 1
    ]


def cmd_check(args: argparse.Namespace) -> int:
    problems = check_out_file("--out", args.out)
    scenario = load_from_args(args, problems)
    if problems:
        raise ScenarioError(scenario.path, problems)
    summary = scenario.summary()
    summary["task"]["goal_reach"] = None  # (None: no plan to reach it, as --json's other keys are there)
    if scenario.actuated and not summary["task"]["unplannable"]:  # (else there is no plan to reach it)
        from planner.ompl_adapter import goal_reach

        with announcing_compile(CHECK_COMPILE_NOTE):  # (a first run: its geometry's kernels)
            summary["task"]["goal_reach"] = goal_reach(scenario)
    if args.out:
        write_atomic(args.out, json.dumps(summary, indent=2) + "\n")
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print_summary(summary)
        if args.out:
            print(f"summary written to {args.out}")
    return EXIT_OK


def cmd_schema(args: argparse.Namespace) -> int:
    from models.schema import json_schema

    problems = check_out_file("--out", args.out)
    if problems:
        raise ScenarioError("ladder schema", problems)
    text = json.dumps(json_schema(), indent=2) + "\n"
    if args.out:
        write_atomic(args.out, text)
        print(f"schema written to {args.out}")
    else:
        print(text, end="")
    return EXIT_OK


#: The most steps one simulate run (or one sweep run) may take: more is a typo in --step.
MAX_STEPS = 10**9


def _many_steps(count: float) -> str:
    """A run's step count past MAX_STEPS, in words: "1e+10 steps" (or, past a float, too many to count)."""
    return f"{count:.3g} steps" if count < float("inf") else "too many steps to count"


def _plan_arrays(path: Path, rung: dict, key: str, width: int, expected: str) -> tuple[np.ndarray, np.ndarray]:
    """A plan rung's controls (one row of `width` finite numbers per duration) and durations
    (numbers; `read_plan` checks their values), as arrays; else bad input naming the key."""

    def number(value) -> bool:
        return isinstance(value, int | float) and not isinstance(value, bool)

    raw_controls, raw_durations = rung.get("controls"), rung.get("durations")
    if not isinstance(raw_durations, list) or not all(number(d) for d in raw_durations):
        raise ScenarioError(path, [Problem(f"{key}.durations", f"must be a list of numbers (seconds); {expected}")])
    if not isinstance(raw_controls, list) or len(raw_controls) != len(raw_durations):
        count = f"{len(raw_controls)} controls" if isinstance(raw_controls, list) else "no list of controls"
        raise ScenarioError(path, [Problem(f"{key}.controls", f"{count} for {len(raw_durations)} durations; {expected}")])
    for k, row in enumerate(raw_controls):
        if not isinstance(row, list) or len(row) != width or not all(number(v) for v in row):
            raise ScenarioError(
                path,
                [
                    Problem(
                        f"{key}.controls[{k}]",
                        f"a control is a list of {width} numbers (one per driven coordinate), got {json.dumps(row)[:80]}",
                    )
                ],
            )
        for j, value in enumerate(row):
            if not math.isfinite(value):
                raise ScenarioError(path, [Problem(f"{key}.controls[{k}][{j}]", f"must be a finite number, got {value}")])
    return np.array(raw_controls, float).reshape(len(raw_durations), width), np.array(raw_durations, float)


def read_plan(path: Path, scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """The last rung's controls and durations of a plan.json that has any (the top rung's, unless
    it failed with none or the plan was interrupted), which must be of this scene
    (same scenario name, contents after parameters, driven coordinates); else bad input."""
    from planner.ladder import scene_mismatch

    expected = "expected a plan.json that `ladder plan` wrote"
    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        raise ScenarioError(path, [Problem("--plan", f"cannot read the plan file: {exc.strerror or exc}")]) from None
    except ValueError as exc:
        raise ScenarioError(path, [Problem("--plan", f"not JSON ({exc}); {expected}")]) from None
    try:
        index = [i for i, r in enumerate(data["rungs"]) if r.get("durations")][-1]
    except (KeyError, IndexError, TypeError, AttributeError):
        raise ScenarioError(path, [Problem("rungs", f"no rung with controls; {expected}")]) from None
    reasons = scene_mismatch(data.get("scene"), scenario)  # (first: another scene's controls may be of another width)
    if reasons:
        raise ScenarioError(path, [Problem("scene", f"not a plan of {scenario.path}: {reason}") for reason in reasons])
    controls, durations = _plan_arrays(path, data["rungs"][index], f"rungs[{index}]", len(scenario.actuated), expected)
    bad = [k for k, d in enumerate(durations) if not (0.0 < d < float("inf"))]
    if bad:
        k = bad[0]
        more = f" ({len(bad) - 1} more)" if len(bad) > 1 else ""
        raise ScenarioError(
            path,
            [
                Problem(
                    f"rungs[{index}].durations[{k}]", f"a control's duration must be a positive number of seconds, got {durations[k]}{more}"
                )
            ],
        )
    return controls, durations


def cmd_simulate(args: argparse.Namespace) -> int:
    """`ladder simulate`: run the policy (or a plan) under one rung, plot it if asked, and report."""
    scenario, plan_controls, h, duration, total = _check_simulate_args(args)
    result = _run_simulation(args, scenario, plan_controls, h, duration, total)
    if result is None:
        return EXIT_INTERRUPTED
    with _writing_results():
        summary = _simulation_summary(args, scenario, result, h, duration)
        if args.plot:
            from planner.plots import plot_rollouts

            plot_rollouts(
                args.plot,
                scenario,
                [(args.model, result.times, result.trajectory)],
                f"{scenario.spec.scenario.name}: {args.model}, h = {h:g}, outcome {result.outcome}",
            )
            summary["plot"] = str(args.plot)
        if args.json:
            print(json.dumps(summary, indent=2))
        else:
            print_simulation(summary)
    return EXIT_OK if result.ok else EXIT_FAILED


@contextmanager
def _writing_results():
    """A command's results written whole: a Ctrl-C meanwhile is said after them (`interrupt.shielded`);
    the command's exit code is its results' (they are complete)."""
    from planner import interrupt

    with interrupt.shielded():
        yield
    if interrupt.held():
        print("interrupted after the results were complete: they are written whole", file=sys.stderr, flush=True)


def _check_simulate_args(args: argparse.Namespace):
    """Load and check simulate's arguments: (scenario, plan controls or None, h, duration, steps); else bad input."""
    problems = check_out_file("--plot", args.plot, PLOT_SUFFIXES)
    scenario = load_from_args(args, problems)
    policy = scenario.spec.task.policy
    if args.model not in RUNG_NAMES:
        problems.append(Problem("--model", f"unknown rung {args.model!r}; rungs: {', '.join(RUNG_NAMES)}"))
    elif args.model == "geometric":
        problems.append(Problem("--model", "the geometric rung is a validity check with no dynamics to simulate"))
    plan_controls = None
    if args.plan is not None and args.policy is not None:  # (the policy is part of the scene a plan was made for)
        problems.append(Problem("--policy", "a plan's controls replace the policy; --policy goes without --plan"))
    elif args.plan is not None:
        plan_controls = read_plan(args.plan, scenario)
        if args.duration is not None:
            problems.append(Problem("--duration", "a plan's controls carry their own durations; --duration goes with the policy"))
    elif policy is None:
        problems.append(Problem("task.policy", "simulate runs the scenario's policy, and this file has none"))
    if any(p.key == "--model" for p in problems):
        h = None  # no step to look for
    else:
        h = args.step if args.step is not None else scenario.rung_settings(args.model).h
    if h is not None and not (h > 0 and h < float("inf")):
        problems.append(Problem("--step", f"must be a positive number, got {h}"))
        h = None
    duration = args.duration if args.duration is not None else (policy.duration if policy else None)
    if plan_controls is not None:
        duration = math.fsum(plan_controls[1])  # (correctly rounded: 90 controls of 0.05 s are 4.5 s, not 4.499999999999998)
    if duration is not None and not (duration > 0 and duration < float("inf")):
        problems.append(Problem("--duration", f"must be a positive number, got {duration}"))
        duration = None
    total = 0
    # the flag that set the run's length: --step, else --duration (or the plan's), else the policy's
    length_key = "--step" if args.step is not None else "--duration" if args.duration is not None else "task.policy.duration"
    if plan_controls is not None and args.step is None:
        length_key = "--plan"
    if h is not None and duration is not None and duration / h > MAX_STEPS:  # (before counting: 1e308 / 1e-3 is inf)
        total = duration / h
    elif h is not None and duration is not None:
        durations = plan_controls[1] if plan_controls is not None else [duration]
        per_control = control_steps(durations, h)
        total = sum(per_control)
        idle = [d for d, n in zip(durations, per_control) if n == 0]
        if idle and plan_controls is not None:
            problems.append(
                Problem(
                    length_key,
                    f"at h = {h:g}, {len(idle)} of the plan's {len(durations)} controls (the shortest {min(idle):g} s) "
                    "would take no step (a control takes round(duration / h) steps); use a smaller --step",
                )
            )
        elif idle:
            problems.append(
                Problem(
                    length_key,
                    f"{duration:g} s at h = {h:g} is no step (a run takes round(duration / h) steps); "
                    "use a smaller --step or a longer --duration",
                )
            )
    if total > MAX_STEPS:
        problems.append(
            Problem(
                length_key,
                f"{duration:g} s at h = {h:g} is {_many_steps(total)}, more than the {MAX_STEPS:.0e} "
                "one run may take; use a larger --step or a shorter --duration",
            )
        )
    if problems:
        raise ScenarioError(scenario.path, problems)
    return scenario, plan_controls, h, duration, total


def _run_simulation(args: argparse.Namespace, scenario: Scenario, plan_controls, h: float, duration: float, total: int, on_progress=None):
    """Run the policy's (or the plan's) controls under the rung; None when Ctrl-C stopped it (said
    on stderr). `on_progress(steps_done, steps)` after each chunk (a service job's progress)."""
    from models.rungs import policy_controls, rung_for
    from planner import interrupt

    rung = rung_for(scenario, args.model)
    if not args.json:
        say_unlisted_rungs(scenario, [args.model], step=args.step)
        say_velocity_dropped(scenario, [args.model])
    state = rung.initial_state(scenario)
    laws = plan_controls is None  # the policy's feedback laws (a plan's controls are open loop)
    controls, durations = plan_controls if plan_controls is not None else policy_controls(scenario, duration)
    live = sys.stderr.isatty() and not args.json
    with interrupt.deferred():
        announce_compile()
        rung.rollout(scenario, state, controls[:1], [h], h)  # load the compiled kernels before timing
        quiet = getattr(args, "quiet", False)  # (a service job: its events say it, not the server's log)
        if not quiet and (not args.json or total > PROGRESS_STEPS):
            # each control runs whole steps (`control_steps`): say so where that is not the duration asked for
            whole = abs(total * h - duration) <= 1e-9 * duration
            span = f"{duration:g} s" if whole else f"{duration:g} s run as {total * h:g} s of whole steps"
            print(f"simulating {counted(total, 'step')} of {args.model} (h = {h:g}, {span}; Ctrl-C stops)", file=sys.stderr, flush=True)
        try:
            interrupt.check()
            return run_with_progress(rung, scenario, state, controls, durations, h, live=live, laws=laws, on_progress=on_progress)
        except KeyboardInterrupt as stop:
            done = getattr(stop, "steps_done", 0)
            if not quiet:
                print(f"interrupted after {done:,} of {total:,} steps; nothing written", file=sys.stderr, flush=True)
            return None


def counted(n: int, noun: str) -> str:
    """`n noun`, the noun plural unless n is 1, the count with thousands separators: 1 step, 14,779 steps."""
    return f"{n:,} {noun}{'' if n == 1 else 's'}"


def say_unlisted_rungs(scenario: Scenario, names, step_flag: bool = True, step: float | None = None) -> None:
    """`unlisted_rung_note` of each rung named (once each), on stderr."""
    for name in dict.fromkeys(names):
        note = unlisted_rung_note(scenario, name, step_flag, step)
        if note:
            print(note, file=sys.stderr, flush=True)


def say_velocity_dropped(scenario: Scenario, names) -> None:
    """On stderr, where the scene starts moving (`task.velocity`) and a rung named runs without
    velocity state: its run starts at rest (a trial's expectation of `none` had passed so,
    silently, where the dynamic rungs slid)."""
    from models.rungs import rung_for

    if not any(scenario.start_velocity):
        return
    for name in dict.fromkeys(names):
        if not np.any(rung_for(scenario, name).initial_state(scenario).nu):
            print(
                f"task.velocity: {name} has no velocity state (the initial velocities are the dynamic rungs'), so its run starts at rest",
                file=sys.stderr,
                flush=True,
            )


def unlisted_rung_note(scenario: Scenario, name: str, step_flag: bool = True, step: float | None = None) -> str | None:
    """What a rung the scenario's ladder does not list runs at (its family's defaults, which
    the file does not show); None for a listed rung. step_flag: the command takes --step;
    step: the --step given (the run's h, no default then)."""
    from models.rungs import rung_for

    model = rung_for(scenario, name).model
    if model is None or name in [r.model for r in scenario.spec.ladder.rungs]:
        return None
    settings = scenario.rung_settings(name)
    quasistatic = model.eps == 0.0 and not model.kinematic
    if step is not None:
        h = ""
    else:
        h = f"h = {settings.h:g}" + (" (unless --step)" if step_flag else "") + ", "
    return (
        f"{name} is not in the scenario's ladder, so it runs at its family's defaults: {h}{settings.contact_solver}"
        + (f", {settings.friction_directions} friction directions" if scenario.spec.scene.dimension == 3 else "")
        + (f", quasistatic inertia scale {model.quasistatic_inertia:g}" if quasistatic else "")
        + "; a [[ladder.rungs]] entry would set them (and add the rung to the ladder)"
    )


def _simulation_summary(args: argparse.Namespace, scenario: Scenario, result, h: float, duration: float) -> dict[str, Any]:
    """The simulate report: the run's outcome, final state, solver counters, the largest
    penetration met at a step's start (m: a compliant contact's deformation, or a rigid contact's
    first-order error at a large step), what the result says beside its status
    (`models.rungs.run_warnings`), the family defaults a rung not in the ladder runs at, and parameters."""
    from models.rungs import run_warnings, rung_for

    return {
        "file": str(scenario.path),
        "model": args.model,
        "h": h,
        "duration": duration,
        "outcome": result.outcome,
        "t": result.t,
        "state": result.state.named(scenario),
        "velocity": {n: float(v) for n, v in zip(scenario.velocities, result.state.nu)},
        "contact_forces": result.contact_forces(scenario),
        "steps": result.steps,
        "wall_s": result.wall_s,
        "steps_per_s": result.steps / result.wall_s if result.wall_s > 0 else None,
        "status": result.status,
        "message": result.message,
        "lcp_solves": result.lcp_solves,
        "pivots": result.pivots,
        "max_residual": result.max_residual,
        "max_lcp_size": result.max_lcp_size,
        "max_penetration": result.max_penetration,
        # (the note stderr has without --json; None: in the ladder)
        "not_in_ladder": unlisted_rung_note(scenario, args.model, step=args.step),
        "warnings": run_warnings(scenario, rung_for(scenario, args.model), h, result),
        "parameters": dict(scenario.parameters),
    }


def rung_order_problems(key: str, names: list[str]) -> list[Problem]:
    """The file's check of a ladder's order (low to high fidelity, each rung once), on a list
    of rung names from the command line, with its message."""
    from types import SimpleNamespace

    from models.scenario import _check_ladder

    rung = lambda name: SimpleNamespace(model=name, h=None, planner=None, control_period=None, friction_cone=None)  # noqa: E731
    stub = SimpleNamespace(ladder=SimpleNamespace(rungs=[rung(n) for n in names], planner="RRT", control_period=1.0))
    return [Problem(key, p.reason) for p in _check_ladder(stub) if p.key.endswith(".model")]


def cmd_plan(args: argparse.Namespace) -> int:
    """`ladder plan`: plan up the ladder, write plan.json, report.json and plots, and report."""
    scenario, names = _check_plan_args(args)
    result = _run_plan(args, scenario, names)
    with _writing_results():
        report, plots = _write_plan_outputs(args, scenario, result)
        _print_plan(args, scenario, result, report, plots)
    if not result.complete:
        done = ", ".join(r.rung for r in result.rungs) or "none"
        print(f"interrupted: INCOMPLETE plan (rungs done: {done}) written to {args.out / 'plan.json'}", file=sys.stderr, flush=True)
        return EXIT_INTERRUPTED
    return EXIT_OK if result.top_holds else EXIT_FAILED


def _check_plan_args(args: argparse.Namespace) -> tuple[Scenario, list[str]]:
    """Load and check plan's arguments: (scenario, the rungs to plan with); else bad input."""
    problems = check_out_dir("--out", args.out)
    problems += positive("--iterations", args.iterations, integer=True)
    if args.iterations is not None and args.iterations > MAX_ITERATIONS:  # (a scenario's `iterations` has the same bound)
        problems.append(Problem("--iterations", f"must be at most {MAX_ITERATIONS:.0e}, got {args.iterations}"))
    problems += positive("--time-limit", args.time_limit)
    if args.seed is not None and not 0 <= args.seed <= MAX_SEED:  # (a scenario's `seed` has the same range)
        problems.append(Problem("--seed", f"must be between 0 and {MAX_SEED}, got {args.seed}"))
    scenario = load_from_args(args, problems)
    names = [r.model for r in scenario.spec.ladder.rungs]
    if args.rungs is not None:
        names = [n.strip() for n in args.rungs.split(",") if n.strip()]
        bad = [n for n in names if n not in RUNG_NAMES]
        if bad:
            problems.append(Problem("--rungs", f"unknown rung(s) {', '.join(bad)}; rungs: {', '.join(RUNG_NAMES)}"))
        elif not names:
            problems.append(Problem("--rungs", "no rungs given"))
        else:
            problems += rung_order_problems("--rungs", names)
    if args.top is not None:
        if args.top not in RUNG_NAMES:
            problems.append(Problem("--top", f"unknown rung {args.top!r}"))
        elif args.top not in names and all(n in RUNG_NAMES for n in names):
            # the ladder would stop below it, and report that rung as the top that holds
            listed = "--rungs" if args.rungs is not None else "the scenario's ladder"
            problems.append(Problem("--top", f"{args.top} is not in {listed} ({', '.join(names)}); add it with --rungs"))
        else:
            names = [n for n in names if n in RUNG_NAMES and RUNG_NAMES.index(n) <= RUNG_NAMES.index(args.top)]
    if problems:
        raise ScenarioError(scenario.path, problems)
    return scenario, names


def _run_plan(args: argparse.Namespace, scenario: Scenario, names: list[str]):
    """Run the ladder over `names`, showing progress on stderr; Ctrl-C ends the rung under way."""

    live = sys.stderr.isatty() and not args.json
    if not args.json:
        say_unlisted_rungs(scenario, names, step_flag=False)
    from planner.ladder import rung_budgets

    budgets = rung_budgets(scenario, names, args.iterations, args.time_limit, args.flat)[0]

    def progress(name: str, iterations: int, propagations: int) -> None:
        """One live line on a terminal (stderr); one line per rung otherwise."""
        if args.json:
            return
        if live:
            print(
                f"\rplanning {name}: {iterations}/{budgets.get(name, 0)} iterations, {propagations} propagations   ",
                end="",
                file=sys.stderr,
                flush=True,
            )
        elif iterations == 0:
            print(f"planning: {name} ...", file=sys.stderr, flush=True)

    from planner import interrupt
    from planner.ladder import check_start

    with interrupt.deferred():  # Ctrl-C ends the rung under way; the rungs done are kept
        check_start(scenario)  # the start's checks (the ladder repeats them), before the folder is made
        problems = make_out_dir("--out", args.out)
        if problems:
            raise ScenarioError(scenario.path, problems)
        announce_compile(planning=True)  # (after the checks: bad input is its one line)
        with announcing_search_compile():
            result = ladder_for(scenario, names, args, progress=progress, stop=interrupt.asked, rung_done=lambda report: interrupt.keep())
    if live:
        print("\r" + " " * 78 + "\r", end="", file=sys.stderr, flush=True)
    return result


def _write_plan_outputs(args: argparse.Namespace, scenario: Scenario, result) -> tuple[dict, list[str]]:
    """Write plan.json, report.json and a plot per planned rung: (the report, the plots' paths).
    Each rung's plan is replayed under it from the start for its plot, and report.json gives
    what that replay says beside its status (`models.rungs.run_warnings`)."""
    from models.rungs import run_warnings, rung_for
    from planner.ladder import plan_json_text
    from planner.plots import plot_rollouts

    report = result.to_json()
    runs = []
    for entry, rung_report in zip(report["rungs"], result.rungs):  # (report.json only: plan.json is the plan)
        rung = rung_for(scenario, rung_report.rung)
        entry["not_in_ladder"] = unlisted_rung_note(scenario, rung_report.rung, step_flag=False)  # (stderr's note; None: listed)
        if rung.propagates and rung_report.durations:
            h = rung_report.h
            replay = rung.rollout(
                scenario, rung.initial_state(scenario), np.array(rung_report.controls), np.array(rung_report.durations), h
            )
            entry["warnings"] = run_warnings(scenario, rung, h, replay)
            runs.append((rung_report, replay.times, replay.trajectory))
            continue
        # no plan to replay, or the geometric path: what the rung's own runs recorded
        entry["warnings"] = [w for w in (penetration_warning(scenario, rung_report.max_penetration),) if w]
        if rung_report.durations:  # the geometric path itself
            runs.append((rung_report, np.concatenate([[0.0], np.cumsum(rung_report.durations)]), np.array(rung_report.states)))
    # plan.json is reproducible (no timings): the same seed gives the same bytes
    write_atomic(args.out / "plan.json", plan_json_text(result))
    write_atomic(args.out / "report.json", json.dumps(report, indent=1) + "\n")
    plots = []
    for rung_report, times, trajectory in runs:
        path = plot_rollouts(
            args.out / f"plan.{rung_report.label}.png",
            scenario,
            [(rung_report.label, times, trajectory)],
            f"{scenario.spec.scenario.name}: plan under {rung_report.label}",
        )
        plots.append(str(path))
    return report, plots


def ladder_for(scenario: Scenario, names, args: argparse.Namespace, *, progress=None, stop=None, rung_done=None):
    """`run_ladder` with the options of `ladder plan` (checked `args`): the CLI's and the service's."""
    from planner.ladder import run_ladder

    return run_ladder(
        scenario,
        rungs=names,
        seed=args.seed,
        iterations=args.iterations,
        progress=progress,
        flat=args.flat,
        planner=args.planner,
        time_limit=args.time_limit,
        seeded=not args.no_seed_roots,
        guided=not args.no_guide,
        stop=stop,
        rung_done=rung_done,
    )


def budget_words(budget: dict) -> str:
    """A plan's budget (`LadderResult.budget`) in words: "2,000 iterations a rung", "flat:
    8,000 iterations at dynamic-rigid", or each rung's where they differ."""
    counts = budget.get("iterations") or {}
    if not counts:
        return "no budget"
    if budget.get("flat"):
        ((rung, n),) = counts.items()
        return f"flat: {n:,} iterations at {rung}"
    if len(set(counts.values())) == 1:
        return f"{next(iter(counts.values())):,} iterations a rung"
    return "iterations " + ", ".join(f"{rung} {n:,}" for rung, n in counts.items())


def _print_plan(args: argparse.Namespace, scenario: Scenario, result, report: dict, plots: list[str]) -> None:
    """Print the plan report: one JSON object, or a table per rung and where the plan went."""
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        from rich.table import Table

        table = Table(title=f"ladder on {scenario.path} (seed {result.seed}; {budget_words(result.budget)})", title_justify="left")
        for col in (
            "rung",
            "ended",
            "outcome",
            "wall s",
            "tracked",
            "rollouts",
            "props",
            "iters",
            "goal dist m",
            "max pen m",
            "force steps",
            "fails",
            "controls",
        ):
            table.add_column(col, no_wrap=True)
        for r in result.rungs:
            distance = "-" if r.goal_distance is None else f"{r.goal_distance:.2g}"
            table.add_row(
                r.label,
                r.ended.label,
                r.outcome,
                f"{r.wall_s:.2f}",
                "-" if r.tracked is None else f"{r.tracked:.0%}",
                str(r.rollouts),
                str(r.propagations),
                str(r.iterations),
                distance,
                f"{r.max_penetration:.1e}",
                str(r.contact_steps),
                str(r.solver_failures),
                str(len(r.durations)),
            )
        console = _console(width=130)
        console.print(table)
        compiling = sum(r.compile_s for r in result.rungs)
        if compiling >= 0.1:
            console.print(f"(wall s includes {compiling:.1f} s compiling or loading the physics kernels: `compile_s` in report.json)")
        for r, entry in zip(result.rungs, report["rungs"]):
            if r.reason:
                console.print(f"{r.label}: {r.reason}")
            for warning in entry["warnings"]:
                console.print(f"[yellow]{r.label}: warning: {warning}[/yellow]")
        if result.complete:
            print(
                f"top rung holds: {'yes' if result.top_holds else 'no'}; plan written to {args.out / 'plan.json'}; "
                f"plots: {', '.join(plots) or 'none'}"
            )


#: A rollout longer than this many steps shows a progress bar (on a terminal).
PROGRESS_STEPS = 200_000


def run_with_progress(rung, scenario, state, controls, durations, h, *, live: bool, laws: bool = False, on_progress=None):
    """The rollout in chunks of bounded wall time (`Rung.rollout_chunked`, the same result as
    one call; laws: as there): Ctrl-C stops it between chunks (KeyboardInterrupt, with
    `steps_done`), and on a terminal a long one shows steps done / total, the rate and the time left."""
    from planner import interrupt

    total = sum(control_steps(durations, h))
    bar = None
    if live and total > PROGRESS_STEPS:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        bar = Progress(
            TextColumn("{task.description}"),
            BarColumn(bar_width=15),
            MofNCompleteColumn(),
            TextColumn("{task.fields[rate]}"),
            TimeRemainingColumn(),
            console=_console(stderr=True),
            transient=True,
        )
        task = bar.add_task(rung.name, total=total, rate="steps")
        bar.start()

    def progress(done: int, total: int, wall: float) -> None:
        if bar is not None:
            bar.update(task, completed=done, rate=f"steps, {done / wall:,.0f}/s" if wall > 0 else "steps")
        if on_progress is not None:
            on_progress(done, total)
        if interrupt.asked():
            stop = KeyboardInterrupt()
            stop.steps_done = done
            raise stop

    try:
        return rung.rollout_chunked(scenario, state, controls, durations, h, progress=progress, laws=laws)
    finally:
        if bar is not None:
            bar.stop()


#: What a run with numba's cache cold says first. `make demo` from an empty cache took 9.5 min on
#: this 2-core machine, the venv's install included, its second core compiling the general contact
#: step (`models.kernel_cache.compile_ahead`; ca7b1d2, docs/measurements.md).
COMPILE_NOTE = "compiling the physics kernels (first run only: about 10 minutes on two cores)"
PLAN_COMPILE_NOTE = "compiling the planners' kernels (first plan only: about a minute on two cores)"
BENCH_COMPILE_NOTE = "compiling the benchmark's kernels (first bench only: about a minute on two cores)"
SEARCH_COMPILE_NOTE = "compiling the control search's kernel (first search only: about half a minute on two cores)"
#: `check`'s, as its goal states are drawn and checked (`goal_reach`): 1.6-1.8 min in a trial, silent.
CHECK_COMPILE_NOTE = "compiling the geometry kernels (first run only: about 2 minutes on two cores)"


def announce_compile(planning: bool = False, bench: bool = False) -> None:
    """Say so (on stderr, with --json too) before the first call compiles the physics kernels
    (numba's cache is cold): otherwise the first run sits silent for minutes. planning: a plan
    also compiles the planners' kernels, which a first plan after a simulation still does (every
    plan replays and tracks with `models.rollout.rollout_each`; `propagate_kernel`, which only a
    rung's own search calls, stayed cold on scenes whose plans track up the ladder, and looking at
    it announced a compile on every plan); bench: `ladder bench` its cost split's (`stage_loop`)."""
    if not kernels_cached():
        print(COMPILE_NOTE, file=sys.stderr, flush=True)
    elif planning and not kernels_cached("rollout_each"):
        print(PLAN_COMPILE_NOTE, file=sys.stderr, flush=True)
    elif bench and not kernels_cached("stage_loop"):
        print(BENCH_COMPILE_NOTE, file=sys.stderr, flush=True)


def announcing_search_compile():
    """A context in which SEARCH_COMPILE_NOTE is printed, once, as the control search's kernel,
    `models.rollout.propagate_kernel`, starts compiling. Only a rung's own search calls that
    kernel, so `announce_compile` cannot tell before a plan whether it will: a first plan that
    searched sat silent while it compiled (23 s on free_transfer)."""
    from models import rollout

    return announcing_compile(SEARCH_COMPILE_NOTE, rollout.propagate_kernel)


def announcing_compile(note: str, kernel=None):
    """A context in which `note` is printed (stderr), once, as a kernel starts compiling (`kernel`
    only, where given; numba's `numba:compile` event, which fires where a kernel is compiled, not
    where it is loaded from the cache)."""
    from numba.core import event

    class CompileNotice(event.Listener):
        said = False

        def on_start(self, ev) -> None:
            if not self.said and (kernel is None or (ev.data or {}).get("dispatcher") is kernel):
                self.said = True
                print(note, file=sys.stderr, flush=True)

        def on_end(self, ev) -> None:
            pass

    return event.install_listener("numba:compile", CompileNotice())


def print_simulation(summary: dict[str, Any]) -> None:
    from rich.table import Table

    console = _console()
    console.print(
        f"[bold]{summary['model']}[/bold] on {summary['file']} (h = {summary['h']:g}, {summary['duration']:g} s): "
        f"outcome [bold]{summary['outcome']}[/bold] at t = {summary['t']:.4f} s, status {summary['status']}"
    )
    if summary["status"] != "ok":
        console.print(f"[red]{summary['message']}[/red]")
    for warning in summary["warnings"]:
        console.print(f"[yellow]warning: {warning}[/yellow]")
    table = Table(title="final state", title_justify="left")
    table.add_column("coordinate")
    table.add_column("q")
    table.add_column("velocity")
    velocity = summary["velocity"]
    for name, value in summary["state"].items():
        table.add_row(name, f"{value:.6g}", f"{velocity[name]:.6g}" if name in velocity else "")
    for name, v in velocity.items():
        if name not in summary["state"]:
            table.add_row(name, "", f"{v:.6g}")
    console.print(table)
    rate = summary["steps_per_s"]
    console.print(
        f"{counted(summary['steps'], 'step')} in {summary['wall_s']:.3f} s"
        + (f" ({rate:,.0f} steps/s)" if rate else "")
        + f"; {counted(summary['lcp_solves'], 'LCP solve')}, {counted(summary['pivots'], 'pivot')}, "
        f"largest LCP {summary['max_lcp_size']}, max residual {summary['max_residual']:.2e}, "
        f"largest penetration {summary['max_penetration']:.2e} m"
    )
    if "plot" in summary:
        console.print(f"plot written to {summary['plot']}")


#: The sweep's check of its grid points stops after this many bad points.
MAX_BAD_POINTS = 1000


def _sweep_setter(name: str, *, model, point: dict) -> str:
    """Which option set a sweep run's parameter, as its problems name it (`load_scenario`'s override_key)."""
    if name in dict(model.overrides):
        return f"--model {model.label}"
    return f"--grid {name}" if name in point else f"--param {name}"


def sweep_point_problems(scenario: Scenario, texts: list[str], axes, models, fixed: dict, step, duration) -> list[Problem]:
    """Every run of a sweep checked before any starts: the scenario with the point's and the
    model's parameters applied must load (the file's validation), and the run must not take
    more than MAX_STEPS steps nor none. A problem names the --grid value(s) (or --model, or the step)
    responsible, the first point it holds at and how many more points it holds at."""
    from planner import interrupt
    from planner import sweep as sw

    found: dict[tuple[str, str, str], list[str]] = {}  # (key, model, reason) -> the points
    seen, bad = set(), 0
    for model in models:
        for point in sw.grid_points(axes):
            interrupt.check()  # a service job's cancel or wall-time limit (`planner.service.jobs.run`)
            params = {**fixed, **point, **dict(model.overrides)}
            signature = tuple(sorted(params.items()))
            if signature in seen:
                continue
            seen.add(signature)
            where = ", ".join(f"{k}={v:g}" for k, v in point.items())
            try:
                setter = functools.partial(_sweep_setter, model=model, point=point)
                variant = load_scenario(scenario.path, params, override_key=setter).with_policy(model.policy)
            except ScenarioError as exc:
                reasons = "; ".join(f"{p.key}: {p.reason}" if p.key else p.reason for p in exc.problems)
                blamed = [t for t, a in zip(texts, axes) if f"from '{a.name}'" in reasons and a.name not in dict(model.overrides)]
                if any(f"from '{name}'" in reasons for name, _ in model.overrides) and not blamed:
                    key = f"--model {model.label}"
                else:
                    key = " ".join(f"--grid {t}" for t in (blamed or texts))
                found.setdefault((key, model.label, f"the scenario is invalid: {reasons}"), []).append(where)
                bad += 1
            else:
                h = step or variant.rung_settings(model.rung).h
                seconds = duration or (variant.spec.task.policy.duration if variant.spec.task.policy else 0.0)
                key = "--step" if step else "--duration" if duration else "task.policy.duration"
                if seconds / h > MAX_STEPS:
                    steps = _many_steps(seconds / h)
                    reason = f"a run of {seconds:g} s at h = {h:g} is {steps}, more than the {MAX_STEPS:.0e} one run may take"
                elif control_steps(seconds, h)[0] == 0:
                    reason = f"a run of {seconds:g} s at h = {h:g} is no step (a run takes round(duration / h) steps)"
                else:
                    reason = None
                if reason is not None:
                    found.setdefault((key, model.label, reason), []).append(where)
                    bad += 1
            if bad >= MAX_BAD_POINTS:
                break
    problems = []
    for (key, label, reason), points in found.items():
        n = len(points) - 1
        more = "" if n == 0 else f" and {n}{' or more' if bad >= MAX_BAD_POINTS else ''} more grid point{'s' if n > 1 else ''}"
        problems.append(Problem(key, f"{label} at {points[0]}{more}: {reason}"))
    return problems


def cmd_sweep(args: argparse.Namespace) -> int:
    """`ladder sweep`: run the policy over a grid of design parameters per model, write and report the classes."""
    existed = args.out.exists()
    scenario, fixed, axes, models, runs = _check_sweep_args(args)
    try:
        result, interrupted = _run_sweep(args, scenario, fixed, axes, models, runs)
    except ScenarioError:  # (a Dask scheduler out of reach, a file its workers cannot read): no empty folder left
        if not existed:
            remove_if_empty(args.out)
        raise
    with _writing_results():
        data, plot = _write_sweep_outputs(args, scenario, result, axes)
        _print_sweep(args, result, data, plot, interrupted)
    if result.error:  # (the executor was lost: a failure, not a stop)
        done = len(data["points"]) + len(data["refine_points"])
        print(f"error: the sweep ended after {counted(done, 'run')}: {result.error}", file=sys.stderr)
        print("error: the runs done are written (sweep.json: complete false, and this error); run the sweep again", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_INTERRUPTED if interrupted else EXIT_OK


def _check_sweep_args(args: argparse.Namespace):
    """Load and check sweep's arguments and every run: (scenario, fixed parameters, axes, models, runs); else bad input."""
    from planner import sweep as sw

    problems = check_out_dir("--out", args.out)
    if args.workers is not None and args.workers < 1:
        problems.append(Problem("--workers", f"must be at least 1, got {args.workers}"))
    problems += executor_problems(args.executor)
    for key, value in (("--duration", args.duration), ("--step", args.step), ("--tolerance", args.tolerance)):
        problems += positive(key, value)
    if args.tolerance is not None and not args.refine and not any(p.key == "--tolerance" for p in problems):  # (unused, silently)
        problems.append(Problem("--tolerance", "is the refinement's bracket: give it with --refine, or leave it out"))
    if args.tolerance is None:
        args.tolerance = sw.TOLERANCE
    scenario = load_from_args(args, problems)
    fixed = parse_overrides(args.param)
    for text in args.grid:
        try:
            sw.parse_axis(text)
        except ScenarioError as exc:
            problems += exc.problems
    try:  # --policy: the policy of the models that name none of their own
        models = [m if m.policy else replace(m, policy=getattr(args, "policy", None)) for m in sw.parse_models(args.model)]
    except ScenarioError as exc:
        problems += exc.problems
        models = []
    if problems:
        raise ScenarioError(scenario.path, problems)
    axes = [sw.parse_axis(text) for text in args.grid]
    for axis in axes:
        if axis.name not in scenario.parameters:
            problems.append(
                Problem(f"--grid {axis.name}", f"not a design parameter of this file; parameters: {', '.join(scenario.parameters)}")
            )
    names = [a.name for a in axes]
    for name in dict.fromkeys(n for n in names if names.count(n) > 1):
        problems.append(Problem(f"--grid {name}", "is given twice; give each axis once (one --grid NAME=VALUES)"))
    for name in dict.fromkeys(n for n in names if n in fixed):
        problems.append(
            Problem(f"--grid {name}", f"is also fixed by --param {name}={fixed[name]:g}; an axis takes its values from --grid alone")
        )
    for model in models:
        for name, _ in model.overrides:
            if name not in scenario.parameters:
                problems.append(Problem(f"--model {model.label}", f"{name!r} is not a design parameter of this file"))
        if model.policy is not None and model.policy not in scenario.spec.task.policies:
            known = ", ".join(scenario.spec.task.policies) or "none"
            problems.append(Problem(f"--model {model.label}", f"no policy named {model.policy!r} in [task.policies] ({known})"))
    if scenario.spec.task.policy is None:
        problems.append(Problem("task.policy", "a sweep runs the scenario's policy, and this file has none"))
    runs = sw.grid_size(axes) * len(models)
    if runs > sw.MAX_RUNS:
        problems.append(
            Problem(
                "--grid",
                f"{' x '.join(str(len(a.values)) for a in axes)} grid points x {len(models)} model(s) = "
                f"{runs:,} runs, more than a sweep may run ({sw.MAX_RUNS:,}); use a coarser grid (and --refine)",
            )
        )
    if problems:
        raise ScenarioError(scenario.path, problems)
    if runs > 10_000 and not args.json:
        print(f"checking the scenario at {runs:,} runs' parameters", file=sys.stderr, flush=True)
    problems = sweep_point_problems(scenario, list(args.grid), axes, models, fixed, args.step, args.duration)
    problems = problems or make_out_dir("--out", args.out)
    if problems:
        raise ScenarioError(scenario.path, problems)
    return scenario, fixed, axes, models, runs


def executor_problems(executor: str | None) -> list[Problem]:
    """--executor (of sweep and serve): dask://HOST:PORT, with the dask extra installed."""
    if executor is None:
        return []
    if not executor.startswith("dask://") or not executor.removeprefix("dask://"):
        return [Problem("--executor", "expected dask://HOST:PORT")]
    if importlib.util.find_spec("distributed") is None:
        return [Problem("--executor", 'a Dask executor needs the dask extra: install the dask extra: pip install "contact-ladder[dask]"')]
    return []


def _run_sweep(args: argparse.Namespace, scenario: Scenario, fixed: dict, axes, models, runs: int, *, on_progress=None):
    """Run the sweep (and its refinement), with a progress bar on a terminal: (result, interrupted).
    `on_progress(data)` after each run ({"runs_done", "runs"}) and refinement step ({"refine_step",
    "brackets"}): the service's sweep jobs; it may raise KeyboardInterrupt to stop the sweep,
    keeping what is done."""
    from planner import sweep as sw

    live = sys.stderr.isatty() and not args.json
    interrupted = False
    bar = None
    if live:
        from rich.progress import Progress

        bar = Progress(transient=True, console=_console(stderr=True))
        bar.start()
        task_id = bar.add_task("sweep", total=None)

    # Ctrl-C sets a flag that is acted on between runs: an interrupt inside a compiled kernel
    # cannot be raised cleanly there
    from planner import interrupt

    def progress(done: int, total: int) -> None:
        interrupt.keep()  # (a run done: a Ctrl-C as a later run compiles waits for it, keeping this one)
        if bar is not None:
            bar.update(task_id, completed=done, total=total)
        if on_progress is not None:
            on_progress({"runs_done": done, "runs": total})

    def refine_progress(step: int, active: int) -> None:
        if bar is not None:
            bar.update(task_id, description=f"refine step {step}: {active} brackets", completed=0, total=None)
        if on_progress is not None:
            on_progress({"refine_step": step, "brackets": active})

    said = []

    def stop() -> bool:
        """Ctrl-C: the runs under way finish and are kept (a second Ctrl-C stops at once)."""
        if interrupt.asked() and not said:
            said.append(True)
            notice("stopping: the runs under way finish and are kept (Ctrl-C again stops at once)")
        return interrupt.asked()

    def notice(text: str) -> None:
        if bar is not None:
            bar.console.print(text, highlight=False, markup=False)
        else:
            print(text, file=sys.stderr, flush=True)

    where = args.executor or counted(args.workers or os.cpu_count() or 1, "local worker")
    if not args.json:
        print(f"sweeping {runs} runs on {where} (Ctrl-C stops and keeps what is done)", file=sys.stderr, flush=True)
        say_unlisted_rungs(scenario, [m.rung for m in models], step=args.step)
        say_velocity_dropped(scenario, [m.rung for m in models])
        announce_compile()
    try:
        with interrupt.deferred(), sw.Executor(args.workers, args.executor, notice) as executor:
            result = sw.sweep(
                str(scenario.path),
                axes,
                models,
                fixed=fixed,
                h=args.step,
                duration=args.duration,
                executor=executor,
                progress=progress,
                stop=stop,
            )
            if result.complete and args.refine:
                result = sw.refine(result, tolerance=args.tolerance, executor=executor, progress=refine_progress, stop=stop)
    finally:
        if bar is not None:
            bar.stop()
    interrupted = not result.complete or interrupt.asked()
    result.complete = not interrupted
    return result, interrupted


def _write_sweep_outputs(args: argparse.Namespace, scenario: Scenario, result, axes, reword=str) -> tuple[dict, Any]:
    """Write sweep.json, sweep.csv and (with any points) sweep.png: (the JSON data, the plot's path or None).
    reword: the notes' words for where the options came from (a service job's: options.step)."""
    from planner import sweep as sw

    data = result.to_json()
    # the note stderr has without --json, per rung the ladder does not list
    notes = {m.rung: unlisted_rung_note(scenario, m.rung, step=args.step) for m in result.models}
    data["not_in_ladder"] = {rung: reword(note) for rung, note in notes.items() if note}
    # the whole grid's (an interrupted one's would end bands at runs not done); at grid points,
    # refined where --refine bracketed them
    if data["points"] and not data["missing"]:
        data["bands"] = {a.name: sw.bands(result, a.name) for a in axes}
    write_atomic(args.out / "sweep.json", json.dumps(data, indent=1) + "\n")
    write_atomic(args.out / "sweep.csv", result.to_csv())
    from planner.plots import plot_feasible_sets

    plot = plot_feasible_sets(args.out / "sweep.png", result) if result.points and any(result.points) else None
    return data, plot


def _edge(edge: dict, end: str) -> str:
    """A band's edge (`sweep.bands`): its value, "(grid end)" where it is the grid's last point."""
    return f"{edge[end]:.4g}" + (" (grid end)" if edge[f"{end}_is_grid_end"] else "")


def _classes_between(result) -> list[str]:
    """Lines naming the outcomes refining found between two neighbouring grid points that neither
    of them has (more than one boundary between them): unsafe | none | goal between grid points
    of unsafe and goal had been printed as a goal band alone, as if unsafe met goal."""
    groups: dict = {}
    swept = [a.name for a in result.axes if len(a.values) > 1]
    for b in result.boundaries:
        rest = tuple((n, b["at"][n]) for n in swept if n != b["axis"] and n in b["at"])
        groups.setdefault((b["model"], b["axis"], rest, b["grid_low"], b["grid_high"]), []).append(b)
    lines = []
    for (model, axis, rest, lo, hi), found in groups.items():
        if len(found) < 2:
            continue
        found.sort(key=lambda b: b["boundary"])
        inner = list(dict.fromkeys(b["high_outcome"] for b in found[:-1]))
        where = "".join(f", {n}={v:g}" for n, v in rest)
        steps = ", ".join(f"{b['low_outcome']} | {b['high_outcome']} at {b['boundary']:.4g}" for b in found)
        lines.append(f"{model}: refining found {' and '.join(inner)} between {axis} = {lo:g} and {hi:g}{where}: {steps}")
    return lines


def _outcome_counts(points) -> dict[str, dict[str, int]]:
    """Per model, how many of `points` (None: a run not done) ended in each outcome."""
    counts: dict = {}
    for p in points:
        if p is not None:
            counts.setdefault(p.model, dict.fromkeys(OUTCOME_LABELS, 0))[p.outcome] += 1
    return counts


def _print_sweep(args: argparse.Namespace, result, data: dict, plot, interrupted: bool) -> None:
    """Print the sweep: one JSON object, or the counts per model, the goal bands and where the results went."""
    if args.json:
        print(json.dumps(data, indent=2))
    else:
        counts, refined = _outcome_counts(result.points), _outcome_counts(result.refine_points)
        for model in (m.label for m in result.models):
            if model not in counts:  # (an interrupted sweep's)
                print(f"{model}: no run done")
                continue
            c, more = counts[model], refined.get(model)
            ran = ", ".join(f"{n} {o}" for o, n in (more or {}).items() if n)
            also = f" on the grid; refining's {sum(more.values())} runs: {ran}" if more else ""
            print(f"{model}: {c['goal']} goal, {c['unsafe']} unsafe, {c['none']} none{also}")
        for line in _classes_between(result):
            print(line)
        if data.get("bands"):  # along the first axis (all axes are in the JSON)
            for axis_name, per_model in list(data["bands"].items())[:1]:
                for model, rows in per_model.items():
                    for rest, edges in rows.items():
                        text = "; ".join(f"{_edge(e, 'from')} .. {_edge(e, 'to')}" for e in edges) or "none"
                        at = "" if rest == "-" else f", {rest}"  # ("-": no other axis)
                        print(f"goal band in {axis_name}, {model}{at}: {text}")
            if result.refine_tolerance is None:
                print("(the bands' edges are grid points: --refine finds the edges between them)")
        failed = sum(p is not None and p.status != "ok" for p in result.points)
        if failed:
            print(f"{failed} runs stopped on a solver failure (outcome none; their status is in the results)")
        failed = sum(p.status != "ok" for p in result.refine_points)
        if failed:
            print(f"{failed} of the {len(result.refine_points)} refinement runs stopped on a solver failure")
        flagged = sum(bool(p.warnings) for p in (*result.points, *result.refine_points) if p is not None)
        if flagged:
            print(
                f"{counted(flagged, 'run')} {'is' if flagged == 1 else 'are'} not physical, whatever the outcome (`warnings` in "
                "sweep.json): bodies passed through each other (a penetration past half the thickness of a body in contact), "
                "or a quasistatic run moved a body that nothing held or drove"
            )
        against = sum(b["low_status"] != "ok" or b["high_status"] != "ok" for b in result.boundaries)
        if against:
            print(
                f"{against} refined boundar{'y lies' if against == 1 else 'ies lie'} against a run a solver failure stopped, "
                "not between two physical outcomes (low_status, high_status in sweep.json)"
            )
        state = "" if not interrupted else "INCOMPLETE (the executor was lost), " if result.error else "INCOMPLETE (interrupted), "
        print(f"{state}results written to {args.out / 'sweep.json'}, {args.out / 'sweep.csv'}" + (f", {plot}" if plot else ""))


def cmd_bench(args: argparse.Namespace) -> int:
    from planner.bench import DEFAULT_PLANNING_SCENES, PLANNING_SCENES, load_results, read_readme, run_all, write_reports

    problems = check_out_file("--doc", args.doc) + check_out_file("--readme", args.readme)
    if args.saved is not None:  # the reports from a saved result: nothing runs
        results, more = load_results(args.saved)
        problems += more
        if args.doc is None and args.readme is None:
            problems.append(Problem("--from", "nothing to write: give --doc and/or --readme"))
        for flag, given in (("--quick", args.quick), ("--planning", args.planning is not None), ("--seeds", args.seeds is not None)):
            if given:
                problems.append(Problem(flag, "sets up a run, and --from runs nothing"))
        if results is not None:
            problems += read_readme(args.readme, bool(results["quick"]))[1]
        if problems:
            raise ScenarioError("ladder bench", problems)
        try:
            write_reports(results, args.saved.parent, args.doc, args.readme)
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as e:  # a result of another shape
            problem = Problem("--from", f"{args.saved}: not a complete `ladder bench` result ({e!r})")
            raise ScenarioError("ladder bench", [problem]) from None
        print(f"written from {args.saved}: " + " and ".join(str(p) for p in (args.doc, args.readme) if p is not None))
        return EXIT_OK
    problems += check_out_dir("--out", args.out) + read_readme(args.readme, args.quick)[1]
    scenes = DEFAULT_PLANNING_SCENES if args.planning is None else tuple(s.strip() for s in args.planning.split(",") if s.strip())
    if not scenes:
        problems.append(Problem("--planning", f"no scene given; give shipped scenes ({', '.join(PLANNING_SCENES)}) or scenario files"))
    problems += _planning_file_problems(scenes)
    if args.seeds is not None and args.seeds < 1:
        problems.append(Problem("--seeds", f"must be at least 1, got {args.seeds}"))
    problems = problems or make_out_dir("--out", args.out)
    if problems:
        raise ScenarioError("ladder bench", problems)
    announce_compile(planning=True, bench=True)

    def progress(text: str) -> None:
        if not args.json:
            print(text, file=sys.stderr, flush=True)

    results = run_all(args.out, args.doc, quick=args.quick, progress=progress, scenes=scenes, seeds=args.seeds, readme=args.readme)
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        _print_throughput(results["throughput"])
        for scene, res in results["planning"].items():
            x = res["summary"]
            print(
                f"planning {scene}: ladder {x['ladder']['success_rate']:.0%} in {x['ladder']['median_wall_s']:.3f} s, "
                f"flat {x['flat']['success_rate']:.0%} in {x['flat']['median_wall_s']:.3f} s (median)"
            )
        print(f"results written to {args.out / 'bench.json'}" + "".join(f" and {p}" for p in (args.doc, args.readme) if p))
    return EXIT_OK


def _planning_file_problems(scenes) -> list[Problem]:
    """`bench --planning`'s scenario files (the names not of a shipped scene): each must load and
    be one the ladder can plan (`ladder plan`'s checks of its start and task); and no two scenes
    may share a stem (the OMPL logs' names)."""
    from planner.bench import PLANNING_SCENES
    from planner.ladder import check_start

    problems = []
    for name in [s for s in scenes if s not in PLANNING_SCENES]:
        if not Path(name).suffix and not Path(name).exists():
            problems.append(Problem("--planning", f"unknown scene {name!r}: not a shipped scene ({', '.join(PLANNING_SCENES)}) nor a file"))
            continue
        try:
            check_start(load_scenario(name))
        except ScenarioError as exc:
            problems += [Problem(f"--planning {name}" + (f": {p.key}" if p.key else ""), p.reason) for p in exc.problems]
    stems = [Path(n).stem for n in scenes]
    problems += [
        Problem("--planning", f"two files named {stem!r}: their OMPL logs would share a name")
        for stem in sorted({s for s in stems if stems.count(s) > 1})
    ]
    return problems


def _print_throughput(throughput: dict) -> None:
    """`ladder bench`'s throughput, each figure with what it counts: the free-flight runs per rung
    and MuJoCo's beside them (a ratio is the median of per-round ratios, ours and MuJoCo's timed
    in turns: it is not the quotient of two medians printed), then the runs with contact."""
    rows = throughput["rows"]
    free = f"{rows[0]['steps']:,} steps at h = {rows[0]['h']:g}" if rows else ""
    print(
        f"throughput in free flight, {throughput['scene']} ({free}; steps with contact force: {rows[0]['contact_steps'] if rows else 0}):"
    )
    for row in rows:
        print(f"  {row['rung']:44s} {row['steps_per_s']:>12,.0f} steps/s")
    peer = throughput["peer"]
    if "skipped" in peer:
        print(f"  peer MuJoCo: skipped: {peer['skipped']}")
    else:
        ours = peer["ours"]
        for row in peer["rows"]:
            left_out = f", without {', '.join(row['inert_pairs_left_out'])}" if row["inert_pairs_left_out"] else ""
            label = f"MuJoCo {peer['version']} ({row['contact']}{left_out})"
            print(
                f"  {label:44s} {row['steps_per_s']:>12,.0f} steps/s: {ours['rung']} "
                f"is {row['ratio']:.2f}x (median of per-round ratios, timed in turns)"
            )
    contact = throughput.get("contact") or {}
    if contact.get("rows"):
        peer_name = contact.get("peer", "MuJoCo")
        print(f"throughput with contact, against {peer_name} on the same runs (median of per-round ratios, timed in turns):")
        for row in contact["rows"]:
            print(
                f"  {row['scene']}, {row['rung']}, h = {row['h']:g}, {row['contact_steps']:,} of {row['steps']:,} steps with "
                f"contact force: {row['us_per_step']:.2f} us/step, MuJoCo {row['mujoco_us_per_step']:.2f}: {row['speed_vs_mujoco']:.2f}x"
            )


#: Hosts `ladder serve` binds without a token.
LOOPBACK = ("127.0.0.1", "localhost", "::1")


def cmd_serve(args: argparse.Namespace) -> int:
    """`ladder serve`: the planning service on uvicorn (imported only here)."""
    if args.token is not None and not args.token.strip():
        print("error: --token: an empty token would let every request in; give a secret, or leave --token out", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.host not in LOOPBACK and not args.token and not args.host.startswith("127."):
        print(f"error: --host {args.host}: serving beyond this machine needs --token (every request must then carry it)", file=sys.stderr)
        return EXIT_BAD_INPUT
    problems = positive("--workers", args.workers, integer=True) + positive("--max-queued", args.max_queued, integer=True)
    problems += positive("--max-job-seconds", args.max_job_seconds)
    if not 0 <= args.port <= 65535:
        problems.append(Problem("--port", f"must be between 0 and 65535, got {args.port}"))
    problems += check_out_file("--db", args.db) + executor_problems(args.executor)
    missing = [m for m in ("fastapi", "uvicorn") if importlib.util.find_spec(m) is None]
    if missing:
        problems.append(
            Problem("ladder serve", f'needs {" and ".join(missing)}: install the serve extra: pip install "contact-ladder[serve]"')
        )
    if problems:
        raise ScenarioError("ladder serve", problems)
    sock = _bound_socket(args.host, args.port)  # (before the database is made: a port in use leaves none)

    from planner.service import create_app
    from planner.service.app import server_for

    try:
        app = create_app(
            args.db,
            workers=args.workers,
            token=args.token,
            max_queued=args.max_queued,
            max_job_seconds=args.max_job_seconds,
            executor=args.executor,
        )
    except BaseException:  # (a database in use, a scheduler out of reach)
        sock.close()
        raise
    where = f"jobs on {args.executor}" if args.executor else f"{args.workers} worker process(es)"
    port = sock.getsockname()[1]  # (--port 0: the one the system chose)
    print(f"serving on http://{args.host}:{port} (jobs in {args.db}, {where}; API at /docs, viewer at /)", file=sys.stderr, flush=True)
    from planner import interrupt

    server_for(app, host=args.host, port=args.port, log_level="info").run(sockets=[sock])  # on Ctrl-C it shuts down and returns
    if interrupt.asked():  # uvicorn hands the SIGINT back to `interrupt.handler` after its shutdown, and swallows the rest
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    return EXIT_OK


def _bound_socket(host: str, port: int) -> socket.socket:
    """The server's listening socket, bound as uvicorn binds it; bad input when it cannot be (in
    use, no such address): uvicorn had said so only after "serving on", exiting 3."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except (OSError, OverflowError) as exc:
        sock.close()
        where = f"[{host}]:{port}" if family == socket.AF_INET6 else f"{host}:{port}"
        reason = getattr(exc, "strerror", None) or exc
        key = "--host" if isinstance(exc, socket.gaierror) or getattr(exc, "errno", None) == errno.EADDRNOTAVAIL else "--port"
        raise ScenarioError("ladder serve", [Problem(key, f"cannot listen on {where}: {reason}")]) from None
    sock.set_inheritable(True)
    return sock


def cmd_submit(args: argparse.Namespace) -> int:
    """`ladder submit`: a plan job sent to a planning service, printed (and followed with --wait)."""
    repeated = _repeated_params(args.param)
    if repeated:
        raise ScenarioError("command line", repeated)
    if importlib.util.find_spec("httpx2") is None:
        raise ScenarioError(
            "ladder submit", [Problem("ladder submit", 'needs httpx2: install the serve extra: pip install "contact-ladder[serve]"')]
        )
    from planner.service.client import Client, ServiceError, job_request

    options = {"seed": args.seed} if args.seed is not None else {}
    if args.flat:
        options["flat"] = True
    body = job_request(args.file, "plan", parameters=parse_overrides(args.param), options=options)
    try:
        with Client(args.server, args.token) as client:
            job = client.submit_request(body)
            if not args.json:
                print(f"job {job['id']}: {job['state']} ({client.url}/jobs/{job['id']})", file=sys.stderr if args.wait else sys.stdout)
            if not args.wait:
                if args.json:
                    print(json.dumps(job, indent=2))
                return EXIT_OK
            try:
                job = client.wait(job["id"], on_event=_job_progress(live=sys.stderr.isatty()))
            except KeyboardInterrupt:  # only the waiting stops: say where the job goes on
                where = f"{client.url}/jobs/{job['id']}"
                print(f"interrupted: job {job['id']} goes on at the service ({where}; DELETE {where} cancels it)", file=sys.stderr)
                return EXIT_INTERRUPTED
            plan = json.loads(client.result(job["id"])) if job["result_available"] else None
    except ServiceError as exc:
        _print_error(_in_submit_words(exc, args.file))
        return EXIT_BAD_INPUT
    if args.json:
        print(json.dumps(job, indent=2))
    else:
        holds = plan is not None and plan.get("top_holds")
        from planner.plan_status import rung_label

        rungs = ", ".join(f"{rung_label(r)} {r['ended']}" for r in job.get("rungs", [])) or "none"
        error = f": {job['error']}" if job.get("error") else ""
        print(f"job {job['id']}: {job['state']}{error}; rungs: {rungs}; top rung holds: {'yes' if holds else 'no'}")
        if job["result_available"]:
            print(f"plan.json: {args.server.rstrip('/')}/jobs/{job['id']}/result")
    return EXIT_OK if job["state"] == "succeeded" and plan is not None and plan.get("top_holds") else EXIT_FAILED


def _in_submit_words(exc: Exception, file: Path) -> str:
    """The service's refusal of what `ladder submit` sent, with the lines about its flags in
    the command line's words, as `ladder plan` words them (`FILE: --param nope: ...`,
    `FILE: --seed: ...`; `planner.service.jobs.cli_flag`); every other line as the service said it."""
    from planner.service.jobs import cli_flag

    def line(text: str) -> str:
        key, sep, reason = text.removeprefix("request: ").partition(": ")
        flag = cli_flag(key) if text.startswith("request: ") and sep else None
        return f"{file}: {flag}: {reason}" if flag else text

    return "\n".join(line(text) for text in str(exc).splitlines())


def _job_progress(live: bool):
    """What `ladder submit --wait` shows of a job's events on stderr: one live line on a
    terminal, else one line per state, rung and end."""
    from planner.plan_status import rung_label

    def show(event) -> None:
        data = event.data
        if event.type == "progress":
            if live and "rung" in data:
                print(
                    f"\r{data['rung']}: {data['iterations']} iterations, {data['propagations']} propagations   ",
                    end="",
                    file=sys.stderr,
                    flush=True,
                )
            return
        text = {
            "state": lambda: f"{data.get('state')}" + (" again (the server restarted)" if data.get("requeued") else ""),
            "rung_started": lambda: f"planning: {data.get('rung')} ...",
            "rung_ended": lambda: f"{rung_label(data)}: {data.get('ended')} ({data.get('outcome')}, {data.get('iterations')} iterations)",
            "cancel_requested": lambda: "cancel requested",
            "job_ended": lambda: f"ended: {data.get('state')}" + (f" ({data['error']})" if data.get("error") else ""),
        }.get(event.type)
        if text is not None:
            print(("\r" + " " * 78 + "\r" if live else "") + text(), file=sys.stderr, flush=True)

    return show


def cmd_reserved(args: argparse.Namespace) -> int:
    print(
        f"error: 'ladder {args.command}' is not built yet ({RESERVED[args.command]}); "
        "available now: ladder check, ladder simulate, ladder plan, ladder sweep, ladder bench, ladder schema, ladder serve, ladder submit",
        file=sys.stderr,
    )
    return EXIT_BAD_INPUT


# ----------------------------------------------------------------------------- output


def write_atomic(path: Path, text: str, key: str = "--out") -> None:
    """Write via a temporary file and a rename, so a failure never leaves half a file. The
    folder must exist (the commands check it up front); the file gets the mode any new file
    gets (0666 less the umask), not mkstemp's 0600. A symbolic link is written through (the
    file it names is replaced, the link kept), and so is a device, pipe or socket (/dev/stdout,
    /dev/null: a stream, written in place; the rename would replace the node with a file). A
    folder that passed the checks but takes no file (root under /proc, a full disk) is bad input
    for `key`: a ScenarioError."""
    tmp = None
    try:
        if _is_stream(path):  # opened by its own name: /dev/stdout's target may be a pipe's
            with open(path, "w", encoding="utf-8") as handle:
                handle.write(text)
            return
        path = Path(os.path.realpath(path))
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise ScenarioError(path, [Problem(key, f"cannot write the file: {exc.strerror or exc}")]) from None
        raise


def _is_stream(path: Path) -> bool:
    """Whether `path` is (or links to) a device, pipe or socket: written in place, not replaced."""
    try:
        mode = os.stat(path).st_mode
    except OSError:  # no such file (or a dangling link): a new file
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: Plot formats --plot writes.
PLOT_SUFFIXES = (".png", ".svg")


def check_out_file(key: str, path: Path | None, suffixes: tuple[str, ...] = ()) -> list[Problem]:
    """Problems with writing a file at `path`: its folder must exist and be writable (it is not
    created), it must not be a folder, and its suffix one of `suffixes` when given."""
    if path is None:
        return []
    if path.is_dir():
        return [Problem(key, f"{path} is a folder; give a file name")]
    problems = []
    if suffixes and path.suffix.lower() not in suffixes:
        problems.append(Problem(key, f"{path}: unsupported file type {path.suffix or '(no suffix)'!r}; use {' or '.join(suffixes)}"))
    parent = Path(os.path.realpath(path)).parent  # a link's file is written, in the link's target's folder
    if not parent.exists():
        problems.append(Problem(key, f"{path}: the folder {parent} does not exist"))
    elif not parent.is_dir():
        problems.append(Problem(key, f"{path}: {parent} is a file, not a folder"))
    elif not os.access(parent, os.W_OK | os.X_OK):
        problems.append(Problem(key, f"{path}: the folder {parent} is not writable"))
    return problems


def check_out_dir(key: str, path: Path) -> list[Problem]:
    """Problems with making `path` an output folder (it and missing parents are created): the
    nearest existing one of it and its parents must be a writable folder."""
    existing = path
    while not os.path.lexists(existing) and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        where = "is a file" if existing == path else f"is under {existing}, which is a file"
        return [Problem(key, f"{path} {where}, not a folder")]
    if not os.access(existing, os.W_OK | os.X_OK):
        return [Problem(key, f"{path}: {existing} is not writable")]
    return []


def make_out_dir(key: str, path: Path) -> list[Problem]:
    """Create the output folder `path` (and missing parents): a problem when that fails although
    `check_out_dir` passed (e.g. root under /proc, whose folders are writable but take no
    new entries). Called once the other arguments are known good, before the work, so a bad
    folder costs no run and a bad argument leaves no folder; a stop at once (`interrupt`) before
    anything is written in the folder it made leaves none either."""
    from planner import interrupt

    made = not path.exists()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return [Problem(key, f"{path}: cannot create the folder: {exc.strerror or exc}")]
    if made:
        interrupt.at_stop(functools.partial(remove_if_empty, path))
    return []


def remove_if_empty(path: Path) -> None:
    """Remove the folder `path` if it is there and empty (one a command made and wrote nothing in)."""
    with suppress(OSError):
        if path.is_dir() and not any(path.iterdir()):
            path.rmdir()


def positive(key: str, value, *, integer: bool = False, allow_zero: bool = False) -> list[Problem]:
    """A problem when a given number is not positive (finite; an integer >= 1 / >= 0)."""
    if value is None:
        return []
    if integer:
        low = 0 if allow_zero else 1
        return [] if value >= low else [Problem(key, f"must be {'>= 0' if allow_zero else 'at least 1'}, got {value}")]
    return [] if (value > 0 and value < float("inf")) else [Problem(key, f"must be a positive number, got {value}")]


def _console(stderr: bool = False, width: int | None = None):
    """A rich console; not on a terminal it does not wrap (a pipe or file gets whole lines)."""
    from rich.console import Console

    stream = sys.stderr if stderr else sys.stdout
    if stream.isatty():
        return Console(highlight=False, stderr=stderr, width=max(Console(stderr=stderr).width, width or 0) or None)
    return Console(highlight=False, stderr=stderr, soft_wrap=True, width=200)


def print_summary(summary: dict[str, Any]) -> None:
    from rich.markup import escape
    from rich.table import Table

    console = _console()
    console.print(f"[bold]{summary['name']}[/bold]  ({summary['file']}, {summary['dimension']}D): ok")
    if summary["description"]:
        console.print(summary["description"])

    bodies = Table(title="bodies", title_justify="left")
    for col in ("name", "role", "shape", "free DOFs", "actuated", "mass"):
        bodies.add_column(col)
    for b in summary["bodies"]:
        mass = "" if b["mass"] is None else f"{b['mass']:g}"
        bodies.add_row(b["name"], b["role"], b["shape"], ", ".join(b["dofs"]) or "-", ", ".join(b["actuated"]) or "-", mass)
    console.print(bodies)

    coords = Table(title="generalized coordinates q (in order)", title_justify="left")
    for col in ("#", "name", "start", "actuated"):
        coords.add_column(col)
    for i, (name, value) in enumerate(summary["start"].items()):
        coords.add_row(str(i), name, f"{value:g}", "yes" if name in summary["actuated"] else "")
    console.print(coords)

    pairs = Table(title="contact pairs", title_justify="left")
    for col in ("bodies", "mu", "K", "C"):
        pairs.add_column(col)
    for p in summary["contact_pairs"]:
        pairs.add_row(" - ".join(p["bodies"]), f"{p['mu']:g}", f"{p['K']:g}", f"{p['C']:g}")
    console.print(pairs)

    if summary["parameters"]:
        params = Table(title="design parameters", title_justify="left")
        params.add_column("name")
        params.add_column("value")
        for name, value in summary["parameters"].items():
            params.add_row(name, f"{value:g}")
        console.print(params)

    ladder = summary["ladder"]
    steps = ", ".join(f"{m} (h={h:g})" if h else m for m, h in ladder["steps"].items())
    console.print(f"ladder: {steps}; planner {ladder['planner']}, seed {ladder['seed']}, {ladder['time_limit']:g} s per rung")
    task = summary["task"]
    policies = [f"policy {_policy_words(task['policy'])}"] if task["policy"] else ["no policy"]
    policies += [f"policy {name!r} {_policy_words(p)}" for name, p in task["policies"].items()]
    console.print(f"task: plans reach the goal within {task['horizon']:g} s (horizon); " + "; ".join(policies))
    for reason in task["unplannable"]:
        console.print(f"[yellow]`ladder plan` refuses this scene: {escape(reason)}[/yellow]")
    reach = task.get("goal_reach")
    if reach and not reach["in_reach"] and reach["late"]:
        console.print(
            f"[yellow]task.horizon: {task['horizon']:g} s looks too short for the goal: the {reach['late']} goal states the geometric "
            f"rung made by projection are all out of reach, the soonest {reach['earliest']:g} s away (the actuators straight at "
            "their max speeds, in whole control periods); `ladder plan` would search for the goal region instead, "
            "and a plan is unlikely to reach it in time[/yellow]"
        )
    expect = summary["expect"]
    if expect:
        if expect["policy"] or expect["plan"] is not None:
            console.print(f"expect (`pytest` on the file): {_expect_words(expect)}")
        for case in expect["cases"]:
            given = [f"{name} = {value:g}" for name, value in case["parameters"].items()]
            given += [f"policy {case['task_policy']!r}"] if case["task_policy"] else []
            console.print(f"expect, case {case['name']} ({', '.join(given) or 'as the file is'}): {_expect_words(case)}")


def _expect_words(runs: dict) -> str:
    """What an [expect] table (or one of its cases) checks, in words."""
    said = [f"the policy under {rung} ends in {outcome}" for rung, outcome in runs["policy"].items()]
    if runs["plan"] is not None:
        settings = [f"seed {runs['seed']}"] if runs["seed"] is not None else []
        settings += [f"{runs['plan_iterations']:,} iterations per rung"] if runs["plan_iterations"] else []
        budget = f" ({', '.join(settings)})" if settings else ""
        said.append(f"a plan {'holds' if runs['plan'] else 'does not hold'} at the top rung{budget}")
    return "; ".join(said)


def _policy_words(policy: dict) -> str:
    """A policy of `Scenario.summary` in words: its type, what it drives and for how long."""
    unit = lambda name: "m/s" if name.rpartition(".")[2] in TRANSLATIONAL_DOFS else "rad/s"  # noqa: E731
    drives = [f"{name} at {speed + 0.0:g} {unit(name)}" for name, speed in policy["speeds"].items()]  # (+ 0.0: -0 is 0)
    drives += [f"{name} by its law" for name in policy["laws"]]
    return f"({policy['type']}: {', '.join(drives) or 'nothing driven'}) for {policy['duration']:g} s"

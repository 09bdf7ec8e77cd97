"""Feasible sets over design parameters (the paper's Section 4, Fig. 5): parameter sweeps.

A sweep evaluates the scenario's parametric open-loop policy (``[task.policy]``: constant
commanded speeds, expressions in the design parameters) at every point of a grid of design
parameters, under one or more models, and classifies each run by its outcome
(`models.task.Outcome`): ``goal`` (the paper's Z_F), ``unsafe`` (Z_U) or ``none`` (including
runs a solver failure stopped: their status says so). A model is a rung, optionally with
parameter overrides (``dynamic-compliant[C=0]``), so the paper's variants (plastic or elastic
impacts, with or without finger dynamics) are one sweep each.

`refine` then finds the boundaries between outcomes by bisection along grid lines, to a
tolerance, instead of leaving them at grid resolution.

Runs are independent, so they go to an executor: a local process pool (default) or a Dask
cluster (``dask://HOST:PORT``, through ``distributed``; a ``LocalCluster`` for tests).
Every run is a pure function of (file, parameters, model, h, duration), so the results do
not depend on the executor or on the order runs finish in.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import re
import time
from concurrent.futures import FIRST_COMPLETED, CancelledError, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from models.scenario import Problem, ScenarioError
from models.task import Outcome

#: The most runs one sweep may hold (grid points times models; the points stream, their
#: results are kept).
MAX_RUNS = 1_000_000  # planner.cli.MAX_RUNS says the same in --help


@dataclass(frozen=True)
class Axis:
    """One grid axis: a design parameter and its values (``log``: log-spaced)."""

    name: str
    values: tuple[float, ...]
    log: bool = False


@dataclass(frozen=True)
class ModelSpec:
    """A rung, the parameter overrides that make a model variant of it, and the policy it runs
    (one of the scenario's [task.policies]; None: [task.policy])."""

    rung: str
    overrides: tuple[tuple[str, float], ...] = ()
    name: str = ""  # a label of the user's (NAME=RUNG[...])
    policy: str | None = None

    @property
    def label(self) -> str:
        if self.name:
            return self.name
        if not self.overrides and self.policy is None:
            return self.rung
        parts = [f"{k}={v:g}" for k, v in self.overrides] + ([f"policy={self.policy}"] if self.policy else [])
        return f"{self.rung}[{','.join(parts)}]"


@dataclass(frozen=True)
class Task:
    """One run: everything a worker needs (picklable)."""

    file: str
    parameters: tuple[tuple[str, float], ...]
    model: ModelSpec
    h: float | None
    duration: float | None


@dataclass
class Point:
    model: str
    parameters: dict
    outcome: str  # an Outcome label: goal, unsafe, none
    t: float
    status: str
    final: dict
    steps: int
    wall_s: float
    max_penetration: float = 0.0  # the largest met at a step's start, m (`RolloutResult.max_penetration`)
    warnings: list[str] = field(default_factory=list)  # what the run says beside its status (`models.rungs.run_warnings`)
    h: float | None = None  # the step the run took, s (the sweep's --step, else its rung's in the scenario)


def _number(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{what} must be a number, got {text.strip()!r}") from None


def _integer(text: str, what: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"{what} must be an integer, got {text.strip()!r}") from None


def parse_axis(text: str, key: str = "--grid") -> Axis:
    """``NAME=START:STOP:COUNT[:log]`` or ``NAME=V1,V2,...``."""
    name, sep, spec = text.partition("=")
    name = name.strip()
    try:
        if not sep or not name:
            raise ValueError("expected NAME=START:STOP:COUNT[:log] or NAME=V1,V2,...")
        if ":" in spec:
            parts = spec.split(":")
            log = len(parts) == 4 and parts[3].strip().lower() == "log"
            if len(parts) not in (3, 4) or (len(parts) == 4 and not log):
                raise ValueError("expected START:STOP:COUNT[:log]")
            start, stop, count = _number(parts[0], "START"), _number(parts[1], "STOP"), _integer(parts[2], "COUNT")
            if count < 1:
                raise ValueError("COUNT must be at least 1")
            if count > MAX_RUNS:
                raise ValueError(f"COUNT {count:,} is more than a sweep may run ({MAX_RUNS:,} runs)")
            if not (math.isfinite(start) and math.isfinite(stop)):
                raise ValueError("START and STOP must be finite")
            if log and (start <= 0 or stop <= 0):
                raise ValueError("a log axis needs START and STOP > 0")
            values = np.geomspace(start, stop, count) if log else np.linspace(start, stop, count)
            # the decimals meant, not the sum's round-off (0.2:0.4:3's middle was 0.30000000000000004
            # in sweep.csv, sweep.json and a job's result): 15 significant digits, 1e-15 apart at most
            # (and 0 where the axis crosses it: -0.7:0.3:11's middle was 1.1e-16)
            values = np.array([0.0 if abs(v) < 1e-13 * max(abs(start), abs(stop)) else float(f"{v:.15g}") for v in values])
        else:
            values = np.array([_number(v, "a value") for v in spec.split(",") if v.strip()])
            log = False
            if len(values) > MAX_RUNS:
                raise ValueError(f"{len(values):,} values are more than a sweep may run ({MAX_RUNS:,} runs)")
            if not len(values) or not np.all(np.isfinite(values)):
                raise ValueError("expected finite values")
    except ValueError as exc:
        raise ScenarioError(Path(key), [Problem(f"{key} {text}", str(exc))]) from None
    return Axis(name, tuple(float(v) for v in values), log)


_MODEL = re.compile(r"^\s*(?:([A-Za-z0-9_.-]+)\s*=\s*)?([a-z-]+)\s*(?:\[(.*)\])?\s*$")


def _model_specs(text: str) -> list[ModelSpec]:
    """One --model text's models (`parse_models`), its labels not yet checked against each other."""
    from models.family import PROPAGATING_RUNGS

    syntax = "[LABEL=]RUNG[NAME=VALUE,...], e.g. elastic=dynamic-compliant[C=0,finger_mass=1e3]"
    models, depth, current = [], 0, ""
    for ch in text + ",":
        if ch == "," and depth == 0:
            if current.strip():
                models.append(current.strip())
            current = ""
            continue
        depth += ch == "["
        depth -= ch == "]"
        if depth < 0 or depth > 1:
            raise ScenarioError(
                Path("--model"), [Problem(f"--model {text}", f"unbalanced '{ch}' in {(current + ch).strip()!r}; expected {syntax}")]
            )
        current += ch
    if depth != 0:
        raise ScenarioError(Path("--model"), [Problem(f"--model {text}", f"a '[' is not closed; expected {syntax}")])
    if not models:
        raise ScenarioError(Path("--model"), [Problem(f"--model {text}", f"no model given; expected {syntax}")])
    specs = []
    for item in models:
        m = _MODEL.match(item)
        if not m or m.group(2) not in PROPAGATING_RUNGS:
            raise ScenarioError(
                Path("--model"),
                [Problem(f"--model {item}", f"expected {syntax}; RUNG one of {', '.join(PROPAGATING_RUNGS)}")],
            )
        overrides, policy = [], None
        for part in re.split(r"[;,]", m.group(3) or ""):
            if not part.strip():
                continue
            name, sep, value = part.partition("=")
            if name.strip() == "policy" and value.strip():
                policy = value.strip()
                continue
            try:
                number = float(value)
                if not sep or not math.isfinite(number):
                    raise ValueError
            except ValueError:
                raise ScenarioError(Path("--model"), [Problem(f"--model {item}", f"override {part!r}: expected NAME=NUMBER")]) from None
            overrides.append((name.strip(), number))
        names = [name for name, _ in overrides]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ScenarioError(Path("--model"), [Problem(f"--model {item}", f"{', '.join(twice)} overridden twice")])
        specs.append(ModelSpec(m.group(2), tuple(overrides), m.group(1) or "", policy))
    return specs


def parse_models(text: str | list[str]) -> list[ModelSpec]:
    """``quasistatic-rigid,elastic=dynamic-compliant[C=0;finger_mass=1e3]``: rungs, each with
    optional overrides (separated by ';' or ',' inside the brackets; ``policy=NAME`` runs one of
    the scenario's [task.policies]) and an optional label; a list: the texts of repeated --model
    options, each parsed on its own, their labels distinct across them."""
    texts = [text] if isinstance(text, str) else list(text)
    specs = [spec for one in texts for spec in _model_specs(one)]
    labels = [spec.label for spec in specs]
    twice = sorted({label for label in labels if labels.count(label) > 1})
    if twice:
        raise ScenarioError(
            Path("--model"),
            [
                Problem(
                    " ".join(f"--model {one}" for one in texts),
                    f"the label {label!r} names two models (or one model is given twice); give each model its own label, LABEL=RUNG[...]",
                )
                for label in twice
            ],
        )
    return specs


def grid_points(axes: list[Axis]):
    """Every combination, the first axis varying slowest, one at a time (a generator)."""
    names = [a.name for a in axes]
    for values in itertools.product(*(a.values for a in axes)):
        yield dict(zip(names, values))


def grid_size(axes: list[Axis]) -> int:
    return math.prod(len(a.values) for a in axes)


def run_task(task: Task) -> Point:
    """One run of the policy (in a worker process, or here)."""
    from models.rungs import policy_controls, run_warnings, rung_for
    from models.scenario import load_scenario

    params = dict(task.parameters)
    params.update(dict(task.model.overrides))
    scenario = load_scenario(task.file, params).with_policy(task.model.policy)
    rung = rung_for(scenario, task.model.rung)
    h = task.h or scenario.rung_settings(task.model.rung).h
    controls, durations = policy_controls(scenario, task.duration)
    out = rung.rollout(scenario, rung.initial_state(scenario), controls, durations, h, max_records=2, laws=True)
    final = out.state.named(scenario)
    return Point(
        task.model.label,
        dict(task.parameters),
        out.outcome,
        out.t,
        out.status,
        final,
        out.steps,
        out.wall_s,
        out.max_penetration,
        warnings=run_warnings(scenario, rung, h, out),
        h=h,
    )


def _warm() -> None:
    """Load the compiled kernels in a fresh worker before its first timed run. Ctrl-C at a
    terminal reaches the workers too: they leave it to the parent, which stops between runs.
    A worker ends with its parent (killed, or stopped at once): workers had been left running,
    then blocked on the pool's pipe for good."""
    import signal

    from models.kernel_cache import _end_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _end_with_parent(os.getppid())  # (the process that started the pool, or its forkserver)
    import models.rollout  # noqa: F401


#: Runs in flight per worker: the pool is fed from the (lazy) task stream this far ahead.
WINDOW_PER_WORKER = 4
#: Seconds between checks of `map`'s `stop` while it waits for a run (a Dask cluster that lost
#: its workers finishes none; a check at each run's end alone had left Ctrl-C unheard).
POLL_S = 0.5
#: Seconds a Dask sweep waits with no worker in the cluster before it says so.
NO_WORKERS_S = 10.0


class ExecutorLost(Exception):
    """The executor can run no more of the sweep: a worker process of the local pool ended
    abruptly (killed, out of memory), or the Dask scheduler went away. The runs done were
    yielded before it; `sweep` and `refine` keep them (`SweepResult.error`)."""


class Executor:
    """Runs tasks, yielding (index, Point) as they finish. `local` (process pool) or Dask.
    `notice(text)`: what the executor has to say while it waits (a Dask cluster with no workers)."""

    def __init__(self, workers: int | None = None, address: str | None = None, notice=None) -> None:
        self.address = address
        self.workers = workers or os.cpu_count() or 1
        self.notice = notice or (lambda text: None)
        self._pool = None
        self._client = None
        self._stack = contextlib.ExitStack()

    def __enter__(self) -> Executor:
        if self.address:
            try:
                from distributed import Client
            except ImportError:
                raise ScenarioError(
                    "command line", [Problem("--executor", f'{self.address}: install the dask extra: pip install "contact-ladder[dask]"')]
                ) from None
            try:
                self._client = Client(self.address.removeprefix("dask://"), set_as_default=False, timeout=10)
            except (OSError, TimeoutError, ValueError) as exc:
                problem = Problem("--executor", f"cannot reach the Dask scheduler at {self.address}: {exc}")
                raise ScenarioError("command line", [problem]) from None
        elif self.workers > 1:
            from planner import interrupt

            self._pool = ProcessPoolExecutor(self.workers, initializer=_warm)
            self._stack.enter_context(interrupt.stopped_at_once(self._kill_workers))
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:  # (a stop at once while it waits still ends the workers)
            self._pool.shutdown(wait=exc[0] is None, cancel_futures=True)
        self._stack.close()
        if self._client is not None:
            close_quietly(self._client)

    def _kill_workers(self) -> None:
        """End the pool's worker processes now (a stop at once: they would outlive the process)."""
        for process in list((self._pool._processes or {}).values()):
            process.kill()

    def map(self, tasks, stop=None):
        """(index, Point) for each task of the iterable `tasks` as it finishes; at most
        WINDOW_PER_WORKER runs per worker are submitted ahead, so a long stream is never held.
        `stop()` is asked after each run and every POLL_S s while waiting: once it is true no
        further run starts, the runs not yet begun are cancelled, and those under way are
        waited for and yielded (they are computed: a Ctrl-C keeps them), then the stream ends."""
        stop = stop or (lambda: False)
        if stop():  # (refine's next batch after a Ctrl-C starts no run)
            return
        stream = enumerate(tasks)
        if self._client is not None:
            yield from self._map_dask(stream, stop)
        elif self._pool is not None:
            window = WINDOW_PER_WORKER * self.workers
            futures = {}
            stopping = False
            try:
                for i, t in itertools.islice(stream, window):
                    futures[self._pool.submit(run_task, t)] = i
                while futures:
                    if not stopping and stop():
                        stopping = True
                        # (a run the pool has begun, or queued for a worker, cannot be cancelled)
                        futures = {f: i for f, i in futures.items() if not f.cancel()}
                        continue
                    done, _ = wait(futures, timeout=POLL_S, return_when=FIRST_COMPLETED)
                    for f in done:
                        i = futures.pop(f)
                        point = f.result()  # (BrokenProcessPool where its worker died)
                        if not stopping:
                            try:
                                for j, t in itertools.islice(stream, 1):
                                    futures[self._pool.submit(run_task, t)] = j
                            except BrokenProcessPool:  # (a worker died since: this run is done all the same)
                                yield i, point
                                raise
                        yield i, point
            except BrokenProcessPool:
                yield from self._pool_lost(futures)
            finally:
                for f in futures:
                    f.cancel()
        else:
            for i, t in stream:
                if stop():
                    return
                yield i, run_task(t)

    def _pool_lost(self, futures):
        """A broken pool: the runs it finished first are yielded, then ExecutorLost."""
        for f, i in list(futures.items()):
            if f.done() and not f.cancelled() and f.exception() is None:
                del futures[f]
                yield i, f.result()
        raise ExecutorLost("a worker process of the local pool ended abruptly (killed, or out of memory), and the pool can run no more")

    def _map_dask(self, stream, stop):
        import queue

        window = WINDOW_PER_WORKER * max(1, sum(self._client.nthreads().values()))
        finished: queue.Queue = queue.Queue()  # futures as they finish (put by Dask's callback thread)
        inflight = {}  # future -> index
        lost = set()  # finished runs whose result went with their worker
        stopping = False
        idle_since, said = None, False

        def submit(i, t):
            future = self._client.submit(run_task, t, pure=False)
            inflight[future] = i
            future.add_done_callback(finished.put)

        try:
            for i, t in itertools.islice(stream, window):
                submit(i, t)
            while inflight:
                if not stopping and stop():
                    stopping = True
                    # the runs a worker has begun go on (Dask cannot stop a task), and those done
                    # but not yet read are computed: keep both
                    under_way = {key for keys in self._client.processing().values() for key in keys}
                    kept = {f: i for f, i in inflight.items() if f.done() or f.key in under_way}
                    self._client.cancel([f for f in inflight if f not in kept])
                    inflight = kept
                    continue
                try:
                    f = finished.get(timeout=POLL_S)
                except queue.Empty:
                    for f in lost:  # (tried again: Dask runs a lost result again once it knows it lost)
                        f.add_done_callback(finished.put)
                    lost.clear()
                    idle_since = None if self._client.scheduler_info(n_workers=1).get("workers") else (idle_since or time.monotonic())
                    if idle_since is not None and not said and time.monotonic() - idle_since >= NO_WORKERS_S:
                        self.notice(
                            f"the Dask cluster at {self.address} has no workers: "
                            "the sweep waits for one (Ctrl-C stops it and keeps what is done)"
                        )
                        said = True
                    continue
                if f not in inflight:  # (cancelled as the sweep stopped)
                    continue
                try:
                    point = _dask_result(f)
                except TimeoutError:
                    if f.status == "error":  # (the run's own TimeoutError)
                        raise
                    lost.add(f)  # its result was lost with its worker: Dask runs it again
                    continue
                i = inflight.pop(f)
                if not stopping:
                    for j, t in itertools.islice(stream, 1):
                        submit(j, t)
                yield i, point
        except (OSError, CancelledError) as exc:  # (a run cancelled by anyone but this sweep: its scheduler is gone)
            inflight.clear()
            raise ExecutorLost(f"lost the Dask scheduler at {self.address}: its connection closed ({type(exc).__name__})") from None
        finally:
            if inflight:
                self._client.cancel(list(inflight))


def close_quietly(client) -> None:
    """Close a Dask client (a sweep's, the service's) without the tracebacks Dask prints then: a
    result lost with its worker leaves Dask's gather waiting, and closing ends it with AllExit,
    which asyncio would print ("Task exception was never retrieved"); a client that lost its
    scheduler logs its reconnect's cancel as an error."""
    client.loop.asyncio_loop.set_exception_handler(_quiet_all_exit)
    with logs_off("distributed"):
        client.close()


@contextlib.contextmanager
def logs_off(name: str):
    """The logger `name` (and those under it) silent for the block."""
    import logging

    names = [n for n in list(logging.root.manager.loggerDict) if n == name or n.startswith(name + ".")]
    loggers = [logging.getLogger(n) for n in names]
    were = [logger.disabled for logger in loggers]
    for logger in loggers:
        logger.disabled = True
    try:
        yield
    finally:
        for logger, was in zip(loggers, were):
            logger.disabled = was


def _quiet_all_exit(loop, context) -> None:
    """The Dask client's loop: AllExit (a gather the client's close ended) is no error of ours."""
    if type(context.get("exception")).__name__ != "AllExit":
        loop.default_exception_handler(context)


def _dask_result(future):
    """A finished Dask run's Point (TimeoutError where its result went with its worker); a file a
    worker could not read is named as the worker's problem."""
    try:
        return future.result(timeout=POLL_S)
    except ScenarioError as exc:
        where = "as a Dask worker reads it: the workers read the scenario, and the files it names, at the same absolute path"
        raise ScenarioError(exc.file, [Problem(p.key, f"{p.reason} ({where})") for p in exc.problems]) from None
    except OSError as exc:
        if future.status == "error":  # (the run's own, not the lost connection `_map_dask` takes an OSError for)
            raise RuntimeError(f"a run raised {exc!r}") from exc
        raise


@dataclass
class SweepResult:
    file: str
    axes: list[Axis]
    models: list[ModelSpec]
    fixed: dict
    h: float | None
    duration: float | None
    points: list[Point | None]
    boundaries: list[dict] = field(default_factory=list)
    complete: bool = True
    error: str | None = None  # what ended it before its end other than a stop (ExecutorLost)
    refine_tolerance: float | None = None
    refine_points: list[Point] = field(default_factory=list)  # the bisection's runs, in the order they ran

    def to_json(self) -> dict:
        return {
            "file": self.file,
            "complete": self.complete,
            "error": self.error,
            "axes": [asdict(a) for a in self.axes],
            "models": [m.label for m in self.models],
            "fixed": self.fixed,
            "h": self.h,
            "duration": self.duration,
            "points": [asdict(p) for p in self.points if p is not None],
            "missing": sum(p is None for p in self.points),
            "boundaries": self.boundaries,
            "refine_tolerance": self.refine_tolerance,
            "refine_points": [asdict(p) for p in self.refine_points],
        }

    def to_csv(self) -> str:
        names = [a.name for a in self.axes]
        coords = sorted({k for p in self.points if p is not None for k in p.final})
        lines = [",".join(["model", *names, "outcome", "t", "status", "steps", "max_penetration", "warnings", *coords])]
        for p in self.points:
            if p is None:
                continue
            lines.append(
                ",".join(
                    [
                        p.model,
                        *(repr(p.parameters[n]) for n in names),
                        p.outcome,
                        repr(p.t),
                        p.status,
                        str(p.steps),
                        repr(p.max_penetration),
                        str(len(p.warnings)),  # (how many: their words are in sweep.json)
                        *(repr(p.final.get(c, float("nan"))) for c in coords),
                    ]
                )
            )
        return "\n".join(lines) + "\n"


def sweep(
    file: str,
    axes: list[Axis],
    models: list[ModelSpec],
    *,
    fixed: dict | None = None,
    h: float | None = None,
    duration: float | None = None,
    executor: Executor | None = None,
    progress=None,
    stop=None,
) -> SweepResult:
    """Every grid point under every model. When `stop()` turns true (`Executor.map`), or on a
    KeyboardInterrupt, the result so far comes back with complete = False (the caller writes it)."""
    fixed = dict(fixed or {})
    runs = grid_size(axes) * len(models)
    if runs > MAX_RUNS:
        raise ScenarioError(Path(file), [Problem("--grid", f"{runs:,} runs are more than a sweep may run ({MAX_RUNS:,})")])
    path = os.path.abspath(file)  # (a Dask worker's working folder is its own)
    tasks = (Task(path, tuple({**fixed, **p}.items()), m, h, duration) for m in models for p in grid_points(axes))
    result = SweepResult(str(file), axes, models, fixed, h, duration, [None] * runs)
    own = executor is None
    executor = executor or Executor(1)
    try:
        if own:
            executor.__enter__()
        done = 0
        for i, point in executor.map(tasks, stop):
            result.points[i] = point
            done += 1
            if progress:
                progress(done, runs)
        result.complete = done == runs
    except KeyboardInterrupt:
        result.complete = False
    except ExecutorLost as exc:
        result.complete, result.error = False, str(exc)
    finally:
        if own:
            executor.__exit__(None, None, None)
    return result


#: `refine`'s bracket, where none is given (relative on log axes).
TOLERANCE = 1e-3


def refine(result: SweepResult, *, tolerance: float = TOLERANCE, executor: Executor | None = None, progress=None, stop=None) -> SweepResult:
    """Bisect every pair of grid neighbours (along one axis) whose outcomes differ, until the
    bracket is below `tolerance` (relative on log axes, absolute otherwise). Each boundary
    records the axis, the other parameters, the two outcomes and the bracket, and the status
    of the two runs that bound it (`low_status`, `high_status`: a side a solver failure ended is
    no physical outcome). Brackets of all boundaries advance together, one batch of runs per
    bisection step; the runs are kept in `result.refine_points`. A stop (`stop()`) keeps the
    runs done, each bracket narrowed by its own; a KeyboardInterrupt keeps the bisection steps
    done before it (its batch is lost); either way complete = False."""
    by_key = {}
    for p in result.points:
        if p is not None:
            by_key[(p.model, tuple(sorted(p.parameters.items())))] = p
    models = {m.label: m for m in result.models}
    brackets = []
    for axis in result.axes:
        for model in result.models:
            for p in result.points:
                if p is None or p.model != model.label:
                    continue
                v = p.parameters[axis.name]
                k = axis.values.index(v) if v in axis.values else -1
                if k < 0 or k + 1 >= len(axis.values):
                    continue
                other = dict(p.parameters)
                other[axis.name] = axis.values[k + 1]
                q = by_key.get((model.label, tuple(sorted(other.items()))))
                if q is not None and q.outcome != p.outcome:
                    brackets.append(
                        {
                            "model": model.label,
                            "axis": axis.name,
                            "log": axis.log,
                            "at": dict(p.parameters),
                            "grid_low": v,
                            "grid_high": axis.values[k + 1],
                            "low": v,
                            "high": axis.values[k + 1],
                            "low_outcome": p.outcome,
                            "high_outcome": q.outcome,
                            "low_status": p.status,
                            "high_status": q.status,
                        }
                    )

    def width(b) -> float:
        return math.log(b["high"] / b["low"]) if b["log"] else b["high"] - b["low"]

    path = os.path.abspath(result.file)

    own = executor is None
    executor = executor or Executor(1)
    try:
        if own:
            executor.__enter__()
        step = 0
        while True:
            active = [b for b in brackets if width(b) > tolerance]
            if not active:
                break
            tasks = []
            for b in active:
                mid = math.sqrt(b["low"] * b["high"]) if b["log"] else 0.5 * (b["low"] + b["high"])
                b["mid"] = mid
                params = {**b["at"], b["axis"]: mid}
                tasks.append(Task(path, tuple(params.items()), models[b["model"]], result.h, result.duration))
            outcomes = [None] * len(tasks)
            try:
                for i, point in executor.map(tasks, stop):
                    outcomes[i] = point
            except ExecutorLost as exc:  # (the batch's runs done are kept, as at a stop)
                result.error = str(exc)
            result.refine_points += [p for p in outcomes if p is not None]
            for b, point in zip(active, outcomes):
                mid = b.pop("mid")
                if point is None:  # (stopped before this run)
                    continue
                if point.outcome == b["low_outcome"]:
                    b["low"], b["low_status"] = mid, point.status
                elif point.outcome == b["high_outcome"]:
                    b["high"], b["high_status"] = mid, point.status
                else:  # a third outcome in between: a boundary on each side of it
                    brackets.append({**b, "low": mid, "low_outcome": point.outcome, "low_status": point.status})
                    b["high"], b["high_outcome"], b["high_status"] = mid, point.outcome, point.status
            if None in outcomes or result.error:
                result.complete = False
                break
            step += 1
            if progress:
                progress(step, len(active))
    except KeyboardInterrupt:
        result.complete = False
    finally:
        if own:
            executor.__exit__(None, None, None)
    for b in brackets:
        b.pop("mid", None)
        b["boundary"] = math.sqrt(b["low"] * b["high"]) if b["log"] else 0.5 * (b["low"] + b["high"])
    result.boundaries = brackets
    result.refine_tolerance = tolerance
    return result


def bands(result: SweepResult, axis: str, outcome: str = Outcome.GOAL.label) -> dict:
    """Per model and per value of the other swept parameters: the intervals of `axis` whose
    grid points end in `outcome` (a label), each edge refined where `refine` bracketed it (else the grid
    point; an edge at the end of the grid is marked so)."""
    others = [a.name for a in result.axes if a.name != axis]
    out: dict = {}
    for model in result.models:
        rows: dict = {}
        for p in result.points:
            if p is not None and p.model == model.label:
                rows.setdefault(tuple(p.parameters[n] for n in others), []).append((p.parameters[axis], p.outcome))
        for rest, values in sorted(rows.items()):
            values.sort()
            key = ", ".join(f"{n}={v:g}" for n, v in zip(others, rest)) or "-"
            edges = []
            k = 0
            while k < len(values):
                if values[k][1] != outcome:
                    k += 1
                    continue
                j = k
                while j + 1 < len(values) and values[j + 1][1] == outcome:
                    j += 1
                lo, hi = values[k][0], values[j][0]
                for b in result.boundaries:
                    if b["model"] != model.label or b["axis"] != axis or tuple(b["at"][n] for n in others) != rest:
                        continue
                    if k > 0 and b["grid_high"] == lo and b["high_outcome"] == outcome:
                        lo = b["boundary"]
                    if j + 1 < len(values) and b["grid_low"] == hi and b["low_outcome"] == outcome:
                        hi = b["boundary"]
                edges.append({"from": lo, "to": hi, "from_is_grid_end": k == 0, "to_is_grid_end": j == len(values) - 1})
                k = j + 1
            out.setdefault(model.label, {})[key] = edges
    return out

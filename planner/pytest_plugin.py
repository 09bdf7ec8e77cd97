"""A pytest plugin: scenario files with an `[expect]` table become test items.

    pytest scenarios/            # or any folder of your own scenario files

Each expectation is one item: `policy[RUNG]` simulates the task's policy under that rung
and checks the outcome; `plan` runs the ladder with the scenario's seed (or the expectation's
`seed`) and checks whether the top rung holds. Each `[[expect.cases]]` entry is a collector,
FILE::NAME, of the same items on the scenario with the case's `parameters` and `task_policy`.
A scenario file (one with a `[scenario]` or an `[expect]` table) that fails to load is one
failing item, `load`, that shows the loader's message: a TOML syntax error or a misspelt
`[expect]` is a failure, not a file left out (and so is a case whose scene does not load with
its parameters, or cannot run its expectations). A scenario that loads with no `[expect]`
table is no test. Registered through the `pytest11` entry point of the contact-ladder distribution.
"""

from __future__ import annotations

import re
import tomllib
import warnings

import pytest

#: A scenario file's table header, looked for in a file that is not valid TOML.
_SCENARIO_TABLE = re.compile(r"^[ \t]*\[[ \t]*(scenario|expect)[ \t]*[\].]", re.MULTILINE)


def pytest_collect_file(file_path, parent):
    if file_path.suffix == ".toml" and _is_scenario_file(file_path):
        return ScenarioFile.from_parent(parent, path=file_path)
    return None


def _is_scenario_file(path) -> bool:
    """Whether `path` is a scenario file for this plugin: its TOML has a `scenario` or an
    `expect` table, or (not valid TOML, or nested too deeply to read) a line heads one."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return False  # not a text file: no scenario
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError):
        return bool(_SCENARIO_TABLE.search(text))
    return "scenario" in data or "expect" in data


def pytest_collection_finish(session):
    """Say so before scenario items compile the physics kernels (numba's cache cold: a first run,
    or an edit of ladder's `models`), as the `ladder` command does: else minutes of silence."""
    if not any(isinstance(item, (PolicyItem, PlanItem)) for item in session.items):
        return
    from models.kernel_cache import kernels_cached

    if kernels_cached():
        return
    from planner.cli import COMPILE_NOTE

    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line(COMPILE_NOTE)


class ScenarioFile(pytest.File):
    def collect(self):
        from planner import models_problem

        problem = models_problem()  # (a project's own `models` package ahead of ladder's on sys.path)
        if problem:
            yield LoadFailure.from_parent(self, name="load", message=f"{self.path}: {problem}")
            return
        from models.scenario import ScenarioError, load_scenario

        try:
            scenario = load_scenario(self.path)
        except ScenarioError as exc:
            yield LoadFailure.from_parent(self, name="load", message=str(exc))
            return
        expect = scenario.spec.expect
        if expect is None:
            return
        yield from _run_items(self, scenario, expect)
        for i, case in enumerate(expect.cases):
            yield ScenarioCase.from_parent(self, name=case.name, case=case, index=i)


def _run_items(parent, scenario, runs):
    """The items of runs (the [expect] table's own, or a case's) on scenario, under parent."""
    for rung, outcome in runs.policy.items():
        # the id given whole: pytest (9) reads a cached "policy[RUNG]" as a name and parameters,
        # and an id built from the name alone never matched it (--lf, --sw ran none of these)
        name = f"policy[{rung}]"
        yield PolicyItem.from_parent(parent, name=name, nodeid=f"{parent.nodeid}::{name}", scenario=scenario, rung=rung, outcome=outcome)
    if runs.plan is not None:
        yield PlanItem.from_parent(parent, name="plan", scenario=scenario, holds=runs.plan, iterations=runs.plan_iterations, seed=runs.seed)


class ScenarioCase(pytest.Collector):
    """An [[expect.cases]] entry: the scenario with the case's parameters and policy, and its
    items (FILE::NAME::policy[RUNG], FILE::NAME::plan). The file's load checks each case's
    variant: a case that cannot run fails the file's load (FILE::load, naming the case)."""

    def __init__(self, *, case, index, **kwargs):
        super().__init__(**kwargs)
        self.case, self.index = case, index

    def collect(self):
        from models.scenario import ScenarioError, case_variant

        try:  # (the file's load checked it: a file changed since is what fails here)
            scenario = case_variant(self.path, self.case, self.index)
        except ScenarioError as exc:
            yield LoadFailure.from_parent(self, name="load", message=f"case {self.case.name!r}: {exc}")
            return
        yield from _run_items(self, scenario, self.case)


class LoadFailure(pytest.Item):
    def __init__(self, *, message, **kwargs):
        super().__init__(**kwargs)
        self.message = message

    def runtest(self):
        raise ScenarioExpectationFailed(self.message)

    def repr_failure(self, excinfo):
        return str(excinfo.value)

    def reportinfo(self):
        return _reportinfo(self)


def _reportinfo(item):
    """(path, line, the failure's heading): "[CASE::]NAME in FILE" (a heading of the name alone
    had been "plan" or "load" for every file's). Not the id's tail "FILE::NAME": pytest -v
    prints an id that ends with the heading with its dots as "::" ("x::toml::plan")."""
    within = item.nodeid.split("::", 1)[-1]
    return item.path, None, f"{within} in {item.path.name}"


class ScenarioExpectationFailed(AssertionError):
    pass


class ScenarioRunWarning(UserWarning):
    """A policy item's run is not physical, whatever its outcome (`models.rungs.run_warnings`)."""


def _failure(item, excinfo) -> str:
    """An item's failure: the file, the case it is of and what went wrong (a ScenarioError names
    its file itself); anything else as pytest shows it."""
    from models.scenario import ScenarioError

    if isinstance(excinfo.value, ScenarioExpectationFailed):
        case = item.parent.case if isinstance(item.parent, ScenarioCase) else None
        if case is None:
            return f"{item.path}: {excinfo.value}"
        given = [f"{name} = {value:g}" for name, value in case.parameters.items()]
        given += [f"policy {case.task_policy!r}"] if case.task_policy else []
        return f"{item.path}: case {case.name!r} ({', '.join(given) or 'as the file is'}): {excinfo.value}"
    if isinstance(excinfo.value, ScenarioError):
        return str(excinfo.value)
    return str(excinfo.getrepr(style="short"))


class PolicyItem(pytest.Item):
    def __init__(self, *, scenario, rung, outcome, **kwargs):
        super().__init__(**kwargs)
        self.scenario, self.rung, self.outcome = scenario, rung, outcome

    def runtest(self):
        from models.rungs import policy_controls, run_warnings, rung_for

        rung = rung_for(self.scenario, self.rung)
        step = self.scenario.rung_settings(self.rung).h
        controls, durations = policy_controls(self.scenario)
        result = rung.rollout(self.scenario, rung.initial_state(self.scenario), controls, durations, step, laws=True)
        for text in run_warnings(self.scenario, rung, step, result):  # (in pytest's warnings summary, whatever the outcome)
            warnings.warn(ScenarioRunWarning(f"{self.nodeid}: {text}"), stacklevel=1)
        if not result.ok:
            raise ScenarioExpectationFailed(f"{self.rung}: the run failed: {result.message}")
        if result.outcome != self.outcome:
            final = ", ".join(f"{name} = {value:.6g}" for name, value in result.state.named(self.scenario).items())
            raise ScenarioExpectationFailed(
                f"{self.rung}: the policy ends in {result.outcome!r} at t = {result.t:.4f} s, expected {self.outcome!r} "
                f"(expect.policy.{self.rung}); the final state: {final}"
            )

    def repr_failure(self, excinfo):
        return _failure(self, excinfo)

    def reportinfo(self):
        return _reportinfo(self)


class PlanItem(pytest.Item):
    def __init__(self, *, scenario, holds, iterations, seed, **kwargs):
        super().__init__(**kwargs)
        self.scenario, self.holds, self.iterations, self.seed = scenario, holds, iterations, seed

    def runtest(self):
        from planner.ladder import run_ladder

        result = run_ladder(self.scenario, iterations=self.iterations, seed=self.seed)
        if result.top_holds != self.holds:
            budget = f"{self.iterations:,} iterations a rung" if self.iterations is not None else "each rung's own iterations"
            ended = "".join(f"\n  {r.label}: {r.ended.label}" + (f" ({r.reason})" if r.reason else "") for r in result.rungs)
            raise ScenarioExpectationFailed(
                f"top rung holds: {result.top_holds}, expected {self.holds} (expect.plan; seed {result.seed}, {budget}):{ended}"
            )

    def repr_failure(self, excinfo):
        return _failure(self, excinfo)

    def reportinfo(self):
        return _reportinfo(self)

"""A pytest plugin: scenario files with an `[expect]` table become test items.

    pytest scenarios/            # or any folder of your own scenario files

Each expectation is one item: `policy[RUNG]` simulates the task's policy under that rung
and checks the outcome; `plan` runs the ladder with the scenario's seed and checks that the
top rung holds. A file that fails to load is one failing item that shows the loader's message.
Registered through the `pytest11` entry point of the contact-ladder distribution.
"""

from __future__ import annotations

import tomllib

import pytest


def pytest_collect_file(file_path, parent):
    if file_path.suffix == ".toml" and _has_expectations(file_path):
        return ScenarioFile.from_parent(parent, path=file_path)
    return None


def _has_expectations(path) -> bool:
    try:
        return "expect" in tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError):
        return False  # not a scenario this plugin can read (RecursionError: nested too deeply)


class ScenarioFile(pytest.File):
    def collect(self):
        from models.scenario import ScenarioError, load_scenario

        try:
            scenario = load_scenario(self.path)
        except ScenarioError as exc:
            yield LoadFailure.from_parent(self, name="load", message=str(exc))
            return
        expect = scenario.spec.expect
        for rung, outcome in expect.policy.items():
            yield PolicyItem.from_parent(self, name=f"policy[{rung}]", scenario=scenario, rung=rung, outcome=outcome)
        if expect.plan is not None:
            yield PlanItem.from_parent(self, name="plan", scenario=scenario, holds=expect.plan, iterations=expect.plan_iterations)


class LoadFailure(pytest.Item):
    def __init__(self, *, message, **kwargs):
        super().__init__(**kwargs)
        self.message = message

    def runtest(self):
        raise ScenarioExpectationFailed(self.message)

    def repr_failure(self, excinfo):
        return str(excinfo.value)


class ScenarioExpectationFailed(AssertionError):
    pass


class PolicyItem(pytest.Item):
    def __init__(self, *, scenario, rung, outcome, **kwargs):
        super().__init__(**kwargs)
        self.scenario, self.rung, self.outcome = scenario, rung, outcome

    def runtest(self):

        from models.rungs import policy_controls, rung_for

        spec = self.scenario.spec
        if spec.task.policy is None:
            raise ScenarioExpectationFailed("[expect.policy] needs a [task.policy]")
        rung = rung_for(self.scenario, self.rung)
        step = self.scenario.rung_settings(self.rung).h
        controls, durations = policy_controls(self.scenario)
        result = rung.rollout(self.scenario, rung.initial_state(self.scenario), controls, durations, step, laws=True)
        if not result.ok:
            raise ScenarioExpectationFailed(f"{self.rung}: the run failed: {result.message}")
        if result.outcome != self.outcome:
            raise ScenarioExpectationFailed(
                f"{self.rung}: the policy ends in {result.outcome!r} at t = {result.t:.4f} s, expected {self.outcome!r}"
            )

    def repr_failure(self, excinfo):
        return f"{self.path}: {excinfo.value}"

    def reportinfo(self):
        return self.path, 0, f"{self.path.name}::{self.name}"


class PlanItem(pytest.Item):
    def __init__(self, *, scenario, holds, iterations, **kwargs):
        super().__init__(**kwargs)
        self.scenario, self.holds, self.iterations = scenario, holds, iterations

    def runtest(self):
        from planner.ladder import run_ladder

        result = run_ladder(self.scenario, iterations=self.iterations)
        if result.top_holds != self.holds:
            ended = ", ".join(f"{r.rung}: {r.ended.label}" for r in result.rungs)
            raise ScenarioExpectationFailed(f"top rung holds: {result.top_holds}, expected {self.holds} ({ended})")

    def repr_failure(self, excinfo):
        return f"{self.path}: {excinfo.value}"

    def reportinfo(self):
        return self.path, 0, f"{self.path.name}::{self.name}"

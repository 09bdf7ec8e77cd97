"""The replan-on-upgrade pipeline: plan with the cheapest rung, then go up the ladder.

For each rung in order (this first version):

- ``geometric``: OMPL geometric planning in the C-space of the free DOFs with validity =
  non-penetration and not unsafe; its path becomes commanded speeds for the actuated DOFs
  (an approximate path too: the goal set is thin), which the next rung replays;
- a rung with dynamics and no usable previous plan plans from scratch (OMPL control
  planning over its rollout);
- every later rung replays the previous rung's controls from its own lifted start; if the
  replay reaches the goal without entering the unsafe set the plan is accepted with no
  search ("replayed"), otherwise the rung plans again ("replanned") with the tree also
  rooted at the states of the longest replayed prefix that still agrees, and the prefix is
  spliced in front of a path that starts at one of them (OMPL-CRIB section 5).

Each rung's report says how it ended, wall time, propagations and planner iterations, and
the replay's outcome. Biased
sampling toward the previous path is not done yet.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from models.rungs import RUNGS, rung_for
from models.scenario import Problem, Scenario, ScenarioError
from models.schema import RUNGS as RUNG_ORDER
from planner.ompl_adapter import plan_control, plan_geometric


@dataclass
class RungReport:
    rung: str
    ended: str  # replayed, replanned, planned, failed, skipped
    reason: str = ""
    outcome: str = "none"  # what the accepted controls reach under this rung
    wall_s: float = 0.0
    propagations: int = 0
    iterations: int = 0
    controls: list = field(default_factory=list)
    durations: list = field(default_factory=list)
    states: list = field(default_factory=list)


@dataclass
class LadderResult:
    scenario: str
    seed: int
    rungs: list[RungReport]

    @property
    def top_holds(self) -> bool:
        return bool(self.rungs) and self.rungs[-1].outcome == "goal"

    def to_json(self, timings: bool = True) -> dict:
        """The plan; without timings it is a pure function of the scenario and the seed."""
        rungs = [asdict(r) for r in self.rungs]
        if not timings:
            for r in rungs:
                del r["wall_s"]
        return {"scenario": self.scenario, "seed": self.seed, "top_holds": self.top_holds, "rungs": rungs}


def check_start(scenario: Scenario) -> None:
    """A start inside the unsafe set is bad input (penetration is caught by the loader)."""
    rung = RUNGS["kinematic"]
    result = rung.rollout(scenario, rung.initial_state(scenario), np.zeros((1, len(scenario.actuated))), [0.0], 1e-3)
    if result.outcome == "unsafe":
        raise ScenarioError(scenario.path, [Problem("task.start", "the start state is inside the unsafe set; nothing can be planned from it")])


def run_ladder(
    scenario: Scenario,
    *,
    rungs: list[str] | None = None,
    seed: int | None = None,
    iterations: int = 2000,
    progress=None,
    seeded: bool = True,
    flat: bool = False,
    planner: str | None = None,
    time_limit: float | None = None,
) -> LadderResult:
    """Plan up the ladder; see the module docstring.

    seeded: replanning roots the tree at the previous plan's states replayed under the rung.
    flat: plan directly at the last rung with the same budget (the baseline).
    """
    if flat:
        rungs = (rungs or [r.model for r in scenario.spec.ladder.rungs])[-1:]
    check_start(scenario)
    spec = scenario.spec.ladder
    names = rungs or [r.model for r in spec.rungs]
    seed = spec.seed if seed is None else seed
    reports: list[RungReport] = []
    previous: RungReport | None = None
    for name in names:
        if progress:
            progress(name)
        rung = rung_for(scenario, name)
        if not rung.propagates:
            reports.append(_geometric(scenario, seed, iterations, planner))
            previous = reports[-1] if reports[-1].durations else None
            continue
        rung_spec = next((r for r in spec.rungs if r.model == name), None)
        h = rung_spec.h if rung_spec and rung_spec.h else _default_step(name)
        period = (rung_spec.control_period if rung_spec and rung_spec.control_period else None) or spec.control_period
        start = rung.initial_state(scenario)
        t0 = time.perf_counter()
        if previous is not None and previous.durations:
            replay = rung.rollout(scenario, start, np.array(previous.controls), np.array(previous.durations), h)
            if replay.outcome == "goal" and replay.ok:
                reports.append(RungReport(name, "replayed", "the previous plan holds under this rung", "goal",
                                          time.perf_counter() - t0, 0, 0, previous.controls, previous.durations, previous.states))
                previous = reports[-1]
                continue
        seeds, prefix_controls, prefix_durations = [], [], []
        if previous is not None and previous.durations and seeded:
            seeds, prefix_controls, prefix_durations = _replayed_prefix(scenario, rung, start, previous, h)
        plan = plan_control(scenario, rung, start, h=h, control_period=period, seed=seed, iterations=iterations,
                            planner=planner or (rung_spec.planner if rung_spec and rung_spec.planner else spec.planner),
                            extra_starts=seeds, time_limit=time_limit)
        if plan.start_index > 0:  # the path starts at a seed: splice the previous prefix in front
            j = plan.start_index
            plan = replace(plan, controls=np.concatenate([np.array(prefix_controls[:j]).reshape(j, -1), plan.controls]),
                           durations=np.concatenate([prefix_durations[:j], plan.durations]))
        wall = time.perf_counter() - t0
        outcome = "none"
        if len(plan.durations):
            outcome = rung.rollout(scenario, start, plan.controls, plan.durations, h).outcome
        ended = ("planned" if previous is None else "replanned") if plan.exact and outcome == "goal" else "failed"
        report = RungReport(name, ended, "" if ended != "failed" else "no exact plan within the iteration budget",
                            outcome, wall, plan.propagations, plan.iterations,
                            plan.controls.tolist(), plan.durations.tolist(), plan.states.tolist())
        reports.append(report)
        if ended == "failed":
            break
        previous = report
    return LadderResult(str(scenario.path), int(seed), reports)


def _geometric(scenario: Scenario, seed: int, iterations: int, planner: str | None) -> RungReport:
    """Plan the geometric rung and turn its path into commanded speeds for the actuated DOFs:
    each segment is driven at the speeds that cover it in whole control periods without
    exceeding any drive's max_speed. An approximate path (the goal set is thin: touching
    within a tolerance) is still offered to the next rung as a seed."""
    spec = scenario.spec.ladder
    rung_spec = next((r for r in spec.rungs if r.model == "geometric"), None)
    t0 = time.perf_counter()
    path = plan_geometric(scenario, seed=seed, iterations=iterations,
                          planner=(rung_spec.planner if rung_spec and rung_spec.planner else "RRTConnect"))
    period = spec.control_period
    index = [scenario.coordinates.index(n) for n in scenario.actuated]
    max_speed = np.array([scenario.body(n.split(".")[0]).actuators[n.split(".")[1]].max_speed for n in scenario.actuated])
    controls, durations = [], []
    for a, b in zip(path.states[:-1], path.states[1:]):
        delta = b[index] - a[index]
        periods = max(1, int(np.ceil(np.max(np.abs(delta) / max_speed / period, initial=0.0) - 1e-9)))
        controls.append((delta / (periods * period)).tolist())
        durations.append(periods * period)
    ended = "planned" if path.exact else "approximate"
    reason = "" if path.exact else "no path into the goal set within the budget; the closest one seeds the next rung"
    return RungReport("geometric", ended, reason, "goal" if path.exact else "none", time.perf_counter() - t0, 0,
                      path.iterations, controls, durations, path.states.tolist())


def _replayed_prefix(scenario, rung, start, previous, h):
    """The previous plan replayed under `rung` control by control, up to where it stops
    agreeing (unsafe, failed or goal): the states there seed the tree."""
    seeds, controls, durations = [], [], []
    state = start
    for u, d in zip(previous.controls, previous.durations):
        out = rung.rollout(scenario, state, np.array(u).reshape(1, -1), [d], h)
        if not out.ok or out.outcome != "none":
            break
        state = out.state
        seeds.append(state)
        controls.append(u)
        durations.append(d)
    return seeds, controls, np.array(durations, dtype=float)


def _default_step(name: str) -> float:
    return {"kinematic": 1e-2, "quasistatic-rigid": 1e-3, "quasistatic-compliant": 1e-3}.get(name, 1e-4)


def rung_names_until(top: str | None, names: list[str]) -> list[str]:
    if top is None:
        return names
    if top not in RUNG_ORDER:
        raise ValueError(top)
    return [n for n in names if RUNG_ORDER.index(n) <= RUNG_ORDER.index(top)]

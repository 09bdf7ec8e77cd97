"""The replan-on-upgrade pipeline: plan with the cheapest rung, then go up the ladder.

For each rung in order:

- ``geometric``: OMPL geometric planning in the C-space of the free DOFs with validity =
  non-penetration and not unsafe, toward goal states made by projection; its path becomes
  commanded speeds for the actuated DOFs (an approximate path too), which the next rung
  replays or is guided by;
- a rung whose physics along the previous plan is the same as the previous rung's (the
  rigid and compliant variants of one model when no contact carries force at the same step
  size) is "skipped", with the reason, and inherits the plan;
- a physics rung that takes more steps per control period than the physics rung above it is
  "omitted": no cheaper to plan with, it is left out and its budget passes up;
- a rung replays the previous plan's controls first: if they reach the goal as they are, the
  rung ends "replayed" (the cheapest way up: one rollout per control);
- else, when the previous plan holds under its own rung, the rung plans first with its own
  model at a coarser step (COARSE_FACTORS; the coarsest whose replay of the previous plan
  agrees with the rung's own) -- a "coarse stage", reported as a rung of its own
  (``dynamic-rigid@0.005``) -- and then tracks that plan at its own step, planning again at the
  coarse step from where tracking is lost (`_track_rounds`); a coarse propagation costs a
  fraction of the rung's, and the coarse plan is one the rung follows closely;
- else a rung above a physics rung *tracks* the previous plan (`planner.tracking`): the previous
  plan's states, recorded per control period under its own rung, are a reference; the rung
  follows it in closed loop, one control period at a time, keeping the previous control while
  its result stays close and otherwise the best of a few sampled controls around it (with a
  one-period look-ahead); where no candidate stays close, a short OMPL search from the last
  tracked states to the reference further along repairs it locally, and tracking goes on.
  Reaching the goal so, the rung ends "tracked" (or "replayed" when no control changed) or
  "repaired", with no global search;
- otherwise the rung plans again ("replanned"; "repaired" when its path starts at a tracked
  state): the tree is also rooted at the states of the tracked (or replayed) prefix that still
  agrees with the previous plan, the prefix is spliced in front of a path that starts at one
  of them (OMPL-CRIB section 5), and RRT / EST draw part of their samples near the previous
  plan's configurations;
- a rung with no usable previous plan plans from scratch ("planned").

The ladder's budget is the flat baseline's: a rung may spend, on top of its own iterations,
those the rungs below it left unspent (a replayed or skipped rung spends none); why, measured:
docs/measurements.md.

Each rung's report says how it ended (`PlanStatus`), wall time, propagations and planner
iterations (of its searches, local repairs included), tracking's rollouts, the fraction of the
previous plan's duration it tracked and where tracking was last lost, how far the accepted
plan ends from the goal, the largest penetration along it, and how many propagations ended in
a solver failure.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import KW_ONLY, asdict, dataclass, field, replace

import numpy as np

from models.rungs import State, rung_for
from models.scenario import Problem, Scenario, ScenarioError, plan_problems
from models.task import Outcome, classify, goal_distance
from planner.clock import compiler_seconds, planning_clock
from planner.ompl_adapter import latest_goal_time, plan_control, plan_geometric, segment_periods, steered_coordinates
from planner.plan_status import PlanStatus
from planner.pushing import free_turn, push_reference
from planner.tracking import TRACK_TOLERANCE, PoseError, Reference, Tracked, track

#: Words of a rung's outcome and its solver status in a report.
GOAL, NONE, OK = Outcome.GOAL.label, Outcome.NONE.label, "ok"


@dataclass
class RungReport:
    rung: str
    ended: PlanStatus  # how the rung ended; its `label` is what the JSON files write
    reason: str = ""  # why, in words ("" for a plan found with nothing to add)
    _: KW_ONLY  # (the rest by name: a field added among them shifted a caller's positional counts)
    outcome: str = NONE  # what the accepted controls reach under this rung (an Outcome label)
    wall_s: float = 0.0
    compile_s: float = 0.0  # of wall_s, the time spent compiling (or loading) the physics kernels (a fresh clone's first plan)
    propagations: int = 0
    iterations: int = 0
    goal_distance: float | None = None  # of the accepted plan's last state (0 in the goal)
    max_penetration: float = 0.0  # along the accepted plan under this rung, m
    contact_steps: int = 0  # steps of that replay in which a contact carried force
    solver_failures: int = 0  # propagations that ended in a numerical failure while planning
    status: str = OK  # the replay's solver status
    tracked: float | None = None  # fraction of the previous plan's duration tracked (None: not tracked)
    diverged_at: float | None = None  # where along the previous plan tracking was (last) lost, s
    repairs: int = 0  # local repairs tried (short searches from tracked states; see planner.tracking)
    rollouts: int = 0  # control periods rolled out by tracking (candidates), beside the search's propagations
    h: float | None = None  # the time step this rung's plan was made and checked at, s (None: geometric)
    stage: str = ""  # "coarse": the rung's model at a coarser step, planned before the rung itself (see COARSE_FACTORS)
    controls: list = field(default_factory=list)
    durations: list = field(default_factory=list)
    states: list = field(default_factory=list)

    @property
    def label(self) -> str:
        """The rung's name, with the step for a coarse stage ("dynamic-rigid@0.005")."""
        return f"{self.rung}@{self.h:g}" if self.stage else self.rung


@dataclass
class LadderResult:
    scenario: str
    seed: int
    rungs: list[RungReport]
    scene: dict = field(default_factory=dict)  # scene_record: what the plan is a plan of
    complete: bool = True  # False: interrupted; `rungs` are the rungs finished before that
    budget: dict = field(default_factory=dict)  # what the rungs were given (`rung_budgets`) and whether flat

    @property
    def top_holds(self) -> bool:
        """The ladder's answer: its last rung accepted a plan that reaches the goal under it."""
        return self.complete and bool(self.rungs) and self.rungs[-1].ended.holds and self.rungs[-1].outcome == GOAL

    def to_json(self, timings: bool = True) -> dict:
        """The plan; without timings it is a pure function of the scenario and the seed."""
        rungs = [rung_json(r, timings) for r in self.rungs]
        return {
            "scenario": self.scenario,
            "scene": self.scene,
            "seed": self.seed,
            "budget": self.budget,
            "complete": self.complete,
            "top_holds": self.top_holds,
            "rungs": rungs,
        }


def rung_json(report: RungReport, timings: bool = True) -> dict:
    """A rung's report as plan.json and the service's rung_ended events write it: its fields,
    `label` after `rung` (a coarse stage's "dynamic-rigid@0.002", which tells it from the rung
    itself), how it ended by its label and, right after it, by its status's name (`cause`: a
    `failed` rung's budget_exhausted, timeout, failed, past_horizon or aborted; `exact` for
    `planned`); without timings, no wall_s or compile_s."""
    fields = asdict(report)
    data = {"rung": fields.pop("rung"), "label": report.label}
    for key, value in fields.items():
        data[key] = value
        if key == "ended":
            data["ended"], data["cause"] = report.ended.label, report.ended.name.lower()
    if not timings:
        del data["wall_s"], data["compile_s"]
    return data


def plan_json_text(result: LadderResult) -> str:
    """The text of plan.json (the CLI's and the service's): the plan without timings, so the
    same scenario and seed give the same bytes."""
    return json.dumps(result.to_json(timings=False), indent=1) + "\n"


def scene_record(scenario: Scenario) -> dict:
    """What a plan is a plan of: the scenario's name, the sha256 of its contents after the
    parameters are applied (the validated spec as canonical JSON), the parameter values and
    the coordinates the controls drive, in the controls' order."""
    spec = json.dumps(scenario.spec.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))
    return {
        "name": scenario.spec.scenario.name,
        "sha256": hashlib.sha256(spec.encode()).hexdigest(),
        "parameters": dict(scenario.parameters),
        "controls": list(scenario.actuated),
    }


def scene_mismatch(record, scenario: Scenario) -> list[str]:
    """Why a plan with scene `record` cannot be replayed on `scenario` ([] if it can)."""
    if not isinstance(record, dict) or not {"name", "sha256", "controls"} <= set(record):
        return ["the plan does not say which scene it is of (plan it again with this version of ladder)"]
    here = scene_record(scenario)
    reasons = []
    if record["name"] != here["name"]:
        reasons.append(f"it is of scenario {record['name']!r}, this file is {here['name']!r}")
    if record["controls"] != here["controls"]:
        reasons.append(
            f"its controls drive {', '.join(record['controls']) or 'nothing'}, this scene's {', '.join(here['controls']) or 'nothing'}"
        )
    if record["sha256"] != here["sha256"] and not reasons:
        theirs = record.get("parameters") or {}
        changed = [f"{k} = {theirs[k]:g} in the plan, {v:g} here" for k, v in here["parameters"].items() if k in theirs and theirs[k] != v]
        reasons.append(
            "the scene's contents differ (sha256 of the resolved scenario)" + (f": parameters {'; '.join(changed)}" if changed else "")
        )
    return reasons


def check_start(scenario: Scenario) -> None:
    """A start inside the unsafe set is bad input (penetration is caught by the loader), and so
    is what `plan_problems` finds: nothing actuated, a scripted obstacle (plan states carry no
    time, so a moving obstacle's pose at a state is unknown; simulate and sweep run such scenes
    from t = 0), a horizon shorter than a control period."""
    problems = plan_problems(scenario.spec)
    if problems:
        raise ScenarioError(scenario.path, problems)
    if classify(scenario, scenario.start) is Outcome.UNSAFE:
        raise ScenarioError(
            scenario.path, [Problem("task.start", "the start state is inside the unsafe set; nothing can be planned from it")]
        )


def rung_budgets(
    scenario: Scenario, names: list[str], iterations: int | None = None, time_limit: float | None = None, flat: bool = False
) -> tuple[dict[str, int], dict[str, float]]:
    """Each rung's planner iterations and time limit, in the ladder's order: `iterations` and
    `time_limit` where given, else the scenario's for the rung. Flat: the top rung alone, with
    the sums of the ladder's (the baseline's equal budget)."""
    settings = {name: scenario.rung_settings(name) for name in names}
    budgets = {name: iterations if iterations is not None else settings[name].iterations for name in names}
    limits = {name: time_limit if time_limit is not None else settings[name].time_limit for name in names}
    if flat:
        return {names[-1]: sum(budgets.values())}, {names[-1]: sum(limits.values())}
    return budgets, limits


def run_ladder(
    scenario: Scenario,
    *,
    rungs: list[str] | None = None,
    seed: int | None = None,
    iterations: int | None = None,
    progress=None,
    seeded: bool = True,
    guided: bool = True,
    flat: bool = False,
    planner: str | None = None,
    time_limit: float | None = None,
    stop=None,
    rung_done=None,
) -> LadderResult:
    """Plan up the ladder; see the module docstring.

    seeded: replanning roots the tree at the previous plan's states replayed under the rung.
    guided: replanning RRT / EST sample near the previous plan's configurations.
    iterations: planner iterations per rung; None: each rung's budget from the scenario
    (`iterations` of the rung, else of [ladder], 2000 by default). A rung may also spend the
    iterations the rungs below it left unspent (a replayed or skipped rung spends none): the
    whole ladder never exceeds the sum.
    time_limit: a wall-clock cap per rung in seconds, on `planner.clock.planning_clock` (time
    spent compiling kernels not counted); None: the scenario's (`time_limit` of the rung, else
    of [ladder]). A safety net on top of the iterations: time a rung leaves passes up too, and
    a plan is reproducible unless a cap ends a search.
    flat: plan directly at the last rung, with the budget of the whole ladder (the sums of the
    rungs' iterations and time limits): the baseline.
    progress: called as progress(rung, iterations, propagations) while a rung plans.
    stop: a function -> True when the planning should stop (Ctrl-C): the rung under way ends
    its search and is dropped, and the result holds the rungs finished, complete = False.
    rung_done: called as rung_done(report) with each rung's RungReport as the rung finishes
    (the service's live per-rung reports); it does not change the plan.
    """
    check_start(scenario)
    spec = scenario.spec.ladder
    names = rungs or [r.model for r in spec.rungs]
    settings = {name: scenario.rung_settings(name) for name in names}
    budgets, limits = rung_budgets(scenario, names, iterations, time_limit, flat)
    names = list(budgets)
    seed = spec.seed if seed is None else seed
    stopped = stop or (lambda: False)
    budget = _Budget()
    reports: list[RungReport] = []
    previous: RungReport | None = None
    interrupted = False
    for i, name in enumerate(names):
        if stopped():
            interrupted = True
            break
        budget.add(budgets[name], limits[name])
        dearer = _no_cheaper(scenario, names[i:], settings)
        if dearer:  # its iterations and time pass up unspent
            report = RungReport(name, PlanStatus.OMITTED, f"{PlanStatus.OMITTED.message}: {dearer}", h=settings[name].h)
            reports.append(report)
            if rung_done:
                rung_done(report)
            continue
        if progress:
            progress(name, 0, 0)
        rung = rung_for(scenario, name)
        step = _Step(scenario, name, rung, settings[name], seed, budgets[name], budget.left(reports), budget, stop, time.perf_counter())
        climbed = _climb(step, previous, planner, seeded, guided, progress)
        if climbed is None:  # interrupted: the rung under way is dropped
            interrupted = True
            break
        own_h = step.h if step.rung.propagates else None
        climbed = [r if r.stage else replace(r, h=own_h) for r in climbed]
        report = climbed[-1]
        if report.ended.holds and not step.rung.propagates and math.fsum(report.durations) > latest_goal_time(scenario):
            # a geometric path reaches the goal at its end (a propagating rung's plans are held to it as they are accepted: `_in_time`)
            reason = _past_horizon_reason(scenario, math.fsum(report.durations)) + (f"; {report.reason}" if report.reason else "")
            climbed[-1] = report = replace(report, ended=PlanStatus.PAST_HORIZON, reason=reason)
        if not report.ended.holds and step.rung.propagates and name != names[-1]:
            climbed[-1] = report = _goes_on(report)
        for done in climbed:
            reports.append(done)
            if rung_done:
                rung_done(done)
        if not step.rung.propagates:
            previous = report if report.durations else None
        else:
            previous = report if (report.ended.holds or (report.durations and report.states)) else None
    record = {"flat": bool(flat), "iterations": budgets, "time_limit_s": limits}
    return LadderResult(str(scenario.path), int(seed), reports, scene_record(scenario), complete=not interrupted, budget=record)


def _no_cheaper(scenario: Scenario, names: list[str], settings: dict) -> str:
    """Why the physics rung names[0] is left out ("" if it is not): it takes more steps per
    control period than the physics rung above it (names[1]), so a propagation costs no less
    there (box_push_3d's kinematic rung at 1e-2 s under a quasi-dynamic rung at one
    0.1 s step per period: 0.35 against 0.3 ms, measured in docs/measurements.md, "Rungs no
    cheaper"), while its plans still have to be carried up by one more rung."""
    if len(names) < 2 or settings[names[0]].h is None or settings[names[1]].h is None:
        return ""
    here, above = (settings[n].control_period / settings[n].h for n in names[:2])
    if round(here) <= round(above):
        return ""
    return (
        f"{round(here)} step(s) per control period at h = {settings[names[0]].h:g} s against "
        f"{round(above)} of {names[1]} at h = {settings[names[1]].h:g} s"
    )


class _Budget:
    """The ladder's budget: a rung may spend what the rungs below left unspent, so the whole
    ladder's is the flat baseline's (iterations, and wall time)."""

    def __init__(self):
        self.allowance, self.deadline = 0, planning_clock()

    def add(self, iterations: int, seconds: float) -> None:
        self.allowance += iterations
        self.deadline += seconds

    def left(self, reports: list[RungReport]) -> int:
        return self.allowance - sum(r.iterations for r in reports)

    def seconds(self) -> float:
        return self.deadline - planning_clock()


@dataclass
class _Step:
    """One rung of the ladder under way: what it plans with."""

    scenario: Scenario
    name: str
    rung: object  # models.rungs.Rung
    settings: object  # models.scenario.RungSettings
    seed: int
    own: int  # the rung's own iterations
    iterations: int  # what the rung may spend (its own and what the rungs below left)
    budget: _Budget
    stop: object
    t0: float
    step: float | None = None  # a coarse stage's time step (None: the rung's own)
    c0: float = field(default_factory=compiler_seconds)  # `compiler_seconds` at t0

    def spent(self) -> dict:
        """A report's timings: wall_s since t0 and compile_s, the part of it in numba's compiler."""
        return {"wall_s": time.perf_counter() - self.t0, "compile_s": compiler_seconds() - self.c0}

    @property
    def h(self) -> float:
        return self.step or self.settings.h

    @property
    def period(self) -> float:
        return self.settings.control_period

    def start(self) -> State:
        return self.rung.initial_state(self.scenario)

    def stopped(self) -> bool:
        return bool(self.stop and self.stop())


def _climb(
    step: _Step, previous: RungReport | None, planner, seeded: bool, guided: bool, progress, coarse: bool = True, replay=None
) -> list[RungReport] | None:
    """How the rung takes the previous plan up, the cheapest way that holds: skip (the same
    physics), replay, else (with `coarse`) plan at a coarser step first and track that
    (`_coarse_first`), else track, else search; the rung's reports (a coarse stage's, then
    its own), None when stopped. `replay`: the previous plan already replayed at this step."""
    if not step.rung.propagates:
        report = _geometric(step.scenario, step.seed, step.own, step.budget.seconds(), stop=step.stop)
        return None if step.stopped() else [report]
    carried = previous is not None and previous.durations
    if carried and previous.ended.holds:
        same = _same_physics(step.scenario, previous, step.name, step.h)
        if same:
            return [_skipped(step, previous, same)]
    tracked = None
    if carried and replay is None:  # the cheapest first: the previous controls as they are (one rollout per control)
        replay = _replay(step.scenario, step.rung, step.start(), previous, step.h, step.period)
        if step.stopped():
            return None
    if carried and _reaches(replay):
        report = _replayed(step, previous, replay)
        if _in_time(step, report):
            return [report]
    if carried and previous.rung == "geometric":  # the object's path, pushed (planner.pushing)
        pushed = _push(step, previous)
        if step.stopped():
            return None
        if pushed is not None:
            pushed_replay = _Replay.of(pushed)
            report = _tracked(step, pushed, pushed_replay, pushed=True) if _reaches(pushed_replay) else None
            if report is not None and _in_time(step, report):
                return [report]
            # where the push is lost, the search is the one without it: seeded with the geometric
            # plan's replay (seeded with the pushed states instead, 2 of 20 box_rotate_3d seeds failed)
            report = _search(step, previous, replay, None, planner, seeded, guided, progress, pushed=pushed)
            return None if report is None else [report]
    if carried and previous.rung != "geometric":
        if coarse and previous.ended.holds:  # not from a failed rung's partial plan (strike.toml: 3 of 5 seeds hold so, 5 of 5 not)
            found = _coarser_step(step, previous, replay)
            if found is not None:
                return _coarse_first(step, previous, planner, seeded, guided, progress, *found, replay)
        tracked = _track(step, previous)
        replay = _Replay.of(tracked)
        if step.stopped():
            return None
        report = _tracked(step, tracked, replay) if _reaches(replay) else None
        if report is not None and _in_time(step, report):
            return [report]
    report = _search(step, previous, replay, tracked, planner, seeded, guided, progress)
    return None if report is None else [report]


#: A physics rung whose replay of the previous plan does not hold plans first with its own
#: model at a step this many times its own (the largest that agrees, tried in this order) and
#: then tracks that plan at its own step: a coarser step costs proportionally less per
#: propagation, and where its trajectories agree with the rung's own (COARSE_AGREEMENT), what it
#: plans the rung tracks closely. Measured: docs/measurements.md, "A coarser step first".
COARSE_FACTORS = (5, 2)
#: The coarser step's replay of the previous plan agrees with the rung's own replay: every
#: state at a control switch within this distance (tracking's `PoseError`, m): half of what
#: tracking tolerates, which leaves it room to correct (at TRACK_TOLERANCE box_push_3d takes
#: 10x steps whose plans it tracks less far).
COARSE_AGREEMENT = TRACK_TOLERANCE / 2


def _coarser_step(step: _Step, previous: RungReport, replay: _Replay) -> tuple[float, _Replay] | None:
    """The coarsest step (COARSE_FACTORS times the rung's; at most the control period, which it
    divides) whose replay of the previous plan agrees with `replay`, the rung's own, at every
    control switch both reached (COARSE_AGREEMENT) and ends the same way, and that replay;
    None if none does."""
    scenario, error = step.scenario, PoseError(step.scenario)
    for factor in COARSE_FACTORS:
        h = factor * step.h
        steps = step.period / h
        if h > step.period or abs(steps - round(steps)) > 1e-9:
            continue
        rough = _replay_controls(scenario, step.rung, step.start(), previous.controls, previous.durations, h, _Replay.empty(step.start()))
        if step.stopped():
            return None
        if rough.status != OK or rough.outcome != replay.outcome:
            continue
        pairs = list(zip(rough.states, replay.states)) + [(rough.state, replay.state)]
        if len(rough.states) == len(replay.states) and all(error(a.q, b.q) <= COARSE_AGREEMENT for a, b in pairs):
            return h, rough
    return None


def _coarse_first(
    step: _Step, previous: RungReport, planner, seeded: bool, guided: bool, progress, h: float, rough: _Replay, replay: _Replay
) -> list[RungReport] | None:
    """The rung's model at step h takes the previous plan up (a coarse stage, its own report),
    then the rung at its own step takes the coarse stage's plan up (tracking it), within the
    rung's iterations; a coarse stage that finds no plan leaves the rung the previous plan (and
    `replay`, its replay at the rung's own step)."""
    # the coarse stage starts from the replay `_coarser_step` made (`rough`), settled as `_replay` would
    settled = _settled(step.scenario, step.rung, rough, previous, h, step.period)
    climbed = _climb(replace(step, step=h), previous, planner, seeded, guided, progress, coarse=False, replay=settled)
    if climbed is None:
        return None
    stage = replace(
        climbed[0],
        h=h,
        stage="coarse",
        reason=f"at h = {h:g} s ({h / step.h:g} x the rung's step, whose replay of the previous plan it agrees with): "
        + (climbed[0].reason or climbed[0].ended.message),
    )
    rest = replace(step, iterations=step.iterations - stage.iterations, t0=time.perf_counter(), c0=compiler_seconds())
    if not stage.ended.holds:
        own = _climb(rest, previous, planner, seeded, guided, progress, coarse=False, replay=replay)
        if own is not None and rest.iterations <= 0 and not own[-1].ended.holds:  # its search had no iteration to run
            why = f"{own[-1].reason or own[-1].ended.message} (the coarse stage spent the rung's {step.iterations} iterations)"
            own = [*own[:-1], replace(own[-1], reason=why)]
        return None if own is None else [stage, *own]
    tracked = _track_rounds(rest, stage, h)
    if step.stopped():
        return None
    replay = _Replay.of(tracked)
    report = _tracked(rest, tracked, replay) if _reaches(replay) else None
    if report is not None and _in_time(rest, report):
        return [stage, report]
    own = _search(rest, stage, replay, tracked, planner, seeded, guided, progress)
    return None if own is None else [stage, own]


#: Where the rung loses track of its coarse stage's plan, it
#: plans again at the coarse step from the last tracked state and tracks that, up to this many
#: times in all, before it searches at its own step (the expensive way); tracking makes no local
#: repairs at the rung's own step here: re-planning at the coarse step is the cheaper repair.
COARSE_ROUNDS = 6
#: The coarse re-plans spend at most this share of the rung's iterations; the rest is kept for
#: the search at the rung's own step, which does not depend on the coarse step agreeing with the
#: rung's (as tracking's local repairs are capped, `planner.tracking.REPAIR_ITERATIONS`). Where a
#: coarse plan from a tracked state is lost again at once, the coarse step disagrees there, and
#: re-plans had spent the whole budget: box_push_3d seed 5, box_rotate_3d seed 25 and
#: push_past_post seed 25 failed with no iteration left to search, and hold so (seeds 1-40 of
#: these, of two_finger_triangle and four_finger_grasp, and strike's 1-20: no other seed's
#: outcome changed; docs/measurements.md, sixtieth session). A coarse plan that tracking loses in
#: its first period ends the rounds at once (the coarse step disagrees with the rung's there):
#: push_past_post seeds 16 and 17 then hold too.
COARSE_SHARE = 0.5


def _track_rounds(step: _Step, stage: RungReport, h: float) -> Tracked:
    """Track the coarse stage's plan at the rung's own step; where tracking is lost, plan
    again with the coarse step from the last tracked state (guided by the rest of the plan
    being tracked) and track that, up to COARSE_ROUNDS plans in all, within the rung's
    iterations (at most COARSE_SHARE of them), and no more once a plan is lost in its first
    period. One run: the tracked controls of every round, from the start."""
    scenario, rung, period = step.scenario, step.rung, step.period
    start = step.start()
    run = Tracked(start)
    controls, durations = stage.controls, stage.durations
    state, left = start, int(step.iterations * COARSE_SHARE)
    for k in range(COARSE_ROUNDS):
        reference = Reference.of(scenario, rung, state, controls, durations, h, period)
        part = track(
            scenario, rung, state, reference, step.h, period, step.seed + k, repairs=0, time_limit=step.budget.seconds(), stop=step.stop
        )
        run.extend(part, first=k == 0)
        left -= part.repair_iterations
        if part.outcome == GOAL or step.stopped() or left <= 0 or k + 1 == COARSE_ROUNDS:
            break
        if len(part.controls) == 0:  # lost in its first period: the coarse step disagrees with the rung's here
            break
        t = part.diverged_at if part.diverged_at is not None else len(part.controls) * period
        before = len(run.controls) - len(part.controls)  # the rounds before this one's
        cut = _time_left_for_search(scenario, run, before)
        if cut < len(run.controls):  # the search starts where it has time to reach the goal
            t = min(t, (cut - before) * period)
            run.truncate(cut)
        guide = np.array([reference.configuration(x) for x in np.arange(t, reference.duration + 1e-9, period)])
        plan = plan_control(
            scenario,
            rung,
            run.state,
            h=h,
            control_period=period,
            seed=step.seed + COARSE_STRIDE * (k + 1),
            iterations=left,
            guide=guide if len(guide) else None,
            time_limit=step.budget.seconds(),
            stop=step.stop,
            horizon=scenario.spec.task.horizon,
            start_times=[math.fsum(run.durations)],
        )
        left -= plan.iterations
        run.repairs += 1
        run.repair_iterations += plan.iterations
        run.repair_propagations += plan.propagations
        if not plan.exact:
            break
        run.repaired += 1
        state, controls, durations = run.state, plan.controls, plan.durations
    return run


#: Seed offset between a rung's coarse re-plans.
COARSE_STRIDE = 15485863
#: A coarse re-plan starts from a tracked state at least this long before the task's horizon
#: (s; at most SEARCH_SHARE of the horizon). Tracking that follows a plan reaching the goal
#: near the horizon goes on to it (the reference's last periods and TRACK_SETTLE more) and may
#: end there, within TRACK_TOLERANCE of the goal set but outside it (the post scene in
#: tests/data: 2.6 mm out at 12 s); a search from that state has no time left and had spent
#: the rung's whole budget in vain.
SEARCH_TIME = 2.0
SEARCH_SHARE = 0.25


def _time_left_for_search(scenario: Scenario, run: Tracked, floor: int) -> int:
    """How many of `run`'s controls (at least `floor`: those of the rounds before) to keep so
    that a search from the state after them has time before the task's horizon (SEARCH_TIME)."""
    left = min(SEARCH_TIME, SEARCH_SHARE * scenario.spec.task.horizon)
    keep = int(np.searchsorted(np.cumsum(run.durations), latest_goal_time(scenario) - left, side="right"))
    return max(floor, min(keep, len(run.controls)))


def _skipped(step: _Step, previous: RungReport, reason: str) -> RungReport:
    return replace(
        previous,
        rung=step.name,
        ended=PlanStatus.SKIPPED,
        reason=reason,
        **step.spent(),
        propagations=0,
        iterations=0,
        solver_failures=0,
    )


def _tracked(step: _Step, tracked: Tracked, replay: _Replay, pushed: bool = False) -> RungReport:
    """The rung's report of a plan tracking made; `pushed`: tracking a pushing reference along the
    geometric rung's object path (`_push`), which is tracked, never replayed."""
    ended = PlanStatus.REPAIRED if tracked.repaired else PlanStatus.TRACKED if tracked.corrected or pushed else PlanStatus.REPLAYED
    return RungReport(
        step.name,
        ended,
        _tracking_reason(ended, tracked, pushed),
        **step.spent(),
        propagations=tracked.repair_propagations,
        iterations=tracked.repair_iterations,
        controls=list(tracked.controls),
        durations=list(tracked.durations),
        states=replay.configurations(step.start()),
        tracked=tracked.fraction,
        repairs=tracked.repairs,
        rollouts=tracked.rollouts,
        **replay.fields(step.scenario),
    )


def _replayed(step: _Step, previous: RungReport, replay: _Replay) -> RungReport:
    """The previous plan's controls that hold under the rung as they are (the states are this
    rung's: a geometric path's move passive bodies on their own)."""
    hold = [[0.0] * len(step.scenario.actuated)] * replay.held
    reason = PlanStatus.REPLAYED.message + (
        f" (its drives held still for {replay.held} control period(s) at the end)" if replay.held else ""
    )
    return RungReport(
        step.name,
        PlanStatus.REPLAYED,
        reason,
        **step.spent(),
        controls=list(previous.controls) + hold,
        durations=list(previous.durations) + [step.period] * replay.held,
        states=replay.configurations(step.start()),
        **replay.fields(step.scenario),
    )


def _search(step: _Step, previous, replay, tracked, planner, seeded: bool, guided: bool, progress, pushed=None) -> RungReport | None:
    """Plan at the rung with OMPL, rooted also at the replayed (or tracked) states that still
    agree with the previous plan and guided by its configurations; the plan's prefix from the
    root it starts at is spliced in front. `pushed`: a push along the geometric plan's object
    path tracked first (`_push`) and lost: its costs count in the rung's."""
    scenario, start = step.scenario, step.start()
    seeds, prefix_controls, prefix_durations = [], [], np.zeros(0)
    if replay is not None and seeded:
        # tracked states agree with the previous plan by construction (TRACK_TOLERANCE)
        m = len(replay.states) if tracked is not None else _agreeing(scenario, replay, previous)
        seeds, prefix_controls, prefix_durations = replay.states[:m], replay.controls[:m], np.array(replay.durations[:m])
    # the geometric path moves passive bodies on their own: its states are no guide for physics
    # (after tracking failed the previous plan still guides: docs/measurements.md, "No guide")
    usable = previous is not None and previous.states and previous.rung != "geometric"
    guide = np.array(previous.states) if usable and guided else None
    spent = tracked or pushed
    budget = step.iterations - (spent.repair_iterations if spent else 0)
    plan = _plan_with_restarts(
        scenario,
        step.rung,
        start,
        h=step.h,
        control_period=step.period,
        seed=step.seed,
        iterations=budget,
        planner=planner or step.settings.planner,
        extra_starts=seeds,
        guide=guide,
        time_limit=step.budget.seconds(),
        stop=step.stop,
        progress=(lambda i, n, _name=step.name: progress(_name, i, n)) if progress else None,
        horizon=scenario.spec.task.horizon,
        start_times=[0.0, *np.cumsum(prefix_durations)[: len(seeds)].tolist()],
    )
    if step.stopped():
        return None
    j = plan.start_index
    if j > 0:  # the path starts at a seed: splice the previous prefix in front
        plan = replace(
            plan,
            controls=np.concatenate([np.array(prefix_controls[:j]).reshape(j, -1), plan.controls]),
            durations=np.concatenate([prefix_durations[:j], plan.durations]),
        )
    # the plan replayed from the start: the prefix's part is known, the rest runs from the seed it starts at
    head = replay.head(j) if j > 0 else _Replay.empty(start)
    tail = _replay_controls(scenario, step.rung, head.state, plan.controls[j:], plan.durations[j:], step.h, head)
    fields = tail.fields(scenario)
    reaches = _reaches(tail)
    goal_t = _goal_time(step, plan) if plan.exact and reaches else math.inf  # (one replay at most: `_goal_time`)
    accepted = goal_t <= latest_goal_time(scenario)
    passed_up = False  # (a failed search's partial plan is the previous plan's run: `_closer_partial`)
    if accepted:
        ended, reason = (PlanStatus.EXACT if previous is None else PlanStatus.REPLANNED), ""
        if ended is PlanStatus.REPLANNED and guide is None:  # the status's words say "guided by it"
            why = " (a geometric path is no guide for physics)" if previous.rung == "geometric" else "" if guided else " (--no-guide)"
            reason = f"the previous plan did not hold; a search found a plan into the goal set{why}"
        elif ended is PlanStatus.REPLANNED:
            reason = ended.message
        if tracked is not None and j > 0:
            ended = PlanStatus.REPAIRED
            reason = _tracking_reason(ended, tracked) + f"; then a search from tracked state {j} of {len(seeds)} to the goal"
        elif tracked is not None:
            reason = _tracking_reason(ended, tracked) + "; then a search from the start"
        if replay is not None and _reaches(replay):  # the previous plan did reach the goal: refused by `_in_time`
            how = f"; {_tracking_words(tracked)}" if tracked is not None else ""
            start_words = f"tracked state {j} of {len(seeds)}" if j > 0 else "the start"
            reason = (
                f"the previous plan reaches the goal later than the task's horizon allows ({scenario.spec.task.horizon:g} s{how}); "
                f"a search from {start_words} found a plan into the goal set within it"
            )
    elif not plan.exact:
        ended = plan.status
        reason = ended.message + (f" ({plan.iterations} of {budget} iterations)" if ended is PlanStatus.TIMEOUT else "")
        if plan.past_horizon:
            from planner.cli import counted

            reason += f"; {counted(plan.past_horizon, 'control')} would have ended past the task's horizon ({_horizon_words(scenario)})"
        closer = _closer_partial(step, replay, fields, tracked=tracked is not None, searched=plan.iterations > 0, pushed=pushed)
        if closer is not None:  # the partial plan passed up is the previous plan's run under the rung
            words, tail = closer
            reason += words
            plan = replace(plan, controls=np.array(tail.controls, float), durations=np.array(tail.durations, float))
            fields, passed_up = tail.fields(scenario), True
    elif reaches:  # the prefix of the previous plan to the root it starts at ran past the horizon
        ended = PlanStatus.PAST_HORIZON
        reason = _past_horizon_reason(scenario, goal_t)
    else:
        ended = PlanStatus.FAILED
        reason = f"{ended.message} ({fields['outcome']}, {fields['status']})"
    if pushed is not None:
        reason = f"{reason or ended.message}; before the search, {_tracking_words(pushed, True)}"
    elif tracked is not None and not accepted:  # (the table's `tracked` column is this tracking's: say so)
        partial = previous is not None and previous.outcome != GOAL  # (a plan refused as late does reach it)
        reason = f"{reason or ended.message}; before the search, {_tracking_words(tracked, partial=partial)}"
    # an accepted plan's states are its replay's under this rung, from the start (the tree's
    # path begins at its root, which may be a seed part-way along the prefix: so are a spliced
    # plan's that is not accepted, whose controls begin with the prefix)
    return RungReport(
        step.name,
        ended,
        reason,
        **step.spent(),
        propagations=plan.propagations + (spent.repair_propagations if spent else 0),
        iterations=plan.iterations + (spent.repair_iterations if spent else 0),
        solver_failures=plan.failures,
        controls=plan.controls.tolist(),
        durations=plan.durations.tolist(),
        states=tail.configurations(start) if accepted or passed_up or j > 0 else plan.states.tolist(),
        tracked=None if spent is None else spent.fraction,
        diverged_at=None if spent is None else spent.diverged_at,
        repairs=0 if spent is None else spent.repairs,
        rollouts=0 if spent is None else spent.rollouts,
        **fields,
    )


def _closer_partial(step: _Step, replay: _Replay | None, fields: dict, tracked: bool = False, searched: bool = True, pushed=None):
    """Where a search found no plan, the previous plan's replay (or tracked run) under the rung, or
    the run of a push along the geometric plan's object path (`pushed`, tracked before the search
    and lost), as the partial plan to pass up: the one that ends closest to the goal, if closer
    than the search's closest path (the start where the search ran no iteration: `searched`
    False): (the reason's words, the run), else None. Only a run's controls that end within the
    task's horizon count, as a search's do. A grasp the geometric path missed by 1.4 mm had been
    dropped for a search's path 0.85 m away (the paper's scene at a 0.76 s horizon); a push lost
    part way (tests/data/push_past_post.toml, seed 9: the box 0.245 m from the goal) for the
    geometric plan's replay, whose robot pushes nothing along (0.48 m). A run that reached the
    goal (late: the plan the rung refused), or ended unsafe or in a solver failure, is not one."""
    candidates = [(replay, "the previous plan's " + ("tracked run" if tracked else "replay"))]
    if pushed is not None:
        candidates.append((_Replay.of(pushed), "the push along the geometric plan's object path, its tracked run"))
    best = None
    for run, what in candidates:
        if run is None or not run.controls or run.outcome != NONE or run.status != OK:
            continue
        ends = np.cumsum(run.durations)
        m = int(np.searchsorted(ends, latest_goal_time(step.scenario), side="right"))
        if m == 0:
            continue
        whole = m == len(run.controls)
        run = run if whole else run.head(m)
        own = run.fields(step.scenario)["goal_distance"]
        if own < fields["goal_distance"] and (best is None or own < best[0]):
            within = "" if whole else f" (its first {m} controls, those within {_horizon_words(step.scenario)})"
            best = (own, what + within, run)
    if best is None:
        return None
    own, what, run = best
    closest = (
        f"the search's closest path ends {fields['goal_distance']:.3g} m from it"
        if searched
        else f"the search had no iteration left to run; the start is {fields['goal_distance']:.3g} m from it"
    )
    return f"; {what}, {own:.3g} m from the goal, is the partial plan passed up ({closest})", run


def _horizon_words(scenario: Scenario) -> str:
    return f"the task's horizon, {scenario.spec.task.horizon:g} s"


def _past_horizon_reason(scenario: Scenario, t: float) -> str:
    return f"{PlanStatus.PAST_HORIZON.message}: it reaches the goal at t = {t:.4g} s ({_horizon_words(scenario)})"


def _goal_time(step: _Step, plan) -> float:
    """When a plan (its `controls` and `durations`) that reaches the goal under the step's rung
    reaches it: at most its durations' sum (the planners' last control runs on past the goal, 1 to
    10 periods, where a rollout stops), else its rollout from the start, which stops there."""
    total = math.fsum(plan.durations)
    if total <= latest_goal_time(step.scenario):
        return total
    out = step.rung.rollout(step.scenario, step.start(), np.array(plan.controls, float), np.array(plan.durations, float), step.h)
    return out.t if out.outcome == GOAL and out.status == OK else math.inf  # (never seen: the replay that reached it agrees)


def _in_time(step: _Step, plan) -> bool:
    """Whether a plan reaches the goal within the task's horizon (`[task] horizon`). The search
    keeps its own states within it (`planner.ompl_adapter._Propagator`), but the previous rung's
    plan, replayed with the drives held still at its end or tracked with repairs, or a search's
    path from a root part-way along it, can come out later."""
    return _goal_time(step, plan) <= latest_goal_time(step.scenario)


def _reaches(replay: _Replay) -> bool:
    """Whether a replayed (or tracked) plan ends in the goal with every step solved."""
    return replay.outcome == GOAL and replay.status == OK


def _goes_on(report: RungReport) -> RungReport:
    """A rung that cannot express the task (a kinematic rung where only momentum reaches the
    goal) does not end the ladder: its best partial plan guides the next rung."""
    partial = bool(report.durations) and bool(report.states)
    more = "the next rung guided by this rung's best partial plan" if partial else "the next rung unguided"
    return replace(report, reason=f"{report.reason}; the ladder goes on, {more}")


#: An unguided search (no previous plan to draw samples near: the first rung that propagates)
#: spends its budget in this many searches with fresh random streams, each with an equal share,
#: since its iteration counts are heavy-tailed; a guided search keeps its whole budget in one
#: tree. The measurements behind both: docs/measurements.md.
RESTARTS = 4
#: Seed offset between the searches of one rung.
RESTART_STRIDE = 7919


def _plan_with_restarts(scenario, rung, start, *, seed: int, iterations: int, time_limit, **kwargs):
    """plan_control in up to RESTARTS searches when unguided (see RESTARTS); the first exact
    plan, else the last search's, ending TIMEOUT (or STOPPED) when no time (or a stop) was
    left for the searches to come; counts summed over the searches."""
    iterations = max(int(iterations), 0)
    # no more searches than iterations (and one with none left: it ends at once, BUDGET_EXHAUSTED)
    searches = max(1, min(RESTARTS if kwargs.get("guide") is None else 1, iterations))
    # equal shares that sum to the budget (a ceiling each would overspend it by up to searches - 1)
    shares = [iterations // searches + (k < iterations % searches) for k in range(searches)]
    t0, used = planning_clock(), {"propagations": 0, "iterations": 0, "failures": 0, "past_horizon": 0}
    plan = None
    for attempt in range(searches):
        left = None if time_limit is None else max(0.0, time_limit - (planning_clock() - t0))
        if plan is not None and left == 0.0:
            return replace(plan, status=PlanStatus.TIMEOUT, **used)
        if plan is not None and kwargs.get("stop") and kwargs["stop"]():
            return replace(plan, status=PlanStatus.STOPPED, **used)
        plan = plan_control(
            scenario, rung, start, seed=seed + attempt * RESTART_STRIDE, iterations=shares[attempt], time_limit=left, **kwargs
        )
        for key in used:
            used[key] += getattr(plan, key)
        if plan.exact:
            break
    return replace(plan, **used)


def assess(scenario: Scenario, name: str, controls, durations) -> dict:
    """Replay controls under a rung from the start: outcome, solver status, goal distance of
    the last state, largest penetration and contact steps, as report fields."""
    rung = rung_for(scenario, name)
    if not len(durations):
        return {
            "outcome": NONE,
            "status": OK,
            "goal_distance": goal_distance(scenario, scenario.start),
            "max_penetration": 0.0,
            "contact_steps": 0,
        }
    out = rung.rollout(
        scenario, rung.initial_state(scenario), np.array(controls, float), np.array(durations, float), scenario.rung_settings(name).h
    )
    distance = 0.0 if out.outcome == GOAL else goal_distance(scenario, out.state.q)
    return {
        "outcome": out.outcome,
        "status": out.status,
        "goal_distance": distance,
        "max_penetration": out.max_penetration,
        "contact_steps": out.force_steps,
    }


#: Rung pairs that are one model with rigid and with compliant contact.
COMPLIANCE_SIBLINGS = ({"quasistatic-rigid", "quasistatic-compliant"}, {"dynamic-rigid", "dynamic-compliant"})


def _same_physics(scenario: Scenario, previous: RungReport, name: str, h: float) -> str:
    """Why rung `name` at step h would compute exactly what `previous` computed, or "" if it might not."""
    if previous.outcome != GOAL or previous.status != OK or {previous.rung, name} not in COMPLIANCE_SIBLINGS:
        return ""
    if previous.contact_steps != 0 or previous.h != h:
        return ""
    a, b = rung_for(scenario, previous.rung).model, rung_for(scenario, name).model
    if a._replace(compliant=b.compliant) != b:
        return ""
    return (
        f"no contact carries force along the plan under {previous.rung} at the same step, and without contact force "
        f"{name} is the same model: the plan holds as it is"
    )


def _geometric(scenario: Scenario, seed: int, iterations: int, time_limit: float | None = None, stop=None) -> RungReport:
    """Plan the geometric rung and turn its path into commanded speeds for the actuated DOFs:
    each segment is driven at the speeds that cover it in whole control periods without
    exceeding any drive's max_speed. An approximate path (the goal set is thin: touching
    within a tolerance) is still offered to the next rung as a seed."""
    settings = scenario.rung_settings("geometric")
    t0, c0 = time.perf_counter(), compiler_seconds()
    path = plan_geometric(scenario, seed=seed, iterations=iterations, time_limit=time_limit, stop=stop, planner=settings.planner)
    period = settings.control_period
    index = [scenario.coordinates.index(n) for n in scenario.actuated]
    max_speed = scenario.max_speeds
    controls, durations, states = [], [], [path.states[0]]
    for a, b in zip(path.states[:-1], path.states[1:]):
        delta = b[index] - a[index]
        periods = segment_periods(delta, max_speed, period)
        # one control per period, so that a replay that stops agreeing part-way along a long
        # segment still leaves the states before that point as seeds
        for k in range(1, periods + 1):
            controls.append((delta / (periods * period)).tolist())
            durations.append(period)
            states.append(a + (b - a) * (k / periods))
    ended = PlanStatus.EXACT if path.exact else PlanStatus.APPROXIMATE
    reason = "" if path.exact else ended.message
    if not path.goal_samples:
        late = (
            f" ({path.late_goals} made were out of reach: the actuators at their max speeds, in whole control periods, "
            f"do not get there by {_horizon_words(scenario)})"
            if path.late_goals
            else ""
        )
        reason += ("; " if reason else "") + f"no goal state could be made by projection{late}, so RRT searched for the goal region"
    return RungReport(
        "geometric",
        ended,
        reason,
        outcome=GOAL if path.exact else NONE,
        wall_s=time.perf_counter() - t0,
        compile_s=compiler_seconds() - c0,
        propagations=0,
        iterations=path.iterations,
        goal_distance=goal_distance(scenario, path.states[-1]),
        controls=controls,
        durations=durations,
        states=np.array(states).tolist(),
    )


@dataclass
class _Replay:
    """A plan replayed control by control: the states after each control while it ran on
    (outcome none, status ok), and what the run met."""

    state: State
    states: list = field(default_factory=list)
    controls: list = field(default_factory=list)
    durations: list = field(default_factory=list)
    outcome: str = NONE
    status: str = OK
    min_psi: float = np.inf
    contact_steps: int = 0
    steps_min_psi: list = field(default_factory=list)  # running (min_psi, contact_steps) after each control
    held: int = 0  # control periods of drives held still added at the end (_replay)

    @staticmethod
    def empty(start: State) -> _Replay:
        return _Replay(start)

    @staticmethod
    def of(tracked: Tracked) -> _Replay:
        """A tracked run as a replay of its own controls (it is one: the same states)."""
        return _Replay(
            tracked.state,
            list(tracked.states),
            list(tracked.controls[: len(tracked.states)]),
            list(tracked.durations[: len(tracked.states)]),
            tracked.outcome,
            tracked.status,
            tracked.min_psi,
            tracked.contact_steps,
            list(tracked.steps_min_psi),
        )

    def head(self, j: int) -> _Replay:
        """The first j controls of this replay."""
        min_psi, contact = self.steps_min_psi[j - 1]
        return _Replay(
            self.states[j - 1], self.states[:j], self.controls[:j], self.durations[:j], NONE, OK, min_psi, contact, self.steps_min_psi[:j]
        )

    def configurations(self, start: State) -> list:
        """q at the start, after each control that ran on, and where the replay ended when a
        control ended it (in the goal, the unsafe set or a failure): one per control boundary.
        A replay whose every control ran on ends at its last state, not listed twice (it had
        been: len(controls) + 2 states, which the service's viewer timed against the controls)."""
        ran_on = self.states[-1] if self.states else None
        ended_in = self.state is not ran_on and (self.states or self.outcome != NONE or self.status != OK)
        return [start.q.tolist()] + [s.q.tolist() for s in self.states] + ([self.state.q.tolist()] if ended_in else [])

    def fields(self, scenario: Scenario) -> dict:
        distance = 0.0 if self.outcome == GOAL else goal_distance(scenario, self.state.q)
        return {
            "outcome": self.outcome,
            "status": self.status,
            "goal_distance": distance,
            "max_penetration": float(max(0.0, -self.min_psi)),
            "contact_steps": int(self.contact_steps),
        }


def _replay_controls(scenario, rung, state, controls, durations, h, so_far: _Replay) -> _Replay:
    """Continue `so_far` with controls, one rollout each (`Rung.rollout_each`), until one ends
    in the goal, the unsafe set or a solver failure."""
    run = _Replay(
        state,
        list(so_far.states),
        list(so_far.controls),
        list(so_far.durations),
        NONE,
        OK,
        so_far.min_psi,
        so_far.contact_steps,
        list(so_far.steps_min_psi),
    )
    ends = rung.rollout_each(scenario, state, controls, durations, h)  # (one compiled call)
    for u, d, out in zip(controls, durations, ends):
        run.min_psi = min(run.min_psi, out.min_psi)
        run.contact_steps += out.force_steps
        run.state = out.state
        if not out.ok or out.outcome != NONE:
            run.outcome, run.status = out.outcome, out.status
            break
        run.states.append(out.state)
        run.controls.append(list(u))
        run.durations.append(float(d))
        run.steps_min_psi.append((run.min_psi, run.contact_steps))
    return run


#: A replayed state agrees with the previous plan's state at the same control switch while
#: every steered coordinate is within this much of it (m or rad) and every passive body's
#: orientation within this angle (rad).
AGREEMENT = 0.05


def _agreeing(scenario: Scenario, replay: _Replay, previous: RungReport) -> int:
    """How many of the replay's states, from the first, still agree with the previous plan
    (AGREEMENT): the rest have drifted off it (a box the lower rung pushed straight has turned)
    and root the tree at states the previous plan never went through. A geometric path moves
    passive bodies on their own, so against it every state agrees."""
    if previous.rung == "geometric":
        return len(replay.states)
    planned = np.asarray(previous.states, float)
    steered = np.array(steered_coordinates(scenario), dtype=int)
    names = scenario.coordinates
    quaternions = [
        [names.index(f"{b}.{c}") for c in ("qw", "qx", "qy", "qz")]
        for b in dict.fromkeys(n.split(".")[0] for n in names)
        if f"{b}.qw" in names
    ]
    for k, s in enumerate(replay.states):
        if k + 1 >= len(planned):
            return k
        ref = planned[k + 1]
        if np.max(np.abs(s.q[steered] - ref[steered]), initial=0.0) > AGREEMENT:
            return k
        for quat in quaternions:
            c = min(1.0, abs(float(np.dot(s.q[quat], ref[quat]))) / max(np.linalg.norm(s.q[quat]) * np.linalg.norm(ref[quat]), 1e-300))
            if 2.0 * np.arccos(c) > AGREEMENT:
                return k
    return len(replay.states)


#: A lifted plan that ends short of the goal may hold its drives still (zero commanded speed)
#: for up to this many control periods: drives with finite gains lag their references, and a
#: lower rung's plan that just reaches the goal with its last control is reached after they
#: settle.
SETTLE_PERIODS = 5


def _track(step: _Step, previous: RungReport) -> Tracked:
    """The previous plan (recorded per control period under its own rung) tracked under the
    step's rung, repaired locally within the iterations the rung may spend."""
    scenario = step.scenario
    below = rung_for(scenario, previous.rung)
    reference = Reference.of(
        scenario,
        below,
        below.initial_state(scenario),
        previous.controls,
        previous.durations,
        previous.h,
        step.period,
    )
    return _follow(step, reference)


def _follow(step: _Step, reference: Reference, free: tuple[str, ...] = ()) -> Tracked:
    """`reference` tracked under the step's rung from its start, repaired locally within the
    iterations and the time the rung may spend; `free`: coordinates tracking leaves out."""
    return track(
        step.scenario,
        step.rung,
        step.start(),
        reference,
        step.h,
        step.period,
        step.seed,
        iterations=step.iterations,
        time_limit=step.budget.seconds(),
        stop=step.stop,
        free=free,
    )


def _push(step: _Step, previous: RungReport) -> Tracked | None:
    """The geometric plan's object path pushed (`planner.pushing.push_reference`) and tracked
    under the step's rung, repaired locally within the iterations the rung may spend; None in a
    scene that is no pushing scene."""
    reference = push_reference(step.scenario, previous.states, step.start().q, step.period)
    return None if reference is None else _follow(step, reference, free_turn(step.scenario))


def _tracking_reason(ended: PlanStatus, tracked: Tracked, pushed: bool = False) -> str:
    """How tracking went, in words: corrections, repairs, where it was lost."""
    return f"{ended.message}: " + _tracking_words(tracked, pushed)


def _tracking_words(tracked: Tracked, pushed: bool = False, partial: bool = False) -> str:
    """What tracking did, in words; `partial`: the previous plan was a failed rung's partial plan."""
    what = "a push along the geometric plan's object path" if pushed else "the previous plan"
    words = [f"tracked {tracked.fraction:.0%} of {what}'s duration" + (" (a partial plan, short of the goal)" if partial else "")]
    if tracked.corrected:
        words.append(f"{tracked.corrected} of {len(tracked.controls)} controls corrected")
    if tracked.repairs:
        words.append(f"{tracked.repaired} of {tracked.repairs} local repair(s) succeeded ({tracked.repair_propagations} propagations)")
    if tracked.lost:
        words.append(f"lost at {tracked.diverged_at:.1f} s ({tracked.lost})")
    return ", ".join(words)


def _replay(scenario, rung, start, previous, h, period: float | None = None) -> _Replay:
    """The previous plan replayed under `rung`: where it stops agreeing (unsafe, failed) or
    holds (goal), and the states before that, which seed the tree when it does not hold. With
    a control period, a replay that runs through every control without an outcome goes on
    with the drives held still (SETTLE_PERIODS); it is that one (`held` periods added) if it
    then reaches the goal."""
    run = _replay_controls(scenario, rung, start, previous.controls, previous.durations, h, _Replay.empty(start))
    return _settled(scenario, rung, run, previous, h, period)


def _settled(scenario, rung, run: _Replay, previous, h, period: float | None) -> _Replay:
    """`run`, the previous plan's controls replayed (`_replay_controls`), or, when it ran through
    every control without an outcome, its continuation with the drives held still if that
    reaches the goal (see `_replay`)."""
    if period and run.outcome == NONE and run.status == OK and len(run.controls) == len(previous.controls):
        zero = [[0.0] * len(scenario.actuated)] * SETTLE_PERIODS
        settled = _replay_controls(scenario, rung, run.state, zero, [period] * SETTLE_PERIODS, h, run)
        if settled.outcome == GOAL and settled.status == OK:
            settled.held = len(settled.controls) - len(run.controls) + 1
            return settled
    return run

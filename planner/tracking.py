"""Carry a lower rung's plan up the ladder by tracking it: the previous plan's states are a
reference trajectory, and the upgraded rung follows it in closed loop, one control period at
a time (predictive sampling): it rolls out the previous plan's control for that period and,
when the result drifts from the reference, a few sampled controls around it, and keeps the
one whose result is closest to the reference in what the task is about (the passive bodies'
positions and orientations). Where no candidate stays within `TRACK_TOLERANCE` of the
reference, tracking ends: the ladder repairs from the last tracked state (`planner.ladder`).

Every candidate is one call of the compiled rollout over one control period; the chosen
one's state is the next period's start, so the tracked plan replays exactly (same controls,
same states) under the rung.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from models.rungs import Rung, State, compiled
from models.scenario import Scenario
from models.task import Outcome
from planner.clock import planning_clock
from planner.ompl_adapter import control_bounds, plan_control, steered_coordinates

#: A tracked state stays within this much of the reference (m for positions, rad for angles)
#: in the passive bodies' pose; the ladder's seeded search calls states this close "agreeing".
TRACK_TOLERANCE = 0.05
#: The previous plan's control is kept without trying others while its result is this close.
TRACK_KEEP = 0.015
#: Controls tried per control period when the previous plan's control drifts (it included).
TRACK_CANDIDATES = 8
#: Spread of the sampled candidates around the previous control, as a fraction of each
#: actuator's speed bound.
TRACK_SPREAD = 0.35
#: After the reference ends short of the goal, periods the tracker may go on toward its last state.
TRACK_SETTLE = 10
#: Candidates are also rolled on one more period with the reference's next control (see _best_control).
LOOKAHEAD = True
#: Local repair: how far along the reference (s) past where tracking was lost its search aims,
#: from how many of the last tracked states, with how many iterations, at most how often.
REPAIR_HORIZONS = (1.0, 2.0)  # a second, longer try when the first repair fails
REPAIR_ROOTS = 3
REPAIR_ITERATIONS = 300
MAX_REPAIRS = 6
#: A repair has rejoined the reference within this fraction of TRACK_TOLERANCE.
REPAIR_REACH = 0.5
#: Seed offset between a rung's repair searches.
REPAIR_STRIDE = 104729


@dataclass
class Tracked:
    """What tracking produced: the controls (one per control period), the states after each,
    how the last rollout ended, and what it cost."""

    start: State
    state: State | None = None
    states: list = field(default_factory=list)
    controls: list = field(default_factory=list)
    durations: list = field(default_factory=list)
    outcome: str = Outcome.NONE.label
    status: str = "ok"
    min_psi: float = np.inf
    contact_steps: int = 0
    steps_min_psi: list = field(default_factory=list)
    corrected: int = 0  # periods where a control other than the previous plan's was kept
    rollouts: int = 0  # candidate rollouts (each one control period)
    fraction: float = 0.0  # of the reference's duration followed by tracking (not by repairs), at most 1
    diverged_at: float | None = None  # reference time where tracking was lost (None: it was not)
    lost: str = ""  # why: "unsafe" (every candidate entered the unsafe set or failed), "drift" (none stayed within TRACK_TOLERANCE),
    # "time" (the rung's time limit passed), "stopped" (Ctrl-C)
    drift: float = 0.0  # the best candidate's distance from the reference where tracking was lost, m
    repairs: int = 0  # local repair searches tried
    repaired: int = 0  # losses of tracking that a repair mended
    repair_propagations: int = 0
    repair_iterations: int = 0

    def __post_init__(self):
        if self.state is None:
            self.state = self.start

    def append(self, out, u: list, duration: float) -> None:
        """The rollout `out` of control u for `duration` from this run's state continues it."""
        self.min_psi = min(self.min_psi, out.min_psi)
        self.contact_steps += out.force_steps
        self.state = out.state
        self.controls.append(u)
        self.durations.append(duration)
        if out.outcome == Outcome.GOAL.label:
            self.outcome, self.status = out.outcome, out.status
            return
        self.states.append(out.state)
        self.steps_min_psi.append((self.min_psi, self.contact_steps))

    def extend(self, other: Tracked, first: bool) -> None:
        """Continue this run with `other`, a run tracked from this run's state; its fraction,
        divergence and loss are this run's when `first` (the first reference's), its counts add."""
        for u, d, x, marks in zip(other.controls, other.durations, other.states + [other.state], other.steps_min_psi + [None]):
            self.controls.append(u)
            self.durations.append(d)
            if marks is None:  # the goal: its state ends the run, not kept in `states`
                break
            self.states.append(x)
            self.steps_min_psi.append((min(self.min_psi, marks[0]), self.contact_steps + marks[1]))
        self.state, self.outcome, self.status = other.state, other.outcome, other.status
        self.min_psi = min(self.min_psi, other.min_psi)
        self.contact_steps += other.contact_steps
        self.corrected += other.corrected
        self.rollouts += other.rollouts
        self.repairs += other.repairs
        self.repaired += other.repaired
        self.repair_propagations += other.repair_propagations
        self.repair_iterations += other.repair_iterations
        if first:
            self.fraction, self.diverged_at, self.lost, self.drift = other.fraction, other.diverged_at, other.lost, other.drift
        else:
            self.lost, self.drift = other.lost, other.drift

    def truncate(self, n: int) -> None:
        """Keep the first n controls (and the states after them)."""
        del self.controls[n:], self.durations[n:], self.states[n:], self.steps_min_psi[n:]
        if n > 0:
            self.state = self.states[n - 1]
            self.min_psi, self.contact_steps = self.steps_min_psi[n - 1]
        else:
            self.state, self.min_psi, self.contact_steps = self.start, np.inf, 0


@dataclass(frozen=True)
class Reference:
    """The previous plan as a function of time: its control and its configuration."""

    times: np.ndarray  # at the previous plan's control switches, from 0
    configurations: np.ndarray  # q at those times
    controls: np.ndarray  # the control that starts at each switch (one fewer than times)

    @staticmethod
    def of(scenario: Scenario, rung: Rung, start: State, controls, durations, h: float, period: float) -> Reference:
        """The previous plan rolled out again under its own rung (`rung`, step h), recorded at
        every control period (its controls may last several), until it reaches the goal."""
        times, states, per_period = [0.0], [start.q.copy()], []
        state, t = start, 0.0
        for u, d in zip(np.asarray(controls, float).reshape(len(durations), -1), durations):
            for _ in range(max(1, int(round(float(d) / period)))):
                out = rung.rollout(scenario, state, u.reshape(1, -1), [period], h)
                state, t = out.state, t + period
                times.append(t)
                states.append(state.q.copy())
                per_period.append(u)
                if not out.ok or out.outcome != Outcome.NONE.label:
                    return Reference(np.array(times), np.array(states), np.array(per_period))
        return Reference(np.array(times), np.array(states), np.array(per_period))

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def control(self, t: float) -> np.ndarray:
        k = min(int(np.searchsorted(self.times, t + 1e-9, side="right")) - 1, len(self.controls) - 1)
        return self.controls[max(k, 0)]

    def configuration(self, t: float) -> np.ndarray:
        t = min(max(t, 0.0), self.duration)
        k = min(int(np.searchsorted(self.times, t, side="right")) - 1, len(self.times) - 2)
        if k < 0:
            return self.configurations[0]
        span = self.times[k + 1] - self.times[k]
        w = 0.0 if span <= 0.0 else (t - self.times[k]) / span
        return (1.0 - w) * self.configurations[k] + w * self.configurations[k + 1]


class PoseError:
    """Distance of a configuration from a reference configuration in what the task is about,
    in m: the passive bodies' steered coordinates, an angle (planar theta, yaw; the angle
    between two orientations) times the body's bounding radius (how far its farthest point
    moves); with no passive body, the actuated coordinates. `free`: coordinates left out (a
    turn the task leaves free, which a pushing reference does not plan: `planner.pushing`)."""

    def __init__(self, scenario: Scenario, free: tuple[str, ...] = ()):
        names = scenario.coordinates
        steered = steered_coordinates(scenario)
        bound = compiled(scenario).scene.bound_radius
        radius = {b.name: float(bound[i]) for i, b in enumerate(scenario.spec.bodies)}
        passive = [i for i in steered if names[i] not in scenario.actuated and names[i] not in free]
        self.coordinates = np.array(passive or [i for i in steered if names[i] in scenario.actuated], dtype=int)
        self.weights = np.array(
            [radius[names[i].split(".")[0]] if names[i].split(".")[1] in ("theta", "yaw") else 1.0 for i in self.coordinates]
        )
        self.quaternions = [
            (np.array([names.index(f"{b}.{c}") for c in ("qw", "qx", "qy", "qz")]), radius[b])
            for b in dict.fromkeys(n.split(".")[0] for n in names)
            if f"{b}.qw" in names
        ]

    def __call__(self, q: np.ndarray, ref: np.ndarray) -> float:
        err = float(np.max(self.weights * np.abs(q[self.coordinates] - ref[self.coordinates]), initial=0.0))
        for quat, radius in self.quaternions:
            a, b = q[quat], ref[quat]
            c = min(1.0, abs(float(a @ b)) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-300))
            err = max(err, 2.0 * float(np.arccos(c)) * radius)
        return err


def track(
    scenario: Scenario,
    rung: Rung,
    start: State,
    reference: Reference,
    h: float,
    period: float,
    seed: int,
    *,
    iterations: int = MAX_REPAIRS * REPAIR_ITERATIONS,
    repairs: int = MAX_REPAIRS,
    time_limit: float | None = None,
    stop=None,
    free: tuple[str, ...] = (),
) -> Tracked:
    """Follow `reference` under `rung` from `start` until the goal is reached or the
    reference (and TRACK_SETTLE periods toward its last configuration) runs out. Where
    tracking is lost, repair locally (`_repair`: a short search to the reference further
    along, REPAIR_HORIZONS) and track on from there: at most `repairs` repairs and
    `iterations` search iterations in all. `free`: coordinates the distance to the reference
    leaves out (`PoseError`)."""
    rng = np.random.default_rng(seed)
    deadline = None if time_limit is None else planning_clock() + time_limit
    follower = _Follower(scenario, rung, reference, h, period, rng, free, deadline, stop)
    run = Tracked(start)
    follower.follow(run, 0.0)
    while run.lost and run.repairs < repairs and not (stop and stop()):
        resumed = None
        for horizon in REPAIR_HORIZONS:
            left = None if deadline is None else deadline - planning_clock()
            budget = min(REPAIR_ITERATIONS, iterations - run.repair_iterations)
            if (left is not None and left <= 0.0) or budget <= 0 or (stop and stop()):
                break
            resumed = _repair(scenario, rung, follower, run, start, seed, horizon, budget, left, stop)
            if resumed is not None:
                break
        if resumed is None:
            break
        run.repaired += 1
        run.lost, run.drift = "", 0.0
        if run.outcome == Outcome.GOAL.label:
            break
        follower.follow(run, resumed)
    return run


class _Follower:
    """Tracking proper: one control period at a time from reference time t."""

    def __init__(self, scenario, rung, reference, h, period, rng, free: tuple[str, ...] = (), deadline=None, stop=None):
        self.scenario, self.rung, self.reference, self.h, self.period, self.rng = scenario, rung, reference, h, period, rng
        self.deadline, self.stop = deadline, stop  # (planning_clock's; a function -> True on Ctrl-C)
        self.low, self.high = control_bounds(scenario)
        self.spread = TRACK_SPREAD * (self.high - self.low) / 2.0
        self.error = PoseError(scenario, free)
        self.periods = int(np.ceil(reference.duration / period - 1e-9))

    def follow(self, run: Tracked, t: float) -> float:
        """Extend `run` from reference time t; returns the reference time reached."""
        period, reference = self.period, self.reference
        first = int(round(t / period))
        cached = None
        for k in range(first, self.periods + TRACK_SETTLE):
            t = k * period
            stopped = self.stop is not None and self.stop()
            if stopped or (self.deadline is not None and planning_clock() > self.deadline):
                run.diverged_at, run.lost = t, "stopped" if stopped else "time"
                return t
            target = reference.configuration(t + period)
            base = reference.control(t) if k < self.periods else np.zeros(len(self.scenario.actuated))
            after = None
            if LOOKAHEAD and k + 1 < self.periods:
                after = (reference.control(t + period), reference.configuration(t + 2 * period))
            best = _best_control(
                self.scenario,
                self.rung,
                run,
                base,
                target,
                self.error,
                self.h,
                period,
                self.rng,
                self.low,
                self.high,
                self.spread,
                after,
                cached,
            )
            cached = None
            if best is None:  # every candidate failed or entered the unsafe set
                run.diverged_at, run.lost = t, "unsafe"
                return t
            u, out, err, ahead = best
            if ahead is not None and ahead.ok and ahead.outcome == Outcome.NONE.label:
                cached = ahead  # the next period's base candidate from the state this one reaches
            if k >= self.periods and out.outcome != Outcome.GOAL.label and err > TRACK_TOLERANCE:
                return t
            if err > TRACK_TOLERANCE and out.outcome != Outcome.GOAL.label:
                run.diverged_at, run.lost, run.drift = t, "drift", err
                return t
            run.corrected += not np.array_equal(u, base)
            run.fraction = min(1.0, run.fraction + period / max(reference.duration, 1e-12))
            run.append(out, u.tolist(), period)
            if run.outcome == Outcome.GOAL.label:
                return t + period
        return min(t + period, reference.duration)


def _repair(scenario, rung, follower: _Follower, run: Tracked, start: State, seed: int, horizon: float, iterations: int, time_limit, stop):
    """A short search under `rung` from the last REPAIR_ROOTS tracked states to a state within
    REPAIR_REACH * TRACK_TOLERANCE of the reference `horizon` seconds past where tracking was lost (or the
    goal), guided by the reference in between. On success the run is cut at the root the
    search's path starts from and continued with its controls; returns the reference time to
    track on from (None: no repair)."""
    reference, period = follower.reference, follower.period
    t_lost = run.diverged_at or 0.0
    t_target = min(t_lost + horizon, reference.duration)
    target = reference.configuration(t_target)
    roots = ([start] + list(run.states))[-REPAIR_ROOTS:]
    first_root = len(run.states) + 1 - len(roots)  # index in [start] + run.states
    guide = np.array([reference.configuration(t) for t in np.arange(max(t_lost - period, 0.0), t_target + 1e-9, period)])
    plan = plan_control(
        scenario,
        rung,
        roots[0],
        h=follower.h,
        control_period=period,
        seed=seed + REPAIR_STRIDE * (run.repairs + 1),
        iterations=iterations,
        extra_starts=roots[1:],
        guide=guide,
        time_limit=time_limit,
        stop=stop,
        reached=lambda q: follower.error(q, target) <= REPAIR_REACH * TRACK_TOLERANCE,
        horizon=scenario.spec.task.horizon,  # (a repair that ends past it only makes a plan refused as late)
        start_times=[math.fsum(run.durations[: first_root + j]) for j in range(len(roots))],
    )
    run.repairs += 1
    run.repair_propagations += plan.propagations
    run.repair_iterations += plan.iterations
    if not plan.exact:
        return None
    run.truncate(first_root + plan.start_index)
    for u, d in zip(plan.controls, plan.durations):
        out = rung.rollout(scenario, run.state, np.asarray(u, float).reshape(1, -1), [float(d)], follower.h)
        if not out.ok or out.outcome == Outcome.UNSAFE.label:
            return None  # the search's own propagation said otherwise: cannot happen for a deterministic rung
        run.append(out, list(map(float, u)), float(d))
        if run.outcome == Outcome.GOAL.label:
            break
    return t_target


def _best_control(scenario, rung, run, base, target, error, h, period, rng, low, high, spread, after=None, cached=None):
    """The candidate control for one period whose result is closest to `target`: the base
    control alone while its result is within TRACK_KEEP, else the best of TRACK_CANDIDATES;
    a candidate reaching the goal wins. With `after` = (control, configuration) of the next
    period, a candidate is also rolled on one period with that control (a look-ahead): one
    that enters the unsafe set there is dropped (a pushed box slides on after the push, which
    a memoryless lower rung did not predict), and the distance there counts too. None when
    every candidate fails or is unsafe. `cached`: the base control's rollout from this state,
    if the previous period's look-ahead made it. Returns (u, rollout, distance, look-ahead
    rollout or None)."""
    best = None
    for c in range(TRACK_CANDIDATES):
        u = base if c == 0 else np.clip(base + spread * rng.standard_normal(len(base)), low, high)
        if c == 0 and cached is not None:
            out = cached
        else:
            out = rung.rollout(scenario, run.state, u.reshape(1, -1), [period], h)
            run.rollouts += 1
        if not out.ok or out.outcome == Outcome.UNSAFE.label:
            continue
        if out.outcome == Outcome.GOAL.label:
            return u, out, 0.0, None
        err = error(out.state.q, target)
        score, ahead = err, None
        if after is not None:
            ahead = rung.rollout(scenario, out.state, np.asarray(after[0], float).reshape(1, -1), [period], h)
            run.rollouts += 1
            if not ahead.ok or ahead.outcome == Outcome.UNSAFE.label:
                continue
            if ahead.outcome != Outcome.GOAL.label:
                score = max(err, error(ahead.state.q, after[1]))
        if best is None or score < best[4]:
            best = (u, out, err, ahead, score)
        if c == 0 and score <= TRACK_KEEP:
            break
    return None if best is None else best[:4]

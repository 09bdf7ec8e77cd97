"""The one module that imports OMPL: control planning over a rung's compiled rollout.

An OMPL state is the rung's whole state flattened: [q, nu, q_ref, delta_n, delta_t, flag],
where flag records how the rollout that produced it ended (0 running, 1 goal, 2 unsafe,
3 numerical failure, 4 outside the limits below). The state space is a compound of the steered coordinates of q (weight
1) and the rest (weight 1e-6), so nearest neighbours are found in the part of configuration
space the planner can steer (`steered_coordinates`: in a spatial scene the height and
orientation of a passive body only follow from contact, and uniform samples of them would
swamp the metric). One propagate call runs one
control period of physics steps in one compiled rollout (OMPL-CRIB section 8: coarse steps
keep the Python callback cost small). Validity: flag is neither unsafe nor failure, q is in
bounds, and no drive is wound up (its reference leads its position by more than a control
period of full-speed travel: it is jammed, and the spring released later would throw what it
touches; kinematic plans that jam a pusher against a wall failed this way under dynamics);
the propagator checks the last two as it makes a state and flags it (`_Limits`).
The goal region's distance is 0 exactly on states whose rollout reached the goal.

Determinism (OMPL-CRIB section 6): the seed is set before any planner exists and the budget
is an iteration count, so the same seed gives the same plan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models.rollout import FLAG_GOAL, FLAG_INVALID, FLAG_RUNNING
from models.rungs import Rung, State
from models.scenario import TRANSLATIONAL_DOFS, Scenario
from models.stepper import StepStatus
from models.task import goal_distance
from planner.clock import planning_clock
from planner.plan_status import PlanStatus

#: Distance weight of everything but q in the state metric.
AUXILIARY_WEIGHT = 1e-6
#: Half-width of the sampling box of passive coordinates around the start (m or rad).
PASSIVE_RANGE = 2.0
#: A plan may last this much (s) past the horizon: a sum of control durations' rounding.
HORIZON_SLACK = 1e-9


def latest_goal_time(scenario: Scenario) -> float:
    """The latest a plan may reach the goal: the task's horizon, with HORIZON_SLACK."""
    return scenario.spec.task.horizon + HORIZON_SLACK


def segment_periods(delta: np.ndarray, max_speeds: np.ndarray, period: float) -> int:
    """The control periods (at least one) that cover a straight move of the actuated
    coordinates by `delta` without exceeding any drive's max speed: how the geometric rung
    times its path (`planner.ladder._geometric`)."""
    return max(1, int(np.ceil(np.max(np.abs(delta) / max_speeds / period, initial=0.0) - 1e-9)))


#: Each control is held for 1 to this many control periods.
MAX_CONTROL_PERIODS = 10
#: Fraction of RRT's samples drawn near the previous rung's plan when one guides it.
GUIDE_BIAS = 0.3
#: Standard deviation of those samples around a guide state, as a fraction of the bounds.
GUIDE_SPREAD = 0.02
#: The progress callback runs every this many planner iterations.
PROGRESS_EVERY = 25


@dataclass(frozen=True)
class ControlPlan:
    controls: np.ndarray  # (k, n_actuated) commanded speeds
    durations: np.ndarray  # (k,) seconds
    states: np.ndarray  # (k + 1, nq) configurations at the control switches
    status: PlanStatus  # how the search ended: EXACT, TIMEOUT, BUDGET_EXHAUSTED, STOPPED or ABORTED
    propagations: int
    iterations: int
    start_index: int = 0  # which start the path begins at (0: the real start; i: extra_starts[i - 1])
    failures: int = 0  # propagations that ended in a numerical failure (a status, pruned from the tree)
    past_horizon: int = 0  # states the search made invalid as their plan would end past the horizon

    @property
    def exact(self) -> bool:
        return self.status is PlanStatus.EXACT


def _layout(scenario: Scenario, state: State) -> tuple[int, int, int, int, int]:
    nq, nv, na = len(state.q), len(state.nu), len(state.q_ref)
    return nq, nv, na, len(state.delta_n), 2 * len(state.delta_n)


def flatten(state: State, flag: float = FLAG_RUNNING) -> np.ndarray:
    return np.concatenate([state.q, state.nu, state.q_ref, state.delta_n, state.delta_t.ravel(), [flag]])


def control_bounds(scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Commanded speed bounds per actuated coordinate: `[task] control_bounds`, else +-max_speed."""
    lo, hi = [], []
    bounds = scenario.spec.task.control_bounds
    for name, top in zip(scenario.actuated, scenario.max_speeds):
        low, high = bounds.get(name, (-top, top))
        lo.append(low)
        hi.append(high)
    return np.array(lo), np.array(hi)


def configuration_limits(scenario: Scenario, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounds on q: the drives' position limits, else q0 +- PASSIVE_RANGE."""
    low, high = np.asarray(q0, float) - PASSIVE_RANGE, np.asarray(q0, float) + PASSIVE_RANGE
    for i, name in enumerate(scenario.coordinates):
        body, dof = name.split(".", 1)
        drive = scenario.body(body).actuators.get(dof)
        if drive is not None and drive.lower is not None:
            low[i] = drive.lower
        if drive is not None and drive.upper is not None:
            high[i] = drive.upper
    return low, high


def goal_coordinates(scenario: Scenario) -> set[str]:
    """The coordinates the goal names an interval of, anywhere in its predicate."""
    intervals: dict = {}
    _goal_intervals(scenario.spec.task.goal, intervals)
    return set(intervals)


def _goal_intervals(node, out: dict) -> None:
    """Every coordinate interval named anywhere in a predicate (all branches of `any`)."""
    kind = type(node).__name__
    if kind == "BoxPredicate":
        for name, (lo, hi) in node.box.items():
            out.setdefault(name, []).append((lo, hi))
    for child in getattr(node, "all", None) or getattr(node, "any", None) or ():
        _goal_intervals(child, out)


def sampling_limits(scenario: Scenario, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the planners draw configurations: configuration_limits, with each passive body's
    translational coordinates narrowed to the workspace on that axis: the span of every
    bounded body's start position, the drives' position limits along the axis and the goal's
    intervals on the coordinate, widened by the body's own reach plus the largest robot's (how
    far from a drive's limit a pushed body's centre can be). A passive body moves
    only when something pushes it, so samples far outside that box (PASSIVE_RANGE around its
    start) would only pull the tree toward places it cannot reach."""
    low, high = configuration_limits(scenario, q0)
    axes = "xyz"[: scenario.dimension]
    placements = scenario.placements(np.asarray(q0, float))
    span = {a: [np.inf, -np.inf] for a in axes}
    reach, robot_reach = {}, 0.0
    for name, g in scenario.geometries.items():
        if g.kind == "halfspace":
            continue
        reach[name] = float(np.max(np.linalg.norm(g.core, axis=1), initial=0.0)) + g.radius
        if scenario.body(name).role == "robot":
            robot_reach = max(robot_reach, reach[name])
        for k, a in enumerate(axes):
            v = float(placements[name].translation[k])
            span[a] = [min(span[a][0], v), max(span[a][1], v)]
    for body in scenario.spec.bodies:
        for dof, drive in body.actuators.items():
            if dof in span:
                for v in (drive.lower, drive.upper):
                    if v is not None:
                        span[dof] = [min(span[dof][0], v), max(span[dof][1], v)]
    intervals: dict = {}
    _goal_intervals(scenario.spec.task.goal, intervals)
    for i, name in enumerate(scenario.coordinates):
        dof = name.rsplit(".", 1)[1]
        if name in scenario.actuated or dof not in span or not np.isfinite(span[dof][0]):
            continue
        lo, hi = span[dof]
        for a, b in intervals.get(name, ()):
            lo, hi = min(lo, a), max(hi, b)
        r = reach.get(name.rsplit(".", 1)[0], 0.0) + robot_reach
        low[i], high[i] = max(low[i], lo - r), min(high[i], hi + r)
    return low, high


#: Coordinates of a passive body in a spatial scene that the planner does not steer toward:
#: its height and its orientation quaternion follow from contact (resting, tipping).
UNSTEERED_DOFS = ("z", "qw", "qx", "qy", "qz")


def steered_coordinates(scenario: Scenario) -> list[int]:
    """Indices of q the planners sample and measure distance in: every coordinate of a planar
    scene; in a spatial scene all but a passive body's z and orientation (UNSTEERED_DOFS),
    which keep their start values in the geometric rung and weigh nothing in the control
    planners' metric."""
    if scenario.dimension == 2:
        return list(range(len(scenario.coordinates)))
    return [i for i, n in enumerate(scenario.coordinates) if n in scenario.actuated or n.rsplit(".", 1)[1] not in UNSTEERED_DOFS]


def _projection_coordinates(scenario: Scenario, most: int = 3) -> list[int]:
    """Positions in the steered coordinates (steered_coordinates) of up to `most`
    translational coordinates, passive bodies first."""
    steered = steered_coordinates(scenario)
    names = [scenario.coordinates[i] for i in steered]
    passive = [k for k, n in enumerate(names) if n not in scenario.actuated and n.split(".")[1] in TRANSLATIONAL_DOFS]
    active = [k for k, n in enumerate(names) if n in scenario.actuated]
    return (passive + active)[:most] or [0]


def _termination(ss, iterations: int, time_limit: float | None, progress=None, stop=None):
    """OMPL's termination condition for both planners, and what it records: stop at an exact
    solution, after `iterations` iterations, or past the wall-clock cap (`planning_clock`).
    OMPL asks before every iteration, so the count is of the iterations it let run;
    progress(count) is called every PROGRESS_EVERY of them. stop() -> True (Ctrl-C) ends the
    search too. ``done["ended"]`` is why the condition ended the search (TIMEOUT,
    BUDGET_EXHAUSTED, STOPPED; None: it did not)."""
    done = {"iterations": 0, "ended": None}
    deadline = None if time_limit is None else planning_clock() + time_limit

    def finished() -> bool:
        if ss.haveExactSolutionPath():
            return True
        if deadline is not None and planning_clock() > deadline:
            done["ended"] = PlanStatus.TIMEOUT
            return True
        if done["iterations"] >= iterations:
            done["ended"] = PlanStatus.BUDGET_EXHAUSTED
            return True
        if stop is not None and stop():
            done["ended"] = PlanStatus.STOPPED
            return True
        done["iterations"] += 1
        if progress is not None and done["iterations"] % PROGRESS_EVERY == 0:
            progress(done["iterations"])
        return False

    return finished, done


def _search_status(exact: bool, done: dict) -> PlanStatus:
    """How a search ended: EXACT, else what ended it (`_termination`); a planner that returned
    without being asked to stop refused its start or goal (ABORTED)."""
    if exact:
        return PlanStatus.EXACT
    return done["ended"] or PlanStatus.ABORTED


def plan_control(
    scenario: Scenario,
    rung: Rung,
    start: State,
    *,
    h: float,
    control_period: float,
    seed: int,
    iterations: int,
    planner: str = "RRT",
    goal_heuristic=None,
    extra_starts: list[State] | None = None,
    guide: np.ndarray | None = None,
    guide_bias: float = GUIDE_BIAS,
    time_limit: float | None = None,
    progress=None,
    stop=None,
    reached=None,
    horizon: float | None = None,
    start_times=None,
) -> ControlPlan:
    """Plan commanded speeds from `start` under `rung` with OMPL's control planner.

    goal_heuristic: q -> a distance to the goal the planner may rank states by (None: every
    state that has not reached the goal is 1 from it).
    extra_starts: more tree roots (OMPL-CRIB section 5), e.g. the previous plan's states
    replayed under this rung; the result says which root its path starts at.
    guide: configurations (k, nq) of the previous rung's plan. RRT and EST then draw this
    fraction (guide_bias) of their samples near them, through the goal's sampler (the only
    sampling hook the 2.0.1 bindings leave: OMPL-CRIB section 5); a drawn guide state is a
    direction to grow toward, never taken for a goal state. KPIECE1 does not sample toward
    goals, so the guide does not bias it.
    time_limit: a wall-clock cap on top of the iteration budget (then not reproducible), on
    `planning_clock` (compiling kernels does not count).
    progress: called as progress(iterations, propagations) every PROGRESS_EVERY iterations.
    stop: a function -> True (Ctrl-C) that ends the search early.
    reached: q -> bool, a subgoal: a propagation ending where it is True ends the search as the
    goal does (the tracker's local repair: a state near the previous plan further along).
    horizon: the task's longest plan, s (`[task] horizon`): a control that would end past it
    makes an invalid state (`_Propagator`). None: no bound.
    start_times: the time (s) at which the plan is at each root, [start] + extra_starts, where
    they are states along an earlier plan (default: 0 for each).
    """
    from ompl import base as ob
    from ompl import control as oc
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)  # before any planner or sampler exists; OMPL wants > 0
    layout = _ControlLayout(scenario, start)
    limits = _Limits(scenario, start, control_period)
    space, projection = _control_state_space(ob, layout, scenario, start)
    si = oc.SpaceInformation(space, _control_space(ob, oc, space, scenario))
    si.setPropagationStepSize(control_period)
    si.setMinMaxControlDuration(1, MAX_CONTROL_PERIODS)
    propagate = _Propagator(scenario, rung, layout, limits, h, reached, horizon)
    si.setStatePropagator(propagate)
    si.setStateValidityChecker(_valid_checker(layout))
    if planner == "EST":
        si.setValidStateSamplerAllocator(_running_sampler(ob, layout))

    ss = oc.SimpleSetup(si)
    roots = []
    for k, st in enumerate([start] + list(extra_starts or [])):
        root = space.allocState()
        layout.write(root, flatten(st, limits.flag(st, FLAG_RUNNING)))
        roots.append(layout.read(root))
        propagate.at(roots[-1], 0.0 if start_times is None else float(start_times[k]))
        if k == 0:
            ss.setStartState(root)
        else:
            ss.addStartState(root)
    chosen = getattr(oc, planner)(si)
    guide_q = None if guide is None or len(guide) == 0 else np.asarray(guide, float).reshape(-1, layout.nq)
    guided = guide_q is not None and planner in ("RRT", "EST")
    ss.setGoal(_control_goal(ob, si, layout, goal_heuristic, guide_q if guided else None, scenario, start, seed))
    if guided and planner == "RRT":
        chosen.setGoalBias(float(guide_bias))
    ss.setPlanner(chosen)
    stop_now, done = _termination(
        ss, iterations, time_limit, None if progress is None else (lambda i: progress(i, propagate.propagations)), stop
    )
    ss.solve(ob.PlannerTerminationCondition(stop_now))
    status = _search_status(bool(ss.haveExactSolutionPath()), done)
    result = _control_result(ss, layout, scenario, start, roots, status, propagate, done)
    del ss, si, space, projection
    return result


class _ControlLayout:
    """Where the rung's flattened state sits in an OMPL compound state: the steered
    coordinates of q in the first part (what the metric sees), then the unsteered ones and
    the rest of the state (nu, q_ref, deformations) with the flag last in the auxiliary part.

    States are written in one call through the space (`copyFromReals`) and read through the
    components' typed wrappers, or through the space where a component comes back as another
    type: the bindings hand out a live wrapper registered at the same address, which can be
    one of a state freed since (seen once in the suite as a CompoundState in place of a
    RealVectorStateType); the space's accessors take the state by address, whatever its
    wrapper. `attach` makes such a space, a twin of the planner's (the same subspaces), before
    any state is read or written: the planner's own would close a reference cycle through
    C++ (its projection's closure holds this layout), which Python cannot collect."""

    def __init__(self, scenario: Scenario, start: State):
        self.sizes = _layout(scenario, start)
        self.nq = self.sizes[0]
        self.n_flat = sum(self.sizes) + 1  # the flattened rung state (flatten)
        self.steered = np.array(steered_coordinates(scenario), dtype=int)
        self.unsteered = np.array([i for i in range(self.nq) if i not in set(self.steered.tolist())], dtype=int)
        self.ns = len(self.steered)
        # where each entry of the auxiliary part comes from in the flattened state
        self.aux_at = np.concatenate([self.unsteered, np.arange(self.nq, self.n_flat)]).astype(int)
        self.n_aux = len(self.aux_at)
        self.order = np.concatenate([self.steered, self.aux_at])  # the flattened index of each OMPL value, in order
        self.value = self.from_reals = self.typed = None

    def attach(self, ob) -> None:
        """Make the space the states are read and written through (see the class docstring)."""
        twin = ob.CompoundStateSpace()
        twin.addSubspace(ob.RealVectorStateSpace(self.ns), 1.0)
        twin.addSubspace(ob.RealVectorStateSpace(self.n_aux), AUXILIARY_WEIGHT)
        twin.lock()
        twin.computeLocations()
        self.value, self.from_reals, self.typed = twin.getValueAddressAtIndex, twin.copyFromReals, ob.RealVectorStateType

    def read(self, s) -> np.ndarray:
        """The flattened rung state held by an OMPL state."""
        q, a = s[0], s[1]
        if type(q) is not self.typed or type(a) is not self.typed:  # another type at the address (see the class docstring)
            return self.read_by_address(s)
        x = np.empty(self.n_flat)
        x[self.steered] = [q[k] for k in range(self.ns)]
        x[self.aux_at] = [a[k] for k in range(self.n_aux)]
        return x

    def read_by_address(self, s) -> np.ndarray:
        """`read` through the space, whatever the components' wrappers."""
        x = np.empty(self.n_flat)
        x[self.order] = [self.value(s, i) for i in range(self.n_flat)]
        return x

    def write(self, s, x: np.ndarray) -> None:
        self.from_reals(s, x[self.order].tolist())

    def q_of(self, s) -> np.ndarray:
        return self.read(s)[: self.nq]

    def flag(self, s) -> float:
        return self.value(s, self.n_flat - 1)


def _control_state_space(ob, layout: _ControlLayout, scenario: Scenario, start: State):
    """The compound space (steered q, weight 1; the rest, AUXILIARY_WEIGHT) with the sampling
    box and the KPIECE1 / EST projection registered."""
    s_low, s_high = sampling_limits(scenario, start.q)  # where samples are drawn
    space = ob.CompoundStateSpace()
    qspace = ob.RealVectorStateSpace(layout.ns)
    qbounds = ob.RealVectorBounds(layout.ns)
    for k, i in enumerate(layout.steered):
        qbounds.setLow(k, float(s_low[i]))
        qbounds.setHigh(k, float(s_high[i]))
    qspace.setBounds(qbounds)
    aux = ob.RealVectorStateSpace(layout.n_aux)
    aux.setBounds(-1e9, 1e9)
    space.addSubspace(qspace, 1.0)
    space.addSubspace(aux, AUXILIARY_WEIGHT)
    space.lock()
    layout.attach(ob)
    projected = _projection_coordinates(scenario)

    class Projection(ob.ProjectionEvaluator):
        """KPIECE1 / EST grid: the passive bodies' positions first, then the actuated ones."""

        def __init__(self, space_):
            super().__init__(space_)
            self.defaultCellSizes()

        def getDimension(self):
            return len(projected)

        def defaultCellSizes(self):
            for k in range(len(projected)):
                self.setCellSizes(k, 0.05)

        def project(self, state, out):
            for k, i in enumerate(projected):
                out[k] = layout.value(state, i)  # the steered part comes first

    projection = Projection(space)
    space.registerDefaultProjection(projection)
    return space, projection  # the caller keeps the projection alive while the space is used


def _control_space(ob, oc, space, scenario: Scenario):
    """Commanded speeds of the actuated coordinates within `control_bounds`."""
    na = len(scenario.actuated)
    cspace = oc.RealVectorControlSpace(space, max(na, 1))
    lo, hi = control_bounds(scenario)
    cb = ob.RealVectorBounds(max(na, 1))
    for j in range(na):
        cb.setLow(j, float(lo[j]))
        cb.setHigh(j, float(hi[j]))
    cspace.setBounds(cb)
    return cspace


class _Limits:
    """What makes a state invalid besides its flag: q outside the configuration limits, or a
    drive wound up (its reference leads its position by more than one control period of travel
    at full speed: it is jammed against something; in the kinematic rung references never
    lead). Such a state is flagged FLAG_INVALID (by the propagation kernel as it makes a state,
    `models.rollout.propagate_kernel`; by `flag` as the roots are written), so that the
    validity checker reads one number."""

    def __init__(self, scenario: Scenario, start: State, control_period: float):
        self.low, self.high = configuration_limits(scenario, start.q)
        self.drive_q = np.array([scenario.coordinates.index(n) for n in scenario.actuated], dtype=np.int64)
        self.windup = control_period * np.asarray(scenario.max_speeds, dtype=float)

    def flag(self, state: State, flag: float) -> float:
        """FLAG_INVALID for a running or goal state outside the limits, else `flag`."""
        if flag != FLAG_RUNNING and flag != FLAG_GOAL:
            return flag
        inside = np.all((self.low <= state.q) & (state.q <= self.high))  # NaN is outside
        wound = np.any(np.abs(state.q_ref - state.q[self.drive_q]) > self.windup)
        return flag if inside and not wound else FLAG_INVALID


def _bound_propagation(scenario: Scenario, rung: Rung, sizes, limits: _Limits, h: float):
    """The planners' compiled propagation (`Rung.propagator`) of the flattened layout `sizes`,
    its states flagged against `limits`."""
    return rung.propagator(scenario, h, sizes[:4], limits.low, limits.high, limits.drive_q, limits.windup)


def planner_propagation(scenario: Scenario, rung: Rung, start: State, h: float, control_period: float):
    """What a planner calls once per control (`_Propagator`'s compiled call), built as `plan`
    builds it from start: (x, u, duration, y) -> the run's `StepStatus` value, x and y
    flattened states (`flatten`). For timing propagation as planning pays it."""
    return _bound_propagation(scenario, rung, _layout(scenario, start), _Limits(scenario, start, control_period), h)


class _Propagator:
    """OMPL's state propagator: one compiled propagation of the rung per control
    (`Rung.propagator`: the rollout, its outcome and the limits, `_Limits`, as the flag of the
    state it makes; see the module docstring), and a `reached` subgoal checked on a running
    state; numerical failures are counted.

    The horizon: each state the search makes is at a time along its plan, its parent's plus
    the control's duration, and one past `horizon` is invalid (FLAG_INVALID), as the plan that
    reaches it would last longer than the task allows. The times are kept here, by the state's
    exact values (`times`: OMPL copies a state's values exactly, and the search propagates only
    from roots and states this propagator made), not as a coordinate of OMPL's state: one more
    coordinate would change every sampler's random stream, so the same seed would plan something
    else where the horizon never binds. A state whose time is not known (`untimed`) is not held
    to the horizon; the ladder checks every plan's length after the search. A goal reached part
    way through a control period counts at the period's end here."""

    def __init__(self, scenario: Scenario, rung: Rung, layout: _ControlLayout, limits: _Limits, h: float, reached=None, horizon=None):
        self.layout, self.reached, self.horizon = layout, reached, horizon
        self.na = len(scenario.actuated)
        self.step = _bound_propagation(scenario, rung, layout.sizes, limits, h)
        self.propagations = 0
        self.failures = 0
        self.times: dict[bytes, float] = {}
        self.untimed = 0  # propagations from a state whose time was not known
        self.past_horizon = 0  # states made invalid by the horizon

    def at(self, x: np.ndarray, t: float) -> None:
        """Record that the flattened state x is at time t along its plan, unless it has a time:
        a control that moves nothing (a drive pressed into its limit) makes a state with its
        parent's exact values, and a later time would hold the parent, still in the tree, to it.
        The earliest time is the lenient one; `planner.ladder._in_time` checks the plan found."""
        self.times.setdefault(x.tobytes(), t)

    def __call__(self, s, control, duration, result) -> None:
        self.propagations += 1
        x = self.layout.read(s)
        if x[-1] != FLAG_RUNNING:
            self.layout.write(result, x)
            return
        y = np.empty_like(x)
        if self.step(x, np.array([control[j] for j in range(self.na)]), float(duration), y) != StepStatus.OK:
            self.failures += 1
        if self.reached is not None and y[-1] == FLAG_RUNNING and self.reached(y[: self.layout.nq]):
            y[-1] = FLAG_GOAL
        if self.horizon is not None:
            t = self.times.get(x.tobytes())
            if t is None:
                self.untimed += 1
            else:
                t += float(duration)
                if t > self.horizon + HORIZON_SLACK and (y[-1] == FLAG_RUNNING or y[-1] == FLAG_GOAL):
                    y[-1] = FLAG_INVALID
                    self.past_horizon += 1
                self.at(y, t)
        self.layout.write(result, y)


def _valid_checker(layout: _ControlLayout):
    """OMPL's validity checker: the flag is running or goal (not unsafe, a failure, or outside
    the limits: `_Limits`)."""
    flag_of = layout.flag

    def valid(s) -> bool:
        flag = flag_of(s)
        return flag == FLAG_RUNNING or flag == FLAG_GOAL

    return valid


def _running_sampler(ob, layout: _ControlLayout):
    """The valid-state sampler control EST draws its expansion targets from (`sampleNear`, about
    a thousand calls a search; RRT and KPIECE1 never call it: OMPL-CRIB section 5). OMPL's own
    keeps drawing states until one is valid, but a drawn state's flag is a uniform number, never
    exactly running or goal (`_valid_checker`), so EST never expanded its tree: no propagation
    in any search. A target is a direction to grow toward, not a state the planner keeps, so
    this one draws as OMPL's state sampler does and marks the draw running."""

    class RunningSampler(ob.ValidStateSampler):
        def __init__(self, si):
            super().__init__(si)
            self.inner = si.allocStateSampler()

        def running(self, s) -> bool:
            x = layout.read_by_address(s)
            x[-1] = FLAG_RUNNING
            layout.write(s, x)
            return True

        def sample(self, s) -> bool:
            self.inner.sampleUniform(s)
            return self.running(s)

        def sampleNear(self, s, near, distance) -> bool:  # noqa: N802 (OMPL's name)
            self.inner.sampleUniformNear(s, near, distance)
            return self.running(s)

    samplers = []  # OMPL holds the sampler by a shared pointer Python does not own: keep it alive here

    def allocate(si):
        samplers.append(RunningSampler(si))
        return samplers[-1]

    return allocate


def _control_goal(ob, si, layout: _ControlLayout, goal_heuristic, guide_q, scenario: Scenario, start: State, seed: int):
    """The goal region: distance 0 exactly on states whose rollout reached the goal (else the
    heuristic's, or 1). With guide configurations, a sampleable region whose sampler hands the
    planner states near them (later ones more often: they lie closer to the goal)."""

    def distance_to_goal(s) -> float:
        if layout.flag(s) == FLAG_GOAL:
            return 0.0
        if goal_heuristic is None:
            return 1.0
        return float(1e-6 + goal_heuristic(layout.q_of(s)))

    if guide_q is None:

        class Goal(ob.GoalRegion):
            def __init__(self, si_):
                super().__init__(si_)
                self.setThreshold(1e-12)

            def distanceGoal(self, s):
                return distance_to_goal(s)

        return Goal(si)

    s_low, s_high = sampling_limits(scenario, start.q)
    rng = np.random.default_rng(int(seed))
    spread = GUIDE_SPREAD * (s_high - s_low)
    blank = flatten(start)[layout.nq :]
    blank[:] = 0.0

    class GuidedGoal(ob.GoalSampleableRegion):
        """The same goal; its sampler hands the planner states near the previous plan."""

        def __init__(self, si_):
            super().__init__(si_)
            self.setThreshold(1e-12)

        def distanceGoal(self, s):
            return distance_to_goal(s)

        def sampleGoal(self, s):
            k = min(int(len(guide_q) * np.sqrt(rng.random())), len(guide_q) - 1)
            q = np.clip(guide_q[k] + spread * rng.standard_normal(layout.nq), s_low, s_high)
            layout.write(s, np.concatenate([q, blank]))

        def maxSampleCount(self):
            return 1 << 30

        def couldSample(self):
            return True

    return GuidedGoal(si)


def _control_result(
    ss, layout: _ControlLayout, scenario: Scenario, start: State, roots, status, propagate: _Propagator, done
) -> ControlPlan:
    """The search's plan (controls, durations, states at the switches, which root it starts
    at), or an empty one when it has no path."""
    na = len(scenario.actuated)
    if not ss.haveSolutionPath():
        return ControlPlan(
            np.zeros((0, na)),
            np.zeros(0),
            start.q[None, :].copy(),
            status,
            propagate.propagations,
            done["iterations"],
            failures=propagate.failures,
            past_horizon=propagate.past_horizon,
        )
    path = ss.getSolutionPath()
    controls = np.array([[c[j] for j in range(na)] for c in path.getControls()]).reshape(-1, na)
    durations = np.array(path.getControlDurations(), dtype=float)
    states = np.array([layout.q_of(s) for s in path.getStates()])
    first = layout.read(path.getState(0))
    start_index = int(np.argmin([np.max(np.abs(first - r)) for r in roots]))
    result = ControlPlan(
        controls,
        durations,
        states,
        status,
        propagate.propagations,
        done["iterations"],
        start_index,
        failures=propagate.failures,
        past_horizon=propagate.past_horizon,
    )
    del path
    return result


@dataclass(frozen=True)
class GeometricPlan:
    states: np.ndarray  # (k, nq) waypoints
    status: PlanStatus  # how the search ended: EXACT, TIMEOUT, BUDGET_EXHAUSTED, STOPPED or ABORTED
    iterations: int
    checks: int
    goal_samples: int = 0  # goal states made by projection (0: the planner searched for the goal region)
    late_goals: int = 0  # goal states made by projection and dropped as out of reach by the horizon (`GoalSampler.in_reach`)

    @property
    def exact(self) -> bool:
        return self.status is PlanStatus.EXACT


def plan_geometric(
    scenario: Scenario, *, seed: int, iterations: int, planner: str = "RRTConnect", time_limit: float | None = None, stop=None
) -> GeometricPlan:
    """The geometric rung (eq. 9): a path in the C-space of all free DOFs whose states do not
    penetrate and are not unsafe, ending in the goal set. In a spatial scene a passive body's
    height and orientation stay at their start values (steered_coordinates): it rests.

    The goal set is thin (touching within a tolerance), so a tree rarely lands in it by
    chance: goal states are made by projection (`goal_samples`), and the planner grows toward
    them too (RRTConnect, the default, a tree from them; RRT, RRTstar and KPIECE1 by their goal
    bias). The path is then shortened with OMPL's simplifier, which keeps its end points.
    Without any goal sample (none found), RRTConnect falls back to RRT toward the goal region.
    Motions are checked in compiled calls (`_compiled_motions`)."""
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    from models.rungs import GeometricChecker

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)
    steered = steered_coordinates(scenario)  # the others keep their start values
    space, low, high = _geometric_space(scenario, steered)
    counter = {"checks": 0}
    x = np.array(scenario.start, float)
    valid_q = GeometricChecker(scenario, low, high)

    def valid(s) -> bool:
        counter["checks"] += 1
        for k, i in enumerate(steered):
            x[i] = s[k]
        return valid_q(x)

    ss = og.SimpleSetup(space)
    ss.setStateValidityChecker(valid)
    si = ss.getSpaceInformation()
    si.setStateValidityCheckingResolution(GEOMETRIC_RESOLUTION)
    sampler = GoalSampler(scenario, np.random.default_rng(int(seed)), low, high, valid_q)
    pool = [q for q in [sampler.draw()] if q is not None]

    start = space.allocState()
    for k, i in enumerate(steered):
        start[k] = float(scenario.start[i])
    ss.setStartState(start)
    ss.setGoal(_geometric_goal(si, scenario, steered, sampler, pool))
    if pool:
        chosen = getattr(og, planner)(si)
    else:
        chosen = og.RRT(si) if planner == "RRTConnect" else getattr(og, planner)(si)
    ss.setPlanner(chosen)
    if chosen.getName() in _SIMPLE_MOTION_PLANNERS:  # for the search and the simplifier
        si.setMotionValidator(_compiled_motions(si, space, valid_q, steered, x, counter))
    stop_now, done = _termination(ss, iterations, time_limit, stop=stop)
    ss.solve(ob.PlannerTerminationCondition(stop_now))
    status = _search_status(bool(ss.haveExactSolutionPath()), done)
    states = _geometric_path(ss, si, scenario, steered, status)
    result = GeometricPlan(states, status, done["iterations"], counter["checks"], len(pool), sampler.late)
    del ss, si, space
    return result


#: Geometric planners whose motion checks ask only whether a motion is valid, not where it
#: stops being valid (OMPL's checkMotion(s1, s2, lastValid), which KPIECE1 asks and a motion
#: validator written in Python cannot answer): `_compiled_motions` checks their motions, in the
#: search and the simplifier. It is set before the search: set again after it (for the others'
#: simplifier), even as the same validator, the simplified paths changed on box_push_3d (seed
#: 4 of 20), where set before the search every path is the one OMPL's own validator gives.
_SIMPLE_MOTION_PLANNERS = ("RRTConnect", "RRT")


def _compiled_motions(si, space, checker, steered: list[int], x: np.ndarray, counter: dict):
    """An OMPL motion validator that checks a straight motion in one compiled call
    (`GeometricChecker.motion`: the states, order and answer of OMPL's default
    DiscreteMotionValidator, whose every state was a call into Python), counting its states in
    counter["checks"]. A motion through a pair only python-fcl measures goes to OMPL's default
    validator, state by state."""
    from ompl import base as ob

    default = si.getMotionValidator()
    index = np.array(steered, np.int64)
    a, b = np.empty(len(steered)), np.empty(len(steered))

    class CompiledMotions(ob.MotionValidator):
        def checkMotion(self, s1, s2):
            for k in range(len(index)):
                a[k], b[k] = s1[k], s2[k]
            ok, checks = checker.motion(x, index, a, b, space.validSegmentCount(s1, s2))
            if ok < 0:
                return default.checkMotion(s1, s2)
            counter["checks"] += checks
            return ok == 1

    return CompiledMotions(si)


def _q_of(scenario: Scenario, steered: list[int], s) -> np.ndarray:
    """The full configuration of an OMPL state over the steered coordinates (the others at their start values)."""
    q = np.array(scenario.start, float)
    for k, i in enumerate(steered):
        q[i] = s[k]
    return q


def _geometric_space(scenario: Scenario, steered: list[int]):
    """The geometric rung's state space over the steered coordinates, bounded by the sampling limits: (space, low, high)."""
    from ompl import base as ob

    ns = len(steered)
    space = ob.RealVectorStateSpace(ns)
    low, high = sampling_limits(scenario, scenario.start)  # passive bodies stay where something can reach them
    bounds = ob.RealVectorBounds(ns)
    for k, i in enumerate(steered):
        bounds.setLow(k, float(low[i]))
        bounds.setHigh(k, float(high[i]))
    space.setBounds(bounds)
    return space, low, high


def _geometric_goal(si, scenario: Scenario, steered: list[int], sampler: GoalSampler, pool: list):
    """The goal set as an OMPL goal: sampleable from `pool` (grown by `sampler`) when it has a state, else a region."""
    from ompl import base as ob

    def q_of(s) -> np.ndarray:
        return _q_of(scenario, steered, s)

    class Goal(ob.GoalRegion):
        def __init__(self, si_):
            super().__init__(si_)
            self.setThreshold(1e-12)

        def distanceGoal(self, s):
            return goal_distance(scenario, q_of(s))

    class SampledGoal(ob.GoalSampleableRegion):
        """The goal region, with the projected goal states to root a goal tree at."""

        def __init__(self, si_):
            super().__init__(si_)
            self.setThreshold(1e-12)
            self.drawn = 0
            self.growing = True

        def distanceGoal(self, s):
            return goal_distance(scenario, q_of(s))

        def sampleGoal(self, s):
            """A new projected goal state while the pool may grow, else one from the pool."""
            if self.growing and len(pool) < GOAL_POOL and self.drawn >= len(pool) - 1:
                q = sampler.draw()
                self.growing = q is not None  # stop trying once the projection fails
                if q is not None:
                    pool.append(q)
            q = pool[self.drawn % len(pool)]
            self.drawn += 1
            for k, i in enumerate(steered):
                s[k] = float(q[i])

        def maxSampleCount(self):
            return GOAL_POOL

        def couldSample(self):
            return True

    return SampledGoal(si) if pool else Goal(si)


def _geometric_path(ss, si, scenario: Scenario, steered: list[int], status: PlanStatus) -> np.ndarray:
    """The solution path's configurations, simplified when exact; the start alone when there is none."""
    from ompl import geometric as og

    if ss.haveSolutionPath():
        path = ss.getSolutionPath()
        if status is PlanStatus.EXACT:
            og.PathSimplifier(si).simplifyMax(path)
        states = np.array([_q_of(scenario, steered, s) for s in path.getStates()])
        del path
    else:
        states = scenario.start[None, :].copy()
    return states


#: Motion checks of the geometric rung: states this fraction of the space's extent apart.
GEOMETRIC_RESOLUTION = 0.002
#: Attempts and Newton iterations of the goal-state projection, and its finite-difference step.
GOAL_ATTEMPTS, GOAL_POOL, PROJECTION_ITERATIONS, PROJECTION_STEP = 50, 24, 25, 1e-6


class GoalSampler:
    """Configurations in the goal set, for goal trees: a uniform sample (coordinates the goal
    bounds drawn inside their interval) projected onto the goal's constraints (intervals by
    clipping, `touch` pairs by Gauss-Newton steps on their signed distances toward half the
    touch tolerance, with finite-difference gradients over the positional and planar-angle
    coordinates; one branch of each `any`, chosen at random), kept when the goal predicate
    holds, `valid` accepts it and it is in reach (`in_reach`). `draw()` tries up to
    GOAL_ATTEMPTS samples, else None; `late` counts the goal states it dropped as out of reach,
    `earliest` the soonest any of them is reached (`reach_time`)."""

    def __init__(self, scenario: Scenario, rng: np.random.Generator, low: np.ndarray, high: np.ndarray, valid) -> None:
        self.scenario, self.rng, self.low, self.high, self.valid = scenario, rng, low, high, valid
        self.actuated = np.array([scenario.coordinates.index(n) for n in scenario.actuated], np.int64)
        self.start_actuated = np.asarray(scenario.start, float)[self.actuated]
        self.max_speeds = scenario.max_speeds
        self.period = scenario.rung_settings("geometric").control_period
        self.late, self.earliest = 0, np.inf
        steered = set(steered_coordinates(scenario))
        self.movable = np.array(
            [i for i, n in enumerate(scenario.coordinates) if i in steered and n.rsplit(".", 1)[1] in ("x", "y", "z", "theta", "yaw")],
            np.int64,
        )

    def _constraints(self, node, boxes, touches) -> None:
        from models.predicates import _pair_index

        kind = type(node).__name__
        if kind == "BoxPredicate":
            for name, (lo, hi) in node.box.items():
                boxes.append((self.scenario.coordinates.index(name), lo, hi))
        elif kind == "TouchPredicate":
            tol = node.tol if node.tol is not None else self.scenario.spec.contact.touch_tolerance
            touches.append((_pair_index(self.scenario, *node.touch), 0.5 * tol))
        elif kind == "AllPredicate":
            for child in node.all:
                self._constraints(child, boxes, touches)
        elif kind == "AnyPredicate":
            self._constraints(node.any[int(self.rng.integers(len(node.any)))], boxes, touches)

    def _terms(self, q: np.ndarray, pairs: np.ndarray, targets: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
        """`models.rungs.projection_terms` in NumPy, on the distances python-fcl completes:
        (1 converged, else 0; the residuals r; their Jacobian J, (touches, movable))."""
        from models.rungs import pair_signed_distances, pair_signed_distances_many

        movable, step = self.movable, PROJECTION_STEP
        d = pair_signed_distances(self.scenario, q)
        r = d[pairs] - targets
        if np.all(np.abs(r) <= targets):
            return 1, r, np.zeros((len(pairs), len(movable)))
        r = np.where(np.isfinite(r), r, 1.0)
        Q = np.repeat(q[None, :], len(movable), axis=0)  # row j: q with coordinate movable[j] moved by step
        Q[np.arange(len(movable)), movable] += step
        de, dp = pair_signed_distances_many(self.scenario, Q)[:, pairs], d[pairs]
        finite = np.isfinite(de) & np.isfinite(dp)
        with np.errstate(invalid="ignore"):  # (inf - inf where a distance is not finite: not used)
            return 0, r, np.where(finite, (de - dp) / step, 0.0).T

    def draw(self) -> np.ndarray | None:
        from models.rungs import projection_terms

        scenario, rng, low, high, movable = self.scenario, self.rng, self.low, self.high, self.movable
        goal = scenario.spec.task.goal
        for _ in range(GOAL_ATTEMPTS):
            boxes, touches = [], []
            self._constraints(goal, boxes, touches)
            q = np.array(scenario.start, float)
            lo, hi = low.copy(), high.copy()
            for i, a, b in boxes:  # box coordinates start inside their interval, not on its edge
                lo[i], hi[i] = max(lo[i], a), min(hi[i], b)
            q[movable] = lo[movable] + rng.random(len(movable)) * (hi[movable] - lo[movable])
            pairs = np.array([p for p, _ in touches], np.int64)
            targets = np.array([target for _, target in touches])
            r, J = np.empty(len(touches)), np.empty((len(touches), len(movable)))  # (J C-contiguous: see projection_terms)
            for _ in range(PROJECTION_ITERATIONS):
                for i, a, b in boxes:
                    q[i] = min(max(q[i], a), b)
                if not touches:
                    break
                # the terms in one compiled call; in NumPy where python-fcl measures a touch pair
                terms = projection_terms(scenario, q, movable, pairs, targets, PROJECTION_STEP, r, J)
                if terms < 0:
                    terms, r[:], J[:] = self._terms(q, pairs, targets)
                if terms == 1:
                    break
                q[movable] -= J.T @ np.linalg.solve(J @ J.T + 1e-12 * np.eye(len(touches)), r)
                q = np.clip(q, low, high)
            if goal_distance(scenario, q) == 0.0 and self.valid(q):
                if self.in_reach(q):
                    return q
                self.late += 1
                self.earliest = min(self.earliest, self.reach_time(q))
        return None

    def reach_time(self, q: np.ndarray) -> float:
        """The soonest the actuators reach q from the start, moving straight at their max speeds,
        as the geometric rung times a path (`segment_periods`), in whole control periods."""
        return segment_periods(q[self.actuated] - self.start_actuated, self.max_speeds, self.period) * self.period

    def in_reach(self, q: np.ndarray) -> bool:
        """Whether the actuators reach q by the task's horizon (`reach_time`): no path to a goal
        state beyond that is in time, however the search finds it."""
        return self.reach_time(q) <= latest_goal_time(self.scenario)


def goal_reach(scenario: Scenario, seed: int = 0) -> dict:
    """What `ladder check` says of the goal set and the horizon: the geometric rung's first goal
    draw (`GoalSampler.draw`, GOAL_ATTEMPTS tries) from the start. {"in_reach": whether it made
    a goal state in reach of the horizon (None: it made none at all), "late": the goal states it made out of reach,
    "earliest": the soonest any of those is reached, s (None: none)}. No goal state in reach
    and some late: the horizon is shorter than the actuators need to get to the goal set. In
    reach is no promise: it times the actuators' own travel, and a body they must push into the
    goal (which the geometric rung moves on its own) can need longer."""
    from models.rungs import GeometricChecker

    low, high = sampling_limits(scenario, scenario.start)
    sampler = GoalSampler(scenario, np.random.default_rng(int(seed)), low, high, GeometricChecker(scenario, low, high))
    made = sampler.draw()
    in_reach = True if made is not None else False if sampler.late else None  # (None: no goal state made, nothing to time)
    return {"in_reach": in_reach, "late": sampler.late, "earliest": float(sampler.earliest) if sampler.late else None}

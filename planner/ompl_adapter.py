"""The one module that imports OMPL: control planning over a rung's compiled rollout.

An OMPL state is the rung's whole state flattened: [q, nu, q_ref, delta_n, delta_t, flag],
where flag records how the rollout that produced it ended (0 running, 1 goal, 2 unsafe,
3 numerical failure). The state space is a compound of q (weight 1) and the rest (weight
1e-6), so nearest neighbours are found in configuration space. One propagate call runs one
control period of physics steps in one compiled rollout (OMPL-CRIB section 8: coarse steps
keep the Python callback cost small). Validity: flag is neither unsafe nor failure, and q is
in bounds. The goal region's distance is 0 exactly on states whose rollout reached the goal.

Determinism (OMPL-CRIB section 6): the seed is set before any planner exists and the budget
is an iteration count, so the same seed gives the same plan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models.rungs import Rung, State
from models.scenario import Scenario

FLAG_RUNNING, FLAG_GOAL, FLAG_UNSAFE, FLAG_FAILED = 0.0, 1.0, 2.0, 3.0
#: Distance weight of everything but q in the state metric.
AUXILIARY_WEIGHT = 1e-6
#: Half-width of the sampling box of passive coordinates around the start (m or rad).
PASSIVE_RANGE = 2.0
#: Each control is held for 1 to this many control periods.
MAX_CONTROL_PERIODS = 10


@dataclass(frozen=True)
class ControlPlan:
    controls: np.ndarray  # (k, n_actuated) commanded speeds
    durations: np.ndarray  # (k,) seconds
    states: np.ndarray  # (k + 1, nq) configurations at the control switches
    exact: bool
    propagations: int
    iterations: int
    start_index: int = 0  # which start the path begins at (0: the real start; i: extra_starts[i - 1])


def _layout(scenario: Scenario, state: State) -> tuple[int, int, int, int, int]:
    nq, nv, na = len(state.q), len(state.nu), len(state.q_ref)
    return nq, nv, na, len(state.delta_n), 2 * len(state.delta_n)


def flatten(state: State, flag: float = FLAG_RUNNING) -> np.ndarray:
    return np.concatenate([state.q, state.nu, state.q_ref, state.delta_n, state.delta_t.ravel(), [flag]])


def unflatten(x: np.ndarray, sizes) -> tuple[State, float]:
    nq, nv, na, nd, _ = sizes
    i = 0
    parts = []
    for n in (nq, nv, na, nd, 2 * nd):
        parts.append(np.array(x[i : i + n]))
        i += n
    return State(parts[0], parts[1], parts[2], parts[3], parts[4].reshape(nd, 2)), float(x[i])


def control_bounds(scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = [], []
    bounds = scenario.spec.task.control_bounds
    for name in scenario.actuated:
        body, dof = name.split(".")
        drive = scenario.body(body).actuators[dof]
        low, high = bounds.get(name, (-drive.max_speed, drive.max_speed))
        lo.append(low)
        hi.append(high)
    return np.array(lo), np.array(hi)


def _configuration_bounds(ob, scenario: Scenario, q0: np.ndarray):
    """OMPL bounds on q: the drives' position limits, else q0 +- PASSIVE_RANGE."""
    bounds = ob.RealVectorBounds(len(scenario.coordinates))
    for i, name in enumerate(scenario.coordinates):
        body, dof = name.split(".", 1)
        drive = scenario.body(body).actuators.get(dof)
        low = drive.lower if drive is not None and drive.lower is not None else q0[i] - PASSIVE_RANGE
        high = drive.upper if drive is not None and drive.upper is not None else q0[i] + PASSIVE_RANGE
        bounds.setLow(i, float(low))
        bounds.setHigh(i, float(high))
    return bounds


def _projection_coordinates(scenario: Scenario, most: int = 3) -> list[int]:
    """Indices of up to `most` translational coordinates, passive bodies first."""
    passive = [i for i, n in enumerate(scenario.coordinates) if n not in scenario.actuated and n.split(".")[1] in ("x", "y", "z")]
    active = [i for i, n in enumerate(scenario.coordinates) if n in scenario.actuated]
    return (passive + active)[:most] or [0]


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
    goal_distance=None,
    extra_starts: list[State] | None = None,
    time_limit: float | None = None,
) -> ControlPlan:
    """Plan commanded speeds from `start` under `rung` with OMPL's control planner.

    extra_starts: more tree roots (OMPL-CRIB section 5), e.g. the previous plan's states
    replayed under this rung; the result says which root its path starts at.
    time_limit: a wall-clock cap on top of the iteration budget (then not reproducible).
    """
    from ompl import base as ob
    from ompl import control as oc
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)  # before any planner or sampler exists; OMPL wants > 0
    sizes = _layout(scenario, start)
    nq = sizes[0]
    n_aux = sum(sizes[1:]) + 1

    space = ob.CompoundStateSpace()
    qspace = ob.RealVectorStateSpace(nq)
    qspace.setBounds(_configuration_bounds(ob, scenario, start.q))
    aux = ob.RealVectorStateSpace(n_aux)
    aux.setBounds(-1e9, 1e9)
    space.addSubspace(qspace, 1.0)
    space.addSubspace(aux, AUXILIARY_WEIGHT)
    space.lock()
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
                out[k] = state[0][i]

    projection = Projection(space)
    space.registerDefaultProjection(projection)

    na = len(scenario.actuated)
    cspace = oc.RealVectorControlSpace(space, max(na, 1))
    lo, hi = control_bounds(scenario)
    cb = ob.RealVectorBounds(max(na, 1))
    for j in range(na):
        cb.setLow(j, float(lo[j]))
        cb.setHigh(j, float(hi[j]))
    cspace.setBounds(cb)

    si = oc.SpaceInformation(space, cspace)
    si.setPropagationStepSize(control_period)
    si.setMinMaxControlDuration(1, MAX_CONTROL_PERIODS)
    counter = {"propagations": 0}

    def read(s) -> np.ndarray:
        x = np.empty(nq + n_aux)
        q, a = s[0], s[1]
        for i in range(nq):
            x[i] = q[i]
        for i in range(n_aux):
            x[nq + i] = a[i]
        return x

    def write(s, x: np.ndarray) -> None:
        q, a = s[0], s[1]
        for i in range(nq):
            q[i] = float(x[i])
        for i in range(n_aux):
            a[i] = float(x[nq + i])

    def propagate(s, control, duration, result):
        counter["propagations"] += 1
        x = read(s)
        state, flag = unflatten(x, sizes)
        u = np.array([control[j] for j in range(na)])
        if flag != FLAG_RUNNING:
            write(result, x)
            return
        out = rung.rollout(scenario, state, u.reshape(1, -1), [duration], h)
        new_flag = FLAG_RUNNING
        if not out.ok:
            new_flag = FLAG_FAILED
        elif out.outcome == "goal":
            new_flag = FLAG_GOAL
        elif out.outcome == "unsafe":
            new_flag = FLAG_UNSAFE
        write(result, flatten(out.state, new_flag))

    def valid(s) -> bool:
        flag = s[1][n_aux - 1]
        return bool(flag != FLAG_UNSAFE and flag != FLAG_FAILED and qspace.satisfiesBounds(s[0]))

    si.setStatePropagator(propagate)
    si.setStateValidityChecker(valid)

    class Goal(ob.GoalRegion):
        def __init__(self, si_):
            super().__init__(si_)
            self.setThreshold(1e-12)

        def distanceGoal(self, s):
            if s[1][n_aux - 1] == FLAG_GOAL:
                return 0.0
            if goal_distance is None:
                return 1.0
            return float(1e-6 + goal_distance(np.array([s[0][i] for i in range(nq)])))

    ss = oc.SimpleSetup(si)
    starts = [start] + list(extra_starts or [])
    roots = []
    for k, st in enumerate(starts):
        root = space.allocState()
        write(root, flatten(st))
        roots.append(read(root))
        if k == 0:
            ss.setStartState(root)
        else:
            ss.addStartState(root)
    ss.setGoal(Goal(si))
    ss.setPlanner(getattr(oc, planner)(si))
    done = {"iterations": 0}

    import time as _time

    deadline = None if time_limit is None else _time.perf_counter() + time_limit

    def stop() -> bool:
        done["iterations"] += 1
        if deadline is not None and _time.perf_counter() > deadline:
            return True
        return done["iterations"] > iterations or ss.haveExactSolutionPath()

    ss.solve(ob.PlannerTerminationCondition(stop))
    exact = bool(ss.haveExactSolutionPath())
    if not ss.haveSolutionPath():
        return ControlPlan(np.zeros((0, na)), np.zeros(0), start.q[None, :].copy(), False, counter["propagations"], done["iterations"])
    path = ss.getSolutionPath()
    controls = np.array([[c[j] for j in range(na)] for c in path.getControls()]).reshape(-1, na)
    durations = np.array(path.getControlDurations(), dtype=float)
    states = np.array([[s[0][i] for i in range(nq)] for s in path.getStates()])
    first = read(path.getState(0))
    start_index = int(np.argmin([np.max(np.abs(first - r)) for r in roots]))
    result = ControlPlan(controls, durations, states, exact, counter["propagations"], done["iterations"], start_index)
    del path, ss, si, space
    return result


@dataclass(frozen=True)
class GeometricPlan:
    states: np.ndarray  # (k, nq) waypoints
    exact: bool
    iterations: int
    checks: int


def plan_geometric(scenario: Scenario, *, seed: int, iterations: int, planner: str = "RRTConnect") -> GeometricPlan:
    """The geometric rung (eq. 9): a path in the C-space of all free DOFs whose states do not
    penetrate and are not unsafe, ending in the goal set. RRTConnect needs a goal it can
    sample, which the goal predicates do not give, so RRTConnect falls back to RRT here."""
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    from models.predicates import pair_distances, predicate_distance
    from models.rungs import GEOMETRIC_TOLERANCE

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)
    nq = len(scenario.coordinates)
    task = scenario.spec.task
    space = ob.RealVectorStateSpace(nq)
    space.setBounds(_configuration_bounds(ob, scenario, scenario.start))
    counter = {"checks": 0}

    def q_of(s) -> np.ndarray:
        return np.array([s[i] for i in range(nq)])

    from models.contact import pair_min_distances
    from models.rungs import compiled

    scene = compiled(scenario).scene
    psi = np.empty(max(len(scenario.pairs), 1))

    def distances(q: np.ndarray) -> np.ndarray:
        """Compiled pair distances; python-fcl only for the pairs the kernels cannot do."""
        pair_min_distances(scene, q, 1e9, psi)
        if np.isnan(psi).any():
            return pair_distances(scenario, q)
        return psi

    def valid(s) -> bool:
        counter["checks"] += 1
        q = q_of(s)
        d = distances(q)
        if np.any(d[: len(scenario.pairs)] < -GEOMETRIC_TOLERANCE):
            return False
        if task.unsafe is not None and predicate_distance(scenario, task.unsafe, q, d) == 0.0:
            return False
        return True

    ss = og.SimpleSetup(space)
    ss.setStateValidityChecker(valid)
    si = ss.getSpaceInformation()
    si.setStateValidityCheckingResolution(0.01)

    class Goal(ob.GoalRegion):
        def __init__(self, si_):
            super().__init__(si_)
            self.setThreshold(1e-12)

        def distanceGoal(self, s):
            q = q_of(s)
            return float(predicate_distance(scenario, task.goal, q, distances(q)))

    start = space.allocState()
    for i in range(nq):
        start[i] = float(scenario.start[i])
    ss.setStartState(start)
    ss.setGoal(Goal(si))
    chosen = og.RRT(si) if planner == "RRTConnect" else getattr(og, planner)(si)
    ss.setPlanner(chosen)
    done = {"iterations": 0}

    def stop() -> bool:
        done["iterations"] += 1
        return done["iterations"] > iterations or ss.haveExactSolutionPath()

    ss.solve(ob.PlannerTerminationCondition(stop))
    exact = bool(ss.haveExactSolutionPath())
    states = np.array([q_of(s) for s in ss.getSolutionPath().getStates()]) if ss.haveSolutionPath() else scenario.start[None, :].copy()
    result = GeometricPlan(states, exact, done["iterations"], counter["checks"])
    del ss, si, space
    return result

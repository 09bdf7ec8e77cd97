"""The rungs of the ladder: one small object each, over the one stepper (models.stepper).

Every rung has the same interface:

- ``initial_state(scenario)`` -> `State` at the scenario's start;
- ``rollout(scenario, state, controls, durations, h, ...)`` -> `RolloutResult` (many steps in
  one compiled call; controls are commanded speeds of the actuated coordinates);
- ``lift(state)`` / ``project(state)``: the paper's kappa between rungs (Definition 1): a
  lower rung's state gains zero velocities / zero deformations, a higher rung's loses them;
- ``valid(scenario, q)``: non-penetration (the geometric rung's whole model, eq. 9).

`RUNGS` holds the rung objects, lowest fidelity first, built from the family's registry
(`models.family.FAMILY`): adding a rung touches its entry there only.
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from dataclasses import dataclass, field, fields, replace

import numba
import numpy as np

from models import geometry as geo
from models.contact import CONTACT_MARGIN, has_script, pair_distance_buffers, pair_min_distances, pair_min_distances_into
from models.family import FAMILY, control_steps
from models.kernel_cache import compile_ahead
from models.kinematics import PI_INERT, SceneData, compile_scene, kernel_array
from models.predicates import OP_TOUCH, Program, compile_predicate, evaluate_with
from models.rollout import bind, general_step_types, propagate_kernel, rollout_bound, rollout_each, rollout_kernel, warm_period_steps
from models.scenario import TRANSLATIONAL_DOFS, Scenario, penetration_warning, principal_inertia
from models.stepper import (
    LAW_ACTIVE,
    LAW_AXIS,
    LAW_BODY,
    LAW_COLUMNS,
    LAW_MAX_SPEED,
    LAW_RATE,
    LAW_TARGET,
    LEMKE,
    SOLVER_LEMKE,
    Drives,
    Model,
    Solver,
    StepStatus,
    contact_solver,
    dynamics_step,
)
from models.task import Outcome

#: Tolerance of the geometric rung's non-penetration check (m).
GEOMETRIC_TOLERANCE = 1e-9
#: Default number of states kept in a rollout's trajectory.
DEFAULT_RECORDS = 2000
#: The most steps one control of a rollout may take: the kernels count a control's steps in an
#: int64 from round(duration / h), exact up to here (a step h of 1e-300 had run on for ever).
MAX_CONTROL_STEPS = 2**53


def _no_basis() -> np.ndarray:
    return np.zeros((0, 0), np.int8)


@dataclass(frozen=True)
class State:
    """A rung's state: q, nu, the drives' reference positions, contact deformations; and
    lcp_basis, the contact solver's warm start (the complementary basis of the last contact
    LCP solved, `models.stepper.basis_table`; empty: none). lcp_basis is no physics: a step
    solves its LCP exactly whatever it holds (it is only tried first), and a state without it
    (e.g. rebuilt from a planner's state vector) steps as well; a rollout that continues from
    its result state takes the same steps as one longer rollout."""

    q: np.ndarray
    nu: np.ndarray
    q_ref: np.ndarray
    delta_n: np.ndarray
    delta_t: np.ndarray
    lcp_basis: np.ndarray = field(default_factory=_no_basis)

    def named(self, scenario: Scenario) -> dict[str, float]:
        return {n: float(v) for n, v in zip(scenario.coordinates, self.q)}


def made(cls, values: dict):
    """An instance of the frozen dataclass `cls` whose fields are `values` (a dict of every
    field by name, which becomes the instance's own `__dict__`: the caller hands it over), made
    without its `__init__`, which sets each field through `object.__setattr__` (2 us for
    `RolloutResult`'s 19 and its `State`, per call of `Rung.rollout`, where tracking's candidate
    of box_push_3d is about 300 us; with keyword arguments, 1.6 us; from a dict display, 0.7 us).
    No field is defaulted and no value checked: every field must be given (made() raises where
    one is missing or unknown), and `cls` must have no `__post_init__`."""
    names = _FIELD_NAMES.get(cls)
    if names is None:
        if getattr(cls, "__post_init__", None) is not None:
            raise TypeError(f"made() cannot make {cls.__name__}: it has a __post_init__")
        names = _FIELD_NAMES[cls] = frozenset(f.name for f in fields(cls))
    if values.keys() != names:
        missing, unknown = sorted(names - values.keys()), sorted(values.keys() - names)
        raise TypeError(f"made({cls.__name__}): missing fields {missing}, unknown fields {unknown}")
    obj = object.__new__(cls)
    object.__setattr__(obj, "__dict__", values)
    return obj


_FIELD_NAMES: dict[type, frozenset] = {}


#: A rollout's status and outcome codes as its result spells them (looked up once, not per call).
_STATUS_TEXT = {int(s): (s.label, s.message) for s in StepStatus}
_OUTCOME_LABEL = {int(o): o.label for o in Outcome}


def _basis_of(state: State) -> np.ndarray:
    """The state's warm start as the kernel takes it (a copy; empty when it has none)."""
    basis = np.asarray(state.lcp_basis)
    return np.array(basis, np.int8) if basis.ndim == 2 else _no_basis()


def policy_drives(scenario: Scenario, drives: Drives) -> Drives:
    """`drives` as the scenario's policy runs them: a drive with a feedback law (`[task.policy]
    laws`, `models.schema.Law`) is a damper kd (v_des - v) toward the law's desired speed
    (kp = 0 in the drive; `models.rollout.law_speeds` sets v_des each step), which is the force
    kp (target - q) - kd v of the law's quadratic well wherever the speed limit does not act."""
    policy = scenario.spec.task.policy
    if policy is None or not policy.laws:
        return drives
    kp, kd, law = drives.kp.copy(), drives.kd.copy(), drives.law.copy()
    bodies = [b.name for b in scenario.spec.bodies]
    for name, spec in policy.laws.items():
        j = scenario.actuated.index(name)
        kp[j], kd[j] = 0.0, spec.kd
        law[j, LAW_ACTIVE], law[j, LAW_RATE] = 1.0, spec.kp / spec.kd
        law[j, LAW_MAX_SPEED] = np.inf if spec.max_speed is None else spec.max_speed
        target = spec.target
        if isinstance(target, (int, float)):
            law[j, LAW_BODY], law[j, LAW_TARGET] = -1.0, target
        else:
            law[j, LAW_BODY] = bodies.index(target.body)
            law[j, LAW_AXIS] = "xyz".index(name.rsplit(".", 1)[-1])
            law[j, LAW_TARGET : LAW_TARGET + len(target.point)] = target.point
    return drives._replace(kp=kp, kd=kd, law=law)


def policy_controls(scenario: Scenario, duration: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The scenario's policy as a rollout takes it (with `laws=True`): one control, its
    commanded speeds (0 for a drive it gives none; a drive under a law takes the law's speed
    each step), held for `duration` (default: the policy's)."""
    policy = scenario.spec.task.policy
    controls = np.array([[policy.speeds.get(name, 0.0) for name in scenario.actuated]])
    return controls, np.array([float(duration if duration is not None else policy.duration)])


@dataclass(frozen=True)
class ControlEnd:
    """Where one control of `Rung.rollout_each` ended: what a `RolloutResult` of that control
    alone says of it, but its records and counters."""

    state: State
    outcome: str  # goal, unsafe, none
    status: str  # ok or a failure code name
    message: str
    min_psi: float  # smallest contact signed distance met in the control's steps, m
    force_steps: int  # its steps in which some contact carried a positive normal force

    @property
    def ok(self) -> bool:
        return self.status == "ok"


@dataclass(frozen=True)
class RolloutResult:
    state: State
    t: float
    outcome: str  # goal, unsafe, none
    status: str  # ok or a failure code name
    message: str
    steps: int
    lcp_solves: int
    pivots: int
    max_residual: float
    max_lcp_size: int
    wall_s: float
    times: np.ndarray
    trajectory: np.ndarray  # (n, nq)
    velocities: np.ndarray  # (n, nv)
    pair_force: np.ndarray  # (n_pairs,) normal force of each contact pair in the last step, N
    min_psi: float = np.inf  # smallest contact signed distance met (negative: penetration), m
    force_steps: int = 0  # steps in which some contact carried a positive normal force
    sweeps: int = 0  # PGS sweeps over all steps (0 with Lemke)
    pair_wrench: np.ndarray | None = None  # (n_pairs, 3) world force on each pair's second body in the last step, N

    @property
    def max_penetration(self) -> float:
        return float(max(0.0, -self.min_psi))

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def contact_forces(self, scenario: Scenario) -> list[dict]:
        """Per contact pair, the contact force of the last step taken (N, world frame): on the
        pair's second body, normal plus friction (`force`), and the sum of the normal
        magnitudes (`normal`); pairs that carried no force are left out. The kinematic rung
        has no forces: an empty list."""
        out = []
        dim = scenario.dimension
        for k, pair in enumerate(scenario.pairs):
            if self.pair_wrench is None or self.pair_force[k] == 0.0:
                continue
            out.append(
                {
                    "bodies": [pair.body_a, pair.body_b],
                    "normal": float(self.pair_force[k]),
                    "force": [float(v) for v in self.pair_wrench[k][:dim]],
                }
            )
        return out


@dataclass
class Compiled:
    """What a scenario compiles to (cached per scenario object)."""

    scene: SceneData
    drives: Drives
    policy_drives: Drives  # the drives as the scenario's policy runs them: its feedback laws (`policy_drives`)
    goal: Program
    unsafe: Program
    capacity: int
    # the shapes of a state's q, nu, q_ref, delta_n and delta_t (`check_state`)
    state_shapes: tuple
    scripted: bool  # some obstacle moves on a script (rollouts then work on a copy of the scene's pose tables)
    # the typed Lists `Rung.rollout` binds (`models.rollout.rollout_bound`), by (model, solver, laws)
    bound: dict = field(default_factory=dict)
    # the scene alone, bound (`models.rollout.bind`): `pair_signed_distances`' one argument for it
    scene_bound: object = None


#: Scenarios whose compiled data `compiled` keeps (the most recently used). A sweep worker
#: loads a new scenario per run: the cache keeps the last few, not every one it met.
CACHE_SIZE = 16
_CACHE: OrderedDict[int, tuple[Scenario, Compiled]] = OrderedDict()


def own_poses(scene: SceneData) -> SceneData:
    """The scene with its own copy of the pose tables the kernels move scripted obstacles in
    (`models.contact.place_scripted`: bf, base_pos, base_quat), the rest shared."""
    return scene._replace(bf=scene.bf.copy(), base_pos=scene.base_pos.copy(), base_quat=scene.base_quat.copy())


def _state_shapes(scenario: Scenario, drives: int, capacity: int) -> tuple:
    """The shapes of a state's q, nu, q_ref, delta_n and delta_t in this scenario."""
    return (len(scenario.coordinates),), (len(scenario.velocities),), (drives,), (capacity,), (capacity, 2)


def run_arrays(scenario: Scenario, controls, durations) -> tuple[np.ndarray, np.ndarray]:
    """A run's controls and durations as the kernels take them, copies (contiguous; the caller's
    stay theirs): durations a 1-d float array, controls a (len(durations), drives) one, also
    given flat where that reads one way only (one control, or one drive). ValueError, in the
    run's words, where the shapes do not match (numpy's reshape had said "cannot reshape array
    of size 6 into shape (2,2)", and had made 2 controls of 3 values, for 3 durations of a
    2-drive scene, into 3 other controls, silently)."""
    durations = np.array(durations, dtype=float, ndmin=1)
    if durations.ndim != 1:
        raise ValueError(f"durations must be a list of seconds, one per control, got an array of shape {durations.shape}")
    controls = np.array(controls, dtype=float)
    k, drives = len(durations), len(scenario.actuated)
    if controls.shape == (k, drives):
        return controls, durations
    if controls.ndim == 1 and (k == 1 and len(controls) == drives or drives == 1 and len(controls) == k):
        return controls.reshape(k, drives), durations  # (flat where it reads one way only)
    names = ", ".join(scenario.actuated) or "none"
    raise ValueError(
        f"controls of shape {controls.shape} for {k} duration(s): a run takes one control per duration, "
        f"each of {drives} commanded speed(s) ({names}), shape ({k}, {drives})"
    )


def check_run(durations: np.ndarray, h: float) -> None:
    """ValueError unless h is a positive number of seconds and every duration a finite one of
    no less than zero, of at most MAX_CONTROL_STEPS steps (h = 0 had been a ZeroDivisionError,
    a negative h a run of no steps, status ok; a NaN duration an undefined step count)."""
    if not (h > 0.0 and math.isfinite(h)):
        raise ValueError(f"the step h must be a positive number of seconds, got {h}")
    if len(durations) == 0:
        return
    lo, hi = (float(durations[0]),) * 2 if len(durations) == 1 else (float(durations.min()), float(durations.max()))
    if not (lo >= 0.0 and hi < math.inf):  # (a NaN fails both)
        bad = next(float(d) for d in durations if not 0.0 <= d < math.inf)
        raise ValueError(f"a control's duration must be a finite number of seconds, no less than 0, got {bad}")
    if hi / h > MAX_CONTROL_STEPS:
        raise ValueError(f"a control of {hi:g} s at h = {h:g} is {hi / h:.3g} steps, more than a rollout counts ({MAX_CONTROL_STEPS:.3g})")


def check_state(scenario: Scenario, c: Compiled, state: State) -> None:
    """ValueError where state's arrays are not shaped as the scenario's states (c: what it
    compiles to): the kernels index them unchecked, and a state of another scene passed to a
    rollout had crashed the process (a segmentation fault)."""
    try:  # (the common case, arrays: no generator, no getattr)
        got = (state.q.shape, state.nu.shape, state.q_ref.shape, state.delta_n.shape, state.delta_t.shape)
    except AttributeError:
        got = tuple(getattr(a, "shape", None) for a in (state.q, state.nu, state.q_ref, state.delta_n, state.delta_t))
    if got != c.state_shapes:
        names = ("q", "nu", "q_ref", "delta_n", "delta_t")
        wrong = [f"{name} {g} (expected {e})" for name, g, e in zip(names, got, c.state_shapes) if g != e]
        raise ValueError(f"the state is not one of {scenario.path.name}'s (a state of another scenario?): {'; '.join(wrong)}")


def compiled(scenario: Scenario) -> Compiled:
    """What `scenario` compiles to, computed once and kept for the CACHE_SIZE scenarios used
    most recently (keyed by identity: the entry holds the scenario, so its id is not reused
    while it is cached)."""
    hit = _CACHE.get(id(scenario))
    if hit is not None and hit[0] is scenario:
        _CACHE.move_to_end(id(scenario))
        return hit[1]
    S = compile_scene(scenario)
    q_index, v_index, kp, kd, lower, upper, max_force = [], [], [], [], [], [], []
    for body in scenario.spec.bodies:
        for dof, drive in body.actuators.items():
            name = f"{body.name}.{dof}"
            q_index.append(scenario.coordinates.index(name))
            v_index.append(scenario.velocities.index(name))
            kp.append(drive.kp)
            kd.append(drive.kd)
            lower.append(-np.inf if drive.lower is None else drive.lower)
            upper.append(np.inf if drive.upper is None else drive.upper)
            max_force.append(np.inf if drive.max_force is None else drive.max_force)
    # drives in the scenario's actuated order
    order = [scenario.coordinates[i] for i in q_index]
    perm = [order.index(name) for name in scenario.actuated]
    gravity = np.zeros(3)
    gravity[: scenario.dimension] = scenario.spec.scene.gravity
    drives = Drives(
        q_index=np.array(q_index, np.int64)[perm] if perm else np.zeros(0, np.int64),
        v_index=np.array(v_index, np.int64)[perm] if perm else np.zeros(0, np.int64),
        kp=np.array(kp, float)[perm] if perm else np.zeros(0),
        kd=np.array(kd, float)[perm] if perm else np.zeros(0),
        lower=np.array(lower, float)[perm] if perm else np.zeros(0),
        upper=np.array(upper, float)[perm] if perm else np.zeros(0),
        gravity=gravity,
        max_force=np.array(max_force, float)[perm] if perm else np.zeros(0),
        law=np.zeros((len(perm), LAW_COLUMNS)),
    )
    goal = compile_predicate(scenario, scenario.spec.task.goal)
    unsafe = compile_predicate(scenario, scenario.spec.task.unsafe)
    watched = {int(i) for P in (goal, unsafe) for op, i in zip(P.op, P.index) if op == OP_TOUCH}
    if watched:
        pi = S.pi.copy()
        pi[sorted(watched), PI_INERT] = 0  # predicates need these distances
        S = S._replace(pi=pi)
    capacity = max(int(S.pair_max_contacts.sum()), 1)
    result = Compiled(
        scene=S,
        drives=drives,
        policy_drives=policy_drives(scenario, drives),
        goal=goal,
        unsafe=unsafe,
        capacity=capacity,
        state_shapes=_state_shapes(scenario, len(q_index), capacity),
        scripted=bool(has_script(S.bf)),
        scene_bound=bind((S,)),
    )
    _CACHE[id(scenario)] = (scenario, result)
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return result


@dataclass(frozen=True)
class Rung:
    """One model of the family: a name, its physics settings (None: geometric) and how its
    contact problems are solved (`models.stepper.Solver`; Lemke unless a scenario says)."""

    name: str
    model: Model | None
    description: str = field(default="", compare=False)
    solver: Solver = LEMKE

    @property
    def propagates(self) -> bool:
        return self.model is not None

    def initial_state(self, scenario: Scenario) -> State:
        c = compiled(scenario)
        q = np.array(scenario.start, dtype=float)
        # initial velocities are a state of the rungs with inertia; the others have none
        dynamic = self.model is not None and not self.model.kinematic and self.model.eps > 0.0
        return State(
            q=q,
            nu=np.array(scenario.start_velocity, dtype=float) if dynamic else np.zeros(len(scenario.velocities)),
            q_ref=q[c.drives.q_index].copy(),
            delta_n=np.zeros(c.capacity),
            delta_t=np.zeros((c.capacity, 2)),
        )

    def lift(self, state: State) -> State:
        """kappa from a lower rung: what this rung does not model starts at zero."""
        if self.model is None:
            return self.project(state)
        if self.model.kinematic or not self.model.compliant:
            return replace(state, delta_n=np.zeros_like(state.delta_n), delta_t=np.zeros_like(state.delta_t))
        return state

    def project(self, state: State) -> State:
        """To the geometric rung: configuration only."""
        return State(state.q, np.zeros_like(state.nu), state.q_ref, np.zeros_like(state.delta_n), np.zeros_like(state.delta_t))

    def rollout(
        self,
        scenario: Scenario,
        state: State,
        controls: np.ndarray,
        durations: np.ndarray,
        h: float,
        *,
        record_every: int = 0,
        max_records: int = DEFAULT_RECORDS,
        stop_at_outcome: bool = True,
        t0: float = 0.0,
        laws: bool = False,
    ) -> RolloutResult:
        """Run controls[k] for durations[k] from state, which is at time t0 (where scripted
        obstacles are); the result's times count from the start of this rollout. laws: the
        drives follow the feedback laws of the scenario's policy (`policy_drives`; the controls
        are `policy_controls`)."""
        controls, durations = run_arrays(scenario, controls, durations)
        check_run(durations, h)
        if record_every <= 0:
            total = float(durations[0]) if len(durations) == 1 else float(durations.sum())  # (one control: no reduction)
            record_every = record_spacing(int(round(total / h)), max_records)
        start = time.perf_counter()
        # the kernel's `RolloutOutput` by position (`rollout_bound`'s plain tuple)
        (
            q, nu, q_ref, delta_n, delta_t, t, outcome, status, steps, lcp_solves, pivots, max_residual, max_lcp_size, times, trajectory,
            velocities, pair_force, min_psi, force_steps, sweeps, pair_wrench, basis,
        ) = self._run(scenario, state, controls, durations, h, record_every, max_records, stop_at_outcome, t0, laws)  # fmt: skip
        wall = time.perf_counter() - start
        label, message = _STATUS_TEXT[status]
        # (the kernel's scalars come back as Python's int and float; its pair buffers hold at least one pair)
        n_pairs = len(scenario.pairs)
        if len(pair_force) != n_pairs:
            pair_force, pair_wrench = pair_force[:n_pairs], pair_wrench[:n_pairs]
        end = made(State, {"q": q, "nu": nu, "q_ref": q_ref, "delta_n": delta_n, "delta_t": delta_t, "lcp_basis": basis})
        return made(
            RolloutResult,
            {
                "state": end,
                "t": t,
                "outcome": _OUTCOME_LABEL[outcome],
                "status": label,
                "message": message,
                "steps": steps,
                "lcp_solves": lcp_solves,
                "pivots": pivots,
                "max_residual": max_residual,
                "max_lcp_size": max_lcp_size,
                "wall_s": wall,
                "times": times,
                "trajectory": trajectory,
                "velocities": velocities,
                "pair_force": pair_force,
                "min_psi": min_psi,
                "force_steps": force_steps,
                "sweeps": sweeps,
                "pair_wrench": pair_wrench,
            },
        )

    def rollout_each(self, scenario: Scenario, state: State, controls, durations, h: float) -> list[ControlEnd]:
        """Each control run from where the one before ended, as separate calls of `rollout`
        (stopping at an outcome, from t0 = 0) would run them, with the same bits, until one
        ends in an outcome or a failure: the end of each control run, in one compiled call
        (`models.rollout.rollout_each`, which copies the state it starts from)."""
        controls, durations = run_arrays(scenario, controls, durations)
        if self.model is None:
            raise ValueError("the geometric rung has no dynamics to roll out; use valid()")
        c = compiled(scenario)
        check_state(scenario, c, state)
        check_run(durations, h)
        self._compile_ahead(c, state, h)
        # scripted obstacles: this call's own pose tables (`_bound`; each control's kernel call
        # places the obstacles at its start, t0 = 0, as a separate `rollout` does)
        bound = self._bound(c, False)
        n, Q, NU, Q_REF, DN, DT, BASIS, status, outcome, min_psi, force_steps = rollout_each(
            bound, state.q, state.nu, state.q_ref, state.delta_n, state.delta_t, _basis_of(state), controls, durations, float(h)
        )
        ends = []
        for k in range(n):
            label, message = _STATUS_TEXT[status[k]]
            end = State(Q[k], NU[k], Q_REF[k], DN[k], DT[k], BASIS[k])
            ends.append(ControlEnd(end, _OUTCOME_LABEL[outcome[k]], label, message, float(min_psi[k]), int(force_steps[k])))
        return ends

    def propagator(self, scenario: Scenario, h: float, sizes, low, high, drive_q, windup):
        """The planners' propagation at step h (`models.rollout.propagate_kernel`: one control
        from a flattened state into another, with the limits checked), bound to this rung and
        scene: a function (x, u, duration, y) -> the run's `StepStatus` value, which writes the
        flattened final state, flagged, into y. sizes: (nq, nv, na, nd) of the flattening;
        low, high: the configuration limits; drive_q, windup: each drive's coordinate and the
        lead of its reference that winds it up. Nothing else crosses into Python per call."""
        if self.model is None:
            raise ValueError("the geometric rung has no dynamics to roll out; use valid()")
        c = compiled(scenario)
        self._compile_ahead(c, self.initial_state(scenario), h)
        sizes = np.array(sizes, dtype=np.int64)
        low, high, windup = (np.ascontiguousarray(a, dtype=float) for a in (low, high, windup))
        drive_q, h = np.ascontiguousarray(drive_q, dtype=np.int64), float(h)

        scene = c.scene
        if c.scripted:
            # the kernel moves scripted obstacles in the pose tables: this propagator's own copy,
            # bound once (`bind`: about 0.1 ms, where a call unboxes it in about 10 us); every
            # call places the obstacles at its start time (t0 = 0) before reading them, so
            # what one call left there does not reach the next. One planner's propagator, not
            # shared between threads.
            scene = own_poses(scene)
        bound = bind((scene, c.drives, self.model, self.solver, c.goal, c.unsafe, sizes, low, high, drive_q, windup, _no_basis()))

        def propagate(x: np.ndarray, u: np.ndarray, duration: float, y: np.ndarray) -> int:
            return propagate_kernel(bound, x, u, duration, h, y)

        return propagate

    def _compile_ahead(self, c, state: State, h: float) -> None:
        """On a first run (numba's cache cold), the general contact step compiled in a helper
        process beside this one's compile of the rollout kernel (`compile_ahead`)."""

        def types():
            arrays = (state.q, state.nu, state.q_ref, state.delta_n, state.delta_t)
            return general_step_types(c.scene, c.drives, self.model, self.solver, *(np.array(a, dtype=float) for a in arrays), float(h))

        compile_ahead(dynamics_step, types)

    def _run(self, scenario, state, controls, durations, h, record_every, max_records, stop_at_outcome, t0, laws=False):
        """The compiled rollout on contiguous float arrays (the kernel works on copies of the
        state's arrays); its raw `models.rollout.RolloutOutput`'s fields, in their order (a plain
        tuple from `rollout_bound`, the named tuple itself where the scene is scripted)."""
        if self.model is None:
            raise ValueError("the geometric rung has no dynamics to roll out; use valid()")
        c = compiled(scenario)
        check_state(scenario, c, state)
        self._compile_ahead(c, state, h)
        drives = c.policy_drives if laws else c.drives
        state_args = (state.q.copy(), state.nu.copy(), state.q_ref.copy(), state.delta_n.copy(), state.delta_t.copy(), _basis_of(state))
        run_args = (controls, durations, float(h), int(record_every), int(max_records), bool(stop_at_outcome), float(t0))
        if c.scripted:  # the kernel moves scripted obstacles in the pose tables: its own copy, every call
            return rollout_kernel(own_poses(c.scene), drives, self.model, self.solver, c.goal, c.unsafe, *state_args, *run_args)
        return rollout_bound(self._bound(c, laws), *state_args, *run_args)

    def _bound(self, c, laws: bool):
        """The scene bound once in a typed List (`bind`, about 0.1 ms) and kept with the compiled
        scenario `c`: one pointer crosses into the kernel per call, not the scene's 30-odd arrays
        one by one (laws: with the policy's drives). A scene with scripted obstacles, whose pose
        tables the kernel writes, is bound anew with tables of its own (`own_poses`), not kept."""
        drives = c.policy_drives if laws else c.drives
        if c.scripted:
            return bind((own_poses(c.scene), drives, self.model, self.solver, c.goal, c.unsafe))
        key = (self.model, self.solver, laws)
        bound = c.bound.get(key)
        if bound is None:
            bound = c.bound[key] = bind((c.scene, drives, self.model, self.solver, c.goal, c.unsafe))
        return bound

    def rollout_chunked(
        self,
        scenario: Scenario,
        state: State,
        controls: np.ndarray,
        durations: np.ndarray,
        h: float,
        *,
        max_records: int = DEFAULT_RECORDS,
        chunk_s: float = 0.25,
        first_chunk: int = 2000,
        progress=None,
        t0: float = 0.0,
        laws: bool = False,
    ) -> RolloutResult:
        """`rollout` (stopping at an outcome) in compiled calls of about `chunk_s` seconds of
        wall time each, so that a long run can report progress and be stopped between them:
        progress(steps_done, steps_total, wall_s) is called after every chunk and may raise
        (KeyboardInterrupt) to stop the run. The result equals the one-call rollout's, bit for
        bit, whatever the machine's speed: chunks end on recorded steps; with PGS or auto, whose
        warm starts (PGS's impulses, auto's switch to Lemke) a call starts without, also on
        steps where the model drops them anyway (a warm period's first, `_chunk_ends`; Lemke's
        basis crosses calls in the State); an outcome that only the end-of-call classification
        of a chunk found is left to the next chunk's first step (as one call would do), and the
        records are joined and capped as one call's. t0: as in `rollout` (each chunk starts
        where the time has got to, so scripted obstacles move on)."""
        controls, durations = run_arrays(scenario, controls, durations)
        check_run(durations, h)
        per_control = control_steps(durations, h)
        total = sum(per_control)
        record_every = record_spacing(int(np.round(durations.sum() / h)), max_records)
        cold_starts = self.model is not None and self.solver.method != SOLVER_LEMKE
        warm_every = warm_period_steps(self.model.warm_period, h) if cold_starts else 0
        first_end, every = _chunk_ends(record_every, warm_every, int(np.round(t0 / h)))
        results: list[RolloutResult] = []
        k, used, done, wall = 0, 0, 0, 0.0  # control index, its steps taken, steps taken
        target = _chunk_length(done, first_chunk, first_end, every)
        while True:
            # the next chunk: `target` steps (to a chunk end, `_chunk_ends`) over the controls left
            chunk_u, chunk_d, n = [], [], 0
            while k < len(per_control) and n < target:
                take = min(per_control[k] - used, target - n)
                if take > 0:
                    chunk_u.append(controls[k])
                    chunk_d.append(take * h)
                    n += take
                used += take
                if used >= per_control[k]:
                    k, used = k + 1, 0
            last = done + n >= total
            if not chunk_d:  # nothing (left) to step: one call classifies the state
                chunk_u, chunk_d = [controls[min(k, len(controls) - 1)]], [0.0]
            out = self.rollout(
                scenario,
                state,
                np.array(chunk_u),
                np.array(chunk_d),
                h,
                record_every=record_every,
                max_records=n // record_every + 3,
                stop_at_outcome=True,
                t0=t0 + done * h,
                laws=laws,
            )
            results.append(out)
            done += out.steps
            wall += out.wall_s
            state = out.state
            if progress is not None:
                progress(done, total, wall)
            # a chunk that ran all its steps met no outcome along them; one it reports came from
            # the classification at the end of the call, which one long call does at the next step
            stopped = out.steps < n or not out.ok
            if last or stopped:
                break
            rate = out.steps / max(out.wall_s, 1e-6)
            target = _chunk_length(done, int(rate * chunk_s), first_end, every)
        return _joined(results, max_records)

    def step(self, scenario: Scenario, state: State, control: np.ndarray, h: float) -> RolloutResult:
        """One step of length h under a commanded speed per actuated coordinate."""
        return self.rollout(scenario, state, np.reshape(control, (1, -1)), [h], h, record_every=1, max_records=2)

    def valid(self, scenario: Scenario, q: np.ndarray, tolerance: float = GEOMETRIC_TOLERANCE) -> bool:
        """Eq. (9): no pair penetrates by more than tolerance."""
        placements = scenario.placements(q)
        for pair in scenario.pairs:
            psi = geo.signed_distance(
                scenario.geometries[pair.body_a], placements[pair.body_a], scenario.geometries[pair.body_b], placements[pair.body_b]
            )
            if psi < -tolerance:
                return False
        return True


def record_spacing(steps: int, max_records: int) -> int:
    """Every how many steps a run of `steps` records its state, so that its records (the start,
    every record_every-th step and the last state) fit in max_records and reach its end: the
    quotient rounded up (rounded down, a run of 3,000 steps had recorded its first 1,998 and
    then jumped to its last)."""
    return max(1, -(-steps // max(max_records - 2, 1)))


def _chunk_ends(record_every: int, warm_every: int, first_step: int) -> tuple[int, int]:
    """Where `Rung.rollout_chunked` may end a chunk, in steps from its start: the first such
    step and their spacing. A recorded step (a multiple of record_every); where warm_every > 0,
    also one that starts a warm period (its index from t = 0, first_step + steps, a multiple of
    warm_every: the rollout drops its warm starts there, so a new call starting there takes the
    same steps), if any recorded step does (else recorded steps only)."""
    if warm_every > 0:
        every = math.lcm(record_every, warm_every)
        for first in range(record_every, every + 1, record_every):
            if (first_step + first) % warm_every == 0:
                return first, every
    return record_every, record_every


def _chunk_length(done: int, wanted: int, first_end: int, every: int) -> int:
    """The steps of the chunk after `done` steps (0 or a chunk end, `_chunk_ends`): to the last
    chunk end at most `wanted` steps on, or the next one if none is."""
    end = first_end if done < first_end else done + every
    if done + wanted > end:
        end += (done + wanted - end) // every * every
    return end - done


def _joined(results: list[RolloutResult], max_records: int) -> RolloutResult:
    """Consecutive chunks of one rollout as one result (see Rung.rollout_chunked)."""
    last = results[-1]
    if len(results) == 1:
        return last
    offsets = np.cumsum([0.0] + [r.t for r in results[:-1]])
    times = np.concatenate([results[0].times] + [r.times[1:] + o for r, o in zip(results[1:], offsets[1:])])
    trajectory = np.concatenate([results[0].trajectory] + [r.trajectory[1:] for r in results[1:]])
    velocities = np.concatenate([results[0].velocities] + [r.velocities[1:] for r in results[1:]])
    if len(times) > max_records:  # one call keeps max_records - 1 records and the last state
        keep = list(range(max_records - 1)) + [len(times) - 1]
        times, trajectory, velocities = times[keep], trajectory[keep], velocities[keep]
    stepped = [r for r in results if r.steps > 0]
    return replace(
        last,
        t=float(offsets[-1] + last.t),
        steps=sum(r.steps for r in results),
        lcp_solves=sum(r.lcp_solves for r in results),
        pivots=sum(r.pivots for r in results),
        max_residual=max(r.max_residual for r in results),
        max_lcp_size=max(r.max_lcp_size for r in results),
        wall_s=sum(r.wall_s for r in results),
        times=times,
        trajectory=trajectory,
        velocities=velocities,
        pair_force=(stepped[-1] if stepped else last).pair_force,
        pair_wrench=(stepped[-1] if stepped else last).pair_wrench,
        min_psi=min(r.min_psi for r in results),
        force_steps=sum(r.force_steps for r in results),
        sweeps=sum(r.sweeps for r in results),
    )


RUNGS: dict[str, Rung] = {
    rung.name: Rung(rung.name, None if rung.physics is None else Model(*rung.physics), rung.description) for rung in FAMILY
}


@numba.njit(cache=True)
def _geometric_check(S, op, index, lo, hi, q, low, high, tolerance, psi, stack, buffers):
    """1 if q is in bounds, penetrates nowhere by more than tolerance and is not unsafe; 0 if
    not; -1 if some pair needs python-fcl to measure. buffers: `pair_distance_buffers`.

    Pairs are measured within CONTACT_MARGIN, as a rollout's detection measures them: a pair
    farther apart is culled by the broadphase and reads more than the margin (inf, or its
    distance where the narrowphase ran), which decides the check as its exact distance would
    (it penetrates nowhere, and no touch tolerance exceeds the margin: `_check_touch_tolerance`).
    Pairs within it read the same bits as measured at any margin. 1.6 -> 0.9 us a state on
    two_finger_triangle, 3.6 -> 0.75 on box_push_3d (states the planner checks, measured)."""
    for i in range(q.shape[0]):
        if q[i] < low[i] or q[i] > high[i]:
            return 0
    pair_min_distances_into(S, q, CONTACT_MARGIN, psi, buffers)
    for p in range(psi.shape[0]):
        if np.isnan(psi[p]):
            return -1
        if psi[p] < -tolerance:
            return 0
    return 0 if evaluate_with(op, index, lo, hi, q, psi, stack) else 1


@numba.njit(cache=True)
def _geometric_check_bound(bound, q):
    """`_geometric_check` on what `GeometricChecker` bound once (`models.rollout.bind`): one
    typed List crosses into the kernel per check, where the scene's 30-odd arrays were unboxed
    one by one (about 4 us of a check's 9-14, measured; the check's own work is 3.4 us on
    two_finger_triangle, 8 on box_push_3d)."""
    S, op, index, lo, hi, low, high, tolerance, psi, stack, buffers = bound[0]
    return _geometric_check(S, op, index, lo, hi, q, low, high, tolerance, psi, stack, buffers)


@numba.njit(cache=True)
def _geometric_motion_bound(bound, x, steered, a, b, nd, trace):
    """OMPL's discrete motion check (`ompl::base::DiscreteMotionValidator::checkMotion(s1, s2)`)
    from a to b over the coordinates `steered` of x (the others as x holds them), in one
    compiled call: b first, then the nd - 1 states a + (b - a) * (j / nd) in OMPL's order (the
    middle of each interval, its halves queued), stopping at the first that `_geometric_check`
    does not pass. The same states, in the same order, with the same arithmetic as OMPL's
    interpolation, so the same answer and the same count. Returns (1 valid, 0 not, -1 a pair
    needs python-fcl; the states checked). trace (k, nq): the states checked are written into
    its rows while they fit (tests; a (0, nq) array for none). x is scratch."""
    S, op, index, lo, hi, low, high, tolerance, psi, stack, buffers = bound[0]
    for k in range(steered.shape[0]):
        x[steered[k]] = b[k]
    checks = 1
    if trace.shape[0] > 0:
        trace[0, :] = x
    r = _geometric_check(S, op, index, lo, hi, x, low, high, tolerance, psi, stack, buffers)
    if r != 1 or nd < 2:
        return r, checks
    queue = np.empty((nd, 2), np.int64)  # each interval queued once, each holds a state: at most nd - 1
    queue[0, 0], queue[0, 1] = 1, nd - 1
    head, tail = 0, 1
    while head < tail:
        first, second = queue[head, 0], queue[head, 1]
        mid = (first + second) // 2
        t = mid / nd
        for k in range(steered.shape[0]):
            x[steered[k]] = a[k] + (b[k] - a[k]) * t
        if checks < trace.shape[0]:
            trace[checks, :] = x
        checks += 1
        r = _geometric_check(S, op, index, lo, hi, x, low, high, tolerance, psi, stack, buffers)
        if r != 1:
            return r, checks
        head += 1
        if first < mid:
            queue[tail, 0], queue[tail, 1] = first, mid - 1
            tail += 1
        if second > mid:
            queue[tail, 0], queue[tail, 1] = mid + 1, second
            tail += 1
    return 1, checks


class GeometricChecker:
    """The geometric rung's validity (bounds, eq. (9) non-penetration, not unsafe), compiled,
    with python-fcl only for the pairs the kernels cannot measure: called with q, a bool;
    `motion` checks a straight motion in one compiled call."""

    def __init__(self, scenario: Scenario, low: np.ndarray, high: np.ndarray, tolerance: float = GEOMETRIC_TOLERANCE) -> None:
        c = compiled(scenario)
        unsafe = c.unsafe
        psi = np.empty(max(c.scene.pi.shape[0], 1))
        stack = np.zeros(unsafe.op.shape[0] + 1, np.bool_)
        low, high = np.ascontiguousarray(low, float), np.ascontiguousarray(high, float)
        buffers = pair_distance_buffers(c.scene)
        self.scenario, self.tolerance = scenario, float(tolerance)
        self.bound = bind((c.scene, unsafe.op, unsafe.index, unsafe.lo, unsafe.hi, low, high, self.tolerance, psi, stack, buffers))
        self._no_trace = np.zeros((0, len(scenario.start)))

    def __call__(self, q: np.ndarray) -> bool:
        ok = _geometric_check_bound(self.bound, q)
        if ok >= 0:
            return ok == 1
        from models.task import Outcome, classify

        d = pair_signed_distances(self.scenario, q)
        if np.any(d < -self.tolerance):
            return False
        return classify(self.scenario, q, d) is not Outcome.UNSAFE

    def motion(self, x: np.ndarray, steered: np.ndarray, a: np.ndarray, b: np.ndarray, nd: int, trace=None) -> tuple[int, int]:
        """`_geometric_motion_bound`: (1 valid, 0 not, -1 a pair needs python-fcl: ask the
        states one by one; the states checked). x: the full configuration, scratch (float,
        contiguous); steered (int64): the coordinates a and b move; nd: OMPL's segment count."""
        return _geometric_motion_bound(self.bound, x, steered, a, b, int(nd), self._no_trace if trace is None else trace)


def _check_configurations(scenario: Scenario, shape: tuple, ndim: int) -> None:
    """ValueError where an array of configurations (ndim 1: one; 2: one per row) does not have the
    scenario's coordinates (the kernels read it unchecked)."""
    if len(shape) != ndim or shape[-1] != len(scenario.coordinates):
        what = "a configuration" if ndim == 1 else "configurations, one per row,"
        raise ValueError(
            f"expected {what} of {len(scenario.coordinates)} coordinates of {scenario.path.name}, got an array of shape {shape}"
        )


def pair_signed_distances(scenario: Scenario, q: np.ndarray) -> np.ndarray:
    """Every contact pair's signed distance at q, m (negative: penetration depth), in
    `scenario.pairs` order: the compiled kernels, the reference geometry (`models.geometry`,
    python-fcl) only for the pairs they cannot measure (inert pairs read inf)."""
    n = len(scenario.pairs)
    out = np.empty(max(n, 1))
    q = kernel_array(q)
    _check_configurations(scenario, q.shape, 1)
    _pair_distances_bound(compiled(scenario).scene_bound, q, out)
    if np.isnan(out[:n]).any():
        _measure_missing(scenario, q, out[:n])
    return out[:n]


def pair_signed_distances_many(scenario: Scenario, Q: np.ndarray) -> np.ndarray:
    """`pair_signed_distances` at each row of Q (k, nq), in one compiled call: (k, n_pairs), each
    row the same numbers as one call at that q gives (the goal sampler's finite differences)."""
    n = len(scenario.pairs)
    Q = kernel_array(np.atleast_2d(Q))
    _check_configurations(scenario, Q.shape, 2)
    out = np.empty((len(Q), max(n, 1)))
    _pair_distances_many_bound(compiled(scenario).scene_bound, Q, out)
    if np.isnan(out[:, :n]).any():
        for k in range(len(Q)):
            _measure_missing(scenario, Q[k], out[k, :n])
    return out[:, :n]


def _measure_missing(scenario: Scenario, q: np.ndarray, d: np.ndarray) -> None:
    """d's NaN entries (the pairs the compiled kernels cannot measure) measured by the reference
    geometry at q, in place."""
    missing = np.flatnonzero(np.isnan(d))
    if len(missing):
        placements = scenario.placements(q)
        for k in missing:
            pair = scenario.pairs[k]
            d[k] = geo.signed_distance(
                scenario.geometries[pair.body_a], placements[pair.body_a], scenario.geometries[pair.body_b], placements[pair.body_b]
            )


@numba.njit(cache=True)
def _pair_distances_bound(bound, q, out):
    """`pair_min_distances` (margin 1e9) on the scene bound alone (`Compiled.scene_bound`): one
    typed List crosses into the kernel, not the scene's 30-odd arrays one by one (about 4 us of
    `pair_signed_distances`' 13, measured; the goal sampler calls it thousands of times a plan)."""
    pair_min_distances(bound[0][0], q, 1e9, out)


@numba.njit(cache=True)
def _pair_distances_many_bound(bound, Q, out):
    """`_pair_distances_bound` at each row of Q into the same row of out, on one set of buffers."""
    S = bound[0][0]
    buffers = pair_distance_buffers(S)
    for k in range(Q.shape[0]):
        pair_min_distances_into(S, Q[k], 1e9, out[k], buffers)


@numba.njit(cache=True)
def _projection_terms_bound(bound, q, movable, pairs, targets, step, r, J):
    """One Gauss-Newton iteration's terms of the goal sampler's projection
    (`planner.ompl_adapter.GoalSampler`) at q, on the scene bound alone, in one call: the touch
    pairs' residuals r[k] = d[pairs[k]] - targets[k] and their finite-difference Jacobian
    J[k, j] = (d at q with q[movable[j]] moved by step, less d) / step (C-contiguous, as the
    NumPy terms' J is: the sampler's step J.T @ x then sums in the same order), 0 where either
    distance is not finite; then each residual that is not finite reads 1. The same operations, in the
    same order, as the sampler's own NumPy terms (`pair_signed_distances`,
    `pair_signed_distances_many`), so the same bits. Returns -1 if a touch pair's distance is
    NaN at some state (python-fcl measures it: the caller computes the terms itself), 1 if
    every |r[k]| <= targets[k] (converged: J not computed), else 0."""
    S = bound[0][0]
    buffers = pair_distance_buffers(S)
    n = max(S.pi.shape[0], 1)
    d, de = np.empty(n), np.empty(n)
    pair_min_distances_into(S, q, 1e9, d, buffers)
    converged = True
    for k in range(pairs.shape[0]):
        if np.isnan(d[pairs[k]]):
            return -1
        r[k] = d[pairs[k]] - targets[k]
        converged = converged and abs(r[k]) <= targets[k]
    if converged:
        return 1
    x = np.empty(q.shape[0])
    for j in range(movable.shape[0]):
        x[:] = q
        x[movable[j]] += step
        pair_min_distances_into(S, x, 1e9, de, buffers)
        for k in range(pairs.shape[0]):
            a, b = de[pairs[k]], d[pairs[k]]
            if np.isnan(a):
                return -1
            J[k, j] = (a - b) / step if np.isfinite(a) and np.isfinite(b) else 0.0
    for k in range(pairs.shape[0]):
        if not np.isfinite(r[k]):
            r[k] = 1.0
    return 0


def projection_terms(scenario: Scenario, q: np.ndarray, movable: np.ndarray, pairs: np.ndarray, targets: np.ndarray, step: float, r, J):
    """`_projection_terms_bound` on the compiled scenario (r, J: the caller's, written)."""
    return _projection_terms_bound(compiled(scenario).scene_bound, kernel_array(q), movable, pairs, targets, float(step), r, J)


def pgs_rung(rung: Rung, exact_cone: bool = False) -> Rung:
    """The rung with its contacts solved by PGS: in space on the exact circular Coulomb cone
    where exact_cone (`models.stepper.Model.exact_cone`: Lemke's LCP is the polygon's only),
    else on the rung's polygon of friction directions."""
    return replace(rung, solver=contact_solver("pgs"), model=rung.model._replace(exact_cone=exact_cone))


def rung_for(scenario: Scenario, name: str) -> Rung:
    """The registry's rung with the scenario's settings for it (`Scenario.rung_settings`:
    theta, friction directions, contact solver; its control period drops Lemke's warm start,
    `models.stepper.Model.warm_period`)."""
    rung = RUNGS[name]
    if rung.model is None:
        return rung
    settings = scenario.rung_settings(name)
    model = rung.model._replace(
        theta=settings.theta,
        friction_directions=settings.friction_directions,
        warm_period=settings.control_period,
        exact_cone=settings.friction_cone == "exact",
        regularization=settings.regularization,
    )
    if settings.inertia is not None and model.eps == 0.0:
        model = model._replace(quasistatic_inertia=settings.inertia)
    return replace(rung, model=model, solver=contact_solver(settings.contact_solver))


#: The share of a body's weight a quasistatic run may leave unbalanced before `unbalanced_motion`
#: looks at it (a compliant contact's settling step leaves about 1e-6 of it).
UNBALANCED_SHARE = 1e-4
#: How much faster than anything driving the run (`_driven_speed`) a body must move for
#: `unbalanced_motion` and `thrown_motion` to say nothing pushed it there (a wedge or a lever drives a body a few times
#: faster than its pusher).
DRIVEN_RATIO = 100.0


@dataclass(frozen=True)
class Unbalanced:
    """A body a quasistatic run moved without equilibrium (`unbalanced_motion`)."""

    body: str
    share: float  # the largest unbalanced force met, as a share of the body's weight (a lower bound)
    speed: float  # the speed that moved it at, m/s (a rotation counted at the radius of gyration)
    driven: float  # the fastest driven speed in the run (`_driven_speed`), m/s (rad/s)


def _peak_speed(scenario: Scenario, result: RolloutResult, velocities: list[int], gyration: float | None = None) -> float:
    """The largest speed met in a run: of any one of the velocity coordinates `velocities`
    (gyration None), or of one body whose velocity coordinates they are (its translation's
    speed, with its rotation counted at the radius of gyration sqrt(gyration)). Met at the
    recorded steps and, as average speeds, over the intervals between records (of the
    coordinates that are positions too: translations, a planar or yaw angle), which are no
    more than the largest step's: what is returned was met."""
    body = gyration is not None
    turning = [i for i in velocities if body and scenario.velocities[i].rpartition(".")[2] not in TRANSLATIONAL_DOFS]
    moving = [i for i in velocities if i not in turning]
    nu = result.velocities
    if body:
        peak = np.max(np.sqrt(np.sum(nu[:, moving] ** 2, axis=1) + gyration * np.sum(nu[:, turning] ** 2, axis=1)), initial=0.0)
    else:
        peak = np.max(np.abs(nu[:, velocities]), initial=0.0)
    dt = np.diff(result.times)
    apart = dt > 0.0
    positions = [scenario.coordinates.index(scenario.velocities[i]) for i in moving if scenario.velocities[i] in scenario.coordinates]
    if positions and np.any(apart):
        rate = np.diff(result.trajectory[:, positions], axis=0)[apart] / dt[apart][:, None]
        peak = max(peak, np.max(np.linalg.norm(rate, axis=1)) if body else np.max(np.abs(rate)))
    return float(peak)


def _driven_speed(scenario: Scenario, result: RolloutResult) -> float:
    """The fastest anything drove a run: an actuated coordinate (`_peak_speed`) or an obstacle
    on its script (m/s, rad/s)."""
    scripted = [abs(float(v)) for body in scenario.spec.bodies if body.role == "obstacle" for v in body.velocity.values()]
    return max([_peak_speed(scenario, result, [scenario.velocities.index(n) for n in scenario.actuated]), *scripted])


def _passive_speeds(scenario: Scenario, result: RolloutResult):
    """(body, its peak speed in the run: `_peak_speed`) for each body with passive DOFs and a mass."""
    for body in scenario.spec.bodies:
        prefix = body.name + "."
        passive = [i for i, n in enumerate(scenario.velocities) if n.startswith(prefix) and n not in scenario.actuated]
        if not passive or not body.mass:
            continue
        turns = any(scenario.velocities[i].rpartition(".")[2] not in TRANSLATIONAL_DOFS for i in passive)
        gyration = min(principal_inertia(body)[0]) / body.mass if turns and body.inertia else 0.0
        yield body, _peak_speed(scenario, result, passive, gyration)


def unbalanced_motion(scenario: Scenario, rung: Rung, h: float, result: RolloutResult) -> Unbalanced | None:
    """The passive body a quasistatic run moved most out of equilibrium, where nothing drove it:
    it left more than UNBALANCED_SHARE of its weight unbalanced and moved DRIVEN_RATIO times faster
    than anything drove the run, an actuated coordinate or a scripted obstacle (`_driven_speed`;
    None otherwise, and for the other rungs).

    The quasistatic step is memoryless: eps M nu = h (forces), with eps the rung's inertia scale.
    A body the contacts hold in equilibrium moves as the bodies pushing it do; a body nothing
    balances (a block on a frictionless incline, a disc dropped through the air) moves at
    h F / (eps m), as fast as eps is small: its motion is the regularization's, not physics'. The
    unbalanced force of a step is eps m v / h for a speed v (|v|^2 plus the least principal
    inertia over m times |omega|^2, for a rotation), at most the force itself where a contact cut
    the step short. Speeds are measured as `_peak_speed` measures them. Only where the run
    outruns what the force would do to the real body, eps * steps < 1 (the default scale, 1e-6,
    not a quasi-dynamic rung's full inertia), and only with gravity (the weight is the scale)."""
    model = rung.model
    if model is None or model.kinematic or model.eps != 0.0:
        return None
    eps, g, steps = model.quasistatic_inertia, float(np.linalg.norm(scenario.spec.scene.gravity)), result.steps
    if g == 0.0 or steps == 0 or eps * steps >= 1.0 or len(result.times) == 0:
        return None
    driven = _driven_speed(scenario, result)
    worst = None
    for body, speed in _passive_speeds(scenario, result):
        share = eps * speed / (h * g)
        if share > UNBALANCED_SHARE and speed > DRIVEN_RATIO * driven and (worst is None or share > worst.share):
            worst = Unbalanced(body.name, share, speed, driven)
    return worst


@dataclass(frozen=True)
class Thrown:
    """A body a kinematic run moved far faster than anything drove it (`thrown_motion`)."""

    body: str
    speed: float  # its peak speed, m/s (a rotation counted at the radius of gyration)
    driven: float  # the fastest driven speed in the run (`_driven_speed`), m/s (rad/s)


def thrown_motion(scenario: Scenario, rung: Rung, h: float, result: RolloutResult) -> Thrown | None:
    """The passive body a kinematic run moved fastest, where it moved DRIVEN_RATIO times faster
    than anything drove it (None otherwise, and for the other rungs).

    The kinematic step (eq. 8) has no forces, friction or inertia: a body moves only as much as
    keeps the contacts apart, at the least kinetic energy. Pushed along a contact normal almost
    across the push (a finger pressing a block into the table at a corner, a wedge at a grazing
    angle), that least motion is the push's speed over the tangent of the angle, without bound: a
    jam that friction and the drives' force limits would hold becomes a body shot out at tens of
    m/s. A lever or a wedge drives a body a few times faster than its pusher; DRIVEN_RATIO times is
    a contact within about half a degree of the push's normal plane. Speeds are measured as
    `_peak_speed` measures them; nothing driving (the passive bodies only pushed out of an initial
    penetration) says nothing."""
    model = rung.model
    if model is None or not model.kinematic or result.steps == 0 or len(result.times) == 0:
        return None
    driven = _driven_speed(scenario, result)
    if driven == 0.0:
        return None
    worst = None
    for body, speed in _passive_speeds(scenario, result):
        if speed > DRIVEN_RATIO * driven and (worst is None or speed > worst.speed):
            worst = Thrown(body.name, speed, driven)
    return worst


def thrown_warning(scenario: Scenario, rung: Rung, h: float, result: RolloutResult) -> str:
    """What `thrown_motion` says, in words ("" where it finds nothing)."""
    found = thrown_motion(scenario, rung, h, result)
    if found is None:
        return ""
    return (
        f"{found.body} was thrown: kinematic steps moved it at up to {found.speed:.3g} m/s, "
        f"{found.speed / found.driven:,.0f} times the fastest anything drove it, {found.driven:.3g} m/s or rad/s "
        "(an actuated coordinate's speed in the run, or a scripted obstacle's); "
        "the kinematic model has "
        f"no forces or friction, and moves a body at whatever speed keeps the contacts apart, without bound where the push "
        f"runs along a contact normal almost across it (a pinch or a grazing wedge, which friction would jam): "
        f"{found.body}'s motion is not physical (a quasistatic or dynamic rung models the forces)"
    )


def unbalanced_warning(scenario: Scenario, rung: Rung, h: float, result: RolloutResult) -> str:
    """What `unbalanced_motion` says, in words ("" where it finds nothing)."""
    found = unbalanced_motion(scenario, rung, h, result)
    if found is None:
        return ""
    driven = (
        f"{found.speed / found.driven:,.0f} times the fastest anything drove it, {found.driven:.3g} m/s or rad/s"
        if found.driven > 0.0
        else "with nothing actuated or scripted moving"
    )
    return (
        f"{found.body} was not held in equilibrium: quasistatic steps moved it at up to {found.speed:.3g} m/s ({driven}), "
        f"which leaves at least {100 * found.share:.3g}% of its weight unbalanced (inertia scale {rung.model.quasistatic_inertia:g} "
        f"x mass x speed / step {h:g} s); the quasistatic model does not say how fast an unbalanced body moves: "
        f"{found.body}'s motion is not physical (a dynamic rung models it)"
    )


def penetrating_pair(scenario: Scenario, result: RolloutResult) -> int | None:
    """The contact pair (its index in `scenario.pairs`) of a run's largest penetration, where a
    recorded state shows it (to 1% of its depth); None where none does (a sweep keeps two
    states; the step of the largest may go unrecorded) or obstacles move on a script (the
    recorded q does not place them)."""
    depth = result.max_penetration
    if not depth > 0.0 or not scenario.pairs or not len(result.trajectory) or compiled(scenario).scripted:
        return None
    psi = pair_signed_distances_many(scenario, result.trajectory)
    record, pair = np.unravel_index(np.argmin(psi), psi.shape)
    return int(pair) if -psi[record, pair] >= 0.99 * depth else None


def run_warnings(scenario: Scenario, rung: Rung, h: float, result: RolloutResult) -> list[str]:
    """What a rollout's result says beside its status (a solver can solve every step of a run
    that is not physical): the bodies passed through each other (`models.scenario.penetration_warning`,
    of the pair that penetrated where the records show it: `penetrating_pair`), a quasistatic run
    moved a body nothing held or drove (`unbalanced_warning`), a kinematic run threw a body far
    faster than anything drove it (`thrown_warning`)."""
    deep = penetration_warning(scenario, result.max_penetration)
    if deep:  # (the pair, only where the thinnest of all is passed)
        deep = penetration_warning(scenario, result.max_penetration, penetrating_pair(scenario, result))
    return [w for w in (deep, unbalanced_warning(scenario, rung, h, result), thrown_warning(scenario, rung, h, result)) if w]

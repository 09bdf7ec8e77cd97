"""The scenario file format: frozen, validated pydantic models (one class per TOML table).

This module says *what a scenario file may contain*; `models.scenario` reads a file,
resolves parameter references, runs the checks that span several tables (names, DOFs,
geometry, initial penetration) and reports every problem with the file and the key path.

Numbers: every numeric field accepts a number or a string naming a design parameter, or a
small expression over parameters (``"-v1"``, ``"2 * r"``; see `models.expressions`). The
parameters come from the validation context (``context={"parameters": {...}}``).
Non-finite numbers (TOML's ``inf``/``nan``) are rejected everywhere, and every number must
lie within the bound of its quantity class (`LIMITS`: lengths and coordinates within 1e6 m,
masses, inertias, gains, speeds, times), so nothing derived from it overflows. Booleans are
TOML booleans only (no ``"no"``, no ``0``) and integers are never booleans.

Units are SI (m, kg, s, rad, N); angles in radians unless a key says ``_deg``.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationInfo,
    WithJsonSchema,
)
from pydantic import Strict as StrictMode
from pydantic_core import PydanticCustomError

from models.expressions import ExpressionError, evaluate
from models.family import PROPAGATING_RUNGS, RUNG_NAMES
from models.task import OUTCOME_LABELS

#: Contact solvers a rung may name (models.stepper.SOLVER_METHODS).
CONTACT_SOLVERS: tuple[str, ...] = ("lemke", "pgs", "auto")
#: OMPL planners of the geometric rung (the first is its default) and of the rungs that
#: propagate (control planning); a rung may name any of PLANNERS, checked per rung on load.
#: Not geometric: EST (OMPL's Python bindings have no geometric EST) and PRM (its roadmap
#: thread calls the Python validity checker while the planner's caller holds the GIL: it hangs).
GEOMETRIC_PLANNERS: tuple[str, ...] = ("RRTConnect", "RRT", "RRTstar", "KPIECE1")
CONTROL_PLANNERS: tuple[str, ...] = ("RRT", "KPIECE1", "EST")
PLANNERS: tuple[str, ...] = tuple(dict.fromkeys(GEOMETRIC_PLANNERS + CONTROL_PLANNERS))
#: Free DOF names per scene dimension, in the canonical order coordinates are stacked.
DOF_NAMES: dict[int, tuple[str, ...]] = {2: ("x", "y", "theta"), 3: ("x", "y", "z", "yaw", "rotation")}
SHAPES_2D = ("halfplane", "disc", "box", "polygon", "capsule")
SHAPES_3D = ("plane", "sphere", "box", "capsule", "mesh")

IDENTIFIER = r"^[A-Za-z_][A-Za-z0-9_]*$"
#: Deepest nesting of predicates (all / any / not inside each other).
MAX_PREDICATE_DEPTH = 32


class Limit:
    """The range of one quantity class: |value| <= high, and for quantities that get
    inverted (masses, inertias) or counted in steps (times) value >= low. Keeps every derived
    quantity finite. Its message names the bound a value passed (a positive quantity's type
    refuses <= 0 before: "between -1e12 and 1e12" would mislead)."""

    def __init__(self, what: str, unit: str, high: float, low: float | None = None):
        self.what, self.unit, self.high, self.low = what, unit, high, low

    def __call__(self, value: float) -> float:
        low = -self.high if self.low is None else self.low
        unit = f" {self.unit}" if self.unit else ""
        if value > self.high:
            raise ValueError(f"{value:g} is out of range: {self.what} must be at most {self.high:g}{unit}")
        if not value >= low:  # (nan too)
            raise ValueError(f"{value:g} is out of range: {self.what} must be at least {low:g}{unit}")
        return value


#: Bounds per quantity class (SI units).
LIMITS = {
    "length": Limit("lengths and coordinates", "m (rad for angles)", 1e6),
    "speed": Limit("speeds", "m/s (rad/s)", 1e6),
    "acceleration": Limit("accelerations", "m/s^2", 1e6),
    "mass": Limit("masses", "kg", 1e6, low=1e-6),
    "inertia": Limit("inertias", "kg m^2", 1e6, low=1e-12),
    "inertia_product": Limit("products of inertia", "kg m^2", 1e6),
    "gain": Limit("gains, stiffnesses, dampings and forces", "", 1e12),
    "time": Limit("times", "s", 1e6, low=1e-9),  # (a step below a nanosecond is a typo: 1 s of it overflows a count)
    "ratio": Limit("friction coefficients, scales and quaternion components", "", 1e6),
}
#: Largest planner seed and iteration count (OMPL takes 32-bit seeds).
MAX_SEED = 10**9
MAX_ITERATIONS = 10**9


def _resolve_number(value: Any, info: ValidationInfo) -> Any:
    """Turn a parameter reference into a float; reject booleans and non-finite numbers."""
    if isinstance(value, bool):
        raise ValueError(f"expected a number, got the boolean {str(value).lower()}")
    if isinstance(value, str):
        parameters = (info.context or {}).get("parameters", {})
        try:
            return evaluate(value, parameters)
        except ExpressionError as exc:
            raise ValueError(str(exc)) from None
    if isinstance(value, (int, float)) and not math.isfinite(value):
        raise ValueError(f"must be a finite number, got {value}")
    return value


_NUMBER_SCHEMA = {
    "anyOf": [
        {"type": "number"},
        {"type": "string", "description": "a parameter name or an expression over parameters"},
    ]
}


def _plain_number(value: Any) -> Any:
    """A literal number (parameter values themselves may not refer to parameters)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"a parameter value must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"must be a finite number, got {value}")
    return value


def _no_boolean_integer(value: Any) -> Any:
    """Integers are TOML integers (or integral floats); true / false are not integers."""
    if isinstance(value, bool):
        raise PydanticCustomError("int_type", "Input should be a valid integer")
    return value


Num = Annotated[float, BeforeValidator(_resolve_number), WithJsonSchema(_NUMBER_SCHEMA)]
ParameterValue = Annotated[float, BeforeValidator(_plain_number)]
Positive = Annotated[Num, Field(gt=0)]
NonNegative = Annotated[Num, Field(ge=0)]
Bool = Annotated[bool, StrictMode()]


def _int(**constraints: int) -> Any:
    """An integer field with `Field` constraints; never a boolean."""
    return Annotated[int, Field(**constraints), BeforeValidator(_no_boolean_integer)]


def _bounded(base: Any, quantity: str) -> Any:
    return Annotated[base, AfterValidator(LIMITS[quantity])]


Length = _bounded(Num, "length")  # also coordinates and angles
PositiveLength = _bounded(Positive, "length")
Speed = _bounded(Num, "speed")
Acceleration = _bounded(Num, "acceleration")
Mass = _bounded(Positive, "mass")
Gain = _bounded(Positive, "gain")
NonNegativeGain = _bounded(NonNegative, "gain")
Time = _bounded(Positive, "time")
Ratio = _bounded(Num, "ratio")
NonNegativeRatio = _bounded(NonNegative, "ratio")
PositiveRatio = _bounded(Positive, "ratio")
Interval = tuple[Length, Length]
SpeedInterval = tuple[Speed, Speed]


def _as_tuple(value: Any) -> Any:
    return value if isinstance(value, (list, tuple)) else (value,)


#: A scalar, or principal moments; stored as a tuple of 1 or 3 numbers.
Inertia = Annotated[
    tuple[_bounded(Positive, "inertia"), ...],
    BeforeValidator(_as_tuple),
    WithJsonSchema({"anyOf": [_NUMBER_SCHEMA, {"type": "array", "items": _NUMBER_SCHEMA, "minItems": 3, "maxItems": 3}]}),
]
#: A spatial inertia tensor's off-diagonal entries (Ixy, Ixz, Iyz), of either sign.
InertiaProducts = tuple[_bounded(Num, "inertia_product"), _bounded(Num, "inertia_product"), _bounded(Num, "inertia_product")]
Name = Annotated[str, Field(pattern=IDENTIFIER)]


class Strict(BaseModel):
    """Every table is closed (unknown keys are errors) and frozen once validated."""

    model_config = ConfigDict(extra="forbid", frozen=True)


# ----------------------------------------------------------------------------- header, scene


class ScenarioInfo(Strict):
    name: str
    description: str = ""


class SceneSpec(Strict):
    dimension: Literal[2, 3] = Field(description="2: planar bodies (x, y, theta); 3: spatial bodies")
    gravity: tuple[Acceleration, ...] = Field(description="gravity vector, one entry per dimension, m/s^2")


class PairMaterial(Strict):
    """Overrides of the default material for one pair of bodies (or disables the pair)."""

    bodies: tuple[Name, Name]
    mu: NonNegativeRatio | None = None
    K: Gain | None = None
    C: NonNegativeGain | None = None
    enabled: Bool = Field(True, description="false: the two bodies never interact")


class ContactSpec(Strict):
    mu: NonNegativeRatio = Field(description="default friction coefficient")
    K: Gain = Field(description="default contact stiffness, N/m (compliant rungs)")
    C: NonNegativeGain = Field(description="default contact damping, N s/m (compliant rungs)")
    touch_tolerance: PositiveLength = Field(1e-3, description="distance at or below which bodies touch, m")
    pairs: tuple[PairMaterial, ...] = ()


# ----------------------------------------------------------------------------- shapes


class HalfPlane(Strict):
    """Planar half-plane {p : normal . p <= offset} in the body frame (solid below the line)."""

    type: Literal["halfplane"]
    normal: tuple[Length, Length]
    offset: Length = 0.0


class Disc(Strict):
    type: Literal["disc"]
    radius: PositiveLength


class Polygon(Strict):
    """Convex polygon, vertices in the body frame, either winding (stored counter-clockwise)."""

    type: Literal["polygon"]
    vertices: tuple[tuple[Length, Length], ...] = Field(min_length=3)


class Box(Strict):
    """Box centred on the body frame; ``size`` holds full edge lengths (2 or 3 of them)."""

    type: Literal["box"]
    size: tuple[PositiveLength, ...]


class Capsule(Strict):
    """Segment of ``length`` along the body's x axis, centred, swept by a disc/sphere of ``radius``."""

    type: Literal["capsule"]
    radius: PositiveLength
    length: PositiveLength


class Plane(Strict):
    """Spatial half-space {p : normal . p <= offset} in the body frame."""

    type: Literal["plane"]
    normal: tuple[Length, Length, Length]
    offset: Length = 0.0


class Sphere(Strict):
    type: Literal["sphere"]
    radius: PositiveLength


class Mesh(Strict):
    """Convex mesh from a Wavefront OBJ file (path relative to the scenario file)."""

    type: Literal["mesh"]
    file: str
    scale: PositiveRatio = 1.0


Shape = Annotated[
    HalfPlane | Disc | Polygon | Box | Capsule | Plane | Sphere | Mesh,
    Field(discriminator="type"),
]


# ----------------------------------------------------------------------------- bodies


class Pose(Strict):
    """Initial pose. Planar: x, y, theta. Spatial: x, y, z and either quaternion (w, x, y, z)
    or rpy (roll, pitch, yaw, rad). Omitted entries are zero / identity."""

    x: Length = 0.0
    y: Length = 0.0
    z: Length | None = None
    theta: Length | None = None
    quaternion: tuple[Ratio, Ratio, Ratio, Ratio] | None = None
    rpy: tuple[Length, Length, Length] | None = None


class Drive(Strict):
    """Drive of one actuated DOF: the PD (impedance) law that tracks the commanded motion
    in the quasistatic and dynamic rungs, and its limits."""

    kp: Gain = Field(description="position gain, N/m (N m/rad for angles)")
    kd: NonNegativeGain = Field(description="velocity gain, N s/m")
    max_speed: _bounded(Positive, "speed") = Field(
        description="largest speed a planner commands, m/s (rad/s): the default [task] control_bounds; a policy's "
        "speeds are its own (the paper's sweep runs past it)"
    )
    max_force: Gain | None = Field(None, description="actuator force limit, N (none: unlimited)")
    lower: Length | None = Field(None, description="lower position limit")
    upper: Length | None = Field(None, description="upper position limit")


class BodySpec(Strict):
    name: Name
    role: Literal["robot", "object", "obstacle"]
    shape: Shape
    pose: Pose = Pose()
    dofs: tuple[str, ...] = Field((), description="free DOFs, e.g. ['y'] or ['x', 'y', 'theta']")
    mass: Mass | None = Field(None, description="kg; required for a body with free DOFs")
    inertia: Inertia | None = Field(
        None,
        description="rotational inertia about the centre of mass (planar: scalar; spatial: "
        "scalar or three moments about the body's axes: its principal moments, or with inertia_products the "
        "tensor's diagonal Ixx, Iyy, Izz); required when a rotation is free",
    )
    inertia_products: InertiaProducts | None = Field(
        None,
        description="spatial: the inertia tensor's off-diagonal entries (Ixy, Ixz, Iyz), kg m^2, about the centre "
        "of mass in the body's axes, as URDF's ixy, ixz, iyz and MuJoCo's fullinertia give them (Ixy = -sum m x y); "
        "for a body whose principal axes are not its own (a CAD mesh's frame); none: the axes are principal",
    )
    actuators: dict[str, Drive] = Field(default_factory=dict, description="robots only: the drive of each actuated DOF")
    velocity: dict[str, Speed] = Field(
        default_factory=dict,
        description="obstacles only: constant scripted velocity per pose coordinate",
    )


# ----------------------------------------------------------------------------- task


class BoxPredicate(Strict):
    """Every named coordinate lies in its closed interval."""

    box: dict[str, Interval]


class TouchPredicate(Strict):
    """The two bodies are within ``tol`` of each other (signed distance <= tol)."""

    touch: tuple[Name, Name]
    tol: PositiveLength | None = Field(None, description="defaults to contact.touch_tolerance")


class AllPredicate(Strict):
    all: tuple[Predicate, ...] = Field(min_length=1)


class AnyPredicate(Strict):
    any: tuple[Predicate, ...] = Field(min_length=1)


class NotPredicate(Strict):
    not_: Predicate = Field(alias="not")
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)


PREDICATE_KEYS = ("box", "touch", "all", "any", "not")


def _predicate_tag(value: Any) -> str | None:
    if isinstance(value, BaseModel):
        return {
            BoxPredicate: "box",
            TouchPredicate: "touch",
            AllPredicate: "all",
            AnyPredicate: "any",
            NotPredicate: "not",
        }[type(value)]
    if isinstance(value, dict):
        for key in PREDICATE_KEYS:
            if key in value:
                return key
    return None


_COUNT_WORDS = {2: "two", 3: "three", 4: "four", 5: "five"}


def _one_predicate_key(value: Any) -> Any:
    """A predicate table names exactly one kind; say so before the union picks a member."""
    if isinstance(value, BaseModel):
        return value
    if not isinstance(value, dict):
        got = f"a list of {len(value)} {'entry' if len(value) == 1 else 'entries'}" if isinstance(value, list) else repr(value)
    else:
        keys = [k for k in PREDICATE_KEYS if k in value]
        if len(keys) == 1:
            return value
        if keys:
            got = f"{_COUNT_WORDS.get(len(keys), len(keys))}: {', '.join(keys)}"
        else:
            got = f"none (keys: {', '.join(map(str, value))})" if value else "an empty table"
    raise PydanticCustomError(
        "predicate",
        "a predicate is a table with exactly one of the keys box, touch, all, any, not; got {got}",
        {"got": got},
    )


Predicate = Annotated[
    Annotated[BoxPredicate, Tag("box")]
    | Annotated[TouchPredicate, Tag("touch")]
    | Annotated[AllPredicate, Tag("all")]
    | Annotated[AnyPredicate, Tag("any")]
    | Annotated[NotPredicate, Tag("not")],
    Discriminator(
        _predicate_tag,
        custom_error_type="predicate",
        custom_error_message="a predicate is a table with one of the keys box, touch, all, any, not",
    ),
    BeforeValidator(_one_predicate_key),
]
AllPredicate.model_rebuild()
AnyPredicate.model_rebuild()
NotPredicate.model_rebuild()


class FeatureTarget(Strict):
    """A point fixed in a body: a feedback law's moving target."""

    body: Name = Field(description="the body the point is fixed in")
    point: tuple[Length, ...] = Field(description="the point in the body's frame, m ([x, y] planar, [x, y, z] spatial)")


class Law(Strict):
    """A feedback law of one drive: the force of the quadratic potential U = kp/2 (q - target)^2
    with damping kd, kd (v_des - v) with v_des = (kp / kd) (target - q) limited to max_speed
    (a velocity-limited attractive well; a PD law to the target where the limit does not act).
    The target is a coordinate value, or a point fixed in a body (the coordinate of its world
    position along the drive's axis, as that body moves)."""

    target: Length | FeatureTarget = Field(description="a coordinate value, or {body, point}: a point fixed in a body")
    kp: Gain = Field(description="the well's stiffness, N/m")
    kd: Gain = Field(description="damping, N s/m")
    max_speed: _bounded(NonNegative, "speed") | None = Field(
        None, description="limit of the desired speed, m/s (0: the drive holds still; none: unlimited)"
    )


class Policy(Strict):
    """What sweeps and `simulate` run: open loop (`constant_speed`: a commanded speed per actuated
    DOF) or closed loop (`feedback`: a `Law` per drive in `laws`; the others keep `speeds`)."""

    type: Literal["constant_speed", "feedback"]
    speeds: dict[str, Speed] = Field(default_factory=dict, description="actuated coordinate name -> commanded speed")
    laws: dict[str, Law] = Field(default_factory=dict, description="actuated coordinate name -> feedback law (type feedback)")
    duration: Time = Field(description="how long the policy runs, s")


class TaskSpec(Strict):
    horizon: Time = Field(description="the latest a plan may reach the goal, s")
    start: dict[str, Length] = Field(default_factory=dict, description="overrides of initial coordinates (default: body poses)")
    velocity: dict[str, Num] = Field(
        default_factory=dict,
        description="initial velocities by velocity name, e.g. 'box.x' (m/s) or 'disc.theta' (rad/s), "
        "'ball.wx'..'ball.wz' for a free rotation (world frame); default 0. Only the dynamic rungs have velocity state",
    )
    goal: Predicate
    unsafe: Predicate | None = None
    control_bounds: dict[str, SpeedInterval] = Field(
        default_factory=dict,
        description="a planner's commanded speed interval per actuated coordinate, within +-max_speed (default: +-max_speed)",
    )
    policy: Policy | None = None
    policies: dict[Name, Policy] = Field(
        default_factory=dict, description="other policies by name, run instead of [task.policy] with --policy NAME"
    )


# ----------------------------------------------------------------------------- ladder


class RungSpec(Strict):
    model: Literal[RUNG_NAMES]  # type: ignore[valid-type]
    h: Time | None = Field(None, description="physics time step, s (not for geometric)")
    control_period: Time | None = Field(None, description="duration of one planner control, s (default: ladder.control_period)")
    time_limit: Time | None = Field(
        None, description="wall-clock cap on this rung's planning, s (default: ladder's); see ladder.time_limit"
    )
    iterations: _int(gt=0, le=MAX_ITERATIONS) | None = Field(None, description="planner iterations of this rung (default: ladder's)")
    planner: Literal[PLANNERS] | None = None  # type: ignore[valid-type]
    theta: Annotated[Num, Field(ge=0, le=1)] = Field(
        1.0,
        description="theta-rule weight: 1 = semi-implicit (paper's scheme); below 1 the position update and the drives' "
        "PD force are evaluated at l+theta (0.5: second order for the drives)",
    )
    friction_directions: _int(ge=2, le=64) | None = Field(
        None, description="directions of the polyhedral friction cone (spatial scenes; planar: 2)"
    )
    friction_cone: Literal["polygon", "exact"] | None = Field(
        None,
        description="spatial friction: polygon (default: the polyhedral cone of friction_directions sides, an LCP) "
        "or exact (the circular Coulomb cone, mu of friction in every direction of sliding, solved by PGS: not "
        "with contact_solver = lemke or force-limited drives)",
    )
    inertia: Annotated[Num, Field(gt=0, le=1)] | None = Field(
        None,
        description="quasistatic rungs: the inertia scale their memoryless step keeps (default 1e-6, the limit "
        "eps -> 0; 1: a quasi-dynamic step with the bodies' full inertia, which resolves a statically "
        "indeterminate support and allows large steps)",
    )
    regularization: Annotated[Num, Field(ge=0, le=1e-3)] = Field(
        0.0,
        description="rigid rungs: this fraction of the largest normal Delassus diagonal added to every normal "
        "diagonal of the contact LCP, so that a statically indeterminate support (a box on a plane that turns "
        "about the vertical only) shares its load as equally stiff contacts would (the rigid limit) instead of "
        "at a vertex solution that loads some contacts only (default 0: exact rigid contact; Lemke's LCP)",
    )
    contact_solver: Literal[CONTACT_SOLVERS] | None = Field(  # type: ignore[valid-type]
        None,
        description="how the contact problems are solved: lemke (default, exact), pgs (projected Gauss-Seidel, "
        "cost linear in the contacts), auto (pgs from a measured contact count on, lemke below and where pgs "
        "does not converge); the kinematic rung always uses lemke",
    )


class LadderSpec(Strict):
    rungs: tuple[RungSpec, ...] = Field(min_length=1)
    planner: Literal[PLANNERS] = "RRT"  # type: ignore[valid-type]
    seed: _int(ge=0, le=MAX_SEED) = 0
    time_limit: Time = Field(
        description="default wall-clock cap on a rung's planning, s: a safety net on top of the iteration budget "
        "(time a rung leaves passes up to the next; a plan is reproducible unless a cap ends a search)"
    )
    iterations: _int(gt=0, le=MAX_ITERATIONS) = Field(2000, description="default planner iterations per rung: the reproducible budget")
    control_period: Time = Field(0.05, description="default duration of one control, s")


class ExpectRuns(Strict):
    """What runs of the scenario must do (run by `pytest` on the file): the policy's outcome
    under rungs, and whether a plan holds."""

    policy: dict[Literal[PROPAGATING_RUNGS], Literal[OUTCOME_LABELS]] = Field(  # type: ignore[valid-type]
        default_factory=dict, description="outcome of the task's policy under each named rung"
    )
    plan: Bool | None = Field(None, description="true: `ladder plan` must find a plan that holds at the top rung")
    plan_iterations: _int(gt=0, le=MAX_ITERATIONS) | None = Field(
        None, description="planner iterations per rung for the plan check (default: the ladder's budgets)"
    )
    seed: _int(ge=0, le=MAX_SEED) | None = Field(None, description="the plan check's seed (default: the ladder's)")


class ExpectCase(ExpectRuns):
    """Expectations of the scenario with other parameters or another of its policies."""

    name: Name = Field(description="the case's name: its items are FILE::NAME::policy[RUNG] and FILE::NAME::plan")
    parameters: dict[Name, ParameterValue] = Field(default_factory=dict, description="overrides of [parameters] for this case")
    task_policy: Name | None = Field(None, description="a [task.policies] entry the case runs instead of [task.policy]")


class ExpectSpec(ExpectRuns):
    """What the scenario must do with its default parameters (run by `pytest scenarios/`), and
    in cases with other parameters or policies."""

    cases: tuple[ExpectCase, ...] = Field(default_factory=tuple, description="[[expect.cases]]: expectations of variants")


class ScenarioSpec(Strict):
    """A whole scenario file."""

    version: Literal[1] = 1
    scenario: ScenarioInfo
    scene: SceneSpec
    parameters: dict[Annotated[str, Field(pattern=IDENTIFIER)], ParameterValue] = Field(
        default_factory=dict, description="design parameters p: name -> number"
    )
    contact: ContactSpec
    bodies: tuple[BodySpec, ...] = Field(min_length=1)
    task: TaskSpec
    ladder: LadderSpec
    expect: ExpectSpec | None = None


def json_schema() -> dict[str, Any]:
    """JSON Schema of the scenario format (for editors: Taplo / Even Better TOML)."""
    schema = ScenarioSpec.model_json_schema(by_alias=True)
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "ladder scenario"
    return schema

"""The scenario file format: frozen, validated pydantic models (one class per TOML table).

This module says *what a scenario file may contain*; `models.scenario` reads a file,
resolves parameter references, runs the checks that span several tables (names, DOFs,
geometry, initial penetration) and reports every problem with the file and the key path.

Numbers: every numeric field accepts a number or a string naming a design parameter, or a
small expression over parameters (``"-v1"``, ``"2 * r"``; see `models.expressions`). The
parameters come from the validation context (``context={"parameters": {...}}``).
Non-finite numbers (TOML's ``inf``/``nan``) are rejected everywhere.

Units are SI (m, kg, s, rad, N); angles in radians unless a key says ``_deg``.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal, Union

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationInfo,
    WithJsonSchema,
)

from models.expressions import ExpressionError, evaluate

#: Rung names, lowest fidelity first. The ladder in a file must respect this order.
RUNGS: tuple[str, ...] = (
    "geometric",
    "kinematic",
    "quasistatic-rigid",
    "quasistatic-compliant",
    "dynamic-rigid",
    "dynamic-compliant",
)
#: Contact solvers a rung may name (models.stepper.SOLVER_METHODS).
CONTACT_SOLVERS: tuple[str, ...] = ("lemke", "pgs", "auto")
#: OMPL planners a rung may name (geometric rung: RRTConnect and friends; control rungs: the rest).
PLANNERS: tuple[str, ...] = ("RRTConnect", "RRT", "RRTstar", "PRM", "KPIECE1", "EST")
#: Free DOF names per scene dimension, in the canonical order coordinates are stacked.
DOF_NAMES: dict[int, tuple[str, ...]] = {2: ("x", "y", "theta"), 3: ("x", "y", "z", "yaw", "rotation")}
SHAPES_2D = ("halfplane", "disc", "box", "polygon", "capsule")
SHAPES_3D = ("plane", "sphere", "box", "capsule", "mesh")

IDENTIFIER = r"^[A-Za-z_][A-Za-z0-9_]*$"


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


Num = Annotated[float, BeforeValidator(_resolve_number), WithJsonSchema(_NUMBER_SCHEMA)]
ParameterValue = Annotated[float, BeforeValidator(_plain_number)]
Positive = Annotated[Num, Field(gt=0)]
NonNegative = Annotated[Num, Field(ge=0)]
Interval = tuple[Num, Num]


def _as_tuple(value: Any) -> Any:
    return value if isinstance(value, (list, tuple)) else (value,)


#: A scalar, or principal moments; stored as a tuple of 1 or 3 numbers.
Inertia = Annotated[
    tuple[Positive, ...],
    BeforeValidator(_as_tuple),
    WithJsonSchema({"anyOf": [_NUMBER_SCHEMA, {"type": "array", "items": _NUMBER_SCHEMA, "minItems": 3, "maxItems": 3}]}),
]
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
    gravity: tuple[Num, ...] = Field(description="gravity vector, one entry per dimension, m/s^2")


class Material(Strict):
    """Contact material: Coulomb friction mu, stiffness K (N/m) and damping C (N s/m)."""

    mu: NonNegative
    K: Positive
    C: NonNegative


class PairMaterial(Strict):
    """Overrides of the default material for one pair of bodies (or disables the pair)."""

    bodies: tuple[Name, Name]
    mu: NonNegative | None = None
    K: Positive | None = None
    C: NonNegative | None = None
    enabled: bool = Field(True, description="false: the two bodies never interact")


class ContactSpec(Strict):
    mu: NonNegative = Field(description="default friction coefficient")
    K: Positive = Field(description="default contact stiffness, N/m (compliant rungs)")
    C: NonNegative = Field(description="default contact damping, N s/m (compliant rungs)")
    touch_tolerance: Positive = Field(1e-3, description="distance at or below which bodies touch, m")
    pairs: tuple[PairMaterial, ...] = ()


# ----------------------------------------------------------------------------- shapes


class HalfPlane(Strict):
    """Planar half-plane {p : normal . p <= offset} in the body frame (solid below the line)."""

    type: Literal["halfplane"]
    normal: tuple[Num, Num]
    offset: Num = 0.0


class Disc(Strict):
    type: Literal["disc"]
    radius: Positive


class Polygon(Strict):
    """Convex polygon, vertices in the body frame, either winding (stored counter-clockwise)."""

    type: Literal["polygon"]
    vertices: tuple[tuple[Num, Num], ...] = Field(min_length=3)


class Box(Strict):
    """Box centred on the body frame; ``size`` holds full edge lengths (2 or 3 of them)."""

    type: Literal["box"]
    size: tuple[Positive, ...]


class Capsule(Strict):
    """Segment of ``length`` along the body's x axis, centred, swept by a disc/sphere of ``radius``."""

    type: Literal["capsule"]
    radius: Positive
    length: Positive


class Plane(Strict):
    """Spatial half-space {p : normal . p <= offset} in the body frame."""

    type: Literal["plane"]
    normal: tuple[Num, Num, Num]
    offset: Num = 0.0


class Sphere(Strict):
    type: Literal["sphere"]
    radius: Positive


class Mesh(Strict):
    """Convex mesh from a Wavefront OBJ file (path relative to the scenario file)."""

    type: Literal["mesh"]
    file: str
    scale: Positive = 1.0


Shape = Annotated[
    Union[HalfPlane, Disc, Polygon, Box, Capsule, Plane, Sphere, Mesh],
    Field(discriminator="type"),
]


# ----------------------------------------------------------------------------- bodies


class Pose(Strict):
    """Initial pose. Planar: x, y, theta. Spatial: x, y, z and either quaternion (w, x, y, z)
    or rpy (roll, pitch, yaw, rad). Omitted entries are zero / identity."""

    x: Num = 0.0
    y: Num = 0.0
    z: Num | None = None
    theta: Num | None = None
    quaternion: tuple[Num, Num, Num, Num] | None = None
    rpy: tuple[Num, Num, Num] | None = None


class Drive(Strict):
    """Drive of one actuated DOF: the PD (impedance) law that tracks the commanded motion
    in the quasistatic and dynamic rungs, and its limits."""

    kp: Positive = Field(description="position gain, N/m (N m/rad for angles)")
    kd: NonNegative = Field(description="velocity gain, N s/m")
    max_speed: Positive = Field(description="largest commanded speed, m/s (rad/s)")
    max_force: Positive | None = Field(None, description="actuator force limit, N (none: unlimited)")
    lower: Num | None = Field(None, description="lower position limit")
    upper: Num | None = Field(None, description="upper position limit")


class BodySpec(Strict):
    name: Name
    role: Literal["robot", "object", "obstacle"]
    shape: Shape
    pose: Pose = Pose()
    dofs: tuple[str, ...] = Field((), description="free DOFs, e.g. ['y'] or ['x', 'y', 'theta']")
    mass: Positive | None = Field(None, description="kg; required for a body with free DOFs")
    inertia: Inertia | None = Field(
        None,
        description="rotational inertia about the centre of mass (planar: scalar; spatial: "
        "scalar or principal moments); required when a rotation is free",
    )
    actuators: dict[str, Drive] = Field(
        default_factory=dict, description="robots only: the drive of each actuated DOF"
    )
    velocity: dict[str, Num] = Field(
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
    tol: Positive | None = Field(None, description="defaults to contact.touch_tolerance")


class AllPredicate(Strict):
    all: tuple["Predicate", ...] = Field(min_length=1)


class AnyPredicate(Strict):
    any: tuple["Predicate", ...] = Field(min_length=1)


class NotPredicate(Strict):
    not_: "Predicate" = Field(alias="not")
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


Predicate = Annotated[
    Union[
        Annotated[BoxPredicate, Tag("box")],
        Annotated[TouchPredicate, Tag("touch")],
        Annotated[AllPredicate, Tag("all")],
        Annotated[AnyPredicate, Tag("any")],
        Annotated[NotPredicate, Tag("not")],
    ],
    Discriminator(
        _predicate_tag,
        custom_error_type="predicate",
        custom_error_message="a predicate is a table with one of the keys box, touch, all, any, not",
    ),
]
AllPredicate.model_rebuild()
AnyPredicate.model_rebuild()
NotPredicate.model_rebuild()


class Policy(Strict):
    """Parametric open-loop policy for sweeps: constant commanded speed per actuated DOF."""

    type: Literal["constant_speed"]
    speeds: dict[str, Num] = Field(description="actuated coordinate name -> commanded speed")
    duration: Positive = Field(description="how long the policy runs, s")


class TaskSpec(Strict):
    horizon: Positive = Field(description="longest plan duration, s")
    start: dict[str, Num] = Field(
        default_factory=dict, description="overrides of initial coordinates (default: body poses)"
    )
    velocity: dict[str, Num] = Field(
        default_factory=dict,
        description="initial velocities by velocity name, e.g. 'box.x' (m/s) or 'disc.theta' (rad/s), "
        "'ball.wx'..'ball.wz' for a free rotation (world frame); default 0. Only the dynamic rungs have velocity state",
    )
    goal: Predicate
    unsafe: Predicate | None = None
    control_bounds: dict[str, Interval] = Field(
        default_factory=dict,
        description="commanded speed interval per actuated coordinate (default: +-max_speed)",
    )
    policy: Policy | None = None


# ----------------------------------------------------------------------------- ladder


class RungSpec(Strict):
    model: Literal[RUNGS]  # type: ignore[valid-type]
    h: Positive | None = Field(None, description="physics time step, s (not for geometric)")
    control_period: Positive | None = Field(
        None, description="duration of one planner control, s (default: ladder.control_period)"
    )
    time_limit: Positive | None = Field(
        None, description="wall-clock cap on this rung's planning, s (default: ladder's); see ladder.time_limit"
    )
    iterations: Annotated[int, Field(gt=0)] | None = Field(None, description="planner iterations of this rung (default: ladder's)")
    planner: Literal[PLANNERS] | None = None  # type: ignore[valid-type]
    theta: Annotated[Num, Field(ge=0, le=1)] = Field(
        1.0, description="theta-rule weight: 1 = semi-implicit (paper's scheme)"
    )
    friction_directions: Annotated[int, Field(ge=2, le=64)] | None = Field(
        None, description="directions of the polyhedral friction cone (spatial scenes; planar: 2)"
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
    seed: Annotated[int, Field(ge=0)] = 0
    time_limit: Positive = Field(
        description="default wall-clock cap on a rung's planning, s: a safety net on top of the iteration budget "
        "(time a rung leaves passes up to the next; a plan is reproducible unless a cap ends a search)"
    )
    iterations: Annotated[int, Field(gt=0)] = Field(2000, description="default planner iterations per rung: the reproducible budget")
    control_period: Positive = Field(0.05, description="default duration of one control, s")


class ExpectSpec(Strict):
    """What the scenario must do with its default parameters (run by `pytest scenarios/`)."""

    policy: dict[Literal[RUNGS[1:]], Literal["goal", "unsafe", "none"]] = Field(  # type: ignore[valid-type]
        default_factory=dict, description="outcome of the task's policy under each named rung"
    )
    plan: bool | None = Field(None, description="true: `ladder plan` must find a plan that holds at the top rung")
    plan_iterations: Annotated[int, Field(gt=0)] | None = Field(
        None, description="planner iterations per rung for the plan check (default: the ladder's budgets)"
    )


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

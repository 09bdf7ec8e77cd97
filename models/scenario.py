"""Read a scenario file into a frozen, fully checked `Scenario`.

`load_scenario(path, overrides)` is the only entry point. It reads TOML with the standard
library, resolves design parameters (with ``--param`` overrides), validates the structure
(`models.schema`), then runs the checks that span tables: unique names, DOF names, shapes
valid for the dimension, geometry (degenerate or non-convex polygons, meshes), predicates
naming real coordinates and bodies, ladder order, and bodies that start in penetration.

Every problem found is reported, not only the first, as a `ScenarioError` whose lines read
``FILE: KEY.PATH: reason``. Nothing is written anywhere.
"""

from __future__ import annotations

import functools
import math
import numbers
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from pydantic import ValidationError

from models import geometry as geo
from models import messages
from models.expressions import ExpressionError, evaluate, names_in
from models.family import RUNG_NAMES, control_steps, definition
from models.schema import (
    CONTROL_PLANNERS,
    DOF_NAMES,
    GEOMETRIC_PLANNERS,
    LIMITS,
    MAX_PREDICATE_DEPTH,
    SHAPES_2D,
    SHAPES_3D,
    BodySpec,
    Drive,
    LadderSpec,
    Predicate,
    ScenarioSpec,
    _plain_number,
)

#: A body may start this far inside another (m) without being reported as penetrating.
PENETRATION_TOLERANCE = 1e-9
#: How far from 1 a quaternion's norm may be.
QUATERNION_NORM_TOLERANCE = 1e-6
#: Most problems listed in one error.
MAX_PROBLEMS = 20

ROTATIONAL_DOFS = ("theta", "yaw", "rotation")
TRANSLATIONAL_DOFS = ("x", "y", "z")


@dataclass(frozen=True)
class Problem:
    key: str
    reason: str


class ScenarioError(ValueError):
    """Bad scenario input. ``problems`` lists (key path, reason); str() has one line each."""

    def __init__(self, file: str | Path, problems: list[Problem]):
        self.file = str(file)
        self.problems = problems[:MAX_PROBLEMS]
        more = len(problems) - len(self.problems)
        lines = [f"{self.file}: {p.key}: {p.reason}" if p.key else f"{self.file}: {p.reason}" for p in self.problems]
        if more > 0:
            lines.append(f"{self.file}: ... and {more} more problems")
        super().__init__("\n".join(lines))

    def __reduce__(self):
        # picklable, so that a worker process's bad input reaches the parent as itself
        return ScenarioError, (self.file, self.problems)

    def to_json(self) -> dict:
        """The error as the service answers it (422) and a command's --json prints it: the
        lines (`detail`), the file and its problems, each a key and a reason."""
        return {"detail": str(self), "file": self.file, "problems": [{"key": p.key, "reason": p.reason} for p in self.problems]}


@dataclass(frozen=True)
class ContactPair:
    """Two bodies that may touch, with their resolved material."""

    body_a: str
    body_b: str
    mu: float
    K: float
    C: float


@dataclass(frozen=True)
class RungSettings:
    """A rung's settings in a scenario, every default resolved: the rung's entry in
    `[[ladder.rungs]]`, else `[ladder]`, else the rung's own default (`models.family`).

    h: time step, s (None for geometric; a rung the ladder does not list takes its family
    default); control_period: s per planner control; planner: OMPL planner name (geometric:
    RRTConnect unless the entry names one; else the ladder's); iterations: planner
    iterations; time_limit: wall-clock cap on its planning, s; contact_solver: lemke, pgs or
    auto; friction_directions: sides of the spatial friction cone (None for geometric);
    friction_cone: polygon (those sides) or exact (the circular cone, by PGS); theta:
    theta-rule weight; inertia: a quasistatic rung's inertia scale (None: the default);
    regularization: rigid contact's shared load (`models.stepper.Model.regularization`)."""

    name: str
    h: float | None
    control_period: float
    planner: str
    iterations: int
    time_limit: float
    contact_solver: str
    friction_directions: int | None
    theta: float
    inertia: float | None = None  # quasistatic rungs' inertia scale (None: the stepper's default)
    friction_cone: str = "polygon"
    regularization: float = 0.0


def resolve_rung_settings(ladder: LadderSpec, name: str) -> RungSettings:
    """`RungSettings` of rung `name` under a ladder table (see `Scenario.rung_settings`)."""
    family = definition(name)
    entry = next((r for r in ladder.rungs if r.model == name), None)

    def given(key: str):
        return None if entry is None else getattr(entry, key)

    geometric = family.physics is None
    return RungSettings(
        name=name,
        h=None if geometric else (given("h") or family.default_step),
        control_period=given("control_period") or ladder.control_period,
        planner=given("planner") or (GEOMETRIC_PLANNERS[0] if geometric else ladder.planner),
        iterations=given("iterations") or ladder.iterations,
        time_limit=given("time_limit") or ladder.time_limit,
        contact_solver=given("contact_solver") or "lemke",
        friction_directions=given("friction_directions") or family.friction_directions,
        theta=1.0 if entry is None else entry.theta,
        inertia=given("inertia"),
        friction_cone=given("friction_cone") or "polygon",
        regularization=0.0 if entry is None else float(entry.regularization),
    )


@dataclass(frozen=True)
class Scenario:
    """A validated scenario: the spec plus everything derived from it.

    coordinates: generalized coordinate names q in stacking order (body order of the file,
    then x, y, z, theta/yaw, qw..qz within a body); velocities: names of nu (rotation: wx..wz);
    actuated: the coordinates driven by a robot's actuators; start: q at the start (read-only);
    start_velocity: nu at the start (`[task] velocity`; zeros where not given; read-only).
    """

    path: Path
    spec: ScenarioSpec
    parameters: Mapping[str, float]
    coordinates: tuple[str, ...]
    velocities: tuple[str, ...]
    actuated: tuple[str, ...]
    start: np.ndarray
    geometries: Mapping[str, geo.Geometry]
    pairs: tuple[ContactPair, ...]
    base_placements: Mapping[str, geo.Placement] = field(repr=False)
    start_velocity: np.ndarray = field(default=None, repr=False)

    @property
    def dimension(self) -> int:
        return self.spec.scene.dimension

    def body(self, name: str) -> BodySpec:
        return next(b for b in self.spec.bodies if b.name == name)

    def with_policy(self, name: str | None) -> Scenario:
        """This scenario running `[task.policies] name` as its policy (None: as it is);
        ScenarioError naming the key when it has no such policy."""
        if name is None:
            return self
        policies = self.spec.task.policies
        if name not in policies:
            known = ", ".join(policies) or "none"
            raise ScenarioError(self.path, [Problem(key_path(("task", "policies")), f"no policy named {name!r} (policies: {known})")])
        task = self.spec.task.model_copy(update={"policy": policies[name]})
        return replace(self, spec=self.spec.model_copy(update={"task": task}))

    def rung_settings(self, name: str) -> RungSettings:
        """Rung `name`'s settings with every default resolved (`RungSettings`); any rung of
        the family, listed in the ladder or not. KeyError for an unknown rung name."""
        return resolve_rung_settings(self.spec.ladder, name)

    def drive(self, coordinate: str) -> Drive:
        """The drive of an actuated coordinate (``"finger1.y"``)."""
        body, dof = coordinate.split(".", 1)
        return self.body(body).actuators[dof]

    @property
    def max_speeds(self) -> np.ndarray:
        """The largest commanded speed of each actuated coordinate, in `actuated` order (m/s or rad/s)."""
        return np.array([self.drive(name).max_speed for name in self.actuated], dtype=float)

    def placements(self, q: np.ndarray) -> dict[str, geo.Placement]:
        """World placement of every body at configuration q."""
        values = dict(zip(self.coordinates, q))
        return {b.name: _placement(b, self.dimension, values, self.base_placements[b.name]) for b in self.spec.bodies}

    def summary(self) -> dict[str, Any]:
        """A JSON-ready description (what ``ladder check --json`` prints)."""
        spec = self.spec
        return {
            "file": str(self.path),
            "name": spec.scenario.name,
            "description": spec.scenario.description,
            "dimension": spec.scene.dimension,
            "gravity": list(spec.scene.gravity),
            "coordinates": list(self.coordinates),
            "velocities": list(self.velocities),
            "actuated": list(self.actuated),
            "start": {n: float(v) for n, v in zip(self.coordinates, self.start)},
            "start_velocity": {n: float(v) for n, v in zip(self.velocities, self.start_velocity) if v != 0.0},
            "parameters": dict(self.parameters),
            "bodies": [
                {
                    "name": b.name,
                    "role": b.role,
                    "shape": b.shape.type,
                    "dofs": list(b.dofs),
                    "mass": b.mass,
                    "actuated": sorted(b.actuators),
                }
                for b in spec.bodies
            ],
            "contact_pairs": [{"bodies": [p.body_a, p.body_b], "mu": p.mu, "K": p.K, "C": p.C} for p in self.pairs],
            "ladder": {
                "rungs": [r.model for r in spec.ladder.rungs],
                "steps": {r.model: r.h for r in spec.ladder.rungs},
                "planner": spec.ladder.planner,
                "seed": spec.ladder.seed,
                "time_limit": spec.ladder.time_limit,
            },
            "task": {
                "horizon": spec.task.horizon,
                "policy": None if spec.task.policy is None else _policy_summary(spec.task.policy),
                "policies": {name: _policy_summary(p) for name, p in spec.task.policies.items()},
                "unplannable": [f"{p.key}: {p.reason}" for p in plan_problems(spec)],  # why `ladder plan` refuses it
            },
            "expect": None if spec.expect is None else spec.expect.model_dump(mode="json"),
        }


def _policy_summary(policy) -> dict[str, Any]:
    """A policy as `Scenario.summary` gives it: its type, duration and what it drives."""
    return {"type": policy.type, "duration": policy.duration, "speeds": dict(policy.speeds), "laws": sorted(policy.laws)}


# ----------------------------------------------------------------------------- entry point


def parse_overrides(items: list[str] | None) -> dict[str, float]:
    """``["mu=0.3", "v1=2"]`` -> ``{"mu": 0.3, "v1": 2.0}``; raise ScenarioError on bad items."""
    result: dict[str, float] = {}
    problems = []
    for item in items or []:
        name, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sep or not name.strip() or not math.isfinite(number):
            problems.append(Problem(f"--param {item}", "expected NAME=NUMBER with a finite number"))
            continue
        result[name.strip()] = number
    if problems:
        raise ScenarioError("command line", problems)
    return result


@functools.lru_cache(maxsize=8)
def _parse_toml(text: str) -> dict:
    """A file's text parsed, the last few kept: a sweep loads one file at every grid point, and
    parsing was half of a load (1.8 ms on the paper's scene). The dict is shared between loads:
    read only (the checks and pydantic's validation only read it)."""
    return tomllib.loads(text)


def penetration_warning(scenario: Scenario, depth: float, pair: int | None = None) -> str:
    """What a run's largest penetration says when it is past half the thickness of the thinner
    body of the pair that penetrated (pair: its index in `scenario.pairs`; None where the run does
    not say which: the thinnest body in any contact pair), "" below: the contacts did not keep the
    bodies apart, whatever the run's status (a solver can solve every step of a box sinking
    through a table)."""
    pairs = scenario.pairs if pair is None else [scenario.pairs[pair]]
    names = {name for p in pairs for name in (p.body_a, p.body_b)}
    sizes = sorted((geo.thickness(scenario.geometries[name]), name) for name in names)
    if not sizes or not depth > 0.5 * sizes[0][0]:
        return ""
    size, name = sizes[0]
    if pair is None:
        where = f"the thinnest body in any contact pair ({name}, {size:.3g} m thick; the run does not say which pair penetrated)"
    else:
        where = f"the thinner body of the pair that penetrated, {pairs[0].body_a} and {pairs[0].body_b} ({name}, {size:.3g} m thick)"
    return (
        f"the largest penetration, {depth:.3g} m, is more than half the thickness of {where}: "
        "the contacts did not keep the bodies apart (a contact too soft for its load, or a step too long for the motion); "
        "the run is not physical"
    )


def load_scenario(
    path: str | Path,
    overrides: Mapping[str, float] | None = None,
    *,
    override_key: str | Callable[[str], str] = "overrides[{!r}]",
    check_expect: bool = True,
) -> Scenario:
    """Read, validate and derive a scenario, with overrides of its parameters (name -> value);
    raise ScenarioError listing every problem. override_key: how a problem names an override,
    a format of its name (the library's dict by default; the CLI's "--param {}") or a function
    of it (a sweep's "--grid mu" or "--model plastic"). check_expect
    False: the [expect] table's runs are not checked on this variant (the pytest plugin loads an
    [[expect.cases]] entry's variant so, and checks the case's runs on it: `expected_run_problems`)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
        raw = _parse_toml(text)
    except FileNotFoundError:
        raise ScenarioError(path, [Problem("", "no such file")]) from None
    except IsADirectoryError:
        raise ScenarioError(path, [Problem("", "is a directory, not a scenario file")]) from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(path, [Problem("", f"not UTF-8 text ({exc.reason})")]) from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(path, [Problem("", f"not valid TOML: {exc}")]) from None
    except RecursionError:  # the standard library's reader recurses once per level
        raise ScenarioError(path, [Problem("", _TOO_DEEP)]) from None
    except OSError as exc:
        raise ScenarioError(path, [Problem("", f"cannot read: {exc.strerror}")]) from None

    problems = _check_predicate_depth(raw) or _check_nesting(raw)
    if problems:
        raise ScenarioError(path, problems)
    # Bounds on every number keep derived quantities finite; should one still overflow (or a
    # structure still be too deep for the checks below), the file is what is wrong with it.
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            named = override_key.format if isinstance(override_key, str) else override_key
            parameters = _parameters(raw, overrides or {}, path, named)
            try:
                spec = ScenarioSpec.model_validate(raw, context={"parameters": parameters})
            except ValidationError as exc:
                overridden = {name: named(name) for name in overrides or {}}
                raise ScenarioError(path, _pydantic_problems(exc, parameters, overridden, raw)) from None
            return _derive(spec, MappingProxyType(parameters), path, text if check_expect else None)
    except (OverflowError, FloatingPointError, ZeroDivisionError) as exc:
        raise ScenarioError(path, [Problem("", f"a number is too large (or small) to compute with: {exc}")]) from None
    except RecursionError:
        raise ScenarioError(path, [Problem("", _TOO_DEEP)]) from None


#: Deepest nesting of arrays and tables in a scenario file.
MAX_NESTING = 100
_TOO_DEEP = f"nesting deeper than {MAX_NESTING} levels (arrays or tables inside each other); scenario files need far fewer"


def _check_nesting(raw: dict) -> list[Problem]:
    """Arrays and tables nested deeper than MAX_NESTING (walked without recursion)."""
    stack: list[tuple[Any, tuple, int]] = [(raw, (), 0)]
    while stack:
        node, loc, depth = stack.pop()
        if depth > MAX_NESTING:
            # the key that holds the deep structure (its own path inside is no help to read)
            head = next((i for i, part in enumerate(loc) if isinstance(part, int)), len(loc))
            return [Problem(key_path(loc[: max(1, min(head, 4))]), _TOO_DEEP)]
        if isinstance(node, dict):
            stack += [(v, (*loc, k), depth + 1) for k, v in node.items()]
        elif isinstance(node, list):
            stack += [(v, (*loc, i), depth + 1) for i, v in enumerate(node)]
    return []


def _check_predicate_depth(raw: dict) -> list[Problem]:
    """Predicates nested deeper than MAX_PREDICATE_DEPTH, reported at the task's goal or
    unsafe key (walked without recursion: this runs before anything else looks at them)."""
    task = raw.get("task")
    if not isinstance(task, dict):
        return []
    out = []
    for name in ("goal", "unsafe"):
        deepest = 0
        stack: list[tuple[Any, int]] = [(task.get(name), 1)]
        while stack:
            node, depth = stack.pop()
            if not isinstance(node, dict):
                continue
            deepest = max(deepest, depth)
            for word in ("all", "any"):
                if isinstance(node.get(word), list):
                    stack += [(child, depth + 1) for child in node[word]]
            if "not" in node:
                stack.append((node["not"], depth + 1))
        if deepest > MAX_PREDICATE_DEPTH:
            out.append(
                Problem(
                    f"task.{name}",
                    f"predicates nested {deepest} levels deep (all / any / not inside each other); at most {MAX_PREDICATE_DEPTH} levels",
                )
            )
    return out


def _parameters(raw: dict, overrides: Mapping[str, float], path: Path, named: Callable[[str], str]) -> dict[str, float]:
    table = raw.get("parameters", {})
    if not isinstance(table, dict):
        raise ScenarioError(path, [Problem("parameters", "must be a table of name = number")])
    values = []
    for name, value in table.items():  # each on its own: the keys that use a bad one would say it is unknown
        try:
            _plain_number(value)
        except ValueError as exc:
            values.append(Problem(key_path(("parameters", name)), str(exc)))
    if values:
        raise ScenarioError(path, values)
    params = dict(table)
    unknown = [name for name in overrides if name not in table]
    if unknown:
        known = ", ".join(sorted(table)) or "none defined"
        raise ScenarioError(
            path,
            [Problem(named(name), f"the file has no parameter {name!r} (parameters: {known})") for name in unknown],
        )
    bad = [(k, v) for k, v in overrides.items() if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v)]
    if bad:  # (float() would take "0.3" and True; a nan would be blamed on the key that uses it)
        raise ScenarioError(path, [Problem(named(k), f"must be a finite number, got {v!r}") for k, v in bad])
    params.update({k: float(v) for k, v in overrides.items()})
    return params


# ----------------------------------------------------------------------------- error paths


def key_path(loc: tuple) -> str:
    """('bodies', 1, 'pose', 'x') -> 'bodies[1].pose.x'; keys with dots are quoted."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part.replace("_", "a").isalnum():
            out += f".{part}" if out else part
        else:
            out += f'."{part}"' if out else f'"{part}"'
    return out


def _shown(value: Any, parameters: Mapping[str, float], overridden: Mapping[str, str]) -> str:
    """How a rejected input is quoted: parameter expressions also show their value, and name the
    overrides (overridden: parameter -> how its override is named, "--param mu") that set it."""
    if isinstance(value, str):
        try:
            shown = f"{evaluate(value, parameters):g} from {value!r}"
        except ExpressionError:
            pass
        else:
            setters = [overridden[name] for name in sorted(names_in(value, parameters)) if name in overridden]
            return f"{shown} ({', '.join(setters)})" if setters else shown
    return messages.got(value)


def _written_as_scalar(raw: Any, loc: tuple) -> bool:
    """Whether `loc` ends in an index into a value the file wrote as one number (a planar
    inertia, which the schema stores as a tuple of one: its key has no [0] in the file)."""
    if not loc or not isinstance(loc[-1], int):
        return False
    node = raw
    for part in loc[:-1]:
        try:
            node = node[part]
        except (KeyError, IndexError, TypeError):
            return False
    return not isinstance(node, (list, tuple, dict))


def _pydantic_problems(
    exc: ValidationError, parameters: Mapping[str, float], overridden: Mapping[str, str], raw: Any = None
) -> list[Problem]:
    """One problem per key, in plain words (see `models.messages`); overridden as `_shown` takes
    it; raw, the file's table: a key the file wrote as one number is named without an index."""
    errors = exc.errors()
    locs = [err["loc"] for err in errors]
    problems: list[Problem] = []
    seen: set[str] = set()
    for err in errors:
        loc = err["loc"]
        if err["type"] in ("too_short", "too_long") and any(len(o) > len(loc) and o[: len(loc)] == loc for o in locs):
            continue  # entries that failed are reported themselves; the count pydantic then gives is not the user's
        clean, annotation = messages.walk(ScenarioSpec, loc)
        if _written_as_scalar(raw, clean):
            clean = clean[:-1]
        known = messages.keys_at(ScenarioSpec, loc[:-1]) if err["type"] == "extra_forbidden" else ()
        suffix, reason = messages.reason(err, annotation, lambda value: _shown(value, parameters, overridden), known)
        key = key_path(clean) + suffix
        if key in seen:
            continue  # a union reports each member's complaint; one per key is clearer
        seen.add(key)
        problems.append(Problem(key, reason))
    return problems


# ----------------------------------------------------------------------------- derivation


def _coordinate_names(body: BodySpec, dimension: int) -> tuple[list[str], list[str]]:
    q_names: list[str] = []
    v_names: list[str] = []
    for dof in DOF_NAMES[dimension]:
        if dof not in body.dofs:
            continue
        if dof == "rotation":
            q_names += [f"{body.name}.q{c}" for c in "wxyz"]
            v_names += [f"{body.name}.w{c}" for c in "xyz"]
        else:
            q_names.append(f"{body.name}.{dof}")
            v_names.append(f"{body.name}.{dof}")
    return q_names, v_names


def _base_placement(body: BodySpec, dimension: int) -> geo.Placement:
    p = body.pose
    if dimension == 2:
        return geo.Placement(geo.rotation_2d(p.theta or 0.0), np.array([p.x, p.y]))
    if p.quaternion is not None:
        quat = np.array(p.quaternion) / np.linalg.norm(p.quaternion)
    elif p.rpy is not None:
        quat = geo.rpy_quaternion(*p.rpy)
    else:
        quat = np.array([1.0, 0.0, 0.0, 0.0])
    return geo.Placement(geo.quaternion_matrix(quat), np.array([p.x, p.y, p.z or 0.0]))


def _placement(body: BodySpec, dimension: int, values: Mapping[str, float], base: geo.Placement) -> geo.Placement:
    t = base.translation.copy()
    for axis, name in enumerate("xyz"[:dimension]):
        t[axis] = values.get(f"{body.name}.{name}", t[axis])
    rotation = base.rotation
    if dimension == 2 and f"{body.name}.theta" in values:
        rotation = geo.rotation_2d(values[f"{body.name}.theta"])
    elif dimension == 3 and f"{body.name}.yaw" in values:
        rotation = geo.quaternion_matrix(geo.rpy_quaternion(0.0, 0.0, values[f"{body.name}.yaw"]))
    elif dimension == 3 and f"{body.name}.qw" in values:
        quat = np.array([values[f"{body.name}.q{c}"] for c in "wxyz"])
        rotation = geo.quaternion_matrix(quat / np.linalg.norm(quat))
    return geo.Placement(rotation, t)


def _start_values(body: BodySpec, dimension: int) -> dict[str, float]:
    p = body.pose
    values = {"x": p.x, "y": p.y, "z": p.z or 0.0, "theta": p.theta or 0.0}
    values["yaw"] = p.rpy[2] if p.rpy is not None else 0.0
    if p.quaternion is not None:
        norm = float(np.linalg.norm(p.quaternion))
        # a zero quaternion is reported by _check_body; the start just needs a number here
        quat = np.array(p.quaternion) / norm if norm > 0.0 else np.array([1.0, 0.0, 0.0, 0.0])
    else:
        quat = geo.rpy_quaternion(*p.rpy) if p.rpy else np.array([1.0, 0.0, 0.0, 0.0])
    values.update({f"q{c}": float(v) for c, v in zip("wxyz", quat)})
    return values


def _derive(spec: ScenarioSpec, parameters: Mapping[str, float], path: Path, text: str | None) -> Scenario:
    """The scenario of a validated spec; text: the file's contents, for [expect]'s checks (None:
    not checked, `load_scenario`'s check_expect)."""
    problems: list[Problem] = []
    dim = spec.scene.dimension
    if len(spec.scene.gravity) != dim:
        problems.append(Problem("scene.gravity", f"needs {dim} entries for a {dim}D scene, got {len(spec.scene.gravity)}"))

    names = [b.name for b in spec.bodies]
    geometries: dict[str, geo.Geometry] = {}
    for i, body in enumerate(spec.bodies):
        if names.index(body.name) != i:
            problems.append(Problem(f"bodies[{i}].name", f"body name {body.name!r} is used twice"))
        problems += _check_body(body, f"bodies[{i}]", dim)
        if not any(p.key.startswith(f"bodies[{i}].shape") for p in problems):
            try:
                geometries[body.name] = geo.make_geometry(body.shape, dim, path.parent, LIMITS["length"].high)
            except geo.GeometryError as exc:
                sub = {"polygon": ".vertices", "mesh": ".file", "halfplane": ".normal", "plane": ".normal"}
                problems.append(Problem(f"bodies[{i}].shape{sub.get(body.shape.type, '')}", str(exc)))

    coordinates: list[str] = []
    velocities: list[str] = []
    actuated: list[str] = []
    start: list[float] = []
    for body in spec.bodies:
        if set(body.dofs) <= set(DOF_NAMES[dim]):
            q_names, v_names = _coordinate_names(body, dim)
            coordinates += q_names
            velocities += v_names
            actuated += [f"{body.name}.{d}" for d in DOF_NAMES[dim] if d in body.actuators and d in body.dofs]
            values = _start_values(body, dim)
            start += [values[n.split(".", 1)[1]] for n in q_names]

    start_overridden: set[str] = set()
    for name, value in spec.task.start.items():
        if name not in coordinates:
            problems.append(Problem(key_path(("task", "start", name)), _unknown_coordinate(name, coordinates)))
        else:
            start[coordinates.index(name)] = value
            start_overridden.add(name.split(".", 1)[0])

    start_velocity = [0.0] * len(velocities)
    for name, value in spec.task.velocity.items():
        if name not in velocities:
            problems.append(Problem(key_path(("task", "velocity", name)), _unknown_coordinate(name, velocities, "velocity", "velocities")))
        else:
            start_velocity[velocities.index(name)] = value

    problems += _check_contacts(spec, names)
    problems += _check_touch_tolerance("contact.touch_tolerance", spec.contact.touch_tolerance)
    problems += _check_task(spec, coordinates, actuated, names, _pair_status(spec))
    problems += _check_ladder(spec)
    problems += _check_rung_settings(spec)
    problems += _check_expected_runs(spec) if text is not None else []
    problems += _check_limits(spec, coordinates, start, dim)
    if problems:
        raise ScenarioError(path, problems)

    pairs = _contact_pairs(spec)
    base = {b.name: _base_placement(b, dim) for b in spec.bodies}
    scenario = Scenario(
        path=path,
        spec=spec,
        parameters=parameters,
        coordinates=tuple(coordinates),
        velocities=tuple(velocities),
        actuated=tuple(actuated),
        start=_frozen(np.array(start, dtype=float)),
        geometries=MappingProxyType(geometries),
        pairs=pairs,
        base_placements=MappingProxyType(base),
        start_velocity=_frozen(np.array(start_velocity, dtype=float)),
    )
    problems = _check_penetration(scenario, start_overridden)
    problems += list(_check_cases(str(path), text)) if text is not None and spec.expect and spec.expect.cases and not problems else []
    if problems:
        raise ScenarioError(path, problems)
    return scenario


@functools.lru_cache(maxsize=8)
def _check_cases(path: str, text: str) -> tuple[Problem, ...]:
    """Each [[expect.cases]] entry of the file at path (its contents `text`) can run on its
    variant (the scenario with the case's parameters and policy, as the pytest plugin loads it):
    the variant loads, and `expected_run_problems` finds nothing in the case's runs on it. The
    last few files' answers are kept: a case's variant does not depend on a load's overrides,
    and a sweep loads one file at every grid point."""
    scenario = load_scenario(path, check_expect=False)
    out = []
    for i, case in enumerate(scenario.spec.expect.cases):
        key = f"expect.cases[{i}]"
        try:
            variant = case_variant(scenario.path, case, i)
        except ScenarioError as exc:
            out += [Problem(key, f"the scene with the case's parameters does not load: {p.key}: {p.reason}") for p in exc.problems]
            continue
        out += expected_run_problems(variant.spec, case, key)
    return tuple(out)


def case_variant(path: Path, case, index: int) -> Scenario:
    """The scenario an [[expect.cases]] entry (index in the file's list) runs on: the file with
    the case's parameters and its `task_policy`; its [expect] runs are not checked again."""
    scenario = load_scenario(path, case.parameters, override_key=f"expect.cases[{index}].parameters.{{}}", check_expect=False)
    return scenario.with_policy(case.task_policy)


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _unknown_coordinate(name: str, coordinates: list[str], noun: str = "coordinate", plural: str = "coordinates") -> str:
    return f"no {noun} {name!r}; the {plural} are: {', '.join(coordinates) or 'none (nothing moves)'}"


def _check_body(body: BodySpec, key: str, dim: int) -> list[Problem]:
    out: list[Problem] = []
    allowed_shapes = SHAPES_2D if dim == 2 else SHAPES_3D
    if body.shape.type not in allowed_shapes:
        out.append(Problem(f"{key}.shape.type", f"{body.shape.type!r} is not a {dim}D shape; use one of {', '.join(allowed_shapes)}"))
    elif body.shape.type == "box" and len(body.shape.size) != dim:
        out.append(Problem(f"{key}.shape.size", f"a {dim}D box needs {dim} edge lengths, got {len(body.shape.size)}"))
    if body.shape.type in ("halfplane", "plane") and body.role != "obstacle":
        out.append(Problem(f"{key}.shape.type", f"a {body.shape.type} is unbounded: only obstacles may have it"))

    pose = body.pose
    if dim == 2:
        for name in ("z", "quaternion", "rpy"):
            if getattr(pose, name) is not None:
                out.append(Problem(f"{key}.pose.{name}", "planar poses have only x, y, theta"))
    else:
        if pose.theta is not None:
            out.append(Problem(f"{key}.pose.theta", "spatial poses use quaternion or rpy, not theta"))
        if pose.quaternion is not None and pose.rpy is not None:
            out.append(Problem(f"{key}.pose", "give either quaternion or rpy, not both"))
        if pose.quaternion is not None and abs(np.linalg.norm(pose.quaternion) - 1.0) > QUATERNION_NORM_TOLERANCE:
            out.append(Problem(f"{key}.pose.quaternion", f"not a unit quaternion (norm {np.linalg.norm(pose.quaternion):.6g})"))
        if "yaw" in body.dofs and pose.quaternion is not None:
            out.append(Problem(f"{key}.pose.quaternion", "a body with a free yaw takes its orientation from rpy = [0, 0, yaw]"))
        if "yaw" in body.dofs and pose.rpy is not None and (pose.rpy[0] or pose.rpy[1]):
            out.append(Problem(f"{key}.pose.rpy", "a body with a free yaw must start with zero roll and pitch"))

    valid = DOF_NAMES[dim]
    for j, dof in enumerate(body.dofs):
        if dof not in valid:
            out.append(Problem(f"{key}.dofs[{j}]", f"no DOF {dof!r}; {'planar' if dim == 2 else 'spatial'} bodies have {', '.join(valid)}"))
        elif body.dofs.index(dof) != j:
            out.append(Problem(f"{key}.dofs[{j}]", f"DOF {dof!r} is listed twice"))
    if "yaw" in body.dofs and "rotation" in body.dofs:
        out.append(Problem(f"{key}.dofs", "yaw and rotation exclude each other (rotation includes yaw)"))

    if body.role == "obstacle":
        if body.dofs:
            out.append(
                Problem(f"{key}.dofs", "an obstacle is fixed or scripted and has no free DOFs; use role = 'object' for a passive body")
            )
        if body.actuators:
            out.append(Problem(f"{key}.actuators", "only robots have actuators"))
    else:
        if body.velocity:
            out.append(Problem(f"{key}.velocity", "only obstacles have a scripted velocity"))
        if body.dofs and body.mass is None:
            out.append(Problem(f"{key}.mass", "required: a body with free DOFs needs a mass > 0"))
        if any(d in ROTATIONAL_DOFS for d in body.dofs) and body.inertia is None:
            out.append(Problem(f"{key}.inertia", "required: a body with a free rotation needs its rotational inertia"))
        if body.inertia is not None and dim == 2 and len(body.inertia) != 1:
            out.append(Problem(f"{key}.inertia", "a planar body's inertia is one number (about the z axis)"))
        if body.inertia is not None and dim == 3 and len(body.inertia) not in (1, 3):
            out.append(Problem(f"{key}.inertia", "a spatial body's inertia is one number or three principal moments"))
        elif body.inertia is not None and dim == 3 and len(body.inertia) == 3 and body.inertia_products is None:
            # a rigid body's principal moments: each at most the sum of the other two (equal for a flat plate)
            problem = _moments_problem(sorted(float(i) for i in body.inertia))
            if problem:
                out.append(Problem(f"{key}.inertia", f"no rigid body has these principal moments: {problem}"))
        if body.inertia_products is not None:
            if dim == 2:
                out.append(Problem(f"{key}.inertia_products", "a planar body has no products of inertia (its inertia is about z alone)"))
            elif body.inertia is None:
                out.append(Problem(f"{key}.inertia_products", "needs inertia, the tensor's diagonal (Ixx, Iyy, Izz)"))
            elif len(body.inertia) in (1, 3):
                moments, _ = principal_inertia(body)
                tensor = ", ".join(f"{v:g}" for v in (*inertia_tensor(body).diagonal(), *body.inertia_products))
                listed = ", ".join(f"{m:.6g}" for m in moments)
                problem = "it is not positive definite" if not moments[0] > 0.0 else _moments_problem(list(moments))
                if problem:
                    out.append(
                        Problem(
                            f"{key}.inertia_products",
                            f"no rigid body has the inertia tensor (Ixx, Iyy, Izz, Ixy, Ixz, Iyz) = ({tensor}): its principal "
                            f"moments are {listed}, and {problem}",
                        )
                    )
    if body.role == "object" and body.actuators:
        out.append(Problem(f"{key}.actuators", "only robots have actuators; an object's DOFs are passive"))
    if body.role == "robot" and not body.actuators:
        out.append(Problem(f"{key}.actuators", "a robot needs at least one actuated DOF (or make it an obstacle)"))
    for dof, drive in body.actuators.items():
        akey = f"{key}.actuators.{dof}"
        if dof not in body.dofs:
            out.append(Problem(akey, f"{dof!r} is not a free DOF of {body.name!r} (dofs: {', '.join(body.dofs) or 'none'})"))
        elif dof == "rotation":
            out.append(Problem(akey, "a free 3D rotation cannot be actuated as one DOF; actuate yaw instead"))
        if drive.lower is not None and drive.upper is not None and drive.lower >= drive.upper:
            out.append(Problem(f"{akey}.lower", f"lower limit {drive.lower} is not below upper limit {drive.upper}"))
    pose_coordinates = ("x", "y", "theta") if dim == 2 else ("x", "y", "z")
    for name in body.velocity:
        if name not in pose_coordinates:
            out.append(Problem(key_path((*_split(key), "velocity", name)), f"scripted velocities are for {', '.join(pose_coordinates)}"))
    return out


def _split(key: str) -> tuple:
    head, index = key.split("[")
    return (head, int(index.rstrip("]")))


def _check_contacts(spec: ScenarioSpec, names: list[str]) -> list[Problem]:
    out = []
    seen = set()
    for k, pair in enumerate(spec.contact.pairs):
        key = f"contact.pairs[{k}].bodies"
        for name in pair.bodies:
            if name not in names:
                out.append(Problem(key, f"no body named {name!r} (bodies: {', '.join(names)})"))
        if pair.bodies[0] == pair.bodies[1]:
            out.append(Problem(key, "a pair needs two different bodies"))
        frozen = frozenset(pair.bodies)
        if frozen in seen:
            out.append(Problem(key, f"the pair {pair.bodies[0]}-{pair.bodies[1]} is given twice"))
        seen.add(frozen)
        bodies = [b for b in spec.bodies if b.name in pair.bodies]
        if len(bodies) == 2 and not any(_moves(b) for b in bodies):
            out.append(
                Problem(
                    key,
                    f"neither {pair.bodies[0]!r} nor {pair.bodies[1]!r} moves, so they are not a contact pair "
                    "and this entry would set nothing",
                )
            )
    return out


def _moves(body: BodySpec) -> bool:
    """Whether a body can move: free DOFs or a scripted velocity (two that cannot never meet anew)."""
    return bool(body.dofs or body.velocity)


def _pair_status(spec: ScenarioSpec) -> Callable[[str, str], str | None]:
    """For two body names: None if they are a contact pair (`_contact_pairs`), else why not."""
    pairs = {frozenset((p.body_a, p.body_b)) for p in _contact_pairs(spec)}
    disabled = {frozenset(p.bodies): k for k, p in enumerate(spec.contact.pairs) if not p.enabled}

    def status(a: str, b: str) -> str | None:
        pair = frozenset((a, b))
        if pair in pairs:
            return None
        if pair in disabled:
            return (
                f"the pair {a}-{b} is disabled (contact.pairs[{disabled[pair]}].enabled = false), "
                "so they never touch; enable the pair or drop this predicate"
            )
        return f"neither {a!r} nor {b!r} moves, so they are not a contact pair and their touching never changes"

    return status


def _check_predicate(
    pred: Predicate, key: str, coordinates: list[str], names: list[str], pair_status: Callable[[str, str], str | None] = lambda a, b: None
) -> list[Problem]:
    kind = type(pred).__name__
    out: list[Problem] = []
    if kind == "BoxPredicate":
        for name, (lo, hi) in pred.box.items():
            sub = key_path((*_parse_key(key), "box", name))
            if name not in coordinates:
                out.append(Problem(sub, _unknown_coordinate(name, coordinates)))
            elif lo > hi:
                out.append(Problem(sub, f"empty interval [{lo}, {hi}]"))
    elif kind == "TouchPredicate":
        for name in pred.touch:
            if name not in names:
                out.append(Problem(f"{key}.touch", f"no body named {name!r} (bodies: {', '.join(names)})"))
        if pred.touch[0] == pred.touch[1]:
            out.append(Problem(f"{key}.touch", "a body always touches itself; name two bodies"))
        elif all(name in names for name in pred.touch):
            why = pair_status(*pred.touch)
            if why is not None:
                out.append(Problem(f"{key}.touch", why))
        if pred.tol is not None:
            out += _check_touch_tolerance(f"{key}.tol", pred.tol)
    elif kind in ("AllPredicate", "AnyPredicate"):
        word = "all" if kind == "AllPredicate" else "any"
        for i, sub in enumerate(getattr(pred, word)):
            out += _check_predicate(sub, f"{key}.{word}[{i}]", coordinates, names, pair_status)
    else:
        out += _check_predicate(pred.not_, f"{key}.not", coordinates, names, pair_status)
    return out


def _check_touch_tolerance(key: str, tol: float) -> list[Problem]:
    """A touch tolerance may not exceed the contact-detection margin: compiled rollouts
    measure a pair only while it is within the margin (farther pairs count as apart), so a
    larger tolerance would make their goal check disagree with `predicate_distance`."""
    from models.contact import CONTACT_MARGIN  # the compiled kernels: loaded when a file is checked, not on import

    if tol <= CONTACT_MARGIN:
        return []
    return [
        Problem(
            key,
            f"touch tolerance {tol:g} m is above the contact-detection margin {CONTACT_MARGIN:g} m "
            "(rollouts see a pair only within the margin); use at most that",
        )
    ]


def _parse_key(key: str) -> tuple:
    """Inverse of key_path for the simple keys built here (no quoted parts)."""
    parts: list = []
    for token in key.split("."):
        while "[" in token:
            head, rest = token.split("[", 1)
            if head:
                parts.append(head)
            index, token = rest.split("]", 1)
            parts.append(int(index))
        if token:
            parts.append(token)
    return tuple(parts)


def _check_task(
    spec: ScenarioSpec, coordinates: list[str], actuated: list[str], names: list[str], pair_status: Callable[[str, str], str | None]
) -> list[Problem]:
    task = spec.task
    out = _check_predicate(task.goal, "task.goal", coordinates, names, pair_status)
    if task.unsafe is not None:
        out += _check_predicate(task.unsafe, "task.unsafe", coordinates, names, pair_status)
    for name, (lo, hi) in task.control_bounds.items():
        key = key_path(("task", "control_bounds", name))
        if name not in actuated:
            out.append(Problem(key, _not_actuated(name, actuated, names)))
        elif lo >= hi:
            out.append(Problem(key, f"lower bound {lo} is not below upper bound {hi}"))
        else:
            body, dof = name.split(".", 1)
            top = next(b for b in spec.bodies if b.name == body).actuators[dof].max_speed
            if lo < -top or hi > top:
                out.append(
                    Problem(
                        key,
                        f"[{lo:g}, {hi:g}] reaches past the drive's max_speed {top:g} (the largest speed a planner "
                        "commands, which also bounds how far a drive may lag its reference)",
                    )
                )
    policies = [(("task", "policy"), task.policy)] if task.policy is not None else []
    policies += [(("task", "policies", name), policy) for name, policy in task.policies.items()]
    for loc, policy in policies:
        out += _check_policy(spec, policy, loc, actuated)
    return out


def _not_actuated(name: str, actuated: list[str], bodies: list[str]) -> str:
    """Why `name` is not an actuated coordinate: no such body, else not one of the drives."""
    body = name.split(".", 1)[0]
    if body not in bodies:
        return f"no body named {body!r} (bodies: {', '.join(bodies)})"
    return f"{name!r} is not an actuated coordinate (actuated: {', '.join(actuated) or 'none'})"


def _check_policy(spec: ScenarioSpec, policy, loc: tuple, actuated: list[str]) -> list[Problem]:
    """A policy's speeds and laws name actuated coordinates; laws only in a feedback policy, and
    one at least; a law's body target names a body, a point of the scene's dimension, and a
    drive along x, y or z (whose world coordinate the point's position gives)."""
    out, names = [], [b.name for b in spec.bodies]
    for part in ("speeds", "laws"):
        for name in getattr(policy, part):
            if name not in actuated:
                out.append(Problem(key_path((*loc, part, name)), _not_actuated(name, actuated, names)))
    if policy.type == "constant_speed" and policy.laws:
        out.append(Problem(key_path((*loc, "laws")), 'feedback laws need type = "feedback"'))
    if policy.type == "feedback" and not policy.laws:
        out.append(Problem(key_path((*loc, "laws")), "a feedback policy needs at least one law"))
    both = sorted(set(policy.speeds) & set(policy.laws))
    if both:
        out.append(Problem(key_path((*loc, "speeds")), f"{', '.join(both)}: a drive has a speed or a law, not both"))
    bodies = [b.name for b in spec.bodies]
    for name, law in policy.laws.items():
        target = law.target
        if isinstance(target, (int, float)):
            continue
        key = key_path((*loc, "laws", name, "target"))
        if target.body not in bodies:
            out.append(Problem(f"{key}.body", f"no body named {target.body!r} (bodies: {', '.join(bodies)})"))
        if len(target.point) != spec.scene.dimension:
            out.append(Problem(f"{key}.point", f"a point of {spec.scene.dimension} coordinates, not {len(target.point)}"))
        if name.rsplit(".", 1)[-1] not in TRANSLATIONAL_DOFS:
            out.append(Problem(key, f"a body's point is a target only for a drive along x, y or z, not {name!r}"))
    return out


def _exact_cone_problems(spec: ScenarioSpec, rung, key: str) -> list[Problem]:
    """A rung with the exact friction cone: PGS solves it, without force-limited drives."""
    out = []
    if rung.contact_solver == "lemke":
        out.append(Problem(f"{key}.friction_cone", 'the exact cone is solved by PGS: not with contact_solver = "lemke"'))
    limited = [f"{b.name}.{dof}" for b in spec.bodies for dof, d in b.actuators.items() if d.max_force is not None]
    if limited:
        out.append(Problem(f"{key}.friction_cone", f"the exact cone's PGS does not take force-limited drives ({', '.join(limited)})"))
    return out


def plan_problems(spec: ScenarioSpec) -> list[Problem]:
    """Why the scene cannot be planned (`planner.ladder.check_start`, and a file's `[expect]
    plan`): nothing is actuated, or an obstacle moves on a script (plan states carry no time, so
    its pose at a state is unknown; simulate and sweep run such scenes from t = 0), or the
    horizon is shorter than every rung's control period (a search's controls last whole periods,
    and a geometric path's)."""
    if not any(b.actuators for b in spec.bodies):
        return [
            Problem("bodies", "nothing to plan: no body has an actuated DOF (a robot's actuators); `ladder simulate` runs such a scene")
        ]
    out = [
        Problem(
            f"bodies[{i}].velocity",
            "planning with a scripted (moving) obstacle is not supported: plan states carry no "
            "time; `ladder simulate` and `ladder sweep` run such scenes",
        )
        for i, body in enumerate(spec.bodies)
        if body.velocity
    ]
    # (the ladder's own period too: `plan --rungs` may pick a rung the file does not list)
    period = min([spec.ladder.control_period, *(resolve_rung_settings(spec.ladder, r.model).control_period for r in spec.ladder.rungs)])
    if spec.task.horizon < period:
        out.append(
            Problem(
                "task.horizon",
                f"the task's horizon, {spec.task.horizon:g} s, is shorter than one control period ({period:g} s, "
                "the shortest of the ladder's): the planners' controls last whole periods, so their plans cannot meet it; "
                "lengthen the horizon or shorten ladder.control_period",
            )
        )
    return out


#: Item names of a scenario file's own (the pytest plugin's FILE::plan, FILE::load), which a case's name would shadow.
RESERVED_CASE_NAMES = ("plan", "load")


def _check_expected_runs(spec: ScenarioSpec) -> list[Problem]:
    """The `[expect]` table's items can run (as `pytest` on the file runs them): its own runs
    (`expected_run_problems`) and its cases' names, parameters and policies. A case's runs are
    checked on its variant once the file's scenario is whole (`_check_cases`)."""
    if spec.expect is None:
        return []
    expect = spec.expect
    out = expected_run_problems(spec, expect, "expect", cases=len(expect.cases))
    names = [case.name for case in expect.cases]
    for i, case in enumerate(expect.cases):
        key = f"expect.cases[{i}]"
        if names.index(case.name) != i:
            out.append(Problem(f"{key}.name", f"case name {case.name!r} is used twice"))
        if case.name in RESERVED_CASE_NAMES:
            out.append(
                Problem(f"{key}.name", f"{case.name!r} names the file's own {case.name} item (FILE::{case.name}); name the case otherwise")
            )
        known = ", ".join(sorted(spec.parameters)) or "none defined"
        out += [
            Problem(f"{key}.parameters.{name}", f"the file has no parameter {name!r} (parameters: {known})")
            for name in case.parameters
            if name not in spec.parameters
        ]
        if case.task_policy is not None and case.task_policy not in spec.task.policies:
            policies = ", ".join(spec.task.policies) or "none"
            out.append(Problem(f"{key}.task_policy", f"no policy named {case.task_policy!r} in [task.policies] (policies: {policies})"))
        if not case.policy and case.plan is None:
            out.append(Problem(key, "names no expectation: give policy = { RUNG = OUTCOME } and/or plan = true or false"))
    return out


def expected_run_problems(spec: ScenarioSpec, runs, key: str, *, cases: int = 0) -> list[Problem]:
    """What keeps runs (`models.schema.ExpectRuns`: the [expect] table's own, or a case's, under
    key) from running on spec: it names one at least (or the table has cases); a seed or budget
    is for a plan check; a plan expectation has something to plan (`plan_problems`); a policy
    expectation has a policy, and each rung's run of it (at the rung's h) takes a step: a run
    takes round(duration / h), so a policy shorter than h / 2 would end where it starts and be
    judged there."""
    out = []
    if not runs.policy and runs.plan is None and not cases:  # (a test that tests nothing passes unseen)
        out.append(Problem(key, "names no expectation: give policy = { RUNG = OUTCOME } and/or plan = true or false, or [[expect.cases]]"))
    for setting in ("seed", "plan_iterations"):
        if getattr(runs, setting) is not None and runs.plan is None:
            out.append(Problem(f"{key}.{setting}", "is the plan check's, and there is none (plan = true or false)"))
    if runs.plan is not None:  # the plan item plans: what `ladder plan` would refuse, under this key
        refused = dict.fromkeys(f"{p.key}: {p.reason}" for p in plan_problems(spec))
        out += [
            Problem(f"{key}.plan", f"`ladder plan` refuses this scene, so [expect] cannot test a plan of it; leave plan out ({why})")
            for why in refused
        ]
    policy = spec.task.policy
    if policy is None:
        if runs.policy:
            out.append(Problem(f"{key}.policy", "runs the task's policy, and this file has no [task.policy]"))
        return out
    for name in runs.policy:
        h = resolve_rung_settings(spec.ladder, name).h
        if h is not None and control_steps(policy.duration, h)[0] == 0:
            out.append(
                Problem(
                    f"{key}.{key_path(('policy', name))}",
                    f"the policy's {policy.duration:g} s (task.policy.duration) at {name}'s h = {h:g} is no step "
                    "(a run takes round(duration / h) steps)",
                )
            )
    return out


def _check_ladder(spec: ScenarioSpec) -> list[Problem]:
    out = []
    ladder = spec.ladder
    order = [RUNG_NAMES.index(r.model) for r in ladder.rungs]
    for i, rung in enumerate(ladder.rungs):
        key = f"ladder.rungs[{i}]"
        if i > 0 and order[i] <= order[i - 1]:
            out.append(
                Problem(
                    f"{key}.model",
                    f"{rung.model!r} after {ladder.rungs[i - 1].model!r}: rungs go from low to high fidelity "
                    f"({' < '.join(RUNG_NAMES)}), each once",
                )
            )
        if rung.model == "geometric":
            if rung.h is not None:
                out.append(Problem(f"{key}.h", "the geometric rung has no time step"))
            if rung.planner is not None and rung.planner not in GEOMETRIC_PLANNERS:
                out.append(Problem(f"{key}.planner", f"geometric planners: {', '.join(GEOMETRIC_PLANNERS)}"))
            continue
        if rung.h is None:
            out.append(Problem(f"{key}.h", f"required: the {rung.model} rung needs a time step h > 0"))
        planner = rung.planner or ladder.planner
        which = f"{key}.planner" if rung.planner else "ladder.planner"
        if planner not in CONTROL_PLANNERS and all(p.key != which for p in out):  # (ladder.planner once, not once per rung)
            out.append(Problem(which, f"{planner!r} is not a control planner; use one of {', '.join(CONTROL_PLANNERS)}"))
        if rung.friction_cone == "exact":
            out += _exact_cone_problems(spec, rung, key)
        period = rung.control_period or ladder.control_period
        if rung.h is not None and rung.h > period:
            out.append(Problem(f"{key}.h", f"time step {rung.h} exceeds the control period {period}"))
    return out


#: The `[[ladder.rungs]]` settings of the contact physics, which the geometric rung (no
#: physics) does not read; the kinematic rung (no forces) reads none of them either.
PHYSICS_SETTINGS = ("theta", "friction_directions", "friction_cone", "inertia", "regularization", "contact_solver")


def _check_rung_settings(spec: ScenarioSpec) -> list[Problem]:
    """A setting given to a rung that does not read it is refused: the run would not be what the
    file says (an `inertia` on a dynamic rung, which keeps the bodies' own, would change nothing).
    Which rung reads what follows its physics in the family (`models.family`)."""
    out = []
    planar = spec.scene.dimension == 2
    for i, rung in enumerate(spec.ladder.rungs):
        given = [n for n in PHYSICS_SETTINGS if n in rung.model_fields_set]
        physics = definition(rung.model).physics
        why: dict[str, str] = {}
        if physics is None:
            why = dict.fromkeys(given, "the geometric rung is a validity check, with no physics to set")
        elif physics[0]:  # kinematic
            why = dict.fromkeys(given, "the kinematic rung has no forces, friction or inertia: it does not read this")
            why["contact_solver"] = "the kinematic rung always solves its contacts with Lemke"
        else:
            _, eps, compliant = physics[:3]
            if eps != 0.0:
                why["inertia"] = "a dynamic rung keeps the bodies' own inertia (this scales a quasistatic rung's)"
            if compliant:
                why["regularization"] = "rigid contact's setting: a compliant contact's K and C share a support's load already"
            if planar:
                why["friction_directions"] = "spatial scenes only: a planar friction cone has two directions"
                why["friction_cone"] = 'spatial scenes only: a planar cone (two directions) is exact; for PGS, contact_solver = "pgs"'
        out += [Problem(f"ladder.rungs[{i}].{name}", why[name]) for name in given if name in why]
    return out


def _check_limits(spec: ScenarioSpec, coordinates: list[str], start: list[float], dim: int) -> list[Problem]:
    """Start values within the drives' limits, reported where the value was written: the
    `[task] start` entry that overrides it, else the body's pose."""
    out = []
    for i, body in enumerate(spec.bodies):
        for dof, drive in body.actuators.items():
            name = f"{body.name}.{dof}"
            if name not in coordinates:
                continue
            value = start[coordinates.index(name)]
            if name in spec.task.start:
                key, where = key_path(("task", "start", name)), "task.start"
            else:
                key, where = _pose_key(body, i, dof, dim), "the body's pose"
            limits = f"bodies[{i}].actuators.{dof}"
            if drive.lower is not None and value < drive.lower:
                out.append(
                    Problem(key, f"{name} starts at {value:g} (from {where}), below its lower limit {drive.lower:g} ({limits}.lower)")
                )
            if drive.upper is not None and value > drive.upper:
                out.append(
                    Problem(key, f"{name} starts at {value:g} (from {where}), above its upper limit {drive.upper:g} ({limits}.upper)")
                )
    return out


def _pose_key(body: BodySpec, index: int, dof: str, dim: int) -> str:
    """The pose key a DOF's start value comes from (the pose itself when it is implicit)."""
    if dof in ("x", "y", "z", "theta"):
        return f"bodies[{index}].pose.{dof}"
    if dof == "yaw" and body.pose.rpy is not None:
        return f"bodies[{index}].pose.rpy[2]"
    return f"bodies[{index}].pose"


def _contact_pairs(spec: ScenarioSpec) -> tuple[ContactPair, ...]:
    overrides = {frozenset(p.bodies): p for p in spec.contact.pairs}
    pairs = []
    bodies = spec.bodies
    for i, a in enumerate(bodies):
        for b in bodies[i + 1 :]:
            if not _moves(a) and not _moves(b):
                continue  # two bodies that never move never meet anew
            o = overrides.get(frozenset((a.name, b.name)))
            if o is not None and not o.enabled:
                continue
            mu = o.mu if o is not None and o.mu is not None else spec.contact.mu
            K = o.K if o is not None and o.K is not None else spec.contact.K
            C = o.C if o is not None and o.C is not None else spec.contact.C
            pairs.append(ContactPair(a.name, b.name, mu, K, C))
    return tuple(pairs)


def _check_penetration(scenario: Scenario, start_overridden: set[str]) -> list[Problem]:
    placements = scenario.placements(scenario.start)
    index = {b.name: i for i, b in enumerate(scenario.spec.bodies)}
    out = []
    for pair in scenario.pairs:
        ga, gb = scenario.geometries[pair.body_a], scenario.geometries[pair.body_b]
        psi = geo.signed_distance(ga, placements[pair.body_a], gb, placements[pair.body_b])
        if psi < -PENETRATION_TOLERANCE:
            mover = pair.body_b if scenario.body(pair.body_b).dofs else pair.body_a
            key = "task.start" if mover in start_overridden else f"bodies[{index[mover]}].pose"
            out.append(Problem(key, f"{pair.body_a!r} and {pair.body_b!r} start in penetration (depth {-psi:.6g} m)"))
    return out


def _moments_problem(moments: list[float]) -> str | None:
    """What is wrong with a rigid body's principal moments (ascending): each is at most the sum of
    the other two (equal for a flat plate); None where none is."""
    if moments[2] > (moments[0] + moments[1]) * (1.0 + 1e-9):
        return (
            f"{moments[2]:g} is more than the sum of the other two ({moments[0]:g} + {moments[1]:g}); each is at most the sum of the others"
        )
    return None


def inertia_tensor(body) -> np.ndarray:
    """A spatial body's inertia tensor about its centre of mass in its own axes (3 x 3): the
    diagonal `inertia` (one number: the same three) and the off-diagonal `inertia_products`
    (Ixy, Ixz, Iyz; none: zero)."""
    diagonal = body.inertia * 3 if len(body.inertia) == 1 else body.inertia
    tensor = np.diag(np.array(diagonal, dtype=float))
    if body.inertia_products is not None:
        xy, xz, yz = (float(v) for v in body.inertia_products)
        tensor[0, 1], tensor[0, 2], tensor[1, 2] = xy, xz, yz
        tensor[1, 0], tensor[2, 0], tensor[2, 1] = xy, xz, yz
    return tensor


def principal_inertia(body) -> tuple[np.ndarray, np.ndarray | None]:
    """A spatial body's principal moments and axes: (moments (3,), axes) where axes (3 x 3, a
    rotation: its columns the principal axes in the body's own) turns the body's axes into its
    principal ones, I = axes diag(moments) axes^T; axes None where they are the body's own (no
    `inertia_products`), the moments then `inertia` as given (in its order, not sorted; a planar
    body's one moment three times)."""
    tensor = inertia_tensor(body)
    if body.inertia_products is None:
        return tensor.diagonal().copy(), None
    moments, axes = np.linalg.eigh(tensor)
    if np.linalg.det(axes) < 0.0:  # (a rotation, not a reflection)
        axes[:, 2] = -axes[:, 2]
    return moments, axes

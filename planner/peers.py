"""MuJoCo as a peer: a planar scenario built in MuJoCo from the loaded `Scenario`, stepped
and timed. The only module that imports mujoco (the optional extra ``peers``).

What maps to what (the plane of the scene is MuJoCo's x-y plane, z points out of it):

- gravity (gx, gy) -> (gx, gy, 0); the step h -> ``option/timestep``; the integrator is
  MuJoCo's default (Euler, implicit in joint damping only).
- halfplane {p : n.p <= offset} -> a plane geom through offset n whose z axis is n (a MuJoCo
  plane is solid below its z = 0);
- disc r -> sphere r (the plane z = 0 cuts it in the disc; the other shapes are prisms
  along z, so every contact normal stays in the plane);
- box (w, h) -> box (w/2, h/2, EXTRUSION/2); polygon -> mesh of the polygon extruded to
  z in [-EXTRUSION/2, EXTRUSION/2]; capsule (r, L) -> capsule from (-L/2, 0) to (L/2, 0).
- a body with DOFs: a MuJoCo body with one joint per DOF (slide x, slide y, hinge z, in that
  order, named like the coordinates, "finger1.y"), placed so that qpos *is* the scenario's
  coordinate; the body frame is the centre of mass (as in `models.kinematics`). Bodies
  without DOFs are bodies without joints (fixed to the world) at their pose.
- a drive (kp, kd, lower, upper) tracks q_ref, q_ref' = u clamped to [lower, upper], with
  force kp (q_ref - q) + kd (u - v). In MuJoCo: an integrator actuator (activation = q_ref,
  ``actrange`` = the limits, gain kp, bias -kp q), a feed-forward actuator (gain kd, force
  kd u) and joint damping kd (-kd v, which MuJoCo's Euler integrates implicitly, as our
  stepper does its drive damping). MuJoCo's position term is explicit (reference and position
  at the start of the step), ours implicit (both at the end); either tracks a ramp with no lag
  but the weight's sag m g / kp (tests/test_peers.py). ``ctrl`` holds u twice per drive
  (`Peer.ctrl`).
- contact pairs: every geom has contype = conaffinity = 0 and each scenario pair is an
  explicit ``<pair>``, condim 1 when mu = 0, else 3 with friction mu. Two contact laws
  (`CONTACT_MAPPINGS`):

  ``force`` (the default): the scene's force law f_n = K r + C r' in N/m and N s/m. MuJoCo's
  soft constraint with a constant impedance d and direct solref (-k, -b) gives, for d -> 0,
  f_n = (k r + b r') / ((1 - d) A~), A~ MuJoCo's diagonal approximation of the pair's
  inverse inertia (the two bodies' ``body_invweight0``). So solref = -(1 - d) A~ (K, C) and
  solimp = (d, d, ...), d = FORCE_IMPEDANCE, with the elliptic cone (MuJoCo's pyramidal
  cone would make the normal law depend on mu). The static force matches K r
  (tests/test_peers.py bounds the error). Friction is MuJoCo's soft Coulomb: viscous, f_t = -C v_t, up to the
  cone, so a resting contact creeps where ours sticks.

  ``direct``: solref = (-K, -C) with MuJoCo's default solimp (0.9, 0.95, 0.001, 0.5, 2) and
  cone (pyramidal): K and C read literally as MuJoCo's direct stiffness and damping, which
  are per unit effective mass, and the impedance d ~ 0.9 makes the constraint nearly rigid
  (its static stiffness on the paper's finger-triangle pair: docs/measurements.md).

  Neither is our model: MuJoCo's contact damping is explicit (the reference acceleration
  uses r and r' at the start of the step), ours is implicit in K and C. With the force
  mapping that bounds the step: h C / m_eff < 2, m_eff the pair's effective mass (0.18 kg
  for a finger on the triangle's face: h < 3.6e-5; at h = 1e-4 the fingers bounce off).

Inert pairs: a frictionless half-plane and a body that can only slide along its boundary
(the paper's triangle, free in x only, resting on the palm) exert no force on any free
DOF. Our stepper drops such contacts (a zero Jacobian column); MuJoCo solves their rows
every step. ``build(..., drop_inert=True)`` leaves those pairs out (`inert_pairs`): the
same trajectory (tests/test_peers.py), fewer constraint rows.

Spatial scenes (`build_spatial`, e.g. box_push_3d) map with MuJoCo's own contact model, as
the issue's comparison did: each scenario pair an explicit ``<pair>`` with friction mu
(condim 3) and MuJoCo's default solref, solimp and (pyramidal) cone; our rigid rungs have no
K or C to map. plane {p : n.p <= offset} -> a plane geom; box -> box (half sizes); sphere ->
sphere; convex mesh -> a mesh asset from the same OBJ file (scaled); a body with the DOFs
x, y, z and rotation -> a free joint (qpos = x, y, z, qw, qx, qy, qz: the scenario's q); a
body with translations only -> slide joints along the world axes; fixed bodies and the
bodies' start placements come from `Scenario.placements`. Drives as in the plane.

Unsupported scenario features (scripted obstacle velocities, actuator force limits; in space
also DOF sets other than translations or all six) raise ValueError in `build` /
`build_spatial`.
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from models.scenario import Scenario, inertia_tensor

#: Constant impedance d of the ``force`` contact mapping: the static force is K r (1 - O(d)).
FORCE_IMPEDANCE = 1e-3
#: Thickness of the prisms standing in for polygons and boxes (m): more than any sphere's
#: diameter in the shipped scenes, so a disc never meets a prism's end caps.
EXTRUSION = 1.0
#: Inertia (kg m^2, times the mass) given to bodies without a free rotation: no joint
#: lets it act; MuJoCo only needs a positive value.
PLACEHOLDER_INERTIA = 1e-3
#: The two contact laws (module docstring).
CONTACT_MAPPINGS = ("force", "direct")
#: MuJoCo's warnings that mean the state blew up.
DIVERGENCE_WARNINGS = ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC")

_AXES = {"x": ("slide", "1 0 0"), "y": ("slide", "0 1 0"), "theta": ("hinge", "0 0 1")}
_AXES_3D = {"x": ("slide", "1 0 0"), "y": ("slide", "0 1 0"), "z": ("slide", "0 0 1")}


def version() -> str:
    return mujoco.__version__


@dataclass(frozen=True)
class Peer:
    """A scenario compiled in MuJoCo (`build`): qpos is the scenario's q (same names, same
    order), ctrl is `ctrl(u)`; ``xml`` is the MJCF."""

    scenario: Scenario
    h: float
    contact: str
    xml: str
    model: mujoco.MjModel
    dropped: tuple[str, ...] = ()  # inert pairs left out, "a-b"

    def ctrl(self, u: np.ndarray) -> np.ndarray:
        """MuJoCo's ctrl for commanded speeds u (one per `scenario.actuated`)."""
        return np.repeat(np.asarray(u, float), 2)

    def reset(self, data: mujoco.MjData, u: np.ndarray) -> None:
        """Start state (the keyframe: the scenario's start, references at the start) and u."""
        mujoco.mj_resetDataKeyframe(self.model, data, 0)
        data.ctrl[:] = self.ctrl(u)

    def q(self, data: mujoco.MjData) -> np.ndarray:
        return data.qpos.copy()


@dataclass(frozen=True)
class PeerRun:
    """A recorded run (`run`): times (n,) and q (n, nq) every `period`, MuJoCo's warnings that
    say the state blew up, whether the last state is finite, and the steps taken."""

    times: np.ndarray
    q: np.ndarray
    diverged: tuple[str, ...]
    finite: bool
    steps: int


def build(scenario: Scenario, h: float, contact: str = "force", drop_inert: bool = False) -> Peer:
    """Compile `scenario` in MuJoCo at step h with a contact mapping of CONTACT_MAPPINGS,
    leaving out the `inert_pairs` if drop_inert.

    Raises ValueError for what the mapping does not cover (module docstring)."""
    if contact not in CONTACT_MAPPINGS:
        raise ValueError(f"contact mapping {contact!r} is not one of {CONTACT_MAPPINGS}")
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"step h = {h} is not a positive number")
    _check_supported(scenario)
    # the force mapping needs MuJoCo's inverse weights, which the compiler computes: compile
    # once with any solref, read them, compile again
    dropped = inert_pairs(scenario) if drop_inert else ()
    weights = None
    if contact == "force":
        probe = mujoco.MjModel.from_xml_string(mjcf(scenario, h, "direct"))
        weights = {body.name: _body_weight(probe, body.name) for body in scenario.spec.bodies}
    xml = mjcf(scenario, h, contact, weights, dropped)
    model = mujoco.MjModel.from_xml_string(xml)
    joints = tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt))
    if joints != tuple(scenario.coordinates):  # qpos must be the scenario's q
        raise ValueError(f"{scenario.path}: MuJoCo joints {joints} are not the coordinates {scenario.coordinates}")
    # a diverged state stays diverged (MuJoCo's default resets it silently; older MuJoCo lacks the flag)
    autoreset = getattr(mujoco.mjtDisableBit, "mjDSBL_AUTORESET", None)
    if autoreset is not None:
        model.opt.disableflags |= int(autoreset)
    return Peer(scenario, h, contact, xml, model, tuple(f"{p.body_a}-{p.body_b}" for p in dropped))


def inert_pairs(scenario: Scenario) -> tuple:
    """The contact pairs no free DOF can feel: a fixed frictionless half-plane and a body whose
    only DOFs are translations along the half-plane's boundary (normal . axis = 0, no rotation).
    (With friction MuJoCo would still apply it: its normal force does not vanish with the
    Jacobian row.)"""
    bodies = {b.name: b for b in scenario.spec.bodies}
    out = []
    for pair in scenario.pairs:
        a, b = bodies[pair.body_a], bodies[pair.body_b]
        plane, other = (a, b) if a.shape.type == "halfplane" else (b, a)
        if pair.mu > 0 or plane.shape.type != "halfplane" or plane.dofs or not other.dofs or "theta" in other.dofs:
            continue
        c, s = math.cos(plane.pose.theta or 0.0), math.sin(plane.pose.theta or 0.0)
        nx, ny = plane.shape.normal
        normal = np.array([c * nx - s * ny, s * nx + c * ny])
        axes = {"x": np.array([1.0, 0.0]), "y": np.array([0.0, 1.0])}
        if all(abs(float(normal @ axes[dof])) <= 1e-12 * np.linalg.norm(normal) for dof in other.dofs):
            out.append(pair)
    return tuple(out)


def _unmapped(body) -> list[str]:
    """What of a body the MuJoCo builds do not map (planar and spatial alike)."""
    problems = [f"{body.name}: scripted obstacle velocities are not mapped"] if body.velocity else []
    for dof, drive in body.actuators.items():
        if drive.max_force is not None:
            problems.append(f"{body.name}.actuators.{dof}: max_force is not mapped")
    return problems


def _check_supported(scenario: Scenario) -> None:
    problems = []
    if scenario.dimension != 2:
        problems.append("the MuJoCo peer builds planar scenes only")
    for body in scenario.spec.bodies:
        problems += _unmapped(body)
        for dof in body.dofs:
            if dof not in _AXES:
                problems.append(f"{body.name}: DOF {dof!r} is not planar")
    if problems:
        raise ValueError(f"{scenario.path}: " + "; ".join(problems))


def _body_weight(model: mujoco.MjModel, name: str) -> float:
    """MuJoCo's translational inverse weight of a body (0 for one without joints)."""
    bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    return float(model.body_invweight0[bid, 0]) if bid >= 0 else 0.0


def mjcf(scenario: Scenario, h: float, contact: str, weights: dict[str, float] | None = None, leave_out=()) -> str:
    """The MJCF of `scenario` (module docstring). `weights`: each body's MuJoCo inverse weight,
    needed by the force mapping; `leave_out`: contact pairs not to write."""
    gx, gy = scenario.spec.scene.gravity
    cone = "elliptic" if contact == "force" else "pyramidal"
    assets, world = [], []
    start = dict(zip(scenario.coordinates, scenario.start))
    for body in scenario.spec.bodies:
        dofs = [dof for dof in _AXES if dof in body.dofs]  # the coordinates' order within a body
        # a fixed rotation turns the geom, not the body: slide axes stay the world's
        geom, asset = _geom(body, 0.0 if "theta" in dofs else (body.pose.theta or 0.0))
        assets += asset
        placed = f'name="{body.name}" pos="{_pos(body, dofs)}"'
        if not dofs:
            world.append(f"    <body {placed}>{geom}</body>")
            continue
        joints = "".join(_joint(body, dof) for dof in dofs)
        inertia = body.inertia[0] if body.inertia else PLACEHOLDER_INERTIA * body.mass
        world.append(
            f"    <body {placed}>{joints}"
            f'<inertial pos="0 0 0" mass="{_n(body.mass)}" diaginertia="{_n(inertia, inertia, inertia)}"/>{geom}</body>'
        )
    actuators = _actuators(scenario)
    pairs = [_pair(scenario, pair, contact, weights) for pair in scenario.pairs if pair not in leave_out]
    qpos = _n(*(start[c] for c in scenario.coordinates))
    act = _n(*(start[c] for c in scenario.actuated))
    option = f'timestep="{_n(h)}" gravity="{_n(gx, gy, 0.0)}" cone="{cone}"'
    return _mjcf_document(scenario, option, assets, world, pairs, actuators, qpos, act)


def _mjcf_document(scenario: Scenario, option: str, assets, world, pairs, actuators, qpos: str, act: str) -> str:
    """An MJCF model from its parts (the planar and the spatial builds share it)."""
    key = f'<key qpos="{qpos}"' + (f' act="{act}"' if act else "") + "/>"
    return "\n".join(
        [
            f'<mujoco model="{scenario.spec.scenario.name}">',
            '  <compiler angle="radian"/>',
            f"  <option {option}/>",
            "  <asset>",
            *assets,
            "  </asset>",
            "  <worldbody>",
            *world,
            "  </worldbody>",
            "  <contact>",
            *pairs,
            "  </contact>",
            "  <actuator>",
            *actuators,
            "  </actuator>",
            f"  <keyframe>{key}</keyframe>",
            "</mujoco>",
        ]
    )


def _n(*values) -> str:
    """Numbers as MJCF writes them: space-separated, full precision."""
    return " ".join(repr(float(v)) for v in values)


def _pos(body, dofs) -> str:
    """Body position: the pose, except along DOFs (their joint carries the coordinate)."""
    return _n(0.0 if "x" in dofs else body.pose.x, 0.0 if "y" in dofs else body.pose.y, 0.0)


def _joint(body, dof: str, axes=_AXES) -> str:
    kind, axis = axes[dof]
    drive = body.actuators.get(dof)
    damping = f' damping="{_n(drive.kd)}"' if drive is not None else ""
    return f'<joint name="{body.name}.{dof}" type="{kind}" axis="{axis}"{damping}/>'


def _actuators(scenario: Scenario) -> list[str]:
    """Each drive as MuJoCo actuators, in ctrl order (the scenario's actuated coordinates): an
    integrator whose state is the reference position, with the drive's stiffness, and the
    commanded speed through the damping as a feed-forward (`Peer.ctrl`)."""
    actuators = []
    for name in scenario.actuated:
        body_name, dof = name.rsplit(".", 1)
        drive = scenario.body(body_name).actuators[dof]
        actuators.append(
            f'    <general name="{name}" joint="{name}" dyntype="integrator" gainprm="{_n(drive.kp)}" biastype="affine" '
            f'biasprm="{_n(0.0, -drive.kp, 0.0)}"{_actrange(drive)}/>\n'
            f'    <general name="{name}.feedforward" joint="{name}" gainprm="{_n(drive.kd)}"/>'
        )
    return actuators


def _actrange(drive) -> str:
    if drive.lower is None and drive.upper is None:
        return ""
    lo = -1e10 if drive.lower is None else drive.lower
    hi = 1e10 if drive.upper is None else drive.upper
    return f' actlimited="true" actrange="{_n(lo, hi)}"'


def _geom(body, theta: float) -> tuple[str, list[str]]:
    """(geom element, asset elements) of a body's shape in its body frame, turned by theta."""
    s = body.shape
    c, si = math.cos(theta), math.sin(theta)
    turn = np.array([[c, -si], [si, c]])
    base = f'<geom name="{body.name}" contype="0" conaffinity="0"'
    if s.type == "halfplane":
        n = turn @ (np.array(s.normal, float) / np.linalg.norm(s.normal))
        p = s.offset * n
        return f'{base} type="plane" size="0 0 1" pos="{_n(p[0], p[1], 0.0)}" zaxis="{_n(n[0], n[1], 0.0)}"/>', []
    if s.type == "disc":
        return f'{base} type="sphere" size="{_n(s.radius)}"/>', []
    if s.type == "box":
        return f'{base} type="box" size="{_n(s.size[0] / 2, s.size[1] / 2, EXTRUSION / 2)}" euler="{_n(0.0, 0.0, theta)}"/>', []
    if s.type == "capsule":
        a, b = turn @ [-s.length / 2, 0.0], turn @ [s.length / 2, 0.0]
        return f'{base} type="capsule" size="{_n(s.radius)}" fromto="{_n(a[0], a[1], 0.0, b[0], b[1], 0.0)}"/>', []
    if s.type == "polygon":
        z = EXTRUSION / 2
        vertex = _n(*(v for sz in (-z, z) for x, y in (turn @ np.array(s.vertices, float).T).T for v in (x, y, sz)))
        return f'{base} type="mesh" mesh="{body.name}.prism"/>', [f'    <mesh name="{body.name}.prism" vertex="{vertex}"/>']
    raise ValueError(f"{body.name}: shape {s.type!r} is not mapped to MuJoCo")


def _pair(scenario: Scenario, pair, contact: str, weights) -> str:
    friction = f' condim="3" friction="{_n(pair.mu, pair.mu, 0.005, 0.0001, 0.0001)}"' if pair.mu > 0 else ' condim="1"'
    if contact == "force":
        d = FORCE_IMPEDANCE
        scale = (1.0 - d) * (weights[pair.body_a] + weights[pair.body_b])
        law = f'solref="{_n(-scale * pair.K, -scale * pair.C)}" solimp="{_n(d, d, 0.001, 0.5, 2)}"'
    else:
        law = f'solref="{_n(-pair.K, -pair.C)}"'
    return f'    <pair geom1="{pair.body_a}" geom2="{pair.body_b}"{friction} {law}/>'


# ----------------------------------------------------------------------------- space


def build_spatial(scenario: Scenario, h: float) -> Peer:
    """Compile a spatial `scenario` in MuJoCo at step h with MuJoCo's own contact model (module
    docstring): qpos is the scenario's q, ctrl is `Peer.ctrl(u)`. Raises ValueError for what
    the mapping does not cover."""
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"step h = {h} is not a positive number")
    problems = [] if scenario.dimension == 3 else ["build_spatial maps spatial scenes only"]
    for body in scenario.spec.bodies:
        problems += _unmapped(body)
        dofs = set(body.dofs)
        if dofs and not (dofs <= set(_AXES_3D) or dofs == {"x", "y", "z", "rotation"}):
            problems.append(f"{body.name}: DOFs {sorted(dofs)} are not mapped (translations, or all six)")
    if problems:
        raise ValueError(f"{scenario.path}: " + "; ".join(problems))
    xml = mjcf_spatial(scenario, h)
    model = mujoco.MjModel.from_xml_string(xml)
    if model.nq != len(scenario.coordinates):
        raise ValueError(f"{scenario.path}: MuJoCo has {model.nq} qpos, the scenario {len(scenario.coordinates)} coordinates")
    autoreset = getattr(mujoco.mjtDisableBit, "mjDSBL_AUTORESET", None)
    if autoreset is not None:
        model.opt.disableflags |= int(autoreset)
    return Peer(scenario, h, "mujoco", xml, model)


def mjcf_spatial(scenario: Scenario, h: float) -> str:
    """The MJCF of a spatial `scenario` (module docstring)."""
    gx, gy, gz = scenario.spec.scene.gravity
    start = scenario.placements(np.asarray(scenario.start, float))
    base = Path(scenario.path).resolve().parent if scenario.path is not None else None
    assets, world = [], []
    for body in scenario.spec.bodies:
        place = start[body.name]
        geom, asset = _geom_3d(body, base)
        assets += asset
        if not body.dofs:  # fixed: the geom where the body is
            world.append(
                f'    <body name="{body.name}" pos="{_n(*place.translation)}" quat="{_n(*_quaternion(place.rotation))}">{geom}</body>'
            )
            continue
        if "rotation" in body.dofs:
            joints = f'<freejoint name="{body.name}"/>'
            pos, quat = place.translation, _quaternion(place.rotation)
            # with products of inertia MuJoCo's fullinertia (the tensor's diagonal, then Ixy, Ixz, Iyz)
            tensor = inertia_tensor(body)
            inertial = f'diaginertia="{_n(*tensor.diagonal())}"'
            if body.inertia_products is not None:
                inertial = f'fullinertia="{_n(*tensor.diagonal(), *body.inertia_products)}"'
        else:  # slides along the world axes: the body sits at its pose off its DOFs' axes
            joints = "".join(_joint(body, dof, _AXES_3D) for dof in ("x", "y", "z") if dof in body.dofs)
            pos = [0.0 if axis in body.dofs else value for axis, value in zip("xyz", place.translation)]
            quat = _quaternion(place.rotation)
            inertial = f'diaginertia="{_n(*(PLACEHOLDER_INERTIA * body.mass,) * 3)}"'
        world.append(
            f'    <body name="{body.name}" pos="{_n(*pos)}" quat="{_n(*quat)}">{joints}'
            f'<inertial pos="0 0 0" mass="{_n(body.mass)}" {inertial}/>{geom}</body>'
        )
    actuators = _actuators(scenario)
    pairs = [
        f'    <pair geom1="{p.body_a}" geom2="{p.body_b}"'
        + (f' condim="3" friction="{_n(p.mu, p.mu, 0.005, 0.0001, 0.0001)}"/>' if p.mu > 0 else ' condim="1"/>')
        for p in scenario.pairs
    ]
    start_q = dict(zip(scenario.coordinates, scenario.start))
    act = _n(*(start_q[c] for c in scenario.actuated))
    option = f'timestep="{_n(h)}" gravity="{_n(gx, gy, gz)}"'
    return _mjcf_document(scenario, option, assets, world, pairs, actuators, _n(*scenario.start), act)


def _quaternion(R: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix (MuJoCo's quat attribute)."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(R, float).ravel())
    return quat


def _geom_3d(body, base) -> tuple[str, list[str]]:
    """(geom element in the body frame, asset elements) of a spatial shape."""
    s = body.shape
    head = f'<geom name="{body.name}" contype="0" conaffinity="0"'
    if s.type == "plane":  # {p : n.p <= offset}: MuJoCo's plane is solid below its z = 0
        n = np.array(s.normal, float) / np.linalg.norm(s.normal)
        return f'{head} type="plane" size="0 0 1" pos="{_n(*(s.offset * n))}" zaxis="{_n(*n)}"/>', []
    if s.type == "sphere":
        return f'{head} type="sphere" size="{_n(s.radius)}"/>', []
    if s.type == "box":
        return f'{head} type="box" size="{_n(*(np.array(s.size, float) / 2))}"/>', []
    if s.type == "mesh":
        path = (base / s.file) if base is not None else s.file
        return f'{head} type="mesh" mesh="{body.name}.mesh"/>', [
            f'    <mesh name="{body.name}.mesh" file="{path}" scale="{_n(s.scale, s.scale, s.scale)}"/>'
        ]
    raise ValueError(f"{body.name}: shape {s.type!r} is not mapped to MuJoCo")


# ----------------------------------------------------------------------------- running


@contextlib.contextmanager
def _warnings_to(sink: list[str]):
    """Collect MuJoCo's warning texts instead of printing them (restored afterwards)."""
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda text: sink.append(text))
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


def timed_run(
    peer: Peer, u: np.ndarray, steps: int, data: mujoco.MjData | None = None, *, after: int = 0, per_call: int = 0
) -> tuple[float, np.ndarray]:
    """(wall seconds, q at the end) of `steps` steps with commanded speeds u, from the start
    state stepped on `after` untimed steps. Only the stepping is timed: one call into MuJoCo
    (``mj_step(nstep=...)``), or calls of `per_call` steps each (as a planner calls a
    simulator, one control period a call), nothing checked on the way. Pass `data` to reuse
    its memory."""
    data = mujoco.MjData(peer.model) if data is None else data
    with _warnings_to([]):
        peer.reset(data, u)
        if after:
            mujoco.mj_step(peer.model, data, nstep=after)
        chunk = per_call if per_call > 0 else steps
        t0 = time.perf_counter()
        for done in range(0, steps, chunk):
            mujoco.mj_step(peer.model, data, nstep=min(chunk, steps - done))
        wall = time.perf_counter() - t0
    return wall, peer.q(data)


def run(peer: Peer, u: np.ndarray, duration: float, period: float = 1e-3) -> PeerRun:
    """Run commanded speeds u for `duration`, recording q every `period` (rounded to whole
    steps). Stops early once the state is not finite."""
    data = mujoco.MjData(peer.model)
    chunk = max(1, int(round(period / peer.h)))
    n = int(round(duration / peer.h))
    times, qs, texts = [0.0], [], []
    with _warnings_to(texts):
        peer.reset(data, u)
        qs.append(peer.q(data))
        done = 0
        while done < n:
            k = min(chunk, n - done)
            mujoco.mj_step(peer.model, data, nstep=k)
            done += k
            times.append(done * peer.h)
            qs.append(peer.q(data))
            if not np.all(np.isfinite(data.qpos)):
                break
    diverged = tuple(w for w in DIVERGENCE_WARNINGS if data.warning[int(getattr(mujoco.mjtWarning, w))].number > 0)
    return PeerRun(np.array(times), np.array(qs), diverged, bool(np.all(np.isfinite(data.qpos))), done)


def contact_forces(peer: Peer, data: mujoco.MjData) -> dict[tuple[str, str], float]:
    """Normal force of each active contact pair at `data` (after mj_forward), summed over
    its contact points, keyed by the two body names in the scenario's pair order."""
    out: dict[tuple[str, str], float] = {}
    wrench = np.zeros(6)
    for i in range(data.ncon):
        c = data.contact[i]
        if c.efc_address < 0:
            continue
        mujoco.mj_contactForce(peer.model, data, i, wrench)
        a = mujoco.mj_id2name(peer.model, mujoco.mjtObj.mjOBJ_GEOM, c.geom1)  # geoms are named after their bodies
        b = mujoco.mj_id2name(peer.model, mujoco.mjtObj.mjOBJ_GEOM, c.geom2)
        key = next((p.body_a, p.body_b) for p in peer.scenario.pairs if {p.body_a, p.body_b} == {a, b})
        out[key] = out.get(key, 0.0) + float(wrench[0])
    return out


def geom_distance(peer: Peer, data: mujoco.MjData, a: str, b: str, limit: float = 10.0) -> float:
    """MuJoCo's signed distance between bodies a and b (their geoms) at `data`, up to limit."""
    ga = mujoco.mj_name2id(peer.model, mujoco.mjtObj.mjOBJ_GEOM, a)
    gb = mujoco.mj_name2id(peer.model, mujoco.mjtObj.mjOBJ_GEOM, b)
    return float(mujoco.mj_geomDistance(peer.model, data, ga, gb, limit, None))

"""Planar stress scenes built from templates, and the invariants every stress run must keep."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from models.rungs import rung_for
from models.scenario import load_scenario
from models.stepper import StepStatus

#: Rigid rungs: the bound on the gap's second derivative along a step (m/s^2) behind the
#: penetration a run may show. The time-stepper keeps the predicted gap psi + h W^T v >= 0
#: with psi and W taken at the step's start, so what remains is the gap's linearization
#: remainder, at most 0.5 h^2 psi'': gravity and, for a rotating body, the angular speed
#: squared times the lever arm (a 0.25 x 0.5 m box tipping at 5.6 rad/s onto a disc at
#: h = 1e-2 shows 1.5e-3 m, 30 m/s^2; test_stress.py: test_penetration_is_second_order_in_h).
RIGID_GAP_CURVATURE = 200.0
#: Energy may not grow by more than this (J) plus rounding relative to its size.
ENERGY_TOL = 1e-9


def rigid_penetration_tol(h: float) -> float:
    """The largest penetration (m) a rigid run at step h may show: 0.5 h^2 RIGID_GAP_CURVATURE
    (1e-4 m at h = 1e-3)."""
    return 0.5 * h * h * RIGID_GAP_CURVATURE


HEADER = """
version = 1
[scenario]
name = "stress"
[scene]
dimension = 2
gravity = [0.0, {g}]
[contact]
mu = {mu}
K = {K}
C = {C}
[[bodies]]
name = "floor"
role = "obstacle"
shape = {{ type = "halfplane", normal = [0.0, 1.0] }}
"""

FOOTER = """
[task]
horizon = 1e6
goal = {{ box = {{ "{first}.x" = [1e5, 2e5] }} }}
[ladder]
time_limit = 1.0
[[ladder.rungs]]
model = "dynamic-rigid"
h = 1e-3
"""


def body(name: str, shape: str, x: float, y: float, theta: float = 0.0, mass: float = 1.0, inertia: float | None = None) -> str:
    inertia_line = f"inertia = {inertia!r}\n" if inertia is not None else ""
    return (
        f'[[bodies]]\nname = "{name}"\nrole = "object"\nmass = {mass!r}\n{inertia_line}shape = {shape}\n'
        f'pose = {{ x = {x!r}, y = {y!r}, theta = {theta!r} }}\ndofs = ["x", "y", "theta"]\n'
    )


def box_shape(w: float, h: float) -> str:
    return f'{{ type = "box", size = [{w!r}, {h!r}] }}'


def disc_shape(r: float) -> str:
    return f'{{ type = "disc", radius = {r!r} }}'


def scene(tmp_path: Path, bodies: list[str], *, mu=0.5, K=1e6, C=1e4, g=-9.81, name="stress"):
    path = tmp_path / f"{name}.toml"
    first = bodies[0].split('"')[1]
    path.write_text(HEADER.format(g=g, mu=mu, K=K, C=C) + "\n".join(bodies) + FOOTER.format(first=first))
    return load_scenario(path)


def box_inertia(m: float, w: float, h: float) -> float:
    return m * (w * w + h * h) / 12


def energy(scenario, q: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """Mechanical energy (kinetic 0.5 nu' M nu + gravitational) of a planar scene along
    records (n, nq), with the compiled scene's mass matrix."""
    from models.rungs import compiled
    from models.stepper import mass_matrix

    S = compiled(scenario).scene
    M = mass_matrix(S.bi, S.bf, q[0], S.nv)
    g = -scenario.spec.scene.gravity[1]
    kinetic = 0.5 * np.einsum("ni,ij,nj->n", nu, M, nu)
    potential = np.zeros(len(q))
    for b in scenario.spec.bodies:
        if b.dofs:
            iy = scenario.coordinates.index(f"{b.name}.y")
            potential += M[scenario.velocities.index(f"{b.name}.y"), scenario.velocities.index(f"{b.name}.y")] * g * q[:, iy]
    return kinetic + potential


def run(scenario, rung_name: str, h: float, duration: float, *, controls=None, every: int = 1, stop=False, state=None):
    rung = rung_for(scenario, rung_name)
    u = np.zeros((1, len(scenario.actuated))) if controls is None else np.atleast_2d(controls)
    steps = int(round(duration / h))
    start = state if state is not None else rung.initial_state(scenario)
    return rung.rollout(scenario, start, u, [duration], h, record_every=every, max_records=steps // every + 3, stop_at_outcome=stop)


def check_invariants(result, *, h: float, rigid: bool, passive: bool, scenario=None, energy_from: int = 0) -> None:
    """No non-finite number, every failure a known status, rigid penetration (run at step h)
    below rigid_penetration_tol(h), energy never increasing in passive rigid scenes (checked record to record)."""
    assert result.status in {s.label for s in StepStatus}, result.status
    for array in (result.state.q, result.state.nu, result.trajectory, result.velocities):
        assert np.all(np.isfinite(array)), "non-finite numbers in a run"
    if result.status != "ok":
        assert result.message  # carried as a status with its reason
        return
    if rigid:
        assert result.max_penetration <= rigid_penetration_tol(h), (result.max_penetration, h)
    if passive and rigid and scenario is not None:
        E = energy(scenario, result.trajectory, result.velocities)[energy_from:]
        scale = max(1.0, float(np.max(np.abs(E))))
        growth = float(np.max(np.diff(E))) if len(E) > 1 else 0.0
        assert growth <= ENERGY_TOL + 1e-12 * scale, f"energy grew by {growth:.3e} J in one record"

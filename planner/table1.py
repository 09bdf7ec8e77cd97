"""The paper's Table 1 in numbers: each model reduction measured on the paper's scene.

Table 1 says which definition of reduction links four pairs of models: compliant dynamic ->
rigid dynamic, compliant dynamic -> rigid quasistatic and rigid dynamic -> rigid quasistatic
by Definition 2 (singular perturbation: K -> infinity, eps -> 0), rigid quasistatic ->
kinematic by Definition 1 (for every input of the reduced model and every sigma > 0 some
input of the full model keeps the trajectories within sigma). Here each row is measured:

- Definition 2 rows: the full model is run with a scale s in `SCALES` (s = 1: the scene's
  own K, C and eps = 1), K = K0 / s and C = C0 / s (fixed relaxation time C / K, so the
  compliance 1 / (h (h K + C)) vanishes like s) and, where the row's limit is quasistatic,
  eps = s; its distance to the limit model's trajectory (same input, same h) should shrink
  as s -> 0. The rate is the least-squares slope of log distance against log s.
- Definition 1 row: for each kinematic input tried (constant finger speeds at the ratios
  `INPUT_RATIOS`), the quasistatic model is given the same input; the distance until the
  kinematic run's outcome (goal or unsafe), and over the whole horizon (the models go on
  after the outcome), with the best of a small grid of other constant inputs where the same
  input is not within sigma. The residual distance under the same input is the drives'
  gravity sag m g / kp (the quasistatic fingers are position-driven, the kinematic ones move
  exactly): stiffening the drives (kp = kp0 / s, kd = kd0 / sqrt(s), same damping ratio)
  is this row's sequence.

The distance between two trajectories is the largest difference of any configuration
coordinate (m) at any common recorded time: the paper's ||kappa(x(t)) - y(t)|| with kappa the
projection to the configuration (`models.rungs.Rung.project`) and the max norm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from models.rungs import RolloutResult, rung_for
from models.scenario import load_scenario

SCENE = Path(__file__).resolve().parent.parent / "scenarios" / "two_finger_triangle.toml"
#: The Definition 2 runs: finger 1 at RATIO times finger 2's speed (1 m/s), mu as the paper's
#: Fig. 4, for HORIZON s at step STEP: finger 2 touches at 1.48 s and pushes the triangle
#: until the grasp forms at about 1.64 s, so the runs cover the approach, the impact and the push.
RATIO = 0.8
MU = 0.5
HORIZON = 1.6
STEP = 1e-4
#: The scales s -> 0 of the Definition 2 rows (and of the drives in the Definition 1 row).
SCALES = (1.0, 1e-1, 1e-2, 1e-3, 1e-4)
#: Definition 1: the kinematic inputs tried (finger speed ratios, finger 2 at 1 m/s), over
#: DEF1_HORIZON s at the quasistatic rung's step DEF1_STEP; the sigmas reported.
INPUT_RATIOS = (0.5, 0.8, 1.0, 1.25, 2.0)
DEF1_HORIZON = 2.5
DEF1_STEP = 1e-3
SIGMAS = (1e-2, 1e-3, 1e-4)
#: Other constant quasistatic inputs tried where the same input is not within the largest
#: sigma: each finger's kinematic speed times each of these factors.
INPUT_FACTORS = (0.5, 0.75, 1.0, 1.5, 2.0)


@dataclass(frozen=True)
class Row:
    """One Definition 2 row of Table 1: `source` (the full model, a rung name) with the scale
    s applied to K and C (`stiffens`) and to eps (`vanishing_inertia`), against `limit`."""

    source_label: str
    limit_label: str
    source: str
    limit: str
    stiffens: bool
    vanishing_inertia: bool

    @property
    def parameter(self) -> str:
        parts = (["K = K0 / s, C = C0 / s"] if self.stiffens else []) + (["eps = s"] if self.vanishing_inertia else [])
        return ", ".join(parts)


ROWS = (
    Row("compliant, dynamic", "rigid, dynamic", "dynamic-compliant", "dynamic-rigid", True, False),
    Row("compliant, dynamic", "rigid, quasistatic", "dynamic-compliant", "quasistatic-rigid", True, True),
    Row("rigid, dynamic", "rigid, quasistatic", "dynamic-rigid", "quasistatic-rigid", False, True),
)


@dataclass(frozen=True)
class Convergence:
    """Distances of a sequence of models from their limit, one per scale (m), and the fitted
    rate p of distance ~ c s^p (nan with fewer than two positive distances). statuses: each
    run's status (a run that failed is reported, not fitted)."""

    label: str
    parameter: str
    scales: tuple[float, ...]
    distances: tuple[float, ...]
    statuses: tuple[str, ...]
    rate: float

    @property
    def monotone(self) -> bool:
        return all(b < a for a, b in zip(self.distances, self.distances[1:]))


@dataclass(frozen=True)
class InputCheck:
    """Definition 1 for one kinematic input: the kinematic run's outcome and its time, the
    quasistatic run's distance from it under the same input until then and over the whole
    horizon, and the best whole-horizon distance of the other constant inputs tried (None:
    not tried, the same input was within the largest sigma)."""

    ratio: float
    outcome: str
    outcome_time: float
    until_outcome: float
    whole_horizon: float
    best_other: float | None
    best_other_input: tuple[float, float] | None
    kinematic_status: str  # "ok", or "blocked" where the kinematic model cannot go on (the grasp)
    kinematic_end: tuple[float, ...]  # last configurations both runs recorded
    quasistatic_end: tuple[float, ...]


@dataclass(frozen=True)
class Table1:
    rows: tuple[Convergence, ...]
    drives: Convergence
    inputs: tuple[InputCheck, ...]
    sag: float  # m g / kp of the scene's fingers, m


def trajectory_distance(a: RolloutResult, b: RolloutResult, until: float = math.inf) -> float:
    """Largest configuration difference (max norm, m) of two rollouts at their common recorded
    times up to `until` (s). The runs must record the same times (same h, duration and
    recording); ValueError otherwise."""
    n = min(len(a.times), len(b.times))
    if n == 0 or not np.allclose(a.times[:n], b.times[:n], rtol=0.0, atol=1e-9):
        raise ValueError("the two rollouts do not record the same times; run them with the same h, duration and recording")
    keep = a.times[:n] <= until + 1e-12
    return float(np.max(np.abs(a.trajectory[:n][keep] - b.trajectory[:n][keep]), initial=0.0))


def fitted_rate(scales, distances) -> float:
    """Least-squares slope of log(distance) against log(scale): p in distance ~ c scale^p
    (positive: the distance vanishes as the scale does). nan with fewer than two positive
    finite points."""
    s, d = np.asarray(scales, float), np.asarray(distances, float)
    ok = (s > 0) & (d > 0) & np.isfinite(d)
    if ok.sum() < 2:
        return math.nan
    return float(np.polyfit(np.log(s[ok]), np.log(d[ok]), 1)[0])


def _rollout(rung_name: str, overrides: dict, controls, horizon: float, h: float, eps: float | None = None, stop: bool = False):
    scenario = load_scenario(SCENE, overrides)
    rung = rung_for(scenario, rung_name)
    if eps is not None:
        rung = replace(rung, model=rung.model._replace(eps=eps))
    return rung.rollout(scenario, rung.initial_state(scenario), np.array(controls, float), [horizon], h, stop_at_outcome=stop)


def _ran(kinematic: RolloutResult) -> bool:
    """A kinematic run ends 'blocked' where its commanded speeds would penetrate what nothing
    can push away (both fingers on the triangle once the grasp forms): its trajectory up to
    there is its whole run; any other failure is one."""
    return kinematic.ok or kinematic.status == "blocked"


def definition2_row(row: Row, scales=SCALES, ratio: float = RATIO, horizon: float = HORIZON, h: float = STEP) -> Convergence:
    """Distances of `row.source` at each scale from `row.limit`, same input and step."""
    base = load_scenario(SCENE).parameters
    common = {"v1": ratio, "v2": 1.0, "mu": MU}
    controls = [[-ratio, -1.0]]
    limit = _rollout(row.limit, common, controls, horizon, h)
    distances, statuses = [], []
    for s in scales:
        overrides = dict(common)
        if row.stiffens:
            overrides.update(K=base["K"] / s, C=base["C"] / s)
        run = _rollout(row.source, overrides, controls, horizon, h, eps=s if row.vanishing_inertia else None)
        statuses.append(run.status)
        distances.append(trajectory_distance(run, limit) if run.ok and limit.ok else math.nan)
    label = f"{row.source_label} -> {row.limit_label}"
    return Convergence(label, row.parameter, tuple(scales), tuple(distances), tuple(statuses), fitted_rate(scales, distances))


def drive_row(scales=SCALES[:-1], ratio: float = RATIO, horizon: float = DEF1_HORIZON, h: float = DEF1_STEP) -> Convergence:
    """Definition 1's residual under the same input as the quasistatic drives stiffen: the
    distance until the kinematic outcome at kp = kp0 / s, kd = kd0 / sqrt(s)."""
    base = load_scenario(SCENE).parameters
    common = {"v1": ratio, "v2": 1.0, "mu": MU}
    controls = [[-ratio, -1.0]]
    kinematic = _rollout("kinematic", common, controls, horizon, h)
    until = _rollout("kinematic", common, controls, horizon, h, stop=True).t
    distances, statuses = [], []
    for s in scales:
        gains = {"finger_kp": base["finger_kp"] / s, "finger_kd": base["finger_kd"] / math.sqrt(s)}
        run = _rollout("quasistatic-rigid", {**common, **gains}, controls, horizon, h)
        statuses.append(run.status)
        distances.append(trajectory_distance(run, kinematic, until) if run.ok and _ran(kinematic) else math.nan)
    label = "rigid, quasistatic -> kinematic (same input)"
    return Convergence(
        label, "kp = kp0 / s, kd = kd0 / sqrt(s)", tuple(scales), tuple(distances), tuple(statuses), fitted_rate(scales, distances)
    )


def definition1_input(ratio: float, horizon: float = DEF1_HORIZON, h: float = DEF1_STEP) -> InputCheck:
    """Definition 1 for the kinematic input 'finger speeds (ratio, 1) down' (see the module)."""
    common = {"v1": ratio, "v2": 1.0, "mu": MU}
    u = np.array([-ratio, -1.0])
    kinematic = _rollout("kinematic", common, [u], horizon, h)
    first = _rollout("kinematic", common, [u], horizon, h, stop=True)
    same = _rollout("quasistatic-rigid", common, [u], horizon, h)
    whole = trajectory_distance(same, kinematic) if _ran(kinematic) and same.ok else math.nan
    best, best_u = None, None
    if not whole < max(SIGMAS):
        for f1 in INPUT_FACTORS:
            for f2 in INPUT_FACTORS:
                v = u * np.array([f1, f2])
                if f1 == f2 == 1.0:
                    continue
                other = _rollout("quasistatic-rigid", common, [v], horizon, h)
                if other.ok:
                    d = trajectory_distance(other, kinematic)
                    if best is None or d < best:
                        best, best_u = d, (float(v[0]), float(v[1]))
    n = min(len(kinematic.times), len(same.times)) - 1
    ends = tuple(map(float, kinematic.trajectory[n])), tuple(map(float, same.trajectory[n]))
    until = trajectory_distance(same, kinematic, first.t) if _ran(kinematic) and same.ok else math.nan
    return InputCheck(ratio, first.outcome, first.t, until, whole, best, best_u, kinematic.status, *ends)


def run(scales=SCALES, ratios=INPUT_RATIOS) -> Table1:
    """Every row of Table 1 measured (a few seconds once the kernels are compiled)."""
    scenario = load_scenario(SCENE)
    p = scenario.parameters
    sag = p["finger_mass"] * abs(scenario.spec.scene.gravity[1]) / p["finger_kp"]
    rows = tuple(definition2_row(row, scales) for row in ROWS)
    return Table1(rows, drive_row(scales[:-1]), tuple(definition1_input(r) for r in ratios), sag)


def _row_line(c: Convergence) -> str:
    cells = " | ".join(f"{d:.2e}" if c.statuses[k] == "ok" else c.statuses[k] for k, d in enumerate(c.distances))
    return f"| {c.label} | {c.parameter} | {cells} | {c.rate:.2f} | {'yes' if c.monotone else 'NO'} |"


def report(table: Table1) -> list[str]:
    """The 'Table 1 in numbers' section of docs/paper-reproduction.md, as markdown lines."""
    scales = table.rows[0].scales
    head = "| row | parameter | " + " | ".join(f"s = {s:g}" for s in scales) + " | fitted rate | shrinks at every step |"
    lines = [
        "## Table 1 in numbers",
        "",
        "Generated by `planner.table1` (the module's docstring has the method). Distance: the largest difference of any",
        "configuration coordinate (triangle x3, finger heights; m) at any common time, same input, same step.",
        "",
        f"**Definition 2 rows** (constant finger speeds rho = {RATIO:g}, mu = {MU:g}, {HORIZON:g} s at h = {STEP:g}: approach,",
        "impact and push until just before the grasp). s = 1 is the scene's own K = 1e6, C = 1e4 and eps = 1; the rate p",
        "is the least-squares slope of log distance against log s (distance ~ s^p).",
        "",
        head,
        "|---|---|" + "---|" * len(scales) + "---|---|",
    ]
    lines += [_row_line(c) for c in table.rows]
    d = table.drives
    lines += [
        "",
        f"**Definition 1 row** (rigid quasistatic -> kinematic; h = {DEF1_STEP:g}, up to {DEF1_HORIZON:g} s). For each kinematic",
        "input tried (constant speeds, finger 2 at 1 m/s), the quasistatic model under the same input: its distance from",
        "the kinematic trajectory until the kinematic run's outcome, and over the whole run (both models go on after it).",
        "",
        "| rho = v1 / v2 | kinematic outcome | at t (s) | distance until then (m) | within sigma = "
        + ", ".join(f"{s:g}" for s in SIGMAS)
        + " | whole run (m) | kinematic run ends | best other constant input, whole run (m) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in table.inputs:
        within = ", ".join("yes" if c.until_outcome < s else "no" for s in SIGMAS)
        other = (
            "not needed" if c.best_other is None else f"{c.best_other:.3f} at ({c.best_other_input[0]:g}, {c.best_other_input[1]:g}) m/s"
        )
        lines.append(
            f"| {c.ratio:g} | {c.outcome} | {c.outcome_time:.3f} | {c.until_outcome:.2e} | {within} | {c.whole_horizon:.2e} "
            f"| {c.kinematic_status} | {other} |"
        )
    apart = [c for c in table.inputs if not c.whole_horizon < max(SIGMAS)]
    if apart:
        lines += ["", "Where the whole runs part, their last common configurations (x3, finger 1 y, finger 2 y):"]
        lines += [
            f"rho = {c.ratio:g}: kinematic ({', '.join(f'{v:.3f}' for v in c.kinematic_end)}), "
            f"quasistatic ({', '.join(f'{v:.3f}' for v in c.quasistatic_end)})."
            for c in apart
        ]
    lines += [
        "",
        "Under the same input, the quasistatic fingers' gravity sag m g / kp = "
        + f"{table.sag:.2e} m (their drives are position controls; the kinematic fingers move exactly) is the distance",
        "until the outcome at rho = "
        + (", ".join(f"{c.ratio:g}" for c in table.inputs if abs(c.until_outcome - table.sag) <= 0.01 * table.sag) or "none")
        + " (within 1%). At rho = "
        + (", ".join(f"{c.ratio:g}" for c in table.inputs if abs(c.until_outcome - table.sag) > 0.01 * table.sag) or "none")
        + " it is larger (see the table). Stiffening the drives at rho = "
        + f"{RATIO:g}:",
        "",
        "| row | parameter | " + " | ".join(f"s = {s:g}" for s in d.scales) + " | fitted rate | shrinks at every step |",
        "|---|---|" + "---|" * len(d.scales) + "---|---|",
        _row_line(d),
        "",
    ]
    return lines

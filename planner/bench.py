"""``ladder bench``: fast and accurate, measured.

Sections (each a function returning a JSON-able dict; `run_all` runs them and writes
``bench.json``, plots and ``docs/benchmarks.md``):

- work_precision: per scene and rung, error against a reference for a range of steps h,
  against wall time. References: closed forms where they exist (the incline block's
  sliding distance; the disc's free fall and plastic landing), otherwise the same rung at a
  much finer step (the paper's scene; the elastically bouncing disc);
- throughput: steps per second per rung on the paper's scene (h = 1e-4, until the grasp),
  and, when the optional peer is installed (``peers`` extra; else: skipped), MuJoCo's on the
  same scene, steps and h (`planner.peers`), with the ratio, where MuJoCo's run ends, and a
  stability sweep (h = 1e-4 to 1e-3, the policy's full 3 s) of ours and MuJoCo's;
- scaling: cost per step against the number of contacts for Lemke and PGS (a row of boxes
  resting on a plane, 2 contacts each, up to 64 contacts; a short stack; a row in space, 4
  contacts each, up to 32), with the fitted
  growth exponent per solver and the contact count from which PGS is cheaper;
- planning: the ladder against planning flat at the top rung over seeds (success rate,
  median wall time), also written as OMPL benchmark logs (``ompl_benchmark_statistics
  LOG -d DB`` turns them into the SQLite database Planner Arena reads).

``--quick`` shrinks every section (fewer steps, seeds and sizes) to a smoke run.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import platform
import socket
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "scenarios"
G = 9.81


def cpu_name(cpuinfo: str) -> str:
    """The first processor of a /proc/cpuinfo text, named so that two machines sold under one
    model name ("AMD EPYC") tell apart: the model name, its family and model numbers, and the
    widest vector extension it has (AVX-512, AVX2 or neither): "AMD EPYC (family 25, model 17,
    AVX-512)". Empty where the text names no processor."""
    fields: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        if not line.strip():
            if fields:
                break
            continue
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())
    name = fields.get("model name", "")
    if not name:
        return ""
    flags = set(fields.get("flags", "").split())
    details = [f"{label} {fields[key]}" for key, label in (("cpu family", "family"), ("model", "model")) if key in fields]
    details += ["AVX-512"] if "avx512f" in flags else ["AVX2"] if "avx2" in flags else []
    return f"{name} ({', '.join(details)})" if details else name


def machine() -> dict:
    from models.cpu_target import tuned_for

    try:
        cpu = cpu_name(Path("/proc/cpuinfo").read_text())
    except OSError:
        cpu = ""
    return {
        "host": socket.gethostname(),
        "cpu": cpu or platform.processor(),
        "kernels_tuned_for": tuned_for(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "system": platform.platform(),
    }


def _timed(fn, repeat: int = 3):
    """(median wall seconds, last result) of fn() over `repeat` calls after one warm-up."""
    result = fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), result


# ----------------------------------------------------------------------------- work-precision


def _rollout(scenario, rung_name, h, duration, controls=None, stop=False, records=4000):
    from models.rungs import rung_for

    rung = rung_for(scenario, rung_name)
    u = np.zeros((1, len(scenario.actuated))) if controls is None else np.atleast_2d(controls)
    return rung.rollout(scenario, rung.initial_state(scenario), u, [duration], h, stop_at_outcome=stop, max_records=records)


def work_precision(quick: bool = False) -> dict:
    from models.scenario import load_scenario

    steps = [1e-2, 1e-3, 1e-4] if quick else [1e-2, 1e-3, 1e-4, 1e-5]
    rows = []

    # incline: slides 0.5 s at a = g (sin a - mu cos a) (continuous closed form)
    alpha, mu, T = 30.0, 0.3, 0.5
    incline = load_scenario(SCENARIOS / "incline_block.toml", {"slope_deg": alpha, "mu": mu})
    a = G * (math.sin(math.radians(alpha)) - mu * math.cos(math.radians(alpha)))
    direction = np.array([math.cos(math.radians(alpha)), math.sin(math.radians(alpha))])
    for rung in ("dynamic-rigid", "dynamic-compliant"):
        for h in steps:
            wall, out = _timed(lambda rung=rung, h=h: _rollout(incline, rung, h, T), repeat=1 if h < 1e-4 else 3)
            travelled = -float(np.dot(out.state.q[:2] - incline.start[:2], direction))
            rows.append(
                {
                    "scene": "incline_block",
                    "rung": rung,
                    "h": h,
                    "reference": "closed form 0.5 a t^2",
                    "error": abs(travelled - 0.5 * a * T * T),
                    "wall_s": wall,
                    "status": out.status,
                }
            )

    # disc dropped from 1 m: rigid (plastic) landing has a closed form; elastic compliant vs fine step
    disc = load_scenario(SCENARIOS / "bouncing_disc.toml")
    T = 1.0
    times = np.linspace(0.0, T, 201)
    landing = math.sqrt(2 * (1.0 - 0.1) / G)
    exact = np.where(times < landing, 1.0 - 0.5 * G * times**2, 0.1)
    for h in steps:
        wall, out = _timed(lambda h=h: _rollout(disc, "dynamic-rigid", h, T), repeat=1 if h < 1e-4 else 3)
        y = np.interp(times, out.times, out.trajectory[:, 1])
        rows.append(
            {
                "scene": "bouncing_disc",
                "rung": "dynamic-rigid",
                "h": h,
                "reference": "closed form (fall, plastic landing)",
                "error": float(np.max(np.abs(y - exact))),
                "wall_s": wall,
                "status": out.status,
            }
        )
    ref_h = 1e-5 if quick else 1e-6
    ref = _rollout(disc, "dynamic-compliant", ref_h, T, records=20000)
    y_ref = np.interp(times, ref.times, ref.trajectory[:, 1])
    for h in [s for s in steps if s > ref_h]:
        wall, out = _timed(lambda h=h: _rollout(disc, "dynamic-compliant", h, T), repeat=1 if h < 1e-4 else 3)
        y = np.interp(times, out.times, out.trajectory[:, 1])
        rows.append(
            {
                "scene": "bouncing_disc",
                "rung": "dynamic-compliant (C = 0)",
                "h": h,
                "reference": f"h = {ref_h:g}",
                "error": float(np.max(np.abs(y - y_ref))),
                "wall_s": wall,
                "status": out.status,
            }
        )

    # the paper's scene, pushing phase, against the same rung at h = 1e-5
    tri = load_scenario(SCENARIOS / "two_finger_triangle.toml", {"v1": 0.8})
    sample = np.linspace(1.45, 1.6, 31)
    controls = np.array([[-0.8, -1.0]])
    for rung in ("kinematic", "quasistatic-rigid", "quasistatic-compliant", "dynamic-rigid", "dynamic-compliant"):
        ref = _rollout(tri, rung, 1e-5, 1.6, controls)
        R = np.array([np.interp(sample, ref.times, ref.trajectory[:, j]) for j in range(ref.trajectory.shape[1])]).T
        for h in [s for s in steps if s > 1e-5]:
            wall, out = _timed(lambda rung=rung, h=h: _rollout(tri, rung, h, 1.6, controls), repeat=1 if h < 1e-4 else 3)
            X = np.array([np.interp(sample, out.times, out.trajectory[:, j]) for j in range(out.trajectory.shape[1])]).T
            rows.append(
                {
                    "scene": "two_finger_triangle",
                    "rung": rung,
                    "h": h,
                    "reference": "h = 1e-5",
                    "error": float(np.max(np.abs(X - R))),
                    "wall_s": wall,
                    "status": out.status,
                }
            )
    return {"rows": rows}


# ----------------------------------------------------------------------------- stability


STABILITY_STEPS = (1e-4, 2e-4, 5e-4, 1e-3)


def _largest_gap(out, ref, x: int) -> tuple[float, float]:
    """(largest |x - x_ref| over the run at its recorded times up to the reference's end, the
    time of it): the reference's records interpolated linearly at the run's times (both runs
    record every step)."""
    keep = out.times <= ref.times[-1]
    gaps = np.abs(out.trajectory[keep, x] - np.interp(out.times[keep], ref.times, ref.trajectory[:, x]))
    k = int(np.argmax(gaps))
    return float(gaps[k]), float(out.times[keep][k])


def stability(quick: bool = False) -> dict:
    """The paper's scene (v1 = 0.8, v2 = 1, K = 1e6) under dynamic-compliant with plastic
    (C = 1e4) and elastic (C = 0) contact, run until the grasp or the unsafe set, at steps up
    to 1e-3 against h = 1e-5: bounded, same outcome, the triangle's x where it ends and the
    largest gap in its x along the way (`_largest_gap`: where the end's error hides one)."""
    from models.scenario import load_scenario

    def every_step(h: float) -> int:  # records for every step of the 3 s runs
        return int(round(3.0 / h)) + 2

    rows = []
    for C in (1e4, 0.0):
        tri = load_scenario(SCENARIOS / "two_finger_triangle.toml", {"v1": 0.8, "C": C, "K": 1e6})
        x = tri.coordinates.index("triangle.x")
        controls = np.array([[-0.8, -1.0]])
        ref = _rollout(tri, "dynamic-compliant", 1e-5, 3.0, controls, stop=True, records=every_step(1e-5))
        for h in STABILITY_STEPS:
            out = _rollout(tri, "dynamic-compliant", h, 3.0, controls, stop=True, records=every_step(h))
            q = out.state.q
            gap, gap_t = _largest_gap(out, ref, x)
            rows.append(
                {
                    "C": C,
                    "h": h,
                    "outcome": out.outcome,
                    "status": out.status,
                    "t": float(out.t),
                    "bounded": bool(np.all(np.isfinite(q)) and np.max(np.abs(q)) < 10.0),
                    "same_outcome": out.outcome == ref.outcome,
                    "triangle_x": float(q[x]),
                    "reference_x": float(ref.state.q[x]),
                    "reference_outcome": ref.outcome,
                    "x_error": float(abs(q[x] - ref.state.q[x])),
                    "largest_x_gap": gap,
                    "largest_x_gap_t": gap_t,
                }
            )
    return {
        "scene": "two_finger_triangle, v1 = 0.8, v2 = 1, K = 1e6, dynamic-compliant, until the grasp (reference h = 1e-5)",
        "rows": rows,
    }


def plot_work_precision(data: dict, out: Path) -> list[str]:
    """Per scene, error against wall time per rung (log-log), each point labelled with its step
    h once (`planner.plots.label_points`: no two labels overlap). Returns the PNGs' paths."""
    import matplotlib

    from planner.plots import LINE_STYLES, MARKERS, label_points

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for scene in sorted({r["scene"] for r in data["rows"]}):
        fig, ax = plt.subplots(figsize=(6, 4.2))
        rows = [r for r in data["rows"] if r["scene"] == scene]
        points, texts = [], []
        for k, rung in enumerate(dict.fromkeys(r["rung"] for r in rows)):
            mine = [r for r in rows if r["rung"] == rung]
            xy = [(r["wall_s"], max(r["error"], 1e-16)) for r in mine]
            ax.loglog(*zip(*xy), marker=MARKERS[k % len(MARKERS)], ls=LINE_STYLES[k % len(LINE_STYLES)], ms=5, mfc="none", label=rung)
            points += xy
            texts += [f"h={r['h']:g}" for r in mine]
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("error (m)")
        ax.set_title(f"work-precision: {scene}")
        ax.legend(fontsize=7)
        fig.tight_layout()
        label_points(ax, points, texts)  # after the layout: labels placed where they land
        path = out / f"work_precision.{scene}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(str(path))
    return paths


# ----------------------------------------------------------------------------- throughput


def throughput(quick: bool = False) -> dict:
    from models.scenario import load_scenario

    tri = load_scenario(SCENARIOS / "two_finger_triangle.toml")
    controls = np.array([[-1.0, -1.0]])
    rows = []
    for rung in ("kinematic", "quasistatic-rigid", "quasistatic-compliant", "dynamic-rigid", "dynamic-compliant"):
        wall, out = _timed(lambda rung=rung: _rollout(tri, rung, 1e-4, 3.0, controls, stop=True, records=2), repeat=3 if quick else 7)
        rows.append(
            {
                "rung": rung,
                "h": 1e-4,
                "steps": out.steps,
                "contact_steps": out.force_steps,
                "outcome": out.outcome,
                "median_wall_s": wall,
                "steps_per_s": out.steps / wall,
            }
        )
    ours = next(row for row in rows if row["rung"] == PEER_RUNG)
    peer = mujoco_peer(
        tri, controls[0], ours["steps"], ours["h"], lambda: _rollout(tri, PEER_RUNG, ours["h"], 3.0, controls, stop=True, records=2), quick
    )
    return {"scene": "two_finger_triangle (v1 = v2 = 1, until the grasp)", "rows": rows, "peer": peer, "contact": contact_steps(quick)}


#: Contact-dominated runs (`contact_steps`): the paper's scene squeezing on after the grasp, and
#: box_push_3d's push as its ladder's top rung steps it (calls of one control period).
CONTACT_SQUEEZE_STEPS = 40_000
CONTACT_PUSH_S = (0.4, 2.6)  # the push's first contact is at 0.35 s: timed from 0.4 s, for 2.6 s
#: How a contact row of box_push_3d names the planners' calls (`planner_propagation`), in its scene.
PLANNERS_WAY = "the planners' propagation"


def contact_steps(quick: bool = False) -> dict:
    """Cost per step where contacts carry force, beside the free steps that dominate the runs
    until the grasp: the paper's scene (v1 = v2 = 1) run on through the squeeze that follows
    the grasp, one call of CONTACT_SQUEEZE_STEPS; and box_push_3d's straight push
    (dynamic-rigid at the scenario's h and friction directions) timed from its first contact in
    calls of one control period each, with the scenario's polygonal cone (Lemke) and with the
    exact cone (PGS), each two ways in turns: as a planner calls it (`planner_propagation`:
    flattened states, the call's fixed cost about a third of `Rung.rollout`'s) and through
    `Rung.rollout` (the pipeline's replays; its state and basis table carried from call to
    call), the four and MuJoCo in turns within each round (`exact_vs_polygon`: the exact
    cone's steps/s over the polygon's, each way); the two ways take the same steps
    (`same_end`: their end states equal, bit for bit, so the propagations' step counts are
    the rollout's). Each row: steps, steps with a
    contact force, median wall and us per step (`repeat` rounds), and MuJoCo on the same run
    timed in turns with ours (`in_turns`): the paper's scene in its fastest mapping
    (`direct`, the inert palm-triangle pair left out), box_push_3d with MuJoCo's own contact
    model (`peers.build_spatial`), stepped in the same calls."""
    from models.rungs import pgs_rung, policy_controls, rung_for
    from models.scenario import load_scenario
    from planner.ompl_adapter import flatten, planner_propagation

    try:
        from planner import peers
    except ImportError:
        peers = None
    repeat = 3 if quick else 7
    rows = []
    tri = load_scenario(SCENARIOS / "two_finger_triangle.toml")
    steps = CONTACT_SQUEEZE_STEPS
    squeeze = np.array([[-1.0, -1.0]])
    peer = None if peers is None else peers.build(tri, 1e-4, "direct", drop_inert=True)
    for rung in ("quasistatic-rigid", "dynamic-rigid", "dynamic-compliant"):
        ours = lambda rung=rung: _rollout(tri, rung, 1e-4, steps * 1e-4, squeeze, records=2)  # noqa: E731
        theirs = [] if peer is None else [lambda: peers.timed_run(peer, squeeze[0], steps)]
        walls, out, _ = in_turns(ours, theirs, repeat)
        row = _contact_row(
            "two_finger_triangle, v1 = v2 = 1 through the squeeze",
            rung,
            1e-4,
            out.steps,
            out.force_steps,
            float(np.median(walls[:, 0])),
            out.pivots,
            out.sweeps,
        )
        rows.append(row | _peer_columns(walls, out.steps))
    box = load_scenario(SCENARIOS / "box_push_3d.toml")
    rung = rung_for(box, "dynamic-rigid")
    settings = box.rung_settings("dynamic-rigid")
    h, period = settings.h, settings.control_period
    u, _ = policy_controls(box)
    first, span = CONTACT_PUSH_S
    start = rung.rollout(box, rung.initial_state(box), u, [first], h, stop_at_outcome=False).state
    calls = int(round(span / period)) // (5 if quick else 1)

    def push(stepper):  # `Rung.rollout`'s calls, the state (with its basis table) carried from call to call
        state, taken, pushed, pivots, sweeps = start, 0, 0, 0, 0
        for _ in range(calls):
            out = stepper.rollout(box, state, u, [period], h)
            state, taken, pushed = out.state, taken + out.steps, pushed + out.force_steps
            pivots, sweeps = pivots + out.pivots, sweeps + out.sweeps
        return taken, pushed, pivots, sweeps, state

    def propagate(step):  # a planner's calls (`planner_propagation`): flattened states, no basis table
        x = flatten(start)
        y = np.empty_like(x)
        for _ in range(calls):
            step(x, u[0], period, y)
            x, y = y, x
        return x

    def timed(run):
        def wall_and_end():
            t0 = time.perf_counter()
            end = run()
            return time.perf_counter() - t0, end

        return wall_and_end

    per_call = int(round(period / h))
    spatial = None if peers is None else peers.build_spatial(box, h)
    skip = int(round(first / h))
    theirs = [] if spatial is None else [lambda: peers.timed_run(spatial, u[0], calls * per_call, after=skip, per_call=per_call)]
    polygon = f"dynamic-rigid ({settings.friction_directions}-sided cone, {settings.contact_solver})"
    exact = pgs_rung(rung, exact_cone=True)
    cones = ((polygon, rung), ("dynamic-rigid (exact cone, pgs)", exact))
    # both cones, each both ways, in turns with MuJoCo within every round, so that the cones' ratio
    # is measured as the ratios to MuJoCo are. Columns: 0 the polygon's planners' calls, then
    # MuJoCo's (when timed), then the polygon's `Rung.rollout`, the exact cone's planners' calls
    # and its `Rung.rollout`
    steps = [planner_propagation(box, stepper, start, h, period) for _, stepper in cones]
    others = [timed(lambda: push(rung)), timed(lambda: propagate(steps[1])), timed(lambda: push(exact))]
    walls, x, ends = in_turns(lambda: propagate(steps[0]), [*theirs, *others], repeat)
    mj = [1] if theirs else []
    base = 1 + len(mj)
    ends = [x, *ends[len(mj) :]]  # per column from 0, MuJoCo's left out
    per_step = {}  # per column: wall per step, each round
    columns = ((0, base), (base + 1, base + 2))  # per cone: its planners' calls, its `Rung.rollout`
    for k, ((label, _), (planners_col, rollout_col)) in enumerate(zip(cones, columns)):
        x_end, (taken, pushed, pivots, sweeps, state) = ends[2 * k], ends[2 * k + 1]
        # the same steps both ways: the propagations' counts are the rollout's where their ends (the
        # flattened states but the propagation's flag) are the same
        same_end = bool(np.array_equal(x_end[:-1], flatten(state)[:-1]))
        ways = (
            (f"{PLANNERS_WAY}, calls of {period:g} s", planners_col),
            (f"`Rung.rollout`, calls of {period:g} s", rollout_col),
        )
        for how, col in ways:
            row = _contact_row(f"box_push_3d, pushing ({how})", label, h, taken, pushed, float(np.median(walls[:, col])), pivots, sweeps)
            rows.append(row | _peer_columns(walls[:, [col, *mj]], calls * per_call) | {"same_end": same_end})
            per_step[col] = walls[:, col] / max(taken, 1)
    # the exact cone's speed against the polygon's in steps per second, each way: the median of the
    # rounds' ratios
    exact_vs_polygon = {
        how: float(np.median(per_step[polygon_col] / per_step[exact_col]))
        for how, polygon_col, exact_col in zip(("planners", "rollout"), *columns)
    }
    squeezed = _rollout(tri, "dynamic-rigid", 1e-4, 2.0, squeeze, records=2).state  # 0.5 s into the squeeze
    split = [
        _cost_split("two_finger_triangle, squeezing", tri, rung_for(tri, "dynamic-rigid"), squeezed, squeeze[0], 1e-4, quick),
        _cost_split(f"box_push_3d, pushing ({polygon})", box, rung, start, u[0], h, quick),
        _cost_split("box_push_3d, pushing (dynamic-rigid, exact cone, pgs)", box, exact, start, u[0], h, quick),
    ]
    return {
        "rows": rows,
        "repeat": repeat,
        "peer": None if peers is None else f"MuJoCo {peers.version()}",
        "split": split,
        "exact_vs_polygon": exact_vs_polygon,
    }


#: Calls per stage and round of the cost split (`_cost_split`).
SPLIT_REPEATS = 4_000


def _cost_split(scene: str, scenario, rung, state, u: np.ndarray, h: float, quick: bool) -> dict:
    """Where a contact step's time goes, at one state (`models.rollout.stage_loop`): detection,
    the pair distances and the task's predicates, the contact Jacobians, and the dynamics step in
    its three parts (`models.stepper.contact_stage`, or the step the rollout takes at the state:
    `models.stepper.planar_warm_step`, `models.stepper.spatial_warm_step`,
    `models.stepper.pgs_warm_step`): the free velocity and the LCP's assembly, the warm-started
    contact solve, and the rest (the impulses' velocity update, the integration), in us per call.
    Each round runs every stage SPLIT_REPEATS times, the stages in turns, so that a busy spell of
    the machine falls on a round's stages alike; a stage's time in a round is its run's less the
    setup's in that round, and the step's parts are differences, within a round, of runs that stop
    after each. Each figure is the median over SPLIT_ROUNDS rounds (--quick: a tenth), floored at
    0; `spread_us` is the interquartile range over the rounds of the round's sum, this machine's
    noise on one round."""
    from models import rollout as R
    from models.rungs import compiled

    c = compiled(scenario)
    rounds = SPLIT_ROUNDS // (10 if quick else 1)
    args = (c.scene, c.drives, rung.model, rung.solver, c.goal, c.unsafe, state.q, state.nu, state.q_ref, state.delta_n, state.delta_t)
    u, h = np.asarray(u, float), float(h)
    order = (R.STAGE_SETUP, R.STAGE_DETECT, R.STAGE_CLASSIFY, R.STAGE_JACOBIANS, R.STAGE_ASSEMBLY, R.STAGE_CONTACT_SOLVE, R.STAGE_SOLVE)
    walls, contacts, pivots, sweeps = np.zeros((rounds, len(order))), 0, 0, 0
    for round_ in range(rounds):
        for k, stage in enumerate(order):
            t0 = time.perf_counter()
            contacts, piv, sw = R.stage_loop(stage, *args, u, h, SPLIT_REPEATS)
            walls[round_, k] = time.perf_counter() - t0
            if stage == R.STAGE_SOLVE:
                pivots, sweeps = piv, sw
    # per round and stage: us per call, less the setup's run of the same round
    per_call = dict(zip(order, ((walls - walls[:, :1]) / SPLIT_REPEATS * 1e6).T))
    parts = {
        "detection": per_call[R.STAGE_DETECT],
        "distances and predicates": per_call[R.STAGE_CLASSIFY],
        "Jacobians": per_call[R.STAGE_JACOBIANS],
    }
    # the step's parts: runs that stop after the assembly, after the contact solve, and the whole step
    upto = [per_call[stage] for stage in (R.STAGE_ASSEMBLY, R.STAGE_CONTACT_SOLVE, R.STAGE_SOLVE)]
    for name, low, high in zip(SPLIT_STEP_PARTS, [0.0, *upto[:2]], upto):
        parts[name] = high - low
    us = {name: max(float(np.median(each)), 0.0) for name, each in parts.items()}
    q1, q3 = np.percentile(sum(parts.values()), [25, 75])
    return {
        "scene": scene,
        "contacts": contacts,
        "us": us,
        "spread_us": float(q3 - q1),
        "repeats": SPLIT_REPEATS,
        "rounds": rounds,
        "pivots": pivots,
        "sweeps": sweeps,
    }


#: Rounds of the cost split: each figure is the median of the rounds' (`_cost_split`).
SPLIT_ROUNDS = 50
#: The dynamics step's parts in the cost split (`_cost_split`).
SPLIT_STEP_PARTS = ("free velocity and assembly", "contact solve", "impulses and integration")


def in_turns(ours, theirs: list, repeat: int):
    """ours() and each of theirs (MuJoCo runs: () -> (wall of the stepping alone, end)) timed
    in turns, `repeat` rounds after a warm-up one, so that load from other work on the machine
    hits them alike. Returns (walls (repeat, 1 + len(theirs)): ours, then theirs; ours' last
    result; theirs' last ends)."""
    walls = np.zeros((repeat, 1 + len(theirs)))
    result, ends = None, [None] * len(theirs)
    for round_ in range(-1, repeat):  # round -1 warms up
        t0 = time.perf_counter()
        result = ours()
        row = [time.perf_counter() - t0]
        for k, run in enumerate(theirs):
            wall, ends[k] = run()
            row.append(wall)
        if round_ >= 0:
            walls[round_] = row
    return walls, result, ends


def _peer_columns(walls: np.ndarray, steps: int) -> dict:
    """A contact row's MuJoCo columns from `in_turns`' walls (MuJoCo's `steps` steps in the
    second column, if timed): its us per step and ours / MuJoCo in steps per second, the median
    of the rounds' ratios."""
    if walls.shape[1] < 2:
        return {"mujoco_us_per_step": None, "speed_vs_mujoco": None}
    return {
        "mujoco_us_per_step": float(np.median(walls[:, 1])) / max(steps, 1) * 1e6,
        "speed_vs_mujoco": float(np.median(walls[:, 1] / walls[:, 0])),
    }


def _contact_row(scene: str, rung: str, h: float, steps: int, contact: int, wall: float, pivots: int, sweeps: int) -> dict:
    """A contact row of `contact_steps`; pivots and sweeps: the run's Lemke pivots and PGS sweeps
    in all (the contact solves' work, per step in the row)."""
    return {
        "scene": scene,
        "rung": rung,
        "h": h,
        "steps": steps,
        "contact_steps": contact,
        "median_wall_s": wall,
        "us_per_step": wall / max(steps, 1) * 1e6,
        "pivots_per_step": pivots / max(steps, 1),
        "sweeps_per_step": sweeps / max(steps, 1),
    }


#: The peer stability sweep (steps STABILITY_STEPS): the paper's scene at these parameters (the policy's
#: constant speeds, for the policy's duration).
STABILITY_SCENES = (("v1 = v2 = 1", {}), ("v1 = 0.8, v2 = 1", {"v1": 0.8}))
#: Records of the stability runs are this far apart (s): goal and unsafe are checked on them.
STABILITY_PERIOD = 1e-3
#: The rung timed against MuJoCo.
PEER_RUNG = "dynamic-compliant"


def mujoco_peer(scenario, u, steps: int, h: float, ours, quick: bool = False) -> dict:
    """MuJoCo on the same scene, commanded speeds u, step h and number of steps as our
    rollout `ours()` (PEER_RUNG): steps/s per contact mapping and the ratio ours / MuJoCo,
    timed in turns (ours, then each mapping, `repeat` rounds after a warm-up one) so that
    load from other work on the machine hits both alike; the ratio is the median of the
    rounds' ratios. Also where MuJoCo's run ends (outcome, touching pairs) and the stability
    sweep. Skipped without mujoco."""
    try:
        from planner import peers
    except ImportError:
        return {"skipped": "mujoco is not installed (pip install 'contact-ladder[peers]'); the peer was not timed"}
    repeat = 3 if quick else 7
    inert = [f"{p.body_a}-{p.body_b}" for p in peers.inert_pairs(scenario)]
    built = [
        peers.build(scenario, h, contact, drop) for contact in peers.CONTACT_MAPPINGS for drop in ((False, True) if inert else (False,))
    ]
    walls, _, ends = in_turns(ours, [lambda peer=peer: peers.timed_run(peer, u, steps) for peer in built], repeat)
    median = np.median(walls, axis=0)
    rows = [
        {
            "contact": peer.contact,
            "inert_pairs_left_out": list(peer.dropped),
            "steps": steps,
            "median_wall_s": float(median[1 + k]),
            "steps_per_s": steps / float(median[1 + k]),
            "ratio": float(np.median(walls[:, 1 + k] / walls[:, 0])),
            "end": _end_state(scenario, ends[k]),
        }
        for k, peer in enumerate(built)
    ]
    fastest = max(rows, key=lambda row: row["steps_per_s"])
    return {
        "version": peers.version(),
        "integrator": "Euler",
        "h": h,
        "steps": steps,
        "simulated_s": steps * h,
        "repeat": repeat,
        "rows": rows,
        "ours": {"rung": PEER_RUNG, "steps_per_s": steps / float(median[0])},
        "inert_pairs": inert,
        "steps_per_s": fastest["steps_per_s"],
        "ratio": fastest["ratio"],
        "against": fastest["contact"]
        + (" without " + ", ".join(fastest["inert_pairs_left_out"]) if fastest["inert_pairs_left_out"] else ""),
        "mapping": {
            "force": f"solref = -(1 - d) A~ (K, C), solimp d = {peers.FORCE_IMPEDANCE:g}, elliptic cone: f_n = K r + C r' per pair",
            "direct": "solref = (-K, -C), MuJoCo's default solimp and (pyramidal) cone",
        },
        "stability": peer_stability(peers),
    }


def _end_state(scenario, q) -> dict:
    """The outcome at q (None when q diverged: a state that diverged has no outcome, the run
    has that status), whether it diverged, the object coordinates and which robot-object
    pairs touch."""
    from models.rungs import pair_signed_distances

    tol = scenario.spec.contact.touch_tolerance
    roles = {b.name: b.role for b in scenario.spec.bodies}
    psi = pair_signed_distances(scenario, q) if np.all(np.isfinite(q)) else np.full(len(scenario.pairs), np.nan)
    touching = {
        f"{p.body_a}-{p.body_b}": bool(psi[i] <= tol)
        for i, p in enumerate(scenario.pairs)
        if {roles[p.body_a], roles[p.body_b]} == {"robot", "object"}
    }
    return {
        "outcome": _outcome(scenario, q),
        "diverged": _diverged(q),
        "q": dict(zip(scenario.coordinates, map(float, q))),
        "touching": touching,
    }


def _diverged(q) -> bool:
    """q is not finite or beyond the stepper's divergence limit (a run's status, not an outcome)."""
    from models.stepper import DIVERGENCE_LIMIT

    return not np.all(np.abs(q) < DIVERGENCE_LIMIT)  # also catches nan


def _outcome(scenario, q) -> str | None:
    """The task's outcome label at q as a rollout classifies it (`models.task.classify`);
    None for a q that diverged."""
    from models.task import classify

    return None if _diverged(q) else classify(scenario, q).label


def _track(scenario, times, Q) -> dict:
    """First times the goal and the unsafe set are met along records (times, Q) and the first
    time the run diverged, the outcome (None: diverged) and q at the last record, and the
    largest displacement of the passive coordinates."""
    passive = [i for i, name in enumerate(scenario.coordinates) if name not in scenario.actuated]
    outcomes = [_outcome(scenario, q) for q in Q]
    first = {kind: next((float(t) for t, o in zip(times, outcomes) if o == kind), None) for kind in ("goal", "unsafe")}
    diverged_at = next((float(t) for t, q in zip(times, Q) if _diverged(q)), None)
    finite = Q[np.all(np.isfinite(Q), axis=1)]
    moved = np.abs(finite[:, passive] - scenario.start[passive]) if passive else np.zeros((1, 1))
    return {
        "goal_at": first["goal"],
        "unsafe_at": first["unsafe"],
        "diverged_at": diverged_at,
        "end": outcomes[-1],
        "end_q": dict(zip(scenario.coordinates, map(float, Q[-1]))),
        "max_object_displacement": float(moved.max()),
        "duration": float(times[-1]),
    }


def peer_stability(peers) -> dict:
    """Ours (dynamic-compliant) and MuJoCo (each contact mapping, default integrator) over the
    steps STABILITY_STEPS on the paper's scene, running the policy for its duration."""
    from models.scenario import load_scenario

    rows = []
    for label, params in STABILITY_SCENES:
        scene = load_scenario(SCENARIOS / "two_finger_triangle.toml", params)
        policy = scene.spec.task.policy
        u = np.array([policy.speeds.get(name, 0.0) for name in scene.actuated])
        for h in STABILITY_STEPS:
            out = _rollout(scene, "dynamic-compliant", h, policy.duration, u, records=int(round(policy.duration / STABILITY_PERIOD)) + 2)
            rows.append(
                {
                    "scene": label,
                    "simulator": "ours (dynamic-compliant)",
                    "h": h,
                    "status": out.status,
                    **_track(scene, out.times, out.trajectory),
                }
            )
            for contact in peers.CONTACT_MAPPINGS:
                run = peers.run(peers.build(scene, h, contact), u, policy.duration, STABILITY_PERIOD)
                status = "ok" if run.finite and not run.diverged else "diverged (" + ", ".join(run.diverged or ("non-finite",)) + ")"
                rows.append(
                    {"scene": label, "simulator": f"MuJoCo ({contact})", "h": h, "status": status, **_track(scene, run.times, run.q)}
                )
    return {"period": STABILITY_PERIOD, "rows": rows}


# ----------------------------------------------------------------------------- scaling

ROW_TEMPLATE = """
version = 1
[scenario]
name = "box_row"
[scene]
dimension = {dimension}
gravity = {gravity}
[contact]
mu = 0.5
K = 1e6
C = 1e4
[[bodies]]
name = "floor"
role = "obstacle"
shape = {floor}
{boxes}
[task]
horizon = 10.0
goal = {{ box = {{ "b0.x" = [100.0, 200.0] }} }}
[ladder]
time_limit = 1.0
[[ladder.rungs]]
model = "dynamic-rigid"
h = 1e-3
"""

BOX = """[[bodies]]
name = "b{i}"
role = "object"
mass = 1.0
inertia = {inertia}
shape = {{ type = "box", size = {size} }}
pose = {pose}
dofs = {dofs}
"""

#: The scaling scenes' floor and boxes (0.1 m, 1 kg) by dimension: (gravity, floor, inertia, size, dofs).
BOX_SCENES = {
    2: ("[0.0, -9.81]", '{ type = "halfplane", normal = [0.0, 1.0] }', "0.0017", "[0.1, 0.1]", '["x", "y", "theta"]'),
    3: (
        "[0.0, 0.0, -9.81]",
        '{ type = "plane", normal = [0.0, 0.0, 1.0], offset = 0.0 }',
        "[0.0017, 0.0017, 0.0017]",
        "[0.1, 0.1, 0.1]",
        '["x", "y", "z", "rotation"]',
    ),
}

SCALING_RUNGS = ("dynamic-rigid", "dynamic-compliant")
SCALING_SOLVERS = ("lemke", "pgs")
#: Rollouts timed per measurement (after one warm-up); the best is kept, as other work on the
#: machine only ever adds time.
SCALING_REPEATS = 3


def box_scene(folder: Path, arrangement: str, n: int, dimension: int = 2):
    """n boxes (0.1 m, 1 kg) resting on a plane: apart in a row, or in a stack (in the plane 2
    contacts each, in space 4)."""
    from models.scenario import load_scenario

    gravity, floor, inertia, size, dofs = BOX_SCENES[dimension]
    up = "y" if dimension == 2 else "z"

    def pose(x, height):
        return f"{{ x = {x}, {up} = {height} }}"

    poses = [pose(0.3 * i, 0.05) if arrangement == "row" else pose(0.0, 0.05 + 0.1 * i) for i in range(n)]
    boxes = "".join(BOX.format(i=i, inertia=inertia, size=size, pose=p, dofs=dofs) for i, p in enumerate(poses))
    path = Path(folder) / f"{arrangement}{n}_{dimension}d.toml"
    path.write_text(ROW_TEMPLATE.format(dimension=dimension, gravity=gravity, floor=floor, boxes=boxes))
    return load_scenario(path)


def _per_step(scene, rung_name: str, solver: str, steps: int) -> dict:
    from models.rungs import rung_for
    from models.stepper import contact_solver

    rung = replace(rung_for(scene, rung_name), solver=contact_solver(solver))
    state = rung.initial_state(scene)
    controls = np.zeros((1, len(scene.actuated)))

    def run():
        return rung.rollout(scene, state, controls, [steps * 1e-3], 1e-3, stop_at_outcome=False, max_records=2)

    out = run()
    best = math.inf
    for _ in range(SCALING_REPEATS):
        t0 = time.perf_counter()
        out = run()
        best = min(best, time.perf_counter() - t0)
    taken = max(out.steps, 1)
    return {
        "rung": rung_name,
        "solver": solver,
        "lcp_size": out.max_lcp_size,
        "us_per_step": 1e6 * best / out.steps if out.steps else None,
        "sweeps_per_step": out.sweeps / taken,
        "steps": out.steps,
        "status": out.status,
        "max_drift": float(np.max(np.abs(out.state.q - scene.start))),
    }


def _growth_exponent(rows: list[dict]) -> float:
    """Slope of log(us/step) against log(contacts) over the rows with 4 contacts and more."""
    mine = [r for r in rows if r["contacts"] >= 4 and r["us_per_step"] is not None]
    if len(mine) < 2:
        return float("nan")
    return float(np.polyfit(np.log([r["contacts"] for r in mine]), np.log([r["us_per_step"] for r in mine]), 1)[0])


def _cheaper_from(rows: list[dict], rung: str, solver: str) -> int | None:
    """The smallest contact count from which `solver` is cheaper per step than the other one at
    that and every larger measured count (a solver whose rollout failed is never cheaper);
    None if it is not cheaper at the largest count."""
    other = "lemke" if solver == "pgs" else "pgs"
    cost = {(r["solver"], r["contacts"]): r["us_per_step"] if r["status"] == "ok" else None for r in rows if r["rung"] == rung}
    found = None
    for c in sorted({c for _, c in cost}, reverse=True):
        mine, theirs = cost[(solver, c)], cost[(other, c)]
        if mine is None or (theirs is not None and mine >= theirs):
            break
        found = c
    return found


def _scaling(quick: bool) -> dict:
    from models.stepper import AUTO_PGS_CONTACTS

    counts = [1, 2, 4, 8, 16] if quick else [1, 2, 4, 8, 16, 32]
    stack_counts = [1, 2, 4] if quick else [1, 2, 4, 8]
    spatial_counts = [1, 2, 4] if quick else [1, 2, 4, 8]
    steps = 200 if quick else 1000
    rows, stack_rows, spatial_rows = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for arrangement, dimension, sizes, out in (
            ("row", 2, counts, rows),
            ("stack", 2, stack_counts, stack_rows),
            ("row", 3, spatial_counts, spatial_rows),
        ):
            for n in sizes:
                scene = box_scene(Path(tmp), arrangement, n, dimension)
                for rung in SCALING_RUNGS:
                    for solver in SCALING_SOLVERS:
                        row = _per_step(scene, rung, solver, steps if arrangement == "row" else steps // 2)
                        out.append({**row, "boxes": n, "contacts": 2 * n if dimension == 2 else 4 * n})
    exponents = {
        rung: {solver: _growth_exponent([r for r in rows if r["rung"] == rung and r["solver"] == solver]) for solver in SCALING_SOLVERS}
        for rung in SCALING_RUNGS
    }
    return {
        "rows": rows,
        "stack_rows": stack_rows,
        "growth_exponent": exponents,
        "crossover_contacts": {rung: _cheaper_from(rows, rung, "pgs") for rung in SCALING_RUNGS},
        "stack_lemke_cheaper_from": {rung: _cheaper_from(stack_rows, rung, "lemke") for rung in SCALING_RUNGS},
        "spatial_rows": spatial_rows,
        "spatial_crossover_contacts": {rung: _cheaper_from(spatial_rows, rung, "pgs") for rung in SCALING_RUNGS},
        "auto_pgs_contacts": AUTO_PGS_CONTACTS,
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
        "note": "contact detection (all n (n + 1) / 2 body pairs), Jacobians and the contact solve of a rollout from rest at h = 1e-3 "
        f"(best of {SCALING_REPEATS} rollouts). Lemke solves the dense Stewart-Trinkle LCP (in the plane 8 unknowns per box: "
        "normal, 2 friction directions and a sliding speed per contact; in space 24: 4 contacts with 4 directions each, "
        "the scenario format's default); PGS iterates on the contact impulses "
        "body by body (models.contact_pgs) to a relative residual of 1e-6, warm-started from the previous step",
    }


def scaling(quick: bool = False) -> dict:
    """Cost per step against the number of contacts, Lemke against PGS (issue 7).

    Row: n boxes resting apart on a plane, 2 contacts each, n up to 32 (64 contacts; --quick: 16).
    Stack: n boxes stacked on the plane, n up to 8 (--quick: 4): coupled contacts, where PGS needs
    many sweeps. Spatial rows: n boxes apart on a plane in space, 4 contacts each, n up to 8
    (--quick: 4). Per rung, solver and n: us/step, PGS sweeps per step, status. growth_exponent
    [rung][solver]: slope of log(us/step) against log(contacts) on the row from 4 contacts on;
    crossover_contacts[rung]: the smallest count from which PGS is cheaper at every larger count
    (None: never); stack_lemke_cheaper_from[rung]: the same for Lemke on the stack;
    spatial_crossover_contacts[rung]: crossover_contacts on the spatial rows.

    Timed in a child process with one OpenBLAS thread (OPENBLAS_NUM_THREADS=1): numba's matrix
    products call OpenBLAS, whose worker threads on a machine with other work add waiting many
    times the step's own cost (docs/measurements.md), and that is noise, not the method's cost.
    """
    if os.environ.get("OPENBLAS_NUM_THREADS") == "1":
        return _scaling(quick)
    import subprocess
    import sys

    code = f"import json\nfrom planner.bench import _scaling\nprint(json.dumps(_scaling({bool(quick)})))"
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    )
    if done.returncode != 0:
        raise RuntimeError(f"the scaling benchmark's child process failed:\n{done.stderr[-4000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


# ----------------------------------------------------------------------------- planning


#: Scenes of the planning section and their parameters (the paper's scene at v1 = 0.8, where
#: the default plan must push the triangle).
PLANNING_SCENES = ("two_finger_triangle", "four_finger_grasp", "box_push_3d", "box_rotate_3d")
#: Seeds per planning scene (1..PLANNING_SEEDS; --quick: QUICK_PLANNING_SEEDS).
PLANNING_SEEDS = 20
QUICK_PLANNING_SEEDS = 3
#: What `ladder bench` plans unless told (the planar scenes; `make bench-doc` plans all four:
#: box_push_3d's and box_rotate_3d's flat runs take several minutes in all).
DEFAULT_PLANNING_SCENES = ("two_finger_triangle", "four_finger_grasp")
PLANNING_PARAMETERS = {"two_finger_triangle": {"v1": 0.8}}


def planning_scene(name: str) -> tuple[Path, dict]:
    """A planning scene's file and parameter overrides: a shipped scene by its name (with
    PLANNING_PARAMETERS), or any other scenario file by its path (its own parameters)."""
    if name in PLANNING_SCENES:
        return SCENARIOS / f"{name}.toml", PLANNING_PARAMETERS.get(name, {})
    return Path(name), {}


def planning(quick: bool = False, out: Path | None = None, scenes=None, seeds: int | None = None, progress=None) -> dict:
    """The ladder against flat on each scene (a shipped scene's name or a scenario file's path;
    default DEFAULT_PLANNING_SCENES) over seeds 1..seeds (default PLANNING_SEEDS, --quick
    QUICK_PLANNING_SEEDS): `planner.benchmark.ladder_vs_flat`'s result per scene, with the
    scene's file, its parameter overrides and the section's total time."""
    from models.scenario import load_scenario
    from planner.benchmark import ladder_vs_flat

    scenes = DEFAULT_PLANNING_SCENES if scenes is None else scenes
    seeds = range(1, (seeds or (QUICK_PLANNING_SEEDS if quick else PLANNING_SEEDS)) + 1)
    results = {}
    for name in scenes:
        path, params = planning_scene(name)
        t0 = time.perf_counter()
        each = (
            None
            if progress is None
            else (
                lambda run, _n=name: progress(
                    f"bench: planning {_n} seed {run.seed} {run.mode}: {'holds' if run.holds else 'fails'} in {run.wall_s:.1f} s"
                )
            )
        )
        if progress is not None:
            progress(f"bench: planning {name}: loading the kernels (an untimed run of each mode) ...")
        result = ladder_vs_flat(load_scenario(path, params), seeds, progress=each)
        result["parameters"] = params
        result["total_s"] = time.perf_counter() - t0
        results[name] = result
        if out is not None:
            write_ompl_log(out / f"ladder_vs_flat.{Path(name).stem}.log", name, result)
    return results


def write_ompl_log(path: Path, name: str, result: dict) -> Path:
    """One experiment in OMPL's benchmark log format, a 'planner' per mode (ladder, flat)."""
    import ompl

    runs = result["runs"]
    seeds = sorted({r["seed"] for r in runs})
    where = f"scenarios/{name}.toml" if name in PLANNING_SCENES else name
    ladder = ", ".join(f"{rung} {n}" for rung, n in result["budget"]["ladder"].items())
    flat = ", ".join(f"{rung} {n}" for rung, n in result["budget"]["flat"].items())
    lines = [
        f"OMPL version {getattr(ompl, '__version__', '2.0.1')}",
        f"Experiment ladder_vs_flat_{Path(name).stem}",
        f"Running on {socket.gethostname()}",
        f"Starting at {_dt.datetime.now().strftime('%Y-%m-%d %H:%M:%S')}",
        "<<<|",
        f"ladder vs flat planning on {where}, iteration budget {ladder} (flat: {flat}, the whole ladder's), seeds "
        + ", ".join(map(str, seeds)),
        "|>>>",
        "<<<|",
        machine()["cpu"],
        "|>>>",
        f"{seeds[0]} is the random seed",
        "0 seconds per run",
        "0 MB per run",
        f"{len(seeds)} runs per planner",
        f"{result.get('total_s', 0.0):.3f} seconds spent to collect the data",
        "0 enum types",
        "2 planners",
    ]
    for mode in ("ladder", "flat"):
        mine = [r for r in runs if r["mode"] == mode]
        lines += [
            f"control_{mode}",
            "0 common properties",
            "4 properties for each run",
            "time REAL",
            "solved BOOLEAN",
            "propagations INTEGER",
            "seed INTEGER",
            f"{len(mine)} runs",
        ]
        lines += [f"{r['wall_s']:.6f}; {int(r['holds'])}; {r['propagations']}; {r['seed']}; " for r in mine]
        lines.append(".")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


# ----------------------------------------------------------------------------- all


def run_all(
    out: Path,
    doc: Path | None,
    quick: bool = False,
    progress=print,
    scenes=None,
    seeds: int | None = None,
    readme: Path | None = None,
) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    results = {"machine": machine(), "quick": quick, "date": _dt.datetime.now().isoformat(timespec="seconds")}
    for name, fn in (("throughput", throughput), ("work_precision", work_precision), ("stability", stability), ("scaling", scaling)):
        t0 = time.perf_counter()
        progress(f"bench: {name} ...")
        results[name] = fn(quick)
        progress(f"bench: {name} done in {time.perf_counter() - t0:.1f} s")
    progress("bench: planning ...")
    t0 = time.perf_counter()
    results["planning"] = planning(quick, out, scenes, seeds, progress)
    progress(f"bench: planning done in {time.perf_counter() - t0:.1f} s")
    results["plots"] = plot_work_precision(results["work_precision"], out)
    from planner.cli import write_atomic  # a failed write leaves the old file, and is bad input, not a traceback

    write_atomic(out / "bench.json", json.dumps(results, indent=1) + "\n")
    write_reports(results, out, doc, readme)
    return results


#: The sections of a `run_all` result (bench.json), which `load_results` asks of a saved one.
RESULT_SECTIONS = ("machine", "quick", "date", "throughput", "work_precision", "stability", "scaling", "planning", "plots")


def load_results(path: Path) -> tuple[dict | None, list]:
    """A saved `run_all` result (`ladder bench --from`), or the problems reading it."""
    from models.scenario import Problem

    try:
        results = json.loads(path.read_text())
    except OSError as e:
        return None, [Problem("--from", f"{path}: cannot read it ({e.strerror})")]
    except (UnicodeDecodeError, ValueError) as e:
        return None, [Problem("--from", f"{path}: not JSON ({e})")]
    missing = [key for key in RESULT_SECTIONS if key not in results] if isinstance(results, dict) else list(RESULT_SECTIONS)
    if missing:
        return None, [Problem("--from", f"{path}: not a `ladder bench` result (no {', '.join(missing)})")]
    return results, []


def read_readme(readme: Path | None, quick: bool) -> tuple[str | None, list]:
    """The README `--readme` writes this run's figures into, or why it cannot: it must be a
    readable file whose blocks' markers stand as `readme_problems` asks, and the run a full one
    (a --quick run's figures are a smoke test's)."""
    from models.scenario import Problem

    if readme is None:
        return None, []
    if quick:
        return None, [Problem("--readme", "a --quick run's figures do not go into a README: run the full bench (make bench-doc)")]
    try:
        text = readme.read_text()
    except (OSError, UnicodeDecodeError) as e:
        return None, [Problem("--readme", f"{readme}: cannot read it ({e.strerror if isinstance(e, OSError) else e})")]
    return text, [Problem("--readme", f"{readme}: block {p.key}: {p.reason}") for p in readme_problems(text)]


def write_reports(results: dict, out: Path, doc: Path | None = None, readme: Path | None = None) -> None:
    """Write the markdown report to `doc` and the README's figures (`readme_blocks`) into `readme`,
    both made before either is written, each written whole or not at all. `out`: the folder of
    bench.json and the OMPL logs the report links to."""
    from models.scenario import ScenarioError
    from planner.cli import write_atomic  # a failed write leaves the old file, and is bad input, not a traceback

    texts = []
    if doc is not None:
        texts.append(("--doc", doc, markdown(results, doc.parent, out)))
    if readme is not None:
        text, problems = read_readme(readme, bool(results.get("quick")))
        if problems:  # (the README changed while the bench ran)
            raise ScenarioError(readme, problems)
        texts.append(("--readme", readme, with_readme_blocks(text, readme_blocks(results))))
    for key, path, text in texts:
        write_atomic(path, text, key=key)


def _us(value) -> str:
    return "-" if value is None else f"{value:.1f}"


def scaling_markdown(s: dict) -> list[str]:
    """The scaling section: Lemke and PGS side by side per rung and contact count."""

    def table(rows: list[dict]) -> list[str]:
        out = [
            "| rung | boxes | contacts | Lemke us/step | PGS us/step | PGS sweeps/step | Lemke status | PGS status |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for rung in dict.fromkeys(r["rung"] for r in rows):
            for n in dict.fromkeys(r["boxes"] for r in rows if r["rung"] == rung):
                by = {r["solver"]: r for r in rows if r["rung"] == rung and r["boxes"] == n}
                lemke, pgs = by["lemke"], by["pgs"]
                out.append(
                    f"| {rung} | {n} | {lemke['contacts']} | {_us(lemke['us_per_step'])} | {_us(pgs['us_per_step'])} | "
                    f"{pgs['sweeps_per_step']:.2f} | {lemke['status']} | {pgs['status']} |"
                )
        return out

    def count(c) -> str:
        # None: at no count does it stay so through the largest measured (it may be at some: the table has each)
        return "from no count on through the largest measured" if c is None else f"from {c} contacts on"

    def cheaper(lead: str, by_rung: dict) -> str:
        return lead + "; ".join(f"{count(c)} ({rung})" for rung, c in by_rung.items()) + "."

    lines = [
        "",
        "## Scaling with the number of contacts (boxes resting on a plane, h = 1e-3)",
        "",
        f"Cost per step: {s['note']}. OpenBLAS threads: {s['blas_threads']}.",
        "",
        "Boxes apart in a row in the plane:",
        "",
    ]
    lines += table(s["rows"])
    lines += [
        "",
        "Fitted growth exponent of cost per step in the number of contacts (4 and more): "
        + "; ".join(f"{rung}: Lemke {e['lemke']:.2f}, PGS {e['pgs']:.2f}" for rung, e in s["growth_exponent"].items())
        + ".",
        cheaper("PGS is cheaper per step than Lemke ", s["crossover_contacts"]),
        "",
        "A stack of boxes (every contact coupled to the ones above and below; `-`: the first step did not converge):",
        "",
    ]
    lines += table(s["stack_rows"])
    lines += [
        "",
        cheaper("On the stack Lemke is cheaper (or PGS fails) ", s["stack_lemke_cheaper_from"]),
    ]
    if s.get("spatial_rows"):  # (a result saved before they were measured has none)
        lines += ["", "Boxes apart in a row in space (4 contacts each, 4 friction directions):", ""]
        lines += table(s["spatial_rows"])
        lines += ["", cheaper("In space PGS is cheaper per step than Lemke ", s["spatial_crossover_contacts"])]
    auto = s["auto_pgs_contacts"]
    lines += ["", f"The `auto` contact solver switches to PGS from {auto} contacts (a fixed rule, not this run's crossovers)."]
    return lines


def planning_markdown(planning: dict) -> list[str]:
    """The planning section: what its numbers count, then per scene each mode's success and
    medians, the speed-up, and the budgets and parameters the runs had."""
    seeds = sorted({len(res["runs"]) // 2 for res in planning.values()})
    lines = [
        "",
        "## Planning: ladder against flat (equal budgets)",
        "",
        f"Each scene is planned on seeds 1 to {'/'.join(map(str, seeds))}, up the ladder and flat (the top rung alone, "
        "with the iterations of every rung of the ladder: `ladder plan --flat`) in turns, in one process. Success is a "
        "plan that holds at the top rung, checked by replaying it there. Wall time is a run's whole planning "
        "(every rung, tracking and replays included); a failed run counts with the time it spent. The kernels are "
        "loaded before the timed runs (an untimed run of each mode on seed 0); `compile s` is what the timed runs "
        "still spent compiling or loading them. Propagations are the searches' (local repairs included); rollouts "
        "are the control periods tracking rolled out along the previous rung's plan, which the iteration budget "
        "does not cap.",
        "",
        "| scene | mode | success | median wall (s) | median wall, held (s) | median propagations | median rollouts | compile s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for scene, res in planning.items():
        for mode in ("ladder", "flat"):
            x = res["summary"][mode]
            runs = [run for run in res["runs"] if run["mode"] == mode]
            held = x.get("median_wall_s_successful")
            rollouts = x.get("median_rollouts", float(np.median([run["rollouts"] for run in runs])))
            compiling = x.get("compile_s")
            lines.append(
                f"| {scene} | {mode} | {x['success_rate']:.0%} ({sum(run['holds'] for run in runs)} of {len(runs)}) "
                f"| {x['median_wall_s']:.3f} | {'-' if held is None else f'{held:.3f}'} | {x['median_propagations']:g} | {rollouts:g} "
                f"| {'-' if compiling is None else f'{compiling:.2f}'} |"
            )
        lines.append(f"| {scene} | speed-up (median wall, flat / ladder) | | {res['summary']['speedup_median_wall']:.2f}x | | | | |")
        budget = res.get("budget")
        said = (
            "ladder "
            + ", ".join(f"{rung} {n:,}" for rung, n in budget["ladder"].items())
            + "; flat "
            + ", ".join(f"{rung} {n:,}" for rung, n in budget["flat"].items())
            if budget
            else "not recorded"
        )
        params = res.get("parameters") or {}
        notes.append(
            f"- {scene}: iterations {said}"
            + (f"; parameters {', '.join(f'{k} = {v:g}' for k, v in params.items())}" if params else "")
            + (f"; {res['total_s']:.0f} s in all" if "total_s" in res else "")
            + "."
        )
    return lines + ["", "Budgets and parameters, and the section's time per scene (its untimed runs included):", ""] + notes


def markdown(r: dict, doc_dir: Path, out: Path) -> str:
    def rel(p) -> str:
        return os.path.relpath(p, doc_dir)

    m = r["machine"]
    lines = [
        "# Benchmarks",
        "",
        f"Generated by `ladder bench{' --quick' if r['quick'] else ''}` on {r['date']}.",
        f"Machine: {m['cpu']}, {m['cores']} cores, Python {m['python']}, {m['system']}"
        + (f"; kernels tuned for `{m['kernels_tuned_for']}` (`models.cpu_target`)." if m.get("kernels_tuned_for") else "."),
        "",
        "## Throughput (paper's scene, h = 1e-4, until the grasp)",
        "",
        "| rung | steps | with contact force | median wall (s) | steps/s |",
        "|---|---|---|---|---|",
    ]
    for row in r["throughput"]["rows"]:
        lines.append(
            f"| {row['rung']} | {row['steps']} | {row.get('contact_steps', '')} | {row['median_wall_s']:.4f} | {row['steps_per_s']:,.0f} |"
        )
    lines += (
        [""]
        + contact_markdown(r["throughput"].get("contact"))
        + [""]
        + peer_markdown(r["throughput"]["peer"])
        + ["", "## Work-precision", "", "| scene | rung | h | reference | error | wall (s) | status |", "|---|---|---|---|---|---|---|"]
    )
    for row in r["work_precision"]["rows"]:
        lines.append(
            f"| {row['scene']} | {row['rung']} | {row['h']:g} | {row['reference']} | {row['error']:.2e} "
            f"| {row['wall_s']:.4f} | {row['status']} |"
        )
    # the plots are in `out` beside bench.json (their recorded paths are relative to where the run ran)
    lines += [""] + [f"![{Path(p).stem}]({rel(out / Path(p).name)})" for p in r["plots"]]
    lines += [
        "",
        f"## Stability at large steps ({r['stability']['scene']})",
        "",
        "Error: the triangle's x where the run ends against where the reference ends. Largest gap: the"
        " largest difference in x at the same time along the run (the reference interpolated at the"
        " run's steps), and when: the end's error is smaller where the grasp brings both runs together.",
        "",
        "| C | h | outcome | status | bounded | same outcome as h = 1e-5 | triangle x at the end | error | largest gap (at t) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in r["stability"]["rows"]:
        lines.append(
            f"| {row['C']:g} | {row['h']:g} | {row['outcome']} (t = {row['t']:.4f}) | {row['status']} | {row['bounded']} | "
            f"{row['same_outcome']} | {row['triangle_x']:.6f} | {row['x_error']:.2e} | "
            f"{row['largest_x_gap']:.2e} ({row['largest_x_gap_t']:.4f}) |"
        )
    lines += scaling_markdown(r["scaling"])
    lines += planning_markdown(r["planning"])
    lines += ["", f"OMPL benchmark logs: `{rel(out)}/ladder_vs_flat.*.log` (`ompl_benchmark_statistics LOG -d bench.db`).", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- the README's figures

#: The README's blocks that `ladder bench --readme` writes (`readme_blocks`), each between its two
#: markers (`readme_markers`); the rest of the README is left as it is.
README_BLOCKS = ("headline", "figures")


def readme_markers(name: str) -> tuple[str, str]:
    """The lines that open and close the README's block `name`."""
    return f"<!-- ladder bench: {name} -->", f"<!-- /ladder bench: {name} -->"


def _ratio_range(ratios: list[float]) -> str:
    lo, hi = f"{min(ratios):.1f}", f"{max(ratios):.1f}"
    return f"{lo}x" if lo == hi else f"{lo}-{hi}x"


def _contacts(r: dict, prefix: str) -> str:
    """The contacts a step of the cost split's state of this scene has ('' when not measured)."""
    counts = {row["contacts"] for row in (r["throughput"].get("contact") or {}).get("split", []) if row["scene"].startswith(prefix)}
    return f"{counts.pop()} contacts a step" if len(counts) == 1 else ""


def readme_blocks(r: dict) -> dict[str, str]:
    """The README's figures from a full run's results (`run_all`'s, as bench.json holds them):
    `headline`, one paragraph of the ratios that matter, each saying what its steps do; `figures`,
    the tables they come from (steps with and without contact against MuJoCo, the ladder against
    flat) and the stability sweep's errors. The text between the blocks is the README's own."""
    m, peer = r["machine"], r["throughput"]["peer"]
    rows = (r["throughput"].get("contact") or {}).get("rows", [])
    timed = [row for row in rows if row.get("speed_vs_mujoco") is not None]
    squeeze = [row["speed_vs_mujoco"] for row in timed if row["scene"].startswith("two_finger_triangle")]
    push = [row["speed_vs_mujoco"] for row in timed if row["scene"].startswith("box_push_3d") and PLANNERS_WAY in row["scene"]]
    planning = {scene: res["summary"]["speedup_median_wall"] for scene, res in r["planning"].items()}
    seeds = {len(res["runs"]) // 2 for res in r["planning"].values()}
    run = f"`ladder bench` of {r['date'][:10]}, {m['cpu']}, {m['cores']} cores"
    parts = []
    if "skipped" in peer:
        parts.append(f"MuJoCo was not timed in the latest {run} ({peer['skipped']})")
    else:
        free = "free flight (the paper's scene until the grasp: no step carries a contact force)"
        said = [f"{peer['ratio']:.1f}x MuJoCo's steps per second in {free}"]
        if squeeze:  # its run starts in free flight: say how many of its steps carry force
            forced = {(row["contact_steps"], row["steps"]) for row in timed if row["scene"].startswith("two_finger_triangle")}
            share = ""
            if len(forced) == 1:
                ((forced_steps, steps),) = forced
                share = f"{forced_steps:,} of its {steps:,} steps carry contact force"
            what = "; ".join(x for x in (share, _contacts(r, "two_finger_triangle")) if x)
            said.append(f"{_ratio_range(squeeze)} on the paper's scene through the squeeze ({what})")
        if push:
            said.append(
                f"{_ratio_range(push)} on box_push_3d's push ({_contacts(r, 'box_push_3d')}; both friction cones, as a planner calls them)"
            )
        parts.append(
            f"Against MuJoCo {peer['version']} on the same runs, timed in turns ({run}), a step runs at "
            + (", ".join(said[:-1]) + " and " + said[-1] if len(said) > 1 else said[0])
        )
    if planning:
        lo, hi = min(planning, key=planning.get), max(planning, key=planning.get)
        parts.append(
            f"planning up the ladder takes {planning[lo]:.1f}x ({lo}) to {planning[hi]:.1f}x ({hi}) less time than planning at "
            f"the top rung alone (median wall over {'/'.join(str(s) for s in sorted(seeds))} seeds, "
            "a failed run counted at the time it spent)"
        )
    headline = "; ".join(parts) + "."

    figures = [
        f"The latest full {run} ([docs/benchmarks.md](docs/benchmarks.md)). "
        + (
            f"Against MuJoCo {peer['version']} on the same runs (`planner/peers.py`), ours and MuJoCo's timed in turns, "
            f"{peer['repeat']} rounds; speed is ours over MuJoCo's in steps per second, the median of the rounds' ratios:"
            if "skipped" not in peer
            else f"MuJoCo was not timed ({peer['skipped']})."
        ),
        "",
        "| run | rung | h | steps with contact force | ours, us a step | MuJoCo, us a step | speed vs MuJoCo |",
        "|---|---|---|---|---|---|---|",
    ]
    if "skipped" not in peer:
        ours = next(row for row in r["throughput"]["rows"] if row["rung"] == peer["ours"]["rung"])
        figures.append(
            f"| {r['throughput']['scene']}: free flight (MuJoCo: `{peer['against']}`) | {peer['ours']['rung']} | {peer['h']:g} "
            f"| {ours['contact_steps']:,} of {ours['steps']:,} | {1e6 / peer['ours']['steps_per_s']:.2f} "
            f"| {1e6 / peer['steps_per_s']:.2f} | {peer['ratio']:.2f}x |"
        )
    for row in rows:
        theirs, speed = row.get("mujoco_us_per_step"), row.get("speed_vs_mujoco")
        figures.append(
            f"| {row['scene']} | {row['rung']} | {row['h']:g} | {row['contact_steps']:,} of {row['steps']:,} | {row['us_per_step']:.2f} "
            f"| {'-' if theirs is None else f'{theirs:.2f}'} | {'-' if speed is None else f'{speed:.2f}x'} |"
        )
    figures += [
        "",
        "Planning up the ladder against planning at the top rung alone with the ladder's whole budget (`--flat`), "
        "seeds 1 to N each, in turns, the same run:",
        "",
        "| scene | seeds | ladder: success, median wall (s) | flat: success, median wall (s) | speed-up (median wall) |",
        "|---|---|---|---|---|",
    ]
    for scene, res in r["planning"].items():
        x = res["summary"]
        figures.append(
            f"| {scene} | {len(res['runs']) // 2} | {x['ladder']['success_rate']:.0%}, {x['ladder']['median_wall_s']:.3f} "
            f"| {x['flat']['success_rate']:.0%}, {x['flat']['median_wall_s']:.3f} | {x['speedup_median_wall']:.2f}x |"
        )
    st = r["stability"]
    by_c = {}
    for row in st["rows"]:
        by_c.setdefault(row["C"], []).append(row)
    errors = "; ".join(
        f"C = {c:g}: " + ", ".join(f"{row['x_error']:.2e} at h = {row['h']:g}" for row in c_rows) for c, c_rows in by_c.items()
    )
    differ = [f"C = {row['C']:g}, h = {row['h']:g}" for row in st["rows"] if not row["same_outcome"]]
    figures += [
        "",
        f"Stability at large steps ({st['scene']}): "
        + ("every run ends with the reference's outcome" if not differ else f"a run ends unlike the reference at {', '.join(differ)}")
        + f"; the triangle's x there is off by {errors}.",
    ]
    return {"headline": headline, "figures": "\n".join(figures)}


def readme_problems(text: str) -> list:
    """What keeps `with_readme_blocks` from writing into this README: each block's markers must
    stand once each, on lines of their own, the opening one first."""
    from models.scenario import Problem

    problems = []
    lines = text.split("\n")
    for name in README_BLOCKS:
        begin, end = readme_markers(name)
        at = [lines.count(begin), lines.count(end)]
        if at != [1, 1]:
            problems.append(Problem(name, f"needs the lines {begin!r} and {end!r} once each (found {at[0]} and {at[1]})"))
        elif lines.index(begin) > lines.index(end):
            problems.append(Problem(name, f"{begin!r} must come before {end!r}"))
    return problems


def _block_span(lines: list[str], name: str) -> slice:
    """The lines between the markers of block `name` (`readme_problems` must find nothing)."""
    begin, end = readme_markers(name)
    return slice(lines.index(begin) + 1, lines.index(end))


def with_readme_blocks(text: str, blocks: dict[str, str]) -> str:
    """The README `text` with each block's lines between its markers replaced by `blocks[name]`."""
    lines = text.split("\n")
    for name in README_BLOCKS:
        lines[_block_span(lines, name)] = blocks[name].split("\n")
    return "\n".join(lines)


def readme_block_text(text: str, name: str) -> str:
    """What the README `text` holds between the markers of block `name`."""
    lines = text.split("\n")
    return "\n".join(lines[_block_span(lines, name)])


def contact_markdown(contact: dict | None) -> list[str]:
    """The throughput section's contact-dominated runs (`contact_steps`)."""
    if not contact:
        return []
    same = all(row.get("same_end", True) for row in contact["rows"])
    lines = [
        "### Steps with contact",
        "",
        "The runs above until the grasp are free flight (no step carries a contact force). Here the "
        f"steps where contacts push: medians of {contact['repeat']} rounds, each ours then "
        f"{contact.get('peer') or 'MuJoCo (not installed: not timed)'} on the same run (the paper's scene: the `direct` "
        "mapping, palm-triangle left out; box_push_3d: MuJoCo's own contact model, `peers.build_spatial`, "
        "stepped in the same calls from the same first contact). box_push_3d's push is timed two ways in the same "
        "rounds, in calls of one control period each: as a planner calls it (`planner.ompl_adapter.planner_propagation`: "
        "flattened states in and out) and through `Rung.rollout` (as the pipeline replays a plan: a result with "
        "records, the state and its basis table carried from call to call); the two take the same steps "
        f"({'their ends equal, bit for bit' if same else 'NOT the same ends: see same_end in the JSON'}), "
        "against the same MuJoCo rounds. Speed: ours / MuJoCo in steps per second, the median of the rounds' ratios.",
        "",
        "| scene | rung | h | steps | with contact force | contact solve per step | median wall (s) | us/step | MuJoCo us/step "
        "| speed vs MuJoCo |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in contact["rows"]:
        mj = row.get("mujoco_us_per_step")
        theirs = "- | -" if mj is None else f"{mj:.2f} | {row['speed_vs_mujoco']:.2f}x"
        lines.append(
            f"| {row['scene']} | {row['rung']} | {row['h']:g} | {row['steps']} | {row['contact_steps']} "
            f"| {_solve_work(row['pivots_per_step'], row['sweeps_per_step'])} "
            f"| {row['median_wall_s']:.4f} | {row['us_per_step']:.2f} | {theirs} |"
        )
    cones = contact.get("exact_vs_polygon")
    if cones:
        lines += [
            "",
            "box_push_3d's two cones were timed in the same rounds (each round: both cones, each both ways"
            f"{', and MuJoCo' if contact.get('peer') else ''}, in turns): the exact cone's steps/s over the polygon's, the "
            f"median of the rounds' ratios, {cones['planners']:.2f}x "
            f"as a planner calls it and {cones['rollout']:.2f}x through `Rung.rollout`.",
        ]
    if contact.get("split"):
        names = list(contact["split"][0]["us"])
        lines += [
            "",
            "Where a contact step's time goes, at one state of each run (`models.rollout.stage_loop`: each stage "
            f"repeated {contact['split'][0]['repeats']:,} times at the state in each of {contact['split'][0]['rounds']} rounds "
            "that run the stages in turns, us per call, the median of the rounds' (a stage's run less the setup's in "
            "the same round; the step's parts: differences, within a round, of runs that stop after each); the dynamics step "
            "in its three parts (`models.stepper.contact_stage`; on a state whose LCP the previous basis solves, the "
            "warm step the rollout takes there, `models.stepper.planar_warm_step` in the plane, "
            "`models.stepper.spatial_warm_step` in space; with PGS, `models.stepper.pgs_warm_step`): A^-1's "
            "rotating bodies' blocks where A depends on q, the free "
            "velocity and the LCP's assembly (PGS "
            "assembles its blocks in its solve), the warm-started contact solve, the impulses' velocity update and the "
            "integration). The solve is warm-started from the state's own solution, so it does less work there than a "
            "step of the runs above does on average (the two `contact solve` columns: Lemke pivots, PGS sweeps); the "
            "rest of the difference is the rollout's bookkeeping (records, forces, the warm start's table), and each "
            "stage timed here also pays a compiled call's argument handling. The last column is the interquartile range of "
            "the rounds' sums, this machine's noise on one round:",
            "",
            "| state | contacts | contact solve at the state | " + " | ".join(names) + " | sum | rounds' spread |",
            "|---|---|---|" + "---|" * (len(names) + 2),
        ]
        for split in contact["split"]:
            cells = " | ".join(f"{split['us'][name]:.2f}" for name in names)
            at_state = _solve_work(split["pivots"], split["sweeps"])
            total = sum(split["us"].values())
            lines.append(f"| {split['scene']} | {split['contacts']} | {at_state} | {cells} | {total:.2f} | {split['spread_us']:.2f} |")
    return lines


def _solve_work(pivots: float, sweeps: float) -> str:
    """The contact solves' work (a run's per step, or one solve's): PGS sweeps where it swept, else
    Lemke pivots."""
    return f"{sweeps:.2f} sweeps" if sweeps else f"{pivots:.2f} pivots"


def peer_markdown(peer: dict) -> list[str]:
    """The throughput section's MuJoCo part: timing per contact mapping, then the stability sweep."""
    if "skipped" in peer:
        return [f"Peer (MuJoCo): skipped: {peer['skipped']}."]

    def q(values: dict) -> str:
        return ", ".join(f"{k} = {v:.4g}" for k, v in values.items())

    def t(value) -> str:
        return "-" if value is None else f"{value:.4f}"

    lines = [
        f"### Peer: MuJoCo {peer['version']}",
        "",
        f"The same scene built in MuJoCo (`planner/peers.py`), MuJoCo's default integrator ({peer['integrator']}), "
        f"h = {peer['h']:g}, the same {peer['steps']} steps ({peer['simulated_s']:.4f} s simulated) in one "
        f"`mj_step(nstep=...)` call; ours and MuJoCo timed in turns, {peer['repeat']} rounds, medians (the ratio: "
        "median of the rounds' ratios). Inert pairs (" + (", ".join(peer["inert_pairs"]) or "none") + "): no free DOF "
        "feels them; our stepper drops their contacts, MuJoCo solves their rows unless they are left out. Contact mappings: "
        + "; ".join(f"`{k}`: {v}" for k, v in peer["mapping"].items())
        + ".",
        "",
        f"| contact mapping | inert pairs left out | steps/s | {peer['ours']['rung']} / MuJoCo "
        "| outcome at the end | fingers touching | end state |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in peer["rows"]:
        end = row["end"]
        touching = ", ".join(f"{k}: {'yes' if v else 'no'}" for k, v in end["touching"].items())
        left_out = ", ".join(row["inert_pairs_left_out"]) or "none"
        lines.append(
            f"| {row['contact']} | {left_out} | {row['steps_per_s']:,.0f} | {row['ratio']:.2f}x "
            f"| {end['outcome'] or '-'} | {touching} | {q(end['q'])} |"
        )
    lines += [
        "",
        f"Ours ({peer['ours']['rung']}, {peer['ours']['steps_per_s']:,.0f} steps/s in these rounds) against the faster MuJoCo mapping "
        f"(`{peer['against']}`): **{peer['ratio']:.2f}x**.",
        "",
    ]
    st = peer["stability"]
    lines += [
        f"### Stability over h (the policy for its full duration; goal and unsafe checked every {st['period'] * 1e3:g} ms)",
        "",
        "| scene | simulator | h | goal first at (s) | unsafe first at (s) | max abs object displacement (m) "
        "| outcome at the end | end state | status |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in st["rows"]:
        lines.append(
            f"| {row['scene']} | {row['simulator']} | {row['h']:g} | {t(row['goal_at'])} | {t(row['unsafe_at'])} | "
            f"{row['max_object_displacement']:.3g} | {row['end'] or '-'} | {q(row['end_q'])} | {row['status']} |"
        )
    return lines

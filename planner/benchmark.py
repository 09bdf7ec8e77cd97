"""Planning benchmarks: the ladder against planning flat at the top rung.

`ladder_vs_flat` runs both over several seeds with equal budgets (flat gets the iterations of
every rung of the ladder) and reports, per mode, the success rate (a plan that holds at the
top rung, checked by replaying it there) and the median wall time, propagation count and
tracking rollouts of the runs; unsuccessful runs count with the time they spent. Before the
timed runs, one untimed run of each mode (seed 0, a small budget) loads every kernel the runs
use; each run's `compile_s` is what it still spent compiling or loading them (0 once warm).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from models.scenario import Scenario
from models.task import Outcome


@dataclass
class Run:
    mode: str  # ladder or flat
    seed: int
    holds: bool
    wall_s: float
    propagations: int  # of the searches (local repairs included)
    rollouts: int  # control periods rolled out by tracking
    rungs: str  # how each rung ended
    compile_s: float = 0.0  # of wall_s, compiling or loading kernels (0 once the warm-up loaded them)


def ladder_vs_flat(
    scenario: Scenario, seeds, *, iterations: int | None = None, rungs: list[str] | None = None, planner: str | None = None, progress=None
) -> dict:
    """Both modes on each seed; see the module docstring. Returns runs and a summary."""
    from planner.ladder import assess, run_ladder, rung_budgets

    _warm_up(scenario, rungs, planner)
    runs: list[Run] = []
    for seed in seeds:
        for mode in ("ladder", "flat"):
            t0 = time.perf_counter()
            result = run_ladder(scenario, rungs=rungs, seed=int(seed), iterations=iterations, flat=mode == "flat", planner=planner)
            wall = time.perf_counter() - t0
            top = result.rungs[-1] if result.rungs else None
            holds = bool(
                result.top_holds
                and top is not None
                and assess(scenario, top.rung, top.controls, top.durations)["outcome"] == Outcome.GOAL.label
            )
            runs.append(
                Run(
                    mode,
                    int(seed),
                    holds,
                    wall,
                    sum(r.propagations for r in result.rungs),
                    sum(r.rollouts for r in result.rungs),
                    ", ".join(f"{r.label}: {r.ended.label}" for r in result.rungs),
                    sum(r.compile_s for r in result.rungs),
                )
            )
            if progress:
                progress(runs[-1])
    summary = {}
    for mode in ("ladder", "flat"):
        mine = [r for r in runs if r.mode == mode]
        summary[mode] = {
            "success_rate": float(np.mean([r.holds for r in mine])),
            "median_wall_s": float(np.median([r.wall_s for r in mine])),
            "median_wall_s_successful": float(np.median([r.wall_s for r in mine if r.holds])) if any(r.holds for r in mine) else None,
            "median_propagations": float(np.median([r.propagations for r in mine])),
            "median_rollouts": float(np.median([r.rollouts for r in mine])),
            "compile_s": float(sum(r.compile_s for r in mine)),
        }
    ladder, flat = summary["ladder"], summary["flat"]
    summary["speedup_median_wall"] = flat["median_wall_s"] / ladder["median_wall_s"] if ladder["median_wall_s"] > 0 else None
    names = rungs or [r.model for r in scenario.spec.ladder.rungs]
    budget = {"ladder": rung_budgets(scenario, names, iterations)[0], "flat": rung_budgets(scenario, names, iterations, flat=True)[0]}
    return {
        "scenario": str(scenario.path),
        "iterations": iterations,
        "budget": budget,
        "runs": [asdict(r) for r in runs],
        "summary": summary,
    }


#: The warm-up runs' iterations per rung: enough to run every rung's search and tracking once.
WARM_UP_ITERATIONS = 20


def _warm_up(scenario: Scenario, rungs: list[str] | None, planner: str | None) -> None:
    """One untimed run of each mode on seed 0 (which the timed runs do not use) with a small
    budget, so that compiling or loading the kernels (the rungs' rollouts, the geometric rung's
    motions, tracking's) is not timed in whichever run comes first."""
    from planner.ladder import run_ladder

    for flat in (False, True):
        run_ladder(scenario, rungs=rungs, seed=0, iterations=WARM_UP_ITERATIONS, flat=flat, planner=planner)

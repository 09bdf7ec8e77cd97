"""What the service's viewer (static/index.html) draws: a job's scene and, for a plan, where
every body is at each state of each rung. The kinematics stay here (Scenario.placements): the
page only applies the placements to the shapes and projects spatial scenes onto x-y (a top view).
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from models.geometry import read_obj
from models.scenario import load_scenario
from planner.plan_status import rung_label
from planner.service.jobs import write_inputs


def _placement(p) -> dict:
    """A placement as JSON: translation t and rotation R (row-major, 2x2 planar, 3x3 spatial)."""
    return {"t": [round(float(x), 9) for x in p.translation], "R": [round(float(x), 9) for x in p.rotation.ravel()]}


def scene_view(inputs: dict, result: str | None = None) -> dict:
    """The scene of a job's `inputs` (parameters applied): `dimension`, `coordinates`, and per
    body its name, role, shape (the scenario's, lengths in metres in the body frame; a mesh
    with its scaled `vertices`), whether it `moves` (has DOFs) and its `start` placement. With a
    plan's `result` (plan.json text), `rungs`: per rung its name and `label`, `times` (s, from 0; one per
    state) and `placements` (per state, the moving bodies' placements)."""
    with tempfile.TemporaryDirectory(prefix="ladder-view-") as tmp:
        root = Path(tmp)
        path = write_inputs(root, inputs)
        scenario = load_scenario(root / path, inputs.get("parameters") or {})
        bodies = []
        start = scenario.placements(scenario.start)
        for body in scenario.spec.bodies:
            shape = body.shape.model_dump(mode="json")
            if shape["type"] == "mesh":
                vertices, _ = read_obj(root / path.parent / shape["file"])
                shape["vertices"] = (vertices * shape["scale"]).round(9).tolist()
            bodies.append(
                {"name": body.name, "role": body.role, "shape": shape, "moves": bool(body.dofs), "start": _placement(start[body.name])}
            )
    view = {
        "name": scenario.spec.scenario.name,
        "dimension": scenario.dimension,
        "coordinates": list(scenario.coordinates),
        "bodies": bodies,
    }
    if result is not None:
        plan = json.loads(result)
        if isinstance(plan, dict) and isinstance(plan.get("rungs"), list):
            view["rungs"] = [_rung_view(scenario, rung) for rung in plan["rungs"]]
    return view


def _rung_view(scenario, rung: dict) -> dict:
    moving = [b.name for b in scenario.spec.bodies if b.dofs]
    times = [0.0] if rung.get("states") else []  # (one per state: an omitted or skipped rung has none)
    for duration in rung.get("durations", [])[: max(0, len(rung.get("states", [])) - 1)]:
        times.append(times[-1] + float(duration))
    placements = []
    for state in rung.get("states", []):
        at = scenario.placements(state)
        placements.append({name: _placement(at[name]) for name in moving})
    return {
        "rung": rung.get("rung"),
        "label": rung_label(rung),
        "ended": rung.get("ended"),
        "outcome": rung.get("outcome"),
        "times": times,
        "placements": placements,
    }

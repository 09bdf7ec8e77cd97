"""`make paper`'s report (planner.paper) on runs made up here: the penetration table and the
statement it feeds, which say where a compliant model's grasp is held by its contact's
deformation."""

from __future__ import annotations

from planner import paper
from planner import sweep as sw


def point(model: str, mu: float, v1: float, outcome: str, penetration: float) -> sw.Point:
    return sw.Point(model, {"v1": v1, "mu": mu}, outcome, 1.0, "ok", {}, 100, 0.0, penetration)


POINTS = [
    point("quasistatic", 1.2, 0.5, "goal", 1e-15),
    point("plastic", 1.2, 0.5, "goal", 0.2),
    point("plastic", 1.2, 2.0, "goal", 0.005),
    point("plastic", 0.3, 2.0, "unsafe", 0.3),  # deep, but no grasp: in the table, not in the list
    None,  # a run a cancelled sweep did not make
]


def test_the_penetration_table_takes_the_deepest_run_per_model_and_mu_and_names_deep_grasps():
    lines = paper._penetration_section(POINTS)
    rows = {line.split(" | ")[0].lstrip("| "): line for line in lines if line.startswith("| (")}
    assert rows[paper.TITLES["quasistatic"]].endswith("| - | - | - | 1e-15 |")
    assert rows[paper.TITLES["plastic"]].endswith("| 0.3 | - | - | 0.2 |")
    assert rows[paper.TITLES["elastic"]].endswith("| - | - | - | - |")
    assert lines[-1] == (
        f"Grasps reached with more than {paper.DEEP:g} m of penetration: plastic at mu = 1.2: 1 of its 2 grasps "
        "(the deepest 0.200 m, at rho = 0.5)."
    )
    assert paper._penetration_section([None]) == []


def test_the_wide_friction_statement_gives_each_compliant_models_deepest_grasp_at_mu_1_2():
    bands = {m: {} for m in paper.TITLES}
    text = paper._wide_statement(bands, {}, POINTS)
    assert "as deep at mu = 1.2 as plastic 0.2 m (the penetration table above)" in text
    assert "as deep" not in paper._wide_statement(bands, {}, [])

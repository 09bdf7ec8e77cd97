"""Scenario files: every shipped scenario loads; the paper's scene is what the issue says;
parameters and overrides resolve; every bad file is rejected with its key and reason."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from models.scenario import ScenarioError, load_scenario, parse_overrides
from tests.conftest import DATA, SCENARIOS

SHIPPED = sorted(SCENARIOS.glob("*.toml"))
BAD = sorted((DATA / "bad").glob("*.toml"))


def expectation(path: Path) -> tuple[str, str]:
    lines = path.read_text().splitlines()
    key = next(l for l in lines if l.startswith("# expect-key:")).split(":", 1)[1].strip()
    reason = next(l for l in lines if l.startswith("# expect-reason:")).split(":", 1)[1].strip()
    return key, reason


def test_all_five_scenarios_ship():
    names = {p.stem for p in SHIPPED}
    assert {"two_finger_triangle", "four_finger_grasp", "incline_block", "free_transfer", "box_push_3d"} <= names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_scenarios_load(path):
    scenario = load_scenario(path)
    assert len(scenario.start) == len(scenario.coordinates)
    assert set(scenario.actuated) <= set(scenario.coordinates)
    assert not scenario.start.flags.writeable


def test_paper_scene_as_the_issue_reads_it(triangle_file):
    s = load_scenario(triangle_file)
    assert s.dimension == 2
    assert s.coordinates == ("triangle.x", "finger1.y", "finger2.y")
    assert s.actuated == ("finger1.y", "finger2.y")
    np.testing.assert_allclose(s.start, [0.0, 2.05, 2.05])
    tri = s.body("triangle")
    assert tri.mass == 1.0 and tri.dofs == ("x",)
    np.testing.assert_allclose(s.geometries["triangle"].core, [[-1, 0], [1, 0], [0, 1]])
    for name, x in (("finger1", -0.5), ("finger2", 0.5)):
        finger = s.body(name)
        assert finger.shape.radius == 0.05 and finger.pose.x == x and finger.dofs == ("y",)
        # lowest point 2 above the palm: the paper's depth x = 0
        assert finger.pose.y - finger.shape.radius == pytest.approx(2.0)
    materials = {frozenset((p.body_a, p.body_b)): p for p in s.pairs}
    assert materials[frozenset(("palm", "triangle"))].mu == 0.0  # frictionless palm
    finger_pair = materials[frozenset(("finger1", "triangle"))]
    assert (finger_pair.mu, finger_pair.K, finger_pair.C) == (0.5, 1e6, 1e4)
    assert s.parameters["v1"] == 1.0 and s.parameters["v2"] == 1.0
    assert s.spec.task.policy.speeds == {"finger1.y": -1.0, "finger2.y": -1.0}


def test_overrides_reach_every_reference(triangle_file):
    s = load_scenario(triangle_file, {"mu": 1.2, "v1": 0.7, "C": 0.0})
    materials = {frozenset((p.body_a, p.body_b)): p for p in s.pairs}
    assert materials[frozenset(("finger2", "triangle"))].mu == 1.2
    assert materials[frozenset(("palm", "triangle"))].C == 0.0
    assert s.spec.task.policy.speeds["finger1.y"] == pytest.approx(-0.7)
    assert s.parameters["mu"] == 1.2


def test_expressions_in_the_incline():
    s = load_scenario(SCENARIOS / "incline_block.toml", {"slope_deg": 20.0})
    alpha = math.radians(20.0)
    block = s.body("block")
    assert block.pose.theta == pytest.approx(alpha)
    assert block.pose.x == pytest.approx(-0.05 * math.sin(alpha))
    assert block.pose.y == pytest.approx(0.05 * math.cos(alpha))


def test_unknown_override_is_rejected(triangle_file):
    with pytest.raises(ScenarioError) as info:
        load_scenario(triangle_file, {"nope": 1.0})
    assert info.value.problems[0].key == "overrides['nope']"  # the library's own argument
    assert "no parameter 'nope'" in info.value.problems[0].reason
    with pytest.raises(ScenarioError) as info:
        load_scenario(triangle_file, {"nope": 1.0}, override_key="--param {}")
    assert info.value.problems[0].key == "--param nope"  # as the CLI names it


@pytest.mark.parametrize("value", ["0.3", True, float("nan"), float("inf"), None])
def test_an_override_that_is_not_a_finite_number_is_refused_under_its_name(triangle_file, value):
    with pytest.raises(ScenarioError) as info:
        load_scenario(triangle_file, {"mu": value})
    assert [(p.key, p.reason) for p in info.value.problems] == [("overrides['mu']", f"must be a finite number, got {value!r}")]
    assert load_scenario(triangle_file, {"mu": np.float64(0.3), "v1": 2}).parameters["mu"] == 0.3  # numpy's numbers and ints are numbers


@pytest.mark.parametrize("item", ["mu", "mu=", "=1", "mu=abc", "mu=inf", "mu=nan"])
def test_malformed_override_items(item):
    with pytest.raises(ScenarioError):
        parse_overrides([item])


def test_override_items_parse():
    assert parse_overrides(["mu=0.3", " v1 = 2"]) == {"mu": 0.3, "v1": 2.0}


def test_at_least_twenty_distinct_bad_files():
    assert len(BAD) >= 20
    assert len({expectation(p) for p in BAD}) == len(BAD)


@pytest.mark.parametrize("path", BAD, ids=lambda p: p.stem)
def test_bad_file_is_rejected_with_key_and_reason(path):
    key, reason = expectation(path)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    first = info.value.problems[0]
    assert first.key == key
    assert reason in first.reason
    assert str(info.value).splitlines()[0].startswith(f"{path}: ")


def test_a_bad_parameter_value_is_its_one_problem(tmp_path, triangle_file):
    """A parameter given as text is refused under its own key, and the keys that use it are not
    also said to name an unknown parameter (they had been: a second and third line blaming
    contact.pairs[0].mu for the parameter's own fault)."""
    text = triangle_file.read_text()
    assert "\nmu = 0.5 " in text
    path = tmp_path / "text_mu.toml"
    path.write_text(text.replace("\nmu = 0.5 ", '\nmu = "0.5" ', 1))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert [(p.key, p.reason) for p in info.value.problems] == [("parameters.mu", "a parameter value must be a number, got '0.5'")]
    path.write_text(text.replace("\nmu = 0.5 ", "\nmu = inf ", 1))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert [(p.key, p.reason) for p in info.value.problems] == [("parameters.mu", "must be a finite number, got inf")]


def test_loads_of_one_file_share_its_parse_and_nothing_else(tmp_path, triangle_file):
    """`load_scenario` keeps the last few files' parsed text (a sweep loads one file at every
    grid point): one load's overrides do not reach the next, and an edited file is read anew."""
    fast = load_scenario(triangle_file, {"v1": 3.0, "mu": 0.9})
    plain = load_scenario(triangle_file)
    assert fast.spec.task.policy.speeds["finger1.y"] == -3.0 and plain.spec.task.policy.speeds["finger1.y"] == -1.0
    assert plain.parameters["mu"] == 0.5 and fast.parameters["mu"] == 0.9
    path = tmp_path / "edited.toml"
    path.write_text(triangle_file.read_text())
    assert load_scenario(path).body("triangle").mass == 1.0
    path.write_text(triangle_file.read_text().replace("mass = 1.0", "mass = 2.5", 1))
    assert load_scenario(path).body("triangle").mass == 2.5


def test_missing_file_is_an_error(tmp_path):
    with pytest.raises(ScenarioError, match="no such file"):
        load_scenario(tmp_path / "nope.toml")


def test_not_utf8_is_an_error(tmp_path):
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(b"name = '\xe9'\n")
    with pytest.raises(ScenarioError, match="not UTF-8"):
        load_scenario(bad)


def test_every_problem_is_reported_not_only_the_first(tmp_path):
    text = (DATA / "good" / "minimal_triangle.toml").read_text()
    text = text.replace("mass = 1.0", "mass = -1.0").replace("h = 1e-4", "h = 0.0")
    path = tmp_path / "two_problems.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    keys = [p.key for p in info.value.problems]
    assert "bodies[1].mass" in keys and "ladder.rungs[1].h" in keys


def test_missing_mesh_names_the_file(tmp_path):
    text = (SCENARIOS / "box_push_3d.toml").read_text().replace("meshes/wedge.obj", "meshes/nowhere.obj")
    path = tmp_path / "box.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.problems[0].key == "bodies[4].shape.file"
    assert "nowhere.obj" in info.value.problems[0].reason


def test_non_convex_mesh_is_rejected(tmp_path):
    (tmp_path / "meshes").mkdir()
    # a cube with one vertex pushed inwards: a dent
    cube = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    cube[7] = (0.4, 0.4, 0.4)
    faces = [(1, 3, 4, 2), (5, 6, 8, 7), (1, 2, 6, 5), (3, 7, 8, 4), (1, 5, 7, 3), (2, 4, 8, 6)]
    obj = "".join(f"v {x} {y} {z}\n" for x, y, z in cube) + "".join("f " + " ".join(map(str, f)) + "\n" for f in faces)
    (tmp_path / "meshes" / "wedge.obj").write_text(obj)
    path = tmp_path / "box.toml"
    path.write_text((SCENARIOS / "box_push_3d.toml").read_text())
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.problems[0].key == "bodies[4].shape.file"
    assert "not convex" in info.value.problems[0].reason


WEDGE_V = "v -0.1 -0.15 0.0\nv 0.1 -0.15 0.0\nv -0.1 -0.15 0.15\nv -0.1 0.15 0.0\nv 0.1 0.15 0.0\nv -0.1 0.15 0.15\n"
WEDGE_F = "f 1 3 2\nf 4 5 6\nf 1 2 5 4\nf 2 3 6 5\nf 1 4 6 3\n"


def _wedge_problem(tmp_path, obj: str, name: str = "wedge.obj") -> str:
    """box_push_3d with its wedge's mesh file replaced by `obj`: the load's one problem, or "" if it loads."""
    (tmp_path / "meshes").mkdir(exist_ok=True)
    (tmp_path / "meshes" / name).write_text(obj)
    path = tmp_path / "box.toml"
    path.write_text((SCENARIOS / "box_push_3d.toml").read_text().replace("meshes/wedge.obj", f"meshes/{name}"))
    try:
        load_scenario(path)
    except ScenarioError as exc:
        assert [p.key for p in exc.problems] == ["bodies[4].shape.file"]
        return exc.problems[0].reason
    return ""


@pytest.mark.parametrize(
    ("obj", "message"),
    [
        # a vertex line of two numbers had been a traceback (numpy's inhomogeneous shape)
        (
            WEDGE_V.replace("v 0.1 -0.15 0.0", "v 0.1 -0.15") + WEDGE_F,
            "wedge.obj line 2: a vertex needs three coordinates, x y z: 'v 0.1 -0.15'",
        ),
        (WEDGE_V + WEDGE_F.replace("f 1 3 2", "f 1 3"), "wedge.obj line 7: a face needs at least three vertices: 'f 1 3'"),
        (WEDGE_V + WEDGE_F.replace("f 1 3 2", "f 1 3 0"), "wedge.obj line 7: a face refers to a vertex that does not exist: 'f 1 3 0'"),
        (WEDGE_V + WEDGE_F.replace("f 1 3 2", "f 1 3 -7"), "line 7: a face refers to a vertex that does not exist"),
        # a face missing: the wedge's hull, silently, had been the body
        (WEDGE_V + WEDGE_F.replace("f 1 3 2\n", ""), "mesh is not closed: 3 edge(s) border one face only, or more than two"),
        (WEDGE_V + "f 1 2 5 4\n", "mesh is not closed: 4 edge(s)"),
        ("solid wedge\n facet normal 0 0 -1\n  outer loop\n   vertex 0 0 0\n  endloop\n endfacet\nendsolid\n", "not a Wavefront OBJ file"),
    ],
)
def test_a_mesh_file_is_read_as_obj_says_and_must_be_closed(tmp_path, obj, message):
    assert message in _wedge_problem(tmp_path, obj)


def test_a_mesh_with_relative_indices_or_a_vertex_per_face_is_the_same_solid(tmp_path):
    """OBJ's negative indices count back from the vertices read so far; a file that repeats a
    vertex for each face it is on (as exporters write with normals) is closed once welded."""
    assert (
        _wedge_problem(
            tmp_path, WEDGE_V + "".join("f " + " ".join(str(int(i) - 7) for i in line.split()[1:]) + "\n" for line in WEDGE_F.splitlines())
        )
        == ""
    )
    corners = [line for line in WEDGE_V.splitlines()]
    unwelded = "".join("".join(corners[int(i) - 1] + "\n" for i in line.split()[1:]) for line in WEDGE_F.splitlines())
    counts = [len(line.split()) - 1 for line in WEDGE_F.splitlines()]
    starts = np.cumsum([0] + counts[:-1])
    faces = "".join("f " + " ".join(str(s + k + 1) for k in range(n)) + "\n" for s, n in zip(starts, counts))
    assert _wedge_problem(tmp_path, unwelded + faces, "split.obj") == ""


def test_principal_moments_no_rigid_body_has_are_refused(tmp_path):
    """Each principal moment of a rigid body is at most the sum of the other two (a flat plate's
    equals it); [1e-4, 1e-4, 1e-2] had loaded."""
    text = (SCENARIOS / "box_push_3d.toml").read_text().replace("meshes/wedge.obj", str(SCENARIOS / "meshes" / "wedge.obj"))
    old = 'inertia = ["box_mass * (0.2**2 + 0.1**2) / 12", "box_mass * (0.2**2 + 0.1**2) / 12", "box_mass * (0.2**2 + 0.2**2) / 12"]'
    assert old in text
    path = tmp_path / "box.toml"
    path.write_text(text.replace(old, "inertia = [1e-4, 1e-4, 1e-2]"))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert [(p.key, p.reason) for p in info.value.problems] == [
        (
            "bodies[1].inertia",
            "no rigid body has these principal moments: 0.01 is more than the sum of the other two (0.0001 + 0.0001); "
            "each is at most the sum of the others",
        )
    ]
    path.write_text(text.replace(old, "inertia = [0.01, 0.005, 0.005]"))  # a flat plate's: the bound itself
    assert load_scenario(path).spec.bodies[1].inertia == (0.01, 0.005, 0.005)


def test_spatial_pose_checks(tmp_path):
    text = (SCENARIOS / "box_push_3d.toml").read_text()
    text = text.replace("pose = { x = 0.0, y = 0.0, z = 0.05 }", "pose = { x = 0.0, y = 0.0, z = 0.05, quaternion = [1.0, 0.1, 0.0, 0.0] }")
    path = tmp_path / "box.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.problems[0].key == "bodies[1].pose.quaternion"
    assert "unit quaternion" in info.value.problems[0].reason


def test_box_sunk_into_the_table_reports_its_depth(tmp_path):
    text = (SCENARIOS / "box_push_3d.toml").read_text().replace("z = 0.05 }\ndofs", "z = 0.02 }\ndofs")
    text = text.replace("meshes/wedge.obj", str(SCENARIOS / "meshes" / "wedge.obj"))
    path = tmp_path / "box.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.problems[0].key == "bodies[1].pose"
    assert "depth 0.03 m" in info.value.problems[0].reason


def test_spatial_rotation_coordinates():
    s = load_scenario(SCENARIOS / "box_push_3d.toml")
    assert s.coordinates[:7] == ("box.x", "box.y", "box.z", "box.qw", "box.qx", "box.qy", "box.qz")
    assert s.velocities[:6] == ("box.x", "box.y", "box.z", "box.wx", "box.wy", "box.wz")
    assert s.actuated == ("pusher.x", "pusher.y")
    np.testing.assert_allclose(s.start[3:7], [1, 0, 0, 0])

"""Bad scenario input as the user meets it: `ladder check FILE` ends in the expected
`error: FILE: KEY: reason` line(s) with exit code 2 -- no traceback, no warning, no silent
acceptance -- and the loader's limits sit where the format says they do."""

from __future__ import annotations

import re

import pytest

from models.scenario import ScenarioError, load_scenario
from planner.pytest_plugin import _is_scenario_file
from tests.conftest import DATA, SCENARIOS
from tests.test_cli import ladder
from tests.test_scenarios import expectation

BAD = DATA / "bad"

#: Bad files for: touch on pairs that never touch, strict booleans and integers, nesting,
#: bounds on numbers, a zero quaternion, predicate tables with two kinds, start values
#: outside a drive's limits, and the plain wording of type and shape errors.
FILES = [
    "touch_disabled_pair",
    "touch_disabled_pair_nested",
    "touch_fixed_pair",
    "boolean_string",
    "boolean_integer",
    "integer_boolean",
    "integer_not_number",
    "nesting_too_deep",
    "array_too_deep",
    "predicate_too_deep",
    "huge_vertex",
    "huge_radius",
    "huge_mass",
    "huge_gain",
    "huge_horizon",
    "huge_mesh",
    "zero_quaternion",
    "inertia_not_positive_definite",
    "predicate_two_keys",
    "start_above_limit",
    "pose_below_limit",
    "number_not_list",
    "normal_wrong_length",
    "list_not_number",
    "string_dimension",
    "bad_name",
    "unknown_rung",
    "unknown_shape",
    "wrong_type",
    "geometric_planner_est",
    "geometric_planner_prm",
    "expect_case_unknown_parameter",
    "expect_case_unknown_policy",
    "expect_case_name_twice",
    "expect_seed_without_plan",
    "expect_case_reserved_name",
    "expect_case_seed_without_plan",
    "expect_case_invalid_variant",
]


def expected_lines(path) -> int:
    line = next((l for l in path.read_text().splitlines() if l.startswith("# expect-lines:")), None)
    return int(line.split(":", 1)[1]) if line else 1


@pytest.mark.parametrize("name", FILES)
def test_check_reports_the_key_and_reason(name):
    path = BAD / f"{name}.toml"
    key, reason = expectation(path)
    result = ladder("check", str(path))
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stdout == ""
    assert "Traceback" not in result.stderr and "Warning" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == expected_lines(path), result.stderr
    prefix = f"error: {path}: {key}: " if key else f"error: {path}: "
    assert lines[0].startswith(prefix), result.stderr
    assert reason in lines[0]
    assert all(line.startswith(f"error: {path}: ") for line in lines), result.stderr  # (each problem's line)


@pytest.mark.parametrize("command", [["simulate", "--model", "kinematic"], ["plan"]])
def test_disabled_touch_stops_simulate_and_plan_too(command, tmp_path):
    path = BAD / "touch_disabled_pair.toml"
    out = ["--out", str(tmp_path / "plan")] if command == ["plan"] else []
    result = ladder(command[0], str(path), *command[1:], *out)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr + result.stdout
    assert result.stderr.startswith(f"error: {path}: task.goal.all[0].touch: ")
    assert "disabled" in result.stderr
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- limits, directly


GOOD = (DATA / "good" / "minimal_triangle.toml").read_text()
UNSAFE = 'unsafe = { not = { box = { "triangle.x" = [-0.51, 0.51] } } }'


def _scene(tmp_path, text):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


def _nested_unsafe(levels: int) -> str:
    """An unsafe predicate `levels` predicates deep: nots around a box."""
    return GOOD.replace(
        UNSAFE, "unsafe = " + "{ not = " * (levels - 1) + '{ box = { "triangle.x" = [-0.51, 0.51] } }' + " }" * (levels - 1)
    )


def test_predicates_32_deep_load_and_33_do_not(tmp_path):
    scenario = load_scenario(_scene(tmp_path, _nested_unsafe(32)))
    from models.predicates import compile_predicate

    assert len(compile_predicate(scenario, scenario.spec.task.unsafe).op) == 32
    with pytest.raises(ScenarioError) as info:
        load_scenario(_scene(tmp_path, _nested_unsafe(33)))
    assert [(p.key, "at most 32" in p.reason) for p in info.value.problems] == [("task.unsafe", True)]


def test_deep_any_all_nesting_is_counted_too(tmp_path):
    deep = "{ any = [ " * 20 + "{ all = [ " * 20 + '{ box = { "triangle.x" = [-0.51, 0.51] } }' + " ] }" * 40
    with pytest.raises(ScenarioError) as info:
        load_scenario(_scene(tmp_path, GOOD.replace(UNSAFE, f"unsafe = {deep}")))
    assert info.value.problems[0].key == "task.unsafe"
    assert "nested 41 levels" in info.value.problems[0].reason


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("x = -0.5, y = 2.05", "x = -1e6, y = 2.05", None),
        ("x = -0.5, y = 2.05", "x = -1.5e6, y = 2.05", "bodies[2].pose.x"),
        ("radius = 0.05", "radius = 1.01e6", "bodies[2].shape.radius"),
        ("mass = 1.0", "mass = 1e6", None),
        ("mass = 1.0", "mass = 2e6", "bodies[1].mass"),
        ("mass = 1.0", "mass = 1e-7", "bodies[1].mass"),
        ("K = 1e6", "K = 1e12", None),
        ("K = 1e6", "K = 1e13", "contact.K"),
        ("max_speed = 2.0", "max_speed = 1e300", "bodies[2].actuators.y.max_speed"),
        ("h = 1e-2", "h = 1e300", "ladder.rungs[0].h"),
        ("gravity = [0.0, -9.81]", "gravity = [0.0, -1e300]", "scene.gravity[1]"),
        ('speeds = { "finger1.y" = "-v1" }', 'speeds = { "finger1.y" = "-v1 * 1e300" }', 'task.policy.speeds."finger1.y"'),
    ],
)
def test_bounds_per_quantity(tmp_path, old, new, key):
    assert old in GOOD
    path = _scene(tmp_path, GOOD.replace(old, new))
    if key is None:
        load_scenario(path)  # on the bound: accepted
        return
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.problems[0].key == key
    assert "out of range" in info.value.problems[0].reason


@pytest.mark.parametrize("value", ["true", "false"])
def test_real_booleans_still_work(tmp_path, value):
    text = GOOD.replace('bodies = ["finger1", "triangle"]\nmu = "mu"', f'bodies = ["finger1", "triangle"]\nmu = "mu"\nenabled = {value}')
    if value == "false":
        text = text.replace('{ touch = ["finger1", "triangle"] },', "")
    scenario = load_scenario(_scene(tmp_path, text))
    pairs = {frozenset((p.body_a, p.body_b)) for p in scenario.pairs}
    assert (frozenset(("finger1", "triangle")) in pairs) == (value == "true")


def test_expect_plan_is_a_real_boolean(tmp_path):
    # (not a file in tests/data/bad: a file with [expect] would be collected by the plugin)
    with pytest.raises(ScenarioError) as info:
        load_scenario(_scene(tmp_path, GOOD + "\n[expect]\nplan = 1\n"))
    assert [(p.key, p.reason) for p in info.value.problems] == [("expect.plan", "expected true or false, got 1")]
    assert load_scenario(_scene(tmp_path, GOOD + "\n[expect]\nplan = true\n")).spec.expect.plan is True


def test_integral_float_is_still_an_integer(tmp_path):
    scenario = load_scenario(_scene(tmp_path, GOOD.replace("time_limit = 5.0", "time_limit = 5.0\niterations = 3e3")))
    assert scenario.spec.ladder.iterations == 3000


def test_touch_on_an_enabled_pair_override_is_fine(tmp_path):
    text = GOOD.replace('bodies = ["finger1", "triangle"]\nmu = "mu"', 'bodies = ["finger1", "triangle"]\nmu = "mu"\nenabled = true')
    load_scenario(_scene(tmp_path, text))


def test_pytest_plugin_collects_a_scenario_too_deep_to_read_to_fail_its_load():
    """(It once left such a file out: a scenario folder's file that does not load is a failure.)"""
    assert _is_scenario_file(BAD / "nesting_too_deep.toml") is True
    with pytest.raises(ScenarioError):
        load_scenario(BAD / "nesting_too_deep.toml")


def test_scenario_error_survives_a_process_boundary():
    """A worker's bad input reaches the parent whole (it once broke the process pool)."""
    import pickle

    from models.scenario import Problem, ScenarioError

    err = ScenarioError("f.toml", [Problem("contact.mu", "must be >= 0")])
    back = pickle.loads(pickle.dumps(err))
    assert isinstance(back, ScenarioError) and str(back) == str(err) and back.problems == err.problems


def test_plan_on_a_scene_with_nothing_to_actuate_is_bad_input(tmp_path):
    """bouncing_disc has no robot: there is nothing to plan (it once ended in a traceback)."""
    done = ladder("plan", "scenarios/bouncing_disc.toml", "--out", str(tmp_path / "p"))
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert "bodies: nothing to plan: no body has an actuated DOF" in done.stderr
    assert not (tmp_path / "p").exists()


def test_bad_input_with_json_is_also_one_object_on_stdout(capsys):
    """A script that reads a command's --json output meets bad input as JSON too, the service's
    422 body (`ScenarioError.to_json`); the error lines still go to stderr. It had been text only."""
    import json

    from planner.cli import main

    path = str(BAD / "negative_mu.toml")
    for argv in (["check", path, "--json"], ["simulate", path, "--model", "kinematic", "--json"]):
        assert main(argv) == 2
        out, err = capsys.readouterr()
        data = json.loads(out)
        assert data["file"] == path and data["detail"] == "\n".join(line.removeprefix("error: ") for line in err.splitlines())
        assert [p["key"] for p in data["problems"]] == ["contact.mu"] and "greater than or equal to 0" in data["problems"][0]["reason"]
    assert main(["check", path]) == 2  # without --json: stderr only
    out, err = capsys.readouterr()
    assert out == "" and err.startswith(f"error: {path}: contact.mu: ")
    good = str(SCENARIOS / "two_finger_triangle.toml")
    assert main(["simulate", good, "--model", "kinematic", "--param", "v1=x", "--json"]) == 2  # a flag's problem, the same way
    data = json.loads(capsys.readouterr().out)
    assert [p["key"] for p in data["problems"]] == ["--param v1=x"]


def test_each_problem_is_its_own_error_line(tmp_path, capsys):
    """A file with two problems gives two `error:` lines (the second had no prefix: a grep for
    ^error: found one of them)."""
    from planner.cli import main

    text = (BAD / "negative_mu.toml").read_text()
    assert "mu = -0.1" in text and "K = 1e6" in text
    path = tmp_path / "two.toml"
    path.write_text(text.replace("K = 1e6", "K = -1e6", 1))
    assert main(["check", str(path)]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2 and all(line.startswith(f"error: {path}: contact.") for line in lines), lines


def test_a_value_out_of_range_names_the_override_that_set_it(capsys, tmp_path):
    """An override that puts a key out of range is named with the key: the option on the command
    line, the dict entry in the library, the option of a sweep run (it said only "from 'mu'")."""
    from planner.cli import main

    triangle = str(SCENARIOS / "two_finger_triangle.toml")
    assert main(["check", triangle, "--param", "mu=-1", "--param", "v1=2"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"error: {triangle}: contact.pairs[{i}].mu: must be greater than or equal to 0, got -1 from 'mu' (--param mu)" for i in (0, 1)
    ]
    with pytest.raises(ScenarioError) as caught:
        load_scenario(triangle, {"finger_mass": -0.1})
    assert [(p.key, p.reason) for p in caught.value.problems] == [
        (f"bodies[{i}].mass", "must be greater than 0, got -0.1 from 'finger_mass' (overrides['finger_mass'])") for i in (2, 3)
    ]
    with pytest.raises(ScenarioError) as caught:  # a function of the name, as a sweep names its grid and models
        load_scenario(triangle, {"K": 0.0, "C": 5.0}, override_key=lambda name: f"--grid {name}")
    assert [(p.key, p.reason) for p in caught.value.problems] == [("contact.K", "must be greater than 0, got 0 from 'K' (--grid K)")]
    shadowing = tmp_path / "pi.toml"  # a parameter named like the constant pi is the one overridden
    text = (SCENARIOS / "box_push_3d.toml").read_text().replace("push_speed = 0.2", "pi = 3.0\npush_speed = 0.2", 1)
    shadowing.write_text(text.replace("radius = 0.03 }", 'radius = "0.01 * pi" }', 1))
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "wedge.obj").write_bytes((SCENARIOS / "meshes" / "wedge.obj").read_bytes())
    assert load_scenario(shadowing).spec.bodies[2].shape.radius == pytest.approx(0.03)
    with pytest.raises(ScenarioError) as caught:
        load_scenario(shadowing, {"pi": -1.0})
    assert [(p.key, p.reason) for p in caught.value.problems] == [
        ("bodies[2].shape.radius", "must be greater than 0, got -0.01 from '0.01 * pi' (overrides['pi'])")
    ]
    with pytest.raises(ScenarioError) as caught:  # a value written in the file is no override's, though another was given
        load_scenario(BAD / "negative_mu.toml", {"v1": 2.0})
    assert [(p.key, p.reason) for p in caught.value.problems] == [("contact.mu", "must be greater than or equal to 0, got -0.1")]


def test_a_flag_argparse_refuses_is_bad_input_as_any_other(capsys):
    """argparse's own refusals (an unknown choice, a missing option, a value of the wrong type)
    end as every other bad input: `error: command line: FLAG: reason` after the usage, and with
    --json the problem on stdout (they had been argparse's `ladder plan: error: argument ...`)."""
    import json

    from planner.cli import main

    free = str(SCENARIOS / "free_transfer.toml")
    assert main(["plan", free, "--planner", "PRM", "--json"]) == 2
    out, err = capsys.readouterr()
    assert json.loads(out)["problems"] == [{"key": "--planner", "reason": "invalid choice: 'PRM' (choose from 'RRT', 'KPIECE1', 'EST')"}]
    assert err.startswith("usage: ladder plan ") and err.splitlines()[-1] == (
        "error: command line: --planner: invalid choice: 'PRM' (choose from 'RRT', 'KPIECE1', 'EST')"
    )
    assert main(["plan", free, "--planner", "PRM", "--js"]) == 2  # (argparse takes an abbreviation: so does the JSON)
    assert json.loads(capsys.readouterr().out)["problems"][0]["key"] == "--planner"
    assert main(["plan", free, "--seed", "x"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.splitlines()[-1] == "error: command line: --seed: invalid int value: 'x'"
    assert main(["sweep", free, "--grid", "gap=1"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == "error: command line: the following arguments are required: --model"
    assert main(["simulate", free, "--polcy", "x"]) == 2  # a misspelt flag is named too, not only the missing option
    assert capsys.readouterr().err.splitlines()[-2:] == [
        "error: command line: --polcy: no such option",
        "error: command line: the following arguments are required: --model",
    ]
    assert main(["simulate", free, "--polcy", "x", "--plott", "p.png"]) == 2  # in the order given
    assert [line for line in capsys.readouterr().err.splitlines() if "no such option" in line] == [
        "error: command line: --polcy: no such option",
        "error: command line: --plott: no such option",
    ]
    assert main(["simulate", "--", "--polcy"]) == 2  # after "--" a positional, not a flag
    assert "no such option" not in capsys.readouterr().err
    assert main([]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "usage: ladder [-h] COMMAND ...",
        "error: command line: the following arguments are required: COMMAND",
    ]


def test_an_option_that_takes_one_value_is_refused_given_twice(capsys):
    """`plan --seed 1 --seed 2` had planned seed 2, silently (argparse keeps the last): every
    command's single-valued options now refuse a second value, in argument groups too, while
    options that take several (`--param`, `--grid`, a sweep's `--model`) and flags still repeat."""
    from planner import cli

    free, box = str(SCENARIOS / "free_transfer.toml"), str(SCENARIOS / "box_push_3d.toml")
    refused = [
        (["plan", box, "--seed", "1", "--seed", "2"], "--seed: given twice (1 and 2); it takes one"),
        (["plan", box, "--out", "a", "--out", "b"], "--out: given twice (a and b); it takes one"),  # (a default of its own)
        (["sweep", free, "--model", "kinematic", "--workers", "1", "--workers", "2"], "--workers: given twice (1 and 2); it takes one"),
        (["serve", "--port", "8001", "--port", "8002"], "--port: given twice (8001 and 8002); it takes one"),
        # an abbreviation is named as its option
        (
            ["simulate", free, "--model", "kinematic", "--duration", "1", "--dur", "2"],
            "--duration: given twice (1.0 and 2.0); it takes one",
        ),
    ]
    for argv, said in refused:
        assert cli.main(argv) == 2, argv
        assert capsys.readouterr().err.splitlines()[-1] == f"error: command line: {said}"
    parser = cli.build_parser()
    args = parser.parse_args(["plan", box, "--seed", "3", "--json", "--json"])
    assert args.seed == 3 and args.json and str(args.out) == "out/plan"  # once, and the defaults as they were
    args = parser.parse_args(["plan", box, "--seed", "4"])  # a second parse by the same parser starts afresh
    assert args.seed == 4
    twice = ["--grid", "gap=0.3,0.4", "--grid", "mu=0.1,0.2", "--param", "a=1", "--param", "b=2"]
    args = parser.parse_args(["sweep", free, *twice, "--model", "kinematic"])
    assert args.grid == ["gap=0.3,0.4", "mu=0.1,0.2"] and args.param == ["a=1", "b=2"]


def test_a_repeated_model_is_every_model_in_a_sweep_and_refused_by_simulate(capsys):
    """`sweep --model A --model B` had kept B alone, and `simulate --model A --model B` run B
    alone, both silently: a sweep runs every one, simulate refuses the second."""
    from planner import cli

    free = str(SCENARIOS / "free_transfer.toml")
    args = cli.build_parser().parse_args(["sweep", free, "--grid", "gap=0.3,0.4", "--model", "kinematic", "--model", "dyn=dynamic-rigid"])
    models = cli._check_sweep_args(args)[3]
    assert [(m.label, m.rung) for m in models] == [("kinematic", "kinematic"), ("dyn", "dynamic-rigid")]
    assert cli.main(["simulate", free, "--model", "kinematic", "--model", "dynamic-rigid"]) == 2
    said = capsys.readouterr().err.splitlines()[-1]
    assert said == "error: command line: --model: given twice (kinematic and dynamic-rigid); it takes one"
    from planner import sweep as sw

    with pytest.raises(ScenarioError) as caught:  # each --model parsed on its own: an open '[' does not take the next
        sw.parse_models(["kinematic[C=0", "dynamic-rigid"])
    assert [p.key for p in caught.value.problems] == ["--model kinematic[C=0"]
    with pytest.raises(ScenarioError, match="no model given"):
        sw.parse_models(["", "kinematic"])
    with pytest.raises(ScenarioError) as caught:  # labels distinct across them
        sw.parse_models(["kinematic", "kinematic"])
    assert [p.key for p in caught.value.problems] == ["--model kinematic --model kinematic"]


def test_a_planar_inertia_is_named_as_the_file_writes_it(tmp_path):
    """A planar inertia is one number in the file (the schema keeps it as a tuple of one): its
    problems name `bodies[1].inertia`, not `bodies[1].inertia[0]`; a spatial one's keep their index."""
    text = (SCENARIOS / "two_finger_triangle.toml").read_text()
    written = re.search(r"^inertia = .*$", text, re.M)[0]
    for value, shown in (("-1.0", "-1"), ('"-mu"', "-0.5 from '-mu'")):
        path = tmp_path / "negative_inertia.toml"
        path.write_text(text.replace(written, f"inertia = {value}", 1))
        with pytest.raises(ScenarioError) as caught:
            load_scenario(path)
        assert [(p.key, p.reason) for p in caught.value.problems] == [("bodies[1].inertia", f"must be greater than 0, got {shown}")]
    with pytest.raises(ScenarioError) as caught:
        load_scenario(SCENARIOS / "box_push_3d.toml", {"box_mass": -1.0})
    assert [p.key for p in caught.value.problems if ".inertia" in p.key] == [f"bodies[1].inertia[{i}]" for i in range(3)]


def test_a_parameter_set_twice_is_refused_and_named(capsys, tmp_path):
    """`--param v1=1 --param v1=3` had taken 3, and `sweep --grid v1=1,2 --param v1=3` run the
    grid while sweep.json's `fixed` said v1 = 3, both silently; `--grid v1=1,2 --grid v1=3`
    said "an axis is given twice" without naming it. Found by a user's trial of the docs."""
    from planner import cli

    free = str(SCENARIOS / "free_transfer.toml")
    refused = [
        (["check", free, "--param", "gap=0.3", "--param", "gap=0.35"], "--param gap: given twice (0.3 and 0.35); give it once"),
        (
            ["sweep", free, "--grid", "gap=0.3,0.4", "--param", "gap=0.35", "--model", "kinematic", "--out", str(tmp_path / "a")],
            "--grid gap: is also fixed by --param gap=0.35; an axis takes its values from --grid alone",
        ),
        (
            ["sweep", free, "--grid", "gap=0.3,0.4", "--grid", "gap=0.5", "--model", "kinematic", "--out", str(tmp_path / "b")],
            "--grid gap: is given twice; give each axis once (one --grid NAME=VALUES)",
        ),
    ]
    for argv, said in refused:
        assert cli.main(argv) == 2, argv
        assert capsys.readouterr().err.splitlines()[-1] == f"error: {free}: {said}"
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
    thrice = ["--param", "gap=0.3", "--param", "gap=0.35", "--param", "gap=0.4"]
    assert cli.main(["submit", free, *thrice, "--server", "http://127.0.0.1:9"]) == 2  # (refused before any request)
    said = "--param gap: given three times (0.3 and 0.35 and 0.4); give it once"
    assert capsys.readouterr().err.splitlines()[-1] == f"error: command line: {said}"


def test_a_plan_file_that_cannot_be_replayed_says_why(capsys, tmp_path):
    """`simulate --plan` of a missing file had said "rungs: not a usable plan file: [Errno 2] ...",
    and with `--policy` "the scene's contents differ", of the same file and parameters."""
    from planner import cli

    triangle = str(SCENARIOS / "two_finger_triangle.toml")
    missing, text, empty = tmp_path / "missing.json", tmp_path / "text.json", tmp_path / "empty.json"
    text.write_text("a plan\n")
    empty.write_text("{}")
    expected = "expected a plan.json that `ladder plan` wrote"
    cases = [
        (missing, f"error: {missing}: --plan: cannot read the plan file: No such file or directory"),
        (text, f"error: {text}: --plan: not JSON (Expecting value: line 1 column 1 (char 0)); {expected}"),
        (empty, f"error: {empty}: rungs: no rung with controls; {expected}"),
    ]
    for path, said in cases:
        assert cli.main(["simulate", triangle, "--model", "kinematic", "--plan", str(path)]) == 2
        assert capsys.readouterr().err.splitlines()[-1] == said
    argv = ["simulate", triangle, "--model", "kinematic", "--plan", str(empty), "--policy", "potential"]
    assert cli.main(argv) == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"error: {triangle}: --policy: a plan's controls replace the policy; --policy goes without --plan"
    )


def test_a_ladders_planner_is_one_problem_and_an_expected_plan_of_an_unplannable_scene_says_why(tmp_path):
    """`[ladder] planner = "RRTConnect"` had been one problem per control rung (the same line
    twice here); `[expect] plan = true` of a scene with a scripted obstacle had said "`ladder
    simulate` and `ladder sweep` run such scenes", which refuse the file as well."""
    with pytest.raises(ScenarioError) as info:
        load_scenario(_scene(tmp_path, GOOD.replace("[ladder]\n", '[ladder]\nplanner = "RRTConnect"\n')))
    assert [(p.key, p.reason) for p in info.value.problems] == [
        ("ladder.planner", "'RRTConnect' is not a control planner; use one of RRT, KPIECE1, EST")
    ]
    scripted = GOOD.replace('role = "obstacle"\n', 'role = "obstacle"\nvelocity = { y = 0.01 }\n', 1)
    load_scenario(_scene(tmp_path, scripted))  # (simulate and sweep run it)
    with pytest.raises(ScenarioError) as info:
        load_scenario(_scene(tmp_path, scripted + "\n[expect]\nplan = true\n"))
    (problem,) = info.value.problems
    assert problem.key == "expect.plan"
    said = "`ladder plan` refuses this scene, so [expect] cannot test a plan of it; leave plan out (bodies[0].velocity: "
    assert problem.reason.startswith(said)

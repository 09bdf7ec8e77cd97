"""The pytest plugin (planner/pytest_plugin.py) as a lab uses it: a folder of its own scenario
files, run by pytest in a fresh process. Trials found files left out without a word, --lf that
reran nothing, ids under -v that pytest would not take back, and a lab's own `models` package
mixed with ladder's."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.conftest import ROOT, SCENARIOS

DISC = (SCENARIOS / "bouncing_disc.toml").read_text()
_EXPECT = '[expect]\npolicy = { dynamic-rigid = "goal", dynamic-compliant = "goal" }'
assert _EXPECT in DISC


def _disc(expect: str) -> str:
    """bouncing_disc with another [expect] table (its schema comment dropped: no schema beside it)."""
    return DISC.replace("#:schema ./scenario.schema.json\n", "").replace(_EXPECT, expect)


def run_pytest(folder, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """pytest in a fresh process on a folder of its own (no ini file: its own rootdir)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), **(env or {}))
    env.pop("PYTEST_ADDOPTS", None)
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:randomly", *args], capture_output=True, text=True, cwd=folder, env=env, timeout=600
    )


@pytest.fixture
def lab(tmp_path):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    (scenes / "good.toml").write_text(_disc('[expect]\npolicy = { dynamic-rigid = "goal" }'))
    (scenes / "wrong.toml").write_text(_disc('[expect]\npolicy = { dynamic-rigid = "unsafe" }'))
    return tmp_path


def test_a_scenario_file_that_does_not_load_is_a_failing_item_not_left_out(lab):
    scenes = lab / "scenes"
    (scenes / "syntax.toml").write_text(_disc('[expect]\npolicy = { dynamic-rigid = "goal" }').replace("drop = 1.0", "drop = 1.0 = 3"))
    (scenes / "misspelt.toml").write_text(_disc('[expcet]\npolicy = { dynamic-rigid = "goal" }'))
    (scenes / "empty.toml").write_text(_disc("[expect]"))
    (scenes / "nothing_to_plan.toml").write_text(_disc("[expect]\nplan = true"))
    (scenes / "no_test.toml").write_text(_disc(""))  # a scene with no expectations: no item
    (scenes / "other.toml").write_text('[tool.other]\nkey = "not a scenario"\n')  # not a scenario: not collected
    done = run_pytest(lab, "scenes", "-q", "-p", "no:cacheprovider", "-rf")
    assert done.returncode == 1, done.stdout + done.stderr
    failed = sorted(line.split(" ")[1] for line in done.stdout.splitlines() if line.startswith("FAILED "))
    assert failed == [
        "scenes/empty.toml::load",
        "scenes/misspelt.toml::load",
        "scenes/nothing_to_plan.toml::load",
        "scenes/syntax.toml::load",
        "scenes/wrong.toml::policy[dynamic-rigid]",
    ], done.stdout
    assert "5 failed, 1 passed" in done.stdout
    text = done.stdout
    assert "syntax.toml: not valid TOML" in text
    assert "expcet: unknown key (did you mean 'expect'?" in text
    assert "expect: names no expectation" in text
    assert (
        "expect.plan: `ladder plan` refuses this scene, so [expect] cannot test a plan of it; leave plan out (bodies: nothing to plan"
        in text
    )
    assert "dynamic-rigid: the policy ends in 'goal'" in text
    assert "expected 'unsafe' (expect.policy.dynamic-rigid); the final state: " in text
    # each failure's heading names its file (they had all been "load", or "plan")
    headings = sorted(line.strip("_ ") for line in text.splitlines() if line.startswith("___"))
    assert headings == [
        "load in empty.toml",
        "load in misspelt.toml",
        "load in nothing_to_plan.toml",
        "load in syntax.toml",
        "policy[dynamic-rigid] in wrong.toml",
    ], text


def test_last_failed_reruns_a_failed_policy_item_and_verbose_ids_paste_back(lab):
    first = run_pytest(lab, "scenes", "-q")
    assert first.returncode == 1 and "1 failed, 1 passed" in first.stdout, first.stdout
    again = run_pytest(lab, "scenes", "-q", "--lf")
    assert again.returncode == 1 and "1 failed" in again.stdout and "passed" not in again.stdout.splitlines()[-1], again.stdout
    verbose = run_pytest(lab, "scenes", "-v", "-p", "no:cacheprovider")
    assert "scenes/good.toml::policy[dynamic-rigid] PASSED" in verbose.stdout, verbose.stdout
    one = run_pytest(lab, "scenes/good.toml::policy[dynamic-rigid]", "-q", "-p", "no:cacheprovider")
    assert one.returncode == 0 and "1 passed" in one.stdout, one.stdout + one.stderr


def test_a_labs_own_models_package_is_named_not_mixed_with_ladders(lab):
    """`python -m` puts the working directory first on sys.path: a `models` package there would
    stand in for ladder's physics package, with ladder's modules loaded into it."""
    (lab / "models").mkdir()
    (lab / "models" / "__init__.py").write_text('"""the lab\'s own models"""\n')
    done = run_pytest(lab, "scenes/good.toml", "-q", "-p", "no:cacheprovider")
    assert done.returncode == 1 and "a package of your own named `models` comes first on sys.path" in done.stdout, done.stdout
    assert f"the package `models` is {lab / 'models' / '__init__.py'}" in done.stdout
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cli = subprocess.run(
        [sys.executable, "-m", "planner", "check", "scenes/good.toml"], capture_output=True, text=True, cwd=lab, env=env, timeout=120
    )
    assert cli.returncode == 2 and cli.stderr.startswith("error: the package `models` is ") and "Traceback" not in cli.stderr


def test_items_that_will_compile_the_kernels_say_so_first(lab, tmp_path):
    """A cold kernel cache (here an empty NUMBA_CACHE_DIR) meant minutes of silence before the
    first item; the plugin prints the `ladder` command's notice once its items are collected."""
    from planner.cli import COMPILE_NOTE

    cold = run_pytest(lab, "scenes", "--collect-only", "-q", "-p", "no:cacheprovider", env={"NUMBA_CACHE_DIR": str(tmp_path / "empty")})
    assert cold.returncode == 0 and COMPILE_NOTE in cold.stdout, cold.stdout + cold.stderr
    warm = run_pytest(lab, "scenes", "--collect-only", "-q", "-p", "no:cacheprovider")
    assert warm.returncode == 0 and COMPILE_NOTE not in warm.stdout, warm.stdout


INCLINE = (SCENARIOS / "incline_block.toml").read_text().replace("#:schema ./scenario.schema.json\n", "")
assert '[[expect.cases]]\nname = "sticks"' in INCLINE


def test_expect_cases_run_the_scene_with_other_parameters(tmp_path):
    """[[expect.cases]]: FILE::NAME::policy[RUNG] on the scene with the case's parameters; a case
    whose scene does not load with them fails the file's load, naming the case; --lf reruns a
    failed case's item."""
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    claim = '[[expect.cases]]\nname = "claims_a_slide"\nparameters = { mu = 0.7 }\npolicy = { dynamic-rigid = "goal" }'
    broken = '[[expect.cases]]\nname = "no_contact"\nparameters = { K = -1.0 }\npolicy = { dynamic-rigid = "goal" }'
    (scenes / "incline.toml").write_text(INCLINE + "\n" + claim + "\n")
    (scenes / "broken.toml").write_text(INCLINE + "\n" + broken + "\n")
    done = run_pytest(tmp_path, "scenes", "-v", "-rf")
    assert done.returncode == 1, done.stdout + done.stderr
    passed = sorted(line.split(" ")[0] for line in done.stdout.splitlines() if line.endswith("]") and " PASSED " in line)
    assert passed == [
        "scenes/incline.toml::policy[dynamic-compliant]",
        "scenes/incline.toml::policy[dynamic-rigid]",
        "scenes/incline.toml::sticks::policy[dynamic-compliant]",
        "scenes/incline.toml::sticks::policy[dynamic-rigid]",
    ], done.stdout
    failed = sorted(line.split(" ")[1] for line in done.stdout.splitlines() if line.startswith("FAILED "))
    assert failed == ["scenes/broken.toml::load", "scenes/incline.toml::claims_a_slide::policy[dynamic-rigid]"], done.stdout
    text = " ".join(done.stdout.split())
    assert (
        "case 'claims_a_slide' (mu = 0.7): dynamic-rigid: the policy ends in 'none'" in text and "expected 'goal'" in text
    )  # mu = 0.7 > tan 30
    assert " claims_a_slide::policy[dynamic-rigid] in incline.toml " in text
    assert "expect.cases[1]: the scene with the case's parameters does not load: contact.K" in text
    again = run_pytest(tmp_path, "scenes", "-q", "--lf")
    assert again.returncode == 1 and "2 failed" in again.stdout and "passed" not in again.stdout.splitlines()[-1], again.stdout


def test_a_passing_item_whose_run_is_not_physical_says_so(tmp_path):
    """The frictionless incline under the quasistatic rung reaches its goal, sliding at 4.9 km/s:
    the item passes (the outcome is what the file expects) with the run's warning in pytest's
    warnings summary."""
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    case = '[[expect.cases]]\nname = "frictionless"\nparameters = { mu = 0.0 }\npolicy = { quasistatic-rigid = "goal" }'
    (scenes / "incline.toml").write_text(INCLINE + "\n" + case + "\n")
    done = run_pytest(tmp_path, "scenes", "-q", "-p", "no:cacheprovider")
    assert done.returncode == 0 and "5 passed, 1 warning" in done.stdout, done.stdout + done.stderr
    text = " ".join(done.stdout.split())
    assert "ScenarioRunWarning: scenes/incline.toml::frictionless::policy[quasistatic-rigid]: block was not held in equilibrium" in text
    strict = run_pytest(tmp_path, "scenes", "-q", "-p", "no:cacheprovider", "-W", "error::planner.pytest_plugin.ScenarioRunWarning")
    assert strict.returncode == 1 and "1 failed, 4 passed" in strict.stdout, strict.stdout + strict.stderr  # (as the README says)


def test_a_plan_expectation_that_fails_says_the_seed_the_budget_and_each_rung_on_a_line(tmp_path):
    """It had been one line of every rung's reason, without the seed or the budget it ran."""
    text = (SCENARIOS / "free_transfer.toml").read_text().replace("#:schema ./scenario.schema.json\n", "")
    assert "plan = true" in text
    (tmp_path / "free.toml").write_text(text.replace("plan = true", "plan = false\nplan_iterations = 2000\nseed = 3"))
    done = run_pytest(tmp_path, "free.toml", "-q", "-k", "plan")
    assert done.returncode == 1, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("___") and " plan in free.toml " in line)
    assert lines[at + 1].endswith("free.toml: top rung holds: True, expected False (expect.plan; seed 3, 2,000 iterations a rung):")
    assert lines[at + 2].startswith("  geometric: planned") and lines[at + 3].startswith("  kinematic: "), lines[at : at + 4]

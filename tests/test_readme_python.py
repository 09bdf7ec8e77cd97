"""The README's Python example runs as written, and says what the CLI says of the same run."""

from __future__ import annotations

import contextlib
import io
import json
import re
import textwrap

from tests.conftest import ROOT


def readme_python_example() -> str:
    """The first indented block of the README's "From Python" section."""
    section = (ROOT / "README.md").read_text().split("## From Python", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"\n((?:    .*\n|\n)+)", section.split(":\n", 1)[1])
    return textwrap.dedent(block.group(1))


def test_the_readme_python_example_runs_and_agrees_with_the_cli(tmp_path, monkeypatch):
    from planner.cli import main

    code = readme_python_example()
    assert "run_ladder(scenario, seed=1)" in code
    monkeypatch.chdir(ROOT)  # the example's paths are the checkout's
    code = code.replace('open("plan.json"', f"open({str(tmp_path / 'plan.json')!r}")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(code, "README.md", "exec"), {})
    run_line, plan_line = printed.getvalue().splitlines()
    args = ["simulate", "scenarios/two_finger_triangle.toml", "--param", "v1=0.8", "--model", "dynamic-compliant", "--json"]
    cli_out = io.StringIO()
    with contextlib.redirect_stdout(cli_out):
        assert main(args) == 0
    cli = json.loads(cli_out.getvalue())
    assert cli["outcome"] == "goal"  # the paper's scene at v1 = 0.8 grasps under the dynamic model
    assert run_line.startswith(f"{cli['outcome']} {cli['status']} {round(cli['t'], 4)} {cli['max_penetration']} ")
    assert plan_line.startswith("True [")
    plan = json.loads((tmp_path / "plan.json").read_text())
    assert plan["top_holds"] is True and plan["seed"] == 1

"""The ``ladder`` command as a user runs it: exit codes, messages, nothing written on bad input."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.conftest import DATA, ROOT, SCENARIOS


def ladder(*args: str, cwd=ROOT) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-m", "planner", *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=120
    )


def test_help_lists_the_commands():
    result = ladder("--help")
    assert result.returncode == 0
    for command in ("check", "schema", "simulate", "plan", "sweep", "bench"):
        assert command in result.stdout


def test_check_help_is_accurate():
    result = ladder("check", "--help")
    assert result.returncode == 0
    for option in ("--param", "--json", "--out"):
        assert option in result.stdout


def test_check_json_on_the_paper_scene():
    result = ladder("check", str(SCENARIOS / "two_finger_triangle.toml"), "--json", "--param", "v1=0.8")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["coordinates"] == ["triangle.x", "finger1.y", "finger2.y"]
    assert summary["start"] == {"triangle.x": 0.0, "finger1.y": 2.05, "finger2.y": 2.05}
    assert summary["parameters"]["v1"] == 0.8
    assert summary["ladder"]["rungs"][0] == "geometric"


def test_check_human_output_names_bodies_and_coordinates():
    result = ladder("check", str(SCENARIOS / "two_finger_triangle.toml"))
    assert result.returncode == 0, result.stderr
    for word in ("triangle.x", "finger1.y", "palm", "dynamic-compliant", "ok"):
        assert word in result.stdout


def test_check_out_writes_the_summary(tmp_path):
    out = tmp_path / "deep" / "summary.json"
    result = ladder("check", str(SCENARIOS / "free_transfer.toml"), "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert json.loads(out.read_text())["actuated"] == ["robot.x", "robot.y"]


@pytest.mark.parametrize("name", ["negative_mass", "syntax_error", "start_penetration", "unknown_parameter"])
def test_bad_file_exit_2_no_traceback_nothing_written(tmp_path, name):
    path = DATA / "bad" / f"{name}.toml"
    out = tmp_path / "summary.json"
    result = ladder("check", str(path), "--json", "--out", str(out))
    assert result.returncode == 2
    assert result.stdout == ""
    assert "Traceback" not in result.stderr
    assert str(path) in result.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_unknown_param_on_the_command_line():
    result = ladder("check", str(SCENARIOS / "two_finger_triangle.toml"), "--param", "speed=3")
    assert result.returncode == 2
    assert "--param speed" in result.stderr and "Traceback" not in result.stderr


def test_missing_file():
    result = ladder("check", "no/such/file.toml")
    assert result.returncode == 2
    assert "no/such/file.toml: no such file" in result.stderr


@pytest.mark.parametrize("command", ["serve"])
def test_reserved_commands_say_so(command):
    result = ladder(command, "scenarios/two_finger_triangle.toml")
    assert result.returncode == 2
    assert "not built yet" in result.stderr


def test_unknown_command_is_a_usage_error():
    result = ladder("fly")
    assert result.returncode == 2


def test_simulate_json_on_the_paper_scene(tmp_path):
    plot = tmp_path / "fig4.png"
    result = ladder(
        "simulate", str(SCENARIOS / "two_finger_triangle.toml"), "--model", "quasistatic-rigid",
        "--param", "v1=0.8", "--json", "--plot", str(plot),
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    for key in ("outcome", "t", "state", "steps", "wall_s", "status", "lcp_solves", "pivots"):
        assert key in summary
    assert summary["outcome"] == "goal" and summary["status"] == "ok"
    assert set(summary["state"]) == {"triangle.x", "finger1.y", "finger2.y"}
    assert plot.stat().st_size > 10_000


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["--model", "nonsense"], "--model: unknown rung"),
        (["--model", "geometric"], "no dynamics"),
        (["--model", "dynamic-rigid"], "--step"),
        (["--model", "kinematic", "--step", "-1"], "--step: must be a positive number"),
    ],
)
def test_simulate_bad_arguments(args, fragment):
    result = ladder("simulate", str(SCENARIOS / "two_finger_triangle.toml"), *args)
    assert result.returncode == 2
    assert fragment in result.stderr and "Traceback" not in result.stderr

"""The README's benchmark figures and docs/benchmarks.md are the saved run's (docs/bench/bench.json),
written by `ladder bench --readme` / `--doc` (`planner.bench.readme_blocks`, `markdown`), never by
hand; `ladder bench --from` writes them from a saved run, and refuses what it cannot use."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from planner.bench import README_BLOCKS, markdown, readme_block_text, readme_blocks, readme_markers, readme_problems, with_readme_blocks
from tests.conftest import ROOT
from tests.test_cli import ladder

SAVED = ROOT / "docs" / "bench" / "bench.json"
README = ROOT / "README.md"


@pytest.fixture(scope="module")
def saved() -> dict:
    return json.loads(SAVED.read_text())


def test_the_readme_figures_are_the_saved_runs(saved):
    text = README.read_text()
    assert readme_problems(text) == []
    blocks = readme_blocks(saved)
    for name in README_BLOCKS:
        assert readme_block_text(text, name) == blocks[name], (
            f"README.md's {name} block is not docs/bench/bench.json's: "
            "ladder bench --from docs/bench/bench.json --readme README.md --doc docs/benchmarks.md"
        )


def test_the_benchmarks_doc_is_the_saved_runs(saved):
    assert (ROOT / "docs" / "benchmarks.md").read_text() == markdown(saved, Path("docs"), Path("docs/bench"))


def test_the_headline_says_what_each_ratio_counts(saved):
    headline = readme_blocks(saved)["headline"]
    peer = saved["throughput"]["peer"]
    assert f"{peer['ratio']:.1f}x MuJoCo's steps per second in free flight" in headline
    assert "no step carries a contact force" in headline
    # the squeeze's and the push's ratios, each with its contacts a step, from the contact rows
    rows = saved["throughput"]["contact"]["rows"]
    squeeze = [row["speed_vs_mujoco"] for row in rows if row["scene"].startswith("two_finger_triangle")]
    (forced,) = {(row["contact_steps"], row["steps"]) for row in rows if row["scene"].startswith("two_finger_triangle")}
    assert 0 < forced[0] < forced[1]  # the run starts in free flight: the headline says how much of it carries force
    assert (
        f"{min(squeeze):.1f}-{max(squeeze):.1f}x on the paper's scene through the squeeze "
        f"({forced[0]:,} of its {forced[1]:,} steps carry contact force; 2 contacts a step)" in headline
    )
    push = [row["speed_vs_mujoco"] for row in rows if "planners' propagation" in row["scene"]]
    assert f"{min(push):.1f}-{max(push):.1f}x on box_push_3d's push (5 contacts a step" in headline
    speedups = {scene: res["summary"]["speedup_median_wall"] for scene, res in saved["planning"].items()}
    lo, hi = min(speedups, key=speedups.get), max(speedups, key=speedups.get)  # (the scenes at the ends move from run to run)
    assert f"{speedups[lo]:.1f}x ({lo}) to {speedups[hi]:.1f}x ({hi}) less time than planning at the top rung alone" in headline


def test_a_run_without_mujoco_says_so_and_times_nothing_against_it(saved):
    r = copy.deepcopy(saved)
    r["throughput"]["peer"] = {"skipped": "the peers extra is not installed"}
    for row in r["throughput"]["contact"]["rows"]:
        row.pop("mujoco_us_per_step", None)
        row.pop("speed_vs_mujoco", None)
    blocks = readme_blocks(r)
    assert blocks["headline"].startswith("MuJoCo was not timed in the latest `ladder bench`")
    assert "the peers extra is not installed" in blocks["headline"] and "x MuJoCo" not in blocks["headline"]
    figures = blocks["figures"].split("\n")
    contact = [line for line in figures if line.startswith("| two_finger_triangle, v1 = v2 = 1 through the squeeze")]
    assert len(contact) == 3 and all(line.endswith("| - | - |") for line in contact)
    assert not any("free flight (MuJoCo" in line for line in figures)


def _readme(headline: str = "old headline", figures: str = "old\n\nfigures") -> str:
    (h0, h1), (f0, f1) = readme_markers("headline"), readme_markers("figures")
    return "\n".join(["# title", h0, headline, h1, "between", f0, figures, f1, "after", ""])


def test_the_blocks_are_replaced_and_nothing_else():
    new = {"headline": "new headline", "figures": "| a |\n|---|\n| 1 |"}
    text = with_readme_blocks(_readme(), new)
    assert text == _readme(new["headline"], new["figures"])
    assert with_readme_blocks(text, new) == text  # again: the same
    assert readme_block_text(text, "figures") == new["figures"]


@pytest.mark.parametrize(
    "edit, found",
    [
        (lambda t: t.replace(readme_markers("figures")[1] + "\n", ""), "(found 1 and 0)"),
        (lambda t: t + readme_markers("headline")[0] + "\n", "(found 2 and 1)"),
        (
            lambda t: (
                t.replace(readme_markers("headline")[0], "X")
                .replace(readme_markers("headline")[1], readme_markers("headline")[0])
                .replace("X", readme_markers("headline")[1])
            ),
            "must come before",
        ),
    ],
)
def test_markers_missing_twice_or_out_of_order_are_named(edit, found):
    problems = readme_problems(edit(_readme()))
    assert len(problems) == 1 and found in problems[0].reason


def test_bench_from_a_saved_run_writes_the_readme_and_the_doc(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(with_readme_blocks(README.read_text(), {"headline": "stale", "figures": "stale"}))
    doc = tmp_path / "benchmarks.md"
    result = ladder("bench", "--from", str(SAVED), "--readme", str(readme), "--doc", str(doc))
    assert result.returncode == 0, result.stderr
    assert readme.read_text() == README.read_text()
    saved = json.loads(SAVED.read_text())
    assert doc.read_text() == markdown(saved, tmp_path, SAVED.parent)


def test_bench_refuses_what_it_cannot_use_and_writes_nothing(tmp_path):
    no_markers = tmp_path / "plain.md"
    no_markers.write_text("# a README without the markers\n")
    (tmp_path / "empty.json").write_text("{}")
    (tmp_path / "quick.json").write_text(json.dumps(json.loads(SAVED.read_text()) | {"quick": True}))
    doc = tmp_path / "benchmarks.md"
    cases = [
        (["--from", str(tmp_path / "missing.json"), "--doc", str(doc)], "--from: " + str(tmp_path / "missing.json") + ": cannot read it"),
        (["--from", str(tmp_path / "empty.json"), "--doc", str(doc)], "not a `ladder bench` result (no machine, quick"),
        (["--from", str(SAVED)], "--from: nothing to write"),
        (["--from", str(SAVED), "--readme", str(no_markers), "--doc", str(doc)], "block headline: needs the lines"),
        (["--from", str(tmp_path / "quick.json"), "--readme", str(README)], "a --quick run's figures do not go into a README"),
        (["--quick", "--readme", str(README)], "a --quick run's figures do not go into a README"),
        (["--from", str(SAVED), "--doc", str(doc), "--seeds", "3"], "--seeds: sets up a run, and --from runs nothing"),
    ]
    for args, message in cases:
        result = ladder("bench", *args)
        assert result.returncode == 2, (args, result.stderr)
        assert message in result.stderr and "Traceback" not in result.stderr, (args, result.stderr)
    assert not doc.exists()
    assert no_markers.read_text() == "# a README without the markers\n"


def test_a_report_written_elsewhere_links_the_plots_where_they_are(saved, tmp_path):
    """(A --doc outside docs/ linked docs/bench/x.png relative to itself: broken links.)"""
    import re

    text = markdown(saved, tmp_path, ROOT / "docs" / "bench")
    links = re.findall(r"!\[[^]]*\]\(([^)]+)\)", text)
    assert len(links) == len(saved["plots"]) > 0
    assert all((tmp_path / link).resolve().is_file() for link in links), links

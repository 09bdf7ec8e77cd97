import os
from pathlib import Path

import pytest
from hypothesis import settings

# Property tests draw the same examples on every run (a seed from each test function), so a
# red CI run is a change's doing, not a new draw; HYPOTHESIS_PROFILE=explore draws fresh ones
# (`HYPOTHESIS_PROFILE=explore pytest -m slow tests/stress` searches the random scenes anew).
settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
DATA = Path(__file__).resolve().parent / "data"
# tests/data holds the tests' input files, not tests: the scenario plugin would collect a file
# with an [expect] table there (tests/data/bad/expect_policy_no_step.toml is one, meant to fail to load)
collect_ignore = ["data"]


def free_port() -> int:
    """A TCP port of the loopback no one listens on (now)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def perf_map_entries(path: Path) -> list[tuple[int, int, str]]:
    """The rows (start, size, name) of a perf map file (`models.perfmap`: "start size name", hex)."""
    rows = []
    for line in path.read_text().splitlines():
        start, size, name = line.split(" ", 2)
        rows.append((int(start, 16), int(size, 16), name))
    return rows


@pytest.fixture
def triangle_file() -> Path:
    return SCENARIOS / "two_finger_triangle.toml"

"""A Dask scheduler and worker as processes of their own, on a port of this machine (a
LocalCluster's scheduler lives in the test's process, and cannot be killed and started again
at the same address as a lab's can)."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys

from tests.conftest import ROOT, free_port  # noqa: F401 (free_port: the tests' port, here too)

QUIET = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}


def scheduler(port: int) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--port", str(port), "--no-dashboard"], **QUIET)


def worker(port: int) -> subprocess.Popen:
    """One worker process of one thread, which imports the planner from this checkout."""
    command = [sys.executable, "-m", "dask", "worker", f"tcp://127.0.0.1:{port}", "--nthreads", "1", "--no-dashboard"]
    return subprocess.Popen(command, env=dict(os.environ, PYTHONPATH=str(ROOT)), **QUIET)


@contextlib.contextmanager
def ended(processes: list):
    """Kill every process in `processes` (which the block may add to) at its end."""
    try:
        yield processes
    finally:
        for proc in processes:
            proc.kill()
            proc.wait(timeout=30)

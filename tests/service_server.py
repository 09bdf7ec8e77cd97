"""A real planning service for tests that talk HTTP to it (the client, the browser, the load):
uvicorn on a free loopback port, in a thread of the test process, on its own database."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from tests.conftest import ROOT

#: The longest a job of these tests may take. Generous: the first job of a fresh checkout
#: compiles the kernels (minutes on a loaded 2-core machine); not a timing assertion.
JOB_TIMEOUT_S = 900.0


@contextlib.contextmanager
def running_service(db: Path, **kwargs) -> Iterator[str]:
    """Serve `create_app(db, **kwargs)` on 127.0.0.1 until the block ends; yields its URL."""
    from planner.service import create_app
    from planner.service.app import server_for

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    server = server_for(create_app(db, **kwargs), log_level="warning", lifespan="on")
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    try:
        while not server.started:
            if not thread.is_alive():
                raise RuntimeError("the service did not start")
            time.sleep(0.05)
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(60)
        sock.close()


def wait_for_state(client, job_id: str, states=("succeeded", "failed", "cancelled")) -> dict:
    """Poll the job (a planner.service.client.Client) until it is in one of `states`."""
    end = time.monotonic() + JOB_TIMEOUT_S
    while (job := client.get(job_id))["state"] not in states:
        assert time.monotonic() < end, f"job {job_id} still {job['state']}"
        time.sleep(0.1)
    return job


def cli_plan_json(scenario_path: Path, seed: int, parameters=None, **kwargs) -> str:
    """plan.json as `ladder plan` writes it (run from the repository root)."""
    import os

    from models.scenario import load_scenario
    from planner.ladder import plan_json_text, run_ladder

    old = os.getcwd()
    os.chdir(ROOT)
    try:
        scenario = load_scenario(scenario_path.relative_to(ROOT), parameters or {})
        return plan_json_text(run_ladder(scenario, seed=seed, **kwargs))
    finally:
        os.chdir(old)

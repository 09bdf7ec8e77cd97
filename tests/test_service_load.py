"""Load on loopback: 100 plan jobs submitted at once to a real service (uvicorn, 2 worker
processes) whose queue holds fewer than that. Submissions the full queue refuses get 429 with
Retry-After and are sent again with the same Idempotency-Key. Every job ends succeeded, none
is lost or made twice, and each plan.json is byte for byte the CLI's for its seed (a sample of
12 seeds is planned again here). About 20 s on 2 busy cores: in the default suite."""

from __future__ import annotations

import json
import time
from concurrent.futures import ThreadPoolExecutor

import pytest

pytest.importorskip("fastapi")
pytest.importorskip("httpx2")

from planner.service.client import Client, ServiceError, job_request  # noqa: E402
from tests.conftest import ROOT  # noqa: E402
from tests.service_server import JOB_TIMEOUT_S, cli_plan_json, running_service  # noqa: E402

JOBS = 100
MAX_QUEUED = 30
#: The paper's scene at v1 = 0.8: a plan takes a fraction of a second.
SCENE = "scenarios/two_finger_triangle.toml"
PARAMETERS = {"v1": 0.8}


def test_100_concurrent_jobs_all_complete_once_with_the_clis_plans(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    refused = []  # (seed, Retry-After) of each 429

    def submit(client: Client, seed: int) -> dict:
        body = job_request(SCENE, parameters=PARAMETERS, options={"seed": seed})
        key = f"load-{seed}"
        while True:
            try:
                return client.submit_request(body, idempotency_key=key)
            except ServiceError as exc:
                if exc.status != 429:
                    raise
                refused.append((seed, exc.retry_after))
                time.sleep(exc.retry_after)

    started = time.monotonic()
    with running_service(tmp_path / "jobs.sqlite", workers=2, max_queued=MAX_QUEUED, retry_after=1) as url, Client(url) as client:
        with ThreadPoolExecutor(JOBS) as pool:
            submitted = list(pool.map(lambda seed: submit(client, seed), range(1, JOBS + 1)))
        ids = {job["options"]["seed"]: job["id"] for job in submitted}
        assert len(set(ids.values())) == JOBS  # one job per submission, the retried ones too
        end = time.monotonic() + JOB_TIMEOUT_S
        while client.jobs("queued") or client.jobs("running"):
            assert time.monotonic() < end, "jobs still waiting"
            time.sleep(0.5)
        wall = time.monotonic() - started
        jobs = client.jobs()
        assert sorted(j["id"] for j in jobs) == sorted(ids.values())  # none lost, none extra
        assert {j["state"] for j in jobs} == {"succeeded"} and {j["runs"] for j in jobs} == {1}
        results = {seed: client.result(job_id) for seed, job_id in ids.items()}
        ended = [e for e in client.events(ids[1]) if e.type == "job_ended"]
        assert len(ended) == 1 and ended[0].data["state"] == "succeeded"
    assert refused and all(after == 1 for _, after in refused)  # the queue did fill, and said when to come back
    for seed in range(1, JOBS + 1, 9):  # a sample against the CLI's plans (in process, one at a time)
        assert results[seed] == cli_plan_json(ROOT / SCENE, seed=seed, parameters=PARAMETERS), f"seed {seed}"
    holds = sum(json.loads(text)["top_holds"] for text in results.values())
    print(f"\nload: {JOBS} jobs, {len(refused)} answers 429 (on {len({s for s, _ in refused})} submissions), {wall:.1f} s, {holds} hold")

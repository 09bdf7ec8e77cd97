"""Jobs on a Dask cluster (`ladder serve --executor dask://...`): a LocalCluster of one worker
process started here. The job's progress and events reach the database through Dask, its
plan.json is the CLI's, and a cancel stops a running job and keeps a queued one from starting."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("fastapi")
distributed = pytest.importorskip("distributed")  # the test extra; CI installs it

from fastapi.testclient import TestClient  # noqa: E402

from models.scenario import ScenarioError  # noqa: E402
from planner.service import create_app  # noqa: E402
from tests.conftest import SCENARIOS  # noqa: E402
from tests.service_server import cli_plan_json  # noqa: E402
from tests.test_service import FREE, STUCK, parse_sse, submit, wait_for  # noqa: E402


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as local:
        yield "dask://" + local.scheduler_address.removeprefix("tcp://")


@pytest.fixture
def on_dask(cluster, tmp_path):
    with TestClient(create_app(tmp_path / "jobs.sqlite", executor=cluster)) as client:
        yield client


def test_a_plan_job_on_dask_reports_through_dask_and_gives_the_clis_plan(on_dask):
    job = submit(on_dask).json()
    ended = wait_for(on_dask, job["id"])
    assert ended["state"] == "succeeded" and ended["runs"] == 1, ended
    assert [r["rung"] for r in ended["rungs"]] == ["geometric", "kinematic"]
    assert on_dask.get(f"/jobs/{job['id']}/result").text == cli_plan_json(SCENARIOS / "free_transfer.toml", seed=3)
    events = parse_sse(on_dask.get(f"/jobs/{job['id']}/events").text)
    kinds = [e["event"] for e in events]
    assert [e["id"] for e in events] == list(range(1, len(events) + 1))
    assert kinds[:2] == ["state", "state"] and [e["data"]["state"] for e in events[:2]] == ["queued", "running"]
    assert kinds[-1] == "job_ended" and kinds.count("job_ended") == 1
    assert kinds.index("rung_started") < kinds.index("rung_ended") < kinds.index("job_ended")
    assert [e["data"]["rung"] for e in events if e["event"] == "rung_ended"] == ["geometric", "kinematic"]


def test_cancel_on_dask_stops_the_running_job_and_the_queued_one_never_starts(on_dask):
    running = submit(on_dask, STUCK).json()
    queued = submit(on_dask, {"kind": "plan", "scenario": FREE, "options": {"seed": 4}}).json()  # behind it: one worker
    wait_for(on_dask, running["id"], states=("running", "succeeded", "failed", "cancelled"))
    assert on_dask.delete(f"/jobs/{queued['id']}").json()["state"] == "cancelled"
    assert on_dask.delete(f"/jobs/{running['id']}").json()["cancel_requested"] is True
    ended = wait_for(on_dask, running["id"])
    assert ended["state"] == "cancelled" and json.loads(on_dask.get(f"/jobs/{running['id']}/result").text)["complete"] is False
    after = submit(on_dask, {"kind": "plan", "scenario": FREE, "options": {"seed": 5}}).json()  # the worker is free again
    assert wait_for(on_dask, after["id"])["state"] == "succeeded"
    never = on_dask.get(f"/jobs/{queued['id']}").json()
    assert never["state"] == "cancelled" and never["runs"] == 0 and never["progress"] is None


def test_an_unreachable_scheduler_is_bad_input(tmp_path, monkeypatch):
    from planner.service import remote

    monkeypatch.setattr(remote, "CONNECT_TIMEOUT_S", 1)
    with pytest.raises(ScenarioError, match="cannot reach the Dask scheduler"):
        create_app(tmp_path / "jobs.sqlite", executor="dask://127.0.0.1:9")
    with TestClient(create_app(tmp_path / "jobs.sqlite", workers=0)) as client:  # (the failed one holds no lock on it)
        assert client.get("/jobs").json()["jobs"] == []


def test_a_scheduler_that_goes_away_queues_its_jobs_again_and_runs_them_when_it_is_back(tmp_path, monkeypatch):
    """The scheduler's tasks go with it: the job under way had stayed `running` for good, and the
    server's client closed itself, so no job ran again even once a scheduler was back."""
    from planner.service import remote
    from tests import dask_processes as dp

    monkeypatch.setattr(remote, "WATCH_S", 0.3)
    said = []
    monkeypatch.setattr(remote.DaskRunner, "__init__", _with_say(remote.DaskRunner.__init__, said.append))
    port = dp.free_port()
    stuck = {**STUCK, "options": {"iterations": 10**7, "time_limit": 3}}  # (a plan job of 3 s a run)
    with dp.ended([dp.scheduler(port)]) as processes:
        processes.append(dp.worker(port))
        with TestClient(create_app(tmp_path / "jobs.sqlite", executor=f"dask://127.0.0.1:{port}")) as client:
            job = submit(client, stuck).json()
            wait_for(client, job["id"], states=("running",))
            processes[0].kill()
            assert wait_for(client, job["id"], states=("queued",), timeout=30)["runs"] == 1
            waiting = submit(client).json()  # accepted while no scheduler is there
            assert client.get(f"/jobs/{waiting['id']}").json()["state"] == "queued"
            processes += [dp.scheduler(port), dp.worker(port)]  # (a Dask worker ends with its scheduler)
            ended = wait_for(client, job["id"])
            assert ended["state"] == "succeeded" and ended["runs"] == 2, ended
            assert wait_for(client, waiting["id"])["state"] == "succeeded"
            states = [e["data"] for e in parse_sse(client.get(f"/jobs/{job['id']}/events").text) if e["event"] == "state"]
            assert states == [{"state": "queued"}, {"state": "running"}, {"state": "queued", "requeued": True}, {"state": "running"}]
            # a scheduler started again at once: Dask's client reconnects by itself, before the
            # server's watch looks, without its subscription to the jobs' messages; the job lost
            # had stayed queued for good
            monkeypatch.setattr(remote, "WATCH_S", 120.0)  # (it looks only when a task is lost)
            again = submit(client, stuck).json()
            wait_for(client, again["id"], states=("running",))
            processes[2].kill()
            processes[2].wait(timeout=30)
            processes += [dp.scheduler(port), dp.worker(port)]
            ended = wait_for(client, again["id"], timeout=60)
            assert ended["state"] == "succeeded" and ended["runs"] == 2, ended
            assert [e["event"] for e in parse_sse(client.get(f"/jobs/{again['id']}/events").text)].count("rung_ended") >= 1
    assert said[0].startswith(f"lost the Dask scheduler at dask://127.0.0.1:{port}: the jobs under way are queued again"), said
    assert said[1] == f"connected again to the Dask scheduler at dask://127.0.0.1:{port}: 2 queued job(s) sent", said
    assert said[2].startswith("lost the Dask scheduler") and said[3].startswith("connected again"), said


def _with_say(init, say):
    def patched(self, *args, **kwargs):
        init(self, *args, **{**kwargs, "say": say})

    return patched

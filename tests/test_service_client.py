"""The service's client (planner.service.client) and `ladder submit`, against a real server on
loopback (uvicorn in a thread): submit, follow, resume, results equal to the CLI's, and the
errors a user sees (one line, exit 2, no traceback)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytest.importorskip("fastapi")
httpx2 = pytest.importorskip("httpx2")

from planner.cli import main  # noqa: E402
from planner.service.client import Client, ServiceError, job_request  # noqa: E402
from tests.conftest import ROOT, SCENARIOS  # noqa: E402
from tests.service_server import cli_plan_json, running_service, wait_for_state  # noqa: E402

FREE = SCENARIOS / "free_transfer.toml"


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """A service with one worker process (module-wide: the worker loads the kernels once)."""
    with running_service(tmp_path_factory.mktemp("live") / "jobs.sqlite", workers=1) as url:
        yield url


@pytest.fixture
def idle(tmp_path):
    """A service that accepts jobs and runs none, with a token and a queue of 1."""
    with running_service(tmp_path / "jobs.sqlite", workers=0, token="s3cret", max_queued=1) as url:
        yield url


def submit_cli(capsys, monkeypatch, *args):
    """`ladder submit ARGS` run here from the repository root: (exit code, stdout, stderr)."""
    monkeypatch.chdir(ROOT)
    code = main(["submit", *args])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_job_request_carries_the_meshes_the_scenario_names(monkeypatch):
    monkeypatch.chdir(ROOT)
    body = job_request("scenarios/box_push_3d.toml", parameters={"mu": 0.4}, options={"seed": 2})
    assert body["filename"] == "scenarios/box_push_3d.toml"
    assert body["files"] == {"meshes/wedge.obj": (SCENARIOS / "meshes" / "wedge.obj").read_text()}
    assert body["scenario"] == (SCENARIOS / "box_push_3d.toml").read_text()
    assert body["parameters"] == {"mu": 0.4} and body["options"] == {"seed": 2} and body["kind"] == "plan"
    outside = job_request(FREE)  # an absolute path: the scenario goes by its file name
    assert outside["filename"] == "free_transfer.toml" and outside["files"] == {}


def test_a_mesh_missing_here_is_named_as_ladder_check_names_it(tmp_path, capsys, monkeypatch):
    """`ladder submit` of a scene whose mesh is missing: it had been sent as none, and the
    service's answer, "not among the files the request carried (none); send its contents in
    'files'", read as advice on the HTTP request."""
    scene = tmp_path / "box_push_3d.toml"
    scene.write_text((SCENARIOS / "box_push_3d.toml").read_text())
    code, out, err = submit_cli(capsys, monkeypatch, str(scene), "--server", "http://127.0.0.1:9")
    assert code == 2 and out == ""
    assert err == f"error: {scene}: bodies[4].shape.file: cannot read 'meshes/wedge.obj': No such file or directory\n", err


def test_submit_then_wait_prints_the_job_and_the_result_is_the_clis(live, capsys, monkeypatch):
    code, out, err = submit_cli(capsys, monkeypatch, "scenarios/free_transfer.toml", "--server", live, "--seed", "3", "--json")
    assert code == 0, err
    job = json.loads(out)
    assert job["state"] in ("queued", "running", "succeeded") and job["kind"] == "plan" and job["options"] == {"seed": 3}
    code, out, err = submit_cli(capsys, monkeypatch, "scenarios/free_transfer.toml", "--server", live, "--seed", "3", "--wait")
    assert code == 0, err
    assert "planning: geometric ..." in err and "ended: succeeded" in err
    assert "succeeded" in out and "top rung holds: yes" in out
    with Client(live) as client:
        first = wait_for_state(client, job["id"])
        assert first["state"] == "succeeded"
        assert client.result(job["id"]) == cli_plan_json(FREE, seed=3)
        ids = [j["id"] for j in client.jobs()]
        assert job["id"] in ids and len(ids) == len(set(ids)) == 2


def test_wait_follows_the_events_and_events_resume_after_an_id(live):
    with Client(live) as client:
        job = client.submit(FREE, options={"seed": 5})
        seen = []
        ended = client.wait(job["id"], on_event=seen.append)
        assert ended["state"] == "succeeded" and ended["id"] == job["id"]
        assert [e.id for e in seen] == list(range(1, len(seen) + 1))
        assert seen[-1].type == "job_ended" and seen[-1].data["state"] == "succeeded"
        assert {"rung_started", "rung_ended"} <= {e.type for e in seen}
        cut = len(seen) // 2
        assert [e.id for e in client.events(job["id"], last_event_id=cut)] == [e.id for e in seen[cut:]]
        assert list(client.events(job["id"], last_event_id=seen[-1].id)) == []


def test_the_client_cancels_and_reports_refusals(idle):
    with Client(idle, token="s3cret") as client:
        job = client.submit(FREE, options={"seed": 3}, idempotency_key="k")
        assert client.submit(FREE, options={"seed": 3}, idempotency_key="k")["id"] == job["id"]  # the same job
        with pytest.raises(ServiceError) as full:
            client.submit(FREE, options={"seed": 4})
        assert full.value.status == 429 and full.value.retry_after > 0 and "queue is full" in str(full.value)
        assert client.cancel(job["id"])["state"] == "cancelled"
        assert client.wait(job["id"])["state"] == "cancelled"
        with pytest.raises(ServiceError) as none:
            client.result(job["id"])
        assert none.value.status == 409
        with pytest.raises(ServiceError) as missing:
            client.get("nope")
        assert missing.value.status == 404 and "no job nope" in str(missing.value)
        bad = job_request(FREE, parameters={"nope": 1.0})
        with pytest.raises(ServiceError) as refused:
            client.submit_request(bad)
        assert refused.value.status == 422 and str(refused.value).startswith("request: body.parameters.nope:")
    with Client(idle) as anonymous, pytest.raises(ServiceError) as denied:
        anonymous.jobs()
    assert denied.value.status == 401 and "--token" in str(denied.value)


def test_a_connection_that_dies_under_a_request_is_tried_once_more_where_repeating_is_safe():
    """A pooled connection that dies under a request: the server closed it as the request went
    out (httpx2.RemoteProtocolError, the keep-alive race), or its socket is gone (a ReadError,
    "Bad file descriptor"; both seen in test_service_load on busy cores). A GET, a DELETE and a
    POST with its Idempotency-Key go once more (the POST with the same key); a second failure,
    a timeout or a POST without a key is the service unreachable (status None)."""
    seen = []  # (method, path, Idempotency-Key) of every request sent
    drops = {"left": 0, "error": httpx2.RemoteProtocolError}

    def answer(request: httpx2.Request) -> httpx2.Response:
        seen.append((request.method, request.url.path, request.headers.get("Idempotency-Key")))
        if drops["left"] > 0:
            drops["left"] -= 1
            raise drops["error"]("Server disconnected without sending a response.", request=request)
        return httpx2.Response(200, json={"id": "j1", "state": "queued", "jobs": []})

    with Client("http://127.0.0.1:9") as client:
        client._http = httpx2.Client(base_url=client.url, transport=httpx2.MockTransport(answer))
        for call, method in ((lambda: client.get("j1"), "GET"), (lambda: client.cancel("j1"), "DELETE")):
            seen.clear()
            drops["left"] = 1
            assert call()["id"] == "j1" and [m for m, _, _ in seen] == [method, method]
        seen.clear()
        drops["left"] = 1
        assert client.submit_request({"kind": "plan"}, idempotency_key="k7")["id"] == "j1"
        assert seen == [("POST", "/jobs", "k7"), ("POST", "/jobs", "k7")]  # one key: never a second job
        drops["left"] = 2
        with pytest.raises(ServiceError) as twice:
            client.jobs()
        assert twice.value.status is None and "cannot reach the service" in str(twice.value)
        seen.clear()
        drops["left"] = 1
        with pytest.raises(ServiceError) as unkeyed:
            client._request("POST", "/jobs", json={})
        assert unkeyed.value.status is None and len(seen) == 1  # not sent again: it might make a second job
        seen.clear()
        drops.update(left=1, error=httpx2.ReadError)  # "[Errno 9] Bad file descriptor"
        assert client.get("j1")["id"] == "j1" and len(seen) == 2
        seen.clear()
        drops.update(left=1, error=httpx2.ReadTimeout)
        with pytest.raises(ServiceError) as slow:
            client.get("j1")
        assert slow.value.status is None and len(seen) == 1  # a timeout is not doubled


@pytest.mark.parametrize(
    "args, message",
    [
        (["scenarios/free_transfer.toml", "--server", "http://127.0.0.1:9"], "error: cannot reach the service at http://127.0.0.1:9"),
        (["scenarios/free_transfer.toml", "--server", "127.0.0.1:8000"], "must start with http:// or https://"),
        (["scenarios/no_such.toml"], "error: scenarios/no_such.toml: no such file"),
        (["scenarios/free_transfer.toml", "--param", "gap"], "--param gap: expected NAME=NUMBER"),
    ],
)
def test_submit_bad_input_is_one_line_and_exit_2(capsys, monkeypatch, args, message):
    code, out, err = submit_cli(capsys, monkeypatch, *args)
    assert code == 2 and out == ""
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_submit_refused_by_the_service_is_exit_2_with_its_reasons(idle, capsys, monkeypatch):
    code, out, err = submit_cli(capsys, monkeypatch, "scenarios/free_transfer.toml", "--server", idle)
    assert code == 2 and out == "" and "401" in err and "--token" in err and "Traceback" not in err
    monkeypatch.setenv("LADDER_TOKEN", "s3cret")
    # the request's options and parameters are the request's (the service names its body's keys),
    # and `ladder submit` says them as the flags that set them, as `ladder plan` does
    args = ["scenarios/free_transfer.toml", "--server", idle, "--seed", "-1", "--param", "nope=1"]
    code, out, both = submit_cli(capsys, monkeypatch, *args)
    assert code == 2 and out == "" and "Traceback" not in both
    assert sorted(both.splitlines()) == [
        "error: scenarios/free_transfer.toml: --param nope: the file has no parameter 'nope' (parameters: gap, vx, vy)",
        "error: scenarios/free_transfer.toml: --seed: must be between 0 and 1000000000, got -1",
    ]
    code, out, err = submit_cli(capsys, monkeypatch, *args[:3], "--param", "nope=1")
    assert code == 2 and out == "" and "Traceback" not in err
    assert err.startswith("error: scenarios/free_transfer.toml: --param nope: the file has no parameter 'nope'")  # (alone)
    plan = subprocess.run(
        [sys.executable, "-m", "planner", "plan", "scenarios/free_transfer.toml", "--param", "nope=1", "--seed", "-1"],
        cwd=ROOT, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert plan.returncode == 2 and sorted(plan.stderr.splitlines()) == sorted(both.splitlines())  # the same words as `ladder plan`'s
    # an address past the service's root (its /jobs route) is a 405: said as a wrong address
    code, out, err = submit_cli(capsys, monkeypatch, "scenarios/free_transfer.toml", "--server", idle + "/jobs")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert f"405 Method Not Allowed: Method Not Allowed at /jobs/jobs: is {idle} a ladder service, and the address its root?" in err


def test_a_server_that_is_not_the_service_is_said_in_one_line(capsys, monkeypatch):
    """Another program's web server answers a job with a page of its own: its status, and the
    question whether the address is a ladder service, not the page's lines (they had been
    printed one `error:` line each)."""
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    class Page(BaseHTTPRequestHandler):
        def do_POST(self):  # noqa: N802 (http.server's name)
            body = b"<!DOCTYPE html>\n<html>\n<body>\n<h1>Not here</h1>\n</body>\n</html>\n"
            self.send_response(501, "Unsupported method ('POST')")
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):  # quiet
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Page)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    url = f"http://127.0.0.1:{server.server_address[1]}"
    try:
        code, out, err = submit_cli(capsys, monkeypatch, "scenarios/free_transfer.toml", "--server", url)
    finally:
        server.shutdown()
        server.server_close()
    assert code == 2 and out == "" and "Traceback" not in err
    assert err.splitlines() == [
        f"error: 501 Unsupported method ('POST') at /jobs: is {url} a ladder service, and the address its root? (ladder submit: --server)"
    ]


def test_ctrl_c_while_waiting_says_the_job_goes_on_and_how_to_cancel_it(idle, capsys, monkeypatch):
    """Ctrl-C stops only the waiting (it had said "interrupted" alone): the job goes on at the
    service, which this says, with the address that cancels it."""

    def interrupted(self, job_id, on_event=None):
        raise KeyboardInterrupt

    monkeypatch.setenv("LADDER_TOKEN", "s3cret")
    monkeypatch.setattr(Client, "wait", interrupted)
    code, out, err = submit_cli(capsys, monkeypatch, "scenarios/free_transfer.toml", "--server", idle, "--wait")
    assert code == 130 and out == "" and "Traceback" not in err
    job_id = err.split()[1].rstrip(":")
    assert err.splitlines()[-1] == (
        f"interrupted: job {job_id} goes on at the service ({idle}/jobs/{job_id}; DELETE {idle}/jobs/{job_id} cancels it)"
    )
    with Client(idle, "s3cret") as client:
        assert client.get(job_id)["state"] == "queued"


def test_a_request_key_goes_back_to_the_flag_it_came_from():
    """`ladder submit`'s words (`cli_flag`) are the service's (`_cli_key`) read the other way."""
    from planner.service.jobs import _cli_key, cli_flag

    for flag in ("--param v1", "--seed", "--flat", "--time-limit", "--grid v1"):
        assert cli_flag("body." + _cli_key(flag)) == flag
    # keys no flag sets, and an option only a negative flag sets: left in the request's words
    assert [cli_flag(k) for k in ("body", "body.scenario", "body.options.guide")] == [None, None, None]

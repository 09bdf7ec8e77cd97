"""A client of the planning service (`ladder serve`) over httpx2 (the maintained fork of httpx,
which Starlette's test client also takes): what `ladder submit` runs, and what a script or a
notebook uses to submit a scenario and wait for its plan.

    from planner.service.client import Client

    with Client("http://127.0.0.1:8000", token=None) as service:
        job = service.submit("scenarios/two_finger_triangle.toml", parameters={"v1": 0.8}, options={"seed": 3})
        job = service.wait(job["id"], on_event=print)  # follows the job's server-sent events
        plan = json.loads(service.result(job["id"]))   # plan.json, as `ladder plan` writes it

Jobs come back as the dicts GET /jobs/{id} answers (`id`, `state`, `progress`, `rungs`, ...).
A request the service refuses, or a service that cannot be reached, raises ServiceError with
a message to show as it is (a bad scenario's `FILE: KEY: reason` lines).
"""

from __future__ import annotations

import json
import time
import tomllib
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import httpx2

from models.scenario import Problem, ScenarioError
from planner.service.jobs import file_references, path_problem
from planner.service.store import TERMINAL

DEFAULT_SERVER = "http://127.0.0.1:8000"
#: Seconds a request may take (an events stream may be quiet longer: the server sends a
#: keep-alive comment every 15 s).
TIMEOUT_S = 30.0
EVENTS_READ_TIMEOUT_S = 60.0
#: How long an events stream is reconnected (with Last-Event-ID) while the server cannot be reached.
RECONNECT_FOR_S = 60.0
RECONNECT_PAUSE_S = 0.5
#: Seconds an idle connection is kept for the next request: under uvicorn's 5 s (its
#: timeout_keep_alive), so the client lets a connection go before the server closes it.
KEEPALIVE_S = 4.0


class ServiceError(Exception):
    """The service refused a request (`status`: its HTTP status) or could not be reached
    (`status` None). str() is the message to print; `retry_after` is the seconds a 429 asked for."""

    def __init__(self, message: str, status: int | None = None, retry_after: float | None = None):
        super().__init__(message)
        self.status = status
        self.retry_after = retry_after


@dataclass(frozen=True)
class Event:
    """One server-sent event of a job: its id (1, 2, ... per job), type and data."""

    id: int
    type: str
    data: dict


def job_request(path: str | Path, kind: str = "plan", *, parameters: dict | None = None, options: dict | None = None) -> dict:
    """The POST /jobs body for the scenario file at `path`: its TOML text, every file it names
    (meshes, relative to it) as contents, and `filename` the path as given when it is relative
    and stays below the working folder (so plan.json names the scenario as `ladder plan PATH`
    would), else the file's name. ScenarioError when the file, or one it names, cannot be read
    here (a missing mesh had been sent as none, and the service's problem, "not among the files
    the request carried", read as advice on the request)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError(path, [Problem("", "no such file")]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(path, [Problem("", f"cannot read it: {getattr(exc, 'strerror', None) or exc}")]) from None
    given = PurePosixPath(path.as_posix())
    filename = given.as_posix() if path_problem("filename", given.as_posix()) is None else path.name
    files = {}
    try:
        raw = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError):
        raw = {}  # the service says what is wrong with the text
    for key, name in file_references(raw):
        if not isinstance(name, str) or path_problem(key, name) is not None or name in files:
            continue
        try:
            files[name] = (path.parent / name).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ScenarioError(path, [Problem(key, f"cannot read {name!r}: {getattr(exc, 'strerror', None) or exc}")]) from None
    return {
        "kind": kind,
        "scenario": text,
        "filename": filename,
        "files": files,
        "parameters": dict(parameters or {}),
        "options": dict(options or {}),
    }


def _message(response: httpx2.Response) -> str:
    """A refused request's message: the service's `detail` (FastAPI's validation errors as `where: what` lines)."""
    try:
        detail = response.json().get("detail")
        answered = True  # JSON, as the service answers
    except (ValueError, AttributeError):
        detail, answered = None, False
    if isinstance(detail, list):  # FastAPI's own 422: [{"loc": [...], "msg": ...}]
        detail = "\n".join(f"{'.'.join(str(x) for x in d.get('loc', []))}: {d.get('msg')}" for d in detail if isinstance(d, dict))
    root = str(response.request.url.copy_with(path="/", query=None, fragment=None)).rstrip("/")
    not_here = f" at {response.request.url.path}: is {root} a ladder service, and the address its root? (ladder submit: --server)"
    if not answered:  # not the service's answer (another server's page, a proxy's): its status, not its body's lines
        return f"{response.status_code} {response.reason_phrase}{not_here}"
    if not detail:
        detail = response.text.strip() or response.reason_phrase
    if response.status_code == 401:
        detail += " (ladder submit: --token, or the LADDER_TOKEN environment variable)"
    elif response.status_code == 405 or (response.status_code == 404 and detail == "Not Found"):  # a route the service lacks
        detail += not_here
    return f"{detail}" if response.status_code == 422 else f"{response.status_code} {response.reason_phrase}: {detail}"


class Client:
    """The planning service at `url` (e.g. http://127.0.0.1:8000), with its bearer `token` if it has one."""

    def __init__(self, url: str = DEFAULT_SERVER, token: str | None = None, *, timeout: float = TIMEOUT_S):
        if not url.startswith(("http://", "https://")):
            raise ServiceError(f"{url}: the service's address must start with http:// or https://")
        self.url = url.rstrip("/")
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        limits = httpx2.Limits(keepalive_expiry=KEEPALIVE_S)
        self._http = httpx2.Client(base_url=self.url, headers=headers, timeout=timeout, limits=limits)

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _request(self, method: str, path: str, **kwargs) -> httpx2.Response:
        # a pooled connection that died under the request (the server closed it as the request
        # went out: RemoteProtocolError, "Server disconnected without sending a response"; or its
        # socket is gone: "Bad file descriptor") is not the service failing: where sending the
        # request again is safe (a GET or DELETE, a POST with its Idempotency-Key), it goes once
        # more, on a new connection. A timeout is not retried: it would double the wait.
        repeatable = method in ("GET", "DELETE") or "Idempotency-Key" in kwargs.get("headers", {})
        for attempt in (0, 1):
            try:
                response = self._http.request(method, path, **kwargs)
                break
            except httpx2.TransportError as exc:
                if not repeatable or attempt == 1 or isinstance(exc, httpx2.TimeoutException):
                    raise ServiceError(f"cannot reach the service at {self.url}: {exc or type(exc).__name__}") from None
        if response.status_code >= 400:
            retry = response.headers.get("retry-after")
            raise ServiceError(
                _message(response), response.status_code, float(retry) if retry and retry.replace(".", "", 1).isdigit() else None
            )
        return response

    # ------------------------------------------------------------------ jobs

    def submit(
        self,
        path: str | Path,
        kind: str = "plan",
        *,
        parameters: dict | None = None,
        options: dict | None = None,
        idempotency_key: str | None = None,
        retries: int = 0,
    ) -> dict:
        """Submit the scenario file at `path` (with the meshes it names) as a job; the job."""
        body = job_request(path, kind, parameters=parameters, options=options)
        return self.submit_request(body, idempotency_key=idempotency_key, retries=retries)

    def submit_request(self, body: dict, *, idempotency_key: str | None = None, retries: int = 0) -> dict:
        """POST /jobs with `body` (see job_request); the job. Each submission carries an
        Idempotency-Key (a fresh one unless given), so that up to `retries` retries, after a
        full queue (429, after its Retry-After) or a lost connection, never make a second job."""
        key = idempotency_key or uuid.uuid4().hex
        for attempt in range(retries + 1):
            try:
                return self._request("POST", "/jobs", json=body, headers={"Idempotency-Key": key}).json()
            except ServiceError as exc:
                if attempt == retries or exc.status not in (None, 429):
                    raise
                time.sleep(exc.retry_after if exc.retry_after is not None else RECONNECT_PAUSE_S)
        raise AssertionError("unreachable")

    def get(self, job_id: str) -> dict:
        """GET /jobs/{id}: state, progress, the rungs' reports so far."""
        return self._request("GET", f"/jobs/{job_id}").json()

    def jobs(self, state: str | None = None) -> list[dict]:
        """GET /jobs, oldest first; only those in `state` when given."""
        return self._request("GET", "/jobs", params={"state": state} if state else None).json()["jobs"]

    def result(self, job_id: str) -> str:
        """The result file's text (a plan's plan.json byte for byte); ServiceError 409 when there is none yet."""
        return self._request("GET", f"/jobs/{job_id}/result").text

    def cancel(self, job_id: str) -> dict:
        """DELETE /jobs/{id}: a queued job is cancelled at once, a running one at its next check."""
        return self._request("DELETE", f"/jobs/{job_id}").json()

    def events(self, job_id: str, last_event_id: int = 0) -> Iterator[Event]:
        """The job's events after `last_event_id`, live, until its job_ended event. A dropped
        connection is resumed with Last-Event-ID (for up to RECONNECT_FOR_S of failures in a
        row), so no event is missed or repeated."""
        last, failing_since = last_event_id, None
        while True:
            try:
                ended = False
                for event in self._stream(job_id, last):
                    last, failing_since = event.id, None
                    yield event
                    if event.type == "job_ended":
                        return
                # the stream ended without job_ended: the job ended before (its events all seen) or the server stopped
                ended = self.get(job_id)["state"] in TERMINAL
            except ServiceError as exc:
                if exc.status is not None:
                    raise
            if ended:
                return
            failing_since = failing_since or time.monotonic()
            if time.monotonic() - failing_since > RECONNECT_FOR_S:
                raise ServiceError(f"lost the events of job {job_id} at {self.url}: no answer for {RECONNECT_FOR_S:g} s")
            time.sleep(RECONNECT_PAUSE_S)

    def _stream(self, job_id: str, last: int) -> Iterator[Event]:
        headers = {"Last-Event-ID": str(last)} if last else {}
        timeout = httpx2.Timeout(TIMEOUT_S, read=EVENTS_READ_TIMEOUT_S)
        try:
            with self._http.stream("GET", f"/jobs/{job_id}/events", headers=headers, timeout=timeout) as response:
                if response.status_code >= 400:
                    response.read()
                    raise ServiceError(_message(response), response.status_code)
                fields: dict[str, str] = {}
                for line in response.iter_lines():
                    if line == "":
                        if "id" in fields:
                            yield Event(int(fields["id"]), fields.get("event", "message"), json.loads(fields.get("data", "{}")))
                        fields = {}
                    elif not line.startswith(":"):
                        name, _, value = line.partition(":")
                        fields[name] = value.removeprefix(" ")
        except httpx2.TransportError as exc:
            raise ServiceError(f"cannot reach the service at {self.url}: {exc or type(exc).__name__}") from None

    def wait(self, job_id: str, on_event: Callable[[Event], Any] | None = None) -> dict:
        """Follow the job's events until it ends (calling `on_event` with each); the job then."""
        for event in self.events(job_id):
            if on_event is not None:
                on_event(event)
        return self.get(job_id)

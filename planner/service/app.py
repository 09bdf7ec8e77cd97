"""The service's HTTP API (FastAPI): jobs as resources, their events as server-sent events.

POST   /jobs                 submit (201, Location: /jobs/{id}); Idempotency-Key honoured
GET    /jobs                 list (?state=)
GET    /jobs/{id}            state, progress, per-rung reports
GET    /jobs/{id}/result     the result file (a plan's plan.json, byte for byte the CLI's; a sweep's sweep.json)
DELETE /jobs/{id}            cancel
GET    /jobs/{id}/events     server-sent events (ids; Last-Event-ID resumes; ?token= for a browser's EventSource)
GET    /jobs/{id}/scene      what the viewer draws: the scene's shapes, a plan's body placements per rung
GET    /                     the viewer (static/index.html)
"""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import json
import multiprocessing
import re
import sqlite3
import threading
import uuid
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any, Literal
from urllib.parse import parse_qs

from fastapi import FastAPI, Header, HTTPException, Query, Request, Response
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, StreamingResponse
from pydantic import BaseModel, ConfigDict, Field
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from models.scenario import Problem, ScenarioError
from planner.service import jobs
from planner.service.store import STATES, TERMINAL, Store, iso
from planner.service.view import scene_view
from planner.service.worker import ignore_stop_signals, run_job

#: Paths that need no token (the API's description, and the viewer's page, which asks for it).
OPEN_PATHS = frozenset({"/openapi.json", "/docs", "/docs/oauth2-redirect", "/redoc", "/"})
#: The one route that also takes the token as ?token=: a browser's EventSource cannot send headers.
EVENTS_PATH = re.compile(r"/jobs/[^/]+/events")
VIEWER = Path(__file__).parent / "static" / "index.html"
DEFAULT_MAX_BODY = 2 * 1024 * 1024
DEFAULT_MAX_QUEUED = 100
RETRY_AFTER_S = 5
#: Seconds between the events stream's looks at the database, and between keep-alive comments.
EVENTS_POLL_S = 0.1
#: Seconds a stopping server gives the requests still open (its event streams end at once).
SHUTDOWN_GRACE_S = 1
KEEPALIVE_S = 15.0


class JobRequest(BaseModel):
    """A job: a scenario (TOML text and the files it names, as contents), parameter overrides and options."""

    model_config = ConfigDict(extra="forbid")
    kind: Literal["plan", "simulate", "sweep"] = Field(
        description="plan: up the ladder (or flat); simulate: the policy under one rung; sweep: the policy over a grid of parameters"
    )
    scenario: str = Field(description="the scenario file's TOML text")
    filename: str = Field("scenario.toml", description="the scenario's relative file name (plan.json's `scenario`)")
    files: dict[str, str] = Field(default_factory=dict, description="files the scenario names (meshes), relative to it: name -> text")
    parameters: dict[str, float] = Field(default_factory=dict, description="design-parameter overrides (the CLI's --param)")
    options: dict[str, Any] = Field(
        default_factory=dict,
        description="; ".join(f"{kind}: {', '.join(names)}" for kind, names in jobs.OPTIONS.items())
        + " (a sweep's grid is a list of `ladder sweep --grid` texts, its model the --model text)",
    )


class ProblemItem(BaseModel):
    key: str = Field(description="where: a key path of the scenario (bodies[2].pose), or of the request (body.options.seed)")
    reason: str


class Problems(BaseModel):
    """Every 422: the CLI's `FILE: KEY: reason` lines, and the same as data."""

    detail: str = Field(description="one `FILE: KEY: reason` line per problem, as the CLI prints them")
    file: str = Field(description="the scenario's file name, or `request` for the request itself")
    problems: list[ProblemItem]


class Error(BaseModel):
    detail: str


class Links(BaseModel):
    self: str
    result: str
    events: str


class Job(BaseModel):
    """A job as GET /jobs/{id} answers it (GET /jobs leaves out `rungs`)."""

    id: str
    kind: Literal["plan", "simulate", "sweep"]
    state: Literal[STATES] = Field(description="queued, running, then succeeded, failed or cancelled")  # type: ignore[valid-type]
    created: str = Field(description="ISO 8601, UTC")
    updated: str = Field(description="ISO 8601, UTC")
    filename: str
    parameters: dict[str, float]
    options: dict[str, Any]
    progress: dict[str, Any] | None = Field(
        description="a plan's rung, iterations, propagations; a sweep's runs_done and runs, or refine_step and brackets"
    )
    cancel_requested: bool
    runs: int = Field(description="times a worker started the job (more than 1 after a restart)")
    error: str | None
    result_available: bool
    links: Links
    rungs: list[dict[str, Any]] | None = Field(None, description="a plan's per-rung reports, as its rungs finished")


class JobList(BaseModel):
    jobs: list[Job]


#: What every route may answer besides its own (the guard's 401 with a token, 400 and 413 on bodies).
COMMON_RESPONSES: dict[int | str, dict[str, Any]] = {
    401: {"model": Error, "description": "missing or wrong bearer token (only when the service has one)"},
}
NOT_FOUND = {404: {"model": Error, "description": "no such job"}}
UNPROCESSABLE = {422: {"model": Problems, "description": "bad input: the problems, one per line"}}


class EventStream(StreamingResponse):
    media_type = "text/event-stream"


def _unprocessable(exc: ScenarioError) -> JSONResponse:
    return JSONResponse(exc.to_json(), status_code=422)


class _Guard:
    """ASGI middleware: the bearer token (when set) and the request-size limit (413)."""

    def __init__(self, app, token: str | None, max_body: int):
        self.app, self.token, self.max_body = app, token, max_body

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        headers = {k.lower(): v for k, v in scope.get("headers", [])}
        if self.token and scope["path"] not in OPEN_PATHS:
            given = headers.get(b"authorization", b"").decode("latin-1")
            if not given and EVENTS_PATH.fullmatch(scope["path"]):
                query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
                given = f"Bearer {query['token'][0]}" if query.get("token") else ""
            scheme, _, credentials = given.partition(" ")
            # the scheme is case-insensitive (RFC 9110, 11.1): "bearer TOKEN" is the same credential
            if scheme.lower() != "bearer" or not hmac.compare_digest(credentials.strip().encode(), self.token.encode()):
                detail = "missing or wrong token: send 'Authorization: Bearer TOKEN'"
                return await _send_json(send, 401, {"detail": detail}, [(b"www-authenticate", b"Bearer")])
        if scope["method"] not in ("POST", "PUT", "PATCH"):
            return await self.app(scope, receive, send)
        length = headers.get(b"content-length")
        too_big = {"detail": f"request body larger than the limit of {self.max_body} bytes"}
        if length is not None:
            try:
                if int(length) > self.max_body:
                    return await _send_json(send, 413, too_big)
            except ValueError:
                return await _send_json(send, 400, {"detail": "bad Content-Length"})
        body, more = b"", True
        while more:  # read it all (bounded), so a body without a Content-Length is limited too
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            body += message.get("body", b"")
            more = message.get("more_body", False)
            if len(body) > self.max_body:
                return await _send_json(send, 413, too_big)
        replayed = False

        async def replay():
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        return await self.app(scope, replay, send)


async def _send_json(send, status: int, data: dict, headers: list | None = None) -> None:
    body = json.dumps(data).encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())] + (headers or []),
        }
    )
    await send({"type": "http.response.body", "body": body})


def _validation_problem(error: dict) -> Problem:
    """One of FastAPI's validation errors as a problem keyed where it is in the request; a body
    that is not JSON says where and what the parser found (FastAPI's own words: `body.17: JSON
    decode error`)."""
    loc = error.get("loc", ())
    if error.get("type") == "json_invalid" and len(loc) == 2 and isinstance(loc[1], int):
        found = (error.get("ctx") or {}).get("error", "")
        return Problem("body", f"not valid JSON at character {loc[1]}" + (f": {found}" if found else ""))
    return Problem(".".join(str(x) for x in loc), str(error.get("msg", "")))


class Service:
    """The jobs' store and what runs them: a local worker pool, or a Dask cluster (`executor`,
    dask://HOST:PORT, connected at once: ScenarioError when it cannot be reached)."""

    def __init__(self, db_path: str | Path, workers: int, max_queued: int, max_job_seconds: float | None, executor: str | None = None):
        self.db_path = str(db_path)
        self.workers = workers
        self.max_queued = max_queued
        self.max_job_seconds = max_job_seconds
        self.executor = executor
        self._owner = None
        self._own()
        self.store = self._open_store()
        self.closed = False
        self.pool: ProcessPoolExecutor | None = None
        self.lock = threading.Lock()
        self.runner = None
        self.stopping = lambda: False  # the server is stopping: event streams end (`server_for`)
        if executor is not None:
            from planner.service.remote import DaskRunner

            try:
                self.runner = DaskRunner(executor, self.store, max_job_seconds)
            except BaseException:  # (out of reach: the database is not this service's after all)
                self.store.close()
                self._owner.close()
                raise

    def start(self) -> None:
        """Run the jobs a stopped service left (also when this service was stopped before: an
        app's lifespan may run more than once in tests)."""
        if self.closed:
            self._own()
            self.store, self.closed = self._open_store(), False
        if self.executor is not None and self.runner is None:
            from planner.service.remote import DaskRunner

            self.runner = DaskRunner(self.executor, self.store, self.max_job_seconds)
        for job_id in self.store.recover():
            self.submit(job_id)

    def stop(self) -> None:
        """Stop the workers at once: a job under way stays `running` in the database and is
        run again from its inputs when the service starts next."""
        with self.lock:
            pool, self.pool = self.pool, None
        if pool is not None:
            processes = list((pool._processes or {}).values())  # noqa: SLF001 (no public way to stop a running task)
            pool.shutdown(wait=False, cancel_futures=True)
            for process in processes:
                process.kill()  # they ignore SIGTERM (`ignore_stop_signals`)
            for process in processes:
                process.join(5)
        if self.runner is not None:
            self.runner.close()  # a task under way finishes on the cluster unheard; the job runs again on restart
            self.runner = None
        self.store.close()
        self.closed = True
        self._owner.close()  # (the lock with it)
        self._owner = None

    def _open_store(self) -> Store:
        """The jobs' store on the database this service owns (`_own`), or ScenarioError naming
        --db where the file is not a ladder jobs database (the lock given up, and its file
        removed where `_own` made it)."""
        try:
            return Store(self.db_path)
        except sqlite3.DatabaseError as exc:
            self._owner.close()
            self._owner = None
            if self._made_lock:
                Path(f"{self.db_path}.lock").unlink(missing_ok=True)
            problem = Problem("--db", f"{self.db_path}: not a ladder jobs database ({exc}); give the jobs' database, or a new file")
            raise ScenarioError("ladder serve", [problem]) from None

    def _own(self) -> None:
        """Run the database's jobs alone, or ScenarioError: a second server on it ran them again
        (its start queues the jobs under way and runs them), beside the first. The lock is an
        exclusive flock on DB.lock, which the system releases when the process ends (kill -9 too);
        not on the database, whose SQLite locks closing another descriptor of it would release."""
        import fcntl

        self._made_lock = not Path(f"{self.db_path}.lock").exists()
        owner = open(f"{self.db_path}.lock", "a")  # noqa: SIM115 (held until `stop`)
        try:
            fcntl.flock(owner, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner.close()
            problem = Problem(
                "--db",
                f"{self.db_path}: another `ladder serve` runs this database's jobs (two would run the same jobs at once); "
                "stop it, or give another --db",
            )
            raise ScenarioError("ladder serve", [problem]) from None
        self._owner = owner

    def _pool(self) -> ProcessPoolExecutor:
        with self.lock:
            if self.pool is None:
                # spawn, not fork: the server has threads; a worker imports the planner once
                self.pool = ProcessPoolExecutor(
                    self.workers, mp_context=multiprocessing.get_context("spawn"), initializer=ignore_stop_signals
                )
            return self.pool

    def submit(self, job_id: str) -> None:
        if self.runner is not None:
            self.runner.submit(job_id)
            return
        if self.workers < 1:
            return  # accept jobs, run none (a store-only service, and the queue tests)
        try:
            future = self._pool().submit(run_job, self.db_path, job_id, self.max_job_seconds)
        except (BrokenProcessPool, RuntimeError):
            with self.lock:
                self.pool = None
            future = self._pool().submit(run_job, self.db_path, job_id, self.max_job_seconds)
        future.add_done_callback(lambda f, job_id=job_id: self._done(job_id, f))

    def cancel(self, job_id: str) -> None:
        """DELETE /jobs/{id}: the store's cancel, and on Dask the task's cancel event."""
        self.store.cancel(job_id)
        if self.runner is not None:
            self.runner.cancel(job_id)

    def _done(self, job_id: str, future: Future) -> None:
        if future.cancelled():
            return  # the service is stopping: the job stays queued and runs after a restart
        exc = future.exception()
        if exc is None:
            return
        if isinstance(exc, BrokenProcessPool):
            if self.pool is None:  # stopping
                return
            with self.lock:
                self.pool = None  # a worker died (killed, out of memory): a new pool for the next jobs
        try:
            self.store.finish(job_id, "failed", error=f"the worker stopped: {type(exc).__name__}: {exc}")
        except Exception:  # the store is closed: the service is stopping
            pass


def _job_json(service: Service, row, *, rungs: bool = True) -> dict:
    job_id = row["id"]
    inputs = json.loads(row["inputs"])
    data = {
        "id": job_id,
        "kind": row["kind"],
        "state": row["state"],
        "created": iso(row["created"]),
        "updated": iso(row["updated"]),
        "filename": inputs.get("filename", "scenario.toml"),
        "parameters": inputs.get("parameters") or {},
        "options": json.loads(row["options"]),
        "progress": json.loads(row["progress"]) if row["progress"] else None,
        "cancel_requested": bool(row["cancel_requested"]),
        "runs": row["runs"],
        "error": row["error"],
        "result_available": row["result"] is not None,
        "links": {"self": f"/jobs/{job_id}", "result": f"/jobs/{job_id}/result", "events": f"/jobs/{job_id}/events"},
    }
    if rungs:
        data["rungs"] = service.store.rung_reports(job_id)
    return data


def server_for(app: FastAPI, **config):
    """A uvicorn Server of the app (`config`: uvicorn.Config's) whose job event streams end as it
    stops: a client following a job holds its connection open, and uvicorn waits for the open
    connections (here at most SHUTDOWN_GRACE_S) before the app's shutdown stops the workers, so
    the server had run on until the followed job ended."""
    import uvicorn

    server = uvicorn.Server(uvicorn.Config(app, timeout_graceful_shutdown=SHUTDOWN_GRACE_S, **config))
    app.state.service.stopping = lambda: server.should_exit
    return server


def create_app(
    db_path: str | Path = "ladder-jobs.sqlite",
    workers: int = 1,
    token: str | None = None,
    *,
    max_body: int = DEFAULT_MAX_BODY,
    max_queued: int = DEFAULT_MAX_QUEUED,
    max_job_seconds: float | None = None,
    retry_after: int = RETRY_AFTER_S,
    executor: str | None = None,
) -> FastAPI:
    """The service's app: jobs in SQLite at `db_path`, run by `workers` processes (0: accept
    jobs, run none), every route but /openapi.json and /docs behind `token` when given;
    bodies above `max_body` bytes get 413, a submission while `max_queued` jobs wait gets
    429 (with `Retry-After: retry_after` seconds), a job running longer than `max_job_seconds`
    is stopped (failed, its rungs kept). With `executor` (dask://HOST:PORT) jobs run on that
    Dask cluster instead of `workers` local processes."""
    service = Service(db_path, workers, max_queued, max_job_seconds, executor)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        service.start()
        try:
            yield
        finally:
            service.stop()

    app = FastAPI(
        title="ladder planning service",
        description="Plans up the ladder of contact models, as `ladder plan` does, as jobs.",
        lifespan=lifespan,
        responses=COMMON_RESPONSES,
    )
    app.state.service = service
    app.add_middleware(_Guard, token=token, max_body=max_body)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException):
        """FastAPI's answer, but a 405's Allow lists every method of the path (Starlette names
        only the first route's, and GET /jobs and POST /jobs are two routes)."""
        if exc.status_code == 405:
            methods = {m for r in app.router.routes if r.matches(request.scope)[0] != Match.NONE for m in getattr(r, "methods", ())}
            exc.headers = {**(exc.headers or {}), "Allow": ", ".join(sorted(methods - {"HEAD"}))}
        return await http_exception_handler(request, exc)

    @app.exception_handler(RequestValidationError)
    async def request_error(request: Request, exc: RequestValidationError):
        """A request that is not what the description says: 422 as every other bad input."""
        return _unprocessable(ScenarioError("request", [_validation_problem(e) for e in exc.errors()]))

    def get_row(job_id: str):
        row = service.store.get(job_id)
        if row is None:
            raise HTTPException(404, f"no job {job_id}")
        return row

    @app.post(
        "/jobs",
        status_code=201,
        response_model=Job,
        responses={
            200: {"model": Job, "description": "the job this Idempotency-Key made before"},
            201: {"description": "the job, queued; `Location` is its URL"},
            400: {"model": Error, "description": "a bad Content-Length"},
            409: {"model": Error, "description": "this Idempotency-Key came with another request"},
            413: {"model": Error, "description": "the body is larger than the limit"},
            429: {"model": Error, "description": "the queue is full; try again after `Retry-After` seconds"},
            **UNPROCESSABLE,
        },
    )
    def submit(job: JobRequest, response: Response, idempotency_key: str | None = Header(None)):
        """Submit a job. A bad scenario is 422 with the CLI's `FILE: KEY: reason` lines."""
        inputs = {"filename": job.filename, "scenario": job.scenario, "files": job.files, "parameters": job.parameters}
        try:
            jobs.validate(job.kind, inputs, job.options)
        except ScenarioError as exc:
            return _unprocessable(exc)
        sha = hashlib.sha256(json.dumps({"kind": job.kind, **inputs, "options": job.options}, sort_keys=True).encode()).hexdigest()
        row, what = service.store.create_job(
            uuid.uuid4().hex, job.kind, inputs, job.options, key=idempotency_key, sha=sha, max_queued=service.max_queued
        )
        if what == "full":
            return JSONResponse(
                {"detail": f"the queue is full ({service.max_queued} jobs waiting); try again later"},
                status_code=429,
                headers={"Retry-After": str(retry_after)},
            )
        if what == "conflict":
            raise HTTPException(409, "this Idempotency-Key was used with a different request")
        response.headers["Location"] = f"/jobs/{row['id']}"
        if what == "existing":
            response.status_code = 200
        else:
            service.submit(row["id"])
        return _job_json(service, row)

    @app.get("/jobs", response_model=JobList, response_model_exclude_unset=True, responses=UNPROCESSABLE)
    def list_jobs(state: str | None = Query(None, description="only jobs in this state")):
        """The jobs, oldest first (without their rungs' reports)."""
        if state is not None and state not in STATES:
            return _unprocessable(ScenarioError("request", [Problem("state", f"unknown state {state!r}; states: {', '.join(STATES)}")]))
        return {"jobs": [_job_json(service, row, rungs=False) for row in service.store.list(state)]}

    @app.get("/jobs/{job_id}", response_model=Job, responses=NOT_FOUND)
    def get_job(job_id: str):
        """A job: its state, progress and the reports of its rungs so far."""
        return _job_json(service, get_row(job_id))

    @app.get(
        "/jobs/{job_id}/result",
        responses={
            200: {"content": {"application/json": {"schema": {"type": "object"}}}, "description": "the result file"},
            **NOT_FOUND,
            409: {"model": Error, "description": "the job has no result (yet)"},
        },
    )
    def get_result(job_id: str):
        """The result file: a plan's plan.json (as `ladder plan` writes it), a simulation's JSON."""
        row = get_row(job_id)
        if row["result"] is None:
            raise HTTPException(409, f"job {job_id} is {row['state']}: no result" + (f" ({row['error']})" if row["error"] else ""))
        return Response(row["result"], media_type="application/json")

    @app.delete("/jobs/{job_id}", response_model=Job, responses=NOT_FOUND)
    def cancel_job(job_id: str):
        """Cancel: a queued job at once; a running one stops at its next check (a plan keeps the rungs done)."""
        get_row(job_id)
        service.cancel(job_id)
        return _job_json(service, get_row(job_id))

    @app.get("/", include_in_schema=False)
    def viewer():
        """The viewer: lists jobs, submits a scenario file, follows a job, animates its plan."""
        return FileResponse(VIEWER, media_type="text/html")

    @app.get(
        "/jobs/{job_id}/scene",
        responses={**NOT_FOUND, 409: {"model": Error, "description": "the job's scenario no longer loads"}},
    )
    def get_scene(job_id: str) -> dict[str, Any]:
        """What the viewer draws: the scene's bodies with their shapes (parameters applied) and,
        for a plan job with a result, each rung's times and body placements per state."""
        row = get_row(job_id)
        result = row["result"] if row["kind"] == "plan" else None
        try:
            return scene_view(json.loads(row["inputs"]), result)
        except ScenarioError as exc:  # accepted once; only a changed planner could refuse it now
            raise HTTPException(409, f"the job's scenario no longer loads: {exc}") from None

    @app.get(
        "/jobs/{job_id}/events",
        response_class=Response,  # no media type of its own: its 200 is text/event-stream, its errors JSON
        responses={
            200: {"content": {"text/event-stream": {"schema": {"type": "string"}}}, "description": "the events, live"},
            **NOT_FOUND,
            **UNPROCESSABLE,
        },
    )
    async def events(
        job_id: str,
        request: Request,
        last_event_id: str | None = Header(None),
        token: str | None = Query(None, description="the bearer token, for clients that cannot send headers (EventSource)"),
    ):
        """Server-sent events: state, rung_started, progress, rung_ended, cancel_requested, job_ended (the last)."""
        get_row(job_id)
        try:
            after = int(last_event_id) if last_event_id else 0
        except ValueError:
            return _unprocessable(ScenarioError("request", [Problem("Last-Event-ID", "must be an event id (an integer)")]))

        async def stream():
            seq, quiet = after, 0.0
            while not service.stopping():  # (a client follows again, with Last-Event-ID, once it is back)
                rows = service.store.events_after(job_id, seq)
                for row in rows:
                    seq = row["seq"]
                    yield f"id: {seq}\nevent: {row['type']}\ndata: {row['data']}\n\n"
                    if row["type"] == "job_ended":
                        return
                if not rows:
                    job = service.store.get(job_id)
                    if job is None or (job["state"] in TERMINAL and not service.store.events_after(job_id, seq)):
                        return
                    if await request.is_disconnected():
                        return
                    await asyncio.sleep(EVENTS_POLL_S)
                    quiet += EVENTS_POLL_S
                    if quiet >= KEEPALIVE_S:
                        quiet = 0.0
                        yield ": keep-alive\n\n"

        return EventStream(stream(), headers={"Cache-Control": "no-cache"})

    return app

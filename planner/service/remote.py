"""Jobs on a Dask cluster: `ladder serve --executor dask://HOST:PORT` (the engine `ladder sweep
--executor` uses too). The service's one use of dask.distributed.

A job is one Dask task (`run_remote`) that runs it from its inputs (`worker.execute`) and needs
no access to the service's database: it reports its claim, progress and events as Dask events
on the topic TOPIC, which the server (`DaskRunner`) writes into the database, and it returns
its result with the events that must not be lost (claim, rung_started, rung_ended), which the
server writes first if their messages have not arrived, then the job's end. A cancel is a Dask
Event per job that the task reads at its stop checks. The workers need the planner installed;
a job runs in its own working directory, so one job at a time runs per worker process.
"""

from __future__ import annotations

import json
import queue
import threading
import uuid

from models.scenario import Problem, ScenarioError
from planner.service.store import TERMINAL, Store
from planner.service.worker import execute

TOPIC = "ladder-jobs"
CONNECT_TIMEOUT_S = 10
#: One job at a time per worker process: a job changes the process's working directory.
_ONE_JOB = threading.Lock()


def _cancel_event(job_id: str, client=None):
    from distributed import Event

    return Event(f"ladder-cancel-{job_id}", client=client)


class TopicSink:
    """A job's sink in a Dask task: messages on TOPIC, numbered per run; the cancel Event."""

    def __init__(self, job_id: str):
        from distributed import get_worker

        self.worker = get_worker()
        self.job_id, self.run, self.n = job_id, uuid.uuid4().hex, 0
        self.kept: list[dict] = []
        self.last: dict | None = None  # the last message sent
        self.cancel = _cancel_event(job_id)

    def send(self, type_: str, data: dict, *, keep: bool) -> None:
        self.n += 1
        message = {"job": self.job_id, "run": self.run, "n": self.n, "type": type_, "data": data}
        if keep:
            self.kept.append(message)
        self.last = message
        self.worker.log_event(TOPIC, message)

    def cancel_requested(self) -> bool:
        return self.cancel.is_set()

    def progress(self, data: dict, event: tuple[str, dict] | None = None) -> None:
        self.send("progress", {"progress": data, "event": event}, keep=event is not None and event[0] != "progress")

    def event(self, type_: str, data: dict) -> None:
        self.send("event", {"type": type_, "data": data}, keep=True)


def run_remote(job_id: str, kind: str, inputs: dict, options: dict, max_seconds: float | None) -> dict:
    """The Dask task of a job: {state, result, error, messages (the ones that must arrive)}."""
    with _ONE_JOB:
        sink = TopicSink(job_id)
        if sink.cancel_requested():  # cancelled while it waited
            return {"state": "cancelled", "result": None, "error": None, "messages": []}
        sink.send("claim", {}, keep=True)
        final, text, error = execute(kind, inputs, options, sink, max_seconds)
        return {"state": final, "result": text, "error": error, "messages": must_arrive(sink.kept, sink.last)}


def must_arrive(kept: list[dict], last: dict | None) -> list[dict]:
    """A task's messages that must reach the store before its end: the kept ones, and the last
    message sent when it is not one of them (the job's last progress, which a topic message
    could bring after the job's end, where it is dropped)."""
    if last is None or (kept and last["n"] <= kept[-1]["n"]):
        return kept
    return [*kept, last]


class DaskRunner:
    """The server's side: sends jobs to the cluster at `address` (dask://HOST:PORT) and writes
    what their tasks report into `store`. ScenarioError when the scheduler cannot be reached."""

    def __init__(self, address: str, store: Store, max_seconds: float | None):
        try:
            from distributed import Client
        except ImportError:
            raise ScenarioError(
                "ladder serve", [Problem(f"--executor {address}", 'install the dask extra: pip install "contact-ladder[dask]"')]
            ) from None
        try:
            self.client = Client(address.removeprefix("dask://"), set_as_default=False, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ScenarioError("ladder serve", [Problem(f"--executor {address}", f"cannot reach the Dask scheduler: {exc}")]) from None
        self.store, self.max_seconds = store, max_seconds
        self.lock = threading.Lock()  # one job's messages and its end are written in order
        self.applied: dict[tuple[str, str], int] = {}  # (job, run) -> the last message written
        self.futures: dict[str, object] = {}  # a future Dask forgets once nothing refers to it
        # the messages are written by a thread of their own: the handler runs on the Dask
        # client's event loop, which must neither block on SQLite nor call Dask synchronously
        self.inbox: queue.Queue = queue.Queue()
        threading.Thread(target=self._write_messages, name="ladder-dask-messages", daemon=True).start()
        self.client.subscribe_topic(TOPIC, lambda event: self.inbox.put(event[1]))

    def close(self) -> None:
        self.inbox.put(None)
        self.client.close()

    def _write_messages(self) -> None:
        while (message := self.inbox.get()) is not None:
            try:
                self._apply(message)
            except Exception:  # the store is closed: the service is stopping
                return

    def submit(self, job_id: str) -> None:
        row = self.store.get(job_id)
        future = self.client.submit(
            run_remote,
            job_id,
            row["kind"],
            json.loads(row["inputs"]),
            json.loads(row["options"]),
            self.max_seconds,
            pure=False,
            key=f"ladder-job-{job_id}-{uuid.uuid4().hex[:8]}",
        )
        self.futures[job_id] = future
        future.add_done_callback(lambda f, job_id=job_id: self._done(job_id, f))

    def cancel(self, job_id: str) -> None:
        """Ask the job's task to stop (the store already says the job is cancelled or to be)."""
        _cancel_event(job_id, self.client).set()
        future = self.futures.get(job_id)
        if future is not None and self.store.get(job_id)["state"] == "cancelled":
            future.cancel()  # not started: it need not start

    def _apply(self, message: dict) -> None:
        job_id, data = message["job"], message["data"]
        with self.lock:
            key = (job_id, message["run"])
            if message["n"] <= self.applied.get(key, 0):
                return
            self.applied[key] = message["n"]
            row = self.store.get(job_id)
            if row is None or row["state"] in TERMINAL:
                if message["type"] == "claim":
                    _cancel_event(job_id, self.client).set()  # cancelled before it started
                return
            if message["type"] == "claim":
                self.store.claim(job_id)  # queued -> running (already running: Dask started it again)
            elif message["type"] == "progress":
                self.store.set_progress(job_id, data["progress"], tuple(data["event"]) if data["event"] else None)
            elif message["type"] == "event":
                self.store.add_event(job_id, data["type"], data["data"])

    def _done(self, job_id: str, future) -> None:
        self.futures.pop(job_id, None)
        if future.cancelled():
            return  # cancelled before it started, or the service is stopping
        try:
            try:
                out = future.result()
            except Exception as exc:  # the task raised or its worker died
                self.store.finish(job_id, "failed", error=f"the Dask task failed: {type(exc).__name__}: {exc}")
                return
            for message in out["messages"]:
                self._apply(message)
            with self.lock:
                self.store.finish(job_id, out["state"], result=out["result"], error=out["error"])
                for key in [k for k in self.applied if k[0] == job_id]:
                    del self.applied[key]
        except Exception:  # the store is closed: the service is stopping (the job runs again on restart)
            pass

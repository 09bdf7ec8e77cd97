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
import sys
import threading
import uuid
from concurrent.futures import CancelledError

from models.scenario import Problem, ScenarioError
from planner.service.store import TERMINAL, Store
from planner.service.worker import execute

TOPIC = "ladder-jobs"
CONNECT_TIMEOUT_S = 10
#: Seconds between the server's checks of its connection to the scheduler (a lost one is made again).
WATCH_S = 2.0
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
    what their tasks report into `store`. ScenarioError when the scheduler cannot be reached.

    A scheduler that goes away (restarted, its machine down) loses the tasks it held: their
    jobs go back to queued, the server says so on stderr and connects again every WATCH_S s
    (each try up to CONNECT_TIMEOUT_S), meanwhile accepting jobs; once connected it sends
    every queued job again, and says so. A lost task (its scheduler gone) makes the server
    connect again even where Dask's client reconnected by itself, since that client's
    subscription to TOPIC does not survive it. `say(text)`: the server's line on stderr."""

    def __init__(self, address: str, store: Store, max_seconds: float | None, say=None):
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise ScenarioError(
                "ladder serve", [Problem(f"--executor {address}", 'install the dask extra: pip install "contact-ladder[dask]"')]
            ) from None
        self.address, self.store, self.max_seconds = address, store, max_seconds
        self.say = say or (lambda text: print(text, file=sys.stderr, flush=True))
        self.lock = threading.Lock()  # one job's messages and its end are written in order
        self.connection = threading.RLock()  # the client, and sending through it
        self.applied: dict[tuple[str, str], int] = {}  # (job, run) -> the last message written
        self.futures: dict[str, object] = {}  # a future Dask forgets once nothing refers to it
        self.futures_lock = threading.Lock()  # (never held across a call to Dask)
        self.generation = 0  # the connection's: a future of an earlier one was sent before a reconnect
        self.lost = threading.Event()  # a task was lost with its scheduler: connect again
        # the messages are written by a thread of their own: the handler runs on the Dask
        # client's event loop, which must neither block on SQLite nor call Dask synchronously
        self.inbox: queue.Queue = queue.Queue()
        try:
            self.client = self._connect()
        except (OSError, TimeoutError, ValueError) as exc:
            raise ScenarioError("ladder serve", [Problem(f"--executor {address}", f"cannot reach the Dask scheduler: {exc}")]) from None
        self.connected = True
        self.closing = threading.Event()
        threading.Thread(target=self._write_messages, name="ladder-dask-messages", daemon=True).start()
        threading.Thread(target=self._watch, name="ladder-dask-watch", daemon=True).start()

    def _connect(self):
        from distributed import Client

        client = Client(self.address.removeprefix("dask://"), set_as_default=False, timeout=CONNECT_TIMEOUT_S)
        client.subscribe_topic(TOPIC, lambda event: self.inbox.put(event[1]))
        return client

    def close(self) -> None:
        self.closing.set()
        self.lost.set()  # (wakes the watch)
        self.inbox.put(None)
        with self.connection:
            self._close_client()

    def _close_client(self) -> None:
        from planner.sweep import close_quietly

        close_quietly(self.client)

    def _watch(self) -> None:
        """A lost scheduler: its jobs queued again, and a connection made again, then every queued job sent."""
        while not self.closing.is_set():
            if self.connected:
                self.lost.wait(WATCH_S)  # (a lost task wakes it at once)
                if self.closing.is_set():
                    return
                if self.client.status == "running" and not self.lost.is_set():
                    continue
                with self.connection:
                    self.connected = False
                    self.generation += 1  # (the old client's futures, cancelled as it closes, are its: `_lost` leaves them)
                    self._close_client()  # (its futures are cancelled: `_done` queues their jobs again)
                    with self.futures_lock:
                        self.futures.clear()
                    self.lost.clear()
                self.say(
                    f"lost the Dask scheduler at {self.address}: the jobs under way are queued again and run when it is back; "
                    f"connecting again every {WATCH_S:g} s"
                )
                continue
            try:
                client = self._connect()
            except (OSError, TimeoutError, ValueError):
                self.closing.wait(WATCH_S)
                continue
            with self.connection:
                if self.closing.is_set():
                    client.close()
                    return
                self.client, self.connected = client, True
                jobs = self.store.recover()
                for job_id in jobs:
                    self.submit(job_id)
            self.say(f"connected again to the Dask scheduler at {self.address}: {len(jobs)} queued job(s) sent")

    def _write_messages(self) -> None:
        while (message := self.inbox.get()) is not None:
            try:
                self._apply(message)
            except Exception:  # the store is closed (the service is stopping), or the client (a reconnect)
                if self.closing.is_set():
                    return

    def submit(self, job_id: str) -> None:
        """Send the job to the cluster (when it is connected: else it waits queued, sent on reconnecting)."""
        with self.connection:
            with self.futures_lock:
                sent = job_id in self.futures
            if self.connected and not sent:
                self._submit(job_id)

    def _submit(self, job_id: str) -> None:
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
        with self.futures_lock:
            self.futures[job_id] = future
        future.add_done_callback(lambda f, job_id=job_id, generation=self.generation: self._done(job_id, f, generation))

    def cancel(self, job_id: str) -> None:
        """Ask the job's task to stop (the store already says the job is cancelled or to be)."""
        with self.connection:  # (the calls to Dask outside it: a scheduler that hangs holds up no submission)
            client, connected = self.client, self.connected
        if not connected:  # (queued again: the store's cancel is the whole of it)
            return
        try:
            _cancel_event(job_id, client).set()
        except Exception:  # (the scheduler went away just now: the job is queued again)
            return
        with self.futures_lock:
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
                    try:
                        _cancel_event(job_id, self.client).set()  # cancelled before it started
                    except Exception:  # (a client closed by a reconnect: the task runs its course, unheard)
                        pass
                return
            if message["type"] == "claim":
                self.store.claim(job_id)  # queued -> running (already running: Dask started it again)
            elif message["type"] == "progress":
                self.store.set_progress(job_id, data["progress"], tuple(data["event"]) if data["event"] else None)
            elif message["type"] == "event":
                self.store.add_event(job_id, data["type"], data["data"])

    def _done(self, job_id: str, future, generation: int) -> None:
        with self.futures_lock:
            if self.futures.get(job_id) is future:
                del self.futures[job_id]
        try:
            try:
                out = None if future.cancelled() else future.result()
            except (OSError, CancelledError):  # its result went with the scheduler
                out = None
            except Exception as exc:  # the task raised or its worker died
                self.store.finish(job_id, "failed", error=f"the Dask task failed: {type(exc).__name__}: {exc}")
                return
            if out is None:
                self._lost(job_id, generation)
                return
            for message in out["messages"]:
                self._apply(message)
            with self.lock:
                self.store.finish(job_id, out["state"], result=out["result"], error=out["error"])
                for key in [k for k in self.applied if k[0] == job_id]:
                    del self.applied[key]
        except Exception:  # the store is closed: the service is stopping (the job runs again on restart)
            pass

    def _lost(self, job_id: str, generation: int) -> None:
        """A task cancelled or its result lost: its job queued again where its scheduler went away
        (not where its user cancelled it, or the service is stopping: it runs again on restart;
        nor where a reconnect since has queued and sent it again), and the server connects again."""
        if self.closing.is_set() or generation != self.generation:
            return
        row = self.store.get(job_id)
        if row is None or row["state"] in TERMINAL:
            return
        self.store.requeue(job_id)
        self.lost.set()

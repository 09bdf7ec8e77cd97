"""What a worker does with one job: run it from its inputs, reporting progress and events to a
sink and checking it for a cancel. A local worker process (`run_job`) reports straight into the
database (its own connection); a Dask task (planner.service.remote) reports through Dask to the
server, which writes them. Both run `execute`."""

from __future__ import annotations

import json
import os
import signal
import time
from collections.abc import Callable
from typing import Protocol

from models.scenario import ScenarioError
from planner.service import jobs
from planner.service.store import Store

#: Seconds between progress writes (and between checks whether the job was cancelled).
PROGRESS_EVERY = 0.5
CANCEL_EVERY = 0.25


class Sink(Protocol):
    """Where a running job's progress and events go, and whether it was asked to stop."""

    def cancel_requested(self) -> bool: ...

    def progress(self, data: dict, event: tuple[str, dict] | None = None) -> None: ...

    def event(self, type_: str, data: dict) -> None: ...


class StoreSink:
    """A job's sink in the service's database (a local worker process)."""

    def __init__(self, store: Store, job_id: str):
        self.store, self.job_id = store, job_id

    def cancel_requested(self) -> bool:
        return self.store.cancel_requested(self.job_id)

    def progress(self, data: dict, event: tuple[str, dict] | None = None) -> None:
        self.store.set_progress(self.job_id, data, event)

    def event(self, type_: str, data: dict) -> None:
        self.store.add_event(self.job_id, type_, data)


def execute(
    kind: str, inputs: dict, options: dict, sink: Sink, max_seconds: float | None = None, *, check: Callable[[], None] | None = None
) -> tuple[str, str | None, str | None]:
    """Run a job: (its final state, the result file's text or None, its error or None).
    `check()` runs at every stop check (a local worker exits there when the server died).
    `max_seconds` leaves out the time spent compiling kernels (a first job on a cold cache
    compiles for minutes; a worker's first job had also failed a limit of 4 s loading them)."""
    from planner import interrupt

    interrupt.watch_compiles()
    deadline = None if max_seconds is None else time.monotonic() + max_seconds - interrupt.compile_seconds()
    state = {"cancel": False, "timeout": False, "checked": 0.0, "written": 0.0, "pending": None}

    def stop() -> bool:
        if check is not None:
            check()
        now = time.monotonic()
        if deadline is not None and now - interrupt.compile_seconds() > deadline:
            state["timeout"] = True
        if now - state["checked"] >= CANCEL_EVERY:
            state["checked"] = now
            state["cancel"] = sink.cancel_requested()
        return state["cancel"] or state["timeout"]

    def report(data: dict, event: tuple[str, dict], now_too: bool) -> None:
        """Progress written at most every PROGRESS_EVERY s (at once when `now_too`); the latest held back is kept."""
        now = time.monotonic()
        if now_too or now - state["written"] >= PROGRESS_EVERY:
            sink.progress(data, event)
            state["written"], state["pending"] = now, None
        else:
            state["pending"] = data

    def progress(rung: str, iterations: int, propagations: int) -> None:
        data = {"rung": rung, "iterations": iterations, "propagations": propagations}
        started = iterations == 0 and propagations == 0
        report(data, ("rung_started", {"rung": rung}) if started else ("progress", data), started)

    def rung_done(report) -> None:
        state["pending"] = None  # (its progress held back is superseded by its end)
        sink.event("rung_ended", jobs.rung_view(report))

    def job_progress(data: dict) -> None:  # (a sweep's runs or refinement step, a simulation's steps)
        last = data["steps_done"] == data["steps"] if "steps" in data else data.get("runs_done") == data.get("runs")
        report(data, ("progress", data), last)

    try:
        text, complete = jobs.run(kind, inputs, options, progress=progress, rung_done=rung_done, job_progress=job_progress, stop=stop)
        # the last progress the throttle held back (a cancelled sweep's had said 10 runs where its result kept 11)
        if state["pending"] is not None:
            sink.progress(state["pending"], ("progress", state["pending"]))
    except ScenarioError as exc:
        return "failed", None, str(exc)
    except Exception as exc:  # a bug, reported on the job rather than lost
        return "failed", None, f"internal error: {type(exc).__name__}: {exc}"
    if complete:
        return "succeeded", text, None
    if state["timeout"] and not state["cancel"]:
        kept = "what was done is in the result" if text is not None else "before it had a result"
        return "failed", text, f"stopped at the wall-time limit of {max_seconds:g} s ({kept})"
    return "cancelled", text, None


def ignore_stop_signals() -> None:
    """A local worker process's start: Ctrl-C in the server's terminal (SIGINT), or a service
    manager's stop (SIGTERM to every process of the service: systemd, docker stop), reaches the
    workers too, and the server alone answers it: it kills its workers (SIGKILL), leaving a job
    under way `running`, to run again on restart. A worker that took the signal itself would
    fail its job before the server stopped it (and print a traceback on SIGINT). It then
    imports what a job runs (about 1.3 s), which a first job's wall-time limit had counted."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    import models.rollout  # noqa: F401
    import planner.cli  # noqa: F401
    import planner.ladder  # noqa: F401


def run_job(db_path: str, job_id: str, max_seconds: float | None = None) -> str | None:
    """Run the job if it is still queued (a local worker process); its final state (None when
    it was not queued)."""
    store = Store(db_path)
    try:
        if not store.claim(job_id):
            return None
        row = store.get(job_id)
        parent = os.getppid()

        def check() -> None:
            if os.getppid() != parent:  # the server died (kill -9): the job stays running and is run again on restart
                os._exit(0)

        final, text, error = execute(
            row["kind"], json.loads(row["inputs"]), json.loads(row["options"]), StoreSink(store, job_id), max_seconds, check=check
        )
        store.finish(job_id, final, result=text, error=error)
        return final
    finally:
        store.close()

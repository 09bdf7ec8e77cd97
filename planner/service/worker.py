"""What a worker process does: run one job from its stored inputs, writing its progress,
events and result into the database itself (its own connection)."""

from __future__ import annotations

import os
import time

from models.scenario import ScenarioError
from planner.service import jobs
from planner.service.store import Store

#: Seconds between progress writes (and between checks whether the job was cancelled).
PROGRESS_EVERY = 0.5
CANCEL_EVERY = 0.25


def run_job(db_path: str, job_id: str, max_seconds: float | None = None) -> str | None:
    """Run the job if it is still queued; its final state (None when it was not queued)."""
    import json

    store = Store(db_path)
    try:
        if not store.claim(job_id):
            return None
        row = store.get(job_id)
        inputs, options = json.loads(row["inputs"]), json.loads(row["options"])
        deadline = None if max_seconds is None else time.monotonic() + max_seconds
        state = {"cancel": False, "timeout": False, "checked": 0.0, "written": 0.0}
        parent = os.getppid()

        def stop() -> bool:
            if os.getppid() != parent:  # the server died (kill -9): the job stays running and is run again on restart
                os._exit(0)
            now = time.monotonic()
            if deadline is not None and now > deadline:
                state["timeout"] = True
            if now - state["checked"] >= CANCEL_EVERY:
                state["checked"] = now
                state["cancel"] = store.cancel_requested(job_id)
            return state["cancel"] or state["timeout"]

        def progress(rung: str, iterations: int, propagations: int) -> None:
            now = time.monotonic()
            data = {"rung": rung, "iterations": iterations, "propagations": propagations}
            if iterations == 0 and propagations == 0:
                store.set_progress(job_id, data, ("rung_started", {"rung": rung}))
                state["written"] = now
            elif now - state["written"] >= PROGRESS_EVERY:
                store.set_progress(job_id, data, ("progress", data))
                state["written"] = now

        def rung_done(report) -> None:
            store.add_event(job_id, "rung_ended", jobs.rung_view(report))

        def sweep_progress(data: dict) -> None:
            now = time.monotonic()
            if now - state["written"] >= PROGRESS_EVERY or data.get("runs_done") == data.get("runs"):
                store.set_progress(job_id, data, ("progress", data))
                state["written"] = now

        try:
            text, complete = jobs.run(
                row["kind"], inputs, options, progress=progress, rung_done=rung_done, sweep_progress=sweep_progress, stop=stop
            )
        except ScenarioError as exc:
            store.finish(job_id, "failed", error=str(exc))
            return "failed"
        except Exception as exc:  # a bug, reported on the job rather than lost
            store.finish(job_id, "failed", error=f"internal error: {type(exc).__name__}: {exc}")
            return "failed"
        if complete:
            final = "succeeded"
            error = None
        elif state["timeout"] and not state["cancel"]:
            final, error = "failed", f"stopped at the wall-time limit of {max_seconds:g} s (the rungs done are in the result)"
        else:
            final, error = "cancelled", None
        store.finish(job_id, final, result=text, error=error)
        return final
    finally:
        store.close()

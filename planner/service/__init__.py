"""The planning service: `ladder serve` (HTTP API over the same planner the CLI runs).

Jobs, their inputs, events and results live in SQLite (`planner.service.store`); worker
processes run them (`planner.service.worker`); `planner.service.app` is the FastAPI app.
Only `create_app` needs FastAPI; the store and the worker need nothing beyond the planner.
"""

from __future__ import annotations


def create_app(*args, **kwargs):
    """The FastAPI app (see `planner.service.app.create_app`); imports FastAPI lazily."""
    from planner.service.app import create_app as _create_app

    return _create_app(*args, **kwargs)

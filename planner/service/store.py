"""SQLite persistence of the service's jobs and their events (WAL mode, stdlib sqlite3).

A job row holds everything needed to run it again (the scenario's TOML text, the files it
names, parameters and options), so a job found queued or running at startup (the server died)
is run again from its inputs: plans are deterministic per seed. Events are numbered per job
(1, 2, ...): the SSE stream's ids, so a client resumes with Last-Event-ID.

The server and each worker process open their own connection; writers are serialised by
SQLite (`BEGIN IMMEDIATE`, a busy timeout).
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

STATES = ("queued", "running", "succeeded", "failed", "cancelled")
TERMINAL = ("succeeded", "failed", "cancelled")

SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    state TEXT NOT NULL,
    inputs TEXT NOT NULL,            -- JSON: filename, scenario (TOML text), files, parameters
    options TEXT NOT NULL,           -- JSON
    created REAL NOT NULL,
    updated REAL NOT NULL,
    idempotency_key TEXT UNIQUE,
    request_sha256 TEXT,
    progress TEXT,                   -- JSON: rung, iterations, propagations
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    runs INTEGER NOT NULL DEFAULT 0, -- times a worker started it (more than 1 after a restart)
    result TEXT,                     -- the result file's text (plan.json / simulate JSON)
    error TEXT
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs (state, created);
CREATE TABLE IF NOT EXISTS events (
    job_id TEXT NOT NULL,
    seq INTEGER NOT NULL,
    type TEXT NOT NULL,
    data TEXT NOT NULL,              -- JSON
    created REAL NOT NULL,
    PRIMARY KEY (job_id, seq)
);
"""


def iso(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _schema_columns() -> dict[str, set[str]]:
    """The columns SCHEMA gives each of its tables (read from SQLite, not written twice)."""
    memory = sqlite3.connect(":memory:")
    try:
        memory.executescript(SCHEMA)
        tables = [name for (name,) in memory.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
        return {table: {row[1] for row in memory.execute(f"PRAGMA table_info({table})")} for table in tables}
    finally:
        memory.close()


class Store:
    """One connection to the service's database; safe to share between threads (a lock).
    sqlite3.DatabaseError where the file is not a database, or is one whose tables are not the
    jobs' (another program's, or a version without some column): nothing is written to it."""

    def __init__(self, path: str | Path):
        self.path = str(path)
        self.conn = sqlite3.connect(self.path, timeout=30, isolation_level=None, check_same_thread=False)
        self.conn.row_factory = sqlite3.Row
        self.lock = threading.RLock()
        try:
            with self.lock:
                self._check_tables()
                self.conn.execute("PRAGMA journal_mode=WAL")
                self.conn.execute("PRAGMA synchronous=NORMAL")
                self.conn.execute("PRAGMA busy_timeout=30000")
                self.conn.executescript(SCHEMA)
        except BaseException:
            self.conn.close()
            raise

    def _check_tables(self) -> None:
        """The database is empty, or has SCHEMA's tables with their columns (reading it: a file
        that is not a database fails here, before any write; another program's is not written)."""
        expected = _schema_columns()
        tables = {name for (name,) in self.conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if tables and not tables & expected.keys():
            shown = ", ".join(sorted(tables)[:5]) + (", ..." if len(tables) > 5 else "")
            raise sqlite3.DatabaseError(f"it holds other tables: {shown}")
        for table, columns in expected.items():
            have = {row[1] for row in self.conn.execute(f"PRAGMA table_info({table})")}
            missing = sorted(columns - have)
            if have and missing:
                raise sqlite3.DatabaseError(f"its {table} table has no column {', '.join(missing)}")

    def close(self) -> None:
        with self.lock:
            self.conn.close()

    # ------------------------------------------------------------------ transactions

    def _write(self, fn):
        """Run fn(conn) in one write transaction."""
        with self.lock:
            self.conn.execute("BEGIN IMMEDIATE")
            try:
                value = fn(self.conn)
            except BaseException:
                self.conn.execute("ROLLBACK")
                raise
            self.conn.execute("COMMIT")
            return value

    @staticmethod
    def _event(conn, job_id: str, type_: str, data: dict) -> int:
        (seq,) = conn.execute("SELECT COALESCE(MAX(seq), 0) + 1 FROM events WHERE job_id = ?", (job_id,)).fetchone()
        conn.execute(
            "INSERT INTO events (job_id, seq, type, data, created) VALUES (?, ?, ?, ?, ?)",
            (job_id, seq, type_, json.dumps(data), time.time()),
        )
        return seq

    # ------------------------------------------------------------------ jobs

    def create_job(
        self, job_id: str, kind: str, inputs: dict, options: dict, *, key: str | None, sha: str, max_queued: int | None
    ) -> tuple[sqlite3.Row | None, str]:
        """Insert a queued job: (row, "created"); the job of an Idempotency-Key seen before:
        (row, "existing"), or (row, "conflict") when that key came with another request;
        (None, "full") when `max_queued` jobs are queued already."""

        def fn(conn):
            if key is not None:
                row = conn.execute("SELECT * FROM jobs WHERE idempotency_key = ?", (key,)).fetchone()
                if row is not None:
                    return row, ("existing" if row["request_sha256"] == sha else "conflict")
            if max_queued is not None:
                (queued,) = conn.execute("SELECT COUNT(*) FROM jobs WHERE state = 'queued'").fetchone()
                if queued >= max_queued:
                    return None, "full"
            now = time.time()
            conn.execute(
                "INSERT INTO jobs (id, kind, state, inputs, options, created, updated, idempotency_key, request_sha256) "
                "VALUES (?, ?, 'queued', ?, ?, ?, ?, ?, ?)",
                (job_id, kind, json.dumps(inputs), json.dumps(options), now, now, key, sha),
            )
            self._event(conn, job_id, "state", {"state": "queued"})
            return conn.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone(), "created"

        return self._write(fn)

    def get(self, job_id: str) -> sqlite3.Row | None:
        with self.lock:
            return self.conn.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()

    def list(self, state: str | None = None) -> list[sqlite3.Row]:
        with self.lock:
            if state is None:
                return self.conn.execute("SELECT * FROM jobs ORDER BY created, rowid").fetchall()
            return self.conn.execute("SELECT * FROM jobs WHERE state = ? ORDER BY created, rowid", (state,)).fetchall()

    def claim(self, job_id: str) -> bool:
        """queued -> running (a worker starts it); False when it is not queued (cancelled)."""

        def fn(conn):
            cur = conn.execute(
                "UPDATE jobs SET state = 'running', runs = runs + 1, progress = NULL, updated = ? WHERE id = ? AND state = 'queued'",
                (time.time(), job_id),
            )
            if cur.rowcount:
                self._event(conn, job_id, "state", {"state": "running"})
            return bool(cur.rowcount)

        return self._write(fn)

    def finish(self, job_id: str, state: str, *, result: str | None = None, error: str | None = None) -> bool:
        """running (or queued) -> a terminal state, with the job-ended event, in one transaction."""

        def fn(conn):
            cur = conn.execute(
                "UPDATE jobs SET state = ?, result = ?, error = ?, updated = ? WHERE id = ? AND state IN ('queued', 'running')",
                (state, result, error, time.time(), job_id),
            )
            if cur.rowcount:
                self._event(conn, job_id, "job_ended", {"state": state, "error": error})
            return bool(cur.rowcount)

        return self._write(fn)

    def cancel(self, job_id: str) -> str | None:
        """DELETE /jobs/{id}: a queued job is cancelled at once, a running one is asked to stop
        (its worker ends it); the job's state after that, None when there is no such job."""

        def fn(conn):
            row = conn.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                return None
            if row["state"] == "queued":
                conn.execute("UPDATE jobs SET state = 'cancelled', cancel_requested = 1, updated = ? WHERE id = ?", (time.time(), job_id))
                self._event(conn, job_id, "job_ended", {"state": "cancelled", "error": None})
                return "cancelled"
            if row["state"] == "running":
                conn.execute("UPDATE jobs SET cancel_requested = 1, updated = ? WHERE id = ?", (time.time(), job_id))
                self._event(conn, job_id, "cancel_requested", {})
            return row["state"]

        return self._write(fn)

    def cancel_requested(self, job_id: str) -> bool:
        with self.lock:
            row = self.conn.execute("SELECT cancel_requested FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return bool(row and row["cancel_requested"])

    def set_progress(self, job_id: str, progress: dict, event: tuple[str, dict] | None = None) -> None:
        def fn(conn):
            conn.execute("UPDATE jobs SET progress = ?, updated = ? WHERE id = ?", (json.dumps(progress), time.time(), job_id))
            if event is not None:
                self._event(conn, job_id, *event)

        self._write(fn)

    def add_event(self, job_id: str, type_: str, data: dict) -> int:
        return self._write(lambda conn: self._event(conn, job_id, type_, data))

    def events_after(self, job_id: str, seq: int) -> list[sqlite3.Row]:
        with self.lock:
            return self.conn.execute("SELECT * FROM events WHERE job_id = ? AND seq > ? ORDER BY seq", (job_id, seq)).fetchall()

    def rung_reports(self, job_id: str) -> list[dict[str, Any]]:
        """The per-rung reports of the job's latest run, as its rungs finished."""
        with self.lock:
            rows = self.conn.execute(
                "SELECT type, data FROM events WHERE job_id = ? AND type IN ('rung_ended', 'state') ORDER BY seq", (job_id,)
            ).fetchall()
        reports: list[dict] = []
        for row in rows:
            data = json.loads(row["data"])
            if row["type"] == "state" and data.get("state") == "running":
                reports = []  # a new run (after a restart) starts the list again
            elif row["type"] == "rung_ended":
                reports.append(data)
        return reports

    @classmethod
    def _requeue(cls, conn, job_id: str) -> None:
        conn.execute("UPDATE jobs SET state = 'queued', progress = NULL, updated = ? WHERE id = ?", (time.time(), job_id))
        cls._event(conn, job_id, "state", {"state": "queued", "requeued": True})

    def requeue(self, job_id: str) -> bool:
        """running -> queued, to run again from its inputs (its run was lost, not ended: a Dask
        scheduler that went away); False when it is not running."""

        def fn(conn):
            row = conn.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None or row["state"] != "running":
                return False
            self._requeue(conn, job_id)
            return True

        return self._write(fn)

    def recover(self) -> list[str]:
        """At startup: jobs left running (the server died) go back to queued; the queued jobs'
        ids, oldest first, to run again from their inputs."""

        def fn(conn):
            for row in conn.execute("SELECT id FROM jobs WHERE state = 'running'").fetchall():
                self._requeue(conn, row["id"])
            cancelled = conn.execute("SELECT id FROM jobs WHERE state = 'queued' AND cancel_requested = 1").fetchall()
            for row in cancelled:  # asked to stop before the server died: it is cancelled, not run again
                conn.execute("UPDATE jobs SET state = 'cancelled', updated = ? WHERE id = ?", (time.time(), row["id"]))
                self._event(conn, row["id"], "job_ended", {"state": "cancelled", "error": None})
            return [r["id"] for r in conn.execute("SELECT id FROM jobs WHERE state = 'queued' ORDER BY created, rowid").fetchall()]

        return self._write(fn)

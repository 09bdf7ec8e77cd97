"""The service against its own OpenAPI description, property-based (schemathesis, in process
over ASGI): generated requests, valid and not, to every route; no answer is a 500, every
answer's status, headers and body are the ones the description gives, bad requests are 4xx.

One check is left out: `positive_data_acceptance` (a request the schema allows must succeed)
cannot hold here, since the schema says `scenario` is a string and only the scenario loader
knows which strings are scenarios (the others are 422 with the loader's problems)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

schemathesis = pytest.importorskip("schemathesis")  # the test extra; CI installs it

from fastapi.testclient import TestClient  # noqa: E402
from hypothesis import HealthCheck, settings  # noqa: E402
from schemathesis.specs.openapi.checks import positive_data_acceptance  # noqa: E402

from planner.service import create_app  # noqa: E402
from tests.conftest import SCENARIOS  # noqa: E402

#: Examples per route: enough to reach each route's answers, bounded so the file runs in seconds.
EXAMPLES = 40


def _app():
    """The app on a fresh database (removed at exit), with a cancelled job to be found by id."""
    app = create_app(Path(_FOLDER.name) / "jobs.sqlite", workers=0, max_queued=10_000)
    client = TestClient(app)
    job = client.post("/jobs", json={"kind": "plan", "scenario": (SCENARIOS / "free_transfer.toml").read_text()}).json()
    client.delete(f"/jobs/{job['id']}")
    return app


_FOLDER = tempfile.TemporaryDirectory(prefix="ladder-schema-")
schema = schemathesis.openapi.from_asgi("/openapi.json", _app())


@schema.parametrize()
@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
def test_the_api_answers_as_its_description_says(case):
    case.call_and_validate(excluded_checks=[positive_data_acceptance])

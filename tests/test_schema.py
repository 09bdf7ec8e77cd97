"""The JSON Schema for editors: committed copy in sync, shipped files valid against it."""

from __future__ import annotations

import json
import tomllib

import jsonschema
import pytest

from models.schema import json_schema
from tests.conftest import DATA, SCENARIOS

SCHEMA_FILE = SCENARIOS / "scenario.schema.json"


def test_committed_schema_is_current():
    assert json.loads(SCHEMA_FILE.read_text()) == json_schema(), "run `make schema` and commit the result"


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.toml")) + [DATA / "good" / "minimal_triangle.toml"], ids=lambda p: p.stem)
def test_scenarios_validate_against_the_schema(path):
    jsonschema.validate(tomllib.loads(path.read_text()), json_schema())


@pytest.mark.parametrize("name", ["unknown_key", "wrong_type", "missing_number", "bad_predicate", "unknown_rung"])
def test_schema_rejects_structural_mistakes(name):
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(tomllib.loads((DATA / "bad" / f"{name}.toml").read_text()), json_schema())

"""The JSON Schema of the scenario format: a valid draft 2020-12 schema that every bundled scenario meets
and malformed ones do not."""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

import pytest
from saved_runs import SCENARIOS

from mpcform.scenario.json_schema import DRAFT, scenario_json_schema
from mpcform.scenario.schema import SCHEMA

jsonschema = pytest.importorskip("jsonschema")
BUNDLED = sorted(SCENARIOS.glob("*.toml"))


@pytest.fixture(scope="module")
def validator() -> Any:
    schema = scenario_json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def load(path: Path) -> dict[str, Any]:
    return tomllib.loads(path.read_text())


def test_the_schema_covers_every_table_and_key() -> None:
    schema = scenario_json_schema()
    assert schema["$schema"] == DRAFT and schema["additionalProperties"] is False
    assert {"version", "dim", "template", "initial", "reference", "controller", "simulation"} <= set(
        schema["required"]
    )
    for table in SCHEMA:
        node = schema if not table.name else schema["$defs"][table.name.replace(".", "_")]
        props = node["properties"]
        assert {k.name for k in table.keys} <= set(props), table.name
    rate = schema["$defs"]["reference"]["properties"]["rate"]
    assert rate["type"] == "number" and rate["exclusiveMinimum"] == 0 and "[1/s]" in rate["description"]
    assert schema["$defs"]["controller"]["properties"]["kind"]["enum"][0] == "proportional"


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.stem)
def test_every_bundled_scenario_meets_the_schema(validator: Any, path: Path) -> None:
    assert [e.message for e in validator.iter_errors(load(path))] == []


def _set(data: dict[str, Any], dotted: str, value: Any) -> dict[str, Any]:
    out = copy.deepcopy(data)
    *tables, key = dotted.split(".")
    node = out
    for t in tables:
        node = node[t]
    node[key] = value
    return out


@pytest.mark.parametrize(
    ("dotted", "value", "fragment"),
    [
        ("controller.gian", 2.0, "'gian' was unexpected"),  # unknown key
        ("limit", {"v_max": 1.0}, "'limit' was unexpected"),  # unknown table
        ("controller.gain", "fast", "is not of type 'number'"),
        ("reference.scale", -2.0, "less than or equal to the minimum of 0"),
        ("controller.kind", "pid", "is not one of"),
        ("template.spacing", 1.0, "False schema does not allow"),  # a key of another shape
        ("version", 2, "is not one of [1]"),
        ("name", "my run", "does not match"),
        ("name", "..", "does not match"),
        ("name", "a" * 101, "is too long"),
        ("simulation.dt", 1e-300, "less than the minimum of 1e-06"),
    ],
)
def test_malformed_scenarios_fail(validator: Any, dotted: str, value: Any, fragment: str) -> None:
    data = _set(load(SCENARIOS / "worked_example.toml"), dotted, value)
    messages = [e.message for e in validator.iter_errors(data)]
    assert any(fragment in m for m in messages), messages


def test_a_missing_required_key_of_a_variant_fails(validator: Any) -> None:
    data = load(SCENARIOS / "worked_example.toml")
    del data["reference"]["rate"]  # required by kind = "exponential"
    assert any("'rate' is a required property" in e.message for e in validator.iter_errors(data))
    del data["simulation"]
    assert any("'simulation' is a required property" in e.message for e in validator.iter_errors(data))

"""Key parsing: one table's keys checked against the schema, defaults filled, errors naming the key."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.errors import ScenarioError, ValidationError
from mpcform.scenario.parse import as_scenario_error, field_name, parse_keys, parse_table, parse_top_level
from mpcform.scenario.schema import TABLES


def test_parse_keys_converts_and_fills_defaults() -> None:
    values = parse_keys(TABLES["graph"], {"kind": "disk", "radius": 2}, "graph", 2, 4)
    assert values["radius"] == 2.0 and isinstance(values["radius"], float)
    assert values["on"] == "template" and values["delay_steps"] == 0
    assert values["k"] is None and values["edges"] is None  # keys of other kinds: unset


def test_parse_keys_reads_vectors_points_and_pairs() -> None:
    explicit = {"shape": "explicit", "offsets": [[1, 0], [-1, 0]]}
    offsets = parse_keys(TABLES["template"], explicit, "template", 2, None)
    np.testing.assert_array_equal(offsets["offsets"], [[1.0, 0.0], [-1.0, 0.0]])
    edges = parse_keys(TABLES["graph"], {"kind": "explicit", "edges": [[0, 1], [1, 2]]}, "graph", 2, 3)
    assert edges["edges"] == ((0, 1), (1, 2))
    with pytest.raises(ScenarioError, match="expected a list of 3 numbers") as err:
        parse_keys(TABLES["obstacles"], {"center": [0, 0], "radius": 1}, "obstacles[2]", 3, None)
    assert err.value.field == "obstacles[2].center"


@pytest.mark.parametrize(
    ("raw", "field", "fragment"),
    [
        ({"kind": "ring", "radius": 1.0}, "graph.radius", "does not apply to kind = 'ring'"),
        ({"radius": 1.0}, "graph.kind", "missing required key"),
        ({"kind": "disk"}, "graph.radius", "missing required key"),
        ({"kind": "ring", "delay": 1}, "graph.delay", "did you mean 'delay_steps'"),
        ({"kind": "ring", "delay_steps": -1}, "graph.delay_steps", "expected an integer >= 0, got -1"),
    ],
)
def test_parse_keys_errors_name_the_key(raw: dict[str, object], field: str, fragment: str) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_keys(TABLES["graph"], raw, "graph", 2, 3)
    assert err.value.field == field and fragment in str(err.value)


def test_parse_table_and_top_level() -> None:
    assert parse_table({}, "limits", 2)["v_max"] is None  # an optional table may be absent
    with pytest.raises(ScenarioError, match=r"missing table \[simulation\]"):
        parse_table({}, "simulation", 2)
    top = parse_top_level({"version": 1, "dim": 3, "simulation": {}})
    assert top == {"version": 1, "name": None, "dim": 3, "seed": 0}
    with pytest.raises(ScenarioError, match="unknown table; did you mean 'limits'") as err:
        parse_top_level({"version": 1, "dim": 2, "limit": {"v_max": 1.0}})
    assert err.value.field == "limit"


def test_as_scenario_error_names_the_scenario_key() -> None:
    with pytest.raises(ScenarioError) as err, as_scenario_error("limits"):
        raise ValidationError("Limits.v_max", "expected a number > 0")
    assert err.value.field == "limits.v_max" and str(err.value) == "limits.v_max: expected a number > 0"
    with pytest.raises(ScenarioError) as err, as_scenario_error("limits"):
        raise ValidationError("speed", "not a key of [limits]")
    assert err.value.field == "speed"
    assert field_name("controller", "gain") == "controller.gain" and field_name("", "dim") == "dim"

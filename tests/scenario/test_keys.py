"""The key reference: the committed copy in scenarios/README.md matches the schema, every key is in it."""

from __future__ import annotations

from saved_runs import SCENARIOS

from mpcform.scenario.keys import key_reference_markdown
from mpcform.scenario.schema import SCHEMA


def test_committed_key_reference_matches_the_schema() -> None:
    text = (SCENARIOS / "README.md").read_text()
    committed = text.split("<!-- keys:start -->\n", 1)[1].split("<!-- keys:end -->", 1)[0]
    assert committed == key_reference_markdown(), "regenerate with `mpcform keys`"


def test_every_key_is_in_the_reference() -> None:
    reference = key_reference_markdown()
    for table in SCHEMA:
        assert f"### {table.title}\n" in reference
        for key in table.keys:
            assert f"`{key.name}`" in reference, (table.name, key.name)


def test_a_row_gives_type_bound_default_unit_and_when() -> None:
    row = (
        "| `rate` | float > 0 | required | 1/s | Convergence rate lambda of eq. 16. "
        "Only with `kind` = `exponential`. |"
    )
    assert row in key_reference_markdown().splitlines()

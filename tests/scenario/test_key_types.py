"""The schema's vocabulary: key bounds, table titles and lookups, and the message helpers."""

from __future__ import annotations

import pytest

from mpcform.scenario.key_types import Key, Table, did_you_mean, listing


@pytest.mark.parametrize(
    ("bound", "text", "inside", "outside"),
    [("> 0", " > 0", 1e-9, 0.0), (">= 1", " >= 1", 1.0, 0.999), ("", "", -1e9, None)],
)
def test_key_bounds(bound: str, text: str, inside: float, outside: float | None) -> None:
    key = Key("x", "float", "A number.", bound=bound)
    assert key.bound_text == text and key.within_bound(inside)
    assert outside is None or not key.within_bound(outside)


def test_listing_and_did_you_mean() -> None:
    assert listing(("a", 2)) == "'a', '2'" and listing((2, 3), "") == "2, 3"
    assert did_you_mean("trackng", ("proportional", "tracking")) == "; did you mean 'tracking'?"
    assert did_you_mean("zzz", ("proportional", "tracking")) == ""


def test_a_table_finds_its_keys_and_titles_itself() -> None:
    keys = (
        Key("kind", "string", "Kind.", required=True, choices=("a", "b")),
        Key("x", "int", "X.", when=("a",)),
    )
    table = Table("outer.inner", "Nested.", keys, required=False, selector="kind")
    assert table.key("x") is keys[1] and table.title == "[outer.inner]"
    assert Table("items", "Array.", keys, array=True).title == "[[items]]"
    assert Table("", "Top.", keys).title == "Top level"

"""The key schema: every key documented, every MPC setting reachable, bounds, listings and hints."""

from __future__ import annotations

import dataclasses

from mpcform import MPCSettings
from mpcform.scenario.mpc_keys import DEPRECATED, MPC_FIELDS
from mpcform.scenario.schema import SCHEMA, TABLES


def test_every_key_is_documented_and_every_mpc_setting_has_a_key() -> None:
    for table in SCHEMA:
        for key in table.keys:
            assert key.doc and key.type, (table.name, key.name)
    keys = TABLES["controller"].keys
    mpc_keys = {k.name for k in keys if ("mpc" in k.when or not k.when) and k.name not in DEPRECATED}
    settings = {MPC_FIELDS.get(k, k) for k in mpc_keys} - {"kind"}
    assert settings == {f.name for f in dataclasses.fields(MPCSettings)}


def test_tables_are_found_by_name_and_selectors_are_keys() -> None:
    assert list(TABLES) == [t.name for t in SCHEMA] and TABLES[""].title == "Top level"
    assert TABLES["obstacles"].title == "[[obstacles]]" and TABLES["limits"].title == "[limits]"
    for table in SCHEMA:
        if table.selector is not None:
            assert table.key(table.selector).choices, table.name

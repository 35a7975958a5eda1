"""The mpc keys and the solve table: defaults stated once (the strategies' own), every old key has
its new place, and each key of the solve table applies to the kinds that read it."""

from __future__ import annotations

import dataclasses

from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.strategy import SOLVE_KINDS, PerDroneSolve, SparseSolve
from mpcform.scenario.mpc_keys import DEPRECATED, MPC_FIELDS, MPC_KEYS, SOLVE_TABLE
from mpcform.scenario.schema import TABLES


def test_the_solve_tables_defaults_are_the_strategies() -> None:
    sparse, per_drone = SparseSolve(), PerDroneSolve()
    key = SOLVE_TABLE.key
    assert key("kind").choices == SOLVE_KINDS and key("kind").required
    assert (key("eps_abs").default, key("eps_rel").default) == (
        sparse.options.eps_abs,
        sparse.options.eps_rel,
    )
    assert key("time_limit").default == sparse.options.time_limit_s
    assert key("max_iter").default == per_drone.max_iter == sparse.options.max_iter
    assert key("split_iterations").default == per_drone.split.iterations
    assert key("stalled_split").default == per_drone.split.stalled
    assert key("split_budget").default is per_drone.split.budget_s is None


def test_each_solve_key_applies_to_the_kinds_that_read_it() -> None:
    kinds = {k.name: set(k.when or SOLVE_KINDS) for k in SOLVE_TABLE.keys if k.name != "kind"}
    assert kinds == {
        "backend": {"sparse", "per_drone"},
        "max_iter": {"sparse", "per_drone"},
        "eps_abs": {"sparse"},
        "eps_rel": {"sparse"},
        "time_limit": {"sparse"},
        "split_iterations": {"per_drone"},
        "stalled_split": {"per_drone"},
        "split_budget": {"per_drone"},
    }


def test_every_old_key_is_deprecated_towards_a_solve_key() -> None:
    controller = {k.name: k for k in TABLES["controller"].keys}
    for old, new in DEPRECATED.items():
        assert (
            controller[old].doc.startswith("Deprecated: `[controller.solve]`")
            and controller[old].default is None
        )
        assert new == "kind" or SOLVE_TABLE.key(new)
    assert SOLVE_TABLE in TABLES.values() and set(MPC_KEYS) <= set(controller.values())


def test_mpc_keys_default_to_the_settings_fields() -> None:
    defaults = {f.name: f.default for f in dataclasses.fields(MPCSettings)}
    for key in MPC_KEYS:
        if key.name not in DEPRECATED and key.name != "solve":
            assert key.default == defaults[MPC_FIELDS.get(key.name, key.name)], key.name

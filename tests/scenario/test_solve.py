"""The solve strategy of a ``[controller]`` table: the coupling's default, the solve table, the
last release's keys with one deprecation line each, and every combination the planner would ignore
refused with the key as written."""

from __future__ import annotations

from typing import Any

import pytest

from mpcform.errors import ScenarioError
from mpcform.mpc.strategy import PerDroneSolve, SparseSolve, SplitPolicy
from mpcform.scenario.solve import solve_strategy
from mpcform.solvers.base import SolverOptions


def strategy(coupling: str = "joint", **controller: Any) -> tuple[Any, list[str]]:
    lines: list[str] = []
    return solve_strategy(controller, coupling, lines), lines


def test_no_table_and_no_old_key_takes_the_couplings_default() -> None:
    assert strategy() == (SparseSolve(), [])
    assert strategy("decoupled") == (PerDroneSolve(), [])


def test_the_solve_table() -> None:
    got, lines = strategy("decoupled", solve={"kind": "sparse", "backend": "osqp", "eps_abs": 1e-6})
    assert got == SparseSolve("osqp", SolverOptions(1e-6, 1e-4, 4000, 0.0)) and lines == []
    table = {"kind": "per_drone", "split_iterations": 3, "split_budget": 0.01, "max_iter": 50}
    got, _ = strategy("decoupled", solve=table)
    assert got == PerDroneSolve("daqp", 50, SplitPolicy(3, 20, 0.01))


def test_old_keys_load_with_one_deprecation_line_each() -> None:
    got, lines = strategy("decoupled", per_drone=False, solver="osqp", time_limit=0.5)
    assert got == SparseSolve("osqp", SolverOptions(1e-4, 1e-4, 4000, 0.5))
    assert lines == [
        "controller.solver is deprecated: write [controller.solve] backend = 'osqp'",
        'controller.per_drone is deprecated: write [controller.solve] kind = "sparse"',
        "controller.time_limit is deprecated: write [controller.solve] time_limit = 0.5",
    ]


@pytest.mark.parametrize(
    ("coupling", "controller", "field", "fragment"),
    [
        ("joint", {"solve": {"kind": "per_drone"}}, "controller.solve.kind", "needs coupling = 'decoupled'"),
        (
            "decoupled",
            {"solve": {"kind": "per_drone", "eps_rel": 0.1}},
            "controller.solve.eps_rel",
            "does not apply",
        ),
        (
            "joint",
            {"solve": {"kind": "sparse", "split_iterations": 2}},
            "controller.solve.split_iterations",
            "only to",
        ),
        (
            "joint",
            {"solve": {"kind": "sparse", "backend": "osqq"}},
            "controller.solve.backend",
            "did you mean 'osqp'",
        ),
        (
            "decoupled",
            {"solve": {"kind": "per_drone", "backend": "piqp"}},
            "controller.solve.backend",
            "per-drone",
        ),
        ("decoupled", {"solver": "osqp"}, "controller.solver", "kind = \"sparse\", backend = 'osqp'"),
        ("decoupled", {"eps_abs": 1e-6}, "controller.eps_abs", "per-drone solve"),
        ("joint", {"split_iterations": 2}, "controller.split_iterations", "coupling = 'joint'"),
        ("joint", {"per_drone": True}, "controller.per_drone", "only to coupling = 'decoupled'"),
        ("joint", {"solver": "osqq"}, "controller.solver", "did you mean 'osqp'"),
        ("joint", {"max_iter": 5, "solve": {"kind": "sparse"}}, "controller.max_iter", "not beside"),
    ],
)
def test_an_ignored_combination_is_refused_in_either_spelling(
    coupling: str, controller: dict[str, Any], field: str, fragment: str
) -> None:
    with pytest.raises(ScenarioError) as err:
        strategy(coupling, **controller)
    assert err.value.field == field and fragment in str(err.value) and "\n" not in str(err.value)

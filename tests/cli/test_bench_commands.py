"""The bench, problems and sweep subcommands' options: solver help, --max-memory, --cvxpy-budget, the
sweep's description."""

from __future__ import annotations

import argparse

import pytest

from mpcform.cli.bench_commands import SWEEP_DESCRIPTION, max_memory_gib, seconds, solver_help
from mpcform.cli.main import build_parser
from mpcform.solvers.casadi_conic import CASADI_CONIC_PLUGINS
from mpcform.solvers.registry import DEFAULT_SOLVER, PERSISTENT_SOLVERS


def test_solver_help_names_the_backends_and_the_families() -> None:
    text = solver_help()
    for name in PERSISTENT_SOLVERS:
        assert name in text
    assert f"{DEFAULT_SOLVER} (default)" in text and "qpsolvers:<name>" in text and "casadi:<plugin>" in text
    assert all(plugin in text for plugin in CASADI_CONIC_PLUGINS) and "casadi:ipopt" in text


@pytest.mark.parametrize("text", ["0", "-1", "nan", "inf", "lots"])
def test_max_memory_must_be_a_positive_number(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="expected a number of GiB > 0"):
        max_memory_gib(text)


def test_max_memory_value() -> None:
    assert max_memory_gib("0.5") == 0.5 and max_memory_gib("64") == 64.0


@pytest.mark.parametrize("text", ["-1", "nan", "inf", "soon"])
def test_seconds_must_be_a_finite_number_at_least_zero(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="expected a number of seconds >= 0"):
        seconds(text)


def test_seconds_value() -> None:
    assert seconds("0") == 0.0 and seconds("60") == 60.0


def test_sweep_has_a_description_and_max_memory() -> None:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    sweep = sub.choices["sweep"]
    assert sweep.description == SWEEP_DESCRIPTION
    assert "--max-memory" in sweep.format_help() and "--tol" in sweep.format_help()
    for command in ("run", "validate"):
        assert "--max-memory GIB" in sub.choices[command].format_help()

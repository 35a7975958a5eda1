"""Persistent backends (osqp, piqp): they solve the recorded problems to the reference, the planner
gives piqp's first input with each, and misuse (a changed pattern, solve before setup) raises."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from mpcform.bench.problems import RecordedQP
from mpcform.errors import SolverError
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.persistent import OSQPBackend, PIQPBackend

RECORDED: dict[str, dict[str, Any]] = {
    "piqp": dict(objective=1e-8, residual=1e-8, all_sizes=True),
    "osqp": dict(objective=1e-5, residual=1e-5, eps=1e-6),
}
"""Tolerances on the relative objective gap and the primal residual, and the eps given."""
FIRST_INPUT: dict[str, dict[str, Any]] = {
    "piqp": dict(tolerance_mps=1e-5),
    "osqp": dict(tolerance_mps=2e-3, eps=1e-6),
}


@pytest.mark.parametrize("name", RECORDED)
def test_backend_solves_recorded_problems(name: str, solves_recorded: Callable[..., None]) -> None:
    solves_recorded(name, **RECORDED[name])


@pytest.mark.parametrize("name", FIRST_INPUT)
def test_planner_first_input_agrees(name: str, first_input_agrees: Callable[..., None]) -> None:
    first_input_agrees(name, **FIRST_INPUT[name])


@pytest.mark.parametrize("backend", [OSQPBackend, PIQPBackend], ids=["osqp", "piqp"])
def test_misuse_is_a_solver_error(
    backend: type[OSQPBackend] | type[PIQPBackend],
    recorded: dict[str, list[RecordedQP]],
    require_usable: Callable[[str], None],
) -> None:
    require_usable(backend.name)
    solver = backend(SolverOptions())
    with pytest.raises(SolverError, match="before setup"):
        solver.solve()
    qp = recorded["swap_planar_8"][0]
    solver.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
    with pytest.raises(SolverError, match="the pattern has"):  # OSQP alone would keep the old A
        solver.update(qp.q, qp.l, qp.u, np.append(qp.A.data, 1.0))

"""qpsolvers backends: they solve the recorded problems to the reference, the planner gives piqp's
first input with each, duals in OSQP's sign convention, a solver's exception is a failed solve,
and HiGHS prints nothing (not even its banner)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mpcform.bench.problems import RecordedQP
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend
from mpcform.solvers.stored import full_symmetric

RECORDED: dict[str, dict[str, Any]] = {
    "qpsolvers:clarabel": dict(objective=1e-8, residual=1e-8, all_sizes=True),
    "qpsolvers:daqp": dict(objective=1e-8, residual=1e-8, problems=1),
    "qpsolvers:highs": dict(objective=1e-6, residual=1e-8),  # HiGHS stops with a larger dual error
    "qpsolvers:osqp": dict(objective=1e-5, residual=1e-5, eps=1e-6),
    "qpsolvers:piqp": dict(objective=1e-7, residual=1e-8),
    "qpsolvers:proxqp": dict(objective=1e-6, residual=1e-6, eps=1e-6, problems=1),
    "qpsolvers:scs": dict(objective=1e-6, residual=1e-6),
}
"""Tolerances on the relative objective gap and the primal residual, the eps given, and how many
of the small swap's problems (slow backends take one)."""
FIRST_INPUT: dict[str, dict[str, Any]] = {
    "qpsolvers:clarabel": dict(tolerance_mps=1e-5),
    "qpsolvers:daqp": dict(tolerance_mps=1e-5),
    "qpsolvers:highs": dict(tolerance_mps=1e-5),
    "qpsolvers:osqp": dict(tolerance_mps=2e-3, eps=1e-6),
    "qpsolvers:piqp": dict(tolerance_mps=1e-5),
    "qpsolvers:proxqp": dict(tolerance_mps=1e-4, eps=1e-6),
    "qpsolvers:scs": dict(tolerance_mps=1e-3),
}


@pytest.mark.parametrize("name", RECORDED)
def test_backend_solves_recorded_problems(name: str, solves_recorded: Callable[..., None]) -> None:
    solves_recorded(name, **RECORDED[name])


@pytest.mark.parametrize("name", FIRST_INPUT)
def test_planner_first_input_agrees(name: str, first_input_agrees: Callable[..., None]) -> None:
    first_input_agrees(name, **FIRST_INPUT[name])


def test_qpsolvers_duals_satisfy_stationarity(recorded: dict[str, list[RecordedQP]]) -> None:
    qp = recorded["swap_planar_8"][0]
    backend = make_backend("qpsolvers:clarabel", SolverOptions(1e-10, 0.0, None))
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
    sol = backend.solve()
    assert sol.success and sol.x is not None and sol.y is not None
    stationarity = full_symmetric(qp.P) @ sol.x + qp.q + qp.A.T @ sol.y
    assert np.abs(stationarity).max() < 1e-6
    ax = qp.A @ sol.x  # OSQP's sign convention: y > 0 only at an upper bound, y < 0 at a lower one
    assert np.all((sol.y <= 1e-7) | (ax >= qp.u - 1e-6)) and np.all((sol.y >= -1e-7) | (ax <= qp.l + 1e-6))


def test_a_solver_exception_is_a_failed_solve(
    recorded: dict[str, list[RecordedQP]], monkeypatch: pytest.MonkeyPatch
) -> None:
    import qpsolvers

    qp = recorded["swap_planar_8"][0]
    backend = make_backend("qpsolvers:clarabel", SolverOptions())
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)

    def broken(*args: object, **kwargs: object) -> None:
        raise ValueError("solver exploded")

    monkeypatch.setattr(qpsolvers, "solve_problem", broken)
    sol = backend.solve()
    assert not sol.success and sol.x is None and "solver exploded" in sol.status


HIGHS_SOLVE = """
from pathlib import Path
from mpcform.bench.problems import load_problem, problem_files
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend

qp = load_problem(problem_files(Path("problems"))[0])
backend = make_backend("qpsolvers:highs", SolverOptions())
backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
raise SystemExit(0 if backend.solve().success else 1)
"""


def test_highs_prints_nothing_in_a_fresh_process(require_usable: Callable[[str], None]) -> None:
    """HiGHS prints its banner once per process, when the first ``highspy.Highs`` is built (before
    any option applies): only a fresh process shows whether the backend lets it through."""
    require_usable("qpsolvers:highs")
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", HIGHS_SOLVE], cwd=root, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert (out.stdout, out.stderr) == ("", "")

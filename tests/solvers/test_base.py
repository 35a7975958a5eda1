"""The backend interface's data types: failed solves, options left to the solver, the QP's size."""

from __future__ import annotations

import pytest

from mpcform.bench.problems import RecordedQP
from mpcform.solvers.base import QPBackend, SolverOptions, failed, given


def test_failed_carries_the_reason_and_no_solution() -> None:
    sol = failed("max iterations", 0.25, 40)
    assert (sol.x, sol.y, sol.success) == (None, None, False)
    assert (sol.status, sol.solve_time_s, sol.iterations) == ("max iterations", 0.25, 40)


def test_given_leaves_out_only_none() -> None:
    kept = given(eps_abs=None, max_iter=0, verbose=False, tol=1e-6)
    assert kept == {"max_iter": 0, "verbose": False, "tol": 1e-6}


def test_options_default_to_the_planner_tolerances() -> None:
    assert SolverOptions() == SolverOptions(1e-5, 1e-5, 4000, 0.0)


def test_context_counts_the_qp_variables(recorded: dict[str, list[RecordedQP]]) -> None:
    for qps in recorded.values():
        qp = qps[0]
        assert qp.context is not None
        ctx = qp.context
        assert ctx.nud == ctx.horizon * ctx.n * ctx.dim
        assert ctx.n_var == qp.P.shape[0] == qp.A.shape[1]
        start, stop = ctx.separation_rows
        assert 0 <= start <= stop <= qp.A.shape[0]


def test_a_backend_must_implement_setup_update_and_solve() -> None:
    class Incomplete(QPBackend):
        name = "incomplete"

    with pytest.raises(TypeError, match="abstract"):
        Incomplete(SolverOptions())  # type: ignore[abstract]

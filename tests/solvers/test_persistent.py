"""Persistent backends (osqp, piqp): they solve the recorded problems to the reference, the planner
gives piqp's first input with each, misuse (a changed pattern, solve before setup) raises, piqp
reuses its solver object when a pattern comes back and solves as a fresh one would, and the row
split and pattern key it keys on are right."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp

from mpcform.bench.problems import RecordedQP
from mpcform.errors import SolverError
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.persistent import OSQPBackend, PIQPBackend, pattern_key, row_split

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


def test_piqp_reuses_its_object_when_a_pattern_comes_back(
    recorded: dict[str, list[RecordedQP]], require_usable: Callable[[str], None]
) -> None:
    require_usable("piqp")
    small, large = recorded["swap_planar_8"][0], recorded["swap_spatial_12"][0]
    q_other = small.q + 0.3 * np.cos(np.arange(small.q.shape[0]))  # new data, same pattern
    options = SolverOptions(1e-9, 1e-9)
    kept = PIQPBackend(options)
    for qp, q in ((small, small.q), (large, large.q), (small, q_other)):
        kept.setup(qp.P, q, qp.A, qp.l, qp.u)
        got = kept.solve()
    fresh = PIQPBackend(options)
    fresh.setup(small.P, q_other, small.A, small.l, small.u)
    want = fresh.solve()
    assert kept.reused == 1 and fresh.reused == 0
    assert got.success and want.success and got.x is not None and want.x is not None
    assert np.max(np.abs(got.x - want.x)) < 1e-9 and got.iterations == want.iterations
    assert got.y is not None and want.y is not None and np.max(np.abs(got.y - want.y)) < 1e-7


@pytest.mark.parametrize("backend", [OSQPBackend, PIQPBackend])
def test_an_iteration_cap_stops_the_next_solves_and_lifts(
    backend: type, recorded: dict[str, list[RecordedQP]], require_usable: Callable[[str], None]
) -> None:
    """``limit_iterations(k)`` stops the next solves after k iterations (not solved); ``None``
    restores the backend's own limit and the QP solves (a freshly set-up backend each time: OSQP
    warm-starts from its last iterate)."""
    require_usable(backend.name)
    qp = recorded["swap_spatial_12"][0]
    capped, lifted = backend(SolverOptions(1e-5, 1e-5)), backend(SolverOptions(1e-5, 1e-5))
    for solver, cap in ((capped, 2), (lifted, None)):
        solver.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
        solver.limit_iterations(2)
        solver.limit_iterations(cap)
    short, full = capped.solve(), lifted.solve()
    assert not short.success and short.iterations == 2
    assert full.success and full.iterations > 2


def test_piqp_keeps_recent_patterns_up_to_its_nonzeros(require_usable: Callable[[str], None]) -> None:
    require_usable("piqp")
    backend = PIQPBackend(SolverOptions(), keep_nnz=30)
    n = 4
    P = sp.identity(n, format="csc")  # 4 nonzeros
    q = np.arange(n, dtype=float)

    def setup(k: int) -> sp.csc_matrix:  # k + 1 rows x_0 + x_j: 2k + 2 nonzeros, a distinct pattern each
        a = sp.csc_matrix(np.array([np.eye(n)[0] + np.eye(n)[1 + j % (n - 1)] for j in range(k + 1)]))
        backend.setup(P, q, a, np.full(a.shape[0], -1.0), np.full(a.shape[0], 1.0))
        return a

    for k in range(5):  # objects of 6, 8, 10, 12, 14 nonzeros: keeping 36 besides the last is over 30
        setup(k)
    a = setup(1)  # kept
    assert backend.reused == 1
    sol = backend.solve()
    fresh = PIQPBackend(SolverOptions())
    fresh.setup(P, q, a, np.full(a.shape[0], -1.0), np.full(a.shape[0], 1.0))
    want = fresh.solve().x
    assert sol.success and sol.x is not None and want is not None and np.max(np.abs(sol.x - want)) < 1e-9
    setup(0)  # the least recently used: dropped
    assert backend.reused == 1


@pytest.mark.parametrize("sort", [True, False], ids=["sorted", "unsorted"])
def test_row_split_selects_the_rows_and_their_entries(sort: bool) -> None:
    rng = np.random.default_rng(3)
    dense = rng.normal(size=(9, 6)) * (rng.random((9, 6)) < 0.4)
    a = sp.csc_matrix(dense)
    a.data[0] = 0.0  # an explicit zero stays an entry
    dense[a.indices[0], 0] = 0.0
    if not sort:  # the same matrix with each column's entries reversed
        idx = np.concatenate([np.arange(a.indptr[j], a.indptr[j + 1])[::-1] for j in range(6)])
        a = sp.csc_matrix((a.data[idx], a.indices[idx], a.indptr), shape=a.shape)
        assert not a.has_sorted_indices
    rows = np.array([True, False, True, True, False, False, True, False, True])
    sub, ids = row_split(a, rows)
    assert np.array_equal(sub.toarray(), dense[rows]) and sub.has_sorted_indices
    assert np.array_equal(sub.data, a.data[ids]) and sub.nnz == np.count_nonzero(rows[a.indices])


def test_pattern_key_follows_the_pattern_not_the_values() -> None:
    a = sp.csc_matrix(np.array([[1.0, 0.0], [2.0, 3.0]]))
    p = sp.identity(2, format="csc")
    eq = np.array([True, False])
    b = a.copy()
    b.data *= -4.0
    assert pattern_key(p, a, eq) == pattern_key(2.0 * p, b, eq)
    assert pattern_key(p, a, eq) != pattern_key(p, a, ~eq)
    assert pattern_key(p, a, eq) != pattern_key(p, sp.csc_matrix(np.array([[1.0, 1.0], [2.0, 3.0]])), eq)

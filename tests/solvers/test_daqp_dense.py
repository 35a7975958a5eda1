"""DAQP as the per-drone backend: ``daqp.solve`` as it is (the same numbers, bit for bit), its
warm start and its iteration limit."""

from __future__ import annotations

import daqp
import numpy as np

from mpcform.solvers.daqp_dense import DAQP_OK, PRIMAL_TOL, DaqpBackend
from mpcform.solvers.dense import NO_BOUND


def problem(seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(12, 6))
    return np.eye(6), rng.normal(size=6) * 3, a, np.full(12, 1.0), np.full(12, -NO_BOUND)


def test_the_backend_returns_daqps_own_solution_bit_for_bit() -> None:
    for seed in range(5):
        h, f, a, up, lo = problem(seed)
        x0 = np.zeros(6)
        x, cost, flag, info = daqp.solve(
            h, f, a, up, lo, primal_start=x0, iter_limit=50, primal_tol=PRIMAL_TOL
        )
        got = DaqpBackend(50).solve(h, f, a, up, lo, x0)
        assert got.success == (flag == DAQP_OK) and got.exit_flag == flag
        assert np.array_equal(got.x, x) and got.cost == cost
        assert np.array_equal(got.multipliers, info["lam"]) and got.iterations == info["iterations"]


def test_the_iteration_limit_stops_a_solve() -> None:
    h, f, a, up, lo = problem(1)
    full = DaqpBackend(None).solve(h, f, a, up, lo)
    assert full.success and full.iterations > 1
    capped = DaqpBackend(1).solve(h, f, a, up, lo)
    assert not capped.success and capped.exit_flag != DAQP_OK


def test_a_warm_start_at_the_optimum_needs_fewer_iterations() -> None:
    h, f, a, up, lo = problem(2)
    cold = DaqpBackend().solve(h, f, a, up, lo)
    warm = DaqpBackend().solve(h, f, a, up, lo, cold.x)
    np.testing.assert_allclose(warm.x, cold.x, atol=1e-12)
    assert warm.iterations <= cold.iterations

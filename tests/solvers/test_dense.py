"""The per-drone backends' contract, checked on every registered backend that is installed: the
optimum, its cost, DAQP's multiplier signs on simple bounds and rows, and an infeasible QP reported
without raising."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.solvers.dense import NO_BOUND, DenseQPBackend
from mpcform.solvers.registry import make_per_drone_backend, solver_info

BACKENDS = ["daqp", "qpsolvers:quadprog", "qpsolvers:clarabel"]


def backend(name: str) -> DenseQPBackend:
    if not solver_info(name, per_drone=True).usable:
        pytest.skip(f"{name} is not installed")
    return make_per_drone_backend(name, 200)


@pytest.mark.parametrize("name", BACKENDS)
def test_optimum_cost_and_multiplier_signs(name: str) -> None:
    """min 0.5 ||x||^2 - x1 - 4 x2 - x3 s.t. x1 <= 0.5 (simple bound), x2 + x3 <= 1, x2 - x3 >= 3.5:
    x = (0.5, 2.25, -1.25); the simple bound and the first row's upper bound are active (> 0), the
    second row's lower bound too (< 0); stationarity gives lam = (0.5, 2, -0.25)."""
    rows = np.array([[0.0, 1.0, 1.0], [0.0, 1.0, -1.0]])
    upper, lower = np.array([0.5, 1.0, NO_BOUND]), np.array([-NO_BOUND, -NO_BOUND, 3.5])
    f = np.array([-1.0, -4.0, -1.0])
    got = backend(name).solve(np.eye(3), f, rows, upper, lower)
    assert got.success
    np.testing.assert_allclose(got.x, [0.5, 2.25, -1.25], atol=1e-6)
    assert got.cost == pytest.approx(0.5 * got.x @ got.x + f @ got.x, abs=1e-9)
    np.testing.assert_allclose(got.multipliers, [0.5, 2.0, -0.25], atol=1e-5)


@pytest.mark.parametrize("name", BACKENDS)
def test_an_infeasible_qp_is_reported_not_raised(name: str) -> None:
    rows = np.array([[1.0, 0.0], [1.0, 0.0]])
    got = backend(name).solve(np.eye(2), np.zeros(2), rows, np.array([0.0, NO_BOUND]), np.array([-1.0, 1.0]))
    assert not got.success


def test_no_bound_means_none() -> None:
    """A row with only NO_BOUND on both sides never binds."""
    got = backend("daqp").solve(
        np.eye(2), np.array([-3.0, 0.0]), np.ones((1, 2)), np.array([NO_BOUND]), np.array([-NO_BOUND])
    )
    np.testing.assert_allclose(got.x, [3.0, 0.0], atol=1e-12)
    assert got.multipliers.tolist() == [0.0]

"""The exact reference (casadi + ipopt on the non-convex problem) and the exact separation
residual: hand-computed violations, and the QP's linearisation is conservative."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from mpcform.bench.problems import RecordedQP
from mpcform.solvers.base import QPContext, SolverOptions
from mpcform.solvers.exact import exact_separation_residual
from mpcform.solvers.registry import make_backend


def _two_drones() -> QPContext:
    """Two planar drones 0.5 m apart that must keep 1 m, drone 0 1 m from an obstacle it must keep
    1.5 m from; horizon 1: z = [u (4) | x (4) | s (2)]."""
    return QPContext(
        n=2,
        dim=2,
        horizon=1,
        separation_rows=(0, 0),
        start_m=np.array([[0.0, 0.0], [0.5, 0.0]]),
        pairs=np.array([[0, 1]]),
        pair_distance_m=1.0,
        metric=np.ones(2),
        obstacle_drones=np.array([0]),
        obstacle_centers_m=np.array([[0.0, -1.0]]),
        obstacle_distance_m=np.array([1.5]),
    )


@pytest.mark.parametrize(
    ("positions", "slacks", "violation"),
    [
        ([0, 0, 0, 0], [0, 0], 0.5),  # both constraints short by 0.5 m
        ([0, 0, 0, 0], [0.25, 0], 0.25),  # drone 0's slack counts in both
        ([0, 0, 0.5, 0], [0, 0], 0.5),  # drone 1 moved away: only the obstacle is violated
        ([0, 0.5, 0.5, 0], [0, 0], 0.0),  # 1.118 m apart, 1.5 m from the obstacle: met
        ([0, 0, 0.5, 0], [0.5, 0], 0.0),
    ],
)
def test_residual_is_the_largest_violation(
    positions: list[float], slacks: list[float], violation: float
) -> None:
    ctx = _two_drones()
    x = np.concatenate([np.zeros(4), positions, slacks])
    assert x.shape == (ctx.n_var,)
    assert exact_separation_residual(ctx, x) == pytest.approx(violation, abs=1e-12)


def test_the_qp_solution_meets_the_exact_constraints(
    recorded: dict[str, list[RecordedQP]],
) -> None:
    """The linearised rows are conservative: a QP solution keeps the true distances."""
    qp = recorded["swap_planar_8"][0]
    assert qp.context is not None
    backend = make_backend("piqp", SolverOptions(1e-9, 1e-9, None))
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
    sol = backend.solve()
    assert sol.success and sol.x is not None
    assert exact_separation_residual(qp.context, sol.x) <= 1e-6


def test_exact_reference_is_below_the_qp_and_feasible(
    recorded: dict[str, list[RecordedQP]],
    reference_objective: Callable[[RecordedQP], float],
    require_usable: Callable[[str], None],
) -> None:
    require_usable("casadi:ipopt")
    qp = recorded["swap_planar_8"][0]
    assert qp.context is not None
    backend = make_backend("casadi:ipopt", SolverOptions(1e-8, 1e-8, None))
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
    assert not backend.solve().success  # without the context it cannot know the exact problem
    backend.set_context(qp.context)
    sol = backend.solve(qp.x0)
    assert sol.success and sol.x is not None
    assert exact_separation_residual(qp.context, sol.x) <= 1e-6
    assert qp.objective(sol.x) <= reference_objective(qp) + 1e-6  # the linearisation is conservative

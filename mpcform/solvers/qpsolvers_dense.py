"""Any qpsolvers solver as a per-drone backend (``qpsolvers:<solver>`` in ``PerDroneSolve``).

The dense problem of :mod:`mpcform.solvers.dense` becomes qpsolvers' ``G x <= h`` (each finite
side of a row, the lower ones negated) with box bounds on the simple-bound variables; the duals
are mapped back to DAQP's one multiplier per bound. Solved to :data:`DENSE_EPS` (the per-drone
path needs its rows met to about DAQP's 1e-9); no iteration count is reported.
"""

from __future__ import annotations

import warnings

import numpy as np

from mpcform._validate import Array
from mpcform.errors import SolverError
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.dense import NO_BOUND, DenseQPBackend, DenseSolution
from mpcform.solvers.qpsolvers_backend import QPSOLVERS_WARM, qpsolvers_settings

DENSE_EPS = 1e-10


class QPSolversDenseBackend(DenseQPBackend):
    """One qpsolvers solver, called afresh for every drone."""

    def __init__(self, solver: str, max_iter: int | None = None) -> None:
        import qpsolvers

        super().__init__(max_iter)
        if solver not in qpsolvers.available_solvers:
            raise SolverError(f"qpsolvers:{solver}", f'not installed: pip install "qpsolvers[{solver}]"')
        self._qpsolvers, self.solver = qpsolvers, solver
        self.name = f"qpsolvers:{solver}"
        self.warm_starts = solver in QPSOLVERS_WARM
        self._settings = qpsolvers_settings(solver, SolverOptions(DENSE_EPS, DENSE_EPS, max_iter))

    def solve(
        self, hessian: Array, f: Array, rows: Array, upper: Array, lower: Array, x0: Array | None = None
    ) -> DenseSolution:
        n, simple = f.shape[0], upper.shape[0] - rows.shape[0]
        up, lo = upper[simple:], lower[simple:]
        has_up, has_lo = up < NO_BOUND, lo > -NO_BOUND
        lb, ub = np.full(n, -np.inf), np.full(n, np.inf)
        lb[:simple] = np.where(lower[:simple] > -NO_BOUND, lower[:simple], -np.inf)
        ub[:simple] = np.where(upper[:simple] < NO_BOUND, upper[:simple], np.inf)
        g = np.vstack([rows[has_up], -rows[has_lo]])
        h = np.concatenate([up[has_up], -lo[has_lo]])
        problem = self._qpsolvers.Problem(hessian, f, g, h, None, None, lb, ub)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sol = self._qpsolvers.solve_problem(
                    problem, solver=self.solver, initvals=x0 if self.warm_starts else None, **self._settings
                )
        except Exception:  # noqa: BLE001 - a solver's own failure is an unsuccessful solve
            return DenseSolution(np.full(n, np.nan), np.inf, False, -1, np.zeros(upper.shape[0]), 0)
        x, z = sol.x, sol.z
        if not sol.found or x is None or z is None or not np.isfinite(x).all():
            return DenseSolution(np.full(n, np.nan), np.inf, False, -1, np.zeros(upper.shape[0]), 0)
        lam = np.zeros(upper.shape[0])
        n_up = int(has_up.sum())
        lam[simple:][has_up] += z[:n_up]
        lam[simple:][has_lo] -= z[n_up:]
        if simple and sol.z_box is not None:
            lam[:simple] = sol.z_box[:simple]
        cost = float(0.5 * x @ hessian @ x + f @ x)
        return DenseSolution(x, cost, True, 1, lam, 0)

"""Any qpsolvers solver as a per-drone backend (``qpsolvers:<solver>`` in ``PerDroneSolve``).

The dense problem of :mod:`mpcform.solvers.dense` (its simple bounds as the first rows) goes
through the sparse backend's own rewriting, :func:`~mpcform.solvers.qpsolvers_backend.qpsolvers_form`,
whose :class:`~mpcform.solvers.qpsolvers_backend.RowSplit` maps the duals back to one multiplier
per bound (DAQP's signs). Solved to :data:`DENSE_EPS` (the per-drone
path needs its rows met to about DAQP's 1e-9); no iteration count is reported.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.dense import NO_BOUND, DenseQPBackend, DenseSolution
from mpcform.solvers.qpsolvers_backend import (
    QPSOLVERS_WARM,
    installed_qpsolvers,
    qpsolvers_form,
    qpsolvers_settings,
)

DENSE_EPS = 1e-10


class QPSolversDenseBackend(DenseQPBackend):
    """One qpsolvers solver, called afresh for every drone."""

    def __init__(self, solver: str, max_iter: int | None = None) -> None:
        super().__init__(max_iter)
        self._qpsolvers, self.solver = installed_qpsolvers(solver), solver
        self.name = f"qpsolvers:{solver}"
        self.warm_starts = solver in QPSOLVERS_WARM
        self._dense = solver not in self._qpsolvers.sparse_solvers
        self._settings = qpsolvers_settings(solver, SolverOptions(DENSE_EPS, DENSE_EPS, max_iter))

    def solve(
        self, hessian: Array, f: Array, rows: Array, upper: Array, lower: Array, x0: Array | None = None
    ) -> DenseSolution:
        n, m = f.shape[0], upper.shape[0]
        a = np.vstack([np.eye(m - rows.shape[0], n), rows])  # the simple bounds as rows first
        lo, hi = np.where(lower > -NO_BOUND, lower, -np.inf), np.where(upper < NO_BOUND, upper, np.inf)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                problem, split = qpsolvers_form(sp.triu(hessian, format="csc"), f, a, lo, hi, self._dense)
                sol = self._qpsolvers.solve_problem(
                    problem, solver=self.solver, initvals=x0 if self.warm_starts else None, **self._settings
                )
        except Exception:  # noqa: BLE001 - a solver's own failure is an unsuccessful solve
            return _failed(n, m)
        x = sol.x
        lam = split.duals(m, np.zeros(0) if sol.y is None else sol.y, sol.z)  # DAQP's signs
        if not sol.found or x is None or lam is None or not np.isfinite(x).all():
            return _failed(n, m)
        return DenseSolution(x, float(0.5 * x @ hessian @ x + f @ x), True, 1, lam, 0)


def _failed(n: int, m: int) -> DenseSolution:
    """An unsuccessful solve of ``n`` variables and ``m`` bounds (built only when one fails)."""
    return DenseSolution(np.full(n, np.nan), np.inf, False, -1, np.zeros(m), 0)

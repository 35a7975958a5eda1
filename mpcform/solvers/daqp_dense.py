"""DAQP (dual active set) as the per-drone backend: the default of ``PerDroneSolve``.

DAQP takes the problem of :mod:`mpcform.solvers.dense` as it is; ``primal_start`` seeds its
active set with the rows nearly active at ``x0``. Rows are met to ``PRIMAL_TOL`` (its default
1e-6 shows in the plans).
"""

from __future__ import annotations

from typing import Any

from mpcform._validate import Array
from mpcform.solvers.dense import DenseQPBackend, DenseSolution

DAQP_OK = 1  # DAQP's exit flag of an optimal solve
PRIMAL_TOL = 1e-9  # DAQP row feasibility tolerance


class DaqpBackend(DenseQPBackend):
    """``daqp.solve`` with a fixed ``primal_tol`` and the iteration limit."""

    name = "daqp"
    warm_starts = True

    def __init__(self, max_iter: int | None = None) -> None:
        import daqp

        super().__init__(max_iter)
        self._daqp = daqp  # looked up at every call (a benchmark may time daqp.solve)
        self._options: dict[str, Any] = {"primal_tol": PRIMAL_TOL}
        if max_iter is not None:
            self._options = {"iter_limit": max_iter, **self._options}

    def solve(
        self, hessian: Array, f: Array, rows: Array, upper: Array, lower: Array, x0: Array | None = None
    ) -> DenseSolution:
        start = {} if x0 is None else {"primal_start": x0}
        x, cost, flag, info = self._daqp.solve(hessian, f, rows, upper, lower, **start, **self._options)
        return DenseSolution(x, cost, flag == DAQP_OK, flag, info["lam"], info["iterations"])

"""Persistent solver objects: set up once per sparsity pattern, then updated in place.

``osqp`` (ADMM, warm-started) and ``piqp`` (proximal interior point). The packages are imported
when a backend is built, not with this module.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.errors import SolverError
from mpcform.solvers.base import QPBackend, QPSolution, SolverOptions, given


class OSQPBackend(QPBackend):
    """Persistent ``osqp.OSQP`` object: set up once per pattern, then ``update`` + warm start."""

    name = "osqp"
    warm_starts = True
    persistent = True

    def __init__(self, options: SolverOptions) -> None:
        super().__init__(options)
        import osqp

        self._osqp = osqp
        self._solver: Any = None
        self._nnz_a = 0

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        o = self.options
        extra = given(eps_abs=o.eps_abs, eps_rel=o.eps_rel, max_iter=o.max_iter,
                      time_limit=o.time_limit_s if o.time_limit_s > 0 else None)  # fmt: skip
        solver = self._osqp.OSQP()
        solver.setup(P.copy(), q, A.copy(), lo, hi, verbose=False, polishing=True, warm_starting=True,
                     adaptive_rho=True, **extra)  # fmt: skip
        self._solver, self._nnz_a = solver, A.nnz

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        if A_data.shape[0] != self._nnz_a:  # OSQP would only print an error and keep the old A
            raise SolverError(self.name, f"A has {A_data.shape[0]} values, the pattern has {self._nnz_a}")
        self._solver.update(q=q, l=lo, u=hi, Ax=A_data)

    def solve(self, x0: Array | None = None) -> QPSolution:
        solver = self._solver
        if solver is None:
            raise SolverError(self.name, "solve() before setup()")
        if x0 is not None:
            solver.warm_start(x=x0)
        start = time.perf_counter()
        res = solver.solve(raise_error=False)
        elapsed = time.perf_counter() - start
        info = res.info
        ok = info.status_val in (1, 2) and res.x is not None and bool(np.all(np.isfinite(res.x)))
        return QPSolution(
            res.x.copy() if ok else None, res.y.copy() if ok else None, ok, str(info.status),
            int(info.iter), elapsed,
        )  # fmt: skip


class PIQPBackend(QPBackend):
    """Persistent ``piqp.SparseSolver`` (proximal interior point); rows with ``l == u`` at setup
    become its equality block, the others its two-sided inequality block."""

    name = "piqp"
    persistent = True

    def __init__(self, options: SolverOptions) -> None:
        super().__init__(options)
        import piqp

        self._piqp = piqp
        self._solver: Any = None

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        self._eq = eq = lo == hi
        ids = A.copy()
        ids.data = np.arange(A.nnz, dtype=float)
        a_eq, g = ids[eq].tocsc(), ids[~eq].tocsc()
        self._eq_ids, self._g_ids = a_eq.data.astype(np.intp), g.data.astype(np.intp)
        self._a_eq, self._g = a_eq, g
        a_eq.data, g.data = A.data[self._eq_ids], A.data[self._g_ids]
        solver = self._piqp.SparseSolver()
        st, o = solver.settings, self.options
        st.verbose = False
        for key, value in given(eps_abs=o.eps_abs, eps_rel=o.eps_rel, max_iter=o.max_iter).items():
            setattr(st, key, value)
        solver.setup(P.copy(), q, a_eq.copy(), lo[eq], g.copy(), lo[~eq], hi[~eq])
        self._solver, self._nnz_a = solver, A.nnz

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        if A_data.shape[0] != self._nnz_a:
            raise SolverError(self.name, f"A has {A_data.shape[0]} values, the pattern has {self._nnz_a}")
        self._a_eq.data, self._g.data = A_data[self._eq_ids], A_data[self._g_ids]
        eq = self._eq
        self._solver.update(c=q, A=self._a_eq, b=lo[eq], G=self._g, h_l=lo[~eq], h_u=hi[~eq])

    def solve(self, x0: Array | None = None) -> QPSolution:
        solver = self._solver
        if solver is None:
            raise SolverError(self.name, "solve() before setup()")
        start = time.perf_counter()
        status = solver.solve()
        elapsed = time.perf_counter() - start
        res = solver.result
        ok = status == self._piqp.PIQP_SOLVED and bool(np.all(np.isfinite(res.x)))
        y = np.zeros(self._eq.shape[0])
        if ok:
            y[self._eq] = res.y
            y[~self._eq] = res.z_u - res.z_l
        return QPSolution(
            np.array(res.x) if ok else None, y if ok else None, ok,
            str(status).split(".")[-1].lower(), int(res.info.iter), elapsed,
        )  # fmt: skip

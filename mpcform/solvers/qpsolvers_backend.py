"""Any solver installed for qpsolvers, called afresh each step (``qpsolvers:<solver>``).

qpsolvers takes ``G z <= h, A_eq z = b``: :func:`qpsolvers_form` rewrites ``l <= A z <= u`` in
that form and :class:`RowSplit` maps the duals back. ``solve`` never raises for a solver's failure
(the solver's own exception text becomes the status) and prints nothing (warnings suppressed,
the solvers of :data:`PRINTS_FROM_C` silenced).
"""

from __future__ import annotations

import time
import warnings
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.errors import SolverError
from mpcform.solvers.base import QPSolution, SolverOptions, failed, given
from mpcform.solvers.stored import StoredQP, full_symmetric, quiet_fds

QPSOLVERS_WARM = frozenset(
    {"cvxopt", "daqp", "hpipm", "kvxopt", "nppro", "osqp", "pdhcg", "proxqp", "pyqpmad", "qpalm", "scs"}
)
"""qpsolvers wrappers that pass ``initvals`` to the solver (the others ignore it, with a warning)."""
PRINTS_FROM_C = frozenset({"highs"})
"""Solvers that print whatever their settings say, solved with stdout and stderr sent to
``/dev/null``: HiGHS prints its banner when a ``highspy.Highs`` object is built, before any
option (``output_flag``, ``log_to_console``) can be set."""


@dataclass(frozen=True)
class RowSplit:
    """Where the rows of ``l <= A z <= u`` went in qpsolvers' ``G z <= h, A_eq z = b``: ``eq``
    (rows with ``l == u``), ``upper`` (finite u) and ``lower`` (finite l) row indices."""

    eq: Array
    upper: Array
    lower: Array

    def duals(self, m: int, y_eq: Array | None, z: Array | None) -> Array | None:
        """Multipliers of the two-sided rows (OSQP's sign: > 0 at an active upper bound)."""
        if y_eq is None or z is None:
            return None
        y = np.zeros(m)
        y[self.eq] = y_eq
        nu = self.upper.shape[0]
        np.add.at(y, self.upper, z[:nu])
        np.subtract.at(y, self.lower, z[nu:])
        return y


def qpsolvers_form(
    P_upper: sp.spmatrix, q: Array, A: sp.spmatrix, lo: Array, hi: Array, dense: bool = False
) -> tuple[Any, RowSplit]:
    """``l <= A z <= u`` (P upper triangular) as a :class:`qpsolvers.Problem` (full symmetric P,
    rows with ``l == u`` as equalities, each finite side of the others as a row of ``G z <= h``)."""
    import qpsolvers

    A = sp.csr_matrix(A)
    eq = np.flatnonzero(lo == hi)
    ineq = lo != hi
    upper = np.flatnonzero(ineq & np.isfinite(hi))
    lower = np.flatnonzero(ineq & np.isfinite(lo))
    G = sp.vstack([A[upper], -A[lower]], format="csc")
    h = np.concatenate([hi[upper], -lo[lower]])
    P, A_eq = full_symmetric(P_upper), A[eq].tocsc()
    if dense:
        return qpsolvers.Problem(P.toarray(), q, G.toarray(), h, A_eq.toarray(), lo[eq]), RowSplit(
            eq, upper, lower
        )
    return qpsolvers.Problem(P, q, G, h, A_eq, lo[eq]), RowSplit(eq, upper, lower)


def installed_qpsolvers(solver: str) -> Any:
    """The qpsolvers module, once ``solver`` is installed for it (else a :class:`SolverError` with
    the install hint)."""
    import qpsolvers

    if solver not in qpsolvers.available_solvers:
        raise SolverError(f"qpsolvers:{solver}", f'not installed: pip install "qpsolvers[{solver}]"')
    return qpsolvers


def qpsolvers_settings(solver: str, options: SolverOptions) -> dict[str, Any]:
    """``options`` in the parameter names of qpsolvers' ``solver`` (None values left out)."""
    a, r, it = options.eps_abs, options.eps_rel, options.max_iter
    tl = options.time_limit_s if options.time_limit_s > 0 else None
    gap_check = True if a is not None else None
    with_gap = given(
        eps_abs=a,
        eps_rel=r,
        eps_duality_gap_abs=a,
        eps_duality_gap_rel=r,
        check_duality_gap=gap_check,
        max_iter=it,
    )
    table: dict[str, dict[str, Any]] = {
        "clarabel": given(tol_feas=a, tol_gap_abs=a, tol_gap_rel=r, max_iter=it, time_limit=tl),
        "cvxopt": given(feastol=a, abstol=a, reltol=r, maxiters=it),
        "daqp": given(primal_tol=a, dual_tol=a, iter_limit=it),
        "ecos": given(feastol=a, abstol=a, reltol=r, max_iters=it),
        "highs": given(primal_feasibility_tolerance=a, dual_feasibility_tolerance=a, time_limit=tl),
        "hpipm": given(tol_stat=a, tol_eq=a, tol_ineq=a, tol_comp=a, iter_max=it),
        "osqp": given(eps_abs=a, eps_rel=r, max_iter=it, time_limit=tl),
        "piqp": with_gap,
        "proxqp": with_gap,
        "qpalm": given(eps_abs=a, eps_rel=r, max_iter=it, time_limit=tl),
        "scs": given(eps_abs=a, eps_rel=r, max_iters=it, time_limit_secs=tl),
    }
    return table.get(solver, {})


class QPSolversBackend(StoredQP):
    """A qpsolvers solver, called afresh each step (qpsolvers sets up on every call).

    Dense-only solvers get dense matrices. ``x0`` goes to ``initvals`` only where the wrapper uses
    it (:data:`QPSOLVERS_WARM`); the solvers of :data:`PRINTS_FROM_C` run with the output silenced.
    """

    def __init__(self, solver: str, options: SolverOptions) -> None:
        super().__init__(options)
        self._qpsolvers, self.solver = installed_qpsolvers(solver), solver
        self.name = f"qpsolvers:{solver}"
        self.warm_starts = solver in QPSOLVERS_WARM
        self._dense = solver not in self._qpsolvers.sparse_solvers
        self._settings = qpsolvers_settings(solver, options)
        self._quiet = solver in PRINTS_FROM_C

    def solve(self, x0: Array | None = None) -> QPSolution:
        if self._P is None:
            raise SolverError(self.name, "solve() before setup()")
        start = time.perf_counter()
        try:
            with warnings.catch_warnings(), quiet_fds() if self._quiet else nullcontext():
                warnings.simplefilter("ignore")
                problem, rows = qpsolvers_form(self._P, self._q, self._A, self._lo, self._hi, self._dense)
                sol = self._qpsolvers.solve_problem(
                    problem,
                    solver=self.solver,
                    initvals=x0 if self.warm_starts else None,
                    verbose=False,
                    **self._settings,
                )
        except Exception as exc:  # noqa: BLE001 - a solver's own error is this solve's failure status
            return failed(f"error: {type(exc).__name__}: {exc}", time.perf_counter() - start)
        elapsed = time.perf_counter() - start
        x = sol.x
        if not sol.found or x is None or not np.all(np.isfinite(x)):
            return failed("not found", elapsed)
        y = rows.duals(self._lo.shape[0], sol.y, sol.z)
        x = np.array(x, dtype=float)
        return QPSolution(x, y, True, "found", 0, elapsed, self.objective(x), dict(sol.extras))

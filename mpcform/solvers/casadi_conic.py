"""casadi's conic interface with one plugin (``casadi:<plugin>``), set up again on every call.

``solve`` never raises for a solver's failure (casadi's error text becomes the status) and
prints nothing: the plugins print from C (qpOASES's banner, casadi's own warnings), so they run
under :func:`~mpcform.solvers.stored.quiet_fds`. ``hpipm`` takes the QP in stage order
(:func:`stage_order`), which needs the :class:`~mpcform.solvers.base.QPContext`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.errors import SolverError
from mpcform.solvers.base import QPContext, QPSolution, SolverOptions, failed, given
from mpcform.solvers.stored import StoredQP, quiet_fds

CASADI_CONIC_PLUGINS = ("osqp", "qpoases", "proxqp", "daqp", "piqp", "ipqp", "hpipm")
"""casadi conic plugins offered as ``casadi:<plugin>`` (``highs`` segfaulted: never offered)."""
CASADI_WARM = frozenset({"osqp", "proxqp"})
"""Plugins that use the initial guess ``x0``."""


def casadi_conic_options(plugin: str, options: SolverOptions) -> dict[str, Any]:
    """casadi ``conic`` options: silent, no exception on failure, ``options`` in the plugin's
    parameter names. Some plugins need a setting for this problem class (P only semi-definite,
    thousands of sparse rows): casadi's DAQP fails without proximal regularisation (``eps_prox``
    1e-6; 0 and -1 fail), ipqp's default LDL factorisation meets zero pivots (QR is used), and
    qpOASES runs in its sparse mode (about 5x faster than its dense default here; casadi's osqp
    takes no time limit)."""
    a, r, it = options.eps_abs, options.eps_rel, options.max_iter
    tl = options.time_limit_s if options.time_limit_s > 0 else None
    per_plugin: dict[str, dict[str, Any]] = {
        "osqp": {"osqp": given(verbose=False, eps_abs=a, eps_rel=r, max_iter=it)},
        "qpoases": given(
            printLevel="none",
            sparse=True,
            nWSR=it,
            CPUtime=tl,
            terminationTolerance=a,
        ),
        "proxqp": {"proxqp": given(verbose=False, eps_abs=a, eps_rel=r, max_iter=it)},
        "daqp": {"daqp": given(eps_prox=1e-6, primal_tol=a, dual_tol=a, iter_limit=it)},
        "piqp": {"piqp": given(verbose=False, eps_abs=a, eps_rel=r, max_iter=it)},
        "ipqp": given(
            print_iter=False,
            print_header=False,
            print_info=False,
            linear_solver="qr",
            constr_viol_tol=a,
            dual_inf_tol=a,
            max_iter=it,
        ),
        "hpipm": {"hpipm": given(res_g_max=a, res_b_max=a, res_d_max=a, res_m_max=a, iter_max=it)},
    }
    return {"error_on_fail": False, "print_time": False, **per_plugin[plugin]}


def casadi_sparse(casadi: Any, M: sp.spmatrix) -> Any:
    """``M`` as a casadi ``DM`` with the same sparsity pattern."""
    M = sp.csc_matrix(M)
    M.sort_indices()
    sparsity = casadi.Sparsity(M.shape[0], M.shape[1], M.indptr.tolist(), M.indices.tolist())
    return casadi.DM(sparsity, M.data)


@dataclass(frozen=True)
class StageOrder:
    """The QP reordered as an optimal-control problem for HPIPM: variables ``[x_0 u_0 .. x_N]``,
    rows ``[gap_0 lincon_0 .. gap_{N-1} lincon_{N-1} lincon_N]``, each gap row scaled so its
    coefficient on the next state is -1."""

    var_perm: Array
    row_perm: Array
    row_scale: Array
    nx: list[int]
    nu: list[int]
    ng: list[int]


def stage_order(ctx: QPContext, A: sp.csc_matrix, lo: Array, hi: Array) -> StageOrder:
    """Stages of the planner's QP: stage 0 has input u_0; stage k = 1..H-1 state x_k and inputs
    (u_k, s_k); stage H state x_H and input s_H; stage H + 1 is empty. Raises
    :class:`SolverError` for a row that couples stages without being a dynamics row (the
    acceleration limit)."""
    n, d, h = ctx.n, ctx.dim, ctx.horizon
    nd, nud = n * d, ctx.nud
    u_cols = [np.arange(j * nd, (j + 1) * nd) for j in range(h)]
    x_cols = [np.empty(0, np.intp)] + [nud + np.arange((e - 1) * nd, e * nd) for e in range(1, h + 1)]
    s_cols = [np.empty(0, np.intp)] + [2 * nud + np.arange((e - 1) * n, e * n) for e in range(1, h + 1)]
    xs = [x_cols[k] if k <= h else np.empty(0, np.intp) for k in range(h + 2)]
    us = [np.concatenate([u_cols[k] if k < h else np.empty(0, np.intp), s_cols[k]]) for k in range(h + 1)]
    n_var = ctx.n_var
    stage = np.empty(n_var, dtype=np.intp)
    is_state = np.zeros(n_var, dtype=bool)
    for k in range(h + 2):
        stage[xs[k]] = k
        is_state[xs[k]] = True
        if k <= h:
            stage[us[k]] = k
    var_perm = np.concatenate([np.concatenate([xs[k], us[k]]) if k <= h else xs[k] for k in range(h + 2)])
    rows = sp.csr_matrix(A)
    state_pos = np.full(n_var, -1)
    for k in range(h + 2):
        state_pos[xs[k]] = np.arange(xs[k].shape[0])
    gaps: list[list[tuple[int, int, float]]] = [[] for _ in range(h + 2)]  # (state index, row, scale)
    lincon: list[list[int]] = [[] for _ in range(h + 2)]
    for r in range(rows.shape[0]):
        cols = rows.indices[rows.indptr[r] : rows.indptr[r + 1]]
        vals = rows.data[rows.indptr[r] : rows.indptr[r + 1]]
        stages = np.unique(stage[cols])
        if stages.shape[0] == 1:
            lincon[int(stages[0])].append(r)
            continue
        k = int(stages[0])
        nxt = (stage[cols] == k + 1) & is_state[cols]
        if (
            stages.shape[0] != 2
            or stages[1] != k + 1
            or lo[r] != hi[r]
            or nxt.sum() != 1
            or np.any((stage[cols] == k + 1) & ~is_state[cols])
        ):
            raise SolverError(
                "casadi:hpipm",
                f"row {r} couples stages {stages.tolist()} and is no dynamics row "
                "(e.g. an acceleration limit): not an optimal-control structure",
            )
        gaps[k].append((int(state_pos[cols[nxt][0]]), r, -1.0 / float(vals[nxt][0])))
    order: list[int] = []
    scale = np.ones(rows.shape[0])
    for k in range(h + 2):
        if k <= h:
            gap = sorted(gaps[k])
            if [g[0] for g in gap] != list(range(xs[k + 1].shape[0])):
                raise SolverError("casadi:hpipm", f"stage {k + 1}: each state needs exactly one dynamics row")
            for _, r, s in gap:
                order.append(r)
                scale[r] = s
        order.extend(lincon[k])
    return StageOrder(
        var_perm,
        np.array(order, dtype=np.intp),
        scale,
        [x.shape[0] for x in xs],
        [u.shape[0] for u in us] + [0],
        [len(c) for c in lincon],
    )


class CasadiConicBackend(StoredQP):
    """casadi's ``conic`` interface with one plugin; the function is rebuilt when the pattern
    changes and casadi sets the solver up on every call. ``hpipm`` gets the QP in stage order
    (it needs the :class:`QPContext`)."""

    def __init__(self, plugin: str, options: SolverOptions) -> None:
        super().__init__(options)
        import casadi

        self._casadi, self.plugin = casadi, plugin
        self.name = f"casadi:{plugin}"
        self.warm_starts = plugin in CASADI_WARM
        self.needs_context = self.stagewise = plugin == "hpipm"
        self._options = casadi_conic_options(plugin, options)
        self._fn: Any = None
        self._order: StageOrder | None = None

    def _changed_pattern(self) -> None:
        self._fn, self._order = None, None

    def solve(self, x0: Array | None = None) -> QPSolution:
        if self._P is None:
            raise SolverError(self.name, "solve() before setup()")
        start = time.perf_counter()
        try:
            with quiet_fds():
                x, y, stats = self._call(x0)
        except (RuntimeError, SolverError) as exc:
            return failed(f"error: {' '.join(str(exc).split())[:300]}", time.perf_counter() - start)
        return casadi_solution(x, y, stats, time.perf_counter() - start, self.objective(x))

    def _call(self, x0: Array | None) -> tuple[Array, Array | None, dict[str, Any]]:
        ca = self._casadi
        P, A, q, lo, hi = self._P, self._A, self._q, self._lo, self._hi
        if P is None:
            raise SolverError(self.name, "solve() before setup()")
        perm = None
        if self.plugin == "hpipm":
            if self._context is None:
                raise SolverError(self.name, "needs the QP's stage structure (set_context) before solve()")
            if self._order is None:
                self._order = stage_order(self._context, A, lo, hi)
            o = self._order
            perm, rows = o.var_perm, o.row_perm
            scale = o.row_scale[rows]
            P = P[perm][:, perm]
            A = sp.diags(scale) @ sp.csr_matrix(A)[rows][:, perm]
            q, lo, hi = q[perm], lo[rows] * scale, hi[rows] * scale
            lo, hi = np.where(scale > 0, lo, hi), np.where(scale > 0, hi, lo)
            if x0 is not None:
                x0 = x0[perm]
        H_dm, A_dm = casadi_sparse(ca, P), casadi_sparse(ca, A)
        if self._fn is None:
            opts = dict(self._options)
            if self._order is not None:
                opts.update(
                    N=len(self._order.nu) - 1, nx=self._order.nx, nu=self._order.nu, ng=self._order.ng
                )
            self._fn = ca.conic("qp", self.plugin, {"h": H_dm.sparsity(), "a": A_dm.sparsity()}, opts)
        n = q.shape[0]
        args = dict(h=H_dm, g=q, a=A_dm, lba=lo, uba=hi, lbx=np.full(n, -np.inf), ubx=np.full(n, np.inf))
        if x0 is not None and self.warm_starts:
            args["x0"] = x0
        out = self._fn(**args)
        x = np.array(out["x"], dtype=float).ravel()
        y: Array | None = np.array(out["lam_a"], dtype=float).ravel()
        if perm is not None:
            z = np.empty_like(x)
            z[perm] = x
            x, y = z, None
        return x, y, dict(self._fn.stats())


def casadi_solution(
    x: Array, y: Array | None, stats: dict[str, Any], elapsed_s: float, objective: float | None = None
) -> QPSolution:
    """A solution from casadi's solver statistics: failed unless it reports success with a finite x
    (its ``objective`` given by the caller; the statistics are its extras)."""
    iters = max(0, int(stats.get("iter_count", 0) or 0))
    status = str(stats.get("return_status", "unknown"))
    if not stats.get("success", False) or not np.all(np.isfinite(x)):
        return failed(status, elapsed_s, iters)
    return QPSolution(x, y, True, status, iters, elapsed_s, objective, stats)

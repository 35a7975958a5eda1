"""Backends over optional solver packages: qpsolvers, casadi's conic plugins, casadi + ipopt.

Imported only by :func:`mpcform.solvers.base.make_backend` when one of them is asked for. Each one
keeps the :class:`~mpcform.solvers.base.QPBackend` contract: ``solve`` never raises for a solver's
failure (the solver's own exception text becomes the status), and nothing is printed: warnings
are suppressed and casadi's plugins, which print from C (qpOASES's banner, casadi's own
warnings), run with the process's stdout and stderr redirected to ``/dev/null``.
"""

from __future__ import annotations

import ctypes
import os
import sys
import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.errors import SolverError
from mpcform.solvers.base import (
    CASADI_WARM,
    QPSOLVERS_WARM,
    QPBackend,
    QPContext,
    QPSolution,
    SolverOptions,
    failed,
)


# ---- shared helpers ---------------------------------------------------------------------------
def full_symmetric(P_upper: sp.spmatrix) -> sp.csc_matrix:
    """The symmetric matrix whose upper triangle is ``P_upper``."""
    upper = sp.triu(P_upper, format="csc")
    return (upper + sp.triu(upper, 1).T).tocsc()


@contextmanager
def quiet_fds() -> Iterator[None]:
    """Send the process's file descriptors 1 and 2 to ``/dev/null`` (C libraries print there),
    flushing C and Python buffers on both sides so nothing leaks out later."""
    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    sys.stderr.flush()
    libc.fflush(None)
    saved = os.dup(1), os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        libc.fflush(None)
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


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


def qpsolvers_form(P_upper: sp.spmatrix, q: Array, A: sp.spmatrix, lo: Array, hi: Array,
                   dense: bool = False) -> tuple[Any, RowSplit]:  # fmt: skip
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


def _given(**values: Any) -> dict[str, Any]:
    return {k: v for k, v in values.items() if v is not None}


class _StoredQP(QPBackend):
    """Keeps the current problem's data; subclasses solve it from scratch each time."""

    def __init__(self, options: SolverOptions) -> None:
        super().__init__(options)
        self._P: sp.csc_matrix | None = None
        self._context: QPContext | None = None

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        self._P, self._A = full_symmetric(P), A.copy()
        self._q, self._lo, self._hi = q.copy(), lo.copy(), hi.copy()
        self._changed_pattern()

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        if self._P is None:
            raise SolverError(self.name, "update() before setup()")
        if A_data.shape[0] != self._A.nnz:
            raise SolverError(self.name, f"A has {A_data.shape[0]} values, the pattern has {self._A.nnz}")
        self._A.data = A_data.copy()
        self._q, self._lo, self._hi = q.copy(), lo.copy(), hi.copy()

    def set_context(self, context: QPContext) -> None:
        self._context = context

    def _changed_pattern(self) -> None:
        """Hook: the sparsity pattern changed (drop what depends on it)."""


# ---- qpsolvers --------------------------------------------------------------------------------
def qpsolvers_settings(solver: str, options: SolverOptions) -> dict[str, Any]:
    """``options`` in the parameter names of qpsolvers' ``solver`` (None values left out)."""
    a, r, it = options.eps_abs, options.eps_rel, options.max_iter
    tl = options.time_limit_s if options.time_limit_s > 0 else None
    gap_check = True if a is not None else None
    with_gap = _given(eps_abs=a, eps_rel=r, eps_duality_gap_abs=a, eps_duality_gap_rel=r,
                      check_duality_gap=gap_check, max_iter=it)  # fmt: skip
    table: dict[str, dict[str, Any]] = {
        "clarabel": _given(tol_feas=a, tol_gap_abs=a, tol_gap_rel=r, max_iter=it, time_limit=tl),
        "cvxopt": _given(feastol=a, abstol=a, reltol=r, maxiters=it),
        "daqp": _given(primal_tol=a, dual_tol=a, iter_limit=it),
        "ecos": _given(feastol=a, abstol=a, reltol=r, max_iters=it),
        "highs": _given(primal_feasibility_tolerance=a, dual_feasibility_tolerance=a, time_limit=tl),
        "hpipm": _given(tol_stat=a, tol_eq=a, tol_ineq=a, tol_comp=a, iter_max=it),
        "osqp": _given(eps_abs=a, eps_rel=r, max_iter=it, time_limit=tl),
        "piqp": with_gap,
        "proxqp": with_gap,
        "qpalm": _given(eps_abs=a, eps_rel=r, max_iter=it, time_limit=tl),
        "scs": _given(eps_abs=a, eps_rel=r, max_iters=it, time_limit_secs=tl),
    }
    return table.get(solver, {})


class QPSolversBackend(_StoredQP):
    """A qpsolvers solver, called afresh each step (qpsolvers sets up on every call).

    Dense-only solvers get dense matrices. ``x0`` goes to ``initvals`` only where the wrapper uses
    it (:data:`~mpcform.solvers.base.QPSOLVERS_WARM`).
    """

    def __init__(self, solver: str, options: SolverOptions) -> None:
        super().__init__(options)
        import qpsolvers

        if solver not in qpsolvers.available_solvers:
            raise SolverError(f"qpsolvers:{solver}", f'not installed: pip install "qpsolvers[{solver}]"')
        self._qpsolvers, self.solver = qpsolvers, solver
        self.name = f"qpsolvers:{solver}"
        self.warm_starts = solver in QPSOLVERS_WARM
        self._dense = solver not in qpsolvers.sparse_solvers
        self._settings = qpsolvers_settings(solver, options)

    def solve(self, x0: Array | None = None) -> QPSolution:
        if self._P is None:
            raise SolverError(self.name, "solve() before setup()")
        start = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                problem, rows = qpsolvers_form(self._P, self._q, self._A, self._lo, self._hi, self._dense)
                sol = self._qpsolvers.solve_problem(
                    problem, solver=self.solver, initvals=x0 if self.warm_starts else None, verbose=False,
                    **self._settings,
                )  # fmt: skip
        except Exception as exc:  # noqa: BLE001 - a solver's own error is this solve's failure status
            return failed(f"error: {type(exc).__name__}: {exc}", time.perf_counter() - start)
        elapsed = time.perf_counter() - start
        x = sol.x
        if not sol.found or x is None or not np.all(np.isfinite(x)):
            return failed("not found", elapsed)
        y = rows.duals(self._lo.shape[0], sol.y, sol.z)
        return QPSolution(np.array(x, dtype=float), y, True, "found", 0, elapsed)


# ---- casadi conic -----------------------------------------------------------------------------
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
        "osqp": {"osqp": _given(verbose=False, eps_abs=a, eps_rel=r, max_iter=it)},
        "qpoases": _given(
            printLevel="none",
            sparse=True,
            nWSR=it,
            CPUtime=tl,
            terminationTolerance=a,
        ),
        "proxqp": {"proxqp": _given(verbose=False, eps_abs=a, eps_rel=r, max_iter=it)},
        "daqp": {"daqp": _given(eps_prox=1e-6, primal_tol=a, dual_tol=a, iter_limit=it)},
        "piqp": {"piqp": _given(verbose=False, eps_abs=a, eps_rel=r, max_iter=it)},
        "ipqp": _given(
            print_iter=False,
            print_header=False,
            print_info=False,
            linear_solver="qr",
            constr_viol_tol=a,
            dual_inf_tol=a,
            max_iter=it,
        ),
        "hpipm": {"hpipm": _given(res_g_max=a, res_b_max=a, res_d_max=a, res_m_max=a, iter_max=it)},
    }
    return {"error_on_fail": False, "print_time": False, **per_plugin[plugin]}


def _casadi_sparse(casadi: Any, M: sp.spmatrix) -> Any:
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
        var_perm, np.array(order, dtype=np.intp), scale,
        [x.shape[0] for x in xs], [u.shape[0] for u in us] + [0], [len(c) for c in lincon],
    )  # fmt: skip


class CasadiConicBackend(_StoredQP):
    """casadi's ``conic`` interface with one plugin; the function is rebuilt when the pattern
    changes and casadi sets the solver up on every call. ``hpipm`` gets the QP in stage order
    (it needs the :class:`QPContext`)."""

    def __init__(self, plugin: str, options: SolverOptions) -> None:
        super().__init__(options)
        import casadi

        self._casadi, self.plugin = casadi, plugin
        self.name = f"casadi:{plugin}"
        self.warm_starts = plugin in CASADI_WARM
        self.needs_context = plugin == "hpipm"
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
        elapsed = time.perf_counter() - start
        iters = max(0, int(stats.get("iter_count", 0) or 0))
        status = str(stats.get("return_status", "unknown"))
        if not stats.get("success", False) or not np.all(np.isfinite(x)):
            return failed(status, elapsed, iters)
        return QPSolution(x, y, True, status, iters, elapsed)

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
        H_dm, A_dm = _casadi_sparse(ca, P), _casadi_sparse(ca, A)
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


# ---- casadi + ipopt on the exact problem --------------------------------------------------------
class CasadiIpoptBackend(_StoredQP):
    """ipopt on the exact non-convex problem behind the QP: the QP's cost and rows, with its
    linearised separation rows replaced by the true distance constraints of the
    :class:`QPContext` (at every position step). A quality reference, not a real-time solver: the
    NLP is built afresh for each solve."""

    name = "casadi:ipopt"
    warm_starts = True
    needs_context = True

    def __init__(self, options: SolverOptions) -> None:
        super().__init__(options)
        import casadi

        self._casadi = casadi
        o = options
        self._options = {
            "print_time": False, "error_on_fail": False,
            "ipopt": _given(print_level=0, sb="yes", tol=o.eps_abs, constr_viol_tol=o.eps_abs,
                            max_iter=o.max_iter,
                            max_cpu_time=o.time_limit_s if o.time_limit_s > 0 else None),
        }  # fmt: skip

    def solve(self, x0: Array | None = None) -> QPSolution:
        if self._P is None:
            raise SolverError(self.name, "solve() before setup()")
        if self._context is None:
            return failed("casadi:ipopt needs the exact separation problem (set_context)")
        start = time.perf_counter()
        try:
            with quiet_fds():
                x, stats = self._call(self._context, x0)
        except RuntimeError as exc:
            return failed(f"error: {' '.join(str(exc).split())[:300]}", time.perf_counter() - start)
        elapsed = time.perf_counter() - start
        iters = max(0, int(stats.get("iter_count", 0) or 0))
        status = str(stats.get("return_status", "unknown"))
        if not stats.get("success", False) or not np.all(np.isfinite(x)):
            return failed(status, elapsed, iters)
        return QPSolution(x, None, True, status, iters, elapsed)

    def _call(self, ctx: QPContext, x0: Array | None) -> tuple[Array, dict[str, Any]]:
        ca = self._casadi
        if self._P is None:
            raise SolverError(self.name, "solve() before setup()")
        z = ca.SX.sym("z", self._q.shape[0])
        f = 0.5 * ca.dot(z, ca.mtimes(_casadi_sparse(ca, self._P), z)) + ca.dot(ca.DM(self._q), z)
        keep = np.ones(self._lo.shape[0], dtype=bool)
        keep[ctx.separation_rows[0] : ctx.separation_rows[1]] = False
        g = [ca.mtimes(_casadi_sparse(ca, sp.csr_matrix(self._A)[keep]), z)]
        lbg, ubg = [self._lo[keep]], [self._hi[keep]]
        for lhs, required in exact_separation_terms(ca, z, ctx):
            g.append(lhs)
            lbg.append(np.full(lhs.shape[0], required) if np.ndim(required) == 0 else required)
            ubg.append(np.full(lhs.shape[0], np.inf))
        nlp = {"x": z, "f": f, "g": ca.vertcat(*g)}
        solver = ca.nlpsol("exact", "ipopt", nlp, self._options)
        out = solver(
            x0=np.zeros(ctx.n_var) if x0 is None else x0, lbg=np.concatenate(lbg), ubg=np.concatenate(ubg)
        )
        return np.array(out["x"], dtype=float).ravel(), dict(solver.stats())


def separation_indices(ctx: QPContext) -> tuple[Array, Array, Array, Array, Array, Array]:
    """Column indices for the exact constraints, per (item, step) row: first drone's positions
    (m, d), second drone's (m, d; pairs only), their slacks, and the constant offsets (m, d)."""
    n, d, h, nud = ctx.n, ctx.dim, ctx.horizon, ctx.nud
    steps = np.arange(h)

    def pos(drones: Array) -> Array:  # (items * H, d), item-major
        base = nud + (steps[None, :] * n + drones[:, None]) * d
        return (base[..., None] + np.arange(d)).reshape(-1, d)

    def slack(drones: Array) -> Array:
        return (2 * nud + steps[None, :] * n + drones[:, None]).ravel()

    i, k = ctx.pairs[:, 0], ctx.pairs[:, 1]
    pair_off = np.repeat(ctx.start_m[i] - ctx.start_m[k], h, axis=0)
    ob = ctx.obstacle_drones
    ob_off = np.repeat(ctx.start_m[ob] - ctx.obstacle_centers_m, h, axis=0)
    return pos(i), pos(k), slack(i), slack(k), np.vstack([pair_off, ob_off]), pos(ob)


def exact_separation_terms(lib: Any, z: Any, ctx: QPContext) -> list[tuple[Any, Any]]:
    """``(lhs, required)`` of the exact constraints ``lhs >= required`` for casadi symbols ``z``."""
    pi, pk, si, sk, off, po = separation_indices(ctx)
    terms: list[tuple[Any, Any]] = []
    m = pi.shape[0]
    if m:
        w = lib.DM(np.tile(ctx.metric, m))
        rel = (z[pi.ravel().tolist()] - z[pk.ravel().tolist()] + lib.DM(off[:m].ravel())) * w
        dist = lib.sqrt(lib.sum1(lib.reshape(rel, ctx.dim, m) ** 2) + 1e-12).T
        terms.append((dist + z[si.tolist()] + z[sk.tolist()], ctx.pair_distance_m))
    mo = po.shape[0]
    if mo:
        h = ctx.horizon
        rel = z[po.ravel().tolist()] + lib.DM(off[m:].ravel())
        dist = lib.sqrt(lib.sum1(lib.reshape(rel, ctx.dim, mo) ** 2) + 1e-12).T
        slack = (2 * ctx.nud + np.arange(h)[None, :] * ctx.n + ctx.obstacle_drones[:, None]).ravel()
        terms.append((dist + z[slack.tolist()], np.repeat(ctx.obstacle_distance_m, h)))
    return terms


def exact_separation_residual(ctx: QPContext, x: Array) -> float:
    """Largest violation [m] of the exact separation constraints by ``x`` (0 when met)."""
    pi, pk, si, sk, off, po = separation_indices(ctx)
    worst = 0.0
    m = pi.shape[0]
    if m:
        dist = np.linalg.norm((x[pi] - x[pk] + off[:m]) * ctx.metric, axis=1)
        worst = max(worst, float(np.max(ctx.pair_distance_m - dist - x[si] - x[sk], initial=0.0)))
    if po.shape[0]:
        h = ctx.horizon
        dist = np.linalg.norm(x[po] + off[m:], axis=1)
        slack = (2 * ctx.nud + np.arange(h)[None, :] * ctx.n + ctx.obstacle_drones[:, None]).ravel()
        need = np.repeat(ctx.obstacle_distance_m, h)
        worst = max(worst, float(np.max(need - dist - x[slack], initial=0.0)))
    return worst

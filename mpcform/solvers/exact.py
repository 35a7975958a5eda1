"""The exact non-convex problem behind the QP, solved by ipopt through casadi (``casadi:ipopt``).

Not a QP solver but a quality reference: the QP's cost and rows with its linearised separation
rows replaced by the true distance constraints of the :class:`~mpcform.solvers.base.QPContext`.
:func:`exact_separation_residual` measures how far any solution violates those constraints.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.errors import SolverError
from mpcform.solvers.base import QPContext, QPSolution, SolverOptions, failed, given
from mpcform.solvers.casadi_conic import casadi_solution, casadi_sparse
from mpcform.solvers.stored import StoredQP, quiet_fds


class CasadiIpoptBackend(StoredQP):
    """ipopt on the exact non-convex problem behind the QP: the QP's cost and rows, with its
    linearised separation rows replaced by the true distance constraints of the
    :class:`QPContext` (at every position step). A quality reference, not a real-time solver: the
    NLP is built afresh for each solve."""

    name = "casadi:ipopt"
    warm_starts = True
    needs_context = True
    point_obstacles_only = True  # the exact distance to a sphere's (a disc's) centre

    def __init__(self, options: SolverOptions) -> None:
        super().__init__(options)
        import casadi

        self._casadi = casadi
        o = options
        self._options = {
            "print_time": False,
            "error_on_fail": False,
            "ipopt": given(
                print_level=0,
                sb="yes",
                tol=o.eps_abs,
                constr_viol_tol=o.eps_abs,
                max_iter=o.max_iter,
                max_cpu_time=o.time_limit_s if o.time_limit_s > 0 else None,
            ),
        }

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
        return casadi_solution(x, None, stats, time.perf_counter() - start, self.objective(x))

    def _call(self, ctx: QPContext, x0: Array | None) -> tuple[Array, dict[str, Any]]:
        ca = self._casadi
        if self._P is None:
            raise SolverError(self.name, "solve() before setup()")
        z = ca.SX.sym("z", self._q.shape[0])
        f = 0.5 * ca.dot(z, ca.mtimes(casadi_sparse(ca, self._P), z)) + ca.dot(ca.DM(self._q), z)
        keep = np.ones(self._lo.shape[0], dtype=bool)
        keep[ctx.separation_rows[0] : ctx.separation_rows[1]] = False
        g = [ca.mtimes(casadi_sparse(ca, sp.csr_matrix(self._A)[keep]), z)]
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

"""Decoupled mode solved drone by drone: one small dense QP per drone, with DAQP.

In decoupled mode every separation row involves one drone, so the planner's sparse QP
(:mod:`mpcform.mpc.qp`) is block-diagonal per drone. Eliminating the positions
(``x_e = dt sum_{j<e} u_j``) leaves per drone ``H d`` inputs and ``H`` slacks::

    min  0.5 ||M u - c||^2 + w1 sum s + 0.5 w2 ||s||^2        M = I + k dt L (x) I_d
    s.t. D u_j <= h,  |u_j - u_{j-1}| <= a_max dt,  lo <= x_e <= hi,
         a_r^T x_{e_r} + s_{e_r} >= b_r,  s >= 0

(``L`` strictly lower triangular ones, so ``(M u)_j = u_j + k x_j``): the sparse QP's block,
with a positive-definite Hessian. Two things make it cheap:

- in the variables ``v = M u`` (``v_j = u_j + k x_j``, what the cost compares with ``c_j``) the
  cost is ``0.5 ||v - c||^2``: DAQP gets an identity Hessian (its cheapest setup), the constant
  rows are transformed once (with their bounds, when those are the same for every drone), and a
  separation row is a Kronecker product ``(w_e (x) a)^T v``, built only where it can be active;
- with a velocity loop (:mod:`mpcform.mpc.loop`) the rows are on the loop's positions
  ``x_e + sum_j G_{e,j} u_j``: only the table ``w_e`` changes (``u = M^-1 v`` is linear in v);
- the slacks are almost always zero, so each drone is first solved without them: if that hard
  QP is feasible, its solution (``s = 0``) is the drone's plan, else the soft QP is solved. The
  L1 penalty is exact once ``w1`` exceeds the hard QP's multipliers at every step; those grow
  with speed and shrink with ``dt`` (a fixed ``w1`` is not exact everywhere), so the hard
  optimum is taken whenever it exists: the limit of the soft optimum as ``w1`` grows.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

from mpcform._validate import Array
from mpcform.formation.geometry import vector_norms
from mpcform.mpc.limits import Limits
from mpcform.mpc.loop import VelocityLoop
from mpcform.mpc.problem import ACTIVE_TOL, StepQP, StepSolver
from mpcform.mpc.rows import LimitRows, positions_of_inputs, row_ends
from mpcform.mpc.settings import MPCSettings
from mpcform.solvers.base import QPSolution, failed

PER_DRONE_SOLVER = "daqp (per drone)"  # the planner's solver_name in decoupled mode with per_drone

DAQP_INF = 1e30  # DAQP's "no bound"
DAQP_OK = 1
PRIMAL_TOL = 1e-9  # DAQP row feasibility tolerance (its default 1e-6 shows in the plans)
MIN_SLACK_QUADRATIC = 1e-6  # keeps the soft QP's Hessian positive definite when w2 = 0
AT_BOUND_M = 1e-7  # a separation row this close to its bound counts as active (sensitivity)
GRAM_EPS = 1e-9  # relative regularisation of the active rows' Gram matrix (sensitivity)
Solved = tuple[QPSolution, int]  # a solution and its number of active rows


@dataclass(frozen=True)
class DroneSolves:
    """Every drone's DAQP solve (n drones, K separation rows kept, in drone order)."""

    v: Array  # (n, H d) the solutions in v = M u
    s: Array  # (n, H) slacks (zero where the hard QP was feasible)
    cost: Array  # (n,) objective values 0.5 ||v||^2 - c^T v (+ the slack penalty)
    flags: Array  # (n,) DAQP exit flags
    soft: Array  # (n,) the drones solved with slacks
    lams: list[Array]  # per drone, the rows' multipliers (soft: the slacks' H bounds, then constant
    # rows, then separation rows; a row at its lower bound has a multiplier <= 0)
    rows: Array  # (K,) the separation rows kept, as flat ``item * R + row`` indices
    offsets: Array  # (n + 1,) drone i's rows are ``rows[offsets[i]:offsets[i + 1]]``
    sep_c: Array  # (K, d) their coefficients
    sep_end: Array  # (K,) their position steps
    sep_lo: Array  # (K,) their lower bounds
    const_lo: Array  # (n or 1, rows) the constant rows' bounds (one row: the same for every drone)
    const_hi: Array
    iterations: int
    time_s: float  # inside DAQP


@dataclass(frozen=True)
class Sensitivity:
    """How one drone's optimum moves with its separation rows' lower bounds ``b`` on its active
    set (:meth:`PerDroneQP.sensitivity`): a separation rows active, r rows active in all (one-sided),
    q rows inactive."""

    active: Array  # (a,) the active separation rows (indices into the drone's rows)
    hessian: Array  # (a, a) d^2 f / db^2
    dv: Array  # (H d, a) dv / db
    dual: Array  # (r,) the active rows' multipliers y >= 0 (constant rows first)
    ddual: Array  # (r, a) dy / db
    const_rows: Array  # (2 c, H d) every drone's one-sided constant rows (shared, not copied)
    const_off: Array  # (2 c,) the inactive ones among them
    sep_rows: Array  # (q - q_c, H d) the inactive separation rows; all one-sided ``rows v >= bound``
    slack: Array  # (q,) how far the inactive rows are from their bounds (constant ones first)
    sep_index: Array  # (q,) an inactive separation row's index in the drone's rows, else -1

    def rate(self, dv: Array) -> Array:
        """How fast the inactive rows' values change (q,) along ``dv`` (H d,)."""
        return np.concatenate([(self.const_rows @ dv)[self.const_off], self.sep_rows @ dv])


class PerDroneQP(StepSolver):
    """The per-drone condensed QPs of the decoupled planner: everything constant built once.

    ``families`` are the limits' rows (:func:`mpcform.mpc.rows.limit_rows`).
    """

    name = PER_DRONE_SOLVER
    warm_starts = True  # nearly active rows of the warm start start DAQP's active set

    def __init__(
        self, dim: int, dt_s: float, limits: Limits, settings: MPCSettings, families: tuple[LimitRows, ...],
        loop: VelocityLoop | None = None,
    ) -> None:
        import daqp

        self._daqp = daqp
        self.dim, self.dt_s, self.limits, self.settings = dim, dt_s, limits, settings
        h, k = settings.horizon, settings.gain_per_s
        self._nu = nu = h * dim
        self.families = families
        self._x_of_u = positions_of_inputs(h, dim, dt_s)  # x_1..x_H from u
        self._m = np.eye(nu) + k * dt_s * np.kron(np.tril(np.ones((h, h)), -1), np.eye(dim))  # v = M u
        self._m_inv = solve_triangular(self._m, np.eye(nu), lower=True)  # u = M^-1 v
        rows = [family.dense() for family in families]  # constant rows over u; bounds per drone from _bounds
        self._const_v = (np.vstack(rows) if rows else np.zeros((0, nu))) @ self._m_inv
        self._const_pm = np.vstack([self._const_v, -self._const_v])  # one-sided: lower, then upper
        self._ends = row_ends(h)
        self._table = position_table(self._m_inv, h, dim, dt_s, loop).reshape(h, h, dim)  # x_e per axis
        self._x_of_v = (self._table[:, None] * np.eye(dim)[:, None, :]).reshape(nu, nu)  # x_1..x_H from v
        reach = 1.0 if loop is None else loop.reach_factor  # the longest step, with a loop's response
        self._step_m = None if limits.v_max_mps is None else limits.v_max_mps * dt_s * reach
        self._eye = np.eye(nu)
        w2 = max(settings.slack_quadratic, MIN_SLACK_QUADRATIC)
        self._hess_soft = np.diag(np.concatenate([np.full(h, w2), np.ones(nu)]))
        self._options: dict[str, Any] = {"iter_limit": settings.max_iter, "primal_tol": PRIMAL_TOL}
        self._a, self._lo, self._hi = np.zeros((0, nu)), np.zeros(0), np.zeros(0)
        self._fixed_bounds = all(family.fixed_bounds for family in families)

    def solve(self, qp: StepQP) -> tuple[QPSolution, int]:
        """Solve every drone's QP (the one-drone separation rows within reach of ``qp.rows``)."""
        rows = qp.rows
        warm_u = np.zeros_like(qp.targets_mps) if qp.warm is None else qp.warm[0]  # inputs only
        return self.solve_drones(
            qp.start_m, qp.targets_mps, qp.u_prev_mps, rows.singles, rows.single_coeffs, rows.single_lower,
            warm_u, rows.single_hard, rows.single_on,
        )  # fmt: skip

    def solve_drones(
        self, p0: Array, c: Array, u_prev: Array, singles: Array, coeffs: Array, lower: Array, warm_u: Array,
        hard: Array | None = None, on: Array | None = None,
    ) -> tuple[QPSolution, int]:
        """Solve every drone's QP.

        ``p0`` (n, d) starts, ``c`` (H, n, d) targets, ``u_prev`` (n, d) last commands; separation
        items ``singles`` (S,) drone index, ``coeffs`` (S, R, d), ``lower`` (S, R); ``warm_u``
        (H, n, d) inputs whose nearly active rows start DAQP's active set; ``hard`` (S,) the items
        whose first row is a hard no-approach row (no slack); ``on`` (S,) the items within reach
        (the others are left out; all by default).
        Returns the solution in the sparse QP's layout ``[u | x | s]`` over these n drones (its
        ``solve_time_s`` is the time spent inside DAQP), and the number of active rows.
        """
        got = self.solve_each(p0, c, u_prev, singles, coeffs, lower, warm_u, hard, on)
        return self.solution(got.v, got.s, got.flags, got.lams, got.iterations, got.time_s)

    def solve_each(
        self, p0: Array, c: Array, u_prev: Array, singles: Array, coeffs: Array, lower: Array, warm_u: Array,
        hard: Array | None = None, on: Array | None = None,
    ) -> DroneSolves:
        """Every drone's solve as DAQP returns it (arguments as :meth:`solve_drones`)."""
        st = self.settings
        h, n, nu, n_const = st.horizon, p0.shape[0], self._nu, self._const_v.shape[0]
        c_v = c.transpose(1, 0, 2).reshape(n, nu)
        f_v = -c_v  # 0.5 ||v - c||^2
        v_warm = warm_u.transpose(1, 0, 2).reshape(n, nu) @ self._m.T
        sep_c, sep_end, sep_lo, sep_soft, counts, at = reachable_rows(n, singles, coeffs, lower, hard, on,
                                                                      self._ends, self._step_m)  # fmt: skip
        a, lo, hi = self._buffers(int(counts.max(initial=0)))
        bounds = None if self._fixed_bounds else self._bounds(p0, u_prev)  # else in the buffers
        offsets = [0, *np.cumsum(counts).tolist()]
        v_out, s_out, flags, lams = [np.empty(0)] * n, np.zeros((n, h)), [DAQP_OK] * n, [np.empty(0)] * n
        cost, free = np.zeros(n), self._free(c_v, bounds, sep_c, sep_end, sep_lo, counts)
        if free.any():  # the unconstrained optimum, no row active
            sq = np.zeros(int(free.sum()))
            for col in c_v[free].T:  # summed in order, as DAQP sums its cost (bit for bit)
                sq += col * col
            cost[free] = -0.5 * sq
            zero = np.zeros(n_const + int(counts.max(initial=0)))
            zero.flags.writeable = False  # views of it are the free drones' multipliers
            for i in np.flatnonzero(free).tolist():
                v_out[i], lams[i] = c_v[i], zero[: n_const + counts[i]]
        iters, in_daqp = 0, 0.0

        def put(i: int) -> int:
            """Put drone i's rows over v and their bounds into the buffers; return their number."""
            first, last = offsets[i], offsets[i + 1]
            m = n_const + last - first
            self._rows_v(sep_c[first:last], sep_end[first:last], out=a[n_const:m])
            lo[n_const:m] = sep_lo[first:last]
            if bounds is not None:
                lo[:n_const], hi[:n_const] = bounds[0][i], bounds[1][i]
            return m

        solve, eye, options = self._daqp.solve, self._eye, self._options
        for i in np.flatnonzero(~free).tolist():  # the hard QPs
            m = put(i)
            t0 = time.perf_counter()
            v_out[i], cost[i], flags[i], info = solve(
                eye, f_v[i], a[:m], hi[:m], lo[:m], primal_start=v_warm[i], **options
            )  # fmt: skip
            in_daqp += time.perf_counter() - t0
            iters += info["iterations"]
            lams[i] = info["lam"]
        soft = [i for i in range(n) if flags[i] != DAQP_OK]  # else the hard optimum (s = 0)
        for i in soft:
            m, first, last = put(i), offsets[i], offsets[i + 1]
            t0 = time.perf_counter()
            v_out[i], s_out[i], flags[i], cost[i], info = self._solve_soft(
                f_v[i], a[:m], hi[:m], lo[:m], sep_end[first:last], sep_soft[first:last], n_const
            )  # fmt: skip
            in_daqp += time.perf_counter() - t0
            iters += info["iterations"]
            lams[i] = info["lam"]
        v_all = np.array(v_out).reshape(n, nu)
        const_bounds = (lo[None, :n_const].copy(), hi[None, :n_const].copy()) if bounds is None else bounds
        is_soft = np.zeros(n, dtype=bool)
        is_soft[soft] = True
        return DroneSolves(v_all, s_out, cost, np.array(flags), is_soft, lams, at, np.array(offsets), sep_c,
                           sep_end, sep_lo, *const_bounds, int(iters), in_daqp)  # fmt: skip

    def solution(self, v: Array, s: Array, flags: Array, lams: list[Array], iters: int, t_s: float) -> Solved:
        """The drones' solves (``v`` (n, H d), slacks ``s`` (n, H), DAQP's exit flags and
        multipliers; ``t_s`` the time in DAQP) as one solution ``[u | x | s]`` (as :meth:`solve_drones`
        returns it)."""
        h, n = self.settings.horizon, v.shape[0]
        bad = np.flatnonzero((flags != DAQP_OK) | ~np.isfinite(v).all(axis=1))
        if bad.size:
            status = f"daqp: exit flag {flags[bad[0]]} (drone {bad[0]})"
            return failed(status, t_s, iters), 0
        u_out, x_out = self.inputs_positions(v)
        flat = [w.reshape(n, h, -1).transpose(1, 0, 2).ravel() for w in (u_out, x_out, s)]
        sol = QPSolution(np.concatenate(flat), None, True, "daqp: optimal", iters, t_s)
        active = np.count_nonzero(np.abs(np.concatenate(lams)) > ACTIVE_TOL) if n else 0
        return sol, int(active)

    def inputs_positions(self, v: Array) -> tuple[Array, Array]:
        """Inputs and relative positions (n, H d) (step-major within a drone) of solutions ``v``
        (n, H d): ``u = M^-1 v``, ``x_e = dt sum_{j<e} u_j``."""
        u = v @ self._m_inv.T
        return u, u @ self._x_of_u.T

    def multipliers(self, solves: DroneSolves, i: int, everything: bool = False) -> Array:
        """Drone i's multipliers of its separation rows (>= 0: the derivative of its optimal cost in
        the rows' lower bounds), or with ``everything`` of its constant rows first."""
        lam = solves.lams[i][self.settings.horizon if solves.soft[i] else 0 :]
        return lam if everything else -lam[self._const_v.shape[0] :]

    def sensitivity(self, solves: DroneSolves, i: int) -> Sensitivity:
        """How drone i's optimum moves with its separation rows' lower bounds on its active set:
        every row one-sided, ``a^T v >= b`` (a constant row's bounds as two rows), multiplier
        ``y >= 0``; active: a multiplier, or within :data:`AT_BOUND_M` of the bound. There
        (identity Hessian; a soft drone's slacks ignored) ``v = c + A^T y``, ``y = (A A^T)^-1 (b -
        A c)``: ``d^2 f / db^2 = dy / db = (A A^T)^-1``, ``dv / db = A^T (A A^T)^-1``; regularised
        (:data:`GRAM_EPS`) so that dependent rows (a segment's two ends at one step) get a large
        curvature, not none. The inactive constant rows stay shared (a mask, not a copy)."""
        n_const, first, last = self._const_v.shape[0], solves.offsets[i], solves.offsets[i + 1]
        lam, v, both = self.multipliers(solves, i, everything=True), solves.v[i], self._const_pm
        lo, hi = (b[min(i, b.shape[0] - 1)] for b in (solves.const_lo, solves.const_hi))
        sep = self._rows_v(solves.sep_c[first:last], solves.sep_end[first:last])
        bound = np.concatenate([lo, -hi, solves.sep_lo[first:last]])
        y = np.concatenate([np.maximum(-lam[:n_const], 0.0), np.maximum(lam[:n_const], 0.0), -lam[n_const:]])
        gap = np.concatenate([both @ v, sep @ v]) - bound
        real = np.abs(bound) < DAQP_INF / 2
        on = real & ((y > ACTIVE_TOL) | (gap <= AT_BOUND_M))
        off, c2 = real & ~on, 2 * n_const
        active = np.concatenate([both[on[:c2]], sep[on[c2:]]])
        gram = active @ active.T
        gram.flat[:: gram.shape[0] + 1] += GRAM_EPS * max(1.0, float(np.diag(gram).max(initial=0.0)))
        sep_on = np.flatnonzero(on[c2:])
        k = np.linalg.inv(gram)[:, on[:c2].sum() :]  # columns: the active separation rows
        idx = np.flatnonzero(off)
        sep_index = np.where(idx >= c2, idx - c2, -1)
        return Sensitivity(sep_on, k[-sep_on.shape[0] :] if sep_on.size else k[:0], active.T @ k, y[on], k,
                           both, off[:c2], sep[off[c2:]], gap[off], sep_index)  # fmt: skip

    def _rows_v(self, coeffs: Array, end: Array, out: Array | None = None) -> Array:
        """Separation rows (K, H d) over ``v`` (into ``out``) of coefficients ``coeffs`` (K, d) at
        position steps ``end`` (K,): ``a^T x_e = (w_e (x) a)^T v``."""
        rows = np.empty((end.shape[0], self._nu)) if out is None else out
        table = self._table.take(end - 1, axis=0)  # (K, H, d)
        np.multiply(table, coeffs[:, None], out=rows.reshape(table.shape))
        return rows

    def _free(
        self, c_v: Array, bounds: tuple[Array, Array] | None, sep_c: Array, sep_end: Array, sep_lo: Array,
        counts: Array,
    ) -> Array:
        """The drones (n,) whose unconstrained optimum ``v = c`` (``c_v`` (n, H d)) meets every row:
        it is their solve (no row active; DAQP returns it bitwise), without a DAQP call."""
        n, n_const, const = c_v.shape[0], self._const_v.shape[0], c_v @ self._const_v.T
        lo, hi = (self._lo[None, :n_const], self._hi[None, :n_const]) if bounds is None else bounds
        free = ((const >= lo) & (const <= hi)).all(axis=1)
        if not free.any():
            return free
        x = (c_v @ self._x_of_v.T).reshape(-1, self.dim)  # x_e at v = c, rows (drone, step e)
        owner = np.repeat(np.arange(n), counts)
        missed = np.einsum("kd,kd->k", sep_c, x[owner * self.settings.horizon + sep_end - 1]) < sep_lo
        free[owner[missed]] = False
        return free

    def _buffers(self, max_sep: int) -> tuple[Array, Array, Array]:
        """Row and bound buffers with room for ``max_sep`` separation rows after the constant ones
        (kept between calls; only the separation part and per-drone bounds are rewritten)."""
        n_const = self._const_v.shape[0]
        if self._a.shape[0] < n_const + max_sep:
            size = n_const + max(max_sep, 2 * (self._a.shape[0] - n_const))
            self._a = np.empty((size, self._nu))
            self._a[:n_const] = self._const_v
            self._lo, self._hi = np.empty(size), np.full(size, DAQP_INF)
            if self._fixed_bounds:  # the same for every drone at every step
                lo, hi = self._bounds(np.zeros((1, self.dim)), np.zeros((1, self.dim)))
                self._lo[:n_const], self._hi[:n_const] = lo[0], hi[0]
        return self._a, self._lo, self._hi

    def _solve_soft(
        self, f_v: Array, a: Array, hi: Array, lo: Array, end: Array, soft: Array, n_const: int
    ) -> tuple[Array, Array, int, float, dict[str, Any]]:
        """The drone's QP with its slacks (first, simple bounds ``s >= 0``; Hessian ``diag(w2, I)``).

        The slacks are not scaled to a unit Hessian: a column ``1 / sqrt(w2)`` would scale DAQP's
        row tolerance up with it (measured: 3.5e-8 misses at ``w2 = 0``)."""
        st, h = self.settings, self.settings.horizon
        a_s = np.zeros((a.shape[0], h))
        a_s[n_const + np.arange(end.shape[0]), end - 1] = soft
        f = np.concatenate([np.full(h, st.slack_weight), f_v])
        z, cost, flag, info = self._daqp.solve(
            self._hess_soft, f, np.hstack([a_s, a]), np.concatenate([np.full(h, DAQP_INF), hi]),
            np.concatenate([np.zeros(h), lo]), **self._options,
        )  # fmt: skip
        return z[h:], z[:h], flag, cost, info

    def _bounds(self, p0: Array, u_prev: Array) -> tuple[Array, Array]:
        """Lower and upper bounds (n, rows) of the constant rows for each drone."""
        n = p0.shape[0]
        if not self.families:
            return np.zeros((n, 0)), np.zeros((n, 0))
        lo, hi = zip(*(family.dense_bounds(p0, u_prev, DAQP_INF) for family in self.families), strict=True)
        return np.hstack(lo), np.hstack(hi)


def position_table(m_inv: Array, h: int, dim: int, dt_s: float, loop: VelocityLoop | None) -> Array:
    """The table (H, H d) of ``w_e (x) 1_d`` per position step e, rows over ``v``.

    ``x_e = dt sum_{j<e} u_j = (sum_{j<e} dt M^-1[(j, .), :]) v`` and ``M^-1 = T (x) I_d``, so
    ``x_e = (w_e (x) I_d) v`` and ``a^T x_e = (w_e (x) a)^T v``. With a velocity ``loop`` the rows
    are on its positions, ``+ sum_j G_{e,j} u_j`` with ``u_j = sum_m T[j, m] v_m`` (per axis)."""
    nu = h * dim
    x_v = dt_s * np.cumsum(m_inv.reshape(h, dim, nu), axis=0)
    table = np.einsum("echc->ehc", x_v.reshape(h, dim, h, dim)).reshape(h, nu)
    if loop is not None:
        t = m_inv.reshape(h, dim, h, dim)[:, 0, :, 0]
        table += np.einsum("ejd,jm->emd", loop.forced[1:], t).reshape(h, nu)
    return table


def reachable_rows(
    n: int, singles: Array, coeffs: Array, lower: Array, hard: Array | None, on: Array | None, ends: Array,
    step_m: float | None,
) -> tuple[Array, Array, Array, Array, Array, Array]:
    """The separation rows that can be active, sorted by drone (item order kept within a drone):
    their coefficients ``a`` (K, d), position steps, lower bounds and whether they have a slack
    (not an item's hard first row); the number of rows per drone; and which they are (K,), as
    flat ``item * R + row`` indices (items ``singles`` (S,), ``coeffs`` (S, R, d), ``lower`` (S, R),
    rows at position steps ``ends`` (R,)).

    A row ``a^T x_e + s_e >= b`` that every reachable ``x_e`` meets (``b <= -|a| e step_m``, the
    longest step ``step_m`` = v_max dt, since the velocity set lies in the ball; None: no limit) is
    left out, the optimum unchanged. The rows over ``v`` are built later, drone by drone into
    DAQP's buffer (:meth:`PerDroneQP._rows_v`).
    """
    keep = np.ones(lower.shape, dtype=bool)
    if on is not None:
        keep &= on[:, None]
    if step_m is not None:
        keep &= lower > -(vector_norms(coeffs) * (ends * step_m))
    order = np.argsort(singles, kind="stable")
    rows = ends.shape[0]
    at = (order[:, None] * rows + np.arange(rows))[keep[order]]  # flat (item, row) indices
    item, r = np.divmod(at, rows)
    soft = r > 0
    if hard is not None:
        soft |= ~hard[item]
    counts = np.bincount(singles[item], minlength=n).astype(np.intp)
    sep_c = np.take(coeffs.reshape(-1, coeffs.shape[2]), at, axis=0)
    return sep_c, ends[r], np.take(lower.reshape(-1), at), soft, counts, at

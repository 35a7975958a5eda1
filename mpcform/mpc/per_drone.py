"""Decoupled mode solved drone by drone: one small dense QP per drone (DAQP by default).

In decoupled mode every separation row involves one drone, so the planner's sparse QP
(:mod:`mpcform.mpc.qp`) is block-diagonal per drone. Eliminating the positions
(``x_e = dt sum_{j<e} u_j``) leaves per drone ``H d`` inputs and ``H`` slacks::

    min  0.5 ||M u - c||^2 + w1 sum s + 0.5 w2 ||s||^2        M = I + k dt L (x) I_d
    s.t. D u_j <= h,  |u_j - u_{j-1}| <= a_max dt,  lo <= x_e <= hi,
         a_r^T x_{e_r} + s_{e_r} >= b_r,  s >= 0

(``L`` strictly lower triangular ones, so ``(M u)_j = u_j + k x_j``): the sparse QP's block,
with a positive-definite Hessian, solved by a per-drone backend
(:class:`~mpcform.solvers.dense.DenseQPBackend`, chosen by :class:`~mpcform.mpc.strategy.PerDroneSolve`;
"DAQP" below is whichever it is). Two things make it cheap:

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
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import solve_triangular

from mpcform._validate import Array
from mpcform.mpc.loop import VelocityLoop
from mpcform.mpc.problem import ACTIVE_TOL, StepQP, StepSolver
from mpcform.mpc.rows import LimitRows, position_table, positions_of_inputs, row_ends
from mpcform.mpc.sensitivity import Sensitivity, drone_sensitivity
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.working_set import (
    misses,
    reachable_rows,
    row_values,
    separation_misses,
    separation_sets,
    stack,
    within_bounds,
    working_sets,
)
from mpcform.solvers.base import QPSolution, failed
from mpcform.solvers.dense import NO_BOUND, DenseQPBackend, DenseSolution
from mpcform.world.limits import Limits

MIN_SLACK_QUADRATIC = 1e-6  # keeps the soft QP's Hessian positive definite when w2 = 0
Solved = tuple[QPSolution, int]  # a solution and its number of active rows


@dataclass(frozen=True)
class DroneSolves:
    """Every drone's DAQP solve (n drones, K separation rows kept, in drone order)."""

    v: Array  # (n, H d) the solutions in v = M u
    s: Array  # (n, H) slacks (zero where the hard QP was feasible)
    cost: Array  # (n,) objective values 0.5 ||v||^2 - c^T v (+ the slack penalty)
    flags: Array  # (n,) the backend's exit flags
    ok: Array  # (n,) the solves that succeeded
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


class PerDroneQP(StepSolver):
    """The per-drone condensed QPs of the decoupled planner: everything constant built once.

    ``families`` are the limits' rows (:func:`mpcform.mpc.rows.limit_rows`); ``backend`` solves
    each drone's QP (its name, with " (per drone)", is the planner's ``solver_name``).
    """

    warm_starts = True  # nearly active rows of the warm start start DAQP's active set

    def __init__(
        self,
        dim: int,
        dt_s: float,
        limits: Limits,
        settings: MPCSettings,
        families: tuple[LimitRows, ...],
        backend: DenseQPBackend,
        loop: VelocityLoop | None = None,
    ) -> None:
        self.backend, self.name = backend, f"{backend.name} (per drone)"
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
        self._a, self._lo, self._hi = np.zeros((0, nu)), np.zeros(0), np.zeros(0)  # _buffers
        fixed = all(family.fixed_bounds for family in families)  # the same for every drone at every step
        self._fixed = dense_bounds(families, np.zeros((1, dim)), np.zeros((1, dim))) if fixed else None

    def solve(self, qp: StepQP) -> tuple[QPSolution, int]:
        """Solve every drone's QP (the one-drone separation rows within reach of ``qp.rows``)."""
        rows = qp.rows
        warm_u = np.zeros_like(qp.targets_mps) if qp.warm is None else qp.warm[0]  # inputs only
        return self.solve_drones(
            qp.start_m,
            qp.targets_mps,
            qp.u_prev_mps,
            rows.singles,
            rows.single_coeffs,
            rows.single_lower,
            warm_u,
            rows.single_hard,
            rows.single_on,
        )

    def solve_drones(
        self,
        p0: Array,
        c: Array,
        u_prev: Array,
        singles: Array,
        coeffs: Array,
        lower: Array,
        warm_u: Array,
        hard: Array | None = None,
        on: Array | None = None,
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
        return self.solution(got.v, got.s, got.ok, got.flags, got.lams, got.iterations, got.time_s)

    def solve_each(
        self,
        p0: Array,
        c: Array,
        u_prev: Array,
        singles: Array,
        coeffs: Array,
        lower: Array,
        warm_u: Array,
        hard: Array | None = None,
        on: Array | None = None,
    ) -> DroneSolves:
        """Every drone's solve as DAQP returns it (arguments as :meth:`solve_drones`).

        With working sets (:func:`mpcform.mpc.working_set.working_sets`), each drone first gives DAQP
        only its rows near their bound; a solve that misses any other row, or fails, is solved again
        with all of them."""
        st = self.settings
        h, n, nu, n_const = st.horizon, p0.shape[0], self._nu, self._const_v.shape[0]
        c_v = c.transpose(1, 0, 2).reshape(n, nu)
        f_v = -c_v  # 0.5 ||v - c||^2
        v_warm = warm_u.transpose(1, 0, 2).reshape(n, nu) @ self._m.T
        sep_c, sep_end, sep_lo, sep_soft, counts, at = reachable_rows(
            n, singles, coeffs, lower, hard, on, self._ends, self._step_m
        )
        a, lo, hi = self._buffers(n_const + int(counts.max(initial=0)))
        b_lo, b_hi = self._fixed if self._fixed is not None else dense_bounds(self.families, p0, u_prev)
        offsets = [0, *np.cumsum(counts).tolist()]
        v_out, s_out, lams = [np.empty(0)] * n, np.zeros((n, h)), [np.empty(0)] * n
        flags, ok = [0] * n, [True] * n
        const_c, owner = c_v @ self._const_v.T, np.repeat(np.arange(n), counts)
        at_x = owner * h + sep_end - 1  # each row's position x_e among the drones'
        cost, free, sep_c_at = np.zeros(n), within_bounds(const_c, b_lo, b_hi), None
        if free.any():  # the wish v = c meets the constant rows: and the separation rows?
            sep_c_at = row_values(self._x_of_v, c_v, sep_c, at_x)
            free[owner[sep_c_at < sep_lo]] = False
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

        def keep(i: int, got: DenseSolution, t0: float) -> Array:
            """Drone i's solve ``got`` (started at ``t0``) recorded; its multipliers."""
            nonlocal iters, in_daqp
            in_daqp += time.perf_counter() - t0
            v_out[i], cost[i], flags[i], ok[i] = got.x, got.cost, got.exit_flag, got.success
            iters += got.iterations
            return got.multipliers

        def hard_qp(i: int, aa: Array, hh: Array, ll: Array) -> Array:
            """Drone i's hard QP with the rows ``aa`` and bounds; its multipliers."""
            t0 = time.perf_counter()
            return keep(i, self.backend.solve(self._eye, f_v[i], aa, hh, ll, v_warm[i]), t0)

        def solve(i: int, soft: bool = False) -> None:
            """Drone i's hard (or ``soft``) QP with all its rows, in the buffer; its multipliers."""
            first, last = offsets[i], offsets[i + 1]
            m = n_const + last - first
            if self._fixed is None:
                lo[:n_const], hi[:n_const] = b_lo[i], b_hi[i]
            self._rows_v(sep_c[first:last], sep_end[first:last], out=a[n_const:m])
            lo[n_const:m] = sep_lo[first:last]
            if not soft:
                lams[i] = hard_qp(i, a[:m], hi[:m], lo[:m])
                return
            t0 = time.perf_counter()
            got = self._solve_soft(
                f_v[i], a[:m], hi[:m], lo[:m], sep_end[first:last], sep_soft[first:last], n_const
            )
            lams[i] = keep(i, replace(got, x=got.x[h:]), t0)
            s_out[i] = got.x[:h]

        busy = np.flatnonzero(~free)
        near = working_sets(self._const_v, const_c, v_warm, b_lo, b_hi, busy)
        if near is None:
            for i in busy.tolist():
                solve(i)
        else:  # working sets, all in one stack; any drone that missed a row left out or failed: all rows
            if sep_c_at is None:
                sep_c_at = row_values(self._x_of_v, c_v, sep_c, at_x)
            given = separation_sets(sep_c_at, row_values(self._x_of_v, v_warm, sep_c, at_x), sep_lo)
            g = np.flatnonzero(given & ~free[owner])
            of_g, place = owner[g], np.cumsum(~free) - 1  # a busy drone's place among them
            stk = stack(
                self._const_v,
                near,
                b_lo,
                b_hi,
                busy,
                self._rows_v(sep_c[g], sep_end[g]),
                sep_lo[g],
                place[of_g],
                g - np.asarray(offsets)[of_g],
                counts[busy],
                NO_BOUND,
            )
            cuts, fs = stk.starts, stk.full_starts
            parts = [
                hard_qp(
                    i,
                    stk.a[cuts[j] : cuts[j + 1]],
                    stk.hi[cuts[j] : cuts[j + 1]],
                    stk.lo[cuts[j] : cuts[j + 1]],
                )
                for j, i in enumerate(busy.tolist())
            ]
            every = np.zeros(fs[-1])
            every[stk.full] = np.concatenate(parts)
            for j, i in enumerate(busy.tolist()):
                lams[i] = every[fs[j] : fs[j + 1]]
            v_all = np.array(v_out)
            again = misses(self._const_v, v_all[busy], near, b_lo, b_hi, busy)
            at_v = row_values(self._x_of_v, v_all, sep_c, at_x)
            again |= separation_misses(at_v, sep_lo, given, owner, n)[busy]
            for i in busy[again | ~np.array(ok)[busy]].tolist():
                solve(i)
        soft = [i for i in range(n) if not ok[i]]  # else the hard optimum (s = 0)
        for i in soft:
            solve(i, soft=True)
        v_all = np.array(v_out).reshape(n, nu)
        is_soft = np.zeros(n, dtype=bool)
        is_soft[soft] = True
        return DroneSolves(
            v_all,
            s_out,
            cost,
            np.array(flags),
            np.array(ok),
            is_soft,
            lams,
            at,
            np.array(offsets),
            sep_c,
            sep_end,
            sep_lo,
            b_lo,
            b_hi,
            int(iters),
            in_daqp,
        )

    def solution(
        self, v: Array, s: Array, ok: Array, flags: Array, lams: list[Array], iters: int, t_s: float
    ) -> Solved:
        """The drones' solves (``v`` (n, H d), slacks ``s`` (n, H), which succeeded, the backend's
        exit flags and multipliers; ``t_s`` the time in the backend) as one solution ``[u | x | s]``
        (as :meth:`solve_drones` returns it)."""
        h, n = self.settings.horizon, v.shape[0]
        bad = np.flatnonzero(~ok | ~np.isfinite(v).all(axis=1))
        if bad.size:
            status = f"{self.backend.name}: exit flag {flags[bad[0]]} (drone {bad[0]})"
            return failed(status, t_s, iters), 0
        u_out, x_out = self.inputs_positions(v)
        flat = [w.reshape(n, h, -1).transpose(1, 0, 2).ravel() for w in (u_out, x_out, s)]
        sol = QPSolution(np.concatenate(flat), None, True, f"{self.backend.name}: optimal", iters, t_s)
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

    def separation_multipliers(self, solves: DroneSolves) -> list[Array]:
        """Every drone's :meth:`multipliers` of its separation rows, negated in one pass (views of
        one array)."""
        hard, soft = self._const_v.shape[0], self._const_v.shape[0] + self.settings.horizon  # rows to skip
        parts = [lam[soft if s else hard :] for lam, s in zip(solves.lams, solves.soft.tolist(), strict=True)]
        mu, cuts = -np.concatenate(parts), solves.offsets.tolist()
        return [mu[a:b] for a, b in zip(cuts[:-1], cuts[1:], strict=True)]

    def sensitivity(self, solves: DroneSolves, i: int) -> Sensitivity:
        """How drone i's optimum moves with its separation rows' lower bounds on its active set
        (:func:`mpcform.mpc.sensitivity.drone_sensitivity`)."""
        first, last, b = solves.offsets[i], solves.offsets[i + 1], min(i, solves.const_lo.shape[0] - 1)
        sep = self._rows_v(solves.sep_c[first:last], solves.sep_end[first:last])
        lam = self.multipliers(solves, i, everything=True)
        lo, hi = solves.const_lo[b], solves.const_hi[b]
        return drone_sensitivity(lam, solves.v[i], self._const_pm, sep, lo, hi, solves.sep_lo[first:last])

    def _rows_v(self, coeffs: Array, end: Array, out: Array | None = None) -> Array:
        """Separation rows (K, H d) over ``v`` (into ``out``) of coefficients ``coeffs`` (K, d) at
        position steps ``end`` (K,): ``a^T x_e = (w_e (x) a)^T v``."""
        rows = np.empty((end.shape[0], self._nu)) if out is None else out
        table = self._table.take(end - 1, axis=0)  # (K, H, d)
        np.multiply(table, coeffs[:, None], out=rows.reshape(table.shape))
        return rows

    def _buffers(self, size: int) -> tuple[Array, Array, Array]:
        """Row and bound buffers with room for ``size`` rows (kept between calls; the constant rows
        first: only the separation part and per-drone bounds are rewritten)."""
        if self._a.shape[0] < size:
            size = max(size, 2 * self._a.shape[0])
            self._a, self._lo, self._hi = np.empty((size, self._nu)), np.empty(size), np.full(size, NO_BOUND)
            n_const = self._const_v.shape[0]
            self._a[:n_const] = self._const_v
            if self._fixed is not None:  # the same bounds for every drone at every step: kept here
                self._lo[:n_const], self._hi[:n_const] = self._fixed[0][0], self._fixed[1][0]
        return self._a, self._lo, self._hi

    def _solve_soft(
        self, f_v: Array, a: Array, hi: Array, lo: Array, end: Array, soft: Array, n_const: int
    ) -> DenseSolution:
        """The drone's QP with its slacks (first, simple bounds ``s >= 0``; Hessian ``diag(w2, I)``):
        its solution ``[s | v]``.

        The slacks are not scaled to a unit Hessian: a column ``1 / sqrt(w2)`` would scale DAQP's
        row tolerance up with it (measured: 3.5e-8 misses at ``w2 = 0``)."""
        st, h = self.settings, self.settings.horizon
        a_s = np.zeros((a.shape[0], h))
        a_s[n_const + np.arange(end.shape[0]), end - 1] = soft
        f = np.concatenate([np.full(h, st.slack_weight), f_v])
        return self.backend.solve(
            self._hess_soft,
            f,
            np.hstack([a_s, a]),
            np.concatenate([np.full(h, NO_BOUND), hi]),
            np.concatenate([np.zeros(h), lo]),
        )


def dense_bounds(families: tuple[LimitRows, ...], p0: Array, u_prev: Array) -> tuple[Array, Array]:
    """Lower and upper bounds (n, rows) of the constant rows of ``families`` for each drone (starts
    ``p0``, last commands ``u_prev`` (n, d)); :data:`~mpcform.solvers.dense.NO_BOUND` where a row has none."""
    n = p0.shape[0]
    if not families:
        return np.zeros((n, 0)), np.zeros((n, 0))
    lo, hi = zip(*(family.dense_bounds(p0, u_prev, NO_BOUND) for family in families), strict=True)
    return np.hstack(lo), np.hstack(hi)

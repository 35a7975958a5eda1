"""One drone's QP of decoupled mode, condensed: the matrices built once (:mod:`mpcform.mpc.solve.per_drone`
solves it).

In decoupled mode every separation row involves one drone, so the planner's sparse QP
(:mod:`mpcform.mpc.solve.sparse_qp`) is block-diagonal per drone. Eliminating the positions
(``x_e = dt sum_{j<e} u_j``) leaves per drone ``H d`` inputs and ``H`` slacks::

    min  0.5 ||M u - c||^2 + w1 sum s + 0.5 w2 ||s||^2        M = I + k dt L (x) I_d
    s.t. D u_j <= h,  |u_j - u_{j-1}| <= a_max dt,  lo <= x_e <= hi,
         a_r^T x_{e_r} + s_{e_r} >= b_r,  s >= 0

(``L`` strictly lower triangular ones, so ``(M u)_j = u_j + k x_j``): the sparse QP's block,
with a positive-definite Hessian. In the variables ``v = M u`` (``v_j = u_j + k x_j``, what the
cost compares with ``c_j``) the cost is ``0.5 ||v - c||^2``: the solver gets an identity Hessian
(DAQP's cheapest setup), the constant rows are transformed once (with their bounds, when those
are the same for every drone), and a separation row is a Kronecker product ``(w_e (x) a)^T v``.
With a velocity loop (:mod:`mpcform.mpc.velocity_loop`) the rows are on the loop's positions
``x_e + sum_j G_{e,j} u_j``: only the table ``w_e`` changes (``u = M^-1 v`` is linear in v).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

from mpcform._blas import one_thread
from mpcform._validate import Array
from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.rows import position_table, positions_of_inputs, row_ends
from mpcform.mpc.constraints.tail import planner_tail
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.drone_solves import DroneSolves
from mpcform.mpc.solve.sensitivity import Sensitivity, drone_sensitivity
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.solvers.dense import NO_BOUND
from mpcform.world.bounds import PlanningBounds

MIN_SLACK_QUADRATIC = 1e-6  # keeps the soft QP's Hessian positive definite when w2 = 0


class CondensedDroneQP:
    """The matrices of every drone's condensed QP (the same for each drone): ``families`` are the
    limits' rows (:func:`mpcform.mpc.constraints.rows.limit_rows`)."""

    def __init__(
        self,
        dim: int,
        dt_s: float,
        limits: PlanningBounds,
        settings: MPCSettings,
        families: tuple[LimitRows, ...],
        loop: VelocityLoop | None = None,
    ) -> None:
        self.dim, self.dt_s, self.limits, self.settings = dim, dt_s, limits, settings
        h, k = settings.horizon, settings.gain_per_s
        self._nu = nu = h * dim
        self.families = families
        self._x_of_u = positions_of_inputs(h, dim, dt_s)  # x_1..x_H from u
        self._m = np.eye(nu) + k * dt_s * np.kron(np.tril(np.ones((h, h)), -1), np.eye(dim))  # v = M u
        with one_thread():  # no spinning thread pool through the first steps (mpcform._blas)
            self._m_inv = solve_triangular(self._m, np.eye(nu), lower=True)  # u = M^-1 v
        rows = [family.dense() for family in families]  # constant rows over u; bounds per drone from _bounds
        self._const_v = (np.vstack(rows) if rows else np.zeros((0, nu))) @ self._m_inv
        self._const_pm = np.vstack([self._const_v, -self._const_v])  # one-sided: lower, then upper
        self.braking = braking = Braking.of(dt_s, limits, settings.braking)
        tail = planner_tail(braking, settings, dim, loop)
        count = 0 if tail is None else tail.count
        self._steps = steps = h + count  # the rows' positions: x_1..x_H (then the braking tail's points)
        self._ends = row_ends(h, count)
        table = position_table(self._m_inv, h, dim, dt_s, loop).reshape(h, h, dim)  # x_e per axis
        reach = 1.0 if loop is None else loop.reach_factor  # the longest step, with a loop's response
        self._reach_steps = self._ends.astype(float)  # how many longest steps each row's position is away
        if tail is not None:  # the tail's points g x_H + sum_j F_j u_j (:mod:`mpcform.mpc.constraints.tail`)
            plain = position_table(self._m_inv, h, dim, dt_s, None).reshape(h, h, dim)
            u_of_v = self._m_inv.reshape(h, dim, h, dim)[:, 0, :, 0]  # u_j per axis, over v
            points = tail.gain * plain[-1] + np.einsum("tjd,jm->tmd", tail.forced, u_of_v)
            table = np.concatenate([table, points])
            self._reach_steps[self._ends > h] = h + tail.reach_s / dt_s
        self._table = table
        # positions x_1..x_H (and the stop) from v, drone by drone ((S d, H d))
        self._x_of_v = (table[:, None] * np.eye(dim)[:, None, :]).reshape(steps * dim, nu)
        self._step_m = None if limits.v_max_mps is None else limits.v_max_mps * dt_s * reach
        self._eye = np.eye(nu)
        w2 = max(settings.slack_quadratic, MIN_SLACK_QUADRATIC)
        self._hess_soft = np.diag(np.concatenate([np.full(h, w2), np.ones(nu)]))
        fixed = all(family.fixed_bounds for family in families)  # the same for every drone at every step
        self._fixed = dense_bounds(families, np.zeros((1, dim)), np.zeros((1, dim))) if fixed else None

    def _rows_v(self, coeffs: Array, end: Array, out: Array | None = None) -> Array:
        """Separation rows (K, H d) over ``v`` (into ``out``) of coefficients ``coeffs`` (K, d) at
        position steps ``end`` (K,): ``a^T x_e = (w_e (x) a)^T v``."""
        rows = np.empty((end.shape[0], self._nu)) if out is None else out
        table = self._table.take(end - 1, axis=0)  # (K, H, d)
        np.multiply(table, coeffs[:, None], out=rows.reshape(table.shape))
        return rows

    def inputs_positions(self, v: Array) -> tuple[Array, Array]:
        """Inputs and relative positions (n, H d) (step-major within a drone) of solutions ``v``
        (n, H d): ``u = M^-1 v``, ``x_e = dt sum_{j<e} u_j``."""
        u = v @ self._m_inv.T
        return u, u @ self._x_of_u.T

    def soft_problem(
        self, f_v: Array, a: Array, hi: Array, lo: Array, end: Array, soft: Array
    ) -> tuple[Array, Array, Array, Array, Array]:
        """A drone's QP with its slacks, in the dense backends' form (Hessian, f, rows, upper,
        lower), from its hard QP (``f_v``, rows ``a`` over v with the constant rows first, bounds;
        the separation rows at steps ``end`` with slack coefficients ``soft``): the slacks are the
        first variables, with simple bounds ``s >= 0`` and Hessian ``diag(w2, I)``; the solution
        is ``[s | v]``.

        The slacks are not scaled to a unit Hessian: a column ``1 / sqrt(w2)`` would scale DAQP's
        row tolerance up with it (measured: 3.5e-8 misses at ``w2 = 0``)."""
        h, n_const = self.settings.horizon, a.shape[0] - end.shape[0]
        a_s = np.zeros((a.shape[0], h))
        a_s[n_const + np.arange(end.shape[0]), np.minimum(end, h) - 1] = soft  # the stop: step H's slack
        f = np.concatenate([np.full(h, self.settings.slack_weight), f_v])
        upper, lower = np.concatenate([np.full(h, NO_BOUND), hi]), np.concatenate([np.zeros(h), lo])
        return self._hess_soft, f, np.hstack([a_s, a]), upper, lower

    def sensitivity(self, solves: DroneSolves, i: int) -> Sensitivity:
        """How drone i's optimum moves with its separation rows' lower bounds on its active set
        (:func:`mpcform.mpc.solve.sensitivity.drone_sensitivity`)."""
        first, last, b = solves.offsets[i], solves.offsets[i + 1], min(i, solves.const_lo.shape[0] - 1)
        sep = self._rows_v(solves.sep_c[first:last], solves.sep_end[first:last])
        lam = solves.multipliers(i, everything=True)
        lo, hi = solves.const_lo[b], solves.const_hi[b]
        return drone_sensitivity(lam, solves.v[i], self._const_pm, sep, lo, hi, solves.sep_lo[first:last])


def dense_bounds(
    families: tuple[LimitRows, ...], p0: Array, u_prev: Array, free_m: Array | None = None
) -> tuple[Array, Array]:
    """Lower and upper bounds (n, rows) of the constant rows of ``families`` for each drone (starts
    ``p0``, last commands ``u_prev`` (n, d), with a loop its free response ``free_m`` (S, n, d));
    :data:`~mpcform.solvers.dense.NO_BOUND` where a row has none."""
    n = p0.shape[0]
    if not families:
        return np.zeros((n, 0)), np.zeros((n, 0))
    lo, hi = zip(*(family.dense_bounds(p0, u_prev, NO_BOUND, free_m) for family in families), strict=True)
    return np.hstack(lo), np.hstack(hi)

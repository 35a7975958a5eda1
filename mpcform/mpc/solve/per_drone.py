"""Decoupled mode solved drone by drone: each drone's condensed QP (:mod:`mpcform.mpc.solve.condensed`)
with a per-drone backend (:class:`~mpcform.solvers.dense.DenseQPBackend`, chosen by
:class:`~mpcform.mpc.strategy.PerDroneSolve`; "DAQP" below is whichever it is).

- A drone whose wish ``v = c`` meets every row gets it without a solver call (bit for bit DAQP's
  solution, multipliers and cost).
- Working sets (:mod:`mpcform.mpc.solve.working_set`): each drone is first given only its rows near
  their bound; a solve that misses another row, or fails, is solved again with all of them.
- The slacks are almost always zero, so each drone is first solved without them: if that hard
  QP is feasible, its solution (``s = 0``) is the drone's plan, else the soft QP is solved. The
  L1 penalty is exact once ``w1`` exceeds the hard QP's multipliers at every step; those grow
  with speed and shrink with ``dt`` (a fixed ``w1`` is not exact everywhere), so the hard
  optimum is taken whenever it exists: the limit of the soft optimum as ``w1`` grows.
"""

from __future__ import annotations

import time

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.condensed import CondensedDroneQP, dense_bounds
from mpcform.mpc.solve.drone_solves import DroneSolves
from mpcform.mpc.solve.problem import ACTIVE_TOL, StepQP, StepSolver
from mpcform.mpc.solve.working_set import (
    misses,
    reachable_rows,
    row_values,
    separation_misses,
    separation_sets,
    stack,
    within_bounds,
    working_sets,
)
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.solvers.base import QPSolution, failed
from mpcform.solvers.dense import NO_BOUND, DenseQPBackend, DenseSolution
from mpcform.world.bounds import PlanningBounds

Solved = tuple[QPSolution, int]  # a solution and its number of active rows


class PerDroneQP(CondensedDroneQP, StepSolver):
    """The per-drone condensed QPs of the decoupled planner (:class:`CondensedDroneQP`), each solved
    by ``backend`` (its name, with " (per drone)", is the planner's ``solver_name``)."""

    warm_starts = True  # nearly active rows of the warm start start DAQP's active set

    def __init__(
        self,
        dim: int,
        dt_s: float,
        limits: PlanningBounds,
        settings: MPCSettings,
        families: tuple[LimitRows, ...],
        backend: DenseQPBackend,
        loop: VelocityLoop | None = None,
    ) -> None:
        super().__init__(dim, dt_s, limits, settings, families, loop)
        self.backend, self.name = backend, f"{backend.name} (per drone)"
        self._a, self._lo, self._hi = np.zeros((0, self._nu)), np.zeros(0), np.zeros(0)  # _buffers

    def solve(self, qp: StepQP) -> tuple[QPSolution, int]:
        """Solve every drone's QP (the one-drone separation rows within reach of ``qp.rows``): the
        solution in the sparse QP's layout ``[u | x | s]`` over these drones (its ``solve_time_s``
        is the time spent inside DAQP), and the number of active rows."""
        rows, places = qp.given_rows, qp.places()  # the drones' rows picked from all, not copied
        warm_u = np.zeros_like(qp.targets_mps) if qp.warm is None else qp.warm[0]  # inputs only
        got = self.solve_each(
            qp.start_m,
            qp.targets_mps,
            qp.u_prev_mps,
            rows.singles,
            rows.single_coeffs,
            rows.single_lower,
            warm_u,
            rows.single_hard,
            rows.single_on,
            qp.free_m,
            places,
        )
        return self.solution(got.v, got.s, got.ok, got.flags, got.lams, got.iterations, got.time_s, got.cost)

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
        free_m: Array | None = None,
        places: Array | None = None,
    ) -> DroneSolves:
        """Every drone's solve as DAQP returns it.

        ``p0`` (n, d) starts, ``c`` (H, n, d) targets, ``u_prev`` (n, d) last commands; separation
        items ``singles`` (S,) drone index, ``coeffs`` (S, R, d), ``lower`` (S, R); ``warm_u``
        (H, n, d) inputs whose nearly active rows start DAQP's active set; ``hard`` (S,) the items
        whose first row is a hard no-approach row (no slack); ``on`` (S,) the items within reach
        (the others are left out; all by default); ``free_m`` (S, n, d) with a velocity loop its
        free response at each bounded position (the geofence's bounds); ``places`` (N,): for items
        ``singles`` over N drones, each one's place among these (-1: not solved, its items left out;
        None: ``singles`` are the places).

        With working sets (:func:`mpcform.mpc.solve.working_set.working_sets`), each drone first gives DAQP
        only its rows near their bound; a solve that misses any other row, or fails, is solved again
        with all of them."""
        st = self.settings
        h, n, nu, n_const = st.horizon, p0.shape[0], self._nu, self._const_v.shape[0]
        c_v = c.transpose(1, 0, 2).reshape(n, nu)
        f_v = -c_v  # 0.5 ||v - c||^2
        v_warm = warm_u.transpose(1, 0, 2).reshape(n, nu) @ self._m.T
        sep_c, sep_end, sep_lo, sep_soft, counts, at = reachable_rows(
            n, singles, coeffs, lower, hard, on, self._ends, self._step_m, self._reach_steps, places
        )
        a, lo, hi = self._buffers(n_const + int(counts.max(initial=0)))
        b_lo, b_hi = (
            self._fixed if self._fixed is not None else dense_bounds(self.families, p0, u_prev, free_m)
        )
        offsets = [0, *np.cumsum(counts).tolist()]
        v_out, s_out, lams = [np.empty(0)] * n, np.zeros((n, h)), [np.empty(0)] * n
        flags, ok = [0] * n, [True] * n
        const_c, owner = c_v @ self._const_v.T, np.repeat(np.arange(n), counts)
        at_x = owner * self._steps + sep_end - 1  # each row's position x_e among the drones'
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
            soft_qp = self.soft_problem(
                f_v[i], a[:m], hi[:m], lo[:m], sep_end[first:last], sep_soft[first:last]
            )
            t0 = time.perf_counter()  # the backend's call only
            got = self.backend.solve(*soft_qp)
            lams[i] = keep(i, got, t0)
            v_out[i], s_out[i] = got.x[h:], got.x[:h]

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
            h,
            n_const,
        )

    def solution(
        self,
        v: Array,
        s: Array,
        ok: Array,
        flags: Array,
        lams: list[Array],
        iters: int,
        t_s: float,
        cost: Array,
    ) -> Solved:
        """The drones' solves (``v`` (n, H d), slacks ``s`` (n, H), which succeeded, the backend's
        exit flags and multipliers; ``t_s`` the time in the backend; their costs) as one solution
        ``[u | x | s]`` (as :meth:`solve` returns it). Its objective is the drones' costs
        summed: the sparse QP's objective at the same point (its block-diagonal cost in ``v``)."""
        h, n = self.settings.horizon, v.shape[0]
        bad = np.flatnonzero(~ok | ~np.isfinite(v).all(axis=1))
        if bad.size:
            status = f"{self.backend.name}: exit flag {flags[bad[0]]} (drone {bad[0]})"
            return failed(status, t_s, iters), 0
        u_out, x_out = self.inputs_positions(v)
        flat = [w.reshape(n, h, -1).transpose(1, 0, 2).ravel() for w in (u_out, x_out, s)]
        status = f"{self.backend.name}: optimal"
        sol = QPSolution(np.concatenate(flat), None, True, status, iters, t_s, float(cost.sum()))
        active = np.count_nonzero(np.abs(np.concatenate(lams)) > ACTIVE_TOL) if n else 0
        return sol, int(active)

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

"""The sparse QP (:mod:`mpcform.mpc.solve.sparse_qp`) solved with a backend (:mod:`mpcform.solvers`).

The QP over the drones solved for is kept while the drones and the items stay the same; the
backend is set up when the QP (its sparsity pattern) changes and updated otherwise.

Exact penalty at any speed and step: the L1 slack weight ``w1`` is exact only above the hard
QP's multipliers, which grow with speed and shrink with ``dt``. When a solve uses slack, the QP
is solved again with the weight raised :data:`RAISE` fold (up to :data:`MAX_RAISES` times) while
that lowers the slack: a feasible hard QP then gives its own optimum (slack within the solver's
tolerance), an infeasible one keeps the least slack. The weight enters the cost linearly, so the
Hessian's conditioning does not change; an interior-point solver can still need far more
iterations at a raised weight, so a re-solve gets at most :data:`RESOLVE_ITER_FACTOR` times the
first solve's iterations (a re-solve that stops there keeps the solution before it).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.mpc.constraints.acceleration import AccelerationRows
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.problem import ACTIVE_TOL, StepQP, StepSolver
from mpcform.mpc.solve.sparse_qp import MPCQP
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.solvers.base import QPBackend, QPContext, QPSolution
from mpcform.world.bounds import PlanningBounds

RAISE = 30.0  # the slack weight is raised this many fold per re-solve
MAX_RAISES = 3  # at most this many re-solves (w1 up to 27,000 times the setting)
RESOLVE_ITER_FACTOR = 4  # a re-solve may take this many times the first solve's iterations, ...
RESOLVE_MIN_ITER = 50  # ... and at least this many (PIQP took 1,000 at 13 ms each at a raised weight)
SLACK_TOL_M = 1e-6  # a solve that misses no row by more than this is final [m]


class SparseSolver(StepSolver):
    """The step's sparse QP, handed to ``backend``."""

    def __init__(
        self,
        backend: QPBackend,
        dim: int,
        dt_s: float,
        limits: PlanningBounds,
        settings: MPCSettings,
        families: tuple[LimitRows, ...],
        separation: Separation,
        loop: VelocityLoop | None = None,
    ) -> None:
        self.backend, self.name, self.warm_starts = backend, backend.name, backend.warm_starts
        self.dim, self.dt_s, self.limits, self.settings = dim, dt_s, limits, settings
        self.families, self.separation, self.loop = families, separation, loop
        if loop is not None and backend.needs_context:
            raise ValidationError(
                "controller.solver",
                f"{backend.name!r} models the separation itself "
                "and cannot take the plant's velocity loop; set controller.plant_model "
                "= false",
            )
        if backend.needs_context and separation.obstacles and not separation.obstacles.shapes.point_cores:
            raise ValidationError(
                "controller.solver",
                f"{backend.name!r} models the exact separation from obstacles as spheres only; "
                "choose another solver for cylinders and boxes",
            )
        if backend.stagewise and any(isinstance(f, AccelerationRows) for f in families):
            raise ValidationError(
                "controller.solver",
                f"{backend.name!r} takes rows within one stage only and a_max's rows join two; "
                "set limits.a_max = inf (no bound, ideal plant) or choose another solver",
            )
        self.reset()

    def reset(self) -> None:
        self._qp: MPCQP | None = None
        self._qp_key = b""
        self._backend_qp: MPCQP | None = None  # the QP the backend was last set up with

    def solve(self, qp: StepQP) -> tuple[QPSolution, int]:
        """Set up (new pattern) or update the backend, then solve."""
        backend, rows = self.backend, qp.rows
        mpc_qp = self._sub_qp(qp.drones, rows, qp.rebuilt)
        q = mpc_qp.cost_vector(qp.targets_mps)
        lower = np.concatenate([rows.pair_lower, rows.single_lower])
        on = np.concatenate([rows.pair_on, rows.single_on])
        lo, hi = mpc_qp.bounds(qp.start_m, qp.u_prev_mps, lower, on, qp.free_m)
        hard = rows.pair_hard, rows.single_hard
        a_data = mpc_qp.separation_values(rows.pair_coeffs, rows.single_coeffs, *hard)
        if self._backend_qp is not mpc_qp:
            a_matrix = mpc_qp.A.copy()
            a_matrix.data = a_data
            start = time.perf_counter()
            backend.setup(mpc_qp.P, q, a_matrix, lo, hi)
            self._backend_qp = mpc_qp
        else:
            start = time.perf_counter()
            backend.update(q, lo, hi, a_data)
        loaded_s = time.perf_counter() - start  # the backend's setup or update: solver time too
        if backend.needs_context:
            backend.set_context(self._context(mpc_qp, qp))
        x0 = None
        if qp.warm is not None:
            y = []  # with a loop, the warm start's true positions y = x + G u
            if self.loop is not None:
                y = [(qp.warm[1] + self.loop.forced_response(qp.warm[0])[1:]).ravel()]
            x0 = np.concatenate([qp.warm.ravel(), np.zeros(mpc_qp.layout.n_slack), *y])
        sol = backend.solve(x0)
        sol = self._exact(
            replace(sol, solve_time_s=loaded_s + sol.solve_time_s), mpc_qp, qp, lo, hi, a_data, x0
        )
        nud = mpc_qp.layout.nud
        active = 0 if sol.y is None else int(np.count_nonzero(np.abs(sol.y[nud:]) > ACTIVE_TOL))
        return sol, active

    def _exact(
        self,
        sol: QPSolution,
        mpc_qp: MPCQP,
        qp: StepQP,
        lo: Array,
        hi: Array,
        a_data: Array,
        x0: Array | None,
    ) -> QPSolution:
        """``sol``, or a re-solve with a raised slack weight that needs less slack (module docstring)."""
        lay, weight = mpc_qp.layout, self.settings.slack_weight
        slack, cap = lay.slack_slice(), max(RESOLVE_MIN_ITER, RESOLVE_ITER_FACTOR * sol.iterations)
        try:
            for _ in range(MAX_RAISES):
                if not sol.success or sol.x is None or not self._short(sol.x, mpc_qp, qp):
                    return sol
                weight *= RAISE
                q = mpc_qp.cost_vector(qp.targets_mps, weight)
                start = time.perf_counter()
                self.backend.update(q, lo, hi, a_data)
                loaded_s = time.perf_counter() - start
                self.backend.limit_iterations(cap)
                again = self.backend.solve(x0)
                spent_s = sol.solve_time_s + loaded_s + again.solve_time_s
                if not again.success or again.x is None or again.x[slack].sum() >= sol.x[slack].sum():
                    return replace(sol, solve_time_s=spent_s)  # the re-solve was solver time too
                iterations, time_s = sol.iterations + again.iterations, spent_s
                sol = replace(again, iterations=iterations, solve_time_s=time_s)
            return sol
        finally:
            if weight != self.settings.slack_weight:  # a re-solve was capped
                self.backend.limit_iterations(None)

    def _short(self, z: Array, mpc_qp: MPCQP, qp: StepQP) -> bool:
        """Whether the solution ``z`` misses a separation row by more than :data:`SLACK_TOL_M` (an
        interior-point solver leaves slacks of its tolerance's order at zero: not counted)."""
        lay = mpc_qp.layout
        if z[lay.slack_slice()].max(initial=0.0) <= SLACK_TOL_M:
            return False
        at = lay.y_cols() if lay.true_positions else lay.x_cols()  # the rows' positions
        x = z[at.ravel()].reshape(lay.horizon, lay.n, lay.dim)
        tail = self.separation.tail
        if tail is not None:  # and the braking tail's points (:mod:`mpcform.mpc.constraints.tail`)
            x_last = z[lay.x_cols()[-1].ravel()].reshape(lay.n, lay.dim)
            u = z[lay.u_cols().ravel()].reshape(lay.horizon, lay.n, lay.dim)
            x = np.concatenate([x, tail.points(x_last, u)])
        return self.separation.shortfall(x, qp.rows, SLACK_TOL_M)[0] > SLACK_TOL_M

    def _sub_qp(self, drones: Array, rows: SeparationRows, rebuilt: bool) -> MPCQP:
        """The QP over ``drones`` and the items of ``rows``, kept while both stay the same."""
        key = drones.tobytes() + rows.pairs.tobytes() + rows.labels.tobytes()
        if rebuilt or self._qp is None or key != self._qp_key:
            self._qp = MPCQP(
                drones.shape[0],
                self.dim,
                self.dt_s,
                self.limits,
                self.settings,
                rows.pairs,
                rows.singles,
                self.families,
                self.loop,
                self.separation.tail,
            )
            self._qp_key = key
        return self._qp

    def _context(self, mpc_qp: MPCQP, qp: StepQP) -> QPContext:
        """What the QP means, numbered locally (for ``casadi:ipopt``'s exact separation and
        ``casadi:hpipm``'s stages): the pairs and obstacle items within reach."""
        rows, sep, drones = qp.rows, self.separation, qp.drones
        local = np.full(qp.n, -1)
        local[drones] = np.arange(drones.shape[0])
        sides = rows.labels[:, 1] >= 0  # decoupled pair sides, global drone indices
        pairs = np.concatenate([rows.pairs[rows.pair_on], local[rows.labels[sides & rows.single_on]]])
        pairs = np.unique(np.sort(pairs[(pairs >= 0).all(axis=1)], axis=1), axis=0).reshape(-1, 2)
        ob = ~sides & rows.single_on
        obstacle = -1 - rows.labels[ob, 1]
        margin, center, required = self.settings.margin_m, np.empty((0, self.dim)), np.empty(0)
        if ob.any() and sep.obstacles is not None:
            center = sep.obstacles.shapes.centers_m[obstacle]
            required = sep.obstacles.required_m[obstacle] + margin
        return QPContext(
            drones.shape[0],
            self.dim,
            self.settings.horizon,
            (mpc_qp.sep_rows.start, mpc_qp.sep_rows.stop),
            qp.start_m,
            pairs,
            (self.limits.d_min_m or 0.0) + margin,
            sep.metric,
            rows.singles[ob],
            center,
            required,
        )

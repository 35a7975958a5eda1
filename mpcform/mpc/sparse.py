"""The sparse QP (:mod:`mpcform.mpc.qp`) solved with a backend (:mod:`mpcform.solvers`).

The QP over the drones solved for is kept while the drones and the items stay the same; the
backend is set up when the QP (its sparsity pattern) changes and updated otherwise.
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.limits import Limits
from mpcform.mpc.problem import ACTIVE_TOL, StepQP, StepSolver
from mpcform.mpc.qp import MPCQP
from mpcform.mpc.rows import LimitRows
from mpcform.mpc.separation import Separation, SeparationRows
from mpcform.mpc.settings import MPCSettings
from mpcform.solvers.base import QPBackend, QPContext, QPSolution


class SparseSolver(StepSolver):
    """The step's sparse QP, handed to ``backend``."""

    def __init__(
        self,
        backend: QPBackend,
        dim: int,
        dt_s: float,
        limits: Limits,
        settings: MPCSettings,
        families: tuple[LimitRows, ...],
        separation: Separation,
    ) -> None:
        self.backend, self.name, self.warm_starts = backend, backend.name, backend.warm_starts
        self.dim, self.dt_s, self.limits, self.settings = dim, dt_s, limits, settings
        self.families, self.separation = families, separation
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
        lo, hi = mpc_qp.bounds(qp.start_m, qp.u_prev_mps, lower, on)
        a_data = mpc_qp.separation_values(rows.pair_coeffs, rows.single_coeffs, rows.pair_hard, rows.single_hard)
        if self._backend_qp is not mpc_qp:
            a_matrix = mpc_qp.A.copy()
            a_matrix.data = a_data
            backend.setup(mpc_qp.P, q, a_matrix, lo, hi)
            self._backend_qp = mpc_qp
        else:
            backend.update(q, lo, hi, a_data)
        if backend.needs_context:
            backend.set_context(self._context(mpc_qp, qp))
        x0 = None
        if qp.warm is not None:
            x0 = np.concatenate([qp.warm.ravel(), np.zeros(mpc_qp.layout.n_slack)])
        sol = backend.solve(x0)
        nud = mpc_qp.layout.nud
        active = 0 if sol.y is None else int(np.count_nonzero(np.abs(sol.y[nud:]) > ACTIVE_TOL))
        return sol, active

    def _sub_qp(self, drones: Array, rows: SeparationRows, rebuilt: bool) -> MPCQP:
        """The QP over ``drones`` and the items of ``rows``, kept while both stay the same."""
        key = drones.tobytes() + rows.pairs.tobytes() + rows.labels.tobytes()
        if rebuilt or self._qp is None or key != self._qp_key:
            self._qp = MPCQP(
                drones.shape[0], self.dim, self.dt_s, self.limits, self.settings, rows.pairs, rows.singles,
                self.families,
            )  # fmt: skip
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
            center, required = sep.obstacles.center_m[obstacle], sep.obstacles.required_m[obstacle] + margin
        return QPContext(
            drones.shape[0], self.dim, self.settings.horizon, (mpc_qp.sep_rows.start, mpc_qp.sep_rows.stop),
            qp.start_m, pairs, (self.limits.d_min_m or 0.0) + margin, sep.metric, rows.singles[ob],
            center, required,
        )  # fmt: skip

"""The planner's sparse QP: built once per candidate set, then updated every step.

Variables (:class:`~mpcform.mpc.constraints.rows.Layout`), all drones stacked, positions relative to the
current positions ``p0`` so that every variable is O(v_max H dt) and the solver's relative
tolerances mean something::

    z = [u_0 .. u_{H-1} | x_1 .. x_H | s_1 .. s_H]      x_j = p_j - p0,  x_0 = 0

(with a velocity loop, then ``y_1 .. y_H``: where the loop takes the drones, the separation rows
on them; :mod:`mpcform.mpc.velocity_loop`).

with one separation slack ``s_{e,i} >= 0`` [m] per drone and position step (shared by the
drone's pair and obstacle rows at that step), so the slack keeps the problem stage-wise
sparse: a slack per pair over the whole horizon would couple all steps and fill the KKT
factor (measured: 80 ms per interior-point iteration for 20 spatial drones instead of ~1).

Cost ``0.5 sum_j ||u_j + k x_j - c_j||^2 + w1 sum slack + 0.5 w2 sum slack^2`` with
``c_j = ff_j + k (p*_j - p0)``: zero for the eq. 14 rollout, which is therefore the optimum
whenever it meets every row. Rows, in order (one family each, :mod:`mpcform.mpc.constraints.rows`):
dynamics ``x_{j+1} - x_j - dt u_j = 0``; velocity set; acceleration (optional); geofence
(optional); separation items (:mod:`mpcform.mpc.constraints.separation`); ``slack >= 0``.

Only the separation rows' coefficients change from step to step; the sparsity pattern is fixed
for a given candidate set, so a persistent solver takes ``update(Ax=...)``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.rows import (
    Layout,
    RowBlock,
    dynamics_rows,
    separation_pattern,
    slack_rows,
    tail_rows,
    true_position_rows,
)
from mpcform.mpc.constraints.tail import Tail
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.world.bounds import PlanningBounds


class MPCQP:
    """The QP of one candidate set of separation items over ``n`` drones.

    ``pairs`` (P, 2) (joint pair rows) and ``singles`` (S,) (the drone of each one-drone row:
    decoupled pair sides, obstacles) fix the sparsity pattern; ``families`` are the limits' rows
    (:func:`mpcform.mpc.constraints.rows.limit_rows`). Each step: :meth:`cost_vector`, :meth:`bounds`,
    :meth:`separation_values`.
    """

    def __init__(
        self,
        n: int,
        dim: int,
        dt_s: float,
        limits: PlanningBounds,
        settings: MPCSettings,
        pairs: Array,
        singles: Array,
        families: tuple[LimitRows, ...],
        loop: VelocityLoop | None = None,
        tail: Tail | None = None,
    ) -> None:
        h = settings.horizon
        self.layout = lay = Layout(n, dim, h, loop is not None)
        self.settings, self.tail = settings, tail
        count, support = (0, None) if tail is None else (tail.count, tail.support)
        self._tail_at = tail_rows(h, count)  # the braking tail's rows among an item's
        self._tail_forced = None if tail is None else tail.forced[:, support]  # (T, J, d)
        blocks = [dynamics_rows(lay, dt_s), *(f.sparse(lay) for f in families)]
        if loop is not None:
            blocks.append(true_position_rows(lay, loop.forced))
        blocks += [separation_pattern(lay, pairs, singles, count, support), slack_rows(lay)]
        rows_all, cols_all, vals, row_slices, entry_slices = _stack(blocks)
        self._families = tuple(zip(families, row_slices[1 : 1 + len(families)], strict=True))
        self.sep_rows, self._sep_entries = row_slices[-2], entry_slices[-2]
        self._coo_vals = vals.astype(float)
        ids = sp.csc_matrix(
            (np.arange(1, rows_all.shape[0] + 1, dtype=float), (rows_all, cols_all)),
            shape=(row_slices[-1].stop, lay.n_var),
        )
        ids.sort_indices()
        self._perm = ids.data.astype(np.intp) - 1
        self.A = sp.csc_matrix((self._coo_vals[self._perm], ids.indices, ids.indptr), shape=ids.shape)
        self.l0 = np.concatenate([b.lower for b in blocks])
        self.u0 = np.concatenate([b.upper for b in blocks])
        self.P = _cost_hessian(lay, settings)
        # rows of inactive items stay in the pattern with a bound no plan can reach (finite, so
        # interior-point backends do not drop them): |c^T (x_i - x_k)| <= 2 v_max (H dt + the tail's reach)
        look_ahead_s = h * dt_s + (0.0 if tail is None else tail.reach_s)
        self._off_lower = -(2.0 * (limits.v_max_mps or 0.0) * look_ahead_s + 1.0)

    def cost_vector(self, c: Array, slack_weight: float | None = None) -> Array:
        """Linear cost term for targets ``c_j = ff_j + k (p*_j - p0)`` (H, n, d) (slack weight: the
        settings' unless given)."""
        lay, k = self.layout, self.settings.gain_per_s
        q = np.empty(lay.n_var)
        q[: lay.nud] = -c.ravel()
        q[lay.nud : 2 * lay.nud - lay.n * lay.dim] = -k * c[1:].ravel()
        q[2 * lay.nud - lay.n * lay.dim : 2 * lay.nud] = 0.0
        q[lay.slack_slice()] = self.settings.slack_weight if slack_weight is None else slack_weight
        q[lay.slack_slice().stop :] = 0.0
        return q

    def bounds(
        self, p0: Array, u_prev: Array, sep_lower: Array, sep_active: Array, free_m: Array | None = None
    ) -> tuple[Array, Array]:
        """Row bounds for start positions p0 (n, d), last command u_prev, separation lower bounds
        (items, R), the mask of items whose rows are on (items,) and, with a velocity loop, its
        free response ``free_m`` (S, n, d) at the positions the geofence bounds."""
        lo, hi = self.l0.copy(), self.u0.copy()
        for family, rows in self._families:
            family.set_bounds(lo[rows], hi[rows], p0, u_prev, free_m)
        sep = np.where(sep_active[:, None], sep_lower, self._off_lower)
        lo[self.sep_rows] = sep.ravel()
        return lo, hi

    def separation_values(
        self,
        coeffs_pairs: Array,
        coeffs_singles: Array,
        hard_pairs: Array | None = None,
        hard_singles: Array | None = None,
    ) -> Array:
        """CSC data of A for row coefficients (P, R, d) of the pairs and (S, R, d) of the singles;
        the items marked ``hard_*`` have no slack in their first row (a hard no-approach row)."""
        vals = self._coo_vals.copy()
        parts, extra = [], []
        if coeffs_pairs.shape[0]:
            ones = np.ones(coeffs_pairs.shape[:2] + (2,))
            if hard_pairs is not None:
                ones[hard_pairs, 0] = 0.0
            main, on_u = self._tail_values(coeffs_pairs)
            parts.append(np.concatenate([main, -main, ones], axis=2).ravel())
            extra.append(np.concatenate([on_u, -on_u], axis=-1).ravel())
        if coeffs_singles.shape[0]:
            ones = np.ones(coeffs_singles.shape[:2] + (1,))
            if hard_singles is not None:
                ones[hard_singles, 0] = 0.0
            main, on_u = self._tail_values(coeffs_singles)
            parts.append(np.concatenate([main, ones], axis=2).ravel())
            extra.append(on_u.ravel())
        if self.tail is not None:
            parts += extra
        if parts:
            vals[self._sep_entries] = np.concatenate(parts)
        return vals[self._perm]

    def _tail_values(self, coeffs: Array) -> tuple[Array, Array]:
        """Coefficients (items, R, d) on the rows' positions, and (items, T, J, d) of the braking
        tail's rows on its inputs (:class:`mpcform.mpc.constraints.tail.Tail`): ``g c`` on ``x_H`` and ``c
        F_j``
        on ``u_j`` (without a loop ``kappa c`` on ``u_{H-1}``)."""
        if self.tail is None:
            return coeffs, coeffs[:, 0, :0]
        main = coeffs.copy()
        main[:, self._tail_at] = coeffs[:, self._tail_at] * self.tail.gain
        return main, coeffs[:, self._tail_at, None] * self._tail_forced


def _stack(blocks: list[RowBlock]) -> tuple[Array, Array, Array, list[slice], list[slice]]:
    """Row families one after the other: COO rows, columns and values, and each family's row and
    entry slices."""
    rows, cols, vals, row_slices, entry_slices = [], [], [], [], []
    r0 = e0 = 0
    for b in blocks:
        rows.append(r0 + b.rows.ravel())
        cols.append(b.cols.ravel())
        vals.append(np.broadcast_to(b.vals, b.rows.shape).ravel())
        row_slices.append(slice(r0, r0 + b.lower.shape[0]))
        entry_slices.append(slice(e0, e0 + b.rows.size))
        r0, e0 = row_slices[-1].stop, entry_slices[-1].stop
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), row_slices, entry_slices


def _cost_hessian(lay: Layout, settings: MPCSettings) -> sp.csc_matrix:
    """Upper triangle of the cost's Hessian: ``0.5 ||u_j + k x_j - c_j||^2`` (x_0 = 0), slack weights."""
    n, dim, nud, ns, k = lay.n, lay.dim, lay.nud, lay.n_slack, settings.gain_per_s
    diag_u = np.ones(nud)
    diag_x = np.full(nud, k * k)
    diag_x[-n * dim :] = 0.0  # x_H does not enter the cost
    cross = sp.coo_matrix(
        (np.full(nud - n * dim, k), (np.arange(n * dim, nud), nud + np.arange(nud - n * dim))),
        shape=(lay.n_var, lay.n_var),
    )
    diag_y = np.zeros(nud if lay.true_positions else 0)
    diag = np.concatenate([diag_u, diag_x, np.full(ns, settings.slack_quadratic), diag_y])
    P = sp.triu(sp.diags(diag) + cross, format="csc")
    P.sort_indices()
    return P

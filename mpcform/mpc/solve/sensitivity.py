"""How a drone's optimum moves with its separation rows' bounds: the Newton model of the split
rounds (:mod:`mpcform.mpc.solve.split`) over one per-drone QP (:mod:`mpcform.mpc.solve.per_drone`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.solve.problem import ACTIVE_TOL

NO_BOUND = 1e29  # bounds beyond this are none (DAQP's "no bound" is 1e30)
AT_BOUND_M = 1e-7  # a separation row this close to its bound counts as active
GRAM_EPS = 1e-9  # relative regularisation of the active rows' Gram matrix


@dataclass(frozen=True)
class Sensitivity:
    """How one drone's optimum moves with its separation rows' lower bounds ``b`` on its active
    set (:func:`drone_sensitivity`): a separation rows active, r rows active in all (one-sided),
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


def drone_sensitivity(
    lam: Array, v: Array, const_pm: Array, sep: Array, lo: Array, hi: Array, sep_lo: Array
) -> Sensitivity:
    """How a drone's optimum ``v`` (multipliers ``lam``: constant rows, then separation rows, as
    DAQP returns them) moves with its separation rows' lower bounds on its active set.

    Constant rows ``const_pm`` (2 c, H d) (``+rows``, then ``-rows``), bounds ``lo``, ``hi`` (c,);
    separation rows ``sep`` (K, H d) over v, ``sep @ v >= sep_lo``. Every row one-sided,
    ``a^T v >= b``, multiplier ``y >= 0``; active: a multiplier, or within :data:`AT_BOUND_M` of the
    bound. There (identity Hessian; a soft drone's slacks ignored) ``v = c + A^T y``,
    ``y = (A A^T)^-1 (b - A c)``: ``d^2 f / db^2 = dy / db = (A A^T)^-1``, ``dv / db = A^T (A A^T)^-1``;
    regularised (:data:`GRAM_EPS`) so that dependent rows (a segment's two ends at one step) get a
    large curvature, not none. The inactive constant rows stay shared (a mask, not a copy)."""
    n_const = lo.shape[0]
    bound = np.concatenate([lo, -hi, sep_lo])
    y = np.concatenate([np.maximum(-lam[:n_const], 0.0), np.maximum(lam[:n_const], 0.0), -lam[n_const:]])
    gap = np.concatenate([const_pm @ v, sep @ v]) - bound
    real = np.abs(bound) < NO_BOUND
    on = real & ((y > ACTIVE_TOL) | (gap <= AT_BOUND_M))
    off, c2 = real & ~on, 2 * n_const
    active = np.concatenate([const_pm[on[:c2]], sep[on[c2:]]])
    gram = active @ active.T
    gram.flat[:: gram.shape[0] + 1] += GRAM_EPS * max(1.0, float(gram.diagonal().max(initial=0.0)))
    sep_on = np.flatnonzero(on[c2:])
    k = np.linalg.inv(gram)[:, on[:c2].sum() :]  # columns: the active separation rows
    idx = np.flatnonzero(off)
    sep_index = np.where(idx >= c2, idx - c2, -1)
    return Sensitivity(
        sep_on,
        k[-sep_on.shape[0] :] if sep_on.size else k[:0],
        active.T @ k,
        y[on],
        k,
        const_pm,
        off[:c2],
        sep[off[c2:]],
        gap[off],
        sep_index,
    )

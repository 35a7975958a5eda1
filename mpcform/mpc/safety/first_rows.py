"""Every first separation row hard, lowered at most to what a feasible first command reaches.

With a velocity loop the planner (:mod:`mpcform.mpc.planner`) takes no slack on the first
interval's rows: see :func:`hard_first_rows`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.separation_rows import SeparationRows

LOWERED_TOL_M = 1e-6
"""A first row lowered by more than this is reported: the previous plan meets its rows only to the
solver's tolerance (a lag run's rows were lowered by 1.4-4.9 nm), the slack report's threshold."""


def hard_first_rows(rows: SeparationRows, first_m: Array) -> tuple[SeparationRows, bool, int]:
    """``rows`` with every item's first row hard (no slack), its bound lowered to the row's value
    at the best of ``first_m`` (k, n, d) (or (n, d)) where that is lower, whether a bound was
    (of an item within reach), and the best's index.

    With a loop the first interval is mostly the free response: a slack there (one per drone and
    step) would let a drone approach one partner as far as another forces it to, and fail the
    certification. ``first_m`` are where feasible first commands take the drones (``x_1 + G_10
    u_0``: braking, the previous plan's next input); the best is the one that needs the least
    lowering, and every row is lowered to that same one, so it meets them all and the rows stay
    feasible (a row-wise best of several would not be met by any one of them).
    """
    first_m = first_m.reshape((-1,) + first_m.shape[-2:])
    i, k = rows.pairs.T
    at_p = np.einsum("pd,kpd->kp", rows.pair_coeffs[:, 0], first_m[:, i] - first_m[:, k])
    at_s = np.einsum("sd,ksd->ks", rows.single_coeffs[:, 0], first_m[:, rows.singles])
    short = np.maximum(rows.pair_lower[:, 0] - at_p, 0.0).sum(axis=1)
    short += np.maximum(rows.single_lower[:, 0] - at_s, 0.0).sum(axis=1)
    best = int(np.argmin(short))
    lower_p, lower_s = rows.pair_lower.copy(), rows.single_lower.copy()
    np.minimum(lower_p[:, 0], at_p[best], out=lower_p[:, 0])
    np.minimum(lower_s[:, 0], at_s[best], out=lower_s[:, 0])
    relaxed = bool(  # (by more than rounding)
        np.any((lower_p[:, 0] < rows.pair_lower[:, 0] - LOWERED_TOL_M) & rows.pair_on)
        or np.any((lower_s[:, 0] < rows.single_lower[:, 0] - LOWERED_TOL_M) & rows.single_on)
    )
    hard = replace(
        rows,
        pair_lower=lower_p,
        single_lower=lower_s,
        pair_hard=np.ones_like(rows.pair_hard),
        single_hard=np.ones_like(rows.single_hard),
    )
    return hard, relaxed, best

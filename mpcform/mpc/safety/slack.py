"""How much slack a certified solve needed, told apart from the rows' growth in wind it used."""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.constraints.separation_rows import SeparationRows

SLACK_REPORT_M = 1e-6  # slack above this is reported


def slack_report(
    sep: Separation,
    z: Array,
    drones: Array,
    x: Array,
    rows: SeparationRows,
    start: tuple[float, Array],
    relaxed: bool,
    horizon: int,
    growing: Array | None = None,
) -> tuple[float, Array, float]:
    """The slack a certified solve ``z`` of ``drones`` over ``horizon`` steps needed [m] and its
    items (m, 2): those whose rows the positions ``x`` (H or H + 1, n, d) miss by more than
    :data:`SLACK_REPORT_M`, and the items that ``start`` (shortfall [m], items) inside their
    required distance; then how far [m] the positions reach into the rows' growth in wind
    (``growing``, :meth:`SeparationRows.ungrown`) while keeping every required distance: the growth
    is a buffer for the next steps, not a distance to keep, so that is not slack (0 otherwise)."""
    nud = horizon * drones.shape[0] * x.shape[2]
    slack = z[2 * nud : 2 * nud + horizon * drones.shape[0]]
    shortfall, missed = start
    if relaxed or slack.max(initial=0.0) > SLACK_REPORT_M / 2:
        planned, late = sep.shortfall(x, rows, SLACK_REPORT_M, joint=True)
        if late.shape[0] and growing is not None:  # into the growth only?
            bare = rows.ungrown(growing, sep.row_growth)
            if sep.shortfall(x, bare, SLACK_REPORT_M, joint=True)[1].shape[0] == 0:
                return max(shortfall, 0.0), missed, planned
        if late.shape[0]:  # a miss within the solver's tolerance is not slack
            shortfall, missed = max(shortfall, planned), np.concatenate([missed, late])
    return max(shortfall, 0.0), missed, 0.0

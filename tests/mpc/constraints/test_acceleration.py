"""The command-change rows by hand."""

from __future__ import annotations

import numpy as np
from helpers import dense_matrix

from mpcform.mpc.constraints.acceleration import AccelerationRows
from mpcform.mpc.constraints.rows import Layout

DT = 0.1


def test_acceleration_bounds_by_hand() -> None:
    """a_max 2 m/s^2, dt 0.1 s: |u_0 - u_prev| <= 0.2 and |u_1 - u_0| <= 0.2 per component."""
    fam = AccelerationRows(2, 2, DT, 2.0)
    lay = Layout(1, 2, 2)
    block = fam.sparse(lay)
    a = dense_matrix(block, lay)[:, :4]
    np.testing.assert_array_equal(a, [[1, 0, 0, 0], [0, 1, 0, 0], [-1, 0, 1, 0], [0, -1, 0, 1]])
    lo, hi = block.lower.copy(), block.upper.copy()
    fam.set_bounds(lo, hi, np.zeros((1, 2)), np.array([[1.0, -1.0]]))
    np.testing.assert_allclose(lo, [0.8, -1.2, -0.2, -0.2])
    np.testing.assert_allclose(hi, [1.2, -0.8, 0.2, 0.2])
    np.testing.assert_array_equal(fam.dense(), a)
    d_lo, d_hi = fam.dense_bounds(np.zeros((1, 2)), np.array([[1.0, -1.0]]), 1e30)
    np.testing.assert_allclose(d_lo[0], lo)
    np.testing.assert_allclose(d_hi[0], hi)

"""The geofence rows by hand, shrunk along the horizon by the growth."""

from __future__ import annotations

import numpy as np
from helpers import dense_matrix

from mpcform.mpc.constraints.geofence import GeofenceRows
from mpcform.mpc.constraints.rows import Layout, positions_of_inputs, step_growth

DT = 0.1


def test_geofence_bounds_by_hand() -> None:
    """Fence [-1, 1] x [0, inf), margin 0.1: a drone at (0.5, -0.2), below the floor, may stay."""
    fam = GeofenceRows(2, 3, DT, np.array([-1.0, 0.0]), np.array([1.0, np.inf]), 0.1)
    p0 = np.array([[0.5, -0.2]])
    lo, hi = fam.box(p0)
    np.testing.assert_allclose(lo, [[-1.4, 0.0]])
    np.testing.assert_allclose(hi, [[0.4, np.inf]])
    lay = Layout(1, 2, 3)
    block = fam.sparse(lay)
    s_lo, s_hi = block.lower.copy(), block.upper.copy()
    fam.set_bounds(s_lo, s_hi, p0, np.zeros((1, 2)))
    np.testing.assert_allclose(s_lo, np.tile([-1.4, 0.0], 3))
    np.testing.assert_allclose(s_hi, np.tile([0.4, np.inf], 3))
    assert np.all(dense_matrix(block, lay)[:, lay.nud : 2 * lay.nud] == np.eye(6))
    np.testing.assert_allclose(fam.dense(), positions_of_inputs(3, 2, DT))


def test_geofence_shrinks_along_the_horizon_by_the_growth() -> None:
    """With the rows' growth the box at position step e is shrunk by ``min(e - 1, E)`` growths (a
    drone outside it may still stay); the violators test reads the same boxes."""
    growth = step_growth(0.01, DT, 3)
    fam = GeofenceRows(2, 3, DT, np.array([-1.0, -1.0]), np.array([1.0, 1.0]), 0.1, growth=growth)
    lo, hi = fam.box(np.zeros((1, 2)))
    np.testing.assert_allclose(hi[:, 0, 0], [0.9, 0.89, 0.88])
    np.testing.assert_allclose(lo[:, 0, 1], [-0.9, -0.89, -0.88])
    x = np.zeros((3, 1, 2))
    x[:, 0, 0] = 0.895  # inside the first box, outside the second
    assert fam.violators(np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((3, 1, 2)), x)[0]
    x[1:, 0, 0] = 0.875
    assert not fam.violators(np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((3, 1, 2)), x)[0]

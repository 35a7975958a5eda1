"""The limits' row families: hand-computed rows, the sparse and dense forms agree, violators match."""

from __future__ import annotations

import numpy as np
from helpers import bounds_of, dense_matrix, z_of
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcform.mpc.constraints.acceleration import AccelerationRows
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.geofence import GeofenceRows
from mpcform.mpc.constraints.limits import admitted, inwards, limit_rows, turned_inwards, violators
from mpcform.mpc.constraints.rows import Layout, step_growth
from mpcform.mpc.constraints.velocity import VelocityRows
from mpcform.mpc.settings import MPCSettings

DT = 0.1


def _families() -> tuple[LimitRows, ...]:
    lim = bounds_of(v_max_mps=1.0, a_max_mps2=4.0, geofence_min_m=[-1.0, -1.0], geofence_max_m=[1.0, 1.0])
    return limit_rows(2, DT, lim, MPCSettings(horizon=4))


def test_limit_rows_in_qp_order() -> None:
    assert [type(f) for f in _families()] == [VelocityRows, AccelerationRows, GeofenceRows]
    assert limit_rows(2, DT, bounds_of(), MPCSettings()) == ()


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_sparse_dense_and_violators_agree(seed: int) -> None:
    """For random plans, per drone: the sparse rows, the dense rows and ``violators`` give one answer."""
    rng = np.random.default_rng(seed)
    n, h, d = 3, 4, 2
    lay = Layout(n, d, h)
    p0 = rng.uniform(-1.2, 1.2, (n, d))
    u_prev = rng.uniform(-0.3, 0.3, (n, d))
    u = u_prev + np.cumsum(rng.uniform(-0.45, 0.45, (h, n, d)), axis=0)  # steps near the 0.4 limit
    x = DT * np.cumsum(u, axis=0)
    z = z_of(lay, u, x, np.zeros((h, n)))
    for fam in _families():
        block = fam.sparse(lay)
        lo, hi = block.lower.copy(), block.upper.copy()
        fam.set_bounds(lo, hi, p0, u_prev)
        r = dense_matrix(block, lay) @ z
        broken = (r < lo - 1e-12) | (r > hi + 1e-12)
        drone_of_row = np.zeros(lo.shape[0], dtype=int)  # every row is about one drone
        for row, col in zip(block.rows.ravel(), block.cols.ravel(), strict=True):
            drone_of_row[row] = (col % lay.nud) // d % n
        sparse_bad = np.zeros(n, dtype=bool)
        sparse_bad[drone_of_row[broken]] = True
        d_lo, d_hi = fam.dense_bounds(p0, u_prev, np.inf)
        rd = u.transpose(1, 0, 2).reshape(n, -1) @ fam.dense().T
        dense_bad = ((rd < d_lo - 1e-12) | (rd > d_hi + 1e-12)).any(axis=1)
        np.testing.assert_array_equal(sparse_bad, dense_bad)
        np.testing.assert_array_equal(fam.violators(p0, u_prev, u, x), dense_bad)
    bad = violators(_families(), p0, u_prev, u, x)
    np.testing.assert_array_equal(bad, np.any([f.violators(p0, u_prev, u, x) for f in _families()], axis=0))


def test_admitted_moves_the_free_response_into_every_grown_box() -> None:
    """The wider fence of an infeasible step (a braking path out of the fence) with the rows'
    growth (wind, ``margin_growth``): one box per bounded position, each admitting the path from
    the second position on (it raised a shape error when the growth met a fence)."""
    growth = step_growth(0.01, DT, 3)
    fence = GeofenceRows(2, 3, DT, np.array([-1.0, -1.0]), np.array([1.0, 1.0]), 0.1, growth=growth)
    p0, free = np.zeros((1, 2)), np.zeros((3, 1, 2))
    path = np.zeros((3, 1, 2))
    path[:, 0, 0] = [0.5, 0.85, 1.2]  # the last past its shrunk box's 0.88
    out = admitted((fence,), p0, free, path)
    lo, hi = fence.box(p0)
    forced = path - free  # the rows bound the forced response by the box less the free one
    assert np.all(lo[1:] - out[1:] <= forced[1:]) and np.all(forced[1:] <= hi[1:] - out[1:])
    np.testing.assert_allclose(out[:, 0, 0], [0.0, 0.0, 0.88 - 1.2])  # moved only where it must


def test_a_path_below_the_floor_is_turned_upwards_and_climbs_at_a_max() -> None:
    """A braking path sinking through the floor (a velocity offset of -0.1 m/s carried over the
    plan) turns upwards; its commands climb by ``a_max dt`` a step from the last one to the rest
    command (0.1 m/s, the offset cancelled) plus one step, the other axis keeps braking, and a
    path inside the box turns nowhere."""
    fence = GeofenceRows(2, 4, DT, np.array([-1.0, 0.0]), np.array([1.0, 2.0]), 0.0)
    p0 = np.array([[0.0, 0.02], [0.0, 1.0]])
    sinking = np.zeros((4, 2, 2))
    sinking[:, :, 1] = -0.01 * np.arange(1, 5)[:, None]  # both sink 1 cm a step
    np.testing.assert_array_equal(inwards((fence,), p0, sinking), [[0.0, 1.0], [0.0, 0.0]])
    brake = np.zeros((4, 2, 2))
    brake[:, :, 0] = [[0.3], [0.2], [0.1], [0.0]]
    u_prev, rest = np.array([[0.4, -0.05], [0.4, -0.05]]), np.array([[0.0, 0.1], [0.0, 0.1]])

    def box(u: np.ndarray, prev: np.ndarray) -> np.ndarray:
        return prev + np.clip(u - prev, -0.1, 0.1)

    up = turned_inwards(brake, u_prev, rest, np.array([[0.0, 1.0], [0.0, 0.0]]), 0.1, box)
    np.testing.assert_allclose(up[:, 0, 1], [0.05, 0.15, 0.2, 0.2])  # to rest + one step, 0.1 a step
    np.testing.assert_allclose(up[:, :, 0], brake[:, :, 0], atol=1e-15)  # still braking along x
    np.testing.assert_allclose(up[:, 1], brake[:, 1], atol=1e-15)  # drone 1 stays in the box: not turned

"""The limits' row families: hand-computed rows, the sparse and dense forms agree, violators match."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import dense_matrix, z_of
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import HalfspaceIntersection

from mpcform.mpc.constraints.limits import (
    AccelerationRows,
    GeofenceRows,
    LimitRows,
    VelocityRows,
    limit_rows,
    velocity_polytope,
    velocity_set,
    violators,
)
from mpcform.mpc.constraints.rows import Layout, positions_of_inputs, step_growth
from mpcform.mpc.settings import MPCSettings
from mpcform.world.limits import Limits

DT = 0.1


def _families() -> tuple[LimitRows, ...]:
    lim = Limits(v_max_mps=1.0, a_max_mps2=4.0, geofence_min_m=[-1.0, -1.0], geofence_max_m=[1.0, 1.0])
    return limit_rows(2, DT, lim, MPCSettings(horizon=4))


def test_velocity_rows_of_one_drone_and_step_by_hand() -> None:
    """Planar square (4 facets): rows are the four normals, each bounded by cos(pi/4) v_max."""
    fam = VelocityRows(2, 1, MPCSettings(facets=4), 2.0)
    lay = Layout(1, 2, 1)
    c = np.sqrt(0.5)
    want = np.array([[c, c], [-c, c], [-c, -c], [c, -c]])
    block = fam.sparse(lay)
    np.testing.assert_allclose(dense_matrix(block, lay)[:, :2], want, atol=1e-15)
    np.testing.assert_allclose(block.upper, 2.0 * c)
    assert np.all(block.lower == -np.inf)
    np.testing.assert_allclose(fam.dense(), want, atol=1e-15)
    lo, hi = fam.dense_bounds(np.zeros((3, 2)), np.zeros((3, 2)), 1e30)
    assert lo.shape == (3, 4) and np.all(lo == -1e30) and np.allclose(hi, 2.0 * c)


@pytest.mark.parametrize("dim", [2, 3])
def test_velocity_polytope_is_inscribed_in_the_ball(dim: int) -> None:
    normals, h = velocity_polytope(dim, None)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    rng = np.random.default_rng(dim)
    u = rng.normal(size=(20000, dim))
    inside = u[(u @ normals.T <= h).all(axis=1)]
    assert inside.shape[0] > 0 and np.linalg.norm(inside, axis=1).max() <= 1.0 + 1e-12


@pytest.mark.parametrize(
    ("dim", "facets"),
    [(2, 4), (2, 5), (2, 16), (2, 17), (2, 64), (3, 8), (3, 12), (3, 32), (3, 33), (3, 100)],
)
def test_velocity_polytope_vertices_are_within_v_max(dim: int, facets: int) -> None:
    """Every vertex of ``{D u <= h v_max}`` (enumerated with HalfspaceIntersection) lies in the ball
    of radius v_max, and some vertex is on the ball (h is not needlessly small) in the spatial case,
    where h is computed from the vertices; planar vertices all lie on the ball."""
    v_max = 2.5
    normals, h = velocity_set(dim, MPCSettings(facets=facets), v_max)
    halfspaces = np.column_stack([normals, -np.full(facets, h)])
    verts = HalfspaceIntersection(halfspaces, np.zeros(dim)).intersections
    radius = np.linalg.norm(verts, axis=1)
    assert radius.max() <= v_max * (1 + 1e-12)
    assert radius.max() == pytest.approx(v_max, rel=1e-9)
    if dim == 2:
        np.testing.assert_allclose(radius, v_max, rtol=1e-12)


def test_box_velocity_set() -> None:
    fam = VelocityRows(3, 2, MPCSettings(velocity_set="box"), 3.0)
    np.testing.assert_array_equal(fam.normals, np.vstack([np.eye(3), -np.eye(3)]))
    assert fam.h_mps == pytest.approx(3.0 / np.sqrt(3.0))


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


def test_limit_rows_in_qp_order() -> None:
    assert [type(f) for f in _families()] == [VelocityRows, AccelerationRows, GeofenceRows]
    assert limit_rows(2, DT, Limits(), MPCSettings()) == ()


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


@pytest.mark.parametrize("velocity_set", ["polytope", "box"])
def test_velocity_violators_near_the_inscribed_ball(velocity_set: str) -> None:
    """The test skips drones inside the inscribed ball ``||u|| <= h``: the same answer as every
    facet checked, also for inputs within rounding of the ball and of a facet."""
    rng = np.random.default_rng(3)
    rows = VelocityRows(3, 4, MPCSettings(velocity_set=velocity_set), 1.0)
    direction = rng.normal(size=(4, 200, 3))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    scale = rows.h_mps * (1.0 + rng.choice([-0.3, -1e-9, -1e-15, 0.0, 1e-15, 0.3], (1, 200, 1)))  # per drone
    near = np.array([[1 - 1e-16], [1.0], [1 + 1e-15]])  # three drones on the first facet, within rounding
    on_facet = np.broadcast_to(rows.normals[0] * rows.h_mps, (4, 3, 3)) * near
    for u in (direction * scale, on_facet):
        brute = (u @ rows.normals.T > rows.h_mps).any(axis=(0, 2))
        got = rows.violators(np.zeros(u.shape[1:]), np.zeros(u.shape[1:]), u, np.zeros_like(u))
        np.testing.assert_array_equal(got, brute)
        assert brute.any() and not brute.all()  # both answers occur


@pytest.mark.parametrize("velocity_set", ["polytope", "box"])
def test_a_vertical_bound_squeezes_the_velocity_set_into_its_spheroid(velocity_set: str) -> None:
    """With ``v_max_z`` every vertex of the set lies in the spheroid ``||S u|| <= v_max`` (so within
    v_max and v_max_z), some on it, and the violator test (inscribed spheroid first) agrees with
    every facet checked, also for inputs well inside the ball that climb too fast."""
    lim = Limits(v_max_mps=2.0, v_max_z_mps=0.5)
    scale = lim.speed_scale(3)
    np.testing.assert_array_equal(scale, [1.0, 1.0, 4.0])
    rows = VelocityRows(3, 2, MPCSettings(velocity_set=velocity_set), 2.0, scale)
    halfspaces = np.column_stack([rows.normals, -np.full(rows.normals.shape[0], rows.h_mps)])
    verts = HalfspaceIntersection(halfspaces, np.zeros(3)).intersections
    squeezed = np.linalg.norm(verts * scale, axis=1)
    assert squeezed.max() <= 2.0 * (1 + 1e-12) and np.abs(verts[:, 2]).max() <= 0.5 * (1 + 1e-12)
    if velocity_set == "polytope":
        assert squeezed.max() == pytest.approx(2.0, rel=1e-9)
    rng = np.random.default_rng(5)
    u = rng.normal(size=(2, 300, 3))
    u *= rng.uniform(0.0, 1.0, (1, 300, 1)) / np.linalg.norm(u, axis=-1, keepdims=True)  # inside ||u|| <= 1
    brute = (u @ rows.normals.T > rows.h_mps).any(axis=(0, 2))
    got = rows.violators(np.zeros((300, 3)), np.zeros((300, 3)), u, np.zeros_like(u))
    np.testing.assert_array_equal(got, brute)
    assert brute.any() and not brute.all()  # the climbs beyond v_max_z are caught
    np.testing.assert_array_equal(limit_rows(3, DT, lim, MPCSettings(horizon=2))[0].scale, scale)
    np.testing.assert_array_equal(Limits(v_max_mps=2.0, v_max_z_mps=0.5).speed_scale(2), [1.0, 1.0])
    np.testing.assert_array_equal(Limits(v_max_mps=2.0, v_max_z_mps=3.0).speed_scale(3), [1.0, 1.0, 1.0])


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

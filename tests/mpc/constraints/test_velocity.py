"""The velocity set's rows: by hand, inscribed in the ball (or its spheroid), violators near it."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import dense_matrix
from scipy.spatial import HalfspaceIntersection

from mpcform.mpc.constraints.limits import limit_rows
from mpcform.mpc.constraints.rows import Layout
from mpcform.mpc.constraints.velocity import VelocityRows, velocity_polytope, velocity_set
from mpcform.mpc.settings import MPCSettings
from mpcform.world.limits import Limits

DT = 0.1


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

"""Separation rows about the guess: pair and obstacle rows by hand, shortfall, subsets, clear test."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import bounds_of
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import sparse

from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.candidates import Candidates
from mpcform.mpc.constraints.half_spaces import segment_normals
from mpcform.mpc.constraints.pairs import PairSeparation
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.settings import MPCSettings
from mpcform.world.closest import closest_in_hull
from mpcform.world.limits import Limits
from mpcform.world.shapes import SphereObstacle

MARGIN = 2e-3  # the default margin


def still(p0: np.ndarray, horizon: int) -> np.ndarray:
    """A guess (H + 1, n, d) that holds at p0."""
    return np.broadcast_to(p0, (horizon + 1,) + p0.shape)


def planned(p0: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The plan's positions (H + 1, n, d) of relative positions ``x`` (H, n, d) from ``p0``."""
    return np.concatenate([p0[None], p0 + x])


def cand(pairs: list[list[int]], obstacles: list[list[int]] | None = None) -> Candidates:
    """Every item within reach."""
    p = np.array(pairs, dtype=np.intp).reshape(-1, 2)
    o = np.array(obstacles or [], dtype=np.intp).reshape(-1, 2)
    return Candidates(p, np.ones(p.shape[0], bool), o, np.ones(o.shape[0], bool), False)


def test_segment_normals_by_hand() -> None:
    rel = np.array([[[2.0, 1.0], [2.0, -1.0]], [[0.0, 0.0], [0.0, 0.0]]])  # (m = 2, H + 1 = 2, d)
    normals = segment_normals(rel, np.array([0]))
    np.testing.assert_allclose(normals[0, 0], [1.0, 0.0])  # closest point (2, 0)
    np.testing.assert_allclose(normals[1, 0], [1.0, 0.0])  # coincident: a fixed unit vector


@pytest.mark.parametrize("dim", [2, 3])
def test_the_closest_point_of_a_hull_is_the_qps(dim: int) -> None:
    """``closest_in_hull`` against clarabel's minimum-norm point ``min |P^T w|`` over the simplex,
    for random hulls of 2-9 points and of 10-40 (in 3-D: the descent, a spatial quadrotor's tail)
    that keep the origin outside (the braking tail's rows), and the closest point's own
    certificate: every point of the hull is at least as far along it."""
    import qpsolvers

    rng = np.random.default_rng(dim)
    for trial in range(90):
        k = 2 + trial % 8 if trial < 60 else 10 + trial % 31
        pts = rng.normal(size=(k, dim)) + rng.uniform(0.5, 3.0) * rng.normal(size=dim)
        hess, row = sparse.csc_matrix(pts @ pts.T), sparse.csc_matrix(np.ones((1, k)))
        w = qpsolvers.solve_qp(hess, np.zeros(k), A=row, b=np.ones(1), lb=np.zeros(k), solver="clarabel")
        want = w @ pts
        if np.linalg.norm(want) < 1e-6:  # the origin inside: no normal is sought
            continue
        got = closest_in_hull(pts[None])[0]
        assert np.linalg.norm(got) == pytest.approx(np.linalg.norm(want), abs=1e-6)
        assert np.all(pts @ got >= got @ got - 1e-12)  # and the certificate: (p - got)^T got >= 0


def test_the_tails_rows_share_the_hulls_normal() -> None:
    """With three tail points every tail row of an item has the normal towards its guess hull's
    closest point (here the middle point's side of the triangle), not the chord's."""
    rel = np.array([[[3.0, 0.0], [2.0, 0.0], [1.0, 1.0], [1.0, -1.0], [2.0, 0.0]]])  # x_1, then 3 points
    normals = segment_normals(rel, np.array([0, 1, 1, 1, 1]), tail=3)
    np.testing.assert_allclose(normals[0, 0], [1.0, 0.0])
    np.testing.assert_allclose(normals[0, 1:], np.tile([[1.0, 0.0]], (4, 1)))  # the edge x = 1
    chord = segment_normals(rel[:, [0, 1, 4]], np.array([0, 1]))
    np.testing.assert_allclose(chord[0, 1], [1.0, 0.0])


def test_joint_pair_row_by_hand() -> None:
    """Drones at (0, 0) and (1, 0), guess holding: normal (-1, 0),
    ``-(x_0 - x_1)_x >= d_min + margin - 1``."""
    p0 = np.array([[0.0, 0.0], [1.0, 0.0]])
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=1), ())
    rows = sep.rows(p0, still(p0, 1), cand([[0, 1]]))
    np.testing.assert_allclose(rows.pair_coeffs, [[[-1.0, 0.0]]])
    np.testing.assert_allclose(rows.pair_lower, [[0.5 + MARGIN - 1.0]])
    assert rows.singles.shape == (0,)


def test_decoupled_pair_rows_by_hand() -> None:
    """The same pair decoupled: each drone keeps half of d_min from the midpoint (0.5, 0)."""
    p0 = np.array([[0.0, 0.0], [1.0, 0.0]])
    sep = Separation(
        2, bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=1, coupling="decoupled"), ()
    )
    rows = sep.rows(p0, still(p0, 1), cand([[0, 1]]))
    assert rows.pairs.shape == (0, 2)
    np.testing.assert_array_equal(rows.labels, [[0, 1], [1, 0]])
    np.testing.assert_array_equal(rows.singles, [0, 1])
    np.testing.assert_allclose(rows.single_coeffs, [[[-1.0, 0.0]], [[1.0, 0.0]]])
    half = 0.5 * (0.5 + MARGIN)
    np.testing.assert_allclose(rows.single_lower, [[half - 0.5], [half - 0.5]])


def test_downwash_pair_row_by_hand() -> None:
    """Stacked 1 m apart in z, kappa 2: metric distance 0.5, row ``-0.5 (x_0 - x_1)_z >= 0.502 - 0.5``."""
    p0 = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    sep = Separation(3, bounds_of(v_max_mps=1.0, d_min_m=0.5, downwash_kappa=2.0), MPCSettings(horizon=1), ())
    rows = sep.rows(p0, still(p0, 1), cand([[0, 1]]))
    np.testing.assert_allclose(rows.pair_coeffs, [[[0.0, 0.0, -0.5]]])
    np.testing.assert_allclose(rows.pair_lower, [[MARGIN]], atol=1e-15)


def test_obstacle_row_by_hand() -> None:
    """Drone at (3, 0), obstacle radius 1 at the origin, clearance 0.5: ``x_x >= 1.5 + margin - 3``."""
    p0 = np.array([[3.0, 0.0]])
    ob = SphereObstacle(np.zeros(2), 1.0, clearance_m=0.5)
    sep = Separation(2, bounds_of(v_max_mps=1.0), MPCSettings(horizon=1), (ob,))
    rows = sep.rows(p0, still(p0, 1), cand([], [[0, 0]]))
    np.testing.assert_array_equal(rows.labels, [[0, -1]])
    np.testing.assert_allclose(rows.single_coeffs, [[[1.0, 0.0]]])
    np.testing.assert_allclose(rows.single_lower, [[1.5 + MARGIN - 3.0]])


def test_rows_at_both_segment_ends() -> None:
    """Horizon 3: R = 5 rows per item, segment j's normal at x_{j+1} and x_j."""
    p0 = np.array([[0.0, 0.0], [1.0, 0.0]])
    guess = np.array([p0, p0 + [[0, 0], [0, 1]], p0 + [[0, 0], [0, 2]], p0 + [[0, 0], [0, 2]]])
    pairs = PairSeparation(0.5, np.ones(2), MPCSettings(horizon=3))
    path = guess.transpose(1, 0, 2)  # drone-major
    (labels, coeffs, lower, on, _), singles = pairs.rows(p0, path, np.array([[0, 1]]), np.ones(1, bool))
    assert coeffs.shape == (1, 5, 2) and lower.shape == (1, 5) and singles is None
    np.testing.assert_allclose(coeffs[0, 0], [-1.0, 0.0])  # segment 0 starts at the closest point
    np.testing.assert_allclose(coeffs[0, 1], coeffs[0, 2])  # segment 1's two rows share a normal
    np.testing.assert_allclose(coeffs[0, 3], coeffs[0, 4])


def test_shortfall_and_conflicted_drones() -> None:
    """Drone 0 moves 0.6 m towards drone 1 (1 m away): its row is missed by 0.6 - 0.498."""
    p0 = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 5.0]])
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=1), ())
    rows = sep.rows(p0, still(p0, 1), cand([[0, 1]]))
    x = np.zeros((1, 3, 2))
    x[0, 0] = [0.6, 0.0]
    worst, missed = sep.shortfall(x, rows, 0.0)
    assert worst == pytest.approx(0.6 - (1.0 - 0.5 - MARGIN))
    np.testing.assert_array_equal(missed, [[0, 1]])
    np.testing.assert_array_equal(sep.conflicted(x, rows), [True, True, False])
    x[0, 0] = [0.4, 0.0]
    assert sep.shortfall(x, rows, 0.0)[1].shape == (0, 2) and not sep.conflicted(x, rows).any()


def test_a_decoupled_pairs_shortfall_taken_jointly_is_the_joint_rows() -> None:
    """Both drones 1 m apart move +0.4 m along x: drone 0 misses its midpoint row (0.251 m from the
    midpoint) by 0.151 m, drone 1 keeps its own by 0.4 m more, and the pair stays 1 m apart: taken
    jointly (as a split moved from the midpoint leaves a pair), no shortfall. Drone 0 moving 0.6 m
    closer alone misses the pair's joint row by ``0.6 - (1 - 0.5 - margin)``, as in joint mode; an
    obstacle's row stays its own."""
    p0 = np.array([[0.0, 0.0], [1.0, 0.0]])
    settings = MPCSettings(horizon=1, coupling="decoupled")
    sphere = (SphereObstacle(np.array([0.0, 3.0]), 0.5, 0.25),)
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.5), settings, sphere)
    rows = sep.rows(p0, still(p0, 1), cand([[0, 1]], [[0, 0]]))
    x = np.full((1, 2, 2), [0.4, 0.0])
    assert sep.shortfall(x, rows, 0.0)[0] == pytest.approx(0.4 - (0.5 - 0.5 * (0.5 + MARGIN)))
    assert sep.shortfall(x, rows, 0.0, joint=True)[1].shape == (0, 2)
    x = np.zeros((1, 2, 2))
    x[0, 0] = [0.6, 0.0]
    worst, missed = sep.shortfall(x, rows, 0.0, joint=True)
    assert worst == pytest.approx(0.6 - (1.0 - 0.5 - MARGIN))
    np.testing.assert_array_equal(missed, [[0, 1]])
    x[0, 0] = [0.0, 2.5]  # into the sphere's clearance
    np.testing.assert_array_equal(sep.shortfall(x, rows, 0.0, joint=True)[1], [[0, -1]])


def test_subset_renumbers_drones() -> None:
    p0 = np.array([[0.0, 0.0], [1.0, 0.0], [9.0, 0.0], [9.0, 1.0]])
    lim, st_ = bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=2, coupling="decoupled")
    rows = Separation(2, lim, st_, ()).rows(p0, still(p0, 2), cand([[0, 1], [2, 3]]))
    sub = rows.subset(np.array([2, 3]), 4, on_only=True)
    np.testing.assert_array_equal(sub.singles, [0, 1])  # drones 2, 3 renumbered
    np.testing.assert_array_equal(sub.labels, [[2, 3], [3, 2]])  # labels keep the global numbers
    np.testing.assert_allclose(sub.single_lower, rows.single_lower[[1, 3]])
    assert rows.subset(np.arange(4), 4, on_only=False) is rows


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_clear_means_no_joint_or_obstacle_row_is_missed(seed: int) -> None:
    """The cheap clear test is sufficient: when it passes, the joint pair rows and the obstacle rows
    are all met (so every pair stays d_min apart over each step)."""
    rng = np.random.default_rng(seed)
    n, h = 4, 4
    p0 = rng.uniform(-3.0, 3.0, (n, 2))  # about half of the draws pass the clear test
    guess = p0 + np.cumsum(np.concatenate([np.zeros((1, n, 2)), rng.uniform(-0.1, 0.1, (h, n, 2))]), axis=0)
    x = np.cumsum(rng.uniform(-0.1, 0.1, (h, n, 2)), axis=0)
    ob = SphereObstacle(np.array([0.0, 0.0]), 0.3, clearance_m=0.25)  # d_min / 2
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=h), (ob,))
    everything = cand([[i, k] for i in range(n) for k in range(i + 1, n)], [[i, 0] for i in range(n)])
    rows = sep.rows(p0, guess, everything)
    if sep.clear(guess, planned(p0, x)):
        assert sep.shortfall(x, rows, 0.0)[0] <= 1e-12


def test_clear_does_not_cover_the_decoupled_rows() -> None:
    """Two drones flying side by side, 0.6 m apart: the pair stays clear, but each crosses the
    guess's midpoint plane (its decoupled row asks for 0.251 m from the holding guess's midpoint)."""
    p0 = np.array([[0.0, 0.0], [0.6, 0.0]])
    x = np.broadcast_to([0.1, 0.0], (2, 2, 2)) * np.array([1.0, 2.0])[:, None, None]
    for coupling, missed in (("joint", False), ("decoupled", True)):
        sep = Separation(
            2, bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=2, coupling=coupling), ()
        )
        assert sep.clear(still(p0, 2), planned(p0, x))
        rows = sep.rows(p0, still(p0, 2), cand([[0, 1]]))
        assert (sep.shortfall(x, rows, 0.0)[0] > 0) == missed


def test_clear_fails_head_on() -> None:
    p0 = np.array([[0.0, 0.0], [1.0, 0.0]])
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=2), ())
    apart = np.zeros((2, 2, 2))
    assert sep.clear(still(p0, 2), planned(p0, apart))
    towards = np.array([[[0.2, 0.0], [-0.2, 0.0]], [[0.4, 0.0], [-0.4, 0.0]]])
    assert not sep.clear(still(p0, 2), planned(p0, towards))


def test_first_segment_items_within_reach() -> None:
    p0 = np.array([[0.0, 0.0], [1.0, 0.0]])
    ob = SphereObstacle(np.array([0.0, 2.0]), 0.5, clearance_m=0.2)  # d_min / 2
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.4), MPCSettings(), (ob,))
    c = cand([[0, 1]], [[1, 0]])
    (a, b, d_pair), (oa, ob_, d_ob) = sep.first_segment(p0, p0 + 0.1, c)
    np.testing.assert_allclose(a, [1.0])  # the pair's distance at the start, and along the segment
    np.testing.assert_allclose(b, [1.0])
    assert d_pair == 0.4
    np.testing.assert_allclose(oa, [np.hypot(1.0, 2.0)])  # drone 1 from the centre (0, 2)
    np.testing.assert_allclose(ob_, [np.hypot(1.1, 1.9)])  # at its segment's end, the nearest
    np.testing.assert_allclose(d_ob, [0.5 + 0.2])  # radius + half of d_min
    off = Candidates(c.pairs, np.zeros(1, bool), c.obstacles, np.zeros(1, bool), False)
    assert sep.first_segment(p0, p0, off) == []


@pytest.mark.parametrize("coupling", ["joint", "decoupled"])
def test_a_pair_inside_d_min_gets_a_hard_no_approach_row(coupling: str) -> None:
    """0.3 m apart (d_min 0.5) along x: row 0 (at x_1) is ``c0^T (x_0 - x_1) >= 0``, c0 = (-1, 0), hard."""
    p0 = np.array([[0.0, 0.0], [0.3, 0.0], [5.0, 0.0]])
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=3, coupling=coupling), ())
    rows = sep.rows(p0, still(p0, 3), cand([[0, 1], [1, 2]]))
    if coupling == "joint":
        np.testing.assert_array_equal(rows.pair_hard, [True, False])
        np.testing.assert_allclose(rows.pair_coeffs[0, 0], [-1.0, 0.0])
        assert rows.pair_lower[0, 0] == 0.0 and rows.pair_lower[0, 1] > 0.1  # the others still ask d_min
    else:
        np.testing.assert_array_equal(rows.single_hard, [True, False, True, False])
        np.testing.assert_allclose(rows.single_coeffs[rows.single_hard, 0], [[-1.0, 0.0], [1.0, 0.0]])
        np.testing.assert_allclose(rows.single_lower[rows.single_hard, 0], 0.0)
    short, labels = sep.start_shortfall(p0, rows)
    assert short == pytest.approx(0.2) and labels.tolist() == [[0, 1]]


def test_a_start_a_solver_tolerance_inside_is_no_shortfall() -> None:
    """A pair that starts 1e-9 m inside d_min (the last plan met its row to the solver's tolerance)
    gets the hard row, but only a shortfall beyond ``tol_m`` is reported."""
    p0 = np.array([[0.0, 0.0], [0.5 - 1e-9, 0.0]])
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=3), ())
    rows = sep.rows(p0, still(p0, 3), cand([[0, 1]]))
    assert rows.pair_hard.tolist() == [True]
    assert sep.start_shortfall(p0, rows)[0] == pytest.approx(1e-9, abs=1e-12)
    short, labels = sep.start_shortfall(p0, rows, 1e-6)
    assert short == 0.0 and labels.shape == (0, 2)


def test_a_drone_inside_an_obstacles_clearance_gets_a_hard_row_and_a_push() -> None:
    ob = SphereObstacle(np.zeros(2), 1.0, clearance_m=0.5)
    p0 = np.array([[0.0, 1.2]])  # 0.3 m inside
    sep = Separation(2, bounds_of(v_max_mps=1.0), MPCSettings(horizon=2), (ob,))
    rows = sep.rows(p0, still(p0, 2), cand([], [[0, 0]]))
    assert rows.single_hard.tolist() == [True]
    np.testing.assert_allclose(rows.single_coeffs[0, 0], [0.0, 1.0])
    assert rows.single_lower[0, 0] == 0.0
    assert sep.start_shortfall(p0, rows)[0] == pytest.approx(0.3)
    np.testing.assert_allclose(sep.push_apart(p0, cand([], [[0, 0]])), [[0.0, 1.0]])


def test_blocked_targets_are_the_pairs_within_d_min_in_the_metric() -> None:
    """Targets 0.45 m apart block each other under d_min 0.5, 0.6 m apart do not; with downwash
    (kappa 2) a vertical 0.8 m counts as 0.4 m; obstacles never block (a moving reference may pass
    through one)."""
    ob = SphereObstacle(np.array([5.0, 5.0, 0.0]), 1.0, clearance_m=0.25)
    sep = Separation(3, bounds_of(v_max_mps=1.0, d_min_m=0.5, downwash_kappa=2.0), MPCSettings(), (ob,))
    targets = np.array([[0, 0, 0], [0.45, 0, 0], [3, 0, 0], [3, 0, 0.8], [6, 0, 0], [5, 5, 0.0]])
    np.testing.assert_array_equal(sep.blocked_targets(targets), [True, True, True, True, False, False])
    sep = Separation(3, bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(), ())
    assert not sep.blocked_targets(
        targets + np.array([[0, 0, 0], [0.15, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]])
    )[:2].any()


def test_targets_within_two_tubes_of_the_tightened_distance_are_blocked() -> None:
    """A plant tube of 0.04 m (limits tightened to d_min 0.58): targets 0.6 m apart are blocked
    (0.6 < 0.58 + 2 x 0.04: the plant cannot hold both without the pair in conflict), 0.7 m apart
    are not; without a tube 0.6 m apart are not."""
    from mpcform.world.bounds import planning_bounds

    targets = np.array([[0.0, 0.0], [0.6, 0.0], [5.0, 0.0], [5.7, 0.0]])
    planned, _ = planning_bounds(Limits(v_max_mps=1.0, d_min_m=0.5), (), 0.04, None)
    assert planned.tube_m == 0.04 and planned.d_min_m == pytest.approx(0.58)
    sep = Separation(2, planned, MPCSettings(), ())
    np.testing.assert_array_equal(sep.blocked_targets(targets), [True, True, False, False])
    plain = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.58), MPCSettings(), ())
    assert not plain.blocked_targets(targets).any()


@pytest.mark.parametrize("kappa", [None, 2.0])
def test_the_block_size_leaves_the_rows(kappa: float | None, monkeypatch: pytest.MonkeyPatch) -> None:
    """Decoupled rows built a few pairs at a time, or all at once, with close starts (hard rows):
    the same rows and row values, bit for bit."""
    rng = np.random.default_rng(4)
    n, h = 9, 4
    p0 = rng.uniform(-1.0, 1.0, (n, 3))
    guess = p0 + np.cumsum(np.concatenate([np.zeros((1, n, 3)), rng.uniform(-0.1, 0.1, (h, n, 3))]), axis=0)
    x = np.cumsum(rng.uniform(-0.1, 0.1, (h, n, 3)), axis=0)
    lim = bounds_of(v_max_mps=1.0, d_min_m=0.5, downwash_kappa=kappa)
    ob = SphereObstacle(np.zeros(3), 0.2, clearance_m=0.25)
    sep = Separation(3, lim, MPCSettings(horizon=h, coupling="decoupled"), (ob,))
    items = cand([[i, k] for i in range(n) for k in range(i + 1, n)], [[i, 0] for i in range(n)])
    out = []
    for block in (2, 1024):
        monkeypatch.setattr("mpcform.mpc.constraints.separation.BLOCK", block)
        rows = sep.rows(p0, guess, items)
        out.append((rows, sep.single_values(x, rows), sep.conflicted(x, rows), sep.meets_joint(x, rows)))
    (a, va, ca, ja), (b, vb, cb, jb) = out
    assert a.single_hard.any() and ca.any() and not ja  # close starts, conflicts
    for field in ("labels", "single_coeffs", "single_lower", "single_on", "single_hard"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    assert np.array_equal(va, vb) and np.array_equal(ca, cb) and ja == jb


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_the_clear_test_answers_the_same_when_it_tries_the_least_clear_first(seed: int) -> None:
    """Many pairs in doubt (a jittered grid): trying the least clear few first, or none, gives one
    answer (about a third of the draws pass)."""
    monkey = pytest.MonkeyPatch()
    rng = np.random.default_rng(seed)
    n, h = 100, 3  # a k-d tree, often more than 8 pairs in doubt
    grid = 0.6 * np.stack(np.meshgrid(np.arange(10), np.arange(10)), -1).reshape(-1, 2)
    p0 = grid + rng.uniform(-0.08, 0.08, (n, 2)) + 3.0
    guess = p0 + np.cumsum(np.concatenate([np.zeros((1, n, 2)), rng.uniform(-0.02, 0.02, (h, n, 2))]), axis=0)
    x = np.cumsum(rng.uniform(-0.02, 0.02, (h, n, 2)), axis=0)
    ob = SphereObstacle(np.zeros(2), 0.5, clearance_m=0.175)  # d_min / 2
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.35), MPCSettings(horizon=h), (ob,))
    answers = []
    for first in (1, 10_000):
        monkey.setattr("mpcform.mpc.constraints.clear.FIRST_TESTED", first)
        answers.append(sep.clear(guess, planned(p0, x)))
    monkey.undo()
    assert answers[0] == answers[1]


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_the_clear_test_answers_the_same_with_its_neighbour_list_kept_between_steps(seed: int) -> None:
    """A jittered grid drifting over several steps: one Separation (its neighbour list kept) answers
    as a fresh one at every step."""
    rng = np.random.default_rng(seed)
    n, h = 100, 3
    grid = 0.6 * np.stack(np.meshgrid(np.arange(10), np.arange(10)), -1).reshape(-1, 2)
    p0 = grid + rng.uniform(-0.08, 0.08, (n, 2))
    limits, st_h = bounds_of(v_max_mps=1.0, d_min_m=0.35), MPCSettings(horizon=h)
    kept = Separation(2, limits, st_h, ())
    for _ in range(8):
        steps = np.concatenate([np.zeros((1, n, 2)), rng.uniform(-0.02, 0.02, (h, n, 2))])
        guess, x = p0 + np.cumsum(steps, axis=0), np.cumsum(rng.uniform(-0.03, 0.03, (h, n, 2)), axis=0)
        fresh = Separation(2, limits, st_h, ())
        assert kept.clear(guess, planned(p0, x)) == fresh.clear(guess, planned(p0, x))
        p0 = p0 + 0.1 + rng.uniform(-0.03, 0.03, (n, 2))


def test_without_the_tail_only_an_obstacles_braking_tail_conflicts() -> None:
    """Horizon 1 with braking: drone 0's stop point lies inside a sphere's clearance, drones 1 and 2
    stop 0.4 m apart (d_min 0.5); every row of the horizon holds. With the tail all three are
    conflicted; without it (the tie-break's encounter test) only drone 0: it turns early for the
    sphere, while a pair's stop rows are left to the QP's braking."""
    lim = bounds_of(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=0.5)
    ob = SphereObstacle(np.array([3.0, 0.0]), 1.0, clearance_m=0.5)
    sep = Separation(2, lim, MPCSettings(horizon=1), (ob,), Braking.of(0.1, lim))
    p0 = np.array([[0.0, 0.0], [0.0, 10.0], [3.0, 10.0]])
    x = np.array([[[0.5, 0.0], [0.5, 0.0], [-0.5, 0.0]], [[1.8, 0.0], [1.3, 0.0], [-1.3, 0.0]]])
    rows = sep.rows(p0, planned(p0, x), cand([[1, 2]], [[0, 0]]))
    np.testing.assert_array_equal(sep.conflicted(x, rows), [True, True, True])
    np.testing.assert_array_equal(sep.conflicted(x, rows, tail=False), [True, False, False])


@pytest.mark.parametrize("coupling", ["joint", "decoupled"])
def test_rows_grow_along_the_horizon_by_the_wind_growth(coupling: str) -> None:
    """With ``growth_m`` the rows at position step e ask for ``min(e - 1, E)`` growths more per
    growing drone (a pair for each of its drones, a decoupled side and an obstacle item for its
    own), the first rows none; the clear test grows with them: a plan that meets the plain rows but
    not the grown ones is not clear. A drone whose target is too close to another's to hold with
    the growth does not grow."""
    p0 = np.array([[0.0, 0.0], [0.9, 0.0], [3.0, 0.0]])
    ob = SphereObstacle(np.array([3.0, 0.6]), 0.2, clearance_m=0.25)
    lim, settings_ = bounds_of(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=4, coupling=coupling)
    c = cand([[0, 1]], [[2, 0]])
    plain_sep = Separation(2, lim, settings_, (ob,), dt_s=0.1)
    plain = plain_sep.rows(p0, still(p0, 4), c)
    sep = Separation(2, replace(lim, growth_m=0.01), settings_, (ob,), dt_s=0.1)
    growing = sep.growing(p0 + np.array([0.0, 5.0]))  # targets far apart: every drone grows
    np.testing.assert_array_equal(growing, [1.0, 1.0, 1.0])
    grown = sep.rows(p0, still(p0, 4), c, growing=growing)
    extra = 0.01 * np.clip(sep.ends - 1, 0, 2)  # E = min(H, ceil(0.2 / 0.1)) = 2
    assert extra[0] == 0.0 and extra.max() == 0.02
    np.testing.assert_allclose(
        grown.pair_lower - plain.pair_lower, 2.0 * np.broadcast_to(extra, plain.pair_lower.shape)
    )
    np.testing.assert_allclose(
        grown.single_lower - plain.single_lower, np.broadcast_to(extra, plain.single_lower.shape)
    )
    x = np.zeros((4, 3, 2))
    x[1:, 1, 0] = -0.39 + 0.005  # pair (0, 1) at 0.515 m from step 2 on: the plain rows hold
    assert plain_sep.clear(still(p0, 4), planned(p0, x))
    assert sep.clear(still(p0, 4), planned(p0, x))  # no growth given
    assert not sep.clear(still(p0, 4), planned(p0, x), growing)
    tight = sep.growing(np.array([[0.0, 0.0], [0.53, 0.0], [3.0, 0.0]]))  # 0.53 < 0.5 + 2e-3 + 0.04
    np.testing.assert_array_equal(tight, [0.0, 0.0, 1.0])
    assert sep.clear(still(p0, 4), planned(p0, x), tight)
    np.testing.assert_allclose(sep.rows(p0, still(p0, 4), c, growing=tight).pair_lower, plain.pair_lower)
    for share in (growing, tight):  # the required distances alone: the rows without growth
        bare = sep.rows(p0, still(p0, 4), c, growing=share).ungrown(share, sep.row_growth)
        np.testing.assert_allclose(bare.pair_lower, plain.pair_lower, atol=1e-15)
        np.testing.assert_allclose(bare.single_lower, plain.single_lower, atol=1e-15)
    assert plain.ungrown(None, sep.row_growth) is plain and plain_sep.row_growth is None


def test_no_growth_without_dt_or_wind() -> None:
    lim = bounds_of(v_max_mps=1.0, d_min_m=0.5, growth_m=0.01)
    assert Separation(2, lim, MPCSettings(), ()).growing(np.zeros((2, 2))) is None  # no dt given
    assert Separation(2, replace(lim, growth_m=0.0), MPCSettings(), (), dt_s=0.1).growth is None

"""Candidate items: reach, hysteresis of the kept set, obstacles, groups of conflicted drones."""

from __future__ import annotations

import numpy as np

from mpcform.mpc.constraints.candidates import Candidates, CandidateSelector, mask_of, qp_drones
from mpcform.mpc.settings import MPCSettings
from mpcform.world.limits import Limits
from mpcform.world.shapes import SphereObstacle
from mpcform.world.shapes.shape_set import ShapeSet

# v_max 1, horizon 2, dt 0.1: travel 0.2 m; pairs within reach 0.5 + 0.002 + 0.4 = 0.902 m, kept
# within one more horizon of reach, 1.302 m
LIMITS = Limits(v_max_mps=1.0, d_min_m=0.5)
SETTINGS = MPCSettings(horizon=2)


def line(*xs: float) -> np.ndarray:
    return np.column_stack([xs, np.zeros(len(xs))])


def test_pairs_within_reach_and_hysteresis() -> None:
    sel = CandidateSelector(3, 0.1, LIMITS, SETTINGS, ShapeSet((), 2))
    first = sel.select(line(0.0, 1.0, 2.5))
    assert first.rebuilt and first.pairs.shape == (0, 2)  # nothing within reach
    near = sel.select(line(0.0, 0.8, 2.5))  # (0, 1) within reach: the set is rebuilt with (0, 1) only
    assert near.rebuilt
    np.testing.assert_array_equal(near.pairs, [[0, 1]])
    np.testing.assert_array_equal(near.pair_on, [True])
    kept = sel.select(line(0.0, 1.0, 2.5))  # out of reach, still kept: same pattern, row off
    assert not kept.rebuilt
    np.testing.assert_array_equal(kept.pairs, [[0, 1]])
    np.testing.assert_array_equal(kept.pair_on, [False])
    grown = sel.select(line(0.0, 1.0, 1.9))  # (1, 2) now within reach: rebuilt
    assert grown.rebuilt
    np.testing.assert_array_equal(grown.pairs, [[0, 1], [1, 2]])
    np.testing.assert_array_equal(grown.pair_on, [False, True])
    sel.reset()
    assert sel.select(line(0.0, 1.0, 1.9)).rebuilt


def test_downwash_widens_the_reach() -> None:
    lim = Limits(v_max_mps=1.0, d_min_m=0.5, downwash_kappa=2.0)  # reach 1.0 + 0.002 + 0.4
    p0 = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.3]])
    assert CandidateSelector(2, 0.1, lim, SETTINGS, ShapeSet((), 2)).select(p0).pair_on.all()
    assert not CandidateSelector(2, 0.1, LIMITS, SETTINGS, ShapeSet((), 2)).select(p0).pair_on.any()


def test_obstacle_items() -> None:
    """Obstacle radius 1 at (3, 0), required 1 + 0.25; gaps within 0.202 are in reach, within
    0.402 kept: drone 0 (gap 0.15) within reach, drone 1 (0.35) only kept, drone 2 (1.75) neither."""
    ob = SphereObstacle(np.array([3.0, 0.0]), 1.0, clearance_m=0.25)  # d_min / 2
    sel = CandidateSelector(3, 0.1, LIMITS, SETTINGS, ShapeSet((ob,), 2))
    cand = sel.select(np.array([[1.6, 0.0], [3.0, 1.6], [3.0, -3.0]]))
    np.testing.assert_array_equal(cand.obstacles, [[0, 0], [1, 0]])
    np.testing.assert_array_equal(cand.obstacle_on, [True, False])
    reach = cand.within_reach()
    np.testing.assert_array_equal(reach.obstacles, [[0, 0]])
    assert reach.obstacle_on.all() and reach.pairs.shape == (0, 2)


def test_within_reach_keeps_only_the_items_on() -> None:
    cand = Candidates(
        np.array([[0, 1], [1, 2]]), np.array([False, True]), np.empty((0, 2), int), np.empty(0, bool), True
    )
    reach = cand.within_reach()
    np.testing.assert_array_equal(reach.pairs, [[1, 2]])
    assert reach.pair_on.all() and reach.rebuilt


def test_qp_drones_are_the_groups_of_the_conflicted() -> None:
    pairs = np.array([[0, 1], [1, 2], [3, 4]])
    bad = np.zeros(6, bool)
    bad[2] = True
    np.testing.assert_array_equal(qp_drones(bad, pairs), [0, 1, 2])
    bad[5] = True  # alone
    np.testing.assert_array_equal(qp_drones(bad, pairs), [0, 1, 2, 5])
    np.testing.assert_array_equal(qp_drones(bad, np.empty((0, 2), int)), [2, 5])


def test_mask_of() -> None:
    codes = np.array([1, 4, 7, 9])
    np.testing.assert_array_equal(mask_of(codes, np.array([4, 9])), [False, True, False, True])
    assert mask_of(codes, np.array([4, 5])) is None
    assert mask_of(codes, np.array([10])) is None
    np.testing.assert_array_equal(mask_of(codes, np.empty(0, int)), [False] * 4)


def test_a_drift_widens_the_reach() -> None:
    """A velocity offset held over the plan carries each drone ``drift_m`` farther: a pair 1.0 m
    apart is out of reach (0.5 + 0.002 + 2 x 0.2 m) without it, within reach with 0.1 m of drift."""
    sel = CandidateSelector(2, 0.1, LIMITS, SETTINGS, ShapeSet((), 2))
    assert sel.select(line(0.0, 1.0)).pairs.shape == (0, 2)
    sel.reset()
    np.testing.assert_array_equal(sel.select(line(0.0, 1.0), drift_m=0.1).pair_on, [True])

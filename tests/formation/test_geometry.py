"""Distances between drones at samples and along straight segments, against brute force."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.distance import pdist

from mpcform.formation.geometry import (
    NearPairs,
    count_pairs_within,
    drone_spreads,
    min_pair_distance,
    min_pair_distances,
    min_path_distance,
    min_segment_distance,
    pairs_within,
)
from mpcform.world.closest import closest_on_segments, squared_norms, vector_norms

TAU = np.linspace(0.0, 1.0, 2001)
seeds = st.integers(0, 2**32 - 1)


def brute_min_segment_distance(start, end):
    """Min over a dense grid of tau and all pairs; exceeds the true min by at most L dtau / 2."""
    path = start + TAU[:, None, None] * (end - start)  # (M, n, d)
    dist = np.linalg.norm(path[:, :, None] - path[:, None], axis=-1)
    i, j = np.triu_indices(start.shape[0], 1)
    return dist[:, i, j].min()


def random_motion(seed, n, dim):
    rng = np.random.default_rng(seed)
    start = rng.uniform(-3.0, 3.0, (n, dim))
    return start, start + rng.uniform(-4.0, 4.0, (n, dim))


@given(seeds, st.integers(2, 7), st.sampled_from([2, 3]))
def test_min_segment_distance_matches_dense_sampling(seed, n, dim):
    start, end = random_motion(seed, n, dim)
    exact, brute = min_segment_distance(start, end), brute_min_segment_distance(start, end)
    # each pair distance is Lipschitz in tau with constant |delta_i - delta_j|
    move = end - start
    lipschitz = pdist(move).max()
    assert exact <= brute + 1e-12
    assert brute - exact <= lipschitz * (TAU[1] - TAU[0]) / 2 + 1e-12


def test_min_segment_distance_sees_a_far_pair_cross():
    """A close static pair must not hide a far pair that passes closer mid-segment."""
    start = np.array([[0.0, 0.0], [1.0, 0.0], [20.0, 5.0], [30.0, 5.2]])
    end = np.array([[0.0, 0.0], [1.0, 0.0], [30.0, 5.0], [20.0, 5.2]])
    assert min_segment_distance(start, end) == pytest.approx(0.2)
    assert min(min_pair_distance(start), min_pair_distance(end)) == pytest.approx(1.0)


def test_min_segment_distance_special_cases():
    assert min_segment_distance(np.zeros((1, 3)), np.ones((1, 3))) == np.inf
    start = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    assert min_segment_distance(start, start + [1.0, 2.0, 3.0]) == pytest.approx(2.0)  # parallel
    assert min_segment_distance(start, start[::-1]) == 0.0  # head-on swap


@pytest.mark.parametrize(("n", "t"), [(1, 5), (7, 1000), (48, 200), (49, 20)])
def test_min_pair_distances_are_min_pair_distance_at_every_sample_bit_for_bit(n, t):
    rng = np.random.default_rng(n * t)
    path = rng.uniform(-1.0, 1.0, (t, n, 2)) * np.sqrt(n)
    expected = np.array([min_pair_distance(p) for p in path])
    assert min_pair_distances(path).tobytes() == expected.tobytes()


@pytest.mark.parametrize(("n", "t"), [(1, 5), (7, 1000), (48, 200), (49, 20)])
def test_count_pairs_within_counts_pairs_within_at_every_sample(n, t):
    """Blocks of every pair (n <= 48, over several blocks) and the k-d tree (n > 48) alike."""
    rng = np.random.default_rng(n + t)
    path = rng.uniform(-1.0, 1.0, (t, n, 3)) * np.sqrt(n)
    expected = sum(pairs_within(p, 0.4).shape[0] for p in path)
    assert count_pairs_within(path, 0.4) == expected
    assert n < 7 or expected > 0


def test_count_pairs_within_leaves_out_a_pair_exactly_at_the_radius():
    path = np.array([[[0.0, 0.0], [0.5, 0.0], [5.0, 0.0]], [[0.0, 0.0], [0.25, 0.0], [5.0, 0.0]]])
    assert count_pairs_within(path, 0.5) == 1


def all_pairs_min_path_distance(path):
    """The closest point of every pair's relative segment, over every segment: no pruning."""
    i, k = np.triu_indices(path.shape[1], 1)
    rel = path[:, i] - path[:, k]
    return np.linalg.norm(closest_on_segments(rel[:-1], rel[1:]), axis=-1).min()


@pytest.mark.parametrize(("n", "t"), [(2, 3), (9, 1200), (60, 150), (200, 30)])
@pytest.mark.parametrize("dim", [2, 3])
def test_min_path_distance_matches_every_pair_on_every_segment(n, t, dim):
    """Over several blocks (n t > PATH_BLOCK) and with the k-d tree (n > 48), a random walk."""
    rng = np.random.default_rng(n * t + dim)
    start = rng.uniform(-2.0, 2.0, (n, dim)) * np.sqrt(n)
    path = start + np.cumsum(rng.normal(0.0, 0.2, (t, n, dim)), axis=0)
    assert min_path_distance(path) == pytest.approx(all_pairs_min_path_distance(path), rel=1e-12)


def test_min_path_distance_sees_a_far_pair_cross_within_a_block():
    """Two drones 20 m apart at the block's first sample meet mid-block; a close static pair elsewhere."""
    t = 500
    path = np.zeros((t, 4, 2))
    path[:, 1] = [1.0, 0.0]  # the static pair: 1 m
    path[:, 2] = np.column_stack([np.linspace(20.0, 40.0, t), np.full(t, 5.0)])
    path[:, 3] = np.column_stack([np.linspace(40.0, 20.0, t), np.full(t, 5.1)])
    assert min_path_distance(path) == pytest.approx(0.1)
    assert min_path_distance(path[:, :3]) == pytest.approx(1.0)
    assert min_path_distance(path[:1]) == min_pair_distance(path[0])
    assert min_path_distance(path[:, :1]) == np.inf


@given(seeds, st.sampled_from([2, 3]))
def test_closest_on_segments_minimises_the_distance_to_the_origin(seed, dim):
    start, end = random_motion(seed, 6, dim)
    closest = closest_on_segments(start, end)
    samples = start + TAU[:, None, None] * (end - start)
    sampled = np.linalg.norm(samples, axis=-1).min(axis=0)
    norms = np.linalg.norm(closest, axis=1)
    assert np.all(norms <= sampled + 1e-12)
    assert np.all(sampled - norms <= np.linalg.norm(end - start, axis=1) * TAU[1] / 2 + 1e-12)
    # on the segment: closest = start + tau (end - start) with tau in [0, 1]
    delta = end - start
    tau = np.einsum("ij,ij->i", closest - start, delta) / np.einsum("ij,ij->i", delta, delta)
    assert np.all((tau >= -1e-12) & (tau <= 1 + 1e-12))
    np.testing.assert_allclose(closest, start + tau[:, None] * delta, atol=1e-12)


def test_closest_on_segments_by_hand():
    start = np.array([[-1.0, 1.0], [1.0, 1.0], [2.0, 3.0], [-2.0, 0.0]])
    end = np.array([[1.0, 1.0], [2.0, 1.0], [2.0, 3.0], [2.0, 1.0]])
    # interior foot, clamped to the start, degenerate segment, and the foot (-2/17, 8/17)
    expected = [[0.0, 1.0], [1.0, 1.0], [2.0, 3.0], [-2.0 / 17, 8.0 / 17]]
    np.testing.assert_allclose(closest_on_segments(start, end), expected, atol=1e-15)


@given(seeds, st.integers(1, 12), st.sampled_from([2, 3]))
def test_pair_queries_match_brute_force(seed, n, dim):
    points = np.random.default_rng(seed).uniform(-2.0, 2.0, (n, dim))
    dist = np.linalg.norm(points[:, None] - points[None], axis=-1)
    i, j = np.triu_indices(n, 1)
    assert min_pair_distance(points) == (dist[i, j].min() if n > 1 else np.inf)
    radius = 1.5
    expected = {(a, b) for a, b in zip(i, j, strict=True) if dist[a, b] <= radius}
    pairs = pairs_within(points, radius)
    assert pairs.shape == (len(expected), 2) and np.all(pairs[:, 0] < pairs[:, 1])
    assert {tuple(p) for p in pairs.tolist()} == expected


@given(seeds, st.integers(49, 120), st.sampled_from([2, 3]))
def test_unsorted_pairs_are_the_same_pairs(seed, n, dim):
    """More than BRUTE_FORCE_MAX_N points go through the k-d tree: unsorted, the same pairs."""
    points = np.random.default_rng(seed).uniform(-3.0, 3.0, (n, dim))
    pairs, unsorted = pairs_within(points, 0.8), pairs_within(points, 0.8, sort=False)
    assert {tuple(p) for p in unsorted.tolist()} == {tuple(p) for p in pairs.tolist()}
    assert unsorted.shape == pairs.shape and np.all(np.diff(pairs[:, 0]) >= 0)


@pytest.mark.parametrize("shape", [(7, 3), (5, 2), (4, 6, 3), (3, 4, 5, 2)])
def test_vector_norms_are_numpys_bitwise(shape):
    rng = np.random.default_rng(1)
    v = rng.normal(size=shape) * rng.uniform(1e-3, 1e3, shape)
    assert np.array_equal(vector_norms(v), np.linalg.norm(v, axis=-1))
    assert np.array_equal(vector_norms(v[::2]), np.linalg.norm(v[::2], axis=-1))  # a strided view


def test_closest_on_segments_of_stacked_segments():
    """Segments stacked along leading axes give the same points as one by one."""
    rng = np.random.default_rng(2)
    start, end = rng.normal(size=(2, 4, 5, 3))
    stacked = closest_on_segments(start, end)
    flat = closest_on_segments(start.reshape(-1, 3), end.reshape(-1, 3)).reshape(stacked.shape)
    assert np.array_equal(stacked, flat)


@given(seeds, st.sampled_from([5, 60, 150]), st.sampled_from([2, 3]))
def test_near_pairs_hold_every_pair_within_the_radius_as_points_move(seed, n, dim):
    """A Verlet list over a moving swarm: at every call, every pair within the radius (brute force)
    is among the pairs returned."""
    rng = np.random.default_rng(seed)
    points, near = rng.uniform(-4.0, 4.0, (n, dim)), NearPairs()
    for _ in range(12):
        radius = rng.uniform(0.5, 1.5)
        pairs = near.within(points, radius)
        dist = np.linalg.norm(points[:, None] - points[None], axis=-1)
        i, j = np.nonzero(np.triu(dist <= radius, 1))
        assert {(a, b) for a, b in zip(i, j, strict=True)} <= {tuple(p) for p in pairs.tolist()}
        assert np.all(pairs[:, 0] < pairs[:, 1])
        points = points + rng.uniform(-1.0, 1.0, dim) + rng.normal(0.0, 0.1, points.shape)


def test_near_pairs_keep_their_list_while_the_swarm_drifts_as_one():
    rng = np.random.default_rng(3)
    points, near = rng.uniform(-4.0, 4.0, (100, 3)), NearPairs()
    pairs = near.within(points, 1.0)  # built for 1.25 m
    moved = points + 7.0 + rng.uniform(-0.05, 0.05, points.shape)  # a drift, small relative moves
    assert near.within(moved, 1.0) is pairs
    assert near.within(moved + rng.uniform(-0.3, 0.3, points.shape), 1.0) is not pairs  # rebuilt


@pytest.mark.parametrize("dim", [2, 3])
def test_spread_is_the_largest_distances_bitwise(dim: int) -> None:
    """Each drone's guess's farthest point from its start plus its positions' from the guess."""
    rng = np.random.default_rng(dim)
    guess = rng.normal(size=(11, 40, dim)) * 3.0
    positions = guess + rng.normal(size=guess.shape) * 1e-2
    expected = vector_norms(guess - positions[0]).max(axis=0) + vector_norms(positions - guess).max(axis=0)
    assert drone_spreads(guess, positions).tobytes() == expected.tobytes()


def test_squared_norms_are_the_norms_squared_in_order() -> None:
    v = np.random.default_rng(5).normal(size=(7, 9, 3)) * 1e2
    expected = (v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1]) + v[..., 2] * v[..., 2]
    assert squared_norms(v).tobytes() == expected.tobytes()
    assert vector_norms(v).tobytes() == np.linalg.norm(v, axis=-1).tobytes()

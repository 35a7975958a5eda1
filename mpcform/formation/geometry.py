"""Distances between drones at samples and along straight segments (zero-order hold paths), the
pairs within a radius (a k-d tree, or a neighbour list kept between calls), and the edges that
draw a template's shape."""

from __future__ import annotations

from collections.abc import Iterator
from functools import lru_cache

import numpy as np
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial import ConvexHull, QhullError, cKDTree
from scipy.spatial.distance import pdist, squareform

from mpcform._validate import Array
from mpcform.world.closest import closest_on_segments, squared_norms, vector_norms

BRUTE_FORCE_MAX_N = 48
PATH_BLOCK = 4096  # drone samples per block of the whole-path measures (bounds their temporaries)


def drone_spreads(guess: Array, positions: Array) -> Array:
    """Per drone (n,): its largest distance along ``guess`` (T, n, d) from ``positions[0]`` plus the
    largest distance of ``positions`` (T, n, d) from ``guess`` (the clear test of
    :meth:`mpcform.mpc.constraints.separation.Separation.clear`)."""
    dev = np.empty((2,) + guess.shape)
    np.subtract(guess, positions[0], out=dev[0])
    np.subtract(positions, guess, out=dev[1])
    far = np.sqrt(squared_norms(dev, overwrite=True).max(axis=1))  # (2, n)
    return far[0] + far[1]


def min_pair_distance(points: Array) -> float:
    """Smallest distance between two rows of ``points`` (n, d); inf for fewer than two."""
    if points.shape[0] < 2:
        return float("inf")
    dist, _ = cKDTree(points).query(points, k=2)
    return float(dist[:, 1].min())


def min_pair_distances(path: Array) -> Array:
    """Smallest distance between two drones at every sample of ``path`` (T, n, d), (T,): every pair
    at once for few drones (:func:`_pair_differences`), else :func:`min_pair_distance`."""
    t, n = path.shape[:2]
    if n < 2 or n > BRUTE_FORCE_MAX_N:
        return np.array([min_pair_distance(p) for p in path]).reshape(t)
    mins = [np.sqrt(squared_norms(diff, overwrite=True).min(axis=1)) for diff in _pair_differences(path)]
    return np.concatenate(mins) if mins else np.empty(0)


def closest_pair(path: Array) -> tuple[int, int, int, float]:
    """``(sample, i, j, distance [m])`` of the closest two drones, ``i < j``, over the samples of
    ``path`` (T, n, d) with n >= 2 (:func:`min_pair_distances`, then that sample's pairs)."""
    sep = min_pair_distances(path)
    k = int(np.argmin(sep))
    dist = squareform(pdist(path[k])) + np.diag(np.full(path.shape[1], np.inf))
    i, j = np.unravel_index(int(np.argmin(dist)), dist.shape)
    return k, int(min(i, j)), int(max(i, j)), float(sep[k])


def pairs_within(points: Array, radius: float, sort: bool = True) -> Array:
    """Index pairs (m, 2), i < j, of rows of ``points`` closer than ``radius`` (sorted unless
    ``sort`` is false: in the tree's order for more than :data:`BRUTE_FORCE_MAX_N` points)."""
    n = points.shape[0]
    if n < 2:
        return np.empty((0, 2), dtype=np.intp)
    if n <= BRUTE_FORCE_MAX_N:  # cheaper than building a tree
        pairs = _upper_pairs(n)
        diff = points[pairs[:, 0]] - points[pairs[:, 1]]
        return pairs[np.einsum("ij,ij->i", diff, diff) < radius * radius]
    tree = cKDTree(points, balanced_tree=False, compact_nodes=False)  # built faster; the same pairs
    pairs = tree.query_pairs(radius, output_type="ndarray").astype(np.intp)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))] if sort else pairs


def count_pairs_within(path: Array, radius: float) -> int:
    """Number of (sample, pair) of ``path`` (T, n, d) closer than ``radius``: :func:`pairs_within`
    at every sample, every pair at once for few drones (:func:`_pair_differences`)."""
    if path.shape[1] > BRUTE_FORCE_MAX_N:
        return sum(pairs_within(p, radius).shape[0] for p in path)
    count = 0
    for diff in _pair_differences(path):
        flat = diff.reshape(-1, diff.shape[2])  # the rows of pairs_within's own test
        count += int(np.count_nonzero(np.einsum("ij,ij->i", flat, flat) < radius * radius))
    return count


def _pair_differences(path: Array) -> Iterator[Array]:
    """``p_i - p_k`` of every pair i < k at the samples of ``path`` (T, n, d), (S, P, d) for blocks
    of S samples (:data:`PATH_BLOCK` drone samples each)."""
    i, k = _upper_pairs(path.shape[1]).T
    samples = max(1, PATH_BLOCK // max(path.shape[1], 1))
    for a in range(0, path.shape[0], samples):
        block = path[a : a + samples]
        yield np.take(block, i, axis=1) - np.take(block, k, axis=1)


@lru_cache(maxsize=32)
def _upper_pairs(n: int) -> Array:
    """Every index pair (n (n - 1) / 2, 2), i < j, sorted (read-only: it is shared)."""
    pairs = np.column_stack(np.triu_indices(n, 1)).astype(np.intp)
    pairs.flags.writeable = False
    return pairs


class NearPairs:
    """Pairs of points that may lie within a radius, kept between calls (a Verlet list).

    :meth:`within` returns the pairs (m, 2), i < j, closer than the list's radius at the points
    it was last built from: a superset of the pairs now within ``radius``, for the caller to
    measure (every pair, for at most :data:`BRUTE_FORCE_MAX_N` points). A pair's distance changes
    by at most the sum of its two points' displacements relative to any common shift (the mean
    displacement here, so a formation flying as one keeps its list), hence the list holds every
    pair within ``radius`` while ``radius`` plus twice the largest such displacement stays within
    the list's radius (less a relative ``ROUNDING``). Otherwise, or when the list's radius exceeds
    twice ``REBUILD_FACTOR * radius`` (too many pairs to measure), it is rebuilt
    (:func:`pairs_within`) with the radius ``REBUILD_FACTOR * radius``.
    """

    REBUILD_FACTOR = 1.25
    ROUNDING = 1e-9

    def __init__(self) -> None:
        self._points = np.empty((0, 0))  # the points the list was built from
        self._radius = -np.inf
        self._pairs = np.empty((0, 2), dtype=np.intp)

    def within(self, points: Array, radius: float) -> Array:
        """A superset (m, 2) of the pairs of rows of ``points`` (n, d) within ``radius``, in no set order."""
        if points.shape[0] <= BRUTE_FORCE_MAX_N:  # measuring every pair is cheaper than keeping a list
            return _upper_pairs(points.shape[0])
        rebuild_m = self.REBUILD_FACTOR * radius
        if points.shape == self._points.shape and self._radius <= 2.0 * rebuild_m:
            shift = points - self._points
            shift -= shift.mean(axis=0)
            reach_m = radius + 2.0 * vector_norms(shift).max(initial=0.0)
            if reach_m <= (1.0 - self.ROUNDING) * self._radius:
                return self._pairs
        self._points, self._radius = points.copy(), rebuild_m
        self._pairs = pairs_within(points, self._radius, sort=False)
        self._pairs.flags.writeable = False  # shared with the callers until the next rebuild
        return self._pairs


def min_segment_distance(start: Array, end: Array) -> float:
    """Smallest distance between two drones moving on straight lines from ``start`` to ``end`` (n, d)."""
    return min_path_distance(np.stack((start, end)))


def min_path_distance(path: Array) -> float:
    """Smallest distance between two drones moving straight between the samples of ``path``
    (T, n, d); inf for fewer than two drones.

    Exact, a block of segments at a time: a pair can come closer within the block than the
    closest pair at its first sample only if it starts within that distance plus twice the
    largest displacement in the block, and only those pairs (a k-d tree) are measured along
    every segment of the block (:data:`PATH_BLOCK` drone samples per block).
    """
    t, n = path.shape[:2]
    if n < 2:
        return float("inf")
    if t == 1:
        return min_pair_distance(path[0])
    best, segments = float("inf"), max(1, PATH_BLOCK // n)
    for a in range(0, t - 1, segments):
        block = path[a : a + segments + 1]
        start = block[0]
        best = min(best, min_pair_distance(start))
        move = float(np.sqrt(squared_norms(block - start, overwrite=True).max()))
        i, k = pairs_within(start, best + 2.0 * move + 1e-12, sort=False).T
        rel = np.take(block, i, axis=1) - np.take(block, k, axis=1)
        closest = closest_on_segments(rel[:-1], rel[1:])
        best = min(best, float(np.sqrt(squared_norms(closest, overwrite=True).min(initial=np.inf))))
    return best


def formation_edges(offsets_m: Array) -> list[tuple[int, int]]:
    """Edges that draw the template's shape: the closed outline (convex hull) of a planar template,
    so a ring or polygon of n drones gets n edges, with the drones inside the outline joined to it
    by their minimum spanning tree; a collinear or truly 3-D template keeps its minimum spanning
    tree (a 3-D hull is a tangle of triangles)."""
    n = offsets_m.shape[0]
    if n < 2:
        return []
    centred = offsets_m - offsets_m.mean(axis=0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    tree = _spanning_tree(offsets_m)
    planar = len(sv) >= 2 and sv[1] > 1e-9 * sv[0] and (len(sv) < 3 or sv[2] <= 1e-9 * sv[0])
    if n < 3 or not planar:
        return tree
    try:
        hull = ConvexHull(centred @ vt[:2].T)  # (facets: a x + b y + c = 0)
    except QhullError:
        return tree
    q = centred @ vt[:2].T
    gap = np.abs(q @ hull.equations[:, :2].T + hull.equations[:, 2]).min(axis=1)
    boundary = np.flatnonzero(gap <= 1e-9 * sv[0])  # hull corners and drones on its sides
    middle = q[hull.vertices].mean(axis=0)
    angle = np.arctan2(*(q[boundary] - middle).T[::-1])
    cycle = [int(v) for v in boundary[np.argsort(angle)]]
    outline = {(min(a, b), max(a, b)) for a, b in zip(cycle, cycle[1:] + cycle[:1], strict=True)}
    inside = set(range(n)) - set(cycle)
    links = {(a, b) for a, b in tree if a in inside or b in inside}
    return sorted(outline | links)


def _spanning_tree(offsets_m: Array) -> list[tuple[int, int]]:
    n = offsets_m.shape[0]
    dist = squareform(pdist(offsets_m)) + 1e-12 * (1 - np.eye(n))  # keep coincident points linked
    tree = minimum_spanning_tree(dist).tocoo()
    return sorted((int(min(a, b)), int(max(a, b))) for a, b in zip(tree.row, tree.col, strict=True))

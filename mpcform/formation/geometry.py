"""Distances between drones at samples and along straight segments (zero-order hold paths)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

from mpcform._validate import Array

BRUTE_FORCE_MAX_N = 48


def closest_on_segments(start: Array, end: Array) -> Array:
    """Point closest to the origin on each segment ``start -> end``; inputs and output (m, d)."""
    delta = end - start
    den = np.einsum("ij,ij->i", delta, delta)
    tau = np.clip(-np.einsum("ij,ij->i", start, delta) / np.where(den > 0, den, 1.0), 0.0, 1.0)
    return start + tau[:, None] * delta


def min_pair_distance(points: Array) -> float:
    """Smallest distance between two rows of ``points`` (n, d); inf for fewer than two."""
    if points.shape[0] < 2:
        return float("inf")
    dist, _ = cKDTree(points).query(points, k=2)
    return float(dist[:, 1].min())


def pairs_within(points: Array, radius: float) -> Array:
    """Index pairs (m, 2), i < j, sorted, of rows of ``points`` closer than ``radius``."""
    n = points.shape[0]
    if n < 2:
        return np.empty((0, 2), dtype=np.intp)
    if n <= BRUTE_FORCE_MAX_N:  # cheaper than building a tree
        i, k = _upper_pairs(n)
        diff = points[i] - points[k]
        close = np.einsum("ij,ij->i", diff, diff) < radius * radius
        return np.column_stack([i[close], k[close]]).astype(np.intp)
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray").astype(np.intp)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


@lru_cache(maxsize=32)
def _upper_pairs(n: int) -> tuple[Array, Array]:
    return np.triu_indices(n, 1)


def min_segment_distance(start: Array, end: Array) -> float:
    """Smallest distance between two drones moving on straight lines from ``start`` to ``end`` (n, d).

    Exact: only pairs that can beat the closest sampled pair are examined (k-d tree).
    """
    if start.shape[0] < 2:
        return float("inf")
    best = min(min_pair_distance(start), min_pair_distance(end))
    move = float(np.linalg.norm(end - start, axis=1).max())
    pairs = pairs_within(start, best + 2.0 * move + 1e-12)
    if pairs.shape[0] == 0:
        return best
    i, j = pairs[:, 0], pairs[:, 1]
    closest = closest_on_segments(start[i] - start[j], end[i] - end[j])
    return min(best, float(np.linalg.norm(closest, axis=1).min()))

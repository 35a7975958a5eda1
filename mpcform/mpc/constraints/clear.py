"""The fast path's test: a cheap sufficient test that a plan meets every joint pair row and
obstacle row about the guess, without building one (:meth:`ClearTest.__call__`)."""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.formation.geometry import drone_spreads
from mpcform.mpc.constraints.family import SeparationFamily
from mpcform.mpc.constraints.half_spaces import ClearInputs, path_bounds

FIRST_TESTED = 32  # the clear test tries this many of the least clear items first
CERTAIN_M = 1e-9  # :meth:`ClearTest.unclear_pairs` counts a pair clear by at least this much [m]


class ClearTest:
    """The test over the separation families ``pairs`` and ``obstacles`` (None: none) with the
    rows' ``margin_m``, the braking tail's ``tail_count`` points and the growth per segment
    ``segment_growth`` (S, 1) [m] (None: none)."""

    def __init__(
        self,
        pairs: SeparationFamily | None,
        obstacles: SeparationFamily | None,
        margin_m: float,
        tail_count: int,
        segment_growth: Array | None,
    ) -> None:
        self.pairs, self.obstacles, self.margin_m = pairs, obstacles, margin_m
        self.tail_count, self._segment_growth = tail_count, segment_growth

    def __call__(self, guess: Array, positions: Array, growing: Array | None = None) -> bool:
        """A cheap sufficient test that the plan's ``positions`` (H + 1, n, d) (row 0 the start)
        meet every joint pair row and obstacle row about ``guess`` (so every pair stays ``d_min``
        apart over each step). It does not cover the decoupled pair-side rows: two drones moving
        side by side can pass it while crossing the guess's midpoint plane.

        A row's normal c is a unit vector with ``c^T (g - a) >= dist(guess segment) >= max(dist(g_j),
        dist(g_j+1)) - |g_j+1 - g_j|`` for the distance to the forbidden set (a pair's: ``|g|``
        relative; an obstacle's: to its core, ``a`` the core's point the row is anchored at), which
        is 1-Lipschitz (the braking tail's hull: its points' largest distance less its diameter,
        :func:`~mpcform.mpc.constraints.half_spaces.path_bounds`), so ``c^T (delta_e - a) >= that -
        |delta_e - g_e|``.
        Before that per-segment bound, a per-drone one: drone i's guess stays within ``spread_i``
        of its start and its positions within ``spread_i`` of the guess, so an item whose start
        distance clears the requirement by the spreads of its drones is clear. No row is built.
        """
        p0, spread = positions[0], drone_spreads(guess, positions)  # spread (n,) [m]
        units = [u for u in (self.pairs if p0.shape[0] > 1 else None, self.obstacles) if u is not None]
        for unit in units:
            i, k, slack = unit.doubtful(p0, spread)
            if i.shape[0] > 8 * FIRST_TESTED:  # the least clear first: a miss among them answers early
                first = np.argpartition(slack, FIRST_TESTED)[:FIRST_TESTED]
                share = self._share(unit, growing, i[first], k[first])
                if not self._passes(unit.clear_test(guess, positions, i[first], k[first]), share):
                    return False
            share = self._share(unit, growing, i, k)
            if i.shape[0] and not self._passes(unit.clear_test(guess, positions, i, k), share):
                return False  # (no item in doubt: all clear by the spreads)
        return True

    def unclear_pairs(self, guess: Array, positions: Array, growing: Array | None = None) -> Array:
        """The drone pairs (m, 2), ``i < k``, that the bounds of :meth:`__call__` do not show clear by
        :data:`CERTAIN_M` (far above the rounding of the rows): every other pair meets its joint
        rows about ``guess`` at ``positions``, so only these need their rows built to test them."""
        if self.pairs is None or positions.shape[1] < 2:
            return np.empty((0, 2), dtype=np.intp)
        p0, spread = positions[0], drone_spreads(guess, positions) + CERTAIN_M
        i, k, _ = self.pairs.doubtful(p0, spread)
        if i.shape[0]:
            dist, points, dev, required = self.pairs.clear_test(guess, positions, i, k)
            seg = path_bounds(dist, points, self.tail_count)
            if self._segment_growth is not None and growing is not None:
                seg = seg - self._segment_growth * (growing[i] + growing[k])
            unclear = seg.min(axis=0, initial=np.inf) - dev < required + self.margin_m + CERTAIN_M
            i, k = i[unclear], k[unclear]
        return np.stack([i, k], axis=1)

    def _share(self, unit: object, growing: Array | None, i: Array, k: Array) -> Array | None:
        """The items' shares (m,) of the rows' growth: a pair's both drones', an obstacle item's drone's."""
        if growing is None:
            return None
        return growing[i] + growing[k] if unit is self.pairs else growing[i]

    def _passes(self, test: ClearInputs, share: Array | None = None) -> bool:
        """Whether the items of the clear ``test`` (a unit's :meth:`clear_test`) meet the
        per-segment bound of :meth:`clear` (with the rows' growth, ``share`` (m,) times each
        segment's larger end's)."""
        dist, points, dev, required = test
        seg = path_bounds(dist, points, self.tail_count)
        if self._segment_growth is not None and share is not None:
            seg = seg - self._segment_growth * share
        return not np.any(seg.min(axis=0, initial=np.inf) - dev < required + self.margin_m)

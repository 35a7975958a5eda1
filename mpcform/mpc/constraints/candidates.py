"""Which separation items the QP holds, and which drones it is solved for.

Items are drone pairs ``(i, k)``, ``i < k``, and ``(drone, obstacle)`` pairs that can come within
their required distance over the horizon, found with a k-d tree. The QP keeps a candidate set
chosen with one extra horizon of reach, so its sparsity pattern lasts (hysteresis); the set is
rebuilt only when an item within reach is missing from it. With grouping, the QP is solved only
for the groups of drones (connected by pair rows within reach) that hold a conflicted drone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from mpcform._validate import Array
from mpcform.formation.geometry import pairs_within
from mpcform.mpc.settings import MPCSettings
from mpcform.world.bounds import PlanningBounds
from mpcform.world.shapes.shape_set import ShapeSet


@dataclass(frozen=True)
class Candidates:
    """Items kept in the QP (fixed pattern) and which of them are within reach this step."""

    pairs: Array  # (P, 2) drone pairs i < k
    pair_on: Array  # (P,) bool
    obstacles: Array  # (O, 2) (drone, obstacle index)
    obstacle_on: Array  # (O,) bool
    rebuilt: bool  # the set changed this step (the QP's pattern with it)

    def within_reach(self) -> Candidates:
        """Only the items within reach this step."""
        p, o = self.pairs[self.pair_on], self.obstacles[self.obstacle_on]
        on = np.ones(p.shape[0], dtype=bool), np.ones(o.shape[0], dtype=bool)
        return Candidates(p, on[0], o, on[1], self.rebuilt)


class CandidateSelector:
    """Keeps the candidate set between steps and marks the items within reach.

    Reach over the horizon: a pair within ``d_min kappa + margin + 2 v_max H dt`` (both drones
    fly towards each other), a drone within ``margin + v_max H dt`` of its required distance from
    an obstacle's core; ``v_max`` times ``speed_gain`` for a velocity loop that overshoots
    (:attr:`mpcform.mpc.velocity_loop.VelocityLoop.speed_gain`); plus ``v_max tail_s`` past the horizon (the
    braking tail to the stop point, :mod:`mpcform.mpc.constraints.braking`), plus the rows' largest growth per
    drone ``growth_m`` (:func:`mpcform.mpc.constraints.rows.step_growth`). The obstacles' clearances are
    resolved
    (:func:`mpcform.world.obstacles.resolve_clearances`).
    """

    def __init__(
        self,
        n: int,
        dt_s: float,
        limits: PlanningBounds,
        settings: MPCSettings,
        obstacles: ShapeSet,
        speed_gain: float = 1.0,
        tail_s: float = 0.0,
        growth_m: float = 0.0,
    ) -> None:
        self.n, self.limits, self.settings = n, limits, settings
        look_ahead_s = speed_gain * settings.horizon * dt_s + tail_s
        self.travel_m = (limits.v_max_mps or 0.0) * look_ahead_s + growth_m  # farthest [m]
        self.obstacles = obstacles
        self.reset()

    def reset(self) -> None:
        """Forget the candidate set (the next :meth:`select` builds one)."""
        self._fresh = True  # no candidate set chosen yet
        self._pairs = np.empty((0, 2), dtype=np.intp)  # candidate pairs (i < k), sorted by code
        self._pair_codes = np.empty(0, dtype=np.intp)  # i * n + k
        self._obstacle_items = np.empty((0, 2), dtype=np.intp)  # (drone, obstacle)
        self._ob_codes = np.empty(0, dtype=np.intp)  # drone * m + obstacle

    def select(self, p0: Array, drift_m: float = 0.0) -> Candidates:
        """Pairs and (drone, obstacle) items within reach over the horizon from ``p0`` (n, d), each
        drone carried up to ``drift_m`` [m] farther (a velocity offset held over the plan,
        :mod:`mpcform.mpc.velocity_loop`)."""
        lim, st, travel = self.limits, self.settings, self.travel_m + drift_m
        rebuilt, self._fresh = self._fresh, False
        pair_on: Array | None = np.zeros(self._pairs.shape[0], dtype=bool)
        if lim.d_min_m is not None:
            reach = lim.d_min_m * (lim.downwash_kappa or 1.0) + st.margin_m + 2.0 * travel
            need = pairs_within(p0, reach)
            need_codes = need[:, 0] * self.n + need[:, 1]
            pair_on = mask_of(self._pair_codes, need_codes)
            if pair_on is None:
                self._pairs = pairs_within(p0, reach + 2.0 * travel)
                self._pair_codes, rebuilt = self._pairs[:, 0] * self.n + self._pairs[:, 1], True
                pair_on = mask_of(self._pair_codes, need_codes)
        m = len(self.obstacles)
        ob_on: Array | None = np.zeros(self._obstacle_items.shape[0], dtype=bool)
        if m:
            gap = (
                self.obstacles.core_distances(p0) - self.obstacles.required_m
            ).ravel()  # drone * m + obstacle
            need_codes = np.flatnonzero(gap <= st.margin_m + travel)
            ob_on = mask_of(self._ob_codes, need_codes)
            if ob_on is None:
                self._ob_codes, rebuilt = np.flatnonzero(gap <= st.margin_m + 2.0 * travel), True
                self._obstacle_items = np.column_stack(np.divmod(self._ob_codes, m))
                ob_on = mask_of(self._ob_codes, need_codes)
        return Candidates(self._pairs, pair_on, self._obstacle_items, ob_on, rebuilt)  # type: ignore[arg-type]


def qp_drones(bad: Array, pairs_on: Array) -> Array:
    """Drones whose group (connected by the pairs ``pairs_on`` (P, 2) within reach) holds a drone
    of ``bad`` (n,) bool.

    Groups are independent blocks of the QP, so every other group's optimum is its rollout.
    """
    if pairs_on.shape[0] == 0:
        return np.flatnonzero(bad)
    n = bad.shape[0]
    graph = sp.coo_matrix((np.ones(pairs_on.shape[0]), (pairs_on[:, 0], pairs_on[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    return np.flatnonzero(np.isin(label, label[bad]))


def mask_of(codes: Array, need: Array) -> Array | None:
    """Mask of the sorted ``codes`` that occur in ``need`` (sorted); None if one is missing."""
    idx = np.searchsorted(codes, need)
    if idx.size and (idx[-1] >= codes.shape[0] or np.any(codes[idx] != need)):
        return None
    mask = np.zeros(codes.shape[0], dtype=bool)
    mask[idx] = True
    return mask

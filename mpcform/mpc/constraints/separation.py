"""Separation rows linearised about the guess: one unit for drone pairs, one for obstacles
(:mod:`mpcform.mpc.constraints.units`), combined here with the tests on a plan.

The exact separation is non-convex: ``||W (p_i - p_k)|| >= d_min`` for a pair (``W = diag(1, 1,
1/kappa)`` with downwash, else the identity) and ``||p_i - c_o|| >= required_o`` for a drone and
obstacle o. The guess is the previous plan shifted one step. For segment j of an item's relative
guess path, ``c`` is the unit vector towards the segment's point closest to the origin; the row
``c^T rel >= required + margin`` (a half-space that excludes the forbidden ball) is placed at both
segment ends (position steps of :func:`mpcform.mpc.constraints.rows.row_ends`; with braking one more segment,
from ``x_H`` to the stop point, :mod:`mpcform.mpc.constraints.braking`: the plans, guesses and positions
given here then have that point last), with a slack:

- joint pair: ``c^T W (x_{e,i} - x_{e,k}) + s_{e,i} + s_{e,k} >= d_min + margin - c^T W (p0_i - p0_k)``;
- decoupled pair: two one-drone rows about the guess's midpoint ``m_e``, each asking for half,
  ``+-c^T W (p0_i + x_{e,i} - m_e) + s_{e,i} >= (d_min + margin) / 2``;
- obstacle: ``c^T (p0_i + x_{e,i} - c_o) + s_{e,i} >= required_o + margin``.

An item that already starts inside its required distance (a close start) cannot meet these rows
at once; its first row (the end of the first segment, ``x_1``) is then replaced by a hard
no-approach row without slack along the start's normal ``c0 = W r0 / |W r0|``: joint
``c0^T W (x_{1,i} - x_{1,k}) >= 0``, decoupled ``+-c0^T W x_{1,side} >= 0`` per drone, obstacle
``c0^T x_{1,i} >= 0``. Along the first segment ``|r(t)| >= c0^T r(t) >= |r0|``: such an item never
gets closer, and every drone holding meets the row, so the hard rows stay feasible.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mpcform import _jit
from mpcform._validate import Array
from mpcform.formation.geometry import pairs_within
from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.candidates import Candidates
from mpcform.mpc.constraints.clear import ClearTest
from mpcform.mpc.constraints.half_spaces import BLOCK, SegmentTest, inside
from mpcform.mpc.constraints.obstacles import ObstacleSeparation
from mpcform.mpc.constraints.pairs import PairSeparation
from mpcform.mpc.constraints.rows import row_ends, row_segments, step_growth
from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.mpc.constraints.tail import planner_tail
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.world.bounds import PlanningBounds
from mpcform.world.closest import vector_norms
from mpcform.world.obstacles import Obstacle
from mpcform.world.shapes.shape_set import ShapeSet


@dataclass(frozen=True, eq=False)
class Conflict:
    """A step's candidate items ``cand``, their ``rows`` about the guess and the drones (n,) whose
    rollout misses one, ``conflicted``."""

    cand: Candidates
    rows: SeparationRows
    conflicted: Array


class Separation:
    """The pair and obstacle units together: the rows of a candidate set, and the tests on them.
    ``dt_s``: the control interval, which the rows' growth in wind needs (``limits.growth_m``,
    :func:`mpcform.mpc.constraints.rows.step_growth`; None: no growth)."""

    def __init__(
        self,
        dim: int,
        limits: PlanningBounds,
        settings: MPCSettings,
        obstacles: ShapeSet | tuple[Obstacle, ...],
        braking: Braking | None = None,
        loop: VelocityLoop | None = None,
        dt_s: float | None = None,
    ) -> None:
        self.dim, self.margin_m, self.braking = dim, settings.margin_m, braking
        h = settings.horizon  # with braking, then the tail's points (:mod:`mpcform.mpc.constraints.tail`)
        self.tail = planner_tail(braking, settings, dim, loop)
        tail = 0 if self.tail is None else self.tail.count
        self.d_min_m, self.tube_m = limits.d_min_m, limits.tube_m
        self.metric = np.ones(dim)  # W's diagonal
        if limits.downwash_kappa is not None:
            self.metric[2] = 1.0 / limits.downwash_kappa
        d_min = limits.d_min_m
        growth = None if dt_s is None else step_growth(limits.growth_m, dt_s, h, tail)
        self.growth = growth  # per drone and position step (H + T + 1,) [m]: the rows' growth, or None
        self.ends, self.n_rows, self.tail_count = row_ends(h, tail), row_segments(h, tail).shape[0], tail
        self.row_growth = None if growth is None else growth[self.ends]  # per drone and row (R,) [m]
        segments = h + tail if tail <= 1 else h + 1  # the clear test's: the polyline, then the tail's hull
        ends = np.minimum(np.arange(1, segments + 1), h + tail)  # each one's last position step
        segment_growth = None if growth is None else growth[ends, None]  # (S, 1) [m]
        grow = self.row_growth
        self.pairs = None if d_min is None else PairSeparation(d_min, self.metric, settings, tail, grow)
        shapes = obstacles if isinstance(obstacles, ShapeSet) else ShapeSet(obstacles, dim)
        self.obstacles = ObstacleSeparation(shapes, settings, tail, grow) if len(shapes) else None
        self.clearing = ClearTest(self.pairs, self.obstacles, self.margin_m, tail, segment_growth)

    def rows(
        self,
        p0: Array,
        guess: Array,
        cand: Candidates,
        stops: Array | None = None,
        growing: Array | None = None,
    ) -> SeparationRows:
        """Closest-point rows about ``guess`` (H + 1, n, d) for every candidate item; ``stops`` (n, d):
        decoupled with braking, the eq. 14 rollout's stop points (a pair whose rollout keeps its
        stop row splits that row about their midpoint: a common speed-up moves both sides);
        ``growing`` (n,): each drone's share of the rows' growth (:meth:`growing`; None: none)."""
        r, no, singles = self.n_rows, np.empty(0, dtype=bool), []
        joint = empty = (np.empty((0, 2), np.intp), np.empty((0, r, self.dim)), np.empty((0, r)), no, no)
        path = np.ascontiguousarray(guess.transpose(1, 0, 2))  # (n, H + 1, d): items gather rows
        if cand.pairs.shape[0] and self.pairs is not None:
            two, one = self.pairs.rows(p0, path, cand.pairs, cand.pair_on, stops, growing)
            joint, singles = joint if two is None else two, [] if one is None else [one]
        if cand.obstacles.shape[0] and self.obstacles is not None:
            singles.append(self.obstacles.rows(p0, path, cand.obstacles, cand.obstacle_on, growing))
        parts = singles[0] if len(singles) == 1 else map(np.concatenate, zip(empty, *singles, strict=True))
        labels, s_coeffs, s_lower, s_on, s_hard = parts
        pairs, p_coeffs, p_lower, p_on, p_hard = joint
        return SeparationRows(
            pairs, p_coeffs, p_lower, p_on, labels[:, 0], labels, s_coeffs, s_lower, s_on, p_hard, s_hard
        )

    def clear(self, guess: Array, positions: Array, growing: Array | None = None) -> bool:
        """Whether the plan's ``positions`` (H + 1, n, d) (row 0 the start) surely meet every joint
        pair row and obstacle row about ``guess``, with the rows' growth shares ``growing`` (n,)
        (the fast path's test, :class:`~mpcform.mpc.constraints.clear.ClearTest`)."""
        return self.clearing(guess, positions, growing)

    def shortfall(
        self, x: Array, rows: SeparationRows, tol: float, joint: bool = False
    ) -> tuple[float, Array]:
        """Largest amount [m] by which positions ``x`` (H, n, d) miss an active separation row,
        and the labels (m, 2) of the items that miss by more than ``tol``; with ``joint`` a
        decoupled pair's two sides are taken together, as the joint row they add up to (an
        iterated split, :mod:`mpcform.mpc.solve.split`, lets one side miss its midpoint row by as much
        as the other keeps it: the pair's row holds)."""
        least, labels = self._least(x, rows.joint() if joint else rows, None)
        return -float(least.min(initial=np.inf)), np.unique(labels[least < -tol], axis=0)

    def single_values(self, x: Array, rows: SeparationRows) -> Array:
        """``c^T x_e - b`` (S, R) of the one-drone rows at positions ``x`` (H, n, d): negative where
        a row is missed (inf for the items out of reach)."""
        xe = np.ascontiguousarray(x[self.ends - 1].transpose(1, 0, 2))  # (n, R, d)
        if _jit.USE:
            from mpcform.mpc.constraints import kernels

            c = np.ascontiguousarray  # the one layout the kernel is compiled for
            args = (c(rows.singles), c(rows.single_coeffs), c(rows.single_lower), c(rows.single_on))
            return kernels.single_values(xe, *args)
        value = np.empty_like(rows.single_lower, dtype=float)
        for a in range(0, rows.singles.shape[0], 2 * BLOCK):  # in blocks: the gathered positions stay small
            b = slice(a, a + 2 * BLOCK)
            dot = np.einsum("srd,srd->sr", rows.single_coeffs[b], xe[rows.singles[b]])
            np.subtract(dot, rows.single_lower[b], out=value[b])
        value[~rows.single_on] = np.inf
        return value

    def meets_joint(self, x: Array, rows: SeparationRows, values: Array | None = None) -> bool:
        """Whether positions ``x`` (H, n, d) meet the joint pair rows (and the obstacle rows) of the
        items within reach, given the decoupled ``rows`` of the whole candidate set: a pair's two
        sides share their normal and their lower bounds add up to the joint one, so the joint row
        is the sum of its two sides' rows. ``values``: :meth:`single_values` when known."""
        value = self.single_values(x, rows) if values is None else values
        pair = rows.labels[:, 1] >= 0
        first = pair & (rows.labels[:, 0] < rows.labels[:, 1])  # side i of pair (i, k), i < k
        if _jit.USE:
            from mpcform.mpc.constraints import kernels

            sides = np.flatnonzero(first), np.flatnonzero(pair & ~first)
            least = kernels.joint_least(np.ascontiguousarray(value), *sides)
        else:
            least = (value[first] + value[pair & ~first]).min(initial=np.inf)  # in the pairs' order
        return bool(least >= 0.0 and value[~pair].min(initial=np.inf) >= 0.0)

    def conflicted(
        self, x: Array, rows: SeparationRows, values: Array | None = None, tail: bool = True
    ) -> Array:
        """Drones (n,) of the items whose rows positions ``x`` (H, n, d) miss (an obstacle item
        names only its drone); ``values``: :meth:`single_values` when known; ``tail`` False: not
        counting the braking tail's rows (its last ones) of drone pairs, only the horizon's (an
        obstacle's tail still counts: a drone turns early for a sphere it would have to brake for)."""
        least, labels = self._least(
            x, rows, values, None if tail or self.braking is None else -1 - self.tail_count
        )
        labels = labels[least < 0.0]
        conflicted = np.zeros(x.shape[1], dtype=bool)
        conflicted[labels[labels >= 0]] = True
        return conflicted

    def _least(
        self, x: Array, rows: SeparationRows, values: Array | None, last: int | None = None
    ) -> tuple[Array, Array]:
        """Each item's least row value ``c^T x_e - b`` (inf out of reach) over its rows (a drone
        pair's up to ``last``, exclusive; None: all), joint pairs then one-drone items, and their
        labels."""
        single_values = self.single_values(x, rows) if values is None else values
        split = rows.labels[:, 1] >= 0  # with last: split pairs' rows up to it; obstacles' all
        if _jit.USE:
            from mpcform.mpc.constraints import kernels

            r = single_values.shape[1]
            stop = r if last is None else len(range(r)[:last])
            single = kernels.item_least(
                np.ascontiguousarray(single_values), np.ascontiguousarray(split), stop
            )
        else:
            single = single_values.min(axis=1, initial=np.inf)
            if last is not None:
                single[split] = single_values[split, :last].min(axis=1, initial=np.inf)
        pair = np.full(rows.pairs.shape[0], np.inf)
        if rows.pair_on.any():
            xe = x[self.ends - 1]  # (R, n, d)
            rel = xe[:, rows.pairs[:, 0]] - xe[:, rows.pairs[:, 1]]
            value = np.einsum("mrd,rmd->mr", rows.pair_coeffs, rel) - rows.pair_lower
            pair[rows.pair_on] = value[rows.pair_on, :last].min(axis=1)
        return np.concatenate([pair, single]), np.concatenate([rows.pairs, rows.labels])

    def encounters(
        self, p0: Array, conflict: Conflict, x_nom: Array, plain: Array | None, growing: Array | None
    ) -> Array:
        """Drones (n,) in an encounter: the single integrator's rollout ``x_nom`` (H, n, d) conflicts
        within the horizon (a stop point's conflict is the QP's to brake for, not one to turn away
        from), on the ``conflict``'s rows, or with a velocity loop on rows about the single
        integrator's guess ``plain`` (H + 1, n, d) (the rows' own are on the loop's positions)."""
        pad = 0 if self.tail is None else self.tail.count  # the tail's rows: not counted here
        rows = conflict.rows
        if plain is not None:
            about = np.concatenate([plain, np.repeat(plain[-1:], max(pad - 1, 0), axis=0)])
            rows = self.rows(p0, about, conflict.cand, growing=growing)
        x_enc = np.concatenate([x_nom, np.repeat(x_nom[-1:], pad, axis=0)])
        return self.conflicted(x_enc, rows, tail=False)

    def blocked_targets(self, targets: Array) -> Array:
        """Drones (n,) whose target (n, d) lies within ``d_min`` + margin + 2 tube (in the metric) of
        another's (:mod:`mpcform.mpc.liveness`; not obstacles: a moving reference may cross one)."""
        return self._near_targets(targets, 0.0)

    def growing(self, targets: Array) -> Array | None:
        """Each drone's share (n,) of the rows' growth: 1, but 0 for a drone whose target (n, d) lies
        within the grown rows' distance at rest (``d_min`` + margin + 2 tube + twice the tail's
        growth) of another's: a tight formation, whose drones could not hold their targets with the
        growth (they keep the one-interval margin alone). None without growth."""
        if self.growth is None:
            return None
        return (~self._near_targets(targets, 2.0 * self.growth[-1])).astype(float)

    def _near_targets(self, targets: Array, extra_m: float) -> Array:
        """Drones (n,) whose target lies within ``d_min`` + margin + 2 tube + ``extra_m`` (in the
        metric) of another's."""
        near = np.zeros(targets.shape[0], dtype=bool)
        if self.pairs is not None and targets.shape[0] > 1:
            reach = self.pairs.d_min_m + self.margin_m + 2.0 * self.tube_m + extra_m
            near[pairs_within(targets * self.metric, reach).ravel()] = True
        return near

    def push_apart(self, p0: Array, cand: Candidates) -> Array:
        """Unit directions (n, d) (zero for a drone with none) away from the partners and
        obstacles within reach whose required distance it is inside: the sum of the start normals."""
        push = np.zeros_like(p0)
        if cand.pair_on.any() and self.pairs is not None:
            i, k = cand.pairs[cand.pair_on].T
            hard, c0 = inside(self.pairs.relative(p0, i, k), self.pairs.d_min_m)
            np.add.at(push, i[hard], c0)
            np.add.at(push, k[hard], -c0)
        if cand.obstacle_on.any() and self.obstacles is not None:
            i, m = cand.obstacles[cand.obstacle_on].T
            dist, c0 = self.obstacles.start_normals(p0[i], m)
            hard = dist < self.obstacles.required_m[m]
            np.add.at(push, i[hard], c0[hard])
        norm = np.linalg.norm(push, axis=1, keepdims=True)
        return np.divide(push, norm, out=np.zeros_like(push), where=norm > 1e-12)

    def start_shortfall(self, p0: Array, rows: SeparationRows, tol_m: float = 0.0) -> tuple[float, Array]:
        """How far [m] the items that start inside their required distance (the hard ones) by more
        than ``tol_m`` are inside it at ``p0``, at most, and their labels (m, 2)."""
        labels = np.concatenate(
            [rows.pairs[rows.pair_hard & rows.pair_on], rows.labels[rows.single_hard & rows.single_on]]
        )
        if labels.shape[0] == 0:
            return 0.0, labels
        pair = labels[:, 1] >= 0
        labels[pair] = np.sort(labels[pair], axis=1)  # a decoupled pair's two sides name it once
        labels = np.unique(labels, axis=0)
        pair, short = labels[:, 1] >= 0, np.zeros(labels.shape[0])
        if pair.any() and self.pairs is not None:
            i, k = labels[pair].T
            short[pair] = self.pairs.d_min_m - vector_norms(self.pairs.relative(p0, i, k))
        if (~pair).any() and self.obstacles is not None:
            i, m = labels[~pair, 0], -1 - labels[~pair, 1]
            short[~pair] = self.obstacles.required_m[m] - self.obstacles.start_distance(p0[i], m)
        inside = short > tol_m
        return float(short[inside].max(initial=0.0)), labels[inside]

    def first_segment(self, p0: Array, p1: Array, cand: Candidates) -> list[SegmentTest]:
        """For the items within reach: their distance at ``p0``, along the segment to ``p1``, and
        the distance required."""
        tests = []
        if cand.pair_on.any() and self.pairs is not None:
            tests.append(self.pairs.first_segment(p0, p1, cand.pairs[cand.pair_on]))
        if cand.obstacle_on.any() and self.obstacles is not None:
            tests.append(self.obstacles.first_segment(p0, p1, cand.obstacles[cand.obstacle_on]))
        return tests


def rollout_meets(
    sep: Separation,
    p0: Array,
    guess: Array,
    positions: Array,
    x: Array,
    cand: Candidates,
    stops: Array | None = None,
    growing: Array | None = None,
) -> bool:
    """Whether a plan's ``positions`` (H + 1, n, d) (row 0 ``p0``; ``x`` (H, n, d) the others
    relative to it) surely meet the rows about ``guess`` of the candidate items ``cand`` as the
    fast path asks (the joint pair rows and the obstacle rows; joint coupling: every row),
    building the rows only of the pairs :meth:`~mpcform.mpc.constraints.clear.ClearTest.unclear_pairs`
    leaves in doubt and of the obstacle items (False: unknown, every row to build); ``stops``,
    ``growing``: see :meth:`Separation.rows`."""
    if sep.pairs is None or not cand.pairs.shape[0]:
        return False
    unclear, n = sep.clearing.unclear_pairs(guess, positions, growing), p0.shape[0]
    keep = np.isin(cand.pairs[:, 0] * n + cand.pairs[:, 1], unclear[:, 0] * n + unclear[:, 1])
    if keep.all():
        return False
    sub = replace(cand, pairs=cand.pairs[keep], pair_on=cand.pair_on[keep])
    rows = sep.rows(p0, guess, sub, stops, growing)
    values = sep.single_values(x, rows)
    if sep.pairs.joint:
        return not sep.conflicted(x, rows, values).any()
    return sep.meets_joint(x, rows, values)

"""One step's linearised separation rows, in the QP's order: joint pairs first, then one-drone
items (decoupled pair sides, obstacles), each item with R rows (:mod:`mpcform.mpc.constraints.separation`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mpcform._validate import Array


@dataclass(frozen=True)
class SeparationRows:
    """Linearised separation rows of one step, in QP order (R rows per item).

    Two-drone items (joint pairs) first, then one-drone items (decoupled pair sides, obstacles);
    ``labels`` (S, 2) names what a one-drone item reports: ``(i, k)`` or ``(i, -1 - obstacle)``;
    ``*_hard`` marks the items that start inside their required distance: their first row is a hard
    no-approach row (no slack).
    """

    pairs: Array  # (P, 2)
    pair_coeffs: Array  # (P, R, d)
    pair_lower: Array  # (P, R)
    pair_on: Array  # (P,)
    singles: Array  # (S,) drone index
    labels: Array  # (S, 2)
    single_coeffs: Array  # (S, R, d)
    single_lower: Array  # (S, R)
    single_on: Array  # (S,)
    pair_hard: Array  # (P,)
    single_hard: Array  # (S,)

    def subset(self, drones: Array, n: int, on_only: bool) -> SeparationRows:
        """The rows of the items within ``drones`` (only those within reach with ``on_only``), with
        drone indices renumbered 0..len(drones)-1 (``labels`` keep the global ones)."""
        local = np.full(n, -1)
        local[drones] = np.arange(drones.shape[0])
        keep_p = (local[self.pairs] >= 0).all(axis=1) & (self.pair_on | (not on_only))
        keep_s = (local[self.singles] >= 0) & (self.single_on | (not on_only))
        if drones.shape[0] == n and keep_p.all() and keep_s.all():  # everything: no copies
            return self
        return SeparationRows(
            local[self.pairs[keep_p]],
            self.pair_coeffs[keep_p],
            self.pair_lower[keep_p],
            self.pair_on[keep_p],
            local[self.singles[keep_s]],
            self.labels[keep_s],
            self.single_coeffs[keep_s],
            self.single_lower[keep_s],
            self.single_on[keep_s],
            self.pair_hard[keep_p],
            self.single_hard[keep_s],
        )

    def ungrown(self, growing: Array | None, grow: Array | None) -> SeparationRows:
        """These rows, grown by ``grow`` (R,) [m] per drone and row times each drone's share
        ``growing`` (n,) (:meth:`Separation.growing`), without their growth in wind: the required
        distances alone (``d_min`` + margin + 2 tube, the clearances). The growth is a buffer that
        keeps the next steps' plans feasible; a plan may reach into it and still keep every required
        distance (:func:`mpcform.mpc.safety.slack.slack_report`)."""
        if growing is None or grow is None:
            return self
        pair_share = growing[self.pairs[:, 0]] + growing[self.pairs[:, 1]]
        return replace(
            self,
            pair_lower=self.pair_lower - pair_share[:, None] * grow,
            single_lower=self.single_lower - growing[self.singles][:, None] * grow,
        )

    def joint(self) -> SeparationRows:
        """The joint pair rows whose split these decoupled rows are: per pair side i's normal and
        the sum of both sides' lower bounds, after the joint pairs there are (the obstacle items
        stay one-drone items)."""
        first, second = pair_sides(self.labels)
        ob = np.flatnonzero(self.labels[:, 1] < 0)
        return SeparationRows(
            np.concatenate([self.pairs, np.column_stack([self.singles[first], self.singles[second]])]),
            np.concatenate([self.pair_coeffs, self.single_coeffs[first]]),
            np.concatenate([self.pair_lower, self.single_lower[first] + self.single_lower[second]]),
            np.concatenate([self.pair_on, self.single_on[first]]),
            self.singles[ob],
            self.labels[ob],
            self.single_coeffs[ob],
            self.single_lower[ob],
            self.single_on[ob],
            np.concatenate([self.pair_hard, self.single_hard[first]]),
            self.single_hard[ob],
        )


def pair_sides(labels: Array) -> tuple[Array, Array]:
    """The pair sides among one-drone items of ``labels`` (S, 2): side i (``(i, k)``, i < k) and
    side k (``(k, i)``) of each pair, in the same pair order."""
    n = int(labels.max(initial=0)) + 1
    key = np.where(labels[:, 1] >= 0, np.minimum(labels[:, 0], labels[:, 1]) * n + labels.max(axis=1), -1)
    first = np.flatnonzero((labels[:, 1] >= 0) & (labels[:, 0] < labels[:, 1]))
    second = np.flatnonzero((labels[:, 1] >= 0) & (labels[:, 0] > labels[:, 1]))
    if first.shape == second.shape and np.array_equal(key[first], key[second]):  # the rows' own layout
        order = np.argsort(key[first])
        return first[order], second[order]
    both = np.intersect1d(key[first], key[second])  # a side whose partner is not solved stays put
    first, second = first[np.isin(key[first], both)], second[np.isin(key[second], both)]
    return first[np.argsort(key[first])], second[np.argsort(key[second])]

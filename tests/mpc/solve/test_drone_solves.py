"""The per-drone solves' record: each drone's separation multipliers read past its constant rows
(and past its slacks' bounds when solved soft), negated to the ``>= 0`` convention."""

from __future__ import annotations

import numpy as np

from mpcform.mpc.solve.drone_solves import DroneSolves


def record(
    lams: list[np.ndarray], soft: list[bool], counts: list[int], horizon: int, n_const: int
) -> DroneSolves:
    n = len(lams)
    z = np.zeros((n, 1))
    offsets = np.concatenate([[0], np.cumsum(counts)])
    return DroneSolves(
        z, z, np.zeros(n), np.ones(n, int), np.ones(n, bool), np.array(soft), lams, np.arange(offsets[-1]),
        offsets, z, z[:, 0], z[:, 0], z, z, 0, 0.0, horizon, n_const,
    )  # fmt: skip # the record's sixteen fields, one argument each


def test_multipliers_skip_the_constant_rows_and_the_slacks_bounds() -> None:
    h, c = 2, 3
    hard = np.array([0.1, 0.2, 0.3, -1.0, -2.0])  # 3 constant rows, 2 separation rows at their lower bound
    soft = np.array([9.0, 9.0, 0.4, 0.5, 0.6, -3.0])  # 2 slack bounds first, then 3 constant, 1 separation
    got = record([hard, soft], [False, True], [2, 1], h, c)
    assert np.array_equal(got.multipliers(0), [1.0, 2.0]) and np.array_equal(got.multipliers(1), [3.0])
    assert np.array_equal(got.multipliers(1, everything=True), soft[h:])
    every = got.separation_multipliers()
    assert [m.tolist() for m in every] == [[1.0, 2.0], [3.0]]

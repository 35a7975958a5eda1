"""scipy's OpenBLAS held to one thread: the same results, and the count restored."""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

from mpcform._blas import one_thread


def test_one_thread_gives_the_same_bits_and_restores_the_count() -> None:
    m = np.eye(30) + 0.1 * np.kron(np.tril(np.ones((10, 10)), -1), np.eye(3))
    pooled = solve_triangular(m, np.eye(30), lower=True)
    with one_thread():
        alone = solve_triangular(m, np.eye(30), lower=True)
        with one_thread():  # nested: still one
            again = solve_triangular(m, np.eye(30), lower=True)
    assert np.array_equal(pooled, alone) and np.array_equal(alone, again)
    np.testing.assert_array_equal(solve_triangular(m, np.eye(30), lower=True), pooled)

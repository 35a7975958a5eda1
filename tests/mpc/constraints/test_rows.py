"""The QP's layout and structural rows, by hand: dynamics, positions, separation pattern, slack."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import dense_matrix, z_of

from mpcform.mpc.constraints.rows import (
    Layout,
    dynamics_rows,
    positions_of_inputs,
    row_ends,
    row_segments,
    separation_pattern,
    slack_rows,
    step_growth,
    tail_rows,
)

DT = 0.1


def test_layout_columns() -> None:
    lay = Layout(n=2, dim=3, horizon=4)
    assert (lay.nud, lay.n_slack, lay.n_var) == (24, 8, 56)
    assert lay.u_cols()[1, 0, 2] == 1 * 6 + 0 * 3 + 2
    assert lay.x_cols()[0, 1, 0] == 24 + 3
    assert lay.s_cols()[3, 1] == 48 + 7


def test_row_order_per_item() -> None:
    np.testing.assert_array_equal(row_ends(3), [1, 2, 1, 3, 2])  # segment 0: end; 1, 2: end then start
    np.testing.assert_array_equal(row_segments(3), [0, 1, 1, 2, 2])


def test_dynamics_rows_vanish_on_a_consistent_trajectory() -> None:
    rng = np.random.default_rng(0)
    lay = Layout(3, 2, 5)
    u = rng.normal(size=(5, 3, 2))
    x = DT * np.cumsum(u, axis=0)
    a = dense_matrix(dynamics_rows(lay, DT), lay)
    np.testing.assert_allclose(a @ z_of(lay, u, x, rng.normal(size=(5, 3))), 0.0, atol=1e-14)
    x[2, 1, 0] += 1e-3
    assert np.abs(a @ z_of(lay, u, x, np.zeros((5, 3)))).max() == pytest.approx(1e-3)


def test_positions_of_inputs() -> None:
    u = np.array([[1.0, 0.0], [0.0, 2.0], [3.0, 0.0]])
    np.testing.assert_allclose(positions_of_inputs(3, 2, 0.5) @ u.ravel(), [0.5, 0, 0.5, 1, 2, 1])


def test_separation_pattern_by_hand() -> None:
    """One pair (0, 1) and one single (drone 1), horizon 1 (one row each): x_1 of both, their slacks."""
    lay = Layout(2, 2, 1)
    block = separation_pattern(lay, np.array([[0, 1]]), np.array([1]))
    assert block.lower.shape == (2,) and np.all(block.upper == np.inf) and np.all(block.vals == 0)
    cols = [sorted(block.cols.ravel()[block.rows.ravel() == r].tolist()) for r in range(2)]
    x0, x1, s = lay.x_cols()[0], lay.x_cols()[0, 1], lay.s_cols()[0]
    assert cols[0] == sorted([*x0[0], *x0[1], s[0], s[1]])
    assert cols[1] == sorted([*x1, s[1]])
    empty = separation_pattern(lay, np.empty((0, 2), dtype=int), np.empty(0, dtype=int))
    assert empty.lower.shape == (0,) and empty.rows.size == 0


def test_slack_rows() -> None:
    lay = Layout(2, 3, 2)
    a = dense_matrix(slack_rows(lay), lay)
    np.testing.assert_array_equal(a[:, 2 * lay.nud :], np.eye(4))


def test_the_braking_tail_adds_a_stop_row_on_x_h_and_u_h_minus_1() -> None:
    """Horizon 1 with the tail: rows at x_1, the stop point and x_1 again (the tail's start); the
    stop row (the last of :func:`tail_rows`) has the single's x_1 and u_0 columns and its step-1 slack."""
    lay = Layout(1, 2, 1)
    block = separation_pattern(lay, np.empty((0, 2), dtype=int), np.array([0]), 1, np.array([0]))
    assert block.lower.shape == (3,) and tail_rows(1, 1)[-1] == 1 and row_ends(1, 1).tolist() == [1, 2, 1]
    cols = [sorted(block.cols.ravel()[block.rows.ravel() == r].tolist()) for r in range(3)]
    x, u, s = lay.x_cols()[0, 0].tolist(), lay.u_cols()[0, 0].tolist(), lay.s_cols()[0, 0]
    assert cols[0] == cols[2] == sorted([*x, s]) and cols[1] == sorted([*u, *x, s])


def test_step_growth_grows_by_one_growth_per_step_for_at_most_the_growth_time() -> None:
    """``growth min(e - 1, E)`` at position steps e = 0 .. H + T, E = min(H, ceil(0.2 s / dt))."""
    assert step_growth(0.0, 0.1, 8) is None
    np.testing.assert_allclose(
        step_growth(0.01, 0.1, 8, 2), 0.01 * np.array([0, 0, 1, 2, 2, 2, 2, 2, 2, 2, 2])
    )
    np.testing.assert_allclose(step_growth(0.01, 0.05, 2), 0.01 * np.array([0, 0, 1]))  # E = H
    assert step_growth(0.02, 0.06, 30)[-1] == pytest.approx(0.02 * 4)  # E = ceil(0.2 / 0.06)

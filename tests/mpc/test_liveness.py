"""Tie-break: conflicted drones turn to the right, more while they stay stalled, up to a quarter turn."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.mpc.liveness import STALL_FRACTION, STALL_GROWTH, TieBreak, norms, turn_about_z


def test_turn_about_z_by_hand() -> None:
    v = np.array([[[1.0, 0.0, 2.0], [0.0, 1.0, -1.0]]])  # (H = 1, n = 2, d = 3)
    out = turn_about_z(v, np.array([np.pi / 2, -np.pi / 2]))
    np.testing.assert_allclose(out, [[[0.0, 1.0, 2.0], [1.0, 0.0, -1.0]]], atol=1e-15)  # z kept
    planar = turn_about_z(np.array([[1.0, 0.0]]), np.array([np.pi]))
    np.testing.assert_allclose(planar, [[-1.0, 0.0]], atol=1e-15)


def test_only_conflicted_drones_turn_to_the_right() -> None:
    tb = TieBreak(2, 0.5)
    c = np.array([[[1.0, 0.0], [1.0, 0.0]]] * 3)
    out = tb.turn(c, np.array([True, False]), np.ones((2, 2)), started=True)
    np.testing.assert_allclose(out[:, 0], [[np.cos(0.5), -np.sin(0.5)]] * 3)  # clockwise seen from +z
    np.testing.assert_array_equal(out[:, 1], c[:, 1])
    assert np.all(norms(out) == pytest.approx(1.0))


def test_angle_grows_while_stalled_up_to_a_quarter_turn() -> None:
    tb = TieBreak(2, 0.5)
    conflicted, wish = np.array([True, True]), np.array([[1.0, 0.0], [1.0, 0.0]])
    u_prev = np.array([[0.5 * STALL_FRACTION, 0.0], [1.0, 0.0]])  # drone 0 stalled, drone 1 moving
    angles = [tb.angles(conflicted, wish, u_prev, started=True) for _ in range(3)]
    np.testing.assert_allclose([a[0] for a in angles], [0.5 * (1 + STALL_GROWTH * s) for s in (1, 2, 3)])
    np.testing.assert_allclose([a[1] for a in angles], 0.5)
    for _ in range(100):
        last = tb.angles(conflicted, wish, u_prev, started=True)
    assert last[0] == pytest.approx(0.5 * np.pi)
    tb.angles(np.array([False, True]), wish, u_prev, started=True)  # out of conflict: count restarts
    assert tb.stalled[0] == 0
    tb.stalled[:] = 4
    tb.clear()
    assert not tb.stalled.any()


def test_nothing_stalls_before_the_first_command_and_zero_disables() -> None:
    tb = TieBreak(1, 0.5)
    assert tb.angles(np.array([True]), np.ones((1, 2)), np.zeros((1, 2)), started=False)[0] == 0.5
    assert tb.stalled[0] == 0
    c = np.ones((2, 1, 2))
    assert TieBreak(1, 0.0).turn(c, np.array([True]), np.zeros((1, 2)), started=True) is c


def test_a_base_angle_above_a_quarter_turn_is_kept() -> None:
    tb = TieBreak(1, 2.0)
    for _ in range(5):
        angle = tb.angles(np.array([True]), np.ones((1, 2)), np.zeros((1, 2)), started=True)[0]
    assert angle == 2.0

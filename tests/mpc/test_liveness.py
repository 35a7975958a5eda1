"""Tie-break: conflicted drones turn to the right, more while they stay stalled; the escalation is kept
while in conflict, capped, and starts afresh after backing off."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.mpc.liveness import (
    BACKOFF_M,
    MOVING_FRACTION,
    STALL_FRACTION,
    STALL_GROWTH,
    TieBreak,
    norms,
    turn_about_z,
)


def test_turn_about_z_by_hand() -> None:
    v = np.array([[[1.0, 0.0, 2.0], [0.0, 1.0, -1.0]]])  # (H = 1, n = 2, d = 3)
    out = turn_about_z(v, np.array([np.pi / 2, -np.pi / 2]))
    np.testing.assert_allclose(out, [[[0.0, 1.0, 2.0], [1.0, 0.0, -1.0]]], atol=1e-15)  # z kept
    planar = turn_about_z(np.array([[1.0, 0.0]]), np.array([np.pi]))
    np.testing.assert_allclose(planar, [[-1.0, 0.0]], atol=1e-15)


def test_only_conflicted_drones_turn_to_the_right() -> None:
    tb = TieBreak(2, 0.5)
    c = np.array([[[1.0, 0.0], [1.0, 0.0]]] * 3)
    out = tb.turn(c, np.array([True, False]), np.zeros((2, 2)), np.ones((2, 2)), started=True)
    np.testing.assert_allclose(out[:, 0], [[np.cos(0.5), -np.sin(0.5)]] * 3)  # clockwise seen from +z
    np.testing.assert_array_equal(out[:, 1], c[:, 1])
    assert np.all(norms(out) == pytest.approx(1.0))


def test_a_drone_with_a_blocked_target_is_not_turned_nor_escalated() -> None:
    """Both drones conflicted and stalled; drone 1's target is blocked: its wish stays as it is and
    its turn never escalates, drone 0's does."""
    tb = TieBreak(2, 0.5, dt_s=0.1)
    c, p = np.array([[[1.0, 0.0], [1.0, 0.0]]] * 3), np.zeros((2, 2))
    blocked, conflicted = np.array([False, True]), np.array([True, True])
    for _ in range(4):
        out = tb.turn(c, conflicted, p, np.array([[10.0, 0.0]] * 2), started=True, blocked=blocked)
    np.testing.assert_array_equal(out[:, 1], c[:, 1])
    assert tb.stalled[1] == 0 and tb.stalled[0] == 3
    assert out[0, 0, 1] < 0.0  # drone 0 turned to the right


def stalls(tb: TieBreak, conflicted: list[bool], moves: list[list[float]], steps: int) -> list[np.ndarray]:
    """Turn angles over ``steps`` steps of drones that start at the origin, head for (10, 0) with a
    wish of 1 m/s, and move by ``moves`` (n, 2) per step."""
    p, wish, out = np.zeros((len(moves), 2)), np.ones(len(moves)), []
    for _ in range(steps):
        out.append(tb.angles(np.array(conflicted), wish, p, np.array([10.0, 0.0]) - p, started=True))
        p = p + np.array(moves)
    return out


def test_angle_grows_while_stalled_and_is_kept_while_in_conflict() -> None:
    tb = TieBreak(2, 0.5, dt_s=0.1)
    slow = 0.5 * STALL_FRACTION * 0.1  # below STALL_FRACTION of the wish's 0.1 m step
    angles = stalls(tb, [True, True], [[slow, 0.0], [0.1, 0.0]], 4)  # drone 0 stalled, drone 1 moving
    np.testing.assert_allclose([a[0] for a in angles], [0.5 * (1 + STALL_GROWTH * s) for s in (0, 1, 2, 3)])
    np.testing.assert_allclose([a[1] for a in angles], 0.5)
    assert tb.new_stalls == 0 and tb.resolving == 1
    # moving again while still in conflict: the raised angle is kept (no fall back into the jam)
    p = np.array([[0.0, 0.0], [0.0, 0.0]])
    again = tb.angles(np.array([True, True]), np.full(2, 2**0.5), p + 0.05, np.array([10.0, 0.0]) - p, True)
    assert again[0] == pytest.approx(0.5 * (1 + STALL_GROWTH * 3))
    tb.angles(np.array([False, True]), np.full(2, 2**0.5), p, np.ones((2, 2)), True)  # out of conflict
    assert tb.stalled[0] == 0 and tb.resolved == 1
    tb.stalled[:] = 4
    tb.clear()
    assert not tb.stalled.any() and tb.resolved == 2 and tb.last_m is None
    tb.clear()  # cleared again without a turn between: nothing more has resolved
    assert tb.resolved == tb.new_stalls == 0 and not tb.stalled.any() and np.isinf(tb.stall_distance_m).all()


def test_with_a_max_the_turn_grows_no_faster_than_the_drone_can_follow_it() -> None:
    # a drone flying 1 m/s whose command changes by at most 0.05 m/s per step, moving away: stalled
    # at every step, but each step raises the turn by 0.05 / (0.2 * 0.5 * 1) = half a growth step
    tb, c, p = TieBreak(1, 0.5, dt_s=0.1), np.tile([1.0, 0.0], (3, 1, 1)), np.zeros((1, 2))
    for _ in range(5):
        tb.turn(
            c, np.array([True]), p, np.array([[10.0, 0.0]]) - p, True, speed_mps=np.ones(1), step_mps=0.05
        )
        p = p - [[0.01, 0.0]]
    assert tb.stalled[0] == pytest.approx(4 * 0.5)  # the first step has no progress to measure
    # speeding up from rest (0.05 m/s reachable): 0.004 m of progress per step is not a stall
    tb, p = TieBreak(1, 0.5, dt_s=0.1), np.zeros((1, 2))
    for _ in range(5):
        tb.turn(
            c, np.array([True]), p, np.array([[10.0, 0.0]]) - p, True, speed_mps=np.zeros(1), step_mps=0.05
        )
        p = p + [[0.004, 0.0]]
    assert tb.stalled[0] == 0


def test_with_a_max_a_drone_deflected_at_speed_is_not_stalled() -> None:
    """Flying across the way to its target at its speed (no progress) is not a stall under a_max
    (a circulating ring is not stuck); a step below MOVING_FRACTION of the wish's is, and without
    a_max any step without progress is."""
    c, conflicted, to_target = np.tile([1.0, 0.0], (3, 1, 1)), np.array([True]), np.array([[10.0, 0.0]])
    for side_m, a_max, stalled in ((0.1, True, 0.0), (0.05 * MOVING_FRACTION, True, 4.0), (0.1, False, 4.0)):
        tb, p = TieBreak(1, 0.5, dt_s=0.1), np.zeros((1, 2))
        for _ in range(5):
            speed = {"speed_mps": np.ones(1), "step_mps": 1.0} if a_max else {}
            tb.turn(c, conflicted, p, to_target - p, True, **speed)
            p = p + [[0.0, side_m]]
        assert tb.stalled[0] == stalled, (side_m, a_max)


def test_a_stuck_drone_sweeps_the_full_circle_and_backing_off_starts_afresh() -> None:
    tb = TieBreak(1, 0.5, dt_s=0.1)
    angles = np.array([a[0] for a in stalls(tb, [True], [[0.0, 0.0]], 200)])
    assert angles.max() > 1.9 * np.pi and angles.min() >= 0.0  # every direction is tried
    np.testing.assert_allclose(angles, np.mod(0.5 * (1 + STALL_GROWTH * np.arange(200)), 2 * np.pi))
    tb = TieBreak(1, 0.5, dt_s=0.1)
    angles = stalls(tb, [True], [[-0.05, 0.0]], 40)  # backing away: 2 m in 40 steps
    assert tb.stalled[0] < 20 and min(a[0] for a in angles[5:]) < 0.6  # restarted after BACKOFF_M
    assert BACKOFF_M < 2.0


def test_the_back_off_budget_is_the_conflicts_so_a_drone_never_walks_away() -> None:
    """A drone carried away from its target while in conflict (5 m in 100 steps) switches side
    once, after BACKOFF_M; beyond the budget it stops escalating (the base angle only) instead of
    renewing the budget at every switch; out of conflict the budget and the switch are cleared."""
    tb = TieBreak(1, 0.5, dt_s=0.1)
    angles = np.array([a[0] for a in stalls(tb, [True], [[-0.05, 0.0]], 100)])
    assert tb.sense[0] == -1.0 and tb.switched[0]  # one switch, not one per metre
    beyond = int(np.ceil(BACKOFF_M / 0.05)) + 2
    np.testing.assert_array_equal(angles[beyond:], 0.5)  # waits: no escalation past the budget
    tb.angles(np.array([False]), np.ones(1), np.zeros((1, 2)), np.array([[10.0, 0.0]]), started=True)
    assert not tb.switched[0] and tb.stall_distance_m[0] == np.inf


def test_a_drone_circling_its_target_has_its_escalation_reset_and_a_jammed_one_keeps_it() -> None:
    """Drone 0 circles its target at a constant 2 m (0.35 m per step: never stalled), drone 1 barely
    moves, drone 2 circles within PROGRESS_M of its target: after WAIT_S without progress only drone
    0's escalated turn is reset (counted in ``unwound``), and out of conflict the counts are cleared."""
    from mpcform.mpc.liveness import PROGRESS_M, WAIT_S

    tb = TieBreak(3, 0.5, dt_s=0.1)
    wish, steps = np.ones(3), round(WAIT_S / 0.1)
    for j in range(steps + 1):  # the first step sets the best distance
        a = 0.35 * j / 2.0
        p = np.array(
            [[2.0 * np.cos(a), 2.0 * np.sin(a)], [1e-3 * j, 0.0], [0.05 * np.cos(a), 0.05 * np.sin(a)]]
        )
        tb.stalled[:] = 7.0  # escalated turns
        target = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 0.0]])
        tb.angles(np.array([True, True, True]), wish, p, target - p, started=True)
        assert (tb.unwound == 1) == (j == steps), j
    assert tb.stalled[0] == 0.0 and tb.stalled[1] > 0.0 and tb.stalled[2] > 0.0
    assert 0.5 * PROGRESS_M < 0.06
    tb.clear()
    assert tb.unwound == 0 and not tb.idle_s.any() and np.isinf(tb.best_m).all()


def test_arrived_or_first_steps_do_not_stall_and_zero_disables() -> None:
    tb = TieBreak(1, 0.5)
    p = np.zeros((1, 2))
    assert tb.angles(np.array([True]), np.full(1, 2**0.5), p, np.ones((1, 2)), started=False)[0] == 0.5
    assert tb.angles(np.array([True]), np.full(1, 2**0.5), p, np.full((1, 2), 1e-3), started=True)[0] == 0.5
    assert tb.stalled[0] == 0
    c = np.ones((2, 1, 2))
    assert TieBreak(1, 0.0).turn(c, np.array([True]), p, np.ones((1, 2)), started=True) is c


def test_a_base_angle_of_a_quarter_turn_or_more_is_kept() -> None:
    tb = TieBreak(1, 3.0)
    assert all(a[0] == 3.0 for a in stalls(tb, [True], [[0.0, 0.0]], 5))

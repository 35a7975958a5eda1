"""Plan: the eq. 14 rollout, the shifted guess and warm start, plans from relative positions."""

from __future__ import annotations

import numpy as np

from mpcform.mpc.plan import Plan, braking_error, guess, rollout, warm_start


def test_rollout_is_eq14_step_by_step() -> None:
    rng = np.random.default_rng(0)
    c, k, dt = rng.normal(size=(5, 3, 2)), 2.0, 0.1
    u, x = rollout(c, k, dt)
    pos = np.zeros((3, 2))
    for j in range(5):
        np.testing.assert_allclose(u[j], c[j] - k * pos)  # u_j = ff_j + k (p*_j - p_j) relative to p0
        pos = pos + dt * u[j]
        np.testing.assert_allclose(x[j], pos)


def test_constant_wish_decays_geometrically() -> None:
    u, x = rollout(np.ones((4, 1, 1)), 5.0, 0.1)  # u_j = 1 - 5 x_j: (1 - k dt)^j
    np.testing.assert_allclose(u[:, 0, 0], 0.5 ** np.arange(4))


def test_plan_from_relative_positions() -> None:
    p0 = np.array([[1.0, 2.0]])
    u = np.array([[[1.0, 0.0]], [[0.0, 1.0]]])
    plan = Plan.from_relative(p0, u, 0.1 * np.cumsum(u, axis=0))
    np.testing.assert_allclose(plan.positions_m[:, 0], [[1.0, 2.0], [1.1, 2.0], [1.1, 2.1]])
    np.testing.assert_allclose(plan.shifted_inputs(), [[[0.0, 1.0]], [[0.0, 0.0]]])


def test_guess_and_warm_start_shift_the_previous_plan() -> None:
    p0 = np.array([[0.0, 0.0]])
    np.testing.assert_array_equal(guess(None, p0, 2), np.zeros((3, 1, 2)))  # first step: holding
    u_nom, x_nom = np.full((2, 1, 2), 3.0), np.full((2, 1, 2), 4.0)
    np.testing.assert_array_equal(warm_start(None, p0, u_nom, x_nom), [u_nom, x_nom])
    positions = np.array([[[0.0, 0.0]], [[1.0, 0.0]], [[2.0, 0.0]]])
    plan = Plan(np.array([[[10.0, 0.0]], [[10.0, 0.0]]]), positions)
    moved = np.array([[0.9, 0.1]])  # measured, not exactly the plan's first position
    np.testing.assert_array_equal(guess(plan, moved, 2)[:, 0], [[0.9, 0.1], [2.0, 0.0], [2.0, 0.0]])
    warm = warm_start(plan, moved, u_nom, x_nom)
    np.testing.assert_array_equal(warm[0, :, 0], [[10.0, 0.0], [0.0, 0.0]])  # ends in a hold
    np.testing.assert_allclose(warm[1, :, 0], [[1.1, -0.1], [1.1, -0.1]])


def test_shifted_inputs_end_in_a_hold_or_slow_down_within_a_max() -> None:
    inputs = np.array([[[1.0, -1.0]], [[2.0, 0.5]], [[3.0, -0.1]]])  # (H = 3, n = 1, d = 2)
    plan = Plan(inputs, np.zeros((4, 1, 2)))
    np.testing.assert_allclose(plan.shifted_inputs()[-1], 0.0)  # a hold: |u| jumps by 3 m/s
    slowed = plan.shifted_inputs(0.2)
    np.testing.assert_allclose(slowed[:2], inputs[1:])
    np.testing.assert_allclose(slowed[-1], [[2.8, 0.0]])
    assert np.abs(slowed[-1] - slowed[-2]).max() <= 0.2 + 1e-12  # the last change within a_max dt


def test_braking_error_leaves_eq14_within_a_max_over_k_squared_and_without_a_max() -> None:
    rng = np.random.default_rng(1)
    k, a_max = 2.0, 0.5  # unchanged within a_max / k^2 = 0.125 m, or where v_max binds first
    near = rng.normal(size=(6, 4, 3))
    near *= 0.12 / np.linalg.norm(near[0], axis=-1)[None, :, None]
    assert braking_error(near, k, a_max, 3.0) is near
    far = 10.0 * near
    assert braking_error(far, k, None, 3.0) is far
    assert braking_error(far, k, a_max, 0.5) is far  # sqrt(a_max |e|) = 0.77 m/s above v_max


def test_braking_error_shortens_the_first_error_to_the_braking_speed_and_shifts_all() -> None:
    rng = np.random.default_rng(2)
    k, a_max, v_max = 2.0, 0.5, 3.0
    error = rng.normal(size=(5, 6, 2)) * np.array([0.01, 0.1, 1.0, 3.0, 10.0, 100.0])[None, :, None]
    out = braking_error(error, k, a_max, v_max)
    dist = np.linalg.norm(error[0], axis=-1)
    brake = np.sqrt(a_max * dist)
    over = brake < np.minimum(k * dist, v_max)
    assert over.any() and not over.all()
    speed = k * np.linalg.norm(out[0], axis=-1)
    np.testing.assert_allclose(speed[over], brake[over], rtol=1e-12)  # the braking profile's speed
    np.testing.assert_array_equal(out[:, ~over], error[:, ~over])
    shift = out - error  # one shift per drone over the horizon, along its first error
    np.testing.assert_allclose(shift, np.broadcast_to(shift[0], shift.shape), atol=1e-12)
    cross = shift[0, :, 0] * error[0, :, 1] - shift[0, :, 1] * error[0, :, 0]
    np.testing.assert_allclose(cross, 0.0, atol=1e-9)
    assert np.all(np.einsum("nd,nd->n", shift[0], error[0]) <= 0.0)

"""Closed-form laws: go-to-goal (eq. 4-5), its discrete form, saturation (eq. 7), eq. 14."""

import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from mpcform.control.laws import (
    check_gain_dt,
    count_saturated,
    go_to_goal_closed_form,
    go_to_goal_discrete,
    saturate,
    tracking_command,
)
from mpcform.errors import ValidationError

commands = arrays(float, st.tuples(st.integers(1, 6), st.sampled_from([2, 3])), elements=st.floats(-50, 50))
speeds = st.floats(0.1, 20.0)


@given(commands, speeds)
def test_saturation_caps_the_speed_and_keeps_the_direction(u, v_max):
    out = saturate(u, v_max)
    norms, out_norms = np.linalg.norm(u, axis=1), np.linalg.norm(out, axis=1)
    assert np.all(out_norms <= v_max * (1 + 1e-12))
    below = norms <= v_max
    np.testing.assert_array_equal(out[below], u[below])  # eq. 7, first case: unchanged
    above = ~below
    np.testing.assert_allclose(out_norms[above], v_max, rtol=1e-12)  # second case: on the ball
    # same direction: out = alpha u with alpha > 0
    cos = np.einsum("ij,ij->i", out[above], u[above]) / (out_norms[above] * norms[above])
    np.testing.assert_allclose(cos, 1.0, rtol=1e-12)


@given(commands, speeds, st.integers(0, 2**32 - 1))
def test_saturation_is_the_projection_onto_the_ball(u, v_max, seed):
    """(u - P u) . (w - P u) <= 0 for every w in the ball: the variational inequality."""
    out = saturate(u, v_max)
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(20,) + u.shape)
    w *= v_max * rng.uniform(0, 1, (20, u.shape[0], 1)) / np.linalg.norm(w, axis=-1, keepdims=True)
    assert np.all(np.einsum("kij,ij->ki", w - out, u - out) <= 1e-9 * (1 + np.abs(u).max()) ** 2)


def test_saturation_edge_cases():
    u = np.array([[0.0, 0.0], [3.0, 4.0], [0.6, 0.8]])
    np.testing.assert_array_equal(saturate(u, None), u)
    np.testing.assert_allclose(saturate(u, 1.0), [[0.0, 0.0], [0.6, 0.8], [0.6, 0.8]])


def test_count_saturated_counts_the_drones_whose_command_changed():
    u = np.array([[0.0, 0.0], [3.0, 4.0], [0.6, 0.8], [0.0, -2.0]])
    assert count_saturated(u, saturate(u, 1.0)) == 2
    assert count_saturated(u, saturate(u, None)) == 0


@pytest.mark.parametrize("v_max", [1.0, 10.0, 100.0])
def test_saturating_a_drone_at_rest_is_silent(v_max):
    """A zero command (a drone at its goal) is common: it must not raise numpy warnings."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(saturate(np.zeros((2, 3)), v_max), 0.0)


def test_go_to_goal_closed_form_solves_the_ode():
    p0, goal, k = np.array([1.0, -2.0, 3.0]), np.array([4.0, 0.0, -1.0]), 1.3
    t = np.linspace(0.0, 5.0, 11)
    p = go_to_goal_closed_form(p0, goal, k, t)
    np.testing.assert_allclose(p[0], p0)
    h = 1e-6
    dp = (go_to_goal_closed_form(p0, goal, k, t + h) - go_to_goal_closed_form(p0, goal, k, t - h)) / (2 * h)
    np.testing.assert_allclose(dp, k * (goal - p), atol=1e-8)  # eq. 1 + eq. 4
    err = np.linalg.norm(goal - p, axis=1)
    np.testing.assert_allclose(err, np.linalg.norm(goal - p0) * np.exp(-k * t), rtol=1e-12)


def test_go_to_goal_discrete_iterates_the_zero_order_hold():
    p0, goal, k, dt = np.array([1.0, 2.0]), np.array([-3.0, 0.5]), 2.0, 0.1
    p, expected = p0.copy(), [p0.copy()]
    for _ in range(30):
        p = p + dt * k * (goal - p)
        expected.append(p)
    np.testing.assert_allclose(go_to_goal_discrete(p0, goal, k, dt, 30), expected, atol=1e-12)
    np.testing.assert_allclose(go_to_goal_discrete(p0, goal, 2.0, 0.5, 3)[1:], [goal] * 3)


def test_tracking_command_is_eq_14():
    p, target, ff = np.array([[0.0, 0.0]]), np.array([[1.0, 2.0]]), np.array([[0.5, -0.5]])
    np.testing.assert_allclose(tracking_command(p, target, ff, 2.0), [[2.5, 3.5]])


def test_check_gain_dt_accepts_up_to_one():
    assert check_gain_dt(2.0, 0.5) == 1.0
    assert check_gain_dt(1.0, 0.02) == pytest.approx(0.02)


@pytest.mark.parametrize(
    ("gain", "dt", "match"),
    [
        (2.1, 0.5, "controller.gain"),  # k dt > 1: overshoot
        (50.0, 0.1, "controller.gain"),  # k dt = 5: divergence
        (0.0, 0.1, "controller.gain"),
        (-1.0, 0.1, "controller.gain"),
        (np.nan, 0.1, "controller.gain"),
        (1.0, 0.0, "simulation.dt"),
        (1.0, -0.1, "simulation.dt"),
    ],
)
def test_check_gain_dt_rejects_k_dt_outside_0_1(gain, dt, match):
    with pytest.raises(ValidationError, match=match):
        check_gain_dt(gain, dt)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: go_to_goal_closed_form([0.0, 0.0], [1.0, 1.0, 1.0], 1.0, 0.0), "goal"),
        (lambda: go_to_goal_closed_form([0.0, np.nan], [1.0, 1.0], 1.0, 0.0), "p0"),
        (lambda: go_to_goal_closed_form([0.0, 0.0], [1.0, 1.0], 0.0, 0.0), "gain"),
        (lambda: go_to_goal_discrete([0.0, 0.0], [1.0, 1.0], 3.0, 0.5, 4), "controller.gain"),
    ],
)
def test_go_to_goal_rejects_bad_input(call, match):
    with pytest.raises(ValidationError, match=match):
        call()

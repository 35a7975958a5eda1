"""Piecewise degree-7 polynomials: exact on polynomials, continuous up to the jerk, fewest pieces."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mpcform.errors import ValidationError
from mpcform.outputs.flight.polynomial import (
    CONTINUITY,
    PiecewisePolynomial,
    fit_piecewise_polynomial,
    fit_positions,
    max_speed,
)


@given(st.lists(st.floats(-3.0, 3.0), min_size=8, max_size=8), st.floats(0.5, 5.0))
def test_one_piece_reproduces_a_degree_7_polynomial(coef: list[float], span: float) -> None:
    t = np.linspace(0.0, span, 60)
    y = np.polynomial.polynomial.polyval(t / span, coef)
    poly = fit_piecewise_polynomial(t, y[:, None], 1)
    assert np.allclose(poly.evaluate(t)[:, 0], y, atol=1e-6 * (1 + np.abs(coef).sum()))


@given(st.integers(2, 12), st.integers(0, 2**32 - 1))
def test_pieces_join_up_to_the_jerk(pieces: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 10.0, 201)
    y = np.cumsum(rng.normal(0.0, 0.1, (201, 2)), axis=0)  # a rough path
    poly = fit_piecewise_polynomial(t, y, pieces)
    joints = poly.breaks_s[1:-1]
    for derivative in range(CONTINUITY):
        before = poly.evaluate(joints - 1e-9, derivative)
        after = poly.evaluate(joints + 1e-9, derivative)
        scale = 1.0 + np.abs(before).max()
        assert np.allclose(before, after, atol=1e-5 * scale)


def test_fit_stops_at_eight_samples_per_piece() -> None:
    t = np.linspace(0.0, 1.0, 41)
    p = np.zeros((41, 1, 2))
    p[::2, 0, 0] = 1.0  # a zigzag no smooth curve follows
    fit = fit_positions(t, p, tolerance_m=1e-6)
    assert not fit.within_tolerance and fit.polynomial.pieces == 5


def test_fewest_pieces_within_tolerance() -> None:
    t = np.linspace(0.0, 8.0, 161)
    p = np.stack([np.sin(t), np.cos(2.0 * t)], axis=-1)[:, None, :]  # one drone, planar
    fit = fit_positions(t, p, tolerance_m=1e-5)
    assert fit.within_tolerance and fit.max_error_m <= 1e-5
    assert fit.polynomial.pieces > 4  # more than the 2 s pieces tried first: the count was searched
    fewer = fit_piecewise_polynomial(t, p.reshape(161, -1), fit.polynomial.pieces - 1)
    err = fewer.as_float32().evaluate(t).reshape(p.shape) - p
    assert np.linalg.norm(err, axis=-1).max() > 1e-5  # one piece less misses the tolerance


def test_evaluation_clamps_to_the_span_and_speed_is_sampled() -> None:
    # x = t, y = 0 over two pieces of 1 s from t0 = 2 s: speed 1 m/s everywhere
    coef = np.zeros((2, 2, 8))
    coef[0, 0, :2] = [0.0, 1.0]
    coef[1, 0, :2] = [1.0, 1.0]
    poly = PiecewisePolynomial(2.0, np.array([1.0, 1.0]), coef)
    assert np.allclose(poly.breaks_s, [2.0, 3.0, 4.0])
    assert np.allclose(poly.evaluate([1.0, 2.5, 3.5, 9.0])[:, 0], [0.0, 0.5, 1.5, 2.0])
    assert max_speed(poly, 1) == pytest.approx(1.0)


def test_rest_ends_start_and_stop_at_rest_exactly() -> None:
    t = np.linspace(0.0, 6.0, 301)
    y = np.stack([np.sin(t), t**2], axis=-1)
    poly = fit_piecewise_polynomial(t, y, 5, rest_ends=True)
    for end, value in ((t[0], y[0]), (t[-1], y[-1])):
        assert np.allclose(poly.evaluate(end)[0], value, atol=1e-12)
        assert np.abs(poly.evaluate(end, 1)).max() < 1e-9 and np.abs(poly.evaluate(end, 2)).max() < 1e-9
        assert np.abs(poly.evaluate(end, 3)).max() < 1e-8  # no jerk step from (or into) hover


def test_pinned_ends_pass_through_the_end_samples_and_barely_move_the_fit() -> None:
    t = np.linspace(0.0, 6.0, 301)
    y = np.stack([np.sin(3.0 * t), t**2], axis=-1)
    free, pinned = (fit_piecewise_polynomial(t, y, 5, pinned_ends=p) for p in (False, True))
    assert np.abs(free.evaluate(t[[0, -1]]) - y[[0, -1]]).max() > 1e-5  # the least squares miss them
    np.testing.assert_allclose(pinned.evaluate(t[[0, -1]]), y[[0, -1]], atol=1e-12)
    inner = slice(30, -30)
    assert np.abs(pinned.evaluate(t[inner]) - free.evaluate(t[inner])).max() < 1e-3


def test_same_as_scipy_lsq_spline() -> None:
    from scipy.interpolate import make_lsq_spline

    from mpcform.outputs.flight.polynomial import knots

    t = np.linspace(0.0, 5.0, 101)
    y = np.cos(1.3 * t)
    spline = make_lsq_spline(t, y, knots(0.0, 5.0, 3), k=7)
    poly = fit_piecewise_polynomial(t, y[:, None], 3)
    assert poly.pieces == 3 and np.allclose(poly.evaluate(t)[:, 0], spline(t), atol=1e-9)


def test_bad_piece_counts_are_rejected() -> None:
    with pytest.raises(ValidationError, match="pieces"):
        fit_piecewise_polynomial(np.arange(3.0), np.zeros((3, 1)), 0)

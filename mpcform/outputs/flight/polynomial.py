"""Piecewise polynomials of degree 7 fitted to sampled positions (for Crazyswarm trajectories).

The fit is scipy's B-spline least squares (:func:`scipy.interpolate.make_lsq_spline`, degree 7)
on uniform breakpoints, each interior knot repeated 4 times so that position, velocity,
acceleration and jerk stay continuous (a knot of multiplicity m leaves a degree-k spline
C^(k-m) there), then converted to per-piece power series with :class:`scipy.interpolate.PPoly`.
:func:`fit_positions` takes the fewest pieces that reproduce every sample within a tolerance
when the coefficients are stored as float32 (as the Crazyflie stores them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import BSpline, PPoly, make_lsq_spline

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError

POLY_DEGREE = 7
CONTINUITY = 4  # position, velocity, acceleration and jerk are continuous at breakpoints
KNOT_MULTIPLICITY = POLY_DEGREE + 1 - CONTINUITY  # 4: C^3 at every interior knot
DEFAULT_TOLERANCE_M = 0.02
MIN_SAMPLES_PER_PIECE = 8
PIN_WEIGHT = 1e3  # least-squares weight of a pinned end sample (the rest weigh 1)
MAX_PIECE_S = 2.0  # longest piece tried first [s] (keeps float32 powers of tau modest)


@dataclass(frozen=True, eq=False)
class PiecewisePolynomial:
    """Polynomial pieces of degree 7 over consecutive intervals starting at ``t0_s``.

    ``coefficients`` (K, m, 8): for piece k and series m, ascending powers of the local time
    ``tau = t - start_k`` [s], ``0 <= tau <= durations_s[k]``.
    """

    t0_s: float
    durations_s: Array  # (K,)
    coefficients: Array  # (K, m, 8)

    @property
    def pieces(self) -> int:
        return int(self.durations_s.shape[0])

    @property
    def breaks_s(self) -> Array:
        """Start of every piece and the end of the last one, (K + 1,) [s]."""
        return self.t0_s + np.concatenate([[0.0], np.cumsum(self.durations_s)])

    @property
    def duration_s(self) -> float:
        return float(self.durations_s.sum())

    def evaluate(self, t_s: ArrayLike, derivative: int = 0) -> Array:
        """Values (T, m) of the series (or their ``derivative``) at ``t_s`` (T,); clamped to the span."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        breaks = self.breaks_s
        k = np.clip(np.searchsorted(breaks, t, side="right") - 1, 0, self.pieces - 1)
        tau = np.clip(t - breaks[k], 0.0, self.durations_s[k])
        coef = self.coefficients[k]  # (T, m, 8)
        for _ in range(derivative):
            coef = coef[..., 1:] * np.arange(1, coef.shape[-1])
        powers = tau[:, None] ** np.arange(coef.shape[-1])
        return np.einsum("tmc,tc->tm", coef, powers)

    def as_float32(self) -> PiecewisePolynomial:
        """The pieces with durations and coefficients rounded to float32 (Crazyflie storage)."""
        return PiecewisePolynomial(
            self.t0_s,
            self.durations_s.astype(np.float32).astype(float),
            self.coefficients.astype(np.float32).astype(float),
        )


def knots(t0_s: float, t1_s: float, pieces: int) -> Array:
    """Knot vector of a degree-7 spline with ``pieces`` uniform pieces, continuous up to the jerk."""
    inner = np.linspace(t0_s, t1_s, pieces + 1)[1:-1]
    return np.concatenate(
        [[t0_s] * (POLY_DEGREE + 1), np.repeat(inner, KNOT_MULTIPLICITY), [t1_s] * (POLY_DEGREE + 1)]
    )


def fit_piecewise_polynomial(
    t_s: Array, values: Array, pieces: int, rest_ends: bool = False, pinned_ends: bool = False
) -> PiecewisePolynomial:
    """Least-squares fit of ``values`` (T, m) at ``t_s`` (T,) by ``pieces`` uniform degree-7 pieces.

    ``rest_ends``: the fit starts and ends exactly at the first and last value with zero
    velocity, acceleration and jerk, so a drone leaves hover without a jerk step (the first and
    last four B-spline coefficients are set to the end values: a clamped spline's value and first
    three derivatives at an end depend on those only). ``pinned_ends``: it passes exactly through
    the first and last value (those samples weighted :data:`PIN_WEIGHT` times, then the end
    coefficients set to them: a clamped spline's end value is its end coefficient).
    """
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(values, dtype=float).reshape(t.shape[0], -1)
    if pieces < 1 or t.shape[0] < 2:
        raise ValidationError("pieces", f"expected >= 1 piece and >= 2 samples, got {pieces}, {t.shape[0]}")
    try:
        w = np.ones(t.shape[0])
        if pinned_ends:
            w[[0, -1]] = PIN_WEIGHT
        spline = make_lsq_spline(t, y, knots(float(t[0]), float(t[-1]), pieces), k=POLY_DEGREE, w=w)
    except (ValueError, np.linalg.LinAlgError) as exc:  # too few samples for the pieces
        raise ValidationError(
            "pieces", f"{pieces} pieces cannot be fitted to {t.shape[0]} samples: {exc}"
        ) from exc
    c = spline.c.copy()
    if rest_ends:
        c[:4], c[-4:] = y[0], y[-1]
    elif pinned_ends:
        c[0], c[-1] = y[0], y[-1]
    return from_spline(BSpline(spline.t, c, POLY_DEGREE))


def from_spline(spline: BSpline) -> PiecewisePolynomial:
    """The non-empty pieces of a B-spline with coefficients (C, m) as ascending power series in
    the local time (:meth:`PPoly.from_spline` converts one series at a time)."""
    series = [
        PPoly.from_spline(BSpline(spline.t, spline.c[:, j], spline.k)) for j in range(spline.c.shape[1])
    ]
    widths = np.diff(series[0].x)
    keep = widths > 0  # repeated knots give empty intervals
    coef = np.stack([pp.c[:, keep] for pp in series], axis=-1)  # (8, K, m), descending powers
    return PiecewisePolynomial(
        float(series[0].x[0]), widths[keep], np.ascontiguousarray(coef[::-1].transpose(1, 2, 0))
    )


@dataclass(frozen=True)
class PolynomialFit:
    """Pieces for all drones (series ``drone * d + axis``) and the worst position error [m]."""

    polynomial: PiecewisePolynomial
    max_error_m: float
    tolerance_m: float

    @property
    def within_tolerance(self) -> bool:
        return self.max_error_m <= self.tolerance_m


def fit_positions(
    t_s: Array,
    positions_m: Array,
    tolerance_m: float = DEFAULT_TOLERANCE_M,
    max_piece_s: float = MAX_PIECE_S,
    rest_ends: bool = False,
    pinned_ends: bool = False,
) -> PolynomialFit:
    """Fewest uniform pieces, none longer than ``max_piece_s``, that reproduce every drone's sampled
    positions (T, n, d) within ``tolerance_m`` with float32 coefficients.

    The count grows by half until the fit is within tolerance, then is bisected down. It stops
    at 8 samples per piece (two per added B-spline coefficient: fewer leave the least squares
    ill-posed); the result then says it is not within tolerance.
    """
    tol = positive("tolerance", tolerance_m)
    t = np.asarray(t_s, dtype=float)
    p = np.asarray(positions_m, dtype=float)
    flat = p.reshape(p.shape[0], -1)

    def attempt(pieces: int) -> PolynomialFit:
        poly = fit_piecewise_polynomial(t, flat, pieces, rest_ends, pinned_ends)
        err = poly.as_float32().evaluate(t).reshape(p.shape) - p
        return PolynomialFit(poly, float(np.linalg.norm(err, axis=-1).max()), tol)

    cap = max(1, (t.shape[0] - 1) // MIN_SAMPLES_PER_PIECE)
    span = float(t[-1] - t[0])
    pieces = min(cap, max(1, math.ceil(span / positive("max_piece", max_piece_s) - 1e-9)))
    failed = pieces - 1  # the largest count known (or taken) to fail
    fit = attempt(pieces)
    while not fit.within_tolerance and pieces < cap:
        failed, pieces = pieces, min(cap, max(pieces + 1, math.ceil(1.5 * pieces)))
        fit = attempt(pieces)
    while fit.within_tolerance and pieces - failed > 1:
        mid = (failed + pieces) // 2
        trial = attempt(mid)
        if trial.within_tolerance:
            pieces, fit = mid, trial
        else:
            failed = mid
    return fit


def max_speed(poly: PiecewisePolynomial, n: int, per_piece: int = 50) -> float:
    """Largest speed [m/s] of ``n`` drones' pieces (series drone * d + axis), sampled finely."""
    t = np.linspace(poly.breaks_s[0], poly.breaks_s[-1], per_piece * poly.pieces + 1)
    vel = poly.evaluate(t, derivative=1).reshape(t.shape[0], n, -1)
    return float(np.linalg.norm(vel, axis=-1).max())

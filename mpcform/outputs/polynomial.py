"""Piecewise polynomials of degree 7 fitted to sampled positions (for Crazyswarm trajectories).

The pieces share uniform breakpoints, are continuous up to the jerk, and are fitted by least
squares; :func:`fit_positions` takes the fewest pieces that reproduce every sample within a
tolerance when the coefficients are stored as float32 (as the Crazyflie stores them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from math import factorial

import numpy as np

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError

POLY_DEGREE = 7
CONTINUITY = 4  # position, velocity, acceleration and jerk are continuous at breakpoints
DEFAULT_TOLERANCE_M = 0.02
MAX_PIECE_S = 2.0  # longest piece tried first [s] (keeps float32 powers of tau modest)
SMOOTHING = 1e-9  # relative weight of the snap integral (regularises pieces with few samples)


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

    def evaluate(self, t_s: object, derivative: int = 0) -> Array:
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


def fit_piecewise_polynomial(t_s: Array, values: Array, pieces: int) -> PiecewisePolynomial:
    """Least-squares fit of ``values`` (T, m) at ``t_s`` (T,) by ``pieces`` uniform degree-7 pieces.

    Continuity of the value and its first three derivatives is imposed at every breakpoint
    (equality constraints, solved with the KKT system); a tiny snap penalty keeps pieces with
    few samples well posed. All m series share the breakpoints and one factorisation.
    """
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(values, dtype=float).reshape(t.shape[0], -1)
    if pieces < 1 or t.shape[0] < 2:
        raise ValidationError("pieces", f"expected >= 1 piece and >= 2 samples, got {pieces}, {t.shape[0]}")
    span = float(t[-1] - t[0])
    h = span / pieces
    nc = POLY_DEGREE + 1
    k = np.minimum(((t - t[0]) / h).astype(int), pieces - 1)
    sigma = (t - t[0]) / h - k  # normalised local time in [0, 1]
    vander = sigma[:, None] ** np.arange(nc)
    size = pieces * nc
    gram = np.zeros((size, size))
    rhs = np.zeros((size, y.shape[1]))
    snap = _snap_gram()
    for piece in range(pieces):
        rows = k == piece
        sl = slice(piece * nc, (piece + 1) * nc)
        v = vander[rows]
        gram[sl, sl] = v.T @ v + SMOOTHING * max(1, int(rows.sum())) * snap
        rhs[sl] = v.T @ y[rows]
    constraints = np.zeros(((pieces - 1) * CONTINUITY, size))
    end_row = np.array([[_falling(m, r) for m in range(nc)] for r in range(CONTINUITY)])
    start_row = np.array([[factorial(r) if m == r else 0.0 for m in range(nc)] for r in range(CONTINUITY)])
    for b in range(pieces - 1):
        rows_b = slice(b * CONTINUITY, (b + 1) * CONTINUITY)
        constraints[rows_b, b * nc : (b + 1) * nc] = end_row
        constraints[rows_b, (b + 1) * nc : (b + 2) * nc] = -start_row
    kkt = np.block([[gram, constraints.T], [constraints, np.zeros((constraints.shape[0],) * 2)]])
    full_rhs = np.vstack([rhs, np.zeros((constraints.shape[0], y.shape[1]))])
    try:
        sol = np.linalg.solve(kkt, full_rhs)
    except np.linalg.LinAlgError:
        sol = np.linalg.lstsq(kkt, full_rhs, rcond=None)[0]
    normalised = sol[:size].reshape(pieces, nc, -1).transpose(0, 2, 1)  # (K, m, 8) in sigma
    coefficients = normalised / h ** np.arange(nc)  # powers of tau = h sigma
    return PiecewisePolynomial(float(t[0]), np.full(pieces, h), coefficients)


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
    t_s: Array, positions_m: Array, tolerance_m: float = DEFAULT_TOLERANCE_M, max_piece_s: float = MAX_PIECE_S
) -> PolynomialFit:
    """Fewest uniform pieces, none longer than ``max_piece_s``, that reproduce every drone's sampled
    positions (T, n, d) within ``tolerance_m`` with float32 coefficients.

    The count grows by half until the fit is within tolerance, then is bisected down. It stops
    at two samples per piece; the result then says it is not within tolerance.
    """
    tol = positive("tolerance", tolerance_m)
    t = np.asarray(t_s, dtype=float)
    p = np.asarray(positions_m, dtype=float)
    flat = p.reshape(p.shape[0], -1)

    def attempt(pieces: int) -> PolynomialFit:
        poly = fit_piecewise_polynomial(t, flat, pieces)
        err = poly.as_float32().evaluate(t).reshape(p.shape) - p
        return PolynomialFit(poly, float(np.linalg.norm(err, axis=-1).max()), tol)

    cap = max(1, (t.shape[0] - 1) // 2)
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


def _falling(m: int, r: int) -> float:
    """r-th derivative of sigma^m at sigma = 1: m! / (m - r)! (0 when r > m)."""
    return float(factorial(m) // factorial(m - r)) if r <= m else 0.0


def _snap_gram() -> Array:
    """Integral over [0, 1] of the products of the 4th derivatives of sigma^m and sigma^l (max 1)."""
    nc = POLY_DEGREE + 1
    gram = np.zeros((nc, nc))
    for m in range(4, nc):
        for ell in range(4, nc):
            gram[m, ell] = _falling(m, 4) * _falling(ell, 4) / (m + ell - 7)
    return gram / gram.max()

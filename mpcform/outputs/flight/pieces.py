"""One phase of an exported flight as flyable pieces: retimed from rest to rest, fitted, float32.

A phase's planned samples (the ascent's, the mission's or the descent's,
:mod:`mpcform.outputs.flight.phases`), up to where every drone has settled at its end, are joined
by a cubic spline (at rest at both ends), fitted by degree-7 pieces within half the tolerance,
retimed time-optimally within the speed, acceleration and jerk limits from rest to rest
(:mod:`mpcform.outputs.flight.retime`), fitted again at the new times with the yaw (retimed with
the limits lowered where the fit exceeds one, then slowed down; retimed with a lower jerk limit
where it needs more pieces than a Crazyflie holds), and rounded to float32 as the Crazyflie stores
them. Every phase ends at rest, so the phases join into one flight (:func:`join`) whose
derivatives are continuous.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import make_interp_spline
from scipy.ndimage import maximum_filter1d

from mpcform._validate import Array
from mpcform.errors import MPCFormError, ValidationError
from mpcform.outputs.flight.limits import FlightLimits, flat_state
from mpcform.outputs.flight.polynomial import (
    MIN_SAMPLES_PER_PIECE,
    PiecewisePolynomial,
    PolynomialFit,
    fit_piecewise_polynomial,
    fit_positions,
)
from mpcform.outputs.flight.retime import Retiming, minimum_time_s, retime

DEFAULT_RATE_HZ = 100.0
PATH_SAMPLES = 10  # per planned interval: the path is fitted to the planned positions joined by lines
FIT_RATE_HZ = 50.0  # samples of the retimed reference per second, besides the planned samples
CHECK_RATE_HZ = 500.0  # sampling of the pieces for limits, floor and separation
CRAZYFLIE_MAX_PIECES = 31
"""Pieces a Crazyflie holds (``TRAJECTORY_MEMORY_SIZE`` 4096 B / 132 B per piece in crazyflie-firmware)."""
SMOOTHER = (0.5, 0.25)
"""A phase whose fit takes more pieces than a Crazyflie holds (but at most twice as many) is
retimed with the jerk limit at these shares in turn (checked against the whole limit): the
time-optimal scaling switches its acceleration abruptly, and a smoother one fits in fewer pieces.
The smoother one is kept only when it fits."""
SETTLED_SHARE = 0.25
"""A phase's last samples, once every drone is within this share of the tolerance of its end, are
flown as its end (each within 5 mm at the default 2 cm)."""
LIMIT_SLACK = 0.95  # the retiming aims at this share of each limit (the fit adds a little)
REFITS = 7
"""A fit within the tolerance can add acceleration and jerk: where the pieces exceed a limit by a
factor, the flight is slowed down by that factor's root (speed 1, acceleration 2, jerk 3) and
fitted again, this many times at most; then the export names the limit. The first
:data:`LOCAL_REFITS` times the path is retimed with its limits lowered only within
:data:`LOCAL_WINDOW_S` of where they were exceeded, the later ones slow the whole flight down."""
LOCAL_REFITS = 6
LOCAL_WINDOW_S = 0.25  # of the flight, either side of an excess
MAX_SAMPLES = 7e6
"""The most samples x drones an export takes (checks at 500 Hz and setpoints at ``rate_hz``): each
took about 560 bytes and 34 us (setpoint CSVs written), so about 4 GiB and 4 minutes."""


@dataclass(frozen=True, eq=False)
class PhasePieces:
    """A phase ``name``: its planned samples (T, n, 3) [m] and the lines joining them
    (``dense_t_s`` (D,), ``dense_m`` (D, n, 3)), its retiming, the fit (error against the planned
    samples at ``t_planned_s``, their retimed times), the float32 pieces ``flown`` (series
    drone * 4 + x, y, z, yaw) and ``min_time_s``, a lower bound on the shortest flight along
    the same path within the limits (:func:`mpcform.outputs.flight.retime.minimum_time_s`)."""

    name: str
    planned_m: Array
    dense_t_s: Array
    dense_m: Array
    timing: Retiming
    fit: PolynomialFit
    flown: PiecewisePolynomial
    t_planned_s: Array
    min_time_s: float


def phase_pieces(
    name: str,
    planned_m: Array,
    dt_s: float,
    yaw_rad: Array,
    limits: FlightLimits,
    tolerance_m: float,
    max_piece_s: float,
    rate_hz: float,
) -> PhasePieces:
    """The pieces of one phase (module docstring): ``planned_m`` (T, n, 3) every ``dt_s``, the
    yaw (T,) [rad] at its samples."""
    n = planned_m.shape[1]
    t = dt_s * np.arange(planned_m.shape[0])
    half = 0.5 * tolerance_m
    # the plan's settling (every drone within SETTLED_SHARE of the tolerance of its end) is left
    # out: its fit's wiggles would cap the scaling's speed where the drones barely move
    moving = np.flatnonzero(
        np.linalg.norm(planned_m - planned_m[-1], axis=-1).max(axis=1) > SETTLED_SHARE * tolerance_m
    )
    cut = min(t.shape[0], (moving[-1] + 2) if moving.size else 2)
    kept = np.concatenate([planned_m[: cut - 1], planned_m[-1:]])
    dense = np.linspace(0.0, t[cut - 1], PATH_SAMPLES * (cut - 1) + 1)  # held commands: lines
    lines = np.stack([np.interp(dense, t[:cut], x) for x in kept.reshape(cut, -1).T], axis=-1)
    lines = lines.reshape(dense.shape[0], n, 3)
    # through the phase's first and last sample exactly: the phases join there
    path = fit_positions(
        dense, _through(t[:cut], kept, dense), half, max_piece_s, pinned_ends=True
    ).polynomial
    timing, poly, flown = _timed(path, t, yaw_rad, limits, half, max_piece_s, n, rate_hz)
    if CRAZYFLIE_MAX_PIECES < flown.pieces <= 2 * CRAZYFLIE_MAX_PIECES:
        for share in SMOOTHER:
            try:
                smoother = _timed(path, t, yaw_rad, limits, half, max_piece_s, n, rate_hz, share)
            except MPCFormError:  # e.g. a flight too long to sample: the faster one stays
                continue
            if smoother[2].pieces <= CRAZYFLIE_MAX_PIECES:  # else the faster one, split into files
                timing, poly, flown = smoother
                break
    check_samples(timing.duration_s, n, rate_hz)
    t_planned = timing.new_time(t)
    err = flown.evaluate(t_planned).reshape(t.shape[0], n, 4)[..., :3] - planned_m
    fit = PolynomialFit(poly, float(np.linalg.norm(err, axis=-1).max()), tolerance_m)
    min_time = minimum_time_s(path, limits.max_speed_mps, limits.max_acc_mps2, limits.max_jerk_mps3)
    return PhasePieces(name, planned_m, dense, lines, timing, fit, flown, t_planned, min_time)


def _through(t_s: Array, samples_m: Array, dense_t_s: Array) -> Array:
    """The cubic spline through ``samples_m`` (T, n, 3) at ``t_s`` (T >= 2), at rest at both ends,
    at ``dense_t_s``: continuous up to the acceleration, so the path keeps no kink of the held
    commands that a tight tolerance would make the flight follow (the lines between the samples
    are off it by about ``a_max dt^2 / 8`` at most, 2 mm at dt 0.1 s)."""
    return make_interp_spline(t_s, samples_m, k=3, bc_type="clamped")(dense_t_s)


def _timed(
    path: PiecewisePolynomial,
    t: Array,
    yaw_rad: Array,
    limits: FlightLimits,
    half: float,
    max_piece_s: float,
    n: int,
    rate_hz: float,
    jerk_share: float = 1.0,
) -> tuple[Retiming, PiecewisePolynomial, PiecewisePolynomial]:
    """``path`` retimed within ``limits`` (its jerk at ``jerk_share`` of the limit:
    :data:`SMOOTHER`) and fitted; a fit that exceeds a limit is retimed with lower limits where it
    does, or slowed down, and fitted again (:data:`REFITS`), the last one returned as it is."""
    aims = (
        LIMIT_SLACK * limits.max_speed_mps,
        LIMIT_SLACK * limits.max_acc_mps2,
        LIMIT_SLACK * jerk_share * limits.max_jerk_mps3,
    )
    longest = MAX_SAMPLES / (n * (CHECK_RATE_HZ + DEFAULT_RATE_HZ))
    timing = retime(path, *aims, max_duration_s=longest)
    for refit in range(REFITS + 1):
        check_samples(timing.duration_s, n, rate_hz)
        poly, flown = _fit_pieces(timing, t, yaw_rad, half, max_piece_s, n)
        check = np.linspace(0.0, flown.duration_s, int(np.ceil(CHECK_RATE_HZ * flown.duration_s)) + 1)
        state = flat_state(flown, check, n)
        slower = np.max(
            [
                (np.linalg.norm(state[key], axis=-1).max(axis=1) / limit) ** (1.0 / order)
                for key, limit, order in (
                    ("vel", limits.max_speed_mps, 1),
                    ("acc", limits.max_acc_mps2, 2),
                    ("jerk", limits.max_jerk_mps3, 3),
                )
            ],
            axis=0,
        )
        if slower.max() <= 1.0 or refit == REFITS:
            break
        if refit < LOCAL_REFITS:
            wide = maximum_filter1d(slower, 2 * round(LOCAL_WINDOW_S * CHECK_RATE_HZ) + 1)
            local = timing.slower_where(check, np.where(wide > 1.0, 1.02 * wide, 1.0))
            timing = retime(path, *aims, max_duration_s=longest, slower=local)
        else:
            timing = timing.slowed(1.02 * slower.max())
    return timing, poly, flown


def _fit_pieces(
    timing: Retiming, t_s: Array, yaw_rad: Array, half_tolerance_m: float, max_piece_s: float, n: int
) -> tuple[PiecewisePolynomial, PiecewisePolynomial]:
    """The fit of the retimed positions and the float32 pieces of the positions and the yaw
    (planned at ``t_s``)."""
    t_planned = timing.new_time(t_s)
    samples = max(
        int(np.ceil(FIT_RATE_HZ * timing.duration_s)) + 1, 2 * MIN_SAMPLES_PER_PIECE
    )  # a short phase too
    grid = np.linspace(0.0, timing.duration_s, samples)
    t_fit = np.unique(np.concatenate([grid, t_planned]))
    poly = fit_positions(
        t_fit, timing.positions(t_fit), half_tolerance_m, max_piece_s, rest_ends=True
    ).polynomial
    yaw_poly = fit_piecewise_polynomial(
        t_fit, np.interp(t_fit, t_planned, yaw_rad)[:, None], poly.pieces, rest_ends=True
    )
    coef = np.concatenate(
        [
            poly.coefficients.reshape(poly.pieces, n, 3, -1),
            np.repeat(yaw_poly.coefficients[:, None], n, axis=1),
        ],
        axis=2,
    )
    flown = PiecewisePolynomial(0.0, poly.durations_s, coef.reshape(poly.pieces, n * 4, -1))
    return poly, flown.as_float32()


def join(parts: list[PhasePieces]) -> PiecewisePolynomial:
    """The phases' pieces one after the other, from t = 0 (each ends at rest, where the next
    starts)."""
    return PiecewisePolynomial(
        0.0,
        np.concatenate([p.flown.durations_s for p in parts]),
        np.concatenate([p.flown.coefficients for p in parts]),
    )


def check_samples(duration_s: float, n: int, rate_hz: float) -> None:
    """Refuse, naming ``rate``, an export of more than :data:`MAX_SAMPLES` samples x drones."""
    samples = duration_s * (CHECK_RATE_HZ + rate_hz) * n
    if samples > MAX_SAMPLES:
        raise ValidationError(
            "rate",
            f"the export would take {samples:.3g} samples x drones ({duration_s:.3g} s x ({rate_hz:g} Hz of "
            f"setpoints + {CHECK_RATE_HZ:g} Hz of checks) x {n:,} drones), above the limit of "
            f"{MAX_SAMPLES:.3g} (about 4 GiB): lower it",
        )

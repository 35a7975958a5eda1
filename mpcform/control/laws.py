"""The seed's closed-form control laws: go-to-goal (eq. 4-5), saturation (eq. 7), tracking (eq. 14)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError


def go_to_goal_closed_form(p0_m: ArrayLike, goal_m: ArrayLike, gain_per_s: float, t_s: ArrayLike) -> Array:
    """Eq. 5: ``p(t) = p* + (p(0) - p*) e^{-k t}``; returns (T, d) for times ``t_s`` (T,)."""
    p0 = finite_array("p0", p0_m, (None,))
    goal = finite_array("goal", goal_m, p0.shape)
    k = positive("gain", gain_per_s)
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    return goal + np.outer(np.exp(-k * t), p0 - goal)


def go_to_goal_discrete(
    p0_m: ArrayLike, goal_m: ArrayLike, gain_per_s: float, dt_s: float, steps: int
) -> Array:
    """Eq. 4 under zero-order hold: ``p_j = p* + (1 - k dt)^j (p0 - p*)``; (steps + 1, d)."""
    p0 = finite_array("p0", p0_m, (None,))
    goal = finite_array("goal", goal_m, p0.shape)
    factor = 1.0 - check_gain_dt(gain_per_s, dt_s)
    return goal + np.outer(factor ** np.arange(steps + 1), p0 - goal)


def check_gain_dt(gain_per_s: float, dt_s: float, field: str = "controller.gain") -> float:
    """Validate ``0 < k dt <= 1`` (monotone discrete decay) and return ``k dt``."""
    k, dt = positive(field, gain_per_s), positive("simulation.dt", dt_s)
    if k * dt > 1.0:
        raise ValidationError(
            field,
            f"gain * dt = {k:g} * {dt:g} = {k * dt:g} must lie in (0, 1]: the discrete error "
            f"factor (1 - k dt) would be {1 - k * dt:g} (overshoot or divergence); "
            f"lower the gain to at most {1 / dt:g} or the step",
        )
    return k * dt


def saturate(u_mps: Array, v_max_mps: float | None) -> Array:
    """Eq. 7 row-wise: scale each drone's command (n, d) into the ball of radius ``v_max``.

    This is the Euclidean projection onto the ball, so it preserves direction.
    """
    if v_max_mps is None:
        return u_mps
    norms = np.linalg.norm(u_mps, axis=-1, keepdims=True)
    factor = np.divide(v_max_mps, norms, out=np.ones_like(norms), where=norms > v_max_mps)
    return u_mps * factor


def count_saturated(raw_mps: Array, command_mps: Array) -> int:
    """How many drones' commands (rows) saturation changed."""
    return int(np.any(raw_mps != command_mps, axis=-1).sum())


def tracking_command(positions_m: Array, target_m: Array, feedforward_mps: Array, gain_per_s: float) -> Array:
    """Eq. 14: ``u_i = feedforward_i + k (p*_i - p_i)`` for all drones, (n, d)."""
    return feedforward_mps + gain_per_s * (target_m - positions_m)

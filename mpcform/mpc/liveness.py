"""Liveness: the tie-break that keeps symmetric encounters from deadlocking.

When the eq. 14 rollout breaks a separation row, the wishes (targets ``c``) of the drones
involved are turned to the right about the world z axis, so antipodal swaps circulate instead of
meeting head-on. A drone that stays stalled in conflict (its last command below
:data:`STALL_FRACTION` of its wish) turns further each step, by :data:`STALL_GROWTH` of the
base angle, up to a quarter turn: a symmetric ring that the first angle holds in balance
(16 drones swapping in decoupled mode) is broken within a few steps.
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array

STALL_FRACTION = 0.02  # a conflicted drone whose last command is below this fraction of its wish is stalled
STALL_GROWTH = 0.1  # the tie-break angle grows by this fraction of itself per stalled step


class TieBreak:
    """The turn of each conflicted drone's wish, and how long each drone has been stalled."""

    def __init__(self, n: int, angle_rad: float) -> None:
        self.angle_rad = angle_rad  # base angle (0 disables)
        self.stalled = np.zeros(n, dtype=int)  # steps in a row each drone was stalled in conflict

    def clear(self) -> None:
        """No drone is stalled (a step without conflict, or a new run)."""
        self.stalled[:] = 0

    def turn(self, c: Array, conflicted: Array, u_prev: Array, started: bool) -> Array:
        """Targets ``c`` (H, n, d) with the ``conflicted`` (n,) drones' turned to the right;
        ``u_prev`` (n, d) the last commands, ``started``: whether any command was given."""
        if self.angle_rad <= 0:
            return c
        angles = self.angles(conflicted, c[0], u_prev, started)
        return np.where(conflicted[:, None], turn_about_z(c, -angles), c)

    def angles(self, conflicted: Array, wish: Array, u_prev: Array, started: bool) -> Array:
        """Turn angle per drone [rad]: the base angle, growing by ``STALL_GROWTH`` of it for every
        step in a row that the drone has been conflicted and stalled, up to a quarter turn (a base
        angle above a quarter turn is kept as it is). Counts this step."""
        stalled = conflicted & (norms(u_prev) < STALL_FRACTION * norms(wish))
        stalled &= started  # no command given yet: nothing has stalled
        self.stalled = np.where(stalled, self.stalled + 1, 0)
        base = self.angle_rad
        return np.minimum(base * (1.0 + STALL_GROWTH * self.stalled), max(base, 0.5 * np.pi))


def norms(v: Array) -> Array:
    """Euclidean norms over the last axis."""
    return np.sqrt(np.einsum("...d,...d->...", v, v))


def turn_about_z(v: Array, angle: Array) -> Array:
    """Rotate vectors (..., n, d) by ``angle`` (n,) [rad] about the world z axis (in-plane when d = 2)."""
    ca, sa = np.cos(angle), np.sin(angle)
    out = v.copy()
    out[..., 0] = ca * v[..., 0] - sa * v[..., 1]
    out[..., 1] = sa * v[..., 0] + ca * v[..., 1]
    return out

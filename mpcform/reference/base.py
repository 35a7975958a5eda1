"""Desired formation trajectories ``xi_d(t)`` and their drone-level targets ``p*_i(t)``, ``p_dot*_i(t)``.

Every reference describes itself by a vectorised :class:`Profile` (centroid, rotation and scale
with their rates at many times); the drone-level targets follow from eq. 13 and eq. 14's
feedforward ``J xi_dot_d``. Times before 0 are clamped to 0.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError, shown
from mpcform.formation.kinematics import velocity_size
from mpcform.formation.rotation import S_PLANAR, geodesic
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template

ROW_ADD_MIN_N = 100  # drones from which add_per_time repeats its rows (below, the broadcast is faster)


@dataclass(frozen=True)
class Profile:
    """Formation states and velocities at T times (world-frame angular velocity)."""

    centroid_m: Array  # (T, d)
    rotation_body_to_world: Array  # (T, d, d)
    scale: Array  # (T,)
    centroid_velocity_mps: Array  # (T, d)
    omega_world_radps: Array  # (T, 1) planar, (T, 3) spatial
    scale_rate_per_s: Array  # (T,)


class Reference(ABC):
    """A desired formation trajectory over ``template``."""

    template: Template

    @abstractmethod
    def profile(self, times_s: Array) -> Profile:
        """Formation states and velocities at ``times_s`` (T,)."""

    def targets(self, times_s: ArrayLike) -> tuple[Array, Array]:
        """Drone targets ``p*`` [m] and ``p_dot*`` [m/s], each (T, n, d), at ``times_s`` (T,)
        (real and finite: :func:`sample_times`)."""
        pr = self.profile(sample_times(times_s))
        q = self.template.offsets @ pr.rotation_body_to_world.transpose(0, 2, 1)  # R_t r_i (T, n, d)
        s = pr.scale[:, None, None]
        if q.shape[-1] == 2:
            spin = pr.omega_world_radps[:, :, None] * (q @ S_PLANAR.T)
        else:
            spin = spin_world(pr.omega_world_radps, q)
        # c + s q and c_dot + s_dot q + s (omega x q), summed in place (no (T, n, d) temporaries)
        pos = s * q
        add_per_time(pos, pr.centroid_m)
        vel = pr.scale_rate_per_s[:, None, None] * q
        add_per_time(vel, pr.centroid_velocity_mps)
        spin *= s
        vel += spin
        return pos, vel

    def start_positions_m(self) -> Array:
        """The drones' targets at t = 0, ``p*_i(0)`` (n, d) [m]: where the reference starts.

        They differ from where the drones start (a scenario's ``initial_positions_m``) when the
        reference does not begin at the start formation: a constant reference holds its goal
        from t = 0 (the swaps start on the opposite side of it), and explicit start positions
        are fitted by a formation state (``Scenario.start``) they need not match exactly.
        """
        return self.targets(0.0)[0][0]

    def state(self, t_s: float) -> FormationState:
        """The desired formation state at ``t_s``."""
        pr = self.profile(np.array([t_s], dtype=float))
        return FormationState(pr.centroid_m[0], pr.rotation_body_to_world[0], float(pr.scale[0]))

    def velocity(self, t_s: float) -> Array:
        """The desired formation velocity ``xi_dot_d`` (4 or 7) at ``t_s``."""
        pr = self.profile(np.array([t_s], dtype=float))
        return np.concatenate([pr.centroid_velocity_mps[0], pr.omega_world_radps[0], pr.scale_rate_per_s[:1]])


def sample_times(times_s: ArrayLike) -> Array:
    """``times_s`` [s] as a 1-D float array (a number: one time); a :class:`ValidationError`
    naming ``times_s`` unless they are real, finite numbers (a NaN time has no targets)."""
    t = np.asarray(times_s)
    if t.dtype.kind not in "biuf" or t.ndim > 1:
        raise ValidationError(
            "times_s", f"expected real times [s] (a number or a 1-D array), got {shown(times_s)}"
        )
    t = np.atleast_1d(t.astype(float, copy=False))
    if not np.isfinite(t).all():
        raise ValidationError("times_s", f"expected finite times [s], got {shown(t.tolist())}")
    return t


def add_per_time(a: Array, b: Array) -> None:
    """``a += b[:, None, :]`` in place for ``a`` (T, n, d) and ``b`` (T, d), bit for bit. From
    :data:`ROW_ADD_MIN_N` drones (``a`` contiguous) ``b`` is first repeated into a block laid out as
    ``a``: the broadcast's inner loop runs over only d values (1000 drones: 90 -> 52 us)."""
    t, n, d = a.shape
    if n < ROW_ADD_MIN_N or not a.flags.c_contiguous:
        a += b[:, None, :]
        return
    flat = a.reshape(t, n * d)  # a view of a
    flat += np.repeat(b, n, axis=0).reshape(t, n * d)


def spin_world(omega_world_radps: Array, q: Array) -> Array:
    """``omega_t x q_t,i`` (T, n, 3) for angular velocities (T, 3) and rows ``q`` (T, n, 3): the
    products and differences of ``np.cross``, component by component, without its generic
    overhead (axis moves, broadcast copies)."""
    w = omega_world_radps[:, None, :]
    w0, w1, w2 = w[..., 0], w[..., 1], w[..., 2]
    q0, q1, q2 = q[..., 0], q[..., 1], q[..., 2]
    spin = np.empty(q.shape)
    np.subtract(w1 * q2, w2 * q1, out=spin[..., 0])
    np.subtract(w2 * q0, w0 * q2, out=spin[..., 1])
    np.subtract(w0 * q1, w1 * q0, out=spin[..., 2])
    return spin


class ConstantReference(Reference):
    """Hold one formation state (the go-to-goal case of eq. 4 for every drone)."""

    def __init__(self, template: Template, state: FormationState) -> None:
        _same_dim(template, state, "reference")
        self.template, self.goal = template, state
        self._held_m: Array | None = None  # the goal's positions (n, d), once computed

    def targets(self, times_s: ArrayLike) -> tuple[Array, Array]:
        """The goal's positions at every time and zero velocity, each (T, n, d): bit for bit the
        general eq. 13 sum, computed once (a swap's targets: 75 -> 7 us at 20 drones). A subclass
        with a profile of its own gets the general sum of that profile."""
        if type(self).profile is not ConstantReference.profile:
            return super().targets(times_s)
        if self._held_m is None:
            self._held_m = super().targets(0.0)[0][0]
        t = sample_times(times_s).shape[0]
        pos = np.repeat(self._held_m[None], t, axis=0)
        return pos, np.zeros_like(pos)

    def profile(self, times_s: Array) -> Profile:
        """The goal at every time, at rest."""
        t = times_s.shape[0]
        g, d = self.goal, self.template.dim
        return Profile(
            np.broadcast_to(g.centroid_m, (t, d)),
            np.broadcast_to(g.rotation_body_to_world, (t, d, d)),
            np.full(t, g.scale),
            np.zeros((t, d)),
            np.zeros((t, velocity_size(d) - d - 1)),
            np.zeros(t),
        )


class ExponentialReference(Reference):
    """Exponential convergence from ``start`` to ``goal`` at ``rate_per_s`` (eq. 16, generalised).

    ``s(t) = s* + (s0 - s*) e^{-lambda t}``; the centroid converges the same way, and the
    rotation turns along the geodesic ``R(t) = R0 exp(phi(t) hat(a))`` with
    ``phi(t) = phi_total (1 - e^{-lambda t})``, so ``omega_world = phi_dot R0 a``.
    """

    def __init__(
        self, template: Template, start: FormationState, goal: FormationState, rate_per_s: float
    ) -> None:
        _same_dim(template, start, "reference.start")
        _same_dim(template, goal, "reference")
        self.template, self.start, self.goal = template, start, goal
        self.rate_per_s = positive("reference.rate", rate_per_s)
        self._axis, self._phi = geodesic(start.rotation_body_to_world, goal.rotation_body_to_world)

    def profile(self, times_s: Array) -> Profile:
        """Eq. 16 at ``times_s`` (T,): the states and their rates."""
        t = np.maximum(times_s, 0.0)
        lam = self.rate_per_s
        decay = np.exp(-lam * t)
        s0, g = self.start, self.goal
        centroid = g.centroid_m + np.outer(decay, s0.centroid_m - g.centroid_m)
        cvel = np.outer(-lam * decay, s0.centroid_m - g.centroid_m)
        scale = g.scale + (s0.scale - g.scale) * decay
        srate = -lam * (s0.scale - g.scale) * decay
        phi = self._phi * (1.0 - decay)
        phi_dot = self._phi * lam * decay
        r0 = s0.rotation_body_to_world
        if self.template.dim == 2:
            ang = self._axis[0] * phi
            c, s = np.cos(ang), np.sin(ang)
            rel = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
            omega = (self._axis[0] * phi_dot)[:, None]
        else:
            rel = Rotation.from_rotvec(np.outer(phi, self._axis)).as_matrix()
            omega = np.outer(phi_dot, r0 @ self._axis)
        return Profile(centroid, r0 @ rel, scale, cvel, omega, srate)


def _same_dim(template: Template, state: FormationState, field: str) -> None:
    if not isinstance(state, FormationState):
        raise ValidationError(field, f"expected a FormationState, got {type(state).__name__}")
    if state.dim != template.dim:
        raise ValidationError(field, f"state has dimension {state.dim}, template has {template.dim}")

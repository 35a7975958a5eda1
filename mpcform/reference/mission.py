"""Keyframe missions: jerk-limited, time-optimal formation references smoothed by ruckig.

A mission starts at a formation state and visits keyframes ("go to (10, 0, 5)", "turn 90
degrees", "double the scale", "hold 3 s", "switch to a line"). Each move between two keyframes
is one rest-to-rest ruckig trajectory over the DOFs ``x = (c [m] (d), phi [rad], s, alpha)``
(:mod:`mpcform.reference.moves`), where ``phi`` is the geodesic angle about the fixed body axis
``a`` of the turn (``R(t) = R0 exp(phi(t) hat(a))``, so ``omega_world = phi_dot R0 a``) and
``alpha`` blends the drones' template offsets when the keyframe switches templates. Moves are
chained rest to rest (every keyframe is reached with zero velocity and acceleration) and holds
are constant segments. Turns take the shortest way (at most half a turn per keyframe; exactly
half a turn picks its axis deterministically): split larger turns into several keyframes.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import linear_sum_assignment
from scipy.spatial.transform import Rotation

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError
from mpcform.formation.rotation import omega_size
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.reference.base import Profile, Reference, add_per_time, sample_times, spin_world
from mpcform.reference.keyframes import (
    Keyframe,
    MissionLimits,
    SpeedBudget,
    as_keyframe,
    centroid_of,
    rotation_of,
)
from mpcform.reference.moves import SNAP_RTOL, plan_move, turn


class CAPTWarning(UserWarning):
    """A template switch whose ends are closer than sqrt(2) d_min: straight blends may collide."""


@dataclass(frozen=True)
class MissionProfile(Profile):
    """:class:`Profile` plus accelerations and the drones' (blended) template offsets.

    ``offsets_m`` (T, n, d) are ``rho_i = (1 - alpha) r_i + alpha r'_pi(i)`` for the drones in
    order, ``offsets_rate_mps`` their rate ``alpha_dot (r'_pi(i) - r_i)``; ``blend`` is the
    progress alpha of the template switch of the current move (0 outside switches).
    """

    centroid_acceleration_mps2: Array  # (T, d)
    angular_acceleration_world_radps2: Array  # (T, 1) planar, (T, 3) spatial
    scale_acceleration_per_s2: Array  # (T,)
    offsets_m: Array  # (T, n, d)
    offsets_rate_mps: Array  # (T, n, d)
    blend: Array  # (T,)
    blend_rate_per_s: Array  # (T,)


@dataclass(frozen=True)
class Segment:
    """One piece of the mission: ``kind`` ``move`` (a ruckig trajectory) or ``hold``."""

    keyframe: int  # index of the keyframe this segment reaches or holds (-1: the start)
    kind: str
    start_s: float
    duration_s: float

    @property
    def end_s(self) -> float:
        """Time the segment ends [s]."""
        return self.start_s + self.duration_s


@dataclass(frozen=True, eq=False)
class _Piece:
    info: Segment
    x0: Array  # (D,) DOFs (c, phi, s, alpha) at the start
    x1: Array  # (D,) at the end
    rotation0: Array  # (d, d)
    axis: Array  # (1,) planar sign or (3,) body-frame unit axis
    offsets0: Array  # (n, d)
    offsets1: Array  # (n, d)
    trajectory: Any  # ruckig.Trajectory or None (hold)


# ---- the reference --------------------------------------------------------------------------
class MissionReference(Reference):
    """A formation reference through keyframes, jerk-limited and time-optimal per move (ruckig).

    Limits: explicit bounds per DOF group (``limits``), and/or a :class:`SpeedBudget` derived
    from the drones' v_max (``budget``); where both apply the smaller wins. With a budget, every
    drone's reference speed stays below ``fraction * v_max`` (:mod:`mpcform.reference.moves`
    splits the budget between the DOFs of each move). ``d_min_m`` enables the CAPT check of
    template switches (:class:`CAPTWarning`, also kept in :attr:`warnings`). Times are clamped
    to ``[0, duration_s]``; :attr:`template` is the start template.
    """

    def __init__(
        self,
        template: Template,
        start: FormationState,
        keyframes: Sequence[Keyframe | Mapping[str, Any]],
        *,
        limits: MissionLimits | None = None,
        budget: SpeedBudget | None = None,
        d_min_m: float | None = None,
    ) -> None:
        if not isinstance(template, Template):
            raise ValidationError("template", f"expected a Template, got {type(template).__name__}")
        if not isinstance(start, FormationState) or start.dim != template.dim:
            got = f"dimension {start.dim}" if isinstance(start, FormationState) else type(start).__name__
            raise ValidationError(
                "reference.start", f"expected a FormationState of dimension {template.dim}, got {got}"
            )
        if limits is not None and not isinstance(limits, MissionLimits):
            raise ValidationError("reference.limits", f"expected MissionLimits, got {type(limits).__name__}")
        if budget is not None and not isinstance(budget, SpeedBudget):
            raise ValidationError("reference.budget", f"expected a SpeedBudget, got {type(budget).__name__}")
        if limits is None and budget is None:
            raise ValidationError(
                "reference",
                "give explicit limits (MissionLimits) or a SpeedBudget derived from v_max (or both)",
            )
        if isinstance(keyframes, str | bytes) or not isinstance(keyframes, Sequence) or not keyframes:
            raise ValidationError(
                "reference.keyframes", f"expected a non-empty list of keyframes, got {keyframes!r}"
            )
        self.template, self.start = template, start
        self.limits = limits if limits is not None else MissionLimits()
        self.budget = budget
        self.d_min_m = None if d_min_m is None else positive("limits.d_min", d_min_m)
        self.keyframes = tuple(as_keyframe(k, i) for i, k in enumerate(keyframes))
        self._warnings: list[str] = []
        self._assignments: list[Array | None] = []
        self._pieces: list[_Piece] = []
        self._arrivals: list[float] = []
        self._build()
        self.warnings: tuple[str, ...] = tuple(self._warnings)
        self.assignments: tuple[Array | None, ...] = tuple(self._assignments)
        """Per keyframe: for a template switch, ``pi`` with drone i -> new offset ``pi[i]``; else None."""
        self.segments: tuple[Segment, ...] = tuple(p.info for p in self._pieces if p.info.duration_s > 0)
        self.duration_s: float = self._pieces[-1].info.end_s
        self.keyframe_times_s: tuple[float, ...] = tuple(self._arrivals)
        """Arrival time [s] at each keyframe (the start of its hold)."""
        self._stack()

    # ---- construction ------------------------------------------------------------------------
    def _build(self) -> None:
        d = self.template.dim
        no_axis = np.ones(omega_size(d))
        c, rot, s = self.start.centroid_m, self.start.rotation_body_to_world, self.start.scale
        offsets, offsets_tpl = np.array(self.template.offsets), self.template  # offsets in drone order
        t = 0.0
        for k, kf in enumerate(self.keyframes):
            name = f"reference.keyframes[{k}]"
            c1 = c if kf.centroid_m is None else centroid_of(kf.centroid_m, d, f"{name}.centroid")
            rot1 = rot if kf.rotation is None else rotation_of(kf.rotation, d, f"{name}.rotation")
            s1 = s if kf.scale is None else float(kf.scale)
            offsets1, perm = offsets, None
            if kf.template is not None:
                offsets1, perm = self._switch(k, offsets_tpl, kf.template, offsets, min(s, s1))
            self._assignments.append(perm)
            axis, phi = turn(rot, rot1)
            blend = 0.0 if np.array_equal(offsets1, offsets) else 1.0
            x0 = np.concatenate([c, [0.0, s, 0.0]])
            x1 = np.concatenate([c1, [phi, s1, blend]])
            tiny = np.abs(x1 - x0) <= SNAP_RTOL * np.maximum(1.0, np.maximum(np.abs(x0), np.abs(x1)))
            x1 = np.where(tiny, x0, x1)
            if np.any(x1 != x0):
                traj = plan_move(k, x0, x1, offsets, offsets1, self.limits, self.budget)
                move = Segment(k, "move", t, float(traj.duration))
                t = self._add(move, x0, x1, rot, axis, offsets, offsets1, traj)
            c, rot, s, offsets = np.array(c1, dtype=float), rot1, s1, offsets1
            offsets_tpl = offsets_tpl if kf.template is None else kf.template
            xk = np.concatenate([c, [0.0, s, 0.0]])
            self._arrivals.append(t)
            t = self._add(Segment(k, "hold", t, kf.hold_s), xk, xk, rot, no_axis, offsets, offsets, None)
        # a final zero-length hold: the mission ends exactly on the last keyframe
        final = Segment(len(self.keyframes) - 1, "hold", t, 0.0)
        self._pieces.append(_Piece(final, xk, xk, rot, no_axis, offsets, offsets, None))

    def _add(
        self,
        info: Segment,
        x0: Array,
        x1: Array,
        rot: Array,
        axis: Array,
        off0: Array,
        off1: Array,
        traj: Any,
    ) -> float:
        """Keep a piece of positive duration; return its end time [s]."""
        if info.duration_s > 0.0:
            self._pieces.append(_Piece(info, x0, x1, rot, axis, off0, off1, traj))
        return info.end_s

    def _switch(
        self, k: int, old: Template, new: Template, offsets: Array, blend_scale: float
    ) -> tuple[Array, Array]:
        """Assign drones to ``new``'s offsets (min sum of squared distances) and check CAPT.

        ``offsets`` (n, d) are the drones' offsets now: ``old``'s, in the drones' order.
        """
        name = f"reference.keyframes[{k}].template"
        if new.dim != self.template.dim or new.n != self.template.n:
            raise ValidationError(
                name,
                f"expected {self.template.n} drones in {self.template.dim}D "
                f"(the mission's template), got {new.n} in {new.dim}D",
            )
        cost = ((offsets[:, None, :] - new.offsets[None, :, :]) ** 2).sum(axis=-1)
        _, perm = linear_sum_assignment(cost)
        if self.d_min_m is not None:
            need = np.sqrt(2.0) * self.d_min_m
            before = blend_scale * old.min_distance()
            after = blend_scale * new.min_distance()
            if min(before, after) < need:
                msg = (
                    f"{name}: the switch to the {new.name!r} template does not meet the CAPT "
                    f"condition at the blend's scale {blend_scale:g}: closest pairs {before:.4g} m "
                    f"(before) and {after:.4g} m (after), need sqrt(2) * d_min = {need:.4g} m; "
                    "the straight blends may bring drones closer than d_min, and only the MPC keeps "
                    "separation"
                )
                self._warnings.append(msg)
                warnings.warn(msg, CAPTWarning, stacklevel=4)
        return np.array(new.offsets[perm]), perm

    def _stack(self) -> None:
        pieces = self._pieces
        self._starts = np.array([p.info.start_s for p in pieces])
        self._rot0 = np.stack([p.rotation0 for p in pieces])
        self._axis = np.stack([p.axis for p in pieces])
        self._off0 = np.stack([p.offsets0 for p in pieces])
        self._off1 = np.stack([p.offsets1 for p in pieces])

    # ---- evaluation ----------------------------------------------------------------------------
    def dofs(self, times_s: ArrayLike) -> tuple[Array, Array, Array, Array]:
        """Segment index (T,) and DOFs ``(c, phi, s, alpha)`` with rates and accelerations, (T, D)."""
        t = finite_array("times", np.atleast_1d(np.asarray(times_s, dtype=float)), (None,))
        t = np.clip(t, 0.0, self.duration_s)
        idx = np.clip(np.searchsorted(self._starts, t, side="right") - 1, 0, len(self._pieces) - 1)
        dof = self._pieces[0].x0.shape[0]
        pos, vel, acc = np.empty((t.size, dof)), np.zeros((t.size, dof)), np.zeros((t.size, dof))
        for k in np.unique(idx):
            piece, mask = self._pieces[k], idx == k
            tau = t[mask] - piece.info.start_s
            if piece.trajectory is None:
                pos[mask] = piece.x0
                continue
            inside = tau < piece.info.duration_s
            sampled = np.array([piece.trajectory.at_time(x) for x in tau[inside]]).reshape(-1, 3, dof)
            rows = np.flatnonzero(mask)
            pos[rows[~inside]] = piece.x1
            pos[rows[inside]], vel[rows[inside]], acc[rows[inside]] = sampled.transpose(1, 0, 2)
        return idx, pos, vel, acc

    def profile(self, times_s: Array) -> MissionProfile:
        """The ruckig segments at ``times_s`` (T,): states, rates, accelerations and blended offsets."""
        d = self.template.dim
        idx, x, v, a = self.dofs(times_s)
        phi, phi_dot, phi_ddot = x[:, d], v[:, d], a[:, d]
        rot0, axis = self._rot0[idx], self._axis[idx]
        if d == 2:
            ang = axis[:, 0] * phi
            cos, sin = np.cos(ang), np.sin(ang)
            rel = np.stack([np.stack([cos, -sin], -1), np.stack([sin, cos], -1)], -2)
            omega, omega_dot = (axis[:, 0] * phi_dot)[:, None], (axis[:, 0] * phi_ddot)[:, None]
        else:
            rel = Rotation.from_rotvec(phi[:, None] * axis).as_matrix()
            world_axis = np.einsum("tij,tj->ti", rot0, axis)
            omega, omega_dot = phi_dot[:, None] * world_axis, phi_ddot[:, None] * world_axis
        swing = self._off1[idx] - self._off0[idx]
        alpha, alpha_dot = x[:, d + 2], v[:, d + 2]
        return MissionProfile(
            centroid_m=x[:, :d],
            rotation_body_to_world=rot0 @ rel,
            scale=x[:, d + 1],
            centroid_velocity_mps=v[:, :d],
            omega_world_radps=omega,
            scale_rate_per_s=v[:, d + 1],
            centroid_acceleration_mps2=a[:, :d],
            angular_acceleration_world_radps2=omega_dot,
            scale_acceleration_per_s2=a[:, d + 1],
            offsets_m=self._off0[idx] + alpha[:, None, None] * swing,
            offsets_rate_mps=alpha_dot[:, None, None] * swing,
            blend=alpha,
            blend_rate_per_s=alpha_dot,
        )

    def targets(self, times_s: ArrayLike) -> tuple[Array, Array]:
        """Drone targets ``p*_i = c + s R rho_i`` [m] and ``p_dot*_i`` [m/s], each (T, n, d).

        ``rho_i = (1 - alpha) r_i + alpha r'_pi(i)``; the velocity includes the blend's term
        ``s R alpha_dot (r'_pi(i) - r_i)`` besides ``J xi_dot_d``.
        """
        pr = self.profile(sample_times(times_s))
        rot_t = pr.rotation_body_to_world.transpose(0, 2, 1)  # R_t rho_i as one stacked matmul
        q, q_rate = pr.offsets_m @ rot_t, pr.offsets_rate_mps @ rot_t
        s = pr.scale[:, None, None]
        if q.shape[-1] == 2:
            spin = pr.omega_world_radps[:, :, None] * np.stack([-q[..., 1], q[..., 0]], -1)
        else:
            spin = spin_world(pr.omega_world_radps, q)
        vel = pr.scale_rate_per_s[:, None, None] * q
        add_per_time(vel, pr.centroid_velocity_mps)
        vel += s * (spin + q_rate)
        pos = s * q
        add_per_time(pos, pr.centroid_m)
        return pos, vel

    def acceleration(self, t_s: float) -> Array:
        """The desired formation acceleration ``(c_ddot, omega_dot_world, s_ddot)`` (4 or 7) at ``t_s``."""
        pr = self.profile(np.array([t_s], dtype=float))
        return np.concatenate(
            [
                pr.centroid_acceleration_mps2[0],
                pr.angular_acceleration_world_radps2[0],
                pr.scale_acceleration_per_s2[:1],
            ]
        )

    def keyframe_state(self, k: int) -> FormationState:
        """The formation state of keyframe ``k`` (keys it leaves unset come from earlier ones)."""
        return self.state(self.keyframe_times_s[k])

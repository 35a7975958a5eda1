"""Keyframe missions: jerk-limited, time-optimal formation references smoothed by ruckig.

A mission starts at a formation state and visits keyframes ("go to (10, 0, 5)", "turn 90
degrees", "double the scale", "hold 3 s", "switch to a line"). Each move between two keyframes
is ONE offline ruckig trajectory with phase synchronisation over the degrees of freedom

    x = (c [m] (d), phi [rad], s, alpha)

where ``phi`` is the geodesic angle about the fixed body axis ``a`` of the turn
(``R(t) = R0 exp(phi(t) hat(a))``, so ``omega_world = phi_dot R0 a``) and ``alpha`` blends the
drones' template offsets when the keyframe switches templates. Moves are chained rest to rest
(every keyframe is reached with zero velocity and acceleration) and holds are constant
segments; ruckig's intermediate waypoints are never used (the community build sends them to a
cloud service). Turns take the shortest way (at most half a turn per keyframe; exactly half a
turn picks its axis deterministically): split larger turns into several keyframes.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from ruckig import InputParameter, Result, Ruckig, RuckigError, Synchronization, Trajectory
from scipy.optimize import linear_sum_assignment
from scipy.spatial.transform import Rotation

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError
from mpcform.formation.rotation import check_rotation, geodesic, omega_size, rotation_matrix
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.reference.base import Profile, Reference

GROUPS = ("centroid", "rotation", "scale", "blend")
"""DOF groups: centroid [m] (d DOF), rotation angle phi [rad], scale s [1], template blend alpha [1]."""
DEFAULT_SPEED_FRACTION = 0.8
RISE_TIME_S = 1.0
"""Default acceleration budget: the speed budget reached in this time (``A = V / 1 s``)."""
JERK_TIME_S = 0.5
"""Default jerk budget: the acceleration budget reached in this time (``J = A / 0.5 s``)."""
SNAP_RTOL = 1e-12
"""Displacements below ``SNAP_RTOL * max(1, |start|, |end|)`` count as zero (no motion)."""
HALF_TURN_TOL = 1e-9
"""Turns within this of pi [rad] are exactly half a turn: the axis is chosen deterministically."""
_KEYFRAME_FIELDS = {"centroid": "centroid", "rotation": "rotation", "scale": "scale", "blend": "template"}


class CAPTWarning(UserWarning):
    """A template switch whose ends are closer than sqrt(2) d_min: straight blends may collide."""


# ---- descriptions ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Keyframe:
    """One mission keyframe; ``None`` keeps the previous keyframe's value (or the start's).

    ``centroid_m`` (d,) [m]; ``rotation`` an angle [rad] (planar) or a rotation vector [rad]
    (spatial), world orientation of the body frame; ``scale`` (> 0); ``hold_s`` [s] to stay at
    the keyframe after reaching it; ``template`` switches the formation to new offsets (same n):
    drones are assigned to them optimally and blended while the move runs.
    """

    centroid_m: Array | None = None
    rotation: Array | float | None = None
    scale: float | None = None
    hold_s: float = 0.0
    template: Template | None = None

    def __post_init__(self) -> None:
        if self.centroid_m is not None:
            c = finite_array("keyframe.centroid", self.centroid_m, (None,))
            if c.shape[0] not in (2, 3):
                raise ValidationError("keyframe.centroid", f"expected 2 or 3 numbers, got {c.shape[0]}")
            c.setflags(write=False)
            object.__setattr__(self, "centroid_m", c)
        if self.rotation is not None:
            try:
                shape = np.shape(np.array(self.rotation, dtype=float))
            except (TypeError, ValueError):
                shape = ()  # finite_array names the problem
            r = finite_array("keyframe.rotation", self.rotation, shape)
            if r.shape not in ((), (3,)):
                raise ValidationError(
                    "keyframe.rotation",
                    f"expected an angle [rad] (planar) or a rotation vector of 3 numbers [rad] "
                    f"(spatial), got shape {r.shape}",
                )
            r.setflags(write=False)
            object.__setattr__(self, "rotation", r)
        if self.scale is not None:
            object.__setattr__(self, "scale", positive("keyframe.scale", self.scale))
        object.__setattr__(self, "hold_s", positive("keyframe.hold", self.hold_s, allow_zero=True))
        if self.template is not None and not isinstance(self.template, Template):
            raise ValidationError(
                "keyframe.template", f"expected a Template, got {type(self.template).__name__}"
            )


@dataclass(frozen=True)
class MissionLimits:
    """Explicit bounds per DOF group (keys of :data:`GROUPS`); a missing group is not bounded here.

    Units per group: ``centroid`` [m/s, m/s^2, m/s^3] on the norm of the centroid's velocity,
    acceleration and jerk (not per axis); ``rotation`` [rad/s, rad/s^2, rad/s^3];
    ``scale`` and ``blend`` [1/s, 1/s^2, 1/s^3].
    """

    max_velocity: Mapping[str, float] = field(default_factory=dict)
    max_acceleration: Mapping[str, float] = field(default_factory=dict)
    max_jerk: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("max_velocity", "max_acceleration", "max_jerk"):
            raw = getattr(self, name)
            if not isinstance(raw, Mapping):
                raise ValidationError(
                    f"reference.{name}", f"expected a table of DOF groups {GROUPS}, got {raw!r}"
                )
            checked: dict[str, float] = {}
            for group, value in raw.items():
                where = f"reference.{name}.{group}"
                if group not in GROUPS:
                    raise ValidationError(where, f"unknown DOF group; expected one of {', '.join(GROUPS)}")
                if isinstance(value, bool):
                    raise ValidationError(where, f"expected a finite number > 0, got {value!r}")
                checked[group] = positive(where, value)
            object.__setattr__(self, name, MappingProxyType(checked))

    def get(self, kind: int, group: str) -> float:
        """Bound of derivative ``kind`` (0 velocity, 1 acceleration, 2 jerk) of ``group`` (inf: none)."""
        table = (self.max_velocity, self.max_acceleration, self.max_jerk)[kind]
        return float(table.get(group, np.inf))


@dataclass(frozen=True)
class SpeedBudget:
    """Limits derived from the drones' ``v_max_mps``: every drone's reference speed stays below
    ``fraction * v_max`` by construction.

    ``acceleration_mps2`` and ``jerk_mps3`` bound the drones' along-path reference acceleration
    and jerk (defaults: the speed budget reached in :data:`RISE_TIME_S`, the acceleration budget
    in :data:`JERK_TIME_S`). See :class:`MissionReference` for how the budget is split.
    """

    v_max_mps: float
    fraction: float = DEFAULT_SPEED_FRACTION
    acceleration_mps2: float | None = None
    jerk_mps3: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "v_max_mps", positive("limits.v_max", self.v_max_mps))
        frac = positive("reference.speed_fraction", self.fraction)
        if frac > 1.0:
            raise ValidationError("reference.speed_fraction", f"expected a number in (0, 1], got {frac:g}")
        object.__setattr__(self, "fraction", frac)
        if self.acceleration_mps2 is not None:
            a = positive("reference.drone_acceleration", self.acceleration_mps2)
            object.__setattr__(self, "acceleration_mps2", a)
        if self.jerk_mps3 is not None:
            object.__setattr__(self, "jerk_mps3", positive("reference.drone_jerk", self.jerk_mps3))

    @property
    def budgets(self) -> tuple[float, float, float]:
        """Speed [m/s], acceleration [m/s^2] and jerk [m/s^3] budgets of the drones' references."""
        v = self.fraction * self.v_max_mps
        a = v / RISE_TIME_S if self.acceleration_mps2 is None else self.acceleration_mps2
        j = a / JERK_TIME_S if self.jerk_mps3 is None else self.jerk_mps3
        return v, a, j


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
    drone's reference speed ``||c_dot|| + |s_dot| |rho_i| + s |omega| |rho_i| + s |alpha_dot|
    |r'_i - r_i|`` (an upper bound of ``||p_dot*_i||``) stays below ``V = fraction * v_max``:

    * On a rest-to-rest move with phase synchronisation every DOF follows one normalised profile
      ``x_k(t) = x_k0 + Delta_k f(t)``, ``f: 0 -> 1``, so the speed bound of drone i is
      ``f_dot(t) K_i`` with ``K_i = ||Delta c|| + (|Delta s| + s_hi |Delta phi|) m_i + s_hi
      |Delta alpha| b_i`` (``s_hi`` the larger end scale, ``m_i = max(|rho_i|)`` over both ends,
      ``b_i = |r'_i - r_i|``).
    * The budget is split between the DOFs in proportion to their share of ``K = max_i K_i``:
      DOF k gets ``v_k = |Delta_k| V / K`` (acceleration ``|Delta_k| A / K``, jerk
      ``|Delta_k| J / K``), i.e. every DOF the same normalised rate, so all of them saturate
      together and ``f_dot <= V / K`` is exactly the time-optimal profile under the bound.
      The centroid's share is spread over its axes along ``Delta c`` (``|Delta c_j| V / K``),
      so its speed ``||c_dot||`` meets its share, not ``sqrt(d)`` times it. (Each DOF within its
      own limit keeps the bound even without phase synchronisation.)
    * The acceleration and jerk budgets bound the along-path part ``f_ddot K_i`` (``f_dddot
      K_i``); the product terms of rotation and scaling (centripetal ``s |omega|^2 |rho|``,
      ``2 s_dot omega x q``) are not included.

    Explicit centroid limits bound the norm the same way (per-axis limits along ``Delta c``).
    A DOF that moves no drone (zero offsets) gets a lever arm of 1 m. ``d_min_m`` enables the
    CAPT check of template switches (:class:`CAPTWarning`, also kept in :attr:`warnings`).
    Times are clamped to ``[0, duration_s]``; :attr:`template` is the start template.
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
        self.keyframes = tuple(_keyframe(k, i) for i, k in enumerate(keyframes))
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
        offsets = np.array(self.template.offsets)
        t = 0.0
        for k, kf in enumerate(self.keyframes):
            name = f"reference.keyframes[{k}]"
            c1 = c if kf.centroid_m is None else self._dim_checked(kf.centroid_m, f"{name}.centroid")
            rot1 = rot if kf.rotation is None else self._rotation(kf.rotation, f"{name}.rotation")
            s1 = s if kf.scale is None else float(kf.scale)
            offsets1, perm = offsets, None
            if kf.template is not None:
                offsets1, perm = self._switch(k, kf.template, offsets, min(s, s1))
            self._assignments.append(perm)
            axis, phi = _turn(rot, rot1)
            blend = 0.0 if np.array_equal(offsets1, offsets) else 1.0
            x0 = np.concatenate([c, [0.0, s, 0.0]])
            x1 = np.concatenate([c1, [phi, s1, blend]])
            tiny = np.abs(x1 - x0) <= SNAP_RTOL * np.maximum(1.0, np.maximum(np.abs(x0), np.abs(x1)))
            x1 = np.where(tiny, x0, x1)
            if np.any(x1 != x0):
                traj = self._trajectory(k, x0, x1, offsets, offsets1)
                move = Segment(k, "move", t, float(traj.duration))
                t = self._add(move, x0, x1, rot, axis, offsets, offsets1, traj)
            c, rot, s, offsets = np.array(c1, dtype=float), rot1, s1, offsets1
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

    def _dim_checked(self, centroid: Array, field_name: str) -> Array:
        d = self.template.dim
        if centroid.shape != (d,):
            raise ValidationError(
                field_name,
                f"expected {d} numbers (the template is {'planar' if d == 2 else 'spatial'}), "
                f"got {centroid.shape[0]}",
            )
        return centroid

    def _rotation(self, param: Array | float, field_name: str) -> Array:
        d = self.template.dim
        shape = np.shape(param)
        if (d == 2 and shape != ()) or (d == 3 and shape != (3,)):
            want = "an angle [rad] (planar)" if d == 2 else "a rotation vector of 3 numbers [rad] (spatial)"
            raise ValidationError(field_name, f"expected {want}, got shape {shape}")
        with np.errstate(all="ignore"):  # huge rotation vectors give NaN: rejected below
            rot = rotation_matrix(d, param, field_name)
        return check_rotation(field_name, rot, d)

    def _switch(self, k: int, new: Template, offsets: Array, blend_scale: float) -> tuple[Array, Array]:
        """Assign drones to ``new``'s offsets (min sum of squared distances) and check CAPT."""
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
            before = blend_scale * _min_pair_distance(offsets)
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

    def _dof_limits(self, x0: Array, x1: Array, offsets0: Array, offsets1: Array) -> list[Array]:
        """Velocity, acceleration and jerk limit per DOF (module docstring; budget split)."""
        d = self.template.dim
        delta = np.abs(x1 - x0)
        dc = float(np.linalg.norm(delta[:d]))
        lever = np.maximum(np.linalg.norm(offsets0, axis=1), np.linalg.norm(offsets1, axis=1))
        swing = np.linalg.norm(offsets1 - offsets0, axis=1)
        s_hi = max(x0[d + 1], x1[d + 1])
        k_i = dc + (delta[d + 1] + s_hi * delta[d]) * lever + s_hi * delta[d + 2] * swing
        k_max = float(k_i.max())
        unit = dc + delta[d + 1] + s_hi * delta[d] + s_hi * delta[d + 2]  # with a 1 m lever arm
        if k_max <= SNAP_RTOL * unit:
            k_max = unit
        groups = _dof_groups(d)
        # direction share of the centroid's norm bound, 1 for the scalar DOFs
        share = np.ones_like(delta)
        if dc > 0:
            share[:d] = delta[:d] / dc
        moving = delta > 0
        out = []
        for kind in range(3):
            explicit = np.array([self.limits.get(kind, g) for g in groups])
            explicit[moving] *= share[moving]
            derived = np.full_like(delta, np.inf)
            if self.budget is not None:
                derived = delta * (self.budget.budgets[kind] / k_max)
            lim = np.minimum(explicit, derived)
            out.append(np.where(moving, lim, 1.0))
        return out

    def _trajectory(self, k: int, x0: Array, x1: Array, offsets0: Array, offsets1: Array) -> Any:
        name = f"reference.keyframes[{k}]"
        groups = _dof_groups(self.template.dim)
        with np.errstate(all="ignore"):
            vel, acc, jerk = self._dof_limits(x0, x1, offsets0, offsets1)
        for kind, lim in zip(("max_velocity", "max_acceleration", "max_jerk"), (vel, acc, jerk), strict=True):
            bad = np.flatnonzero(~np.isfinite(lim) | (lim <= 0))
            if bad.size:
                g = groups[bad[0]]
                if not np.isinf(lim[bad[0]]):
                    raise ValidationError(
                        f"{name}.{_KEYFRAME_FIELDS[g]}",
                        f"the move gives a degenerate {kind} limit {lim[bad[0]]:g} for the {g} DOF",
                    )
                raise ValidationError(
                    f"reference.{kind}.{g}",
                    f"keyframe {k} moves the {g} DOF but no limit is set for it: set "
                    f"limits.v_max (derived limits) or reference.{kind}.{g}",
                )
        traj, problem = _ruckig(x0, x1, vel, acc, jerk)
        if traj is None:
            group = _failing_group(x0, x1, vel, acc, jerk, groups)
            where = name if group is None else f"{name}.{_KEYFRAME_FIELDS[group]}"
            raise ValidationError(
                where,
                f"ruckig cannot plan the move to this keyframe ({problem}); check the keyframe's "
                "values and the limits",
            )
        return traj

    def _stack(self) -> None:
        pieces = self._pieces
        self._starts = np.array([p.info.start_s for p in pieces])
        self._rot0 = np.stack([p.rotation0 for p in pieces])
        self._axis = np.stack([p.axis for p in pieces])
        self._off0 = np.stack([p.offsets0 for p in pieces])
        self._off1 = np.stack([p.offsets1 for p in pieces])

    # ---- evaluation ----------------------------------------------------------------------------
    def dofs(self, times_s: object) -> tuple[Array, Array, Array, Array]:
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

    def targets(self, times_s: object) -> tuple[Array, Array]:
        """Drone targets ``p*_i = c + s R rho_i`` [m] and ``p_dot*_i`` [m/s], each (T, n, d).

        ``rho_i = (1 - alpha) r_i + alpha r'_pi(i)``; the velocity includes the blend's term
        ``s R alpha_dot (r'_pi(i) - r_i)`` besides ``J xi_dot_d``.
        """
        pr = self.profile(np.atleast_1d(np.asarray(times_s, dtype=float)))
        rot = pr.rotation_body_to_world
        q = np.einsum("tij,tnj->tni", rot, pr.offsets_m)
        q_rate = np.einsum("tij,tnj->tni", rot, pr.offsets_rate_mps)
        s = pr.scale[:, None, None]
        if q.shape[-1] == 2:
            spin = pr.omega_world_radps[:, :, None] * np.stack([-q[..., 1], q[..., 0]], -1)
        else:
            spin = np.cross(pr.omega_world_radps[:, None, :], q)
        vel = (
            pr.centroid_velocity_mps[:, None, :]
            + pr.scale_rate_per_s[:, None, None] * q
            + s * (spin + q_rate)
        )
        return pr.centroid_m[:, None, :] + s * q, vel

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


# ---- helpers --------------------------------------------------------------------------------
def _keyframe(item: Keyframe | Mapping[str, Any], k: int) -> Keyframe:
    if isinstance(item, Keyframe):
        return item
    name = f"reference.keyframes[{k}]"
    if not isinstance(item, Mapping):
        raise ValidationError(name, f"expected a Keyframe or a table of its fields, got {item!r}")
    try:
        return Keyframe(**item)
    except TypeError as exc:
        raise ValidationError(name, f"bad keyframe fields {sorted(item)}: {exc}") from None
    except ValidationError as exc:
        raise ValidationError(exc.field.replace("keyframe", name, 1), str(exc).split(": ", 1)[1]) from None


def _turn(r0: Array, r1: Array) -> tuple[Array, float]:
    """Geodesic axis and angle; exactly half a turn gets a deterministic axis (+z planar: +1)."""
    axis, phi = geodesic(r0, r1)
    if abs(phi - np.pi) > HALF_TURN_TOL:
        return axis, phi
    if r0.shape == (2, 2):
        return np.array([1.0]), float(np.pi)
    outer = (r0.T @ r1 + np.eye(3)) / 2.0  # = a a^T for a half turn about a
    j = int(np.argmax(np.diag(outer)))
    a = outer[:, j] / np.linalg.norm(outer[:, j])
    lead = a[np.flatnonzero(np.abs(a) > 1e-9)[0]]
    return a * np.sign(lead), float(np.pi)


def _dof_groups(dim: int) -> list[str]:
    """The group of each DOF of ``x = (c (d), phi, s, alpha)``."""
    return ["centroid"] * dim + ["rotation", "scale", "blend"]


def _min_pair_distance(points: Array) -> float:
    if points.shape[0] < 2:
        return float("inf")
    dist = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    return float(dist[np.triu_indices(points.shape[0], 1)].min())


def _ruckig(x0: Array, x1: Array, vel: Array, acc: Array, jerk: Array) -> tuple[Any, str]:
    """Offline rest-to-rest trajectory with phase synchronisation, or (None, the problem)."""
    dofs = x0.shape[0]
    inp = InputParameter(dofs)
    inp.current_position, inp.target_position = x0.tolist(), x1.tolist()
    inp.current_velocity = inp.current_acceleration = [0.0] * dofs
    inp.target_velocity = inp.target_acceleration = [0.0] * dofs
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = vel.tolist(), acc.tolist(), jerk.tolist()
    inp.synchronization = Synchronization.Phase
    traj = Trajectory(dofs)
    try:
        result = Ruckig(dofs).calculate(inp, traj)
    except RuckigError as exc:
        return None, str(exc).strip().splitlines()[0] if str(exc).strip() else "RuckigError"
    except ValueError as exc:  # result codes the binding's enum lacks (-101: duration too long)
        return None, f"ruckig result {exc}"
    if result != Result.Working:
        return None, f"result {result.name}"
    if not np.isfinite(traj.duration) or traj.duration < 0:
        return None, f"duration {traj.duration}"
    end = np.asarray(traj.at_time(traj.duration)[0])
    if not np.all(np.isfinite(end)) or np.abs(end - x1).max() > 1e-6 * max(1.0, float(np.abs(x1).max())):
        return None, "the trajectory does not reach the keyframe"
    return traj, ""


def _failing_group(
    x0: Array, x1: Array, vel: Array, acc: Array, jerk: Array, groups: list[str]
) -> str | None:
    """The first DOF group that ruckig cannot plan on its own (to name the keyframe's field)."""
    names = np.array(groups)
    for g in GROUPS:
        sel = names == g
        if np.any(x1[sel] != x0[sel]) and _ruckig(x0[sel], x1[sel], vel[sel], acc[sel], jerk[sel])[0] is None:
            return g
    return None

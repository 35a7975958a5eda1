"""Formation tracking with secondary objectives in the null space of the formation Jacobian (eq. 15).

The seed prints ``u = J xi_dot_d + (I - J^+ J) u_sec``; ``J^+ J`` is 4 x 4 or 7 x 7 and does not
type-check. The projector onto drone motions that leave the formation velocity unchanged is
``N = I - J J^+`` (:func:`~mpcform.formation.kinematics.nullspace_projector`). This module
implements

    ``u = J xi_dot_d + k (p* - p) + N u_sec``

with the feedback **outside** the projection: the primary task is eq. 14 unchanged (its
feedback also corrects shape errors, which live in the null space), and the secondary
contribution ``N u_sec`` has formation velocity ``J^+ N u_sec = 0`` exactly (to machine
precision, also when J is rank-deficient: N and J^+ come from the same SVD with the same
rank tolerance). In particular ``sum_i (N u_sec)_i = 0`` (translation is in range(J)), so the
centroid moves exactly as under eq. 14. J is evaluated at the best-fit formation state of
the measured positions (:func:`~mpcform.formation.kinematics.fit_formation`): the secondary term does
not change the formation velocity of the drones as they are, to first order.

Objectives (``u_sec``, (n, d)):

- ``repulsion``: pairs closer than ``radius`` (found with a k-d tree) push apart,
  ``u_sec_i = c sum_j (radius - d_ij) (p_i - p_j) / d_ij``. Only its shape-changing part
  survives the projection: it cannot change the scale, so it deforms the shape to open up
  close pairs, and the feedback pulls back; the equilibrium deformation is about
  ``N u_sec / k``.
- ``energy``: ``u_sec = -w (J xi_dot_d + k (p* - p))`` with ``w`` in [0, 1], which gives
  ``u = (1 - w) u_14 + w J J^+ u_14``: w = 1 is the smallest command with the same formation
  velocity as eq. 14 (but then shape errors are no longer corrected); smaller w slows the
  shape correction to the rate ``(1 - w) k``.
- ``none``: eq. 14.

Saturation (eq. 7, per drone) is applied to the sum; a saturated step no longer keeps the
formation velocity of eq. 14 (reported as ``StepInfo.saturated``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, positive
from mpcform.control.base import FEEDFORWARDS, Controller, ControlStep, StepInfo, feedforward_targets
from mpcform.control.laws import check_gain_dt, count_saturated, saturate, tracking_command
from mpcform.errors import ValidationError
from mpcform.formation.geometry import pairs_within
from mpcform.formation.kinematics import fit_formation, formation_jacobian, nullspace_projector
from mpcform.reference.base import Reference

OBJECTIVES = ("repulsion", "energy", "none")


@dataclass(frozen=True)
class NullSpaceSettings:
    """Parameters of the null-space controller.

    ``gain_per_s``: feedback gain k [1/s] of eq. 14; ``feedforward``: ``jacobian`` or ``secant``
    (as for the tracking controller); ``objective``: ``repulsion``, ``energy`` or ``none`` (the
    default: eq. 14 alone);
    ``repulsion_radius_m``: pairs closer than this [m] repel (required for ``repulsion``);
    ``repulsion_gain_per_s``: c [1/s]; ``energy_weight``: w in [0, 1].
    """

    gain_per_s: float = 1.0
    feedforward: str = "jacobian"
    objective: str = "none"
    repulsion_radius_m: float | None = None
    repulsion_gain_per_s: float = 1.0
    energy_weight: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "gain_per_s", positive("controller.gain", self.gain_per_s))
        if self.feedforward not in FEEDFORWARDS:
            raise ValidationError(
                "controller.feedforward", f"expected one of {FEEDFORWARDS}, got {self.feedforward!r}"
            )
        if self.objective not in OBJECTIVES:
            raise ValidationError(
                "controller.objective", f"expected one of {OBJECTIVES}, got {self.objective!r}"
            )
        rep_gain = positive("controller.repulsion_gain", self.repulsion_gain_per_s)
        object.__setattr__(self, "repulsion_gain_per_s", rep_gain)
        if self.repulsion_radius_m is not None:
            radius = positive("controller.repulsion_radius", self.repulsion_radius_m)
            object.__setattr__(self, "repulsion_radius_m", radius)
        elif self.objective == "repulsion":
            raise ValidationError(
                "controller.repulsion_radius", "the repulsion objective needs a radius [m] (e.g. 1.5 * d_min)"
            )
        w = positive("controller.energy_weight", self.energy_weight, allow_zero=True)
        if w > 1.0:
            raise ValidationError("controller.energy_weight", f"expected a weight in [0, 1], got {w!r}")
        object.__setattr__(self, "energy_weight", w)


def repulsion_velocity(positions_m: Array, radius_m: float, gain_per_s: float) -> Array:
    """``u_i = c sum_{j: d_ij < radius} (radius - d_ij) (p_i - p_j) / d_ij`` [m/s], (n, d).

    Pairs come from a k-d tree (:func:`~mpcform.formation.geometry.pairs_within`); coincident drones
    (d_ij = 0) have no direction and are skipped.
    """
    out = np.zeros_like(positions_m)
    pairs = pairs_within(positions_m, radius_m)
    if pairs.shape[0] == 0:
        return out
    i, j = pairs[:, 0], pairs[:, 1]
    diff = positions_m[i] - positions_m[j]
    dist = np.linalg.norm(diff, axis=1)
    ok = dist > 0.0
    push = (gain_per_s * (radius_m - dist[ok]) / dist[ok])[:, None] * diff[ok]
    np.add.at(out, i[ok], push)
    np.add.at(out, j[ok], -push)
    return out


def project_secondary(jacobian: Array, secondary_mps: Array) -> Array:
    """``N u_sec`` with ``N = I - J J^+`` (corrected eq. 15), as (n, d) drone velocities [m/s]."""
    n, d = secondary_mps.shape
    return (nullspace_projector(jacobian) @ secondary_mps.reshape(n * d)).reshape(n, d)


class NullSpaceController(Controller):
    """Eq. 14 plus a secondary objective in the null space of J (corrected eq. 15).

    See the module docstring for the law, where the feedback sits and the objectives.
    ``v_max_mps`` saturates each drone's command (eq. 7). The last step's terms are kept in
    :attr:`last_primary_mps`, :attr:`last_secondary_mps` (the projected ``N u_sec``) and
    :attr:`last_jacobian` for inspection.
    """

    name = "nullspace"

    def __init__(
        self,
        reference: Reference,
        dt_s: float,
        settings: NullSpaceSettings | None = None,
        v_max_mps: float | None = None,
    ) -> None:
        self.settings = st = settings or NullSpaceSettings()
        check_gain_dt(st.gain_per_s, dt_s)
        self.reference, self.dt_s = reference, dt_s
        self.v_max_mps = None if v_max_mps is None else positive("limits.v_max", v_max_mps)
        tpl = reference.template
        self.last_primary_mps = np.zeros((tpl.n, tpl.dim))
        self.last_secondary_mps = np.zeros((tpl.n, tpl.dim))
        self.last_jacobian = np.zeros((tpl.n * tpl.dim, 0))

    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        """Eq. 14's tracking command plus the secondary objective projected by ``N = I - J J^+``."""
        p = self._check_positions(positions_m)
        st = self.settings
        target, ff = feedforward_targets(self.reference, t_s, self.dt_s, 1, st.feedforward)
        primary = tracking_command(p, target[0], ff[0], st.gain_per_s)
        if st.objective == "none":
            secondary = np.zeros_like(p)
        else:
            jac = formation_jacobian(self.reference.template, fit_formation(self.reference.template, p).state)
            radius = st.repulsion_radius_m  # set whenever objective == "repulsion"
            if st.objective == "repulsion" and radius is not None:
                wish = repulsion_velocity(p, radius, st.repulsion_gain_per_s)
            else:
                wish = -st.energy_weight * primary
            secondary = project_secondary(jac, wish)
            self.last_jacobian = jac
        self.last_primary_mps, self.last_secondary_mps = primary, secondary
        raw = primary + secondary
        u = saturate(raw, self.v_max_mps)
        return ControlStep(u, StepInfo("law", saturated=count_saturated(raw, u)))

"""Formation kinematics: forward map (eq. 10), Jacobian (eq. 12), pseudo-inverse, null space,
and the position-level inverse (best-fit similarity transform, Umeyama).

The formation velocity is ``xi_dot = (c_dot [m/s] (d), omega_world [rad/s] (1 or 3), s_dot [1/s])``,
so J is 2n x 4 (planar) or 3n x 7 (spatial); drone velocities are stacked drone by drone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from mpcform._validate import Array, finite_array
from mpcform.errors import ValidationError
from mpcform.formation.rotation import S_PLANAR, cross_world, omega_size
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template

PINV_RTOL = 1e-10
"""Singular values below ``PINV_RTOL * sigma_max`` count as zero in :func:`jacobian_pinv`."""


def velocity_size(dim: int) -> int:
    """Length of the formation velocity: 4 (planar) or 7 (spatial)."""
    return dim + omega_size(dim) + 1


def _check(template: Template, state: FormationState) -> None:
    if template.dim != state.dim:
        raise ValidationError("state", f"state has dimension {state.dim}, template has {template.dim}")


def forward_kinematics(template: Template, state: FormationState) -> Array:
    """Drone positions ``p_i = c + s R r_i`` [m], shape (n, d) (eq. 10 and eq. 13)."""
    _check(template, state)
    return state.centroid_m + state.scale * template.offsets @ state.rotation_body_to_world.T


def formation_jacobian(template: Template, state: FormationState) -> Array:
    """Formation Jacobian J (d n, 4 or 7): ``p_dot = J xi_dot`` (eq. 12, world-frame omega)."""
    _check(template, state)
    n, d = template.n, template.dim
    q = template.offsets @ state.rotation_body_to_world.T  # q_i = R r_i
    jac = np.zeros((n, d, velocity_size(d)))
    jac[:, :, :d] = np.eye(d)
    if d == 2:
        jac[:, :, 2] = state.scale * q @ S_PLANAR.T
    else:  # -s hat(q_i)
        jac[:, :, 3:6] = -state.scale * _hat_rows(q)
    jac[:, :, -1] = q
    return jac.reshape(n * d, -1)


def drone_velocities(template: Template, state: FormationState, xi_dot: Array) -> Array:
    """``J xi_dot`` as (n, d) drone velocities [m/s] without forming J (eq. 14 feedforward)."""
    _check(template, state)
    d = template.dim
    xi_dot = finite_array("xi_dot", xi_dot, (velocity_size(d),))
    q = template.offsets @ state.rotation_body_to_world.T
    omega = xi_dot[d:-1]
    return xi_dot[:d] + xi_dot[-1] * q + state.scale * cross_world(omega, q)


@dataclass(frozen=True)
class PseudoInverse:
    """SVD pseudo-inverse of J with its numerical rank (tolerance ``rtol * sigma_max``)."""

    matrix: Array
    rank: int
    singular_values: Array


def jacobian_pinv(jacobian: Array, rtol: float = PINV_RTOL) -> PseudoInverse:
    """Moore-Penrose pseudo-inverse by SVD; rank-aware, so collinear templates and n <= 2 work."""
    u, sv, vt = np.linalg.svd(jacobian, full_matrices=False)
    keep = sv > rtol * (sv[0] if sv.size else 0.0)
    inv = (vt[keep].T / sv[keep]) @ u[:, keep].T
    return PseudoInverse(inv, int(keep.sum()), sv)


def nullspace_projector(jacobian: Array, rtol: float = PINV_RTOL) -> Array:
    """``N = I - J J^+``: drone motions that leave the formation velocity unchanged.

    The seed's eq. 15 prints ``I - J^+ J``, which is (7 x 7) and does not type-check against
    ``u in R^{3n}``; the projector onto the orthogonal complement of range(J) is ``I - J J^+``
    (from the SVD of J with a rank tolerance, so rank-deficient J work too). It is symmetric,
    idempotent, and ``J^+ N = 0``. Numerically, drone velocities ``J J^+ N u`` stay at roundoff; a
    formation rate along a direction whose singular value is barely above the cut carries roundoff
    amplified by ``sigma_max / sigma_min`` (at most ``1 / rtol``), as any pseudo-inverse does.
    """
    u, sv, _ = np.linalg.svd(jacobian, full_matrices=False)
    basis = u[:, sv > rtol * (sv[0] if sv.size else 0.0)]
    return np.eye(jacobian.shape[0]) - basis @ basis.T


@dataclass(frozen=True)
class FormationFit:
    """Best-fit formation state of measured positions and its residual.

    ``residual_rms_m`` is the shape error: the RMS distance [m] between the positions and
    the fitted formation. ``rotation_identifiable`` is False when the template spans fewer
    than d - 1 dimensions (collinear in 3D, or one point): then compare positions, not R.
    ``scale_identifiable`` is False when no proper rotation and positive scale fit the positions
    (they are close to a mirror image of the template, or the template is one point): ``state``
    is then the fallback of :func:`fit_formation`, not a best fit.
    """

    state: FormationState
    residual_rms_m: float
    rotation_identifiable: bool
    scale_identifiable: bool = True


def fit_formation(template: Template, positions_m: ArrayLike) -> FormationFit:
    """Similarity Procrustes (Umeyama 1991): argmin over (c, R, s) of sum ||p_i - c - s R r_i||^2.

    R is a proper rotation and s > 0. The reflection-corrected scale is ``(sv_1 - sv_2) / var_r``
    in 2-D: zero when the positions mirror a regular polygon (in 3-D ``sv_1 + sv_2 - sv_3 > 0``).
    When it is at most 1e-9 of the size ratio, no proper rotation and positive scale fit the
    positions: the fit falls back to the centroid, the best proper rotation and the RMS size ratio
    ``s = sqrt(sum ||p_i - c||^2 / sum ||r_i||^2)``, and says ``scale_identifiable=False``.
    Only positions that all coincide (zero spread) are an error.
    """
    d = template.dim
    p = finite_array("positions", positions_m, (template.n, d))
    centroid = p.mean(axis=0)
    y, r = p - centroid, template.offsets
    var_r, var_y = float((r * r).sum() / template.n), float((y * y).sum() / template.n)
    if var_r == 0.0:
        return FormationFit(FormationState(centroid, np.eye(d), 1.0), float(np.sqrt(var_y)), False, False)
    if var_y == 0.0:
        raise ValidationError("positions", "all drones coincide: the formation scale is not identifiable")
    u, sv, vt = np.linalg.svd(y.T @ r / template.n)
    sign = np.ones(d)
    sign[-1] = np.sign(np.linalg.det(u @ vt)) or 1.0
    rot = (u * sign) @ vt
    scale = float((sv * sign).sum() / var_r)
    size_ratio = float(np.sqrt(var_y / var_r))
    identifiable = scale > 1e-9 * size_ratio
    if not identifiable:
        scale = size_ratio
    resid = y - scale * r @ rot.T
    rank_r = int(np.linalg.matrix_rank(r, tol=1e-9 * np.abs(r).max()))
    return FormationFit(
        FormationState(centroid, rot, scale),
        float(np.sqrt((resid * resid).sum() / template.n)),
        rank_r >= d - 1,
        identifiable,
    )


def _hat_rows(q: Array) -> Array:
    """Skew matrices of the rows of q (n, 3) -> (n, 3, 3)."""
    out = np.zeros((q.shape[0], 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -q[:, 2], q[:, 1]
    out[:, 1, 0], out[:, 1, 2] = q[:, 2], -q[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -q[:, 1], q[:, 0]
    return out

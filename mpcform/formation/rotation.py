"""Rotations in one convention for planar (angle) and spatial (rotation vector) formations.

Spatial rotations go through :class:`scipy.spatial.transform.Rotation`; a rotation
*parameter* is an angle [rad] (d = 2) or a rotation vector [rad] (d = 3). Angular
velocities are world-frame (``R_dot = hat(w_world) R``, seed eq. 11).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from mpcform._validate import Array, finite_array
from mpcform.errors import ValidationError

ORTHONORMAL_TOL = 1e-9
S_PLANAR = np.array([[0.0, -1.0], [1.0, 0.0]])  # planar cross product: w x q = w * S q


def omega_size(dim: int) -> int:
    """Number of angular-velocity components: 1 (planar) or 3 (spatial)."""
    return 1 if dim == 2 else 3


def rotation_matrix(dim: int, param: ArrayLike, field: str = "rotation") -> Array:
    """Rotation matrix (d, d) of an angle (d = 2) or a rotation vector (d = 3), in radians."""
    if dim == 2:
        theta = float(finite_array(field, param, ()))
        c, s = np.cos(theta), np.sin(theta)
        return np.array([[c, -s], [s, c]])
    rotvec = finite_array(field, param, (3,))
    return Rotation.from_rotvec(rotvec).as_matrix()


def rotation_param(rotation: Array) -> Array:
    """Inverse of :func:`rotation_matrix`: the angle in (-pi, pi] or the rotation vector."""
    if rotation.shape == (2, 2):
        return np.array(np.arctan2(rotation[1, 0], rotation[0, 0]))
    return Rotation.from_matrix(rotation).as_rotvec()


def check_rotation(field: str, value: ArrayLike, dim: int) -> Array:
    """Validate a proper rotation matrix (orthonormal, det = +1) of size d."""
    r = finite_array(field, value, (dim, dim))
    err = np.abs(r.T @ r - np.eye(dim)).max()
    if err > ORTHONORMAL_TOL or np.linalg.det(r) < 0:
        raise ValidationError(
            field,
            f"expected a proper rotation matrix (R^T R = I, det R = +1); "
            f"got |R^T R - I| = {err:.2e}, det R = {np.linalg.det(r):.6g}",
        )
    return r


def hat(w: Array) -> Array:
    """Skew-symmetric matrix of a 3-vector: ``hat(w) @ a == cross(w, a)``."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def cross_world(omega: Array, q: Array) -> Array:
    """``omega x q`` for rows ``q`` (m, d): scalar omega (planar) or 3-vector (spatial)."""
    if q.shape[-1] == 2:
        return float(np.asarray(omega).reshape(-1)[0]) * (q @ S_PLANAR.T)
    return np.cross(np.asarray(omega).reshape(3), q)


def geodesic(r0: Array, r1: Array) -> tuple[Array, float]:
    """Unit axis a and angle phi >= 0 with ``r1 = r0 exp(phi hat(a))`` (planar axis: [1] or [-1])."""
    rel = r0.T @ r1
    if rel.shape == (2, 2):
        ang = float(np.arctan2(rel[1, 0], rel[0, 0]))
        return np.array([1.0 if ang >= 0 else -1.0]), abs(ang)
    rotvec = Rotation.from_matrix(rel).as_rotvec()
    phi = float(np.linalg.norm(rotvec))
    axis = rotvec / phi if phi > 0 else np.array([0.0, 0.0, 1.0])
    return axis, phi


def exp_body(r0: Array, axis: Array, phi: float) -> Array:
    """``r0 exp(phi hat(axis))``: rotation by ``phi`` about the body-frame ``axis`` of r0."""
    if r0.shape == (2, 2):
        return r0 @ rotation_matrix(2, float(axis[0]) * phi)
    return r0 @ Rotation.from_rotvec(axis * phi).as_matrix()

"""The formation's rotation about z, as a yaw for every drone (``--yaw formation``).

At each sample the rotation ``R`` that best maps the centred template offsets onto the centred
positions (least squares, the Kabsch/Procrustes solution: ``R = V diag(1, .., det) U^T`` from the
SVD ``U S V^T`` of ``offsets^T positions``; scale does not change it) gives the yaw
``atan2(R[1, 0], R[0, 0])``: the rotation angle of a planar formation, the z-yaw of a spatial
one's rotation. The angles are unwrapped so the yaw is continuous.
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array


def formation_yaw(positions_m: Array, offsets_m: Array) -> Array:
    """Yaw (T,) [rad] of positions (T, n, d) relative to the template offsets (n, d)."""
    p = positions_m - positions_m.mean(axis=1, keepdims=True)
    o = offsets_m - offsets_m.mean(axis=0)
    h = np.einsum("nd,tne->tde", o, p)  # (T, d, d)
    u, _, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, -1, -2)
    sign = np.sign(np.linalg.det(v @ np.swapaxes(u, -1, -2)))
    v[..., -1] *= sign[:, None]
    r = v @ np.swapaxes(u, -1, -2)
    return np.unwrap(np.arctan2(r[:, 1, 0], r[:, 0, 0]))

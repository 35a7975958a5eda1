"""The formation's yaw: the rotation that maps the template onto the positions."""

from __future__ import annotations

import numpy as np

from mpcform.outputs.flight.yaw import formation_yaw


def test_planar_and_spatial_rotations_about_z() -> None:
    offsets = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.5], [-1.0, -0.5, -0.5], [0.3, 0.2, 1.0]])
    angles = np.linspace(0.0, 4.0, 30)  # beyond pi: unwrapped
    c, s = np.cos(angles), np.sin(angles)
    rot = np.zeros((30, 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, -s, s, c, 1.0
    positions = 1.7 * np.einsum("tij,nj->tni", rot, offsets) + np.array([3.0, -1.0, 2.0])
    assert np.allclose(formation_yaw(positions, offsets), angles)
    assert np.allclose(formation_yaw(positions[..., :2], offsets[:, :2]), angles)

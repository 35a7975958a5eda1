"""The formation state ``xi = (c, R, s)`` (seed eq. 9)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from mpcform._validate import Array, dimension, finite_array, positive
from mpcform.formation.rotation import check_rotation, rotation_matrix, rotation_param


@dataclass(frozen=True, eq=False)
class FormationState:
    """Centroid ``centroid_m`` (d,), rotation ``rotation_body_to_world`` (d, d), scale (> 0).

    Build one from a rotation parameter with :meth:`from_param` (an angle [rad] for d = 2, a
    rotation vector [rad] for d = 3).
    """

    centroid_m: Array
    rotation_body_to_world: Array
    scale: float

    def __post_init__(self) -> None:
        c = finite_array("state.centroid", self.centroid_m, (None,))
        dim = dimension("state.centroid (length)", c.shape[0])
        rot = check_rotation("state.rotation", self.rotation_body_to_world, dim)
        c.setflags(write=False)
        rot.setflags(write=False)
        object.__setattr__(self, "centroid_m", c)
        object.__setattr__(self, "rotation_body_to_world", rot)
        object.__setattr__(self, "scale", positive("state.scale", self.scale))

    @classmethod
    def from_param(
        cls, centroid_m: ArrayLike, rotation: ArrayLike | None = None, scale: float = 1.0
    ) -> FormationState:
        """State from a centroid, a rotation parameter (default identity) and a scale."""
        c = finite_array("state.centroid", centroid_m, (None,))
        dim = dimension("state.centroid (length)", c.shape[0])
        if rotation is None:
            rotation = 0.0 if dim == 2 else np.zeros(3)
        return cls(c, rotation_matrix(dim, rotation, "state.rotation"), scale)

    @property
    def dim(self) -> int:
        """Spatial dimension d (2 planar, 3 spatial)."""
        return int(self.centroid_m.shape[0])

    @property
    def rotation_param(self) -> Array:
        """Angle [rad] (planar) or rotation vector [rad] (spatial)."""
        return rotation_param(self.rotation_body_to_world)

    def __repr__(self) -> str:
        return (
            f"FormationState(centroid_m={self.centroid_m.tolist()}, "
            f"rotation={np.round(self.rotation_param, 12).tolist()}, scale={self.scale:.12g})"
        )

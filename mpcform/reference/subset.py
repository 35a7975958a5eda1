"""Some drones of a formation reference: the targets of the drones still flying.

When drones are lost (flipped or on the floor), the planner of the others plans over their
columns of the formation's targets (:meth:`mpcform.mpc.planner.MPCPlanner.lose`): the formation
keeps its shape, centroid and scale (eq. 13), the lost drones' places stay empty.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.formation.template import Template
from mpcform.reference.base import Profile, Reference


class SubsetReference(Reference):
    """The targets of drones ``keep`` (sorted, unique) of ``parent``; ``template`` holds their
    offsets centred again (its ``n`` and ``dim`` are what a planner reads; the targets are the
    parent's)."""

    def __init__(self, parent: Reference, keep: ArrayLike) -> None:
        keep = np.asarray(keep, dtype=int)
        n = parent.template.n
        if keep.ndim != 1 or keep.size == 0 or np.any(np.diff(keep) <= 0) or keep[0] < 0 or keep[-1] >= n:
            raise ValidationError("drones", f"expected sorted unique drone indices in 0..{n - 1}, got {keep}")
        self.parent, self.keep = parent, keep
        self.template, _ = Template.centred(parent.template.offsets[keep], parent.template.name)

    def profile(self, times_s: Array) -> Profile:
        """The parent's formation profile (centroid, rotation and scale)."""
        return self.parent.profile(times_s)

    def targets(self, times_s: ArrayLike) -> tuple[Array, Array]:
        """The parent's targets ``p*``, ``p_dot*`` of the kept drones, each (T, len(keep), d)."""
        pos, vel = self.parent.targets(times_s)
        return pos[:, self.keep], vel[:, self.keep]

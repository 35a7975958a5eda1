"""Random templates and formation states shared by the test modules (seeded numpy)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mpcform.state import FormationState
from mpcform.template import Template


def random_template(rng: np.random.Generator, n: int, dim: int) -> Template:
    """n random offsets in [-2, 2]^dim, centred."""
    return Template.centred(rng.uniform(-2.0, 2.0, (n, dim)))[0]


def random_state(rng: np.random.Generator, dim: int) -> FormationState:
    """A random centroid, rotation (any angle or axis) and scale in [0.5, 3]."""
    rotation = rng.uniform(-np.pi, np.pi) if dim == 2 else Rotation.random(rng=rng).as_rotvec()
    return FormationState.from_param(rng.uniform(-10.0, 10.0, dim), rotation, rng.uniform(0.5, 3.0))

"""Random templates and formation states, and QP row blocks as dense matrices, shared by the test
modules (seeded numpy)."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.spatial.transform import Rotation

from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.constraints.rows import Layout, RowBlock
from mpcform.reference.base import ConstantReference
from mpcform.world.bounds import PlanningBounds
from mpcform.world.limits import Limits


def random_template(rng: np.random.Generator, n: int, dim: int) -> Template:
    """n random offsets in [-2, 2]^dim, centred."""
    return Template.centred(rng.uniform(-2.0, 2.0, (n, dim)))[0]


def random_state(rng: np.random.Generator, dim: int) -> FormationState:
    """A random centroid, rotation (any angle or axis) and scale in [0.5, 3]."""
    rotation = rng.uniform(-np.pi, np.pi) if dim == 2 else Rotation.random(rng=rng).as_rotvec()
    return FormationState.from_param(rng.uniform(-10.0, 10.0, dim), rotation, rng.uniform(0.5, 3.0))


def tiny_swap_toml(name: str, radius_m: float, horizon: int, duration_s: float) -> str:
    """A scenario file: 4 planar drones on a ring swapping sides (half a turn) under the MPC."""
    return f"""version = 1
name = "{name}"
dim = 2
seed = 0

[template]
shape = "polygon"
n = 4
radius = {radius_m}

[initial]
centroid = [0.0, 0.0]
rotation = 3.141592653589793

[reference]
kind = "constant"
rotation = 0.0

[limits]
v_max = 1.0
d_min = 0.5

[controller]
kind = "mpc"
horizon = {horizon}

[simulation]
dt = 0.1
duration = {duration_s}
"""


def crowd_and_swap(dim: int = 2) -> list[tuple[ConstantReference, np.ndarray]]:
    """A crowd of 6 drones 0.3-0.6 m apart crossing to a line 1 m apart, and an antipodal swap of 4."""
    rng = np.random.default_rng(7)
    crowd_start = np.array([[0.0, 0.0], [0.6, 0.0], [1.2, 0.0], [0.0, 0.6], [0.6, 0.6], [1.2, 0.6]])
    crowd = ConstantReference(Template.line(6, 5.0), FormationState.from_param([0.6, 0.3], 1.0))
    ring = Template.polygon(4, 1.5)
    swap = ConstantReference(ring, FormationState.from_param([0.0, 0.0]))
    return [(crowd, crowd_start + rng.normal(0, 0.01, (6, 2))), (swap, -ring.offsets.copy())]


def dense_matrix(block: RowBlock, lay: Layout) -> np.ndarray:
    """The block's rows as a dense matrix over all of z (duplicate entries summed, as in CSC)."""
    m = block.lower.shape[0]
    vals = np.broadcast_to(block.vals, block.rows.shape).ravel()
    return sp.coo_matrix((vals, (block.rows.ravel(), block.cols.ravel())), shape=(m, lay.n_var)).toarray()


def z_of(lay: Layout, u: np.ndarray, x: np.ndarray, s: np.ndarray) -> np.ndarray:
    return np.concatenate([u.ravel(), x.ravel(), s.ravel()])


def bounds_of(tube_m: float = 0.0, growth_m: float = 0.0, **limits: Any) -> PlanningBounds:
    """Planning bounds exactly as these limits state them (no default a_max, nothing tightened):
    what the planner's parts are built with."""
    return PlanningBounds.of(Limits(**limits), tube_m, growth_m)

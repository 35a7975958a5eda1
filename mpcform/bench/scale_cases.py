"""The two spatial scenarios of ``mpcform bench scale``, at constant density for any number of drones.

Every formation is a lattice of spacing ``SPACING_M`` (so the occupied volume grows with n); the
runs use ``dt = 0.1 s``, ``v_max = 1 m/s``, ``d_min = 0.5 m``:

- **formation**: a cubic grid formation translating and turning about z
  (:class:`~mpcform.reference.base.ExponentialReference`, rate 0.1/s; at the start the centroid moves
  at 0.3 m/s and the outermost drone turns at 0.2 m/s, so reference speeds stay well inside the
  velocity polytope and the fast path normally applies), drones starting on the reference with
  a seeded 5 cm perturbation;
- **crossing**: two slab-shaped grid formations (two layers deep along x) flying head-on
  through each other at 0.5 m/s each, laterally offset by less than ``d_min`` so that every
  drone of a column meets the drones of the opposite column (:class:`CrossingReference`). The
  run starts with the fronts one spacing apart, so the measured steps are inside the crossing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.formation.kinematics import velocity_size
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.reference.base import ExponentialReference, Profile, Reference
from mpcform.world.limits import Limits

SCENARIOS = ("formation", "crossing")
SPACING_M = 1.5  # lattice spacing of every formation [m] (constant density)
LIMITS = Limits(v_max_mps=1.0, d_min_m=0.5)
DT_S = 0.1
FORMATION_RATE_PER_S = 0.1  # ExponentialReference rate
FORMATION_TRANSLATION_MPS = 0.3  # centroid speed at t = 0
FORMATION_RIM_MPS = 0.2  # speed of the outermost drone due to the turn, at t = 0
FORMATION_PERTURBATION_M = 0.05
CROSSING_SPEED_MPS = 0.5  # each slab's speed; they close at twice this
CROSSING_LATERAL_M = (0.15, 0.1)  # y, z offset of the second slab's columns (< d_min)


class CrossingReference(Reference):
    """Drone ``i``'s target moves from ``start_m[i]`` at constant ``velocity_mps[i]``.

    Two groups flying through each other are not a rigid formation motion, so :meth:`targets`
    is given directly; :meth:`profile` describes the (centred) template at rest.
    """

    def __init__(self, start_m: Array, velocity_mps: Array) -> None:
        self.template, shift = Template.centred(start_m, name="crossing")
        self.start_m = np.asarray(start_m, dtype=float) - shift
        self.velocity_mps = np.asarray(velocity_mps, dtype=float)

    def profile(self, times_s: Array) -> Profile:
        t, d = times_s.shape[0], self.template.dim
        zeros = np.zeros((t, d))
        return Profile(
            zeros,
            np.broadcast_to(np.eye(d), (t, d, d)),
            np.ones(t),
            zeros,
            np.zeros((t, velocity_size(d) - d - 1)),
            np.zeros(t),
        )

    def targets(self, times_s: ArrayLike) -> tuple[Array, Array]:
        t = np.atleast_1d(np.asarray(times_s, dtype=float))
        pos = self.start_m + t[:, None, None] * self.velocity_mps
        return pos, np.broadcast_to(self.velocity_mps, pos.shape).copy()


def lattice(n: int, shape: Sequence[int], spacing_m: float = SPACING_M) -> Array:
    """The first ``n`` points (n, len(shape)) of a ``shape`` lattice (row-major order), centred along
    every axis but the first."""
    axes = [spacing_m * np.arange(k) for k in shape]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(shape))[:n]
    pts[:, 1:] -= 0.5 * spacing_m * (np.asarray(shape[1:]) - 1)
    return pts


def formation_case(n: int, seed: int = 0) -> tuple[Reference, Array]:
    """Grid formation translating and turning about z; start positions (n, 3) near its start."""
    side = max(1, math.ceil(round(n ** (1.0 / 3.0), 9)))
    tpl, _ = Template.centred(lattice(n, (side, side, side)), name="grid")
    rim = max(float(np.linalg.norm(tpl.offsets, axis=1).max()), SPACING_M)
    lam = FORMATION_RATE_PER_S
    move = FORMATION_TRANSLATION_MPS / lam * np.array([2.0, 1.0, 0.5]) / np.sqrt(5.25)
    start = FormationState.from_param(np.array([0.0, 0.0, 20.0]))
    turn = np.array([0.0, 0.0, FORMATION_RIM_MPS / (lam * rim)])  # rotation vector [rad]
    goal = FormationState.from_param(start.centroid_m + move, turn)
    ref = ExponentialReference(tpl, start, goal, lam)
    rng = np.random.default_rng([seed, n])
    p0 = ref.targets(0.0)[0][0] + rng.normal(0.0, FORMATION_PERTURBATION_M, (n, 3))
    return ref, p0


def crossing_case(n: int, gap_m: float = SPACING_M) -> tuple[Reference, Array]:
    """Two slabs (2 layers deep along x), fronts ``gap_m`` apart, flying head-on through each other."""
    if n < 2:
        raise ValidationError("n", f"a crossing needs at least 2 drones, got {n}")
    m_a, m_b = n // 2, n - n // 2
    face = math.ceil(m_b / 2)
    width = math.ceil(math.sqrt(face))
    shape = (2, width, math.ceil(face / width))
    a = lattice(m_a, shape)
    b = lattice(m_b, shape) * np.array([-1.0, 1.0, 1.0])  # layers mirrored: the fronts face each other
    a[:, 0] -= 0.5 * gap_m + SPACING_M  # front layer at x = -gap/2
    b[:, 0] += 0.5 * gap_m + SPACING_M
    b[:, 1:] += CROSSING_LATERAL_M
    velocity = np.zeros((n, 3))
    velocity[:m_a, 0], velocity[m_a:, 0] = CROSSING_SPEED_MPS, -CROSSING_SPEED_MPS
    ref = CrossingReference(np.vstack([a, b]), velocity)
    return ref, ref.targets(0.0)[0][0].copy()


def make_case(scenario: str, n: int) -> tuple[Reference, Array]:
    """Reference and start positions of a scenario of ``SCENARIOS``."""
    if scenario == "formation":
        return formation_case(n)
    if scenario == "crossing":
        return crossing_case(n)
    raise ValidationError("scenario", f"expected one of {SCENARIOS}, got {scenario!r}")

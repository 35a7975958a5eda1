"""What a constraint family is: one unit per constraint, from its rows to its tests.

Two kinds share the planner's step (:mod:`mpcform.mpc.planner`):

- a **limit family** (:class:`LimitRows`: the velocity set, :mod:`~mpcform.mpc.constraints.velocity`;
  command changes, :mod:`~mpcform.mpc.constraints.acceleration`; the geofence,
  :mod:`~mpcform.mpc.constraints.geofence`) has the same rows on every drone at every step: it
  builds them for the sparse QP of all drones (:mod:`mpcform.mpc.solve.sparse_qp`) and for one
  drone's dense QP over its inputs (:mod:`mpcform.mpc.solve.per_drone`), writes their bounds each
  step, and names the drones whose plan breaks them (the fast path's test);
- a **separation family** (:class:`SeparationFamily`: drone pairs,
  :mod:`~mpcform.mpc.constraints.pairs`; obstacles, :mod:`~mpcform.mpc.constraints.obstacles`)
  has rows per item within reach, linearised about the guess every step (``c^T x + s >= b``, one
  layout for all, :mod:`mpcform.mpc.constraints.separation_rows`): it builds them, and answers the
  fast path's clear test and the certification of the first segment for its items.

The braking tail (:mod:`~mpcform.mpc.constraints.braking`, :mod:`~mpcform.mpc.constraints.tail`)
is not a family of its own: it adds the positions past the horizon at which the geofence and
separation families write their rows. The variables and their layout are in
:mod:`mpcform.mpc.constraints.rows`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

from mpcform._validate import Array
from mpcform.mpc.constraints.half_spaces import ClearInputs, SegmentTest
from mpcform.mpc.constraints.rows import Layout, RowBlock


class LimitRows(ABC):
    """One limit's rows on every drone at every step, for the sparse and the per-drone QP."""

    fixed_bounds = False  # whether the dense rows' bounds are the same for every drone and step

    @abstractmethod
    def sparse(self, lay: Layout) -> RowBlock:
        """Rows of the sparse QP, with the bounds that stay the same from step to step."""

    def set_bounds(  # noqa: B027
        self, lower: Array, upper: Array, p0: Array, u_prev: Array, free_m: Array | None = None
    ) -> None:
        """Write this step's bounds into the family's part of the sparse QP's bounds (in place);
        ``p0`` (n, d) starts [m], ``u_prev`` (n, d) last commands [m/s], ``free_m`` (S, n, d) with a
        velocity loop its free response at each bounded position (:mod:`mpcform.mpc.velocity_loop`)."""

    @abstractmethod
    def dense(self) -> Array:
        """Rows (m, H d) over one drone's inputs u_0 .. u_{H-1} (the per-drone QP)."""

    @abstractmethod
    def dense_bounds(
        self, p0: Array, u_prev: Array, inf: float, free_m: Array | None = None
    ) -> tuple[Array, Array]:
        """Bounds (n, m) of the dense rows for each drone; ``inf`` stands for no bound."""

    @abstractmethod
    def violators(self, p0: Array, u_prev: Array, u: Array, x: Array, tol: float = 0.0) -> Array:
        """Drones (n,) whose inputs ``u`` and relative positions ``x`` (H, n, d) break a row by more
        than ``tol`` [m/s or m]."""


class SeparationFamily(ABC):
    """One separation family's items (``(drone, partner)`` with ``partner`` a drone, or
    ``(drone, obstacle)``): rows about the guess and the tests on a plan."""

    margin_m: float

    @abstractmethod
    def doubtful(self, p0: Array, spread: Array) -> tuple[Array, Array, Array]:
        """The items ``(i, k)`` the per-drone spread bound of the clear test leaves in doubt from
        the starts ``p0`` (n, d) and the spreads (n,), and by how much they clear it (negative)."""

    @abstractmethod
    def clear_test(self, guess: Array, pos: Array, i: Array, k: Array) -> ClearInputs:
        """The clear test's inputs for the items ``(i, k)``
        (:data:`~mpcform.mpc.constraints.half_spaces.ClearInputs`)."""

    @abstractmethod
    def first_segment(self, p0: Array, p1: Array, items: Array) -> SegmentTest:
        """The items' distance at ``p0``, along the first segment to ``p1``, and the required one
        (the certification's test, :mod:`mpcform.mpc.safety.certify`)."""

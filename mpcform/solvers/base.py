"""QP backends behind one interface: set up once, update the data that changes, solve.

Problem form (OSQP's): ``min 0.5 z^T P z + q^T z  s.t.  l <= A z <= u`` with ``P`` upper
triangular CSC and +-inf for absent bounds. A backend never raises inside the planning loop:
failures come back as a :class:`QPSolution` with ``success = False`` and the solver's status.

The backends themselves, and the names that select them, are in :mod:`mpcform.solvers.registry`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import scipy.sparse as sp

from mpcform._validate import Array


@dataclass(frozen=True)
class QPSolution:
    """Primal ``x`` and dual ``y`` (None unless ``success``; ``y`` also None when the backend
    gives no duals), status text, iterations (0 when not reported), wall time [s], the
    ``objective`` ``0.5 x^T P x + q^T x`` at ``x`` (None unless ``success``) and solver-specific
    ``extras`` (residuals, gaps: whatever the backend reports)."""

    x: Array | None
    y: Array | None
    success: bool
    status: str
    iterations: int
    solve_time_s: float
    objective: float | None = None
    extras: Mapping[str, Any] = field(default_factory=dict)


def failed(status: str, elapsed_s: float = 0.0, iterations: int = 0) -> QPSolution:
    """A failed solve with its reason."""
    return QPSolution(None, None, False, status, iterations, elapsed_s)


@dataclass(frozen=True)
class SolverOptions:
    """Tolerances and limits passed to the solver; ``None`` keeps the solver's own default.

    ``eps_abs`` / ``eps_rel``: absolute / relative tolerance on residuals (mapped to each
    solver's own parameters); ``max_iter``: iteration limit; ``time_limit_s``: per-solve time
    limit [s] for solvers that take one (0: none).
    """

    eps_abs: float | None = 1e-5
    eps_rel: float | None = 1e-5
    max_iter: int | None = 4000
    time_limit_s: float = 0.0


def given(**values: Any) -> dict[str, Any]:
    """The keyword arguments whose value is not None: a solver's settings from
    :class:`SolverOptions`, leaving out what keeps the solver's own default."""
    return {k: v for k, v in values.items() if v is not None}


@dataclass(frozen=True)
class QPContext:
    """What the planner's QP means, for backends that need more than its matrices.

    Variables (see :mod:`mpcform.mpc.solve.sparse_qp`): ``z = [u_0 .. u_{H-1} | x_1 .. x_H | s_1 .. s_H]``,
    inputs and positions relative to the start (``x_j = p_j - p0``), each block (H, n, d) stacked
    step-major, then one slack per step and drone (H, n). Rows ``separation_rows`` (start, stop)
    are the linearised separation rows. The exact (non-convex) separation they stand for, at every
    position step e = 1..H::

        ||W (p0_i + x_{e,i} - p0_k - x_{e,k})|| + s_{e,i} + s_{e,k} >= pair_distance_m
        ||p0_i + x_{e,i} - c_o|| + s_{e,i} >= obstacle_distance_m[o]

    for the ``pairs`` (i, k) within reach and the (``obstacle_drones[o]``, obstacle o) items,
    with ``W = diag(metric)`` (downwash scaling).
    """

    n: int
    dim: int
    horizon: int
    separation_rows: tuple[int, int]
    start_m: Array  # (n, d) p0
    pairs: Array  # (P, 2) int
    pair_distance_m: float
    metric: Array  # (d,)
    obstacle_drones: Array  # (O,) int
    obstacle_centers_m: Array  # (O, d)
    obstacle_distance_m: Array  # (O,)

    @property
    def nud(self) -> int:
        """Number of input (and of position) variables, H n d."""
        return self.horizon * self.n * self.dim

    @property
    def n_var(self) -> int:
        return 2 * self.nud + self.horizon * self.n


class QPBackend(ABC):
    """One QP family, solved repeatedly. ``setup`` whenever the sparsity pattern changes.

    Class attributes say what a caller may rely on: ``warm_starts`` (``solve`` uses ``x0``),
    ``persistent`` (``update`` is cheaper than ``setup``), ``needs_context`` (call
    :meth:`set_context` before each solve), ``stagewise`` (every row but the dynamics lies in
    one stage: no acceleration rows), ``point_obstacles_only`` (it writes each obstacle's exact
    distance to its centre: only obstacles whose core is a point).
    """

    name: str
    warm_starts: bool = False
    """Whether :meth:`solve` uses ``x0`` (callers skip building it otherwise)."""
    persistent: bool = False
    needs_context: bool = False
    stagewise: bool = False
    point_obstacles_only: bool = False

    def __init__(self, options: SolverOptions) -> None:
        self.options = options

    @abstractmethod
    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        """Take a new problem (copies what it keeps)."""

    @abstractmethod
    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        """New cost vector, bounds and values of A (same pattern as at setup)."""

    @abstractmethod
    def solve(self, x0: Array | None = None) -> QPSolution:
        """Solve, warm-started from ``x0`` where the backend supports it."""

    def set_context(self, context: QPContext) -> None:  # noqa: B027 - optional hook
        """The meaning of the current problem (used only by backends with ``needs_context``)."""

    def limit_iterations(self, max_iter: int | None) -> None:  # noqa: B027 - optional hook
        """Cap the next solves at ``max_iter`` iterations (None: the limit set up again); a
        backend without the setting ignores it."""

"""Small dense QPs solved one after another: the interface of the per-drone backends.

Problem form (DAQP's)::

    min 0.5 x^T H x + f^T x   s.t.  lower_k <= x_k <= upper_k  (k < s),   lower <= A x <= upper

with ``H`` positive definite, the first ``s = len(upper) - rows(A)`` bounds simple bounds on the
first ``s`` variables and :data:`NO_BOUND` for an absent bound. The per-drone planner
(:mod:`mpcform.mpc.solve.per_drone`) takes from a solve its primal point, its cost, whether it is
optimal (an infeasible hard QP sends the drone to its soft QP) and the multipliers of every
bound in DAQP's sign convention, which its split rounds (:mod:`mpcform.mpc.solve.split`) and working
sets rely on. The backends and their names are in :mod:`mpcform.solvers.registry`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

from mpcform._validate import Array

NO_BOUND = 1e30
"""An absent bound (DAQP's infinity): an upper bound of ``NO_BOUND`` or a lower of ``-NO_BOUND``."""


@dataclass(frozen=True)
class DenseSolution:
    """One dense solve: ``x`` (undefined unless ``success``), the cost ``0.5 x^T H x + f^T x``, the
    backend's ``exit_flag``, the ``multipliers`` (s + rows,) of the simple bounds then the rows
    (``> 0`` at an upper bound, ``< 0`` at a lower bound, ``0`` inactive) and ``iterations``
    (0 when not reported)."""

    x: Array
    cost: float
    success: bool
    exit_flag: int
    multipliers: Array
    iterations: int


class DenseQPBackend(ABC):
    """Solves small dense QPs of the form above, each from scratch (``x0`` a warm start where
    ``warm_starts``). ``max_iter`` caps the iterations of a solve (None: the backend's own)."""

    name: str
    warm_starts: bool = False

    def __init__(self, max_iter: int | None = None) -> None:
        self.max_iter = max_iter

    @abstractmethod
    def solve(
        self, hessian: Array, f: Array, rows: Array, upper: Array, lower: Array, x0: Array | None = None
    ) -> DenseSolution:
        """The QP's solution; never raises for an infeasible or failed solve (``success`` False)."""
